"""Report figures. Each function takes plain tables and returns a matplotlib Figure.

Every figure carries a footnote ``note`` naming the data source (e.g. "virtual bench
(synthetic)") so a plot copied out of the report can never pass for real measurements.
"""

from __future__ import annotations


import matplotlib

matplotlib.use("Agg")  # batch jobs have no display
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.ticker import FormatStrFormatter, NullFormatter  # noqa: E402

from condmon.atomic import temporary_path  # noqa: E402
from condmon.labels import protocol_title  # noqa: E402
import numpy as np  # noqa: E402

ACCURACY_LABEL = "accuracy on held-out measured records"
PERCENT_LABEL = "measured data in training set (%)"


def _colours(names):
    cycle = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    return {name: cycle[i % len(cycle)] for i, name in enumerate(names)}


# inches per character of DejaVu Sans at 1 pt, on average (wrapping text to a figure's width)
CHAR_WIDTH_PER_POINT = 0.0085


def wrap_to_width(text: str, width_inches: float, fontsize: float) -> list[str]:
    """`text` in lines that fit `width_inches` at `fontsize` (a footnote must never run off the
    figure; matplotlib neither wraps nor clips a figure text to the figure)."""
    import textwrap

    chars = max(20, int(width_inches / (CHAR_WIDTH_PER_POINT * fontsize)))
    return textwrap.wrap(text, chars) or [""]


def short_title(text: str, width: int = 48, max_lines: int = 2) -> str:
    """A panel title wrapped at `width` characters, at most `max_lines` lines (the rest cut with
    an ellipsis): detail belongs in the caption, not over a panel."""
    import textwrap

    return "\n".join(textwrap.wrap(text, width, max_lines=max_lines, placeholder=" ..."))


