"""The team's TLS files as the deployed configs and the Zenoh settings name them."""

from __future__ import annotations

import tomllib
from pathlib import Path

TLS_DIR = "/etc/heft/tls"
"""Where the deployed configs (deploy/paper) name the team's certificates."""


def loadable_copy(path: Path, folder: Path) -> Path:
    """``path`` with its TLS files moved to placeholders in ``folder`` (they exist on the
    robots only; the agent checks only that they are readable when it loads the file)."""
    tls = folder / "tls"
    tls.mkdir(exist_ok=True)
    from agent.platform.zenoh_session import TLS_FILES

    text = path.read_text(encoding="utf-8")
    for key in TLS_FILES:
        name = Path(tomllib.loads(text)["zenoh"][key]).name
        (tls / name).write_text("placeholder\n", encoding="utf-8")
    copy = folder / path.name
    copy.write_text(text.replace(f'"{TLS_DIR}/', f'"{tls}/'), encoding="utf-8")
    return copy


def tls_files(folder: Path, identity: str) -> dict[str, str]:
    """The Zenoh settings' TLS files of ``identity`` among the certificates in ``folder``."""
    return {
        "root_ca": str(folder / "ca.pem"),
        "certificate": str(folder / f"{identity}.pem"),
        "private_key": str(folder / f"{identity}-key.pem"),
    }
