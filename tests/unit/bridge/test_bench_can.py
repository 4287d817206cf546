"""``heft bench can``: its pure parts (the rate search, ticks carried in frame values, the
report, its goal) and its command line. The short benchmark of a real bridge on vcan is in
tests/hil/test_bench_can_on_vcan.py."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from agent.platform.goals import judge
from agent.platform.heft import main
from agent.platform.protocol import Command, Measurement
from agent.platform.statistics import percentile
from bridge.bench import can as benchmark
from bridge.bench.can import (
    FORCE_STEP,
    GOALS,
    TICK_BASE,
    VELOCITY_STEP,
    CanBenchReport,
    CanBenchSettings,
    RateSearch,
    RateStep,
    RoundTrips,
    figures,
    format_can_report,
    tick_of,
    tick_values,
    vcan_problem,
    where_measured,
)
from bridge.codec import AgvCodec, AppliedForce, ForceCommand, Odometry
from bridge.config import load_bridge_config
from bridge.devtools.echo_agent import echo
from bridge.devtools.rig import bridge_toml, cpu_seconds


# ------------------------------------------------------------------------------ the rate search
def tried(search: RateSearch, capacity: float) -> list[float]:
    """The rates ``search`` tries against a bridge that is clean up to ``capacity``."""
    rates = []
    while (rate := search.next()) is not None:
        rates.append(rate)
        search.record(rate, rate <= capacity)
    return rates


def test_the_rate_search_doubles_then_bisects() -> None:
    search = RateSearch(start=50, limit=12_800, refine=2)
    assert tried(search, capacity=300) == [50, 100, 200, 400, 300, 350]
    assert (search.best, search.worst) == (300, 350)


def test_the_rate_search_halves_when_the_first_rate_is_lossy() -> None:
    search = RateSearch(start=50, refine=2)
    assert tried(search, capacity=20) == [50, 25, 12.5]
    assert search.best == 12.5 and search.worst == 25


def test_the_rate_search_stops_at_its_limit_or_when_told() -> None:
    search = RateSearch(start=50, limit=400)
    assert tried(search, capacity=1e9) == [50, 100, 200, 400]
    assert search.best == 400 and search.worst is None
    search = RateSearch(start=50)
    search.record(50, True)
    search.stop()
    assert search.next() is None
    with pytest.raises(ValueError):
        RateSearch(start=0)


# ------------------------------------------------------------------------------ ticks in frames
@pytest.mark.parametrize("tick", [0, 1, 9_999, 10_000, 123_456, 12_345_678, TICK_BASE**2 - 1])
def test_a_tick_survives_the_bus_and_the_echo_agent(tick: int) -> None:
    """The driver's values carry the tick; the echo agent's command carries it back in the
    ForceCommand, as the bridge encodes it."""
    codec = AgvCodec()
    sent = codec.encode(Odometry(1, tick % 16, tick_values(tick, VELOCITY_STEP)))
    assert tick_of(codec.decode(sent).velocity, VELOCITY_STEP) == tick
    applied = codec.decode(codec.encode(AppliedForce(1, tick % 16, tick_values(tick, FORCE_STEP))))
    assert tick_of(applied.force, FORCE_STEP) == tick
    command = echo(Measurement(1, tick, tick * 0.01, (0.0, 0.0), applied.force))
    assert command == Command(1, tick, applied.force)
    back = codec.decode(codec.encode(ForceCommand(1, tick % 16, command.force)))
    assert tick_of(back.force, FORCE_STEP) == tick


def test_tick_values_refuse_a_tick_they_cannot_carry() -> None:
    with pytest.raises(ValueError):
        tick_values(TICK_BASE**2, FORCE_STEP)
    with pytest.raises(ValueError):
        tick_values(-1, FORCE_STEP)


# ------------------------------------------------------------------------------ where, vcan, rig
def test_where_the_figures_were_measured() -> None:
    uml = "processor\t: 0\nvendor_id\t: User Mode Linux\nmodel name\t: UML\n"
    assert where_measured(uml) == "in User-Mode Linux"
    assert where_measured("vendor_id\t: GenuineIntel\n") == "natively"
    assert where_measured() in ("natively", "in User-Mode Linux")


def test_vcan_problem_names_what_is_missing(tmp_path: Path, monkeypatch) -> None:
    import bridge.devtools.vcan

    monkeypatch.setattr(bridge.devtools.vcan, "socketcan_available", lambda: False)
    assert vcan_problem("vcan8", tmp_path) == "this kernel has no SocketCAN"
    monkeypatch.setattr(bridge.devtools.vcan, "socketcan_available", lambda: True)
    assert vcan_problem("vcan8", tmp_path) == "there is no interface vcan8"
    (tmp_path / "vcan8").mkdir()
    assert vcan_problem("vcan8", tmp_path) is None


def test_the_rigs_robot_toml_is_a_bridge_config(tmp_path: Path) -> None:
    path = tmp_path / "robot-1.toml"
    path.write_text(bridge_toml("tcp/127.0.0.1:7447", "bench", "vcan8", 0.02, 100), "utf-8")
    config = load_bridge_config(path)
    assert (config.robot.robot, config.robot.team, config.robot.period_s) == (1, "bench", 0.02)
    assert (config.can.channel, config.node, config.can.time_source) == ("vcan8", 1, "sync")
    assert config.zenoh.connect == ("tcp/127.0.0.1:7447",)


def test_cpu_seconds_of_a_process() -> None:
    assert cpu_seconds(os.getpid()) >= 0
    assert cpu_seconds(2**22 + 1) is None  # above the kernel's pid limit


# ------------------------------------------------------------------------------ the report
def step(asked: float, **changes) -> RateStep:
    fields = dict(
        asked=asked,
        ticks=int(asked),
        frames_sent=int(asked) * 3 + 10,
        send_failures=0,
        seconds=1.0,
        frames_read=int(asked) * 3 + 10,
        missed_ticks=0,
        answered=int(asked),
        bridge_cpu_percent=12.5,
        latencies_ms=[1.0, 2.0],
    )
    return RateStep(**{**fields, **changes})


def test_a_step_is_clean_only_without_any_loss() -> None:
    assert step(100).clean and step(100).dropped == 0
    assert not step(100, frames_read=300).clean and step(100, frames_read=300).dropped == 10
    assert not step(100, missed_ticks=1).clean
    assert not step(100, answered=99).clean and step(100, answered=99).unanswered == 1
    assert not step(100, send_failures=1, frames_read=309).clean
    assert step(100, seconds=2.0).sender_limited and not step(100).sender_limited


def test_the_report_gives_the_figures_and_where(tmp_path: Path) -> None:
    trips = RoundTrips(
        latencies_ms=[0.5, 0.6, 0.7, 4.0],
        sent=5,
        lost=1,
        unmatched=0,
        seconds=10.0,
        cpu_percent={"bridge": 7.25, "router": 3.0, "echo agent": 2.0, "driver": 4.0},
    )
    report = CanBenchReport(
        CanBenchSettings(), "in User-Mode Linux", trips, [step(50), step(100, answered=90)], False
    )
    text = format_can_report(report)
    assert "measured in User-Mode Linux" in text
    assert "4 measured, 1 lost" in text
    assert f"p50                {percentile(trips.latencies_ms, 50):.3f} ms" in text
    assert f"p99                {percentile(trips.latencies_ms, 99):.3f} ms" in text
    assert [v.met for v in judge(GOALS, figures(report))] == [True]  # p99 3.9 ms
    assert "bridge CPU         7.2 % of one CPU" in text
    assert "fastest without loss: 50 ticks/s = 160 frames/s read + 50 frames/s written" in text
    assert report.fastest_clean is report.steps[0]
    native = CanBenchReport(CanBenchSettings(), "natively", trips, [step(50, answered=1)], False)
    text = format_can_report(native)
    assert "measured natively" in text and "User-Mode Linux" not in text
    assert "no step without loss, down to 50 ticks/s" in text


def test_the_goal_is_the_round_trips_p99_below_5_ms() -> None:
    def verdict(latencies: list[float]) -> bool:
        trips = RoundTrips(latencies, len(latencies), 0, 0, 1.0)
        report = CanBenchReport(CanBenchSettings(), "natively", trips, [], False)
        return judge(GOALS, figures(report))[0].met

    assert verdict([1.0] * 99 + [4.99]) and not verdict([1.0] * 98 + [5.0, 5.0])
    assert not verdict([])  # nothing measured meets no goal


# ------------------------------------------------------------------------------ the command
@pytest.mark.parametrize("slowest, status", [(4.0, 0), (9.0, 1)])
def test_bench_can_exits_with_its_goals_verdict(monkeypatch, capsys, slowest, status) -> None:
    """A fake run of the benchmark (no bus): exit 1 when the p99 misses its goal."""
    asked = []

    def run(settings: CanBenchSettings) -> CanBenchReport:
        asked.append(settings)
        trips = RoundTrips([1.0] * 50 + [slowest] * 2, 52, 0, 0, settings.seconds)
        return CanBenchReport(settings, "natively", trips, [step(50)], False)

    monkeypatch.setattr(benchmark, "vcan_problem", lambda channel: None)
    monkeypatch.setattr(benchmark, "run_can_benchmark", run)
    argv = ["bench", "can", "--channel", "vcan3", "--seconds", "2", "--period-ms", "20"]
    assert main(argv) == status
    assert asked == [CanBenchSettings(channel="vcan3", seconds=2.0, period_s=0.02)]
    out = capsys.readouterr().out
    assert out.startswith("heft bench can: one AGV bridge on vcan3")
    verdict = "met" if status == 0 else "NOT met"
    assert f"(below 5 ms): {verdict}\ngoals: {verdict}\n" in out


def test_bench_can_without_vcan_says_where_to_run_it(capsys) -> None:
    """No interface vcan99 exists here nor in ``heft vcan`` (vcan0..vcan8): one line."""
    assert main(["bench", "can", "--channel", "vcan99", "--seconds", "2"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("heft: error: bench can needs")
    assert "heft vcan -- heft bench can" in err


@pytest.mark.parametrize(
    "argv, message",
    [
        (["bench", "can", "--period-ms", "0.5"], "--period-ms"),
        (["bench", "can", "--seconds", "nan"], "--seconds"),
        (["bench", "can", "--channel", "a b"], "--channel"),
    ],
)
def test_bench_can_refuses_bad_options_in_one_line(argv, message, capsys) -> None:
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err, err
