"""Snakemake script: measured features -> split table of one protocol.

`snakemake` is injected by Snakemake's script directive.
"""

import pandas as pd

from condmon.features import read_feature_table
from condmon.hybrid import write_split_table
from condmon.protocols import make_splits, protocol_from
from condmon.runlog import setup_logging

log = setup_logging(snakemake)  # to snakemake.log[0]
params = snakemake.params

measured, _ = read_feature_table(snakemake.input.features)
condition = getattr(params, "condition", "speed_rpm")
# hybrid.simulated_validation_share > 0: the rule also gives the simulated features (record list)
share = float(getattr(params, "simulated_validation_share", 0.0))
simulated = (
    pd.read_parquet(snakemake.input.simulated, columns=["record_id", "health_state", condition])
    if share
    else None
)
# the physical specimen of every record, where the system's measured stage knows it
records = pd.read_csv(snakemake.input.records, dtype=str, keep_default_na=False)
specimens = records if {"specimen", "specimen_group"} <= set(records.columns) else None
# each protocol takes the shared parameters and its own (measured_classes, condition_split, ...)
offered = dict(
    measured_percent=list(params.measured_percent),
    repeats=int(params.repeats),
    seed=int(params.seed),
    min_test_records=int(params.min_test_records),
    condition=condition,
    healthy_state=params.healthy_state,
    measured_classes=getattr(params, "measured_classes", None),
    condition_split=getattr(params, "condition_split", None),
    specimens=specimens,
)
protocol = protocol_from(params.protocol, offered)
splits = make_splits(
    measured[["record_id", "segment", "health_state", condition]],
    protocol,
    simulated_records=simulated,
    simulated_validation_share=share,
    reserve=dict(params.reserve),
    segment_samples=getattr(params, "segment_samples", None),
)
write_split_table(splits, snakemake.output.splits)
log.info(
    "%s: %d rows, %d records, roles %s",
    params.protocol,
    len(splits),
    splits["record_id"].nunique(),
    splits["role"].value_counts().to_dict(),
)
