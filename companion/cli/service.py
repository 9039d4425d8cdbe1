"""`wireavoid run` (the companion service as systemd starts it at boot, `systemd/`) and
`wireavoid fly` (the same flight process in the foreground against any autopilot)."""

from __future__ import annotations

import contextlib
import logging
import os
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Annotated

import typer

from companion.cli.gcs import MqttUrlOption, VehicleIdOption

ConfigOption = Annotated[
    Path | None,
    typer.Option("--config", help="TOML settings file", exists=True, dir_okay=False),
]
VerboseOption = Annotated[
    bool, typer.Option("--verbose", "-v", help="debug logging, MAVSDK's own lines included")
]
RecordOption = Annotated[
    str | None,
    typer.Option(
        "--record",
        help="record the flight to this MCAP file (record.path; strftime fields are filled "
        "in, e.g. flight-%Y%m%d-%H%M%S.mcap); `wireavoid log info` and `replay` read it",
    ),
]


def run(
    config: ConfigOption = None,
    mqtt: MqttUrlOption = None,
    vehicle_id: VehicleIdOption = None,
    record: RecordOption = None,
    verbose: VerboseOption = False,
) -> None:
    """Run the companion service: the whole flight process, as systemd starts it at boot.

    Loads the wire CNN, retries until an autopilot is heard, then flies what the mission is
    given (ground station commands over MQTT, or `mission.auto_start` goals), logs a status
    line and the stage timings, and notifies systemd (READY, STATUS, WATCHDOG) when
    $NOTIFY_SOCKET is set. SIGTERM or Ctrl-C stops it (exit 0); exit 1 when the link gave up
    reconnecting or the flight process failed.
    """
    _serve(config, None, mqtt, vehicle_id, None, verbose, record)


def fly(
    connect: Annotated[
        str | None,
        typer.Option(
            "--connect",
            help="the autopilot's MAVSDK URL (PX4 SITL: udpin://0.0.0.0:14540; default "
            "link.connection_url)",
        ),
    ] = None,
    camera: Annotated[
        str | None,
        typer.Option("--camera", help="camera source: oakd or none (default camera.source)"),
    ] = None,
    mqtt: MqttUrlOption = None,
    vehicle_id: VehicleIdOption = None,
    record: RecordOption = None,
    config: ConfigOption = None,
    verbose: VerboseOption = False,
) -> None:
    """Fly a real or SITL autopilot with the whole flight process, in the foreground.

    The same process as `wireavoid run`, for an engineer at a terminal: goals come from the
    ground station (`--mqtt`, `wireavoid gcs`) or from the mission settings with
    `auto_start`.
    Ctrl-C stops it.
    """
    _serve(config, connect, mqtt, vehicle_id, camera, verbose, record)


def _serve(
    config: Path | None,
    connect: str | None,
    mqtt: str | None,
    vehicle_id: str | None,
    camera: str | None,
    verbose: bool,
    record: str | None = None,
) -> None:
    import asyncio

    from pydantic import ValidationError

    from companion.config import load_settings
    from companion.ground.options import apply_ground_options
    from companion.service import run_service

    try:
        settings = apply_ground_options(load_settings(config), mqtt, vehicle_id)
        updates = {}
        if connect is not None:
            updates["link"] = settings.link.model_copy(update={"connection_url": connect})
        if camera is not None:
            updates["camera"] = type(settings.camera).model_validate(
                {**settings.camera.model_dump(), "source": camera}
            )
        if record is not None:
            updates["record"] = settings.record.model_copy(update={"path": record})
        settings = settings.model_copy(update=updates)
    except ValidationError as e:
        raise typer.BadParameter(str(e)) from e
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
    """Add `wireavoid run` and `wireavoid fly`."""
    app.command("run")(run)
    app.command("fly")(fly)
