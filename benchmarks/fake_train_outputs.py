"""Small but contract-conforming train and calibration outputs for the report and tracking tests
and the tracking benchmark (benchmarks/track_logging.py; the tests find it through conftest.py).

By default two classifiers x two protocols (record_split; condition_holdout over two speeds),
measured percentages 0 and 50, two repeats; real fitted sklearn pipelines on a six-feature table.
Every size is a parameter of ``build`` (the tracking benchmark builds a default-run-sized set,
see ``default_run_size``); the models, their ``info.json`` and the CNN's training history are
written by condmon.train itself, the split tables by condmon.hybrid, and ``model_store`` packages
the models as the `track` job does (condmon.model_store).
"""

from __future__ import annotations

import inspect
import json
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
from sklearn.linear_model import LogisticRegression
from sklearn.metrics import accuracy_score, f1_score
from sklearn.neighbors import KNeighborsClassifier
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler

from condmon import classifiers as registry
from condmon.hybrid import WHOLE_RECORD, write_split_table
from condmon.train import METRIC_COLUMNS, write_models

ROOT = Path(__file__).resolve().parents[1]

LABELS = ["healthy", "missing_tooth", "surface_fault"]
SPEEDS = [600.0, 900.0]
PERCENTS = [0, 50]
REPEATS = [0, 1]
CLASSIFIERS = {"knn": {"n_neighbors": 3}, "logreg": {"C": 1.0, "max_iter": 200}}
PROTOCOL_HOLDOUTS = {"record_split": [""], "condition_holdout": ["speed_rpm=600", "speed_rpm=900"]}
FEATURES = [f"fft_A1_x_{f:06.1f}Hz" for f in (10, 20, 30, 40, 50, 60)]
ID_COLUMNS = ["record_id", "segment", "source", "health_state", "speed_rpm", "load", "fs_hz"]
SAMPLES = 256  # per segment of the signal tables' stand-ins


def _features_table(
    rng, source: str, n_per_stratum: int, speeds=SPEEDS, features=FEATURES
) -> pd.DataFrame:
    rows = []
    for label_index, label in enumerate(LABELS):
        for speed in speeds:
            for k in range(n_per_stratum):
                for segment in range(2):
                    values = rng.normal(label_index, 1.1, len(features)).astype(np.float32)
                    rows.append(
                        {
                            "record_id": f"{source}_{label}_{speed:g}_{k}",
                            "segment": segment,
                            "source": source,
                            "health_state": label,
                            "speed_rpm": speed,
                            "load": 1.0,
                            "fs_hz": 5000.0,
                            **dict(zip(features, values)),
                        }
                    )
    return pd.DataFrame(rows)


def _write_features(frame: pd.DataFrame, path: Path, features=FEATURES) -> None:
    table = pa.Table.from_pandas(frame, preserve_index=False)
    table = table.replace_schema_metadata(
        {
            b"condmon.feature_names": json.dumps(features).encode(),
            b"condmon.feature_kind": b"spectrum",
        }
    )
    path.parent.mkdir(parents=True, exist_ok=True)
    pq.write_table(table, path)


def _make_classifier(name: str, params: dict):
    if name == "logreg":
        return make_pipeline(StandardScaler(), LogisticRegression(**params))
    if name.startswith("knn"):
        return make_pipeline(StandardScaler(), KNeighborsClassifier(**params))
    return registry.make_classifier(name, params, seed=0)  # svm, cnn: the project's own


def feature_settings(features=FEATURES) -> dict:
    """What a packaged model of these outputs says it computes (`SignalModel.features`): FFT band
    spectra of the channels its feature names give."""
    channels = sorted({"_".join(name.split("_")[1:3]) for name in features})
    return {"kind": "spectrum", "channels": channels, "spectrum": {}}


def _signals(frame: pd.DataFrame, rng) -> pd.DataFrame:
    """A signal table's stand-in for the rows of a features table: their ids, one channel and a
    noise segment each (the tracking logs the digest of its files, the store reads its shape)."""
    return frame[ID_COLUMNS].assign(
        channel="A1_x",
        signal=[rng.normal(0, 1, SAMPLES).astype(np.float32) for _ in range(len(frame))],
    )


