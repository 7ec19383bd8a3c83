"""Multibody models and their physics: pure functions of parameters, returning signals.

One subpackage per system that runs them (`gear`: the geared drivetrain, which the `cfrp` system
builds from its own parameters; `cfrp`: laminate shafts; `bearing`: the bearing rig), and at the
top what several share (`numerics`, `structure`). Installed as `condmon.models`; a model imports
nothing of the workflow above it, nor another system's subpackage (tests/test_systems.py)."""
