# Stage 4: features (FFT spectra of every channel, concatenated; statistical features; a system's own
# families; or several of these side by side).


rule features_measured:
    input:
        signals=[rules.measured.output[0]],
    output:
        # + the calibration set's mean features per condition (features.healthy_reference)
        **measured_reference_output(),
        features=f"{RESULTS}/features/measured.parquet",
    params:
        **healthy_reference_params("measured"),
        channels=config["features"]["channels"],
        spectrum=config["features"]["spectrum"],
        kind=config["features"]["kind"],
        statistical=statistical_feature_params(),
        families=system_family_params(),
        system=SYSTEM.job_spec("features"),
    # every core where a family spreads its segments over them (the residual signatures do)
    threads: feature_threads()
    conda:
        "../envs/learning.yaml"
    benchmark:
        f"{BENCHMARKS}/features_measured.tsv"
    log:
        f"{LOGS}/features_measured.log",
    script:
        "../scripts/features.py"


rule features_simulated:
    input:
        # a family's measured references, where it shares something with the simulated runs
        **measured_family_references_input(),
        signals=simulated_batches(),
    output:
        features=f"{RESULTS}/features/simulated.parquet",
    params:
        **healthy_reference_params("simulated"),
        channels=config["features"]["channels"],
        spectrum=config["features"]["spectrum"],
        kind=config["features"]["kind"],
        statistical=statistical_feature_params(),
        families=system_family_params(),
        system=SYSTEM.job_spec("features"),
    # every core where a family spreads its segments over them (the residual signatures do)
    threads: feature_threads()
    conda:
        "../envs/learning.yaml"
    benchmark:
        f"{BENCHMARKS}/features_simulated.tsv"
    log:
        f"{LOGS}/features_simulated.log",
    script:
        "../scripts/features.py"
