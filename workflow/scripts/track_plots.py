"""Snakemake script: log the report's plots into the run's MLflow parent (report/mlflow_run.json)
-> report/mlflow_plots.json, the artifacts logged. The logic lives in condmon.tracking.
`snakemake` is injected by Snakemake's script directive.
"""

import json
import sys

from condmon.atomic import write_json
from condmon.runlog import setup_logging
from condmon.tracking import TrackingError, log_run_artifacts

log = setup_logging(snakemake)  # to snakemake.log[0]
with open(snakemake.input.run_info) as file:
    info = json.load(file)
try:
    logged = log_run_artifacts(info, {"plots": snakemake.input.plots})
except TrackingError as error:  # a store that is down: say so plainly
    log.error("%s", error)
    sys.exit(1)
log.info("logged %d plots into parent run %s", len(logged), info["parent_run_id"])
write_json({"parent_run_id": info["parent_run_id"], "artifacts": logged}, snakemake.output[0])
