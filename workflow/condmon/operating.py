"""Operating points: the conditions a rig is calibrated and simulated at (a speed, and a load
where the rig runs several)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd


@dataclass(frozen=True)
class OperatingPoint:
    """One operating condition the rig is calibrated and simulated at: its input speed and, where
    the rig runs several, its load (in the measured table's unit; None: the model's one load)."""

    speed_rpm: float
    load: float | None = None
    load_unit: str = "N m"

    @property
    def label(self) -> str:
        """The point in job and file names: `450rpm`, or `450rpm_20Nm` / `450rpm_50pct`."""
        speed = f"{float(self.speed_rpm):g}rpm"
        if self.load is None:
            return speed
        return f"{speed}_{float(self.load):g}{LOAD_UNIT_TAGS[self.load_unit]}"

    def describe(self) -> str:
        """The point in messages: `450 rpm` or `450 rpm, 20 N m`."""
        speed = f"{float(self.speed_rpm):g} rpm"
        if self.load is None:
            return speed
        unit = "%" if self.load_unit == "percent" else f" {self.load_unit}"
        return f"{speed}, {float(self.load):g}{unit}"

    def holds(self, frame: pd.DataFrame) -> pd.Series:
        """Which rows of a signal table (speed_rpm, load) were taken at this point."""
        at = np.isclose(frame["speed_rpm"].astype(float), float(self.speed_rpm))
        if self.load is not None:
            at &= np.isclose(frame["load"].astype(float), float(self.load))
        return pd.Series(at, index=frame.index)


# the tag of a load's unit in a point's label (file names hold no spaces or %)
LOAD_UNIT_TAGS = {"N m": "Nm", "percent": "pct"}


def as_point(point) -> OperatingPoint:
    """An `OperatingPoint`, or a speed (rpm) as the point at the model's one load."""
    return point if isinstance(point, OperatingPoint) else OperatingPoint(float(point))
