"""Calibrate the bearing rig on the healthy measured records with CMA-ES (condmon.rig_calibration)."""
from condmon.atomic import write_frame, write_json
from condmon.plots import calibration_convergence, save_figure
from condmon.report import data_source_label
from condmon.rig_calibration import calibrate_rig
from condmon.runlog import setup_logging
from condmon.signals import read_signal_table

log = setup_logging(snakemake)
p = snakemake.params
frame = read_signal_table(snakemake.input.measured)
segment_length = int(round(p.segment_seconds * p.numerics["output_rate_hz"]))
result, history, spectra = calibrate_rig(frame, p.model, p.numerics, p.calibration, p.spectrum,
                                         segment_length, processes=snakemake.threads)
write_frame(spectra, snakemake.output.spectra)
write_frame(history, snakemake.output.history)
save_figure(calibration_convergence(history, "hertz", data_source_label(p.data_source)), snakemake.output.plot)
write_json(result, snakemake.output.params)
log.info("rig calibration (%s): cost %s (nominal %s), %d evaluations, %s s: %s", result["cost_function"],
         result["cost"], result["nominal_cost"], result["evaluations"], result["seconds"], result["parameters"])
