# Stage 1: measured records into one signal table (the virtual bench, or the user's table).


rule virtual_bench:
    output:
        temp(f"{RESULTS}/measured/virtual_bench/{{health}}_{{speed}}rpm.parquet"),
    params:
        model=config["model"],
        bench=config["virtual_bench"],
        numerics=NUMERICS,
        segment_seconds=config["rig"]["segment_seconds"],
    log:
        f"{LOGS}/virtual_bench/{{health}}_{{speed}}rpm.log",
    script:
        "../scripts/virtual_bench.py"


rule measured:
    input:
        measured_inputs,
    output:
        f"{RESULTS}/measured/signals.parquet",
    params:
        source=data_source(),
        health_states=HEALTH_STATES,
        channels=config["features"]["channels"],
        output_rate_hz=config["rig"]["output_rate_hz"],
        segment_seconds=config["rig"]["segment_seconds"],
    log:
        f"{LOGS}/measured.log",
    script:
        "../scripts/measured.py"
