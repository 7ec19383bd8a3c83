"""The measured records' own separability (condmon.separability): a measured-only classifier,
each record left out in turn, per operating condition."""

import numpy as np
import pandas as pd

from condmon.report.simulated_ceiling import separability_table
from condmon.separability import (
    held_out_accuracy,
    machine_folds,
    measured_separability,
    simulated_separability,
)
from condmon.simulate import machine_of


def records(rng, classes, per_class=3, segments=4, spread=0.1, speeds=(450.0, 775.0)):
    """Segments of `per_class` records per class and speed; feature f0 sits at the class's index
    (classes apart by 1, each segment scattered by `spread`), f1 is noise."""
    rows = []
    for speed in speeds:
        for c, state in enumerate(classes):
            for k in range(per_class):
                for s in range(segments):
                    rows.append(
                        {
                            "record_id": f"{state}-{speed:g}-{k}",
                            "segment": s,
                            "health_state": state,
                            "speed_rpm": speed,
                            "f0": c + rng.normal(0, spread),
                            "f1": rng.normal(),
                        }
                    )
    return pd.DataFrame(rows)


def test_separable_records_score_one_and_noise_does_not():
    rng = np.random.default_rng(0)
    frame = records(rng, ["healthy", "missing_tooth", "surface_fault"])
    out = measured_separability(frame, ["f0", "f1"], "speed_rpm", permutations=10)
    assert out["all"]["balanced_accuracy"] == 1.0 and out["all"]["reads_above_chance"]
    assert {k: v["balanced_accuracy"] for k, v in out["per_condition"].items()} == {
        "450": 1.0,
        "775": 1.0,
    }
    assert (
        out["all"]["records"] == 18
        and out["per_condition"]["450"]["records_per_class"]["healthy"] == 3
    )
    # classes that differ in nothing the features hold: about chance (1/3), far from separable
    noise = records(rng, ["healthy", "missing_tooth", "surface_fault"], spread=0.0)
    noise["f0"] = rng.normal(size=len(noise))
    assert held_out_accuracy(noise, ["f0", "f1"]) < 0.7


def test_the_recall_per_class_names_the_class_the_records_cannot_show():
    rng = np.random.default_rng(2)
    frame = records(rng, ["healthy", "missing_tooth", "surface_fault"])
    hidden = frame["health_state"] == "missing_tooth"
    frame.loc[hidden, "f0"] = rng.normal(
        0.0, 0.1, hidden.sum()
    )  # a missing tooth that looks healthy
    out = measured_separability(frame, ["f0", "f1"], "speed_rpm", permutations=10)["per_condition"][
        "450"
    ]
    assert out["recall_per_class"]["surface_fault"] == 1.0
    assert (
        out["recall_per_class"]["missing_tooth"] < 0.8 and out["recall_per_class"]["healthy"] < 0.9
    )
    assert out["balanced_accuracy"] == np.mean(list(out["recall_per_class"].values()))
    # the class its own records cannot show is named: exempt from what simulation is asked
    assert "missing_tooth" in out["not_shown"] and "surface_fault" not in out["not_shown"]


def test_a_class_of_fewer_than_three_records_gets_no_figure_and_says_why():
    """Held out, a class of one or two records is learnt from one record or none: no figure (None)
    at a speed with two normal records, and the reason; over both speeds (five) a figure."""
    rng = np.random.default_rng(1)
    frame = records(rng, ["normal", "inner_race"])
    frame = frame[frame["record_id"] != "normal-450-2"]
    out = measured_separability(frame, ["f0", "f1"], "speed_rpm", permutations=10)
    assert out["per_condition"]["450"]["balanced_accuracy"] is None
    assert out["per_condition"]["450"]["refused"] == "fewer than 3 records of normal (2)"
    assert out["per_condition"]["450"]["records_per_class"] == {"inner_race": 3, "normal": 2}
    assert out["all"]["records_per_class"]["normal"] == 5 and out["all"]["balanced_accuracy"] == 1.0
    assert held_out_accuracy(frame[frame["health_state"] == "inner_race"], ["f0", "f1"]) is None


