"""Bad input gets a clear ValueError naming the problem and never a NaN state."""

from __future__ import annotations

import math

import numpy as np
import pytest

from quadsitl.physics import PAPER, Airframe, Fleet, get_airframe


@pytest.mark.parametrize("backend", ["compiled", "reference"])
@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_non_finite_rotor_commands_raise_and_leave_state_untouched(backend, bad):
    fleet = Fleet(3, backend=backend)
    before = fleet.state.copy()
    cmd = np.full((3, 4), 200.0)
    cmd[1, 2] = bad
    with pytest.raises(ValueError, match="vehicle 1 is not finite"):
        fleet.step(cmd)
    np.testing.assert_array_equal(fleet.state, before)
    assert fleet.time == 0.0


@pytest.mark.parametrize("shape", [(3,), (1, 4), (4, 4), (2, 3), (4,), ()])
def test_wrong_command_shape_raises(shape):
    fleet = Fleet(2)
    with pytest.raises(ValueError, match=r"shape \(2, 4\)"):
        fleet.step(np.zeros(shape))


def test_single_vehicle_accepts_a_flat_command():
    fleet = Fleet(1)
    fleet.step(np.full(4, PAPER.hover_rotor_speed))
    assert fleet.time == pytest.approx(0.01)


@pytest.mark.parametrize("backend", ["compiled", "reference"])
@pytest.mark.parametrize("n", [1, 3])
def test_every_form_of_a_command_steps_the_same(backend, n):
    """(n, 4) or, for one vehicle, (4,); float64 or not, contiguous or not, array or list:
    the fast path of Fleet.step takes some as they are and converts the rest."""
    command = np.linspace(150.0, 320.0, 4 * n).reshape(n, 4)
    wide = np.zeros((n, 8))
    wide[:, ::2] = command  # a non-contiguous view of the same numbers
    forms = [command, wide[:, ::2], command.tolist(), command.astype(np.float32)]
    if n == 1:
        forms += [command[0], wide[0, ::2], command[0].tolist()]
    results = []
    for form in forms:
        fleet = Fleet(n, backend=backend)
        fleet.step(form, n_substeps=3)
        results.append(fleet.state.copy())
    expected = Fleet(n, backend=backend)
    expected.step(command.astype(np.float32).astype(np.float64), n_substeps=3)
    assert not np.array_equal(expected.state, results[0])  # the forms are told apart
    for form, state in zip(forms, results, strict=True):
        # float32 differs from float64 only by the rounding of the command itself
        same_as = expected.state if np.asarray(form).dtype == np.float32 else results[0]
        np.testing.assert_array_equal(state, same_as)


def test_unknown_airframe_name():
    with pytest.raises(ValueError, match=r"unknown airframe 'bogus'.*paper"):
        get_airframe("bogus")
    with pytest.raises(ValueError, match="unknown airframe"):
        Fleet(1, airframe="bogus")


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("mass", -0.65),
        ("mass", 0.0),
        ("mass", math.nan),
        ("thrust_coeff", 0.0),
        ("drag_coeff", -1.0),
        ("gravity", math.inf),
        ("hover_thrust_fraction", 1.5),
    ],
)
def test_non_physical_parameters_are_named(field, value):
    with pytest.raises(ValueError, match=field):
        PAPER.replace(**{field: value})


@pytest.mark.parametrize("inertia", [(0.0, 7.5e-3, 1.3e-2), (7.5e-3, -1.0, 1.3e-2), (1.0, 1.0)])
def test_zero_or_negative_inertia(inertia):
    with pytest.raises(ValueError, match="inertia"):
        Airframe(name="broken", inertia=inertia)


def test_unknown_parameter_name():
    with pytest.raises(ValueError, match=r"unknown airframe parameter.*'masss'"):
        PAPER.replace(masss=1.0)


def test_bad_fleet_arguments():
    with pytest.raises(ValueError, match="dt"):
        Fleet(1, dt=0.0)
    with pytest.raises(ValueError, match="positive integer"):
        Fleet(0)
    with pytest.raises(ValueError, match="backend"):
        Fleet(1, backend="gpu")
    fleet = Fleet(2)
    with pytest.raises(ValueError, match="finite"):
        fleet.reset(np.full(17, math.nan))
    with pytest.raises(ValueError, match="shape"):
        fleet.reset(np.zeros((3, 17)))
