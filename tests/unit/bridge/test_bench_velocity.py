"""``heft bench can --profile velocity``: its pure parts (the base and contact model, the
pushes, the tracking figures, the report and its goals) and its command line. The benchmark of
a real bridge runs on vcan (``heft vcan -- heft bench can --profile velocity``)."""

from __future__ import annotations

import math

import pytest

from agent.platform.goals import judge
from agent.platform.heft import main
from agent.platform.protocol import Measurement
from bridge.bench import velocity as benchmark
from bridge.bench.contact import ContactModel, ContactSettings
from bridge.bench.velocity import (
    GOALS,
    PUSH_N,
    SETTLE_S,
    VelocityBenchReport,
    VelocityBenchSettings,
    figures,
    format_velocity_report,
    steady_push,
    tracking_error,
)
from bridge.config import load_bridge_config
from bridge.devtools.echo_agent import CYCLE_S, PUSH_S, REST_S, push, pusher
from bridge.devtools.rig import bridge_toml

PERIOD = 0.01


# ------------------------------------------------------------------------------ the model
def test_the_base_follows_its_command_with_its_speed_loop() -> None:
    model = ContactModel(ContactSettings(max_accel=100.0), PERIOD)
    for _ in range(5):  # one time constant
        model.advance((0.5, 0.0))
    assert model.v[0] == pytest.approx(0.5 * (1 - math.exp(-1)), rel=0.02)
    assert model.v[1] == 0.0


def test_the_base_keeps_its_own_acceleration_and_speed_limits() -> None:
    settings = ContactSettings(max_accel=3.0, max_speed=0.2)
    model = ContactModel(settings, PERIOD)
    model.advance((10.0, 10.0))
    assert math.hypot(*model.v) == pytest.approx(3.0 * PERIOD)  # a vector clamp
    for _ in range(100):
        model.advance((10.0, 10.0))
    assert math.hypot(*model.v) == pytest.approx(0.2)


def test_a_steady_push_carries_the_load_at_the_drags_speed() -> None:
    """Base and load at the same speed ``c``: the contact carries the drag, ``f = b c``, and
    the sensor reads it with its bias."""
    settings = ContactSettings(noise_std=0.0, drag=5.0, max_accel=100.0)
    model = ContactModel(settings, PERIOD)
    for _ in range(2000):
        model.advance((0.4, -0.3))
    assert model.pd == pytest.approx((0.4, -0.3), abs=1e-4)
    assert model.force == pytest.approx((2.0, -1.5), abs=1e-3)
    sensed = model.sensed()
    assert sensed == pytest.approx((2.0 + settings.bias[0], -1.5 + settings.bias[1]), abs=1e-3)


def test_the_contact_is_a_spring_and_a_damper() -> None:
    settings = ContactSettings(noise_std=0.0, stiffness=2000.0, damping=0.0, load_mass=1e9)
    model = ContactModel(settings, PERIOD)  # an immovable load
    model.x = (0.01, -0.02)
    model.advance((0.0, 0.0))
    assert model.force == pytest.approx((20.0, -40.0), rel=1e-6)


def test_the_sensors_noise_is_seeded() -> None:
    a, b = (ContactModel(ContactSettings(), PERIOD, seed=3) for _ in range(2))
    assert [a.sensed() for _ in range(5)] == [b.sensed() for _ in range(5)]
    assert a.sensed() != ContactModel(ContactSettings(), PERIOD, seed=4).sensed()


# ------------------------------------------------------------------------------ the pushes
def test_a_cycle_is_a_rest_a_push_and_a_push_back_along_x_then_y() -> None:
    assert push(0.0, 5.0) == (0.0, 0.0) and push(REST_S - 0.01, 5.0) == (0.0, 0.0)
    assert push(REST_S + 0.01, 5.0) == (5.0, 0.0)
    assert push(REST_S + PUSH_S + 0.01, 5.0) == (-5.0, 0.0)
    assert push(CYCLE_S + REST_S + 0.01, 5.0) == (0.0, 5.0)
    assert push(CYCLE_S + REST_S + PUSH_S + 0.01, 5.0) == (0.0, -5.0)
    assert PUSH_S >= 0.5  # a push holds its force at least half a second
    answer = pusher(5.0)(Measurement(1, 60, 0.6, (0.0, 0.0), (9.0, 9.0)))
    assert (answer.robot, answer.tick, answer.force) == (1, 60, (5.0, 0.0))


