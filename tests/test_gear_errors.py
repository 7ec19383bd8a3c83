"""Gear manufacturing errors by ISO 1328-1 grade, flank maps, and how they act in the mesh."""

import math

import numpy as np
import pytest
import yaml
from conftest import ROOT

from condmon.models.gear.drivetrain import GearDrivetrainParameters, SimulationSettings, simulate
from condmon.models.gear.errors import (
    FlankMap,
    draw_gear_errors,
    iso1328_tolerances,
    wear_flank_map,
)
from condmon.models.gear.mesh import GearGeometry, GearMesh
from condmon.models.gear.virtual_bench import bench_fault, broken_tooth_map, pitting_map

GEOMETRY = GearGeometry()
PINION_DIAMETER = 2 * GEOMETRY.pitch_radius(GEOMETRY.teeth_pinion)


def test_tolerances_match_the_worked_example():
    """../shared/notes/gear-tolerances.md: the helical pinion (d = 72.6 mm) at grade 4 has
    f_pt = 4.0 um and F_p = 13 um; at grade 6, 8.1 um and 26 um."""
    assert PINION_DIAMETER == pytest.approx(72.6e-3, abs=0.1e-3)
    grade4 = iso1328_tolerances(4, GEOMETRY.normal_module, PINION_DIAMETER, GEOMETRY.face_width)
    grade6 = iso1328_tolerances(6, GEOMETRY.normal_module, PINION_DIAMETER, GEOMETRY.face_width)
    assert grade4.single_pitch == pytest.approx(4.0e-6, abs=0.05e-6)
    assert grade4.cumulative_pitch == pytest.approx(13e-6, abs=0.5e-6)
    assert grade6.single_pitch == pytest.approx(8.1e-6, abs=0.05e-6)
    assert grade6.cumulative_pitch == pytest.approx(26e-6, abs=0.5e-6)
    assert grade6.runout == pytest.approx(0.8 * grade6.cumulative_pitch)
    with pytest.raises(ValueError, match="grades 1 to 12"):
        iso1328_tolerances(13, GEOMETRY.normal_module, PINION_DIAMETER, GEOMETRY.face_width)


@pytest.mark.parametrize("grade", [4, 5, 6, 8, 11])
def test_a_grade_yields_deviations_within_its_limits(grade):
    rng = np.random.default_rng(grade)
    for share in (1.0, 0.5):
        for _ in range(40):
            gear = draw_gear_errors(
                rng, grade, 29, GEOMETRY.normal_module, PINION_DIAMETER, GEOMETRY.face_width, share
            )
            tol = gear.tolerances
            assert np.abs(gear.single_pitch_deviations()).max() <= share * tol.single_pitch * (
                1 + 1e-9
            )
            assert gear.total_cumulative_pitch() <= share * tol.cumulative_pitch * (1 + 1e-9)
            assert 2 * gear.eccentricity <= share * tol.runout * (1 + 1e-9)
            for flank in gear.flank_maps:
                values = flank.array()
                profile = np.ptp(values[:, 0])  # root to tip at one face edge
                helix = np.ptp(values[0, :])  # across the face at the root
                assert profile <= share * tol.profile * (1 + 1e-9)
                assert helix <= share * tol.helix * (1 + 1e-9)
    # a real gear of the grade, not a perfect one: its largest pitch deviation a fair part of the limit
    gear = draw_gear_errors(
        np.random.default_rng(1),
        grade,
        29,
        GEOMETRY.normal_module,
        PINION_DIAMETER,
        GEOMETRY.face_width,
        1.0,
    )
    assert np.abs(gear.single_pitch_deviations()).max() > 0.3 * gear.tolerances.single_pitch


def test_flank_map_interpolates_and_adds():
    flank = FlankMap.from_function(lambda roll, face: 2e-6 * roll + 1e-6 * face, rows=3, columns=2)
    assert flank.at(np.array(0.25), np.array(0.5)) == pytest.approx(2e-6 * 0.25 + 0.5e-6)
    total = flank + FlankMap.of([[1e-6]])
    assert total.at(np.array(1.0), np.array(1.0)) == pytest.approx(4e-6)
    with pytest.raises(ValueError, match="non-finite"):
        FlankMap.of([[np.nan]])


def test_wear_removes_most_at_root_and_tip():
    wear = wear_flank_map(2e-5, 0.0, np.random.default_rng(0)).array()
    middle = wear.shape[0] // 2
    assert wear[0].mean() == pytest.approx(2e-5) and wear[-1].mean() == pytest.approx(2e-5)
    assert wear[middle].mean() < 0.3 * 2e-5


