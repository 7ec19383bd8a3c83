"""The cluster profiles: they name real rules, the SLURM plugin is pinned, and Snakemake applies the
SLURM profile's resources to the jobs (a dry run, seconds). The smoke run through a real SLURM
cluster is the opt-in test in tests/test_pipeline.py."""

import re
import subprocess
import sys
from importlib.metadata import version

import pytest
import yaml
from conftest import ROOT

PROFILES = ["slurm", "kubernetes"]


def profile(name: str) -> dict:
    return yaml.safe_load((ROOT / "profiles" / name / "config.yaml").read_text())


def rule_names() -> set:
    sources = [ROOT / "workflow" / "Snakefile", *(ROOT / "workflow" / "rules").glob("*.smk")]
    return {
        name
        for path in sources
        for name in re.findall(r"^rule (\w+):", path.read_text(), re.MULTILINE)
    }


@pytest.mark.parametrize("name", PROFILES)
def test_a_profile_sets_resources_of_existing_rules_only(name):
    config = profile(name)
    assert config["executor"] == name
    named = set(config.get("set-threads", {})) | set(config.get("set-resources", {}))
    assert named and named <= rule_names(), f"profiles/{name}: unknown rules {named - rule_names()}"


@pytest.mark.parametrize(
    "package", ["snakemake-executor-plugin-slurm", "snakemake-executor-plugin-slurm-jobstep"]
)
def test_the_slurm_plugin_is_pinned_at_the_installed_version(package):
    pins = dict(
        line.split("==")
        for line in (ROOT / "environment.txt").read_text().splitlines()
        if "==" in line
    )
    assert pins.get(package) == version(package), (
        f"environment.txt pins {package} at {pins.get(package)}"
    )


@pytest.mark.slow  # a Snakemake dry run of the smoke pipeline: 5 s
def test_the_slurm_profile_gives_each_rule_its_resources(tmp_path):
    # --forceall: every job is planned whatever results/ holds; per-state calibration on, so that
    # its rule is planned too
    per_state = tmp_path / "per_state.yaml"
    per_state.write_text("calibration: {per_state: {states: [missing_tooth]}}\n")
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "snakemake",
            "-n",
            "--forceall",
            "--profile",
            "profiles/slurm",
            "--configfile",
            ".test/config/smoke.yaml",
            str(per_state),
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    assert result.returncode == 0, result.stderr[-3000:]
    jobs = {}  # rule -> its first job's block of the dry run
    for block in result.stdout.split("\nrule ")[1:]:
        jobs.setdefault(block.split(":", 1)[0], block)
    config = profile("slurm")
    assert set(config["set-resources"]) | set(config["set-threads"]) <= set(jobs), result.stdout[
        -2000:
    ]
    for rule, block in jobs.items():
        resources = re.search(r"resources: (.*)", block).group(1) + ","
        for key, value in {
            **config["default-resources"],
            **config["set-resources"].get(rule, {}),
        }.items():
            assert f"{key}={value}," in resources, f"{rule}: {key}={value} not in {resources}"
        threads = re.search(r"threads: (\d+)", block)
        assert (int(threads.group(1)) if threads else 1) == config["set-threads"].get(rule, 1), rule
