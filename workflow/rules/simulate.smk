# Stage 3: perturbed model runs per health state, speed and batch.


rule simulate:
    input:
        calibration=calibration_outputs("params.json", SIM_STIFFNESS),
    output:
        signals=f"{RESULTS}/simulated/{{health}}/{{speed}}rpm/batch{{batch}}.parquet",
        report=f"{RESULTS}/simulated/{{health}}/{{speed}}rpm/batch{{batch}}.json",
    params:
        system=SYSTEM,
        model=MODEL,
        numerics=NUMERICS,
        simulation=config["simulation"],
        samples=lambda wc: batch_samples(wc.batch),
        segment_seconds=SEGMENT_SECONDS,
    log:
        f"{LOGS}/simulate/{{health}}_{{speed}}rpm_batch{{batch}}.log",
    script:
        "../scripts/simulate.py"
