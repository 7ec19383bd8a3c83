"""Snakemake script: a classifier's and the physics rule's predictions + the features and split
table -> the joined method's predictions, metrics, info and coverage (per tested record, its
share of segments outside the fit's training range; condmon.joined).

`snakemake` is injected by Snakemake's script directive.
"""

import json

import pandas as pd

from condmon.atomic import write_json, write_text
from condmon.features import read_feature_table
from condmon.hybrid import read_split_table
from condmon.joined import joined_metrics, joined_name, joined_predictions, prediction_frame
from condmon.runlog import setup_logging
from condmon.train import matching_feature_names, write_metrics, write_predictions

log = setup_logging(snakemake)  # to snakemake.log[0]
inputs, classifier = snakemake.input, snakemake.params.classifier
simulated, simulated_names = read_feature_table(inputs.simulated)
measured, measured_names = read_feature_table(inputs.measured)
names = matching_feature_names(simulated_names, measured_names)
info = json.loads(open(inputs.info).read())
joined, summary, coverage = joined_predictions(
    classifier,
    pd.read_parquet(inputs.predictions),
    pd.read_parquet(inputs.rule),
    info["models"],
    simulated,
    measured,
    read_split_table(inputs.splits),
    names,
)
write_predictions(prediction_frame(joined), snakemake.output.predictions)
write_metrics(
    joined_metrics(classifier, joined, pd.read_csv(inputs.metrics, dtype={"holdout": str})),
    snakemake.output.metrics,
)
write_text(coverage.to_csv(index=False), snakemake.output.coverage)
write_json({**summary, "protocol": info["protocol"]}, snakemake.output.info)
log.info(
    "%s: %d predictions, %.3f of them outside the training range (the rule's call there)",
    joined_name(classifier),
    len(joined),
    summary["outside_training_share"],
)
