"""Physics checks of the 3-D gear drivetrain model, its mesh force and its contact laws."""

import math

import numpy as np
import pytest
from scipy.signal import resample_poly

from condmon.features import SpectrumFeatures
from condmon.models.gear.contact_laws import CONTACT_LAWS, contact_force, hysteresis_factor
from condmon.models.gear.drivetrain import (
    Drivetrain,
    GearDrivetrainParameters,
    GearGeometry,
    SimulationSettings,
    sensor_channels,
    simulate,
    steps_per_sensor_sample,
)
from condmon.models.gear.mesh_force import (
    DEFLECTION_REF,
    MESH_HEALTH_STATES,
    MeshForce,
    TVMSMeshForce,
)
from condmon.models.numerics import SimulationError, decimation_filter
from condmon.models.structure import LinearStructure, Section

SIMPLE = "simple"


def test_all_eight_table1_laws_with_their_factors():
    assert len(CONTACT_LAWS) == 8
    cr = 0.8
    expected = {
        "gharib_hurmuzlu": 1 / cr,
        "herbert_mcwhannel": 6 * 0.2 / ((2 * cr - 1) ** 2 + 3),
        "flores": 8 * 0.2 / (5 * cr),
        "lee_wang": 3 * 0.2 / 4,
        "hunt_crossley": 3 * 0.2 / 2,
        "lankarani_nikravesh": 3 * (1 - cr**2) / 4,
        "zhiying_qishao": 3 * (1 - cr**2) * math.exp(2 * 0.2) / 4,
        "gonthier": (1 - cr**2) / cr,
    }
    for law, value in expected.items():
        assert hysteresis_factor(law, cr) == pytest.approx(value)
    # Every law but Gharib-Hurmuzlu dissipates nothing for a perfectly elastic contact.
    assert all(hysteresis_factor(law, 1.0) == 0 for law in CONTACT_LAWS if law != "gharib_hurmuzlu")


def test_unknown_law_and_bad_restitution_are_named():
    with pytest.raises(ValueError, match="unknown contact law 'hertz'"):
        hysteresis_factor("hertz", 0.9)
    with pytest.raises(ValueError, match="restitution"):
        hysteresis_factor("flores", 1.5)


def test_contact_force_never_pulls():
    assert contact_force(-1e-6, 0.0, 1e9, 1.5, 0.1, 0.02) == 0.0
    assert contact_force(1e-6, -10.0, 1e9, 1.5, 0.5, 0.02) == 0.0
    assert contact_force(1e-6, 0.0, 1e9, 1.0, 0.5, 0.02) == pytest.approx(1e3)


def test_geometry_matches_the_study_rig():
    g = GearGeometry()
    # Table 2 of the helical-gear study: pitch diameters 72.7 and 110.3 mm.
    assert 2 * g.pitch_radius(29) == pytest.approx(72.7e-3, abs=0.2e-3)
    assert 2 * g.pitch_radius(44) == pytest.approx(110.3e-3, abs=0.2e-3)
    assert 1.2 < g.contact_ratio < 2.0


def test_decimation_filter_removes_what_would_alias():
    fs_sensor, factor = 51200.0, 10
    t = np.arange(int(fs_sensor)) / fs_sensor
    lowpass = decimation_filter(factor)
    in_band = resample_poly(np.sin(2 * np.pi * 1000.0 * t), 1, factor, window=lowpass)[500:-500]
    above = resample_poly(np.sin(2 * np.pi * 2700.0 * t), 1, factor, window=lowpass)[500:-500]
    assert np.abs(in_band).max() == pytest.approx(1.0, abs=0.01)
    assert np.abs(above).max() < 1e-3  # would fold to 2420 Hz


def test_simple_mesh_force_missing_tooth_removes_one_pair_and_neighbours_catch_the_gear():
    healthy = MeshForce(GearDrivetrainParameters(speed_rpm=600.0, mesh_stiffness_model=SIMPLE))
    missing = MeshForce(
        GearDrivetrainParameters(
            speed_rpm=600.0, health_state="missing_tooth", mesh_stiffness_model=SIMPLE
        )
    )
    ratio = healthy.contact_ratio
    period = 1.0 / healthy.mesh_frequency
    # Middle of the single-contact zone of pair 0 (the missing tooth), static deflection 1 um.
    t = (ratio - 1.0 + (1.0 - (ratio - 1.0)) / 2) * period
    assert healthy(t, 1e-6, 0.0) > 0
    assert missing(t, 1e-6, 0.0) == 0.0
    # Far larger deflection: the neighbouring pairs' extended contact carries the load.
    assert missing(t, 60e-6, 0.0) > 0
    # One pinion revolution later the same tooth is missing again; a tooth away it is not (a
    # fresh force: after the loss of contact above, the next contact would count as an impact).
    assert missing(t + 29 * period, 1e-6, 0.0) == 0.0
    missing = MeshForce(
        GearDrivetrainParameters(
            speed_rpm=600.0, health_state="missing_tooth", mesh_stiffness_model=SIMPLE
        )
    )
    assert missing(t + period, 1e-6, 0.0) == pytest.approx(healthy(t + period, 1e-6, 0.0))


