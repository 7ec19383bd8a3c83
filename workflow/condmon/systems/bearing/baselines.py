"""The bearing system's training-free physics baseline: the envelope rule.

A reviewer's first question of a bearing classifier is whether it beats the textbook rule: look
at the envelope spectrum and name the fault whose defect line stands out (Randall & Antoni 2011;
Smith & Randall 2015 for CWRU). `EnvelopeRule` is that rule on the project's own features, the
envelope line-to-floor ratios at BPFO, BPFI and 2 x BSF (`condmon.stat_features`, columns
`<channel>_env_ratio_<line>` or their logs `<channel>_log_env_ratio_<line>`):
- the predicted fault is the line with the largest ratio (outer race, inner race, ball);
- the segment is healthy where that largest ratio is at or below `threshold_`.
It learns nothing from labelled faults. Its one number, the healthy threshold, comes from the
healthy calibration segments only (the calibration set, never a test segment): the `quantile`
(default 0.95, `bearing.envelope_rule.quantile`) of their largest line ratio. So a healthy test
segment is called faulty about as often as a calibration segment would be, if the healthy
record's line ratios stay alike.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

# the envelope line each fault location strikes at (stat_features' line names)
LINE_OF_DEFECT = {"outer_race": "bpfo", "inner_race": "bpfi", "ball": "bsf_x2"}


def envelope_columns(feature_names) -> dict | None:
    """{line: (column, logged)} of the first channel whose features hold all three line ratios
    (BPFO, BPFI, 2 x BSF), or None when no channel does."""
    names = list(feature_names)
    channels = []
    for name in names:
        channel = name.split("_", 1)[0]
        if channel not in channels:
            channels.append(channel)
    for channel in channels:
        found = {}
        for line in LINE_OF_DEFECT.values():
            for column, logged in (
                (f"{channel}_env_ratio_{line}", False),
                (f"{channel}_log_env_ratio_{line}", True),
            ):
                if column in names:
                    found[line] = (column, logged)
                    break
        if len(found) == len(LINE_OF_DEFECT):
            return found
    return None


class EnvelopeRule:
    """Argmax of the envelope line ratios at BPFO, BPFI and 2 x BSF, healthy under a threshold.

    Parameters
    - columns: {line: (feature column, logged)} (`envelope_columns`).
    - labels: {line: the health label of that fault location}, e.g. {"bpfo": "outer_race"}.
    - healthy_state: the label of a segment whose largest ratio is at or below the threshold.
    - quantile: of the calibration segments' largest ratio, the healthy threshold.

    `fit(calibration)`: a feature frame of healthy calibration segments only; sets `threshold_`
    and `n_calibration_`. `predict(frame)`: labels.
    """

    def __init__(self, columns: dict, labels: dict, healthy_state: str, quantile: float = 0.95):
        self.columns = columns
        self.labels = labels
        self.healthy_state = healthy_state
        self.quantile = quantile

    def line_ratios(self, frame: pd.DataFrame) -> pd.DataFrame:
        """The line ratios (not their logs) of every row, one column per line."""
        missing = [column for column, _ in self.columns.values() if column not in frame.columns]
        if missing:
            raise ValueError(f"envelope rule: the features lack column(s) {missing}")
        return pd.DataFrame(
            {
                line: np.exp(frame[column].to_numpy(float))
                if logged
                else frame[column].to_numpy(float)
                for line, (column, logged) in self.columns.items()
            },
            index=frame.index,
        )

    def fit(self, calibration: pd.DataFrame) -> "EnvelopeRule":
        if not 0 < self.quantile <= 1:
            raise ValueError(f"envelope rule: quantile {self.quantile!r} must lie in (0, 1]")
        if calibration.empty:
            raise ValueError("envelope rule: no healthy calibration segment to set the threshold")
        largest = self.line_ratios(calibration).max(axis=1).to_numpy()
        self.threshold_ = float(np.quantile(largest, self.quantile))
        self.n_calibration_ = len(largest)
        return self

    def predict(self, frame: pd.DataFrame) -> np.ndarray:
        ratios = self.line_ratios(frame)
        strongest = ratios.idxmax(axis=1).map(self.labels).to_numpy(object)
        healthy = ratios.max(axis=1).to_numpy() <= self.threshold_
        return np.where(healthy, self.healthy_state, strongest).astype(str)

    def fault_lines(self, frame: pd.DataFrame) -> list[dict]:
        """Whether each fault record of `frame` shows its defect's envelope line: the median over
        its segments of the line ratio at the line of its label (BPFO for an outer-race record)
        above `threshold_`, the level the healthy calibration segments stay under. A fault whose
        line does not stand out is one no envelope analysis sees, and the record says so beside its
        recall (a criterion "at every size that shows a BPFO line" is taken on these)."""
        line_of_label = {label: line for line, label in self.labels.items()}
        faulty = frame[frame["health_state"].astype(str).isin(line_of_label)].reset_index(drop=True)
        ratios = self.line_ratios(faulty)
        rows = []
        for (record_id, label), index in faulty.groupby(
            ["record_id", "health_state"], sort=True
        ).groups.items():
            line = line_of_label[str(label)]
            median = float(np.median(ratios.loc[index, line]))
            rows.append(
                {
                    "record_id": str(record_id),
                    "label": str(label),
                    "line": line,
                    "median_ratio": median,
                    "threshold": self.threshold_,
                    "shows_line": bool(median > self.threshold_),
                }
            )
        return rows

    def describe(self) -> dict:
        """What the rule is and the threshold it took from the calibration segments."""
        return {
            "rule": "argmax of the envelope line-to-floor ratios at "
            + ", ".join(f"{line} ({self.labels[line]})" for line in self.columns)
            + f"; {self.healthy_state} where the largest is at or below the threshold",
            "threshold_from": (
                f"the {self.quantile:g} quantile of the largest line ratio "
                "over the healthy calibration segments (never a test "
                "segment)"
            ),
            "columns": {line: column for line, (column, _) in self.columns.items()},
            "threshold": getattr(self, "threshold_", None),
            "n_calibration_segments": getattr(self, "n_calibration_", None),
        }