def _finish(fig, title: str, note: str, legend_from=None):
    """Title, data-source footnote (wrapped to the figure's width) and, from axes
    ``legend_from``, one legend below the panels (inside a panel it would hide bars or lines)."""
    fig.suptitle(title, fontsize=13)
    lines = wrap_to_width(note, fig.get_figwidth() - 0.2, 9)
    fig.text(0.01, 0.005, "\n".join(lines), fontsize=9, color="0.3", ha="left", va="bottom")
    bottom = 0.01 + len(lines) * 9 * 1.3 / 72 / fig.get_figheight()  # the note's lines
    if legend_from is not None:
        handles, labels = legend_from.get_legend_handles_labels()
        # as many columns as fit the figure's width (an entry: its handle, its text, a gap)
        entry = 1.0 + max((len(label) for label in labels), default=0) * CHAR_WIDTH_PER_POINT * 9
        ncol = max(1, min(len(labels), 6, int((fig.get_figwidth() - 0.2) // entry)))
        rows = -(-len(labels) // ncol)
        fig.legend(
            handles,
            labels,
            loc="lower center",
            ncol=ncol,
            fontsize=9,
            bbox_to_anchor=(0.5, bottom),
            frameon=False,
        )
        bottom += (0.1 + 0.25 * rows) / fig.get_figheight()  # inches of legend -> figure fraction
    fig.tight_layout(rect=(0, bottom, 1, 1))
    return fig


def save_figure(fig, path) -> None:
    """Save as PNG via a temporary file and rename, then release the figure."""
    try:
        with temporary_path(path) as tmp:
            fig.savefig(tmp, format="png", dpi=110)
    finally:
        plt.close(fig)


def accuracy_vs_measured_percent(per_repeat, chance: float, note: str):
    """One panel per protocol, one line per classifier: mean over repeats, min-max band.

    ``per_repeat``: columns classifier, protocol, measured_percent, repeat, accuracy.
    """
    protocols = sorted(per_repeat["protocol"].unique())
    colours = _colours(sorted(per_repeat["classifier"].unique()))
    fig, axes = plt.subplots(
        1, len(protocols), figsize=(5.5 * len(protocols), 4.5), sharey=True, squeeze=False
    )
    for ax, protocol in zip(axes[0], protocols):
        rows = per_repeat[per_repeat["protocol"] == protocol]
        for classifier, group in rows.groupby("classifier"):
            stats = group.groupby("measured_percent")["accuracy"].agg(["mean", "min", "max"])
            ax.plot(
                stats.index, stats["mean"], marker="o", color=colours[classifier], label=classifier
            )
            ax.fill_between(
                stats.index,
                stats["min"],
                stats["max"],
                alpha=0.2,
                color=colours[classifier],
                linewidth=0,
            )
        ax.axhline(chance, linestyle="--", color="0.4", label=f"chance ({chance:.2f})")
        ax.set_title(protocol_title(protocol))
        ax.set_xlabel(PERCENT_LABEL)
        ax.set_ylim(0, 1.05)
        ax.grid(alpha=0.3)
    axes[0, 0].set_ylabel(f"{ACCURACY_LABEL} (fraction)")
    return _finish(
        fig,
        "Accuracy vs share of measured data in training\n(line: mean over repeats, band: min-max)",
        note,
        legend_from=axes[0, 0],
    )


def simulation_gain(gain, chance: float, note: str):
    """Per protocol, top: accuracy with the simulated data (solid, per classifier) against the
    strongest baseline at each share (dashed: the strongest of the measured-only classifier,
    the physics baseline and the majority class; whichever columns ``gain`` has are drawn thin
    and grey); bottom: the gain against the strongest, negative where a baseline wins.
    ``gain``: columns classifier, protocol, measured_percent, hybrid, strongest, gain, and
    optionally measured_only_best, physics_baseline_accuracy, majority_class."""
    protocols = sorted(gain["protocol"].unique())
    colours = _colours(sorted(gain["classifier"].unique()))
    others = [
        (column, label, style)
        for column, label, style in (
            ("measured_only_best", "measured only (best classifier)", "--"),
            ("physics_baseline_accuracy", "physics baseline (no training)", "-."),
            ("majority_class", "majority class", ":"),
        )
        if column in gain.columns
    ]
    fig, axes = plt.subplots(
        2,
        len(protocols),
        figsize=(5.5 * len(protocols), 7.6),
        sharey="row",
        sharex=True,
        squeeze=False,
        gridspec_kw={"height_ratios": [3, 2]},
    )
    for top, bottom, protocol in zip(axes[0], axes[1], protocols):
        rows = gain[gain["protocol"] == protocol]
        for column, label, style in others:
            line = rows.groupby("measured_percent")[column].mean()
            if line.notna().any():
                top.plot(
                    line.index,
                    line.to_numpy(),
                    linestyle=style,
                    color="0.55",
                    linewidth=1,
                    label=label,
                )
        for classifier, group in rows.groupby("classifier"):
            group = group.sort_values("measured_percent")
            top.plot(
                group["measured_percent"],
                group["hybrid"],
                marker="o",
                color=colours[classifier],
                label=f"{classifier}: simulated + measured",
            )
            top.plot(
                group["measured_percent"],
                group["strongest"],
                marker="x",
                linestyle="--",
                color=colours[classifier],
                label=f"{classifier}: strongest baseline",
            )
            bottom.plot(
                group["measured_percent"], group["gain"], marker="o", color=colours[classifier]
            )
        top.axhline(chance, linestyle=":", color="0.75", label=f"chance ({chance:.2f})")
        # what the protocol tests: the report's protocols table
        top.set_title(short_title(protocol_title(protocol)), fontsize=10)
        top.set_ylim(0, 1.05)
        top.grid(alpha=0.3)
        bottom.axhline(0.0, color="0.2", linewidth=1)
        bottom.axhspan(
            min(-0.05, float(gain["gain"].min()) - 0.05), 0, color="tab:red", alpha=0.08
        )  # below 0: a baseline wins
        bottom.set_xlabel(PERCENT_LABEL)
        bottom.grid(alpha=0.3)
    axes[0, 0].set_ylabel(f"{ACCURACY_LABEL} (fraction)")
    axes[1, 0].set_ylabel("gain vs strongest\n(red: a baseline wins)")
    return _finish(
        fig,
        "The simulation's gain against the strongest baseline (a negative gain: a baseline wins)",
        note,
        legend_from=axes[0, 0],
    )


def recall_per_class(recalls, note: str):
    """Grid protocol x classifier: recall of every class against the measured percentage
    (pooled over repeats and holdouts). ``recalls``: columns classifier, protocol,
    measured_percent, true_label, recall."""
    protocols = sorted(recalls["protocol"].unique())
    classifiers = sorted(recalls["classifier"].unique())
    colours = _colours(sorted(recalls["true_label"].unique()))
    fig, axes = plt.subplots(
        len(protocols),
        len(classifiers),
        figsize=(5.0 * len(classifiers), 3.6 * len(protocols)),
        sharey=True,
        squeeze=False,
    )
    for i, protocol in enumerate(protocols):
        for j, classifier in enumerate(classifiers):
            ax = axes[i, j]
            rows = recalls[
                (recalls["protocol"] == protocol) & (recalls["classifier"] == classifier)
            ]
            for label, group in rows.groupby("true_label"):
                group = group.sort_values("measured_percent")
                ax.plot(
                    group["measured_percent"],
                    group["recall"],
                    marker="o",
                    color=colours[label],
                    label=label,
                )
            # one or two lines; what the protocol tests: the report's protocols table
            ax.set_title(short_title(f"{classifier}, {protocol_title(protocol)}"), fontsize=10)
            ax.set_ylim(0, 1.05)
            ax.grid(alpha=0.3)
            if i == len(protocols) - 1:
                ax.set_xlabel(PERCENT_LABEL)
        axes[i, 0].set_ylabel("recall")
    handles = {}
    for ax in axes.flat:  # one legend entry per class over all panels
        for handle, label in zip(*ax.get_legend_handles_labels()):
            handles.setdefault(label, handle)
    legend_ax = axes[0, 0]
    legend_ax.legend(handles.values(), handles.keys(), fontsize=7, loc="lower right")
    return _finish(fig, "Recall per class on held-out measured segments", note)


def accuracy_per_speed(speed_rows, percents, chance: float, note: str):
    """Grid protocol x chosen measured percentage; grouped bars per speed, one per classifier.

    ``speed_rows``: metrics rows with a speed (columns classifier, protocol, measured_percent,
    speed_rpm, accuracy). Bar = mean over evaluations, whisker = min-max.
    """
    if speed_rows.empty:
        raise ValueError(
            "accuracy per speed: the metrics have no per-speed rows "
            "(speed_rpm set); the train stage should write one per tested speed"
        )
    protocols = sorted(speed_rows["protocol"].unique())
    classifiers = sorted(speed_rows["classifier"].unique())
    colours = _colours(classifiers)
    width = 0.8 / len(classifiers)
    fig, axes = plt.subplots(
        len(protocols),
        len(percents),
        figsize=(4.8 * len(percents), 3.6 * len(protocols)),
        sharey=True,
        squeeze=False,
    )
    for i, protocol in enumerate(protocols):
        for j, percent in enumerate(percents):
            ax = axes[i, j]
            rows = speed_rows[
                (speed_rows["protocol"] == protocol) & (speed_rows["measured_percent"] == percent)
            ]
            speeds = sorted(rows["speed_rpm"].unique())
            x = np.arange(len(speeds))
            for k, classifier in enumerate(classifiers):
                stats = (
                    rows[rows["classifier"] == classifier]
                    .groupby("speed_rpm")["accuracy"]
                    .agg(["mean", "min", "max"])
                    .reindex(speeds)
                )
                ax.bar(
                    x + (k - (len(classifiers) - 1) / 2) * width,
                    stats["mean"],
                    width,
                    # clip: the mean of equal values can differ from them by rounding
                    yerr=np.clip(
                        [stats["mean"] - stats["min"], stats["max"] - stats["mean"]], 0, None
                    ),
                    color=colours[classifier],
                    label=classifier,
                    capsize=2,
                    error_kw={"elinewidth": 0.8},
                )
            ax.axhline(chance, linestyle="--", color="0.4", label="chance")
            ax.set_xticks(x, [f"{s:g}" for s in speeds])
            ax.set_title(
                f"{protocol_title(protocol)}, {percent} % measured in training", fontsize=10
            )
            ax.set_ylim(0, 1.05)
            ax.grid(axis="y", alpha=0.3)
            if i == len(protocols) - 1:
                ax.set_xlabel("input shaft speed (rpm)")
            if j == 0:
                ax.set_ylabel("accuracy (fraction)")
    return _finish(
        fig,
        "Accuracy per operating speed (bar: mean, whisker: min-max over repeats)",
        note,
        legend_from=axes[0, 0],
    )


def confusion_figure(panels, labels, title: str, note: str, colour_bar: bool = True):
    """Confusion matrices side by side, one per (counts, panel title or None) of `panels`.

    Colour = row-normalised share (recall per true class); text = share and count; a class absent
    from the test set leaves its row blank. Laid out by fixed margins in inches, with no layout
    pass: the tracking job draws one per nested run (hundreds), where a layout pass costs about
    0.3 s a figure. (sklearn's ConfusionMatrixDisplay colours and writes the matrix it is given;
    shares in colour with counts in the text and blank untested rows would override all of it.)
    """
    n, k = len(labels), len(panels)
    side, gap, left = max(1.8, 0.65 * n), 0.25, 1.5  # inches
    right = 1.1 if colour_bar else 0.3
    width = left + k * side + (k - 1) * gap + right
    # the title wrapped to the figure's width, and room for its lines and the panels' titles
    title_lines = wrap_to_width(title, width - 0.2, 10)
    top = 0.3 + 0.18 * len(title_lines) + (0.45 if any(t for _, t in panels) else 0.0)
    # the footnote wrapped to the figure's width, under the tick labels (1.2 in)
    note_lines = wrap_to_width(note, width - 0.2, 7)
    note_height = len(note_lines) * 7 * 1.3 / 72
    bottom = 1.2 + note_height + 0.1
    height = bottom + side + top
    fig = plt.figure(figsize=(width, height))
    image = None
    for i, (counts, panel_title) in enumerate(panels):
        ax = fig.add_axes(
            ((left + i * (side + gap)) / width, bottom / height, side / width, side / height)
        )
        totals = counts.sum(axis=1, keepdims=True)
        shares = np.where(totals > 0, counts / np.maximum(totals, 1), np.nan)
        image = ax.imshow(shares, cmap="Blues", vmin=0, vmax=1, aspect="auto")
        for r, c in np.ndindex(n, n):
            if totals[r, 0]:
                ax.text(
                    c,
                    r,
                    f"{shares[r, c]:.2f}\n({counts[r, c]})",
                    ha="center",
                    va="center",
                    fontsize=7,
                    color="white" if shares[r, c] > 0.6 else "black",
                )
        ax.set_xticks(range(n), labels, rotation=35, ha="right", fontsize=8)
        ax.set_yticks(range(n), labels if i == 0 else [], fontsize=8)
        ax.set_xlabel("predicted state", fontsize=8)
        if i == 0:
            ax.set_ylabel("true state", fontsize=8)
        if panel_title:
            ax.set_title(panel_title, fontsize=9)
    if colour_bar:
        colour_axes = fig.add_axes(
            ((width - right + 0.2) / width, bottom / height, 0.15 / width, side / height)
        )
        fig.colorbar(image, cax=colour_axes).set_label("share of true class (row)", fontsize=8)
    fig.suptitle("\n".join(title_lines), fontsize=10, y=1 - 0.1 / height, va="top")
    fig.text(
        0.1 / width, 0.05 / height, "\n".join(note_lines), fontsize=7, color="0.3", va="bottom"
    )
    return fig


def condition_label(condition: str, value) -> str | None:
    """An operating condition's value as titles and ticks show it: "450 rpm", "load 2" (None:
    all conditions)."""
    if value is None:
        return None
    return f"{float(value):g} rpm" if condition == "speed_rpm" else f"{condition} {float(value):g}"


def condition_axis_label(condition: str) -> str:
    return "speed (rpm)" if condition == "speed_rpm" else f"operating condition: {condition}"


def confusion_matrices(
    matrices: dict, labels, classifier: str, protocol: str, where: str | None, note: str
):
    """One panel per measured percentage; ``matrices`` maps percent -> (counts, n_repeats);
    ``where``: the operating condition's value (condition_label; None: all conditions)."""
    panels = []
    for percent, (counts, n_repeats) in sorted(matrices.items()):
        training = "simulation only" if percent == 0 else f"{percent} % measured"
        panels.append(
            (
                counts,
                f"training: {training}\n{int(counts.sum())} test segments, {n_repeats} repeat(s)",
            )
        )
    where = "all conditions" if where is None else where
    return confusion_figure(
        panels,
        labels,
        f"Confusion matrix: {classifier}, {protocol_title(protocol)}, {where}",
        note + " | counts summed over repeats",
    )


def prediction_shares(
    shares,
    labels,
    classifier: str,
    protocol: str,
    percents,
    note: str,
    condition: str = "speed_rpm",
):
    """The CFRP study's Fig. 9 for one classifier and protocol: a panel per (measured percentage,
    true class), in it per operating condition (speed, or e.g. load) a stacked bar of the
    percentage of that class's test segments predicted as each class (text: shares of 8 % and
    more; tick: the condition's value and test segments).

    ``shares``: rows of prediction_shares.csv (classifier, protocol, measured_percent,
    `condition`, true_label, predicted_label, share, n) of this classifier and protocol.
    """
    true_labels = [label for label in labels if label in set(shares["true_label"])]
    colours = _colours(labels)
    n_cols = max(1, min(len(true_labels), 4))
    blocks = max(1, -(-len(true_labels) // n_cols))  # rows of panels per percentage
    fig, axes = plt.subplots(
        len(percents) * blocks,
        n_cols,
        figsize=(3.3 * n_cols + 0.6, 3.1 * len(percents) * blocks + 1.4),
        sharey=True,
        squeeze=False,
    )
    for ax in axes.flat:
        ax.set_visible(False)
    legend_ax = None
    for a, percent in enumerate(percents):
        training = "simulation only" if percent == 0 else f"{percent} % measured"
        for k, true in enumerate(true_labels):
            ax = axes[a * blocks + k // n_cols, k % n_cols]
            ax.set_visible(True)
            ax.set_title(f"true: {true}\ntraining: {training}", fontsize=9)
            ax.set_ylim(0, 100)
            ax.grid(axis="y", alpha=0.3)
            rows = shares[(shares["measured_percent"] == percent) & (shares["true_label"] == true)]
            if rows.empty:
                ax.text(0.5, 0.5, "not tested", ha="center", va="center", transform=ax.transAxes)
                ax.set_xticks([])
                continue
            legend_ax = legend_ax or ax
            speeds = sorted(rows[condition].unique())
            counts = rows.groupby(condition)["n"].first().reindex(speeds)
            x = np.arange(len(speeds))
            bottom = np.zeros(len(speeds))
            for predicted in labels:
                percent_of = 100 * (
                    rows[rows["predicted_label"] == predicted]
                    .set_index(condition)["share"]
                    .reindex(speeds)
                    .fillna(0.0)
                    .to_numpy()
                )
                ax.bar(
                    x,
                    percent_of,
                    0.6,
                    bottom=bottom,
                    color=colours[predicted],
                    label=predicted,
                    edgecolor="white",
                    linewidth=0.5,
                )
                for xi, low, value in zip(x, bottom, percent_of):
                    if value >= 8:
                        ax.text(
                            xi,
                            low + value / 2,
                            f"{value:.0f}",
                            ha="center",
                            va="center",
                            fontsize=7,
                        )
                bottom += percent_of
            ax.set_xticks(x, [f"{s:g}\nn={int(c)}" for s, c in zip(speeds, counts)], fontsize=7)
            ax.set_xlabel(condition_axis_label(condition), fontsize=8)
        axes[a * blocks, 0].set_ylabel("predicted as (% of true class)")
    per = "speed" if condition == "speed_rpm" else condition
    title = (
        f"Prediction shares per {per}: {classifier}, {protocol_title(protocol)}\n"
        "(bar: a true class's test segments by predicted class, pooled over repeats)"
    )
    return _finish(fig, title, note, legend_from=legend_ax)


def confusion_matrix_small(counts, labels, title: str, note: str):
    """One confusion matrix without a colour bar: the tracking job's per-run artifact."""
    return confusion_figure([(counts, None)], labels, title, note, colour_bar=False)


def spectra_grid(spectra, note: str):
    """Grid speed x channel: mean amplitude spectrum measured vs calibrated model, log axis.

    With a `calibration_variant` column (several calibrations, same measured spectra) one
    calibrated line per variant."""
    models = (
        list(dict.fromkeys(spectra["calibration_variant"]))
        if "calibration_variant" in spectra.columns
        else [None]
    )
    model_colours = dict(zip(models, ("tab:red", "tab:blue", "tab:green", "tab:orange")))
    speeds = sorted(spectra["speed_rpm"].unique())
    channels = sorted(spectra["channel"].unique())
    fig, axes = plt.subplots(
        len(speeds),
        len(channels),
        figsize=(max(4.2 * len(channels), 7.0), 2.8 * len(speeds) + 0.8),
        sharex=True,
        squeeze=False,
    )
    for i, speed in enumerate(speeds):
        for j, channel in enumerate(channels):
            ax = axes[i, j]
            at = spectra[
                (spectra["speed_rpm"] == speed) & (spectra["channel"] == channel)
            ].sort_values("freq_hz")
            lines = []
            for model in models:
                rows = at if model is None else at[at["calibration_variant"] == model]
                if model == models[0]:
                    lines.append((rows, "measured", "measured", {"color": "black", "lw": 1.0}))
                lines.append(
                    (
                        rows,
                        "calibrated",
                        "calibrated model" if len(models) == 1 else f"calibrated model ({model})",
                        {"color": model_colours[model], "lw": 1.0, "alpha": 0.8},
                    )
                )
            for rows, column, label, style in lines:
                # log axis: non-positive amplitudes cannot be drawn, leave gaps
                values = rows[column].where(rows[column] > 0)
                ax.plot(rows["freq_hz"], values, label=label, **style)
            ax.set_yscale("log")
            ax.set_title(f"{speed:g} rpm, {channel}", fontsize=9)
            ax.grid(alpha=0.3, which="both", linewidth=0.4)
            if i == len(speeds) - 1:
                ax.set_xlabel("frequency (Hz)")
            if j == 0:
                ax.set_ylabel("amplitude (m/s²)")
    axes[0, -1].legend(fontsize=8, loc="upper right")
    return _finish(
        fig, "Mean amplitude spectra of healthy records: measured vs calibrated model", note
    )


def background_grid(table, note: str, method: str = "incoherent"):
    """Grid speed x channel: PSD (dB re 1 (m/s²)²/Hz) of the measured healthy records, of the
    calibrated model and the background between them (`condmon.background`'s table; with
    `method` incoherent, the parts of each that no other channel explains)."""
    speeds = sorted(table["speed_rpm"].unique())
    channels = list(dict.fromkeys(table["channel"]))
    fig, axes = plt.subplots(
        len(speeds),
        len(channels),
        figsize=(max(4.2 * len(channels), 7.0), 2.8 * len(speeds) + 0.8),
        sharex=True,
        squeeze=False,
    )
    # the background underneath, the measured record thin on top: where they coincide the model adds nothing
    part = " (no other channel explains)" if method == "incoherent" else ""
    styles = (
        ("background_psd", "background (measured - model, >= 0)", {"color": "tab:cyan", "lw": 1.6}),
        (
            "model_psd",
            f"calibrated model (mean of runs){part}",
            {"color": "tab:red", "lw": 0.7, "alpha": 0.8},
        ),
        ("measured_psd", f"measured{part}", {"color": "black", "lw": 0.5}),
    )
    for i, speed in enumerate(speeds):
        for j, channel in enumerate(channels):
            ax = axes[i, j]
            rows = table[(table["speed_rpm"] == speed) & (table["channel"] == channel)].sort_values(
                "freq_hz"
            )
            for column, label, style in styles:
                # dB: a zero (clipped) background is a gap, not minus infinity
                values = rows[column].where(rows[column] > 0)
                ax.plot(rows["freq_hz"], 10 * np.log10(values), label=label, **style)
            ax.set_title(f"{speed:g} rpm, {channel}", fontsize=9)
            ax.grid(alpha=0.3, linewidth=0.4)
            if i == len(speeds) - 1:
                ax.set_xlabel("frequency (Hz)")
            if j == 0:
                ax.set_ylabel("PSD (dB re 1 (m/s²)²/Hz)")
    return _finish(
        fig,
        "Background of healthy records: measured vs calibrated model PSD",
        note,
        legend_from=axes[0, 0],
    )


def state_fit_label(result: dict) -> str:
    """A per-state calibration's fit (`calibrate.change_fit` in its params.json) in words, for a
    plot's note; empty for a result without it."""
    if "explained_share" not in result:
        return ""
    fit = (
        f"explains {result['explained_share']:.0%} of the measured change "
        f"(correlation {result['change_correlation']:.2f})"
    )
    return fit if result.get("identified", True) else f"NOT IDENTIFIED by its records: {fit}"


def calibration_convergence(history, chosen: str, note: str, no_change_cost: float | None = None):
    """Best cost so far against model evaluation, one colour per model variant.

    Dots are single evaluations; non-finite costs (failed simulations) are left out. With
    `no_change_cost` (per-state calibration: the cost of a fault that changes nothing), a dashed
    line: a best cost above it fits the measured change no better than no fault.
    """
    variants = sorted(history["model_variant"].unique())
    colours = _colours(variants)
    fig, ax = plt.subplots(figsize=(7, 4.5))
    costs = []
    for variant in variants:
        rows = history[history["model_variant"] == variant].sort_values("evaluation")
        cost = rows["cost"].astype(float).where(np.isfinite(rows["cost"].astype(float)))
        best = cost.cummin().ffill()  # a failed evaluation does not break the line
        label = f"{variant} (chosen)" if variant == chosen else variant
        ax.scatter(rows["evaluation"], cost, s=6, alpha=0.25, color=colours[variant])
        ax.step(
            rows["evaluation"],
            best,
            where="post",
            color=colours[variant],
            label=label,
            linewidth=2 if variant == chosen else 1.2,
        )
        costs.extend(cost.dropna().tolist())
    if no_change_cost is not None:
        ax.axhline(
            no_change_cost,
            color="0.3",
            linestyle="--",
            linewidth=1.2,
            label="no fault (the model changes nothing)",
        )
        costs.append(no_change_cost)
    positive = [c for c in costs if c > 0]
    if positive and len(positive) == len(costs) and max(positive) / min(positive) > 20:
        ax.set_yscale("log")
    ax.set_xlabel("model evaluation (count)")
    ax.set_ylabel("cost (best so far; dots: single evaluations)")
    ax.grid(alpha=0.3)
    ax.legend(title="model variant", fontsize=9)
    return _finish(fig, "Calibration convergence", note)


def job_timings(timings, note: str):
    """Per rule: the wall seconds of all its jobs (the longest job marked) and the largest peak
    memory of one job. ``timings``: condmon.job_timings.summarise's table."""
    rules = list(timings["rule"])
    fig, (wall, memory) = plt.subplots(1, 2, figsize=(10, 1.2 + 0.45 * len(rules)), sharey=True)
    wall.barh(rules, timings["wall_seconds_total"], color="C0", label="all jobs")
    wall.plot(timings["wall_seconds_max"], rules, "k|", markersize=14, label="longest job")
    wall.set_xlabel("wall seconds (all jobs)")
    memory.barh(rules, timings["peak_rss_mb_max"], color="C1")
    memory.set_xlabel("peak memory per job (MB)")
    wall.invert_yaxis()  # rules top to bottom as in the table
    for ax in (wall, memory):
        ax.grid(axis="x", alpha=0.3)
    return _finish(fig, "Job timings per rule (Snakemake benchmark files)", note, legend_from=wall)


def job_timeline(jobs, busy, cores: int | None, note: str):
    """When each job ran (one bar per job, coloured by rule, in the order they started) and, below,
    the jobs running and the cores their CPU work kept busy against the run's cores: where a run
    waits on one job while cores idle. ``jobs``, ``busy``: condmon.job_timings.timeline and
    busy_cores."""
    rules = list(dict.fromkeys(jobs["rule"]))
    colours = dict(zip(rules, [f"C{k % 10}" for k in range(len(rules))]))
    fig, (bars, load) = plt.subplots(
        2,
        1,
        figsize=(10, 2.5 + 0.12 * len(jobs)),
        sharex=True,
        gridspec_kw={"height_ratios": [max(2.0, 0.12 * len(jobs)), 1.5]},
    )
    labelled = set()
    for k, row in enumerate(jobs.itertuples()):
        label = None if row.rule in labelled else row.rule  # one legend entry per rule
        labelled.add(row.rule)
        bars.barh(
            k, row.end - row.start, left=row.start, color=colours[row.rule], height=0.8, label=label
        )
    bars.set_yticks([])
    bars.set_ylabel("jobs, in the order they started")
    bars.invert_yaxis()
    load.step(busy["time"], busy["jobs"], where="post", color="0.3", label="jobs running")
    load.step(busy["time"], busy["cores"], where="post", color="C0", label="cores busy (CPU work)")
    if cores:
        load.axhline(cores, color="C3", linestyle=":", label=f"cores given ({cores})")
    load.set_xlabel("seconds from the first job's start")
    load.set_ylabel("count")
    load.legend(loc="upper right", fontsize="small")
    for ax in (bars, load):
        ax.grid(axis="x", alpha=0.3)
    return _finish(fig, "When each job ran (Snakemake benchmark files)", note, legend_from=bars)


def accuracy_per_subset(summary, column: str, chance: float, note: str, title: str):
    """One panel per protocol: accuracy against the measured share per value of ``column``
    (colour; e.g. `condition`: the load) and classifier (line style), with the 95 % Wilson
    interval as error bars. ``summary``: condmon.evaluation.summarise's rows of that subset."""
    protocols = sorted(summary["protocol"].unique())
    colours = _colours(sorted(summary[column].unique()))
    styles = dict(zip(sorted(summary["classifier"].unique()), ["-", "--", ":", "-."] * 4))
    # at least 9 inches: the two-line title must fit over a single panel
    fig, axes = plt.subplots(
        1, len(protocols), figsize=(max(5.5 * len(protocols), 9.0), 4.8), sharey=True, squeeze=False
    )
    for ax, protocol in zip(axes[0], protocols):
        rows = summary[summary["protocol"] == protocol]
        for (value, classifier), group in rows.groupby([column, "classifier"], sort=True):
            group = group.sort_values("measured_percent")
            mean = group["accuracy_mean"].to_numpy()
            error = np.clip(
                [mean - group["accuracy_ci_low"], group["accuracy_ci_high"] - mean], 0, None
            )
            ax.errorbar(
                group["measured_percent"],
                mean,
                yerr=error,
                marker="o",
                capsize=3,
                color=colours[value],
                linestyle=styles[classifier],
                label=f"{value}, {classifier}",
            )
        ax.axhline(chance, linestyle=":", color="0.4", label=f"chance ({chance:.2f})")
        ax.set(title=protocol_title(protocol), xlabel=PERCENT_LABEL, ylim=(0, 1.05))
        ax.grid(alpha=0.3)
    axes[0, 0].set_ylabel(f"{ACCURACY_LABEL} (fraction)")
    return _finish(
        fig,
        f"{title}\n(mean over repeats; bars: 95 % Wilson interval on one repeat's test segments)",
        note,
        legend_from=axes[0, 0],
    )


def fault_signatures(table, condition: str, note: str):
    """One panel per value of the operating ``condition``: per fault class, how far its measured
    and its simulated segments lie from their healthy ones (bars, in simulated healthy spreads,
    log scale; the dotted line is one spread), and above them how alike the two shifts are in
    direction (r). ``table``: condmon.signature.signature_table's rows."""
    values = list(dict.fromkeys(table["condition"]))
    shifts = table[["measured_shift", "simulated_shift"]].to_numpy(float)
    low, high = min(np.nanmin(shifts), 1.0) / 1.5, max(np.nanmax(shifts), 1.0) * 1.8  # room for r
    fig, axes = plt.subplots(
        1, len(values), figsize=(max(4.2 * len(values), 9.0), 4.8), sharey=True, squeeze=False
    )
    for ax, value in zip(axes[0], values):
        rows = table[table["condition"] == value].reset_index(drop=True)
        x = np.arange(len(rows))
        ax.bar(x - 0.2, rows["measured_shift"], width=0.4, color="tab:blue", label="measured fault")
        ax.bar(
            x + 0.2, rows["simulated_shift"], width=0.4, color="tab:orange", label="simulated fault"
        )
        for position, row in zip(x, rows.itertuples()):
            top = np.nanmax([row.measured_shift, row.simulated_shift])
            text = (
                "r n/a"
                if row.direction_correlation is None or np.isnan(row.direction_correlation)
                else f"r {row.direction_correlation:+.2f}"
            )
            ax.annotate(
                text,
                (position, top),
                textcoords="offset points",
                xytext=(0, 3),
                ha="center",
                fontsize=8,
            )
        ax.axhline(1.0, linestyle=":", color="0.4", label="one simulated healthy spread")
        ax.set_xticks(x, rows["health_state"], rotation=30, ha="right", fontsize=8)
        ax.set_yscale("log")
        ax.set_ylim(low, high)
        ax.set_yticks(
            [
                tick
                for tick in (0.05, 0.1, 0.2, 0.5, 1, 2, 5, 10, 20, 50, 100, 200)
                if low <= tick <= high
            ]
        )
        ax.yaxis.set_major_formatter(FormatStrFormatter("%g"))  # 0.5, 2: not 5 x 10^-1
        ax.yaxis.set_minor_formatter(NullFormatter())
        ax.set_title(condition_label(condition, value), fontsize=10)
        ax.grid(alpha=0.3, axis="y")
    axes[0, 0].set_ylabel("shift from healthy\n(rms over features, simulated healthy spreads)")
    return _finish(
        fig,
        "Does the simulation move the features as the measured faults do?\n"
        "(bars: shift from healthy; r: correlation of the two shifts over features)",
        note,
        legend_from=axes[0, 0],
    )
