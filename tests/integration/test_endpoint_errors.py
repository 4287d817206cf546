"""Where the network says no: a busy port, no router to connect to, an address not on this
machine. ``heft router``, ``heft sim``, ``heft agent`` and ``heft dashboard`` say so in one
``heft: error:`` line with exit status 4 (worth retrying), and a value in range gets as far as
the router. The refusals of values out of range, before any network, are in
tests/unit/agent/test_input_bounds.py."""

from __future__ import annotations

import contextlib
import io
import socket

import pytest

from agent.platform.children import free_port
from agent.platform.heft import main
from agent.platform.zenoh_session import SessionError, ZenohSettings, open_session
from tests.helpers.bad_input import refused, robot_file
from tests.helpers.paths import PAPER


# ------------------------------------------------------------------------------ heft dashboard
def heft(*argv: str) -> tuple[int, str]:
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        code = main(list(argv))
    return code, err.getvalue()


def test_a_busy_port_is_status_4() -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        code, err = heft("dashboard", "--replay", str(PAPER), "--port", str(port))
    assert code == 4 or "not an MCAP file" in err  # the file is checked first
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        code, err = heft("dashboard", "--team", "t", "--port", str(port))
    assert code == 4, err
    assert err.strip() == f"heft: error: listen 127.0.0.1:{port}: Address already in use"


# ------------------------------------------------------------------------------ router, sim, agent
@pytest.mark.parametrize("value", ["0.001", "3600"])
def test_a_start_timeout_in_range_is_accepted(capsys, value) -> None:
    """It gets as far as the router (none there, and no waiting for one)."""
    port = free_port()
    argv = ["sim", str(PAPER), f"--start-timeout={value}", f"--connect=tcp/127.0.0.1:{port}"]
    refused(capsys, [*argv, "--connect-timeout-ms=0"], f"connect tcp/127.0.0.1:{port}", status=4)


def test_a_busy_port_is_one_line(capsys) -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        argv = ["router", "--listen", f"tcp/127.0.0.1:{port}"]
        refused(capsys, argv, f"listen tcp/127.0.0.1:{port}: address already in use", status=4)


def test_no_router_to_connect_to_is_one_line(tmp_path, capsys) -> None:
    port = free_port()  # nothing listens there
    path = robot_file(
        tmp_path,
        {"zenoh.connect": [f"tcp/127.0.0.1:{port}"], "zenoh.connect_timeout_ms": 300},
    )
    refused(
        capsys,
        ["agent", "--config", str(path)],
        f"connect tcp/127.0.0.1:{port}: no answer within 300 ms (connect_timeout_ms)",
        status=4,
    )


def test_the_plant_without_a_router_is_one_line(capsys) -> None:
    port = free_port()
    argv = ["sim", str(PAPER), f"--connect=tcp/127.0.0.1:{port}", "--connect-timeout-ms=300"]
    refused(capsys, argv, f"connect tcp/127.0.0.1:{port}: no answer within 300 ms", status=4)


def test_open_session_says_which_endpoint_failed() -> None:
    port = free_port()
    router = ZenohSettings(mode="router", connect=(), listen=(f"tcp/127.0.0.1:{port}",))
    with open_session(router):
        with pytest.raises(SessionError, match=f"^listen tcp/127.0.0.1:{port}: address already"):
            open_session(router)


def test_an_address_not_on_this_machine_is_one_line(capsys) -> None:
    # TEST-NET-1 (RFC 5737): never assigned to this machine's interfaces
    argv = ["router", "--listen", "tcp/192.0.2.1:7447", "--allow-plain"]
    refused(capsys, argv, "listen tcp/192.0.2.1:7447", status=4)
