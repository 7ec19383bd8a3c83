"""The test suite's own layout: a test module imports no other test module (shared helpers live in
conftest.py, or benchmarks/fake_train_outputs.py, shared with a benchmark), and the project's paths are found
once, in conftest.py (`ROOT`, `SCRIPTS`, `CWRU`)."""

import ast
import re

from conftest import ROOT, file_times, pytest_collection_modifyitems

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


class Item:
    """What conftest's collection hook reads of a collected test."""

    def __init__(self, nodeid, marks=(), fixturenames=()):
        self.nodeid, self.marks, self.fixturenames = nodeid, set(marks), fixturenames

    def add_marker(self, mark):
        self.marks.add(mark.name)

    def get_closest_marker(self, name):
        return name if name in self.marks else None


def test_the_pipeline_files_go_first_each_file_together_and_in_order():
    """pytest-xdist hands the files out in the collection's order (--no-loadscope-reorder): the
    files with the most pipeline tests first (a test that reads a smoke run is one), then the
    most slow ones, then the rest as collected."""
    items = [
        Item("tests/test_a.py::fast"),
        Item("tests/test_b.py::one", ["slow"]),
        Item("tests/test_c.py::reads_the_run", fixturenames=["smoke", "tmp_path"]),
        Item("tests/test_c.py::plain"),
        Item("tests/test_d.py::fast"),
        Item("tests/test_e.py::first", ["pipeline"]),
        Item("tests/test_e.py::second", ["pipeline"]),
    ]
    pytest_collection_modifyitems(items)
    assert [item.nodeid for item in items] == [
        "tests/test_e.py::first",
        "tests/test_e.py::second",
        "tests/test_c.py::reads_the_run",
        "tests/test_c.py::plain",
        "tests/test_b.py::one",
        "tests/test_a.py::fast",
        "tests/test_d.py::fast",
    ]
    assert items[2].marks == {"pipeline"}


def test_the_time_per_test_file_sums_each_tests_setup_call_and_teardown():
    from types import SimpleNamespace as Report

    stats = {
        "passed": [Report(when="call", nodeid="tests/test_a.py::t[1]", duration=2.0)],
        "": [
            Report(when="setup", nodeid="tests/test_a.py::t[1]", duration=30.0),
            Report(when="setup", nodeid="tests/test_a.py::t[2]", duration=0.25),
            Report(when="teardown", nodeid="tests/test_b.py::u", duration=40.0),
        ],
        "warnings": [object()],
    }
    assert file_times(stats) == {
        "tests/test_b.py": {"seconds": 40.0, "tests": 1},
        "tests/test_a.py": {"seconds": 32.2, "tests": 2},
    }
