"""The report's inputs read and checked: the train stage's optional tables, the calibrations, the
physics baselines' fault lines, each record's operating condition, design and unmodelled records.
Every problem is a ReportInputError naming the file."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd

from condmon.hybrid import SIMULATED_VALIDATION
from condmon.report.inputs import CalibrationOutputs
from condmon.train_tables import ReportInputError, load_metrics, read_table


def load_simulated_validation(paths) -> pd.DataFrame | None:
    """The train stage's simulated_validation.csv files as one table (columns ACCURACY_COLUMNS
    and test_source), or None when no file has a row (no simulated record was held out)."""
    with_rows = [p for p in paths if len(pd.read_csv(p))]
    if not with_rows:
        return None
    table = load_metrics(with_rows, extra_columns=("test_source",))
    sources = set(table["test_source"]) if "test_source" in table.columns else {None}
    if sources != {SIMULATED_VALIDATION}:
        raise ReportInputError(
            f"simulated validation files {[str(p) for p in with_rows]}: "
            f"test_source {sorted(map(str, sources))}, expected "
            f"only {SIMULATED_VALIDATION!r}"
        )
    return table


def load_calibration(params_path) -> dict:
    """The calibration summary: model variant, cost, evaluations, parameters."""
    params_path = Path(params_path)
    try:
        params = json.loads(params_path.read_text())
    except FileNotFoundError:
        raise ReportInputError(f"{params_path}: no such calibration file") from None
    except json.JSONDecodeError as exc:
        raise ReportInputError(f"{params_path}: not valid JSON ({exc})") from exc
    missing = [k for k in ("model_variant", "parameters", "cost", "evaluations") if k not in params]
    if missing:
        raise ReportInputError(f"{params_path}: calibration file lacks keys {missing}")
    summary = {
        "model_variant": params["model_variant"],
        "cost": params["cost"],
        "evaluations": params["evaluations"],
        "parameters": params["parameters"],
    }
    for key in ("nominal_cost", "seconds", "sensor_noise"):
        if key in params:
            summary[key] = params[key]
    return summary


def load_calibrations(calibration: CalibrationOutputs) -> tuple:
    """(summaries, spectra, histories) of the calibration files: each {variant: ...} with one
    calibration per variant (each summary with its `calibration_variant`), else the one's own."""
    params_paths, spectra_paths, history_paths = calibration.by_variant()
    if not (list(params_paths) == list(spectra_paths) == list(history_paths)) or not params_paths:
        raise ReportInputError(
            "calibration params, spectra and history must name the same "
            f"calibration variants: {list(params_paths)}, "
            f"{list(spectra_paths)}, {list(history_paths)}"
        )
    calibrations = {m: load_calibration(p) for m, p in params_paths.items()}
    for variant, summary in calibrations.items():
        if variant is not None:
            summary["calibration_variant"] = variant
    spectra = {
        m: read_table(
            p, ["speed_rpm", "channel", "freq_hz", "measured", "calibrated"], "calibration spectra"
        )
        for m, p in spectra_paths.items()
    }
    history = {
        m: read_table(p, ["evaluation", "model_variant", "cost"], "calibration history")
        for m, p in history_paths.items()
    }
    if not calibration.per_variant:
        return calibrations[None], spectra[None], history[None]
    return calibrations, spectra, history


def load_fault_lines(info_paths) -> tuple[pd.DataFrame | None, dict]:
    """(per fault record whether its defect line shows, the rule's description) from the physics
    baselines' info.json (the first rule that gives `fault_lines`, `EnvelopeRule.fault_lines`);
    (None, {}) without one."""
    for path in info_paths:
        for name, rule in json.loads(Path(path).read_text()).get("baselines", {}).items():
            if rule.get("fault_lines"):
                return pd.DataFrame(rule["fault_lines"]), {
                    "rule": name,
                    "threshold": rule.get("threshold"),
                    "threshold_from": rule.get("threshold_from"),
                    # the envelope analyses the rule consults and each one's healthy threshold
                    **{
                        key: rule[key] for key in ("analyses", "analysis_thresholds") if key in rule
                    },
                }
    return None, {}


def record_conditions(measured_features_path, condition: str) -> dict:
    """{record_id: its value of the operating condition} from the measured features."""
    features = pd.read_parquet(measured_features_path, columns=["record_id", condition])
    return dict(zip(features["record_id"].astype(str), features[condition].astype(float)))


def with_condition(predictions: pd.DataFrame, conditions: dict, condition: str) -> pd.DataFrame:
    """The predictions with a column `condition` (each record's operating condition, e.g. a
    motor load, where each file's stored speed would split one load into many groups);
    speed_rpm is there already. A tested record without a condition is an error."""
    if condition in predictions.columns:
        return predictions
    values = predictions["record_id"].astype(str).map(conditions)
    missing = sorted(set(predictions.loc[values.isna(), "record_id"].astype(str)))
    if missing:
        raise ReportInputError(
            f"the measured features give no {condition!r} (hybrid.condition) "
            f"for the tested records {missing[:5]}"
        )
    return predictions.assign(**{condition: values.astype(float)})


def design_record_ids(design_records, design_specimens, measured_records) -> tuple[list, dict]:
    """The records reported as design records: `design_records` (report.design_records) and every
    record of a design specimen (System.design_specimens, matched to records.csv's `specimen`);
    and {record_id: specimen} of the measured records (empty where records.csv names none).
    Design specimens without a specimen column to match are an error, never ignored."""
    specimens = {}
    if measured_records is not None:
        records = pd.read_csv(measured_records, dtype=str, keep_default_na=False)
        if "specimen" in records.columns:
            kept = records[records["status"] == "kept"] if "status" in records.columns else records
            specimens = dict(zip(kept["record_id"], kept["specimen"]))
    design_specimens = set(map(str, design_specimens))
    if design_specimens and not specimens:
        raise ReportInputError(
            f"design specimens {sorted(design_specimens)} are declared, but the measured records "
            f"({measured_records}) name no specimen to match them to"
        )
    of_specimens = {r for r, specimen in specimens.items() if specimen in design_specimens}
    return sorted(set(map(str, design_records)) | of_specimens), specimens


def unmodelled_records(unmodelled: dict, specimens: dict) -> dict:
    """{record_id: reason} of the unmodelled records: every record whose specimen (records.csv's,
    `specimens`: {record_id: specimen}) the system says its model does not describe
    (`unmodelled`: {specimen: reason}, System.unmodelled_specimens). Declared without a
    specimen to match: an error, never ignored."""
    if unmodelled and not specimens:
        raise ReportInputError(
            f"unmodelled specimens {sorted(unmodelled)} are declared, "
            "but the measured records name no specimen to match them to"
        )
    return {
        record: unmodelled[specimen]
        for record, specimen in sorted(specimens.items())
        if specimen in unmodelled
    }
