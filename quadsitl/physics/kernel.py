"""The compiled physics kernel: :mod:`quadsitl.physics.reference`, loop by loop, in numba.

Same model, same order of operations, written with scalars. Vehicles are copied in
blocks of B (``BLOCK`` for a batch, 1 for a single vehicle) into structure-of-arrays
scratch (value k of vehicle j at ``s[k * B + j]``) so that the compiler vectorises
each RK4 stage across vehicles. The row length B is a compile-time constant on purpose:
with it the compiler can tell the rows apart and vectorises the derivative (4× over 2-D
scratch, whose row length is only known at run time): each build is a closure over its
B (:func:`compile_step`). This module holds the RK4 step (:func:`rk4_step`, one for
still air and for the world, which adds each rotor's efficiency and ground effect and
the air) and the loops over blocks and substeps around it (the weather's step first,
in the world); the derivative and the ground contact it inlines are in
:mod:`quadsitl.physics.kernel_dynamics`. The four builds (``batch_step``,
``single_step`` and their ``_wind`` twins) are one source: they agree bit for bit, and
``tests/test_physics_equivalence.py`` holds them to the reference within 1e-12.
:func:`specific_force` gives what an accelerometer feels at a state, from the same
derivative and the same world (a weak rotor, ground effect, the air).
Read the reference to understand the physics; read this only to change its speed.
"""

from __future__ import annotations

import math
from typing import Any

import numba
import numpy as np

from quadsitl.physics import layout as L
from quadsitl.physics import wind_kernel
from quadsitl.physics.kernel_dynamics import (
    AIR0,
    SUMS_ROWS,
    derivative,
    ground_contact,
    rotor_factors,
)

BLOCK = 32  # vehicles per vectorised block (measured best of 16..256)
# FMA contraction and reciprocal division only: no fast-math NaN/inf assumptions, so
# the finiteness check stays exact.
_OPTIONS: dict[str, Any] = dict(
    cache=True, error_model="numpy", fastmath={"contract", "arcp", "nsz"}
)
# The helpers are inlined into ``step`` (numba IR), where B is a compile-time constant.
_inline = numba.njit(inline="always", **_OPTIONS)


@_inline
def first_invalid_command(commands):  # pragma: no cover - compiled
    """Index of the first vehicle whose command holds NaN or inf, or -1."""
    for i in range(commands.size):
        if not math.isfinite(commands[i]):
            return i // L.N_ROTORS
    return -1


@_inline
def _axpy(out, x, a, y, m, B):  # pragma: no cover - compiled
    """out = x + a·y over the state rows of the first m columns."""
    for k in range(L.STATE_SIZE):
        for j in range(m):
            out[k * B + j] = x[k * B + j] + a * y[k * B + j]


@_inline
def _scratch_size(B):  # pragma: no cover - compiled
    """Block scratch: state, previous state, RK4 temp, k1..k4, parameters, commands, sums."""
    return (7 * L.STATE_SIZE + L.N_PARAMS + L.N_ROTORS + SUMS_ROWS) * B


@_inline
def _world_size(B):  # pragma: no cover - compiled
    """The world's block scratch: the weather's parameters, state and scratch."""
    return (L.N_WIND_PARAMS + L.N_WIND_STATE + wind_kernel.N_SCRATCH) * B


@_inline
def _load_block(state, params, commands, s, p, cmd, first, m, B):  # pragma: no cover
    """Vehicles first..first+m−1 into the block's rows: state, parameters, commands."""
    for j in range(m):
        for k in range(L.STATE_SIZE):
            s[k * B + j] = state[first + j, k]
        for k in range(L.N_PARAMS):
            p[k * B + j] = params[first + j, k]
        for k in range(L.N_ROTORS):
            cmd[k * B + j] = commands[(first + j) * L.N_ROTORS + k]


