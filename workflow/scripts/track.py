"""Snakemake script: log the whole run to MLflow -> report/mlflow_run.json.

The only job that writes to the tracking store, run once after all training, so parallel jobs
never race on it. The logic lives in condmon.tracking.
`snakemake` is injected by Snakemake's script directive.
"""

import sys
from pathlib import Path

import pandas as pd

from condmon.model_store import build_store
from condmon.runlog import setup_logging
from condmon.signal_model import packaged_features
from condmon.systems import load_system
from condmon.tracking import (
    TrackedRun,
    TrackingError,
    check_tracking_server,
    log_pipeline_run,
    resolve_tracking_uri,
    write_run_info,
)

log = setup_logging(snakemake)  # to snakemake.log[0]
params, inputs = snakemake.params, snakemake.input
train_dirs = [Path(path).parent for path in inputs.info]  # train/<classifier>/<protocol>
try:
    check_tracking_server(
        resolve_tracking_uri(params.tracking_uri)
    )  # a dead server: before any work
    # every fit as a model from raw segments (the features and training domain with it): what
    # MLflow logs, and what `condmon predict` takes
    store = snakemake.output.models
    system = load_system(params.features_system)
    reference = None
    if "reference" in inputs.keys():  # features.healthy_reference: new records taken against it
        reference = {
            "condition": params.condition,
            "table": pd.read_parquet(inputs.reference).to_dict("list"),
        }
    family_references = None  # a family's own references (waveforms), packaged in its settings
    if "family_references" in inputs.keys():
        family_references = pd.read_parquet(inputs.family_references)
    features = packaged_features(
        dict(params.features),
        system.defect_orders(),
        system.feature_families(),
        reference,
        family_references,
    )
    index = build_store(
        store,
        train_dirs,
        dict(zip(params.protocols, inputs.splits)),
        inputs.measured_signals,
        inputs.features_simulated,
        inputs.features_measured,
        features,
        params.healthy_state,
        dict(params.measured_system),
        params.config_hash,
    )
    log.info("packaged %d models in %s; best %s", len(index["models"]), store, index["best"])
    info = log_pipeline_run(
        tracking_uri=params.tracking_uri,
        run=TrackedRun(
            run_name=params.run_name,
            config_hash=params.config_hash,
            data_source=params.data_source,
            config=dict(params.config),
            healthy_state=params.healthy_state,
        ),
        train_dirs=train_dirs,
        datasets={
            "measured_signals": [inputs.measured_signals],
            "simulated_signals": list(inputs.simulated_signals),
            "measured_features": [inputs.features_measured],
            "simulated_features": [inputs.features_simulated],
        },
        log_models=params.log_models,
        model_store=store,
    )
except TrackingError as error:  # a store that is down, inconsistent inputs: say so plainly
    log.error("%s", error)
    sys.exit(1)
write_run_info(info, snakemake.output.run_info)
