"""The envelope analysis chosen on the design records only (issue 71): the fixed band against the
kurtogram's band, each with and without cepstral prewhitening, lines read at the fundamental or
with harmonics and sidebands, judged by the training-free envelope rule on the measured records of
the config's design specimens.

    python3 benchmarks/envelope_choice.py [--configfile config/cwru.yaml] [--harmonics 1 2]

For every candidate (analysis x harmonics) the statistical features of the design records
(`condmon.features.statistical_feature_table`, the config's `features.statistical` with that
`envelope` section) and the envelope rule on them (`BearingSystem.physics_baselines`): its
threshold from the healthy calibration segments (the first `calibration.reserve.calibration_segments`
of the healthy record), its calls on every other design segment but the guard segments after them:
balanced accuracy, each class's recall, the false-alarm rate, and which fault records show their
line (`EnvelopeRule.fault_lines`). Then the same rule consulting every analysis at once
(`bearing.envelope_rule.line_analyses`). No record of an evaluation specimen is read: the choice
may be made on these figures. The classifiers' figures over simulation seeds come from
`benchmarks/bench_seeds.py --system bearing` with config/cwru-envelopes/*.yaml.
Its record: benchmarks/records/envelope_choice-<run_name>.json (condmon.records).
"""

from __future__ import annotations

import argparse
import copy
import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

from condmon.config import apply_base
from condmon.envelope import ANALYSES
from condmon.features import statistical_feature_table
from condmon.records import save_record
from condmon.systems.bearing import BearingSystem
from condmon.systems.bearing.cwru import cwru_rows, specimen_name
from condmon.systems.bearing.model import bearing_defaults

ROOT = Path(__file__).resolve().parents[1]


def load_config(configfiles) -> dict:
    """The config files merged as Snakemake merges them (each file's `base` first)."""
    config = {}
    for path in configfiles:
        layer = apply_base(yaml.safe_load((ROOT / path).read_text()) or {}, ROOT)
        config = _merge(config, layer)
    return config


def _merge(into: dict, layer: dict) -> dict:
    for key, value in layer.items():
        into[key] = _merge(dict(into.get(key) or {}), value) if isinstance(value, dict) else value
    return into


def design_signals(config: dict) -> pd.DataFrame:
    """The signal rows of the design specimens' records (the config's `cwru.design_specimens`)."""
    bearing = config.get("bearing", {})
    ingest = cwru_rows(
        ROOT / config["measured_dir"],
        task=config["cwru"]["task"],
        channels=tuple(bearing.get("channels", ["DE"])),
        fs_hz=float(bearing.get("fs_hz", 12000)),
        segment_length=int(bearing.get("segment_length", 4096)),
    )
    design = {
        specimen_name(s["fault"], s.get("diameter_in", 0.0), s.get("position"))
        for s in config["cwru"]["design_specimens"]
    }
    kept = set(ingest.records.loc[ingest.records["specimen"].isin(design), "record_id"].astype(str))
    if not kept:
        raise ValueError(
            f"no record of a design specimen {sorted(design)} in {config['measured_dir']}"
        )
    frame = pd.DataFrame(ingest.rows)
    return frame[frame["record_id"].astype(str).isin(kept)].reset_index(drop=True)


def roles(features: pd.DataFrame, healthy_state: str, reserve: dict) -> pd.Series:
    """calibration (the first healthy record's first segments), guard (the segments after them)
    or test, per row."""
    healthy = sorted(
        features.loc[features["health_state"] == healthy_state, "record_id"].astype(str).unique()
    )
    if not healthy:
        raise ValueError(f"no {healthy_state!r} design record to set the rule's threshold on")
    first = features["record_id"].astype(str) == healthy[0]
    calibration = first & (features["segment"] < reserve["calibration_segments"])
    guard = (
        first
        & ~calibration
        & (features["segment"] < reserve["calibration_segments"] + reserve["guard_segments"])
    )
    return pd.Series(
        np.where(calibration, "calibration", np.where(guard, "guard", "test")), index=features.index
    )


def judge(rule, features: pd.DataFrame, role: pd.Series, healthy_state: str) -> dict:
    """The rule's figures on the test segments."""
    rule.fit(features[role == "calibration"])
    test = features[role == "test"]
    predicted = rule.predict(test)
    truth = test["health_state"].astype(str).to_numpy()
    recall = {
        label: float(np.mean(predicted[truth == label] == label)) for label in sorted(set(truth))
    }
    lines = rule.fault_lines(features)
    return {
        "balanced_accuracy": float(np.mean(list(recall.values()))),
        "recall": recall,
        "false_alarm_rate": float(np.mean(predicted[truth == healthy_state] != healthy_state)),
        "records_showing_line": {
            label: sorted(r["record_id"] for r in lines if r["label"] == label and r["shows_line"])
            for label in sorted({r["label"] for r in lines})
        },
        "records_without_line": sorted(r["record_id"] for r in lines if not r["shows_line"]),
        "test_segments": int(len(test)),
    }


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--configfile", nargs="+", default=["config/cwru.yaml"])
    parser.add_argument("--harmonics", nargs="+", type=int, default=[1, 2])
    args = parser.parse_args(argv)
    config = load_config(args.configfile)
    signals = design_signals(config)
    statistical = dict(config["features"]["statistical"])
    healthy_state = (config.get("bearing") or {}).get("healthy_state", "normal")
    reserve = config["calibration"]["reserve"]
    bearing = copy.deepcopy(bearing_defaults())
    bearing.update(copy.deepcopy(config.get("bearing") or {}))
    candidates = []
    for harmonics in args.harmonics:
        for analysis in ANALYSES + ("every analysis",):
            own = analysis if analysis in ANALYSES else "fixed"
            envelope = dict(
                statistical.get("envelope") or {},
                harmonics=harmonics,
                band=own.replace("prewhitened_", ""),
                prewhiten=own.startswith("prewhitened_"),
            )
            params = dict(statistical, envelope=envelope)
            system = BearingSystem(
                {
                    "bearing": dict(
                        bearing,
                        envelope_rule=dict(
                            bearing.get("envelope_rule") or {},
                            line_analyses=list(ANALYSES) if analysis not in ANALYSES else [],
                        ),
                    ),
                    "cwru": {"task": config["cwru"]["task"]},
                    "features": {"statistical": params},
                }
            )
            params["line_sidebands"] = system.defect_sidebands()
            features = statistical_feature_table(
                signals, list(config["features"]["channels"]), params, system.defect_orders()
            )
            names = [
                c for c in features.columns if c.split("_", 1)[0] in config["features"]["channels"]
            ]
            rule = system.physics_baselines(names, signals if analysis not in ANALYSES else None)[
                "envelope_rule"
            ]
            figures = judge(rule, features, roles(features, healthy_state, reserve), healthy_state)
            candidates.append({"analysis": analysis, "harmonics": harmonics, **figures})
            print(
                f"{analysis:22s} harmonics {harmonics}: rule balanced {figures['balanced_accuracy']:.3f}, "
                f"false alarms {figures['false_alarm_rate']:.3f}, recall "
                f"{json.dumps({k: round(v, 2) for k, v in figures['recall'].items()})}, no line: "
                f"{figures['records_without_line']}",
                flush=True,
            )
    result = {
        "configfiles": args.configfile,
        "records": sorted(signals["record_id"].astype(str).unique()),
        "calibration": dict(reserve),
        "candidates": candidates,
    }
    name = config.get("run_name", "cwru")
    save_record(
        "envelope_choice", name, result, script=__file__, argv=argv, configfiles=args.configfile
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
