"""The registry of simulated systems: `system` in the config names one.

A system (a rig and its model family) implements `condmon.systems.base.System`. The built-in
ones are listed in `BUILT_IN` by import path, so a run imports only its own system's code; a
system of the user's registers itself with `register` from a Python file or module that the
config lists under `system_modules` (imported by `import_modules` before any lookup, in the
Snakefile and in every job). Rules and scripts ask this registry; nothing else in the workflow
branches on a system's name.
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
from pathlib import Path

from condmon.systems.base import System

# name -> "module:Class" of the systems that ship with the project (one line per system)
BUILT_IN = {
    "gear": "condmon.systems.gear:GearSystem",
    "bearing": "condmon.systems.bearing:BearingSystem",
    "cfrp": "condmon.systems.cfrp:CfrpSystem",
}
_REGISTERED: dict[str, type[System]] = {}


def register(system_class: type[System]) -> type[System]:
    """Add a system under its `name` (usable as a class decorator). A name taken by another
    class is an error, never a silent override."""
    name = getattr(system_class, "name", None)
    if not isinstance(name, str) or not name:
        raise ValueError(f"{system_class!r} has no `name` to register under")
    if not issubclass(system_class, System):
        raise TypeError(f"{system_class.__name__} does not implement condmon.systems.base.System")
    taken = _REGISTERED.get(name)
    if (
        taken is not None
        and taken is not system_class
        and (taken.__module__, taken.__qualname__)
        != (system_class.__module__, system_class.__qualname__)
    ):
        raise ValueError(
            f"system {name!r} is already registered ({taken.__module__}.{taken.__qualname__})"
        )
    if name in BUILT_IN and not _is_built_in(name, system_class):
        raise ValueError(f"system {name!r} is a built-in system; register yours under another name")
    _REGISTERED[name] = system_class
    return system_class


def _is_built_in(name: str, system_class: type) -> bool:
    module, qualname = BUILT_IN[name].split(":")
    return (system_class.__module__, system_class.__qualname__) == (module, qualname)


def import_modules(modules) -> None:
    """Import the user's system modules: a path to a .py file, or an importable module name."""
    for entry in modules or []:
        path = Path(entry)
        if entry.endswith(".py"):
            if not path.is_file():
                raise ValueError(f"system_modules: {entry}: no such file")
            module_name = "condmon_system_" + path.stem
            if module_name in sys.modules and getattr(
                sys.modules[module_name], "__file__", None
            ) == str(path.resolve()):
                continue
            spec = importlib.util.spec_from_file_location(module_name, path.resolve())
            module = importlib.util.module_from_spec(spec)
            sys.modules[module_name] = module
            spec.loader.exec_module(module)
        else:
            try:
                importlib.import_module(entry)
            except ImportError as exc:
                raise ValueError(f"system_modules: cannot import {entry!r} ({exc})") from exc


def system_names(modules=()) -> list[str]:
    import_modules(modules)
    return sorted(set(BUILT_IN) | set(_REGISTERED))


def system_class(name: str, modules=()) -> type[System]:
    """The class registered as `name` (after importing `modules`)."""
    import_modules(modules)
    if name not in _REGISTERED and name in BUILT_IN:
        module, qualname = BUILT_IN[name].split(":")
        register(getattr(importlib.import_module(module), qualname))
    if name not in _REGISTERED:
        raise ValueError(
            f"system: unknown system {name!r}; registered: {system_names()} (a system of "
            "your own: list its module under system_modules)"
        )
    return _REGISTERED[name]


def get_system(config: dict) -> System:
    """The system a validated config chooses, built on that config."""
    return system_class(config["system"], config.get("system_modules", ()))(config)


def load_system(spec: dict) -> System:
    """The system of a job, from the `system` param a rule passes (`System.job_spec`)."""
    return system_class(spec["name"], spec.get("modules", ()))(spec["config"])
