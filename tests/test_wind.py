"""The wind field against its specification: σ and spectrum of the Dryden turbulence at
any physics step, the exact discretisation, closed forms (tilt in steady wind, gust peak,
log profile), batched vs reference, bad input, and still air left exactly as it was."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from quadsitl.frames import quat_normalize
from quadsitl.physics import PAPER, Fleet, kernel
from quadsitl.physics import dryden as D
from quadsitl.physics import layout as L
from quadsitl.physics.wind import Gust, Wind, profile_factor

# Drag-free airframe: the wind cannot move it, so a hovering vehicle samples the
# turbulence at a fixed height and airspeed (V = the mean wind speed).
STILL = PAPER.replace(drag_coeff=0.0, aero_moment_coeff=0.0)
HOVER = PAPER.hover_rotor_speed
HEIGHT = 10.0  # m
MEAN = 10.0  # m/s, from the west: the turbulence x axis is east, y north


def _hover_state(height: float = HEIGHT) -> np.ndarray:
    state = np.zeros(L.STATE_SIZE)
    state[L.I_PZ], state[L.I_QW] = height, 1.0
    state[L.ROTORS] = HOVER
    return state


def _record(n: int, dt: float, steps: int, weather: Wind, seed: int = 1) -> np.ndarray:
    """(steps, n, 6) air velocity minus the mean (u, v, w) and air rates (p, q, r)."""
    fleet = Fleet(n, airframe=STILL, dt=dt, ground_z=-np.inf)
    fleet.reset(_hover_state())
    fleet.set_wind(weather, seed=seed)
    cmd = np.full((n, 4), HOVER)
    out = np.empty((steps, n, 6))
    for k in range(steps):
        fleet.step(cmd)
        out[k] = fleet.wind_state[:, L.WS_AIR_VELOCITY.start : L.WS_AIR_RATES.stop]
    assert np.isfinite(out).all()
    assert np.abs(fleet.position[:, 2] - HEIGHT).max() < 1e-6  # it did hover in place
    out[:, :, 0] -= MEAN
    return out


def _expected_sigmas(height: float = HEIGHT, sigma_w: float = 1.5) -> np.ndarray:
    """σ of (u, v, w, p, q, r) from the model's formulas (not from the filters)."""
    su, sv, sw = D.intensities(height, sigma_w)
    lu, lw = D.spectral_lengths(height)
    span = 2 * (PAPER.arm_length + PAPER.rotor_radius)
    sp = D.roll_rate_sigma(height, sigma_w, span)
    sq = sigma_w / lw * D.rate_sigma(D.RATE_LENGTH_P * span / lw)
    sr = sv / lu * D.rate_sigma(D.RATE_LENGTH_R * span / lu)
    return np.array([su, sv, sw, sp, sq, sr], dtype=np.float64)


@pytest.mark.parametrize("dt", [0.001, 0.004, 0.01])
def test_turbulence_sigma_per_axis_at_any_physics_step(dt):
    record = _record(64, dt, 100_000, Wind(speed=MEAN, from_deg=270, turbulence=1.5))
    measured = record.reshape(-1, 6).std(axis=0)
    np.testing.assert_allclose(measured, _expected_sigmas(), rtol=0.05)


def _psd(x: np.ndarray, dt: float, segment: int) -> tuple[np.ndarray, np.ndarray]:
    """One-sided PSD (per rad/s) by averaged Hann-windowed periodograms over segments of
    each column of x (steps, n)."""
    window = np.hanning(segment)
    count = x.shape[0] // segment
    chunks = x[: count * segment].reshape(count, segment, -1).transpose(0, 2, 1)
    chunks = chunks - chunks.mean(axis=2, keepdims=True)
    spectrum = np.abs(np.fft.rfft(chunks * window, axis=2)) ** 2
    density = spectrum.mean(axis=(0, 1)) * dt / (np.sum(window**2) * math.pi)
    density[1:-1] *= 2  # one-sided
    return 2 * math.pi * np.fft.rfftfreq(segment, dt), density / 2


