"""Frame-timing statistics: frame intervals, dropped frames, latency."""
from __future__ import annotations

import math
from typing import List, Sequence


def percentile(xs: Sequence[float], q: float) -> float:
    """Linear-interpolated percentile (numpy's default), nan when empty."""
    if not xs:
        return float("nan")
    s = sorted(xs)
    pos = (len(s) - 1) * q / 100.0
    lo = math.floor(pos)
    hi = min(lo + 1, len(s) - 1)
    return s[lo] + (s[hi] - s[lo]) * (pos - lo)


def missed_periods(interval_s: float, period_s: float) -> int:
    """Frames dropped in one interval: an interval of n periods (rounded)
    shows n - 1 missed frames; jitter below half a period is not a drop."""
    if interval_s <= 1.5 * period_s:
        return 0
    return int(round(interval_s / period_s)) - 1


class FrameStats:
    # Bounded so an all-day session keeps a constant memory footprint (~1 h at 60 Hz).
    MAX_SAMPLES = 216000

    def __init__(self, refresh_hz: float):
        self.period_s = 1.0 / refresh_hz
        self.refresh_hz = refresh_hz
        self.frames = 0
        self.dropped = 0
        self.intervals_ms: List[float] = []
        self.latency_ms: List[float] = []
        self.age_ms: List[float] = []
        self.last_present = None
        self.states_received = 0
        self.states_shown = 0
        self.decode_errors = 0

    def _add(self, xs: List[float], v: float) -> None:
        if len(xs) >= self.MAX_SAMPLES:
            del xs[: self.MAX_SAMPLES // 2]
        xs.append(v)

    def presented(self, t_present: float) -> None:
        self.frames += 1
        if self.last_present is not None:
            dt = t_present - self.last_present
            self._add(self.intervals_ms, dt * 1e3)
            self.dropped += missed_periods(dt, self.period_s)
        self.last_present = t_present

    def shown(self, latency_s: float, age_s: float = float("nan")) -> None:
        self.states_shown += 1
        self._add(self.latency_ms, latency_s * 1e3)
        if math.isfinite(age_s):
            self._add(self.age_ms, age_s * 1e3)

    def summary(self) -> dict:
        return {
            "frames": self.frames,
            "dropped_frames": self.dropped,
            "refresh_hz": self.refresh_hz,
            "frame_interval_p50_ms": percentile(self.intervals_ms, 50),
            "frame_interval_p99_ms": percentile(self.intervals_ms, 99),
            "frame_interval_max_ms": max(self.intervals_ms) if self.intervals_ms else float("nan"),
            "latency_p50_ms": percentile(self.latency_ms, 50),
            "latency_p99_ms": percentile(self.latency_ms, 99),
            "latency_max_ms": max(self.latency_ms) if self.latency_ms else float("nan"),
            "state_age_p50_ms": percentile(self.age_ms, 50),
            "state_age_p99_ms": percentile(self.age_ms, 99),
            "states_received": self.states_received,
            "states_shown": self.states_shown,
            "decode_errors": self.decode_errors,
        }
