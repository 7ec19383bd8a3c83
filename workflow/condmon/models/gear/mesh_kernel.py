"""The mesh force's hot path, compiled (numba): the excitation, the tooth-pair contacts in touch
and their steady force sum, for `mesh_force.py`, four calls per RK44 step.

Pure functions of plain floats and arrays, so numba compiles them once per machine (`cache=True`
keeps the machine code beside this file). `MeshForce` and `TVMSMeshForce` pack their tables into
the arrays these take. While the mesh is in steady contact, one compiled call gives the force; an
impact (a contact that closes after the whole mesh lost contact, or on the back flank) keeps its
state in Python, which takes the same contacts from the enumerators here.

The exudyn callback calls the `*_gated_force` kernels, which take their arrays by address (an
`ArrayBlock`): numba unboxes every ndarray argument on each call from Python (about 0.15 us
each, 1.2 us of the 1.5 us a call with eight arrays took), while four scalars cost what a call
does. They also hold the Python path's gate (an impact tracked, the mesh out of contact) in the
block's state vector, so the callback needs no Python attribute lookups either.
"""

from __future__ import annotations

import math

import numpy as np
from numba import carray, njit
from numba.core import cgutils, types
from numba.extending import intrinsic

DEFLECTION_REF = 1.0e-6  # m; K = mesh stiffness at this deflection keeps K's unit N/m for any n


def entry_point(kernel):
    """`kernel`'s machine code for its one signature, called without numba's type dispatch (about
    0.5 us of a call's 1.3 us): the arrays passed must have exactly the signature's types
    (C-contiguous float64, int64 where stated; another type raises TypeError)."""
    (signature,) = kernel.signatures
    return kernel.overloads[signature].entry_point


# the excitation and the steady sums' arguments: constants, run-out rows, then per kernel its tables
VECTOR, MATRIX, TABLE, INDEX = (
    "float64[::1]",
    "float64[:, ::1]",
    "float64[:, :, ::1]",
    "int64[:, ::1]",
)

# excitation_constants: the layout `MeshForce` packs
(
    START_PHASE,
    MESH_FREQUENCY,
    FLUCTUATION,
    FLUCTUATION_W,
    FLUCTUATION_PHASE,
    FLUCTUATION_COS0,
    INVERSE_BASE_PITCH,
) = range(7)


@njit(f"UniTuple(float64, 4)(float64, {VECTOR}, {MATRIX})", cache=True)
def mesh_excitation(t, excitation_constants, runout):
    """(mesh phase in mesh periods, its rate, run-out of both shafts along the line of action (m),
    its rate) at time t. runout: one row (amplitude, shaft angle per mesh period, phase) per shaft
    that has one."""
    c = excitation_constants
    mesh_frequency, fluctuation = c[MESH_FREQUENCY], c[FLUCTUATION]
    if fluctuation != 0.0:
        angle = c[FLUCTUATION_W] * t + c[FLUCTUATION_PHASE]
        phase = c[START_PHASE] + mesh_frequency * (
            t + fluctuation * (c[FLUCTUATION_COS0] - math.cos(angle)) / c[FLUCTUATION_W]
        )
        phase_rate = mesh_frequency * (1.0 + fluctuation * math.sin(angle))
    else:
        phase, phase_rate = c[START_PHASE] + mesh_frequency * t, mesh_frequency
    e = 0.0
    e_t = 0.0
    for row in range(runout.shape[0]):
        amplitude, per_phase, offset = runout[row, 0], runout[row, 1], runout[row, 2]
        angle = per_phase * phase + offset
        e += amplitude * math.sin(angle)
        e_t += amplitude * per_phase * phase_rate * math.cos(angle)
    if runout.shape[0] > 0:
        # an eccentric gear moves its flanks along the line of action by e: the contact lies e
        # further along every pair's path, so the mesh cycle is phase-modulated as well as displaced
        phase += e * c[INVERSE_BASE_PITCH]
        phase_rate += e_t * c[INVERSE_BASE_PITCH]
    return phase, phase_rate, e, e_t


# contacts[m] = (key, stiffness at 1 um, deflection, rate) of the m-th contact in touch; the
# enumerators return how many, or BACK_FLANK (contacts[0, 2:] then holds the mesh's d and d')
CONTACTS = "float64[:, ::1]"
BACK_FLANK = -1
TOO_MANY_CONTACTS = -2