def test_pure_noise_scores_within_the_permutation_band_of_chance_not_zero():
    """Six classes of 4-5 records, two segments each, features that hold nothing: the ceiling
    reads chance (about 1/6, within its permutation band), exempts nothing, and says it does not
    read. Left out one record at a time (unbalanced training) the same records scored 0.00-0.02."""
    rng = np.random.default_rng(3)
    counts = {"healthy": 4, **{f"fault{k}": 5 for k in range(5)}}
    rows = [
        {
            "record_id": f"{state}-{k}",
            "segment": s,
            "health_state": state,
            "speed_rpm": 450.0,
            **{f"n{i}": v for i, v in enumerate(rng.normal(size=100))},
        }
        for state, n in counts.items()
        for k in range(n)
        for s in range(2)
    ]
    out = measured_separability(
        pd.DataFrame(rows), [f"n{i}" for i in range(100)], "speed_rpm", permutations=20
    )["all"]
    assert abs(out["chance"]["mean"] - 1 / 6) < 0.05
    assert 0.05 < out["balanced_accuracy"] <= out["chance"]["upper"]
    assert out["reads_above_chance"] is False and out["not_shown"] == []


def machines(rng, classes, count=8, effect=1.0, hidden=(), scatter=0.1, speed=450.0):
    """Simulated twins: `count` machines at `speed`, each with a record of every class
    (sim-<state>-<speed>rpm-b000-s<k>, two segments); f0 is the machine's own offset (`scatter`)
    plus `effect` x the class's index, except for a class in `hidden` (its fault moves nothing)."""
    rows = []
    for k in range(count):
        offset = rng.normal(0, scatter)
        for c, state in enumerate(classes):
            for s in range(2):
                rows.append(
                    {
                        "record_id": f"sim-{state}-{speed:g}rpm-b000-s{k:03d}",
                        "segment": s,
                        "health_state": state,
                        "speed_rpm": speed,
                        "f0": offset + (0.0 if state in hidden else effect * c),
                        "f1": rng.normal(),
                    }
                )
    return pd.DataFrame(rows)


def test_a_simulated_machine_is_held_out_with_all_its_twins():
    rng = np.random.default_rng(4)
    frame = machines(rng, ["healthy", "missing_tooth", "surface_fault"], count=5)
    machine = frame["record_id"].map(machine_of).to_numpy()
    folds = machine_folds(machine)
    assert len(folds) == 5
    for train, test in folds:
        assert len(set(machine[test])) == 1 and not set(machine[test]) & set(machine[train])
        # every class of the held-out machine is tested, none of its records trains
        assert set(frame["health_state"].to_numpy()[test]) == {
            "healthy",
            "missing_tooth",
            "surface_fault",
        }


def test_the_simulation_confusing_a_class_on_unseen_machines_names_it_and_what_it_is_taken_for():
    rng = np.random.default_rng(5)
    classes = ["healthy", "missing_tooth", "surface_fault"]
    apart = simulated_separability(machines(rng, classes), ["f0", "f1"], "speed_rpm")
    assert apart["per_condition"]["450"]["balanced_accuracy"] == 1.0
    assert apart["per_condition"]["450"]["machines"] == 8
    # a surface fault that moves nothing, in machines scattered as much as the faults apart: found
    # on an unseen machine at about chance, taken for healthy
    frame = machines(rng, classes, hidden=("surface_fault",), scatter=0.6)
    out = simulated_separability(frame, ["f0", "f1"], "speed_rpm")["per_condition"]["450"]
    assert out["recall_per_class"]["surface_fault"] < 0.8
    assert out["confusion"]["surface_fault"].get("healthy", 0) > 0
    table = separability_table({"per_condition": {"450": out}})
    row = table.set_index("health_state").loc["surface_fault"]
    assert row["recall"] < 0.8 and "healthy" in row["confused_with"]
    one = simulated_separability(machines(rng, classes, count=1), ["f0", "f1"], "speed_rpm")
    assert one["per_condition"]["450"]["refused"] == "one simulated machine only"
