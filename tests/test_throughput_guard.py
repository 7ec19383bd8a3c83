"""The regression guard on simulation cost (issue 51, item 3): every system's wall time per
simulated second over a fixed reference workload timed in the same process, against the baseline
in benchmarks/throughput_baseline.json; fails when one grew more than GROWTH_LIMIT (1.5) times.
A ratio, never an absolute time: a slower or faster machine moves both alike. Remeasure the
baseline (`python3 benchmarks/throughput_guard.py --write`) after a change that is meant to cost
more, and say so in the commit."""

import importlib.util

import pytest

from conftest import ROOT

spec = importlib.util.spec_from_file_location(
    "throughput_guard", ROOT / "benchmarks" / "throughput_guard.py"
)
guard = importlib.util.module_from_spec(spec)
spec.loader.exec_module(guard)


def test_baseline_names_every_benchmarked_system():
    baseline = guard.read_baseline()
    assert set(baseline["systems"]) == set(guard.SYSTEMS)
    assert baseline["commit"] and baseline["machine"]["cpu"]
    assert all(entry["ratio"] > 0 for entry in baseline["systems"].values())


@pytest.mark.slow
def test_no_system_grew_over_the_limit():
    failures = guard.check(guard.read_baseline())
    assert not failures, "\n".join(failures)
