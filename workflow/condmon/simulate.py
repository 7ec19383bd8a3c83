"""Simulation stage: batches of perturbed model runs per health state and speed."""
from __future__ import annotations

import dataclasses
import json
import logging
import time

from condmon.gear_model import build_parameters, perturb, simulation_settings
from condmon.seeds import job_rng
from condmon.signals import make_rows
from models.gear_drivetrain import SimulationError, simulate

log = logging.getLogger(__name__)


class TooManyFailures(RuntimeError):
    """More simulations of a batch failed than the config tolerates."""


def simulate_with_retry(params, settings):
    """Run the model; if it diverges, retry once with half the time step.

    Returns (signals or None, list of error messages).
    """
    errors = []
    for attempt in (settings, dataclasses.replace(settings,
                                                  steps_per_sensor_sample=2 * settings.steps_per_sensor_sample)):
        try:
            return simulate(params, attempt), errors
        except SimulationError as exc:
            errors.append(f"h = 1/{attempt.output_rate * attempt.oversampling * attempt.steps_per_sensor_sample:g}"
                          f" s: {exc}")
    return None, errors


def simulate_batch(model: dict, calibrated: dict, health_state: str, speed_rpm: float, batch: int,
                   samples: int, perturbation: dict, numerics: dict, segment_seconds: float,
                   segments_per_sample: int, seed: int, max_failed_share: float = 0.0):
    """Signal-table rows for `samples` runs of one (health state, speed, batch), and a report
    (timings, failures with their parameters).

    Every sample draws its own perturbation of the calibrated parameters from the job's
    stream, seeded by (seed, health state, speed, batch): reruns and any job order give the
    same records. White noise of the calibrated sensor-noise RMS stands in for the measurement
    chain the model lacks, so classifiers do not learn a noise-free floor. A sample whose
    simulation fails twice is left out and reported; more than `max_failed_share` of the batch
    failing stops the job.
    """
    rng = job_rng(seed, "simulate", health_state, float(speed_rpm), batch)
    settings = simulation_settings(numerics, duration=segment_seconds * segments_per_sample)
    fs = settings.output_rate
    rows, failures, seconds = [], [], []
    for i in range(samples):
        values = perturb(calibrated["parameters"], perturbation["parameters"], perturbation["sigma"], rng)
        noise_seed = int(rng.integers(2 ** 32))  # drawn for every sample, failed or not: streams stay aligned
        params = build_parameters(model, contact_law=calibrated["contact_law"], speed_rpm=float(speed_rpm),
                                  health_state=health_state, **values)
        record_id = f"sim-{health_state}-{speed_rpm:g}rpm-b{batch:03d}-s{i:03d}"
        start = time.perf_counter()
        signals, errors = simulate_with_retry(params, settings)
        seconds.append(time.perf_counter() - start)
        for error in errors:
            log.warning("%s: %s", record_id, error)
        if signals is None:
            failures.append({"record_id": record_id, "errors": errors, "params": values})
            continue
        log.info("%s: %.2f s", record_id, seconds[-1])
        noise = job_rng(noise_seed, "noise")
        signals = {name: signal + noise.normal(0.0, calibrated["sensor_noise"], size=signal.shape)
                   for name, signal in signals.items()}
        rows += make_rows(record_id, "simulated", health_state, speed_rpm, params.load_torque, fs, signals,
                          segment_length=int(round(segment_seconds * fs)),
                          params={"contact_law": calibrated["contact_law"], **values})
    report = batch_report(health_state, speed_rpm, batch, samples, failures, seconds,
                          settings.settle_time + settings.duration, max_failed_share)
    return rows, report


def batch_report(health_state, speed_rpm, batch, samples, failures, seconds, simulated_seconds,
                 max_failed_share, what="simulations") -> dict:
    """A simulation job's report (samples, failures with their parameters, wall seconds per
    sample); TooManyFailures when more than `max_failed_share` of the samples failed."""
    if len(failures) > max_failed_share * samples:
        first = failures[0]
        raise TooManyFailures(
            f"{len(failures)} of {samples} {what} of {health_state} at {speed_rpm:g} rpm batch {batch} "
            f"failed (tolerated share {max_failed_share:g}); first: {first['record_id']} "
            f"{first['errors'][-1]} with parameters {json.dumps(first['params'], default=str)}")
    return {"health_state": health_state, "speed_rpm": float(speed_rpm), "batch": batch, "samples": samples,
            "succeeded": samples - len(failures), "failures": failures,
            "simulated_seconds_per_sample": simulated_seconds, "wall_seconds": seconds}