def test_the_steady_part_of_a_push_leaves_out_its_transient() -> None:
    assert steady_push(REST_S + SETTLE_S - 0.01) is None
    assert steady_push(REST_S + SETTLE_S + 0.01) == (PUSH_N, 0.0)
    assert steady_push(REST_S + PUSH_S + 0.1) is None
    assert steady_push(0.1) is None  # the rest is no push
    assert tracking_error((5.5, 0.0), (5.0, 0.0)) == pytest.approx(0.1)
    assert tracking_error((5.0, 0.3), (5.0, 0.0)) == pytest.approx(0.06)


# ------------------------------------------------------------------------------ the report
def report(errors, latencies, where="natively") -> VelocityBenchReport:
    return VelocityBenchReport(
        VelocityBenchSettings(stiffness=10_000.0),
        where,
        errors,
        latencies,
        sent=1000,
        lost=2,
        seconds=10.0,
        cpu_percent={"bridge": 12.5, "router": 3.0, "echo agent": 2.0, "driver": 8.0},
        bridge_rms_n=0.125,
        bridge_p95_n=0.25,
    )


def test_the_report_gives_tracking_round_trip_and_cpu() -> None:
    errors = [0.01] * 90 + [0.04] * 10
    text = format_velocity_report(report(errors, [1.0, 2.0, 3.0]))
    assert "contact 10000 N/m" in text and "measured natively" in text
    assert "samples            100" in text
    assert f"rms                {100 * math.sqrt(0.9e-4 + 0.1 * 0.0016):.2f} %" in text
    assert "p95                4.00 %" in text
    assert "rms 0.125 N, p95 0.250 N" in text
    assert "3 measured, 2 lost" in text and "bridge CPU         12.5 % of one CPU" in text
    uml = format_velocity_report(report(errors, [1.0], where="in User-Mode Linux"))
    assert "User-Mode Linux" in uml


def test_the_goals_are_tracking_p95_at_most_5_percent_and_p99_below_5_ms() -> None:
    def met(errors, latencies) -> list[bool]:
        return [v.met for v in judge(GOALS, figures(report(errors, latencies)))]

    assert met([0.01] * 95 + [0.05] * 5, [1.0] * 100) == [True, True]
    assert met([0.01] * 90 + [0.2] * 10, [1.0] * 100) == [False, True]
    assert met([0.01] * 100, [1.0] * 90 + [6.0] * 10) == [True, False]
    assert met([], []) == [False, False]  # nothing measured meets no goal


def test_the_rigs_velocity_robot_toml_is_a_bridge_config(tmp_path) -> None:
    settings = VelocityBenchSettings()
    path = tmp_path / "robot-1.toml"
    text = bridge_toml(
        "tcp/127.0.0.1:7447",
        "bench",
        "vcan8",
        0.01,
        100,
        profile="velocity",
        admittance=settings.admittance,
    )
    path.write_text(text, "utf-8")
    config = load_bridge_config(path)
    assert config.can.profile == "velocity" and config.can.admittance == settings.admittance


# ------------------------------------------------------------------------------ the command
@pytest.mark.parametrize("p95, status", [(0.04, 0), (0.2, 1)])
def test_bench_can_velocity_exits_with_its_goals_verdict(monkeypatch, capsys, p95, status):
    """A fake run (no bus): the options reach the settings; exit 1 when tracking misses."""
    asked = []

    def run(settings: VelocityBenchSettings) -> VelocityBenchReport:
        asked.append(settings)
        return report([0.01] * 90 + [p95] * 10, [1.0] * 50)

    from bridge.bench import can

    monkeypatch.setattr(can, "vcan_problem", lambda channel: None)
    monkeypatch.setattr(benchmark, "run_velocity_benchmark", run)
    argv = ["bench", "can", "--profile", "velocity", "--stiffness", "1000", "--seconds", "3"]
    assert main(argv) == status
    assert asked == [VelocityBenchSettings(seconds=3.0, stiffness=1000.0)]
    out = capsys.readouterr().out
    assert out.startswith("heft bench can --profile velocity: one AGV bridge on vcan8")
    assert ("goals: met" if status == 0 else "goals: NOT met") in out


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--profile", "velocity", "--stiffness", "999"], "--stiffness: expected a number in"),
        (["--profile", "velocity", "--stiffness", "20000"], "--stiffness"),
        (["--stiffness", "3000"], "--stiffness: only with --profile velocity"),
    ],
)
def test_bench_can_velocity_refuses_bad_options_in_one_line(argv, message, capsys) -> None:
    assert main(["bench", "can", *argv]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err, err
