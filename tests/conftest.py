"""Session guard: a test hung where pytest-timeout cannot reach ends the run, with its stacks.

pytest-timeout (`timeout` in pyproject.toml) fails a test from a signal handler, which runs only
between Python bytecodes; a test stuck inside a C library (MAVSDK joins its threads in C) never
gets there, and the run would sit until CI's limit with nothing printed. `HANG_GRACE_S` past a
test's own timeout, faulthandler writes every thread's stack to the session's stderr and exits.
"""

from __future__ import annotations

import faulthandler
import os
from collections.abc import Iterator

import pytest

HANG_GRACE_S = 300.0
"""Past its timeout, only a test that pytest-timeout's signal could not stop still runs, s."""

_stderr_fd: list[int] = []


def pytest_configure(config: pytest.Config) -> None:
    # the terminal's stderr, kept before tests capture fd 2
    _stderr_fd.append(os.dup(2))


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None) -> Iterator[None]:
    marker = item.get_closest_marker("timeout")
    timeout_s = float(marker.args[0]) if marker else float(item.config.getini("timeout"))
    faulthandler.dump_traceback_later(timeout_s + HANG_GRACE_S, exit=True, file=_stderr_fd[0])
    try:
        yield
    finally:
        faulthandler.cancel_dump_traceback_later()
