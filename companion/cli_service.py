"""`wireavoid run`: the companion service as systemd starts it at boot (`systemd/`)."""

from __future__ import annotations

import contextlib
import logging
import os
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Annotated

import typer


def run(
    config: Annotated[
        Path | None,
        typer.Option("--config", help="TOML settings file", exists=True, dir_okay=False),
    ] = None,
    verbose: Annotated[
        bool, typer.Option("--verbose", "-v", help="debug logging, MAVSDK's own lines included")
    ] = False,
) -> None:
    """Run the companion service: connect to PX4, supervise the link, report to systemd.

    Retries until an autopilot is heard, then logs a status line (link, mode, armed, landed
    state, position, battery, health) and notifies systemd (READY, STATUS, WATCHDOG) when
    $NOTIFY_SOCKET is set. It does not command the vehicle. SIGTERM or Ctrl-C stops it (exit 0);
    exit 1 when the link gave up reconnecting.
    """
    import asyncio

    from companion.config import load_settings
    from companion.service import run_service

    settings = load_settings(config)
    with _log_to_stderr(verbose):
        code = asyncio.run(run_service(settings, settings.service))
    raise typer.Exit(code)


class _JournalFormatter(logging.Formatter):
    """`<priority>logger: message`: journald reads the syslog priority prefix (no timestamps)."""

    def format(self, record: logging.LogRecord) -> str:
        priority = _syslog_priority(record.levelno)
        return "\n".join(f"<{priority}>{line}" for line in super().format(record).splitlines())


def _syslog_priority(levelno: int) -> int:
    """The syslog priority of a logging level (crit 2, err 3, warning 4, info 6, debug 7)."""
    for level, priority in (
        (logging.CRITICAL, 2),
        (logging.ERROR, 3),
        (logging.WARNING, 4),
        (logging.INFO, 6),
    ):
        if levelno >= level:
            return priority
    return 7


def _stderr_is_journal() -> bool:
    """Whether stderr is connected to the journal (`$JOURNAL_STREAM` is its device:inode)."""
    try:
        device, inode = (int(x) for x in os.environ.get("JOURNAL_STREAM", "").split(":"))
        stat = os.fstat(sys.stderr.fileno())
    except (ValueError, OSError):
        return False
    return (stat.st_dev, stat.st_ino) == (device, inode)


@contextlib.contextmanager
def _log_to_stderr(verbose: bool) -> Iterator[None]:
    """Route log records to stderr while inside: journald's format under systemd."""
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(
        _JournalFormatter("%(name)s: %(message)s")
        if _stderr_is_journal()
        else logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s")
    )
    root, mavsdk = logging.getLogger(), logging.getLogger("mavsdk")
    saved = [(root, root.level), (mavsdk, mavsdk.level)]
    root.addHandler(handler)
    root.setLevel(logging.DEBUG if verbose else logging.INFO)
    mavsdk.setLevel(logging.DEBUG if verbose else logging.WARNING)
    try:
        yield
    finally:
        root.removeHandler(handler)
        for logger, level in saved:
            logger.setLevel(level)


def register(app: typer.Typer, bench: typer.Typer) -> None:
    """Add `wireavoid run`."""
    app.command("run")(run)
