"""One way to layer a config (issue 72, item 5): a file that states only how a run differs names
its `base`, so it runs alone as it runs stacked over that base; the other files are whole runs over
the schema's defaults, each listed here with why it names none. Everything loads through
`condmon.config.load_config`, as the Snakefile does."""

import re
import subprocess
import sys

import pytest
import yaml
from conftest import DATA_FOLDERS, ROOT

from condmon.config import ConfigError, load_config, read_config

# Whole runs: no base, every key they lack the schema's default (and their own comments say so).
WHOLE = {
    "config/config.yaml": "the default run",
    "config/cfrp.yaml": "the CFRP rig's own run (system: cfrp)",
    "config/cwru.yaml": "the bearing rig's own run on CWRU records (system: bearing)",
    "config/cfrp-study.yaml": "the CFRP study's set-up; over config/cfrp.yaml it would keep that "
    "bench's spall and surface-fault forms, which a layer cannot remove",
    "config/helical-study.yaml": "the helical-gear study's set-up at paper size, its own and not "
    "the default run's (an edit of config.yaml must not reach it)",
    "config/cwru-pdm-bench.yaml": "pdm-bench's cwru_cross_load task as that benchmark defines it",
}


def run_configs():
    """Every run config of the project: config/ (but the schema) and the CI's .test/config/."""
    files = sorted(ROOT.glob("config/**/*.yaml")) + sorted(ROOT.glob(".test/config/*.yaml"))
    return [str(p.relative_to(ROOT)) for p in files if p.name != "schema.yaml"]


def base_of(path) -> str | None:
    return (yaml.safe_load((ROOT / path).read_text()) or {}).get("base")


def loaded(paths) -> dict:
    """The validated config of `paths`; a data folder it names is this machine's copy."""
    named = read_config(paths, project=ROOT)
    overrides = {key: str(folder) for key, folder in DATA_FOLDERS.items() if key in named}
    return load_config(paths, overrides, project=ROOT)


def test_every_config_names_its_base_or_is_a_whole_run():
    layered = {path for path in run_configs() if base_of(path)}
    whole = set(run_configs()) - layered
    assert whole == set(WHOLE), (
        f"a config without a base that is no whole run: {sorted(whole - set(WHOLE))}"
    )
    for path in layered:
        assert (ROOT / base_of(path)).is_file(), f"{path}: base {base_of(path)} is no file"
    # the overlays the issue names among them
    assert {
        "config/per-state.yaml",
        "config/cfrp-per-state.yaml",
        "config/benches/noisy-chain.yaml",
        "config/cwru-tasks/severity.yaml",
        ".test/config/smoke.yaml",
        "config/cfrp-study-pitting.yaml",
    } <= layered


@pytest.mark.parametrize("path", [p for p in run_configs() if base_of(p)])
def test_a_layer_alone_is_the_run_it_is_stacked_over_its_base(path):
    alone = loaded([path])
    assert alone == loaded([base_of(path), path])
    assert alone["run_name"] != loaded([base_of(path)])["run_name"], (
        f"{path} shares its base's results folder"
    )


def test_load_config_names_a_missing_file_and_takes_overrides_as_the_command_line_does(tmp_path):
    with pytest.raises(ConfigError, match=r"no config file .*config/none\.yaml"):
        load_config(["config/none.yaml"], project=ROOT)
    config = load_config(
        [".test/config/smoke.yaml"],
        {"classifiers": {"svm": {"C": "3"}}, "set": "hybrid.repeats=1"},
        project=ROOT,
    )
    assert (
        config["classifiers"]["svm"]["C"] == 3.0
        and config["hybrid"]["repeats"] == 1
        and "set" not in config
    )
    # no file: the overrides alone (a whole config as a dict) over the schema's defaults
    assert load_config([], {"run_name": "mine"}, project=ROOT)["rig"]["segment_seconds"] == 0.5


def planned_jobs(*configfiles, config=()) -> dict:
    """{rule: jobs} of a dry run with `configfiles` (and `--config` entries `config`)."""
    entries = ["--config", *config] if config else []
    result = subprocess.run(
        [sys.executable, "-m", "snakemake", "-n", "--forceall", "--configfile", *configfiles]
        + entries,
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    assert result.returncode == 0, result.stderr[-3000:]
    table = result.stdout[result.stdout.index("Job stats:") :]
    return dict(re.findall(r"^(\w+)\s+(\d+)$", table, re.M))


@pytest.mark.slow  # two Snakemake dry runs of the default bench's per-state run: about 20 s
def test_snakemake_plans_a_layer_alone_as_stacked_over_its_base():
    alone = planned_jobs("config/per-state.yaml")
    assert alone == planned_jobs("config/config.yaml", "config/per-state.yaml")
    assert int(alone["calibrate_state"]) == 2  # the layer's own two states: it was not dropped


@pytest.mark.slow  # a Snakemake dry run a config file: 5-10 s each
@pytest.mark.parametrize("path", [p for p in run_configs() if p.startswith("config/")])
def test_every_config_file_plans_its_run_alone(path):
    """`snakemake -n --configfile <it>` for every config file under config/, alone (a data
    folder it names is this machine's copy). A layer's plan is its base's plus its own changes:
    the config it loads alone is the stacked one (test_a_layer_alone_is_the_run_it_is_stacked_
    over_its_base), and the Snakefile plans from that config only (condmon.config.load_config)."""
    named = read_config([path], project=ROOT)
    config = [f"{key}={folder}" for key, folder in DATA_FOLDERS.items() if key in named]
    jobs = planned_jobs(path, config=config)
    assert jobs.get("all") == "1", jobs
