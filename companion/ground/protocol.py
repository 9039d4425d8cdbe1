"""The ground-station protocol (pure): versioned JSON commands, acks, status and events.

Topics, per vehicle id (`ground.vehicle_id`):

    wireavoid/<id>/cmd     ground -> vehicle  commands (QoS 1, never retained)
    wireavoid/<id>/ack     vehicle -> ground  exactly one ack per command (QoS 1)
    wireavoid/<id>/status  vehicle -> ground  retained, 1-2 Hz; the broker's Last Will turns it
                                              into {"online": false} when the vehicle drops
    wireavoid/<id>/events  vehicle -> ground  state changes and warnings (QoS 1)

A command is one JSON object: `{"v": 1, "id": "<1-64 of A-Za-z0-9._:->", "type": ..., ...}`
with the fields of its type and nothing else. Numbers are finite JSON numbers (no NaN or
infinities, no strings), within the bounds below; positions are local NED from the
autopilot's origin (m); altitudes are above home (m). Commands are parsed strictly: anything
malformed, unknown or out of range is rejected with a reason a person can act on, and a
rejected command changes nothing. `parse_command` never raises.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Annotated, Any, Literal, Self

import numpy as np
import pydantic_core
from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Discriminator,
    Field,
    StringConstraints,
    Tag,
    TypeAdapter,
    ValidationError,
    model_validator,
)

from companion.ground.params import GroundParams
from planning.params import YawPolicy

PROTOCOL_VERSION = 1
COMMAND_ID_PATTERN = r"^[A-Za-z0-9._:-]{1,64}$"
MAX_WAYPOINTS = 200
MAX_SPEED_MPS = 20.0
MAX_HORIZONTAL_M = 100_000.0  # any local goal farther than 100 km is a typo
MAX_ALTITUDE_M = 10_000.0
MAX_REASON_CHARS = 400
DEFAULT_MAX_PAYLOAD_BYTES: int = GroundParams.model_fields["max_payload_bytes"].default


# ---------------------------------------------------------------------------- topics


@dataclass(frozen=True, slots=True)
class VehicleTopics:
    """The four topics of one vehicle (`wireavoid/<vehicle_id>/...`)."""

    cmd: str
    ack: str
    status: str
    events: str


def vehicle_topics(vehicle_id: str) -> VehicleTopics:
    """The topics of vehicle `vehicle_id` (one topic level: no '/', '+' or '#')."""
    if not re.fullmatch(r"[A-Za-z0-9_-]{1,64}", vehicle_id):
        raise ValueError(f"vehicle id {vehicle_id!r}: use 1-64 letters, digits, _ or -")
    root = f"wireavoid/{vehicle_id}"
    return VehicleTopics(f"{root}/cmd", f"{root}/ack", f"{root}/status", f"{root}/events")


# ---------------------------------------------------------------------------- commands

_STRICT = ConfigDict(extra="forbid", strict=True, allow_inf_nan=False, frozen=True)
CommandId = Annotated[str, StringConstraints(pattern=COMMAND_ID_PATTERN)]
Speed = Annotated[float, Field(gt=0.0, le=MAX_SPEED_MPS)]


class NedTarget(BaseModel):
    """A goal in local NED from the autopilot's origin, m (down is negative above it)."""

    model_config = _STRICT

    north_m: float = Field(ge=-MAX_HORIZONTAL_M, le=MAX_HORIZONTAL_M)
    east_m: float = Field(ge=-MAX_HORIZONTAL_M, le=MAX_HORIZONTAL_M)
    down_m: float = Field(ge=-MAX_ALTITUDE_M, le=MAX_ALTITUDE_M)

    @property
    def ned_m(self) -> np.ndarray:
        """(3,) float64, local NED, m."""
        return np.array([self.north_m, self.east_m, self.down_m])


