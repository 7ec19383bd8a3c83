"""An ensemble of small one-dimensional CNNs on the concatenated channel spectra (PyTorch).

The helical-gear study classified the drivetrain's health with an ensemble of 10 1D-CNNs
trained on simulated FFT spectra (25 epochs, Adam, learning rate 0.002, categorical
cross-entropy). ``CNNEnsembleClassifier`` is that classifier as a scikit-learn estimator:

- input: the flat feature vector of the features table (``fft_<channel>_<band>Hz``, channels
  concatenated), reshaped to (input channels, bands): one input channel per sensor channel, so
  the convolutions slide along frequency over all sensors at once. When other feature families
  sit beside the spectra (``features.kind: spectrum+order``) and ``fit`` gets the feature names,
  it reads the spectrum columns only and says so in the log (``feature_columns_``); with
  ``side_features`` the others (the condition indicators a feature family gives beside its bands)
  join the network after the convolutions (``side_columns_``),
  each standardised as the SVM standardises it. Standardisation uses the data given to ``fit``
  only, never the test set: ``standardize="channel"`` (default) one mean and std per sensor
  channel, which keeps the shape of each spectrum (its peaks over the floor); ``"feature"`` per
  band as the SVM does. On the virtual bench, per-band scaling made
  the members learn simulation-only details (healthy measured records read as surface faults,
  about 0.75 accuracy without measured data, against 0.95+ per channel).
- network per member: optional average pooling of the input (``input_pool``, coarser bands,
  fewer operations; it has no weights, so training pools once), then [Conv1d -> BatchNorm
  (``batch_norm``) -> ReLU -> MaxPool1d] per ``conv_channels`` entry, flatten, [Linear -> ReLU
  -> Dropout] per ``dense_units`` entry, Linear to the classes. Batch normalisation matters:
  without it the members sat for many epochs on the plateau "missing tooth found, healthy vs
  surface fault at chance" (loss 2/3 ln 2) and early stopping kept that state.
  Side features: on the gear rig's residual bands alone the ensemble missed at the lowest speed,
  on some virtual benches, a fault the SVM (which reads the indicators too) found; with them
  joined it finds it as well (docs/experiments/2026-12-06-cnn-side-features.md).
- ensemble: ``members`` networks, each with its own seed (weights, batch order, validation
  split); the prediction is the class of the mean member probability, and the spread of the
  members' probability of that class (std) is the uncertainty of the prediction.
- training: Adam, cross-entropy, at most ``epochs`` epochs; early stopping on a validation split
  drawn from the training data (stratified by class and, given ``groups``, by whole records, so
  segments of one record never sit on both sides); the weights of the best validation loss are
  kept.
- reproducibility: every random stream is derived from ``random_state`` and the member index;
  training runs with ``torch.use_deterministic_algorithms`` and ``threads`` intra-op threads
  (default 1: the result of a float reduction can depend on the thread count). So the same data
  and seed give the same model on the same machine. The GPU is used when present
  (``device="auto"``); its results are deterministic too but differ from the CPU's in the last
  bits.
- serialisation: the fitted estimator holds the members' state dicts (CPU tensors) and pickles
  with joblib like the sklearn pipelines; ``to_torch_module`` gives one ``nn.Module`` with the
  standardisation folded in (raw features in, mean probabilities out) for MLflow.
"""

from __future__ import annotations

import contextlib
import copy
import logging
import os
import time

import numpy as np
import torch
from sklearn.base import BaseEstimator, ClassifierMixin
from sklearn.utils.validation import check_is_fitted
from torch import nn

from condmon.bands import channels_from_feature_names, spectrum_columns
from condmon.seeds import derive_seed

log = logging.getLogger(__name__)
# An epoch's progress line at most this often (and the first epoch's), so a long fit shows it is
# alive without thousands of lines in the job log.
EPOCH_LOG_SECONDS = 10.0

HISTORY_COLUMNS = ["member", "epoch", "train_loss", "train_accuracy", "val_loss", "val_accuracy"]
DEVICES = ("auto", "cpu", "cuda")
STANDARDIZE = ("channel", "feature")


class CNNConfigError(ValueError):
    """A CNN parameter or the input layout is unusable."""


# --------------------------------------------------------------------------- network


