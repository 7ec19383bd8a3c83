"""JSON-schema helpers for the config schemas (YAML files): load one, read its defaults, merge a
system's fragment into the shared schema. Pure functions that import nothing of condmon, so the
systems use them without importing `condmon.config` (which asks the system registry)."""

from __future__ import annotations

import copy
from pathlib import Path

import yaml


def load_schema(path) -> dict:
    return yaml.safe_load(Path(path).read_text())


def schema_defaults(schema: dict) -> dict:
    """The defaults a JSON schema object declares, nested (what validation would fill in)."""
    out = {}
    for name, sub in (schema.get("properties") or {}).items():
        if "default" in sub:
            out[name] = sub["default"]
            if isinstance(sub["default"], dict) and sub.get("properties"):
                out[name] = {**schema_defaults(sub), **sub["default"]}
        elif sub.get("type") == "object" and sub.get("properties"):
            out[name] = schema_defaults(sub)
    return out


def merge_schema(base: dict, fragment: dict) -> dict:
    """`base` with a system's schema fragment merged in, key by key (the fragment's `properties`
    and `definitions` join the base's; its values win where both set one). A `default` is one
    value: the fragment's replaces the base's whole."""
    merged = copy.deepcopy(base)
    for key, value in fragment.items():
        if key != "default" and isinstance(value, dict) and isinstance(merged.get(key), dict):
            merged[key] = merge_schema(merged[key], value)
        else:
            merged[key] = copy.deepcopy(value)
    return merged