def _split_rows(protocol, percent, repeat, holdout, records, train, test) -> list[dict]:
    """One split's rows of a split table (condmon.hybrid): train, test, the other records unused."""
    role = {**dict.fromkeys(records, "unused"), **dict.fromkeys(test, "test")}
    role.update(dict.fromkeys(train, "train"))
    return [
        {
            "protocol": protocol,
            "measured_percent": percent,
            "repeat": repeat,
            "holdout": holdout,
            "record_id": record,
            "segment": WHOLE_RECORD,
            "role": role[record],
        }
        for record in records
    ]


def _fit(model, x, y, records, features):
    """fit(), with the feature names and record ids for the estimators that take them (CNN)."""
    if "feature_names" in inspect.signature(model.fit).parameters:
        return model.fit(x, y, feature_names=features, groups=records)
    return model.fit(x, y)


def default_run_size(cnn: dict | None = None) -> dict:
    """``build`` arguments for a set the size of config/config.yaml's run: SVM and k-NN on 11
    measured percentages x 3 repeats, the CNN ensemble on 0/50/100 % x 2 repeats, both protocols
    over 3 speeds (4 evaluations per percentage and repeat): 288 fitted models; 4000 spectral
    features (4 channels x 1000 bands). ``cnn``: the CNN's settings (the default run's, unless
    given: ten members, 25 epochs)."""
    speeds = [450.0, 775.0, 1100.0]
    features = [
        f"fft_{ch}_{f:07.1f}Hz"
        for ch in ("A1_x", "A1_y", "A2_x", "A2_y")
        for f in np.arange(1.0, 2000.0, 2.0)
    ]
    cnn = cnn or {"members": 10, "epochs": 25, "conv_channels": [4, 8], "dense_units": [16]}
    return dict(
        classifiers={
            "svm": {"C": 1.2, "gamma": "scale"},
            "knn": {"n_neighbors": 5, "weights": "uniform"},
            "cnn": cnn,
        },
        percents=list(range(0, 101, 10)),
        repeats=[0, 1, 2],
        speeds=speeds,
        features=features,
        selection={"cnn": {"measured_percent": [0, 50, 100], "repeats": 2}},
    )