def test_a_flank_map_of_constant_depth_is_a_later_contact():
    """Material removed evenly from a tooth's flank (h) lowers its pair's contact exactly as a pitch
    deviation of -h would: the loaded transmission error of the mesh is the same."""
    depth = 3e-6
    maps = tuple(
        FlankMap.of([[depth]]) if tooth == 5 else None for tooth in range(GEOMETRY.teeth_pinion)
    )
    with_map = GearMesh(GEOMETRY, slices=20, flank_maps=maps)
    plain = GearMesh(GEOMETRY, slices=20)
    phase = np.linspace(3.0, 9.0, 301)
    te_map = with_map.loaded_transmission_error(phase, 300.0)
    te_plain = plain.loaded_transmission_error(phase, 300.0)
    # the worn tooth's pair carries less: the mesh deflects more while it is in contact
    assert te_map.max() > te_plain.max()
    assert np.allclose(
        te_map[phase < 5.0 - with_map.window], te_plain[phase < 5.0 - with_map.window]
    )


SPUR = GearGeometry(
    teeth_pinion=20, teeth_gear=30, normal_module=2e-3, helix_angle_deg=0.0, face_width=0.012
)


def test_a_lead_slope_many_times_the_deflection_loads_one_face_end():
    """A spur pair's lead slope s (across the face b) under a load that deflects the whole face by
    d0 << s: the contact lines averaged at their mean deviation ignore it (the mesh deflects d0
    past the mean), while face strips of their own touch from the proud end only, over
    c = b sqrt(2 d0 / s) (linear slices), which deflects by s c / b."""
    slope = 15e-6
    lead = FlankMap.from_function(lambda roll, face: slope * face, rows=2, columns=2)
    maps = (lead,) * SPUR.teeth_pinion
    phase = np.linspace(3.0, 5.0, 201)
    load = 100.0
    whole_face = GearMesh(SPUR, slices=40).loaded_transmission_error(phase, load)
    line = GearMesh(SPUR, slices=40, flank_maps=maps).loaded_transmission_error(phase, load)
    strips = GearMesh(SPUR, slices=40, flank_maps=maps, contact_step=0.25e-6)
    edge = strips.loaded_transmission_error(phase, load)
    assert np.allclose(line - slope / 2, whole_face)
    d0 = whole_face.mean()
    assert slope > 20 * d0
    assert edge.mean() == pytest.approx(slope * np.sqrt(2 * d0 / slope), rel=0.05)
    # the strips far above the proud end (they never touch) are one contact
    assert len(strips.groups(0)) <= strips.contact_strips + 1
    # a flank without deviations stays one contact
    assert len(GearMesh(SPUR, slices=40, contact_step=0.25e-6).groups(0)) == 1
    with pytest.raises(ValueError, match="contact_step"):
        GearMesh(SPUR, slices=40, contact_step=0.0)


def _sideband(signal, fs, gmf, shaft):
    window = np.hanning(len(signal))
    amplitude = np.abs(np.fft.rfft(signal * window)) / window.sum() * 2
    freqs = np.fft.rfftfreq(len(signal), 1 / fs)

    def peak(f):
        i = int(np.argmin(abs(freqs - f)))
        return amplitude[i - 1 : i + 2].max()

    return peak(gmf - shaft) + peak(gmf + shaft)


def test_eccentricity_raises_the_mesh_sidebands_as_it_grows():
    """An eccentric pinion shifts its mesh cycle by e / base pitch once per revolution: the first
    sidebands of the mesh frequency grow with the eccentricity."""
    speed = 1100.0
    shaft = speed / 60
    gmf = shaft * GEOMETRY.teeth_pinion
    settings = SimulationSettings(duration=0.6)
    levels = []
    for eccentricity in (0.0, 5e-6, 20e-6):
        signals = simulate(
            GearDrivetrainParameters(speed_rpm=speed, runout_pinion=eccentricity), settings
        )
        levels.append(_sideband(signals["A1_y"], settings.output_rate, gmf, shaft))
    assert levels[0] < levels[1] < levels[2]
    assert levels[2] > 3 * levels[1] > 9 * levels[0]


