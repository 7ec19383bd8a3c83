# Stage 8: a trained model applied to new measurements:
#   snakemake predict --config predict_input=PATH [predict_model=MODEL]
# writes results/<run>/predict/<input name>/ (condmon/predict.py; `condmon predict` is the same).


rule predict:
    input:
        unpack(lambda wildcards: predict_inputs()),
    output:
        directory(f"{RESULTS}/predict/{PREDICT_NAME}"),
    params:
        model=config["predict_model"],
        tracking_uri=config["tracking"]["uri"],  # where an MLflow predict_model is looked up
    conda:
        "../envs/report.yaml"
    log:
        f"{LOGS}/predict/{PREDICT_NAME}.log",
    script:
        "../scripts/predict.py"
