"""Calibrate the system's model on the healthy measured records with CMA-ES (one calibration
variant: the wildcard's, one of the system's calibration_variants()), then, with
calibration.background, the background those records carry and the model lacks."""

import time

from condmon.atomic import write_frame, write_json
from condmon.background import background_rms, estimate_background
from condmon.hybrid import calibration_frame
from condmon.plots import background_grid, calibration_convergence, save_figure
from condmon.labels import data_source_label
from condmon.runlog import setup_logging
from condmon.signals import read_signal_table
from condmon.systems import load_system

log = setup_logging(snakemake)
p = snakemake.params
system = load_system(p.system)
frame = read_signal_table(snakemake.input.measured)  # or a bench's healthy records alone
# only the calibration set (calibration.reserve): segments no split ever tests or trains on
frame = calibration_frame(frame, system.healthy_state, p.condition, p.calibration["reserve"])
result, history, spectra = system.calibrate(
    frame, p.variant, p.calibration, p.spectrum, list(p.channels), processes=snakemake.threads
)
if p.calibration["background"]:
    started = time.perf_counter()
    background = estimate_background(
        system,
        frame,
        result,
        list(p.channels),
        p.calibration["background_runs"],
        p.calibration["sim_seconds"],
        p.calibration["seed"],
        processes=snakemake.threads,
        method=p.calibration["background_method"],
    )
    result["background"] = background_rms(background) or None
    result["background_seconds"] = round(time.perf_counter() - started, 1)
    if background.empty:
        log.warning(
            "no measured healthy records at the simulated speeds: no background, the simulation adds "
            "white sensor noise only"
        )
    write_frame(background, snakemake.output.background)
    save_figure(
        background_grid(
            background, data_source_label(p.data_source), p.calibration["background_method"]
        ),
        snakemake.output.background_plot,
    )
write_frame(spectra, snakemake.output.spectra)
write_frame(history, snakemake.output.history)
save_figure(
    calibration_convergence(history, result["model_variant"], data_source_label(p.data_source)),
    snakemake.output.plot,
)
write_json(result, snakemake.output.params)
log.info(
    "%s calibration %s (%s): cost %s (nominal %s), %d evaluations, %s s: %s",
    system.name,
    p.variant,
    result["cost_function"],
    result["cost"],
    result["nominal_cost"],
    result["evaluations"],
    result["seconds"],
    result["parameters"],
)
