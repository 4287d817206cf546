"""``heft vcan`` (bridge/devtools/vcan.py, bridge/devtools/vcan_run.py): the pure parts (sizes, the
guest's environment and init script, the filters of its output and console). Its real runs are
in tests/integration/test_vcan_runner.py."""

from __future__ import annotations

import os
import shlex

import pytest

from bridge.devtools.vcan import (
    MAX_COUNT,
    MIN_MEMORY,
    SYSTEM_PATH,
    ConsoleScanner,
    EndFilter,
    check_count,
    exit_status,
    guest_environment,
    init_script,
    interface_names,
    memory_option,
    parse_memory,
)

NONCE = "0123456789abcdef"
HOSTILE = "a'b; rm -rf /"


# ------------------------------------------------------------------------------ sizes, names
@pytest.mark.parametrize(
    ("text", "size"),
    [
        ("512M", 512 << 20),
        ("2G", 2 << 30),
        ("2g", 2 << 30),
        (" 1G ", 1 << 30),
        ("1048576K", 1 << 30),
        ("134217728", MIN_MEMORY),
        ("128M", MIN_MEMORY),
    ],
)
def test_parse_memory_reads_sizes(text: str, size: int) -> None:
    assert parse_memory(text) == size


@pytest.mark.parametrize("text", ["", "G", "12X", "1.5G", "-1G", "2 G", "2GB", "0", "127M", "64K"])
def test_parse_memory_refuses_other_text_in_one_line(text: str) -> None:
    with pytest.raises(ValueError, match=r"^--memory: ") as caught:
        parse_memory(text)
    assert "\n" not in str(caught.value)


def test_memory_option_is_mebibytes_rounded_up() -> None:
    assert memory_option(2 << 30) == "2048M"
    assert memory_option((128 << 20) + 1) == "129M"


def test_check_count_allows_1_to_max() -> None:
    assert check_count(1) == 1
    assert check_count(MAX_COUNT) == MAX_COUNT
    for bad in (0, -1, MAX_COUNT + 1):
        with pytest.raises(ValueError, match=r"^--count: "):
            check_count(bad)


def test_interface_names() -> None:
    assert interface_names(3) == ["vcan0", "vcan1", "vcan2"]
    assert interface_names(9)[-1] == "vcan8"


# ------------------------------------------------------------------------------ the guest
def test_guest_environment_puts_the_venv_first_and_marks_the_guest() -> None:
    environ = {
        "PATH": "/usr/bin:/venv/bin:/opt/tool/bin",
        "HOME": "/home/me",
        "HEFT_VCAN": "0",
        "KEEP": "yes",
    }
    env = guest_environment(environ, venv="/venv", extra={"KEEP": "replaced"})
    path = env["PATH"].split(os.pathsep)
    assert path[0] == "/venv/bin"
    assert path.count("/venv/bin") == 1
    assert path[1:3] == ["/usr/bin", "/opt/tool/bin"]
    assert set(SYSTEM_PATH.split(":")) <= set(path)
    assert env["VIRTUAL_ENV"] == "/venv"
    assert env["HEFT_VCAN"] == "1"
    assert env["HOME"] == "/home/me"
    assert env["PYTHONUNBUFFERED"] == "1"
    assert env["KEEP"] == "replaced"
    assert environ["HEFT_VCAN"] == "0"  # the caller's mapping is left alone


def test_guest_environment_without_a_venv_keeps_the_callers_choices() -> None:
    env = guest_environment({"PYTHONUNBUFFERED": "", "BAD=KEY": "x", "NUL": "a\0b"})
    assert "VIRTUAL_ENV" not in env
    assert env["PYTHONUNBUFFERED"] == ""
    assert "BAD=KEY" not in env and "NUL" not in env
    assert env["PATH"] == SYSTEM_PATH
    assert env["HOME"] == "/root"
    assert env["HEFT_VCAN"] == "1"


def _words(script: str, start: str, end: str) -> list[str]:
    """The shell words of ``script`` from ``start`` up to (not including) ``end``."""
    at = script.index(start)
    return shlex.split(script[at : script.index(end, at)].replace("\\\n", " "))


