# Stage 7: MLflow tracking (one writer) and the report.


rule track:
    input:
        predictions=train_outputs("predictions.parquet"),
        metrics=train_outputs("metrics.csv"),
        models=train_outputs("models"),
        features_simulated=rules.features_simulated.output.features,
        features_measured=rules.features_measured.output.features,
    output:
        run_info=f"{RESULTS}/report/mlflow_run.json",
    params:
        tracking_uri=config["tracking"]["uri"],
        run_name=config["run_name"],
        config_hash=config_hash,
        data_source=data_source(),
        classifier_params={name: classifier_params(name) for name in CLASSIFIERS},
    log:
        f"{LOGS}/track.log",
    script:
        "../scripts/track.py"


rule report:
    input:
        metrics=train_outputs("metrics.csv"),
        predictions=train_outputs("predictions.parquet"),
        calibration_params=rules.calibrate.output.params,
        calibration_spectra=rules.calibrate.output.spectra,
        calibration_history=rules.calibrate.output.history,
        simulation_reports=simulated_batches("json"),
    output:
        accuracy=f"{RESULTS}/report/accuracy.csv",
        summary=f"{RESULTS}/report/summary.json",
        plots=directory(f"{RESULTS}/report/plots"),
    params:
        run_name=config["run_name"],
        data_source=data_source(),
        confusion_percent=config["report"]["confusion_percent"],
    log:
        f"{LOGS}/report.log",
    script:
        "../scripts/report.py"