@njit(f"float64({CONTACTS}, int64, float64, float64, float64)", cache=True)
def steady_sum(contacts, count, exponent, damping_per_stiffness, inverse_damping_onset):
    """The steady mesh force of `count` contacts: per contact elastic plus viscous, the viscous part
    grown in by the smooth step 3 x^2 - 2 x^3 of x = d / d_op; a contact never pulls. (The Python
    path's `MeshForce._contact` is this plus an impact's hysteresis.)"""
    total = 0.0
    for m in range(count):
        stiffness_ref, d, d_t = contacts[m, 1], contacts[m, 2], contacts[m, 3]
        x = d * inverse_damping_onset
        onset = x * x * (3.0 - 2.0 * x) if x < 1.0 else 1.0
        force = (
            stiffness_ref * (d / DEFLECTION_REF) ** exponent
            + damping_per_stiffness * stiffness_ref * onset * d_t
        )
        if force > 0.0:
            total += force
    return total


# simple_constants: the layout `MeshForce` packs
(
    S_BACKLASH,
    S_CONTACT_RATIO,
    S_BASE_PITCH,
    S_TIP_RADIUS,
    S_PAIR_FORCE_REF,
    S_EXPONENT,
    S_DAMPING,
    S_INVERSE_ONSET,
    S_TE_AMPLITUDE,
) = range(9)
SIMPLE_TABLES = f"{VECTOR}, {MATRIX}, {VECTOR}, {VECTOR}, {VECTOR}"


@njit(f"int64({SIMPLE_TABLES}, float64, float64, float64, {CONTACTS})", cache=True)
def simple_contacts(
    excitation_constants,
    runout,
    constants,
    stiffness_factor,
    pair_pitch_error,
    t,
    deflection,
    rate,
    contacts,
):
    """The `simple` mesh's contacts in touch (`MeshForce`): pair j nominally in contact while its
    phase is in [0, contact ratio), all pairs equally stiff, the tip gap s^2 / (2 rho) outside."""
    phase, phase_rate, e, e_t = mesh_excitation(t, excitation_constants, runout)
    c = constants
    te = c[S_TE_AMPLITUDE]
    if te != 0.0:
        w = 2 * math.pi
        e += te * math.sin(w * phase)
        e_t += te * w * phase_rate * math.cos(w * phase)
    d, d_t = deflection - e, rate - e_t
    if -d - c[S_BACKLASH] > 0.0:
        contacts[0, 2], contacts[0, 3] = d, d_t
        return BACK_FLANK
    contact_ratio, pitch, rho = c[S_CONTACT_RATIO], c[S_BASE_PITCH], c[S_TIP_RADIUS]
    teeth, period = stiffness_factor.shape[0], pair_pitch_error.shape[0]
    pitch_rate = pitch * phase_rate
    count = 0
    for j in range(math.floor(phase - contact_ratio), math.floor(phase) + 2):
        u = phase - j
        if u < 0.0:  # approaching: the gap closes as the pair nears its start of contact
            s = -u * pitch
            gap, gap_t = s * s / (2 * rho), -s * pitch_rate / rho
        elif u > contact_ratio:  # receding
            s = (u - contact_ratio) * pitch
            gap, gap_t = s * s / (2 * rho), s * pitch_rate / rho
        else:
            gap, gap_t = 0.0, 0.0
        stiffness = stiffness_factor[j % teeth] * c[S_PAIR_FORCE_REF]
        pair_d = d - gap + pair_pitch_error[j % period]
        if pair_d > 0.0 and stiffness > 0.0:
            if count == contacts.shape[0]:
                return TOO_MANY_CONTACTS
            contacts[count, 0], contacts[count, 1] = j, stiffness
            contacts[count, 2], contacts[count, 3] = pair_d, d_t - gap_t
            count += 1
    return count


@njit(f"float64({SIMPLE_TABLES}, {CONTACTS}, float64, float64, float64)", cache=True)
def simple_steady_force(
    excitation_constants,
    runout,
    constants,
    stiffness_factor,
    pair_pitch_error,
    contacts,
    t,
    deflection,
    rate,
):
    """The `simple` mesh's force in steady contact; -1 where the back flank touches (an impact)
    or the contacts overflow `contacts`: the caller's Python path takes both. The tables and the
    contacts' scratch space come first, so that functools.partial binds them once."""
    count = simple_contacts(
        excitation_constants,
        runout,
        constants,
        stiffness_factor,
        pair_pitch_error,
        t,
        deflection,
        rate,
        contacts,
    )
    if count < 0:
        return -1.0
    c = constants
    return steady_sum(contacts, count, c[S_EXPONENT], c[S_DAMPING], c[S_INVERSE_ONSET])


# tvms_constants: the layout `TVMSMeshForce` packs
(
    T_BACKLASH,
    T_WINDOW,
    T_POINTS_PER_PITCH,
    T_BASE_PITCH,
    T_TIP_RADIUS,
    T_EXPONENT,
    T_DAMPING,
    T_INVERSE_ONSET,
    T_EDGE_EXCESS,
    T_EXTENDED,
    T_MAX_DEFLECTION,
) = range(11)
TVMS_TABLES = f"{VECTOR}, {MATRIX}, {VECTOR}, {TABLE}, {MATRIX}, {INDEX}, {VECTOR}"


