"""Cost per simulated second of the gear drivetrain: both mesh stiffness models (issue 3: within
2x of `simple`) and, with `--shaft-model flexible`, the flexible-shaft variant.

Method: one process pinned to one core (`os.sched_setaffinity`, BLAS threads 1), the default
model of config/config.yaml and the default numerics (RK44, h = 19.5 us, sensors at 51.2 kHz,
output 5120 Hz). For each stiffness model, speed and health state, `condmon.models.gear.drivetrain.simulate`
runs `--seconds` recorded seconds after the default 0.15 s settling; the timer (perf_counter and
process CPU time) spans the whole call: building the mesh (the potential-energy tables included),
the exudyn run, filtering and decimation. Each case runs `--repeats` times, interleaved between the
models so that load from other processes hits both alike; the minimum is reported (the least
disturbed run), the median alongside. Cost per simulated second divides by settle + recorded
seconds (both are integrated); per output sample by the recorded samples.

    python3 benchmarks/mesh_stiffness_cost.py [--seconds 1.0] [--repeats 3] [--core 0] [--out FILE]
        [--shaft-model rigid|flexible]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

ROOT = Path(__file__).resolve().parents[1]

import yaml  # noqa: E402

from condmon.systems.gear.parameters import build_parameters, simulation_settings  # noqa: E402
from condmon.models.gear.drivetrain import simulate  # noqa: E402
from condmon.models.gear.mesh_force import MeshForce  # noqa: E402
from condmon.records import save_record  # noqa: E402

MODELS = ("simple", "potential_energy")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=1.0, help="recorded seconds per run")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--core", type=int, default=0, help="CPU core to pin to")
    parser.add_argument("--speeds", type=float, nargs="+", default=[450.0, 775.0, 1100.0])
    parser.add_argument("--health", nargs="+", default=["healthy", "missing_tooth"])
    parser.add_argument("--out", type=Path, default=None, help="write the results as JSON here")
    parser.add_argument("--shaft-model", default="rigid", choices=["rigid", "flexible"])
    args = parser.parse_args(argv)
    os.sched_setaffinity(0, {args.core})

    config = yaml.safe_load((ROOT / "config" / "config.yaml").read_text())
    numerics = dict(config["numerics"], output_rate=config["rig"]["output_rate_hz"])
    settings = simulation_settings(numerics, duration=args.seconds)
    simulated = settings.settle_time + settings.duration
    samples = int(round(settings.duration * settings.output_rate))

    rows = []
    for health in args.health:
        for speed in args.speeds:
            times = {m: [] for m in MODELS}
            for _ in range(args.repeats):
                for model in MODELS:
                    params = build_parameters(
                        config["model"],
                        mesh_stiffness_model=model,
                        speed_rpm=speed,
                        health_state=health,
                        shaft_model=args.shaft_model,
                    )
                    wall, cpu = time.perf_counter(), time.process_time()
                    simulate(params, settings)
                    times[model].append((time.perf_counter() - wall, time.process_time() - cpu))
            for model in MODELS:
                params = build_parameters(
                    config["model"],
                    mesh_stiffness_model=model,
                    speed_rpm=speed,
                    health_state=health,
                )
                start = time.perf_counter()
                MeshForce(params)
                build = time.perf_counter() - start
                walls = [w for w, _ in times[model]]
                cpus = [c for _, c in times[model]]
                rows.append(
                    dict(
                        model=model,
                        shaft_model=args.shaft_model,
                        health_state=health,
                        speed_rpm=speed,
                        wall_s=min(walls),
                        wall_median_s=statistics.median(walls),
                        cpu_s=min(cpus),
                        mesh_build_s=build,
                        wall_per_simulated_second=min(walls) / simulated,
                        wall_us_per_output_sample=1e6 * min(walls) / samples,
                    )
                )
                print(
                    f"{model:17s} {health:14s} {speed:6.0f} rpm: {min(walls):6.2f} s wall "
                    f"(median {statistics.median(walls):.2f}, cpu {min(cpus):.2f}, mesh build "
                    f"{build:.3f} s) = {min(walls) / simulated:.3f} s per simulated s",
                    flush=True,
                )
    print("\nratio potential_energy / simple (min wall time):")
    ratios = []
    for health in args.health:
        for speed in args.speeds:
            pick = {
                r["model"]: r["wall_s"]
                for r in rows
                if r["health_state"] == health and r["speed_rpm"] == speed
            }
            ratio = pick["potential_energy"] / pick["simple"]
            ratios.append(ratio)
            print(f"  {health:14s} {speed:6.0f} rpm: {ratio:.2f}")
    print(f"  mean {statistics.mean(ratios):.2f}, max {max(ratios):.2f}")
    figures = dict(
        seconds=args.seconds,
        repeats=args.repeats,
        simulated_seconds_per_run=simulated,
        rows=rows,
        ratios=ratios,
    )
    if args.out:
        args.out.write_text(json.dumps(dict(method=__doc__, **figures), indent=2) + "\n")
    save_record(
        "mesh_stiffness_cost",
        args.shaft_model,
        figures,
        script=__file__,
        argv=argv,
        configfiles=["config/config.yaml"],
    )


if __name__ == "__main__":
    main()
