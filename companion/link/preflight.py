"""The pre-flight failsafe check: what PX4 does when our control stops, near wires.

When the companion stops sending setpoints, PX4 keeps flying the last one for COM_OF_LOSS_T and
then takes the action of COM_OBL_RC_ACT; without a pilot's sticks its default (Position) falls
back to Return, which climbs straight up to RTL_RETURN_ALT (30 m on SITL, 60 m on hardware)
and flies home at that height: through whatever wires are overhead or on the way, which the
companion, the only one that sees them, no longer watches. A lost pilot stick link (NAV_RCL_ACT)
does the same. `failsafe_report` reads those parameters and says, per failsafe, what PX4 would
do and the setting that makes it hold or land instead; a climb or a blind flight home is
`Severity.REFUSE` (the mission should not start offboard), a blind descent, a motor cut or a long
blind setpoint is `WARN`. `check_failsafes(link, ...)` reads the parameters from the autopilot
(`VehicleLink.read_parameters`). The RTL altitude follows PX4 (RTL_TYPE 0): RTL_RETURN_ALT, within
RTL_MIN_DIST of home only the RTL_CONE_ANG cone, within NAV_ACC_RAD nothing, never lower than now.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

PREFLIGHT_PARAMETERS = (
    "COM_OBL_RC_ACT",
    "COM_OF_LOSS_T",
    "RTL_RETURN_ALT",
    "RTL_MIN_DIST",
    "RTL_CONE_ANG",
    "NAV_ACC_RAD",
    "NAV_RCL_ACT",
    "COM_RC_IN_MODE",
    "COM_RCL_EXCEPT",
)
# PX4-Autopilot main defaults, for a parameter the autopilot does not report
_PX4_DEFAULTS: dict[str, float] = {
    "COM_OBL_RC_ACT": 0,
    "COM_OF_LOSS_T": 1.0,
    "RTL_RETURN_ALT": 60.0,
    "RTL_MIN_DIST": 10.0,
    "RTL_CONE_ANG": 45,
    "NAV_ACC_RAD": 2.0,
    "NAV_RCL_ACT": 2,
    "COM_RC_IN_MODE": 3,
    "COM_RCL_EXCEPT": 0,
}
_STICKS_DISABLED = 4  # COM_RC_IN_MODE: no manual control at all
_RCL_EXCEPT_OFFBOARD = 1 << 2  # COM_RCL_EXCEPT bit: stick loss ignored in Offboard
BLIND_DISTANCE_WARN_M = 1.0  # the last setpoint flown blind farther than this is a warning
HOLD_FIX_OFFBOARD = "set COM_OBL_RC_ACT to 5 (Hold: stops where it is) or 4 (Land)"


class Severity(StrEnum):
    """How bad a failsafe is near wires."""

    OK = "ok"
    WARN = "warn"
    REFUSE = "refuse"


@dataclass(frozen=True)
class FailsafeFinding:
    """One failsafe: what PX4 would do, how bad that is near wires, how to make it hold."""

    failsafe: str
    severity: Severity
    action: str
    fix: str = ""

    def text(self) -> str:
        """One line: "refuse: offboard loss: ... -> fix"."""
        fix = f"; {self.fix}" if self.fix else ""
        return f"{self.severity.value}: {self.failsafe}: {self.action}{fix}"


@dataclass(frozen=True)
class FailsafeReport:
    """Every failsafe's finding and the parameters they came from."""

    findings: tuple[FailsafeFinding, ...]
    parameters: dict[str, float]

    @property
    def refuse(self) -> bool:
        """A failsafe would climb or fly home blind: offboard should not start."""
        return any(f.severity is Severity.REFUSE for f in self.findings)

    @property
    def problems(self) -> list[FailsafeFinding]:
        """The findings worse than OK, worst first."""
        order = {Severity.REFUSE: 0, Severity.WARN: 1}
        bad = [f for f in self.findings if f.severity is not Severity.OK]
        return sorted(bad, key=lambda f: order[f.severity])


def rtl_return_altitude_m(
    px4: Mapping[str, float], height_m: float, home_distance_m: float
) -> float:
    """PX4's RTL return height above home from `height_m` at `home_distance_m` (RTL_TYPE 0)."""
    return_alt = px4["RTL_RETURN_ALT"]
    acceptance = px4["NAV_ACC_RAD"]
    if home_distance_m <= acceptance:
        return_alt = 2.0 * home_distance_m
    else:
        cone_deg = px4["RTL_CONE_ANG"]
        if home_distance_m <= px4["RTL_MIN_DIST"] and cone_deg > 0:
            cone = math.radians(min(max(cone_deg, 1.0), 89.0))
            return_alt = min(return_alt, home_distance_m / math.tan(cone))
        return_alt = max(return_alt, 2.0 * acceptance)
    return max(return_alt, height_m)


