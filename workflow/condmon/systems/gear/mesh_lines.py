"""Where a user's records put the gear mesh line, checked before any job (issue 73, item 4).

The mesh line lies at teeth x shaft speed. A signal table whose sampling rate is wrong (a guess
where the data's documentation is silent) scales every frequency by declared / true rate: the
mesh line then sits off its place, the shaft tracking falls back to the nominal speed, and the
features read other orders. The healthy records' spectrum shows it: a strong line near the mesh
frequency but not on it names the rate that would put it there, rate x expected / found.

Each function is small and pure but `healthy_records`, which reads the table.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.signal import welch

from condmon.systems.gear.order_features import spectrum_line_to_floor

# A line: its peak power within LINE_WIDTH (relative, at least two bins) over the median power of
# the band around it (FLOOR_BAND), the line's own neighbourhood (FLOOR_GAP) left out.
LINE_WIDTH, FLOOR_BAND, FLOOR_GAP = 0.004, 0.15, 0.03
# A rate is refused only on clear evidence: no line at the mesh frequency (nor at its second
# harmonic) stands PRESENT above its floor, while one within SEARCH of it stands CLEAR above
# its floor and ABOVE times higher than the expected place.
PRESENT, CLEAR, ABOVE = 4.0, 10.0, 3.0
SEARCH = 1.3


def power_spectrum(signals: np.ndarray, fs_hz: float, resolution_hz: float):
    """(freqs, power) of `signals` (channels x samples, or several segments stacked): Welch
    (Hann, half overlap) at `resolution_hz` or the finest the samples allow, averaged over rows."""
    signals = np.atleast_2d(np.asarray(signals, float))
    nperseg = int(min(signals.shape[1], round(fs_hz / resolution_hz)))
    freqs, power = welch(signals, fs=fs_hz, nperseg=nperseg, axis=-1)
    return freqs, power.mean(axis=0)


def line_to_floor(freqs, power, line_hz: float) -> float:
    """Peak power within `LINE_WIDTH` of `line_hz` (at least two bins) over the median power of
    its band's floor (`spectrum_line_to_floor`, the tracking's measure on powers); 0 where the
    line lies beyond the spectrum."""
    step = freqs[1] - freqs[0]
    half = max(LINE_WIDTH * line_hz, 2 * step)
    if line_hz + half > freqs[-1] or line_hz - half < freqs[0]:
        return 0.0
    gap = max(FLOOR_GAP * line_hz, 3 * step)
    return spectrum_line_to_floor(freqs, power, line_hz, half, FLOOR_BAND * line_hz, gap_hz=gap)


def strongest_line(freqs, power, low_hz: float, high_hz: float) -> tuple[float, float]:
    """(frequency, line-to-floor) of the strongest line between `low_hz` and `high_hz`: of the
    spectrum's local maxima there (a line's own bin, not a neighbour whose window reaches it)."""
    peaks = np.r_[False, (power[1:-1] >= power[:-2]) & (power[1:-1] >= power[2:]), False]
    inside = np.flatnonzero((freqs >= low_hz) & (freqs <= high_hz) & peaks)
    if not len(inside):
        return float("nan"), 0.0
    ratios = np.array([line_to_floor(freqs, power, freqs[i]) for i in inside])
    peak = inside[int(np.argmax(ratios))]
    # the line's frequency between bins: the power-weighted centre of its bin and the two beside
    near = slice(max(peak - 1, 0), peak + 2)
    return float(np.average(freqs[near], weights=power[near])), float(ratios.max())


def implied_rate(freqs, power, fs_hz: float, mesh_hz: float) -> dict:
    """What the spectrum says of the mesh line: its line-to-floor at `mesh_hz` (the larger of the
    first two harmonics, `at_mesh`), the strongest line within `SEARCH` of it (`found_hz`,
    `found`), and `rate_hz`, the rate that puts that line on the mesh frequency where the evidence
    is clear, else None. Clear: a clear line off the mesh frequency, `ABOVE` times any there, and
    either nothing at the mesh's first two harmonics or its own second harmonic clear where the
    mesh's is absent (a wrong rate moves the harmonics together, so another machine line that a
    wrong rate happens to put on the mesh frequency does not hide it)."""
    first, second = (line_to_floor(freqs, power, k * mesh_hz) for k in (1, 2))
    at_mesh = max(first, second)
    found_hz, found = strongest_line(freqs, power, mesh_hz / SEARCH, mesh_hz * SEARCH)
    harmonics_moved = (
        second < PRESENT and line_to_floor(freqs, power, 2 * found_hz) >= CLEAR
        if np.isfinite(found_hz)
        else False
    )
    clear = (
        (at_mesh < PRESENT or harmonics_moved)
        and found >= CLEAR
        and found >= ABOVE * max(at_mesh, 1.0)
    )
    off = abs(found_hz - mesh_hz) > LINE_WIDTH * mesh_hz
    return {
        "mesh_hz": mesh_hz,
        "at_mesh": at_mesh,
        "found_hz": found_hz,
        "found": found,
        "rate_hz": fs_hz * mesh_hz / found_hz if clear and off else None,
    }


def rate_problem(findings: dict, fs_hz: float, teeth: int) -> str | None:
    """The config check's message for {speed_rpm: implied_rate(...)} of one table rate, or None
    where no speed gives clear evidence against the rate."""
    wrong = {speed: f for speed, f in findings.items() if f["rate_hz"] is not None}
    if not wrong:
        return None
    rates = [f["rate_hz"] for f in wrong.values()]
    speed, first = next(iter(wrong.items()))
    agree = max(rates) - min(rates) <= 0.01 * np.mean(rates)
    implied = (
        f"the lines imply a rate of {np.mean(rates):.0f} Hz"
        if agree
        else f"the speeds imply rates of {', '.join(f'{r:.0f}' for r in rates)} Hz"
    )
    return (
        f"measured_table: the healthy records at {speed:g} rpm show their mesh line elsewhere than "
        f"fs_hz {fs_hz:g} Hz, the speed and model.geometry.teeth_pinion {teeth} put it "
        f"({first['mesh_hz']:.1f} Hz, line to floor {first['at_mesh']:.1f}): a line at "
        f"{first['found_hz']:.1f} Hz ({first['found']:.0f}); {implied}: check the table's fs_hz "
        "(or speed_rpm and the tooth counts)"
    )


def healthy_records(measured_table, healthy_state: str, max_rows: int = 64):
    """{(speed_rpm, fs_hz): signals (rows x samples)} of the table's healthy records, at most
    `max_rows` rows (a channel's segment each) per speed and rate: a spectrum's lines need no more,
    and the config check runs at every start, so only the row groups holding them are read;
    {} where the table cannot be read (the measured job names its problem)."""
    if not measured_table or not Path(measured_table).is_file():
        return {}
    import pyarrow.parquet as pq

    try:
        parquet = pq.ParquetFile(measured_table)
        keys = parquet.read(columns=["health_state", "speed_rpm", "fs_hz"]).to_pandas()
        chosen = (
            keys[keys["health_state"] == healthy_state]
            .groupby(["speed_rpm", "fs_hz"])
            .head(max_rows)
        )
        sizes = [parquet.metadata.row_group(i).num_rows for i in range(parquet.num_row_groups)]
        starts = np.cumsum([0, *sizes])
        groups = sorted(set(np.searchsorted(starts, chosen.index, side="right") - 1))
        signals = parquet.read_row_groups(groups, columns=["signal"]).column("signal")
    except Exception:  # pyarrow raises several types
        return {}
    # a chosen row's place among the row groups read
    read_before = dict(zip(groups, np.cumsum([0, *(sizes[g] for g in groups)])))
    group_of = np.searchsorted(starts, chosen.index, side="right") - 1
    chosen = chosen.assign(
        at=[read_before[g] + i - starts[g] for g, i in zip(group_of, chosen.index)]
    )
    out = {}
    for (speed, fs), rows in chosen.groupby(["speed_rpm", "fs_hz"], sort=True):
        rows_signals = [np.asarray(signals[int(at)].as_py(), float) for at in rows["at"]]
        if len({len(signal) for signal in rows_signals}) == 1:  # the measured job checks lengths
            out[float(speed), float(fs)] = np.vstack(rows_signals)
    return out


def mesh_line_problems(measured_table, healthy_state: str, teeth: int) -> list[str]:
    """The config check: per table rate, a problem where the healthy records' mesh lines say the
    rate is wrong (`rate_problem`)."""
    by_rate: dict = {}
    silent = []
    for (speed, fs), signals in healthy_records(measured_table, healthy_state).items():
        if not np.any(signals):
            silent.append(
                f"measured_table: the healthy records at {speed:g} rpm hold only zeros (the "
                f"{len(signals)} segments read): a dead sensor or an empty export, no spectrum "
                "to calibrate on or to check fs_hz against"
            )
            continue
        shaft_hz = speed / 60.0
        freqs, power = power_spectrum(signals, fs, resolution_hz=shaft_hz / 8)
        by_rate.setdefault(fs, {})[speed] = implied_rate(freqs, power, fs, teeth * shaft_hz)
    problems = [rate_problem(findings, fs, teeth) for fs, findings in by_rate.items()]
    return silent + [p for p in problems if p]
