"""Fixtures the unit tests of more than one package share."""

from __future__ import annotations

import argparse

import pytest

from agent.platform.heft import build_parser


@pytest.fixture(scope="module")
def heft() -> argparse.ArgumentParser:
    """The ``heft`` command's parser, every package's subcommands registered."""
    return build_parser()
