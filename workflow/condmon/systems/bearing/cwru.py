"""CWRU bearing data: a folder of original Case Western Reserve University `.mat` files in,
signal-table rows out (see ARCHITECTURE.md, "Signal table").

The CWRU Bearing Data Center (engineering.case.edu/bearingdatacenter) publishes every record as a
MATLAB v5 file named after its file number `<n>`; the variables are `X<nnn>_DE_time` (drive-end
accelerometer, g), `X<nnn>_FE_time` (fan end, g), `X<nnn>_BA_time` (base, g; fault files only)
and `X<nnn>RPM` (measured shaft speed), `<nnn>` the file number zero-padded to three digits. Some
original files carry a stray copy of another record's variables, so variables are always selected
by the file's own number, never by "the first `*_DE_time`".

What a file is (fault, size, outer-race position, motor load, sampling rate) is not stored in it:
it comes from the file number through `CWRU_TABLE` (the normal baseline and the 12 kHz drive-end
fault records of the data centre's catalogue), which a manifest CSV in the columns of the shared
`index.csv` may override or extend.

Each record becomes one signal-table record `cwru-<n>`: source `measured`, channel `DE` (and
optionally `FE`), acceleration in m/s^2, resampled to `fs_hz` (the 48 kHz baseline by 1/4 with
`scipy.signal.resample_poly`), cut into segments of `segment_length` samples, `speed_rpm` the
speed stored in the file, `load` the motor load in HP, `health_state` the label of the chosen task
(`health_label`). Records whose class is outside the task are left out and reported.
"""

from __future__ import annotations

import hashlib
import io
import logging
import re
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path

import numpy as np
import pandas as pd
import scipy.io
from scipy.signal import resample_poly

from condmon.signals import make_rows, write_signal_table

log = logging.getLogger(__name__)

G = 9.80665  # m/s^2 per g (standard gravity)
SOURCE = "measured"
CHANNELS = ("DE", "FE", "BA")
TASKS = ("location", "severity", "ten_class")
FAULTS = ("normal", "inner_race", "ball", "outer_race")
MANIFEST_COLUMNS = (
    "cwru_number",
    "file",
    "fault",
    "or_position",
    "diameter_in",
    "load_hp",
    "rpm",
    "fs_hz",
    "de_samples",
    "sha256",
)
NOMINAL_RPM = {0: 1797.0, 1: 1772.0, 2: 1750.0, 3: 1730.0}  # data centre's nominal speed per HP
ON_BAD_RECORD = ("stop", "skip")  # what cwru_rows does with a bad file
EXCLUDED_COLUMNS = [
    "file",
    "cwru_number",
    "fault",
    "or_position",
    "diameter_in",
    "load_hp",
    "reason",
    "bad_record",
]


class CwruError(ValueError):
    """A CWRU file (or the request to read one) cannot be turned into signal-table rows."""


