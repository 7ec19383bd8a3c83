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
        log_models=config["tracking"]["log_models"],
        run_name=config["run_name"],
        config_hash=config_hash,
        data_source=data_source(),
        classifier_params={name: classifier_params(name) for name in CLASSIFIERS},
        healthy_state=SYSTEM.healthy_state,
    conda:
        "../envs/report.yaml"
    benchmark:
        f"{BENCHMARKS}/track.tsv"
    log:
        f"{LOGS}/track.log",
    script:
        "../scripts/track.py"


rule report:
    input:
        metrics=train_outputs("metrics.csv"),
        predictions=train_outputs("predictions.parquet"),
        # one calibration per variant (dict keys of the same order in each)
        **{f"calibration_params_{m}": p for m, p in calibration_outputs("params.json").items()},
        **{f"calibration_spectra_{m}": p for m, p in calibration_outputs("spectra.parquet").items()},
        **{f"calibration_history_{m}": p for m, p in calibration_outputs("history.parquet").items()},
        simulation_reports=simulated_batches("json"),
        measured_only=train_outputs("measured_only.csv"),
        measured_records=rules.measured.output.records,
        measured_features=rules.features_measured.output.features,  # each record's condition
        # accuracy on the held-out simulated records (hybrid.simulated_validation_share > 0)
        simulated_validation=(train_outputs("simulated_validation.csv")
                              if SIMULATED_VALIDATION_SHARE else []),
    output:
        accuracy=f"{RESULTS}/report/accuracy.csv",
        prediction_shares=f"{RESULTS}/report/prediction_shares.csv",
        summary=f"{RESULTS}/report/summary.json",
        recall_per_record=f"{RESULTS}/report/recall_per_record.csv",
        evaluation=f"{RESULTS}/report/evaluation.csv",
        evaluation_summary=f"{RESULTS}/report/evaluation_summary.csv",
        job_timings=f"{RESULTS}/report/job_timings.csv",
        plots=directory(f"{RESULTS}/report/plots"),
    params:
        run_name=config["run_name"],
        data_source=data_source(),
        bench_effects=SYSTEM.bench_effects(),
        confusion_percent=config["report"]["confusion_percent"],
        benchmarks=BENCHMARKS,
        healthy_state=SYSTEM.healthy_state,
        calibrations=CALIBRATIONS,  # the first one's calibration made the simulated data
        condition=CONDITION,
        design_records=config["report"]["design_records"],
    conda:
        "../envs/report.yaml"
    benchmark:
        f"{BENCHMARKS}/report.tsv"
    log:
        f"{LOGS}/report.log",
    script:
        "../scripts/report.py"
