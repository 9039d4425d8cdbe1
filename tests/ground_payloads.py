"""Hypothesis strategies of ground-station payloads: valid commands, and hostile ones that the
vehicle must refuse (each hostile mutation is known to be invalid), and plain junk.

`payloads()` draws `(payload bytes, expected)` with expected "valid", "invalid" or "junk"
(random bytes or JSON whose validity is left to the oracle).
"""

from __future__ import annotations

import json
import math
from typing import Any

from hypothesis import strategies as st

from companion.ground.protocol import COMMAND_TYPES, DEFAULT_MAX_PAYLOAD_BYTES

_ids = st.from_regex(r"\A[A-Za-z0-9._:-]{1,64}\Z", fullmatch=True)
_speed = st.floats(0.01, 20.0)
_ned = st.fixed_dictionaries(
    {
        "north_m": st.floats(-1000, 1000),
        "east_m": st.floats(-1000, 1000),
        "down_m": st.floats(-500, 50),
    }
)
_geo = st.fixed_dictionaries(
    {
        "lat_deg": st.floats(-89.0, 89.0),
        "lon_deg": st.floats(-179.0, 179.0),
        "altitude_m": st.floats(-10, 500),
    }
)


@st.composite
def _waypoint(draw: st.DrawFn) -> dict[str, Any]:
    waypoint: dict[str, Any] = {"target": draw(st.one_of(_ned, _geo))}
    if draw(st.booleans()):
        waypoint["speed_mps"] = draw(_speed)
    yaw = draw(st.sampled_from([None, "motion", "goal", "fixed"]))
    if yaw is not None:
        waypoint["yaw"] = yaw
    if yaw == "fixed":
        waypoint["yaw_rad"] = draw(st.floats(-math.pi, math.pi))
    return waypoint


@st.composite
def valid_commands(draw: st.DrawFn) -> dict[str, Any]:
    """A valid command of any type, as a JSON object."""
    kind = draw(st.sampled_from(COMMAND_TYPES))
    command: dict[str, Any] = {"v": 1, "id": draw(_ids), "type": kind}
    if kind == "takeoff":
        command["altitude_m"] = draw(st.floats(0.5, 100.0))
    elif kind == "goto":
        command.update(draw(_waypoint()))
    elif kind == "mission":
        command["waypoints"] = draw(st.lists(_waypoint(), min_size=1, max_size=5))
    elif kind == "set_speed":
        command["speed_mps"] = draw(_speed)
    return command


def _numeric_paths(value: Any, path: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    """Paths to every number in a JSON value (not the version)."""
    if isinstance(value, dict):
        return [p for k, v in value.items() if k != "v" for p in _numeric_paths(v, (*path, k))]
    if isinstance(value, list):
        return [p for i, v in enumerate(value) for p in _numeric_paths(v, (*path, i))]
    return [path] if isinstance(value, float) else []


def _set(value: Any, path: tuple[Any, ...], new: Any) -> None:
    for key in path[:-1]:
        value = value[key]
    value[path[-1]] = new


_NON_FINITE = ["NaN", "Infinity", "-Infinity", "1e999", "-1e999"]
_OUT_OF_RANGE = {
    "speed_mps": [0.0, -1.0, 20.5, 1e6],
    "altitude_m": [1e5, -1e5],
    "lat_deg": [90.5, -91.0],
    "lon_deg": [180.5, -181.0],
    "north_m": [1e6],
    "east_m": [-1e6],
    "down_m": [1e5],
    "yaw_rad": [7.0, -7.0],
}
_REQUIRED = {
    "takeoff": "altitude_m",
    "goto": "target",
    "mission": "waypoints",
    "set_speed": "speed_mps",
}
_BAD_IDS = ["", "x" * 65, "a b", "a/b", "a+b", "#", "\u00e9t\u00e9", "a\nb", None, 7, ["a"]]


@st.composite
def hostile(draw: st.DrawFn) -> bytes:
    """A payload built from a valid command by a mutation that makes it invalid."""
    command = draw(valid_commands())
    mutation = draw(
        st.sampled_from(
            [
                "non_finite",
                "wrong_type",
                "out_of_range",
                "unknown_field",
                "version",
                "type",
                "id",
                "missing",
                "oversized",
                "truncated",
                "not_object",
                "deep",
            ]
        )
    )
    numbers = _numeric_paths(command)
    if mutation in ("non_finite", "wrong_type", "out_of_range") and not numbers:
        mutation = "unknown_field"
    if mutation == "non_finite":
        marker = "__NON_FINITE__"
        _set(command, draw(st.sampled_from(numbers)), marker)
        return (
            json.dumps(command).replace(f'"{marker}"', draw(st.sampled_from(_NON_FINITE))).encode()
        )
    if mutation == "wrong_type":
        wrong = st.one_of(st.text(max_size=5), st.booleans(), st.lists(st.integers()))
        _set(command, draw(st.sampled_from(numbers)), draw(wrong))
    elif mutation == "out_of_range":
        candidates = [p for p in numbers if p[-1] in _OUT_OF_RANGE]
        if not candidates:
            command["v"] = 2
        else:
            path = draw(st.sampled_from(candidates))
            _set(command, path, draw(st.sampled_from(_OUT_OF_RANGE[path[-1]])))
    elif mutation == "unknown_field":
        key = "x_" + draw(st.text(max_size=30))  # no field of any command starts with x_
        command[key] = draw(st.one_of(st.integers(), st.text(max_size=10), st.none()))
    elif mutation == "version":
        command["v"] = draw(st.sampled_from([0, 2, "1", 1.5, True, None, [1]]))
    elif mutation == "type":
        command["type"] = draw(
            st.one_of(st.text(max_size=12).filter(lambda t: t not in COMMAND_TYPES), st.integers())
        )
    elif mutation == "id":
        command["id"] = draw(st.sampled_from(_BAD_IDS))
    elif mutation == "missing":
        own = _REQUIRED.get(command["type"])
        del command[draw(st.sampled_from(["v", "id", "type", *([own] if own else [])]))]
    elif mutation == "oversized":
        text = json.dumps(command)
        return (text[:-1] + " " * DEFAULT_MAX_PAYLOAD_BYTES + "}").encode()
    elif mutation == "truncated":
        text = json.dumps(command).encode()
        return text[: draw(st.integers(0, len(text) - 1))]
    elif mutation == "not_object":
        return json.dumps(draw(st.sampled_from([[command], command["type"], 1, None]))).encode()
    elif mutation == "deep":
        depth = draw(st.integers(100, 5000))
        command[draw(st.sampled_from(["target", "nested"]))] = "@"
        return json.dumps(command).replace('"@"', "[" * depth + "]" * depth).encode()
    return json.dumps(command).encode()


_json_values = st.recursive(
    st.none() | st.booleans() | st.floats(allow_nan=False) | st.integers() | st.text(max_size=20),
    lambda children: (
        st.lists(children, max_size=4) | st.dictionaries(st.text(max_size=10), children, max_size=4)
    ),
    max_leaves=20,
)


def payloads() -> st.SearchStrategy[tuple[bytes, str]]:
    """(payload, expected): "valid", "invalid" (must be refused) or "junk" (left to the oracle)."""
    return st.one_of(
        valid_commands().map(lambda c: (json.dumps(c).encode(), "valid")),
        hostile().map(lambda p: (p, "invalid")),
        st.binary(max_size=300).map(lambda p: (p, "junk")),
        _json_values.map(lambda v: (json.dumps(v).encode(), "junk")),
    )