# -- the built-in catalogue ------------------------------------------------------------------
def _catalogue() -> pd.DataFrame:
    """Normal baseline (48 kHz) and 12 kHz drive-end fault records of the CWRU catalogue.

    File numbers per (fault, size, position) for motor loads 0, 1, 2, 3 HP. The speed is the
    data centre's nominal speed for the load, except for the files of the shared subset, whose
    stored speed (and sha256 of the original file) is listed (`_SHARED_SUBSET`).
    """
    groups = [  # fault, or_position, diameter_in, fs_hz, file numbers at 0/1/2/3 HP
        ("normal", "", 0.0, 48000, (97, 98, 99, 100)),
        ("inner_race", "", 0.007, 12000, (105, 106, 107, 108)),
        ("ball", "", 0.007, 12000, (118, 119, 120, 121)),
        ("outer_race", "6:00", 0.007, 12000, (130, 131, 132, 133)),
        ("outer_race", "3:00", 0.007, 12000, (144, 145, 146, 147)),
        ("outer_race", "12:00", 0.007, 12000, (156, 158, 159, 160)),
        ("inner_race", "", 0.014, 12000, (169, 170, 171, 172)),
        ("ball", "", 0.014, 12000, (185, 186, 187, 188)),
        ("outer_race", "6:00", 0.014, 12000, (197, 198, 199, 200)),
        ("inner_race", "", 0.021, 12000, (209, 210, 211, 212)),
        ("ball", "", 0.021, 12000, (222, 223, 224, 225)),
        ("outer_race", "6:00", 0.021, 12000, (234, 235, 236, 237)),
        ("outer_race", "3:00", 0.021, 12000, (246, 247, 248, 249)),
        ("outer_race", "12:00", 0.021, 12000, (258, 259, 260, 261)),
        ("inner_race", "", 0.028, 12000, (3001, 3002, 3003, 3004)),
        ("ball", "", 0.028, 12000, (3005, 3006, 3007, 3008)),
    ]
    rows = []
    for fault, position, diameter, fs_hz, numbers in groups:
        for load_hp, number in enumerate(numbers):
            rpm, sha = _SHARED_SUBSET.get(number, (NOMINAL_RPM[load_hp], ""))
            rows.append(
                dict(
                    cwru_number=number,
                    file=f"{number}.mat",
                    fault=fault,
                    or_position=position,
                    diameter_in=diameter,
                    load_hp=float(load_hp),
                    rpm=rpm,
                    fs_hz=float(fs_hz),
                    de_samples=np.nan,
                    sha256=sha,
                )
            )
    return pd.DataFrame(rows, columns=MANIFEST_COLUMNS)


# Stored speed and sha256 of the original files of the shared subset (../shared/data/cwru).
_SHARED_SUBSET = {
    97: (1796.0, "16bf48babcf1c7ac224bc1a81cd9eafdb27e42d5cf559761907e067e8eeadf3c"),
    105: (1797.0, "f80b0ea04fd06b372a0eaec7c056543ea37e4bb4727a5b173d2a5bacd2aa9cab"),
    106: (1772.0, "e5cec7cdd138e6cd1deb9ed8634e5aaa9bc1bd7094ddc075bff606580eb6e883"),
    118: (1796.0, "b00628f8dd8d1d930af77fa465d1e5cdb385fe259489053f91f3680bda7f640e"),
    119: (1772.0, "bc72d9df7668219e004a0f711232b23ec0aed393eb9bd8f9f5483426f6b51330"),
    130: (1796.0, "35a095307d0971477049b343a1b5981dde465a58fb7f233ad89b035068c1717d"),
    131: (1773.0, "7883f7b83beadc54b2f301767f9145ce07055707182fb0278fdf0a6bb53ce3cb"),
    169: (1796.0, "f5448673725c4ea2735fe7d3fe4b16ad82b217eac6b62c4bf351c4549b0a5229"),
    170: (1774.0, "bcb73a5208b67265468232a2e342f53719850901671d0ee28494f3af97621f46"),
    185: (1796.0, "5bea2c60f177215ba3ec4ae287faf745d7e14aed1a12efe9e37b27c27044bafc"),
    186: (1772.0, "1b3b6f3ad38e891feaa8026fe957b34f62f9082785089cc74f6878acdfe88ec5"),
    197: (1796.0, "fa571b47cd942f9514a920b403fb7c053cd442bb2963a360a96d0f61432f03e9"),
    198: (1772.0, "dbd58e4585ca8f8332c708b15936987ec0990ca701359fd2483dae2719df5b49"),
    209: (1797.0, "9f723d6d9d2eba714c6dc50f99321dffa73d8b1e4d3605675b2c2251511eff80"),
    210: (1774.0, "596692397e77e129a00f7b7a61c4c3ffd6c7a59979b89039e7f70a7431cce1c7"),
    222: (1796.0, "fcc0ee740fa123b1f4683f555458891719efb2857afd9fdee63e8fde0ed14469"),
    223: (1774.0, "7287410fd2217e3b332c5ab4732a68963be046d7d17bd40efa41cabe6a0514e5"),
    234: (1796.0, "ebcbdb96612e8085bbdbf81f0e5e8e8a8d1a693d1ec559c4894f7792771aa9b2"),
    235: (1771.0, "667e4bf1f213f92d10dca71d494ad002d8fd22bfd8004b31a4c71ccf0d764b66"),
}

