"""A degraded link's schedule, without ROS: which messages are dropped and when the others go out.

``LossyLink`` decides for each message offered at wall time ``now``: dropped with probability ``loss``
(a seeded ``random.Random``: the same seed and arrivals give the same drops), else due at
``now + delay + U(0, jitter)``. Order is kept: a message never leaves before one offered earlier (its due
time is raised to the previous one's), like a reliable in-order DDS stream that is slow, not a datagram
network that reorders. relay_node (nodes/relay_node.py) holds one link per relayed topic.
"""

from __future__ import annotations

import math
import random
from collections import deque
from collections.abc import Iterator
from dataclasses import dataclass, field

#: Limits of the link's settings (relay_node validates run-time changes against them).
MAX_DELAY_S = 10.0
MAX_JITTER_S = 10.0
#: Forwarded messages whose delay is kept for the summary's percentiles (bounded memory).
DELAY_WINDOW = 200_000


def link_error(loss: float, delay_s: float, jitter_s: float) -> str | None:
    """Why these settings are refused (None if they are valid)."""
    for name, value, hi in (("loss", loss, 1.0), ("delay", delay_s, MAX_DELAY_S),
                            ("jitter", jitter_s, MAX_JITTER_S)):
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
            return f"{name} must be a finite number, got {value!r}"
        if not 0.0 <= value <= hi:
            unit = "" if name == "loss" else " s"
            return f"{name} must be in [0, {hi:g}]{unit}, got {value!r}"
    return None


@dataclass
class LossyLink:
    """Drop / delay schedule of one stream. ``offer`` each arriving message, ``release`` the due ones."""

    loss: float = 0.0
    delay_s: float = 0.0
    jitter_s: float = 0.0
    seed: int = 0
    received: int = 0
    dropped: int = 0
    forwarded: int = 0
    #: measured delays (release - offer, s) of the last DELAY_WINDOW forwarded messages
    delays_s: deque = field(default_factory=lambda: deque(maxlen=DELAY_WINDOW))
    _queue: deque = field(default_factory=deque)  # (due, offered, item), due non-decreasing
    _last_due: float = -math.inf

    def __post_init__(self) -> None:
        self.configure(self.loss, self.delay_s, self.jitter_s)
        self._rng = random.Random(self.seed)

    def configure(self, loss: float, delay_s: float, jitter_s: float) -> None:
        """New settings (ValueError with the reason if invalid); messages already queued keep their time."""
        reason = link_error(loss, delay_s, jitter_s)
        if reason:
            raise ValueError(reason)
        self.loss, self.delay_s, self.jitter_s = float(loss), float(delay_s), float(jitter_s)

    def offer(self, now: float, item: object) -> bool:
        """A message arrived at ``now`` (wall s): False if dropped, else queued until its due time."""
        self.received += 1
        # one draw per decision, always both, so a seed gives the same drops whatever the delay settings
        drop, spread = self._rng.random() < self.loss, self._rng.random()
        if drop:
            self.dropped += 1
            return False
        due = max(now + self.delay_s + spread * self.jitter_s, self._last_due)
        self._last_due = due
        self._queue.append((due, now, item))
        return True

    def next_due(self) -> float | None:
        """Wall time the oldest queued message is due (None: nothing queued)."""
        return self._queue[0][0] if self._queue else None

    def release(self, now: float) -> Iterator[object]:
        """The queued messages due by ``now``, oldest first; each counted as forwarded with its delay."""
        q = self._queue
        while q and q[0][0] <= now:
            _, offered, item = q.popleft()
            self.forwarded += 1
            self.delays_s.append(now - offered)
            yield item

    @property
    def queued(self) -> int:
        return len(self._queue)

    def summary(self) -> dict:
        """Counters, the settings and the measured delay (ms: p50/p99/max of the forwarded messages)."""
        out = {"received": self.received, "dropped": self.dropped, "forwarded": self.forwarded,
               "queued": self.queued, "drop_fraction": round(self.dropped / self.received, 5)
               if self.received else None,
               "loss": self.loss, "delay_s": self.delay_s, "jitter_s": self.jitter_s}
        if self.delays_s:
            d = sorted(self.delays_s)
            out["delay_ms"] = {"p50": round(_quantile(d, 0.5) * 1e3, 4),
                               "p99": round(_quantile(d, 0.99) * 1e3, 4), "max": round(d[-1] * 1e3, 4)}
        return out


def _quantile(sorted_values: list[float], q: float) -> float:
    """The ``q`` quantile (linear interpolation, as numpy's default) of a sorted non-empty list."""
    pos = q * (len(sorted_values) - 1)
    lo = math.floor(pos)
    hi = min(lo + 1, len(sorted_values) - 1)
    return sorted_values[lo] + (sorted_values[hi] - sorted_values[lo]) * (pos - lo)
