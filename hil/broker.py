"""A real MQTT broker for simulated flights and the tests: Debian's mosquitto on loopback.

`Mosquitto` writes a mosquitto.conf into a folder and runs `/usr/sbin/mosquitto` with it
(`.ci/run` installs it). `start`, `stop` and `restart` keep the port, so a client finds the
broker again at the same URL after a restart: the **mqtt_restart** fault
(`hil.faults.BrokerRestart`) stops and starts the broker of a simulated flight's ground link,
and the ground-link tests restart theirs. `Mosquitto.open(folder)` is an anonymous broker
without an ACL on a free port; the constructor takes any configuration (the tests run the
shipped, secured one).
"""

from __future__ import annotations

import os
import shutil
import socket
import subprocess
import time
import weakref
from pathlib import Path

MOSQUITTO = shutil.which("mosquitto") or "/usr/sbin/mosquitto"  # Debian keeps it in sbin
START_TIMEOUT_S = 5.0  # for the broker to listen on its ports


def free_tcp_port() -> int:
    """A TCP port nothing listens on right now (loopback)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _listening(port: int) -> bool:
    with socket.socket() as s:
        s.settimeout(0.2)
        return s.connect_ex(("127.0.0.1", port)) == 0


def _terminate(process: subprocess.Popen[bytes]) -> None:
    """End the broker process (by its id) and wait for it."""
    if process.poll() is None:
        process.terminate()
        try:
            process.wait(timeout=5.0)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait(timeout=5.0)


class Mosquitto:
    """One broker process; `config` is the text of its mosquitto.conf (ports filled in).

    Persistence is off: a restarted broker has forgotten its retained messages and sessions,
    as a broker restarted without a database has. The process is ended when this object is
    collected or the interpreter exits, should `stop` never be called.
    """

    def __init__(self, folder: Path, config: str, port: int, tls_port: int | None = None) -> None:
        self.folder = folder
        self.port = port
        self.tls_port = tls_port
        self.conf = folder / "mosquitto.conf"
        self.log = folder / "mosquitto.log"
        # run as root (CI), mosquitto would switch to its own user, who cannot read the folder
        stay = "user root\n" if os.geteuid() == 0 else ""
        self.conf.write_text(f"{config}\npersistence false\nlog_dest file {self.log}\n{stay}")
        self._process: subprocess.Popen[bytes] | None = None
        self._finalizer: weakref.finalize | None = None

    @classmethod
    def open(cls, folder: Path) -> Mosquitto:
        """An anonymous broker with no ACL on a free loopback port (not started)."""
        port = free_tcp_port()
        return cls(
            folder, f"listener {port} 127.0.0.1\nallow_anonymous true\nset_tcp_nodelay true", port
        )

    @property
    def url(self) -> str:
        return f"mqtt://127.0.0.1:{self.port}"

    @property
    def tls_url(self) -> str:
        return f"mqtts://localhost:{self.tls_port}"

    @property
    def running(self) -> bool:
        return self._process is not None and self._process.poll() is None

    def start(self, timeout_s: float = START_TIMEOUT_S) -> None:
        """Run the broker and return once it listens on its ports (RuntimeError if it exits
        or does not listen within `timeout_s`)."""
        process = subprocess.Popen(
            [MOSQUITTO, "-c", str(self.conf)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE
        )
        self._process = process
        self._finalizer = weakref.finalize(self, _terminate, process)
        deadline = time.monotonic() + timeout_s
        ports = [p for p in (self.port, self.tls_port) if p is not None]
        while not all(_listening(p) for p in ports):
            if process.poll() is not None:
                stderr = process.stderr.read().decode() if process.stderr else ""
                log = self.log.read_text() if self.log.exists() else ""
                raise RuntimeError(f"mosquitto exited: {stderr}{log}")
            if time.monotonic() > deadline:
                self.stop()
                raise RuntimeError(f"mosquitto did not listen on {ports} within {timeout_s} s")
            time.sleep(0.01)

    def stop(self) -> None:
        """End the broker (SIGTERM, as `systemctl stop` does); the port is free again."""
        if self._finalizer is not None:
            self._finalizer()  # terminates the process once; later calls do nothing
        self._process = None
        self._finalizer = None

    def restart(self) -> None:
        self.stop()
        self.start()
