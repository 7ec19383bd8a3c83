"""What a report section declares: the inputs it reads, the tables it writes, its summary.json keys.

A section is one module of condmon.report with a `SECTION`; the registry (condmon.report.registry)
lists them in the order write_report runs them. `write(report)` adds the section's summary.json
keys to `report.summary` and its plot names to `report.plots` (plots drawn into `report.staging`),
and returns {table name: DataFrame} of the tables it made; write_report writes those the outputs
name (ReportOutputs.tables) and refuses a table or a summary key the section did not declare.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Callable

import pandas as pd

from condmon.report.inputs import (
    CalibrationOutputs,
    EvaluationInputs,
    RunIdentity,
    StageRecords,
    TrainOutputs,
)

# the groups of ReportInputs a section's inputs are named by ("group.field")
GROUPS = {
    "run": RunIdentity,
    "train": TrainOutputs,
    "calibration": CalibrationOutputs,
    "evaluation": EvaluationInputs,
    "upstream": StageRecords,
}


@dataclass(frozen=True)
class Table:
    """One CSV of the report stage: `name` its key (report.smk's output, ReportOutputs.tables,
    the report page's file name), `file` its name under report/, `title` and `note` its report
    page's heading and text; `page`: shown as an HTML table by report_pages."""

    name: str
    file: str
    title: str = ""
    note: str = ""
    page: bool = True


@dataclass(frozen=True)
class Section:
    """One part of the report. `inputs`: the ReportInputs fields it reads ("group.field", e.g.
    "train.physics_info"); `requires`: those of them without which it is left out (a field that
    is None, or an empty sequence: ReportInputs stores sequences as tuples); `tables`: what it writes; `summary_keys`: summary.json's top-level keys
    it adds; `write`: see the module docstring."""

    name: str
    write: Callable[..., dict[str, pd.DataFrame]]
    inputs: tuple[str, ...] = ()
    requires: tuple[str, ...] = ()
    tables: tuple[Table, ...] = ()
    summary_keys: tuple[str, ...] = ()

    def __post_init__(self):
        for name in self.inputs:
            group, _, field = name.partition(".")
            if group not in GROUPS or field not in {f.name for f in fields(GROUPS[group])}:
                raise ValueError(
                    f"report section {self.name!r}: no report input {name!r} "
                    f"(a field of one of {sorted(GROUPS)}, e.g. 'train.metrics')"
                )
        unread = sorted(set(self.requires) - set(self.inputs))
        if unread:
            raise ValueError(f"report section {self.name!r} requires {unread} without reading them")

    def applies(self, inputs) -> bool:
        """Whether every required input is given (not None, not an empty tuple)."""
        return all(
            getattr(getattr(inputs, group), field) not in (None, ())
            for group, _, field in (name.partition(".") for name in self.requires)
        )
