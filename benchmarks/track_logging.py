"""Time the `track` job (packaging the models, MLflow logging) on synthetic train outputs the size
of the default run.

The set (benchmarks/fake_train_outputs.default_run_size: SVM and k-NN on 11 measured percentages x 3
repeats, the CNN ensemble on 0/50/100 % x 2 repeats, both protocols over 3 speeds: 288 nested
runs, 4000 spectral features) is built once into ``--work`` (fitting its 24 CNN ensembles takes a
few minutes) and reused. Each repeat runs workflow/scripts/track.py as the rule runs it, in a fresh
Python (imports included): it packages every fit into a model store of its own and logs them, as
pyfunc models, into a fresh SQLite store, with config/config.yaml's
``tracking.log_models`` unless --log-models gives another (JSON). Writes ``--out`` (wall and CPU
seconds per repeat and their median, what was logged, the machine and its load).

    python3 benchmarks/track_logging.py [--repeats 3] [--work results/benchmark/track_set]
        [--out results/benchmark/track.json] [--log-models '"none"']
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "benchmarks"), str(ROOT / "workflow")]  # fake_train_outputs, condmon
from condmon.records import save_record  # noqa: E402

TARGET_S = 15.0  # issue #15: the default run's track job


def default_log_models():
    import yaml
    from condmon.config import load_schema, validate_config

    config = yaml.safe_load((ROOT / "config" / "config.yaml").read_text())
    return validate_config(config, load_schema(ROOT / "config" / "schema.yaml"))["tracking"][
        "log_models"
    ]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--work", type=Path, default=ROOT / "results/benchmark/track_set")
    parser.add_argument("--out", type=Path, default=ROOT / "results/benchmark/track.json")
    parser.add_argument(
        "--log-models",
        type=json.loads,
        default=None,
        help="tracking.log_models as JSON, e.g. '\"none\"' or '{\"repeat\": [0]}'",
    )
    args = parser.parse_args(argv)

    import fake_train_outputs as fake

    log_models = default_log_models() if args.log_models is None else args.log_models
    paths_file = args.work / "paths.json"
    # a set built before the outputs held split tables cannot be packaged: built again
    if not paths_file.exists() or "splits" not in json.loads(paths_file.read_text()):
        print(
            f"building the synthetic train outputs in {args.work} (minutes, once) ...", flush=True
        )
        paths = fake.build(args.work / "default", **fake.default_run_size())
        paths_file.write_text(json.dumps(paths, default=str))
    paths = json.loads(paths_file.read_text())

    runs = []
    for repeat in range(args.repeats):
        store = args.work / f"store{repeat}"
        shutil.rmtree(store, ignore_errors=True)
        store.mkdir(parents=True)
        command = fake.track_job(
            paths,
            f"sqlite:///{store}/mlflow.db",
            store,
            run_name="default",
            config={"run_name": "default", "tracking": {"log_models": log_models}},
            log_models=log_models,
        )
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        started = time.perf_counter()
        result = subprocess.run(command, cwd=store, capture_output=True, text=True)
        wall = time.perf_counter() - started
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        if result.returncode != 0:
            print((store / "track.log").read_text()[-3000:], result.stderr[-3000:])
            return 1
        info = json.loads((store / "mlflow_run.json").read_text())
        runs.append(
            {
                "wall_s": round(wall, 2),
                "cpu_s": round(
                    after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime, 2
                ),
                "logging_s": info["seconds"],
                "n_nested_runs": info["n_nested_runs"],
                "n_models_logged": info["n_models_logged"],
            }
        )
        print(runs[-1], flush=True)
    wall = statistics.median(r["wall_s"] for r in runs)
    result = {
        "what": "the track job (fresh Python, imports included, new SQLite store) on a "
        "default-run-sized synthetic set",
        "log_models": log_models,
        "target_s": TARGET_S,
        "wall_s_median": wall,
        "cpu_s_median": statistics.median(r["cpu_s"] for r in runs),
        "meets_target": wall <= TARGET_S,
        "runs": runs,
        "machine": {
            "cpus": os.cpu_count(),
            "platform": platform.platform(),
            "python": platform.python_version(),
            "load_average_1_5_15": [round(x, 2) for x in os.getloadavg()],
        },
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=1) + "\n")
    print(json.dumps({k: v for k, v in result.items() if k != "runs"}))
    save_record(
        "track_logging",
        "default",
        {k: v for k, v in result.items() if k != "machine"},
        script=__file__,
        argv=argv,
        configfiles=["config/config.yaml"],
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
