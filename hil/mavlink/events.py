"""PX4's events protocol on the hil vehicle: EVENT messages a ground station or MAVSDK decodes.

PX4 reports mode changes, arming results, failsafes and landings as EVENTs (MAVLink 410) whose
meaning is in a metadata file the receiver downloads over MAVFTP (announced by
COMPONENT_METADATA, `component_general.json`). The hil vehicle sends the events of PX4's own
definitions (`data/px4_events.json`, a subset of PX4's `all_events.json`) with PX4's ids and
argument encodings, so MAVSDK's events plugin shows "Armed by external command" against it as
against PX4. `EventSender` numbers them (16-bit sequence), keeps the recent ones for
REQUEST_EVENT and answers what it no longer has with RESPONSE_EVENT_ERROR.
"""

from __future__ import annotations

import json
import lzma
import struct
import zlib
from collections import OrderedDict
from dataclasses import dataclass
from importlib import resources
from typing import Any

from hil.mavlink import extra_messages as xm
from hil.vehicle.px4_modes import Px4Event, Px4Mode, Px4Vehicle

_ARG_FORMATS = {
    "uint8_t": "B",
    "int8_t": "b",
    "uint16_t": "H",
    "int16_t": "h",
    "uint32_t": "I",
    "int32_t": "i",
    "uint64_t": "Q",
    "int64_t": "q",
    "float": "f",
}
# PX4's log levels (events::Log) of the events sent; Info unless listed
_LOG_LEVELS = {
    "commander_failsafe_enter_generic": 2,
    "commander_arm_denied_resolve_failures": 2,
    "commander_modeswitch_not_avail": 2,
    "commander_disarm_denied_not_landed": 2,
}
LOG_INFO = 6
COMPONENT_GENERAL_PATH = "etc/extras/component_general.json.xz"
EVENTS_METADATA_PATH = "etc/extras/px4_events.json.xz"
COMPONENT_METADATA_TYPE_EVENTS = 4  # COMP_METADATA_TYPE_EVENTS


@dataclass(frozen=True)
class EventDefinition:
    """One event: its MAVLink id and the struct format of its arguments."""

    event_id: int
    name: str
    arguments_format: str


def _load_definitions() -> tuple[dict[str, EventDefinition], bytes]:
    raw = resources.files("hil.mavlink").joinpath("data/px4_events.json").read_bytes()
    metadata = json.loads(raw)
    definitions = {}
    for component_id, component in metadata["components"].items():
        namespace = component["namespace"]
        enums = component.get("enums", {})
        for group in component["event_groups"].values():
            for sub_id, event in group["events"].items():
                fmt = "<"
                for argument in event.get("arguments", []):
                    kind = argument["type"].removeprefix(namespace + "::")
                    fmt += _ARG_FORMATS[enums[kind]["type"] if kind in enums else kind]
                event_id = (int(component_id) << 24) | int(sub_id)
                definitions[event["name"]] = EventDefinition(event_id, event["name"], fmt)
    return definitions, raw


DEFINITIONS, _EVENTS_JSON = _load_definitions()


def metadata_files() -> dict[str, bytes]:
    """The files the vehicle serves over MAVFTP: the general metadata and the events'."""
    events_xz = lzma.compress(_EVENTS_JSON)
    general = {
        "version": 1,
        "metadataTypes": [
            {
                "type": COMPONENT_METADATA_TYPE_EVENTS,
                "uri": f"mftp://{EVENTS_METADATA_PATH}",
                "fileCrc": zlib.crc32(events_xz),
            }
        ],
    }
    return {
        COMPONENT_GENERAL_PATH: lzma.compress(json.dumps(general).encode()),
        EVENTS_METADATA_PATH: events_xz,
    }


def general_metadata_uri_and_crc() -> tuple[str, int]:
    """(uri, CRC32) of the general metadata file for COMPONENT_METADATA."""
    return f"mftp://{COMPONENT_GENERAL_PATH}", zlib.crc32(metadata_files()[COMPONENT_GENERAL_PATH])