CWRU_TABLE = _catalogue()


def read_manifest(path) -> pd.DataFrame:
    """A manifest CSV in the columns of the shared `index.csv` (`MANIFEST_COLUMNS`).

    Required: `cwru_number, fault, diameter_in, load_hp, fs_hz`; `file, or_position, rpm,
    de_samples, sha256` may be empty or absent.
    """
    path = Path(path)
    try:
        frame = pd.read_csv(path, dtype={"or_position": str, "sha256": str, "file": str})
    except FileNotFoundError:
        raise CwruError(f"{path}: no such manifest") from None
    except Exception as exc:
        raise CwruError(f"{path}: not a readable CSV manifest ({exc})") from exc
    required = ["cwru_number", "fault", "diameter_in", "load_hp", "fs_hz"]
    missing = [c for c in required if c not in frame.columns]
    if missing:
        raise CwruError(
            f"{path}: manifest lacks column(s) {missing}; expected the columns of "
            f"index.csv: {list(MANIFEST_COLUMNS)}"
        )
    for column in MANIFEST_COLUMNS:
        if column not in frame.columns:
            frame[column] = np.nan
    frame = frame[list(MANIFEST_COLUMNS)].copy()
    frame["cwru_number"] = pd.to_numeric(frame["cwru_number"], errors="coerce")
    if frame["cwru_number"].isna().any():
        raise CwruError(f"{path}: cwru_number must be an integer in every row")
    frame["cwru_number"] = frame["cwru_number"].astype(int)
    bad = sorted(set(frame["fault"]) - set(FAULTS))
    if bad:
        raise CwruError(f"{path}: unknown fault {bad}; use one of {list(FAULTS)}")
    for column in ("diameter_in", "load_hp", "fs_hz", "rpm"):
        frame[column] = pd.to_numeric(frame[column], errors="coerce").astype(float)
    if not (frame["fs_hz"] > 0).all():
        raise CwruError(f"{path}: fs_hz must be a positive number in every row")
    for column in ("or_position", "sha256", "file"):
        frame[column] = frame[column].fillna("").astype(str).str.strip()
    frame.loc[frame["file"] == "", "file"] = frame["cwru_number"].astype(str) + ".mat"
    return frame


def merged_table(manifest=None) -> pd.DataFrame:
    """The built-in `CWRU_TABLE` with a manifest's rows replacing or adding file numbers."""
    if manifest is None:
        return CWRU_TABLE.copy()
    extra = manifest if isinstance(manifest, pd.DataFrame) else read_manifest(manifest)
    base = CWRU_TABLE[~CWRU_TABLE["cwru_number"].isin(extra["cwru_number"])]
    return pd.concat([base, extra[list(MANIFEST_COLUMNS)]], ignore_index=True)


# -- labels ----------------------------------------------------------------------------------
def health_label(task: str, fault: str, diameter_in: float) -> str | None:
    """The health-state label of a (fault, fault diameter in inches) for a task, or None when the
    class is not part of that task.

    - `location`: `normal`, `inner_race`, `ball`, `outer_race` (every fault size);
    - `severity`: the outer-race sizes `outer_race_0.007in`, `outer_race_0.014in`,
      `outer_race_0.021in` and `normal` (the bearing study's task: outer-race fault sizes);
    - `ten_class`: `normal` and `<fault>_<size>in` for inner race, ball and outer race at
      0.007, 0.014 and 0.021 in (the usual 10-class CWRU benchmark).
    """
    if task not in TASKS:
        raise ValueError(f"unknown task {task!r}; choose one of {list(TASKS)}")
    if fault not in FAULTS:
        raise ValueError(f"unknown fault {fault!r}; choose one of {list(FAULTS)}")
    if fault == "normal":
        return "normal"
    size = f"{fault}_{float(diameter_in):.3f}in"
    if task == "location":
        return fault
    if task == "severity":
        if fault != "outer_race" or round(float(diameter_in), 3) not in (0.007, 0.014, 0.021):
            return None
        return size
    if round(float(diameter_in), 3) not in (0.007, 0.014, 0.021):  # ten_class
        return None
    return size


