"""The potential-energy mesh stiffness (models/gear/mesh.py) on its own: no exudyn."""

import math

import numpy as np
import pytest

from condmon.models.gear.mesh import (
    GearGeometry,
    GearMesh,
    ProfileDeviation,
    ToothDamage,
    iso6336_mesh_stiffness,
    pair_stiffness_per_width,
    tooth_compliances,
)

RIG = (
    GearGeometry()
)  # the helical-gear study's pair: 29/44, m_n 2.25 mm, 20 deg, 26 deg helix, b 20 mm
SPUR = GearGeometry(helix_angle_deg=0.0)


@pytest.fixture(scope="module")
def rig_mesh():
    return GearMesh(RIG)


def test_rig_geometry_and_cases_of_root_vs_base_circle():
    # Table 2 of the study: pitch diameters 72.7 and 110.3 mm.
    assert 2 * RIG.pitch_radius(29) == pytest.approx(72.7e-3, abs=0.2e-3)
    assert 2 * RIG.pitch_radius(44) == pytest.approx(110.3e-3, abs=0.2e-3)
    # The pinion's root circle lies inside its base circle (case 1), the gear's outside (case 2).
    assert RIG.root_below_base(29) and not RIG.root_below_base(44)
    assert 1.2 < RIG.contact_ratio < 2.0 and RIG.overlap_ratio == pytest.approx(
        RIG.face_width * math.sin(RIG.helix_angle) / (math.pi * RIG.normal_module)
    )


def test_the_two_cases_meet_where_root_and_base_circle_coincide():
    """Tooth compliance is continuous as the root circle crosses the base circle (case 1 -> 2)."""
    crossing = (RIG.pitch_radius(29) - RIG.base_radius(29)) / RIG.normal_module  # dedendum factor
    s = np.linspace(RIG.path_start, RIG.path_end, 5)
    alpha1 = s / RIG.base_radius(29) - RIG.half_tooth_angle(29)
    below = GearGeometry(dedendum_factor=crossing * 1.0001)
    above = GearGeometry(dedendum_factor=crossing * 0.9999)
    assert below.root_below_base(29) and not above.root_below_base(29)
    for part in ("bending", "shear", "axial", "fillet"):
        a = tooth_compliances(below, 29, alpha1)[part]
        b = tooth_compliances(above, 29, alpha1)[part]
        np.testing.assert_allclose(a, b, rtol=2e-3, err_msg=part)


def test_every_stiffness_part_is_positive_and_bending_softest_at_the_tip():
    s = np.linspace(RIG.path_start, RIG.path_end, 7)
    alpha1 = s / RIG.base_radius(29) - RIG.half_tooth_angle(29)
    parts = tooth_compliances(RIG, 29, alpha1)
    for value in parts.values():
        assert np.all(value > 0)
    assert np.all(np.diff(parts["bending"]) > 0)  # load moving towards the pinion tip


def test_helical_tvms_has_the_mesh_period_and_the_iso_6336_mean(rig_mesh):
    phase = np.linspace(0.0, 1.0, 401)
    k = rig_mesh.mesh_stiffness(phase)
    np.testing.assert_allclose(rig_mesh.mesh_stiffness(phase + 1.0), k, rtol=1e-9)
    np.testing.assert_allclose(rig_mesh.mesh_stiffness(phase + 7.0), k, rtol=1e-9)
    assert (
        np.abs(rig_mesh.mesh_stiffness(phase + 0.5) - k).max() > 0.05 * k.mean()
    )  # not a shorter period
    iso = iso6336_mesh_stiffness(RIG)
    assert 2.5e8 < iso < 4.5e8  # c_gamma_alpha ~ 17 N/(mm um) times 20 mm
    assert rig_mesh.mean_stiffness == pytest.approx(iso, rel=0.25)
    assert k.mean() == pytest.approx(rig_mesh.mean_stiffness, rel=1e-3)


