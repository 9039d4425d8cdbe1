"""Tunables of the ground link (`companion.ground.link`) and of the geofence (`geofence`).

Nothing connects unless `ground.broker_url` is set. Secrets never live in the TOML file: the
password is read from `ground.password_file` (mode 0640, group wireavoid) at each connection.
The ground-link-lost failsafe (how long, and what it does) belongs to the mission
(`mission.ground_lost_s`, `mission.ground_lost_action`); the link only reports its health.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum
from typing import Self
from urllib.parse import urlsplit

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from companion.ground.polygon import polygon_problem

VEHICLE_ID_PATTERN = r"^[A-Za-z0-9_-]{1,64}$"  # one MQTT topic level: no '/', '+', '#'


@dataclass(frozen=True, slots=True)
class BrokerAddress:
    """Where the broker listens: `host`, TCP `port`, and whether the connection is TLS."""

    host: str
    port: int
    tls: bool

    @property
    def loopback(self) -> bool:
        """Whether the broker is on this machine (plain MQTT is then not on the wire)."""
        return self.host in ("localhost", "::1") or self.host.startswith("127.")


def broker_address(url: str) -> BrokerAddress:
    """`mqtt://HOST[:PORT]` (1883 by default) or `mqtts://HOST[:PORT]` (TLS, 8883).

    Raises ValueError naming what is wrong (scheme, host, port, a path or credentials in the
    URL: the username is `ground.username`, the password lives in `ground.password_file`).
    """
    parts = urlsplit(url)
    if parts.scheme not in ("mqtt", "mqtts"):
        raise ValueError(f"broker URL {url!r}: the scheme must be mqtt:// or mqtts://")
    if parts.username is not None or parts.password is not None:
        raise ValueError(
            f"broker URL {url!r}: no credentials in the URL; use ground.username and "
            "ground.password_file"
        )
    if parts.path not in ("", "/") or parts.query or parts.fragment:
        raise ValueError(f"broker URL {url!r}: expected mqtt[s]://HOST[:PORT] and nothing else")
    if not parts.hostname:
        raise ValueError(f"broker URL {url!r}: no host")
    try:
        port = parts.port
    except ValueError as e:
        raise ValueError(f"broker URL {url!r}: {e}") from None
    tls = parts.scheme == "mqtts"
    return BrokerAddress(parts.hostname, port or (8883 if tls else 1883), tls)


class MqttVersion(StrEnum):
    """The MQTT protocol the vehicle speaks to the broker."""

    AUTO = "auto"  # MQTT 5, falling back to 3.1.1 when the broker refuses version 5
    V5 = "5"
    V311 = "3.1.1"


class GroundParams(BaseModel):
    """The MQTT link to the ground station (`companion.ground.link`)."""

    model_config = ConfigDict(extra="forbid")

    broker_url: str = Field(
        "",
        description="MQTT broker, mqtt://HOST[:PORT] or mqtts://HOST[:PORT] (TLS); empty: no "
        "ground link",
        examples=["mqtts://gcs.local:8883"],
    )
    vehicle_id: str = Field(
        "drone1",
        pattern=VEHICLE_ID_PATTERN,
        description="this vehicle's id in the topics wireavoid/<vehicle_id>/cmd|ack|status|events "
        "(letters, digits, _ and -)",
    )
    client_id: str = Field(
        "",
        max_length=64,
        description="MQTT client id; empty: wireavoid-<vehicle_id>",
    )
    username: str = Field("", max_length=128, description="MQTT username; empty: anonymous")
    password_file: str = Field(
        "",
        description="file holding the MQTT password (first line), read at each connection; "
        "empty: no password",
        examples=["/etc/wireavoid/mqtt-password"],
    )
    tls_ca_file: str = Field(
        "",
        description="CA certificate(s) the broker's certificate must chain to (mqtts://); empty: "
        "the system's CAs",
    )
    tls_cert_file: str = Field(
        "", description="client certificate for brokers that require one (mqtts://); empty: none"
    )
    tls_key_file: str = Field("", description="private key of tls_cert_file; empty: none")
    mqtt_version: MqttVersion = Field(
        MqttVersion.AUTO,
        description="MQTT protocol: auto (5, falling back to 3.1.1 if the broker refuses it), "
        "5 or 3.1.1",
    )
    keepalive_s: int = Field(
        5,
        ge=2,
        le=300,
        description="MQTT keepalive; a silent connection is declared lost after about 1.5x this, s",
    )
    connect_timeout_s: float = Field(
        5.0, gt=0, le=60, description="time for the broker to accept a connection, s"
    )
    reconnect_min_s: float = Field(
        0.5, gt=0, le=60, description="first pause before reconnecting after a lost connection, s"
    )
    reconnect_max_s: float = Field(
        10.0,
        gt=0,
        le=600,
        description="longest pause between reconnection attempts (the pause doubles each "
        "failure), s",
    )
    status_rate_hz: float = Field(
        2.0, ge=1, le=2, description="rate of the retained status on wireavoid/<id>/status, Hz"
    )
    max_payload_bytes: int = Field(
        32768,
        ge=512,
        le=262144,
        description="commands larger than this are rejected unread, bytes",
    )
    command_queue_size: int = Field(
        64,
        ge=1,
        le=4096,
        description="incoming messages buffered while the link is busy; beyond it a flood is "
        "dropped (unacked), count",
    )
    event_queue_size: int = Field(
        256,
        ge=1,
        le=65536,
        description="events kept while the broker is unreachable (oldest dropped first), count",
    )

    @field_validator("broker_url")
    @classmethod
    def _valid_url(cls, url: str) -> str:
        if url:
            broker_address(url)
        return url

    @model_validator(mode="after")
    def _consistent(self) -> Self:
        if self.reconnect_max_s < self.reconnect_min_s:
            raise ValueError("reconnect_max_s must be >= reconnect_min_s")
        if bool(self.tls_cert_file) != bool(self.tls_key_file):
            raise ValueError("tls_cert_file and tls_key_file go together")
        tls_files = self.tls_ca_file or self.tls_cert_file
        if self.broker_url and tls_files and not broker_address(self.broker_url).tls:
            raise ValueError("TLS files are set but broker_url is mqtt://: use mqtts://")
        if self.password_file and not self.username:
            raise ValueError("password_file is set without a username")
        return self

    @property
    def enabled(self) -> bool:
        """Whether a broker is configured (the process then runs the ground link)."""
        return bool(self.broker_url)

    @property
    def mqtt_client_id(self) -> str:
        """The client id the vehicle connects with."""
        return self.client_id or f"wireavoid-{self.vehicle_id}"


class FenceShape(StrEnum):
    """The horizontal outline of the geofence."""

    CYLINDER = "cylinder"  # a circle of radius_m around center_ned_m
    POLYGON = "polygon"  # the simple polygon polygon_ned_m


class GeofenceParams(BaseModel):
    """The geofence that operator goals and the legs to them must stay in (`ground.geofence`).

    Horizontal positions are local NED (north, east) from the autopilot's origin, m;
    altitudes are above home, m.
    """

    model_config = ConfigDict(extra="forbid")

    shape: FenceShape = Field(
        FenceShape.CYLINDER, description="cylinder (center_ned_m, radius_m) or polygon"
    )
    center_ned_m: tuple[float, float] = Field(
        (0.0, 0.0), description="centre of the cylinder, local (north, east), m"
    )
    radius_m: float = Field(100.0, gt=0, le=100000, description="radius of the cylinder, m")
    polygon_ned_m: list[tuple[float, float]] = Field(
        default_factory=list,
        max_length=256,
        description="vertices of the polygon in order, local (north, east), m (3 to 256; used "
        "when shape = polygon)",
    )
    min_altitude_m: float = Field(
        1.0, ge=-100, le=10000, description="lowest goal altitude above home (landing aside), m"
    )
    max_altitude_m: float = Field(
        50.0, gt=0, le=10000, description="highest goal altitude above home, m"
    )

    @model_validator(mode="after")
    def _valid_outline(self) -> Self:
        if self.max_altitude_m <= self.min_altitude_m:
            raise ValueError("max_altitude_m must be above min_altitude_m")
        values = [*self.center_ned_m, *(x for v in self.polygon_ned_m for x in v)]
        if not all(math.isfinite(x) for x in values):
            raise ValueError("geofence coordinates must be finite")
        if self.shape is FenceShape.POLYGON:
            problem = polygon_problem(self.polygon_ned_m)
            if problem:
                raise ValueError(f"polygon_ned_m: {problem}")
        return self
