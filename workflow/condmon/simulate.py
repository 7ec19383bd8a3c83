"""Simulation stage: batches of one system's runs per health state and speed, each sample with
its own draw of the parameters (perturbation or domain randomisation, the system's rule)."""

from __future__ import annotations

import json
import logging
import time

from condmon.models.numerics import SimulationError
from condmon.seeds import job_rng
from condmon.signals import make_rows
from condmon.operating import OperatingPoint

log = logging.getLogger(__name__)


class TooManyFailures(RuntimeError):
    """More simulations of a batch failed than the config tolerates."""


def simulate_with_retry(
    system, parameters: dict, health_state: str, speed_rpm: float, duration_s: float, seed: int
):
    """Run one sample; if it fails, retry once at half the time step with the same seed.

    Returns (signals or None, list of error messages)."""
    errors = []
    for refinement in (1, 2):
        try:
            return system.simulate_sample(
                parameters, health_state, speed_rpm, duration_s, seed, step_refinement=refinement
            ), errors
        except SimulationError as exc:
            errors.append(f"time step 1/{refinement} of the configured: {exc}")
    return None, errors


def machine_id(point: OperatingPoint, batch: int, index: int) -> str:
    """The simulated machine a sample is: the same in every health state (``reference_segments``)."""
    return f"{point.label}-b{batch:03d}-s{index:03d}"


def machine_of(record_id: str) -> str:
    """The machine id of a simulated record id (``sim-<health state>-<machine id>``)."""
    parts = str(record_id).rsplit("-", 3)
    if len(parts) != 4 or not parts[0].startswith("sim-") or "rpm" not in parts[1]:
        raise ValueError(
            f"{record_id!r} is not a simulated record id (sim-<health state>-<operating "
            "point>-b<batch>-s<sample>, the point 450rpm or 450rpm_20Nm)"
        )
    return "-".join(parts[1:])


