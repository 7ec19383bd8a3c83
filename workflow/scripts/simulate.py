"""One simulation job: a batch of the system's runs for one health state and operating point."""

import json

from condmon.atomic import write_json
from condmon.background import read_background
from condmon.runlog import setup_logging
from condmon.signals import write_signal_table
from condmon.simulate import simulate_batch
from condmon.systems import load_system

log = setup_logging(snakemake)
p = snakemake.params
with open(snakemake.input.calibration) as handle:
    calibrated = json.load(handle)
# calibration.per_state: a fault state with its own calibrated model runs its tuned severities
if "state_calibration" in snakemake.input.keys():
    with open(snakemake.input.state_calibration) as handle:
        state = json.load(handle)
    calibrated["state_models"] = {
        state["state"]: {
            "variant": state["model_variant"],
            "parameters": state["parameters"],
            "spread": state["spread"],
        }
    }
# calibration.background: the input is there only when it is on
background = (
    read_background(snakemake.input.background) if "background" in snakemake.input.keys() else None
)
system = load_system(p.system)
point = system.operating_point(snakemake.wildcards.point)
rows, report = simulate_batch(
    system,
    calibrated,
    snakemake.wildcards.health,
    point.speed_rpm,
    int(snakemake.wildcards.batch),
    load=point.load,
    samples=p.samples,
    simulation=p.simulation,
    background=background,
    reference_segments=int(getattr(p, "reference_segments", 0)),
)
write_signal_table(rows, snakemake.output.signals, config=dict(p.items()))
write_json(report, snakemake.output.report)
log.info(
    "wrote %d rows; %d of %d samples failed", len(rows), len(report["failures"]), report["samples"]
)
