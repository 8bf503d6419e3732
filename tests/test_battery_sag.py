"""The battery: voltage from charge, internal resistance and current (closed forms), and
the rotors' top speed following it when SIM_BAT_SAG is set (off by default)."""

from __future__ import annotations

import numpy as np
import pytest

from quadsitl.flight_software.battery import Battery, ocv_shape
from quadsitl.flight_software.vehicle import Vehicle
from quadsitl.physics import layout as L


def test_voltage_under_a_constant_current_is_the_closed_form():
    """V(t) = n·(V_empty + (V_full − V_empty)·f(1 − I t / C)) − I·n·R, f the discharge
    curve's shape; drawn in 10 ms steps for 30 min at 4 A from a 2200 mAh 4S pack."""
    battery = Battery(capacity_mah=2200.0, cells=4, cell_resistance=0.012)
    current, dt = 4.0, 0.01
    for k in range(1, 180_001):
        battery.draw(current, dt)
        if k % 6000 == 0:
            t = k * dt
            charge = 1.0 - current * t / 3600.0 / 2.2
            ocv = 4 * (3.5 + 0.7 * float(ocv_shape(charge)))
            assert battery.remaining == pytest.approx(charge, abs=1e-9)
            assert battery.voltage == pytest.approx(ocv - current * 4 * 0.012, abs=1e-6)
    assert battery.voltage < battery.open_circuit_voltage < battery.full_voltage


def test_the_discharge_curve_runs_from_empty_to_full_and_only_falls():
    charge = np.linspace(0, 1, 1001)
    shape = ocv_shape(charge)
    assert shape[0] == 0.0 and shape[-1] == 1.0
    assert (np.diff(shape) > 0).all()
    assert Battery().voltage == pytest.approx(4 * 4.2)  # full, at rest


def test_current_delivers_the_power_at_the_voltage_it_leaves():
    """I = I_av + P / V and V = E − R·I: the motors get exactly the power asked for."""
    battery = Battery(cell_resistance=0.01)
    for shaft in (0.0, 35.0, 200.0, 800.0):
        current = battery.current_for(shaft)
        battery.draw(current, 0.0)  # no charge drawn: just the load
        motors = current - battery.avionics_current
        assert motors * battery.voltage == pytest.approx(shaft / battery.efficiency, rel=1e-9)


def test_beyond_what_the_pack_can_give_the_current_is_that_of_its_maximum_power():
    battery = Battery(cell_resistance=0.05)
    e = battery.open_circuit_voltage - battery.resistance * battery.avionics_current
    most = e * e / (4 * battery.resistance)  # W, at V = E/2
    current = battery.current_for(10 * most * battery.efficiency)
    assert np.isfinite(current)
    battery.draw(current, 0.0)
    assert battery.voltage == pytest.approx(e / 2, rel=1e-9)


def _fly_up(v: Vehicle, seconds: float) -> None:
    v.arm()
    v.takeoff(20.0)
    for _ in range(round(seconds / v.fleet.dt)):
        v.step()


def test_without_sim_bat_sag_the_rotors_top_speed_stays_the_airframes():
    v = Vehicle()
    v.battery.used_mah = 0.9 * v.battery.capacity_mah  # nearly empty
    _fly_up(v, 1.0)
    assert v.fleet.params[0, L.P_OMEGA_MAX] == v.airframe.max_rotor_speed


def test_with_sim_bat_sag_the_rotors_top_speed_follows_the_voltage():
    v = Vehicle()
    v.set_param("SIM_BAT_SAG", 1)
    v.battery.used_mah = 0.9 * v.battery.capacity_mah
    _fly_up(v, 1.0)
    scale = v.battery.voltage / v.battery.full_voltage
    assert 0.7 < scale < 0.95
    omega_max = v.fleet.params[0, L.P_OMEGA_MAX]
    assert omega_max == pytest.approx(v.airframe.max_rotor_speed * scale, rel=1e-12)
    assert (v.fleet.state[0, L.ROTORS] <= omega_max).all()
    v.set_param("SIM_BAT_SAG", 0)  # switched off: the airframe's again
    assert v.fleet.params[0, L.P_OMEGA_MAX] == v.airframe.max_rotor_speed


def test_a_weak_battery_climbs_slower():
    """Full throttle up: with a sagging, nearly empty battery the climb is slower than
    with a full one, and slower than without the sag."""
    heights = {}
    for name, sag, used in (("full", 1, 0.0), ("weak", 1, 0.95), ("no sag", 0, 0.95)):
        v = Vehicle()
        v.set_param("MPC_Z_VEL_MAX_UP", 8.0)
        v.set_param("MPC_TKO_SPEED", 5.0)
        v.set_param("SIM_BAT_SAG", sag)
        v.battery.used_mah = used * v.battery.capacity_mah
        _fly_up(v, 2.0)
        heights[name] = v.altitude
        assert np.isfinite(v.fleet.state).all()
    assert heights["weak"] < heights["full"] - 0.2
    assert heights["weak"] < heights["no sag"] - 0.2


def test_battery_parameters_are_checked():
    v = Vehicle()
    v.set_param("BAT1_R_INTERNAL", 0.02)
    assert v.battery.resistance == pytest.approx(4 * 0.02)
    for name, bad in (("BAT1_R_INTERNAL", -0.1), ("BAT1_R_INTERNAL", float("nan")),
                      ("SIM_BAT_SAG", 2)):  # fmt: skip
        with pytest.raises(ValueError) as error:
            v.set_param(name, bad)
        assert "\n" not in str(error.value)


def test_one_cells_shape_is_numpys_interpolation_bit_for_bit():
    """The scalar path a battery drains through each control period gives np.interp's
    bits (ends, table points, between them, beyond them, NaN)."""
    import math

    from quadsitl.flight_software.battery import OCV_CHARGE, ocv_shape, ocv_shape_of

    charges = np.concatenate(
        [np.linspace(-0.5, 1.5, 20_001), OCV_CHARGE, np.random.default_rng(0).random(20_000)]
    )
    for charge in charges.tolist():
        assert ocv_shape_of(charge) == float(ocv_shape(charge))
    assert math.isnan(ocv_shape_of(math.nan)) and math.isnan(float(ocv_shape(math.nan)))
