"""Deterministic replay: perception, mapping and planning re-run on a recording's inputs.

In the spirit of openpilot's process replay (STYLE.md practice 9), each stage runs the same
pure objects the flight process runs (`WireDetector`, `MapBuilder`, `Pilot`), synchronously,
on the inputs that stage had in the recording, in the recorded order, with the recording's
settings; its outputs are compared with the recorded ones. A stage is fed the *recorded*
outputs of the stages before it (the map is built from the recorded wire masks, not the
replayed ones), so a difference shows where it arises and does not cascade.

- perception: each recorded frame through the CNN -> the wire mask, compared pixel by pixel.
- map: the recorded poses into the pose history in bus order; each recorded perception that
  the map stage took is registered at the pose interpolated at its stamp and inserted ->
  the camera pose, DROAN's insert result, the node and wire counts. Which poses had arrived
  when the stage looked the pose up is timing, not recorded: of the histories it can have had
  (the poses published before the perception, and each one published until the map update)
  the replay takes the first that gives the recorded registration, else all of them.
- plan: each recorded planning cycle (its time, vehicle state, goal, hold, cruise speed and
  starting velocity) on the map holding exactly the frames the recorded cycle saw (every
  insert up to `PlanUpdate.frame_stamp_s`) -> the planner's state, label, cost, counts and
  chosen reference.

Timing fields are not compared (a replay runs at its own pace); numbers agree within
`Tolerance`. `bless` writes the recording again with the replayed outputs in place of the
recorded ones: an intentional change re-blesses the regression data with one command.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from collections import OrderedDict, deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from companion.config import Settings
from companion.flight.map_builder import MapBuilder, MapUpdate
from companion.flight.perceive import Perception, WireDetector
from companion.flight.pilot import Pilot
from companion.flight.pose_jump import pose_jump_m
from companion.flight.process import PlanUpdate
from companion.ingest.frames import CameraFrame
from companion.link.telemetry import LocalPosition
from companion.record.codec import (
    decode_camera,
    decode_map,
    decode_perception,
    decode_plan,
    decode_vehicle,
    encode_map,
    encode_perception,
    encode_plan,
    stamp_ns,
)
from companion.record.reader import RecordedMessage, iter_recorded, read_metadata
from companion.record.writer import open_mcap
from geometry.pose import Pose, PoseHistory
from mapping.query import OccupancyMap
from perception.segmenter import WireSegmenter
from planning.types import PlannerOutput

REPLAYED_TOPICS = ("perception", "map", "plan")
_FRAMES_KEPT = 256  # camera frames kept for perceptions that come after them


@dataclass(frozen=True)
class Tolerance:
    """How far a replayed output may differ from the recorded one and still agree."""

    mask_fraction: float = 0.002  # of the mask's pixels (CNN arithmetic differs by CPU)
    pose_m: float = 1e-6  # camera position, and rotation matrix entries
    plan_m: float = 1e-6  # reference waypoints and velocities, m and m/s
    cost_rel: float = 1e-6  # eq. 4.8 cost and distance to the goal, relative


@dataclass
class TopicDiff:
    """The comparison of one replayed topic: messages, how many differ, the first and the
    largest difference of each field."""

    replayed: int = 0
    divergent: int = 0
    first: dict[str, Any] | None = None
    largest: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {
            "replayed": self.replayed,
            "divergent": self.divergent,
            "first_divergence": self.first,
            "largest_difference": {k: _json_number(v) for k, v in sorted(self.largest.items())},
        }


@dataclass(frozen=True)
class ProbeChange:
    """What the replayed map said at probe point `probe` from the planning cycle at `t_s`
    (recorded time, s) on: the first cycle, then each one at which `collision`, `solid` or
    `seen` changed (`OccupancyQuery`); `occupancy` is M of eq. 4.5 at that cycle."""

    t_s: float
    probe: int
    collision: bool
    solid: bool
    seen: bool
    occupancy: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "t_s": _json_number(self.t_s),
            "collision": self.collision,
            "solid": self.solid,
            "seen": self.seen,
            "occupancy": _json_number(self.occupancy),
        }


@dataclass
class ReplayResult:
    """What `wireavoid replay --json` prints."""

    files: list[str]
    messages: int = 0
    messages_replayed: int = 0
    topics: dict[str, TopicDiff] = field(
        default_factory=lambda: {t: TopicDiff() for t in REPLAYED_TOPICS}
    )
    unmatched: int = 0  # recorded outputs whose inputs are not in the recording
    probes_ned_m: list[list[float]] = field(default_factory=list)
    probe_changes: list[ProbeChange] = field(default_factory=list)

    @property
    def divergences(self) -> int:
        """Replayed messages that differ from the recording (0: the code did not change)."""
        return sum(t.divergent for t in self.topics.values())

    @property
    def first_divergence(self) -> dict[str, Any] | None:
        """The earliest divergence over every topic."""
        firsts = [t.first for t in self.topics.values() if t.first is not None]
        return min(firsts, key=lambda f: f["index"]) if firsts else None

    def to_dict(self) -> dict[str, Any]:
        out = {
            "files": self.files,
            "messages": self.messages,
            "messages_replayed": self.messages_replayed,
            "divergences": self.divergences,
            "first_divergence": self.first_divergence,
            "unmatched": self.unmatched,
            "topics": {name: t.to_dict() for name, t in self.topics.items()},
        }
        if self.probes_ned_m:
            out["probes"] = [
                {
                    "point_ned_m": point,
                    "changes": [c.to_dict() for c in self.probe_changes if c.probe == k],
                }
                for k, point in enumerate(self.probes_ned_m)
            ]
        return out


def _json_number(value: float) -> float | None:
    return None if not math.isfinite(value) else float(f"{value:.6g}")


def recording_settings(path: str | Path) -> Settings:
    """The flight `Settings` a recording was made with (the simulator's sections left out)."""
    values = json.loads(read_metadata(path)["settings"])
    flight_keys = set(Settings.model_fields)
    return Settings.model_validate({k: v for k, v in values.items() if k in flight_keys})


class _Comparison:
    """Collects the differences of one replayed message."""

    def __init__(self) -> None:
        self.differences: dict[str, float] = {}
        self.failed: list[tuple[str, Any, Any]] = []

    def number(self, name: str, recorded: float, replayed: float, tolerance: float) -> None:
        if math.isnan(recorded) and math.isnan(replayed):
            return
        difference = abs(recorded - replayed)
        if recorded == replayed:
            difference = 0.0
        self.differences[name] = difference if math.isfinite(difference) else math.inf
        if not difference <= tolerance:
            self.failed.append((name, recorded, replayed))

    def array(self, name: str, recorded: np.ndarray, replayed: np.ndarray, tol: float) -> None:
        a, b = np.asarray(recorded, float), np.asarray(replayed, float)
        if a.shape != b.shape:
            self.differences[name] = math.inf
            self.failed.append((name, list(a.shape), list(b.shape)))
            return
        if a.size == 0:
            return
        both_nan = np.isnan(a) & np.isnan(b)
        diff = np.where(both_nan, 0.0, np.abs(a - b))
        worst = float(np.nan_to_num(diff, nan=np.inf).max())
        self.differences[name] = worst
        if not worst <= tol:
            self.failed.append((name, float(a.reshape(-1)[0]), float(b.reshape(-1)[0])))

    def same(self, name: str, recorded: Any, replayed: Any) -> None:
        if recorded != replayed:
            self.differences[name] = math.inf
            self.failed.append((name, _plain(recorded), _plain(replayed)))


def _plain(value: Any) -> Any:
    return getattr(value, "value", value)


class Replayer:
    """Re-runs the stages on one recording; feed it with `run`, read `result`."""

    def __init__(
        self,
        settings: Settings,
        segmenter: WireSegmenter | None = None,
        tolerance: Tolerance | None = None,
        on_replayed: Callable[[str, float, Any], None] | None = None,
        probes_ned_m: np.ndarray | None = None,
    ) -> None:
        """on_replayed: called with (bus topic, recorded time, message) for every input the
        replay reads (camera, vehicle) and every output it computes (the live view).
        probes_ned_m: `(P, 3)` NED points, m, at which every planning cycle's map is queried
        (`ReplayResult.probe_changes`): when the map first held a point a flight struck."""
        self.settings = settings
        self.tolerance = tolerance or Tolerance()
        seg = segmenter or WireSegmenter.load(params=settings.perception)
        self.detector = WireDetector(seg)
        self.builder = MapBuilder(settings.mapping, settings.catenary)
        self.pilot = Pilot(settings.planning)
        self.result = ReplayResult(files=[])
        self._probes = np.zeros((0, 3)) if probes_ned_m is None else np.asarray(probes_ned_m)
        self.result.probes_ned_m = self._probes.tolist()
        self._probe_states: list[tuple[bool, bool, bool] | None] = [None] * len(self._probes)
        self.replaced: dict[int, list[Any]] = {}  # recording index -> the replayed payloads
        self._on_replayed = on_replayed
        self._frames: OrderedDict[int, CameraFrame] = OrderedDict()
        self._perceptions: OrderedDict[int, Perception] = OrderedDict()
        self._pending: deque[tuple[RecordedMessage, PlanUpdate]] = deque()
        self._previous_pose: LocalPosition | None = None
        self._pose_log: list[tuple[float, Pose]] = []  # every pose since the last map reset
        self._poses_before: dict[int, int] = {}  # frame sequence -> poses when perceived

    # ------------------------------------------------------------------ feeding

    def run(self, messages: Iterable[RecordedMessage]) -> ReplayResult:
        """Replay `messages` (a recording in bus order) and return the comparison."""
        camera: list[RecordedMessage] = []
        for m in messages:
            self.result.messages += 1
            if m.bus_topic == "camera":
                if camera and camera[0].payload.get("sequence") != m.payload.get("sequence"):
                    self._camera(camera)
                    camera = []
                camera.append(m)
                continue
            if camera:
                self._camera(camera)
                camera = []
            if m.bus_topic == "vehicle":
                snap = decode_vehicle(m.payload)
                world_from_body = snap.world_from_body()
                if snap.pose is not None and world_from_body is not None:
                    self._pose(snap.pose, world_from_body)
                self._show("vehicle", m.stamp_s, snap)
            elif m.channel == "/perception/wire_mask":
                self._perception(m)
            elif m.channel == "/map":
                self._map(m)
            elif m.channel == "/plan":
                self._pending.append((m, decode_plan(m.payload)))
                self._flush_plans()
        self._flush_plans(final=True)
        return self.result

    def _pose(self, pose: LocalPosition, world_from_body: Pose) -> None:
        """What the process' vehicle stage does with a position: rebuild the map after a
        jump of the local frame (`FlightProcess.reset_map`), then add it to the history."""
        p = self.settings.flight
        jump_m = pose_jump_m(self._previous_pose, pose, p.pose_jump_max_gap_s)
        self._previous_pose = pose
        if jump_m > p.pose_jump_m:
            self._flush_plans(final=True)  # cycles before the jump ran on the old map
            self.builder = MapBuilder(self.settings.mapping, self.settings.catenary)
            self.pilot.reset()
            self._pose_log.clear()
            self._poses_before.clear()
        self.builder.add_pose(pose.stamp_s, world_from_body)
        self._pose_log.append((pose.stamp_s, world_from_body))

    def _camera(self, group: list[RecordedMessage]) -> None:
        image = next((m.payload for m in group if m.channel == "/camera/image"), None)
        disparity = next((m.payload for m in group if m.channel == "/camera/disparity"), None)
        if image is None and disparity is None:
            return
        frame = decode_camera(image, disparity)
        self._show("camera", group[0].stamp_s, frame)
        self._frames[frame.sequence] = frame
        while len(self._frames) > _FRAMES_KEPT:
            self._frames.popitem(last=False)

    # ------------------------------------------------------------------ the stages

    def _perception(self, m: RecordedMessage) -> None:
        sequence = int(m.payload["sequence"])
        frame = self._frames.get(sequence)
        if frame is None:
            self.result.unmatched += 1
            return
        recorded = decode_perception(m.payload, frame.disparity_px)
        self._perceptions[sequence] = recorded
        self._poses_before[sequence] = len(self._pose_log)
        while len(self._perceptions) > _FRAMES_KEPT:
            self._perceptions.popitem(last=False)
        replayed = self.detector(frame)
        c = _Comparison()
        a, b = recorded.wire_mask, replayed.wire_mask
        if a is None or b is None:
            c.same("has_mask", a is not None, b is not None)
        elif a.shape != b.shape:
            c.same("mask_shape", a.shape, b.shape)
        else:
            differing = int(np.count_nonzero(a != b))
            c.number("mask_pixels", 0.0, float(differing), self.tolerance.mask_fraction * a.size)
        self._record("perception", m, c, replayed)

    def _map(self, m: RecordedMessage) -> None:
        recorded = decode_map(m.payload)
        perception = self._perceptions.get(recorded.sequence)
        if perception is None:
            self.result.unmatched += 1
            return
        pose = self._registration(perception, recorded)
        replayed = self.builder.insert(perception, pose, recorded.wire_evidence)
        if (refit := self.builder.take_catenary_refit()) is not None:
            # at once: the flight refits on a worker of its own and uses the refit when done,
            # which no recording marks yet, so with the catenary on a replay may diverge
            self.builder.use_catenary_fits(refit())
        c = _Comparison()
        a, b = recorded.world_from_camera, replayed.world_from_camera
        c.same("registered", a is not None, b is not None)
        if a is not None and b is not None:
            c.array("camera_position_m", a.translation_m, b.translation_m, self.tolerance.pose_m)
            c.array("camera_rotation", a.rotation, b.rotation, self.tolerance.pose_m)
        c.same("result", recorded.result, replayed.result)
        c.same("nodes", recorded.nodes, replayed.nodes)
        c.same("wires", recorded.wires, replayed.wires)
        self._record("map", m, c, replayed)
        self._flush_plans()

    def _registration(self, perception: Perception, recorded: MapUpdate) -> Pose | None:
        """The camera pose of `perception` from the pose history the map stage can have had
        that reproduces `recorded`'s (see the module docstring); else from every pose."""
        first = self._poses_before.pop(perception.sequence, len(self._pose_log))
        mapping = self.settings.mapping
        full = self.builder.poses
        try:
            for count in range(first, len(self._pose_log)):
                history = PoseHistory(mapping.pose_max_extrapolation_s, mapping.pose_history_size)
                for stamp_s, pose in self._pose_log[
                    max(0, count - mapping.pose_history_size) : count
                ]:
                    history.add(stamp_s, pose)
                self.builder.poses = history
                candidate = self.builder.camera_pose_at(perception.stamp_s)
                if _same_pose(candidate, recorded.world_from_camera, self.tolerance.pose_m):
                    return candidate
        finally:
            self.builder.poses = full
        return self.builder.camera_pose_at(perception.stamp_s)

    def _flush_plans(self, final: bool = False) -> None:
        """Run the waiting planning cycles whose map is complete (in order)."""
        while self._pending:
            m, recorded = self._pending[0]
            if recorded.frame_stamp_s > self.builder.newest_frame_s and not final:
                return  # the map update it saw is published after it: wait for it
            self._pending.popleft()
            self._plan(m, recorded)

    def _plan(self, m: RecordedMessage, recorded: PlanUpdate) -> None:
        vehicle = recorded.vehicle
        self.pilot.set_speed(recorded.speed_mps, vehicle.stamp_s)
        occupancy_map = self.builder.occupancy_map()
        output = self.pilot.plan(
            recorded.output.stamp_s,
            vehicle,
            occupancy_map,
            recorded.goal_ned_m,
            recorded.hold,
            recorded.commanded_velocity_ned_mps,
        )
        c = _Comparison()
        _compare_plans(c, recorded.output, output, self.tolerance)
        c.number("frame_stamp_s", recorded.frame_stamp_s, self.builder.newest_frame_s, 0.0)
        replayed = PlanUpdate(
            output, vehicle, recorded.frame_stamp_s, recorded.goal_index, recorded.goal_ned_m,
            recorded.hold, recorded.speed_mps, recorded.commanded_velocity_ned_mps,
        )  # fmt: skip
        self._record("plan", m, c, replayed)
        if len(self._probes):
            self._probe(recorded.output.stamp_s, occupancy_map)

    def _probe(self, stamp_s: float, occupancy_map: OccupancyMap) -> None:
        """Log the probe points whose answer changed since the last planning cycle."""
        answer = occupancy_map.query(self._probes)
        for k in range(len(self._probes)):
            state = (bool(answer.collision[k]), bool(answer.solid[k]), bool(answer.seen[k]))
            if state != self._probe_states[k]:
                self._probe_states[k] = state
                self.result.probe_changes.append(
                    ProbeChange(stamp_s, k, *state, float(answer.occupancy[k]))
                )

    def _record(self, topic: str, m: RecordedMessage, c: _Comparison, replayed: Any) -> None:
        diff = self.result.topics[topic]
        diff.replayed += 1
        self.result.messages_replayed += 1
        for name, value in c.differences.items():
            diff.largest[name] = max(diff.largest.get(name, 0.0), value)
        if c.failed:
            diff.divergent += 1
            if diff.first is None:
                name, recorded, replayed_value = c.failed[0]
                diff.first = {
                    "topic": topic,
                    "index": m.index,
                    "t_s": round(m.stamp_s, 6),
                    "field": name,
                    "recorded": recorded,
                    "replayed": replayed_value,
                    "fields": [f[0] for f in c.failed],
                }
        self.replaced[m.index] = _encoded(topic, replayed, m.stamp_s)
        self._show(topic, m.stamp_s, replayed)

    def _show(self, topic: str, stamp_s: float, message: Any) -> None:
        if self._on_replayed is not None:
            self._on_replayed(topic, stamp_s, message)


def _same_pose(a: Pose | None, b: Pose | None, tolerance: float) -> bool:
    if a is None or b is None:
        return a is None and b is None
    return bool(
        np.abs(a.translation_m - b.translation_m).max() <= tolerance
        and np.abs(a.rotation - b.rotation).max() <= tolerance
    )


def _compare_plans(
    c: _Comparison, recorded: PlannerOutput, replayed: PlannerOutput, tol: Tolerance
) -> None:
    c.same("state", recorded.state, replayed.state)
    c.same("label", recorded.label, replayed.label)
    c.same("checked", recorded.checked, replayed.checked)
    c.same("queries", recorded.queries, replayed.queries)
    c.same("points", recorded.points, replayed.points)
    c.number("cost", recorded.cost, replayed.cost, tol.cost_rel * max(1.0, abs(recorded.cost)))
    c.number(
        "distance_to_goal_m",
        recorded.distance_to_goal_m,
        replayed.distance_to_goal_m,
        tol.cost_rel * max(1.0, abs(recorded.distance_to_goal_m)),
    )
    a, b = recorded.reference, replayed.reference
    c.same("plan_id", a.plan_id, b.plan_id)
    c.same("brake", a.brake, b.brake)
    c.number("reference_start_s", a.start_s, b.start_s, 1e-9)
    c.array("reference_positions_m", a.positions_ned_m, b.positions_ned_m, tol.plan_m)
    c.array("reference_velocities_mps", a.velocities_ned_mps, b.velocities_ned_mps, tol.plan_m)


def _encoded(topic: str, replayed: Any, stamp_s: float) -> list[Any]:
    if topic == "perception":
        return encode_perception(replayed, stamp_s)
    if topic == "map":
        assert isinstance(replayed, MapUpdate)
        return encode_map(replayed, stamp_s)
    return encode_plan(replayed, stamp_s)


def replay(
    paths: list[Path],
    settings: Settings | None = None,
    segmenter: WireSegmenter | None = None,
    tolerance: Tolerance | None = None,
    on_replayed: Callable[[str, float, Any], None] | None = None,
    probes_ned_m: np.ndarray | None = None,
) -> tuple[ReplayResult, Replayer]:
    """Replay the recording made of the parts `paths`; the comparison and the replayer (whose
    `replaced` outputs `bless` writes). `probes_ned_m`: see `Replayer`."""
    replayer = Replayer(
        settings or recording_settings(paths[0]), segmenter, tolerance, on_replayed, probes_ned_m
    )
    result = replayer.run(iter_recorded(paths))
    result.files = [str(p) for p in paths]
    return result, replayer


def bless(path: Path, replayer: Replayer) -> Path:
    """Write the recording at `path` (one part) again with the replayed outputs in place of
    the recorded perception, map and plan messages; atomically replaces the file."""
    metadata = read_metadata(path)
    handle, temporary = tempfile.mkstemp(dir=path.parent, suffix=".mcap")
    with os.fdopen(handle, "wb") as stream:
        writer, channel_ids = open_mcap(stream, metadata)
        index, plan_replaced = 0, False
        for m in iter_recorded([path]):
            if m.channel == "/plan/path" and plan_replaced:
                continue  # written with its replayed plan
            encoded = replayer.replaced.get(m.index)
            if m.channel == "/plan":
                plan_replaced = encoded is not None
            payloads = (
                [(e.channel, e.payload) for e in encoded]
                if encoded is not None
                else [(m.channel, m.payload)]
            )
            for channel, payload in payloads:
                data = json.dumps(payload, separators=(",", ":"), allow_nan=False).encode()
                ns = stamp_ns(m.stamp_s)
                writer.add_message(channel_ids[channel], ns, data, ns, index)
                index += 1
        writer.finish()
    Path(temporary).replace(path)
    return path
