"""The CFRP drivetrain of the CFRP study (`system: cfrp`): a single-stage spur pair of 3D-printed
composite gears on two carbon-fibre tube shafts, four bearings, four accelerometers (x, y each).

The same exudyn drivetrain model as the helical rig (`condmon.models.gear.drivetrain`), built from
the CFRP rig's config: flexible Timoshenko shafts whose sections come from the laminate (classical
laminate theory), the gears' modulus that of a quasi-isotropic laminate of the same ply, the
study's calibrated contact law and bushings (Table 3), and two shaft faults a rigid shaft cannot
show: a breathing crack and a delamination (`condmon.models.gear.shaft_damage`).

Config sections as the gear system's (`rig`, `model`, `numerics`, `virtual_bench`), with this
rig's defaults (schema.yaml beside this file, merged over the gear system's) and `model.laminate`.
"""

from __future__ import annotations

from pathlib import Path

import yaml

from condmon.schema import merge_schema
from condmon.systems.cfrp.parameters import build_cfrp_parameters
from condmon.systems.gear import GearSystem


class CfrpSystem(GearSystem):
    name = "cfrp"
    schema_file = Path(__file__).with_name("schema.yaml")

    @classmethod
    def schema(cls) -> dict:
        """The gear system's schema with this rig's defaults and its laminate section."""
        return merge_schema(GearSystem.schema(), yaml.safe_load(cls.schema_file.read_text()))

    def parameters(self, **overrides):
        return build_cfrp_parameters(self.config["model"], **overrides)
