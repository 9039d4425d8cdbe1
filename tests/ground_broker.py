"""A real mosquitto broker for the ground-link tests, on loopback on a free port.

`Mosquitto` is the harness' broker (`hil.broker`: Debian's mosquitto, installed by .ci/run;
`start`/`stop`/`restart` keep the port). `secured()` runs the shipped configuration
(`systemd/mosquitto/wireavoid.conf`, its ACL as it is, a password file made with
mosquitto_passwd and certificates made with openssl), with only the ports and file paths
changed.
"""

from __future__ import annotations

import asyncio
import contextlib
import subprocess
import threading
import time
from collections.abc import AsyncIterator, Callable
from pathlib import Path

from companion.clock import WallClock, cancel_and_wait
from companion.ground.link import CommandHandler, GroundLink, GroundLinkHealth
from companion.ground.params import GroundParams
from companion.ground.protocol import Ack, Command, StageReport, Status
from hil.broker import Mosquitto
from hil.broker import free_tcp_port as free_port

REPO = Path(__file__).resolve().parents[1]
SHIPPED = REPO / "systemd" / "mosquitto"
PASSWORDS = {"gcs": "gcs-secret", "drone1": "drone1-secret", "drone2": "drone2-secret"}
PASSWORDS["intruder"] = "intruder-secret"  # valid credentials, no line in the ACL


def make_password_file(path: Path, passwords: dict[str, str]) -> None:
    """A mosquitto password file (hashed by mosquitto_passwd)."""
    path.write_text("")
    for user, password in passwords.items():
        subprocess.run(["mosquitto_passwd", "-b", str(path), user, password], check=True)


def _openssl(*args: object) -> None:
    subprocess.run(["openssl", *map(str, args)], check=True, capture_output=True)


EC_KEY = ("-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes")


def make_ca(folder: Path, name: str) -> tuple[Path, Path]:
    """A self-signed CA (EC P-256, two days): its certificate and key."""
    crt, key = folder / f"{name}.crt", folder / f"{name}.key"
    _openssl(
        "req", "-x509", *EC_KEY, "-keyout", key, "-out", crt, "-days", 2, "-subj", f"/CN={name}"
    )
    return crt, key


def make_certificates(folder: Path) -> dict[str, Path]:
    """A CA and the server certificate it signs for localhost / 127.0.0.1."""
    ca_crt, ca_key = make_ca(folder, "ca")
    key, csr, crt = folder / "server.key", folder / "server.csr", folder / "server.crt"
    ext = folder / "san.ext"
    ext.write_text("subjectAltName=DNS:localhost,IP:127.0.0.1\n")
    _openssl("req", *EC_KEY, "-keyout", key, "-out", csr, "-subj", "/CN=localhost")
    _openssl(
        "x509", "-req", "-in", csr, "-CA", ca_crt, "-CAkey", ca_key, "-CAcreateserial",
        "-out", crt, "-days", 2, "-extfile", ext,
    )  # fmt: skip
    return {"ca": ca_crt, "key": key, "crt": crt}


def secured(folder: Path) -> Mosquitto:
    """The shipped configuration with test ports and files (the shipped ACL unchanged)."""
    make_password_file(folder / "passwd", PASSWORDS)
    certs = make_certificates(folder)
    port, tls_port = free_port(), free_port()
    replaced = {
        "password_file": str(folder / "passwd"),
        "acl_file": str(SHIPPED / "acl"),
        "cafile": str(certs["ca"]),
        "certfile": str(certs["crt"]),
        "keyfile": str(certs["key"]),
    }
    listeners = iter((f"{port} 127.0.0.1", f"{tls_port} 127.0.0.1"))
    lines = []
    for line in (SHIPPED / "wireavoid.conf").read_text().splitlines():
        key = line.split(" ", 1)[0]
        if key == "listener":
            line = f"listener {next(listeners)}"
        elif key in replaced:
            line = f"{key} {replaced[key]}"
        lines.append(line)
    return Mosquitto(folder, "\n".join(lines), port, tls_port)


CLOCK = WallClock()


class Recorder:
    """A command handler that accepts everything and records what it was given."""

    def __init__(self) -> None:
        self.commands: list[Command] = []

    def handle(self, command: Command, now_s: float) -> Ack:
        self.commands.append(command)
        return Ack.accept(command, now_s)


