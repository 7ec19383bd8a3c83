"""The calibration section: the measured against the calibrated spectra and each calibration's
convergence (one calibration, or one per calibration variant: all against the measured spectra,
then each); per-state calibration (calibration.per_state) each state's convergence
(``calibration_convergence_state_<state>.png``); summary.json's `state_calibration` and, with one
calibration per variant, `calibration_by_variant` (each one's model variant, final and nominal
cost, evaluations and seconds). The calibration the simulated data come from is summary.json's
`calibration` (the accuracy section's head).
"""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd

from condmon import plots
from condmon.report.section import Section


def write(report) -> dict:
    """The calibration plots and summary keys."""
    note, calibration = report.note(report.design_tested), report.calibrations
    spectra, history = report.spectra, report.history
    if not isinstance(spectra, dict):  # one calibration
        report.save(plots.spectra_grid(spectra, note), "spectra_measured_vs_calibrated.png")
        report.save(
            plots.calibration_convergence(history, calibration["model_variant"], note),
            "calibration_convergence.png",
        )
    else:  # one calibration per calibration variant: all against the measured spectra, then each
        report.save(
            plots.spectra_grid(
                pd.concat(
                    [
                        frame.assign(calibration_variant=variant)
                        for variant, frame in spectra.items()
                    ],
                    ignore_index=True,
                ),
                note,
            ),
            "spectra_measured_vs_calibrated.png",
        )
        for variant in spectra:
            variant_note = f"{note} | calibration variant: {variant}" if len(spectra) > 1 else note
            if len(spectra) > 1:
                report.save(
                    plots.spectra_grid(spectra[variant], variant_note),
                    f"spectra_measured_vs_calibrated_{variant}.png",
                )
            report.save(
                plots.calibration_convergence(
                    history[variant], calibration[variant]["model_variant"], variant_note
                ),
                f"calibration_convergence_{variant}.png",
            )
    states = report.inputs.calibration.states
    # calibration.per_state: what each fault's own records tuned
    state_results = {state: json.loads(Path(path).read_text()) for state, path in states.items()}
    report.plots.extend(
        state_convergence_plots(
            state_results, report.inputs.calibration.state_histories, report.staging, report.note()
        )
    )
    if state_results:
        report.summary["state_calibration"] = state_results
    if report.inputs.calibration.per_variant:
        report.summary["calibration_by_variant"] = calibration
    return {}


def state_convergence_plots(results: dict, histories, plots_dir: Path, note: str) -> list[str]:
    """Per-state calibration (calibration.per_state): each state's convergence from its history
    file (`histories`: state -> path; `results`: state -> its params.json content),
    `calibration_convergence_state_<state>.png` in `plots_dir`, `note` the run's footnote; the
    file names."""
    names = []
    for state, path in histories.items():
        name = f"calibration_convergence_state_{state}.png"
        fit = plots.state_fit_label(results[state])
        plots.save_figure(
            plots.calibration_convergence(
                pd.read_parquet(path),
                results[state]["model_variant"],
                f"{note} | the {state} model" + (f": {fit}" if fit else ""),
                no_change_cost=results[state].get("no_change_cost"),
            ),
            plots_dir / name,
        )
        names.append(name)
    return names


SECTION = Section(
    "calibration",
    write,
    inputs=(
        "calibration.params",
        "calibration.spectra",
        "calibration.history",
        "calibration.states",
        "calibration.state_histories",
        "run.state_models",
    ),
    summary_keys=("state_calibration", "calibration_by_variant"),
)
