"""PX4's full parameter table on the hil vehicle: 888 names, PX4's types and defaults.

`data/px4_parameters.json` is every parameter a fresh PX4 SITL (airframe 10040) reports over
MAVLink, with its MAVLink type (INT32 or REAL32). `Px4ParameterTable` serves them: the ones a
`VehicleSimParams` field mirrors (its `px4` name) read and write that field, so setting
COM_OBL_RC_ACT changes what the simulated failsafe does; the others are stored and echoed like
PX4 does, without effect, so a ground station sees a complete PX4. Integer parameters travel
byte-wise in PARAM_VALUE's float (MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE), as PX4 sends
them.
"""

from __future__ import annotations

import contextlib
import json
import math
import struct
from dataclasses import dataclass
from importlib import resources

from pydantic import ValidationError

from hil.vehicle.params import VehicleSimParams, px4_parameter_table

MAV_PARAM_TYPE_INT32 = 6
MAV_PARAM_TYPE_REAL32 = 9


def px4_defaults() -> dict[str, tuple[float | int, int]]:
    """PX4 parameter name -> (default value, MAVLink type), from the PX4 SITL snapshot."""
    raw = resources.files("hil.vehicle").joinpath("data/px4_parameters.json").read_text()
    return {name: (value, kind) for name, (value, kind) in json.loads(raw)["parameters"].items()}


def encode_param_value(value: float | int, param_type: int) -> float:
    """PARAM_VALUE.param_value: the float itself, or an INT32's bytes read as a float."""
    if param_type == MAV_PARAM_TYPE_INT32:
        return struct.unpack("<f", struct.pack("<i", int(value)))[0]
    return float(value)


def decode_param_value(raw: float, param_type: int) -> float | int:
    """The inverse of `encode_param_value` (PARAM_SET.param_value)."""
    if param_type == MAV_PARAM_TYPE_INT32:
        return struct.unpack("<i", struct.pack("<f", raw))[0]
    return float(raw)


@dataclass(frozen=True)
class ParameterValue:
    """One parameter as PARAM_VALUE reports it."""

    name: str
    value: float | int
    param_type: int
    index: int
    count: int


class Px4ParameterTable:
    """PX4's parameters, the simulated ones live in `params` (updated in place)."""

    def __init__(self, params: VehicleSimParams) -> None:
        self.params = params
        self._fields = px4_parameter_table()
        defaults = px4_defaults()
        self._types = {name: kind for name, (_value, kind) in defaults.items()}
        self._stored: dict[str, float | int] = {n: v for n, (v, _k) in defaults.items()}
        for name, field in self._fields.items():
            kind = (
                MAV_PARAM_TYPE_INT32
                if isinstance(getattr(params, field), int)
                else MAV_PARAM_TYPE_REAL32
            )
            self._types.setdefault(name, kind)
        self.names = sorted(self._types)
        self._index = {name: i for i, name in enumerate(self.names)}

    def __len__(self) -> int:
        return len(self.names)

    def index_of(self, name: str) -> int | None:
        """The index of `name`, None when PX4 has no such parameter."""
        return self._index.get(name)

    def get(self, name: str) -> ParameterValue:
        """The current value of `name` (KeyError when unknown)."""
        kind = self._types[name]
        field = self._fields.get(name)
        value = getattr(self.params, field) if field is not None else self._stored[name]
        value = int(value) if kind == MAV_PARAM_TYPE_INT32 else float(value)
        return ParameterValue(name, value, kind, self._index[name], len(self.names))

    def at(self, index: int) -> ParameterValue:
        """The parameter at `index` of PARAM_REQUEST_LIST's order."""
        return self.get(self.names[index])

    def set(self, name: str, raw: float) -> ParameterValue:
        """PARAM_SET: store the decoded value if valid (bounds of the field); the result."""
        kind = self._types[name]
        if kind == MAV_PARAM_TYPE_REAL32 and not math.isfinite(raw):
            return self.get(name)
        value = decode_param_value(raw, kind)
        field = self._fields.get(name)
        if field is None:
            self._stored[name] = value
        else:
            # validated against the field's bounds; the params object is shared with the
            # simulation, so it changes in place; PX4 echoes the old value of a rejected set
            with contextlib.suppress(ValidationError):
                setattr(self.params, field, value)
        return self.get(name)