class GeoTarget(BaseModel):
    """A goal as WGS84 latitude and longitude (deg) and altitude above home (m)."""

    model_config = _STRICT

    lat_deg: float = Field(ge=-90.0, le=90.0)
    lon_deg: float = Field(ge=-180.0, le=180.0)
    altitude_m: float = Field(ge=-MAX_ALTITUDE_M, le=MAX_ALTITUDE_M)


def _target_kind(value: Any) -> str:
    """Which target a JSON object describes: geographic when it names a latitude/longitude."""
    if isinstance(value, dict):
        return "geo" if "lat_deg" in value or "lon_deg" in value else "ned"
    return "geo" if isinstance(value, GeoTarget) else "ned"


Target = Annotated[
    Annotated[NedTarget, Tag("ned")] | Annotated[GeoTarget, Tag("geo")],
    Discriminator(_target_kind),
]


class Waypoint(BaseModel):
    """A goal with how to fly there: speed (None: the mission's cruise speed) and yaw policy
    (None: the planner's `yaw_policy`; `fixed` needs `yaw_rad`, from north, rad)."""

    model_config = _STRICT

    target: Target
    speed_mps: Speed | None = None
    yaw: YawPolicy | None = None
    yaw_rad: float | None = Field(None, ge=-2 * math.pi, le=2 * math.pi)

    @model_validator(mode="after")
    def _yaw_rad_with_fixed(self) -> Self:
        if (self.yaw is YawPolicy.FIXED) != (self.yaw_rad is not None):
            raise ValueError('yaw_rad is required with yaw "fixed" and only with it')
        return self


class _Command(BaseModel):
    model_config = _STRICT

    v: Literal[1]
    id: CommandId


class TakeoffCommand(_Command):
    """Arm, take off to `altitude_m` above home and hold."""

    type: Literal["takeoff"]
    altitude_m: float = Field(gt=0.0, le=MAX_ALTITUDE_M)


class GotoCommand(Waypoint, _Command):
    """Fly to one goal (replacing the goal queue); from the ground, take off first."""

    type: Literal["goto"]


class MissionCommand(_Command):
    """Fly these waypoints in order (replacing the goal queue)."""

    type: Literal["mission"]
    waypoints: list[Waypoint] = Field(min_length=1, max_length=MAX_WAYPOINTS)


class HoldCommand(_Command):
    """Brake and hold where the vehicle is."""

    type: Literal["hold"]


class ResumeCommand(_Command):
    """Continue to the active goal after a hold."""

    type: Literal["resume"]


class LandCommand(_Command):
    """Land where the vehicle is."""

    type: Literal["land"]


class RtlCommand(_Command):
    """Return to launch and land."""

    type: Literal["rtl"]


class AbortCommand(_Command):
    """Brake and hold at once, dropping the remaining goals."""

    type: Literal["abort"]


class SetSpeedCommand(_Command):
    """Change the cruise speed, m/s."""

    type: Literal["set_speed"]
    speed_mps: Speed


Command = Annotated[
    TakeoffCommand
    | GotoCommand
    | MissionCommand
    | HoldCommand
    | ResumeCommand
    | LandCommand
    | RtlCommand
    | AbortCommand
    | SetSpeedCommand,
    Field(discriminator="type"),
]
COMMAND_TYPES = (
    "takeoff",
    "goto",
    "mission",
    "hold",
    "resume",
    "land",
    "rtl",
    "abort",
    "set_speed",
)
_COMMAND = TypeAdapter(Command)


@dataclass(frozen=True, slots=True)
class Rejection:
    """A payload that is not a valid command: the id and type when they could be read."""

    command_id: str | None
    command_type: str | None
    reason: str


def parse_command(
    payload: bytes, *, max_payload_bytes: int = DEFAULT_MAX_PAYLOAD_BYTES
) -> Command | Rejection:
    """The command in `payload` (UTF-8 JSON), or why it is refused. Never raises."""
    try:
        return _parse(bytes(payload), max_payload_bytes)
    except Exception as e:  # the contract: hostile input never escapes as an exception
        return Rejection(None, None, f"unreadable command ({type(e).__name__})")


