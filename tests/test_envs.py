"""The set-up: environment.txt, the rules' conda environments (they pin what environment.txt pins
and hold every package their rules' code imports), the Python check, and `snakemake --lint`."""

import ast
import os
import re
import subprocess
import sys
import tomllib
from importlib import metadata

import pytest
import yaml
from packaging.requirements import Requirement

import condmon
from conftest import ROOT

ENVS = ROOT / "workflow" / "envs"
PYTORCH_CPU_INDEX = "--extra-index-url https://download.pytorch.org/whl/cpu"


def pins(lines) -> dict:
    out = {}
    for line in lines:
        match = re.fullmatch(r"\s*([A-Za-z0-9_.\-]+)==([^\s#]+)\s*", line)
        if match:
            out[match.group(1).lower()] = match.group(2)
    return out


def pip_section(path) -> list[str]:
    spec = yaml.safe_load(path.read_text())
    return next(d["pip"] for d in spec["dependencies"] if isinstance(d, dict))


def rule_scripts() -> dict:
    """{rule: (environment name, script path)} from workflow/rules/*.smk."""
    out = {}
    for smk in (ROOT / "workflow" / "rules").glob("*.smk"):
        for block in re.split(r"^rule ", smk.read_text(), flags=re.M)[1:]:
            name = block.split(":")[0]
            env = re.search(r'conda:\n\s+"\.\./envs/(\w+)\.yaml"', block)
            script = re.search(r'script:\n\s+"\.\./scripts/(\w+\.py)"', block)
            assert env and script, f"rule {name}: a conda: environment and a script:"
            out[name] = (env.group(1), ROOT / "workflow" / "scripts" / script.group(1))
    return out


def condmon_file(module: str):
    """The source file of a condmon module, or None."""
    parts = module.split(".")
    path = (ROOT / "workflow" / "condmon").joinpath(*parts[1:])
    for candidate in (path / "__init__.py", path.with_suffix(".py")):
        if candidate.is_file():
            return candidate
    return None


