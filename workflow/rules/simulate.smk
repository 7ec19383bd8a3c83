# Stage 3: perturbed model runs per health state, speed and batch.


rule simulate:
    input:
        calibration=rules.calibrate.output.params,
    output:
        signals=f"{RESULTS}/simulated/{{health}}/{{speed}}rpm/batch{{batch}}.parquet",
        report=f"{RESULTS}/simulated/{{health}}/{{speed}}rpm/batch{{batch}}.json",
    params:
        model=config["model"],
        numerics=NUMERICS,
        simulation=config["simulation"],
        samples=lambda wc: batch_samples(wc.batch),
        segment_seconds=config["rig"]["segment_seconds"],
    log:
        f"{LOGS}/simulate/{{health}}_{{speed}}rpm_batch{{batch}}.log",
    script:
        "../scripts/simulate.py"
