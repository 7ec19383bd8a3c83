"""Regression guard on simulation cost (issue 51, item 3): each system's CPU time per simulated
second divided by a fixed reference workload timed in the same process, so machines of other
speeds compare; tests/test_throughput_guard.py fails when a system's ratio grows more than
GROWTH_LIMIT over the baseline stored in benchmarks/throughput_baseline.json.

Short runs (settling plus DURATION s of output, the healthy state at the middle speed, the
config's own numerics); each figure is the minimum over REPEATS runs after a warm-up, and the
reference is timed again beside every system (minima: a shared core slows a run, never speeds
it up). Times are the process's CPU seconds, not wall seconds: in CI the guard shares the two
cores with the other test worker and the pipeline tests' jobs, and wall time then counts the
time slices given to them (at 0cae326 it doubled the CFRP rig's figure while the 40 ms reference
runs still caught idle moments).

    python3 benchmarks/throughput_guard.py            # print the ratios against the baseline
    python3 benchmarks/throughput_guard.py --write    # measure and store a new baseline
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))
import throughput  # noqa: E402  (the benchmark's system loading and machine description)

BASELINE = ROOT / "benchmarks" / "throughput_baseline.json"
GROWTH_LIMIT = 1.5  # a ratio this many times the baseline's fails
DURATION = 0.25  # s of output per run (plus the system's settling)
REPEATS = 3
BASELINE_PASSES = 3  # --write stores the median of this many measurements
SYSTEMS = [
    "config/config.yaml",
    "config/config.yaml:flexible",
    "config/cfrp.yaml",
    "config/cwru.yaml",
]


def reference_workload() -> float:
    """CPU seconds of a fixed exudyn run with what the models' hot paths hold: a chain of 8
    point masses on Cartesian spring-dampers, RK44, 4000 steps, one spring with a symbolic
    force function (compiled expression tree, as the bearing's) and one with a Python user
    function (as the gear's mesh)."""
    import exudyn as exu
    from exudyn.utilities import CreateSymbolicUserFunction

    eii = exu.itemInterface
    container = exu.SystemContainer()
    try:
        mbs = container.AddSystem()
        ground = mbs.AddObject(eii.ObjectGround())
        previous = mbs.AddMarker(
            eii.MarkerBodyPosition(bodyNumber=ground, localPosition=[0.0, 0.0, 0.0])
        )
        springs = []
        for i in range(8):
            node = mbs.AddNode(
                eii.NodePoint2D(referenceCoordinates=[0.0, 0.0], initialCoordinates=[1e-3 * i, 0.0])
            )
            mbs.AddObject(eii.ObjectMassPoint2D(mass=1.0, nodeNumber=node))
            marker = mbs.AddMarker(eii.MarkerNodePosition(nodeNumber=node))
            springs.append(
                mbs.AddObject(
                    eii.ObjectConnectorCartesianSpringDamper(
                        markerNumbers=[previous, marker],
                        stiffness=[1e6, 1e6, 0.0],
                        damping=[10.0, 10.0, 0.0],
                    )
                )
            )
            previous = marker

        def symbolic_force(mbs_, t, item, u, v, k, d, offset):
            esym = exu.symbolic
            hertz = [
                esym.pow(
                    esym.max(u[i] + esym.sin(t * (100.0 * j)) * 1e-4, esym.Real(0.0)),
                    esym.Real(1.5),
                )
                * 1e9
                for i in (0, 1)
                for j in range(1, 6)
            ]
            return esym.Vector(
                [sum(hertz[:5]) + v[0] * 10.0, sum(hertz[5:]) + v[1] * 10.0, esym.Real(0.0)]
            )

        def python_force(mbs_, t, item, u, v, k, d, offset):
            return [1e6 * u[0] + 10.0 * v[0], 1e6 * u[1] + 10.0 * v[1], 0.0]

        keep = CreateSymbolicUserFunction(
            mbs, symbolic_force, "springForceUserFunction", springs[0]
        )
        mbs.SetObjectParameter(springs[0], "springForceUserFunction", keep)
        mbs.SetObjectParameter(springs[1], "springForceUserFunction", python_force)
        mbs.Assemble()
        sim = exu.SimulationSettings()
        sim.timeIntegration.numberOfSteps = 4000
        sim.timeIntegration.endTime = 4000 * 1e-5
        sim.timeIntegration.verboseMode = 0
        sim.solution.file.write = False
        start = time.process_time()
        mbs.SolveDynamic(sim, solverType=exu.DynamicSolverType.RK44)
        seconds = time.process_time() - start
        del keep
        return seconds
    finally:
        container.Reset()


def system_cost(spec: str, duration: float = DURATION, repeats: int = REPEATS) -> dict:
    """The system's CPU seconds per simulated second (minimum over `repeats` runs after a
    warm-up), the reference workload's seconds (minimum, timed between the runs) and their
    ratio."""
    # One BLAS thread, as the pipeline's jobs: under pytest numpy is loaded before
    # throughput.py sets OPENBLAS_NUM_THREADS, and an idle second thread spins on CPU time.
    with threadpool_limits(limits=1):
        return _system_cost(spec, duration, repeats)


def _system_cost(spec: str, duration: float, repeats: int) -> dict:
    system, config = throughput.load_system(spec)
    values = system.sample_parameters(
        system.nominal_calibration(),
        system.healthy_state,
        np.random.default_rng(0),
        config["simulation"],
    )
    speed = throughput._speed(system)
    simulated = system.settle_seconds + duration
    system.simulate_sample(values, system.healthy_state, speed, duration, 1)  # warm-up
    reference_workload()
    runs, references = [], []
    for i in range(repeats):
        references.extend(
            reference_workload() for _ in range(3)
        )  # 40 ms each: more minima, little time
        start = time.process_time()
        system.simulate_sample(values, system.healthy_state, speed, duration, 1)
        runs.append((time.process_time() - start) / simulated)
    return {
        "seconds_per_simulated_second": round(min(runs), 4),
        "reference_seconds": round(min(references), 5),
        "ratio": round(min(runs) / min(references), 3),
        "simulated_seconds": round(simulated, 4),
    }


def read_baseline(path: Path = BASELINE) -> dict:
    return json.loads(Path(path).read_text())


def check(baseline: dict, specs=None) -> list[str]:
    """Every system whose ratio grew more than GROWTH_LIMIT over `baseline`'s, as messages
    (empty: none did); prints each system's figures."""
    failures = []
    for spec in specs or list(baseline["systems"]):
        base = baseline["systems"][spec]
        now = system_cost(spec, baseline.get("duration", DURATION))
        growth = now["ratio"] / base["ratio"]
        print(
            f"{spec}: ratio {now['ratio']:.3f} (baseline {base['ratio']:.3f}, x{growth:.2f}; "
            f"{now['seconds_per_simulated_second']:.3f} s/s, reference {now['reference_seconds']:.4f} s)",
            flush=True,
        )
        if growth > GROWTH_LIMIT:
            failures.append(
                f"{spec}: cost per simulated second / reference workload {now['ratio']:.3f}, "
                f"{growth:.2f} x the baseline's {base['ratio']:.3f} (limit {GROWTH_LIMIT} x; "
                f"baseline at {baseline['commit'][:10]} on {baseline['machine']['cpu']})"
            )
    return failures


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--write", action="store_true", help=f"measure and write {BASELINE.name}")
    parser.add_argument("--baseline", type=Path, default=BASELINE)
    parser.add_argument("--systems", nargs="+", default=None)
    args = parser.parse_args(argv)
    if args.write:
        commit = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True
        ).stdout.strip()
        dirty = bool(
            subprocess.run(
                ["git", "status", "--porcelain", "models", "workflow"],
                cwd=ROOT,
                capture_output=True,
                text=True,
            ).stdout.strip()
        )
        systems = {}
        for spec in args.systems or SYSTEMS:
            # the median of BASELINE_PASSES measurements: one lucky minimum would leave a later,
            # ordinary run looking grown (the CFRP rig's ratio ranged 59-76 on one quiet machine)
            passes = sorted(
                (system_cost(spec) for _ in range(BASELINE_PASSES)),
                key=lambda entry: entry["ratio"],
            )
            systems[spec] = passes[len(passes) // 2] | {
                "ratios_measured": [entry["ratio"] for entry in passes]
            }
            print(spec, systems[spec], flush=True)
        baseline = {
            "commit": commit + (" (uncommitted changes)" if dirty else ""),
            "machine": throughput.machine(),
            "duration": DURATION,
            "repeats": REPEATS,
            "passes": BASELINE_PASSES,
            "growth_limit": GROWTH_LIMIT,
            "systems": systems,
        }
        args.baseline.write_text(json.dumps(baseline, indent=2) + "\n")
        print(f"wrote {args.baseline}")
        return
    failures = check(read_baseline(args.baseline), args.systems)
    print("\n".join(failures) if failures else "every system within the limit")
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()