def test_bench_fault_forms_are_its_own_geometry():
    """The bench's surface fault (pitting), missing tooth (broken tooth) and spall (a crater) are
    flank geometry it builds itself: the model runs them as a healthy mesh with those flanks."""
    rng = np.random.default_rng(3)
    faults = {
        "surface_fault": {"form": "pitting", "teeth": 4, "pit_depth": 3e-5, "pitted_area": 0.3},
        "missing_tooth": {"form": "broken_tooth", "broken_height": 0.8},
    }
    state, maps = bench_fault("surface_fault", faults, 29, 27, rng)
    assert state == "healthy"
    assert [i for i, m in enumerate(maps) if m is not None] == [0, 1, 27, 28]
    pits = maps[27].array()
    roll = np.linspace(0, 1, pits.shape[0])
    band = pits[(roll >= 0.3) & (roll <= 0.6)]
    assert (band > 0).mean() >= 0.3 and pits.max() <= 3e-5 and pits[:8].max() == 0.0
    state, maps = bench_fault("missing_tooth", faults, 29, 3, rng)
    assert (
        state == "healthy"
        and maps[3].array()[-1, 0] == pytest.approx(1e-3)
        and maps[3].array()[0, 0] == 0.0
    )
    assert bench_fault("spall", faults, 29, 3, rng) == ("spall", ())  # no bench form: the model's
    with pytest.raises(ValueError, match="unknown form"):
        bench_fault("spall", {"spall": {"form": "crater"}}, 29, 3, rng)
    # its spall: a crater with a rough floor over the stated region of one tooth
    faults["spall"] = {"form": "spall", "depth": 2e-4, "profile": [0.3, 0.6], "face": [0.1, 0.9]}
    state, maps = bench_fault("spall", faults, 20, 11, rng)
    assert state == "healthy" and [i for i, m in enumerate(maps) if m is not None] == [11]
    crater = maps[11].array()
    roll, face = np.meshgrid(
        np.linspace(0, 1, crater.shape[0]), np.linspace(0, 1, crater.shape[1]), indexing="ij"
    )
    inside = (roll >= 0.3) & (roll <= 0.6) & (face >= 0.1) & (face <= 0.9)
    assert crater[~inside].max() == 0.0
    assert (
        0.7 * 2e-4 <= crater[inside].min()
        and crater[inside].max() <= 2e-4
        and np.ptp(crater[inside]) > 0
    )
    assert pitting_map(rng, 1e-5, 0.5).array().max() <= 1e-5
    assert broken_tooth_map(0.5).array()[:20].max() == 0.0


def test_per_sample_gear_errors_come_from_the_config():
    from conftest import system_of

    system = system_of(".test/config/smoke.yaml")
    params = system.parameters()
    from condmon.systems.gear.parameters import sample_effects

    effects = sample_effects(system.config["model"], params.geometry, np.random.default_rng(0))
    again = sample_effects(system.config["model"], params.geometry, np.random.default_rng(0))
    assert effects["pitch_errors_pinion"] == again["pitch_errors_pinion"]
    assert len(effects["flank_maps_pinion"]) == params.geometry.teeth_pinion
    low, high = system.config["model"]["fault_severity"]["wear_depth"]
    assert low <= effects["wear_depth"] <= high
    widths = []
    for k in range(20):  # the spall: its width drawn in its range, anywhere across the face
        start, end = sample_effects(
            system.config["model"], params.geometry, np.random.default_rng(k)
        )["spall_face"]
        assert 0.0 <= start < end <= 1.0
        widths.append(end - start)
    low, high = system.config["model"]["fault_severity"]["spall_width"]
    assert low <= min(widths) and max(widths) <= high and np.ptp(widths) > (high - low) / 4
    grade_high = system.config["model"]["gear_errors"]["grade"][1]
    tol = iso1328_tolerances(
        grade_high, params.geometry.normal_module, PINION_DIAMETER, params.geometry.face_width
    )
    pitch = np.asarray(effects["pitch_errors_pinion"])
    assert np.ptp(pitch) <= tol.cumulative_pitch and math.isfinite(effects["runout_pinion"])
    cycle = math.lcm(params.geometry.teeth_pinion, params.geometry.teeth_gear)
    starts = [
        sample_effects(system.config["model"], params.geometry, np.random.default_rng(k))[
            "start_mesh_phase"
        ]
        for k in range(20)
    ]
    assert 0.0 <= min(starts) and max(starts) < cycle and np.ptp(starts) > cycle / 4