def build(
    root: Path,
    classifiers: dict | None = None,
    percents=PERCENTS,
    repeats=REPEATS,
    speeds=SPEEDS,
    features=FEATURES,
    selection: dict | None = None,
) -> dict:
    """Write the fake outputs under ``root`` (a results/<run> directory); returns the paths.

    ``classifiers``: name -> params (default CLASSIFIERS); ``selection``: name -> the
    measured_percent / repeats subset it trains on (like classifiers.<name> in the config).
    """
    classifiers = CLASSIFIERS if classifiers is None else classifiers
    rng = np.random.default_rng(7)
    simulated = _features_table(rng, "simulated", 3, speeds, features)
    measured = _features_table(rng, "virtual_bench", 3, speeds, features)
    _write_features(simulated, root / "features/simulated.parquet", features)
    _write_features(measured, root / "features/measured.parquet", features)
    # stand-ins for the signal tables (the tracking logs their digests, not their contents)
    _signals(measured, rng).to_parquet(root / "measured_signals.parquet", index=False)
    simulated_signals = []
    for label in LABELS:
        path = root / "simulated" / label / "batch000.parquet"
        path.parent.mkdir(parents=True, exist_ok=True)
        _signals(simulated[simulated["health_state"] == label], rng).to_parquet(path, index=False)
        simulated_signals.append(path)
    records = measured["record_id"].unique()
    protocol_holdouts = {
        "record_split": [""],
        "condition_holdout": [f"speed_rpm={s:g}" for s in speeds],
    }

    paths = {"metrics": [], "predictions": [], "models": [], "info": [], "splits": {}}
    split_rows = {}  # {(protocol, percent, repeat, holdout): its rows of the split table}
    for clf, params in classifiers.items():
        subset = (selection or {}).get(clf, {})
        clf_percents = subset.get("measured_percent") or percents
        clf_repeats = list(repeats)[: subset.get("repeats") or len(repeats)]
        for protocol, holdouts in protocol_holdouts.items():
            out = root / "train" / clf / protocol
            out.mkdir(parents=True, exist_ok=True)
            metric_rows, prediction_frames, models = [], [], {}
            for percent in clf_percents:
                for repeat in clf_repeats:
                    for h_index, holdout in enumerate(holdouts):
                        split_rng = np.random.default_rng([percent, repeat, h_index])
                        if holdout:
                            held_speed = float(holdout.split("=")[1])
                            test_mask = measured["speed_rpm"] == held_speed
                            candidates = measured.loc[~test_mask, "record_id"].unique()
                        else:
                            test_records = split_rng.choice(
                                records, len(records) // 2, replace=False
                            )
                            test_mask = measured["record_id"].isin(test_records)
                            candidates = measured.loc[~test_mask, "record_id"].unique()
                        n_train = int(round(len(candidates) * percent / 100))
                        train_records = split_rng.choice(candidates, n_train, replace=False)
                        # a split is the same for every classifier (its seed is the split's)
                        split_rows.setdefault(
                            (protocol, percent, repeat, holdout),
                            _split_rows(
                                protocol,
                                percent,
                                repeat,
                                holdout,
                                records,
                                train_records,
                                measured.loc[test_mask, "record_id"].unique(),
                            ),
                        )
                        train = pd.concat(
                            [simulated, measured[measured["record_id"].isin(train_records)]]
                        )
                        test = measured[test_mask]
                        # bare float32 arrays, as the train stage fits them
                        model = _fit(
                            _make_classifier(clf, params),
                            train[features].to_numpy(np.float32),
                            train["health_state"].to_numpy(),
                            train["record_id"].to_numpy(),
                            features,
                        )
                        models[(percent, repeat, holdout)] = model
                        x_test = test[features].to_numpy(np.float32)
                        if hasattr(model, "predict_with_uncertainty"):  # the CNN ensemble
                            predicted, uncertainty = model.predict_with_uncertainty(x_test)
                        else:
                            predicted, uncertainty = model.predict(x_test), np.nan
                        prediction_frames.append(
                            pd.DataFrame(
                                {
                                    "protocol": protocol,
                                    "measured_percent": np.int32(percent),
                                    "repeat": np.int32(repeat),
                                    "holdout": holdout,
                                    "record_id": test["record_id"].to_numpy(),
                                    "segment": test["segment"].to_numpy(np.int32),
                                    "speed_rpm": test["speed_rpm"].to_numpy(),
                                    "true_label": test["health_state"].to_numpy(),
                                    "predicted_label": predicted,
                                    "uncertainty": uncertainty,
                                }
                            )
                        )
                        common = {
                            "classifier": clf,
                            "protocol": protocol,
                            "measured_percent": percent,
                            "repeat": repeat,
                            "holdout": holdout,
                            "n_train_simulated": len(simulated),
                            "n_train_measured": len(train) - len(simulated),
                            "fit_seconds": 0.01,
                        }
                        truth = test["health_state"].to_numpy()
                        metric_rows.append(
                            {
                                **common,
                                "speed_rpm": None,
                                "accuracy": accuracy_score(truth, predicted),
                                "macro_f1": f1_score(truth, predicted, average="macro"),
                                "n_test": len(test),
                            }
                        )
                        for speed in sorted(test["speed_rpm"].unique()):
                            at = (test["speed_rpm"] == speed).to_numpy()
                            metric_rows.append(
                                {
                                    **common,
                                    "speed_rpm": speed,
                                    "accuracy": accuracy_score(truth[at], predicted[at]),
                                    "macro_f1": f1_score(truth[at], predicted[at], average="macro"),
                                    "n_test": int(at.sum()),
                                }
                            )
            metrics = pd.DataFrame(metric_rows)[METRIC_COLUMNS]
            metrics.to_csv(out / "metrics.csv", index=False)
            pd.concat(prediction_frames).to_parquet(out / "predictions.parquet", index=False)
            # named and listed as the train stage does (zero-padded percent, holdout index)
            entries = write_models(models, out / "models", features)
            complete = (
                registry.classifier_params(clf, params) if clf in registry.CLASSIFIERS else params
            )
            (out / "info.json").write_text(
                json.dumps(
                    {  # the keys of condmon.train.train_info used
                        "classifier": clf,
                        "classifier_params": complete,
                        "protocol": protocol,
                        "labels": LABELS,
                        "models": entries,
                        "selection": subset,
                    }
                )
            )
            paths["metrics"].append(out / "metrics.csv")
            paths["predictions"].append(out / "predictions.parquet")
            paths["models"].append(out / "models")
            paths["info"].append(out / "info.json")

    for protocol in protocol_holdouts:
        rows = [row for key, rows in split_rows.items() if key[0] == protocol for row in rows]
        paths["splits"][protocol] = root / "hybrid" / f"{protocol}.parquet"
        paths["splits"][protocol].parent.mkdir(parents=True, exist_ok=True)
        write_split_table(pd.DataFrame(rows), paths["splits"][protocol])

    calibration = root / "calibration"
    calibration.mkdir(parents=True, exist_ok=True)
    (calibration / "params.json").write_text(
        json.dumps(
            {
                "model_variant": "hertz",
                "parameters": {"stiffness": 1.2e8, "damping": 0.02},
                "cost": 0.031,
                "evaluations": 40,
            }
        )
    )
    freqs = np.linspace(5, 2500, 200)
    spectra = []
    for speed in SPEEDS:
        for channel in ("A1_x", "A1_y"):
            base = 1.0 / (1 + freqs / 200) + 0.5 * np.exp(-(((freqs - speed / 60 * 23) / 15) ** 2))
            spectra.append(
                pd.DataFrame(
                    {
                        "speed_rpm": speed,
                        "channel": channel,
                        "freq_hz": freqs,
                        "measured": base * rng.uniform(0.8, 1.2, len(freqs)),
                        "calibrated": base,
                    }
                )
            )
    pd.concat(spectra).to_parquet(calibration / "spectra.parquet", index=False)
    history = pd.DataFrame(
        {
            "generation": np.arange(40) // 8,
            "evaluation": np.arange(40),
            "model_variant": np.where(np.arange(40) % 2, "hertz", "linear"),
            "cost": np.abs(rng.normal(1, 0.5, 40)) / (1 + np.arange(40) / 4),
            "stiffness": rng.uniform(1e7, 1e9, 40),
        }
    )
    history.loc[5, "cost"] = np.inf  # a failed simulation
    history.to_parquet(calibration / "history.parquet", index=False)
    paths.update(
        calibration_params=calibration / "params.json",
        calibration_spectra=calibration / "spectra.parquet",
        calibration_history=calibration / "history.parquet",
        features_measured=root / "features/measured.parquet",
        features_simulated=root / "features/simulated.parquet",
        measured_signals=root / "measured_signals.parquet",
        simulated_signals=simulated_signals,
        feature_names=list(features),
    )
    return paths


