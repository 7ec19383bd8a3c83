"""Signatures of a gear run's simulated records (issue #8's acceptance figures).

For every housing (A1, A2) and speed: the y/x amplitude ratio at the gear mesh harmonics 1..4 of
the healthy records (mean line amplitudes over the records; a line is the largest Hann-windowed
FFT bin within 0.55 bins), and their max/min per housing over harmonics and speeds. For every speed:
the sideband energy at GMF +/- shaft frequency (all four channels) of the missing-tooth records
over the healthy ones. The same for the measured (virtual bench) table with --measured.

    python3 benchmarks/gear_signatures.py [--results results/default] [--teeth 29] [--out FILE]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pandas as pd

from condmon.records import run_configfiles, save_record
from condmon.signals import read_signal_table


def line(signal: np.ndarray, frequency: float, fs: float) -> float:
    """Amplitude of the line at `frequency`: the largest Hann-windowed bin within 0.55 bins."""
    spectrum = np.abs(np.fft.rfft(signal * np.hanning(len(signal)))) * 2 / len(signal)
    freqs = np.fft.rfftfreq(len(signal), 1 / fs)
    return float(spectrum[np.abs(freqs - frequency) <= 0.55 * fs / len(signal)].max())


def signatures(frame: pd.DataFrame, teeth: int) -> dict:
    fs = float(frame["fs_hz"].iloc[0])
    out = {"y_over_x": {}, "y_over_x_max_over_min": {}, "sideband_gain": {}}
    speeds = sorted(frame["speed_rpm"].unique())
    for housing in ("A1", "A2"):
        ratios = []
        for speed in speeds:
            healthy = frame[(frame["health_state"] == "healthy") & (frame["speed_rpm"] == speed)]
            gmf = teeth * speed / 60
            per_harmonic = []
            for k in (1, 2, 3, 4):
                amp = {
                    axis: np.mean(
                        [
                            line(np.asarray(s), k * gmf, fs)
                            for s in healthy[healthy["channel"] == f"{housing}_{axis}"]["signal"]
                        ]
                    )
                    for axis in ("x", "y")
                }
                per_harmonic.append(amp["y"] / amp["x"])
            out["y_over_x"][f"{housing} {speed:g} rpm"] = [round(r, 3) for r in per_harmonic]
            ratios += per_harmonic
        out["y_over_x_max_over_min"][housing] = round(max(ratios) / min(ratios), 2)
    for speed in speeds:
        shaft = speed / 60
        gmf = teeth * shaft
        energy = {}
        for state in ("healthy", "missing_tooth"):
            rows = frame[(frame["health_state"] == state) & (frame["speed_rpm"] == speed)]
            per_segment = rows.groupby(["record_id", "segment"])["signal"].apply(
                lambda signals: sum(
                    line(np.asarray(s), gmf + side * shaft, fs) ** 2
                    for s in signals
                    for side in (-1, 1)
                )
            )
            energy[state] = float(per_segment.mean())
        out["sideband_gain"][f"{speed:g} rpm"] = round(
            energy["missing_tooth"] / energy["healthy"], 2
        )
    return out


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results", type=Path, default=Path("results/default"))
    parser.add_argument("--teeth", type=int, default=29, help="pinion teeth (input shaft)")
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args(argv)
    simulated = pd.concat(
        [read_signal_table(p) for p in sorted((args.results / "simulated").rglob("*.parquet"))]
    )
    result = {"simulated": signatures(simulated, args.teeth)}
    measured_path = args.results / "measured" / "signals.parquet"
    if measured_path.exists():
        result["virtual_bench"] = signatures(read_signal_table(measured_path), args.teeth)
    text = json.dumps(result, indent=2)
    print(text)
    if args.out:
        args.out.write_text(text + "\n")
    save_record(
        "gear_signatures",
        args.results.name,
        result,
        script=__file__,
        argv=argv,
        configfiles=run_configfiles(args.results),
    )


if __name__ == "__main__":
    main()
