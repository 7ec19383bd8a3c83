"""Snakemake script: log the whole run to MLflow -> report/mlflow_run.json.

The only job that writes to the tracking store, run once after all training jobs, so parallel
jobs never race on the SQLite file. The logic lives in condmon.tracking.
`snakemake` is injected by Snakemake's script directive.
"""
import sys

from condmon.runlog import setup_logging
from condmon.tracking import DEFAULT_TRACKING_URI, TrackingError, log_pipeline_run, write_run_info

log = setup_logging(snakemake)  # to snakemake.log[0]
params = snakemake.params
try:
    info = log_pipeline_run(
        tracking_uri=params.get("tracking_uri") or DEFAULT_TRACKING_URI,
        run_name=params.run_name,
        config_hash=params.config_hash,
        data_source=params.data_source,
        classifier_params=dict(params.classifier_params),
        metrics_paths=list(snakemake.input.metrics),
        predictions_paths=list(snakemake.input.predictions),
        model_dirs=list(snakemake.input.models),
        features_measured=snakemake.input.features_measured,
        features_simulated=snakemake.input.features_simulated,
        models=params.get("log_models", "all"),
        healthy_state=params.get("healthy_state"),
    )
except TrackingError as error:  # a store that is down, inconsistent inputs: say so plainly
    log.error("%s", error)
    sys.exit(1)
write_run_info(info, snakemake.output.run_info)
