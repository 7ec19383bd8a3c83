"""How the simulated faults move the features against the measured faults (condmon.signature),
and the report's summary.json `fault_signatures` and plot."""

import json

import numpy as np
import pandas as pd
import pytest

import fake_train_outputs as fake
from condmon.features import read_feature_table, write_feature_table
from condmon.signature import (
    COVERAGE_TOLERANCE,
    fault_signatures,
    outside_simulation,
    pooled_coverage,
    signature_table,
    simulation_coverage,
)
from condmon.train_tables import ReportInputError

NAMES = [f"f{i}" for i in range(8)]


def segments(rng, source, shifts: dict, speeds=(450.0,), n=200):
    """`n` segments per class and speed; the features are unit normal noise plus the class's
    shift vector (`shifts`: class -> 8 values), the healthy class unshifted."""
    rows = []
    for speed in speeds:
        for state, shift in {"healthy": np.zeros(len(NAMES)), **shifts}.items():
            values = rng.normal(0.0, 1.0, (n, len(NAMES))) + np.asarray(shift, float)
            for k, row in enumerate(values):
                rows.append(
                    {
                        "record_id": f"{source}-{state}-{speed:g}-{k // 4}",
                        "segment": k % 4,
                        "health_state": state,
                        "speed_rpm": speed,
                        **dict(zip(NAMES, row)),
                    }
                )
    return pd.DataFrame(rows)


def test_shifts_in_healthy_spreads_and_their_direction():
    rng = np.random.default_rng(0)
    along = np.array([3.0, -3.0, 0, 0, 0, 0, 0, 0])
    simulated = segments(rng, "sim", {"missing_tooth": along, "surface_fault": along})
    # the measured missing tooth as the simulated one; the surface fault small and the other way
    measured = segments(rng, "bench", {"missing_tooth": along, "surface_fault": -0.3 * along})
    out = fault_signatures(measured, simulated, NAMES, "healthy", "speed_rpm")
    rows = out["per_condition"]["450"]["classes"]
    simulated_rms = np.sqrt(np.mean(along**2))  # 1.5 spreads
    assert rows["missing_tooth"]["simulated_shift"] == pytest.approx(simulated_rms, rel=0.1)
    assert rows["missing_tooth"]["measured_shift"] == pytest.approx(simulated_rms, rel=0.1)
    assert rows["missing_tooth"]["direction_correlation"] > 0.9
    assert rows["surface_fault"]["measured_shift"] < 0.5 * simulated_rms
    assert rows["surface_fault"]["direction_correlation"] < -0.5
    assert (
        rows["missing_tooth"]["features"] == len(NAMES)
        and rows["missing_tooth"]["measured_records"] == 50
    )
    table = signature_table(out)
    assert list(table["health_state"]) == ["missing_tooth", "surface_fault"] and set(
        table["condition"]
    ) == {"450"}


def test_each_measured_condition_takes_the_nearest_simulated_one_and_skips_what_it_cannot_compare():
    rng = np.random.default_rng(1)
    simulated = segments(rng, "sim", {"missing_tooth": np.full(8, 2.0)}, speeds=(450.0, 1100.0))
    simulated.loc[:, "f7"] = 1.0  # no healthy spread: left out
    measured = segments(
        rng,
        "bench",
        {"missing_tooth": np.full(8, 2.0), "spall": np.full(8, 2.0)},
        speeds=(460.0, 1090.0),
    )
    out = fault_signatures(measured, simulated, NAMES, "healthy", "speed_rpm")
    assert {k: v["simulated_at"] for k, v in out["per_condition"].items()} == {
        "460": 450.0,
        "1090": 1100.0,
    }
    for entry in out["per_condition"].values():
        assert list(entry["classes"]) == ["missing_tooth"]  # spall was never simulated
        assert entry["classes"]["missing_tooth"]["features"] == 7
    # measured records without their healthy class: nothing to take a shift from
    alone = measured[measured["health_state"] != "healthy"]
    assert fault_signatures(alone, simulated, NAMES, "healthy", "speed_rpm")["per_condition"] == {}
    assert signature_table({"per_condition": {}}).empty


def test_outside_simulation_marks_the_segments_no_simulated_example_covers():
    simulated = pd.DataFrame({"record_id": "sim", "a": [0.0, 1.0, 2.0], "b": [10.0, 20.0, 30.0]})
    measured = pd.DataFrame(
        {
            "record_id": ["in", "in", "low", "low", "both"],
            "a": [0.0, 2.0, -0.1, 1.0, 3.0],
            "b": [10.0, 30.0, 15.0, 15.0, 5.0],
        }
    )
    out = outside_simulation(measured, simulated, ["a", "b"]).set_index("record_id")
    assert out["outside_simulation"].to_dict() == {"both": 1.0, "in": 0.0, "low": 0.5}
    assert out["features_outside_simulation"].to_dict() == {"both": "a, b", "in": "", "low": "a"}
    # the features out on most segments first, the rest counted
    measured = pd.DataFrame({"record_id": "r", "a": [5.0, 5.0], "b": [15.0, 40.0]})
    (row,) = outside_simulation(measured, simulated, ["b", "a"], listed=1).itertuples()
    assert row.features_outside_simulation == "a (+1 more)" and row.outside_simulation == 1.0