def imported_top_levels(script) -> set[str]:
    """Third-party top-level modules a script can import: its imports and, through every condmon
    module it reaches, theirs (lazy ones and the systems' "module:Class" paths too)."""
    seen, third_party, todo = set(), set(), [script]
    while todo:
        tree = ast.parse(todo.pop().read_text())
        names = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                names |= {alias.name for alias in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names |= {node.module} | {f"{node.module}.{alias.name}" for alias in node.names}
            elif (
                isinstance(node, ast.Constant)
                and isinstance(node.value, str)
                and re.fullmatch(r"condmon(\.\w+)+:\w+", node.value)
            ):
                names.add(node.value.split(":")[0])
        for name in names:
            parts = name.split(".")
            if parts[0] != "condmon":
                if parts[0] not in sys.stdlib_module_names:
                    third_party.add(parts[0])
                continue
            for end in range(1, len(parts) + 1):
                module = ".".join(parts[:end])
                path = condmon_file(module)
                if path is not None and module not in seen:
                    seen.add(module)
                    todo.append(path)
    return third_party


def with_dependencies(names) -> set[str]:
    """The installed distributions `names` pull in (their whole dependency closure)."""
    closure, todo = set(), [n.lower() for n in names]
    while todo:
        name = todo.pop()
        if name in closure:
            continue
        closure.add(name)
        for requirement in metadata.requires(name) or []:
            requirement = Requirement(requirement)
            if requirement.marker is None or requirement.marker.evaluate({"extra": ""}):
                todo.append(requirement.name.lower().replace("_", "-"))
    return closure


def test_every_rule_environment_pins_what_environment_txt_pins():
    lines = (ROOT / "environment.txt").read_text().splitlines()
    environment = pins(lines)
    # the CPU build from PyTorch's index where it answers; no local label, so the pin also resolves on PyPI
    assert environment["torch"] == "2.13.0" and PYTORCH_CPU_INDEX in lines, (
        "the CPU torch, chosen explicitly"
    )
    envs = sorted(ENVS.glob("*.yaml"))
    assert envs
    for path in envs:
        spec = yaml.safe_load(path.read_text())
        assert "python>=3.11,<3.14" in spec["dependencies"], path.name
        pip = pip_section(path)
        packages = [p for p in pip if not p.startswith("-")]
        assert all("==" in p for p in packages), f"{path.name}: unpinned {packages}"
        for name, version in pins(packages).items():
            assert environment.get(name) == version, (
                f"{path.name}: {name}=={version}, environment.txt {environment.get(name)}"
            )
        assert ("torch" in pins(packages)) == (PYTORCH_CPU_INDEX in pip), (
            f"{path.name}: torch's CPU index"
        )
        assert "-e ../.." in pip, f"{path.name} must install the project"


@pytest.mark.slow
def test_every_rule_environment_holds_what_its_code_imports():
    distributions = metadata.packages_distributions()
    for rule, (env, script) in sorted(rule_scripts().items()):
        listed = with_dependencies(pins(pip_section(ENVS / f"{env}.yaml")))
        needed = {
            dist.lower().replace("_", "-")
            for top in imported_top_levels(script)
            for dist in distributions.get(top, [top])
        }
        assert needed - {"condmon"} <= listed, (
            f"rule {rule}: {env}.yaml lacks {sorted(needed - listed - {'condmon'})}"
        )


def test_the_import_scan_finds_the_systems_models():
    """The scan follows the registry's "module:Class" paths: the features script reaches exudyn."""
    assert {"exudyn", "sklearn", "numpy"} <= imported_top_levels(
        ROOT / "workflow" / "scripts" / "features.py"
    )


def test_a_wrong_python_is_named(monkeypatch):
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert pyproject["project"]["requires-python"] == ">=3.11,<3.14"
    assert condmon.python_version_error() is None
    monkeypatch.setattr(condmon, "SUPPORTED_PYTHONS", ((3, 98), (3, 99)))
    assert "needs Python 3.98, 3.99" in condmon.python_version_error()


def test_every_rule_has_an_environment():
    assert {env for env, _ in rule_scripts().values()} == {p.stem for p in ENVS.glob("*.yaml")}


@pytest.mark.slow  # Snakemake parses the whole workflow: 5-7 s a config
@pytest.mark.parametrize("configfile", ["config/config.yaml", ".test/config/smoke.yaml"])
def test_the_linter_is_content(configfile):
    result = subprocess.run(
        [sys.executable, "-m", "snakemake", "--lint", "--configfile", configfile],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]


def pypi_reachable() -> bool:
    import urllib.request

    try:
        urllib.request.urlopen("https://pypi.org/simple/pip/", timeout=10).close()
        return True
    except OSError:
        return False


@pytest.mark.slow
def test_the_pins_resolve_for_the_other_pythons(tmp_path):
    """Every pin of environment.txt has a distribution for Python 3.12 and 3.13 on PyPI: wheels
    (--only-binary), and the pure-Python sdists (connection_pool) as they are. A dry run: only the
    index and the wheels' metadata are fetched, for both Pythons at once (the wait is the network's)."""
    if not pypi_reachable():
        pytest.skip("PyPI cannot be reached from here")
    lines = (ROOT / "environment.txt").read_text().splitlines()
    requirements = [f"{name}=={version}" for name, version in pins(lines).items()]
    sdist_only = {"connection-pool", "connection_pool"}
    wheels = [r for r in requirements if r.split("==")[0] not in sdist_only]
    sdists = [r for r in requirements if r.split("==")[0] in sdist_only]
    env = {
        k: v for k, v in os.environ.items() if not k.startswith("PIP_")
    }  # PyPI only, no local wheels
    runs = {}
    for python in ("3.12", "3.13"):
        pip = [
            sys.executable,
            "-m",
            "pip",
            "install",
            "--dry-run",
            "--no-deps",
            "--ignore-installed",
            "--isolated",
            "--python-version",
            python,
            "--target",
            str(tmp_path / python),
            "--quiet",
        ]
        for kind, extra, names in (
            ("wheels", ["--only-binary=:all:"], wheels),
            ("sdists", [], sdists),
        ):
            runs[python, kind] = subprocess.Popen(
                [*pip, *extra, *names],
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                text=True,
                env=env,
            )
    for (python, kind), run in runs.items():
        _, stderr = run.communicate(timeout=900)
        assert run.returncode == 0, f"Python {python} ({kind}): " + stderr[-3000:]


def test_the_workflow_is_formatted_as_the_workflow_catalog_checks():
    """snakefmt --check (the version the Snakemake workflow catalog runs, pinned) on every
    Snakemake file."""
    result = subprocess.run(
        [sys.executable, "-m", "snakefmt", "--check", "Snakefile", "workflow"],
        cwd=ROOT,
        capture_output=True,
        text=True,
    )
    assert result.returncode == 0, result.stderr[-3000:]