class EventSender:
    """Numbers and encodes events; keeps the last `history` for re-requests."""

    def __init__(self, history: int = 64) -> None:
        self.sequence = 0  # the sequence of the next event
        self._sent: OrderedDict[int, xm.ExtraMessage] = OrderedDict()
        self._history = history

    @property
    def last_sequence(self) -> int:
        """The sequence of the newest event sent (CURRENT_EVENT_SEQUENCE)."""
        return (self.sequence - 1) & 0xFFFF

    def encode(
        self, event: Px4Event, time_boot_ms: int, log_level: int | None = None
    ) -> xm.ExtraMessage:
        """The EVENT message of `event`, numbered; raises KeyError for an unknown name."""
        definition = DEFINITIONS[event.name]
        arguments = struct.pack(definition.arguments_format, *event.arguments)
        level = _LOG_LEVELS.get(event.name, LOG_INFO) if log_level is None else log_level
        msg = xm.message(
            xm.EVENT,
            id=definition.event_id,
            event_time_boot_ms=time_boot_ms & 0xFFFFFFFF,
            sequence=self.sequence,
            destination_component=0,
            destination_system=0,
            log_levels=(level << 4) | level,
            arguments=arguments.ljust(40, b"\0"),
        )
        self._sent[self.sequence] = msg
        while len(self._sent) > self._history:
            self._sent.popitem(last=False)
        self.sequence = (self.sequence + 1) & 0xFFFF
        return msg

    def requested(self, fields: dict[str, Any], target: tuple[int, int]) -> list[xm.ExtraMessage]:
        """Answers to REQUEST_EVENT: the events still kept, an error for the others."""
        out: list[xm.ExtraMessage] = []
        first, last = fields["first_sequence"], fields["last_sequence"]
        count = ((last - first) & 0xFFFF) + 1
        oldest = next(iter(self._sent), self.sequence)
        for k in range(min(count, self._history)):
            seq = (first + k) & 0xFFFF
            if seq in self._sent:
                out.append(self._sent[seq])
            else:
                out.append(
                    xm.message(
                        xm.RESPONSE_EVENT_ERROR,
                        target_system=target[0],
                        target_component=target[1],
                        sequence=seq,
                        sequence_oldest_available=oldest,
                        reason=xm.MAV_EVENT_ERROR_REASON_UNAVAILABLE,
                    )
                )
        return out


# PX4 health_component_t bits and navigation_mode_group_t bits (the events' enums)
COMPONENT_BITS = {
    "absolute_pressure": 1 << 1,
    "gps": 1 << 3,
    "remote_control": 1 << 7,
    "battery": 1 << 11,
    "communication_links": 1 << 12,
    "attitude_estimate": 1 << 16,
    "local_position_estimate": 1 << 17,
    "system": 1 << 20,
    "global_position_estimate": 1 << 24,
    "magnetometer": 1 << 27,
    "accel": 1 << 28,
    "gyro": 1 << 29,
}
MODE_GROUP_BITS = {
    Px4Mode.HOLD: 1 << 4,
    Px4Mode.RTL: 1 << 5,
    Px4Mode.OFFBOARD: 1 << 14,
    Px4Mode.TAKEOFF: 1 << 17,
    Px4Mode.LAND: 1 << 18,
}
_MANUAL_GROUPS = (1 << 0) | (1 << 1) | (1 << 2) | (1 << 10) | (1 << 15)  # need sticks
_ALL_GROUPS = _MANUAL_GROUPS | sum(MODE_GROUP_BITS.values())
_EVERY_MODE = 0xFFFFFFFF
_LOG_ERROR, _LOG_WARNING = 3, 4


@dataclass(frozen=True)
class HealthReport:
    """PX4's health and arming check report: the problems (event, log level), the summaries."""

    problems: tuple[tuple[Px4Event, int], ...]
    present: int
    error: int
    warning: int
    can_arm: int
    can_run: int

    def events(self) -> list[tuple[Px4Event, int]]:
        """The report as PX4 sends it (libevents' order): the arming-check summary, the
        problems, the health summary."""
        summary_arming = Px4Event(
            "commander_arming_check_summary",
            (0, self.error, self.warning, self.can_arm, self.can_run),
        )
        summary_health = Px4Event(
            "commander_health_summary", (0, self.present, self.error, self.warning)
        )
        return [(summary_arming, LOG_INFO), *self.problems, (summary_health, LOG_INFO)]


def health_report(vehicle: Px4Vehicle) -> HealthReport:
    """What PX4's commander reports for the hil vehicle now: no RC ever (a warning, the
    stick modes cannot run), no attitude before the estimator converged, and no offboard
    signal when Offboard is chosen without fresh setpoints (an error: cannot arm or run it)."""
    present = sum(COMPONENT_BITS.values())
    remote = COMPONENT_BITS["remote_control"]
    problems: list[tuple[Px4Event, int]] = [
        (
            # as PX4 reports it: for every mode (a warning), though only stick modes need it
            Px4Event("check_modes_manual_control", (_EVERY_MODE, remote.bit_length() - 1)),
            _LOG_WARNING,
        )
    ]
    error, warning = 0, remote
    can_run = _ALL_GROUPS & ~_MANUAL_GROUPS
    if not vehicle.healthy:
        attitude = COMPONENT_BITS["attitude_estimate"]
        problems.append(
            (Px4Event("check_modes_attitude", (_ALL_GROUPS, attitude.bit_length() - 1)), _LOG_ERROR)
        )
        error |= attitude
        can_run = 0
    offboard = MODE_GROUP_BITS[Px4Mode.OFFBOARD]
    if not vehicle.offboard_setpoint_fresh(vehicle.params.offboard_entry_max_age_s):
        system = COMPONENT_BITS["system"]
        problems.append(
            (
                Px4Event("check_modes_offboard_signal", (offboard, system.bit_length() - 1)),
                _LOG_ERROR,
            )
        )
        can_run &= ~offboard
    can_arm = can_run & ~(MODE_GROUP_BITS[Px4Mode.RTL] | MODE_GROUP_BITS[Px4Mode.LAND])
    if vehicle.time_s < vehicle.params.arm_denied_after_boot_s:
        can_arm = 0
    return HealthReport(tuple(problems), present, error, warning, can_arm, can_run)