def test_simple_surface_fault_lowers_the_stiffness_of_the_affected_teeth_by_15_percent():
    p = GearDrivetrainParameters(
        speed_rpm=600.0,
        health_state="surface_fault",
        surface_fault_model="stiffness_loss",
        contact_exponent=1.0,
        transmission_error=0.0,
        mesh_stiffness_model=SIMPLE,
    )
    faulty, healthy = MeshForce(p), MeshForce(p.replace(health_state="healthy"))
    period = 1.0 / healthy.mesh_frequency
    t = 0.5 * (1 + healthy.contact_ratio - 1) * period  # single contact of pair 0
    assert faulty(t, 1e-6, 0.0) == pytest.approx(0.85 * healthy(t, 1e-6, 0.0))


@pytest.mark.parametrize("loss", [0.15, 0.5, 0.9])
def test_surface_fault_mesh_force_follows_its_stiffness_loss(loss):
    """Potential-energy mesh, one faulty tooth, at the static deflection and beyond it: the force
    lost is exactly `loss` x that tooth's pair force, at every phase of its mesh (the studies'
    -15 % contact stiffness acts, whatever the loaded deflection)."""
    p = GearDrivetrainParameters(
        speed_rpm=600.0,
        transmission_error=0.0,
        health_state="surface_fault",
        surface_fault_teeth=1,
        surface_fault_stiffness_loss=loss,
        surface_fault_model="stiffness_loss",
    )
    healthy, faulty = MeshForce(p.replace(health_state="healthy")), MeshForce(p)
    period = 1.0 / healthy.mesh_frequency
    scale = p.mesh_stiffness * DEFLECTION_REF / healthy.tvms.mean_stiffness
    for deflection in (0.65e-6, 2e-6):
        for phase in (0.3, 0.9, 1.6, 2.2):
            t = phase * period
            pair = (
                float(healthy.tvms.pair_stiffness(phase))
                * scale
                * (deflection / DEFLECTION_REF) ** p.contact_exponent
            )
            lost = healthy(t, deflection, 0.0) - faulty(t, deflection, 0.0)
            assert lost == pytest.approx(loss * pair, rel=1e-9)


def test_mesh_stiffness_model_switch():
    assert type(MeshForce(GearDrivetrainParameters())) is TVMSMeshForce  # the default
    assert type(MeshForce(GearDrivetrainParameters(mesh_stiffness_model=SIMPLE))) is MeshForce
    with pytest.raises(ValueError, match="mesh_stiffness_model"):
        MeshForce(GearDrivetrainParameters(mesh_stiffness_model="fem"))
    with pytest.raises(ValueError, match="unknown health state 'cracked'"):
        MeshForce(GearDrivetrainParameters(health_state="cracked"))


@pytest.mark.parametrize("model", ["potential_energy", SIMPLE])
def test_both_mesh_models_carry_the_same_mean_load(model):
    """mesh_stiffness is the mean mesh stiffness at 1 um in both models: over a mesh cycle at a fixed
    deflection the mean force is the same."""
    p = GearDrivetrainParameters(
        speed_rpm=600.0, transmission_error=0.0, mesh_stiffness_model=model
    )
    mesh = MeshForce(p)
    times = (5.0 + np.arange(400) / 400) / mesh.mesh_frequency
    mean = np.mean([mesh(t, 1e-6, 0.0) for t in times])
    if model == SIMPLE:  # its extended contact near the window edges adds a few per cent
        assert 1.0 <= mean / (p.mesh_stiffness * 1e-6) < 1.05
    else:  # the helical pairs enter and leave slice by slice: no extended contact
        assert mean == pytest.approx(p.mesh_stiffness * 1e-6, rel=1e-3)


def test_tvms_mesh_force_missing_tooth_removes_its_pair_once_per_revolution():
    p = GearDrivetrainParameters(speed_rpm=600.0, transmission_error=0.0)
    healthy, missing = MeshForce(p), MeshForce(p.replace(health_state="missing_tooth"))
    period = 1.0 / healthy.mesh_frequency
    window = healthy.window  # eps_alpha + eps_beta: pinion tooth 0 meshes for phase in [0, window)
    for revolution in (0, 1, 2):
        for phase in (0.5, 1.0, 1.5, 2.0, 2.5):
            t = (29 * revolution + phase) * period
            lost = healthy(t, 1e-6, 0.0) - missing(t, 1e-6, 0.0)
            # Exactly tooth 0's pair: the TVMS pair stiffness at u = phase, at 1 um.
            pair = (
                healthy.tvms.pair_stiffness(phase)
                * 1e-6
                * p.mesh_stiffness
                / healthy.tvms.mean_stiffness
            )
            assert lost == pytest.approx(float(pair), rel=1e-6)
            assert 0 < lost < healthy(t, 1e-6, 0.0)  # the neighbours still carry
        for phase in (window + 0.05, 10.0, 28.5):
            t = (29 * revolution + phase) * period
            assert missing(t, 1e-6, 0.0) == pytest.approx(healthy(t, 1e-6, 0.0), rel=1e-12)


