"""The bearing system's training-free physics baseline: the envelope rule.

A reviewer's first question of a bearing classifier is whether it beats the textbook rule: look
at the envelope spectrum and name the fault whose defect line stands out (Randall & Antoni 2011;
Smith & Randall 2015 for CWRU). `EnvelopeRule` is that rule on the project's own features, the
envelope line ratios at BPFO, BPFI and 2 x BSF (`condmon.stat_features`, columns
`<channel>_env_ratio_<line>` or their logs `<channel>_log_env_ratio_<line>`), and on the line
ratios of further envelope analyses of the measured segments (`line_table`: fixed band or
kurtogram band, with or without cepstral prewhitening, `bearing.envelope_rule.line_analyses`):
- each analysis's ratios are divided by their median over the healthy calibration segments
  (largest line), and a segment's ratio at a line is the largest of these over the analyses:
  the strongest analysis speaks for every line;
- the predicted fault is the line with the largest ratio (outer race, inner race, ball);
- the segment is healthy where that largest ratio is at or below `threshold_`.
It learns nothing from labelled faults. Its numbers come from the healthy calibration segments
only (the calibration set, never a test segment): each analysis's median, and the `quantile`
(default 0.95, `bearing.envelope_rule.quantile`) of the combined largest line ratio. So a healthy
test segment is called faulty about as often as a calibration segment would be, if the healthy
record's line ratios stay alike. With the features' analysis alone, the rule is the plain argmax
of its line ratios under the quantile of their largest.

`fault_lines` says whether each fault record shows its defect's line: where any analysis lifts
the median of its line ratio over the record's segments above that analysis's own healthy
threshold, and which analyses do (`shown_by`), or why none does (`no_line_why`).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from condmon import envelope
from condmon.signals import to_arrays
from condmon.stat_features import highpass

# the envelope line each fault location strikes at (stat_features' line names)
LINE_OF_DEFECT = {"outer_race": "bpfo", "inner_race": "bpfi", "ball": "bsf_x2"}
# the features' own analysis, as the rule names it beside `line_table`'s
FEATURES = "features"


def line_table(
    signals: pd.DataFrame, channel: str, orders: dict, sidebands: dict, statistical: dict, analyses
) -> pd.DataFrame:
    """The envelope line ratios of every measured segment by every analysis in `analyses`.

    Parameters
    ----------
    signals : pandas.DataFrame
        A signal table (`condmon.signals`), one sampling rate.
    channel : str
        The channel read.
    orders, sidebands : dict
        The defect lines {name: shaft order} the rule reads (BPFO, BPFI, 2 x BSF) and their
        sideband spacings {name: shaft order} (`condmon.envelope.fault_line_sets`).
    statistical : dict
        `features.statistical`: band_hz (the fixed band), highpass_hz, line_tolerance,
        floor_halfwidth_orders and the `envelope` section's harmonics and kurtogram_max_level.
    analyses : sequence of str
        Of `condmon.envelope.ANALYSES`.

    Returns
    -------
    pandas.DataFrame
        Indexed by (record_id, segment); columns `<analysis>:<line>` (the ratio).
    """
    unknown = sorted(set(analyses) - set(envelope.ANALYSES))
    if unknown:
        raise ValueError(
            f"bearing.envelope_rule.line_analyses: unknown analyses {unknown}; choose among "
            f"{list(envelope.ANALYSES)}"
        )
    rates = signals["fs_hz"].unique()
    if len(rates) != 1:
        raise ValueError(
            f"envelope rule: the measured records have several sampling rates {sorted(rates)}"
        )
    fs_hz = float(rates[0])
    ids, arrays = to_arrays(signals, [channel])
    x = highpass(arrays[:, 0, :], fs_hz, statistical.get("highpass_hz", 10.0))
    options = dict(statistical.get("envelope") or {})
    tolerance = float(statistical.get("line_tolerance", 0.015))
    sets = envelope.fault_line_sets(orders, sidebands, int(options.get("harmonics", 1)), tolerance)
    columns = {}
    for analysis in analyses:
        ratios = envelope.line_ratios(
            x,
            fs_hz,
            ids["speed_rpm"].to_numpy(float),
            sets,
            analysis,
            tuple(statistical.get("band_hz", (2000.0, 5000.0))),
            int(options.get("kurtogram_max_level", 3)),
            tolerance,
            float(statistical.get("floor_halfwidth_orders", 0.5)),
        )
        columns.update({f"{analysis}:{line}": ratios[line] for line in orders})
    index = pd.MultiIndex.from_arrays(
        [ids["record_id"].astype(str), ids["segment"].astype(int)], names=["record_id", "segment"]
    )
    return pd.DataFrame(columns, index=index)


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
    """Argmax of the envelope line ratios at BPFO, BPFI and 2 x BSF over the strongest analysis,
    healthy under a threshold (module docstring).

    Parameters
    ----------
    columns : dict
        {line: (feature column, logged)} (`envelope_columns`): the features' own analysis.
    labels : dict
        {line: the health label of that fault location}, e.g. {"bpfo": "outer_race"}.
    healthy_state : str
        The label of a segment whose largest ratio is at or below the threshold.
    quantile : float
        Of the calibration segments' largest (combined) ratio, the healthy threshold.
    lines : pandas.DataFrame, optional
        `line_table` of the measured segments: further analyses consulted beside the features'.

    `fit(calibration)`: a feature frame of healthy calibration segments only; sets `threshold_`,
    `scales_` (each analysis's median largest ratio), `thresholds_` (each analysis's own
    quantile) and `n_calibration_`. `predict(frame)`: labels.
    """

    def __init__(
        self,
        columns: dict,
        labels: dict,
        healthy_state: str,
        quantile: float = 0.95,
        lines: pd.DataFrame | None = None,
    ):
        self.columns = columns
        self.labels = labels
        self.healthy_state = healthy_state
        self.quantile = quantile
        self.lines = lines

    def analyses(self) -> list[str]:
        """The analyses consulted: the features' own, then `lines`'."""
        found = [FEATURES]
        if self.lines is not None:
            found += list(dict.fromkeys(column.split(":", 1)[0] for column in self.lines.columns))
        return found

    def analysis_ratios(self, frame: pd.DataFrame) -> dict:
        """{analysis: ratios (not their logs) of every row, one column per line}."""
        missing = [column for column, _ in self.columns.values() if column not in frame.columns]
        if missing:
            raise ValueError(f"envelope rule: the features lack column(s) {missing}")
        out = {
            FEATURES: pd.DataFrame(
                {
                    line: np.exp(frame[column].to_numpy(float))
                    if logged
                    else frame[column].to_numpy(float)
                    for line, (column, logged) in self.columns.items()
                },
                index=frame.index,
            )
        }
        if self.lines is not None:
            keys = pd.MultiIndex.from_arrays(
                [frame["record_id"].astype(str), frame["segment"].astype(int)]
            )
            absent = ~keys.isin(self.lines.index)
            if absent.any():
                raise ValueError(
                    f"envelope rule: no line ratios of segment(s) {list(keys[absent][:5])} in the "
                    "measured signals"
                )
            rows = self.lines.loc[keys]
            for analysis in self.analyses()[1:]:
                out[analysis] = pd.DataFrame(
                    {line: rows[f"{analysis}:{line}"].to_numpy(float) for line in self.columns},
                    index=frame.index,
                )
        return out

    def line_ratios(self, frame: pd.DataFrame) -> pd.DataFrame:
        """Every row's ratio per line: the largest over the analyses of the ratio over that
        analysis's healthy median (`fit`)."""
        ratios = self.analysis_ratios(frame)
        lines = list(self.columns)
        scaled = np.max(
            [ratios[a][lines].to_numpy(float) / self.scales_[a] for a in ratios], axis=0
        )
        return pd.DataFrame(scaled, index=frame.index, columns=lines)

    def fit(self, calibration: pd.DataFrame) -> "EnvelopeRule":
        if not 0 < self.quantile <= 1:
            raise ValueError(f"envelope rule: quantile {self.quantile!r} must lie in (0, 1]")
        if calibration.empty:
            raise ValueError("envelope rule: no healthy calibration segment to set the threshold")
        largest = {
            a: r.max(axis=1).to_numpy() for a, r in self.analysis_ratios(calibration).items()
        }
        self.scales_ = {
            a: float(max(np.median(v), np.finfo(float).tiny)) for a, v in largest.items()
        }
        self.thresholds_ = {a: float(np.quantile(v, self.quantile)) for a, v in largest.items()}
        combined = self.line_ratios(calibration).max(axis=1).to_numpy()
        self.threshold_ = float(np.quantile(combined, self.quantile))
        self.n_calibration_ = len(combined)
        return self

    def predict(self, frame: pd.DataFrame) -> np.ndarray:
        ratios = self.line_ratios(frame)
        strongest = ratios.idxmax(axis=1).map(self.labels).to_numpy(object)
        healthy = ratios.max(axis=1).to_numpy() <= self.threshold_
        return np.where(healthy, self.healthy_state, strongest).astype(str)

    def fault_lines(self, frame: pd.DataFrame) -> list[dict]:
        """Whether each fault record of `frame` shows its defect's envelope line, by each analysis:
        the median over its segments of that analysis's line ratio at the line of its label
        (BPFO for an outer-race record) above the level the healthy calibration segments stay
        under by that analysis (`thresholds_`). A record shows its line where any analysis shows
        it (`shown_by` names them, strongest first); one no analysis shows says why
        (`no_line_why`): a criterion "on the records that show their line" is taken on these."""
        line_of_label = {label: line for line, label in self.labels.items()}
        faulty = frame[frame["health_state"].astype(str).isin(line_of_label)].reset_index(drop=True)
        ratios = self.analysis_ratios(faulty)
        rows = []
        for (record_id, label), index in faulty.groupby(
            ["record_id", "health_state"], sort=True
        ).groups.items():
            line = line_of_label[str(label)]
            medians = {a: float(np.median(r.loc[index, line])) for a, r in ratios.items()}
            margins = {a: medians[a] / self.thresholds_[a] for a in medians}
            shown = sorted((a for a in margins if margins[a] > 1), key=lambda a: -margins[a])
            best = max(margins, key=margins.get)
            why = (
                ""
                if shown
                else (
                    f"no analysis lifts the median {line} ratio above its healthy threshold (the "
                    f"strongest, {best}: {medians[best]:.2f} against {self.thresholds_[best]:.2f}): the "
                    "record's envelope spectra hold no line of its defect"
                )
            )
            rows.append(
                {
                    "record_id": str(record_id),
                    "label": str(label),
                    "line": line,
                    "median_ratio": medians[FEATURES],
                    "threshold": self.thresholds_[FEATURES],
                    "median_ratios": medians,
                    "thresholds": dict(self.thresholds_),
                    "shows_line": bool(shown),
                    "shown_by": ", ".join(shown),
                    "no_line_why": why,
                }
            )
        return rows

    def describe(self) -> dict:
        """What the rule is and the thresholds it took from the calibration segments."""
        return {
            "rule": "argmax of the envelope line-to-floor ratios at "
            + ", ".join(f"{line} ({self.labels[line]})" for line in self.columns)
            + " (each the largest over the analyses "
            + ", ".join(self.analyses())
            + f" of its ratio over that analysis's healthy median); {self.healthy_state} "
            "where the largest is at or below the threshold",
            "threshold_from": (
                f"the {self.quantile:g} quantile of the largest line ratio "
                "over the healthy calibration segments (never a test "
                "segment)"
            ),
            "columns": {line: column for line, (column, _) in self.columns.items()},
            "analyses": self.analyses(),
            "threshold": getattr(self, "threshold_", None),
            "analysis_thresholds": getattr(self, "thresholds_", None),
            "n_calibration_segments": getattr(self, "n_calibration_", None),
        }
