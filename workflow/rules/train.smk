# Stage 6: classifiers trained on every hybrid set, evaluated on its held-out measured records.


rule train:
    input:
        simulated=rules.features_simulated.output.features,
        measured=rules.features_measured.output.features,
        splits=rules.hybrid.output.splits,
    output:
        **(
            {
                "simulated_validation": f"{RESULTS}/train/{{classifier}}/{{protocol}}/simulated_validation.csv"
            }
            if SIMULATED_VALIDATION_SHARE
            else {}
        ),
        predictions=f"{RESULTS}/train/{{classifier}}/{{protocol}}/predictions.parquet",
        metrics=f"{RESULTS}/train/{{classifier}}/{{protocol}}/metrics.csv",
        models=directory(f"{RESULTS}/train/{{classifier}}/{{protocol}}/models"),
        info=f"{RESULTS}/train/{{classifier}}/{{protocol}}/info.json",
        measured_only=f"{RESULTS}/train/{{classifier}}/{{protocol}}/measured_only.csv",
        # its predictions (the report scores it on design and evaluation records apart)
        measured_only_predictions=f"{RESULTS}/train/{{classifier}}/{{protocol}}/measured_only_predictions.parquet",
        # metrics on the held-out simulated records: only with hybrid.simulated_validation_share > 0
    params:
        classifier=lambda wc: wc.classifier,
        classifier_params=lambda wc: classifier_params(wc.classifier),
        selection=lambda wc: classifier_selection(wc.classifier),
        seed=config["hybrid"]["seed"],
        feature_selection=config["features"]["selection"],
        measured_only_baseline=config["hybrid"]["measured_only_baseline"],
    # the CNN's intra-op threads (classifiers.cnn.threads), so Snakemake reserves the cores
    threads: lambda wc: config["classifiers"][wc.classifier].get("threads", 1)
    # the likely longest train jobs first, so the others fill the other cores beside them
    # instead of one long job standing alone at the end: the CNN ensemble's fits, then the
    # protocols with a split per held-out group (the most splits; a seed-free classifier fits
    # each distinct training set once, so the time follows the distinct sets, not the splits)
    priority:
        lambda wc: (
            2
            if wc.classifier == "cnn"
            else int(PROTOCOL_CLASSES[wc.protocol].holds_out_each_group)
        )
    conda:
        "../envs/learning.yaml"
    benchmark:
        f"{BENCHMARKS}/train/{{classifier}}_{{protocol}}.tsv"
    log:
        f"{LOGS}/train/{{classifier}}_{{protocol}}.log",
    script:
        "../scripts/train.py"


# The system's training-free physics baselines (System.physics_baselines), on the same test
# sets: their thresholds come from the calibration segments only; the measured signals too, where
# the system's rules read them (System.baselines_read_signals).
rule physics_baseline:
    input:
        **(
            {"signals": rules.measured.output[0]}
            if SYSTEM.baselines_read_signals
            else {}
        ),
        measured=rules.features_measured.output.features,
        splits=rules.hybrid.output.splits,
    output:
        predictions=f"{RESULTS}/baselines/{{protocol}}/predictions.parquet",
        info=f"{RESULTS}/baselines/{{protocol}}/info.json",
    params:
        system=SYSTEM.job_spec("baselines"),
    conda:
        "../envs/learning.yaml"
    benchmark:
        f"{BENCHMARKS}/physics_baseline/{{protocol}}.tsv"
    log:
        f"{LOGS}/physics_baseline/{{protocol}}.log",
    script:
        "../scripts/physics_baseline.py"


# The joined method (condmon/joined.py): the classifier's call where a test segment lies inside
# its fit's training range, the physics rule's outside it; in train's format, so the report
# scores it beside both parts.
rule joined:
    input:
        predictions=rules.train.output.predictions,
        metrics=rules.train.output.metrics,
        info=rules.train.output.info,
        rule=rules.physics_baseline.output.predictions,
        simulated=rules.features_simulated.output.features,
        measured=rules.features_measured.output.features,
        splits=rules.hybrid.output.splits,
    output:
        predictions=f"{RESULTS}/joined/joined_{{classifier}}/{{protocol}}/predictions.parquet",
        metrics=f"{RESULTS}/joined/joined_{{classifier}}/{{protocol}}/metrics.csv",
        info=f"{RESULTS}/joined/joined_{{classifier}}/{{protocol}}/info.json",
        # per tested record: its share of segments outside the fit's training range
        coverage=f"{RESULTS}/joined/joined_{{classifier}}/{{protocol}}/coverage.csv",
    params:
        classifier=lambda wc: wc.classifier,
    conda:
        "../envs/learning.yaml"
    benchmark:
        f"{BENCHMARKS}/joined/{{classifier}}_{{protocol}}.tsv"
    log:
        f"{LOGS}/joined/{{classifier}}_{{protocol}}.log",
    script:
        "../scripts/joined.py"
