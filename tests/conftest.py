"""Shared test constants, helpers and the pipeline fixtures (pytest puts this folder on sys.path:
`from conftest import ROOT`).

Markers (pyproject.toml): `pipeline` runs a Snakemake pipeline, `slow` takes over about 5 s
otherwise. `pytest -q` runs everything; `pytest -q -m "not pipeline and not slow"` the fast ones.
Each pipeline config that several tests read runs once per session, in a fixture here (`smoke`,
`cwru_run`); a test that changes a run works on a copy of it. Each is read by one test file, and
pytest-xdist hands a whole file to one worker (`--dist loadfile`, pyproject.toml), so it still runs once.
"""

import copy
import json
import logging
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
# benchmarks/fake_train_outputs.py (`import fake_train_outputs as fake`): the synthetic train
# outputs the report and tracking tests share with the tracking benchmark. Tests may import from
# benchmarks/, never the reverse.
sys.path.insert(0, str(ROOT / "benchmarks"))
SCRIPTS = (
    ROOT / "workflow" / "scripts"
)  # the rules' scripts, which some tests run as Snakemake would
# The shared CWRU files: beside the checkout, or where CONDMON_CWRU_DIR points (a git worktree
# elsewhere, another machine's data folder).
CWRU = Path(os.environ.get("CONDMON_CWRU_DIR", ROOT.parent / "shared" / "data" / "cwru")).resolve()
# Config keys that point at a data folder, and where that data lies on this machine: a project
# config that sets one (whatever its system) reads this copy, so tests run from any folder.
DATA_FOLDERS = {"measured_dir": CWRU}


def pytest_configure(config):
    """A wrong interpreter stops the tests at once, naming the Python the pins need."""
    from condmon import python_version_error

    if python_version_error():
        pytest.exit(python_version_error(), returncode=4)
    if not hasattr(config, "workerinput"):  # once, before pytest-xdist starts its workers
        compile_mesh_kernel()


def compile_mesh_kernel():
    """The gear mesh's compiled kernel written into this checkout's numba cache. Every process
    that loads it (each worker, each pipeline job, each dry run's config check) then reads the
    cache instead of compiling it again (about 8 CPU-s each), and `copy_project` carries the cache
    into its copies: numba keys it on the source's content, not its path. In a process of its own
    with this checkout's workflow/ first, whichever checkout the installed package points at."""
    subprocess.run(
        [sys.executable, "-c", "import condmon.models.gear.mesh_kernel"],  # compiles on import
        env={**os.environ, "PYTHONPATH": str(ROOT / "workflow")},
        check=True,
    )


PIPELINE_FIXTURES = {"smoke", "cwru_run"}


def pytest_collection_modifyitems(items):
    """A test that reads a pipeline fixture is a pipeline test, marked or not. The test files
    go longest first: those with the most pipeline tests, then the most slow ones, then the rest
    as collected, each file's tests together and in order. pytest-xdist hands the files out in
    this order (`--no-loadscope-reorder`, pyproject.toml; its own order is by number of tests),
    so the smoke runs start at once, side by side, and the short files fill in around them."""
    for item in items:
        if PIPELINE_FIXTURES & set(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.pipeline)
    weight = {}
    for item in items:
        pipeline, slow = weight.get(file_of(item.nodeid), (0, 0))
        weight[file_of(item.nodeid)] = (
            pipeline + (item.get_closest_marker("pipeline") is not None),
            slow + (item.get_closest_marker("slow") is not None),
        )
    first = {name: n for n, name in enumerate(weight)}  # collection order
    items.sort(
        key=lambda item: (
            *(-n for n in weight[file_of(item.nodeid)]),
            first[file_of(item.nodeid)],
        )
    )


def file_of(nodeid: str) -> str:
    """The test file of a test's node id (`tests/test_x.py::test_y[1]`: `tests/test_x.py`)."""
    return nodeid.split("::", 1)[0]