class LinkThread:
    """A `GroundLink` running on its own event loop in a thread (for synchronous callers: the
    CLI runner, hypothesis). `with LinkThread(...) as link:` runs it; leaving cancels it."""

    def __init__(self, params: GroundParams, handler: CommandHandler | None = None) -> None:
        self.handler = handler or Recorder()
        self.statuses = 0
        self.link: GroundLink | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._task: asyncio.Task[None] | None = None
        self._params = params
        self._ready = threading.Event()
        self._thread = threading.Thread(target=self._main, daemon=True)

    def _status(self) -> Status:
        self.statuses += 1
        return Status(mode="hold", position_ned_m=(1.0, 2.0, -3.0))

    def _main(self) -> None:
        async def main() -> None:
            self._loop = asyncio.get_running_loop()
            self.link = GroundLink(self._params, CLOCK, self.handler, self._status)
            self._task = asyncio.ensure_future(self.link.run())
            self._ready.set()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task

        asyncio.run(main())

    def __enter__(self) -> LinkThread:
        self._thread.start()
        assert self._ready.wait(5)
        deadline = time.monotonic() + 5
        while not self.health().connected:
            assert time.monotonic() < deadline, "the link did not connect"
            time.sleep(0.01)
        return self

    def health(self) -> GroundLinkHealth:
        assert self.link is not None
        return self.link.health()

    def alive(self) -> bool:
        return self._thread.is_alive() and self._task is not None and not self._task.done()

    def __exit__(self, *exc: object) -> None:
        assert self._loop is not None and self._task is not None
        self._loop.call_soon_threadsafe(self._task.cancel)
        self._thread.join(timeout=10)


class Mqtt311Proxy:
    """A broker that speaks MQTT 3.1.1 only: it refuses an MQTT 5 CONNECT the way such brokers
    do (CONNACK return code 1, "unacceptable protocol version") and passes every other
    connection through to the real broker at `port`."""

    def __init__(self, port: int) -> None:
        self.backend_port = port
        self.refused_v5 = 0
        self.port = 0
        self._server: asyncio.Server | None = None

    async def __aenter__(self) -> Mqtt311Proxy:
        self._server = await asyncio.start_server(self._serve, "127.0.0.1", 0)
        self.port = self._server.sockets[0].getsockname()[1]
        return self

    async def __aexit__(self, *exc: object) -> None:
        assert self._server is not None
        self._server.close()

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        header = await reader.readexactly(1)
        length, multiplier, length_bytes = 0, 1, b""
        while True:
            byte = await reader.readexactly(1)
            length_bytes += byte
            length += (byte[0] & 0x7F) * multiplier
            multiplier *= 128
            if not byte[0] & 0x80:
                break
        body = await reader.readexactly(length)
        name_length = int.from_bytes(body[:2], "big")
        level = body[2 + name_length]
        if level == 5:
            self.refused_v5 += 1
            writer.write(b"\x20\x02\x00\x01")
            await writer.drain()
            writer.close()
            return
        up_reader, up_writer = await asyncio.open_connection("127.0.0.1", self.backend_port)
        up_writer.write(header + length_bytes + body)

        async def pipe(source: asyncio.StreamReader, sink: asyncio.StreamWriter) -> None:
            with contextlib.suppress(ConnectionError):
                while data := await source.read(65536):
                    sink.write(data)
                    await sink.drain()
            sink.close()

        await asyncio.gather(pipe(reader, up_writer), pipe(up_reader, writer))


def hold_status() -> Status:
    return Status(
        mode="hold",
        armed=True,
        position_ned_m=(1.0, 2.0, -3.0),
        stages={"perception": StageReport(ok=True, rate_hz=10.0, latency_ms=45.0, age_s=0.05)},
    )


@contextlib.asynccontextmanager
async def running(
    params: GroundParams,
    handler: object | None = None,
    status: Callable[[], Status] = hold_status,
    connect: bool = True,
) -> AsyncIterator[GroundLink]:
    """The link running as a task; connected on entry unless `connect` is False."""
    link = GroundLink(params, CLOCK, handler or Recorder(), status)  # type: ignore[arg-type]
    task = asyncio.create_task(link.run())
    try:
        if connect:
            await until(lambda: link.health().connected, 10.0)
        yield link
    finally:  # re-cancelled: aiomqtt's wait_for can swallow one cancel (a SUBACK racing it)
        await cancel_and_wait([task])


async def until(condition: Callable[[], bool], timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        await asyncio.sleep(0.01)