def task_labels(task: str) -> list[str]:
    """Every label of a task, in a fixed order."""
    sizes = ("0.007", "0.014", "0.021")
    if task == "location":
        return list(FAULTS)
    if task == "severity":
        return [f"outer_race_{s}in" for s in sizes] + ["normal"]
    if task == "ten_class":
        return ["normal"] + [f"{f}_{s}in" for f in FAULTS[1:] for s in sizes]
    raise ValueError(f"unknown task {task!r}; choose one of {list(TASKS)}")


# -- one file --------------------------------------------------------------------------------
@dataclass
class CwruRecord:
    """One CWRU file read: signals in m/s^2 at the original rate, and what it is."""

    path: Path
    number: int
    fs_hz: float
    speed_rpm: float
    speed_from_file: bool
    signals: dict = field(default_factory=dict)  # channel -> float64 array, m/s^2
    sha256: str = ""


def file_number(path, table: pd.DataFrame | None = None) -> int | None:
    """The CWRU file number of a path: by the manifest's `file` column, else the last digits of
    the file name (`130.mat`, `OR007@6_0_130.mat`); None if neither gives one."""
    path = Path(path)
    if table is not None:
        hit = table.loc[table["file"] == path.name, "cwru_number"]
        if len(hit):
            return int(hit.iloc[-1])
    digits = re.findall(r"\d+", path.stem)
    return int(digits[-1]) if digits else None


