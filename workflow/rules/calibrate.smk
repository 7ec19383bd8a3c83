# Stage 2: CMA-ES calibration of the gear model on the healthy measured spectra, one job per mesh
# stiffness model (calibration.mesh_stiffness_models plus model.mesh_stiffness_model); or of the
# bearing rig on the healthy CWRU records (one job, stiffness "rig").


rule calibrate:
    input:
        measured=rules.measured.output[0],
    output:
        params=f"{RESULTS}/calibration/{{stiffness}}/params.json",
        history=f"{RESULTS}/calibration/{{stiffness}}/history.parquet",
        spectra=f"{RESULTS}/calibration/{{stiffness}}/spectra.parquet",
        plot=f"{RESULTS}/calibration/{{stiffness}}/convergence.png",
    params:
        # the wildcard's stiffness model, so model.mesh_stiffness_model never reruns a calibration
        model=lambda wc: (MODEL if SYSTEM == "bearing"
                          else dict(config["model"], mesh_stiffness_model=wc.stiffness)),
        numerics=NUMERICS,
        calibration={k: v for k, v in config["calibration"].items() if k != "mesh_stiffness_models"},
        speeds_rpm=config["rig"]["speeds_rpm"],
        channels=config["features"]["channels"],
        spectrum=config["features"]["spectrum"],
        segment_seconds=SEGMENT_SECONDS,
        data_source=data_source(),
    threads: workflow.cores
    log:
        f"{LOGS}/calibrate_{{stiffness}}.log",
    script:
        "../scripts/calibrate.py" if SYSTEM == "gear" else "../scripts/calibrate_rig.py"
