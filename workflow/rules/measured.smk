# Stage 1: measured records into one signal table (the virtual bench, the user's table, or the
# CWRU .mat files of measured_dir), with a list of what was kept and what was left out.


rule virtual_bench:
    output:
        temp(f"{RESULTS}/measured/virtual_bench/{{health}}_{{speed}}rpm.parquet"),
    params:
        # the bench's mesh is virtual_bench.true_parameters.mesh_stiffness_model, not the model's
        model={k: v for k, v in config["model"].items() if k != "mesh_stiffness_model"},
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
        records=f"{RESULTS}/measured/records.csv",
    params:
        source="cwru" if SYSTEM == "bearing" else data_source(),
        health_states=HEALTH_STATES,
        channels=config["features"]["channels"],
        output_rate_hz=OUTPUT_RATE,
        segment_seconds=SEGMENT_SECONDS,
        measured_dir=config["measured_dir"] if SYSTEM == "bearing" else None,
        cwru=config["cwru"] if SYSTEM == "bearing" else None,
        on_bad_record=config["on_bad_record"],
    log:
        f"{LOGS}/measured.log",
    script:
        "../scripts/measured.py"