def test_init_script_quotes_every_caller_given_word() -> None:
    command = ["printf", "%s\n", HOSTILE, "$(reboot)", "`halt`", "x\ny", ""]
    cwd = "/tmp/it's here; rm -rf /"
    environ = {"EVIL": HOSTILE, "PATH": "/venv/bin:/usr/bin", "SUB": "$(id)", "NL": "a\nb"}
    script = init_script(command, cwd, environ, 3, NONCE)

    # Round trip: the shell reads back exactly the words given, each as one word.
    words = _words(script, "env -i", "</dev/null")
    assert words[:3] == ["env", "-i", "--"]
    at = words.index("/bin/sh")
    assert words[3:at] == [f"{k}={v}" for k, v in sorted(environ.items())]
    assert words[at:] == ["/bin/sh", "-c", 'exec "$0" "$@"', *command]
    assert _words(script, "cd ", "||") == ["cd", cwd]

    # Nowhere in the script does the hostile text become words of its own: only quoted.
    tokens = shlex.split(script.replace("\\\n", " "), comments=True)
    assert not {"rm", "-rf", "/", "reboot", "halt`"} & set(tokens)
    assert tokens.count(f"EVIL={HOSTILE}") == 1
    assert "vcan0..vcan2" in script and "-lt 3 ]" in script


def test_init_script_refuses_a_bad_nonce_or_no_command() -> None:
    for nonce in ("", "abc", "0123456789ABCDEF", "0123456g", "01234567; reboot", "01234567\n"):
        with pytest.raises(ValueError, match="nonce"):
            init_script(["true"], "/", {}, 1, nonce)
    with pytest.raises(ValueError, match="no command"):
        init_script([], "/", {}, 1, NONCE)


# ------------------------------------------------------------------------- reading the guest
TOKEN = f"heft-vcan {NONCE} end".encode()


def test_end_filter_finds_the_token_split_across_feeds() -> None:
    end = EndFilter(NONCE)
    shown = end.feed(b"hello\n" + TOKEN[:5])
    assert shown == b"hello\n"
    shown += end.feed(TOKEN[5:12])
    shown += end.feed(TOKEN[12:] + b"after the token")
    assert end.ended
    assert shown == b"hello\n"
    assert end.feed(b"more") == b""
    assert end.close() == b""


def test_end_filter_byte_by_byte() -> None:
    end = EndFilter(NONCE)
    data = b"line one\nheft-vcan other\n" + TOKEN + b"junk"
    shown = b"".join(end.feed(data[i : i + 1]) for i in range(len(data)))
    assert shown == b"line one\nheft-vcan other\n"
    assert end.ended


def test_end_filter_passes_a_false_start_and_returns_the_tail_at_close() -> None:
    end = EndFilter(NONCE)
    assert end.feed(b"x heft-v") == b"x "
    assert end.feed(b"ideo heft-vcan ") == b"heft-video "
    assert end.close() == b"heft-vcan "
    assert not end.ended


def test_end_filter_ignores_another_nonces_token() -> None:
    end = EndFilter(NONCE)
    other = b"heft-vcan fedcba9876543210 end"
    assert end.feed(other) + end.close() == other
    assert not end.ended


def test_console_scanner_reads_start_and_exit_split_across_feeds() -> None:
    console = ConsoleScanner(NONCE, keep=3)
    console.feed(b"Linux version 6.1\r\ncan: controller area network core\n")
    console.feed(f"heft-vcan {NONCE} start\n".encode())
    console.feed(b"heft-vcan fedcba9876543210 exit 9\n")  # another guest's: ignored
    console.feed(b"heft-vcan fedcba9876543210 error no\n")
    console.feed(f"heft-vcan {NONCE} ex".encode())
    console.feed(b"it 3\r\nreboot: System halted")
    report = console.report()
    assert report.started
    assert report.status == 3
    assert report.error is None
    assert len(report.tail) == 3
    assert report.tail[-1] == "reboot: System halted"
    assert all(NONCE not in line for line in report.tail)


def test_console_scanner_reads_an_error_and_a_last_line_without_newline() -> None:
    console = ConsoleScanner(NONCE)
    console.feed(f"heft-vcan {NONCE} exit abc\n".encode())  # not a status
    console.feed(f"heft-vcan {NONCE} error cannot load the CAN modules (can)".encode())
    report = console.report()
    assert not report.started
    assert report.status is None
    assert report.error == "cannot load the CAN modules (can)"


def test_exit_status_is_the_shells() -> None:
    assert exit_status(0) == 0
    assert exit_status(3) == 3
    assert exit_status(-9) == 137
    assert exit_status(-15) == 143
