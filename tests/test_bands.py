"""Band-spectrum names and their standardisation per channel (condmon.bands), and the SVM and
KNN that take it (`classifiers.<name>.standardize`)."""

import numpy as np
import pytest
from sklearn.preprocessing import StandardScaler

from condmon.bands import BandScaler, band_blocks
from condmon.classifiers import make_classifier
from condmon.train import build_model, fit_with_metadata

CHANNELS = ("A1_x", "A2_y")
NAMES = [f"res_{c}_pinion_b{k:02d}" for c in CHANNELS for k in range(6)] + [
    f"res_{c}_pinion_FM4" for c in CHANNELS
]


def features(rng, n=200):
    """Band spectra whose bands vary unequally (the last band of each channel ten times less
    than the others) and two indicators on their own scales."""
    bands = rng.normal(0.0, 1.0, (n, 2, 6)) * np.array([1, 1, 1, 1, 1, 0.1]) + np.arange(6)
    indicators = rng.normal([5.0, -3.0], [2.0, 0.5], (n, 2))
    return np.hstack([bands.reshape(n, -1), indicators])


def test_band_blocks_are_each_channels_bands_in_order():
    blocks = band_blocks(NAMES)
    assert [list(b) for b in blocks] == [list(range(6)), list(range(6, 12))]
    assert band_blocks(["rms_A1_x", "kurtosis_A1_x"]) == []


def test_channel_scaling_keeps_each_spectrums_shape_and_scales_the_rest_alone():
    rng = np.random.default_rng(0)
    x = features(rng)
    scaler = BandScaler("channel").fit(x, feature_names=NAMES)
    scaled = scaler.transform(x)
    for block in band_blocks(NAMES):
        # one mean and scale per block: the bands' differences keep their ratios
        assert len(set(np.round(scaler.scale_[block], 12))) == 1
        np.testing.assert_allclose(scaled[:, block].mean(), 0.0, atol=1e-12)
        np.testing.assert_allclose(scaled[:, block].std(), 1.0, rtol=1e-12)
        np.testing.assert_allclose(
            np.diff(scaled[:, block], axis=1),
            np.diff(x[:, block], axis=1) / scaler.scale_[block[0]],
        )
    # the quiet last band stays quiet (per feature it would be blown up to unit spread)
    assert scaled[:, 5].std() < 0.2 < StandardScaler().fit_transform(x)[:, 5].std()
    np.testing.assert_allclose(scaled[:, 12:], StandardScaler().fit_transform(x)[:, 12:])
    # without names (a selection before it), or per feature: sklearn's StandardScaler
    for scaler in (BandScaler("channel").fit(x), BandScaler("feature").fit(x, feature_names=NAMES)):
        np.testing.assert_allclose(scaler.transform(x), StandardScaler().fit_transform(x))
    with pytest.raises(ValueError, match="standardize='block'"):
        BandScaler("block").fit(x)


@pytest.mark.parametrize("name", ["svm", "knn"])
def test_the_classifiers_take_the_names_through_the_train_stages_routing(name):
    """`standardize: channel` builds the BandScaler, and the train stage's fit hands it the
    feature names; the default stays sklearn's StandardScaler; a selection before it takes them."""
    rng = np.random.default_rng(1)
    x, y = features(rng), np.repeat(["healthy", "pitting"], 100)
    model = make_classifier(name, {"standardize": "channel"}, seed=0)
    fit_with_metadata(model, x, y, feature_names=NAMES, groups=np.arange(len(y)))
    assert [list(b) for b in model.named_steps["scale"].blocks_] == [
        list(range(6)),
        list(range(6, 12)),
    ]
    assert isinstance(make_classifier(name, {}, seed=0).named_steps["scale"], StandardScaler)
    selected = build_model(name, {"standardize": "channel"}, 0, {"n_features": 4, "cv": 2})
    fit_with_metadata(selected, x, y, feature_names=NAMES, groups=np.arange(len(y)))
    assert selected.predict(x).shape == y.shape