def test_every_health_state_runs_in_both_models():
    for model in ("potential_energy", SIMPLE):
        p = GearDrivetrainParameters(
            speed_rpm=775.0, mesh_stiffness_model=model, transmission_error=0.0
        )
        healthy = MeshForce(p)
        t = np.arange(29 * 40) / 40 / healthy.mesh_frequency  # one pinion revolution
        reference = np.array([healthy(x, 1e-6, 0.0) for x in t])
        for state in MESH_HEALTH_STATES[1:]:  # the shaft states leave the mesh healthy
            faulty = MeshForce(p.replace(health_state=state))
            force = np.array([faulty(x, 1e-6, 0.0) for x in t])
            assert np.all(force <= reference + 1e-9) and force.sum() < reference.sum(), (
                model,
                state,
            )


@pytest.mark.parametrize("speed", [450.0, 775.0, 1100.0])
def test_missing_tooth_is_numerically_sound_at_every_speed(speed):
    """Helical rig with the potential-energy TVMS: the neighbouring pairs carry the load over the
    missing tooth, so the teeth never separate; the run is finite and the deflection bounded."""
    params = GearDrivetrainParameters(speed_rpm=speed, health_state="missing_tooth")
    diagnostics = {}
    signals = simulate(
        params, SimulationSettings(duration=60.0 / speed + 0.01, settle_time=0.05), diagnostics
    )
    deflection = diagnostics["deflection"]
    assert all(np.isfinite(s).all() for s in signals.values())
    assert 0.0 < deflection.min() and deflection.max() < 5e-6


def test_spur_missing_tooth_reengages_within_backlash():
    """Spur gears (helix 0): the gear flies free over the missing tooth and the next pair's extended
    contact catches it: no flight beyond the backlash, no NaN, a bounded impact."""
    params = GearDrivetrainParameters(
        geometry=GearGeometry(helix_angle_deg=0.0),
        helix_slices=1,
        speed_rpm=1100.0,
        health_state="missing_tooth",
    )
    diagnostics = {}
    signals = simulate(params, SimulationSettings(duration=0.12, settle_time=0.05), diagnostics)
    deflection = diagnostics["deflection"]
    assert all(np.isfinite(s).all() for s in signals.values())
    assert deflection.min() > -params.backlash  # never on the back flank
    assert deflection.min() < 0.0  # it did lose contact ...
    assert deflection.max() < 50e-6  # ... and the re-engagement impact stays bounded


@pytest.fixture(scope="module")
def healthy_run():
    params = GearDrivetrainParameters(speed_rpm=1100.0)
    return params, simulate(params, SimulationSettings(duration=0.5, settle_time=0.1))


def test_simulation_output_is_finite_at_the_output_rate(healthy_run):
    _, signals = healthy_run
    assert sorted(signals) == ["A1_x", "A1_y", "A2_x", "A2_y"]
    for signal in signals.values():
        assert len(signal) == 2560 and np.isfinite(signal).all() and signal.std() > 0


