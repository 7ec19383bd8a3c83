"""Calibration of the bearing rig: the study's feature cost, and a folder without a healthy record."""

import numpy as np
import pandas as pd
import pytest

from conftest import system_of
from condmon.systems.bearing.model import build_rig_parameters, rig_settings
from condmon.calibrate import spectrum_cost
from condmon.systems.bearing.calibration import CALIBRATION_FEATURES, COSTS, calibrate_rig
from condmon.signals import make_rows
from condmon.models.bearing.rig import simulate_rig

NUMERICS = {"output_rate_hz": 12000.0, "oversampling": 4, "settle_time": 0.05}
SPECTRUM = {
    "f_min_hz": 0.0,
    "f_max_hz": 6000.0,
    "resolution_hz": 50.0,
    "scale": "log",
    "band_statistic": "rms",
}
CALIBRATION = {
    "parameters": {"noise_rms": {"low": 0.05, "high": 2.0, "log": True}},
    "population": 4,
    "generations": 2,
    "sigma0": 0.3,
    "sim_seconds": 0.35,
    "resolution_hz": 50.0,
    "seed": 3,
    "cost": "features_eq6",
}
SEGMENT = 2048


def rig(model=None):
    """The bearing system with these numerics, segments and nominal `bearing.model` values."""
    return system_of(
        ".test/config/cwru-smoke.yaml",
        {
            "bearing": {
                "segment_length": SEGMENT,
                "numerics": {"oversampling": 4, "settle_time": 0.05},
                "model": model or {},
            }
        },
    )


def rig_table(health_state, noise_rms, seconds=0.7, seed=0):
    """A 'measured' table made by the rig itself at a known sensor noise."""
    params = build_rig_parameters({}, "normal", 1797.0, noise_rms=noise_rms)
    signal = simulate_rig(params, rig_settings(NUMERICS, seconds), np.random.default_rng(seed))[
        "DE"
    ]
    return pd.DataFrame(
        make_rows(
            "rec",
            "measured",
            health_state,
            1796.0,
            0.0,
            12000.0,
            {"DE": signal},
            segment_length=SEGMENT,
        )
    )


def test_feature_cost_is_relative_per_feature():
    measured = np.array([[[1.0, 100.0]]])
    assert spectrum_cost(
        np.array([[[1.1, 100.0]]]), measured, "features_eq6", COSTS
    ) == pytest.approx(0.01)
    assert spectrum_cost(
        np.array([[[1.0, 110.0]]]), measured, "features_eq6", COSTS
    ) == pytest.approx(0.01)
    # the bearing system declares it; the shared calibration knows only the spectral costs
    with pytest.raises(ValueError, match="unknown calibration cost 'features_eq6'"):
        spectrum_cost(measured, measured, "features_eq6")


@pytest.mark.slow
def test_feature_cost_calibration_moves_the_noise_towards_the_record():
    frame = rig_table("normal", noise_rms=1.0)
    system = rig({"noise_rms": 0.1})  # nominal far below the record's noise
    result, history, spectra = calibrate_rig(system, frame, CALIBRATION, SPECTRUM)
    assert result["calibrated"] and result["cost_function"] == "features_eq6"
    assert result["cost"] < 0.5 * result["nominal_cost"]
    assert result["parameters"]["noise_rms"] > 0.3
    assert len(history) == 8 and len(CALIBRATION_FEATURES) == 7
    assert set(spectra.columns) >= {"speed_rpm", "channel", "freq_hz", "measured", "calibrated"}


def test_without_a_healthy_record_the_nominal_parameters_stay_and_say_why():
    frame = rig_table("inner_race", noise_rms=0.3)
    result, history, spectra = calibrate_rig(rig(), frame, CALIBRATION, SPECTRUM)
    assert result["calibrated"] is False and "normal" in result["reason"]
    assert result["parameters"] == {"noise_rms": 0.3} and result["evaluations"] == 0
    assert spectra["measured"].isna().all() and spectra["calibrated"].gt(0).all()
    with pytest.raises(ValueError, match="not bearing.model parameters"):
        calibrate_rig(
            rig(),
            frame,
            dict(CALIBRATION, parameters={"mesh_stiffness": {"low": 1.0, "high": 2.0}}),
            SPECTRUM,
        )
