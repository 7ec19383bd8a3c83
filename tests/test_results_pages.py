"""docs/results.md and README.md's table are what benchmarks/render_results.py renders from the
committed records: a stale page fails, a seed record shows as a table, no record says so."""

import importlib.util
import json

import pytest

from conftest import ROOT

spec = importlib.util.spec_from_file_location(
    "render_results", ROOT / "benchmarks" / "render_results.py"
)
render = importlib.util.module_from_spec(spec)
spec.loader.exec_module(render)


def test_the_pages_are_rendered_from_the_committed_records():
    """Run `python3 benchmarks/render_results.py` after adding or changing a record."""
    for path, text in render.pages().items():
        assert path.read_text() == text, (
            f"{path.relative_to(ROOT)} is stale: run python3 benchmarks/render_results.py"
        )


def seed_record(name: str, configfiles: list[str], date: str, balanced: float) -> dict:
    """A bench_seeds record of two seeds at one speed, as bench_seeds.py writes it."""
    per_seed = [
        {
            "seed": seed,
            "speed_rpm": 450.0,
            "measured_percent": percent,
            "classifier": "svm",
            "balanced_accuracy": balanced if percent == 0 else 1.0,
            "false_alarm_rate": 0.125 * (seed == 8),
            "recall": {"healthy": 1.0, "missing_tooth": 0.75},
            "exempt": [] if seed == 7 else ["healthy"],
            "bench_only_recall": {},
            "signature_correlation": {},
        }
        for seed in (7, 8)
        for percent in (0, 100)
    ]
    mean = [
        {
            "speed_rpm": 450.0,
            "measured_percent": percent,
            "seeds": 2,
            "balanced_accuracy": balanced if percent == 0 else 1.0,
            "lowest_balanced_accuracy": balanced - 0.1,
            "false_alarm_rate": 0.0625,
            "highest_false_alarm_rate": 0.125,
            "recall": {"healthy": 1.0, "missing_tooth": 0.75},
            "signature_correlation": {},
            "exempt": {"8": ["healthy"]},
        }
        for percent in (0, 100)
    ]
    return {
        "benchmark": "bench_seeds",
        "name": name,
        "command": f"python3 benchmarks/bench_seeds.py --name {name}",
        "commit": "0123456789abcdef",
        "configfiles": configfiles,
        "config_hash": "feed",
        "date": date,
        "machine": {"cpu_count": 2, "cpu": "test CPU", "python": "3.11.7"},
        "figures": {"per_seed": per_seed, "mean": mean},
    }


def test_a_seed_record_renders_per_seed_and_state_and_the_readme_takes_the_newest_default():
    records = [
        seed_record("old", ["config/config.yaml", "benchmarks/seeds.yaml"], "2026-12-01", 0.812),
        seed_record("new", ["config/config.yaml", "benchmarks/seeds.yaml"], "2026-12-05", 0.937),
        seed_record(
            "variant", ["config/config.yaml", "config/benches/noisy-chain.yaml"], "2026-12-06", 0.5
        ),
    ]
    page = render.render_results(records)
    default = page.split("## The default bench over seeds")[1].split("## The CFRP rig")[0]
    assert (
        "| seed 8 | 450 | 0 % | svm | 0.937 | 0.125 | 1.000 | 0.750 | - | - | healthy |" in default
    )
    assert "| **mean of 2** | 450 | 0 % | svm | 0.937 | 0.062 |" in default
    assert default.index("### new") < default.index("### old")  # newest first
    assert "at commit `0123456789`" in default and "test CPU" in default
    assert "### variant (noisy-chain bench" in page.split("## The bench variants")[1]
    assert "No record yet" in page.split("## The CFRP rig over seeds")[1].split("##")[0]
    readme = render.render_readme_table(records)
    assert (
        "| 450 | 0.937 | 0.837 | 0.062 | 1.000 |" in readme
    )  # the newest default record, not the variant
    assert "2026" not in readme  # the README carries no dates
    json.dumps(records)  # the fixtures are what a record file holds


def test_without_records_the_pages_say_no_record_yet(tmp_path):
    (tmp_path / "README.md").write_text(
        f"intro\n{render.README_BEGIN}\nold figures\n{render.README_END}\nrest\n"
    )
    pages = render.pages(tmp_path, records=[])
    readme = pages[tmp_path / "README.md"]
    assert (
        "old figures" not in readme
        and "No record yet" in readme
        and readme.endswith(f"{render.README_END}\nrest\n")
    )
    results = pages[tmp_path / "docs" / "results.md"]
    for section in (
        "the default bench",
        "the CFRP rig",
        "the bench variants",
        "CWRU",
        "simulation throughput",
    ):
        part = results.lower().split(f"## {section.lower()}")[1].split("\n## ")[0]
        assert "no record yet" in part, section