def _coverage(rows):
    return pd.DataFrame(
        [
            dict(
                zip(
                    [
                        "classifier",
                        "protocol",
                        "measured_percent",
                        "repeat",
                        "holdout",
                        "record_id",
                        "n_segments",
                        "outside_training",
                        "features_outside_training",
                        "features",
                    ],
                    row,
                )
            )
            for row in rows
        ]
    )


def test_simulation_coverage_judges_the_design_records_at_the_lowest_share():
    """Item 2 of issue 49: the design records inside the range of the features the classifier
    uses; a record pooled over its splits, weighted by their segments; evaluation records listed
    apart, never judged; a higher measured share (measured training data widen the range) never
    counts."""
    rows = [
        # design d1: 1 of 40 segments out over two repeats (0.025: covered)
        ("svm", "unseen_fault", 0, 0, "", "d1", 20, 0.05, "b", "a, b"),
        ("svm", "unseen_fault", 0, 1, "", "d1", 20, 0.0, "", "a, b"),
        # design d2 inside; evaluation e1 far out
        ("svm", "unseen_fault", 0, 0, "", "d2", 20, 0.0, "", "a, b"),
        ("svm", "unseen_fault", 0, 0, "", "e1", 10, 0.8, "a", "a, b"),
        # at 50 % d2 is out: not the simulation's range
        ("svm", "unseen_fault", 50, 0, "", "d2", 20, 1.0, "a", "a, b"),
    ]
    pooled = pooled_coverage(_coverage(rows)).set_index(["measured_percent", "record_id"])
    assert pooled.loc[(0, "d1"), ["n_segments", "outside_training"]].tolist() == [40, 0.025]
    (entry,) = simulation_coverage(_coverage(rows), ["d1", "d2"])["results"]
    assert entry["measured_percent"] == 0 and entry["features"] == ["a", "b"]
    assert entry["covers_design_records"] and entry["design_records"] == 2
    assert entry["design_segments_outside"] == pytest.approx(1 / 60)
    assert entry["other_records_outside"] == {"e1": 0.8} and entry["design_records_outside"] == {}
    # d1 with 3 of 20 segments out (0.15 > the tolerance): not covered, and which feature
    rows[0] = ("svm", "unseen_fault", 0, 0, "", "d1", 20, 0.3, "b", "a, b")
    (entry,) = simulation_coverage(_coverage(rows), ["d1", "d2"])["results"]
    assert 0.15 > COVERAGE_TOLERANCE and not entry["covers_design_records"]
    assert entry["design_records_outside"] == {"d1": {"share": 0.15, "features": "b"}}
    # no design record tested: nothing is covered
    (entry,) = simulation_coverage(_coverage(rows), ["x"])["results"]
    assert not entry["covers_design_records"] and entry["design_segments_outside"] is None


def test_the_report_gives_the_signatures_and_their_plot(knn_train_outputs, tmp_path):
    _, paths = knn_train_outputs
    out = tmp_path / "report"
    summary = fake.write_sections(
        paths,
        out,
        ["fault_signatures", "recall_per_record"],
        evaluation={
            "measured_features": paths["features_measured"],
            "simulated_features": paths["features_simulated"],
        },
        outputs={"recall_per_record": out / "recall_per_record.csv"},
    )
    signatures = json.loads((out / "summary.json").read_text())["fault_signatures"]
    assert signatures == summary["fault_signatures"] and signatures["condition"] == "speed_rpm"
    measured, names = read_feature_table(paths["features_measured"])
    simulated, _ = read_feature_table(paths["features_simulated"])
    assert signatures == json.loads(
        json.dumps(fault_signatures(measured, simulated, names, "healthy", "speed_rpm"))
    )
    assert signatures["per_condition"] and "fault_signatures.png" in summary["plots"]
    assert (out / "plots" / "fault_signatures.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # each record's share of segments outside the simulated range stands beside its recall
    per_record = pd.read_csv(out / "recall_per_record.csv", keep_default_na=False)
    outside = outside_simulation(measured, simulated, names).set_index("record_id")
    for _, row in per_record.iterrows():
        assert row["outside_simulation"] == pytest.approx(
            outside.loc[row["record_id"], "outside_simulation"]
        )


def test_simulated_features_of_other_names_are_refused_with_the_file_named(
    knn_train_outputs, tmp_path
):
    _, paths = knn_train_outputs
    simulated, names = read_feature_table(paths["features_simulated"])
    other = tmp_path / "simulated.parquet"
    write_feature_table(simulated.drop(columns=names[-1]), names[:-1], other)
    with pytest.raises(ReportInputError, match="simulated.parquet: its features differ"):
        fake.write_sections(
            paths,
            tmp_path / "report",
            ["fault_signatures"],
            evaluation={
                "measured_features": paths["features_measured"],
                "simulated_features": other,
            },
        )