def model_store(paths: dict, directory: Path, config_hash: str = "h") -> Path:
    """The outputs of ``build`` packaged into ``directory`` as the `track` job packages a run's
    models (condmon.model_store.build_store; no system reads their records); returns it."""
    from condmon.model_store import build_store

    build_store(
        directory,
        train_dirs(paths),
        paths["splits"],
        paths["measured_signals"],
        paths["features_simulated"],
        paths["features_measured"],
        feature_settings(paths["feature_names"]),
        "healthy",
        None,
        config_hash,
    )
    return Path(directory)


def system_specs() -> tuple[dict, dict]:
    """The `features` and `measured` job specs of the default config's system (the gear rig), as
    the `track` rule passes them."""
    from condmon.config import load_config
    from condmon.systems import get_system

    system = get_system(load_config([], {"run_name": "demo"}, project=ROOT))
    return system.job_spec("features"), system.job_spec("measured")


TRACK_RUNNER = """
import json, sys, types
class Section(dict):
    __getattr__ = dict.__getitem__
args = json.loads(sys.argv[1])
snakemake = types.SimpleNamespace(params=Section(args["params"]), input=Section(args["input"]),
                                  output=Section(args["output"]), log=[args["log"]], rule="track")
exec(compile(open(args["script"]).read(), args["script"], "exec"),
     {"snakemake": snakemake, "__name__": "__main__"})
"""


def track_job(
    paths: dict,
    tracking_uri: str,
    workdir: Path,
    config_hash: str = "h",
    run_name: str = "demo",
    config: dict | None = None,
    log_models="all",
) -> list[str]:
    """The command line that runs workflow/scripts/track.py as the `track` rule does (a fresh
    Python, `snakemake` injected) on the outputs of ``build``: it packages the models into
    ``workdir``/models (the default config's system as the features' and records' reader) and
    logs them; log and mlflow_run.json go to ``workdir``."""
    import sys

    features_system, measured_system = system_specs()
    args = dict(
        script=str(ROOT / "workflow" / "scripts" / "track.py"),
        log=str(workdir / "track.log"),
        params=dict(
            tracking_uri=tracking_uri,
            run_name=run_name,
            config_hash=config_hash,
            data_source="virtual_bench",
            config=config or {"run_name": run_name},
            log_models=log_models,
            healthy_state="healthy",
            protocols=list(paths["splits"]),
            features=feature_settings(paths["feature_names"]),
            features_system=features_system,
            measured_system=measured_system,
            condition="speed_rpm",
        ),
        input=dict(
            info=list(map(str, paths["info"])),
            features_measured=str(paths["features_measured"]),
            features_simulated=str(paths["features_simulated"]),
            measured_signals=str(paths["measured_signals"]),
            simulated_signals=list(map(str, paths["simulated_signals"])),
            splits=list(map(str, paths["splits"].values())),
        ),
        output=dict(run_info=str(workdir / "mlflow_run.json"), models=str(workdir / "models")),
    )
    return [sys.executable, "-c", TRACK_RUNNER, json.dumps(args)]