def sha256_of(path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _loadmat(path: Path, data: bytes) -> dict:
    if not data.startswith(b"MATLAB"):
        raise CwruError(
            f"{path}: not a CWRU record: not a MATLAB v5 .mat file (starts with {data[:16]!r})"
        )
    try:
        return scipy.io.loadmat(io.BytesIO(data))
    except NotImplementedError as exc:  # v7.3 (HDF5)
        raise CwruError(
            f"{path}: not a CWRU record: MATLAB v7.3 files are not supported ({exc})"
        ) from exc
    except Exception as exc:  # scipy raises several types for corrupt files
        raise CwruError(
            f"{path}: not a readable MATLAB file, truncated or corrupt ({exc})"
        ) from exc


# The data centre's 0.028-in files (3001-3008) hold their record under another number:
# 3001.mat (inner race, 0 HP) stores X056_DE_time, 3005.mat (ball, 0 HP) X048_DE_time.
_STORED_AS = {3001: 56, 3002: 57, 3003: 58, 3004: 59, 3005: 48, 3006: 49, 3007: 50, 3008: 51}


def _stored_numbers(number: int) -> list[int]:
    """The record numbers a file of this number may store its variables under."""
    return [number] + ([_STORED_AS[number]] if number in _STORED_AS else [])


def _variable_prefixes(number: int) -> list[str]:
    """`X097` (the CWRU spelling) first, then the unpadded `X97` if a file uses it; for the
    0.028-in files, the same for the number they store their record under."""
    return list(
        dict.fromkeys(
            prefix
            for stored in _stored_numbers(number)
            for prefix in (f"X{stored:03d}", f"X{stored}")
        )
    )


def read_cwru_file(
    path, channels=("DE",), table: pd.DataFrame | None = None, number: int | None = None
) -> CwruRecord:
    """Read one original CWRU `.mat` file: the requested channels (g -> m/s^2), the measured
    speed and the sampling rate of its catalogue row.

    The file number comes from `number`, else from `file_number(path, table)`; when the name
    carries none and the file holds exactly one `X<n>_DE_time`, that n. Errors (`CwruError`,
    naming the file) for: no such file, an unreadable or truncated file, not a MATLAB file or
    no `X<n>_DE_time` (not a CWRU record), a requested channel missing, NaN/inf samples, a
    constant (dead) channel, a file number not in the table, a drive-end length other than the
    table's `de_samples` (where listed: a truncated or different recording), and a sampling rate
    stored in the file (a scalar `fs`/`X<n>_fs`/`sampling_rate`... variable; the original files
    store none) other than the table's `fs_hz`.
    """
    path = Path(path)
    table = CWRU_TABLE if table is None else table
    unknown = sorted(set(channels) - set(CHANNELS))
    if unknown or not channels:
        raise CwruError(f"channels {list(channels)}: choose from {list(CHANNELS)}")
    if not path.exists():
        raise CwruError(f"{path}: no such file")
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise CwruError(f"{path}: cannot read ({exc})") from exc
    variables = _loadmat(path, data)
    de_numbers = sorted(
        {int(m.group(1)) for name in variables if (m := re.fullmatch(r"X(\d+)_DE_time", name))}
    )
    if not de_numbers:
        raise CwruError(
            f"{path}: not a CWRU record: no X<n>_DE_time variable "
            f"(variables: {sorted(k for k in variables if not k.startswith('__'))})"
        )
    if number is None:
        number = file_number(path, table)
    if number is None:
        if len(de_numbers) != 1:
            raise CwruError(
                f"{path}: no file number in the name and several records in the file "
                f"{de_numbers}; name the file <number>.mat or list it in a manifest"
            )
        number = de_numbers[0]
    if not set(_stored_numbers(number)) & set(de_numbers):
        raise CwruError(
            f"{path}: no X{number:03d}_DE_time for file number {number}; the file "
            f"holds record(s) {de_numbers} (a stray copy, or a misnamed file?)"
        )
    rows = table.loc[table["cwru_number"] == number]
    if rows.empty:
        raise CwruError(
            f"{path}: file number {number} is not in the CWRU table; add it to a "
            f"manifest (columns {list(MANIFEST_COLUMNS)})"
        )
    row = rows.iloc[-1]
    prefix = next(p for p in _variable_prefixes(number) if f"{p}_DE_time" in variables)
    signals = {}
    for channel in channels:
        name = f"{prefix}_{channel}_time"
        if name not in variables:
            raise CwruError(f"{path}: channel {channel} missing (no variable {name})")
        values = np.asarray(variables[name], dtype=np.float64).ravel()
        if values.size == 0:
            raise CwruError(f"{path}: {name} is empty")
        bad = ~np.isfinite(values)
        if bad.any():
            raise CwruError(
                f"{path}: {name} has {int(bad.sum())} non-finite samples (NaN or inf),"
                f" first at index {int(np.flatnonzero(bad)[0])}"
            )
        if np.ptp(values) == 0.0:
            raise CwruError(
                f"{path}: {name} is constant ({values[0]:g} g in all {values.size} "
                "samples): dead sensor or disconnected channel"
            )
        signals[channel] = values * G
    _check_against_table(path, variables, prefix, number, row)
    rpm_name = f"{prefix}RPM"
    speed, from_file = np.nan, False
    if rpm_name in variables:
        value = np.asarray(variables[rpm_name], dtype=np.float64).ravel()
        if value.size == 1 and np.isfinite(value[0]) and value[0] > 0:
            speed, from_file = float(value[0]), True
    if not from_file:
        speed = (
            float(row["rpm"])
            if np.isfinite(row["rpm"])
            else NOMINAL_RPM.get(int(row["load_hp"]), np.nan)
        )
        if not (np.isfinite(speed) and speed > 0):
            raise CwruError(f"{path}: no usable {rpm_name} and no speed in the table")
        log.warning(
            "%s: no usable %s variable; using the table speed %.1f rpm", path, rpm_name, speed
        )
    return CwruRecord(
        path=path,
        number=int(number),
        fs_hz=float(row["fs_hz"]),
        speed_rpm=speed,
        speed_from_file=from_file,
        signals=signals,
        sha256=hashlib.sha256(data).hexdigest(),
    )


_RATE_VARIABLE = r"(?:X0*{number}_?)?(?:fs|fs_hz|sampling_?rate|sample_?rate)"


def _check_against_table(path: Path, variables: dict, prefix: str, number: int, row) -> None:
    """The drive-end length against the table's `de_samples` (if listed) and a sampling rate
    stored in the file (if any) against the table's `fs_hz`."""
    de = np.asarray(variables[f"{prefix}_DE_time"]).size
    expected = pd.to_numeric(pd.Series([row["de_samples"]]), errors="coerce").iloc[0]
    if np.isfinite(expected) and int(expected) != de:
        raise CwruError(
            f"{path}: {prefix}_DE_time has {de} samples but the table lists "
            f"de_samples = {int(expected)} for file number {number} (truncated, or "
            "another recording?)"
        )
    pattern = re.compile(_RATE_VARIABLE.format(number=number), re.IGNORECASE)
    for name, value in variables.items():
        if name.startswith("__") or not pattern.fullmatch(name):
            continue
        value = np.asarray(value).ravel()
        if value.size != 1 or not np.issubdtype(value.dtype, np.number):
            continue
        if not np.isclose(float(value[0]), float(row["fs_hz"]), rtol=1e-6):
            raise CwruError(
                f"{path}: sampling rate {float(value[0]):g} Hz stored in {name} "
                f"differs from the table's fs_hz {float(row['fs_hz']):g} Hz for file "
                f"number {number}; fix the manifest's fs_hz or the file"
            )


def resample(signal, fs_in: float, fs_out: float) -> np.ndarray:
    """Polyphase resampling from fs_in to fs_out (48 kHz -> 12 kHz is up 1, down 4)."""
    if fs_in == fs_out:
        return np.asarray(signal, dtype=np.float64)
    ratio = Fraction(fs_out / fs_in).limit_denominator(1000)
    if abs(float(ratio) - fs_out / fs_in) > 1e-9 * fs_out / fs_in:
        raise CwruError(f"cannot resample {fs_in:g} Hz to {fs_out:g} Hz by a small rational factor")
    return resample_poly(np.asarray(signal, dtype=np.float64), ratio.numerator, ratio.denominator)


# -- a folder --------------------------------------------------------------------------------
@dataclass
class CwruIngest:
    """What `cwru_rows` made of a folder: the signal-table rows, one line per record kept
    (`records`), and the files left out (`excluded`, with a `reason`): their class is outside
    the task, or (`on_bad_record="skip"`) they are bad records (`bad_record` true)."""

    rows: list
    records: pd.DataFrame
    excluded: pd.DataFrame
    task: str


def cwru_rows(
    folder,
    task: str = "location",
    channels=("DE",),
    fs_hz: float = 12000.0,
    segment_length: int = 4096,
    manifest="auto",
    files=None,
    on_bad_record: str = "stop",
    segment_hop: int | None = None,
) -> CwruIngest:
    """Signal-table rows of every `*.mat` in `folder` (or of the given `files` names), cut into
    segments of `segment_length` samples starting every `segment_hop` (default: no overlap).

    `manifest`: a CSV (columns of `index.csv`) overriding/extending the built-in table; "auto"
    uses `<folder>/index.csv` if there is one; None uses the built-in table only. A file listed
    in the table with a sha256 is checked; a mismatch is a warning (other versions exist).
    A record shorter than one segment (after resampling) is an error naming the file. Files
    whose class (by file number) is outside the task are left out unread and listed in
    `excluded`. A file an explicitly given manifest lists (with a class of the task) but the
    folder lacks is a missing file; a folder's own `index.csv` ("auto") may describe more files
    than the folder holds (a partial download, a chosen subset), so it only describes them.

    `on_bad_record`: "stop" (default): the first bad file (see `read_cwru_file`; also too short,
    missing) raises a `CwruError` naming it and the reason; "skip": it is left out, logged, and
    listed in `excluded` with `bad_record` true and the reason; no usable record left is still
    an error.
    """
    if on_bad_record not in ON_BAD_RECORD:
        raise ValueError(f"on_bad_record={on_bad_record!r}; choose one of {list(ON_BAD_RECORD)}")
    folder = Path(folder)
    if task not in TASKS:
        raise ValueError(f"unknown task {task!r}; choose one of {list(TASKS)}")
    if not folder.is_dir():
        raise CwruError(f"{folder}: no such folder")
    if int(segment_length) < 2:
        raise ValueError(f"segment_length must be at least 2, got {segment_length}")
    segment_hop = int(segment_hop or segment_length)
    if not 1 <= segment_hop <= int(segment_length):
        raise ValueError(
            f"segment_hop must lie in 1..segment_length ({segment_length}), got {segment_hop}"
        )
    explicit = manifest not in ("auto", None)
    if manifest == "auto":
        manifest = folder / "index.csv" if (folder / "index.csv").exists() else None
    listed = read_manifest(manifest) if manifest is not None else None
    table = merged_table(listed)
    paths = sorted(folder.glob("*.mat")) if files is None else [folder / f for f in files]
    if not paths:
        raise CwruError(f"{folder}: no .mat files")
    if files is None and explicit:  # listed but absent: a missing file, not silence
        present = {p.name for p in paths}
        paths += [folder / name for name in listed["file"] if name not in present]
    numbered = [(file_number(p, table), p) for p in paths]
    keyed = sorted(
        ((-1 if n is None else n, p) for n, p in numbered), key=lambda t: (t[0], str(t[1]))
    )
    rows, records, excluded = [], [], []
    for number, path in keyed:
        try:
            kept = _ingest_file(
                path, number, table, task, channels, fs_hz, segment_length, excluded, segment_hop
            )
        except CwruError as exc:
            if on_bad_record == "stop":
                raise
            excluded.append(_bad_file(path, number, table, exc))
            log.warning("%s: bad record, skipped: %s", path, exc)
            continue
        if kept is not None:
            rows += kept[0]
            records.append(kept[1])
    bad = [e for e in excluded if e.get("bad_record")]
    if not records and bad:
        raise CwruError(
            f"{folder}: no usable record left; {len(bad)} bad file(s) skipped: "
            + "; ".join(f"{e['file']}: {e['reason']}" for e in bad)
        )
    if not records:
        raise CwruError(f"{folder}: no record belongs to a class of task {task!r}")
    excluded = pd.DataFrame(excluded, columns=EXCLUDED_COLUMNS)
    excluded["cwru_number"] = excluded["cwru_number"].astype("Int64")
    excluded["bad_record"] = excluded["bad_record"].astype(bool)
    return CwruIngest(rows=rows, records=pd.DataFrame(records), excluded=excluded, task=task)


def _bad_file(path: Path, number, table: pd.DataFrame, error: CwruError) -> dict:
    """The `excluded` line of a bad file: what the table says it is, and why it was skipped."""
    reason = str(error)
    if reason.startswith(f"{path}: "):
        reason = reason[len(f"{path}: ") :]
    entry = dict(
        file=path.name,
        cwru_number=None if number in (None, -1) else int(number),
        fault="",
        or_position="",
        diameter_in=np.nan,
        load_hp=np.nan,
        reason=reason,
        bad_record=True,
    )
    known = table.loc[table["cwru_number"] == entry["cwru_number"]]
    if len(known):
        info = known.iloc[-1]
        entry.update(
            fault=info["fault"],
            or_position=info["or_position"],
            diameter_in=float(info["diameter_in"]),
            load_hp=float(info["load_hp"]),
        )
    return entry


def specimen_of(info) -> dict:
    """The physical bearing a record was taken from, and its group (the fault size): CWRU made
    each fault (class, size, outer-race position) once and recorded it at every load, so the
    records of one specimen are not independent; the healthy bearing is one specimen, group ""."""
    if info["fault"] == "normal":
        return {"specimen": "normal", "specimen_group": ""}
    return {
        "specimen": specimen_name(info["fault"], info["diameter_in"], info["or_position"]),
        "specimen_group": f"{float(info['diameter_in']):.3f}",
    }


def specimen_name(fault: str, diameter_in=0.0, position=None) -> str:
    """A specimen's name in records.csv: "normal", "inner_race 0.007 in", "outer_race 0.021 in
    at 6:00" (also how `cwru.design_specimens` entries are matched to records)."""
    if fault == "normal":
        return "normal"
    where = f" at {position}" if str(position or "") else ""
    return f"{fault} {float(diameter_in):.3f} in{where}"


def _ingest_file(
    path: Path,
    number: int,
    table: pd.DataFrame,
    task: str,
    channels,
    fs_hz: float,
    segment_length: int,
    excluded: list,
    segment_hop: int | None = None,
):
    """(rows, record line) of one file, or None when its class is outside the task (then a line
    is appended to `excluded`). Raises CwruError for a bad file."""
    known = table.loc[table["cwru_number"] == number]
    if (
        len(known)
        and health_label(task, known.iloc[-1]["fault"], known.iloc[-1]["diameter_in"]) is None
    ):
        info = known.iloc[-1]  # class outside the task: left out without reading the file
        excluded.append(
            dict(
                file=path.name,
                cwru_number=int(number),
                fault=info["fault"],
                or_position=info["or_position"],
                diameter_in=float(info["diameter_in"]),
                load_hp=float(info["load_hp"]),
                reason=f"class not in task {task!r}",
                bad_record=False,
            )
        )
        log.info(
            "%s: %s %.3f in is not a class of task %s; left out",
            path.name,
            info["fault"],
            info["diameter_in"],
            task,
        )
        return None
    record = read_cwru_file(path, channels=channels, table=table)
    info = table.loc[table["cwru_number"] == record.number].iloc[-1]
    label = health_label(task, info["fault"], info["diameter_in"])
    description = dict(
        file=path.name,
        cwru_number=record.number,
        fault=info["fault"],
        or_position=info["or_position"],
        diameter_in=float(info["diameter_in"]),
        load_hp=float(info["load_hp"]),
        **specimen_of(info),
    )
    if label is None:  # number known only from the file's variables
        excluded.append(
            {**description, "reason": f"class not in task {task!r}", "bad_record": False}
        )
        log.info(
            "%s: %s %.3f in is not a class of task %s; left out",
            path.name,
            info["fault"],
            info["diameter_in"],
            task,
        )
        return None
    expected = str(info["sha256"] or "")
    sha_ok = None
    if expected:
        sha_ok = expected.lower() == record.sha256
        if not sha_ok:
            log.warning(
                "%s: sha256 %s differs from the table's %s (another version of the file?)",
                path,
                record.sha256,
                expected,
            )
    signals = {ch: resample(sig, record.fs_hz, fs_hz) for ch, sig in record.signals.items()}
    n = min(len(s) for s in signals.values())
    if n < segment_length:
        raise CwruError(
            f"{path}: {n} samples at {fs_hz:g} Hz, shorter than one segment ({segment_length})"
        )
    record_id = f"cwru-{record.number}"
    rows = make_rows(
        record_id,
        SOURCE,
        label,
        record.speed_rpm,
        float(info["load_hp"]),
        fs_hz,
        {ch: s[:n] for ch, s in signals.items()},
        segment_length=int(segment_length),
        segment_hop=segment_hop,
    )
    return rows, {
        **description,
        "record_id": record_id,
        "health_state": label,
        "speed_rpm": record.speed_rpm,
        "speed_from_file": record.speed_from_file,
        "fs_original_hz": record.fs_hz,
        "n_samples": n,
        "n_segments": len(rows) // len(signals),
        "sha256": record.sha256,
        "sha256_ok": sha_ok,
    }


def write_cwru_signal_table(folder, path, config: dict | None = None, **reading) -> CwruIngest:
    """`cwru_rows(folder, **reading)` written as a signal table at `path` (`config`: stored with
    it); returns the ingest summary (bad files left out with `on_bad_record="skip"` are in its
    `excluded`)."""
    ingest = cwru_rows(folder, **reading)
    write_signal_table(ingest.rows, path, config=config)
    return ingest
