"""Property-based fuzz of the ground link through a real broker: malformed and hostile
messages leave the vehicle's client alive, its status flowing, every payload answered by
exactly one ack, and nothing accepted that should not be."""

from __future__ import annotations

import asyncio
from collections.abc import Iterator
from pathlib import Path

import pytest
from ground_broker import LinkThread, Mosquitto
from ground_payloads import payloads
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from companion.ground.params import GroundParams
from companion.ground.protocol import Rejection, parse_command
from companion.ground.station import GroundStation


@pytest.fixture(scope="module")
def vehicle(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LinkThread]:
    broker = Mosquitto.open(Path(tmp_path_factory.mktemp("fuzz-broker")))
    broker.start()
    with LinkThread(GroundParams(broker_url=broker.url)) as link:
        yield link
    broker.stop()


class Oracle:
    """What the vehicle must answer: valid commands with an id not used before are accepted."""

    def __init__(self) -> None:
        self.used_ids: set[str] = set()
        self.accepted: list[str] = []

    def expect_accepted(self, payload: bytes) -> bool:
        parsed = parse_command(payload)
        if isinstance(parsed, Rejection) or parsed.id in self.used_ids:
            return False
        self.used_ids.add(parsed.id)
        self.accepted.append(parsed.id)
        return True


ORACLE = Oracle()


@settings(
    max_examples=60,
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(st.lists(payloads(), min_size=1, max_size=8))
def test_hostile_messages_leave_the_link_alive_and_accept_nothing_wrong(
    vehicle: LinkThread, batch: list[tuple[bytes, str]]
) -> None:
    answers = asyncio.run(_exchange(vehicle, [payload for payload, _ in batch]))
    for (payload, expected), ack in zip(batch, answers, strict=True):
        assert ack is not None, f"no ack for {payload[:80]!r}"
        assert ack.accepted == ORACLE.expect_accepted(payload), (payload[:200], ack)
        if expected == "invalid":
            assert not ack.accepted, payload[:200]
        if not ack.accepted:
            assert ack.reason
    assert vehicle.alive() and vehicle.health().connected
    assert [c.id for c in vehicle.handler.commands] == ORACLE.accepted  # type: ignore[attr-defined]


async def _exchange(vehicle: LinkThread, payloads: list[bytes]) -> list:
    """Send each payload in turn and collect its ack; then check no extra ack follows."""
    assert vehicle.link is not None
    async with GroundStation(vehicle.link.params) as station:
        answers = [await station.send_raw(p, timeout_s=3.0) for p in payloads]
        await asyncio.sleep(0.05)
        assert len(station.acks) == len(payloads)  # one each, no more
    return answers


def test_after_the_fuzz_status_still_flows_and_commands_work(vehicle: LinkThread) -> None:
    async def check() -> tuple[int, object]:
        assert vehicle.link is not None
        async with GroundStation(vehicle.link.params) as station:
            await station.next_status(3.0)
            first = station.status_count
            await station.wait_for(lambda: station.status_count >= first + 2, 3.0)
            ack = await station.send_raw(b'{"v":1,"id":"after-the-fuzz","type":"hold"}', 3.0)
            return station.status_count - first, ack

    new_statuses, ack = asyncio.run(check())
    assert new_statuses >= 2
    assert ack is not None and ack.accepted  # type: ignore[attr-defined]