def _parse(payload: bytes, max_payload_bytes: int) -> Command | Rejection:
    if len(payload) > max_payload_bytes:
        return Rejection(
            None,
            None,
            f"payload of {len(payload)} bytes exceeds the limit of {max_payload_bytes} bytes",
        )
    try:  # NaN and Infinity literals are read here so that the ack can name the command
        value = pydantic_core.from_json(payload, allow_inf_nan=True)
    except ValueError as e:
        return Rejection(None, None, _clip(f"not valid JSON: {e}"))
    if not isinstance(value, dict):
        return Rejection(None, None, f"a command is a JSON object, got {_json_kind(value)}")
    raw_id, raw_type = value.get("id"), value.get("type")
    command_id = (
        raw_id if isinstance(raw_id, str) and re.fullmatch(COMMAND_ID_PATTERN, raw_id) else None
    )
    command_type = raw_type if raw_type in COMMAND_TYPES else None
    version = value.get("v")
    if version != PROTOCOL_VERSION or isinstance(version, bool):
        said = "no protocol version" if "v" not in value else f"protocol version {_show(version)}"
        reason = f'{said}: this vehicle speaks "v": {PROTOCOL_VERSION}'
        return Rejection(command_id, command_type, reason)
    if command_type is None:
        said = "no command type" if "type" not in value else f"unknown type {_show(raw_type)}"
        return Rejection(command_id, None, f"{said}; expected one of: {', '.join(COMMAND_TYPES)}")
    try:
        return _COMMAND.validate_json(payload)
    except ValidationError as e:
        return Rejection(command_id, command_type, validation_reason(e))


def validation_reason(error: ValidationError, max_errors: int = 3) -> str:
    """A readable summary of pydantic's errors: `field.path: message; ...` (clipped)."""
    parts = []
    for item in error.errors(include_url=False, include_input=False)[:max_errors]:
        path = ".".join(_show_key(k) for k in item["loc"] if k not in _TAGS)
        message = item["msg"].removeprefix("Value error, ")
        if item["type"] == "extra_forbidden":
            message = f"unknown field {path}"
        elif item["type"] == "finite_number":
            message = f"{path}: NaN and infinities are not allowed"
        elif path == "id" and item["type"] != "missing":
            message = "id: use 1-64 characters of A-Z a-z 0-9 . _ : -"
        elif path:
            message = f"{path}: {message}"
        parts.append(message)
    more = error.error_count() - max_errors
    if more > 0:
        parts.append(f"and {more} more")
    return _clip("; ".join(parts))


_TAGS = frozenset({*COMMAND_TYPES, "ned", "geo"})


def _show_key(key: object) -> str:
    """A location key as safe text (a field name an attacker chose is clipped and escaped)."""
    text = str(key)
    text = text if text.isprintable() else text.encode("unicode_escape").decode("ascii")
    return text if len(text) <= 40 else text[:37] + "..."


def _show(value: object) -> str:
    """A JSON value for a message, clipped."""
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _json_kind(value: object) -> str:
    for kind, name in ((list, "an array"), (str, "a string"), (bool, "a boolean")):
        if isinstance(value, kind):
            return name
    return "null" if value is None else "a number"


def _clip(text: str) -> str:
    return text if len(text) <= MAX_REASON_CHARS else text[: MAX_REASON_CHARS - 3] + "..."


# ---------------------------------------------------------------------------- vehicle -> ground


def _finite_or_none(value: Any) -> Any:
    """Unknown (NaN, inf) numbers travel as null."""
    if isinstance(value, (float, np.floating)) and not math.isfinite(value):
        return None
    return value


def _vector_or_none(value: Any) -> Any:
    """A vector with any non-finite component is unknown as a whole (null)."""
    if value is None:
        return None
    values = tuple(float(x) for x in np.asarray(value, dtype=np.float64).reshape(-1))
    return values if all(math.isfinite(x) for x in values) else None


