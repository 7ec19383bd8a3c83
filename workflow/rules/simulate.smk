# Stage 3: the system's model runs per health state, operating point (speed, and load where the
# rig runs several) and batch, each sample drawn anew.


rule simulate:
    input:
        # a fault state with its own calibrated model (calibration.per_state): its params.json
        unpack(lambda wc: state_calibration_output(wc.health)),
        **calibration_background_outputs(SIM_CALIBRATION, plot=False),
        calibration=calibration_outputs("params.json", SIM_CALIBRATION),
        # the background the simulation adds (calibration.background), so an edit of it reruns simulate
    output:
        signals=f"{RESULTS}/simulated/{{health}}/{{point}}/batch{{batch}}.parquet",
        report=f"{RESULTS}/simulated/{{health}}/{{point}}/batch{{batch}}.json",
    params:
        # + features.healthy_reference: twins in every health state, healthy samples this much longer
        **({"reference_segments": REFERENCE_SEGMENTS} if REFERENCE_SEGMENTS else {}),
        system=SYSTEM.job_spec("simulate"),
        simulation=config["simulation"],
        samples=lambda wc: batch_samples(wc.batch),
    # the healthy samples run longest (their twins' reference segments with
    # features.healthy_reference): started first, the short jobs fill the cores at the end
    priority: lambda wc: 1 if wc.health == SYSTEM.healthy_state else 0
    conda:
        "../envs/simulation.yaml"
    benchmark:
        f"{BENCHMARKS}/simulate/{{health}}_{{point}}_batch{{batch}}.tsv"
    log:
        f"{LOGS}/simulate/{{health}}_{{point}}_batch{{batch}}.log",
    script:
        "../scripts/simulate.py"
