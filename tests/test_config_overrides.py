"""Nested and dotted (`set=classifiers.svm.C=3`) `--config` overrides read as the schema's types
(Snakemake hands their values over as text), and a measured speed that rig.speeds_rpm lacks
refused before any job runs."""

import re
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest
import yaml

from condmon.config import (
    ConfigError,
    apply_dotted_overrides,
    apply_typed_overrides,
    load_schema,
    validate_config,
)
from condmon.signals import make_rows, write_signal_table
from conftest import ROOT, config_file, config_of, copy_project, deep_update

SCHEMA = load_schema(ROOT / "config" / "schema.yaml")


def smoke_with(overrides: dict) -> dict:
    """The smoke config with ``overrides`` merged in as Snakemake merges --config, then typed."""
    config = deep_update(config_file(".test/config/smoke.yaml"), overrides)
    return apply_typed_overrides(config, overrides, SCHEMA)


def test_text_values_of_a_nested_override_take_the_schemas_types():
    config = smoke_with(
        {
            "classifiers": {
                "svm": {"C": "3", "gamma": "0.5", "enabled": "true"},
                "knn": {"n_neighbors": "7", "weights": "distance"},
            },
            "rig": {"speeds_rpm": ["450", "1.1e3"]},
            "hybrid": {"min_test_records": "2"},
        }
    )
    validate_config(config, SCHEMA)
    svm, knn = config["classifiers"]["svm"], config["classifiers"]["knn"]
    assert (svm["C"], svm["gamma"], svm["enabled"]) == (3, 0.5, True)
    assert (knn["n_neighbors"], knn["weights"]) == (7, "distance")
    assert config["rig"]["speeds_rpm"] == [450, 1100.0]
    assert config["hybrid"]["min_test_records"] == 2
    assert (
        smoke_with({"classifiers": {"svm": {"gamma": "scale"}}})["classifiers"]["svm"]["gamma"]
        == "scale"
    )


def test_text_that_is_no_value_of_the_key_still_fails_naming_it():
    with pytest.raises(ConfigError, match=r"classifiers\.svm\.C: 'three' is not of type 'number'"):
        validate_config(smoke_with({"classifiers": {"svm": {"C": "three"}}}), SCHEMA)


def test_a_config_files_text_is_not_retyped_and_the_hint_fits_the_text():
    config = config_file(".test/config/smoke.yaml")
    config["model"]["mesh_stiffness"] = "4e8"  # YAML 1.1: text
    config["classifiers"]["svm"]["C"] = "3"
    apply_typed_overrides(config, {}, SCHEMA)
    with pytest.raises(ConfigError) as error:
        validate_config(config, SCHEMA)
    assert "model.mesh_stiffness: '4e8' is text, not a number; YAML 1.1 reads an exponent" in str(
        error.value
    )
    assert "classifiers.svm.C: '3' is text, not a number; write it without quotes" in str(
        error.value
    )


def smoke_set(text: str) -> dict:
    """The smoke config with `--config set=<text>` as Snakemake hands it over, applied."""
    return apply_dotted_overrides({**config_file(".test/config/smoke.yaml"), "set": text}, SCHEMA)


def test_dotted_overrides_set_the_keys_they_name_as_the_schemas_types():
    config = smoke_set(
        "classifiers.svm.C=3  hybrid.measured_percent=[0, 100] classifiers.svm.gamma=scale"
        " features.selection.n_features=null run_name=svm-c3"
    )
    assert "set" not in config  # no job sees it
    # the rest of each section stays as the config file has it: as the nested form gives it
    assert config == smoke_with(
        {
            "classifiers": {"svm": {"C": "3", "gamma": "scale"}},
            "hybrid": {"measured_percent": ["0", "100"]},
            "features": {"selection": {"n_features": "null"}},
            "run_name": "svm-c3",
        }
    )
    validate_config(config, SCHEMA)
    assert (
        config["classifiers"]["svm"]["C"] == 3 and config["classifiers"]["svm"]["gamma"] == "scale"
    )
    assert config["hybrid"]["measured_percent"] == [0, 100]
    assert config["features"]["selection"]["n_features"] is None and config["run_name"] == "svm-c3"


@pytest.mark.parametrize(
    "text, says",
    [
        ("classifiers.svm.CC=3", "unknown key classifiers.svm.CC"),
        ("classifiers.svm.C=three", "classifiers.svm.C: 'three' is not of type 'number'"),
        (
            "classifiers.svm.C",
            "set: 'classifiers.svm.C' is no dotted key=value (e.g. set=classifiers.svm.C=3",
        ),
        ("run_name=a run_name.x=b", "set: run_name.x lies inside a key set to a value"),
    ],
)
def test_a_bad_dotted_override_is_refused_naming_it(text, says):
    with pytest.raises(ConfigError) as error:
        validate_config(smoke_set(text), SCHEMA)
    assert says in str(error.value)