def datasets(paths: dict) -> dict:
    """``log_pipeline_run``'s datasets argument for the outputs of ``build``."""
    return {
        "measured_signals": [paths["measured_signals"]],
        "simulated_signals": paths["simulated_signals"],
        "measured_features": [paths["features_measured"]],
        "simulated_features": [paths["features_simulated"]],
    }


def train_dirs(paths: dict) -> list[Path]:
    return [Path(p).parent for p in paths["info"]]


def report_inputs(paths: dict, out: Path, **parts):
    """`condmon.report.inputs.ReportInputs` of the fake train outputs (`build`): run "demo" on the
    virtual bench, healthy first, confusion matrices at 0 %, accuracy.csv, summary.json, plots/
    and the evaluation tables into `out`. `parts`: {group: {field: value}} replacing fields of a
    group, e.g. evaluation={"measured_features": ...}, train={"measured_only": [...]}; `outputs`
    takes tables by name beside summary and plots, e.g. outputs={"headline": out / "headline.csv"}."""
    from dataclasses import replace

    from condmon.report.inputs import (
        CalibrationOutputs,
        EvaluationInputs,
        ReportInputs,
        ReportOutputs,
        RunIdentity,
        TrainOutputs,
    )

    outputs = dict(parts.pop("outputs", {}))
    files = {key: outputs.pop(key) for key in ("summary", "plots") if key in outputs}
    inputs = ReportInputs(
        run=RunIdentity(run_name="demo", data_source="virtual_bench", healthy_state="healthy"),
        train=TrainOutputs(metrics=paths["metrics"], predictions=paths["predictions"]),
        calibration=CalibrationOutputs(
            params=paths["calibration_params"],
            spectra=paths["calibration_spectra"],
            history=paths["calibration_history"],
        ),
        evaluation=EvaluationInputs(confusion_percent=[0]),
        outputs=ReportOutputs(
            summary=files.get("summary", out / "summary.json"),
            plots=files.get("plots", out / "plots"),
            tables={
                "accuracy": out / "accuracy.csv",
                "evaluation": out / "evaluation.csv",
                "evaluation_summary": out / "evaluation_summary.csv",
                **outputs,
            },
        ),
    )
    return replace(
        inputs,
        **{group: replace(getattr(inputs, group), **fields) for group, fields in parts.items()},
    )


def write_report(paths: dict, out: Path, **parts) -> dict:
    """`condmon.report.write.write_report` on `report_inputs(paths, out, **parts)`."""
    from condmon.report.write import write_report

    return write_report(report_inputs(paths, out, **parts))


def write_sections(paths: dict, out: Path, sections, **parts) -> dict:
    """Only the report `sections` (registry names, run in the registry's order) on
    `report_inputs(paths, out, **parts)`: the tables the outputs name written, summary.json, the
    sections' plots in out / plots. A test of one claim draws that section's plots, not the ~20
    of the whole report (most of a report's time). Returns the summary dict."""
    import json

    from condmon.report import registry
    from condmon.report.context import Report
    from condmon.report.write import run_section

    inputs = report_inputs(paths, out, **parts)
    chosen = [section for section in registry.SECTIONS if section.name in set(sections)]
    unknown = sorted(set(sections) - {section.name for section in chosen})
    assert not unknown, f"no report sections {unknown}"
    inputs.outputs.plots.mkdir(parents=True, exist_ok=True)
    report = Report(inputs, inputs.outputs.plots)
    for section in chosen:
        if section.applies(inputs):
            for name, frame in run_section(section, report).items():
                if name in inputs.outputs.tables:
                    frame.to_csv(inputs.outputs.tables[name], index=False)
    report.summary.setdefault("plots", report.plots)
    Path(inputs.outputs.summary).write_text(json.dumps(report.summary, indent=2) + "\n")
    return report.summary
