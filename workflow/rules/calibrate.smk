# Stage 2: CMA-ES calibration of the gear model on the healthy measured spectra.


rule calibrate:
    input:
        measured=rules.measured.output[0],
    output:
        params=f"{RESULTS}/calibration/params.json",
        history=f"{RESULTS}/calibration/history.parquet",
        spectra=f"{RESULTS}/calibration/spectra.parquet",
        plot=f"{RESULTS}/calibration/convergence.png",
    params:
        model=config["model"],
        numerics=NUMERICS,
        calibration=config["calibration"],
        speeds_rpm=config["rig"]["speeds_rpm"],
        channels=config["features"]["channels"],
        spectrum=config["features"]["spectrum"],
        segment_seconds=config["rig"]["segment_seconds"],
        data_source=data_source(),
    threads: workflow.cores
    log:
        f"{LOGS}/calibrate.log",
    script:
        "../scripts/calibrate.py"
