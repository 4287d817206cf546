"""The AGV bridge's configuration: the robot's ``robot.toml`` with a ``[can]`` table.

A robot computer runs its agent and its bridge from the same file, so the two cannot disagree
on who the robot is, its team, its sensor period or where the Zenoh network is. The agent
ignores ``[can]``; the bridge reads the rest as the agent does
(:func:`agent.node.load_agent_config`'s checks) plus::

    [can]
    interface = "socketcan"    # python-can interface: socketcan on robots, virtual in tests
    channel = "can0"           # the AGV's bus
    bitrate = 1000000          # bit/s (set on the interface by the system, see deploy/)
    node = 1                   # the AGV's node id in the CAN ids (default: the robot's id)
    watchdog_ms = 100          # no valid command for this long: zero force
    watchdog_clock = "wall"    # what the watchdog's time is ("bus": ticks, lockstep sims only)
    time_source = "sync"       # ticks from the bus's Sync frames ("clock": this host's clock)
    realtime_priority = 0      # 1..99: run under SCHED_FIFO at this priority (0: do not)
    profile = "force"          # the AGV's protocol: "force" (agv.dbc) or "velocity"

    [can.admittance]           # the velocity profile's admittance loop (bridge/admittance.py)
    mass = 10.0                # kg, the virtual mass M
    damping = 0.0              # N s/m, the virtual damper D
    integral_time_s = 0.05     # s, the base's speed-loop time constant (0: no integral)
    deadzone_n = 0.1           # N
    max_speed = 1.5            # m/s
    max_accel = 2.0            # m/s²
    tare_samples = 20          # F/T samples averaged into the sensor's bias at start-up

With ``profile = "force"`` the driver takes force commands (``ForceCommand``) and reports the
force it applied; with ``"velocity"`` the base takes velocity commands (``MotionCommand``), a
force/torque sensor at the contact reports the force, and the bridge closes the admittance
loop between them (:mod:`bridge.bridge`). ``[can.admittance]`` is read with either profile and
used with the velocity one only.

The bridge is a Zenoh client of the ``[zenoh]`` table's ``connect`` endpoints (the robot's
router) and never listens itself: on a robot the agent's own listen endpoints stay the agent's.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

from agent.node import AgentNodeConfig
from agent.platform.config import (
    ConfigError,
    bounded,
    check_bounds,
    from_table,
    read_toml,
    toml_fields,
    toml_tables,
)
from agent.platform.zenoh_session import ZenohSettings
from bridge.admittance import AdmittanceSettings
from bridge.dbc import MAX_NODE, PROFILES

TIME_SOURCES = ("sync", "clock")
"""How the bridge gives each sample its tick (see :mod:`bridge.timing`)."""
WATCHDOG_CLOCKS = ("wall", "bus")
"""What the bridge's watchdog times silences with (:attr:`CanSettings.watchdog_clock`)."""


