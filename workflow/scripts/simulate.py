"""One simulation job: a batch of perturbed model runs for one health state and speed."""
import json

from condmon.atomic import write_json
from condmon.runlog import setup_logging
from condmon.signals import write_signal_table
from condmon.simulate import simulate_batch

log = setup_logging(snakemake)
p = snakemake.params
with open(snakemake.input.calibration) as handle:
    calibrated = json.load(handle)
sim = p.simulation
health, speed, batch = snakemake.wildcards.health, float(snakemake.wildcards.speed), int(snakemake.wildcards.batch)
if p.system == "bearing":
    from condmon.bearing_model import simulate_bearing_batch

    # the rig model draws its own domain randomisation (bearing.randomisation) around the calibration
    rows, report = simulate_bearing_batch(
        p.model, calibrated, health, speed, batch, samples=p.samples, numerics=p.numerics,
        segment_length=int(round(p.segment_seconds * p.numerics["output_rate_hz"])),
        segments_per_sample=sim["segments_per_sample"], seed=sim["seed"],
        max_failed_share=sim["max_failed_share"])
else:
    rows, report = simulate_batch(
        p.model, calibrated, health, speed, batch,
        samples=p.samples, perturbation={"sigma": sim["perturbation_sigma"], "parameters": list(calibrated["parameters"])},
        numerics=p.numerics, segment_seconds=p.segment_seconds, segments_per_sample=sim["segments_per_sample"],
        seed=sim["seed"], max_failed_share=sim["max_failed_share"])
write_signal_table(rows, snakemake.output.signals, config=dict(p.items()))
write_json(report, snakemake.output.report)
log.info("wrote %d rows; %d of %d samples failed", len(rows), len(report["failures"]), report["samples"])
