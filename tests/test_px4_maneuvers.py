"""The hil vehicle against PX4 SITL's own flights: px4_maneuvers.py flown, px4_compare.py judging.

`../shared/tools/px4_maneuvers.py` (the script that recorded the three PX4 SITL flights of
`../shared/data/px4-sitl-traces`) flies its fixed sequence against the hil vehicle with the
`sih_quadx` airframe over real MAVLink; `px4_compare.py --json` compares the flight with PX4's.
The script times itself with `time.monotonic()` and waits in pymavlink's `recv_match`: here its
clock is the vehicle's simulated clock and its waits advance the vehicle (lockstep), so the flight
is the one it flies in real time, in vehicle seconds, as fast as the machine runs and the same on
a loaded one (`wireavoid vehicle-sim --airframe sih_quadx` in real time gives the same figures).

Targets (issue 18): the velocity within PX4's own run-to-run spread in every segment (RMS <=
0.36 m/s), the braking distances and the takeoff time inside the range PX4's flights span, the
same offboard-loss action (Return).
"""

from __future__ import annotations

import glob
import importlib.util
import json
import socket
import subprocess
import sys
import time
from pathlib import Path
from types import ModuleType

import pytest

from hil.mavlink.server import VehicleServer
from hil.vehicle.airframes import airframe_params

SHARED = Path(__file__).resolve().parents[2] / "shared"
TOOLS = SHARED / "tools"
TRACES = SHARED / "data" / "px4-sitl-traces"
PX4_SPREAD_MAX_MPS = 0.36

# px4_maneuvers divides by a yaw step that is zero in segments with no yaw step.
pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning")


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class _LockstepConnection:
    """The script's pymavlink connection: a blocking wait advances the lockstep vehicle."""

    def __init__(self, conn: object, server: VehicleServer) -> None:
        self._conn = conn
        self._server = server

    def recv_match(self, *, blocking: bool = False, timeout: float | None = None, **kw: object):
        msg = self._conn.recv_match(blocking=False, **kw)  # type: ignore[attr-defined]
        if msg is None and blocking:
            self._server.advance(timeout or 0.0)  # at least one physics step
            msg = self._conn.recv_match(blocking=False, **kw)  # type: ignore[attr-defined]
        return msg

    def __getattr__(self, name: str) -> object:
        return getattr(self._conn, name)


class _VehicleTime:
    """`time` for the script: monotonic() is the vehicle's simulated time."""

    def __init__(self, server: VehicleServer) -> None:
        self._server = server

    def monotonic(self) -> float:
        return self._server.time_s

    def __getattr__(self, name: str) -> object:
        return getattr(time, name)


def _load_script(server: VehicleServer) -> ModuleType:
    sys.path.insert(0, str(TOOLS))
    spec = importlib.util.spec_from_file_location("px4_maneuvers", TOOLS / "px4_maneuvers.py")
    assert spec is not None and spec.loader is not None, f"no px4_maneuvers.py in {TOOLS}"
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    module.time = _VehicleTime(server)  # type: ignore[attr-defined]
    return module


def _px4_range(segment: str, figure: str) -> tuple[float, float]:
    values = []
    for path in glob.glob(str(TRACES / "px4_run*_meta.json")):
        values.append(json.loads(Path(path).read_text())["metrics"][segment][figure])
    assert len(values) == 3, f"PX4 traces missing in {TRACES}"
    return min(values), max(values)


@pytest.fixture(scope="module")
def comparison(tmp_path_factory: pytest.TempPathFactory) -> dict:
    out = tmp_path_factory.mktemp("maneuvers") / "hil.csv"
    port = _free_udp_port()
    with VehicleServer(airframe_params("sih_quadx"), port, lockstep=True) as server:
        script = _load_script(server)
        flyer = script.Flyer(f"udpin:127.0.0.1:{port}", str(out), "hil", verbose=False)
        flyer.m = _LockstepConnection(flyer.m, server)
        try:
            flyer.fly()
        finally:
            flyer.close()
        assert server.error is None
    pos, att, _ = script.load_csv(str(out))
    flyer.meta["metrics"] = script.segment_metrics(pos, att, flyer.meta)
    out.with_name("hil_meta.json").write_text(json.dumps(flyer.meta, default=float))
    compare = subprocess.run(
        [sys.executable, str(TOOLS / "px4_compare.py"), str(out), "--ref", str(TRACES), "--json"],
        capture_output=True,
        text=True,
        check=True,
    )
    return {"compare": json.loads(compare.stdout), "metrics": flyer.meta["metrics"]}


@pytest.mark.slow
@pytest.mark.timeout(120)
def test_velocity_within_px4s_own_spread_in_every_segment(comparison: dict) -> None:
    rms = comparison["compare"]["rms_vel_diff_mps"]
    assert len(rms) == 9, rms  # every moving segment was flown
    assert comparison["compare"]["px4_spread_max_mps"] == pytest.approx(
        PX4_SPREAD_MAX_MPS, abs=0.01
    )
    assert max(rms.values()) <= PX4_SPREAD_MAX_MPS, rms


@pytest.mark.slow
@pytest.mark.timeout(120)
def test_braking_and_takeoff_inside_px4s_range_and_the_same_loss_action(comparison: dict) -> None:
    metrics = comparison["metrics"]
    for segment, figure in (
        ("stop_1", "brake_dist_final_m"),
        ("brake_1", "brake_dist_final_m"),
        ("takeoff", "duration_s"),
    ):
        low, high = _px4_range(segment, figure)
        assert low <= metrics[segment][figure] <= high, (segment, figure, metrics[segment][figure])
    compare = comparison["compare"]
    assert compare["offboard_loss_mode_px4"] == ["AUTO.RTL"]
    assert compare["offboard_loss_mode_sim"] == "AUTO.RTL"