def file_times(stats: dict) -> dict[str, dict]:
    """{test file: {"seconds", "tests"}} from the terminal reporter's reports, longest first:
    each test's setup, call and teardown summed (a session fixture's run counts in the first test
    that reads it), on the worker that ran the file; `tests` counts each test once."""
    seconds, tests = {}, {}
    for reports in stats.values():
        for report in reports:
            if getattr(report, "when", None) not in ("setup", "call", "teardown"):
                continue
            name = file_of(report.nodeid)
            seconds[name] = seconds.get(name, 0.0) + report.duration
            tests.setdefault(name, set()).add(report.nodeid)
    return {
        name: {"seconds": round(seconds[name], 1), "tests": len(tests[name])}
        for name in sorted(seconds, key=seconds.get, reverse=True)
    }


def pytest_terminal_summary(terminalreporter, config):
    """With --durations (the README's test command has it): beside the slowest tests, the time
    per test file, longest first (as many files as --durations names tests; 0: all). Where
    CONDMON_TEST_TIMES names a file, the times of every file and the outcomes go there as JSON
    (benchmarks/suite_times.py records them)."""
    if hasattr(config, "workerinput"):  # a pytest-xdist worker: the controller reports
        return
    times = file_times(terminalreporter.stats)
    if config.option.durations is not None and times:
        shown = list(times.items())[: config.option.durations or None]
        terminalreporter.write_sep("=", f"time per test file (the {len(shown)} longest)")
        for name, entry in shown:
            terminalreporter.write_line(
                f"{entry['seconds']:8.1f}s {entry['tests']:4d} tests  {name}"
            )
    path = os.environ.get("CONDMON_TEST_TIMES")
    if path:
        outcomes = {
            key: len(reports)
            for key, reports in terminalreporter.stats.items()
            if key in ("passed", "failed", "skipped", "error", "xfailed", "xpassed")
        }
        Path(path).write_text(json.dumps({"outcomes": outcomes, "files": times}, indent=1) + "\n")


def logical_lines(text: str) -> int:
    """Lines of Python as a formatter cannot change them: its logical lines (one per simple
    statement, def or class line and compound statement's header, however it is wrapped; a
    docstring counts once). Length rules count these, so `ruff format` never breaks them."""
    import io
    import tokenize

    return sum(
        token.type == tokenize.NEWLINE
        for token in tokenize.generate_tokens(io.StringIO(text).readline)
    )


def deep_update(base: dict, changes: dict) -> dict:
    for key, value in changes.items():
        if isinstance(value, dict) and isinstance(base.get(key), dict):
            deep_update(base[key], value)
        else:
            base[key] = copy.deepcopy(value)
    return base


def config_file(path) -> dict:
    """A project config file as the Snakefile reads it: merged over its `base`, if it names one
    (not validated: no defaults filled in)."""
    from condmon.config import read_config

    return read_config([path], project=ROOT)


def config_of(configfile=".test/config/smoke.yaml", changes: dict | None = None) -> dict:
    """A validated config, as the workflow loads it (`condmon.config.load_config`): a project config
    file (or a config dict) with `changes` merged in; a data folder it names is this machine's."""
    from condmon.config import load_config, read_config

    paths, overrides = (
        ([], copy.deepcopy(configfile)) if isinstance(configfile, dict) else ([configfile], {})
    )
    named = read_config(paths, overrides, project=ROOT)
    deep_update(
        overrides, {key: str(folder) for key, folder in DATA_FOLDERS.items() if key in named}
    )
    return load_config(paths, overrides, project=ROOT, changes=changes)


def system_of(configfile: str = ".test/config/smoke.yaml", changes: dict | None = None):
    """The system object a project config file (with `changes`) builds."""
    from condmon.systems import get_system

    return get_system(config_of(configfile, changes))


