"""Process replay in CI (openpilot's process_replay): the recorded flight in tests/data/replay
re-run through perception, mapping and planning agrees with its blessed outputs; a change of
behaviour is caught with its first divergence, and `--bless` takes it as the new reference.

Regenerate the flight (after a change of its inputs' format):
    wireavoid sim --world tests/data/replay/hop.toml --config tests/data/replay/hop-settings.toml \
        --record tests/data/replay/hop.mcap
Re-bless it (after an intentional change of a stage's output; each stage replays on its
recorded inputs, so repeat until a plain replay reports no divergence):
    wireavoid replay tests/data/replay/hop.mcap --bless
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from companion.cli import app
from companion.record.reader import iter_recorded, summary
from companion.record.replay import bless, recording_settings, replay
from perception.segmenter import WireSegmenter

BLESSED = Path(__file__).parent / "data" / "replay" / "hop.mcap"


@pytest.fixture(scope="module")
def segmenter() -> WireSegmenter:
    return WireSegmenter.load(params=recording_settings(BLESSED).perception)


def test_the_blessed_flight_replays_without_a_divergence() -> None:
    result = CliRunner().invoke(app, ["replay", str(BLESSED), "--json"])
    assert result.exit_code == 0, result.output
    out = json.loads(result.output)
    assert out["divergences"] == 0 and out["first_divergence"] is None
    topics = out["topics"]
    # every stage ran on the whole flight: 84 frames perceived and fused, 170 planning cycles
    assert topics["perception"]["replayed"] == 84 and topics["map"]["replayed"] == 84
    assert topics["plan"]["replayed"] == 170
    assert out["messages_replayed"] == 84 + 84 + 170 and out["unmatched"] == 0
    assert topics["plan"]["largest_difference"]["reference_positions_m"] <= 1e-6


def test_a_changed_planner_diverges_and_says_where_first(segmenter: WireSegmenter) -> None:
    settings = recording_settings(BLESSED)
    slower = settings.model_copy(
        update={"planning": settings.planning.model_copy(update={"max_speed_mps": 1.5})}
    )
    result, _ = replay([BLESSED], slower, segmenter)
    assert result.topics["perception"].divergent == 0 and result.topics["map"].divergent == 0
    plan = result.topics["plan"]
    assert plan.divergent > 10
    first = result.first_divergence
    assert first is not None and first["topic"] == "plan"
    assert "reference_velocities_mps" in first["fields"] or "label" in first["fields"]
    assert plan.largest["reference_velocities_mps"] > 0.1


def test_bless_takes_the_replayed_outputs_as_the_new_reference(
    tmp_path: Path, segmenter: WireSegmenter
) -> None:
    copy = tmp_path / "hop.mcap"
    shutil.copy(BLESSED, copy)
    settings = recording_settings(copy)
    coarser = settings.model_copy(
        update={"planning": settings.planning.model_copy(update={"max_speed_mps": 1.5})}
    )
    before, replayer = replay([copy], coarser, segmenter)
    assert before.divergences > 0
    bless(copy, replayer)
    after, _ = replay([copy], coarser, segmenter)
    assert after.divergences == 0 and after.messages_replayed == before.messages_replayed
    # the inputs are untouched: the same frames, poses and messages in the same order
    assert summary(copy)["channels"]["/camera/disparity"]["messages"] == 84
    original = [m.payload for m in iter_recorded([BLESSED], {"/vehicle", "/camera/disparity"})]
    blessed = [m.payload for m in iter_recorded([copy], {"/vehicle", "/camera/disparity"})]
    assert original == blessed


def test_a_probe_says_when_the_replayed_map_first_held_a_point() -> None:
    """`--probe`: the pole beside the path (5, 2.5) is held from the first frames, the wire
    (9, 0, 2 m up) only once the flight has come close, and a point far behind the take-off
    is never seen; probing changes nothing in the replay itself."""
    probes = ["--probe", "9,0,-2", "--probe", "5,2.5,-2", "--probe", "-60,0,-1.5"]
    result = CliRunner().invoke(app, ["replay", str(BLESSED), "--json", *probes])
    assert result.exit_code == 0, result.output
    out = json.loads(result.output)
    assert out["divergences"] == 0
    wire, pole, behind = (p["changes"] for p in out["probes"])
    assert out["probes"][0]["point_ned_m"] == [9.0, 0.0, -2.0]

    def first_collision_s(changes: list[dict]) -> float:
        return min(c["t_s"] for c in changes if c["collision"])

    assert first_collision_s(pole) < 2.0 < first_collision_s(wire)
    # each probe is logged at the first planning cycle, before any frame saw it
    assert wire[0]["t_s"] == pole[0]["t_s"] == behind[0]["t_s"] and not wire[0]["seen"]
    assert all(c["seen"] for c in wire[1:])
    assert len(behind) == 1 and not behind[0]["seen"] and not behind[0]["collision"]


def test_a_malformed_probe_is_refused_with_the_expected_form() -> None:
    result = CliRunner().invoke(app, ["replay", str(BLESSED), "--probe", "9,0"])
    assert result.exit_code == 2
    assert "N,E,D" in result.output
