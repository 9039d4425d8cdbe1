"""Session guards: a run stuck inside a C library ends, with every thread's stack printed.

pytest-timeout (`timeout` in pyproject.toml) fails a test from a signal handler, which runs only
between Python bytecodes; a test stuck inside a C library (MAVSDK joins its threads in C) never
gets there, and the run would sit until CI's limit with nothing printed. `HANG_GRACE_S` past a
test's own timeout, faulthandler writes every thread's stack to the session's stderr and exits.
After the last test, the process has `EXIT_GRACE_S` to exit (its threads joined, MAVSDK's atexit
destroy run); past that the stacks are printed and it exits with the session's status.
"""

from __future__ import annotations

import faulthandler
import os
import threading
import time
from collections.abc import Iterator

import pytest

HANG_GRACE_S = 300.0
"""Past its timeout, only a test that pytest-timeout's signal could not stop still runs, s."""

EXIT_GRACE_S = 60.0
"""Time from the session's end to the process' exit before the exit guard ends it, s."""

_stderr_fd: list[int] = []


def pytest_configure(config: pytest.Config) -> None:
    # the terminal's stderr, kept before tests capture fd 2
    _stderr_fd.append(os.dup(2))


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None) -> Iterator[None]:
    marker = item.get_closest_marker("timeout")
    timeout_s = float(marker.args[0] if marker else item.config.getini("timeout") or 0)
    if timeout_s > 0:
        faulthandler.dump_traceback_later(timeout_s + HANG_GRACE_S, exit=True, file=_stderr_fd[0])
    try:
        yield
    finally:
        faulthandler.cancel_dump_traceback_later()


@pytest.hookimpl(trylast=True)
def pytest_sessionfinish(session: pytest.Session, exitstatus: int) -> None:
    def exit_guard() -> None:
        time.sleep(EXIT_GRACE_S)
        fd = _stderr_fd[0]
        os.write(
            fd, f"\nprocess still alive {EXIT_GRACE_S:.0f} s after the session; stacks:\n".encode()
        )
        faulthandler.dump_traceback(file=fd, all_threads=True)
        os._exit(int(exitstatus))

    threading.Thread(target=exit_guard, name="exit-guard", daemon=True).start()
