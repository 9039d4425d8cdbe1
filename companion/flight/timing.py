"""Per-stage latency statistics of the flight process: p50 / p99 over a bounded window."""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

STAGES = ("ingest", "cnn", "map", "catenary", "plan", "stream", "frame_to_setpoint")


@dataclass(frozen=True, slots=True)
class LatencySummary:
    """Latency of one stage over the window, ms; `count` samples in all, NaN without any."""

    count: int
    p50_ms: float
    p99_ms: float
    max_ms: float

    def to_dict(self) -> dict[str, float | int]:
        """JSON-ready, rounded to 0.1 ms."""
        return {
            "count": self.count,
            "p50_ms": _round(self.p50_ms),
            "p99_ms": _round(self.p99_ms),
            "max_ms": _round(self.max_ms),
        }


def _round(value: float) -> float | None:
    return None if np.isnan(value) else round(float(value), 1)


class StageTimes:
    """Latency samples per stage (the newest `window` of each) and dropped-frame counts.

    ingest: exposure to the frame on the bus; cnn, map, plan: each stage's computation;
    stream: a new plan to its first setpoint handed to the link; frame_to_setpoint: exposure of
    the newest frame a plan used to the first setpoint of that plan.
    """

    def __init__(self, window: int) -> None:
        self._samples = {stage: deque(maxlen=window) for stage in STAGES}
        self._counts = dict.fromkeys(STAGES, 0)
        self.dropped_frames = 0
        self.overruns = dict.fromkeys(STAGES, 0)

    def add(self, stage: str, duration_s: float) -> None:
        """Record one latency of `stage`, s."""
        self._samples[stage].append(1e3 * duration_s)
        self._counts[stage] += 1

    def summary(self, stage: str) -> LatencySummary:
        """p50 / p99 / max of `stage` over the window."""
        samples = np.fromiter(self._samples[stage], dtype=np.float64)
        if samples.size == 0:
            return LatencySummary(self._counts[stage], np.nan, np.nan, np.nan)
        p50, p99 = np.percentile(samples, [50, 99])
        return LatencySummary(self._counts[stage], float(p50), float(p99), float(samples.max()))

    def to_dict(self) -> dict[str, object]:
        """Every stage's summary, dropped frames and planning overruns, JSON-ready."""
        return {
            **{stage: self.summary(stage).to_dict() for stage in STAGES},
            "dropped_frames": self.dropped_frames,
            "plan_overruns": self.overruns["plan"],
        }

    def line(self) -> str:
        """One log line: p50/p99 of each stage in ms, drops and overruns."""
        parts = []
        for stage in STAGES:
            s = self.summary(stage)
            if s.count:
                parts.append(f"{stage}={s.p50_ms:.0f}/{s.p99_ms:.0f}ms")
        parts.append(f"dropped={self.dropped_frames} overruns={self.overruns['plan']}")
        return " ".join(parts)
