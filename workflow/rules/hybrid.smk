# Stage 5: hybrid training sets: which measured records train and which test, per protocol.


rule hybrid:
    input:
        **(
            {"simulated": rules.features_simulated.output.features}
            if SIMULATED_VALIDATION_SHARE
            else {}
        ),
        features=rules.features_measured.output.features,
        records=rules.measured.output.records,  # specimens (specimen_holdout)
        # the simulated record list, only with hybrid.simulated_validation_share > 0 (common.smk)
    output:
        splits=f"{RESULTS}/hybrid/{{protocol}}.parquet",
    params:
        **(
            {"simulated_validation_share": SIMULATED_VALIDATION_SHARE}
            if SIMULATED_VALIDATION_SHARE
            else {}
        ),
        protocol=lambda wc: wc.protocol,
        measured_percent=config["hybrid"]["measured_percent"],
        repeats=config["hybrid"]["repeats"],
        seed=config["hybrid"]["seed"],
        min_test_records=config["hybrid"]["min_test_records"],
        condition=CONDITION,
        healthy_state=SYSTEM.healthy_state,
        reserve=RESERVE,  # the calibration set (with per-state calibration records): never in a split
        # (length, hop) of the measured segments: a guard gap under one segment is refused
        segment_samples=[SYSTEM.segment_length, SYSTEM.segment_hop],
        measured_classes=lambda wc: (
            config["hybrid"]["measured_classes"]
            if wc.protocol == "unseen_fault"
            else None
        ),
        condition_split=lambda wc: (
            config["hybrid"]["condition_split"]
            if wc.protocol == "condition_holdout"
            else None
        ),
    conda:
        "../envs/learning.yaml"
    benchmark:
        f"{BENCHMARKS}/hybrid/{{protocol}}.tsv"
    log:
        f"{LOGS}/hybrid/{{protocol}}.log",
    script:
        "../scripts/hybrid.py"