def test_turbulence_spectrum_is_drydens_over_a_decade():
    """Each axis's PSD, in fifth-of-a-decade bands over the decade above its corner
    frequency V/L, within 15 % of the Dryden form (aliased as sampling at dt aliases it:
    the samples are the continuous process's, exactly)."""
    dt = 0.01
    record = _record(64, dt, 40_000, Wind(speed=MEAN, from_deg=270, turbulence=1.5), seed=7)
    span = 2 * (PAPER.arm_length + PAPER.rotor_radius)
    lu, lw = (float(x) for x in D.spectral_lengths(HEIGHT))
    lengths = dict(u=lu, v=lu, w=lw, p=D.RATE_LENGTH_P * span, q=lw, r=D.RATE_LENGTH_R * span)
    sampling = 2 * math.pi / dt  # rad/s
    for axis, name in enumerate("uvwpqr"):
        omega, measured = _psd(record[:, :, axis], dt, 8192)
        model = sum(
            D.psd(np.abs(omega + k * sampling), MEAN, HEIGHT, 1.5, span)[name] for k in range(-3, 4)
        )
        edges = MEAN / lengths[name] * np.geomspace(1.0, 10.0, 6)
        for low, high in itertools.pairwise(edges):
            band = (omega >= low) & (omega < high)
            ratio = measured[band].mean() / model[band].mean()
            assert abs(ratio - 1) < 0.15, (name, low, ratio)


def test_both_dryden_forms_are_the_same_spectra_at_low_altitude():
    omega = np.geomspace(0.01, 100, 50)
    a = D.psd(omega, 7.0, 30.0, 1.2, 0.66, "8785C")
    b = D.psd(omega, 7.0, 30.0, 1.2, 0.66, "1797")
    for name in a:
        np.testing.assert_allclose(a[name], b[name], rtol=1e-12)
    lu, lv, lw = D.scale_lengths(30.0, "1797")
    assert lv == pytest.approx(lu / 2) and lw == pytest.approx(30.0 / 2)


def _expm(a: np.ndarray) -> np.ndarray:
    """Matrix exponential by scaling and squaring of its Taylor series."""
    k = 10
    x, term, result = a / 2**k, np.eye(len(a)), np.eye(len(a))
    for i in range(1, 20):
        term = term @ x / i
        result = result + term
    for _ in range(k):
        result = result @ result
    return result


@pytest.mark.parametrize("rho", [0.05, 0.3, 0.7])
def test_discretisation_closed_forms_against_the_state_space_model(rho):
    a = np.array([[-1.0, 0, 0], [1.0, -1.0, 0], [0, 0, -1.0 / rho]])
    b = np.array([1.0, 0.0, 1.0 / rho])
    p = D.stationary_covariance(rho)
    np.testing.assert_allclose(a @ p + p @ a.T + np.outer(b, b), 0, atol=1e-12)
    for dtau in (1e-4, 0.05, 2.0):
        phi = D.transition(dtau, rho)
        np.testing.assert_allclose(phi, _expm(a * dtau), rtol=1e-10, atol=1e-14)
        theta = np.linspace(0, dtau, 20_001)  # Q = ∫ e^{Aθ} b bᵀ e^{Aᵀθ} dθ
        small_step, g = _expm(a * theta[1]), [b]
        for _ in theta[1:]:
            g.append(small_step @ g[-1])
        g = np.array(g)
        q_ref = np.trapezoid(g[:, :, None] * g[:, None, :], theta, axis=0)
        factor = D.noise_factor(dtau, rho)
        np.testing.assert_allclose(factor @ factor.T, q_ref, rtol=1e-5, atol=1e-12)
    ra, rb, rc = D.rate_gains(rho)
    for s in (0.3 + 0.2j, 2.0, -0.4j):
        lhs = s * (1 + D.SQRT3 * s) / ((1 + s) ** 2 * (1 + rho * s))
        assert lhs == pytest.approx(ra / (1 + s) + rb / (1 + s) ** 2 + rc / (1 + rho * s))


