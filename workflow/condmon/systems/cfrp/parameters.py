"""Bridge between the CFRP rig's config sections and the drivetrain model: the gear drivetrain's
parameters with laminate tube shafts (classical laminate theory, `models/cfrp/laminate.py`)."""

from __future__ import annotations

import dataclasses

from condmon.models.cfrp.laminate import Laminate, Ply, laminate_tube_section
from condmon.models.gear.drivetrain import GearDrivetrainParameters, ShaftLayout
from condmon.systems.gear.parameters import build_parameters


def shaft_laminate(laminate: dict) -> Laminate:
    """The `model.laminate` section: the ply (Table 2 of the CFRP study), the layup from inside to
    outside (degrees from the shaft axis) and the ply thickness."""
    return Laminate(
        Ply(**laminate["ply"]), tuple(laminate["angles_deg"]), laminate["ply_thickness"]
    )


def build_cfrp_parameters(model: dict, **overrides) -> GearDrivetrainParameters:
    """GearDrivetrainParameters of the CFRP rig: both shafts are tubes of the laminate, their outer
    diameters from the shaft layouts, their bores the laminate's wall inside them."""
    laminate = shaft_laminate(model["laminate"])
    params = build_parameters({k: v for k, v in model.items() if k != "laminate"}, **overrides)
    shafts = {}
    for name in ("input_shaft", "output_shaft"):
        layout: ShaftLayout = getattr(params, name)
        bore = layout.diameter - 2 * laminate.thickness
        if bore <= 0:
            raise ValueError(
                f"model.laminate: the wall ({laminate.thickness * 1e3:.3g} mm) fills model.{name} "
                f"(diameter {layout.diameter * 1e3:.3g} mm)"
            )
        shafts[name] = dataclasses.replace(layout, inner_diameter=bore)
    sections = tuple(
        laminate_tube_section(shafts[name].diameter, laminate)
        for name in ("input_shaft", "output_shaft")
    )
    return params.replace(shaft_sections=sections, **shafts)
