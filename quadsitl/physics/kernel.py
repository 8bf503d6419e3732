"""The compiled physics kernel: :mod:`quadsitl.physics.reference`, loop by loop, in numba.

Same model, same order of operations, written with scalars. Vehicles are copied in
blocks of B (``BLOCK`` for a batch, 1 for a single vehicle) into structure-of-arrays
scratch (value k of vehicle j at ``s[k * B + j]``) so that the compiler vectorises
each RK4 stage across vehicles. The row length B is a compile-time constant on purpose:
with it the compiler can tell the rows apart and vectorises the derivative (4× over 2-D
scratch, whose row length is only known at run time). This module holds the RK4 step
over blocks (scratch, substeps, the weather first); the derivative and the ground
contact it inlines are in :mod:`quadsitl.physics.kernel_dynamics`. The same source is
compiled once per block size (:func:`compile_step`): ``batch_step`` and ``single_step``
agree bit for bit, and ``tests/test_physics_equivalence.py`` holds them to the reference
within 1e-12. :func:`specific_force` gives what an accelerometer feels at a state, from
the same derivative and the same world (a weak rotor, ground effect, the air).
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


def compile_step(B: int, release_gil: bool, wind: bool = False):
    """The kernel's ``step`` for blocks of ``B`` vehicles (B is a compile-time constant).

    A batch uses ``B = BLOCK`` and releases the GIL while it computes; a single vehicle
    uses ``B = 1`` (straight-line code, scratch of a few hundred bytes) and keeps the GIL,
    since releasing it would cost more than the step. Same source, same arithmetic.
    ``wind`` (compile-time too) builds the world: the weather of
    :mod:`quadsitl.physics.wind_kernel` before each physics step, and each rotor's
    efficiency and ground effect; without it the arithmetic is that of still air and
    healthy rotors far from the ground, unchanged (and the world's columns unread).
    """
    jit = numba.njit(nogil=release_gil, **_OPTIONS)
    WIND = wind
    # Block scratch: state, previous state, RK4 temp, k1..k4, parameters, commands, sums.
    scratch_size = (7 * L.STATE_SIZE + L.N_PARAMS + L.N_ROTORS + SUMS_ROWS) * B
    # The world's block arrays after them, in the same allocation: slices of one array
    # at constant offsets are provably apart, so the loops that read one and write
    # another vectorise (separate arrays defeated the compiler).
    w_params = scratch_size
    w_state = w_params + L.N_WIND_PARAMS * B
    w_scratch = w_state + L.N_WIND_STATE * B
    world_size = w_scratch + wind_kernel.N_SCRATCH * B

    def advance(
        state,
        params,
        rotor_cmd,
        contact,
        touchdown_speed,
        dt,
        n_substeps,
        wind_params,
        wind_state,
        streams,
    ):  # pragma: no cover
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
        size = L.STATE_SIZE
        # One allocation cut into the block arrays (each a run of rows of B values).
        z = size * B
        scratch = np.zeros(world_size)  # zeros: the air stays still without weather
        s, prev, tmp = scratch[0:z], scratch[z : 2 * z], scratch[2 * z : 3 * z]
        k1, k2 = scratch[3 * z : 4 * z], scratch[4 * z : 5 * z]
        k3, k4 = scratch[5 * z : 6 * z], scratch[6 * z : 7 * z]
        p = scratch[7 * z : 7 * z + L.N_PARAMS * B]
        cmd = scratch[7 * z + L.N_PARAMS * B : 7 * z + (L.N_PARAMS + L.N_ROTORS) * B]
        sums = scratch[7 * z + (L.N_PARAMS + L.N_ROTORS) * B : scratch_size]
        wp, ws = scratch[w_params:w_state], scratch[w_state:w_scratch]
        wscratch = scratch[w_scratch:world_size]
        rng = np.empty(B, np.uint64)
        sixth = dt / 6.0
        for first in range(0, state.shape[0], B):
            m = min(B, state.shape[0] - first)
            for j in range(m):
                for k in range(size):
                    s[k * B + j] = state[first + j, k]
                for k in range(L.N_PARAMS):
                    p[k * B + j] = params[first + j, k]
                for k in range(L.N_ROTORS):
                    cmd[k * B + j] = commands[(first + j) * L.N_ROTORS + k]
                if weather:
                    for k in range(L.N_WIND_PARAMS):
                        wp[k * B + j] = wind_params[first + j, k]
                    for k in range(L.N_WIND_STATE):
                        ws[k * B + j] = wind_state[first + j, k]
                    rng[j] = streams[first + j]
            # A short block is padded with copies of its first vehicle (finite values,
            # computed and never written back): the weather's loops then run over the
            # whole block, a count the compiler knows, and vectorise (1.5x the speed of
            # loops to m, measured; the RK4 loops are faster to m, so they stay so).
            for j in range(m, B):
                for k in range(size):
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
            calm = True  # no turbulence in the whole block: its weather skips the filters
            for j in range(B):
                calm = calm and not wp[L.W_SIGMA_W * B + j] > 0.0
            for _ in range(n_substeps):
                for j in range(m):  # a crashed vehicle keeps its pose: remember it
                    if contact[first + j] == L.CRASHED:
                        for k in range(size):
                            prev[k * B + j] = s[k * B + j]
                if weather:
                    wind_kernel.advance_block(s, p, wp, ws, rng, wscratch, sums, B, B, dt, calm)
                rotor_factors(s, p, sums, m, B)
                derivative(s, p, cmd, k1, m, sums, B, WIND)
                _axpy(tmp, s, 0.5 * dt, k1, m, B)
                derivative(tmp, p, cmd, k2, m, sums, B, WIND)
                _axpy(tmp, s, 0.5 * dt, k2, m, B)
                derivative(tmp, p, cmd, k3, m, sums, B, WIND)
                _axpy(tmp, s, dt, k3, m, B)
                derivative(tmp, p, cmd, k4, m, sums, B, WIND)
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
            for j in range(m):
                for k in range(size):
                    state[first + j, k] = s[k * B + j]
                if weather:
                    for k in range(L.N_WIND_STATE):
                        wind_state[first + j, k] = ws[k * B + j]
                    streams[first + j] = rng[j]
        return -1

    if wind:
        return jit(advance)

    # Still air: the same steps without the weather's, written out again because a
    # compiled function calling ``advance`` would hold it as a closure variable, and
    # numba's cache key pickles those (a dispatcher by a random UUID): every process
    # then missed the cache and compiled the kernel again (15–30 s). Three arguments
    # fewer also matter here: numba's call costs ~0.35 µs with 7 arrays and scalars,
    # ~1 µs with 10, against a single vehicle's step of about 1 µs.
    @jit
    def still_step(
        state, params, rotor_cmd, contact, touchdown_speed, dt, n_substeps
    ):  # pragma: no cover
        """Advance every vehicle ``n_substeps`` physics steps of ``dt`` in place.

        Returns -1, or the index of the first
        vehicle with a non-finite command, in which case nothing was changed.
        """
        commands = rotor_cmd.ravel()  # (n, 4), or (4,) for one vehicle: 4 per vehicle
        bad = first_invalid_command(commands)
        if bad >= 0:
            return bad
        size = L.STATE_SIZE
        # One allocation cut into the block arrays (each a run of rows of B values).
        z = size * B
        scratch = np.empty(scratch_size)
        s, prev, tmp = scratch[0:z], scratch[z : 2 * z], scratch[2 * z : 3 * z]
        k1, k2 = scratch[3 * z : 4 * z], scratch[4 * z : 5 * z]
        k3, k4 = scratch[5 * z : 6 * z], scratch[6 * z : 7 * z]
        p = scratch[7 * z : 7 * z + L.N_PARAMS * B]
        cmd = scratch[7 * z + L.N_PARAMS * B : 7 * z + (L.N_PARAMS + L.N_ROTORS) * B]
        sums = scratch[7 * z + (L.N_PARAMS + L.N_ROTORS) * B :]
        sixth = dt / 6.0
        for first in range(0, state.shape[0], B):
            m = min(B, state.shape[0] - first)
            for j in range(m):
                for k in range(size):
                    s[k * B + j] = state[first + j, k]
                for k in range(L.N_PARAMS):
                    p[k * B + j] = params[first + j, k]
                for k in range(L.N_ROTORS):
                    cmd[k * B + j] = commands[(first + j) * L.N_ROTORS + k]
            for _ in range(n_substeps):
                for j in range(m):  # a crashed vehicle keeps its pose: remember it
                    if contact[first + j] == L.CRASHED:
                        for k in range(size):
                            prev[k * B + j] = s[k * B + j]
                derivative(s, p, cmd, k1, m, sums, B, False)
                _axpy(tmp, s, 0.5 * dt, k1, m, B)
                derivative(tmp, p, cmd, k2, m, sums, B, False)
                _axpy(tmp, s, 0.5 * dt, k2, m, B)
                derivative(tmp, p, cmd, k3, m, sums, B, False)
                _axpy(tmp, s, dt, k3, m, B)
                derivative(tmp, p, cmd, k4, m, sums, B, False)
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
            for j in range(m):
                for k in range(size):
                    state[first + j, k] = s[k * B + j]
        return -1

    return still_step


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
