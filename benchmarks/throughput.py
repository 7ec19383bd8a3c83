"""Simulation throughput of every system, on one core and on two (issue #11).

For each config: a warm-up sample, then `--repeats` timed samples of the pipeline's own length
(settling plus `segments_per_sample` segments), in a fresh worker process; then the same on
`--workers` processes at once. Every worker runs with one BLAS/OpenMP thread, as pipeline jobs do.
A cProfile of one sample says where the time goes. Also the step convergence check: the features of a noise-free healthy run (the config's spectrum
bands, every channel) at the configured step against a step four times smaller, in dB; and, with
--dag, the job count of `snakemake -n` for the given configs.

Writes <out>/throughput.json (seconds of wall time per simulated second: median, min, max;
samples per hour per core; the speed-up on `--workers` cores; peak memory per worker; the
convergence; the machine) and <out>/throughput.png, and its record
benchmarks/records/throughput-<name>.json (condmon.records).

    python3 benchmarks/throughput.py [--configs config/config.yaml config/cwru.yaml ...]
        [--repeats 3] [--workers 2] [--dag config/cfrp-study.yaml ...] [--out results/benchmark]
        [--name default]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import resource
import statistics
import subprocess
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

# One thread per worker, as Snakemake gives the pipeline's jobs (OMP_NUM_THREADS and the like =
# the job's threads). Set before numpy loads OpenBLAS: its second thread spins while idle, and on
# two cores each worker's spinning thread took about a quarter of a core from the other worker.
for variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[variable] = "1"

import numpy as np  # noqa: E402
import yaml  # noqa: E402

from condmon.records import save_record  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]

DEFAULT_CONFIGS = [
    "config/config.yaml",
    "config/config.yaml:flexible",
    "config/cfrp.yaml",
    "config/cwru.yaml",
]
CONVERGENCE_DB = 0.5  # the tolerance on the features
# bands more than 40 dB under a channel's strongest sit at or below a sensor noise floor of a few
# mm/s^2 (the default run's calibrated 1.6 mm/s^2): the features there see the noise, not the model;
# the json gives the 20 and 60 dB figures beside it
CONVERGENCE_FLOOR_DB = 40


def load_system(spec: str):
    """The system of `path[:flexible]` (flexible: the gear model with Timoshenko shafts)."""
    from condmon.config import load_schema, validate_config
    from condmon.systems import get_system

    path, _, variant = spec.partition(":")
    config = yaml.safe_load((ROOT / path).read_text())
    if "measured_dir" in config and not Path(config["measured_dir"]).is_absolute():
        config["measured_dir"] = str((ROOT / config["measured_dir"]).resolve())
    if variant == "flexible":
        config.setdefault("model", {})["shaft_model"] = "flexible"
    elif variant:
        raise ValueError(f"--configs {spec}: unknown variant {variant!r} (known: flexible)")
    config = validate_config(config, load_schema(ROOT / "config" / "schema.yaml"))
    return get_system(config), config


def sample_duration(system, config) -> float:
    """The length of one pipeline sample (s of output), as the simulate stage asks for it."""
    return (
        system.segment_length * config["simulation"]["segments_per_sample"] / system.output_rate_hz
    )


def _speed(system) -> float:
    speeds = system.speeds_rpm
    return float(speeds[len(speeds) // 2])


def time_samples(spec: str, repeats: int, seed: int) -> dict:
    """Wall seconds of `repeats` samples after one warm-up, and this process's peak memory."""
    system, config = load_system(spec)
    calibrated = system.nominal_calibration()
    rng = np.random.default_rng(seed)
    duration = sample_duration(system, config)
    healthy, speed = system.healthy_state, _speed(system)
    seconds = []
    for i in range(repeats + 1):
        values = system.sample_parameters(calibrated, healthy, rng, config["simulation"])
        start = time.perf_counter()
        system.simulate_sample(values, healthy, speed, duration, seed + i)
        if i:  # the first is the warm-up (imports, caches, compiled user functions)
            seconds.append(time.perf_counter() - start)
    return {
        "seconds": seconds,
        "simulated_seconds": system.settle_seconds + duration,
        "peak_memory_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    }


def profile_sample(spec: str, top: int = 6) -> list[dict]:
    """Where one sample's time goes: the `top` functions by own time under cProfile, as shares of
    the total (the profiler inflates Python-side time, so read the shares, not the seconds)."""
    import cProfile
    import pstats

    system, config = load_system(spec)
    values = system.sample_parameters(
        system.nominal_calibration(),
        system.healthy_state,
        np.random.default_rng(0),
        config["simulation"],
    )
    duration, speed = sample_duration(system, config), _speed(system)
    system.simulate_sample(values, system.healthy_state, speed, duration, 5)  # warm-up
    profiler = cProfile.Profile()
    profiler.runcall(system.simulate_sample, values, system.healthy_state, speed, duration, 5)
    stats = pstats.Stats(profiler).stats  # {(file, line, name): (calls, _, own, cumulative, _)}
    total = sum(own for _, _, own, _, _ in stats.values())
    rows = sorted(stats.items(), key=lambda item: -item[1][2])[:top]
    return [
        {
            "function": f"{Path(file).name}:{line}({name})",
            "calls": calls,
            "share": round(own / total, 3),
        }
        for (file, line, name), (calls, _, own, _, _) in rows
    ]


def run_workers(spec: str, repeats: int, workers: int) -> list[dict]:
    """`workers` fresh processes timing samples at the same time (distinct seeds)."""
    with ProcessPoolExecutor(workers) as pool:
        return list(
            pool.map(
                time_samples,
                [spec] * workers,
                [repeats] * workers,
                [1000 * (w + 1) for w in range(workers)],
            )
        )


def convergence(spec: str, refinement: int = 4) -> dict:
    """Largest difference (dB) of the spectrum features of one noise-free healthy run at the
    configured step and at a step `refinement` times smaller, over the bands within 20, 40
    (the criterion) and 60 dB of a channel's strongest."""
    from condmon.features import SpectrumFeatures

    system, config = load_system(spec)
    values = system.noise_free(
        system.sample_parameters(
            system.nominal_calibration(),
            system.healthy_state,
            np.random.default_rng(0),
            config["simulation"],
        )
    )
    duration, speed = sample_duration(system, config), _speed(system)
    channels = config["features"]["channels"]
    # linear amplitudes: the dB difference is taken here
    spectrum = SpectrumFeatures(
        channels=channels, **{**config["features"]["spectrum"], "scale": "linear"}
    )
    levels = []
    for step_refinement in (1, refinement):
        signals = system.simulate_sample(
            values, system.healthy_state, speed, duration, 11, step_refinement
        )
        n = system.segment_length
        stack = np.stack([[signals[c][:n] for c in channels]])
        bands = spectrum.transform(stack, system.output_rate_hz).reshape(len(channels), -1)
        levels.append(20 * np.log10(np.maximum(bands, 1e-300)))
    coarse, fine = levels
    difference = np.abs(coarse - fine)
    below_strongest = fine.max(axis=1, keepdims=True) - fine
    worst = {
        f"bands_within_{floor}_db": round(float(difference[below_strongest <= floor].max()), 3)
        for floor in (20, CONVERGENCE_FLOOR_DB, 60)
    }
    return {
        "max_difference_db": worst,
        "step_refinement": refinement,
        "criterion_floor_db": CONVERGENCE_FLOOR_DB,
        "within_0_5_db": worst[f"bands_within_{CONVERGENCE_FLOOR_DB}_db"] <= CONVERGENCE_DB,
    }


def dag_jobs(configfile: str) -> int:
    """Jobs in the whole DAG of `configfile` (`snakemake -n --forceall`: whatever results exist)."""
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "snakemake",
            "-n",
            "--forceall",
            "--quiet",
            "rules",
            "--configfile",
            configfile,
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    if out.returncode:
        raise RuntimeError(f"snakemake -n --configfile {configfile} failed:\n{out.stderr[-2000:]}")
    total = re.search(r"^total\s+(\d+)", out.stdout + out.stderr, re.MULTILINE)
    if total is None:
        raise RuntimeError(f"no job count in the dry run of {configfile}")
    return int(total.group(1))


def machine() -> dict:
    cpuinfo = Path("/proc/cpuinfo").read_text() if Path("/proc/cpuinfo").exists() else ""
    model = re.search(r"model name\s*:\s*(.*)", cpuinfo)
    memory = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30
    import exudyn

    return {
        "cpu": model.group(1) if model else platform.processor(),
        "cores": os.cpu_count(),
        "memory_gib": round(memory, 1),
        "python": platform.python_version(),
        "exudyn": exudyn.__version__,
        "platform": platform.platform(),
        "load_average_at_start": [round(x, 2) for x in os.getloadavg()],
    }


def summarise(one_core: dict, parallel: list[dict], workers: int) -> dict:
    per_simulated = [s / one_core["simulated_seconds"] for s in one_core["seconds"]]
    rate_one = len(one_core["seconds"]) / sum(one_core["seconds"]) * 3600
    rate_all = sum(len(w["seconds"]) / sum(w["seconds"]) * 3600 for w in parallel)
    return {
        "simulated_seconds_per_sample": round(one_core["simulated_seconds"], 4),
        "wall_seconds_per_simulated_second": {
            "median": round(statistics.median(per_simulated), 3),
            "min": round(min(per_simulated), 3),
            "max": round(max(per_simulated), 3),
        },
        "samples_per_hour_one_core": round(rate_one),
        f"samples_per_hour_{workers}_cores": round(rate_all),
        "speedup": round(rate_all / rate_one, 2),
        "peak_memory_mb_per_worker": round(max(w["peak_memory_mb"] for w in [one_core, *parallel])),
    }


def plot(results: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(results["systems"])
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4))
    cost = [results["systems"][n]["wall_seconds_per_simulated_second"] for n in names]
    median = [c["median"] for c in cost]
    errors = [
        [m - c["min"] for m, c in zip(median, cost)],
        [c["max"] - m for m, c in zip(median, cost)],
    ]
    left.bar(names, median, yerr=errors, capsize=4, color="tab:blue")
    left.set_ylabel("wall s per simulated s (one core)")
    left.set_title("simulation cost (median, min-max)")
    workers = results["workers"]
    x = np.arange(len(names))
    one = [results["systems"][n]["samples_per_hour_one_core"] for n in names]
    many = [results["systems"][n][f"samples_per_hour_{workers}_cores"] for n in names]
    right.bar(x - 0.2, one, 0.4, label="1 core")
    right.bar(x + 0.2, many, 0.4, label=f"{workers} cores")
    right.set_xticks(x, names)
    right.set_ylabel("samples per hour")
    right.set_title("throughput")
    right.legend()
    for axis in (left, right):
        axis.tick_params(axis="x", rotation=20)
    fig.suptitle(f"{results['machine']['cpu']}, {results['machine']['cores']} cores", fontsize=9)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--configs", nargs="+", default=DEFAULT_CONFIGS)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--dag", nargs="*", default=[], help="configs whose DAG size to count")
    parser.add_argument("--no-convergence", action="store_true")
    parser.add_argument("--out", type=Path, default=ROOT / "results" / "benchmark")
    parser.add_argument("--name", default="default", help="the record's name")
    args = parser.parse_args(argv)
    if args.repeats < 1 or args.workers < 1:
        parser.error("--repeats and --workers must be at least 1")

    results = {
        "machine": machine(),
        "repeats": args.repeats,
        "workers": args.workers,
        "systems": {},
    }
    for spec in args.configs:
        print(f"{spec}: one core ...", flush=True)
        one_core = run_workers(spec, args.repeats, 1)[0]
        print(f"{spec}: {args.workers} cores ...", flush=True)
        parallel = run_workers(spec, args.repeats, args.workers)
        entry = summarise(one_core, parallel, args.workers)
        entry["profile"] = profile_sample(spec)
        if not args.no_convergence:
            entry["convergence"] = convergence(spec)
        results["systems"][spec] = entry
        print(json.dumps(entry), flush=True)
    if args.dag:
        results["dag_jobs"] = {configfile: dag_jobs(configfile) for configfile in args.dag}
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "throughput.json").write_text(json.dumps(results, indent=2) + "\n")
    plot(results, args.out / "throughput.png")
    configfiles = sorted({spec.partition(":")[0] for spec in args.configs} | set(args.dag))
    save_record(
        "throughput", args.name, results, script=__file__, argv=argv, configfiles=configfiles
    )
    print(f"wrote {args.out / 'throughput.json'} and throughput.png")


if __name__ == "__main__":
    main()
