"""The healthy floor of the residual signatures against the record length (issue 48): how far a
healthy bench record's pinion pattern lies from another healthy record's, after alignment.

Each pinion tooth meets other gear teeth in turn; only over the pair's hunting cycle (29/44 teeth:
44 pinion revolutions, 5.87 s at 450 rpm) does it meet them all. A shorter record covers part of
the cycle, from a random start, so its synchronous pattern depends on which part: two healthy
records then differ by more than their noise. This draws `--records` healthy records of the
config's virtual bench (its seed, gears, noise, tones) at one speed for each `--seconds`, takes
every record's pinion pattern as the residual family does (`segment_patterns`), aligns each to
every other (`aligned`, on the bands' orders) and prints the residual's rms over the reference's:
median and range over the ordered pairs. With `--contiguous` also the two halves of records twice
as long (a simulated sample against its healthy twin's next segment). With `--cycle S` also
what the residual family does where the reference covers the hunting cycle: every record's first
segment against another record's average over the cycle (records of S seconds, `hunting_cycle`,
`cycle_residual`), the pinion's residual pattern over the cycle's pinion pattern.

    python3 benchmarks/hunting_cycle.py [--configfile config/config.yaml] [--seed 9] [--speed 450]
        [--records 5] [--seconds 3.0 5.8667] [--contiguous] [--cycle 6.0]
"""

from __future__ import annotations

import argparse
import itertools
from pathlib import Path

import numpy as np
import pandas as pd

from condmon.config import load_config
from condmon.records import save_record
from condmon.signals import to_arrays
from condmon.systems import get_system
from condmon.systems.gear import BENCH_NUMERICS
from condmon.operating import OperatingPoint
from condmon.systems.gear.bench import virtual_bench_rows
from condmon.systems.gear.residual_features import (
    aligned,
    cycle_shaft_patterns,
    hunting_cycle,
    hunting_revolutions,
    input_angle,
    segment_patterns,
    top_band_order,
    window_harmonics,
)

ROOT = Path(__file__).resolve().parents[1]


def bench_records(system, bench: dict, speed: float, seconds: float, records: int, pieces: int = 1):
    """(ids, arrays, fs_hz) of `records` healthy bench records of `pieces` x `seconds`, each piece
    a segment of its own: the bench's own records (`virtual_bench_rows`)."""
    # a sample more than the pieces, so rounding to whole samples never drops the last one
    bench = dict(
        bench,
        records_per_state=records,
        record_seconds=pieces * seconds + 1.0 / system.output_rate_hz,
    )
    numerics = dict(system.numerics, **{k: bench[k] for k in BENCH_NUMERICS})
    rows = virtual_bench_rows(
        system.parameters, bench, ["healthy"], [OperatingPoint(speed)], numerics, seconds
    )
    ids, arrays = to_arrays(pd.DataFrame(rows), list(system.config["features"]["channels"]))
    return ids.reset_index(drop=True), arrays, float(rows[0]["fs_hz"])


def pinion_patterns(
    system, bench: dict, speed: float, seconds: float, records: int, pieces: int = 1
) -> list:
    """[records][pieces] pinion patterns (n_channels, P) of healthy bench records of `pieces` x
    `seconds` (`bench_records`)."""
    ids, arrays, fs_hz = bench_records(system, bench, speed, seconds, records, pieces)
    patterns = {}
    for (record, _), segment in zip(ids[["record_id", "segment"]].itertuples(index=False), arrays):
        patterns.setdefault(record, []).append(
            segment_patterns(segment, fs_hz, speed, system.shafts(), 1024)[0][0]
        )
    return list(patterns.values())


def residual_share(pattern, reference, teeth: int, top: int) -> float:
    """rms of `pattern` aligned to `reference`, less it, over the reference's rms."""
    residual = aligned(pattern, reference, teeth, top) - reference
    return float(np.sqrt(np.mean(residual**2)) / np.sqrt(np.mean(reference**2)))


def cycle_shares(system, bench: dict, speed: float, seconds: float, records: int, top: int) -> list:
    """Each record's first segment (the config's segment length) against every other record's
    hunting-cycle average: the pinion residual's rms over the cycle's pinion pattern's."""
    segment_seconds = system.segment_length / system.output_rate_hz
    ids, arrays, fs_hz = bench_records(
        system, bench, speed, segment_seconds, records, int(round(seconds / segment_seconds))
    )
    shafts, phase = system.shafts(), (1, 0.3, 5.0)
    revolutions = hunting_revolutions(shafts)
    records_in_order = [group.sort_values("segment").index for _, group in ids.groupby("record_id")]
    joined = [np.concatenate(list(arrays[rows]), axis=-1) for rows in records_in_order]
    firsts = [arrays[rows[0]] for rows in records_in_order]
    cycles = [
        hunting_cycle(
            record, input_angle(record, fs_hz, speed, shafts, phase)[0], revolutions, 1024
        )
        for record in joined
    ]
    if any(cycle is None for cycle in cycles):
        raise SystemExit(f"--cycle {seconds}: a record covers less than the hunting cycle")
    shares = []
    for i, j in itertools.permutations(range(len(joined)), 2):
        residual = segment_patterns(
            firsts[i], fs_hz, speed, shafts, 1024, *phase, cycle=cycles[j], top_order=top
        )[0][0]
        reference = cycle_shaft_patterns(cycles[j], shafts, revolutions, 1024)[0]
        shares.append(float(np.sqrt(np.mean(residual**2)) / np.sqrt(np.mean(reference**2))))
    return shares