def _random_states(n: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    state = np.zeros((n, L.STATE_SIZE))
    state[:, L.POS] = rng.uniform(-2, 2, (n, 3))
    state[:, L.I_PZ] = rng.uniform(0.2, 80, n)
    state[:, L.VEL] = rng.normal(0, 3.0, (n, 3))
    state[:, L.QUAT] = quat_normalize(np.c_[np.ones(n), rng.normal(0, 0.2, (n, 3))])
    state[:, L.RATES] = rng.normal(0, 1.0, (n, 3))
    state[:, L.ROTORS] = rng.uniform(150, 300, (n, 4))
    return state


def _weathers(n: int) -> list[Wind]:
    gust = Gust(amplitude=(1.0, -2.0, 0.5), length=3.0, start=0.05, hold=1.0)
    kinds = [
        Wind(speed=6, from_deg=30, turbulence="moderate", gust=gust),
        Wind(speed=12, from_deg=200, profile="log", turbulence="severe"),
        Wind(turbulence=0.8, turbulence_model="1797"),
        Wind(speed=3, from_deg=90),
    ]
    return [kinds[i % len(kinds)] for i in range(n)]


def test_batched_wind_equals_the_numpy_reference_and_single_vehicles():
    n = 40
    states = _random_states(n, 3)
    commands = np.random.default_rng(4).uniform(150, 320, (n, 4))
    fleets = {b: Fleet(n, dt=0.005, ground_z=-np.inf, backend=b) for b in ("compiled", "reference")}
    singles = [Fleet(1, dt=0.005, ground_z=-np.inf) for _ in range(3)]
    for fleet in fleets.values():
        fleet.reset(states)
        fleet.set_wind(_weathers(n), seed=11)
    for i, single in enumerate(singles):  # vehicle i of seed 11 is the i-th stream
        single.reset(states[i])
        single.set_wind(_weathers(n)[i])
        single.wind_streams[:] = fleets["compiled"].wind_streams[i]
        single.wind_state[:] = fleets["compiled"].wind_state[i]
    for _ in range(30):
        for fleet in fleets.values():
            fleet.step(commands, n_substeps=2)
        for i, single in enumerate(singles):
            single.step(commands[i], n_substeps=2)
    compiled, reference = fleets["compiled"], fleets["reference"]
    # Not to 1e-12 as the still-air physics: the compiled normals are float32 (rounding
    # 1e-7), and the smallest directions of the step noise (variance ~τ⁵, τ ~1e-4 here)
    # are known to either implementation only to the rounding of P − ΦPΦᵀ (~1e-16).
    air = slice(L.WS_AIR_VELOCITY.start, L.WS_AIR_RATES.stop)
    np.testing.assert_allclose(compiled.wind_state[:, air], reference.wind_state[:, air], atol=1e-4)
    np.testing.assert_allclose(
        compiled.wind_state[:, L.WS_TURBULENCE],
        reference.wind_state[:, L.WS_TURBULENCE],
        rtol=2e-4,
        atol=2e-3,
    )
    np.testing.assert_allclose(compiled.state, reference.state, rtol=0, atol=1e-5)
    np.testing.assert_array_equal(compiled.wind_streams, reference.wind_streams)
    for i, single in enumerate(singles):
        np.testing.assert_allclose(single.state[0], compiled.state[i], rtol=0, atol=1e-12)
    assert np.abs(compiled.air_velocity).max() > 1.0  # the weather did blow


def test_a_block_without_turbulence_skips_its_filters_in_step_with_the_reference():
    """A mean wind (uniform or log profile, with a gust or not) on a whole block of 32
    vehicles takes the kernel's calm path: the same air as the reference, the filter
    states left as they were, the random streams moved past the draws skipped, so that
    turbulence given later starts from the same draws in both."""
    n = 40  # vehicles 0-31: one block without turbulence; 32-39: a mixed block
    gust = Gust(amplitude=(1.5, 0.5, -1.0), length=2.0, start=0.02, hold=0.5)
    calm = [
        Wind(
            speed=5,
            from_deg=270,
            profile="log" if i % 2 else "uniform",
            gust=gust if i % 3 else None,
        )
        for i in range(32)
    ]
    states = _random_states(n, 8)
    commands = np.random.default_rng(9).uniform(150, 320, (n, 4))
    fleets = {b: Fleet(n, dt=0.005, ground_z=-np.inf, backend=b) for b in ("compiled", "reference")}
    single = Fleet(1, dt=0.005, ground_z=-np.inf)  # a block of one, calm too
    for fleet in fleets.values():
        fleet.reset(states)
        fleet.set_wind(calm + _weathers(8), seed=21)
    single.reset(states[:1])
    single.set_wind(calm[0], seed=0)
    single.wind_streams[:] = fleets["compiled"].wind_streams[0]
    before = fleets["compiled"].wind_state[:32, L.WS_TURBULENCE].copy()
    for _ in range(30):
        for fleet in fleets.values():
            fleet.step(commands, n_substeps=2)
        single.step(commands[0], n_substeps=2)
    compiled, reference = fleets["compiled"], fleets["reference"]
    air = slice(L.WS_AIR_VELOCITY.start, L.WS_AIR_RATES.stop)
    np.testing.assert_allclose(
        compiled.wind_state[:32, air], reference.wind_state[:32, air], atol=1e-9
    )
    np.testing.assert_array_equal(compiled.wind_state[:32, L.WS_TURBULENCE], before)
    np.testing.assert_array_equal(reference.wind_state[:32, L.WS_TURBULENCE], before)
    np.testing.assert_array_equal(compiled.wind_streams, reference.wind_streams)
    np.testing.assert_allclose(compiled.state[:32], reference.state[:32], rtol=0, atol=1e-9)
    np.testing.assert_allclose(single.state[0], compiled.state[0], rtol=0, atol=1e-12)
    assert np.ptp(compiled.air_velocity[:32, 2]) > 0.5  # the gusts blew (up and down)
    # Turbulence given later starts from the same draws in both implementations.
    stirred = np.arange(n) < 32
    for fleet in fleets.values():
        fleet.set_wind(Wind(speed=5, from_deg=270, turbulence="moderate"), mask=stirred)
        for _ in range(10):
            fleet.step(commands, n_substeps=2)
    np.testing.assert_allclose(compiled.wind_state[:, air], reference.wind_state[:, air], atol=1e-4)
    assert np.abs(compiled.wind_state[:32, L.WS_AIR_RATES]).max() > 0.01  # rate gusts now


def test_still_air_is_the_windless_physics_bit_for_bit():
    n = 33
    states = _random_states(n, 5)
    commands = np.random.default_rng(6).uniform(0, 330, (n, 4))
    plain, calm = Fleet(n, dt=0.01), Fleet(n, dt=0.01)
    for fleet in (plain, calm):
        fleet.reset(states)
    calm.set_wind(Wind(), seed=2)  # still air: the windless kernel
    # The wind build itself, with every parameter zero, also leaves the physics as it is.
    windy_args = (np.zeros((n, L.N_WIND_PARAMS)), np.zeros((n, L.N_WIND_STATE)))
    forced = states.copy()
    contact, touchdown = np.zeros(n, np.int8), np.zeros(n)
    forced_params = plain.params.copy()
    forced_wind = windy_args[0]
    forced_wind[:, L.W_SPAN] = 0.66
    forced_wind[:, L.W_GUST_LENGTH] = np.inf
    streams = np.arange(n, dtype=np.uint64)
    for _ in range(20):
        plain.step(commands, n_substeps=3)
        calm.step(commands, n_substeps=3)
        kernel.batch_step_wind(
            forced, forced_params, commands, contact, touchdown, 0.01, 3, *windy_args, streams
        )
    np.testing.assert_array_equal(calm.state, plain.state)
    np.testing.assert_allclose(forced, plain.state, rtol=0, atol=1e-12)  # (FMA order)
    assert not calm.windy


def _hold_state(tilt: float, airframe=PAPER) -> np.ndarray:
    """At rest, tilted by ``tilt`` rad about north (the thrust leaning west), rotors
    giving a vertical thrust equal to the weight."""
    state = _hover_state(20.0)
    state[L.QUAT] = (math.cos(-tilt / 2), 0.0, math.sin(-tilt / 2), 0.0)
    state[L.ROTORS] = math.sqrt(airframe.weight / (4 * airframe.thrust_coeff * math.cos(tilt)))
    return state


def test_steady_wind_tilt_equals_atan_of_drag_over_weight():
    speed = 8.0  # from the west: blows east
    drag = PAPER.drag_coeff * speed**2  # the paper's law, F = kd |v_a| v_a
    tilt = math.atan(drag / PAPER.weight)
    accelerations = []
    for trial in (tilt, tilt + math.radians(1), tilt - math.radians(1)):
        fleet = Fleet(1, dt=0.001, ground_z=-np.inf)
        fleet.reset(_hold_state(trial))
        fleet.set_wind(Wind(speed=speed, from_deg=270))
        fleet.step(_hold_state(trial)[L.ROTORS])
        accelerations.append(np.abs(fleet.velocity[0]).max() / fleet.dt)
    assert accelerations[0] < 1e-6  # in equilibrium: holding position in the wind
    assert min(accelerations[1:]) > 0.05  # one degree off is not


def test_one_cosine_gust_peaks_at_its_amplitude_and_dies_away():
    dt, length, start = 0.01, 2.0, 0.3
    fleet = Fleet(1, airframe=STILL, dt=dt, ground_z=-np.inf)
    fleet.reset(_hover_state())
    fleet.set_wind(Wind(gust=Gust(amplitude=(0.0, 0.0, 3.0), length=length, start=start)))
    up = []
    for _ in range(700):
        fleet.step(np.full(4, HOVER))
        up.append(fleet.air_velocity[0, 2])
    up = np.array(up)
    time = np.arange(len(up)) * dt
    # Hovering in still air it flies through the gust at the 1 m/s floor: peak after d m.
    assert up.max() == pytest.approx(3.0, abs=1e-4)
    assert time[np.argmax(up)] == pytest.approx(start + length, abs=1.5 * dt)
    assert np.all(up[time < start] == 0.0)
    assert np.all(up[time > start + 2 * length + dt] == 0.0)
    held = Fleet(1, airframe=STILL, dt=dt, ground_z=-np.inf)
    held.reset(_hover_state())
    held.set_wind(Wind(gust=Gust((1.0, 0, 0), length=0.5, hold=math.inf)))  # the standard's
    held.step(np.full(4, HOVER), n_substeps=200)
    assert held.air_velocity[0, 0] == pytest.approx(1.0)


def test_log_profile_is_w20_at_20_ft():
    assert profile_factor(np.array([20 * D.FT]), np.array([1.0]))[0] == pytest.approx(1.0)
    factor = profile_factor(np.array([3.0]), np.array([1.0]))[0]
    assert factor == pytest.approx(math.log(3.0 / D.FT / 0.15) / math.log(20 / 0.15))
    for height, expected in ((20 * D.FT, 9.0), (3.0, 9.0 * factor)):
        fleet = Fleet(1, airframe=STILL, dt=0.01, ground_z=-np.inf)
        fleet.reset(_hover_state(height))
        fleet.set_wind(Wind(speed=9.0, from_deg=180, profile="log"))  # from the south
        fleet.step(np.full(4, HOVER))
        np.testing.assert_allclose(fleet.air_velocity[0], (0, expected, 0), atol=1e-12)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(speed=-1.0), "wind speed must be a finite number >= 0"),
        (dict(speed=math.nan), "wind speed must be a finite number >= 0"),
        (dict(speed=math.inf), "wind speed must be a finite number >= 0"),
        (dict(from_deg=math.nan), "wind direction must be finite"),
        (dict(turbulence="extreme"), "unknown turbulence severity 'extreme'"),
        (dict(turbulence=-0.5), "turbulence σ_w must be a finite number >= 0"),
        (dict(turbulence_model="von karman"), "unknown turbulence model"),
        (dict(profile="power"), "unknown wind profile"),
    ],
)
def test_bad_weather_is_a_one_line_error(kwargs, message):
    with pytest.raises(ValueError, match=message) as error:
        Wind(**kwargs)
    assert "\n" not in str(error.value)


