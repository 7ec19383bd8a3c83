"""Can an engineer see the bench's faults with the bench's own data? (issue 26)

A measured-only SVM (standardised features, C 1.2, RBF, balanced class weights), every record
held out once, over the measured (virtual bench) records of a finished run less its calibration
set (the records the calibration saw and the features were taken against): per speed and over all
speeds, balanced accuracy per segment with its permutation chance level (condmon.separability;
every run's report gives it too, summary.json `measured_separability`). No simulation is
involved: it says whether the bench's health states differ at all in the run's features, the
ceiling a simulation-trained classifier can approach.

    python3 benchmarks/bench_separability.py --results results/default [--out FILE]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import yaml

from condmon.features import read_feature_table
from condmon.hybrid import calibration_frame
from condmon.records import run_configfiles, save_record
from condmon.separability import measured_separability
from condmon.systems import get_system


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results", default="results/default")
    parser.add_argument("--out", default=None)
    args = parser.parse_args(argv)
    results = Path(args.results)
    # the run's own config (report/config.yaml): its condition, calibration set and states
    config = yaml.safe_load((results / "report" / "config.yaml").read_text())
    healthy, condition = get_system(config).healthy_state, config["hybrid"]["condition"]
    states = [healthy, *config["calibration"]["per_state"]["states"]]
    frame, names = read_feature_table(results / "features" / "measured.parquet")
    calibration = calibration_frame(
        frame, healthy, condition, dict(config["calibration"]["reserve"]), states
    )
    out = measured_separability(frame.drop(index=calibration.index), names, condition)
    out["calibration_records_left_out"] = sorted(set(calibration["record_id"].astype(str)))
    text = json.dumps(out, indent=2)
    print(text)
    if args.out:
        Path(args.out).write_text(text + "\n")
    save_record(
        "bench_separability",
        Path(args.results).name,
        out,
        script=__file__,
        argv=argv,
        configfiles=run_configfiles(Path(args.results)),
    )
    return out


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