def simulate_batch(
    system,
    calibrated: dict,
    health_state: str,
    speed_rpm: float,
    batch: int,
    samples: int,
    simulation: dict,
    background=None,
    reference_segments: int = 0,
    load: float | None = None,
):
    """Signal-table rows for `samples` runs of one (health state, speed, batch), and a report
    (timings, failures with their parameters); at `load` (an `OperatingPoint.load`, the rig's
    unit; None: the model's one load).

    Every sample draws its parameters (`system.sample_parameters`) and then a run seed from the
    job's stream, seeded by (simulation.seed, health state, speed, batch, and the load where
    there is one): reruns and any job order give the same records. With a `background` (`condmon.background.Background`, the calibration's
    estimate of what healthy records carry and the model lacks) every sample gets a random-phase
    Gaussian realisation of it per channel, drawn from the sample's own stream; without one (or on a
    channel it does not cover), white noise of the calibrated `sensor_noise` RMS (when the
    calibration estimated one) stands in for the measurement chain the model lacks, so classifiers
    do not learn a noise-free floor. A sample whose simulation fails twice is left out and reported;
    more than `simulation.max_failed_share` of the batch failing stops the job.

    With `reference_segments` (features.healthy_reference) every sample has twins: the stream
    leaves the health state out, so sample i of (speed, batch) draws the same parameters and run
    seed (the system's manufacturing scatter, fluctuations and fault severities) in every health
    state (common random numbers): one machine, healthy and damaged; only the measurement noise
    and background differ. A healthy sample runs `reference_segments` segments longer: its last
    segments are that machine's healthy reference (`condmon.reference`), its others coincide in
    time with its damaged twins' samples.
    """
    paired = reference_segments > 0
    point = OperatingPoint(float(speed_rpm), load)
    stream = (
        ("simulate", float(speed_rpm), batch)
        if paired
        else ("simulate", health_state, float(speed_rpm), batch)
    )
    # a load draws a stream of its own; the speed alone keeps the one it had
    stream += () if load is None else (float(load),)
    rng = job_rng(simulation["seed"], *stream)
    acquisition = (health_state,) if paired else ()  # paired twins: each state its own noise
    fs, segment_length = system.output_rate_hz, system.segment_length
    segments = simulation["segments_per_sample"] + (
        reference_segments if health_state == system.healthy_state else 0
    )
    duration = segment_length * segments / fs
    sensor_noise = float(calibrated.get("sensor_noise") or 0.0)
    if background:
        source = background.source_speed(speed_rpm)
        if source != float(speed_rpm):
            log.warning(
                "no measured healthy records at %g rpm: its samples take the background of the nearest "
                "measured speed, %g rpm, as it is (its shaft-synchronous lines are not moved)",
                speed_rpm,
                source,
            )
        else:
            log.info("adding the calibrated background of %g rpm to every sample", source)
    elif background is not None:
        log.info(
            "the calibration found no measured healthy records: no background, white sensor noise only"
        )
    rows, failures, seconds = [], [], []
    for i in range(samples):
        values = system.at_load(
            system.sample_parameters(calibrated, health_state, rng, simulation), load
        )
        sample_seed = int(
            rng.integers(2**32)
        )  # drawn for every sample, failed or not: streams stay aligned
        record_id = f"sim-{health_state}-{machine_id(point, batch, i)}"
        start = time.perf_counter()
        signals, errors = simulate_with_retry(
            system, values, health_state, float(speed_rpm), duration, sample_seed
        )
        seconds.append(time.perf_counter() - start)
        for error in errors:
            log.warning("%s: %s", record_id, error)
        if signals is None:
            failures.append({"record_id": record_id, "errors": errors, "params": values})
            continue
        log.info(
            "%s: %.2f s (%d of %d, about %.0f s left)",
            record_id,
            seconds[-1],
            i + 1,
            samples,
            sum(seconds) / (i + 1) * (samples - i - 1),
        )
        white = list(signals)
        if background:
            signals, white = background.add(
                signals, float(speed_rpm), fs, job_rng(sample_seed, "background", *acquisition)
            )
        if sensor_noise > 0 and white:
            noise = job_rng(sample_seed, "noise", *acquisition)
            signals = {
                name: signal + noise.normal(0.0, sensor_noise, size=signal.shape)
                if name in white
                else signal
                for name, signal in signals.items()
            }
        rows += make_rows(
            record_id,
            "simulated",
            health_state,
            speed_rpm,
            system.sample_load(speed_rpm, values) if load is None else float(load),
            fs,
            signals,
            segment_length=segment_length,
            params={**values, "seed": sample_seed},
        )
    report = batch_report(
        health_state,
        point,
        batch,
        samples,
        failures,
        seconds,
        system.settle_seconds + duration,
        simulation["max_failed_share"],
        what=f"{system.name} simulations",
    )
    return rows, report


def batch_report(
    health_state,
    point,
    batch,
    samples,
    failures,
    seconds,
    simulated_seconds,
    max_failed_share,
    what="simulations",
) -> dict:
    """A simulation job's report (samples, failures with their parameters, wall seconds per
    sample); TooManyFailures when more than `max_failed_share` of the samples failed."""
    if len(failures) > max_failed_share * samples:
        first = failures[0]
        raise TooManyFailures(
            f"{len(failures)} of {samples} {what} of {health_state} at {point.describe()} batch {batch} "
            f"failed (tolerated share {max_failed_share:g}); first: {first['record_id']} "
            f"{first['errors'][-1]} with parameters {json.dumps(first['params'], default=str)}"
        )
    return {
        "health_state": health_state,
        "speed_rpm": float(point.speed_rpm),
        **({} if point.load is None else {"load": float(point.load)}),
        "batch": batch,
        "samples": samples,
        "succeeded": samples - len(failures),
        "failures": failures,
        "simulated_seconds_per_sample": simulated_seconds,
        "wall_seconds": seconds,
    }
