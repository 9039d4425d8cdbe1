"""Reading an autopilot's parameters by name through MAVSDK's param plugin.

PX4 types each parameter (INT32 or REAL32) and MAVSDK refuses a read of the wrong type
(`WRONG_TYPE`), so each name is read as a float first and as an int when that is its type; a
name the autopilot does not have reads as None. Used by the pre-flight failsafe check
(`companion.link.preflight`) and for the planner's limits (`companion.link.px4_limits`).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from companion.link.calls import MavsdkCalls


async def read_parameters(
    system: Any, names: Iterable[str], calls: MavsdkCalls, drain_timeout_s: float
) -> dict[str, float | int | None]:
    """{name: value} of a connected MAVSDK `System`; None for a parameter it does not have.
    The reads go through `calls`; the param plugin is destroyed once they have returned (up to
    `drain_timeout_s`)."""
    from mavsdk.asyncio.plugins.param import ParamAsync, ParamError, ParamResult

    param = ParamAsync(system)
    values: dict[str, float | int | None] = {}
    try:
        for name in names:
            try:
                values[name] = float(await calls.call(param.get_param_float(name)))
            except ParamError as e:
                if e.result is not ParamResult.WRONG_TYPE:
                    values[name] = None
                    continue
                try:
                    values[name] = int(await calls.call(param.get_param_int(name)))
                except ParamError:
                    values[name] = None
    finally:
        await calls.drained(drain_timeout_s)
        param.destroy()
    return values