def test_bad_gusts_and_fleet_arguments_are_one_line_errors():
    for kwargs in (
        dict(amplitude=(1.0, 2.0), length=1.0),
        dict(amplitude=(1.0, 2.0, math.nan), length=1.0),
        dict(amplitude=(1.0, 2.0, 3.0), length=0.0),
        dict(amplitude=(1.0, 2.0, 3.0), length=1.0, start=-1.0),
        dict(amplitude=(1.0, 2.0, 3.0), length=1.0, hold=-1.0),
    ):
        with pytest.raises(ValueError, match="gust"):
            Gust(**kwargs)
    fleet = Fleet(3)
    with pytest.raises(ValueError, match="one Wind for each of the 3"):
        fleet.set_wind([Wind(), Wind()])
    with pytest.raises(ValueError, match="wind seed must be an integer"):
        fleet.set_wind(Wind(), seed=1.5)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="span"):
        Fleet(1, airframe=PAPER.replace(arm_length=3.0)).set_wind(Wind(turbulence="light"))


def test_no_nan_in_extreme_weather_and_states():
    n = 64
    rng = np.random.default_rng(8)
    states = _random_states(n, 9)
    states[:, L.I_PZ] = rng.uniform(-50, 3000, n)  # below ground to far above 1000 ft
    states[:, L.VEL] = rng.normal(0, 60, (n, 3))
    for dt in (0.0001, 0.05):
        fleet = Fleet(n, dt=dt, ground_z=0.0)
        fleet.reset(states)
        severe = Gust((30.0, -30.0, 20.0), length=0.01, hold=0.0)
        fleet.set_wind(
            [Wind(speed=50, from_deg=i * 7, turbulence="severe", gust=severe) for i in range(n)],
            seed=3,
        )
        for _ in range(100):
            fleet.step(rng.uniform(0, 330, (n, 4)))
        assert np.isfinite(fleet.state).all() and np.isfinite(fleet.wind_state).all()


