"""`wireavoid vehicle-sim` standalone: MAVLink out, status lines, clean exit on SIGINT/SIGTERM."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys

import pytest
from typer.testing import CliRunner

from companion.cli import app
from hil.mavlink.server import mavlink, mavutil


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_vehicle_sim_runs_until_signalled(sig: signal.Signals) -> None:
    port = free_udp_port()
    conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=245)
    proc = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "from companion.cli import app; app()",
            "vehicle-sim",
            "--port",
            str(port),
            "--speed",
            "2",
            "--seed",
            "5",
            "--status-period-s",
            "0.2",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    try:
        heartbeat = conn.recv_match(type="HEARTBEAT", blocking=True, timeout=30.0)
        assert heartbeat is not None and heartbeat.autopilot == mavlink.MAV_AUTOPILOT_PX4
        lines = []
        while len(lines) < 2:
            line = proc.stdout.readline()
            assert line, "vehicle-sim exited early"
            if line.startswith("t="):
                lines.append(line)
        assert "HOLD" in lines[-1] and "disarmed" in lines[-1]
        proc.send_signal(sig)
        out, _ = proc.communicate(timeout=15.0)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        conn.close()
    assert proc.returncode == 0
    assert "vehicle-sim: stopped" in out


def test_bench_vehicle_sim_reports_real_time_factors() -> None:
    result = CliRunner().invoke(app, ["bench", "vehicle-sim", "--json", "--duration-s", "8"])
    assert result.exit_code == 0, result.output
    report = json.loads(result.output)
    assert report["sim_duration_s"] == 8.0
    assert report["dynamics_real_time_factor"] > 0.0
    assert report["mavlink_lockstep_real_time_factor"] > 0.0
