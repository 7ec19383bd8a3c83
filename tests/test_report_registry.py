"""The report as sections: write_report runs exactly the registered sections (condmon.report.registry),
each declaring its inputs, tables and summary.json keys; a new table is one module and one line."""

import json

import pandas as pd
import pytest

import fake_train_outputs as fake
from conftest import ROOT, logical_lines
from condmon.report import registry
from condmon.report.section import Section, Table
from condmon.train_tables import ReportInputError

REPORT = ROOT / "workflow" / "condmon" / "report"


def records_per_class(report) -> dict:
    """A toy section's table: the tested records of each true class."""
    counts = report.predictions.groupby("true_label")["record_id"].nunique()
    report.summary["records_per_class"] = {label: int(n) for label, n in counts.items()}
    return {"records_per_class": counts.rename("records").reset_index()}


TOY = Section(
    "records_per_class",
    records_per_class,
    inputs=("train.predictions",),
    tables=(Table("records_per_class", "records_per_class.csv", "Records per class"),),
    summary_keys=("records_per_class",),
)


def test_a_registered_section_writes_its_table_and_summary_key(
    knn_train_outputs, tmp_path, monkeypatch
):
    """One module's SECTION and one registry line: the report writes the new table where the
    outputs name it, its summary key after every other section's, and the rule's outputs and the
    pages' tables (registry.tables) list it."""
    _, paths = knn_train_outputs
    # the registry as two real sections and the new one: the claim is write_report's loop over
    # whatever is registered, not the other sections' plots
    real = [section for section in registry.SECTIONS if section.name in ("accuracy", "evaluation")]
    monkeypatch.setattr(registry, "SECTIONS", [*real, TOY])
    out = tmp_path / "report"
    summary = fake.write_report(
        paths, out, outputs={"records_per_class": out / "records_per_class.csv"}
    )
    table = pd.read_csv(out / "records_per_class.csv")
    predictions = pd.concat(pd.read_parquet(p) for p in paths["predictions"])
    assert (
        dict(zip(table["true_label"], table["records"]))
        == predictions.groupby("true_label")["record_id"].nunique().to_dict()
    )
    written = json.loads((out / "summary.json").read_text())
    assert list(written)[-1] == "records_per_class" and written == summary
    assert "records_per_class" in {t.name: t.file for t in registry.tables()}
    # not registered: no section writes it, and asking for it says so
    monkeypatch.setattr(registry, "SECTIONS", [s for s in registry.SECTIONS if s is not TOY])
    with pytest.raises(
        ReportInputError, match=r"\['records_per_class'\] asked for, but no report section"
    ):
        fake.write_report(paths, tmp_path / "again", outputs={"records_per_class": out / "x.csv"})


def test_a_section_that_adds_what_it_does_not_declare_is_refused(
    knn_train_outputs, tmp_path, monkeypatch
):
    _, paths = knn_train_outputs

    def sloppy(report):
        report.summary["surprise"] = 1
        return {}

    # first, so that the refusal comes before the other sections' plots
    monkeypatch.setattr(registry, "SECTIONS", [Section("sloppy", sloppy), *registry.SECTIONS])
    with pytest.raises(ValueError, match=r"'sloppy' added summary keys \['surprise'\]"):
        fake.write_report(paths, tmp_path / "report")


def test_a_section_names_only_inputs_that_exist():
    with pytest.raises(ValueError, match="no report input 'train.metric'"):
        Section("typo", records_per_class, inputs=("train.metric",))
    with pytest.raises(ValueError, match="requires"):
        Section("unread", records_per_class, requires=("train.physics",))


def test_the_registry_declares_every_summary_key_and_table_once():
    keys = [key for section in registry.SECTIONS for key in section.summary_keys]
    assert len(keys) == len(set(keys))
    names = [section.name for section in registry.SECTIONS]
    assert len(names) == len(set(names))
    assert [t.file for t in registry.tables()] == [f"{t.name}.csv" for t in registry.tables()]


def test_no_report_module_is_over_200_logical_lines():
    """The report is a package of small modules (issue 50): no module of it over 200 logical lines
    (conftest.logical_lines, which the formatter cannot change; 300 lines as written before the
    code was formatted at 100 columns), and the old single module is gone."""
    lengths = {path.name: logical_lines(path.read_text()) for path in REPORT.glob("*.py")}
    assert {"registry.py", "write.py", "headline.py"} <= set(lengths)
    assert max(lengths.values()) <= 200, lengths
    assert not (ROOT / "workflow" / "condmon" / "report.py").exists()
