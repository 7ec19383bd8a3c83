"""Shared test constants and helpers (pytest puts this folder on sys.path: `from conftest import ROOT`)."""
import copy
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
CWRU = ROOT.parent / "shared" / "data" / "cwru"
# Config keys that point at a data folder, and where that data lies on this machine: a project
# config that sets one (whatever its system) reads this copy, so tests run from any folder.
DATA_FOLDERS = {"measured_dir": CWRU}


def pytest_configure(config):
    """A wrong interpreter stops the tests at once, naming the Python the pins need."""
    from condmon import python_version_error

    if python_version_error():
        pytest.exit(python_version_error(), returncode=4)


def deep_update(base: dict, changes: dict) -> dict:
    for key, value in changes.items():
        if isinstance(value, dict) and isinstance(base.get(key), dict):
            deep_update(base[key], value)
        else:
            base[key] = copy.deepcopy(value)
    return base


def config_of(configfile="config/smoke.yaml", changes: dict | None = None) -> dict:
    """A validated config: a project config file (or a config dict) with `changes` merged in."""
    from condmon.config import load_schema, validate_config

    if isinstance(configfile, dict):
        config = copy.deepcopy(configfile)
    else:
        config = yaml.safe_load((ROOT / configfile).read_text())
    config.update({key: str(folder) for key, folder in DATA_FOLDERS.items() if key in config})
    deep_update(config, changes or {})
    return validate_config(config, load_schema(ROOT / "config" / "schema.yaml"))


def system_of(configfile: str = "config/smoke.yaml", changes: dict | None = None):
    """The system object a project config file (with `changes`) builds."""
    from condmon.systems import get_system

    return get_system(config_of(configfile, changes))
