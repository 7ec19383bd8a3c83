"""README.md is a user's manual that works as written: short, undated, its two main commands as
CI runs them, and every command in it runs in a fresh copy of the project (Snakemake ones as a dry
run, the others as far as they run without a finished run: `--help`)."""

import importlib.util
import json
import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import CWRU, ROOT

README = ROOT / "README.md"
INSTALL = "python3 -m pip install -r environment.txt"
MAIN_RUN = f"{INSTALL} && snakemake --cores all"
TEST_RUN = f"{INSTALL} && python3 -m pytest -q --durations=25"
# set-up steps that install or change the shell: shown, not run by a test
SET_UP = ("sudo apt-get install", "python3 -m venv", ". .venv/bin/activate", INSTALL)
# files a command names that the user brings (their own rig's table): made empty in the copy
USER_FILES = ("data/rig1/signals.parquet",)


def readme_commands(text: str) -> list[str]:
    """Every command of the README: each line of a ```sh block, and each inline code span that
    starts with a program the README runs (snakemake, condmon, python3, mlflow)."""
    blocks = re.findall(r"```sh\n(.*?)```", text, re.DOTALL)
    lines = [line.strip() for block in blocks for line in block.splitlines() if line.strip()]
    inline = re.findall(r"`((?:snakemake|condmon|condmon-compare|python3|mlflow) [^`]+)`", text)
    return lines + inline


def steps(command: str) -> list[str]:
    """The steps of a `a && b` command line, the set-up steps left out."""
    return [step.strip() for step in command.split("&&") if not step.strip().startswith(SET_UP)]


def check_of(step: str) -> list[str] | None:
    """How a test runs `step`: a Snakemake command as a dry run (`--report FILE` left out: a report
    needs a finished run, the pipeline tests make one; the dry run checks its config and plan),
    a program as `<program> [subcommand] --help`; None for the test commands themselves
    (CI runs them, `.ci/run`)."""
    words = shlex.split(step)
    if words[0] == "snakemake":
        if "--report" in words:
            at = words.index("--report")
            del words[at : at + 2]
        return [sys.executable, "-m", "snakemake", "-n", "--quiet", "rules", *words[1:]]
    if words[:3] == ["python3", "-m", "pytest"]:
        return None
    if words[0] == "python3" and words[1].startswith("benchmarks/"):
        return [sys.executable, words[1], "--help"]
    if words[0] in ("condmon", "mlflow"):
        return [words[0], words[1], "--help"]
    if words[0] == "condmon-compare":
        return [words[0], "--help"]
    raise AssertionError(
        f"README command {step!r}: no test knows how to run it (add it to check_of)"
    )


def test_the_readme_is_short_undated_and_reaches_predict_early():
    text = README.read_text()
    lines = text.splitlines()
    assert len(lines) <= 200
    assert not re.search(r"\b20\d\d-\d\d-\d\d\b", text), (
        "a date in README.md: history goes to docs/experiments/"
    )
    predict = next(
        n for n, line in enumerate(lines, 1) if line.startswith("#") and "predict" in line
    )
    assert predict < 120
    assert "before" not in " ".join(line.lower() for line in lines if line.startswith("|"))


def test_the_two_main_commands_are_as_ci_runs_them():
    commands = readme_commands(README.read_text())
    assert MAIN_RUN in commands and TEST_RUN in commands
    ci = [
        line
        for line in (ROOT / ".ci" / "run").read_text().splitlines()
        if line and not line.startswith("#")
    ]
    assert ci[-1] == TEST_RUN


def test_the_suite_times_benchmark_times_the_readme_test_command(monkeypatch):
    """benchmarks/suite_times.py runs the README's test command (its pytest step) and records
    the outcomes and the time per test file that conftest.py writes where CONDMON_TEST_TIMES
    points, beside the wall and CPU seconds (a fake suite here)."""
    spec = importlib.util.spec_from_file_location(
        "suite_times", ROOT / "benchmarks" / "suite_times.py"
    )
    suite_times = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(suite_times)
    assert [" ".join(suite_times.COMMAND)] == steps(TEST_RUN)
    files = {"tests/test_a.py": {"seconds": 2.0, "tests": 4}}

    def fake_suite(command, cwd, env):
        assert command == [sys.executable, *suite_times.COMMAND[1:], "-k", "a"] and cwd == ROOT
        outcomes = {"passed": 3, "skipped": 1}
        Path(env["CONDMON_TEST_TIMES"]).write_text(
            json.dumps({"outcomes": outcomes, "files": files})
        )
        return subprocess.CompletedProcess(command, 0)

    monkeypatch.setattr(suite_times.subprocess, "run", fake_suite)
    figures = suite_times.time_suite(["-k", "a"])
    assert figures["command"] == "python3 -m pytest -q --durations=25 -k a"
    assert figures["tests"] == 4 and figures["files"] == files and figures["returncode"] == 0
    assert figures["wall_seconds"] >= 0 and figures["cpu_seconds"] >= 0
    assert set(figures["machine"]) == {"cores", "load_average_at_start", "load_average_at_end"}


def test_every_readme_command_is_one_the_test_can_run():
    for command in readme_commands(README.read_text()):
        for step in steps(command):
            check_of(step)  # raises for a command no test runs


def broken_links(page: Path) -> list[str]:
    """Relative links of a Markdown page whose file does not exist (anchors are not checked)."""
    targets = re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", page.read_text())
    return [t for t in targets if "://" not in t and not (page.parent / t).exists()]


def test_the_pages_link_to_files_that_exist(tmp_path):
    pages = [
        README,
        ROOT / "CHANGELOG.md",
        ROOT / "config" / "README.md",
        *sorted((ROOT / "docs").rglob("*.md")),
    ]
    assert {str(p.relative_to(ROOT)): broken_links(p) for p in pages if broken_links(p)} == {}
    page = tmp_path / "a.md"
    page.write_text("[here](b.md), [web](https://example.org), [there](a.md#top)")
    assert broken_links(page) == ["b.md"]


def fresh_copy(folder: Path) -> Path:
    """The project's files as a fresh clone has them (tracked, and new files not ignored), with the
    shared data beside it where this machine has them, and the user's own files made empty."""
    listed = subprocess.run(
        ["git", "ls-files", "--cached", "--others", "--exclude-standard", "-z"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=True,
    ).stdout.split("\0")
    copy = folder / "condmon"
    for name in filter(None, listed):
        source = ROOT / name
        if source.is_file():
            (copy / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(source, copy / name)
    if CWRU.exists():
        (folder / "shared" / "data").mkdir(parents=True)
        (folder / "shared" / "data" / "cwru").symlink_to(CWRU)
    for name in USER_FILES:
        (copy / name).parent.mkdir(parents=True, exist_ok=True)
        (copy / name).touch()
    return copy


@pytest.mark.slow
def test_every_readme_command_runs_in_a_fresh_copy(tmp_path):
    """About 10 s a Snakemake dry run."""
    copy = fresh_copy(tmp_path)
    env = {k: v for k, v in os.environ.items() if k != "CONDMON_CWRU_DIR"}
    failures = []
    for command in dict.fromkeys(readme_commands(README.read_text())):
        for step in steps(command):
            check = check_of(step)
            if check is None:
                continue
            result = subprocess.run(check, cwd=copy, capture_output=True, text=True, env=env)
            if result.returncode:
                failures.append(
                    f"{step}\n  -> {' '.join(check)}\n{(result.stdout + result.stderr)[-1500:]}"
                )
    assert not failures, "\n\n".join(failures)