def test_turbulence_is_reproducible_per_vehicle_and_seed():
    weather = Wind(speed=5, turbulence="light")
    a = _record(4, 0.01, 200, weather, seed=5)
    b = _record(4, 0.01, 200, weather, seed=5)
    c = _record(4, 0.01, 200, weather, seed=6)
    np.testing.assert_array_equal(a, b)
    assert not np.allclose(a, c)
    assert not np.allclose(a[:, 0], a[:, 1])  # each vehicle has its own stream


def test_envs_fly_in_the_wind_option_reproducibly_and_refuse_bad_weather():
    """``wind=`` as an env option: a steady wind from the west carries a vehicle on
    hover thrust east; turbulence repeats with the seed; bad weather is one line."""
    import gymnasium as gym

    import quadsitl  # noqa: F401

    def fly(wind, seed=3):
        env = gym.make("QuadSITL/Hover-v0", wind=wind)
        env.reset(seed=seed)
        for _ in range(20):
            env.step(np.zeros(4, np.float32))
        position = env.unwrapped.engine.fleet.state[0, L.POS].copy()
        env.close()
        return position

    still = fly(None)
    westerly = fly({"speed": 6.0, "from_deg": 270.0})
    assert np.allclose(still, 0.0, atol=1e-6)
    assert westerly[0] > 0.1 and abs(westerly[1]) < 1e-6  # carried east, not north
    gusty = {"speed": 6.0, "from_deg": 270.0, "turbulence": "moderate"}
    np.testing.assert_array_equal(fly(gusty), fly(gusty))
    assert not np.allclose(fly(gusty), fly(gusty, seed=4))
    for bad, says in (
        ({"speed": -1}, "wind speed"),
        ({"sped": 3}, "unknown wind field"),
        ([1], "wind must be a Wind or a dict"),
        ({"speed": 3, "turbulence": "storm"}, "severity"),
    ):
        with pytest.raises(ValueError, match=says):
            gym.make("QuadSITL/Hover-v0", wind=bad)
    with pytest.raises(ValueError, match="backend='mavlink'"):
        gym.make("QuadSITL/Hover-v0", wind=gusty, backend="mavlink")


