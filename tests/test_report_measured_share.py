"""The measured_share section: where measured data of other records lower a figure, and why."""

import pandas as pd
import pytest

from condmon.report.measured_share import COLUMNS, measured_share
from condmon.report.registry import SECTIONS


def predictions(classifier, percent, calls):
    """One prediction per (record, label, called) of `calls`, in train's format."""
    return pd.DataFrame(
        [
            {
                "classifier": classifier,
                "protocol": "specimen_holdout",
                "measured_percent": percent,
                "record_id": record,
                "true_label": label,
                "predicted_label": called,
            }
            for record, label, called in calls
        ]
    )


def test_a_figure_lowered_by_measured_data_names_the_class_record_and_why():
    right = [("or1", "outer_race", "outer_race")] * 4 + [("ir1", "inner_race", "inner_race")] * 4
    # at 100 % the outer-race record is called normal on three of its four segments
    worse = (
        [("or1", "outer_race", "outer_race")]
        + [("or1", "outer_race", "normal")] * 3
        + [("ir1", "inner_race", "inner_race")] * 4
    )
    frame = pd.concat(
        [
            predictions("svm", 0, right),
            predictions("svm", 100, worse),
            predictions("knn", 0, right),
            predictions("knn", 100, right),
        ],
        ignore_index=True,
    )
    table = measured_share(frame, specimens={"or1": "outer_race 0.014 in at 6:00"}).set_index(
        "classifier"
    )
    assert list(table.reset_index().columns) == COLUMNS
    svm = table.loc["svm"]
    assert (svm["balanced_from"], svm["balanced_to"]) == (1.0, pytest.approx(0.625))
    assert bool(svm["lowered"]) and svm["class_most_lowered"] == "outer_race"
    assert svm["record_most_lowered"] == "or1" and svm["record_called"] == "normal"
    assert svm["record_change"] == pytest.approx(-0.75)
    assert (
        "or1 (outer_race 0.014 in at 6:00), labelled outer_race, is then called normal"
        in svm["why"]
    )
    assert "75% of its segments it misses" in svm["why"]
    knn = table.loc["knn"]
    assert not bool(knn["lowered"]) and knn["why"] == "" and knn["change"] == 0.0


def test_one_measured_share_gives_no_row_and_the_section_is_registered():
    one = predictions("svm", 0, [("or1", "outer_race", "outer_race")])
    assert measured_share(one).empty
    names = [section.name for section in SECTIONS]
    assert "measured_share" in names and names.index("measured_share") > names.index(
        "recall_per_record"
    )
