"""The admittance loop on its own (bridge/admittance.py): the tare, the law over a tick, the
deadzone, the limits and the protective stop. (On the paper's load behind velocity-commanded
bases: tests/unit/simulator/test_admittance_stability.py.)"""

from __future__ import annotations

import math

import pytest

from bridge.admittance import Admittance, AdmittanceSettings, deadzone

T = 0.01


def tared(settings: AdmittanceSettings, bias=(0.3, -0.2)) -> Admittance:
    loop = Admittance(settings, T)
    for _ in range(settings.tare_samples):
        loop.measure(bias)
    return loop


def test_the_bias_is_the_mean_of_the_first_samples_and_the_base_waits_for_it() -> None:
    loop = Admittance(AdmittanceSettings(tare_samples=4), T)
    for raw in ((1.0, 0.0), (3.0, -2.0), (2.0, -1.0)):
        loop.measure(raw)
        assert loop.step((5.0, 5.0)) == (0.0, 0.0) and not loop.tared
    loop.measure((2.0, -1.0))
    assert loop.tared and loop.bias == (2.0, -1.0)
    assert loop.measure((7.0, 1.0)) == (5.0, 2.0)  # the tared force
    assert loop.bias == (2.0, -1.0)  # no longer moved by samples


def test_a_steady_error_drives_the_base_towards_e_over_d_exactly() -> None:
    """``M v̇ = e − D v`` solved over each tick: after ``n`` ticks ``v = e/D (1 − e^{−nDT/M})``,
    and a ``D T / M`` far beyond 2 (where a forward Euler step diverges) converges."""
    for mass, damping in ((100.0, 1000.0), (0.01, 1000.0)):
        settings = AdmittanceSettings(
            mass=mass, damping=damping, deadzone_n=0.0, max_speed=8.0, max_accel=100.0
        )
        loop = tared(settings, bias=(0.0, 0.0))
        loop.measure((0.0, 0.0))
        for n in range(1, 6):
            v = loop.step((40.0, 0.0))
            expected = 40.0 / damping * (1.0 - math.exp(-n * damping * T / mass))
            assert v[0] == pytest.approx(expected, rel=1e-9) and v[1] == 0.0


def test_the_deadzone_shortens_the_error_continuously() -> None:
    assert deadzone((0.06, -0.08), 0.1) == (0.0, 0.0)
    assert deadzone((3.0, 4.0), 1.0) == pytest.approx((2.4, 3.2))
    settings = AdmittanceSettings(deadzone_n=0.5)
    loop = tared(settings, bias=(0.0, 0.0))
    loop.measure((0.0, 0.0))
    assert loop.step((0.4, 0.0)) == (0.0, 0.0)


def test_the_command_keeps_within_max_accel_and_max_speed() -> None:
    settings = AdmittanceSettings(
        mass=0.01, damping=0.0, integral_time_s=0.05, max_speed=0.5, max_accel=2.0
    )
    loop = tared(settings, bias=(0.0, 0.0))
    last = (0.0, 0.0)
    for _ in range(100):
        loop.measure((0.0, 0.0))
        v = loop.step((30.0, 40.0))
        assert math.dist(v, last) <= 2.0 * T + 1e-12
        assert math.hypot(*v) <= 0.5 + 1e-12
        last = v
    assert math.hypot(*last) == pytest.approx(0.5)
    assert last[1] / last[0] == pytest.approx(4.0 / 3.0)  # along the error


def test_a_force_beyond_the_limit_commands_standstill_and_forgets_the_state() -> None:
    loop = tared(AdmittanceSettings(max_contact_force=50.0, damping=10.0, mass=1.0))
    loop.measure((10.3, -0.2))  # 10 N
    assert loop.step((20.0, 0.0)) != (0.0, 0.0) and not loop.overloaded
    loop.measure((45.3, 30.0 - 0.2))  # 54 N
    assert loop.step((20.0, 0.0)) == (0.0, 0.0)
    assert loop.overloaded and loop.overloads == 1 and loop.velocity == (0.0, 0.0)
    loop.measure((10.3, -0.2))
    assert loop.step((20.0, 0.0)) != (0.0, 0.0) and not loop.overloaded
    assert loop.overloads == 1


def test_tracking_is_the_error_over_the_last_steps() -> None:
    loop = tared(AdmittanceSettings(), bias=(0.0, 0.0))
    assert loop.tracking().samples == 0
    for k in range(20):
        loop.measure((float(k % 2), 0.0))  # errors 2 and 1 N in turn
        loop.step((2.0, 0.0))
    tracking = loop.tracking()
    assert tracking.samples == 20
    assert tracking.rms == pytest.approx(math.sqrt(2.5)) and tracking.p95 == 2.0