def test_a_run_starts_at_its_drawn_mesh_phase():
    """start_mesh_phase: the mesh excitation of a run started that many mesh periods on is the one
    of a run from phase 0, shifted in time (constant speed) or in phase (with a fluctuation)."""
    from condmon.models.gear.mesh_force import MeshForce

    base = GearDrivetrainParameters(speed_rpm=600.0)
    later = base.replace(start_mesh_phase=7.25)
    period = 1.0 / (600.0 / 60 * GEOMETRY.teeth_pinion)
    for t in (0.0, 0.013, 0.2):
        assert MeshForce(later).excitation(t)[0] == pytest.approx(
            MeshForce(base).excitation(t + 7.25 * period)[0]
        )
    fluctuating = base.replace(speed_fluctuation=0.01, speed_fluctuation_phase=0.4)
    shifted = fluctuating.replace(start_mesh_phase=3.0)
    assert MeshForce(shifted).excitation(0.1)[0] == pytest.approx(
        MeshForce(fluctuating).excitation(0.1)[0] + 3.0
    )


def test_every_bench_record_starts_at_its_own_shaft_angle(monkeypatch):
    """A real acquisition starts at any angle of the shafts: the bench draws each record's
    start_mesh_phase over the pair's full cycle from the record's stream (reproducibly), as the
    model's samples do."""
    import condmon.models.gear.virtual_bench as vb

    seen = []
    monkeypatch.setattr(
        vb,
        "simulate",
        lambda params, settings, extra_loads=(): (
            seen.append(params.start_mesh_phase) or {"A1_x": np.zeros(8)}
        ),
    )
    truth, settings = GearDrivetrainParameters(speed_rpm=775.0), SimulationSettings(duration=0.1)
    for seed in (5, 5):
        rng = np.random.default_rng(seed)
        for _ in range(10):
            vb.bench_record(truth, vb.BenchForm(), settings, rng, gears={})
    cycle = math.lcm(GEOMETRY.teeth_pinion, GEOMETRY.teeth_gear)
    assert seen[:10] == seen[10:] and len(set(seen[:10])) == 10
    assert 0.0 <= min(seen) and max(seen) < cycle and np.ptp(seen) > cycle / 4


@pytest.mark.parametrize(
    "variant", sorted(p.name for p in (ROOT / "config" / "benches").glob("*.yaml"))
)
def test_bench_variants_layer_over_the_default_config(variant):
    """Each shipped bench variant states only what differs from config/config.yaml, its base: alone
    (`--configfile config/benches/<variant>`) it validates, names its own run and differs from the
    default bench in what the report lists. A bench of the default rig changes its bench alone; a
    rig of its own (two-stage.yaml: a gear train) its model, conditions and channels too."""
    from conftest import deep_update, system_of

    changes = yaml.safe_load((ROOT / "config" / "benches" / variant).read_text())
    default = system_of("config/config.yaml")
    system = system_of(f"config/benches/{variant}")
    assert not system.problems()
    assert changes.pop("base") == "config/config.yaml"
    assert system.config["run_name"] != default.config["run_name"]
    assert system.bench_differences() != default.bench_differences()
    own_rig = {"rig", "model", "features", "hybrid"} if variant == "two-stage.yaml" else set()
    assert set(changes) <= {"run_name", "virtual_bench"} | own_rig
    assert deep_update({}, changes)  # plain mapping


def test_the_report_lists_the_cfrp_benchs_own_spall():
    from conftest import system_of

    rows = {row["difference"]: row for row in system_of("config/cfrp.yaml").bench_differences()}
    spall = rows["spall as its own spall (depth 0.0002, profile [0.3, 0.6], face [0.1, 0.9])"]
    assert spall["handled"] == "randomised" and spall["within_range"]
    assert rows["shaft_crack: no form of its own"]["handled"] == "same"


def _differences(changes=None):
    from conftest import system_of

    rows = system_of("config/config.yaml", changes).bench_differences()
    assert all(row["handled"] in ("calibrated", "randomised", "neither", "same") for row in rows)
    return {row["difference"].split(" (")[0].split(":")[0]: row for row in rows}


def test_every_difference_of_the_default_bench_says_whether_it_is_calibrated_randomised_or_neither():
    rows = _differences()
    # the mesh's compliance is drawn per sample (model.mesh_compliance); the bench's lies inside
    mesh = rows["mesh_stiffness 5.5e+08 at contact_exponent 1.3"]
    assert mesh["handled"] == "randomised" and mesh["within_range"]
    assert mesh["difference"].endswith("a static deflection of 0.45 um")
    assert rows["restitution 0.8"]["handled"] == "calibrated"
    assert rows["contact_law flores"]["handled"] == "calibrated"
    assert rows["housings as rigid blocks on four feet"]["handled"] == "neither"
    # bearing tones reach every channel through the structure: the incoherent background leaves them out
    tones = next(row for name, row in rows.items() if name.startswith("rolling-bearing tones"))
    assert tones["handled"] == "neither"
    assert rows["coloured sensor noise 0.002 m/s^2 rms"]["handled"] == "calibrated"
    gears = next(row for name, row in rows.items() if name.startswith("its own gears"))
    assert gears["handled"] == "randomised" and gears["within_range"]
    assert rows["missing_tooth as its own broken tooth"]["handled"] == "randomised"


