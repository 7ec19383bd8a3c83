"""Candidate joins of a classifier and the physics rule, scored on the DESIGN records only.

    python benchmarks/join_candidates.py results/cwru_full [--protocol unseen_fault]

How `joined.classifiers`' method (condmon.joined: the classifier inside its fit's training range,
the rule outside it) was chosen against other ways of joining the classifier and the physics
evidence, at 0 % measured (trained on simulation alone), per segment, on the design records of a
finished run (summary.json `design_records`; loads 0-1 and 2-3 apart, the CWRU loads of
measured/records.csv). It never prints an evaluation record's figure: the choice is made on the
design records, so the evaluation specimens stay a test.

Candidates (each from the run's own predictions and features, repeat 0):
- joined: the run's joined_svm (the SVM inside its fit's training range, the rule outside);
- class_range: also the rule where the segment leaves the simulated range of the class the SVM
  names (per-class support, on the fit's features);
- vote: the majority of SVM, KNN and rule (the joined call where all three differ);
- lines_svm / lines_knn: a classifier on the rule's three line ratios (BPFO, BPFI, 2 x BSF) as
  its only inputs, trained on the run's simulated features as the pipeline trains (scaling + SVM
  C 1.2 gamma scale / KNN 5);
- all_svm: the SVM on every candidate feature, no selection;
- line_over_k: the rule's call where the line it names stands at least k times above its healthy
  threshold (the envelope rule's `threshold`, from the calibration segments), the joined call
  elsewhere: trusting a clear defect line over the classifier (k 1, 2, 3, 5).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pandas as pd
from sklearn.neighbors import KNeighborsClassifier
from sklearn.pipeline import Pipeline
from sklearn.preprocessing import StandardScaler
from sklearn.svm import SVC

from condmon.records import run_configfiles, save_record

KEYS = ["measured_percent", "repeat", "holdout", "record_id", "segment"]


def calls(run: Path, protocol: str) -> pd.DataFrame:
    """Per tested segment at 0 %, repeat 0: the true label and each method's call."""
    parts = {
        "svm": f"train/svm/{protocol}",
        "knn": f"train/knn/{protocol}",
        "rule": f"baselines/{protocol}",
        "joined": f"joined/joined_svm/{protocol}",
    }
    frame = None
    for name, folder in parts.items():
        p = pd.read_parquet(run / folder / "predictions.parquet")
        p = p[(p["measured_percent"] == 0) & (p["repeat"] == 0)]
        p = p[KEYS + (["true_label"] if frame is None else []) + ["predicted_label"]].rename(
            columns={"predicted_label": name}
        )
        frame = p if frame is None else frame.merge(p, on=KEYS, how="inner")
    return frame


def balanced(frame: pd.DataFrame, column: str) -> tuple[float, dict]:
    recalls = (frame[column] == frame["true_label"]).groupby(frame["true_label"]).mean()
    return float(recalls.mean()), {k: round(float(v), 2) for k, v in recalls.items()}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("run", type=Path)
    parser.add_argument("--protocol", default="unseen_fault")
    args = parser.parse_args(argv)
    run = args.run
    summary = json.loads((run / "report" / "summary.json").read_text())
    design = set(summary["design_records"]["records"])
    records = pd.read_csv(run / "measured" / "records.csv", dtype={"record_id": str})
    load = records.set_index("record_id")["load_hp"]
    measured = pd.read_parquet(run / "features" / "measured.parquet").astype({"record_id": str})
    simulated = pd.read_parquet(run / "features" / "simulated.parquet")
    names = [
        c for c in simulated.columns if c.startswith(tuple(f"{ch}_" for ch in ("DE", "FE", "BA")))
    ]
    lines = [
        c for c in names if c.endswith(("env_ratio_bpfo", "env_ratio_bpfi", "env_ratio_bsf_x2"))
    ]
    fits = json.loads((run / "train" / "svm" / args.protocol / "info.json").read_text())["models"]
    own = next(m["selected_features"] for m in fits if m["measured_percent"] == 0) or names

    frame = calls(run, args.protocol)
    frame = frame[frame["record_id"].isin(design)].merge(
        measured[["record_id", "segment"] + names], on=["record_id", "segment"], how="left"
    )
    svm, knn, rule, joined = (frame[c].to_numpy(object) for c in ("svm", "knn", "rule", "joined"))
    out_class = np.zeros(len(frame), bool)
    for state, rows in simulated.groupby("health_state"):
        low, high = rows[own].min(), rows[own].max()
        out_class |= (svm == state) & (frame[own].lt(low) | frame[own].gt(high)).any(
            axis=1
        ).to_numpy()
    threshold = json.loads((run / "baselines" / args.protocol / "info.json").read_text())[
        "baselines"
    ]["envelope_rule"]["threshold"]
    strongest = (
        np.exp(frame[lines].to_numpy(float)).max(axis=1)
        if all("_log_" in c for c in lines)
        else frame[lines].to_numpy(float).max(axis=1)
    )
    candidates = {
        "joined (the run's)": joined,
        "class_range": np.where(out_class, rule, joined),
        "vote": np.where((knn == rule) & (knn != joined), knn, joined),
    }
    for label, columns, make in (
        ("lines_svm", lines, lambda: SVC(C=1.2, gamma="scale")),
        ("lines_knn", lines, lambda: KNeighborsClassifier(5)),
        ("all_svm", names, lambda: SVC(C=1.2, gamma="scale")),
    ):
        model = Pipeline([("scale", StandardScaler()), ("model", make())])
        model.fit(simulated[columns], simulated["health_state"])
        candidates[label] = model.predict(frame[columns])
    for k in (1, 2, 3, 5):
        candidates[f"line_over_{k}"] = np.where(
            strongest > k * threshold, rule, joined
        )  # k >= 1: a fault call
    candidates.update({"svm": svm, "knn": knn, "rule": rule})
    groups = {
        "design, loads 0-1": frame["record_id"].map(load).le(1).to_numpy(),
        "design, loads 2-3": frame["record_id"].map(load).gt(1).to_numpy(),
    }
    print(
        f"{run}: {args.protocol}, 0 % measured, design records only, per segment; the fit's "
        f"features: {', '.join(own)}\n"
    )
    figures = {}
    for name, called in candidates.items():
        scored = frame.assign(call=called)
        figures[name] = {
            group: dict(zip(("balanced", "recall"), balanced(scored[mask], "call")))
            for group, mask in groups.items()
            if mask.any()
        }
        cells = [f"{group} {f['balanced']:.3f} {f['recall']}" for group, f in figures[name].items()]
        print(f"{name:20s}", " | ".join(cells))
    save_record(
        "join_candidates",
        f"{run.name}-{args.protocol}",
        {"protocol": args.protocol, "candidates": figures},
        script=__file__,
        argv=argv,
        configfiles=run_configfiles(run),
    )


if __name__ == "__main__":
    main()
