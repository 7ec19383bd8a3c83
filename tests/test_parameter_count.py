"""A lint rule: no function or method of the workflow or the benchmarks takes more than
MAX_PARAMETERS parameters (a long list of "skip if None" arguments wants an object: see
condmon.report.inputs). The physics models (workflow/condmon/models/) lie outside the rule; the systems' code is
inside it. Counted: every parameter a caller can pass (positional, keyword-only, *args and
**kwargs one each), a method's self or cls not."""

import ast

from conftest import ROOT

SCANNED = ("workflow", "benchmarks")
PHYSICS = "workflow/condmon/models/"  # parameters in, signals out: a model's parameters are many
MAX_PARAMETERS = 10
# (file, qualified name) -> why it may take more. An entry no longer needed fails the test too.
EXEMPT = {
    (
        "workflow/condmon/cnn.py",
        "CNNEnsembleClassifier.__init__",
    ): "a scikit-learn estimator: get_params, set_params and clone read every hyperparameter "
    "from __init__'s signature (classifiers.cnn's config keys map onto it one to one)",
    (
        "workflow/condmon/systems/gear/order_features.py",
        "OrderFeatures.__init__",
    ): "a scikit-learn transformer: its hyperparameters are __init__'s keywords (features.order)",
}


def parameter_count(node: ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda, method: bool) -> int:
    args = node.args
    positional = [*args.posonlyargs, *args.args]
    if method and positional and positional[0].arg in ("self", "cls"):
        positional = positional[1:]
    return (
        len(positional)
        + len(args.kwonlyargs)
        + (args.vararg is not None)
        + (args.kwarg is not None)
    )


def long_signatures(tree: ast.Module) -> dict[str, int]:
    """{qualified name: parameter count} of every function, method and lambda over the limit."""
    found = {}

    def visit(node, prefix: str, in_class: bool):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.ClassDef):
                visit(child, f"{prefix}{child.name}.", True)
            elif isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
                name = f"{prefix}{getattr(child, 'name', '<lambda>')}"
                if (count := parameter_count(child, in_class)) > MAX_PARAMETERS:
                    found[name] = count
                visit(child, f"{name}.", False)
            else:
                visit(child, prefix, in_class)

    visit(tree, "", False)
    return found


def test_the_counter_counts_what_a_caller_passes():
    tree = ast.parse(
        "class A:\n    def m(self, a, b=1, *c, d, **e): pass\n"
        "def f(a, b, c, d, e, f, g, h, i, j, k): pass\n"
        "def g(a, b, c, d, e, f, g, h, i, j): pass\n"
        "def outer():\n    def inner(*, a, b, c, d, e, f, g, h, i, j, k): pass\n"
    )
    assert long_signatures(tree) == {"f": 11, "outer.inner": 11}
    method = tree.body[0].body[0]
    assert parameter_count(method, method=True) == 5


def test_no_function_takes_more_than_ten_parameters():
    found = {}
    for folder in SCANNED:
        for path in sorted((ROOT / folder).rglob("*.py")):
            relative = path.relative_to(ROOT).as_posix()
            if relative.startswith(PHYSICS):
                continue
            for name, count in long_signatures(ast.parse(path.read_text(), relative)).items():
                found[(relative, name)] = count
    unexpected = {key: count for key, count in found.items() if key not in EXEMPT}
    assert not unexpected, (
        f"more than {MAX_PARAMETERS} parameters (group them into an object, "
        f"as condmon.report.inputs does): {unexpected}"
    )
    stale = sorted(set(EXEMPT) - set(found))
    assert not stale, f"exempt but no longer over the limit, drop from EXEMPT: {stale}"