@_inline
def _load_weather(wind_params, wind_state, streams, wp, ws, rng, first, m, B):  # pragma: no cover
    """The same vehicles' weather into the block's world rows, and its random streams."""
    for j in range(m):
        for k in range(L.N_WIND_PARAMS):
            wp[k * B + j] = wind_params[first + j, k]
        for k in range(L.N_WIND_STATE):
            ws[k * B + j] = wind_state[first + j, k]
        rng[j] = streams[first + j]


@_inline
def _pad_block(s, p, cmd, wp, ws, rng, m, B):  # pragma: no cover - compiled
    """Columns m..B−1 of a short block become copies of its first vehicle (finite values,
    computed and never written back): the weather's loops then run over the whole
    block, a count the compiler knows, and vectorise (1.5x the speed of loops to m,
    measured; the RK4 loops are faster to m, so they stay so)."""
    for j in range(m, B):
        for k in range(L.STATE_SIZE):
            s[k * B + j] = s[k * B]
        for k in range(L.N_PARAMS):
            p[k * B + j] = p[k * B]
        for k in range(L.N_ROTORS):
            cmd[k * B + j] = cmd[k * B]
        for k in range(L.N_WIND_PARAMS):
            wp[k * B + j] = wp[k * B]
        for k in range(L.N_WIND_STATE):
            ws[k * B + j] = ws[k * B]
        rng[j] = rng[0]


@_inline
def _store_weather(ws, rng, wind_state, streams, first, m, B):  # pragma: no cover
    """The block's weather state and random streams back to vehicles first.."""
    for j in range(m):
        for k in range(L.N_WIND_STATE):
            wind_state[first + j, k] = ws[k * B + j]
        streams[first + j] = rng[j]


@_inline
def rk4_step(
    s, prev, tmp, k1, k2, k3, k4, p, cmd, sums, contact, touchdown_speed, dt, first, m, B, wind
):  # pragma: no cover - compiled
    """One physics step of ``dt`` of the block's first m vehicles (vehicles first..),
    in place in ``s``: RK4 on :func:`derivative`, the quaternion normalised, the rotor
    speeds clipped, then the ground contact. ``wind`` builds the world (each rotor's
    efficiency and ground effect at the step's start, the air the weather left in
    ``sums``); without it the arithmetic of still air, unchanged. Inlined into the step
    that owns the scratch (:func:`_block_arrays`)."""
    size = L.STATE_SIZE
    for j in range(m):  # a crashed vehicle keeps its pose: remember it
        if contact[first + j] == L.CRASHED:
            for k in range(size):
                prev[k * B + j] = s[k * B + j]
    if wind:
        rotor_factors(s, p, sums, m, B)
    derivative(s, p, cmd, k1, m, sums, B, wind)
    _axpy(tmp, s, 0.5 * dt, k1, m, B)
    derivative(tmp, p, cmd, k2, m, sums, B, wind)
    _axpy(tmp, s, 0.5 * dt, k2, m, B)
    derivative(tmp, p, cmd, k3, m, sums, B, wind)
    _axpy(tmp, s, dt, k3, m, B)
    derivative(tmp, p, cmd, k4, m, sums, B, wind)
    sixth = dt / 6.0
    for k in range(size):
        for j in range(m):
            i = k * B + j
            s[i] = s[i] + sixth * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
    for j in range(m):
        qw, qx = s[L.I_QW * B + j], s[L.I_QX * B + j]
        qy, qz = s[L.I_QY * B + j], s[L.I_QZ * B + j]
        norm = math.sqrt(qw**2 + qx**2 + qy**2 + qz**2)
        for k in range(L.I_QW, L.I_QZ + 1):
            s[k * B + j] /= norm
        omega_max = p[L.P_OMEGA_MAX * B + j]
        for k in range(L.I_ROTOR0, size):
            s[k * B + j] = min(max(s[k * B + j], 0.0), omega_max)
    ground_contact(prev, s, p, contact, touchdown_speed, first, m, B)


