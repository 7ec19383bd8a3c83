"""Does the measured data itself carry each class? Classifiers trained on the measured DESIGN
records alone, each record (or each specimen) held out in turn.

    python benchmarks/measured_holdout.py results/cwru_full

A figure a simulation-trained method misses is only called impossible if the measured records
themselves cannot find it either. Two hold-outs, on the run's measured features
(features/measured.parquet) of its design records (summary.json `design_records`), every
candidate feature (features.statistical.names), scaling + the run's SVM and KNN settings
(train/<classifier>/unseen_fault/info.json):
- leave one record out: the held-out record's other loads train, so the same specimen is seen
  (data README: one specimen per fault size, recorded at four loads): an upper bound;
- leave one specimen out: no record of the held-out specimen trains, as for an unseen fault.
A class with a single specimen (the healthy bearing) cannot be held out and keep a training
example, so its figure is 0 there. It prints per class and per specimen the share of segments
called right. It never reads an evaluation record.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pandas as pd
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import StandardScaler

from condmon.classifiers import make_classifier
from condmon.records import run_configfiles, save_record


def held_out_calls(
    frame: pd.DataFrame, names: list[str], unit: str, classifier: str, params: dict, seed: int
) -> pd.Series:
    """Each segment's call by a classifier trained on every row of another `unit`."""
    calls = pd.Series(index=frame.index, dtype=object)
    for _, tested in frame.groupby(unit):
        train = frame[frame[unit] != tested[unit].iloc[0]]
        model = Pipeline(
            [("scale", StandardScaler()), ("model", make_classifier(classifier, params, seed))]
        )
        model.fit(train[names], train["health_state"])
        calls[tested.index] = model.predict(tested[names])
    return calls


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("run", type=Path, help="the run's results folder, e.g. results/cwru_full")
    args = parser.parse_args(argv)
    run = args.run
    design = set(
        json.loads((run / "report" / "summary.json").read_text())["design_records"]["records"]
    )
    records = pd.read_csv(run / "measured" / "records.csv", dtype={"record_id": str}).set_index(
        "record_id"
    )
    measured = pd.read_parquet(run / "features" / "measured.parquet").astype({"record_id": str})
    frame = measured[measured["record_id"].isin(design)].reset_index(drop=True)
    frame["specimen"] = frame["record_id"].map(records["specimen"])
    names = [c for c in frame.columns if c.startswith("DE_")]
    print(
        f"{run}: measured design records only ({frame['record_id'].nunique()} records, "
        f"{len(frame)} segments), features {', '.join(names)}\n"
    )
    figures = {}
    for classifier in ("svm", "knn"):
        info = json.loads((run / "train" / classifier / "unseen_fault" / "info.json").read_text())
        for unit, label in (
            ("record_id", "leave one record out"),
            ("specimen", "leave one specimen out"),
        ):
            right = (
                held_out_calls(
                    frame, names, unit, classifier, info["classifier_params"], int(info["seed"])
                )
                == frame["health_state"]
            )
            per_class = right.groupby(frame["health_state"]).mean().round(3)
            per_specimen = right.groupby(frame["specimen"]).mean().round(3)
            print(f"{classifier}, {label}: per class {per_class.to_dict()}")
            print(f"    per specimen {per_specimen.to_dict()}\n")
            figures.setdefault(classifier, {})[unit] = {
                "per_class": per_class.to_dict(),
                "per_specimen": per_specimen.to_dict(),
            }
    save_record(
        "measured_holdout",
        run.name,
        figures,
        script=__file__,
        argv=argv,
        configfiles=run_configfiles(run),
    )


if __name__ == "__main__":
    main()
