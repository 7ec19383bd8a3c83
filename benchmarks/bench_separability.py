"""Can an engineer see the bench's faults with the bench's own data? (issue 26)

A measured-only SVM (standardised features, C 1.2, RBF), leave-one-record-out over the measured
(virtual bench) records of a finished run: per speed and over all speeds, balanced accuracy per
segment. No simulation is involved: it says whether the bench's health states differ at all in
the run's features, the ceiling a simulation-trained classifier can approach.

    python3 benchmarks/bench_separability.py --results results/default [--out FILE]
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from sklearn.metrics import balanced_accuracy_score
from sklearn.model_selection import LeaveOneGroupOut, cross_val_predict
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler
from sklearn.svm import SVC

from condmon.features import read_feature_table


def leave_one_record_out(frame, names) -> float:
    model = make_pipeline(StandardScaler(), SVC(C=1.2, gamma="scale"))
    predicted = cross_val_predict(model, frame[names].to_numpy(float), frame["health_state"].to_numpy(),
                                  groups=frame["record_id"].to_numpy(), cv=LeaveOneGroupOut())
    return float(balanced_accuracy_score(frame["health_state"], predicted))


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results", default="results/default")
    parser.add_argument("--out", default=None)
    args = parser.parse_args(argv)
    frame, names = read_feature_table(Path(args.results) / "features" / "measured.parquet")
    out = {"per_speed": {f"{speed:g}": leave_one_record_out(frame[frame["speed_rpm"] == speed], names)
                         for speed in sorted(frame["speed_rpm"].unique())},
           "all_speeds": leave_one_record_out(frame, names), "records": int(frame["record_id"].nunique()),
           "features": len(names)}
    text = json.dumps(out, indent=2)
    print(text)
    if args.out:
        Path(args.out).write_text(text + "\n")
    return out


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
