"""Calibrate the gear model on the healthy measured records with CMA-ES, with the mesh stiffness
model of the job (`model.mesh_stiffness_model` in params carries the wildcard's)."""
import time

import pandas as pd

from condmon.calibrate import (Bound, Calibrator, SpectrumModel, estimate_sensor_noise, measured_spectra,
                               spectrum_cost, with_sensor_noise)
from condmon.gear_model import build_parameters
from condmon.plots import calibration_convergence, save_figure
from condmon.report import data_source_label
from condmon.runlog import setup_logging
from condmon.atomic import write_frame, write_json
from condmon.signals import read_signal_table
from models.gear_drivetrain import operating_mesh_stiffness

log = setup_logging(snakemake)
p = snakemake.params
cal = p.calibration
start = time.perf_counter()

frame = read_signal_table(snakemake.input.measured)
fs = float(frame["fs_hz"].iloc[0])
speeds = sorted(float(s) for s in frame.loc[frame["health_state"] == "healthy", "speed_rpm"].unique()
                if float(s) in [float(x) for x in p.speeds_rpm])
target = measured_spectra(frame, speeds, p.channels, p.spectrum, cal["resolution_hz"], fs)
spectrum_model = SpectrumModel(p.model, p.numerics, speeds, p.channels, p.spectrum, cal["resolution_hz"],
                               cal["sim_seconds"], p.segment_seconds)
bounds = [Bound(name, b["low"], b["high"], b.get("log", False)) for name, b in cal["parameters"].items()]
calibrator = Calibrator(bounds, cal["contact_laws"], strategy=cal["strategy"], population=cal["population"],
                        generations=cal["generations"], sigma0=cal["sigma0"], seed=cal["seed"],
                        processes=snakemake.threads, initial={n: p.model[n] for n in cal["parameters"]})
log.info("calibrating %s (%s mesh stiffness) on %d healthy speeds %s, %d processes", [b.name for b in bounds],
         p.model["mesh_stiffness_model"], len(speeds), speeds, snakemake.threads)
best, history = calibrator.run(spectrum_model, target, cal["cost"])

nominal = {b.name: p.model[b.name] for b in bounds}
nominal_cost = spectrum_cost(spectrum_model(p.model["contact_law"], nominal), target, cal["cost"])
calibrated = spectrum_model(best["contact_law"], best["parameters"])
freqs = spectrum_model.spectrum.band_centres()
sensor_noise = estimate_sensor_noise(target, calibrated, spectrum_model.segment_length)
# What simulated records look like: the model plus the estimated sensor noise (6 sigma^2 / N per bin).
with_noise = with_sensor_noise(calibrated, sensor_noise, spectrum_model.segment_length)
rows = []
for i, speed in enumerate(speeds):
    for j, channel in enumerate(p.channels):
        rows.append(pd.DataFrame(dict(speed_rpm=speed, channel=channel, freq_hz=freqs, measured=target[i, j],
                                      calibrated=with_noise[i, j], model_only=calibrated[i, j])))
write_frame(pd.concat(rows, ignore_index=True), snakemake.output.spectra)
write_frame(history, snakemake.output.history)
save_figure(calibration_convergence(history, best["contact_law"], data_source_label(p.data_source)),
            snakemake.output.plot)
# K and n trade off at one load; the stiffness the vibration sees is what the data pin down.
mesh_stiffness = operating_mesh_stiffness(build_parameters(p.model, contact_law=best["contact_law"],
                                                           **best["parameters"]))
result = dict(best, mesh_stiffness_model=p.model["mesh_stiffness_model"], nominal_cost=nominal_cost,
              sensor_noise=sensor_noise, operating_mesh_stiffness=mesh_stiffness,
              strategy=cal["strategy"], cost_function=cal["cost"], speeds_rpm=speeds, seconds=round(time.perf_counter() - start, 1),
              seconds_per_evaluation=float(history["seconds"].mean()),
              failed_evaluations=int((history["error"] != "").sum()))
write_json(result, snakemake.output.params)
log.info("%s mesh: best %s cost %.4g (nominal %.4g) after %d evaluations: %s; sensor noise %.3g m/s^2",
         p.model["mesh_stiffness_model"], best["contact_law"], best["cost"], nominal_cost, best["evaluations"],
         best["parameters"], sensor_noise)
