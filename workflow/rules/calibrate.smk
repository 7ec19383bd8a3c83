# Stage 2: CMA-ES calibration of the system's model on the healthy measured records, one job per
# calibration variant (System.calibration_variants; a system without a choice has one, "rig").


# The run's cores shared by the calibrations, which run side by side (one alone would leave the
# others waiting for every core), less one where a bench still makes its fault records: the
# calibration then runs beside them rather than waiting for two cores the bench never frees at
# once. None are given to `snakemake --report` or `--lint`.
CALIBRATION_THREADS = max(
    1,
    ((workflow.resource_settings.cores or 1) - EARLY_CALIBRATION) // len(CALIBRATIONS),
)


rule calibrate:
    input:
        measured=calibration_measured(),
    output:
        **calibration_background_outputs("{variant}"),
        params=f"{RESULTS}/calibration/{{variant}}/params.json",  # a table in report_pages
        history=f"{RESULTS}/calibration/{{variant}}/history.parquet",
        spectra=f"{RESULTS}/calibration/{{variant}}/spectra.parquet",
        plot=f"{RESULTS}/calibration/{{variant}}/convergence.png",
        # calibration.background: what healthy records carry that the model lacks, and its plot
    params:
        system=lambda wc: SYSTEM.job_spec("calibrate", wc.variant),
        variant=lambda wc: wc.variant,
        # the variants are wildcards, so the list of them never reruns a calibration
        calibration=SYSTEM.calibration_settings(config["calibration"]),
        channels=config["features"]["channels"],
        spectrum=config["features"]["spectrum"],
        data_source=data_source(),
        condition=CONDITION,  # calibration.reserve: a lone healthy record per condition
    threads: CALIBRATION_THREADS
    conda:
        "../envs/simulation.yaml"
    benchmark:
        f"{BENCHMARKS}/calibrate/{{variant}}.tsv"
    log:
        f"{LOGS}/calibrate_{{variant}}.log",
    script:
        "../scripts/calibrate.py"


# Per-state calibration (calibration.per_state): one job per listed fault state tunes its model's
# form and severities on its calibration records, the healthy calibration (the simulation's) fixed.
rule calibrate_state:
    input:
        measured=rules.measured.output[0],
        calibration=calibration_outputs("params.json", SIM_CALIBRATION),
    output:
        params=f"{RESULTS}/state_calibration/{{state}}/params.json",  # read by its simulate jobs
        history=f"{RESULTS}/state_calibration/{{state}}/history.parquet",
        plot=f"{RESULTS}/state_calibration/{{state}}/convergence.png",
    params:
        system=SYSTEM.job_spec("calibrate", SIM_CALIBRATION),
        state=lambda wc: wc.state,
        calibration=config["calibration"],
        reserve=RESERVE,
        channels=config["features"]["channels"],
        spectrum=config["features"]["spectrum"],
        data_source=data_source(),
        condition=CONDITION,
    threads: workflow.resource_settings.cores or 1
    conda:
        "../envs/simulation.yaml"
    benchmark:
        f"{BENCHMARKS}/calibrate_state/{{state}}.tsv"
    log:
        f"{LOGS}/calibrate_state_{{state}}.log",
    script:
        "../scripts/calibrate_state.py"