@pytest.fixture
def isolated_logging(monkeypatch):
    """A test that runs a rule's script (which reconfigures logging and sys.excepthook, as
    `condmon.runlog.setup_logging` does): both put back afterwards."""
    monkeypatch.setattr(sys, "excepthook", sys.excepthook)
    root = logging.getLogger()
    handlers, level = root.handlers[:], root.level
    yield
    for handler in root.handlers:
        if handler not in handlers:
            handler.close()
    root.handlers[:], root.level = handlers, level
    logging.captureWarnings(False)


@pytest.fixture(scope="module")
def knn_train_outputs(tmp_path_factory):
    """(results folder, paths) of fake train outputs (benchmarks/fake_train_outputs.py) of one
    classifier, k-NN: what a report section reads, without the plots of several classifiers
    (most of the report's time). Once per test module."""
    import fake_train_outputs as fake

    root = tmp_path_factory.mktemp("results") / "demo"
    return root, fake.build(root, classifiers={"knn": {"n_neighbors": 3}})


# -- the pipeline fixtures --------------------------------------------------------------------
SNAKEMAKE = [sys.executable, "-m", "snakemake"]


def snakemake(workdir, *args, check=True):
    result = subprocess.run(SNAKEMAKE + list(args), cwd=workdir, capture_output=True, text=True)
    if check and result.returncode != 0:
        raise AssertionError(
            f"snakemake {' '.join(args)} failed:\n{result.stdout[-3000:]}\n{result.stderr[-5000:]}"
        )
    return result


def copy_project(target: Path) -> Path:
    """The workflow's files (no results) in `target`, to run a pipeline in."""
    target.mkdir(parents=True, exist_ok=True)
    for name in ("Snakefile", "workflow", "config", ".test", "profiles"):
        source = ROOT / name
        if source.is_dir():
            # __pycache__ comes along: the bytecode (valid while the sources keep their times,
            # which copytree keeps) and numba's cache (compile_mesh_kernel)
            shutil.copytree(source, target / name)
        else:
            shutil.copy(source, target / name)
    return target


@pytest.fixture(scope="session")
def smoke(tmp_path_factory):
    """The gear bench's smoke run (.test/config/smoke.yaml, every target) in a copy of the project:
    (project folder, results folder). Read-only: a test that reruns or edits copies it."""
    workdir = copy_project(tmp_path_factory.mktemp("smoke"))
    snakemake(workdir, "--cores", "2", "--configfile", ".test/config/smoke.yaml")
    return workdir, workdir / "results" / "smoke"


# normal, inner race, ball, outer race 0.007 in at 0 HP, and the faults again at 1 HP
CWRU_SLICE = ["97.mat", "105.mat", "118.mat", "130.mat", "106.mat", "119.mat", "131.mat"]


def cwru_folder(path: Path, files) -> Path:
    """A folder of links to some of the shared CWRU files and their index."""
    path.mkdir()
    for name in files:  # links, never copies of the data
        os.symlink(CWRU / name, path / name)
    os.symlink(CWRU / "index.csv", path / "index.csv")
    return path


@pytest.fixture(scope="session")
def cwru_run(tmp_path_factory):
    """The bearing rig's smoke run (.test/config/cwru-smoke.yaml, every target) on CWRU_SLICE:
    (project folder, results folder). Its files are read only; a test may add a run of another
    run_name beside it (test_cwru_pipeline.py's second folder)."""
    if not CWRU.is_dir():
        pytest.skip(f"no CWRU data at {CWRU} (set CONDMON_CWRU_DIR)")
    root = tmp_path_factory.mktemp("cwru")
    workdir = copy_project(root / "project")
    folder = cwru_folder(root / "slice", CWRU_SLICE)
    snakemake(
        workdir,
        "--cores",
        "2",
        "--configfile",
        ".test/config/cwru-smoke.yaml",
        "--config",
        f"measured_dir={folder}",
    )
    return workdir, workdir / "results" / "cwru-smoke"