def _hover_lean(*options: str) -> tuple[np.ndarray, str]:
    """Take off to 2 m in ``quadsitl sim OPTIONS`` (through MAVLink) and hold for three
    simulated seconds; the mean horizontal part of the thrust direction over the hold
    (north, east: the sine of the lean towards each), and the console."""
    from tests.conftest import sim_with_client

    with sim_with_client("--speed 4 --logs none", *options, connect_timeout=60) as (client, sim):
        client.arm()
        client.takeoff(2.0)
        client.wait(lambda: client.position_enu()[2] > 1.9, 60, "take-off")
        first = client.wait_message("ATTITUDE_QUATERNION").time_boot_ms
        leans = []
        while True:  # three simulated seconds
            q = client.wait_message("ATTITUDE_QUATERNION")
            # Thrust along body −z (FRD): its world (NED) direction is −R·(0, 0, 1).
            north = -2 * (q.q2 * q.q4 + q.q1 * q.q3)
            east = -2 * (q.q3 * q.q4 - q.q1 * q.q2)
            leans.append((north, east))
            if q.time_boot_ms - first > 3000:
                break
    return np.mean(leans, axis=0), sim.output


def test_sim_flies_in_the_wind_it_is_given():
    """``quadsitl sim --wind 8,270``: a west wind blows east; holding position, the
    vehicle leans into it, west (its thrust has a westward part). In still air it
    hovers level."""
    still, _ = _hover_lean()
    windy, out = _hover_lean("--wind", "8,270")
    assert "wind 8 m/s from 270°" in out
    assert np.all(np.abs(still) < 0.005), still
    north, east = windy
    assert east < -0.02 and abs(north) < 0.2 * abs(east), windy