def test_bench_differences_follow_the_config():
    """Each row is read from the config: a deficit background takes the tones, a truth outside the
    search range or a fluctuation beyond the drawn one says so, an override no calibration tunes is
    neither, per-state calibration calibrates its state, a parameter the search leaves out is neither."""
    deficit = _differences({"calibration": {"background_method": "deficit"}})
    assert (
        next(row for name, row in deficit.items() if name.startswith("motor torque ripple"))[
            "handled"
        ]
        == "calibrated"
    )
    outside = _differences(
        {
            "model": {"variability": {"speed_fluctuation_source": "config"}},
            "virtual_bench": {
                "true_parameters": {"mesh_stiffness": 2.0e9},
                "speed_fluctuation": 0.01,
                "model_overrides": {"gear_mass": 1.6},
                "faults": {"missing_tooth": {"form": "broken_tooth", "broken_height": 0.3}},
            },
        }
    )
    assert (
        outside["mesh_stiffness 2e+09 at contact_exponent 1.3"]["within_range"] is False
    )  # 0.17 um
    calibrated_mesh = _differences(
        {
            "model": {"mesh_compliance": None},
            "calibration": {
                "parameters": {"mesh_stiffness": {"low": 1e8, "high": 1.5e9, "log": True}}
            },
        }
    )
    assert calibrated_mesh["mesh_stiffness 5.5e+08"]["handled"] == "calibrated"
    assert calibrated_mesh["contact_exponent 1.3"]["handled"] == "neither"
    assert outside["speed fluctuation 0.01 at 1.5 Hz"]["within_range"] is False
    assert outside["gear_mass 1.6"]["handled"] == "neither"
    assert outside["missing_tooth as its own broken tooth"]["within_range"] is False
    per_state = _differences({"calibration": {"per_state": {"states": ["surface_fault"]}}})
    assert per_state["surface_fault as its own pitting"]["handled"] == "calibrated"
    from conftest import system_of
    from condmon.systems.gear.differences import bench_differences

    system = system_of("config/config.yaml")
    calibration = dict(
        system.config["calibration"], parameters={"mesh_stiffness": {"low": 1e8, "high": 1.5e9}}
    )
    rows = bench_differences(
        dict(system.config, calibration=calibration), system.health_states, system.healthy_state
    )
    assert (
        next(row for row in rows if row["difference"].startswith("bushing_damping"))["handled"]
        == "neither"
    )


def test_pitting_starts_between_the_lowest_point_of_single_contact_and_the_pitch_point():
    """The band is B..C on the pinion's profile: B at (eps_alpha - 1) / eps_alpha of the path of
    contact (one base pitch before its end), C at the pitch point; the pits lie in it."""
    from condmon.models.gear.errors import contact_fatigue_band, pitted_flank_map

    for geometry in (
        GEOMETRY,
        GearGeometry(teeth_pinion=20, teeth_gear=30, normal_module=2e-3, helix_angle_deg=0.0),
    ):
        low, high = contact_fatigue_band(geometry)
        eps = geometry.contact_ratio
        pitch = (geometry.pitch_point - geometry.path_start) / (
            geometry.path_end - geometry.path_start
        )
        assert (low, high) == pytest.approx(tuple(sorted(((eps - 1) / eps, pitch))))
        assert 0.25 < low < high < 0.6  # the dedendum, up to the pitch line
    band = contact_fatigue_band(GEOMETRY)
    pits = pitted_flank_map(3e-5, 0.3, band, np.random.default_rng(4)).array()
    roll = np.linspace(0, 1, pits.shape[0])
    assert pits.max() <= 3e-5
    assert pits[roll > 0.8].max() < 0.01 * 3e-5 and pits[roll < 0.1].max() < 0.01 * 3e-5
    assert (pits[(roll >= band[0]) & (roll <= band[1])] > 3e-6).mean() >= 0.3
    with pytest.raises(ValueError, match="pitting band"):
        pitted_flank_map(3e-5, 0.3, (0.6, 0.4), np.random.default_rng(4))


