# Stage 1: measured records into one signal table (a synthetic bench's parts, the user's table, or
# the system's own record files), with a list of what was kept and what was left out.


rule measured_part:
    output:
        temp(f"{RESULTS}/measured/parts/{{part}}.parquet"),
    params:
        system=SYSTEM.job_spec("bench"),
    # the healthy parts first: the calibrations wait for them alone
    priority: lambda wc: 1 if EARLY_CALIBRATION and wc.part in HEALTHY_PARTS else 0
    conda:
        "../envs/simulation.yaml"
    benchmark:
        f"{BENCHMARKS}/measured_part/{{part}}.tsv"
    log:
        f"{LOGS}/measured_part/{{part}}.log",
    script:
        "../scripts/measured_part.py"


rule measured:
    input:
        measured_inputs,
    output:
        f"{RESULTS}/measured/signals.parquet",
        records=f"{RESULTS}/measured/records.csv",
    params:
        system=SYSTEM.job_spec("measured"),
        parts=len(MEASURED_PARTS),  # the last inputs are the bench parts
        channels=config["features"]["channels"],
        on_bad_record=config["on_bad_record"],
    conda:
        "../envs/simulation.yaml"
    benchmark:
        f"{BENCHMARKS}/measured.tsv"
    log:
        f"{LOGS}/measured.log",
    script:
        "../scripts/measured.py"


# A bench's healthy parts alone, what the calibrations read: they start while the bench still makes
# its fault records (the parts are temporary; a table of their own keeps an edit of the calibration
# from making the bench's records again).
rule measured_healthy:
    input:
        expand(f"{RESULTS}/measured/parts/{{part}}.parquet", part=HEALTHY_PARTS),
    output:
        f"{RESULTS}/measured/healthy.parquet",
    params:
        system=SYSTEM.job_spec("measured"),
        parts=len(HEALTHY_PARTS),
        channels=config["features"]["channels"],
        on_bad_record=config["on_bad_record"],
    conda:
        "../envs/simulation.yaml"
    benchmark:
        f"{BENCHMARKS}/measured_healthy.tsv"
    log:
        f"{LOGS}/measured_healthy.log",
    script:
        "../scripts/measured.py"