@_inline
def _block_arrays(scratch, B):  # pragma: no cover - compiled
    """The block's arrays cut from one allocation (each a run of rows of B values):
    state, previous state, RK4 temp, k1..k4, parameters, commands, sums. Slices of one
    array at constant offsets are provably apart, so the loops that read one and write
    another vectorise (separate arrays, or arrays handed to a function that is not
    inlined, defeated the compiler: half the speed, measured)."""
    z = L.STATE_SIZE * B
    c = 7 * z + L.N_PARAMS * B
    return (
        scratch[0:z], scratch[z : 2 * z], scratch[2 * z : 3 * z],
        scratch[3 * z : 4 * z], scratch[4 * z : 5 * z],
        scratch[5 * z : 6 * z], scratch[6 * z : 7 * z],
        scratch[7 * z : c], scratch[c : c + L.N_ROTORS * B],
        scratch[c + L.N_ROTORS * B : _scratch_size(B)],
    )  # fmt: skip


@_inline
def _world_arrays(scratch, B):  # pragma: no cover - compiled
    """The world's block arrays, after the block's in the same allocation: the weather's
    parameters, its state and its scratch."""
    start = _scratch_size(B)
    w_state = start + L.N_WIND_PARAMS * B
    w_scratch = w_state + L.N_WIND_STATE * B
    end = start + _world_size(B)
    return scratch[start:w_state], scratch[w_state:w_scratch], scratch[w_scratch:end]


@_inline
def _store_block(state, s, first, m, B):  # pragma: no cover - compiled
    for j in range(m):
        for k in range(L.STATE_SIZE):
            state[first + j, k] = s[k * B + j]


def compile_step(B: int, release_gil: bool, wind: bool = False):
    """The kernel's ``step`` for blocks of ``B`` vehicles (B is a compile-time constant).

    A batch uses ``B = BLOCK`` and releases the GIL while it computes; a single vehicle
    uses ``B = 1`` (straight-line code, scratch of a few hundred bytes) and keeps the GIL,
    since releasing it would cost more than the step. Same source, same arithmetic.
    ``wind`` (compile-time too) builds the world (:func:`_world_step`); without it the
    arithmetic is that of still air and healthy rotors far from the ground
    (:func:`_still_step`). Both take the same RK4 step (:func:`rk4_step`)."""
    jit = numba.njit(nogil=release_gil, **_OPTIONS)
    return jit(_world_step(B) if wind else _still_step(B))


def _still_step(B: int):
    """``step`` in still air. A function of its own rather than the world's step with no
    weather: numba's call costs ~0.35 µs with these 7 arrays and scalars, ~1 µs with the
    world's 10, against a single vehicle's step of about 1 µs. (The steps are closures
    over B, and call only module-level functions: a compiled function held in a closure
    variable would enter numba's cache key as a random UUID, and every process missed
    the cache and compiled the kernel again.)"""

    def still_step(
        state, params, rotor_cmd, contact, touchdown_speed, dt, n_substeps
    ):  # pragma: no cover
        """Advance every vehicle ``n_substeps`` physics steps of ``dt`` in place.

        Returns -1, or the index of the first vehicle with a non-finite command, in
        which case nothing was changed."""
        commands = rotor_cmd.ravel()  # (n, 4), or (4,) for one vehicle: 4 per vehicle
        bad = first_invalid_command(commands)
        if bad >= 0:
            return bad
        scratch = np.empty(_scratch_size(B))
        s, prev, tmp, k1, k2, k3, k4, p, cmd, sums = _block_arrays(scratch, B)
        for first in range(0, state.shape[0], B):
            m = min(B, state.shape[0] - first)
            _load_block(state, params, commands, s, p, cmd, first, m, B)
            for _ in range(n_substeps):
                rk4_step(s, prev, tmp, k1, k2, k3, k4, p, cmd, sums, contact,
                         touchdown_speed, dt, first, m, B, False)  # fmt: skip
            _store_block(state, s, first, m, B)
        return -1

    return still_step