@njit(f"int64({TVMS_TABLES}, float64, float64, float64, {CONTACTS})", cache=True)
def tvms_contacts(
    excitation_constants,
    runout,
    constants,
    tables,
    edges,
    tooth_groups,
    pair_pitch_error,
    t,
    deflection,
    rate,
    contacts,
):
    """The `potential_energy` mesh's contacts in touch (`TVMSMeshForce`), one per contact group of
    each pair (key 4 j + group).

    tables[group, i] = (K_i, K_(i+1) - K_i, e_i, e_(i+1) - e_i) on the pair-phase grid; edges[group] =
    (K, e) at the window's start and end; tooth_groups[tooth] = that pinion tooth's groups (-1:
    none); pair_pitch_error[j mod lcm(z1, z2)]: pair j's pitch errors. A pair whose stiffness does
    not vanish at its window's edges (spur gears) keeps the extended contact beyond them, as far as
    the largest pitch error lets a flank stand proud of the mesh."""
    phase, phase_rate, e, e_t = mesh_excitation(t, excitation_constants, runout)
    c = constants
    d, d_t = deflection - e, rate - e_t
    if -d - c[T_BACKLASH] > 0.0:
        contacts[0, 2], contacts[0, 3] = d, d_t
        return BACK_FLANK
    window, ppp, pitch, rho = c[T_WINDOW], c[T_POINTS_PER_PITCH], c[T_BASE_PITCH], c[T_TIP_RADIUS]
    reach = d + c[T_EDGE_EXCESS]  # the largest pair deflection at a window's edge
    ext = math.sqrt(2.0 * rho * reach) / pitch if (c[T_EXTENDED] > 0.0 and reach > 0.0) else 0.0
    deviation_rate = ppp * phase_rate  # d(table position)/dt
    gap_rate = pitch * phase_rate / rho
    teeth, slots, period = tooth_groups.shape[0], tooth_groups.shape[1], pair_pitch_error.shape[0]
    count = 0
    for j in range(math.floor(phase - window - ext) + 1, math.floor(phase + ext) + 1):
        u = phase - j
        d_pair = d + pair_pitch_error[j % period]
        inside = 0.0 <= u < window
        i, x, gap, gap_t = 0, 0.0, 0.0, 0.0
        if inside:
            x = u * ppp
            i = int(x)
            x -= i
        else:  # extended contact beyond the window: tip gap s^2 / (2 rho)
            s = -u * pitch if u < 0.0 else (u - window) * pitch
            gap, gap_t = s * s / (2 * rho), (s if u < 0.0 else -s) * gap_rate
        for slot in range(slots):
            group = tooth_groups[j % teeth, slot]
            if group < 0:
                break
            if inside:
                k = tables[group, i, 0] + x * tables[group, i, 1]
                gd = d_pair - tables[group, i, 2] - x * tables[group, i, 3]
                gd_t = d_t - tables[group, i, 3] * deviation_rate
            else:
                side = 0 if u < 0.0 else 2
                k = edges[group, side]
                gd = d_pair - edges[group, side + 1] - gap
                gd_t = d_t + gap_t
            if k > 0.0 and gd > 0.0:
                if count == contacts.shape[0]:
                    return TOO_MANY_CONTACTS
                contacts[count, 0], contacts[count, 1] = 4 * j + slot, k
                contacts[count, 2], contacts[count, 3] = gd, gd_t
                count += 1
    return count


@njit(f"float64({TVMS_TABLES}, {CONTACTS}, float64, float64, float64)", cache=True)
def tvms_steady_force(
    excitation_constants,
    runout,
    constants,
    tables,
    edges,
    tooth_groups,
    pair_pitch_error,
    contacts,
    t,
    deflection,
    rate,
):
    """The `potential_energy` mesh's force in steady contact; -1 where the back flank touches (an
    impact), the deflection is out of range (divergence) or the contacts overflow `contacts`: the
    caller's Python path takes them. The tables and the contacts' scratch space come first, so
    that functools.partial binds them once."""
    c = constants
    if not abs(deflection) < c[T_MAX_DEFLECTION]:
        return -1.0
    count = tvms_contacts(
        excitation_constants,
        runout,
        constants,
        tables,
        edges,
        tooth_groups,
        pair_pitch_error,
        t,
        deflection,
        rate,
        contacts,
    )
    if count < 0:
        return -1.0
    return steady_sum(contacts, count, c[T_EXPONENT], c[T_DAMPING], c[T_INVERSE_ONSET])


