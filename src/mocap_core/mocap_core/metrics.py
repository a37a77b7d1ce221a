"""Running rate, latency and counter statistics for diagnostics and benchmarks (no ROS)."""

from __future__ import annotations

import collections
import time
from typing import Deque, Dict, Optional

import numpy as np


class RateMeter:
    """Events per second over a sliding time window.

    Args:
        window_s: length of the window, seconds.
        clock: monotonic time source in seconds (injectable for tests).
    """

    def __init__(self, window_s: float = 5.0, clock=time.monotonic) -> None:
        if window_s <= 0:
            raise ValueError('window_s must be positive')
        self.window_s = float(window_s)
        self._clock = clock
        self._times: Deque[float] = collections.deque()
        self.total = 0

    def tick(self, now: Optional[float] = None) -> None:
        """Record one event (at ``now`` seconds, default the clock)."""
        now = self._clock() if now is None else now
        self._times.append(now)
        self.total += 1
        self._trim(now)

    def _trim(self, now: float) -> None:
        while self._times and self._times[0] < now - self.window_s:
            self._times.popleft()

    def rate(self, now: Optional[float] = None) -> float:
        """Events per second in the window ending at ``now`` (0 with fewer than 2 events)."""
        now = self._clock() if now is None else now
        self._trim(now)
        if len(self._times) < 2:
            return 0.0
        span = self._times[-1] - self._times[0]
        return (len(self._times) - 1) / span if span > 0 else 0.0


class LatencyStats:
    """Median / mean / 95th percentile / max of the last ``size`` durations (seconds)."""

    def __init__(self, size: int = 200) -> None:
        self._values: Deque[float] = collections.deque(maxlen=size)

    def add(self, seconds: float) -> None:
        self._values.append(float(seconds))

    def __len__(self) -> int:
        return len(self._values)

    def summary(self) -> Dict[str, float]:
        """{'median', 'mean', 'p95', 'max'} in seconds (NaN when empty)."""
        if not self._values:
            return {'median': float('nan'), 'mean': float('nan'), 'p95': float('nan'),
                    'max': float('nan')}
        v = np.fromiter(self._values, dtype=np.float64)
        return {'median': float(np.median(v)), 'mean': float(v.mean()),
                'p95': float(np.percentile(v, 95)), 'max': float(v.max())}


class Stopwatch:
    """Context manager measuring wall time into a :class:`LatencyStats`."""

    def __init__(self, stats: LatencyStats) -> None:
        self.stats = stats
        self.elapsed = 0.0

    def __enter__(self) -> 'Stopwatch':
        self._t0 = time.perf_counter()
        return self

    def __exit__(self, *exc) -> None:
        self.elapsed = time.perf_counter() - self._t0
        self.stats.add(self.elapsed)
