"""config/README.md is rendered from the schemas (config/render_readme.py): a stale page fails,
every key of the YAML schemas carries a description, and descriptions change neither validation
nor the defaults."""

import copy
import importlib.util

import yaml

from condmon.config import load_schema, validate_config
from condmon.schema import schema_defaults
from conftest import ROOT

spec = importlib.util.spec_from_file_location("render_readme", ROOT / "config" / "render_readme.py")
render = importlib.util.module_from_spec(spec)
spec.loader.exec_module(render)
SCHEMAS = [
    ROOT / "config" / "schema.yaml",
    *sorted((ROOT / "workflow" / "condmon" / "systems").glob("*/schema.yaml")),
]


def test_the_config_reference_is_rendered_from_the_schemas():
    """Run `python3 config/render_readme.py` after editing a schema."""
    assert (ROOT / "config" / "README.md").read_text() == render.page(), (
        "config/README.md is stale: run python3 config/render_readme.py"
    )


def undescribed(schema: dict, definitions: dict, prefix: str = "") -> list[str]:
    """Keys below `schema` (properties, map values, list items, oneOf branches; definitions
    followed) without a description."""
    missing = []
    for name, sub in render.children(schema):
        key = f"{prefix}{name}"
        resolved = render.resolve(sub, definitions)
        if not resolved.get("description"):
            missing.append(key)
        missing += undescribed(resolved, definitions, f"{key}.")
    return missing


def test_every_key_of_the_yaml_schemas_has_a_description():
    shared = load_schema(SCHEMAS[0])
    for path in SCHEMAS:
        schema = load_schema(path)
        definitions = {**shared.get("definitions", {}), **schema.get("definitions", {})}
        assert undescribed(schema, definitions) == [], path.relative_to(ROOT)
    # the check bites: a key without one is named
    assert undescribed(
        {"properties": {"a": {"type": "object", "properties": {"b": {"type": "string"}}}}}, {}
    ) == ["a", "a.b"]


def without_descriptions(value):
    """A schema with every `description` removed (a property named `description` stays)."""
    if isinstance(value, dict):
        return {
            k: without_descriptions(v)
            for k, v in value.items()
            if not (k == "description" and isinstance(v, str))
        }
    if isinstance(value, list):
        return [without_descriptions(v) for v in value]
    return value


def test_descriptions_change_neither_the_defaults_nor_validation():
    for path in SCHEMAS:
        schema = load_schema(path)
        assert schema_defaults(schema) == schema_defaults(without_descriptions(schema)), path
    config = yaml.safe_load((ROOT / "config" / "config.yaml").read_text())
    shared = load_schema(SCHEMAS[0])
    assert validate_config(copy.deepcopy(config), shared) == validate_config(
        copy.deepcopy(config), without_descriptions(shared)
    )