def gear_table(path, speeds):
    rows = []
    for speed in speeds:
        for state in ("healthy", "missing_tooth"):
            signals = {
                ch: np.random.default_rng(1).normal(size=5120)
                for ch in ("A1_x", "A1_y", "A2_x", "A2_y")
            }
            rows += make_rows(
                f"{state}-{speed:g}",
                "measured",
                state,
                speed,
                10.0,
                5120.0,
                signals,
                segment_length=1280,
            )
    write_signal_table(pd.DataFrame(rows), path)
    return path


def test_a_measured_speed_that_rig_speeds_lacks_is_refused_naming_it(tmp_path):
    path = gear_table(tmp_path / "measured.parquet", [450.0, 900.0])
    with pytest.raises(
        ConfigError,
        match=r"measured_table: records at \[900.0\] rpm \(\['healthy-900', "
        r"'missing_tooth-900'\]\) but rig.speeds_rpm is \[450, 1100\]",
    ):
        config_of(".test/config/smoke.yaml", {"measured_table": str(path)})
    config_of(
        ".test/config/smoke.yaml",
        {"measured_table": str(gear_table(tmp_path / "ok.parquet", [450.0, 1100.0]))},
    )


@pytest.mark.slow
def test_snakemake_refuses_it_before_any_job(tmp_path):
    copy_project(tmp_path)
    path = gear_table(tmp_path / "measured.parquet", [450.0, 900.0])
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "snakemake",
            "-n",
            "--configfile",
            ".test/config/smoke.yaml",
            "--config",
            f"measured_table={path}",
        ],
        cwd=tmp_path,
        capture_output=True,
        text=True,
    )
    assert result.returncode != 0
    assert "records at [900.0] rpm" in result.stderr + result.stdout
    # a nested override is typed: the dry run plans the whole (fresh) run
    result = subprocess.run(
        [
            sys.executable,
            "-m",
            "snakemake",
            "-n",
            "--configfile",
            ".test/config/smoke.yaml",
            "--config",
            "classifiers={svm: {C: 3}, knn: {n_neighbors: 3}}",
        ],
        cwd=tmp_path,
        capture_output=True,
        text=True,
    )
    assert result.returncode == 0, result.stderr[-2000:]
    # through the top-level Snakefile, whose default target is the pipeline's rule all
    assert re.search(r"^all\s+1$", result.stdout, re.M) and re.search(
        r"^train\s+4$", result.stdout, re.M
    )


def test_a_config_file_merges_over_its_base_as_several_configfiles_do(tmp_path):
    from condmon.config import apply_base

    (tmp_path / "config").mkdir()
    (tmp_path / "config" / "root.yaml").write_text(
        yaml.safe_dump(
            {
                "run_name": "root",
                "hybrid": {"repeats": 3, "seed": 1},
                "tracking": {"log_models": {"repeat": [0]}},
            }
        )
    )
    (tmp_path / "config" / "mid.yaml").write_text(
        yaml.safe_dump({"base": "config/root.yaml", "hybrid": {"seed": 2}})
    )
    config = {"base": "config/mid.yaml", "run_name": "leaf", "tracking": {"log_models": "all"}}
    same = config
    assert apply_base(config, tmp_path) is same  # in place: Snakemake's config object
    assert config == {
        "run_name": "leaf",
        "hybrid": {"repeats": 3, "seed": 2},
        "tracking": {"log_models": "all"},
    }
    with pytest.raises(ConfigError, match=r"base: no config file .*config/none.yaml"):
        apply_base({"base": "config/none.yaml"}, tmp_path)


@pytest.mark.parametrize(
    "layer",
    [".test/config/smoke.yaml", ".test/config/cwru-smoke.yaml", ".test/config/cfrp-smoke.yaml"],
)
def test_the_ci_configs_state_only_how_they_differ_from_their_base(layer):
    text = (ROOT / layer).read_text()
    own = yaml.safe_load(text)
    base = config_file(own["base"])
    assert len(text.splitlines()) <= 40

    def repeated(mine, theirs, where=""):
        for key, value in mine.items():
            if isinstance(value, dict) and isinstance(theirs.get(key), dict):
                yield from repeated(value, theirs[key], f"{where}{key}.")
            elif key in theirs and theirs[key] == value:
                yield f"{where}{key}"

    assert list(repeated({k: v for k, v in own.items() if k != "base"}, base)) == []