def mesh_harmonics(system, bench: dict, speed: float, configured) -> int:
    """The mesh harmonics the residual bands reach: the config's count, or with `auto` the
    features job's window rule (`window_harmonics`) on two healthy bench records of the segment
    length at this speed, as the features job takes it from the calibration records."""
    if configured != "auto":
        return int(configured)
    _, arrays, fs_hz = bench_records(
        system, bench, speed, system.segment_length / system.output_rate_hz, 2
    )
    return window_harmonics({speed: arrays}, fs_hz, system.shafts())[0]


def figures_of(shares) -> dict:
    """The median, range and count of residual shares (the record's figures of one case)."""
    return {
        "median": round(float(np.median(shares)), 3),
        "min": round(min(shares), 3),
        "max": round(max(shares), 3),
        "pairs": len(shares),
    }


def summary(shares) -> str:
    f = figures_of(shares)
    return f"median {f['median']:.3f} (range {f['min']:.3f}-{f['max']:.3f}, {f['pairs']} pairs)"


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--configfile", default="config/config.yaml")
    parser.add_argument(
        "--seed", type=int, default=None, help="virtual_bench.seed (default: the config's)"
    )
    parser.add_argument("--speed", type=float, default=450.0)
    parser.add_argument("--records", type=int, default=5)
    parser.add_argument("--seconds", type=float, nargs="+", default=[3.0, 5.8667])
    parser.add_argument("--contiguous", action="store_true")
    parser.add_argument(
        "--cycle", type=float, default=None, help="record seconds for the hunting-cycle reference"
    )
    args = parser.parse_args(argv)
    changes = {} if args.seed is None else {"virtual_bench": {"seed": args.seed}}
    system = get_system(load_config([args.configfile], project=ROOT, changes=changes))
    bench = dict(system.config["virtual_bench"])
    _, _, teeth = system.shafts()[0]
    residual = system.config["features"]["residual"]
    harmonics = mesh_harmonics(system, bench, args.speed, residual["mesh_harmonics"])
    top = top_band_order(teeth / residual["bands_per_mesh"], residual["bands_per_mesh"] * harmonics)
    hunting = np.lcm(*[t for _, _, t in system.shafts()]) / teeth / (args.speed / 60.0)
    print(f"bench seed {bench['seed']}, {args.speed:g} rpm: the hunting cycle is {hunting:.2f} s")
    figures = {
        "bench_seed": bench["seed"],
        "speed_rpm": args.speed,
        "hunting_cycle_s": round(float(hunting), 3),
        "cases": {},
    }
    for seconds in args.seconds:
        patterns = [p[0] for p in pinion_patterns(system, bench, args.speed, seconds, args.records)]
        shares = [
            residual_share(patterns[i], patterns[j], teeth, top)
            for i, j in itertools.permutations(range(len(patterns)), 2)
        ]
        print(f"{seconds:.2f} s records, random starts: {summary(shares)}", flush=True)
        figures["cases"][f"{seconds:.2f} s records, random starts"] = figures_of(shares)
        if args.contiguous:
            halves = pinion_patterns(system, bench, args.speed, seconds, args.records, pieces=2)
            shares = [
                residual_share(a, b, teeth, top)
                for first, second in halves
                for a, b in ((first, second), (second, first))
            ]
            print(f"{seconds:.2f} s, the two halves of one record: {summary(shares)}", flush=True)
            figures["cases"][f"{seconds:.2f} s, the two halves of one record"] = figures_of(shares)
    if args.cycle:
        shares = cycle_shares(system, bench, args.speed, args.cycle, args.records, top)
        case = (
            f"{system.segment_length / system.output_rate_hz:.2f} s segments against another {args.cycle:g} s "
            "record's hunting cycle"
        )
        print(f"{case}: {summary(shares)}", flush=True)
        figures["cases"][case] = figures_of(shares)
    save_record(
        "hunting_cycle",
        f"seed{bench['seed']}-{args.speed:g}rpm",
        figures,
        script=__file__,
        argv=argv,
        configfiles=[args.configfile],
    )


if __name__ == "__main__":
    main()
