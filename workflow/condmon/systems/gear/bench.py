"""The gear system's virtual bench: records of the hidden true rig, labelled `virtual_bench`."""

from __future__ import annotations

import logging
import time

from condmon.models.gear.virtual_bench import BenchForm, bench_fault, bench_gears, bench_record
from condmon.seeds import job_rng
from condmon.signals import make_rows
from condmon.systems.gear.parameters import simulation_settings

log = logging.getLogger(__name__)
FORM_KEYS = tuple(BenchForm.__dataclass_fields__)


def bench_form(bench: dict) -> BenchForm:
    """The `virtual_bench` config section's effects the model lacks."""
    return BenchForm(
        **{k: tuple(v) if isinstance(v, list) else v for k, v in bench.items() if k in FORM_KEYS}
    )


def virtual_bench_rows(
    parameters,
    bench: dict,
    health_states,
    points,
    numerics: dict,
    segment_seconds: float,
    load_torque=float,
    table_load=float,
) -> list[dict]:
    """Records of the virtual bench: `records_per_state` acquisitions per health state and
    operating point (`OperatingPoint`s), each `record_seconds` long, cut into segments. Source is
    always `virtual_bench`. `parameters(**overrides)` builds the rig's GearDrivetrainParameters
    (the system's); the bench overrides any of its fields (`model_overrides`, then
    `true_parameters`), has its own gears and its own fault forms (`faults`); a point's load
    (`load_torque(load)`: its output torque, N m) is the operator's, over the truth. The records'
    `load` is the point's, or `table_load(torque)` of the bench's one torque."""
    form = bench_form(bench)
    settings = simulation_settings(numerics, duration=bench["record_seconds"])
    segment_length = int(round(segment_seconds * settings.output_rate))
    truth = dict(bench.get("model_overrides", {}), **bench["true_parameters"])
    rig = parameters(**truth)
    gears = bench_gears(form, rig.geometry, bench["seed"], rig.stages)
    pairs = [rig.geometry] + [stage.geometry for stage in rig.stages]
    rows = []
    for health_state in health_states:
        # the pair whose pinion the bench damaged (its fault's `stage`; the first pair's otherwise)
        stage = int(bench.get("faults", {}).get(health_state, {}).get("stage", 0))
        model_state, fault_maps = bench_fault(
            health_state,
            bench.get("faults", {}),
            pairs[stage].teeth_pinion,
            bench["faulty_tooth"],
            job_rng(bench["seed"], "bench fault", health_state),
        )
        on_stage = {"faulty_stage": stage} if rig.stages else {}
        for point in points:
            speed = float(point.speed_rpm)
            # a point with a load draws a stream of its own; the speed alone keeps the one it had
            loaded = () if point.load is None else (float(point.load),)
            rng = job_rng(bench["seed"], "virtual_bench", health_state, speed, *loaded)
            at_load = {} if point.load is None else {"load_torque": load_torque(point.load)}
            params = parameters(
                speed_rpm=speed, health_state=model_state, **dict(truth, **at_load, **on_stage)
            )
            for k in range(bench["records_per_state"]):
                start = time.perf_counter()
                signals, mesh_phase = bench_record(params, form, settings, rng, gears, fault_maps)
                log.info(
                    "virtual bench %s %s record %d of %d: %.1f s",
                    health_state,
                    point.describe(),
                    k + 1,
                    bench["records_per_state"],
                    time.perf_counter() - start,
                )
                # the truth a located tooth is scored against: where the teeth stood at the first
                # sample, and which pinion teeth the bench damaged (of which pair in a train)
                truth_of_record = {
                    "mesh_phase": mesh_phase,
                    "damaged_teeth": [t for t, m in enumerate(fault_maps) if m is not None],
                    **({"damaged_stage": stage} if rig.stages else {}),
                }
                rows += make_rows(
                    f"vb-{health_state}-{point.label}-r{k:02d}",
                    "virtual_bench",
                    health_state,
                    speed,
                    table_load(params.load_torque) if point.load is None else point.load,
                    settings.output_rate,
                    signals,
                    segment_length=segment_length,
                    params=truth_of_record,
                )
    return rows
