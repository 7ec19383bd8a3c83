"""Simulation stage: batches of perturbed model runs per health state and speed."""
from __future__ import annotations

import logging
import time

from condmon.gear_model import build_parameters, perturb, simulation_settings
from condmon.seeds import job_rng
from condmon.signals import make_rows
from models.gear_drivetrain import simulate

log = logging.getLogger(__name__)


def simulate_batch(model: dict, calibrated: dict, health_state: str, speed_rpm: float, batch: int,
                   samples: int, perturbation: dict, numerics: dict, segment_seconds: float,
                   segments_per_sample: int, seed: int) -> list[dict]:
    """Signal-table rows for `samples` runs of one (health state, speed, batch).

    Every sample draws its own perturbation of the calibrated parameters from the job's
    stream, seeded by (seed, health state, speed, batch): reruns and any job order give the
    same records. White noise of the calibrated sensor-noise RMS stands in for the measurement
    chain the model lacks, so classifiers do not learn a noise-free floor.
    """
    rng = job_rng(seed, "simulate", health_state, float(speed_rpm), batch)
    settings = simulation_settings(numerics, duration=segment_seconds * segments_per_sample)
    fs = settings.output_rate
    rows = []
    for i in range(samples):
        values = perturb(calibrated["parameters"], perturbation["parameters"], perturbation["sigma"], rng)
        params = build_parameters(model, contact_law=calibrated["contact_law"], speed_rpm=float(speed_rpm),
                                  health_state=health_state, **values)
        start = time.perf_counter()
        signals = {name: signal + rng.normal(0.0, calibrated["sensor_noise"], size=signal.shape)
                   for name, signal in simulate(params, settings).items()}
        log.info("%s %s rpm batch %d sample %d/%d: %.2f s", health_state, speed_rpm, batch, i + 1,
                 samples, time.perf_counter() - start)
        record_id = f"sim-{health_state}-{speed_rpm:g}rpm-b{batch:03d}-s{i:03d}"
        rows += make_rows(record_id, "simulated", health_state, speed_rpm, params.load_torque, fs, signals,
                          segment_length=int(round(segment_seconds * fs)),
                          params={"contact_law": calibrated["contact_law"], **values})
    return rows
