"""Per-state calibration (calibration.per_state): the CFRP study's "optimal damaged MBD models".

A fault state's first measured record per condition tunes its model's form and severities and
joins the calibration set (never trained on, never tested); its simulated samples then take the
tuned severities."""

import numpy as np
import pandas as pd
import pytest

from conftest import config_of, system_of
from condmon.calibrate import calibrate_state, change_fit
from condmon.hybrid import SplitError, calibration_frame, measured_layout
from condmon.protocols import make_splits
from condmon.plots import state_fit_label
from condmon.report.context import plot_note
from condmon.signals import make_rows
from condmon.systems.gear.parameters import state_model_fields

RESERVE = {"records": [], "calibration_segments": 4, "guard_segments": 1, "blocks": 2}


def bench_records(per_stratum=3):
    rows = [
        (f"{h}-{int(s)}-r{i}", seg, h, s)
        for h in ("healthy", "surface_fault", "missing_tooth")
        for s in (450.0, 1100.0)
        for i in range(per_stratum)
        for seg in range(2)
    ]
    return pd.DataFrame(rows, columns=["record_id", "segment", "health_state", "speed_rpm"])


def test_a_calibrated_states_first_record_per_condition_calibrates_and_never_joins_a_split():
    records = bench_records()
    reserve = dict(RESERVE, fault_states=["missing_tooth"])
    layout = measured_layout(records, "healthy", "speed_rpm", reserve)
    calibrating = set(layout.record_id[layout.fixed_role == "calibration"])
    assert calibrating == {
        "healthy-450-r0",
        "healthy-1100-r0",
        "missing_tooth-450-r0",
        "missing_tooth-1100-r0",
    }
    splits = make_splits(
        records,
        "record_split",
        measured_percent=[0, 100],
        repeats=2,
        seed=1,
        min_test_records=1,
        condition="speed_rpm",
        healthy_state="healthy",
        reserve=reserve,
    )
    tuned = splits[splits.record_id.isin(["missing_tooth-450-r0", "missing_tooth-1100-r0"])]
    assert set(tuned.role) == {"calibration"}
    tested = splits[(splits.role == "test") & splits.record_id.str.startswith("missing_tooth")]
    assert set(tested.record_id) == {
        "missing_tooth-450-r1",
        "missing_tooth-450-r2",
        "missing_tooth-1100-r1",
        "missing_tooth-1100-r2",
    }
    # the calibrate jobs see a state's calibration records and the healthy ones, nothing else
    seen = calibration_frame(
        records, "healthy", "speed_rpm", reserve, states=["missing_tooth", "healthy"]
    )
    assert set(seen.record_id) == calibrating
    assert set(calibration_frame(records, "healthy", "speed_rpm", reserve).record_id) == {
        "healthy-450-r0",
        "healthy-1100-r0",
    }  # the healthy reference and calibration: healthy only


@pytest.mark.parametrize(
    "per_stratum, reserve",
    [
        (3, RESERVE),  # the first healthy record per condition
        (3, dict(RESERVE, healthy_records=2)),
        (3, dict(RESERVE, records=["healthy-1100-r2"])),
        (3, dict(RESERVE, each_condition=True)),
        # one healthy record per condition: split in time
        (1, dict(RESERVE, calibration_segments=1, guard_segments=0, blocks=1)),
    ],
)
def test_the_healthy_records_alone_give_the_calibration_set_of_the_whole_table(
    per_stratum, reserve
):
    """The calibrate jobs read a bench's healthy parts only (they start before its fault records
    are made): the healthy rows alone must give the set the whole table gives the splits."""
    records = bench_records(per_stratum)
    healthy = records[records.health_state == "healthy"]
    whole = calibration_frame(records, "healthy", "speed_rpm", reserve)
    assert len(whole)
    pd.testing.assert_frame_equal(
        calibration_frame(healthy, "healthy", "speed_rpm", reserve), whole
    )


def test_a_state_with_one_record_at_a_condition_or_the_healthy_state_is_refused():
    records = bench_records()
    lonely = records[~records.record_id.isin(["surface_fault-1100-r1", "surface_fault-1100-r2"])]
    with pytest.raises(SplitError, match="'surface_fault' has one record at condition 1100"):
        measured_layout(
            lonely, "healthy", "speed_rpm", dict(RESERVE, fault_states=["surface_fault"])
        )
    with pytest.raises(SplitError, match="is the healthy state"):
        measured_layout(records, "healthy", "speed_rpm", dict(RESERVE, fault_states=["healthy"]))
    with pytest.raises(SplitError, match="no measured 'spall' records"):
        measured_layout(records, "healthy", "speed_rpm", dict(RESERVE, fault_states=["spall"]))


