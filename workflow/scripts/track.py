"""Snakemake script: log the whole run to MLflow -> report/mlflow_run.json.

The only job that writes to the tracking store, run once after all training, so parallel jobs
never race on it. The logic lives in condmon.tracking.
`snakemake` is injected by Snakemake's script directive.
"""
import sys
from pathlib import Path

from condmon.runlog import setup_logging
from condmon.tracking import TrackingError, log_pipeline_run, write_run_info

log = setup_logging(snakemake)  # to snakemake.log[0]
params, inputs = snakemake.params, snakemake.input
try:
    info = log_pipeline_run(
        tracking_uri=params.tracking_uri,
        run_name=params.run_name,
        config_hash=params.config_hash,
        data_source=params.data_source,
        train_dirs=[Path(path).parent for path in inputs.info],  # train/<classifier>/<protocol>
        datasets={"measured_signals": [inputs.measured_signals],
                  "simulated_signals": list(inputs.simulated_signals),
                  "measured_features": [inputs.features_measured],
                  "simulated_features": [inputs.features_simulated]},
        config=dict(params.config),
        log_models=params.log_models,
        healthy_state=params.healthy_state,
    )
except TrackingError as error:  # a store that is down, inconsistent inputs: say so plainly
    log.error("%s", error)
    sys.exit(1)
write_run_info(info, snakemake.output.run_info)