# -- the arrays by address ------------------------------------------------------------------------
# An ArrayBlock's layout: one row (address, shape...) per array; its first array is the state
# vector of the callback's gate (`MeshForce` keeps it in step with its impacts):
SEPARATED, TRACKING = range(
    2
)  # the whole mesh was out of contact at the last call; an impact is tracked
LAYOUT_COLUMNS = 4  # address and up to three dimensions


class ArrayBlock:
    """The addresses and shapes of arrays that a compiled kernel reads in place (`address`: of the
    layout, an int the kernel takes). The arrays must be C-contiguous float64 or int64, are not
    copied, and must not be resized; the block holds them, so they live as long as it does."""

    def __init__(self, *arrays: np.ndarray):
        self.arrays = arrays
        self.layout = np.zeros((len(arrays), LAYOUT_COLUMNS), dtype=np.int64)
        for row, array in enumerate(arrays):
            if (
                array.dtype not in (np.float64, np.int64)
                or not array.flags.c_contiguous
                or array.ndim >= LAYOUT_COLUMNS
            ):
                raise TypeError(
                    f"array {row}: a kernel reads C-contiguous float64 or int64 arrays of up to "
                    f"{LAYOUT_COLUMNS - 1} dimensions by address (got {array.dtype}, {array.ndim} d)"
                )
            self.layout[row, 0] = array.ctypes.data
            self.layout[row, 1 : 1 + array.ndim] = array.shape
        self.address = int(self.layout.ctypes.data)


@intrinsic
def _pointer(typingctx, address):
    """The void pointer at an integer address."""
    if not isinstance(address, types.Integer):
        return None

    def codegen(context, builder, signature, args):
        return builder.inttoptr(args[0], cgutils.voidptr_t)

    return types.voidptr(address), codegen


@njit(cache=True)
def _layout(address, rows):
    return carray(_pointer(address), (rows, LAYOUT_COLUMNS), np.int64)


@njit(cache=True)
def _vector(layout, row):
    return carray(_pointer(layout[row, 0]), (layout[row, 1],), np.float64)


@njit(cache=True)
def _matrix(layout, row):
    return carray(_pointer(layout[row, 0]), (layout[row, 1], layout[row, 2]), np.float64)


@njit(cache=True)
def _table(layout, row):
    return carray(
        _pointer(layout[row, 0]), (layout[row, 1], layout[row, 2], layout[row, 3]), np.float64
    )


@njit(cache=True)
def _index(layout, row):
    return carray(_pointer(layout[row, 0]), (layout[row, 1], layout[row, 2]), np.int64)


@njit(cache=True)
def _gate(state, total):
    """The steady sum's `total` as the callback returns it, remembering whether the mesh lost
    contact (a negative total, for the Python path, leaves the state to it)."""
    if total >= 0.0:
        state[SEPARATED] = 0.0 if total > 0.0 else 1.0
    return total


@njit("float64(int64, float64, float64, float64)", cache=True)
def simple_gated_force(address, t, deflection, rate):
    """`simple_steady_force` on the ArrayBlock (state, excitation constants, run-out, constants,
    stiffness factors, pair pitch errors, contacts) at `address`; -1 while an impact is tracked
    or the mesh was out of contact at the last call (the caller's Python path takes those)."""
    a = _layout(address, 7)
    state = _vector(a, 0)
    if state[SEPARATED] != 0.0 or state[TRACKING] != 0.0:
        return -1.0
    return _gate(
        state,
        simple_steady_force(
            _vector(a, 1),
            _matrix(a, 2),
            _vector(a, 3),
            _vector(a, 4),
            _vector(a, 5),
            _matrix(a, 6),
            t,
            deflection,
            rate,
        ),
    )


@njit("float64(int64, float64, float64, float64)", cache=True)
def tvms_gated_force(address, t, deflection, rate):
    """`tvms_steady_force` on the ArrayBlock (state, excitation constants, run-out, constants,
    tables, edges, tooth groups, pair pitch errors, contacts) at `address`; -1 while an impact is
    tracked or the mesh was out of contact at the last call (the caller's Python path takes those)."""
    a = _layout(address, 9)
    state = _vector(a, 0)
    if state[SEPARATED] != 0.0 or state[TRACKING] != 0.0:
        return -1.0
    return _gate(
        state,
        tvms_steady_force(
            _vector(a, 1),
            _matrix(a, 2),
            _vector(a, 3),
            _table(a, 4),
            _matrix(a, 5),
            _index(a, 6),
            _vector(a, 7),
            _matrix(a, 8),
            t,
            deflection,
            rate,
        ),
    )
