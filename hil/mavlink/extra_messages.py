"""MAVLink 2 messages PX4 speaks that pymavlink's bundled dialect lacks, packed and parsed here.

pymavlink 2.4 ships a common.xml without the events protocol (EVENT 410,
CURRENT_EVENT_SEQUENCE 411, REQUEST_EVENT 412, RESPONSE_EVENT_ERROR 413), COMPONENT_METADATA
(397) and PROTOCOL_VERSION (300). Their fields and CRC_EXTRA follow MAVLink's common.xml (the
CRC_EXTRA is computed from the definition exactly as mavgen does; `crc_extra` checks it).
Outgoing ones are `MAVLink_message` subclasses that pymavlink frames, sequences and signs like
any other; incoming ones arrive as pymavlink's `UNKNOWN_<id>` and `parse_unknown` reads them.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Any

from pymavlink.generator.mavcrc import x25crc

from hil.mavlink.dialect import mavlink

_SIZES = {"uint32_t": 4, "uint16_t": 2, "uint8_t": 1, "char": 1}


def crc_extra(name: str, fields: list[tuple[str, str, int]]) -> int:
    """mavgen's CRC_EXTRA of a message: (type, name, array length) fields, in XML order."""
    crc = x25crc((name + " ").encode())
    for ftype, fname, length in sorted(fields, key=lambda f: -_SIZES[f[0]]):
        crc.accumulate((ftype + " ").encode())
        crc.accumulate((fname + " ").encode())
        if length:
            crc.accumulate([length])
    return (crc.crc & 0xFF) ^ (crc.crc >> 8)


@dataclass(frozen=True)
class _Definition:
    msg_id: int
    name: str
    fields: list[tuple[str, str, int]]  # XML order
    wire_format: str  # struct format of the wire order (sorted by type size)
    wire_names: tuple[str, ...]

    @property
    def crc_extra(self) -> int:
        return crc_extra(self.name, self.fields)


EVENT = _Definition(
    410,
    "EVENT",
    [
        ("uint8_t", "destination_component", 0),
        ("uint8_t", "destination_system", 0),
        ("uint32_t", "id", 0),
        ("uint32_t", "event_time_boot_ms", 0),
        ("uint16_t", "sequence", 0),
        ("uint8_t", "log_levels", 0),
        ("uint8_t", "arguments", 40),
    ],
    "<IIHBBB40s",
    (
        "id",
        "event_time_boot_ms",
        "sequence",
        "destination_component",
        "destination_system",
        "log_levels",
        "arguments",
    ),
)
CURRENT_EVENT_SEQUENCE = _Definition(
    411,
    "CURRENT_EVENT_SEQUENCE",
    [("uint16_t", "sequence", 0), ("uint8_t", "flags", 0)],
    "<HB",
    ("sequence", "flags"),
)
REQUEST_EVENT = _Definition(
    412,
    "REQUEST_EVENT",
    [
        ("uint8_t", "target_system", 0),
        ("uint8_t", "target_component", 0),
        ("uint16_t", "first_sequence", 0),
        ("uint16_t", "last_sequence", 0),
    ],
    "<HHBB",
    ("first_sequence", "last_sequence", "target_system", "target_component"),
)
RESPONSE_EVENT_ERROR = _Definition(
    413,
    "RESPONSE_EVENT_ERROR",
    [
        ("uint8_t", "target_system", 0),
        ("uint8_t", "target_component", 0),
        ("uint16_t", "sequence", 0),
        ("uint16_t", "sequence_oldest_available", 0),
        ("uint8_t", "reason", 0),
    ],
    "<HHBBB",
    ("sequence", "sequence_oldest_available", "target_system", "target_component", "reason"),
)
COMPONENT_METADATA = _Definition(
    397,
    "COMPONENT_METADATA",
    [("uint32_t", "time_boot_ms", 0), ("uint32_t", "file_crc", 0), ("char", "uri", 100)],
    "<II100s",
    ("time_boot_ms", "file_crc", "uri"),
)
PROTOCOL_VERSION = _Definition(
    300,
    "PROTOCOL_VERSION",
    [
        ("uint16_t", "version", 0),
        ("uint16_t", "min_version", 0),
        ("uint16_t", "max_version", 0),
        ("uint8_t", "spec_version_hash", 8),
        ("uint8_t", "library_version_hash", 8),
    ],
    "<HHH8s8s",
    ("version", "min_version", "max_version", "spec_version_hash", "library_version_hash"),
)
_BY_ID = {
    d.msg_id: d
    for d in (
        EVENT,
        CURRENT_EVENT_SEQUENCE,
        REQUEST_EVENT,
        RESPONSE_EVENT_ERROR,
        COMPONENT_METADATA,
        PROTOCOL_VERSION,
    )
}

# RESPONSE_EVENT_ERROR reason
MAV_EVENT_ERROR_REASON_UNAVAILABLE = 0


class ExtraMessage(mavlink.MAVLink_message):
    """An outgoing message of one of the definitions above."""

    def __init__(self, definition: _Definition, **values: Any) -> None:
        super().__init__(definition.msg_id, definition.name)
        self._definition = definition
        self._fieldnames = list(definition.wire_names)
        for name in definition.wire_names:
            setattr(self, name, values[name])

    def pack(self, mav: Any, force_mavlink1: bool = False) -> bytes:
        d = self._definition
        payload = struct.pack(d.wire_format, *(getattr(self, n) for n in d.wire_names))
        return self._pack(mav, d.crc_extra, payload, force_mavlink1=force_mavlink1)


def message(definition: _Definition, **values: Any) -> ExtraMessage:
    """A message ready for `conn.mav.send(...)`."""
    return ExtraMessage(definition, **values)


def parse_unknown(msg: Any) -> tuple[_Definition, dict[str, Any]] | None:
    """(definition, fields) of a pymavlink `UNKNOWN_<id>` message of a known definition."""
    kind = msg.get_type()
    if not kind.startswith("UNKNOWN_"):
        return None
    definition = _BY_ID.get(int(kind[len("UNKNOWN_") :]))
    if definition is None:
        return None
    frame = bytes(msg.data)
    if not frame or frame[0] != 0xFD:  # MAVLink 2 only
        return None
    length = frame[1]
    payload = frame[10 : 10 + length].ljust(struct.calcsize(definition.wire_format), b"\0")
    values = struct.unpack(definition.wire_format, payload)
    return definition, dict(zip(definition.wire_names, values, strict=True))


def source_of(msg: Any) -> tuple[int, int]:
    """(system, component) of an incoming `UNKNOWN_<id>` MAVLink 2 frame."""
    frame = bytes(msg.data)
    return frame[5], frame[6]
