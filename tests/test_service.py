"""The companion service against the hil vehicle over real UDP with the real MAVSDK, as systemd
sees it: a temporary `$NOTIFY_SOCKET` bound by the test collects what the service sends.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import select
import signal
import socket
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest
import typer
from typer.testing import CliRunner

from companion.cli import service as cli_service
from companion.cli.demo_flight import free_udp_port
from companion.config import Settings
from companion.ingest.params import CameraParams
from companion.link.params import LinkParams
from companion.link.telemetry import FlightMode, Health, LandedState, TelemetryCache
from companion.link.vehicle_link import LinkState
from companion.service import ReadinessWatch, run_service, status_line
from companion.service_params import ServiceParams
from companion.systemd_notify import SystemdNotifier, watchdog_interval_s
from hil.mavlink.server import VehicleServer
from hil.vehicle.params import VehicleSimParams

pytestmark = pytest.mark.timeout(60)

SPEED = 3.0  # real-time factor of the simulated vehicle


class NotifyListener:
    """The systemd side of sd_notify: a bound AF_UNIX datagram socket, read as it fills (as
    systemd does; an unread socket fills up and the sender gets EAGAIN). One dict per datagram.
    """

    def __init__(self, address: str) -> None:
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
        self.sock.bind(address)
        self.sock.setblocking(False)
        self.messages: list[dict[str, str]] = []
        self._lock = threading.Lock()
        self._closed = threading.Event()
        self._reader = threading.Thread(target=self._read_until_closed, daemon=True)
        self._reader.start()

    def _read_until_closed(self) -> None:
        while not self._closed.is_set():
            readable, _, _ = select.select([self.sock], [], [], 0.05)
            if readable:
                self.drain()

    def drain(self) -> None:
        """Read every pending datagram into `messages`."""
        new = []
        with self._lock:
            while True:
                try:
                    data = self.sock.recv(4096)
                except (BlockingIOError, OSError):
                    break
                new.append(dict(line.split("=", 1) for line in data.decode().splitlines()))
            self.messages.extend(new)

    def with_key(self, key: str) -> list[dict[str, str]]:
        self.drain()
        return [m for m in self.messages if key in m]

    def last(self) -> dict[str, str]:
        self.drain()
        return self.messages[-1]

    def close(self) -> None:
        self._closed.set()
        self._reader.join()
        self.sock.close()


@pytest.fixture
def listener(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[NotifyListener]:
    path = str(tmp_path / "notify")
    notify = NotifyListener(path)
    monkeypatch.setenv("NOTIFY_SOCKET", path)
    yield notify
    notify.close()


def _settings(port: int, connect_timeout_s: float = 5.0) -> Settings:
    return Settings(
        link=LinkParams(
            connection_url=f"udpin://0.0.0.0:{port}", connect_timeout_s=connect_timeout_s
        ),
        camera=CameraParams(source="none"),
    )


FAST = ServiceParams(tick_rate_hz=10.0, status_period_s=1.0, connect_retry_interval_s=0.2)


@contextlib.contextmanager
def _vehicle(port: int) -> Iterator[VehicleServer]:
    server = VehicleServer(VehicleSimParams(), port, speed=SPEED)
    server.start()
    try:
        yield server
    finally:
        server.stop()


async def _until(predicate: Callable[[], bool], timeout_s: float, what: str) -> None:
    end = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > end:
            raise AssertionError(f"timed out waiting for {what}")
        await asyncio.sleep(0.02)


def _reported_healthy(listener: NotifyListener) -> bool:
    return any("health=ready" in m["STATUS"] for m in listener.with_key("STATUS"))


def _port_is_free(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.bind(("0.0.0.0", port))
        except OSError:
            return False
        return True


# ---------------------------------------------------------------------------- sd_notify


def test_notifier_is_a_noop_without_notify_socket(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("NOTIFY_SOCKET", raising=False)
    notifier = SystemdNotifier.from_environment()
    assert not notifier.enabled
    assert notifier.ready("up") is False
    assert notifier.watchdog() is False
    assert notifier.stopping("bye") is False
    assert notifier._sock is None  # not even a socket was opened


def test_notifier_sends_datagrams_to_a_path(listener: NotifyListener) -> None:
    notifier = SystemdNotifier.from_environment()
    assert notifier.ready("line one\nline two")
    assert notifier.watchdog("ticking")
    assert notifier.extend_timeout(12.5, "waiting")
    assert notifier.stopping("bye")
    listener.drain()
    assert listener.messages == [
        {"READY": "1", "STATUS": "line one line two"},
        {"WATCHDOG": "1", "STATUS": "ticking"},
        {"EXTEND_TIMEOUT_USEC": "12500000", "STATUS": "waiting"},
        {"STOPPING": "1", "STATUS": "bye"},
    ]


def test_notifier_reaches_an_abstract_socket() -> None:
    name = f"wireavoid-test-{os.getpid()}-{time.monotonic_ns()}"
    notify = NotifyListener("\0" + name)
    try:
        assert SystemdNotifier.from_environment({"NOTIFY_SOCKET": "@" + name}).ready("up")
        notify.drain()
        assert notify.messages == [{"READY": "1", "STATUS": "up"}]
    finally:
        notify.close()


def test_notifier_never_raises_when_nobody_listens(tmp_path: Path) -> None:
    notifier = SystemdNotifier(str(tmp_path / "absent"))
    assert notifier.enabled
    assert notifier.watchdog() is False
    assert notifier.watchdog() is False


def test_watchdog_interval_is_for_this_process_only() -> None:
    assert watchdog_interval_s({}) is None
    assert watchdog_interval_s({"WATCHDOG_USEC": "10000000"}) == 10.0
    assert watchdog_interval_s({"WATCHDOG_USEC": "10000000", "WATCHDOG_PID": "7"}, pid=7) == 10.0
    assert watchdog_interval_s({"WATCHDOG_USEC": "10000000", "WATCHDOG_PID": "7"}, pid=8) is None
    assert watchdog_interval_s({"WATCHDOG_USEC": "0"}) is None


# ---------------------------------------------------------------------------- status line


def test_status_line_marks_unknown_values() -> None:
    line = status_line(LinkState.DISCONNECTED, TelemetryCache().snapshot(5.0))
    assert line == (
        "link=disconnected mode=UNKNOWN armed=? landed=UNKNOWN ned_m=? battery=? health=? age_s=?"
    )


def test_status_line_reports_telemetry_and_failed_checks() -> None:
    cache = TelemetryCache()
    cache.update_pose(np.array([1.0, -2.5, -3.04]), np.zeros(3), 10.0)
    cache.update_flight_mode(FlightMode.HOLD, 10.0)
    cache.update_armed(False, 10.0)
    cache.update_landed_state(LandedState.ON_GROUND, 10.0)
    cache.update_battery(12.4, 0.871, 10.0)
    cache.update_health(Health(True, True, False, False, True, 10.0), 10.5)
    line = status_line(LinkState.CONNECTED, cache.snapshot(11.0))
    assert line == (
        "link=connected mode=HOLD armed=no landed=ON_GROUND ned_m=1.00,-2.50,-3.04 "
        "battery=12.40V/87% health=not-ready(home,armable) age_s=0.50"
    )


def test_readiness_watch_reports_once_per_not_ready_episode() -> None:
    watch = ReadinessWatch(timeout_s=30.0, now_s=100.0)
    assert [watch.overdue(False, t) for t in (110.0, 130.0, 130.5, 200.0)] == [
        False,
        False,
        True,
        False,
    ]
    assert not watch.overdue(True, 201.0)  # ready: the episode ends
    assert [watch.overdue(False, t) for t in (300.0, 330.0, 330.5)] == [False, False, True]


# ---------------------------------------------------------------------------- the service (SIL)


async def test_service_readies_reports_feeds_watchdog_never_arms_and_stops_on_sigterm(
    listener: NotifyListener, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level("INFO")
    port = free_udp_port()
    with _vehicle(port) as server:
        task = asyncio.create_task(run_service(_settings(port), FAST))
        await _until(lambda: bool(listener.with_key("READY")), 15.0, "READY=1")
        await _until(lambda: _reported_healthy(listener), 15.0, "a healthy status")
        watchdogs_before = len(listener.with_key("WATCHDOG"))
        await asyncio.sleep(1.0)  # 10 ticks at 10 Hz
        assert len(listener.with_key("WATCHDOG")) - watchdogs_before >= 5
        assert not server.armed
        assert server.flight_mode.name == "HOLD"

        os.kill(os.getpid(), signal.SIGTERM)
        assert await asyncio.wait_for(task, 10.0) == 0
        assert not server.armed

    assert "STOPPING" in listener.last()
    sent = listener.messages
    ready_at = next(i for i, m in enumerate(sent) if "READY" in m)
    # Before READY: start-up extensions while the autopilot is looked for; no watchdog.
    assert "EXTEND_TIMEOUT_USEC" in sent[0]
    assert all("WATCHDOG" not in m for m in sent[:ready_at])
    assert "link=connected" in sent[ready_at]["STATUS"]
    fed = [m["STATUS"] for m in sent[ready_at:] if "WATCHDOG" in m]
    assert all("mode=HOLD" in s and "armed=no" in s for s in fed[-5:])
    assert not any("armed=yes" in m["STATUS"] for m in sent)
    # The link's own events reach the log, and the status lines with them; the port is released.
    logged = caplog.text
    assert "connected: udpin://" in logged
    assert "link=connected mode=HOLD armed=no landed=ON_GROUND" in logged
    assert "SIGTERM received" in logged
    assert _port_is_free(port)


async def test_a_stalled_loop_does_not_feed_the_watchdog(listener: NotifyListener) -> None:
    port = free_udp_port()
    params = FAST.model_copy(update={"watchdog_max_lag_s": 0.5})
    with _vehicle(port):
        stop = asyncio.Event()
        task = asyncio.create_task(run_service(_settings(port), params, stop=stop))
        await _until(lambda: len(listener.with_key("WATCHDOG")) >= 3, 15.0, "watchdog pings")
        listener.drain()
        mark = len(listener.messages)
        time.sleep(1.5)  # block the event loop: the service's next tick starts 1.5 s late

        def watchdogs_after_stall() -> int:
            listener.drain()
            return sum("WATCHDOG" in m for m in listener.messages[mark:])

        await _until(lambda: watchdogs_after_stall() >= 3, 5.0, "watchdog pings again")
        stop.set()
        assert await asyncio.wait_for(task, 10.0) == 0
    late, *later = listener.messages[mark:]
    assert "STATUS" in late and "WATCHDOG" not in late  # alive, but not fed: it was late
    assert "link=connected" in late["STATUS"]
    assert any("WATCHDOG" in m for m in later[:3])  # on time again: fed again


async def test_service_waits_for_a_vehicle_that_boots_later(listener: NotifyListener) -> None:
    port = free_udp_port()
    task = asyncio.create_task(run_service(_settings(port, connect_timeout_s=0.5), FAST))

    def attempts() -> list[dict[str, str]]:
        extended = listener.with_key("EXTEND_TIMEOUT_USEC")
        return [m for m in extended if "waiting for an autopilot" in m["STATUS"]]

    await _until(lambda: len(attempts()) >= 2, 10.0, "a second attempt")
    assert not listener.with_key("READY")
    assert "loading the wire CNN" in listener.messages[0]["STATUS"]  # before any attempt
    assert "(attempt 2)" in attempts()[1]["STATUS"]
    # Each attempt asks systemd for its own duration plus the pause and the grace time.
    assert int(attempts()[0]["EXTEND_TIMEOUT_USEC"]) == round((0.5 + 0.2 + 10.0) * 1e6)
    with _vehicle(port) as server:
        await _until(lambda: bool(listener.with_key("READY")), 15.0, "READY=1 once PX4 is up")
        task.cancel()
        with pytest.raises(asyncio.CancelledError):
            await task
        assert not server.armed
    assert "STOPPING" in listener.last()
    assert _port_is_free(port)


async def test_service_exits_1_when_the_link_gives_up(listener: NotifyListener) -> None:
    """A link that stops rebuilding (LinkState.FAILED) ends the process for systemd to restart."""
    port = free_udp_port()
    settings = _settings(port)
    settings.link = settings.link.model_copy(
        update={
            "link_loss_timeout_s": 0.5,
            "reconnect_soft_s": 0.0,
            "reconnect_interval_s": 0.5,
            "reconnect_max_attempts": 1,
        }
    )
    with _vehicle(port) as server:
        task = asyncio.create_task(run_service(settings, FAST, handle_signals=False))
        # Healthy: the link's start-up requests were answered before the autopilot dies.
        await _until(lambda: _reported_healthy(listener), 15.0, "a healthy status")
        server.stop()  # the autopilot dies and does not come back
        assert await asyncio.wait_for(task, 10.0) == 1
    assert "STOPPING" in listener.last()
    statuses = [m["STATUS"] for m in listener.messages]
    assert any("link=lost" in s for s in statuses)


async def test_service_stopped_before_any_autopilot_exits_cleanly(
    listener: NotifyListener,
) -> None:
    port = free_udp_port()
    stop = asyncio.Event()
    task = asyncio.create_task(run_service(_settings(port, connect_timeout_s=30.0), stop=stop))
    await _until(lambda: bool(listener.with_key("EXTEND_TIMEOUT_USEC")), 5.0, "an attempt")
    stop.set()
    assert await asyncio.wait_for(task, 5.0) == 0  # the 30 s connect attempt was cut short
    assert not listener.with_key("READY")
    assert "STOPPING" in listener.last()
    assert _port_is_free(port)


def test_cli_run_with_config_stops_on_sigint(listener: NotifyListener, tmp_path: Path) -> None:
    app = typer.Typer()
    app.callback()(lambda: None)  # a group, as in companion.cli: `run` is a subcommand
    cli_service.register(app, typer.Typer())
    port = free_udp_port()
    config = tmp_path / "wireavoid.toml"
    config.write_text(
        f'[link]\nconnection_url = "udpin://0.0.0.0:{port}"\n[camera]\nsource = "none"\n'
    )

    def interrupt_once_ready() -> None:
        end = time.monotonic() + 20.0
        while time.monotonic() < end:
            if listener.with_key("READY"):
                time.sleep(0.3)
                os.kill(os.getpid(), signal.SIGINT)
                return
            time.sleep(0.05)

    with _vehicle(port):
        killer = threading.Thread(target=interrupt_once_ready)
        killer.start()
        result = CliRunner().invoke(app, ["run", "--config", str(config)])
        killer.join()
    assert result.exit_code == 0, result.output
    assert listener.with_key("READY")
    assert "STOPPING" in listener.last()
    assert f"link up on udpin://0.0.0.0:{port}" in result.output
    assert "SIGINT received: stopping" in result.output


# ---------------------------------------------------------------------------- a real process

REPO = Path(__file__).resolve().parents[1]

_RUN_APP = (
    "import typer; from companion.cli import service as cli_service; app = typer.Typer(); "
    "app.callback()(lambda: None); cli_service.register(app, typer.Typer()); app()"
)


def test_process_under_a_journal_stream_stops_on_sigterm(tmp_path: Path) -> None:
    """As systemd runs it: its own process, stderr on the journal, SIGTERM to stop: exit 0."""
    import subprocess
    import sys

    notify = NotifyListener(str(tmp_path / "notify"))
    port = free_udp_port()
    config = tmp_path / "wireavoid.toml"
    config.write_text(
        f'[link]\nconnection_url = "udpin://0.0.0.0:{port}"\n[camera]\nsource = "none"\n'
    )
    read_fd, write_fd = os.pipe()
    stat = os.fstat(write_fd)
    env = dict(
        os.environ,
        NOTIFY_SOCKET=notify.sock.getsockname(),
        JOURNAL_STREAM=f"{stat.st_dev}:{stat.st_ino}",
    )
    try:
        with _vehicle(port):
            proc = subprocess.Popen(
                [sys.executable, "-c", _RUN_APP, "run", "--config", str(config)],
                cwd=REPO,
                env=env,
                stderr=write_fd,
            )
            os.close(write_fd)
            try:
                end = time.monotonic() + 30.0
                while not notify.with_key("READY") and time.monotonic() < end:
                    time.sleep(0.05)
                assert notify.with_key("READY"), "no READY=1 from the process"
                proc.send_signal(signal.SIGTERM)
                assert proc.wait(timeout=15.0) == 0
            finally:
                if proc.poll() is None:
                    proc.kill()
                    proc.wait()
        with os.fdopen(read_fd) as stderr:
            journal = stderr.read().splitlines()
        assert "STOPPING" in notify.last()
    finally:
        notify.close()
    # Journal format: a syslog priority prefix, no timestamp of our own.
    assert f"<6>companion.service: link up on udpin://0.0.0.0:{port}; flying" in journal
    assert "<6>companion.service: SIGTERM received: stopping" in journal
    assert all(line.startswith("<") for line in journal), journal


# ---------------------------------------------------------------------------- unit and example


def _unit_values(path: Path) -> dict[str, str]:
    """`Key=Value` lines of a systemd unit; a key set on several lines (DeviceAllow) has its
    values joined by newlines."""
    lines = [line.strip() for line in path.read_text().splitlines()]
    pairs = [line.split("=", 1) for line in lines if "=" in line and not line.startswith("#")]
    values: dict[str, str] = {}
    for key, value in pairs:
        values[key] = f"{values[key]}\n{value}" if key in values else value
    return values


def test_unit_file_matches_the_service_it_starts() -> None:
    unit = _unit_values(REPO / "systemd" / "wireavoid.service")
    assert unit["Type"] == "notify"
    assert unit["Restart"] == "on-failure"
    assert unit["ExecStart"] == (
        "/opt/wireavoid/.venv/bin/wireavoid run --config /etc/wireavoid/wireavoid.toml"
    )
    assert "dialout" in unit["SupplementaryGroups"].split()
    assert {"AF_INET", "AF_UNIX"} <= set(unit["RestrictAddressFamilies"].split())
    # the UART to PX4 and the camera stay reachable under the closed device policy
    assert "PrivateDevices" not in unit and unit["DevicePolicy"] == "closed"
    allowed = unit["DeviceAllow"].splitlines()
    assert "char-ttyTHS rw" in allowed and "char-usb_device rw" in allowed
    # /opt is read-only: numba must cache the query kernel in the unit's own cache directory
    assert unit["ProtectSystem"] == "strict" and "MemoryDenyWriteExecute" not in unit
    environment = dict(item.split("=", 1) for item in unit["Environment"].split())
    assert environment["NUMBA_CACHE_DIR"].startswith(f"/var/cache/{unit['CacheDirectory']}/")
    # The default ticks feed the watchdog at least twice per WatchdogSec, late ticks included.
    watchdog_s = float(unit["WatchdogSec"].removesuffix("s"))
    p = ServiceParams()
    assert 1.0 / p.tick_rate_hz + p.watchdog_max_lag_s <= watchdog_s / 2


def test_example_config_loads_with_the_serial_link() -> None:
    from companion.config import load_settings

    settings = load_settings(REPO / "systemd" / "wireavoid.toml")
    assert settings.link.connection_url == "serial:///dev/ttyTHS1:921600"