def test_a_tuned_state_model_sets_each_samples_severity_within_its_spread():
    drawn = {"spall_face": (0.1, 0.6)}
    exact = state_model_fields(
        {
            "variant": "spall",
            "parameters": {"spall_depth": 2e-5, "spall_width": 0.3},
            "spread": 0.0,
        },
        drawn,
        seed=4,
    )
    assert exact["spall_depth"] == 2e-5
    assert exact["spall_face"] == pytest.approx((0.2, 0.5))  # the width about the drawn centre
    pitting = {
        "variant": "pitting",
        "parameters": {"pit_depth": 3e-5, "pitted_area": 0.95},
        "spread": 0.1,
    }
    values = [state_model_fields(pitting, drawn, seed) for seed in range(50)]
    assert {v["surface_fault_model"] for v in values} == {"pitting"}
    depths = np.array([v["pit_depth"] for v in values])
    assert depths.min() >= 2.7e-5 and depths.max() <= 3.3e-5 and depths.std() > 1e-6
    assert max(v["pitted_area"] for v in values) <= 1.0  # a share stays a share
    assert state_model_fields(pitting, drawn, 3) == state_model_fields(pitting, drawn, 3)


def test_the_twins_stay_twins_a_state_model_draws_from_no_shared_stream():
    """sample_parameters hands the state model on without a draw from the job's stream, so with
    features.healthy_reference sample i is the same machine in every health state."""
    system = system_of("config/config.yaml")
    calibrated = {
        "contact_law": "flores",
        "parameters": {"mesh_stiffness": 5e8},
        "state_models": {
            "missing_tooth": {
                "variant": "missing_tooth",
                "parameters": {"missing_share": 0.7},
                "spread": 0.1,
            }
        },
    }
    simulation = {"seed": 1}
    draws = {}
    for state in ("healthy", "missing_tooth"):
        rng = np.random.default_rng(5)
        values = system.sample_parameters(calibrated, state, rng, simulation)
        draws[state] = (
            values.pop("mesh_stiffness"),
            rng.integers(2**32),
            values.get("state_model"),
        )
    assert draws["healthy"][:2] == draws["missing_tooth"][:2]
    assert draws["healthy"][2] is None and draws["missing_tooth"][2]["parameters"] == {
        "missing_share": 0.7
    }


@pytest.mark.slow  # a CMA-ES calibration: 14 gear simulations
def test_per_state_calibration_finds_the_broken_share_of_a_tooth():
    """ "Measured" records of the model itself (another seed: other gear errors) with 0.6 of a
    tooth's profile broken off; CMA-ES over the share in [0.3, 1.0] on their change of the
    spectrum from healthy finds it. The gears are fine (grade 4, a third of its tolerances), so
    every tooth carries load: with coarser ones a tooth standing back hides its break, and no
    record could tell the share."""
    config = config_of(
        "config/config.yaml",
        {
            "rig": {"segment_seconds": 0.5},
            "model": {
                "fault_severity": {"missing_share": [0.3, 1.0]},
                "gear_errors": {"grade": [4, 4], "deviation_share": [0.3, 0.3]},
            },
            "calibration": {
                "sim_seconds": 0.5,
                "per_state": {"states": ["missing_tooth"], "population": 4, "generations": 3},
            },
        },
    )
    from condmon.systems import get_system

    system = get_system(config)
    calibrated = {
        "contact_law": config["model"]["contact_law"],
        "parameters": {"mesh_stiffness": config["model"]["mesh_stiffness"]},
    }
    truth = {"variant": "missing_tooth", "parameters": {"missing_share": 0.6}}
    rows = []
    for state, model in (("healthy", None), ("missing_tooth", truth)):
        signals = system.simulate_state(calibrated, state, model, 1100.0, 1.0, seed=11)
        rows += make_rows(
            f"{state}-r0",
            "measured",
            state,
            1100.0,
            10.0,
            system.output_rate_hz,
            signals,
            segment_length=system.segment_length,
        )
    frame = pd.DataFrame(rows)
    result, history = calibrate_state(
        system,
        frame,
        "missing_tooth",
        calibrated,
        config["calibration"],
        config["features"]["spectrum"],
        config["features"]["channels"],
    )
    print(result, history[["cost", "missing_share"]])
    assert len(history) == 12 and result["speeds_rpm"] == [1100.0]
    assert result["records"] == ["missing_tooth-r0"] and result["parameters"].keys() == {
        "missing_share"
    }
    assert result["parameters"]["missing_share"] == pytest.approx(0.6, abs=0.15)
    assert result["cost"] < history["cost"].max()
    # the model's own records: its change is of the measured change's form (other gear errors:
    # much of it differs all the same, so it explains less than none of it)
    assert result["identified"] and "warning" not in result and result["at_bounds"] == []
    assert result["change_correlation"] > 0.15 and result["no_change_cost"] > 0


