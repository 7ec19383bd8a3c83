"""Band-spectrum features by name, and their standardisation per sensor channel.

The feature families name their band spectra per channel: Hz bands (``fft_<channel>_<band>Hz``),
a system's order bands (``ord_<channel>_<order>x``) or the residual signatures' bands of each
channel and shaft (``res_<channel>_<shaft>_b<k>``). A classifier that standardises every band on
its own magnifies the small deviations of the bands that vary least in simulation, and a
machine's own band profile, one to two simulated spreads off in several bands at once, then
reads as a fault; one mean and scale per channel's block keeps each spectrum's shape (the CNN
ensemble's ``standardize: channel``, and `BandScaler` for the SVM and KNN).
"""

from __future__ import annotations

import re

import numpy as np
from sklearn.base import BaseEstimator, TransformerMixin
from sklearn.utils.validation import check_is_fitted

# band spectra per channel: Hz bands, or a system's order bands when there are no Hz bands
# (features.kind: order), or else the residual signatures' bands of each channel and shaft
# (features.kind: residual)
FEATURE_NAME = re.compile(r"fft_(?P<channel>.+)_(?P<band>[0-9.]+)Hz")
ORDER_NAME = re.compile(r"ord_(?P<channel>.+)_(?P<band>[0-9.]+)x")
RESIDUAL_NAME = re.compile(r"res_(?P<channel>.+)_b(?P<band>[0-9]+)")
STANDARDIZE = ("feature", "channel")


def band_pattern(feature_names):
    """The band-spectrum names among `feature_names`: the Hz bands if there are any, else the
    order bands if any, else the residual bands."""
    names = [str(name) for name in feature_names]
    return next(
        (
            pattern
            for pattern in (FEATURE_NAME, ORDER_NAME)
            if any(pattern.fullmatch(n) for n in names)
        ),
        RESIDUAL_NAME,
    )


def channels_from_feature_names(feature_names) -> int | None:
    """Number of sensor channels in band-spectrum names (``fft_<channel>_<band>Hz``, or
    ``ord_<channel>_<order>x`` without Hz bands; concatenated channel blocks of equal size), or
    None if the names do not follow that pattern."""
    channels = []
    pattern = band_pattern(feature_names)
    for name in feature_names:
        match = pattern.fullmatch(str(name))
        if match is None:
            return None
        channel = match["channel"]
        if not channels or channels[-1] != channel:
            if channel in channels:
                return None  # not contiguous blocks
            channels.append(channel)
    if not channels or len(feature_names) % len(channels):
        return None
    return len(channels)


def spectrum_columns(feature_names) -> np.ndarray | None:
    """Positions of the band-spectrum names when other features sit beside them (``spectrum+order``:
    the Hz bands; ``order``: the order bands, not the condition indicators); None when all or none
    of the names are spectrum bands (then every column is an input, as before)."""
    if feature_names is None:
        return None
    names = [str(name) for name in feature_names]
    pattern = band_pattern(names)
    columns = np.array(
        [i for i, name in enumerate(names) if pattern.fullmatch(name)], dtype=np.int64
    )
    if len(columns) in (0, len(names)):
        return None
    return columns


def band_blocks(feature_names) -> list[np.ndarray]:
    """The positions of each channel's band-spectrum names (`band_pattern`), one array per
    channel in order of appearance; none without such names."""
    names = [str(name) for name in feature_names]
    pattern = band_pattern(names)
    blocks: dict[str, list[int]] = {}
    for i, name in enumerate(names):
        match = pattern.fullmatch(name)
        if match is not None:
            blocks.setdefault(match["channel"], []).append(i)
    return [np.array(positions, dtype=np.int64) for positions in blocks.values()]


class BandScaler(TransformerMixin, BaseEstimator):
    """Standardisation from the training data: every feature on its own (``standardize=
    "feature"``, sklearn's StandardScaler) or, with ``"channel"``, each channel's band spectrum
    as one block (one mean and scale over its bands and samples, which keeps the spectrum's
    shape) and every other feature on its own. ``fit`` takes the feature names (sklearn metadata
    routing); without them every feature is scaled on its own. A constant input keeps scale 1."""

    __metadata_request__fit = {"feature_names": True}

    def __init__(self, standardize: str = "feature"):
        self.standardize = standardize

    def fit(self, X, y=None, feature_names=None):
        if self.standardize not in STANDARDIZE:
            raise ValueError(f"standardize={self.standardize!r}: choose one of {list(STANDARDIZE)}")
        X = np.asarray(X, dtype=np.float64)
        mean, scale = X.mean(axis=0), X.std(axis=0)
        self.blocks_ = (
            band_blocks(feature_names)
            if self.standardize == "channel" and feature_names is not None
            else []
        )
        for block in self.blocks_:
            mean[block], scale[block] = X[:, block].mean(), X[:, block].std()
        self.mean_, self.scale_ = mean, np.where(scale > 1e-12, scale, 1.0)
        self.n_features_in_ = X.shape[1]
        return self

    def transform(self, X):
        check_is_fitted(self, "mean_")
        return (np.asarray(X, dtype=np.float64) - self.mean_) / self.scale_
