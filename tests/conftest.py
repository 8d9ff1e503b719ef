"""Shared test helpers: the public sample scenes (mrstereo.recordings.samples) and how tests skip without them.

Tests that need a real scene either take the ``sample_data`` fixture (``sample_data("tsukuba")``
returns its folder) or carry ``@pytest.mark.sample_data("tsukuba", ...)`` and build paths with
:func:`mrstereo.recordings.samples.local_path`. Without the files they skip with a reason that names the
environment variable and the fetch command; nothing is downloaded during a test run. CI
(``.ci/run``) points ``MRSTEREO_DATA`` at a local copy.
"""
from __future__ import annotations

import pytest

from mrstereo.recordings import samples as data


def skip_reason(name: str) -> str | None:
    """Why the scene ``name`` cannot be used (None when all its files are present)."""
    missing = data.missing_files(name)
    if not missing:
        return None
    return (f"sample data {name!r} not found ({missing[0]} is missing): set {data.ENV_VAR} to a local copy "
            f"or run `mrstereo data fetch {name}`")


def pytest_configure(config):
    config.addinivalue_line("markers", "sample_data(*names): the test needs these mrstereo.recordings.samples scenes; "
                                       "skipped with the fetch command when they are missing")


def pytest_runtest_setup(item):
    for marker in item.iter_markers("sample_data"):
        for name in marker.args:
            reason = skip_reason(name)
            if reason:
                pytest.skip(reason)


@pytest.fixture
def sample_data():
    """``sample_data(name) -> Path`` of a complete local scene; skips the test otherwise."""
    def get(name: str):
        reason = skip_reason(name)
        if reason:
            pytest.skip(reason)
        return data.local_path(name)
    return get
