"""Fixtures of the plain python suite: every tool a test needs must be there (no skips)."""

from __future__ import annotations

import pytest

import ddct_testlib as lib


@pytest.fixture(scope="session")
def ddct():
    return lib.ddct_bin()


@pytest.fixture(scope="session")
def db():
    return lib.ddct_can.load_dbc()
