"""Fixtures that tests of more than one level share (the helpers they share are in
tests/helpers; a fixture of one level only is in that level's conftest.py)."""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.fixture(scope="module")
def certs(tmp_path_factory) -> Path:
    """The team's certificates (four robots), valid for 127.0.0.1."""
    from agent.security.certificates import make_certificates, team_identities

    folder = tmp_path_factory.mktemp("pki") / "tls"
    make_certificates(folder, team_identities(4), hosts=["127.0.0.1"])
    return folder
