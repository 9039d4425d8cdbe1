"""The `--mqtt URL` and `--vehicle-id ID` options of `wireavoid fly` and `wireavoid sim`."""

from __future__ import annotations

from typing import TypeVar

from companion.config import Settings
from companion.ground.params import GroundParams

S = TypeVar("S", bound=Settings)


def apply_ground_options(settings: S, mqtt_url: str | None, vehicle_id: str | None) -> S:
    """`settings` with `ground.broker_url` and `ground.vehicle_id` replaced where given.

    None keeps the configured value (file or WIREAVOID_GROUND__* environment). Raises
    `pydantic.ValidationError` naming the option's field for a bad URL or id.
    """
    updates = {
        key: value
        for key, value in (("broker_url", mqtt_url), ("vehicle_id", vehicle_id))
        if value is not None
    }
    if not updates:
        return settings
    ground = GroundParams.model_validate({**settings.ground.model_dump(), **updates})
    return settings.model_copy(update={"ground": ground})
