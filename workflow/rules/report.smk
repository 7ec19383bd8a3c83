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
    output:
        run_info=f"{RESULTS}/report/mlflow_run.json",
        # every fit as a model from raw segments, in a folder of this config's own (model_store.py)
        models=directory(f"{RESULTS}/models/{config_hash}"),
    params:
        # every config key: a change reruns the job, and its reason names the changed keys
        *config_keys(RUN_CONFIG),
        tracking_uri=config["tracking"]["uri"],
        log_models=config["tracking"]["log_models"],
        run_name=config["run_name"],
        config_hash=config_hash,
        config=run_config,  # the parent run's params
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


# The report's plots into the run's MLflow parent: a job of its own, so `track` (packaging and
# logging every model) runs beside the report instead of after it.
rule track_plots:
    input:
        run_info=rules.track.output.run_info,
        plots=f"{RESULTS}/report/plots",
    output:
        f"{RESULTS}/report/mlflow_plots.json",
    conda:
        "../envs/report.yaml"
    benchmark:
        f"{BENCHMARKS}/track_plots.tsv"
    log:
        f"{LOGS}/track_plots.log",
    script:
        "../scripts/track_plots.py"


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
        **{
            f"state_calibration_{state}": f"{RESULTS}/state_calibration/{state}/params.json"
            for state in STATE_CALIBRATIONS
        },
        **{
            f"state_history_{state}": f"{RESULTS}/state_calibration/{state}/history.parquet"
            for state in STATE_CALIBRATIONS
        },
        **{f"benchmarks_{rule}": files for rule, files in upstream_benchmarks().items()},
        # where on the machine each measured segment's change sits (a system family's)
        **measured_fault_locations_input(),
        # the classifiers' and the joined methods' (scored alike, beside their parts)
        metrics=train_outputs("metrics.csv") + joined_outputs("metrics.csv"),
        predictions=train_outputs("predictions.parquet")
        + joined_outputs("predictions.parquet"),
        # one calibration per variant (dict keys of the same order in each)
        simulation_reports=simulated_batches("json"),
        measured_only=train_outputs("measured_only.csv"),
        measured_only_predictions=train_outputs("measured_only_predictions.parquet"),
        # the system's training-free physics baselines on the same test sets (may be empty)
        physics_baselines=physics_baseline_outputs("predictions.parquet"),
        # + whether each fault record shows its defect line (the envelope rule's fault_lines)
        physics_baseline_info=physics_baseline_outputs("info.json"),
        # each tested record's share outside its classifier's training range (the joined jobs')
        coverage=joined_outputs("coverage.csv"),
        measured_records=rules.measured.output.records,
        measured_features=rules.features_measured.output.features,  # each record's condition
        # beside it: how each simulated fault moves the features against the measured one
        simulated_features=rules.features_simulated.output.features,
        # accuracy on the held-out simulated records (hybrid.simulated_validation_share > 0)
        simulated_validation=(
            train_outputs("simulated_validation.csv")
            if SIMULATED_VALIDATION_SHARE
            else []
        ),
        # the benchmark files of every job before this one, named benchmarks_<rule>
    # report_pages presents these files (HTML tables, the plots) in `snakemake --report`
    output:
        # the registered sections' tables (condmon/report/registry.py): accuracy.csv,
        # headline.csv (the front page's table), evaluation.csv, ...
        **{name: f"{RESULTS}/report/{file}" for name, file in REPORT_TABLES.items()},
        summary=f"{RESULTS}/report/summary.json",
        plots=directory(f"{RESULTS}/report/plots"),
    params:
        run_name=config["run_name"],
        data_source=data_source(),
        bench_differences=SYSTEM.bench_differences(),
        confusion_percent=config["report"]["confusion_percent"],
        benchmarked_rules=list(upstream_benchmarks()),
        healthy_state=SYSTEM.healthy_state,
        calibrations=CALIBRATIONS,  # the first one's calibration made the simulated data
        state_models=STATE_CALIBRATIONS,  # calibration.per_state: labelled in every plot
        condition=CONDITION,
        design_records=config["report"]["design_records"],
        # the specimens whose records the design looked at (records.csv's specimen)
        design_specimens=SYSTEM.design_specimens(),
        # {specimen: reason} of specimens the model does not describe: reported apart, never in
        # the headline
        unmodelled=SYSTEM.unmodelled_specimens(),
        # the calibration set (what the calibrate jobs saw, and the healthy reference where it is
        # on): the measured-only ceiling leaves it out
        calibration_set=dict(
            healthy_state=SYSTEM.healthy_state,
            condition=CONDITION,
            reserve=config["calibration"]["reserve"],
            states=[SYSTEM.healthy_state, *STATE_CALIBRATIONS],
        ),
    resources:
        # the run's --cores, to set its elapsed time against its CPU seconds / cores: a resource,
        # not a param, so running with other cores reruns nothing (no --resources limits it)
        run_cores=workflow.resource_settings.cores or 1,
    conda:
        "../envs/report.yaml"
    benchmark:
        f"{BENCHMARKS}/report.tsv"
    log:
        f"{LOGS}/report.log",
    script:
        "../scripts/report.py"


rule run_config:
    output:
        f"{RESULTS}/report/config.yaml",
    params:
        # every config key (a rerun names the changed ones); the config files with the schema's
        # defaults filled in, for the script
        *config_keys(RUN_CONFIG),
        config=run_config,
    conda:
        "../envs/report.yaml"
    benchmark:
        f"{BENCHMARKS}/run_config.tsv"
    log:
        f"{LOGS}/run_config.log",
    script:
        "../scripts/run_config.py"


# What `snakemake --report report.html` shows: the report's tables as HTML, its plots, the
# headline (embedded in the front page, workflow/report/workflow.rst) and the full config. A job
# of its own, so a result's details pane lists these few params, not the report job's settings.
rule report_pages:
    input:
        **{
            f"calibration_params_{m}": p
            for m, p in calibration_outputs("params.json").items()
        },
        **{name: rules.report.output[name] for name in REPORT_PAGES},
        headline=rules.report.output.headline,
        summary=rules.report.output.summary,  # what each protocol tests
        plots=rules.report.output.plots,
        config=rules.run_config.output[0],
    output:
        tables=report(
            directory(f"{RESULTS}/report/pages/tables"),
            patterns=["{name}.html"],
            caption="../report/tables.rst",
            category=plot_category,
            labels={"name": "{name} table"},
        ),
        plots=report(
            directory(f"{RESULTS}/report/pages/plots"),
            patterns=["{name}.png"],
            caption="../report/plots.rst",
            category=plot_category,
            labels={"name": "{name}"},
        ),
        headline=report(
            f"{RESULTS}/report/pages/headline.csv",
            caption="../report/tables.rst",
            category="Accuracy",
            labels={"name": "headline table (CSV)"},
        ),
        config=report(
            f"{RESULTS}/report/pages/config.yaml",
            caption="../report/config.rst",
            category="Configuration",
            labels={"name": "full config"},
        ),
    params:
        run_name=config["run_name"],
        system=config["system"],
        config_hash=config_hash,
        protocols=PROTOCOLS,
        classifiers=CLASSIFIERS,
        full_config=lambda wildcards, output: output.config,  # its path, in the pane
    conda:
        "../envs/report.yaml"
    benchmark:
        f"{BENCHMARKS}/report_pages.tsv"
    log:
        f"{LOGS}/report_pages.log",
    script:
        "../scripts/report_pages.py"
