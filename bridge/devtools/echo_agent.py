"""A stand-in agent for measuring a bridge: ``python -m bridge.devtools.echo_agent --connect
ENDPOINT
--team TEAM --robot N``.

It answers every :class:`~agent.platform.protocol.Measurement` of robot ``N`` at once with the
:class:`~agent.platform.protocol.Command` for the same tick whose force is the force the measurement
reports (an echo): the ``ForceCommand`` frame that comes back on the bus then names the tick
it answers, whatever its 4-bit counter says. It does no estimation, so what a round trip
through it costs is the bridge's and Zenoh's, not an estimator's.

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


def echo(measurement: Measurement) -> Command:
    """The command answering ``measurement``: its tick, the force it reports."""
    return Command(measurement.robot, measurement.tick, measurement.force)


def run_echo_agent(settings: ZenohSettings, team: str, robot: int) -> int:
    """Answer robot ``robot``'s measurements until a stop signal; 0."""
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
                publisher.put(encode(echo(measurement)))

        subscriber = session.declare_subscriber(keys.velocity(robot), answer)
        print(READY, flush=True)
        stop.wait()
        subscriber.undeclare()
        publisher.undeclare()
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m bridge.devtools.echo_agent",
        description="Answer every measurement of one robot with a command echoing its force.",
    )
    parser.add_argument("--connect", required=True, help="the router, e.g. tcp/127.0.0.1:7447")
    parser.add_argument("--team", required=True)
    parser.add_argument("--robot", type=int, default=1)
    args = parser.parse_args(argv)
    settings = ZenohSettings(mode="client", connect=(args.connect,))
    try:
        settings.validate("--connect")
        Keys(args.team).velocity(args.robot)
    except ValueError as err:  # ConfigError is one
        print(f"echo agent: error: {err}", file=sys.stderr)
        return 2
    try:
        return run_echo_agent(settings, args.team, args.robot)
    except SessionError as err:
        print(f"echo agent: error: {err}", file=sys.stderr)
        return 4


if __name__ == "__main__":
    raise SystemExit(main())
