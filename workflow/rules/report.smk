# Stage 7: MLflow tracking (one writer) and the report. report(...) marks what
# `snakemake --report report.html` shows, captioned by workflow/report/*.rst.


rule track:
    input:
        # + the machine's healthy reference a packaged model takes new records against
        **measured_reference_output(),
        predictions=train_outputs("predictions.parquet"),
        metrics=train_outputs("metrics.csv"),
        models=train_outputs("models"),
        info=train_outputs("info.json"),  # lists each job's model files and fitted settings
        # logged as datasets, with digests of their files
        measured_signals=rules.measured.output[0],
        simulated_signals=simulated_batches(),
        features_simulated=rules.features_simulated.output.features,
        features_measured=rules.features_measured.output.features,
        # each fit's measured training records (the speeds its packaged model was trained at)
        splits=expand(rules.hybrid.output.splits, protocol=PROTOCOLS),
        plots=f"{RESULTS}/report/plots",  # the report rule's; logged as artifacts of the parent run
    output:
        run_info=f"{RESULTS}/report/mlflow_run.json",
        # every fit as a model from raw segments, in a folder of this config's own (model_store.py)
        models=directory(f"{RESULTS}/models/{config_hash}"),
    params:
        tracking_uri=config["tracking"]["uri"],
        log_models=config["tracking"]["log_models"],
        run_name=config["run_name"],
        config_hash=config_hash,
        config=RUN_CONFIG,  # the parent run's params (any edit changes config_hash anyway)
        data_source=data_source(),
        healthy_state=SYSTEM.healthy_state,
        protocols=PROTOCOLS,
        # what a packaged model computes from a signal table, and how the system reads its records
        features=dict(
            channels=config["features"]["channels"],
            spectrum=config["features"]["spectrum"],
            kind=config["features"]["kind"],
            statistical=statistical_feature_params(),
            families=system_family_params(),
        ),
        features_system=SYSTEM.job_spec("features"),
        measured_system=SYSTEM.job_spec("measured"),
        condition=CONDITION,
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
        **{
            f"calibration_params_{m}": p
            for m, p in calibration_outputs("params.json").items()
        },
        **{
            f"calibration_spectra_{m}": p
            for m, p in calibration_outputs("spectra.parquet").items()
        },
        **{
            f"calibration_history_{m}": p
            for m, p in calibration_outputs("history.parquet").items()
        },
        **{f"benchmarks_{rule}": files for rule, files in upstream_benchmarks().items()},
        metrics=train_outputs("metrics.csv"),
        predictions=train_outputs("predictions.parquet"),
        # one calibration per variant (dict keys of the same order in each)
        simulation_reports=simulated_batches("json"),
        measured_only=train_outputs("measured_only.csv"),
        # the system's training-free physics baselines on the same test sets (may be empty)
        physics_baselines=physics_baseline_outputs("predictions.parquet"),
        measured_records=rules.measured.output.records,
        measured_features=rules.features_measured.output.features,  # each record's condition
        # accuracy on the held-out simulated records (hybrid.simulated_validation_share > 0)
        simulated_validation=(
            train_outputs("simulated_validation.csv")
            if SIMULATED_VALIDATION_SHARE
            else []
        ),
        # the benchmark files of every job before this one, named benchmarks_<rule>
    output:
        accuracy=report(
            f"{RESULTS}/report/accuracy.csv",
            caption="../report/accuracy.rst",
            category="Accuracy",
            labels={"name": "accuracy table"},
        ),
        prediction_shares=report(
            f"{RESULTS}/report/prediction_shares.csv",
            caption="../report/prediction_shares.rst",
            category="Confusion matrices",
            labels={"name": "prediction shares table"},
        ),
        summary=f"{RESULTS}/report/summary.json",
        recall_per_record=report(
            f"{RESULTS}/report/recall_per_record.csv",
            caption="../report/recall_per_record.rst",
            category="Accuracy",
            labels={"name": "recall per record table"},
        ),
        evaluation=f"{RESULTS}/report/evaluation.csv",
        evaluation_summary=f"{RESULTS}/report/evaluation_summary.csv",
        physics_baselines=f"{RESULTS}/report/physics_baselines.csv",
        job_timings=report(
            f"{RESULTS}/report/job_timings.csv",
            caption="../report/job_timings.rst",
            category="Job timings",
            labels={"name": "job timings table"},
        ),
        plots=report(
            directory(f"{RESULTS}/report/plots"),
            patterns=["{name}.png"],
            caption="../report/plots.rst",
            category=plot_category,
            labels={"name": "{name}"},
        ),
    params:
        run_name=config["run_name"],
        data_source=data_source(),
        bench_effects=SYSTEM.bench_effects(),
        confusion_percent=config["report"]["confusion_percent"],
        benchmarked_rules=list(upstream_benchmarks()),
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