class SpectrumCNN(nn.Module):
    """One member: (N, channels, bands) [and side features (N, k)] -> logits (N, n_classes).

    ``prepare`` (the fixed input pooling) and the learnable rest (``learn``: ``body``, and with
    side features ``head``, the dense layers they join) are separate so training can pool the
    inputs once instead of in every step.
    """

    def __init__(
        self,
        input_shape: tuple[int, int],
        n_classes: int,
        conv_channels,
        kernel_size: int,
        pool_size: int,
        input_pool: int,
        dense_units,
        dropout: float,
        batch_norm: bool = False,
        side_features: int = 0,
    ):
        super().__init__()
        in_channels, length = input_shape
        layers, in_length = [], length
        self.prepare = nn.AvgPool1d(input_pool) if input_pool > 1 else nn.Identity()
        length //= input_pool
        channels = in_channels
        for out_channels in conv_channels:
            layers.append(nn.Conv1d(channels, out_channels, kernel_size, padding=kernel_size // 2))
            if batch_norm:
                layers.append(nn.BatchNorm1d(out_channels))
            layers += [nn.ReLU(), nn.MaxPool1d(pool_size)]
            channels = out_channels
            # padding k//2 keeps the length (odd k) or adds one (even k); pooling floors it
            length = (length + 2 * (kernel_size // 2) - kernel_size + 1) // pool_size
            if length < 1:
                raise CNNConfigError(
                    f"the spectrum of {in_length} bands per channel is pooled away: input_pool "
                    "x pool_size^(number of conv layers) must not exceed the bands per channel"
                )
        layers.append(nn.Flatten())
        width = channels * length + side_features
        head = []
        for units in dense_units:
            head += [nn.Linear(width, units), nn.ReLU(), nn.Dropout(dropout)]
            width = units
        head.append(nn.Linear(width, n_classes))
        # without side features one sequence, as the models fitted before them hold it
        self.body = nn.Sequential(*layers) if side_features else nn.Sequential(*layers, *head)
        self.head = nn.Sequential(*head) if side_features else None

    def learn(self, x, side=None):
        """Logits of prepared inputs `x` (N, channels, bands after `prepare`) and, with side
        features, `side` (N, side features), joined after the convolutions."""
        if self.head is None:
            return self.body(x)
        return self.head(torch.cat([self.body(x), side], dim=1))

    def forward(self, x, side=None):
        return self.learn(self.prepare(x), side)


class EnsembleModule(nn.Module):
    """The fitted ensemble as one module: raw features (N, F) -> mean probabilities (N, K).

    The standardisation is folded in as buffers, so it takes the same inputs as the sklearn
    models; ``classes`` names the output columns.
    """

    def __init__(self, members, mean, scale, input_shape, classes, columns=None, side=None):
        super().__init__()
        self.members = nn.ModuleList(members)
        # the spectrum columns among the raw features (None: all of them)
        self.register_buffer("columns", _long(columns))
        self.register_buffer("mean", torch.as_tensor(mean, dtype=torch.float32))
        self.register_buffer("scale", torch.as_tensor(scale, dtype=torch.float32))
        # the side features' columns, mean and scale (None: no side features)
        side_columns, side_mean, side_scale = side if side is not None else (None, None, None)
        self.register_buffer("side_columns", _long(side_columns))
        self.register_buffer("side_mean", _float(side_mean))
        self.register_buffer("side_scale", _float(side_scale))
        self.input_shape = tuple(int(n) for n in input_shape)
        self.classes = [str(c) for c in classes]

    def forward(self, x):
        x = torch.as_tensor(x, dtype=torch.float32)
        side = None
        if self.side_columns is not None:
            side = (x[:, self.side_columns] - self.side_mean) / self.side_scale
        if self.columns is not None:
            x = x[:, self.columns]
        x = ((x - self.mean) / self.scale).reshape(-1, *self.input_shape)
        return torch.stack([torch.softmax(m(x, side), dim=1) for m in self.members]).mean(dim=0)


def _long(values):
    return None if values is None else torch.as_tensor(values, dtype=torch.long)


def _float(values):
    return None if values is None else torch.as_tensor(values, dtype=torch.float32)


# --------------------------------------------------------------------------- helpers


def resolve_device(device: str) -> torch.device:
    if device not in DEVICES:
        raise CNNConfigError(f"device={device!r}; choose one of {DEVICES}")
    if device == "auto":
        device = "cuda" if torch.cuda.is_available() else "cpu"
    if device == "cuda" and not torch.cuda.is_available():
        raise CNNConfigError("device='cuda' but PyTorch sees no GPU; use 'auto' or 'cpu'")
    return torch.device(device)


@contextlib.contextmanager
def torch_settings(threads: int, device: torch.device):
    """Deterministic algorithms and a fixed intra-op thread count for the block, then the
    previous process-wide settings again (the estimator must not leak global state)."""
    previous_threads = torch.get_num_threads()
    previous_deterministic = torch.are_deterministic_algorithms_enabled()
    previous_benchmark = torch.backends.cudnn.benchmark
    if device.type == "cuda":
        # cuBLAS is only deterministic with a fixed workspace; read when CUDA starts up
        os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")
    torch.set_num_threads(int(threads))
    torch.use_deterministic_algorithms(True)
    torch.backends.cudnn.benchmark = False
    # the members seed torch's global generators; fork them so the caller's streams survive
    devices = [device.index or 0] if device.type == "cuda" else []
    try:
        with torch.random.fork_rng(devices=devices):
            yield
    finally:
        torch.set_num_threads(previous_threads)
        torch.use_deterministic_algorithms(previous_deterministic)
        torch.backends.cudnn.benchmark = previous_benchmark


def validation_split(y_codes: np.ndarray, groups, fraction: float, rng: np.random.Generator):
    """Boolean mask of validation rows: per class, ``fraction`` of its groups (records) at
    random, at least one if the class has two or more, never all of them."""
    val = np.zeros(len(y_codes), dtype=bool)
    if fraction <= 0:
        return val
    groups = np.arange(len(y_codes)) if groups is None else np.asarray(groups)
    for code in np.unique(y_codes):
        in_class = y_codes == code
        class_groups = np.unique(groups[in_class])
        if len(class_groups) < 2:
            continue
        n_val = min(max(1, int(round(fraction * len(class_groups)))), len(class_groups) - 1)
        chosen = rng.choice(class_groups, size=n_val, replace=False)
        val |= in_class & np.isin(groups, chosen)
    return val


# --------------------------------------------------------------------------- estimator


class CNNEnsembleClassifier(ClassifierMixin, BaseEstimator):
    """Ensemble of 1D-CNNs on concatenated spectra; see the module docstring.

    ``fit(X, y, feature_names=None, groups=None)``: ``feature_names`` lets
    ``input_channels="auto"`` find the sensor channels; ``groups`` (record ids) keeps records
    whole in the validation split. Both are requested for ``fit`` (sklearn metadata routing),
    so a Pipeline or the training loop passes them on.
    """

    __metadata_request__fit = {"feature_names": True, "groups": True}

    def __init__(
        self,
        members=10,
        epochs=25,
        batch_size=64,
        learning_rate=0.002,
        conv_channels=(4, 8),
        kernel_size=7,
        pool_size=4,
        input_pool=2,
        dense_units=(16,),
        dropout=0.3,
        batch_norm=True,
        standardize="channel",
        side_features=False,
        validation_fraction=0.2,
        patience=5,
        input_channels="auto",
        device="auto",
        threads=1,
        random_state=0,
    ):
        self.members = members
        self.epochs = epochs
        self.batch_size = batch_size
        self.learning_rate = learning_rate
        self.conv_channels = conv_channels
        self.kernel_size = kernel_size
        self.pool_size = pool_size
        self.input_pool = input_pool
        self.dense_units = dense_units
        self.dropout = dropout
        self.batch_norm = batch_norm
        self.validation_fraction = validation_fraction
        self.patience = patience
        self.input_channels = input_channels
        self.device = device
        self.threads = threads
        self.standardize = standardize
        self.side_features = side_features
        self.random_state = random_state

    # -- checks ---------------------------------------------------------------------------
    def _check_params(self) -> None:
        positive = {
            "members": self.members,
            "epochs": self.epochs,
            "batch_size": self.batch_size,
            "kernel_size": self.kernel_size,
            "pool_size": self.pool_size,
            "input_pool": self.input_pool,
            "patience": self.patience,
            "threads": self.threads,
        }
        for name, value in positive.items():
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise CNNConfigError(f"cnn parameter {name}={value!r}: must be an integer >= 1")
        for name in ("conv_channels", "dense_units"):
            values = list(getattr(self, name))
            if any(
                isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 1 for v in values
            ):
                raise CNNConfigError(
                    f"cnn parameter {name}={values!r}: must be a list of integers >= 1"
                )
        if not list(self.conv_channels):
            raise CNNConfigError(
                "cnn parameter conv_channels is empty: a CNN needs at least one convolution layer"
            )
        if not (self.learning_rate > 0):
            raise CNNConfigError(
                f"cnn parameter learning_rate={self.learning_rate!r}: must be positive"
            )
        if not (0 <= self.dropout < 1):
            raise CNNConfigError(f"cnn parameter dropout={self.dropout!r}: must be in [0, 1)")
        if not isinstance(self.side_features, (bool, np.bool_)):
            raise CNNConfigError(
                f"cnn parameter side_features={self.side_features!r}: must be true or false"
            )
        if self.standardize not in STANDARDIZE:
            raise CNNConfigError(
                f"cnn parameter standardize={self.standardize!r}: choose one of {STANDARDIZE}"
            )
        if not (0 <= self.validation_fraction < 1):
            raise CNNConfigError(
                f"cnn parameter validation_fraction={self.validation_fraction!r}: must be in [0, 1)"
            )
        if self.input_channels != "auto" and (
            isinstance(self.input_channels, bool)
            or not isinstance(self.input_channels, (int, np.integer))
            or self.input_channels < 1
        ):
            raise CNNConfigError(
                f"cnn parameter input_channels={self.input_channels!r}: 'auto' or an integer >= 1"
            )
        resolve_device(self.device)

    def _input_shape(self, n_features: int, feature_names) -> tuple[int, int]:
        if self.input_channels == "auto":
            channels = (
                channels_from_feature_names(feature_names) if feature_names is not None else None
            )
            if channels is None:
                channels = 1  # unknown layout: the whole vector is one sequence
                log.info(
                    "input_channels=auto: no band-spectrum feature names per channel, "
                    "treating the %d features as one channel",
                    n_features,
                )
        else:
            channels = int(self.input_channels)
        if n_features % channels:
            raise CNNConfigError(
                f"cnn parameter input_channels={channels}: {n_features} "
                "features do not split into that many equal channel blocks"
            )
        return channels, n_features // channels

    # -- fitting --------------------------------------------------------------------------
    def _new_member(self, n_classes: int) -> SpectrumCNN:
        return SpectrumCNN(
            tuple(self.input_shape_),
            n_classes,
            list(self.conv_channels),
            int(self.kernel_size),
            int(self.pool_size),
            int(self.input_pool),
            list(self.dense_units),
            float(self.dropout),
            bool(self.batch_norm),
            0 if getattr(self, "side_columns_", None) is None else len(self.side_columns_),
        )

    def fit(self, X, y, feature_names=None, groups=None):
        self._check_params()
        X = np.asarray(X, dtype=np.float32)
        y = np.asarray(y)
        if X.ndim != 2:
            raise CNNConfigError(f"X must be 2-D (samples, features), got shape {X.shape}")
        if len(X) != len(y):
            raise CNNConfigError(f"X has {len(X)} rows but y has {len(y)} labels")
        if not np.isfinite(X).all():
            raise CNNConfigError("X contains NaN or infinite values")
        if groups is not None and len(groups) != len(y):
            raise CNNConfigError(f"groups has {len(groups)} entries for {len(y)} samples")
        self.classes_, codes = np.unique(y, return_inverse=True)
        if len(self.classes_) < 2:
            raise CNNConfigError(f"training data has only class(es) {list(self.classes_)}")
        self.n_features_in_ = X.shape[1]
        self._choose_columns(X.shape[1], feature_names)
        self._fit_standardisation(X)
        device = resolve_device(self.device)
        x_all, side_all = self._standardised(X)
        # the input pooling has no weights: apply it once here, train the body on the result
        x_all = self._new_member(len(self.classes_)).prepare(x_all)
        y_all = torch.from_numpy(codes.astype(np.int64))

        self.members_, self.history_, self.member_info_ = [], [], []
        started = time.perf_counter()
        with torch_settings(self.threads, device):
            for member in range(int(self.members)):
                seed = derive_seed(int(self.random_state), member)
                rng = np.random.default_rng(seed)
                val = validation_split(codes, groups, float(self.validation_fraction), rng)
                state, history, info = self._fit_member(
                    member,
                    seed,
                    (x_all[~val], side_all[~val], y_all[~val]),
                    (x_all[val], side_all[val], y_all[val]),
                    device,
                )
                self.members_.append(state)
                self.history_ += history
                self.member_info_.append(info)
        self.fit_seconds_ = time.perf_counter() - started
        # where it trained (logged with the MLflow run): "cpu", or "cuda:<n> (<GPU name>)"
        self.device_ = (
            f"cuda:{device.index or 0} ({torch.cuda.get_device_name(device)})"
            if device.type == "cuda"
            else "cpu"
        )
        self._modules = None
        return self

    def _choose_columns(self, n_features: int, feature_names) -> None:
        """The band-spectrum columns (`feature_columns_`, None: every column) and, with
        `side_features`, the others as side features (`side_columns_`, else None); the input
        shape of the bands."""
        self.feature_columns_ = spectrum_columns(feature_names)
        self.side_columns_ = None
        if self.feature_columns_ is None:
            self.input_shape_ = self._input_shape(n_features, feature_names)
            return
        others = np.array(
            sorted(set(range(n_features)) - set(self.feature_columns_)), dtype=np.int64
        )
        if self.side_features:
            self.side_columns_ = others
        log.info(
            "CNN: reads the %d band-spectrum features (per channel) and %s the %d others (%s ...)",
            len(self.feature_columns_),
            "joins after its convolutions" if self.side_features else "leaves out",
            len(others),
            ", ".join(str(feature_names[i]) for i in others[:3]),
        )
        self.input_shape_ = self._input_shape(
            len(self.feature_columns_), [feature_names[i] for i in self.feature_columns_]
        )

    def _fit_standardisation(self, X: np.ndarray) -> None:
        """Means and scales from the training data only (a constant input keeps scale 1 rather
        than dividing by zero): the bands per `standardize`, the side features each its own."""
        bands = X if self.feature_columns_ is None else X[:, self.feature_columns_]
        if self.standardize == "feature":
            mean, scale = bands.mean(axis=0, dtype=np.float64), bands.std(axis=0, dtype=np.float64)
        else:
            # one mean/std per input channel keeps the shape of each spectrum (its peaks)
            blocks = bands.reshape(len(bands), *self.input_shape_)
            mean = np.repeat(blocks.mean(axis=(0, 2), dtype=np.float64), self.input_shape_[1])
            scale = np.repeat(blocks.std(axis=(0, 2), dtype=np.float64), self.input_shape_[1])
        self.mean_ = mean.astype(np.float32)
        self.scale_ = np.where(scale > 1e-12, scale, 1.0).astype(np.float32)
        side = X[:, self.side_columns_ if self.side_columns_ is not None else []]
        side_scale = side.std(axis=0, dtype=np.float64)
        self.side_mean_ = side.mean(axis=0, dtype=np.float64).astype(np.float32)
        self.side_scale_ = np.where(side_scale > 1e-12, side_scale, 1.0).astype(np.float32)

    def _standardised(self, X: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
        """(bands (N, channels, bands), side features (N, k; k 0 without them)) of raw features
        `X`, standardised as fitted."""
        columns = getattr(self, "feature_columns_", None)  # absent in models fitted before it
        side_columns = getattr(self, "side_columns_", None)
        bands = X if columns is None else X[:, columns]
        x = torch.from_numpy((bands - self.mean_) / self.scale_).reshape(-1, *self.input_shape_)
        if side_columns is None:
            return x, torch.zeros((len(X), 0))
        return x, torch.from_numpy((X[:, side_columns] - self.side_mean_) / self.side_scale_)

    def _fit_member(self, member, seed, train, validation, device):
        """One member trained on `train` and stopped early on `validation`, each (inputs,
        side features, class codes): (its best state, its history, its info)."""
        torch.manual_seed(seed)  # weight initialisation and dropout masks
        generator = torch.Generator().manual_seed(seed)  # batch order
        net = self._new_member(len(self.classes_)).to(device)
        optimiser = torch.optim.Adam(net.parameters(), lr=float(self.learning_rate))
        loss_fn = nn.CrossEntropyLoss()
        x_train, side_train, y_train = (t.to(device) for t in train)
        x_val, side_val, y_val = (t.to(device) for t in validation)
        has_val = len(y_val) > 0
        best = (np.inf, 0, None)  # validation loss, epoch, state
        history, waited = [], 0
        last_logged = -np.inf
        for epoch in range(1, int(self.epochs) + 1):
            net.train()
            order = torch.randperm(len(y_train), generator=generator).to(device)
            loss_sum, correct = 0.0, 0
            for start in range(0, len(order), int(self.batch_size)):
                batch = order[start : start + int(self.batch_size)]
                optimiser.zero_grad()
                logits = net.learn(x_train[batch], side_train[batch])
                loss = loss_fn(logits, y_train[batch])
                loss.backward()
                optimiser.step()
                loss_sum += loss.item() * len(batch)
                correct += int((logits.argmax(dim=1) == y_train[batch]).sum())
            row = {
                "member": member,
                "epoch": epoch,
                "train_loss": loss_sum / len(y_train),
                "train_accuracy": correct / len(y_train),
                "val_loss": np.nan,
                "val_accuracy": np.nan,
            }
            if has_val:
                net.eval()
                with torch.no_grad():
                    logits = net.learn(x_val, side_val)
                    row["val_loss"] = float(loss_fn(logits, y_val))
                    row["val_accuracy"] = float((logits.argmax(dim=1) == y_val).float().mean())
            history.append(row)
            if time.perf_counter() - last_logged >= EPOCH_LOG_SECONDS:
                last_logged = time.perf_counter()
                log.info(
                    "CNN member %d of %d, epoch %d of at most %d: train loss %.4g, validation loss %.4g, "
                    "validation accuracy %.3f",
                    member + 1,
                    int(self.members),
                    epoch,
                    int(self.epochs),
                    row["train_loss"],
                    row["val_loss"],
                    row["val_accuracy"],
                )
            if not has_val:
                continue
            if row["val_loss"] < best[0]:
                best, waited = (row["val_loss"], epoch, copy.deepcopy(net.state_dict())), 0
            else:
                waited += 1
                if waited >= int(self.patience):
                    break
        if best[2] is not None:
            net.load_state_dict(best[2])
        state = {k: v.detach().cpu().clone() for k, v in net.state_dict().items()}
        info = {
            "member": member,
            "seed": seed,
            "epochs_run": len(history),
            "best_epoch": best[1] if has_val else len(history),
            "best_val_loss": float(best[0]) if has_val else None,
            "n_train": int(len(y_train)),
            "n_val": int(len(y_val)),
        }
        log.info(
            "CNN member %d of %d: %d epochs (best epoch %s, validation loss %s)",
            member + 1,
            int(self.members),
            len(history),
            info["best_epoch"],
            "n/a" if info["best_val_loss"] is None else f"{info['best_val_loss']:.4g}",
        )
        return state, history, info

    # -- prediction -----------------------------------------------------------------------
    def _member_modules(self):
        if getattr(self, "_modules", None) is None:
            modules = []
            for state in self.members_:
                net = self._new_member(len(self.classes_))
                net.load_state_dict(state)
                modules.append(net.eval())
            self._modules = modules
        return self._modules

    def member_proba(self, X) -> np.ndarray:
        """Class probabilities of every member, shape (members, samples, classes)."""
        check_is_fitted(self, "members_")
        X = np.asarray(X, dtype=np.float32)
        if X.ndim != 2 or X.shape[1] != self.n_features_in_:
            raise CNNConfigError(
                f"X has shape {X.shape}; the ensemble was fitted on {self.n_features_in_} features"
            )
        x, side = self._standardised(X)
        # prediction on the CPU: cheap, and the same numbers wherever the model was trained
        with torch_settings(self.threads, torch.device("cpu")), torch.no_grad():
            return np.stack(
                [torch.softmax(m(x, side), dim=1).numpy() for m in self._member_modules()]
            )

    def predict_proba(self, X) -> np.ndarray:
        return self.member_proba(X).mean(axis=0)

    def predict(self, X) -> np.ndarray:
        return self.classes_[self.predict_proba(X).argmax(axis=1)]

    def predict_with_uncertainty(self, X) -> tuple[np.ndarray, np.ndarray]:
        """(labels, uncertainty): the class of the mean probability, and the std over the
        members of their probability of that class (0 = the members agree)."""
        members = self.member_proba(X)
        chosen = members.mean(axis=0).argmax(axis=1)
        spread = members[:, np.arange(members.shape[1]), chosen].std(axis=0)
        return self.classes_[chosen], spread.astype(np.float64)

    # -- export and pickling --------------------------------------------------------------
    def to_torch_module(self) -> EnsembleModule:
        """The ensemble (standardisation included) as one eval-mode nn.Module."""
        check_is_fitted(self, "members_")
        return EnsembleModule(
            copy.deepcopy(self._member_modules()),
            self.mean_,
            self.scale_,
            self.input_shape_,
            self.classes_,
            getattr(self, "feature_columns_", None),
            None
            if getattr(self, "side_columns_", None) is None
            else (self.side_columns_, self.side_mean_, self.side_scale_),
        ).eval()

    def __getstate__(self):
        state = dict(super().__getstate__())  # a copy: object.__getstate__ gives __dict__
        state.pop("_modules", None)  # rebuilt from the state dicts on demand
        return state
