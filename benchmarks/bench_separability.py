"""Can an engineer see the bench's faults with the bench's own data? (issue 26)

A measured-only SVM (standardised features, C 1.2, RBF), leave-one-record-out over the measured
(virtual bench) records of a finished run: per speed and over all speeds, balanced accuracy per
segment (condmon.separability; every run's report gives it too, summary.json
`measured_separability`). No simulation is involved: it says whether the bench's health states
differ at all in the run's features, the ceiling a simulation-trained classifier can approach.

    python3 benchmarks/bench_separability.py --results results/default [--condition speed_rpm] [--out FILE]
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from condmon.features import read_feature_table
from condmon.records import run_configfiles, save_record
from condmon.separability import measured_separability


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--results", default="results/default")
    parser.add_argument("--condition", default="speed_rpm", help="the operating condition (load for CWRU runs)")
    parser.add_argument("--out", default=None)
    args = parser.parse_args(argv)
    out = measured_separability(*read_feature_table(Path(args.results) / "features" / "measured.parquet"),
                                args.condition)
    text = json.dumps(out, indent=2)
    print(text)
    if args.out:
        Path(args.out).write_text(text + "\n")
    save_record("bench_separability", Path(args.results).name, out, script=__file__, argv=argv,
                configfiles=run_configfiles(Path(args.results)))
    return out


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
