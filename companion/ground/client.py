"""MQTT clients for the ground link, built from `GroundParams` (the vehicle's and the station's).

The one place that turns the settings into an `aiomqtt.Client`: broker address, MQTT 5 or
3.1.1, clean sessions (a command sent while the vehicle was away is never delivered late),
username and the password read from its file, TLS with certificate and hostname checks.
"""

from __future__ import annotations

import logging
import socket
import ssl
from pathlib import Path

import aiomqtt
from aiomqtt.exceptions import MqttConnectError
from paho.mqtt.client import MQTT_CLEAN_START_FIRST_ONLY
from paho.mqtt.reasoncodes import ReasonCode

from companion.ground.params import GroundParams, MqttVersion, broker_address

log = logging.getLogger(__name__)

# Reason code of a CONNACK refusing the protocol: 132 in MQTT 5, return code 1 in 3.1.1.
_UNSUPPORTED_PROTOCOL = (132, 1)


def read_password(path: str) -> str | None:
    """The first line of the password file (None when no file is configured).

    Raises OSError when the file cannot be read.
    """
    if not path:
        return None
    text = Path(path).read_text(encoding="utf-8")
    return text.splitlines()[0] if text else ""


def tls_context(params: GroundParams) -> ssl.SSLContext:
    """TLS >= 1.2 verifying the broker's certificate and host name against `tls_ca_file` (the
    system's CAs when empty), presenting `tls_cert_file` when set."""
    context = ssl.create_default_context(cafile=params.tls_ca_file or None)
    context.minimum_version = ssl.TLSVersion.TLSv1_2
    if params.tls_cert_file:
        context.load_cert_chain(params.tls_cert_file, params.tls_key_file)
    return context


def first_version(params: GroundParams) -> MqttVersion:
    """The protocol version a first connection tries (auto starts with MQTT 5)."""
    return MqttVersion.V311 if params.mqtt_version is MqttVersion.V311 else MqttVersion.V5


def refused_protocol(error: BaseException) -> bool:
    """Whether a connection failed because the broker does not speak the protocol version."""
    if not isinstance(error, MqttConnectError):
        return False
    rc = error.rc
    value = rc.value if isinstance(rc, ReasonCode) else rc
    return value in _UNSUPPORTED_PROTOCOL


def broker_client(
    params: GroundParams,
    *,
    identifier: str,
    version: MqttVersion,
    will: aiomqtt.Will | None = None,
) -> aiomqtt.Client:
    """An unconnected client (`async with` connects) for `params.broker_url`.

    Raises OSError when the password file cannot be read, `ssl.SSLError`/OSError for
    unreadable TLS files.
    """
    address = broker_address(params.broker_url)
    password = read_password(params.password_file)
    if params.username and not address.tls and not address.loopback:
        log.warning(
            "sending MQTT credentials unencrypted to %s: use mqtts:// off this machine",
            address.host,
        )
    v5 = version is MqttVersion.V5
    return aiomqtt.Client(
        address.host,
        address.port,
        username=params.username or None,
        password=password,
        identifier=identifier,
        protocol=aiomqtt.ProtocolVersion.V5 if v5 else aiomqtt.ProtocolVersion.V311,
        clean_session=None if v5 else True,  # 3.1.1: a clean session on every connection
        clean_start=True if v5 else MQTT_CLEAN_START_FIRST_ONLY,  # 5: clean start on every one
        will=will,
        keepalive=params.keepalive_s,
        timeout=params.connect_timeout_s,
        max_queued_incoming_messages=params.command_queue_size,
        tls_context=tls_context(params) if address.tls else None,
        # commands and acks are small: send each at once (Nagle and delayed ACKs add ~40 ms)
        socket_options=[(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)],
    )


async def connect_client(
    params: GroundParams,
    *,
    identifier: str,
    version: MqttVersion,
    will: aiomqtt.Will | None = None,
) -> tuple[aiomqtt.Client, MqttVersion]:
    """A connected client and the protocol it speaks: `version`, or 3.1.1 when the broker
    refused MQTT 5 and `mqtt_version` is auto. Leave it with `await client.__aexit__(...)`.

    Raises `aiomqtt.MqttError` when no connection is made, OSError/ValueError for unreadable
    credential or TLS files.
    """
    client = broker_client(params, identifier=identifier, version=version, will=will)
    try:
        await client.__aenter__()
    except aiomqtt.MqttError as e:
        fall_back = params.mqtt_version is MqttVersion.AUTO and version is MqttVersion.V5
        if not (fall_back and refused_protocol(e)):
            raise
        log.info("the broker refused MQTT 5: falling back to MQTT 3.1.1")
        version = MqttVersion.V311
        client = broker_client(params, identifier=identifier, version=version, will=will)
        await client.__aenter__()
    return client, version
