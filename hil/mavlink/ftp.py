"""A read-only MAVFTP server (FILE_TRANSFER_PROTOCOL) over in-memory files, as PX4 answers it.

Ground stations and MAVSDK fetch component metadata this way (COMPONENT_METADATA points at
`mftp://...`). Supported: TerminateSession, ResetSessions, ListDirectory, OpenFileRO, ReadFile,
BurstReadFile, CalcFileCRC32; writing is refused (PX4 would write its SD card, the hil vehicle
has none). Payload layout and opcodes from the MAVLink FTP specification: seq u16, session u8,
opcode u8, size u8, req_opcode u8, burst_complete u8, padding u8, offset u32, data[239].
"""

from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass

HEADER = struct.Struct("<HBBBBBBI")
DATA_MAX = 239
PAYLOAD_SIZE = 251

OP_TERMINATE_SESSION = 1
OP_RESET_SESSIONS = 2
OP_LIST_DIRECTORY = 3
OP_OPEN_FILE_RO = 4
OP_READ_FILE = 5
OP_CALC_FILE_CRC32 = 14
OP_BURST_READ_FILE = 15
OP_ACK = 128
OP_NAK = 129

ERR_FAIL = 1
ERR_INVALID_SESSION = 4
ERR_EOF = 6
ERR_UNKNOWN_COMMAND = 7
ERR_FILE_NOT_FOUND = 10


@dataclass(frozen=True)
class FtpRequest:
    """A decoded request payload."""

    seq: int
    session: int
    opcode: int
    size: int
    offset: int
    data: bytes

    @classmethod
    def decode(cls, payload: bytes | list[int]) -> FtpRequest:
        raw = bytes(payload).ljust(PAYLOAD_SIZE, b"\0")
        seq, session, opcode, size, _req, _burst, _pad, offset = HEADER.unpack_from(raw)
        data = raw[HEADER.size : HEADER.size + min(size, DATA_MAX)]
        return cls(seq, session, opcode, size, offset, data)


def _reply(
    request: FtpRequest,
    opcode: int,
    data: bytes = b"",
    *,
    offset: int = 0,
    session: int | None = None,
    burst_complete: bool = False,
    index: int = 0,
) -> bytes:
    """A reply payload; the `index`-th packet of a burst carries sequence seq + 1 + index."""
    header = HEADER.pack(
        (request.seq + 1 + index) & 0xFFFF,
        request.session if session is None else session,
        opcode,
        len(data),
        request.opcode,
        1 if burst_complete else 0,
        0,
        offset,
    )
    return (header + data).ljust(PAYLOAD_SIZE, b"\0")


def _normalise(path: bytes) -> str:
    return path.split(b"\0", 1)[0].decode(errors="replace").strip("/")


class FtpServer:
    """Answers FTP request payloads from `files` (path without leading '/' -> bytes)."""

    def __init__(self, files: dict[str, bytes]) -> None:
        self._files = {k.strip("/"): v for k, v in files.items()}
        self._sessions: dict[int, str] = {}

    def handle(self, payload: bytes | list[int]) -> list[bytes]:
        """The reply payloads (251 bytes each) to one request payload."""
        r = FtpRequest.decode(payload)
        if r.opcode == OP_TERMINATE_SESSION:
            self._sessions.pop(r.session, None)
            return [_reply(r, OP_ACK)]
        if r.opcode == OP_RESET_SESSIONS:
            self._sessions.clear()
            return [_reply(r, OP_ACK)]
        if r.opcode == OP_OPEN_FILE_RO:
            path = _normalise(r.data)
            if path not in self._files:
                return [_reply(r, OP_NAK, bytes([ERR_FILE_NOT_FOUND]))]
            session = next(i for i in range(256) if i not in self._sessions)
            self._sessions[session] = path
            size = struct.pack("<I", len(self._files[path]))
            return [_reply(r, OP_ACK, size, session=session)]
        if r.opcode in (OP_READ_FILE, OP_BURST_READ_FILE):
            return self._read(r)
        if r.opcode == OP_CALC_FILE_CRC32:
            path = _normalise(r.data)
            if path not in self._files:
                return [_reply(r, OP_NAK, bytes([ERR_FILE_NOT_FOUND]))]
            return [_reply(r, OP_ACK, struct.pack("<I", zlib.crc32(self._files[path])))]
        if r.opcode == OP_LIST_DIRECTORY:
            return [self._list(r)]
        return [_reply(r, OP_NAK, bytes([ERR_UNKNOWN_COMMAND]))]

    def _read(self, r: FtpRequest) -> list[bytes]:
        path = self._sessions.get(r.session)
        if path is None:
            return [_reply(r, OP_NAK, bytes([ERR_INVALID_SESSION]))]
        content = self._files[path]
        if r.offset >= len(content):
            return [_reply(r, OP_NAK, bytes([ERR_EOF]))]
        if r.opcode == OP_READ_FILE:
            chunk = content[r.offset : r.offset + min(r.size or DATA_MAX, DATA_MAX)]
            return [_reply(r, OP_ACK, chunk, offset=r.offset)]
        replies = []
        offset = r.offset
        while offset < len(content):
            chunk = content[offset : offset + DATA_MAX]
            last = offset + len(chunk) >= len(content)
            replies.append(
                _reply(r, OP_ACK, chunk, offset=offset, burst_complete=last, index=len(replies))
            )
            offset += len(chunk)
        return replies

    def _list(self, r: FtpRequest) -> bytes:
        directory = _normalise(r.data)
        prefix = directory + "/" if directory else ""
        entries: list[bytes] = []
        for path, content in sorted(self._files.items()):
            if not path.startswith(prefix):
                continue
            rest = path[len(prefix) :]
            if "/" in rest:
                entry = b"D" + rest.split("/", 1)[0].encode()
            else:
                entry = b"F" + rest.encode() + b"\t" + str(len(content)).encode()
            if entry not in entries:
                entries.append(entry)
        entries = entries[r.offset :]
        if not entries:
            return _reply(r, OP_NAK, bytes([ERR_EOF]))
        data = b""
        for entry in entries:
            if len(data) + len(entry) + 1 > DATA_MAX:
                break
            data += entry + b"\0"
        return _reply(r, OP_ACK, data)