def test_helical_contact_zones_match_the_contact_ratios(rig_mesh):
    ppp = rig_mesh.points_per_pitch
    # Every slice is a spur gear of the transverse profile: two pairs during eps_alpha - 1 of a cycle.
    for i in (0, rig_mesh.slices // 2, rig_mesh.slices - 1):
        inside = (rig_mesh.inside[:, i] > 0.5).astype(int)  # the slice centre in contact
        n = len(inside)
        per_phase = np.zeros(ppp, dtype=int)
        for j in range(-4, 1):  # pairs j at u = phase - j
            idx = np.arange(ppp) - j * ppp
            ok = (idx >= 0) & (idx < n)
            per_phase[ok] += inside[idx[ok]]
        assert set(np.unique(per_phase)) == {1, 2}
        assert np.mean(per_phase == 2) == pytest.approx(RIG.contact_ratio - 1.0, abs=2.0 / ppp)
    # The pair as a whole meshes over eps_alpha + eps_beta: 2 or 3 pairs, 3 during eps_gamma - 2.
    phase = (np.arange(4000) + 0.5) / 4000
    count = rig_mesh.pairs_in_contact(phase)
    assert set(np.unique(count)) == {2, 3}
    assert np.mean(count == 3) == pytest.approx(RIG.total_contact_ratio - 2.0, abs=0.01)


def test_spur_pair_gives_the_rectangular_wave():
    mesh = GearMesh(SPUR, slices=1)
    phase = (np.arange(2000) + 0.5) / 2000
    k = mesh.mesh_stiffness(phase)
    pairs = mesh.pairs_in_contact(phase)
    assert set(np.unique(pairs)) == {1, 2}
    assert np.mean(pairs == 2) == pytest.approx(SPUR.contact_ratio - 1.0, abs=0.002)
    # Two flat levels, the double-contact level well above the single one, sharp jumps between them
    # (a jump spans one cell of the table, 1 / points_per_pitch).
    edge = 1.5 / mesh.points_per_pitch
    switch = SPUR.contact_ratio - 1.0
    clear = (np.abs(phase - switch) > edge) & (phase > edge) & (phase < 1 - edge)
    double, single = k[clear & (pairs == 2)], k[clear & (pairs == 1)]
    assert double.min() > 1.4 * single.max()
    assert (double.max() - double.min()) < 0.1 * double.mean()
    assert (single.max() - single.min()) < 0.1 * single.mean()
    # Double contact from the start of each cycle to eps_alpha - 1 (the entering pair's window opens).
    assert np.all(pairs[phase < SPUR.contact_ratio - 1.0 - 0.002] == 2)
    assert np.all(pairs[phase > SPUR.contact_ratio - 1.0 + 0.002] == 1)
    # The single-pair stiffness per unit face width is of the order of ISO 6336's c' (~14 N/(mm um)).
    peak = pair_stiffness_per_width(SPUR, SPUR.pitch_point)[0] * 1e-9  # N/(mm um) per mm
    assert 9.0 < peak < 18.0


def test_slicing_converges_as_the_number_of_slices_grows():
    phase = np.linspace(0.0, 1.0, 501)
    reference = GearMesh(RIG, slices=640).mesh_stiffness(phase)
    errors = [
        np.abs(GearMesh(RIG, slices=m).mesh_stiffness(phase) - reference).max() / reference.mean()
        for m in (5, 10, 20, 40, 80)
    ]
    assert all(b < a for a, b in zip(errors, errors[1:])), errors
    assert errors[-1] < 0.01  # the drivetrain's default of 80 slices
    # each slice enters and leaves contact gradually (its share of contact line in the path), so
    # even a coarse slicing follows the helix (all-or-nothing slices: 16 % off with 5 slices)
    assert errors[0] < 0.02


def test_pair_stiffness_has_no_slice_staircase(rig_mesh):
    # Slices switching on and off whole make the pair stiffness a staircase (second differences of
    # 1 % of the peak with 80 slices): a ripple far above the output band that the integrator's
    # step cannot follow, so the features changed with the step. Left: the contact lines' corners.
    k = rig_mesh.healthy_groups[0].stiffness
    assert np.abs(np.diff(k, 2)).max() < 0.005 * k.max()


def test_missing_tooth_removes_exactly_one_tooth_share_once_per_pinion_revolution(rig_mesh):
    missing = GearMesh(RIG, damage=ToothDamage("missing", teeth=(0,)))
    z = RIG.teeth_pinion
    phase = np.arange(2 * z * 100) / 100.0  # two pinion revolutions
    loss = rig_mesh.mesh_stiffness(phase) - missing.mesh_stiffness(phase)
    assert np.all(loss >= -1e-6 * rig_mesh.mean_stiffness)
    for rev in (0, 1):
        in_window = (phase >= rev * z) & (phase < rev * z + missing.window)
        # Exactly pinion tooth 0's pair: its whole stiffness over its mesh ...
        np.testing.assert_allclose(
            loss[in_window],
            rig_mesh.pair_stiffness(phase[in_window] - rev * z),
            rtol=1e-9,
            atol=1e-6 * rig_mesh.mean_stiffness,
        )
        # ... which integrates to one tooth's share: one mesh period of the mean stiffness.
        assert loss[(phase >= rev * z) & (phase < (rev + 1) * z)].sum() * 0.01 == pytest.approx(
            rig_mesh.mean_stiffness, rel=0.01
        )
    # Nothing changes while tooth 0 is out of mesh.
    out = ((phase % z) >= missing.window + 0.01) & ((phase % z) < z - 0.01)
    assert np.abs(loss[out]).max() < 1e-6 * rig_mesh.mean_stiffness


def test_spall_chip_and_crack_act_on_their_tooth_and_region_only(rig_mesh):
    u = rig_mesh.u
    healthy = rig_mesh.pair_stiffness(u)
    spall = GearMesh(
        RIG,
        damage=ToothDamage(
            "spall",
            teeth=(3,),
            profile=(0.35, 0.65),
            face=(0.25, 0.75),
            depth=2e-5,
            stiffness_loss=0.15,
        ),
    )
    groups = spall.groups(3)
    assert len(groups) == 2 and spall.groups(4) is spall.healthy_groups
    pit = groups[1]
    # The pit is 20 um below the flank and softer; both parts add up to less than the healthy pair.
    inside = pit.stiffness > 0
    assert inside.any() and np.allclose(pit.deviation[inside], 2e-5)
    assert np.all(groups[0].stiffness + pit.stiffness <= healthy + 1e-6)
    assert groups[0].stiffness + pit.stiffness / 0.85 == pytest.approx(healthy, rel=1e-9)
    # Chip: the tooth loses contact near its tip only (the pair's late phases).
    chip = GearMesh(
        RIG, damage=ToothDamage("chip", teeth=(0,), profile=(0.6, 1.0), face=(0.0, 0.5))
    )
    loss = healthy - chip.pair_stiffness(u, tooth=0)
    assert loss.max() > 0.1 * healthy.max() and np.all(loss[u < 0.5] == 0)
    # Root crack: stiffness falls with crack depth over the whole mesh of the tooth.
    means = [
        GearMesh(RIG, damage=ToothDamage("crack", crack_depth=q)).pair_stiffness(u, tooth=0).mean()
        for q in (0.0, 0.25, 0.5, 0.75)
    ]
    assert means[0] == pytest.approx(healthy.mean(), rel=1e-9)
    assert all(b < a for a, b in zip(means, means[1:]))


def test_damage_deeper_than_the_deflection_takes_its_part_of_the_line_out_of_contact():
    """Material removed over half the face, far deeper than the deflection: that half stops
    touching and the other half carries the load (the deflection doubles, a fraction of a um);
    one contact averaged over the face would lower the whole line by half the depth (15 um). The
    damage map's depth-level groups agree with the spall, a contact group of its own."""
    from condmon.models.gear.errors import FlankMap

    load, depth, tooth = 196.0, 3e-5, 5
    half = FlankMap.of(np.where(np.linspace(0, 1, 101) <= 0.5, depth, 0.0)[None, :])
    maps = tuple(half if t == tooth else None for t in range(SPUR.teeth_pinion))
    mapped = GearMesh(SPUR, slices=20, damage_maps=maps)
    spall = GearMesh(
        SPUR,
        slices=20,
        damage=ToothDamage(
            "spall",
            teeth=(tooth,),
            profile=(0.0, 1.0),
            face=(0.0, 0.5),
            depth=depth,
            stiffness_loss=0.0,
        ),
    )
    healthy = GearMesh(SPUR, slices=20)
    alone = tooth + np.linspace(
        SPUR.contact_ratio - 1 + 0.05, 0.95, 20
    )  # tooth 5's pair alone in mesh
    base = healthy.loaded_transmission_error(alone, load)
    change = mapped.loaded_transmission_error(alone, load) - base
    assert change == pytest.approx(base, rel=0.1)  # half the line: twice the deflection
    assert change.max() < 0.1 * depth / 2  # not half the depth
    assert mapped.loaded_transmission_error(alone, load) == pytest.approx(
        spall.loaded_transmission_error(alone, load), rel=1e-6
    )
    with pytest.raises(ValueError, match="damage map and a spall"):
        GearMesh(SPUR, slices=20, damage_maps=maps, damage=ToothDamage("spall", teeth=(tooth,)))


def test_static_transmission_error_follows_the_profile_deviation():
    # N along the line of action, 100 N m on the gear: the deflection (about 5 um) exceeds the 1 um
    # deviation, so every pair in mesh stays in contact and the TE is linear in the deviation (at
    # 10 N m, 0.5 um, pairs standing back would leave the contact)
    load = 1960.0
    phase = np.arange(1000) / 1000.0
    for geometry, slices, gain in ((SPUR, 1, 1.0), (RIG, 80, abs(np.sinc(RIG.overlap_ratio)))):
        smooth = GearMesh(geometry, slices=slices).loaded_transmission_error(phase, load)
        wavy = GearMesh(geometry, slices=slices, profile_deviation=ProfileDeviation(1e-6))
        te = wavy.loaded_transmission_error(phase, load) - smooth
        amplitude = 2 * abs(np.fft.rfft(te)[1]) / len(te)
        # Spur: the flank deviation is the transmission error; helical: averaged over the contact
        # lines across the face (overlap ratio eps_beta), sinc(eps_beta) of it remains.
        assert amplitude == pytest.approx(1e-6 * gain, rel=0.05)
        assert wavy.sine_te_gain == pytest.approx(gain, rel=0.05)
        # Asked for a static TE instead, the flank deviation is sized to give it.
        sized = GearMesh(geometry, slices=slices, transmission_error=0.3e-6)
        te = sized.loaded_transmission_error(phase, load) - smooth
        assert 2 * abs(np.fft.rfft(te)[1]) / len(te) == pytest.approx(0.3e-6, rel=1e-3)
        assert sized.flank_amplitude == pytest.approx(0.3e-6 / sized.sine_te_gain)
    # Tip relief lowers the stiffness-weighted engagement and adds a static TE of its own.
    relief = GearMesh(SPUR, slices=1, profile_deviation=ProfileDeviation(tip_relief=5e-6))
    assert (
        relief.loaded_transmission_error(phase, load).mean()
        > GearMesh(SPUR, slices=1).loaded_transmission_error(phase, load).mean()
    )


def test_damage_and_geometry_errors_are_named():
    with pytest.raises(ValueError, match="unknown tooth damage"):
        ToothDamage("dent")
    with pytest.raises(ValueError, match="profile"):
        ToothDamage("spall", profile=(0.7, 0.3))
    with pytest.raises(ValueError, match="slices"):
        GearMesh(RIG, slices=0)