def test_pitting_is_the_surface_fault_and_wear_a_state_of_its_own():
    from condmon.models.gear.mesh_force import (
        contact_stiffness_factors,
        damage_maps,
        pitting_band,
        surface_fault_form,
    )

    p = GearDrivetrainParameters(health_state="surface_fault", surface_fault_teeth=4)
    assert surface_fault_form(p) == "pitting"
    maps = damage_maps(p)  # pitting on the surface fault's teeth only
    assert [i for i, m in enumerate(maps) if m is not None] == [0, 1, 2, 3]
    # progressive pitting spreads beyond the band where it starts
    low, high = pitting_band(p)
    assert pitting_band(p.replace(pitting_growth=0.1)) == pytest.approx((low - 0.1, high + 0.1))
    worn = damage_maps(
        p.replace(health_state="wear")
    )  # wear: every tooth slides alike, every tooth wears
    assert all(m is not None for m in worn) and len(worn) == p.geometry.teeth_pinion
    assert not np.array_equal(worn[0].array(), worn[1].array())  # each its own rough surface
    # the CFRP study's -15 %: on the surface fault's teeth, or on the whole mesh
    teeth_only = contact_stiffness_factors(p.replace(surface_fault_model="stiffness_loss"))
    assert teeth_only[:4] == [0.85] * 4 and teeth_only[4:] == [1.0] * (p.geometry.teeth_pinion - 4)
    assert (
        contact_stiffness_factors(p.replace(surface_fault_model="mesh_stiffness_loss"))
        == [0.85] * p.geometry.teeth_pinion
    )
    assert (
        contact_stiffness_factors(
            p.replace(surface_fault_model="mesh_stiffness_loss", health_state="wear")
        )
        == [1.0] * p.geometry.teeth_pinion
    )
    with pytest.raises(ValueError, match="unknown surface_fault_model"):
        surface_fault_form(p.replace(surface_fault_model="rust"))


def test_a_tooth_broken_short_of_its_root_is_a_damage_map_and_a_whole_one_is_missing():
    """missing_tooth with missing_share < 1: the part above a diagonal fracture is gone (a damage
    map of the faulty tooth); at 1 the whole tooth is missing (tooth geometry, no map)."""
    from condmon.models.gear.errors import broken_tooth_flank_map
    from condmon.models.gear.mesh_force import damage_maps, tooth_damage

    gone = broken_tooth_flank_map(0.6).array() > 0
    assert gone.mean() == pytest.approx(0.6, abs=0.05)
    assert gone[-1].all() and not gone[0].any()  # the tip is gone, the root stays
    assert gone[:, 0].sum() > gone[:, -1].sum()  # the fracture runs across the face
    with pytest.raises(ValueError, match="missing_share"):
        broken_tooth_flank_map(0.0)
    broken = GearDrivetrainParameters(
        health_state="missing_tooth", missing_share=0.6, faulty_tooth=3
    )
    maps = damage_maps(broken)
    assert (
        tooth_damage(broken) is None
        and maps[3] is not None
        and sum(m is not None for m in maps) == 1
    )
    whole = broken.replace(missing_share=1.0)
    assert tooth_damage(whole).kind == "missing" and damage_maps(whole) == ()


def test_the_run_starts_at_the_deflection_its_engaged_teeth_carry_the_load_at():
    """Pitch errors of tens of micrometres against a deflection under one: at the mean mesh's
    static deflection the teeth in contact at t = 0 carry the load several times over or not at
    all; `starting_deflection` finds where they carry it, and leaves no impact behind."""
    from condmon.models.gear.mesh_force import MeshForce, static_mesh_force

    rng = np.random.default_rng(0)
    base = GearDrivetrainParameters(speed_rpm=600.0, start_mesh_phase=3.3)
    for share in (0.0, 10e-6, 30e-6):
        p = base.replace(
            pitch_errors_pinion=tuple(rng.uniform(-share, share, GEOMETRY.teeth_pinion))
        )
        mesh, force = MeshForce(p), static_mesh_force(p)
        start = mesh.starting_deflection(force)
        assert mesh(0.0, start, 0.0) == pytest.approx(force, rel=1e-6)
        assert not mesh.separated and not mesh.impacts
        if share:  # the mean mesh misses by more than the load itself
            assert abs(mesh(0.0, mesh.static_deflection(force), 0.0) - force) > 0.5 * force