def test_ground_station_sees_and_sets_the_weather():
    """The weather of ``quadsitl sim --wind 5,270 --turbulence moderate`` reads back as
    the SIM_WIND_* parameters and is sent as WIND_COV (the air blowing east, the
    turbulence's variance); a ground station that sets SIM_WIND_SPD to 0 and
    SIM_WIND_TURB to 0 in flight calms the air, and VFR_HUD's airspeed then equals the
    speed over the ground (horizontal and climb)."""
    from tests.conftest import sim_with_client

    options = "--speed 4 --logs none --wind 5,270 --turbulence moderate"
    with sim_with_client(options, connect_timeout=60) as (client, _):
        params = client.get_params(timeout=30)
        assert params["SIM_WIND_SPD"] == 5 and params["SIM_WIND_DIR"] == 270
        moderate_sigma_w = 0.1 * D.SEVERITY_W20_KT["moderate"] * D.KNOT
        assert params["SIM_WIND_TURB"] == pytest.approx(moderate_sigma_w, rel=1e-6)
        east = []
        while len(east) < 5:  # one a second: the air blows east, 5 m/s on average
            wind = client.wait_message("WIND_COV", timeout=30)
            east.append(wind.wind_y)
            assert wind.var_vert == pytest.approx(moderate_sigma_w**2, rel=1e-5)
            assert wind.var_horiz > 2 * wind.var_vert  # σ_u, σ_v > σ_w near the ground
        assert 2.0 < np.mean(east) < 8.0, east
        client.arm()
        client.takeoff(2.0)
        client.wait(lambda: client.position_enu()[2] > 1.9, 60, "take-off")
        hud = client.wait_message("VFR_HUD", timeout=10)
        assert hud.airspeed > hud.groundspeed + 1.0  # holding position against the wind
        assert client.set_param("SIM_WIND_SPD", 0.0) == 0.0
        assert client.set_param("SIM_WIND_TURB", 0.0) == 0.0
        client.wait_message(
            "WIND_COV", 30, lambda w: w.wind_x == w.wind_y == w.wind_z == w.var_horiz == 0
        )
        assert any(t.startswith("wind 0 m/s from 270 deg") for t in client.texts), client.texts
        hud = client.wait_message("VFR_HUD", timeout=10)
        assert hud.airspeed == pytest.approx(math.hypot(hud.groundspeed, hud.climb), abs=1e-4)


@pytest.mark.slow
def test_the_demo_mission_flies_in_wind_and_turbulence(tmp_path):
    """``quadsitl demo --wind 5,270 --turbulence moderate``: the mission is flown and the
    vehicle lands at home; the path holds within 0.3 m RMS (0.04 m in still air)."""
    import re
    import subprocess

    from tests.conftest import cli

    result = subprocess.run(
        cli("demo --wind 5,270 --turbulence moderate --logs", tmp_path),
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    assert "wind 5 m/s from 270°; moderate turbulence (MIL-F-8785C)" in result.stdout
    rms = float(re.search(r"path tracking error: RMS ([\d.]+) m", result.stdout).group(1))
    assert rms < 0.3, result.stdout
    assert "landed: True" in result.stdout
