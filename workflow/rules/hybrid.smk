# Stage 5: hybrid training sets: which measured records train and which test, per protocol.

# hybrid.simulated_validation_share > 0: the split table also lists the simulated records held out
# as the simulated validation set, so the job reads the simulated record list. At 0 (default) the
# rule has neither that input nor that param: its jobs are those of a run without the key.
SIMULATED_VALIDATION_SHARE = config["hybrid"]["simulated_validation_share"]


def simulated_validation_inputs():
    if not SIMULATED_VALIDATION_SHARE:
        return {}
    return {"simulated": rules.features_simulated.output.features}


def simulated_validation_params():
    if not SIMULATED_VALIDATION_SHARE:
        return {}
    return {"simulated_validation_share": SIMULATED_VALIDATION_SHARE}


rule hybrid:
    input:
        features=rules.features_measured.output.features,
        **simulated_validation_inputs(),
    output:
        splits=f"{RESULTS}/hybrid/{{protocol}}.parquet",
    params:
        protocol=lambda wc: wc.protocol,
        measured_percent=config["hybrid"]["measured_percent"],
        repeats=config["hybrid"]["repeats"],
        seed=config["hybrid"]["seed"],
        min_test_records=config["hybrid"]["min_test_records"],
        condition=CONDITION,
        measured_classes=lambda wc: (config["hybrid"]["measured_classes"]
                                     if wc.protocol == "unseen_fault" else None),
        **simulated_validation_params(),
    conda:
        "../envs/learning.yaml"
    benchmark:
        f"{BENCHMARKS}/hybrid/{{protocol}}.tsv"
    log:
        f"{LOGS}/hybrid/{{protocol}}.log",
    script:
        "../scripts/hybrid.py"