MaybeFloat = Annotated[float | None, BeforeValidator(_finite_or_none)]
MaybeVec3 = Annotated[tuple[float, float, float] | None, BeforeValidator(_vector_or_none)]
_OUTGOING = ConfigDict(extra="ignore", frozen=True)  # newer vehicles may add fields


class Ack(BaseModel):
    """The one answer to a command: accepted, or rejected with a reason a person can act on.

    `id` is the command's (None when the payload had no readable id), `command` its type,
    `stamp_s` the vehicle's process clock when it answered, s.
    """

    model_config = _OUTGOING

    v: int = PROTOCOL_VERSION
    id: str | None
    command: str | None
    accepted: bool
    reason: str = ""
    stamp_s: MaybeFloat = None

    @classmethod
    def accept(cls, command: Command, now_s: float, detail: str = "") -> Ack:
        """`command` accepted (with an optional note)."""
        return cls(id=command.id, command=command.type, accepted=True, reason=detail, stamp_s=now_s)

    @classmethod
    def reject(cls, command: Command | Rejection, reason: str, now_s: float) -> Ack:
        """`command` refused because of `reason`."""
        if isinstance(command, Rejection):
            command_id, command_type = command.command_id, command.command_type
        else:
            command_id, command_type = command.id, command.type
        return cls(
            id=command_id,
            command=command_type,
            accepted=False,
            reason=_clip(reason),
            stamp_s=now_s,
        )


class BatteryReport(BaseModel):
    """Battery voltage (V) and remaining charge (0..1); null where not reported."""

    model_config = _OUTGOING

    voltage_v: MaybeFloat = None
    remaining_frac: MaybeFloat = None


class StageReport(BaseModel):
    """One stage of the process: healthy or not, its output rate (Hz), the latency from its
    input's sample time to its output (ms) and the age of its last output (s)."""

    model_config = _OUTGOING

    ok: bool
    rate_hz: MaybeFloat = None
    latency_ms: MaybeFloat = None
    age_s: MaybeFloat = None
    detail: str = ""


class GoalReport(BaseModel):
    """The goal being flown: index in the queue of `count`, its position (local NED, m) and the
    id of the command that set it."""

    model_config = _OUTGOING

    index: int
    count: int
    target_ned_m: MaybeVec3 = None
    command_id: str | None = None


class Status(BaseModel):
    """The vehicle's retained status (`wireavoid/<id>/status`); null where unknown.

    `stamp_s` is the vehicle's process clock, s; `mode` the mission state, `flight_mode`
    PX4's; positions and velocities are local NED (m, m/s), `yaw_rad` from north.
    """

    model_config = _OUTGOING

    v: int = PROTOCOL_VERSION
    vehicle_id: str = ""
    online: bool = True
    stamp_s: MaybeFloat = None
    mode: str | None = None
    failsafe: str | None = None
    flight_mode: str | None = None
    armed: bool | None = None
    in_air: bool | None = None
    position_ned_m: MaybeVec3 = None
    velocity_ned_mps: MaybeVec3 = None
    yaw_rad: MaybeFloat = None
    speed_mps: MaybeFloat = None
    active_goal: GoalReport | None = None
    planner_state: str | None = None
    battery: BatteryReport | None = None
    stages: dict[str, StageReport] = Field(default_factory=dict)


class Event(BaseModel):
    """Something that happened (`wireavoid/<id>/events`): a state change, a warning, a link
    event. `state` is the mission state after it; `stamp_s` the process clock, s."""

    model_config = _OUTGOING

    v: int = PROTOCOL_VERSION
    vehicle_id: str = ""
    stamp_s: MaybeFloat = None
    kind: str
    severity: Literal["info", "warning", "error"] = "info"
    state: str | None = None
    text: str


def offline_status(vehicle_id: str) -> Status:
    """The status a vehicle that drops off leaves behind (its Last Will); a clean stop leaves
    its last status instead, marked offline."""
    return Status(vehicle_id=vehicle_id, online=False)
