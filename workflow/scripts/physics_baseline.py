"""Snakemake script: measured features + split table (+ the measured signals, where the system's
rules read more of them than the features hold) -> the system's physics baselines' predictions on
every split's test set (condmon.baselines).

`snakemake` is injected by Snakemake's script directive.
"""

from condmon.atomic import write_frame, write_json
from condmon.baselines import physics_predictions
from condmon.features import read_feature_table
from condmon.hybrid import read_split_table
from condmon.runlog import setup_logging
from condmon.signals import read_signal_table
from condmon.systems import load_system

log = setup_logging(snakemake)  # to snakemake.log[0]
measured, feature_names = read_feature_table(snakemake.input.measured)
splits = read_split_table(snakemake.input.splits)
signals = (
    read_signal_table(snakemake.input.signals) if "signals" in snakemake.input.keys() else None
)
baselines = load_system(snakemake.params.system).physics_baselines(feature_names, signals)
predictions, info = physics_predictions(baselines, measured, splits)
write_frame(predictions, snakemake.output.predictions)
write_json({"protocol": str(splits["protocol"].iloc[0]), "baselines": info}, snakemake.output.info)
log.info(
    "%d physics baseline(s) %s, %d predictions", len(baselines), sorted(baselines), len(predictions)
)