def test_sensors_as_the_rig_has_them_project_the_housing_acceleration(healthy_run):
    """One-axis sensors are channels of their own name; an angled one reads the housing's x and y
    acceleration projected on its direction, on the same run as the two-axis sensors."""
    params, signals = healthy_run
    sensors = (("A1", 0), ("v1", 0, ("y",)), ("d2", 2, (45.0, "x")))
    assert sensor_channels(sensors) == ("A1_x", "A1_y", "v1", "d2_45", "d2_x")
    mapped = simulate(
        params.replace(sensors=sensors), SimulationSettings(duration=0.5, settle_time=0.1)
    )
    assert sorted(mapped) == ["A1_x", "A1_y", "d2_45", "d2_x", "v1"]
    np.testing.assert_allclose(mapped["A1_y"], signals["A1_y"], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(mapped["v1"], signals["A1_y"], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(mapped["d2_x"], signals["A2_x"], rtol=1e-9, atol=1e-12)
    diagonal = (signals["A2_x"] + signals["A2_y"]) / math.sqrt(2.0)
    np.testing.assert_allclose(
        mapped["d2_45"], diagonal, rtol=1e-9, atol=1e-9 * np.abs(diagonal).max()
    )


@pytest.mark.parametrize(
    "sensors, message",
    [
        ((("a", 0, ("z",)),), "direction 'z'"),
        ((("a", 0, ("x", "x")),), "distinct"),
        ((("a", 0), ("a_x", 1, ("y",))), "not distinct"),
    ],
)
def test_bad_sensors_are_named(sensors, message):
    with pytest.raises(ValueError, match=message):
        sensor_channels(sensors)


def test_healthy_spectrum_peaks_at_gear_mesh_harmonics(healthy_run):
    params, signals = healthy_run
    gmf = params.speed_rpm / 60 * 29
    x = signals["A1_y"]
    freqs = np.fft.rfftfreq(len(x), 1 / 5120)
    amplitude = np.abs(np.fft.rfft((x - x.mean()) * np.hanning(len(x))))
    top = freqs[np.argsort(amplitude)[-5:]]
    orders = top / gmf
    assert np.all(np.abs(orders - np.round(orders)) < 0.02), orders


@pytest.mark.parametrize("model", ["potential_energy", SIMPLE])
def test_divergence_is_an_error_that_names_the_run(model):
    params = GearDrivetrainParameters(
        speed_rpm=450.0, mesh_stiffness=1.0, mesh_stiffness_model=model
    )
    with pytest.raises(SimulationError, match="450"):
        simulate(params, SimulationSettings(duration=0.2, settle_time=0.05))


# -- the 3-D structure --------------------------------------------------------------------------
def _exudyn_rigid_rig(p: GearDrivetrainParameters, mesh_stiffness: float):
    """The rigid rig of `p` built independently from exudyn's own items: each shaft assembly one
    ObjectRigidBody (NodeRigidBodyRxyz) at its centre of mass with its inertia by the parallel-
    axis theorem, point-mass housings, Cartesian spring-dampers for bushings and mounts, a
    coordinate spring for the motor coupling and a linear spring along the mesh normal."""
    import exudyn as exu
    import exudyn.itemInterface as eii

    g = p.geometry
    system = exu.SystemContainer()
    mbs = system.AddSystem()
    ground = mbs.AddObject(eii.ObjectGround())
    centre_distance = g.pitch_radius(g.teeth_pinion) + g.pitch_radius(g.teeth_gear)
    bodies = []
    for x, layout, gear_mass, gear_inertia, hub_mass, hub_inertia in (
        (0.0, p.input_shaft, p.pinion_mass, p.pinion_inertia, p.coupling_mass, p.coupling_inertia),
        (
            centre_distance,
            p.output_shaft,
            p.gear_mass,
            p.gear_inertia,
            p.brake_mass,
            p.brake_inertia,
        ),
    ):
        radius = layout.diameter / 2
        shaft_mass = 7850.0 * math.pi * radius**2 * layout.length
        parts = [
            (
                shaft_mass,
                layout.length / 2,
                shaft_mass * (3 * radius**2 + layout.length**2) / 12,
                shaft_mass * radius**2 / 2,
            ),
            (gear_mass, layout.gear, gear_inertia / 2, gear_inertia),
            (hub_mass, layout.hub, hub_inertia / 2, hub_inertia),
        ]
        mass = sum(m for m, *_ in parts)
        z_c = sum(m * z for m, z, *_ in parts) / mass
        transverse = sum(i_t + m * (z - z_c) ** 2 for m, z, i_t, _ in parts)
        polar = sum(i_p for *_, i_p in parts)
        node = mbs.AddNode(eii.NodeRigidBodyRxyz(referenceCoordinates=[x, 0.0, z_c, 0.0, 0.0, 0.0]))
        body = mbs.AddObject(
            eii.ObjectRigidBody(
                mass=mass, inertia=[transverse, transverse, polar, 0, 0, 0], nodeNumber=node
            )
        )
        bodies.append((body, node, x, z_c))
        for z in layout.bearings:
            housing = mbs.AddObject(
                eii.ObjectMassPoint(
                    mass=p.housing_mass,
                    nodeNumber=mbs.AddNode(eii.NodePoint(referenceCoordinates=[x, 0.0, z])),
                )
            )
            on_shaft = mbs.AddMarker(
                eii.MarkerBodyPosition(bodyNumber=body, localPosition=[0.0, 0.0, z - z_c])
            )
            on_housing = mbs.AddMarker(eii.MarkerBodyPosition(bodyNumber=housing))
            on_base = mbs.AddMarker(
                eii.MarkerBodyPosition(bodyNumber=ground, localPosition=[x, 0.0, z])
            )
            mbs.AddObject(
                eii.ObjectConnectorCartesianSpringDamper(
                    markerNumbers=[on_shaft, on_housing],
                    stiffness=[p.bushing_stiffness, p.bushing_stiffness, p.bushing_axial_stiffness],
                )
            )
            mbs.AddObject(
                eii.ObjectConnectorCartesianSpringDamper(
                    markerNumbers=[on_base, on_housing], stiffness=list(p.housing_stiffness)
                )
            )
    pinion_node = bodies[0][1]
    mbs.AddObject(
        eii.ObjectConnectorCoordinateSpringDamper(
            markerNumbers=[
                mbs.AddMarker(
                    eii.MarkerNodeCoordinate(
                        nodeNumber=mbs.AddNode(eii.NodePointGround()), coordinate=0
                    )
                ),
                mbs.AddMarker(eii.MarkerNodeCoordinate(nodeNumber=pinion_node, coordinate=5)),
            ],
            stiffness=p.coupling_stiffness,
        )
    )
    # Mesh: a spring along the unit normal n of the helical flank, between the pitch point on the
    # pinion and a point one unit length along n on the gear. Along n its stiffness is
    # k_transverse / cos^2(beta_b): the transverse-equivalent deflection is delta_n / cos(beta_b).
    alpha, beta_b = g.transverse_pressure_angle, g.base_helix_angle
    normal = np.array(
        [math.sin(alpha) * math.cos(beta_b), math.cos(alpha) * math.cos(beta_b), math.sin(beta_b)]
    )
    pitch = np.array([g.pitch_radius(g.teeth_pinion), 0.0, p.input_shaft.gear])
    (pinion, _, x1, z1), (gear, _, x2, z2) = bodies
    on_pinion = mbs.AddMarker(
        eii.MarkerBodyPosition(bodyNumber=pinion, localPosition=list(pitch - [x1, 0, z1]))
    )
    on_gear = mbs.AddMarker(
        eii.MarkerBodyPosition(bodyNumber=gear, localPosition=list(pitch + normal - [x2, 0, z2]))
    )
    mbs.AddObject(
        eii.ObjectConnectorSpringDamper(
            markerNumbers=[on_pinion, on_gear],
            referenceLength=1.0,
            stiffness=mesh_stiffness / math.cos(beta_b) ** 2,
        )
    )
    mbs.Assemble()
    values, _ = mbs.ComputeODE2Eigenvalues(useSparseSolver=False)
    return np.sqrt(np.clip(np.sort(values), 0, None)) / (2 * math.pi)


@pytest.mark.parametrize("mesh_stiffness", [0.0, 4.0e8])
def test_natural_frequencies_match_an_exudyn_rigid_body_model(mesh_stiffness):
    """The assembled matrices against the same rig built from exudyn's rigid bodies and connectors
    (an independent route: body frames, parallel-axis inertia, exudyn's own linearisation)."""
    p = GearDrivetrainParameters()
    assembled = Drivetrain(p).natural_frequencies(mesh_stiffness)
    reference = _exudyn_rigid_rig(p, mesh_stiffness)
    assert len(assembled) == len(reference) == 24
    np.testing.assert_allclose(
        assembled, reference, rtol=1e-6, atol=1e-3
    )  # atol: the free spin without mesh


def test_flexible_beam_bends_at_the_analytical_frequency():
    """A simply supported steel shaft of 12 Timoshenko elements: first bending frequency against
    the Timoshenko beam solution (Euler-Bernoulli with shear and rotary inertia corrections)."""
    length, diameter, youngs, poisson, density = 0.5, 0.03, 2.1e11, 0.3, 7850.0
    section = Section.tube(diameter, 0.0, youngs, poisson, density)
    structure = LinearStructure()
    nodes = [structure.add_node((0.0, 0.0, z)) for z in np.linspace(0.0, length, 13)]
    for a, b in zip(nodes[:-1], nodes[1:]):
        structure.add_beam(a, b, section)
    for node in (nodes[0], nodes[-1]):  # pinned: translations held, rotations free
        structure.add_spring((node, structure.positions[node]), None, [1e13, 1e13, 1e13], [0, 0, 0])
    structure.add_coordinate_spring(nodes[0], 5, 1e9, 0.0)  # no free spin
    frequencies = structure.natural_frequencies()
    euler = (
        (math.pi / length) ** 2
        * math.sqrt(section.bending / section.mass_per_length)
        / (2 * math.pi)
    )
    # Timoshenko's first-order correction for mode 1: 1 - (pi r_g / L)^2 (1 + E / (kappa G)) / 2
    gyration = section.bending / section.axial
    correction = 1 - 0.5 * (math.pi / length) ** 2 * gyration * (1 + section.axial / section.shear)
    bending = frequencies[frequencies > 1.0][0]  # the two planes: a double root
    assert bending == pytest.approx(euler * correction, rel=2e-3)
    assert frequencies[frequencies > 1.0][1] == pytest.approx(bending, rel=1e-9)


def test_flexible_shafts_run_and_soften_the_rig():
    rigid = GearDrivetrainParameters(speed_rpm=775.0)
    flexible = rigid.replace(shaft_model="flexible")
    assert (
        Drivetrain(flexible).natural_frequencies()[:12].sum()
        < Drivetrain(rigid).natural_frequencies()[:12].sum()
    )
    signals = simulate(flexible, SimulationSettings(duration=0.1, settle_time=0.05))
    assert all(np.isfinite(s).all() and s.std() > 0 for s in signals.values())


def test_static_mesh_deflection_follows_load_over_stiffness():
    """Linear mesh law (n = 1), no excitation but the TVMS: the mean mesh deflection carries the
    load torque, delta = (T / r_b2) / k_mean + the static TE's mean, at two loads."""
    deflections = []
    for load in (10.0, 20.0):
        p = GearDrivetrainParameters(
            speed_rpm=450.0, contact_exponent=1.0, load_torque=load, transmission_error=0.0
        )
        diagnostics = {}
        simulate(p, SimulationSettings(duration=0.3, settle_time=0.1), diagnostics)
        mean = diagnostics["deflection"][len(diagnostics["deflection"]) // 3 :].mean()
        force = load / p.geometry.base_radius(p.geometry.teeth_gear)
        assert mean == pytest.approx(force / p.mesh_stiffness, rel=0.02)
        deflections.append(mean)
    assert deflections[1] / deflections[0] == pytest.approx(2.0, rel=0.01)


def _line(signal, frequency, fs=5120.0, half_width=0.6):
    spectrum = np.abs(np.fft.rfft(signal * np.hanning(len(signal))))
    freqs = np.fft.rfftfreq(len(signal), 1 / fs)
    return spectrum[np.abs(freqs - frequency) < half_width].max()


@pytest.fixture(scope="module")
def rig_runs():
    """Healthy and missing-tooth runs of one drivetrain (run-out and pitch errors drawn as for a
    training sample) at the three study speeds."""
    rng = np.random.default_rng(3)
    geometry = GearGeometry()
    effects = dict(
        runout_pinion=1e-6,
        runout_gear=1e-6,
        runout_phase_gear=1.0,
        pitch_errors_pinion=tuple(rng.normal(0, 0.05e-6, 29)),
        pitch_errors_gear=tuple(rng.normal(0, 0.05e-6, 44)),
    )
    runs = {}
    for speed in (450.0, 775.0, 1100.0):
        for state in ("healthy", "missing_tooth"):
            p = GearDrivetrainParameters(
                geometry=geometry, speed_rpm=speed, health_state=state, **effects
            )
            runs[speed, state] = simulate(p, SimulationSettings(duration=1.0, settle_time=0.1))
    return runs


@pytest.mark.slow
@pytest.mark.parametrize("speed", [450.0, 775.0, 1100.0])
def test_missing_tooth_raises_the_mesh_sidebands_at_every_speed(rig_runs, speed):
    shaft = speed / 60
    gmf = 29 * shaft

    def sidebands(signals):
        return sum(
            _line(signals[c], gmf + s * shaft) ** 2 for c in ("A1_x", "A1_y") for s in (-1, 1)
        )

    assert sidebands(rig_runs[speed, "missing_tooth"]) > 2.0 * sidebands(rig_runs[speed, "healthy"])


@pytest.mark.slow
def test_housing_x_and_y_are_not_collinear(rig_runs):
    """The 3-D rig's housings move in x and y through different paths (anisotropic mounts, tilt,
    the axial mesh force): the channels are far from collinear and their y/x ratio at the mesh
    harmonics changes with harmonic and speed."""
    ratios = []
    for speed in (450.0, 775.0, 1100.0):
        signals = rig_runs[speed, "healthy"]
        assert abs(np.corrcoef(signals["A1_x"], signals["A1_y"])[0, 1]) < 0.9
        gmf = 29 * speed / 60
        ratios += [
            _line(signals["A1_y"], k * gmf) / _line(signals["A1_x"], k * gmf) for k in (1, 2, 3, 4)
        ]
    assert max(ratios) / min(ratios) > 1.5


@pytest.mark.slow
def test_the_step_has_converged():
    """The spectral features the classifiers see (2 Hz log bands to 2 kHz, every channel) within
    0.5 dB of a run with a four times smaller step, in every band within 40 dB of the strongest."""
    p = GearDrivetrainParameters(speed_rpm=1100.0, health_state="missing_tooth")
    features = SpectrumFeatures(
        channels=["A1_x", "A1_y", "A2_x", "A2_y"],
        f_max_hz=2000.0,
        resolution_hz=2.0,
        band_statistic="rms",
    )
    levels = []
    for steps in (1, 4):
        signals = simulate(
            p, SimulationSettings(duration=0.5, settle_time=0.1, steps_per_sensor_sample=steps)
        )
        segment = np.stack([signals[c] for c in features.channels])[None]
        levels.append(20 * np.log10(features.transform(segment, fs_hz=5120.0)[0] + 1e-12))
    strong = levels[1] > levels[1].max() - 40.0
    assert np.abs(levels[0] - levels[1])[strong].max() < 0.5


@pytest.mark.slow
def test_the_central_difference_matches_rk44_at_a_quarter_step():
    """The gear configs' integrator (numerics: the central difference, two steps a sample at 6 x
    the output rate) against RK44 at four steps a sample: the same spectral features within
    0.5 dB in every band within 40 dB of the strongest, a missing tooth at 1100 rpm (its
    impacts are the hardest on the step), and one force call a step."""
    p = GearDrivetrainParameters(speed_rpm=1100.0, health_state="missing_tooth")
    features = SpectrumFeatures(
        channels=["A1_x", "A1_y", "A2_x", "A2_y"],
        f_max_hz=2000.0,
        resolution_hz=2.0,
        band_statistic="rms",
    )
    levels, calls = [], []
    for integrator, steps in (("central_difference", 2), ("rk44", 4)):
        diagnostics = {}
        settings = SimulationSettings(
            duration=0.5,
            settle_time=0.1,
            oversampling=6,
            integrator=integrator,
            steps_per_sensor_sample=steps,
        )
        signals = simulate(p, settings, diagnostics=diagnostics)
        calls.append(
            diagnostics["mesh_calls"]
            / (diagnostics["steps_per_sensor_sample"] * len(diagnostics["time"]))
        )
        segment = np.stack([signals[c] for c in features.channels])[None]
        levels.append(20 * np.log10(features.transform(segment, fs_hz=5120.0)[0] + 1e-12))
    strong = levels[1] > levels[1].max() - 40.0
    assert np.abs(levels[0] - levels[1])[strong].max() < 0.5
    assert calls[0] == pytest.approx(1.0, abs=0.01) and calls[1] == pytest.approx(4.0, abs=0.01)


def test_features_do_not_depend_on_the_sensor_rate():
    """The same integration (one step size) sensed at 10 and at 20 x the output rate gives the
    same features: the sensors average the acceleration over their period, so the mesh harmonics
    near the sensor rate do not fold into the band. Point samples of the acceleration folded the
    harmonics near 51.2 kHz to 250-290 Hz at 775 rpm, 14 dB above this run's band there, and the
    benchmark's convergence check measured that aliasing, not the model."""
    p = GearDrivetrainParameters(speed_rpm=775.0)
    features = SpectrumFeatures(
        channels=["A2_y"], f_max_hz=400.0, resolution_hz=4.0, band_statistic="rms"
    )
    levels = []
    for oversampling, steps in ((10, 2), (20, 1)):
        signals = simulate(
            p,
            SimulationSettings(
                duration=0.25,
                settle_time=0.05,
                oversampling=oversampling,
                steps_per_sensor_sample=steps,
            ),
        )
        levels.append(
            20 * np.log10(features.transform(signals["A2_y"][None, None], fs_hz=5120.0)[0])
        )
    strong = levels[1] > levels[1].max() - 60.0
    assert np.abs(levels[0] - levels[1])[strong].max() < 1.0


def test_step_refinement_divides_the_step_the_run_would_take():
    """A refined run (the convergence check, the retry of a failed sample) takes a smaller step
    than the run it checks, also where the model's fastest mode and not the setting chose it."""
    flexible = GearDrivetrainParameters(speed_rpm=775.0, shaft_model="flexible")
    drivetrain = Drivetrain(flexible)
    chosen = steps_per_sensor_sample(drivetrain, SimulationSettings())
    assert (
        chosen > SimulationSettings().steps_per_sensor_sample
    )  # the flexible shafts' modes chose it
    assert steps_per_sensor_sample(drivetrain, SimulationSettings(step_refinement=4)) == 4 * chosen


def test_the_mesh_force_is_continuous_where_pairs_close_and_open():
    """Spur gears with a tooth 20 um proud (a printed gear's pitch error) and a light load: over a
    sweep of the mesh deflection through zero, at any mesh phase, the force never jumps (a pair
    that entered the sum only once the deflection grew made it jump, and the CFRP rig's step check
    read 30 dB), and the steady damping grows in from zero as a pair closes (a viscous force that
    jumps at contact onset makes RK4 first order)."""
    z1, z2 = 20, 30
    p = GearDrivetrainParameters(
        geometry=GearGeometry(teeth_pinion=z1, teeth_gear=z2, helix_angle_deg=0.0),
        speed_rpm=775.0,
        load_torque=2.0,
        transmission_error=0.0,
        contact_exponent=1.2,
        pitch_errors_pinion=[2.0e-5] + [0.0] * (z1 - 1),
        pitch_errors_gear=[0.0] * z2,
        restitution=1.0,
    )  # no impact damping: the steady damping alone
    mesh = MeshForce(p, damping=50.0)
    assert mesh.extended
    deflections = np.linspace(-3.0e-5, 1.5e-5, 4501)  # 10 nm apart
    for phase in np.linspace(
        -0.6, 1.9, 26
    ):  # the proud pair from far before to far after its window
        t = phase / mesh.mesh_frequency
        forces = {}
        for rate in (
            0.0,
            0.05,
        ):  # closing at 0.05 m/s, a viscous force would jump by 2.5 N at onset
            forces[rate] = np.array([mesh(t, d, rate) for d in deflections])
            steps = np.abs(np.diff(forces[rate]))
            # a continuous force's increments change gradually; a jump is one far above both neighbours
            neighbours = np.maximum(steps[:-2], steps[2:])
            jumps = np.flatnonzero(steps[1:-1] > 4.0 * neighbours + 1e-9)
            assert not jumps.size, (
                f"the force jumps at phase {phase:.2f}, {rate} m/s, deflection "
                f"{deflections[jumps[0] + 1] * 1e6:.2f} um: {steps[jumps[0] + 1]:.3g} N"
            )
        first_contact = np.flatnonzero(forces[0.0] > 0.0)[0]
        damping_force = forces[0.05][first_contact] - forces[0.0][first_contact]
        assert damping_force < 0.01 * 50.0 * 0.05, f"the damping jumps in at phase {phase:.2f}"


def test_the_compiled_mesh_force_is_the_python_one():
    """The steady force sum runs compiled (mesh_kernel); the Python path that tracks impacts sums
    the same contacts with its own per-contact law. With no impact to track, both give the same
    force (to rounding) at random times, deflections and rates, for a helical TVMS mesh with run-out
    and speed fluctuation, a spur TVMS mesh with a spall (two contact groups on one tooth) and
    printed-gear pitch errors (extended contact), and the simple mesh with a sine transmission
    error."""
    rng = np.random.default_rng(3)
    spur = GearGeometry(teeth_pinion=20, teeth_gear=30, helix_angle_deg=0.0)
    meshes = {
        "helical": GearDrivetrainParameters(
            speed_rpm=775.0,
            pitch_errors_pinion=rng.normal(0, 3e-6, 29).tolist(),
            pitch_errors_gear=rng.normal(0, 3e-6, 44).tolist(),
            runout_pinion=5e-6,
            runout_gear=3e-6,
            speed_fluctuation=0.002,
        ),
        "spur, spall": GearDrivetrainParameters(
            geometry=spur,
            speed_rpm=775.0,
            load_torque=2.0,
            health_state="spall",
            spall_depth=1e-4,
            pitch_errors_pinion=rng.normal(0, 2e-5, 20).tolist(),
            pitch_errors_gear=rng.normal(0, 2e-5, 30).tolist(),
        ),
        SIMPLE: GearDrivetrainParameters(
            mesh_stiffness_model=SIMPLE,
            speed_rpm=450.0,
            transmission_error=3e-7,
            runout_pinion=5e-6,
            pitch_errors_pinion=rng.normal(0, 3e-6, 29).tolist(),
            pitch_errors_gear=rng.normal(0, 3e-6, 44).tolist(),
        ),
    }
    for name, p in meshes.items():
        mesh = MeshForce(p, damping=300.0)
        loaded = 0
        for t, deflection, rate in zip(
            rng.uniform(0, 2, 3000), rng.uniform(-3e-6, 3e-5, 3000), rng.uniform(-0.05, 0.05, 3000)
        ):
            compiled = mesh.steady_force(t, deflection, rate)
            python = mesh.tracked_force(t, deflection, rate)
            mesh.separated = (
                False  # the Python path remembers contact; each state here stands alone
            )
            assert compiled == pytest.approx(python, rel=1e-12, abs=1e-9), f"{name} at t = {t}"
            loaded += python > 0
        assert loaded > 2000, f"{name}: too few states in contact to compare"
    # the back flank is an impact: the compiled sum hands it to the Python path
    mesh = MeshForce(meshes["helical"], damping=300.0)
    assert mesh.steady_force(0.1, -2.0e-4, 0.0) == -1.0
    assert mesh(0.1, -2.0e-4, 0.0) < 0.0


@pytest.mark.parametrize("model", ["potential_energy", SIMPLE])
def test_the_callbacks_gate_follows_the_impacts_python_tracks(model):
    """The exudyn callback's compiled gate (mesh_kernel's state vector) hands every call to the
    Python path while the mesh is out of contact or an impact is tracked: a run of calls through
    the callback that loses contact, hits again and settles gives, call by call, the force and the
    impact state of a twin mesh that takes every call in Python (to rounding)."""
    p = GearDrivetrainParameters(
        mesh_stiffness_model=model, speed_rpm=775.0, contact_law="flores", restitution=0.7
    )
    callback, python = MeshForce(p, damping=300.0), MeshForce(p, damping=300.0)
    t = np.linspace(0.0, 0.02, 4000)
    deflection = 2e-6 * np.cos(2 * np.pi * 150.0 * t) + 1e-6  # in and out of contact
    rate = np.gradient(deflection, t)
    tracked = 0
    for time, d, d_t in zip(t, deflection, rate):
        tracked += bool(callback.impacts) or callback.separated
        force = callback.spring_force(None, time, 0, d, d_t, 0.0, 0.0, 0.0)
        assert force == pytest.approx(python.tracked_force(time, d, d_t), rel=1e-12, abs=1e-9), time
        assert (
            callback.impacts.keys() == python.impacts.keys()
            and callback.separated == python.separated
        )
    assert tracked > 100 and tracked < len(t) - 100  # both paths taken


@pytest.mark.parametrize("exponent", [1.0, 1.3, 1.5])
def test_the_stiffness_for_a_deflection_carries_the_load_there(exponent):
    """stiffness_for_deflection inverts operating_deflection: the mesh it gives deflects by the
    asked amount under the rig's load, whatever the exponent; a lighter load deflects it less."""
    from condmon.models.gear.mesh_force import operating_deflection, stiffness_for_deflection

    p = GearDrivetrainParameters()
    stiffness = stiffness_for_deflection(p, 0.6e-6, exponent)
    assert operating_deflection(
        p.replace(mesh_stiffness=stiffness, contact_exponent=exponent)
    ) == pytest.approx(0.6e-6)
    assert (
        operating_deflection(
            p.replace(
                mesh_stiffness=stiffness, contact_exponent=exponent, load_torque=p.load_torque / 2
            )
        )
        < 0.6e-6
    )
    with pytest.raises(ValueError, match="must be positive"):
        stiffness_for_deflection(p, 0.0, exponent)
