"""The test suite's own layout: a test module imports no other test module (shared helpers live in
conftest.py, or benchmarks/fake_train_outputs.py, shared with a benchmark), and the project's paths are found
once, in conftest.py (`ROOT`, `SCRIPTS`, `CWRU`)."""

import ast
import re

from conftest import ROOT

TESTS = ROOT / "tests"
OWN_LOCATION = re.compile(r"Path\(__file__\)|dirname\(__file__\)")


def imported_modules(path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names |= {alias.name.split(".")[0] for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split(".")[0])
    return names


def test_no_test_module_imports_another():
    test_modules = {path.stem for path in TESTS.glob("test_*.py")}
    hits = {path.name: sorted(imported_modules(path) & test_modules) for path in TESTS.glob("*.py")}
    assert {name: found for name, found in hits.items() if found} == {}


def test_the_project_root_is_found_only_in_conftest():
    """A path built from a test file's own location (its `__file__`'s parents) is a second ROOT."""
    hits = [
        f"{path.name}:{n}"
        for path in sorted(TESTS.glob("*.py"))
        if path.name != "conftest.py"
        for n, line in enumerate(path.read_text().splitlines(), 1)
        if OWN_LOCATION.search(line)
    ]
    assert hits == []


def test_no_benchmark_imports_from_tests():
    """benchmarks/ load configs as the workflow does (condmon.config.load_config), never through
    the test suite's helpers: no import of a tests/ module, no tests/ folder put on sys.path."""
    test_modules = {path.stem for path in TESTS.glob("*.py")}
    hits = {}
    for path in sorted((ROOT / "benchmarks").glob("*.py")):
        found = sorted(imported_modules(path) & test_modules)
        if found or re.search(r"ROOT\s*/\s*[\"']tests[\"']", path.read_text()):
            hits[path.name] = found
    assert hits == {}


def fixtures(path) -> dict[str, str]:
    """{name: its code (AST, comments aside)} of the fixtures a test file defines."""
    found = {}
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.FunctionDef):
            for decorator in node.decorator_list:
                target = decorator.func if isinstance(decorator, ast.Call) else decorator
                if isinstance(target, ast.Attribute) and target.attr == "fixture":
                    found[node.name] = ast.dump(node)
    return found


def test_a_fixture_two_test_files_share_lives_in_conftest():
    """The same fixture (the same code) in two test files belongs in conftest.py, once."""
    seen = {}
    for path in sorted(TESTS.glob("test_*.py")):
        for name, code in fixtures(path).items():
            seen.setdefault(code, []).append(f"{path.name}::{name}")
    assert [where for where in seen.values() if len(where) > 1] == []
