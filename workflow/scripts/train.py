"""Snakemake script: features + split table -> predictions, metrics, models, info.

`snakemake` is injected by Snakemake's script directive.
"""

import resource
import time

from condmon.atomic import write_json
from condmon.features import read_feature_table
from condmon.hybrid import read_split_table
from condmon.runlog import setup_logging
from condmon.train import (
    BASELINE_COLUMNS,
    JobCost,
    fit_and_evaluate,
    matching_feature_names,
    run_protocol,
    train_info,
    write_metrics,
    write_models,
    write_predictions,
    write_simulated_validation,
)

log = setup_logging(snakemake)  # to snakemake.log[0]
start = time.perf_counter()
name = snakemake.params.classifier
params = dict(snakemake.params.classifier_params or {})
seed = int(snakemake.params.seed)
# optional per-classifier subset of the split table (classifiers.<name>.measured_percent/repeats)
selection = dict(getattr(snakemake.params, "selection", None) or {})

simulated, simulated_names = read_feature_table(snakemake.input.simulated)
measured, measured_names = read_feature_table(snakemake.input.measured)
feature_names = matching_feature_names(simulated_names, measured_names)
splits = read_split_table(snakemake.input.splits)

# sequential backward selection inside every fit (features.selection; n_features null = off)
feature_selection = snakemake.params.feature_selection
subset = dict(
    measured_percent=selection.get("measured_percent"),
    repeats=selection.get("repeats"),
    feature_selection=feature_selection,
)
# also the metrics on the held-out simulated records (hybrid.simulated_validation_share > 0)
predictions, metrics, models, validation = fit_and_evaluate(
    name, params, simulated, measured, splits, feature_names, seed, **subset
)
if snakemake.params.measured_only_baseline:
    # the same classifier on the same measured training data alone: the simulation's gain (its
    # selection chosen by its own inner CV, never forced)
    baseline_predictions, baseline, _ = run_protocol(
        name, params, None, measured, splits, feature_names, seed, **subset
    )
    log.info("measured-only baseline: %d metric rows", len(baseline))
else:
    baseline, baseline_predictions = metrics.iloc[:0], predictions.iloc[:0]

out = snakemake.output
write_predictions(predictions, out.predictions)
write_metrics(metrics, out.metrics)
write_metrics(baseline, out.measured_only, BASELINE_COLUMNS)
write_predictions(baseline_predictions, out.measured_only_predictions)
# declared by the rule only when hybrid.simulated_validation_share > 0
validation_path = getattr(out, "simulated_validation", None)
if validation_path is not None:
    write_simulated_validation(validation, validation_path)
elif len(validation):
    log.warning(
        "the split table holds out simulated records but the rule declares no "
        "simulated_validation output: their %d metric rows are not written",
        len(validation),
    )
model_files = write_models(models, out.models, feature_names)
labels = set(simulated["health_state"]) | set(measured["health_state"])
peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # Linux: KiB
write_json(
    train_info(
        name,
        params,
        seed,
        str(splits["protocol"].iloc[0]),
        labels,
        feature_names,
        metrics,
        model_files,
        JobCost(time.perf_counter() - start, peak_mb),
        selection=selection,
    ),
    out.info,
)
log.info(
    "%d models, %d metric rows written; %.1f s, peak memory %.0f MB",
    len(model_files),
    len(metrics),
    time.perf_counter() - start,
    peak_mb,
)
