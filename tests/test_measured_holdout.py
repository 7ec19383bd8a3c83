"""benchmarks/measured_holdout.py: leaving one record out still trains on the held-out record's
specimen (its other loads), leaving one specimen out never does."""

import importlib.util

import numpy as np
import pandas as pd

from conftest import ROOT

spec = importlib.util.spec_from_file_location(
    "measured_holdout", ROOT / "benchmarks" / "measured_holdout.py"
)
measured_holdout = importlib.util.module_from_spec(spec)
spec.loader.exec_module(measured_holdout)


def segments() -> pd.DataFrame:
    """Two classes, two specimens each, two records (loads) per specimen; one specimen of class b
    (b2) sits where only itself lies, far from b1 and on a's side of the feature."""
    rng = np.random.default_rng(0)
    centres = {("a", "a1"): 0.0, ("a", "a2"): 0.5, ("b", "b1"): 10.0, ("b", "b2"): -3.0}
    rows = []
    for (label, specimen), centre in centres.items():
        for load in (0, 1):
            for segment in range(6):
                rows.append(
                    {
                        "record_id": f"{specimen}-{load}",
                        "specimen": specimen,
                        "health_state": label,
                        "x": centre + 0.05 * rng.standard_normal(),
                    }
                )
    return pd.DataFrame(rows)


def test_a_specimen_only_its_own_records_show_is_found_by_record_and_lost_by_specimen():
    frame = segments()
    b2 = frame["specimen"] == "b2"
    by_record = measured_holdout.held_out_calls(
        frame, ["x"], "record_id", "knn", {"n_neighbors": 3}, 0
    )
    by_specimen = measured_holdout.held_out_calls(
        frame, ["x"], "specimen", "knn", {"n_neighbors": 3}, 0
    )
    assert (by_record[b2] == "b").all()  # its other load trains
    assert (by_specimen[b2] == "a").all()  # nothing like it trains
    assert (by_specimen[frame["specimen"] == "a1"] == "a").all()
