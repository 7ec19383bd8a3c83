"""The measured records' own separability (condmon.separability): a measured-only classifier,
each record left out in turn, per operating condition."""
import numpy as np
import pandas as pd

from condmon.separability import leave_one_record_out, measured_separability


def records(rng, classes, per_class=3, segments=4, spread=0.1, speeds=(450.0, 775.0)):
    """Segments of `per_class` records per class and speed; feature f0 sits at the class's index
    (classes apart by 1, each segment scattered by `spread`), f1 is noise."""
    rows = []
    for speed in speeds:
        for c, state in enumerate(classes):
            for k in range(per_class):
                for s in range(segments):
                    rows.append({"record_id": f"{state}-{speed:g}-{k}", "segment": s, "health_state": state,
                                 "speed_rpm": speed, "f0": c + rng.normal(0, spread), "f1": rng.normal()})
    return pd.DataFrame(rows)


def test_separable_records_score_one_and_noise_does_not():
    rng = np.random.default_rng(0)
    frame = records(rng, ["healthy", "missing_tooth", "surface_fault"])
    out = measured_separability(frame, ["f0", "f1"], "speed_rpm")
    assert out["all"]["balanced_accuracy"] == 1.0
    assert {k: v["balanced_accuracy"] for k, v in out["per_condition"].items()} == {"450": 1.0, "775": 1.0}
    assert out["all"]["records"] == 18 and out["per_condition"]["450"]["records_per_class"]["healthy"] == 3
    # classes that differ in nothing the features hold: about chance (1/3), far from separable
    noise = records(rng, ["healthy", "missing_tooth", "surface_fault"], spread=0.0)
    noise["f0"] = rng.normal(size=len(noise))
    assert leave_one_record_out(noise, ["f0", "f1"]) < 0.7


def test_the_recall_per_class_names_the_class_the_records_cannot_show():
    rng = np.random.default_rng(2)
    frame = records(rng, ["healthy", "missing_tooth", "surface_fault"])
    hidden = frame["health_state"] == "missing_tooth"
    frame.loc[hidden, "f0"] = rng.normal(0.0, 0.1, hidden.sum())  # a missing tooth that looks healthy
    out = measured_separability(frame, ["f0", "f1"], "speed_rpm")["per_condition"]["450"]
    assert out["recall_per_class"]["surface_fault"] == 1.0
    assert out["recall_per_class"]["missing_tooth"] < 0.8 and out["recall_per_class"]["healthy"] < 0.9
    assert out["balanced_accuracy"] == np.mean(list(out["recall_per_class"].values()))
    # the class its own records cannot show is named: exempt from what simulation is asked
    assert "missing_tooth" in out["not_shown"] and "surface_fault" not in out["not_shown"]


def test_a_class_of_one_record_cannot_be_left_out():
    """A class with one record would be tested on a model that never saw it: no figure (None) at a
    speed with one normal record; over both speeds (two normal records) a figure."""
    rng = np.random.default_rng(1)
    frame = records(rng, ["normal", "inner_race"])
    frame = frame[~frame["record_id"].str.startswith("normal") | frame["record_id"].str.endswith("-0")]
    out = measured_separability(frame, ["f0", "f1"], "speed_rpm")
    assert out["per_condition"]["450"]["balanced_accuracy"] is None
    assert out["per_condition"]["450"]["records_per_class"] == {"inner_race": 3, "normal": 1}
    assert out["all"]["records_per_class"]["normal"] == 2 and out["all"]["balanced_accuracy"] == 1.0
    assert leave_one_record_out(frame[frame["health_state"] == "inner_race"], ["f0", "f1"]) is None