def test_a_model_whose_change_is_not_the_measured_ones_is_not_identified():
    """The default bench's per-state calibration of its missing tooth: the model's change of the
    spectrum correlated at -0.2 with the records', and no fault fitted better than any (the search
    settled near the range's lower bound). change_fit says so; of a model of the measured form, not."""
    rng = np.random.default_rng(3)
    measured = 10 ** rng.normal(0.0, 0.1, (3, 4, 50))
    same = change_fit(measured, measured)
    assert same["explained_share"] == pytest.approx(1.0) and same[
        "change_correlation"
    ] == pytest.approx(1.0)
    assert same["identified"]
    half = change_fit(np.sqrt(measured), measured)  # the right form at half the size (in decades)
    assert half["explained_share"] == pytest.approx(0.75) and half["identified"]
    opposite = change_fit(1 / measured, measured)
    assert opposite["explained_share"] == pytest.approx(-3.0) and opposite[
        "change_correlation"
    ] == pytest.approx(-1.0)
    assert not opposite["identified"]
    unrelated = change_fit(10 ** rng.normal(0.0, 0.1, (3, 4, 50)), measured)
    assert unrelated["explained_share"] < 0 and not unrelated["identified"]
    nothing = change_fit(np.ones_like(measured), measured)
    assert (
        nothing["explained_share"] == 0.0
        and nothing["change_correlation"] == 0.0
        and not nothing["identified"]
    )
    assert nothing["no_change_cost"] == pytest.approx(np.mean(np.log10(measured) ** 2))
    assert state_fit_label(dict(opposite)).startswith(
        "NOT IDENTIFIED by its records: explains -300%"
    )
    assert state_fit_label(dict(same)) == "explains 100% of the measured change (correlation 1.00)"
    assert state_fit_label({"model_variant": "pitting"}) == ""


def test_per_state_calibration_is_checked_before_any_job():
    from condmon.config import ConfigError

    with pytest.raises(ConfigError, match="'crack' is not a fault state of this run"):
        config_of("config/config.yaml", {"calibration": {"per_state": {"states": ["crack"]}}})
    with pytest.raises(ConfigError, match="stiffness_loss removes no material"):
        config_of(
            "config/config.yaml",
            {
                "model": {"surface_fault_model": "stiffness_loss"},
                "calibration": {"per_state": {"states": ["surface_fault"]}},
            },
        )
    with pytest.raises(ConfigError, match="the bearing system has no per-state calibration"):
        config_of("config/cwru.yaml", {"calibration": {"per_state": {"states": ["ball"]}}})
    config_of(
        "config/config.yaml",
        {"calibration": {"per_state": {"states": ["surface_fault", "missing_tooth"]}}},
    )


def test_every_plot_says_which_fault_models_their_own_records_tuned():
    differences = [{"difference": "d", "handled": "calibrated"}]
    note = plot_note("run", "virtual_bench", differences, state_models=("missing_tooth",))
    assert "PER-STATE CALIBRATION: missing_tooth models tuned" in note
    assert "PER-STATE" not in plot_note("run", "virtual_bench", differences)


def test_the_report_draws_each_tuned_states_convergence(tmp_path):
    from condmon.report.calibration import state_convergence_plots

    history = pd.DataFrame(
        {
            "generation": [0, 0, 1, 1],
            "evaluation": [0, 1, 2, 3],
            "model_variant": ["pitting", "pitting", "pitting", "pitting"],
            "cost": [0.2, 0.08, 0.06, 0.1],
            "seconds": 1.0,
            "error": "",
        }
    )
    history.to_parquet(tmp_path / "history.parquet")
    note = plot_note("run", "virtual_bench", state_models=("surface_fault",))
    fit = {
        "no_change_cost": 0.07,
        "explained_share": -0.2,
        "change_correlation": -0.1,
        "identified": False,
    }
    names = state_convergence_plots(
        {"surface_fault": {"model_variant": "pitting", **fit}},
        {"surface_fault": tmp_path / "history.parquet"},
        tmp_path,
        note,
    )
    assert names == ["calibration_convergence_state_surface_fault.png"]
    assert (tmp_path / "calibration_convergence_state_surface_fault.png").stat().st_size > 10_000