def _return_finding(
    failsafe: str, px4: Mapping[str, float], height_m: float, home_distance_m: float, fix: str
) -> FailsafeFinding:
    return_alt = rtl_return_altitude_m(px4, height_m, home_distance_m)
    climb = return_alt - height_m
    if climb > 0.5:
        action = (
            f"Return climbs {climb:.0f} m straight up to {return_alt:.0f} m (RTL_RETURN_ALT "
            f"{px4['RTL_RETURN_ALT']:.0f}) and flies home blind: through any wire above or between"
        )
    else:
        action = f"Return flies home at {return_alt:.0f} m without seeing wires"
    return FailsafeFinding(failsafe, Severity.REFUSE, action, fix)


def _offboard_loss(px4: Mapping[str, float], height_m: float, home_distance_m: float):
    action = int(px4["COM_OBL_RC_ACT"])
    name = "offboard loss (COM_OBL_RC_ACT)"
    if action in (0, 1, 2, 3):
        finding = _return_finding(name, px4, height_m, home_distance_m, HOLD_FIX_OFFBOARD)
        if action != 3:
            mode = ("Position", "Altitude", "Stabilized")[action]
            finding = FailsafeFinding(
                finding.failsafe,
                finding.severity,
                f"{mode} mode needs a pilot's sticks; without them PX4 falls back to Return: "
                + finding.action,
                finding.fix,
            )
        return finding
    if action == 4:
        return FailsafeFinding(
            name,
            Severity.WARN,
            "Land descends where it is, blind (a wire below it is hit)",
            "COM_OBL_RC_ACT 5 (Hold) stops where it is",
        )
    if action == 5:
        return FailsafeFinding(name, Severity.OK, "Hold stops where it is")
    return FailsafeFinding(
        name,
        Severity.WARN,
        "cuts the motors: the vehicle falls" if action == 6 else "disarms: the vehicle falls",
        HOLD_FIX_OFFBOARD,
    )


def _blind_setpoint(px4: Mapping[str, float], max_speed_mps: float) -> FailsafeFinding:
    timeout_s = px4["COM_OF_LOSS_T"]
    distance = timeout_s * max_speed_mps
    name = "setpoint timeout (COM_OF_LOSS_T)"
    if distance <= BLIND_DISTANCE_WARN_M:
        return FailsafeFinding(
            name, Severity.OK, f"the last setpoint is flown {distance:.1f} m before the failsafe"
        )
    return FailsafeFinding(
        name,
        Severity.WARN,
        f"PX4 flies the last setpoint blind for {timeout_s:.1f} s: {distance:.1f} m at "
        f"{max_speed_mps:.1f} m/s, then brakes",
        f"lower COM_OF_LOSS_T (0.5 s: {0.5 * max_speed_mps:.1f} m) or fly slower",
    )


def _stick_loss(px4: Mapping[str, float], height_m: float, home_distance_m: float):
    name = "pilot stick loss (NAV_RCL_ACT)"
    if int(px4["COM_RC_IN_MODE"]) == _STICKS_DISABLED:
        return FailsafeFinding(name, Severity.OK, "no manual control input is used")
    if int(px4["COM_RCL_EXCEPT"]) & _RCL_EXCEPT_OFFBOARD:
        return FailsafeFinding(name, Severity.OK, "ignored in Offboard (COM_RCL_EXCEPT)")
    action = int(px4["NAV_RCL_ACT"])
    fix = "NAV_RCL_ACT 1 (Hold), or add 4 to COM_RCL_EXCEPT to ignore it in Offboard"
    if action == 2:
        finding = _return_finding(name, px4, height_m, home_distance_m, fix)
        # only if a pilot's RC or joystick is connected and then lost: a warning
        return FailsafeFinding(
            name, Severity.WARN, "if a connected RC/joystick link drops: " + finding.action, fix
        )
    if action == 1:
        return FailsafeFinding(name, Severity.OK, "Hold stops where it is")
    if action == 3:
        return FailsafeFinding(name, Severity.WARN, "Land descends blind where it is", fix)
    return FailsafeFinding(name, Severity.WARN, "the motors stop: the vehicle falls", fix)


def failsafe_report(
    px4: Mapping[str, float | int | None],
    *,
    flight_height_m: float,
    max_speed_mps: float,
    home_distance_m: float = math.inf,
) -> FailsafeReport:
    """What PX4's failsafes do to a flight at `flight_height_m` above home, up to
    `home_distance_m` from it (inf: far, RTL_RETURN_ALT applies), at up to `max_speed_mps`."""
    values = {**_PX4_DEFAULTS, **{k: float(v) for k, v in px4.items() if v is not None}}
    findings = (
        _offboard_loss(values, flight_height_m, home_distance_m),
        _blind_setpoint(values, max_speed_mps),
        _stick_loss(values, flight_height_m, home_distance_m),
    )
    return FailsafeReport(findings, values)


async def check_failsafes(
    link: Any,
    *,
    flight_height_m: float,
    max_speed_mps: float,
    home_distance_m: float = math.inf,
) -> FailsafeReport:
    """`failsafe_report` on the parameters the autopilot behind `link` reports."""
    values = await link.read_parameters(PREFLIGHT_PARAMETERS)
    return failsafe_report(
        values,
        flight_height_m=flight_height_m,
        max_speed_mps=max_speed_mps,
        home_distance_m=home_distance_m,
    )