def _world_step(B: int):
    """``step`` in the world: the weather, each rotor's efficiency, ground effect."""

    def world_step(
        state, params, rotor_cmd, contact, touchdown_speed, dt, n_substeps,
        wind_params, wind_state, streams,
    ):  # pragma: no cover - compiled  # fmt: skip
        """Advance every vehicle ``n_substeps`` physics steps of ``dt`` in place, each
        after a step of its weather: ``wind_params`` (n, N_WIND_PARAMS), ``wind_state``
        (n, N_WIND_STATE), random ``streams`` (n,) uint64. Weather arrays with no rows
        mean still air for every vehicle: only the rotors' world (efficiency, ground
        effect) is added to the physics.

        Returns -1, or the index of the first vehicle with a non-finite command, in
        which case nothing was changed."""
        commands = rotor_cmd.ravel()  # (n, 4), or (4,) for one vehicle: 4 per vehicle
        bad = first_invalid_command(commands)
        if bad >= 0:
            return bad
        weather = wind_params.shape[0] > 0
        scratch = np.zeros(_scratch_size(B) + _world_size(B))  # zeros: still air
        s, prev, tmp, k1, k2, k3, k4, p, cmd, sums = _block_arrays(scratch, B)
        wp, ws, wscratch = _world_arrays(scratch, B)
        rng = np.empty(B, np.uint64)
        for first in range(0, state.shape[0], B):
            m = min(B, state.shape[0] - first)
            _load_block(state, params, commands, s, p, cmd, first, m, B)
            if weather:
                _load_weather(wind_params, wind_state, streams, wp, ws, rng, first, m, B)
            _pad_block(s, p, cmd, wp, ws, rng, m, B)
            calm = True  # no turbulence in the whole block: its weather skips the filters
            for j in range(B):
                calm = calm and not wp[L.W_SIGMA_W * B + j] > 0.0
            for _ in range(n_substeps):
                if weather:
                    wind_kernel.advance_block(s, p, wp, ws, rng, wscratch, sums, B, B, dt, calm)
                rk4_step(s, prev, tmp, k1, k2, k3, k4, p, cmd, sums, contact,
                         touchdown_speed, dt, first, m, B, True)  # fmt: skip
            _store_block(state, s, first, m, B)
            if weather:
                _store_weather(ws, rng, wind_state, streams, first, m, B)
        return -1

    return world_step


batch_step = compile_step(BLOCK, release_gil=True)
single_step = compile_step(1, release_gil=False)
batch_step_wind = compile_step(BLOCK, release_gil=True, wind=True)
single_step_wind = compile_step(1, release_gil=False, wind=True)


@numba.njit(**_OPTIONS)
def specific_force(state, params, contact, air_velocity, out):  # pragma: no cover - compiled
    """The non-gravitational acceleration of each vehicle, m/s² world ENU, into ``out``
    (n, 3): a − g, what an ideal accelerometer feels (before it is turned into the body).

    In the air: the physics' own :func:`derivative`, with the world the kernel builds at
    the state (each rotor's efficiency and ground-effect gain, the air's velocity
    ``air_velocity`` (n, 3) m/s world ENU), so thrust and drag are those integrated; on
    the ground, which holds the vehicle up, gravity's reaction (0, 0, g).
    """
    sums = np.zeros(SUMS_ROWS)  # the air's angular velocity stays 0: moments are unused
    rate = np.empty(L.STATE_SIZE)
    idle = np.zeros(L.N_ROTORS)  # the command only moves the rotors, not read here
    for j in range(state.shape[0]):
        gravity = params[j, L.P_GRAVITY]
        if contact[j] != L.AIRBORNE:
            out[j, 0], out[j, 1], out[j, 2] = 0.0, 0.0, gravity
            continue
        s, p = state[j], params[j]  # a block of one vehicle: value k at s[k]
        for k in range(3):
            sums[AIR0 + k] = air_velocity[j, k]
        rotor_factors(s, p, sums, 1, 1)
        derivative(s, p, idle, rate, 1, sums, 1, True)
        out[j, 0], out[j, 1], out[j, 2] = rate[L.I_VX], rate[L.I_VY], rate[L.I_VZ] + gravity
