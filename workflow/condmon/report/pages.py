"""The report's pages: what `snakemake --report` shows, from the report stage's files.

The report stage (condmon.report.write) computes; this module presents. It writes, under one folder
(``report/pages/``), every table the report stage wrote as CSV also as an HTML table (the
Snakemake report offers a CSV only as a download, an HTML file it shows in place), each
calibration's parameters as a table, the plots, the headline table the front page
(workflow/report/workflow.rst) embeds, and the run's full config. A separate job with few params
marks them for the report, so a result's details pane lists what identifies the run (run name,
system, config hash, protocols, classifiers, the full config's file), not every setting of the
job that computed it.
"""

from __future__ import annotations

import html
import json
import os
import shutil
from pathlib import Path

import pandas as pd

from condmon.atomic import staging_directory
from condmon.report import registry

STYLE = """<style>
body { font-family: sans-serif; font-size: 14px; margin: 1em; }
table { border-collapse: collapse; }
th, td { border: 1px solid #ccc; padding: 2px 8px; text-align: right; }
th { background: #eef; position: sticky; top: 0; }
td:first-child, th:first-child, td.text { text-align: left; }
caption { text-align: left; font-weight: bold; padding-bottom: 0.5em; }
p.note { color: #555; max-width: 60em; }
</style>"""


# Each table's heading and what it holds (the captions, workflow/report/tables.rst, say more):
# the registered sections' tables (condmon.report.registry), then the pages' own.
TITLES = {table.name: table.title for table in registry.tables() if table.title}
NOTES = {
    **{table.name: table.note for table in registry.tables() if table.note},
    "calibration": "The calibrated parameters, then the rest of the calibration's params.json.",
    "protocols": "What each test protocol holds out; every number of the report carries its protocol.",
    "bench_differences": (
        "Every way the virtual bench differs from the model, and what the pipeline does "
        "about it: calibrated (healthy records tune it), randomised (drawn per simulated "
        "sample over the stated range; within_range: the bench's value lies inside), "
        "neither (the classifier has to live with it) or same (a part the bench copies from "
        "the model, so it does not test it)."
    ),
}


def html_page(frame: pd.DataFrame, title: str, note: str = "") -> str:
    """A whole HTML document with `frame` as a table (numbers to 4 significant digits)."""
    table = frame.to_html(
        index=False, na_rep="", float_format=lambda x: f"{x:.4g}", border=0, escape=True
    )
    note_html = f'<p class="note">{html.escape(note)}</p>' if note else ""
    return (
        f'<!DOCTYPE html>\n<html><head><meta charset="utf-8"><title>{html.escape(title)}'
        f"</title>{STYLE}</head><body><h3>{html.escape(title)}</h3>{note_html}\n{table}\n"
        "</body></html>\n"
    )


def calibration_frame(params: dict) -> pd.DataFrame:
    """One calibration's params.json as rows of (what, value): the fitted parameters first."""
    rows = [
        (f"parameter: {name}", value) for name, value in (params.get("parameters") or {}).items()
    ]
    rows += [
        (key, json.dumps(value) if isinstance(value, (dict, list)) else value)
        for key, value in params.items()
        if key != "parameters"
    ]
    return pd.DataFrame(rows, columns=["what", "value"]).astype({"value": str})


def _place(source: Path, target: Path) -> None:
    """A plot into the pages: a hard link where the filesystem allows, else a copy."""
    try:
        os.link(source, target)
    except OSError:
        shutil.copy2(source, target)


def write_pages(
    tables: dict,
    headline,
    calibration_params: dict,
    plots_dir,
    config_path,
    out_dir,
    protocols: dict | None = None,
    titles: dict = TITLES,
    notes: dict = NOTES,
    bench_differences=(),
) -> list[str]:
    """Write the report's pages into `out_dir`: tables/<name>.html of every CSV of `tables`
    ({name: path}; `titles` and `notes` by name) and of the headline, tables/protocols.html (what
    each test protocol of `protocols`, {name: description}, tests: the plots' titles name the
    protocol only), tables/bench_differences.html (rows of `System.bench_differences`, where a
    bench made the data), tables/calibration_<variant>.html of every calibration ({variant:
    params.json}), plots/ (the report's PNGs), headline.csv (for the front page) and config.yaml
    (the run's full config). Returns the table names."""
    out_dir = Path(out_dir)
    names = []
    with staging_directory(out_dir) as staging:
        (staging / "tables").mkdir()
        (staging / "plots").mkdir()
        for name, path in {"headline": headline, **tables}.items():
            frame = pd.read_csv(path, keep_default_na=False, na_values=[""])
            (staging / "tables" / f"{name}.html").write_text(
                html_page(frame, titles.get(name, name), notes.get(name, ""))
            )
            names.append(name)
        if protocols:
            frame = pd.DataFrame(list(protocols.items()), columns=["protocol", "its test set"])
            (staging / "tables" / "protocols.html").write_text(
                html_page(frame, "Test protocols", notes.get("protocols", ""))
            )
            names.append("protocols")
        if bench_differences:
            (staging / "tables" / "bench_differences.html").write_text(
                html_page(
                    pd.DataFrame(list(bench_differences)),
                    "How the bench differs from the model",
                    notes.get("bench_differences", ""),
                )
            )
            names.append("bench_differences")
        for variant, path in calibration_params.items():
            params = json.loads(Path(path).read_text())
            (staging / "tables" / f"calibration_{variant}.html").write_text(
                html_page(
                    calibration_frame(params),
                    f"Calibration {variant}",
                    notes.get("calibration", ""),
                )
            )
            names.append(f"calibration_{variant}")
        for plot in sorted(Path(plots_dir).glob("*.png")):
            _place(plot, staging / "plots" / plot.name)
        shutil.copyfile(headline, staging / "headline.csv")
        shutil.copyfile(config_path, staging / "config.yaml")
    return names
