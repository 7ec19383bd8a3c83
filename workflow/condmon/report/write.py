"""write_report: the report stage as a loop over the registered sections (condmon.report.registry).

Each section that applies (its required inputs given) adds its summary.json keys and plots, and
returns its tables; the tables the outputs name are written, then summary.json. Every output is
written atomically, the plots folder as a whole.
"""

from __future__ import annotations

import json
import logging

from condmon.atomic import staging_directory, write_text
from condmon.report import registry
from condmon.report.context import Report
from condmon.report.inputs import ReportInputs
from condmon.report.section import Section
from condmon.train_tables import ReportInputError

log = logging.getLogger(__name__)


def write_report(inputs: ReportInputs) -> dict:
    """Build the whole report from `inputs` (condmon.report.inputs: what each input adds, and
    which outputs are optional) through every registered section; returns the summary dict.

    With the measured features (inputs.evaluation.measured_features) the evaluation tables
    (condmon.evaluation: per evaluation; over repeats) get `design_records` and the records of
    `design_specimens` apart as design records, summary.json's results the per-record, balanced,
    false-alarm and baseline figures (all test records, and design and evaluation records
    apart; the headline is then on the evaluation records), and plots/simulation_gain.png the
    gain against the strongest baseline (without them: against the same classifier's
    measured-only baseline)."""
    out = inputs.outputs
    known = {table.name for table in registry.tables()}
    unknown = sorted(set(out.tables) - known)
    if unknown:
        raise ReportInputError(
            f"report tables {unknown} asked for, but no report section writes "
            f"them; the sections' tables: {sorted(known)}"
        )
    with staging_directory(out.plots) as staging:
        report = Report(inputs, staging)
        tables = {}
        for section in registry.SECTIONS:
            if section.applies(inputs):
                tables.update(run_section(section, report))
        for name, frame in tables.items():
            if name in out.tables:
                write_text(frame.to_csv(index=False), out.tables[name])
        write_text(json.dumps(report.summary, indent=2) + "\n", out.summary)
    log.info(
        "wrote %d tables, %s and %d plots in %s",
        len(set(tables) & set(out.tables)),
        out.summary,
        len(report.plots),
        out.plots,
    )
    return report.summary


def run_section(section: Section, report: Report) -> dict:
    """One section's tables; what it adds beyond its declaration (a summary key, a table) is an
    error naming the section."""
    before = set(report.summary)
    tables = section.write(report)
    added = sorted(set(report.summary) - before - set(section.summary_keys))
    undeclared = sorted(set(tables) - {table.name for table in section.tables})
    if added or undeclared:
        raise ValueError(
            f"report section {section.name!r} added summary keys {added} and tables "
            f"{undeclared} it does not declare (Section.summary_keys, Section.tables)"
        )
    return tables
