"""The product against the real PX4: `../shared/px4-sitl` (PX4 main, SIH quadrotor, headless).

A module fixture starts PX4 SITL on a free instance (1-9: its ports 14540+i and the others PX4
binds) and stops it after. PX4 runs in real time, so this file flies once: `fly-pattern`'s flight,
graded as the hil vehicle's is (tests/test_demo_flight.py), with PX4's events and arming-check
reports surfaced by the link and its default failsafe flagged by the pre-flight check; then the
check reads a changed COM_OBL_RC_ACT.
"""

from __future__ import annotations

import os
import socket
import struct
import subprocess
from collections.abc import Iterator
from pathlib import Path

import pytest

from companion.cli.demo_flight import run_demo
from companion.cli.settings import SimSettings
from companion.link.params import LinkParams
from companion.link.preflight import check_failsafes
from companion.link.vehicle_link import VehicleLink
from hil.mavlink.server import mavlink, mavutil

PX4_SITL = Path(__file__).resolve().parents[2] / "shared" / "px4-sitl"
# UDP ports PX4 instance i binds or sends to: offboard/API, its local ends, GCS, gimbal, ...
_PORT_BASES = (14540, 14580, 18570, 14280, 14030, 13030, 13280, 19450, 19410)


def _px4_build(tmp: Path) -> Path:
    """The PX4 to start: the shared one, or, where its module commands (bin/px4-*: links to
    bin/px4 in PX4's build) arrived as plain 3-byte files, a directory of links to it."""
    module = PX4_SITL / "bin" / "px4-param"
    if os.access(module, os.X_OK):
        return PX4_SITL
    build = tmp / "px4-build"
    (build / "bin").mkdir(parents=True)
    (build / "etc").symlink_to(PX4_SITL / "etc")
    for f in (PX4_SITL / "bin").iterdir():
        flattened = f.name.startswith("px4-") and f.stat().st_size <= 4
        if flattened and f.read_text().strip() == "px4":
            (build / "bin" / f.name).symlink_to("px4")
        else:
            (build / "bin" / f.name).symlink_to(f)
    return build


def _free_instance() -> int:
    """A PX4 instance whose ports are free; 1-9 only: from 10 on PX4 shares one API port."""
    for instance in range(9, 0, -1):
        sockets = []
        try:
            for base in _PORT_BASES:
                s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                sockets.append(s)
                s.bind(("0.0.0.0", base + instance))
            return instance
        except OSError:
            continue
        finally:
            for s in sockets:
                s.close()
    raise RuntimeError("no free PX4 SITL instance")


@pytest.fixture(scope="module")
def px4_url(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    tmp = tmp_path_factory.mktemp("px4")
    instance = _free_instance()
    rundir = tmp / "run"
    env = {**os.environ, "PX4_BUILD": str(_px4_build(tmp))}
    started = subprocess.run(
        [str(PX4_SITL / "start"), str(rundir), str(instance)],
        env=env,
        capture_output=True,
        text=True,
        timeout=90,
    )
    assert started.returncode == 0, f"PX4 SITL did not start: {started.stdout}{started.stderr}"
    try:
        yield f"udpin://0.0.0.0:{14540 + instance}"
    finally:
        subprocess.run([str(PX4_SITL / "stop"), str(rundir)], timeout=30, check=False)


def _settings(url: str) -> SimSettings:
    settings = SimSettings()
    return settings.model_copy(
        update={"link": settings.link.model_copy(update={"connection_url": url})}
    )


@pytest.mark.slow
@pytest.mark.timeout(150)
async def test_fly_pattern_passes_against_px4_sitl(px4_url: str) -> None:
    summary = await run_demo(_settings(px4_url), connect_url=px4_url)
    assert summary.ok, summary.to_text()
    assert [leg.name for leg in summary.legs] == [
        "takeoff",
        "velocity north",
        "velocity east",
        "velocity south",
        "velocity west",
        "position",
        "land",
    ]
    details = [(event["kind"], event["detail"]) for event in summary.events]
    # PX4's events reach the link (STATUSTEXT stays nearly empty on PX4)
    assert ("vehicle_event", "info: Armed by external command (px4/commander_armed_by)") in details
    assert any(kind == "arming_check" and "No manual control input" in d for kind, d in details)
    # PX4's default: offboard loss falls back to Return, which climbs to RTL_RETURN_ALT (30 m)
    assert any(
        line.startswith("refuse: offboard loss") and "30 m" in line for line in summary.preflight
    )


@pytest.mark.slow
@pytest.mark.timeout(60)
async def test_the_failsafe_check_reads_px4s_parameters(px4_url: str) -> None:
    params = LinkParams(connection_url=px4_url, connect_timeout_s=20.0)

    async def report():
        async with VehicleLink(params) as link:
            await link.wait_healthy()
            return await check_failsafes(link, flight_height_m=3.0, max_speed_mps=2.0)

    assert (await report()).refuse
    # COM_OBL_RC_ACT 5 (Hold) set over MAVLink like a ground station does (INT32 byte-wise)
    port = int(px4_url.rsplit(":", 1)[1])
    conn = mavutil.mavlink_connection(
        f"udpin:0.0.0.0:{port}", source_system=255, source_component=190
    )
    try:
        heartbeat = conn.wait_heartbeat(timeout=10)
        assert heartbeat is not None
        value = struct.unpack("<f", struct.pack("<i", 5))[0]
        for _ in range(5):
            conn.mav.param_set_send(
                conn.target_system, 1, b"COM_OBL_RC_ACT", value, mavlink.MAV_PARAM_TYPE_INT32
            )
            echo = conn.recv_match(type="PARAM_VALUE", blocking=True, timeout=1.0)
            if echo is not None and echo.param_id == "COM_OBL_RC_ACT":
                break
        assert echo is not None and struct.unpack("<i", struct.pack("<f", echo.param_value))[0] == 5
    finally:
        conn.close()
    after = await report()
    assert not after.refuse
    assert after.parameters["COM_OBL_RC_ACT"] == 5