def test_other_records_render_their_like_rows_as_a_table():
    record = {
        "benchmark": "hunting_cycle",
        "name": "seed9",
        "command": "python3 benchmarks/hunting_cycle.py",
        "commit": "0123456789abcdef",
        "configfiles": [],
        "config_hash": None,
        "date": "2026-12-06",
        "machine": {"cpu_count": 2, "cpu": "test CPU", "python": "3.11.7"},
        "figures": {
            "speed_rpm": 450.0,
            "cases": {"3 s": {"median": 0.5, "pairs": 20}, "6 s": {"median": 0.1, "pairs": 20}},
        },
    }
    page = render.render_results([record]).split("## Other benchmarks")[1]
    assert "|  | median | pairs |" in page and "| 6 s | 0.100 | 20 |" in page
    assert "| speed_rpm | 450.000 |" in page


def test_a_bearing_seed_record_renders_its_mean_and_spread_and_stays_out_of_the_gear_tables():
    bench_spec = importlib.util.spec_from_file_location(
        "bench_seeds", ROOT / "benchmarks" / "bench_seeds.py"
    )
    bench = importlib.util.module_from_spec(bench_spec)
    bench_spec.loader.exec_module(bench)
    per_seed = [
        {
            "seed": seed,
            "protocol": "unseen_fault",
            "measured_percent": 0,
            "group": "design, loads 0-1",
            "classifier": "joined_svm",
            "accuracy": balanced,
            "balanced_accuracy": balanced,
            "recall": {"ball": balanced - 0.1, "normal": 1.0},
            "recall_shows_line": {"ball": 0.9},
            "recall_no_line": {"ball": 0.5},
            "per_specimen": {"ball 0.007 in": balanced},
        }
        for seed, balanced in ((1, 0.8), (2, 0.9), (3, 0.85))
    ]
    mean = bench.bearing_means(per_seed)
    (row,) = mean
    assert row["seeds"] == [1, 2, 3] and row["balanced_accuracy"]["mean"] == pytest.approx(0.85)
    assert (row["balanced_accuracy"]["lowest"], row["balanced_accuracy"]["highest"]) == (0.8, 0.9)
    assert row["recall_shows_line"]["ball"]["mean"] == 0.9
    record = dict(
        seed_record(
            "cwru", ["config/cwru.yaml", "benchmarks/bearing_seeds.yaml"], "2026-12-06", 0.5
        ),
        figures={"system": "bearing", "per_seed": per_seed, "mean": mean},
    )
    page = render.render_results([record])
    section = page[page.index("## The CWRU bearing rig over simulation seeds") :]
    assert (
        "| unseen_fault | 0 % | design, loads 0-1 | joined_svm | 1, 2, 3 | 0.850 | 0.800-0.900 |"
        in section
    )
    assert "No record yet of the default run" in render.render_readme_table([record])
    assert "### cwru" not in page[: page.index("## The CWRU bearing rig")]


def run_times_record(name: str, collected: bool, wall: float, cpu: float) -> dict:
    """A run_times record as benchmarks/run_times.py writes it (one rule)."""
    figures = {
        "run": "default",
        "cores": 2,
        "collected": collected,
        "jobs_window_seconds": wall - 10.0,
        "jobs_cpu_seconds": cpu - 200.0,
        "parallel_efficiency": 0.68,
        "window_over_cpu_per_core": 1.46,
        "rules": [
            {
                "rule": "simulate",
                "jobs": 18,
                "wall_seconds_total": 213.7,
                "wall_seconds_max": 20.0,
                "cpu_seconds_total": 180.6,
                "peak_rss_mb_max": 599.4,
            }
        ],
    }
    if not collected:
        figures.update(
            snakemake="snakemake --cores 2",
            wall_seconds=wall,
            cpu_seconds=cpu,
            load_average_at_start=[0.5, 1.0, 1.5],
        )
    return {
        "benchmark": "run_times",
        "name": name,
        "command": "python3 benchmarks/run_times.py",
        "commit": "0123456789abcdef",
        "configfiles": [],
        "config_hash": None,
        "date": "2026-12-06",
        "machine": {"cpu_count": 2, "cpu": "test CPU", "python": "3.11.7"},
        "figures": figures,
    }


def test_run_times_render_as_a_table_and_the_readme_names_the_timed_default_run():
    """A run timed by run_times.py shows its whole CPU against its elapsed time; a collected
    one its jobs' window and sampled CPU; the README's sentence takes the newest timed one."""
    timed = run_times_record("default-alone", False, 352.4, 680.0)
    collected = run_times_record("default-collected", True, 370.0, 670.0)
    page = render.render_results([collected, timed]).split("## Run times")[1]
    assert (
        "| default-alone | snakemake --cores 2 | 0123456789 | 5 min 52 s | 680 | 1.04 | 0.500 |"
        in page
    )
    assert (
        "| default-collected | (collected: the jobs' window) | 0123456789 | 6 min 0 s | 470 |"
        in page
    )
    assert "| simulate | 18 | 213.7 | 20.0 | 180.6 | 599 |" in page
    assert "## Other benchmarks" not in page.split("### default-collected")[0]
    sentence = render.run_time_sentence([timed, collected])
    assert sentence[-1].startswith(
        "The default run took 5 min 52 s alone on 2 cores, for 11.3 CPU minutes"
    )
    assert render.run_time_sentence([collected]) == []
