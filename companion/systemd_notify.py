"""sd_notify(3) without libsystemd: tell systemd that we are ready, alive, what we do, stopping.

Messages are newline-separated `KEY=value` assignments sent as one datagram to the AF_UNIX
socket named by `$NOTIFY_SOCKET` (a file-system path, or a Linux abstract address when it
starts with `@`). Without the variable (not started by systemd, or not a `Type=notify` unit)
every call is a no-op that returns False. Sending never raises and never blocks: the flight
process must not stall or die for its supervisor's sake, so a failed send is logged and
reported as False (a missing WATCHDOG=1 then lets systemd restart us, which is the point).
"""

from __future__ import annotations

import logging
import os
import socket
from collections.abc import Mapping

log = logging.getLogger(__name__)


def notify_address(value: str) -> str:
    """The socket address of a `$NOTIFY_SOCKET` value: `@name` is the abstract `\\0name`."""
    return "\0" + value[1:] if value.startswith("@") else value


def watchdog_interval_s(
    env: Mapping[str, str] = os.environ, pid: int | None = None
) -> float | None:
    """The systemd watchdog timeout (`$WATCHDOG_USEC`) meant for this process, s.

    None when no watchdog is armed, or when `$WATCHDOG_PID` names another process (the
    variable was inherited). Like sd_watchdog_enabled(3); ping at least twice per interval.
    """
    usec = env.get("WATCHDOG_USEC", "")
    owner = env.get("WATCHDOG_PID", "")
    if not usec.isdigit() or int(usec) == 0:
        return None
    if owner and owner != str(os.getpid() if pid is None else pid):
        return None
    return int(usec) / 1e6


class SystemdNotifier:
    """Sends sd_notify messages to `socket_path` (None: notifications are disabled).

    `from_environment()` reads `$NOTIFY_SOCKET`. The socket is opened on the first send.
    """

    def __init__(self, socket_path: str | None) -> None:
        self.socket_path = socket_path or None
        self._sock: socket.socket | None = None
        self._failed = False

    @classmethod
    def from_environment(cls, env: Mapping[str, str] = os.environ) -> SystemdNotifier:
        """A notifier for `$NOTIFY_SOCKET`; disabled when it is unset or empty."""
        return cls(env.get("NOTIFY_SOCKET"))

    @property
    def enabled(self) -> bool:
        """Whether a notification socket is configured."""
        return self.socket_path is not None

    def send(self, *assignments: str) -> bool:
        """Send `KEY=value` assignments as one datagram; True when it was delivered."""
        if self.socket_path is None or not assignments:
            return False
        try:
            if self._sock is None:
                self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC)
                self._sock.setblocking(False)
            self._sock.sendto("\n".join(assignments).encode(), notify_address(self.socket_path))
        except OSError as e:
            if not self._failed:  # once, not at every tick
                log.warning("sd_notify to %s failed: %s", self.socket_path, e)
            self._failed = True
            return False
        self._failed = False
        return True

    def ready(self, status: str) -> bool:
        """Start-up is complete: `READY=1` with a status line."""
        return self.send("READY=1", status_assignment(status))

    def status(self, status: str) -> bool:
        """What the service is doing now (shown by `systemctl status`)."""
        return self.send(status_assignment(status))

    def watchdog(self, status: str | None = None) -> bool:
        """Keep-alive `WATCHDOG=1` (send only when the main loop made progress)."""
        extra = () if status is None else (status_assignment(status),)
        return self.send("WATCHDOG=1", *extra)

    def extend_timeout(self, seconds: float, status: str) -> bool:
        """Ask for `seconds` more of start-up (EXTEND_TIMEOUT_USEC), e.g. while waiting for PX4."""
        return self.send(f"EXTEND_TIMEOUT_USEC={round(seconds * 1e6)}", status_assignment(status))

    def stopping(self, status: str) -> bool:
        """Shutdown has begun: `STOPPING=1`."""
        return self.send("STOPPING=1", status_assignment(status))

    def close(self) -> None:
        """Close the socket (idempotent); a later send opens it again."""
        if self._sock is not None:
            self._sock.close()
            self._sock = None


def status_assignment(text: str) -> str:
    """`STATUS=text` on one line (a newline would start a new assignment)."""
    return "STATUS=" + " ".join(text.splitlines())
