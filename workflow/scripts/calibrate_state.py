"""Per-state calibration of one fault state's model (calibration.per_state): CMA-ES over its
fault's form and severities on its calibration records, the healthy calibration fixed."""

import json

from condmon.atomic import write_frame, write_json
from condmon.calibrate import calibrate_state
from condmon.hybrid import calibration_frame
from condmon.labels import data_source_label
from condmon.plots import calibration_convergence, save_figure, state_fit_label
from condmon.runlog import setup_logging
from condmon.signals import read_signal_table
from condmon.systems import load_system

log = setup_logging(snakemake)
p = snakemake.params
system = load_system(p.system)
with open(snakemake.input.calibration) as handle:
    calibrated = json.load(handle)
# only the calibration set: the state's calibration records and the healthy ones
frame = calibration_frame(
    read_signal_table(snakemake.input.measured),
    system.healthy_state,
    p.condition,
    dict(p.reserve),
    states=[p.state, system.healthy_state],
)
result, history = calibrate_state(
    system,
    frame,
    p.state,
    calibrated,
    p.calibration,
    p.spectrum,
    list(p.channels),
    processes=snakemake.threads,
)
write_frame(history, snakemake.output.history)
save_figure(
    calibration_convergence(
        history,
        result["model_variant"],
        f"{p.state} model, {data_source_label(p.data_source)} | {state_fit_label(result)}",
        no_change_cost=result["no_change_cost"],
    ),
    snakemake.output.plot,
)
write_json(result, snakemake.output.params)