@dataclass(frozen=True)
class CanSettings:
    """The ``[can]`` table (see the module docstring)."""

    interface: str = "socketcan"
    """python-can interface name: ``socketcan`` on robots and in the HIL tests, ``virtual``
    within one process."""
    channel: str = "can0"
    """The AGV's bus: ``can0`` on a robot, ``vcan1`` ... in tests."""
    bitrate: int = bounded(1_000_000, 10_000, 1_000_000, "bit/s")
    """The bus's bit rate. SocketCAN takes it from the interface (``ip link set can0 type can
    bitrate …``, see deploy/); other interfaces are opened with it."""
    node: int = bounded(0, 0, MAX_NODE)
    """The AGV's node id in the frames' ids, 1..32; 0 (the default): the robot's id."""
    watchdog_ms: int = bounded(100, 10, 10_000, "ms")
    """No valid command from the agent for this long: the bridge commands zero force."""
    watchdog_clock: str = "wall"
    """What ``watchdog_ms`` (and the stale-sensor stop) is timed with. ``wall`` (the default,
    and the only choice on a robot): this host's monotonic clock. ``bus``: the ticks the bus's
    ``Sync`` frames open, ``T`` seconds each, for a lockstep simulation, where the bus master
    opens no tick before it has every robot's command for the last one, so a silence is timed
    by the ticks that went by without a command, not by how slowly the machine runs them
    (``heft run --can`` in lockstep writes it). A bus whose master stops opens no tick, so
    this clock stops too: never on a robot. Needs ``time_source = "sync"``."""
    time_source: str = "sync"
    """``sync``: a sample's tick is the one the bus's last ``Sync`` frame opened (CANopen
    SYNC); ``clock``: the tick this host's clock (synchronised by chrony or PTP) is in."""

    realtime_priority: int = bounded(0, 0, 99)
    """1 to 99: the bridge runs under the kernel's real-time scheduler (``SCHED_FIFO``) at
    this priority, so that its watchdog and its frames keep their timing on a loaded
    computer; it needs the right (root, ``CAP_SYS_NICE``, or systemd's
    ``CPUSchedulingPolicy=fifo`` instead). 0 (the default): the normal scheduler."""
    profile: str = "force"
    """The AGV protocol's profile (:data:`bridge.dbc.PROFILES`): ``force``, a driver that
    takes force commands; ``velocity``, a base that takes velocity commands with a
    force/torque sensor at its contact."""
    admittance: AdmittanceSettings = AdmittanceSettings()
    """``[can.admittance]``: the velocity profile's admittance loop."""

    def validate(self, where: str) -> None:
        if not self.interface.isidentifier():
            raise ConfigError(
                f"{where}.interface: expected a python-can interface name like socketcan or"
                f" virtual, got {self.interface!r}"
            )
        if not self.channel or not self.channel.isprintable() or " " in self.channel:
            raise ConfigError(
                f"{where}.channel: expected a channel name like can0, got {self.channel!r}"
            )
        if self.time_source not in TIME_SOURCES:
            raise ConfigError(
                f"{where}.time_source: expected sync or clock, got {self.time_source!r}"
            )
        if self.watchdog_clock not in WATCHDOG_CLOCKS:
            raise ConfigError(
                f"{where}.watchdog_clock: expected wall or bus, got {self.watchdog_clock!r}"
            )
        if self.watchdog_clock == "bus" and self.time_source != "sync":
            raise ConfigError(
                f'{where}.watchdog_clock: bus needs the bus\'s Sync frames (time_source = "sync"),'
                f" got time_source = {self.time_source!r}"
            )
        if self.profile not in PROFILES:
            raise ConfigError(
                f"{where}.profile: expected {' or '.join(PROFILES)}, got {self.profile!r}"
            )
        check_bounds(self, where)


@dataclass(frozen=True)
class BridgeConfig:
    """What ``heft bridge`` runs with: the robot's agent config and its ``[can]`` table."""

    robot: AgentNodeConfig
    can: CanSettings

    @property
    def node(self) -> int:
        """The AGV's node id on the bus."""
        return self.can.node or self.robot.robot

    @property
    def zenoh(self) -> ZenohSettings:
        """The bridge's Zenoh session: a client of the robot's router (see the module
        docstring)."""
        return dataclasses.replace(self.robot.zenoh, mode="client", listen=())


def can_table(can: CanSettings) -> str:
    """``can`` as ``robot.toml``'s ``[can]`` table and its ``[can.admittance]``, every key
    written (what :func:`load_bridge_config` reads back as ``can``)."""
    return "\n".join(["", "[can]", *toml_fields(can), *toml_tables(can, "can.")]) + "\n"


def load_bridge_config(path: str | Path) -> BridgeConfig:
    """Read ``robot.toml`` for the bridge; :class:`ConfigError` (one line naming the key) if
    it is bad or has no ``[can]`` table."""
    data = read_toml(path)
    table = data.pop("can", None)
    try:
        if table is None:
            raise ConfigError("can: missing (the bridge needs a [can] table: interface, channel)")
        can = from_table(CanSettings, table, "can")
        robot = from_table(AgentNodeConfig, data, "agent")
        config = BridgeConfig(robot, can)
        if config.zenoh.mode == "client" and not config.zenoh.connect:
            raise ConfigError("zenoh.connect: the bridge needs the robot's router endpoint")
        return config
    except ConfigError as err:
        raise ConfigError(f"{path}: {err}") from None
