"""Gear manufacturing errors sized by an ISO 1328-1 accuracy grade, and tooth flanks as geometry.

Pure: parameters in, per-tooth deviations out.

ISO 1328-1:1995 gives, for accuracy grade 5, tolerances of the single pitch (f_pt), total
cumulative pitch (F_p), total profile (F_alpha) and total helix (F_beta) deviations and the radial
run-out (F_r) from the normal module m, the reference diameter d and the face width b (mm, um);
every grade step multiplies them by sqrt(2) (`iso1328_tolerances`, unrounded as in
`../shared/notes/gear-tolerances.md`). A gear *of* grade Q keeps every deviation within Q's
tolerance; `draw_gear_errors` draws one such gear: deviations a share of the tolerance
(`deviation_share`), shaped as real gears are (a smooth cumulative pitch pattern over the
revolution plus tooth-to-tooth scatter; a profile slope per tooth around a common one; a common
helix slope), and the eccentricity that makes its run-out.

A tooth flank's deviation from the perfect involute helicoid is a `FlankMap`: material removed
(m, > 0) on a grid over the active profile (rows: roll fraction, 0 at the start of contact on the
pinion root, 1 at its tip) and the face (columns: fraction of the face width). The mesh
(`mesh.GearMesh`) lowers the contact of every slice by the map at its contact point, so
manufacturing deviations, wear and a virtual bench's own damage are one kind of input.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

GRADE_STEP = math.sqrt(2.0)


@dataclass(frozen=True)
class IsoTolerances:
    """ISO 1328-1 tolerances of one gear at one grade, m."""

    single_pitch: float  # f_pt
    cumulative_pitch: float  # F_p
    profile: float  # F_alpha
    helix: float  # F_beta
    runout: float  # F_r (radial run-out, twice the eccentricity)


def iso1328_tolerances(
    grade: float, normal_module: float, reference_diameter: float, face_width: float
) -> IsoTolerances:
    """The unrounded ISO 1328-1:1995 tolerances (SI in, m out) of a gear of accuracy `grade`
    (grade 5 formulas times sqrt(2)^(grade - 5); fractional grades interpolate geometrically)."""
    if not 1 <= grade <= 12:
        raise ValueError(
            f"ISO 1328-1 accuracy grade {grade}: the standard defines grades 1 to 12 "
            "(ground gears 4-6, hobbed 7-9)"
        )
    m, d, b = normal_module * 1e3, reference_diameter * 1e3, face_width * 1e3
    scale = GRADE_STEP ** (grade - 5) * 1e-6
    cumulative = 0.3 * m + 1.25 * math.sqrt(d) + 7
    return IsoTolerances(
        single_pitch=(0.3 * (m + 0.4 * math.sqrt(d)) + 4) * scale,
        cumulative_pitch=cumulative * scale,
        profile=(3.2 * math.sqrt(m) + 0.22 * math.sqrt(d) + 0.7) * scale,
        helix=(0.1 * math.sqrt(d) + 0.63 * math.sqrt(b) + 4.2) * scale,
        runout=0.8 * cumulative * scale,
    )


@dataclass(frozen=True)
class FlankMap:
    """Material removed from a tooth flank (m; negative: proud material) on a grid: rows over the
    active profile (roll fraction 0..1), columns over the face width (0..1), both evenly spaced.
    One row or one column means constant along that direction."""

    values: tuple  # rows of columns

    @staticmethod
    def of(array) -> "FlankMap":
        array = np.atleast_2d(np.asarray(array, dtype=float))
        if not np.isfinite(array).all():
            raise ValueError("flank map: non-finite deviation")
        return FlankMap(tuple(tuple(float(v) for v in row) for row in array))

    @staticmethod
    def from_function(function, rows: int = 21, columns: int = 11) -> "FlankMap":
        """The map of function(roll fraction, face fraction) (arrays) on a rows x columns grid."""
        roll, face = np.meshgrid(np.linspace(0, 1, rows), np.linspace(0, 1, columns), indexing="ij")
        return FlankMap.of(function(roll, face))

    def array(self) -> np.ndarray:
        return np.asarray(self.values, dtype=float)

    def at(self, roll, face) -> np.ndarray:
        """Bilinear interpolation at roll and face fractions (arrays of one shape; clipped to 0..1)."""
        return FlankPoints(roll, face).values(self)

    def __add__(self, other: "FlankMap") -> "FlankMap":
        """The sum of two maps on the finer of their grids."""
        a, b = self.array(), other.array()
        rows, cols = max(a.shape[0], b.shape[0]), max(a.shape[1], b.shape[1])
        roll, face = np.meshgrid(np.linspace(0, 1, rows), np.linspace(0, 1, cols), indexing="ij")
        return FlankMap.of(self.at(roll, face) + other.at(roll, face))


class FlankPoints:
    """Fixed points on a flank (roll and face fractions, arrays of one shape; clipped to 0..1) at
    which many maps are read (`values`, bilinear): the cells and weights of each grid shape are
    worked out once, not per map (a mesh reads every tooth's map at the same slice points)."""

    def __init__(self, roll, face):
        self.roll = np.clip(np.asarray(roll, dtype=float), 0.0, 1.0)
        self.face = np.clip(np.asarray(face, dtype=float), 0.0, 1.0)
        # grid shape -> the flat grid indices of each point's cell corners (i, j), (i + 1, j),
        # (i, j + 1), (i + 1, j + 1) (clipped to the grid) and their four weights
        self._cells = {}

    def values(self, flank_map: "FlankMap") -> np.ndarray:
        grid = flank_map.array()
        cells = self._cells.get(grid.shape)
        if cells is None:
            rows, cols = grid.shape
            i, fx = _cell(self.roll, rows)
            j, fy = _cell(self.face, cols)
            i1, j1 = np.minimum(i + 1, rows - 1), np.minimum(j + 1, cols - 1)
            cells = self._cells[grid.shape] = (
                i * cols + j,
                i1 * cols + j,
                i * cols + j1,
                i1 * cols + j1,
                (1 - fx) * (1 - fy),
                fx * (1 - fy),
                (1 - fx) * fy,
                fx * fy,
            )
        c00, c10, c01, c11, w00, w10, w01, w11 = cells
        flat = grid.ravel()  # take on the flat grid: a tenth of the time of 2-d fancy indexing
        return (
            w00 * flat.take(c00)
            + w10 * flat.take(c10)
            + w01 * flat.take(c01)
            + w11 * flat.take(c11)
        )


def _cell(fraction: np.ndarray, points: int) -> tuple[np.ndarray, np.ndarray]:
    """(index of the grid cell, position within it) of fractions 0..1 on `points` even points."""
    if points == 1:
        return np.zeros(fraction.shape, int), np.zeros(fraction.shape)
    x = fraction * (points - 1)
    index = np.minimum(x.astype(int), points - 2)
    return index, x - index


def add_flank_maps(first: tuple, second: tuple) -> tuple:
    """Tooth-wise sum of two per-tooth tuples of FlankMap or None (an empty tuple: no maps)."""
    if not first:
        return tuple(second)
    if not second:
        return tuple(first)
    if len(first) != len(second):
        raise ValueError(f"flank maps for {len(first)} and {len(second)} teeth")
    return tuple(b if a is None else a if b is None else a + b for a, b in zip(first, second))


@dataclass(frozen=True)
class GearErrors:
    """One manufactured gear: tooth position (cumulative pitch) deviations, m, per tooth; the flank
    map of every tooth (profile and helix deviations); the eccentricity (m) and its phase."""

    grade: float
    tolerances: IsoTolerances
    pitch_deviations: tuple
    flank_maps: tuple
    eccentricity: float
    eccentricity_phase: float

    def single_pitch_deviations(self) -> np.ndarray:
        """f_pt,k: each pitch's deviation (tooth k's position minus tooth k-1's)."""
        p = np.asarray(self.pitch_deviations)
        return p - np.roll(p, 1)

    def total_cumulative_pitch(self) -> float:
        """F_p: the range of the tooth position deviations."""
        p = np.asarray(self.pitch_deviations)
        return float(p.max() - p.min())


def draw_gear_errors(
    rng: np.random.Generator,
    grade: float,
    teeth: int,
    normal_module: float,
    reference_diameter: float,
    face_width: float,
    deviation_share: float = 0.7,
    misalignment: float = 0.0,
    profile_rows: int = 5,
) -> GearErrors:
    """One gear of accuracy `grade`: every deviation `deviation_share` (0..1] of its tolerance at
    most, shaped as follows.

    - Tooth positions: a smooth pattern over the revolution (orders 1-3, random phases; what a
      hobbing or grinding machine's indexing leaves) plus independent scatter per tooth, scaled
      so that F_p and the largest single pitch deviation stay within share x tolerance.
    - Eccentricity: a radial run-out F_r = 2 e of share x tolerance at most (uniform up to it).
    - Profile: a slope deviation per tooth (root to tip), a common part plus scatter, within
      share x F_alpha; helix: one slope across the face for all teeth plus `misalignment` (m of
      mesh misalignment across the face: the shafts' non-parallelism seen at the flank)."""
    if not 0 <= deviation_share <= 1:
        raise ValueError(
            f"deviation_share {deviation_share}: a share of the tolerance in [0, 1] (0: a perfect gear)"
        )
    tol = iso1328_tolerances(grade, normal_module, reference_diameter, face_width)
    angle = 2 * math.pi * np.arange(teeth) / teeth
    smooth = sum(
        rng.normal(0.0, 1.0 / order) * np.sin(order * angle + rng.uniform(0, 2 * math.pi))
        for order in (1, 2, 3)
    )
    scatter = rng.normal(0.0, 1.0, teeth)
    smooth = smooth / max(np.ptp(smooth), 1e-12)
    scatter = scatter / max(np.abs(scatter - np.roll(scatter, 1)).max(), 1e-12)
    # cumulative pattern near the F_p limit, scatter near the f_pt limit, then both scaled together
    positions = smooth * tol.cumulative_pitch * rng.uniform(
        0.5, 1.0
    ) + scatter * tol.single_pitch * rng.uniform(0.5, 1.0)
    single = np.abs(positions - np.roll(positions, 1)).max()
    scale = deviation_share * min(
        tol.cumulative_pitch / max(np.ptp(positions), 1e-18),
        tol.single_pitch / max(single, 1e-18),
        1.0,
    )
    positions = (positions - positions.mean()) * scale

    eccentricity = 0.5 * tol.runout * deviation_share * rng.uniform(0.0, 1.0)
    # profile slopes: material removed rising linearly from root to tip (negative: falling)
    common = rng.uniform(-1.0, 1.0)
    slopes = (
        deviation_share
        * tol.profile
        * np.clip(0.6 * common + 0.4 * rng.uniform(-1.0, 1.0, teeth), -1.0, 1.0)
    )
    helix = deviation_share * tol.helix * rng.uniform(-1.0, 1.0) + misalignment
    roll = np.linspace(0.0, 1.0, profile_rows)[:, None]
    face = np.array([[0.0, 1.0]])
    maps = tuple(FlankMap.of(slope * (roll - 0.5) + helix * (face - 0.5)) for slope in slopes)
    return GearErrors(
        grade=float(grade),
        tolerances=tol,
        pitch_deviations=tuple(positions.tolist()),
        flank_maps=maps,
        eccentricity=float(eccentricity),
        eccentricity_phase=float(rng.uniform(0, 2 * math.pi)),
    )


def contact_fatigue_band(geometry) -> tuple[float, float]:
    """The roll fractions of the pinion flank where pitting starts: from its lowest point of single
    tooth contact B up to the pitch point C. At B the pinion's contact stress peaks (one pair
    carries the load where the radii of curvature are small: ISO 6336-2 rates the pinion there,
    factor Z_B), and below C the sliding opposes the rolling, which drives the cracks into the
    flank; so pits start in the dedendum near the pitch line. Sorted, each clipped to 0..1."""
    lowest_single_contact = geometry.roll_fraction(geometry.path_end - geometry.base_pitch)
    pitch = geometry.roll_fraction(geometry.pitch_point)
    low, high = sorted(float(np.clip(x, 0.0, 1.0)) for x in (lowest_single_contact, pitch))
    return low, high


def wear_flank_map(
    depth: float,
    roughness: float,
    rng: np.random.Generator,
    pitch_line: float = 0.5,
    rows: int = 21,
    columns: int = 11,
) -> FlankMap:
    """Sliding wear of a flank (the gear model's surface fault): material removed in proportion to
    the sliding distance (Archard's law), which grows with the distance from the pitch line (roll
    fraction `pitch_line`: the geometry's `roll_fraction` of the pitch point), so the depth is
    `depth` at the far end of the flank and a fifth of it at the pitch line, plus a rough surface
    (Gaussian, `roughness` rms, correlated over a grid cell)."""
    roll = np.linspace(0.0, 1.0, rows)[:, None]
    sliding = np.abs(roll - pitch_line) / max(pitch_line, 1 - pitch_line)
    removed = depth * (0.2 + 0.8 * sliding) * np.ones((1, columns))
    if roughness:
        removed = removed + rng.normal(0.0, roughness, (rows, columns))
    return FlankMap.of(np.maximum(removed, 0.0))


def broken_tooth_flank_map(
    missing_share: float, slant: float = 0.2, rows: int = 41, columns: int = 11
) -> FlankMap:
    """A tooth broken off (the gear model's missing tooth short of a whole tooth): the flank above a
    fracture line is gone (1 mm removed: it never touches). The fracture runs diagonally across the
    face, as tooth breakage of a helical gear does: at face position f it leaves the profile below
    roll fraction 1 - `missing_share` + `slant` (f - 0.5), clipped to [0, 1]."""
    if not 0.0 < missing_share <= 1.0:
        raise ValueError(
            f"missing_share {missing_share}: the share of the profile lost lies in (0, 1]"
        )
    roll, face = np.meshgrid(np.linspace(0, 1, rows), np.linspace(0, 1, columns), indexing="ij")
    fracture = np.clip(1.0 - missing_share + slant * (face - 0.5), 0.0, 1.0)
    return FlankMap.of(np.where(roll >= fracture, 1.0e-3, 0.0))


def pitted_flank_map(
    pit_depth: float,
    pitted_area: float,
    band: tuple,
    rng: np.random.Generator,
    rows: int = 31,
    columns: int = 16,
) -> FlankMap:
    """Pitting of a flank (the gear model's other surface fault): craters where contact fatigue
    starts (`band`: roll fractions, `contact_fatigue_band`), each a Gaussian bowl up to
    `pit_depth` deep, centred in the band, added until `pitted_area` of the band is pitted."""
    low, high = band
    if not 0.0 <= low <= high <= 1.0:
        raise ValueError(f"pitting band {band}: roll fractions 0 <= low <= high <= 1")
    roll, face = np.meshgrid(np.linspace(0, 1, rows), np.linspace(0, 1, columns), indexing="ij")
    # a band narrower than two grid rows still has rows to measure its pitted share on
    half_row = 1.0 / (rows - 1)
    zone = (roll >= low - half_row) & (roll <= high + half_row)
    removed = np.zeros_like(roll)
    for _ in range(500):
        if (removed[zone] > 0.1 * pit_depth).mean() >= pitted_area:
            break
        centre_roll, centre_face = rng.uniform(low, high), rng.uniform(0.0, 1.0)
        width_roll, width_face = rng.uniform(0.02, 0.06), rng.uniform(0.04, 0.12)
        bowl = (
            pit_depth
            * rng.uniform(0.4, 1.0)
            * np.exp(
                -0.5
                * (
                    ((roll - centre_roll) / width_roll) ** 2
                    + ((face - centre_face) / width_face) ** 2
                )
            )
        )
        removed = np.maximum(removed, bowl)
    return FlankMap.of(removed)


def pair_errors(rng, grade: float, share: float, geometry, misalignment) -> dict:
    """One gear pair's manufacturing deviations (`draw_gear_errors`) as
    GearDrivetrainParameters (or GearStage) fields: pitch deviations, run-out, and the pinion's
    flank maps with the mesh misalignment (`misalignment()`, m, drawn for the pinion only)."""
    fields = {}
    for name, teeth in (("pinion", geometry.teeth_pinion), ("gear", geometry.teeth_gear)):
        gear = draw_gear_errors(
            rng,
            grade,
            teeth,
            geometry.normal_module,
            2 * geometry.pitch_radius(teeth),
            geometry.face_width,
            share,
            misalignment=misalignment() if name == "pinion" else 0.0,
        )
        fields.update(
            {
                f"pitch_errors_{name}": gear.pitch_deviations,
                f"runout_{name}": gear.eccentricity,
                f"runout_phase_{name}": gear.eccentricity_phase,
            }
        )
        if name == "pinion":
            fields["flank_maps_pinion"] = gear.flank_maps
    return fields
