"""A stand-in agent for measuring a bridge: ``python -m bridge.devtools.echo_agent --connect
ENDPOINT
--team TEAM --robot N``.

It answers every :class:`~agent.platform.protocol.Measurement` of robot ``N`` at once with the
:class:`~agent.platform.protocol.Command` for the same tick whose force is the force the measurement
reports (an echo): the ``ForceCommand`` frame that comes back on the bus then names the tick
it answers, whatever its 4-bit counter says. It does no estimation, so what a round trip
through it costs is the bridge's and Zenoh's, not an estimator's.

With ``--push F`` it answers instead with the pushes of :func:`push` (F newtons), as a team
pushing a load would: what the velocity profile's bench (``heft bench can --profile velocity``)
measures the bridge's force tracking with.

It prints ``echo agent up`` once its subscriber is declared, and runs until SIGINT, SIGTERM
or SIGHUP (exit status 0; 4 if its router cannot be reached).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from agent.platform.process import StopSignals
from agent.platform.protocol import Command, DecodeError, Keys, Measurement, decode, encode
from agent.platform.zenoh_session import SessionError, ZenohSettings, open_session, tick_publisher

READY = "echo agent up"
"""The line printed on stdout once the agent answers."""
REST_S = 0.5
PUSH_S = 1.0
"""A cycle of :func:`push`: a rest, a push one way, a push back (the load stops again)."""
CYCLE_S = REST_S + 2 * PUSH_S


def echo(measurement: Measurement) -> Command:
    """The command answering ``measurement``: its tick, the force it reports."""
    return Command(measurement.robot, measurement.tick, measurement.force)


def push(time_s: float, force: float) -> tuple[float, float]:
    """The force commanded at ``time_s``: cycles of :data:`CYCLE_S` seconds, each a rest
    (zero force) of :data:`REST_S`, then ``force`` newtons for :data:`PUSH_S` and as long
    back, along x in even cycles and y in odd ones."""
    cycle, phase = divmod(time_s, CYCLE_S)
    if phase < REST_S:
        return (0.0, 0.0)
    signed = force if phase < REST_S + PUSH_S else -force
    return (signed, 0.0) if int(cycle) % 2 == 0 else (0.0, signed)


def pusher(force: float):
    """The command answering a measurement with :func:`push`."""

    def answer(measurement: Measurement) -> Command:
        return Command(measurement.robot, measurement.tick, push(measurement.time_s, force))

    return answer


def run_echo_agent(
    settings: ZenohSettings, team: str, robot: int, push_n: float | None = None
) -> int:
    """Answer robot ``robot``'s measurements until a stop signal (with :func:`echo`, or
    :func:`push` of ``push_n`` newtons); 0."""
    respond = echo if push_n is None else pusher(push_n)
    stop = StopSignals().take().event
    keys = Keys(team)
    with open_session(settings) as session:
        publisher = tick_publisher(session, keys.force(robot))

        def answer(sample) -> None:
            try:
                measurement = decode(Measurement, sample.payload.to_bytes())
            except DecodeError:
                return
            if measurement.robot == robot:
                publisher.put(encode(respond(measurement)))

        subscriber = session.declare_subscriber(keys.velocity(robot), answer)
        print(READY, flush=True)
        stop.wait()
        subscriber.undeclare()
        publisher.undeclare()
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m bridge.devtools.echo_agent",
        description="Answer every measurement of one robot with a command echoing its force"
        " (or pushing).",
    )
    parser.add_argument("--connect", required=True, help="the router, e.g. tcp/127.0.0.1:7447")
    parser.add_argument("--team", required=True)
    parser.add_argument("--robot", type=int, default=1)
    parser.add_argument("--push", type=float, metavar="NEWTONS", help="push instead of echoing")
    args = parser.parse_args(argv)
    settings = ZenohSettings(mode="client", connect=(args.connect,))
    try:
        settings.validate("--connect")
        Keys(args.team).velocity(args.robot)
    except ValueError as err:  # ConfigError is one
        print(f"echo agent: error: {err}", file=sys.stderr)
        return 2
    if args.push is not None and not 0 < args.push <= 500:
        print(f"echo agent: error: --push: expected (0, 500] N, got {args.push}", file=sys.stderr)
        return 2
    try:
        return run_echo_agent(settings, args.team, args.robot, args.push)
    except SessionError as err:
        print(f"echo agent: error: {err}", file=sys.stderr)
        return 4


if __name__ == "__main__":
    raise SystemExit(main())
