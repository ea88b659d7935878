"""Faults in the simulation: event schedules, LiDAR scan dropout and blanked sectors, command-link stalls.

The keys and their ranges are documented in ``bigcbf/params/faults.py``. Each fault draws from its own random
stream (``SimWorld.STREAMS``; pedestrians' faults in ``bigcbf/sim/pedestrians.py``), so turning one fault on
changes the draws of no other, and with every fault off nothing here draws at all: the episodes of the shipped
scenes are unchanged.

The stack sees these faults only through its sensors and its actuators: ``SimWorld.scan`` returns None for a scan
that never arrives and inf for blanked beams; a stalled command simply reaches the wheels later.
"""
from __future__ import annotations

import bisect
import math

import numpy as np

from ..params.faults import EventSchedule
from ..types import LaserScan

#: how far past a time an event search looks at most [s] (longer than any episode, MAX_TIME_LIMIT_S): events that
#: overlap without a gap for longer than this count as one stall of this length
HORIZON_S = 600.0


class EventProcess:
    """The events of an :class:`EventSchedule`: the explicit ``times_s`` and a Poisson process of ``rate_per_s``
    (exponential gaps drawn lazily, as time advances, from ``rng``); each event covers [start, start + duration).

    ``active(t)``: whether t falls in an event; ``event_at(t)``: the start of the latest event covering t (None);
    ``end_of_outage(t)``: when the union of overlapping events containing t ends (t when none covers it).
    """

    def __init__(self, schedule: EventSchedule, rng: np.random.Generator | None):
        self.schedule = schedule
        self.duration = float(schedule.duration_s)
        self._explicit = sorted(float(x) for x in schedule.times_s)
        self._random: list[float] = []
        self._rng = rng if schedule.rate_per_s > 0 else None
        self._next = 0.0                  # the random process has been drawn up to here (its last start)
        self._outage = (0.0, 0.0)         # [t, end) of the last outage end_of_outage found
        if self._rng is not None:
            self._next = float(self._rng.exponential(1.0 / schedule.rate_per_s))
            self._random.append(self._next)

    @property
    def enabled(self) -> bool:
        return self.schedule.enabled

    def _draw_until(self, t: float) -> None:
        """Random starts drawn until one lies after t."""
        if self._rng is None:
            return
        while self._next <= t:
            self._next += float(self._rng.exponential(1.0 / self.schedule.rate_per_s))
            self._random.append(self._next)

    def covering(self, t: float) -> list[float]:
        """The starts of the events that cover t (start <= t < start + duration), sorted."""
        self._draw_until(t)
        out = []
        for starts in (self._explicit, self._random):        # both sorted
            lo, hi = bisect.bisect_right(starts, t - self.duration), bisect.bisect_right(starts, t)
            out += [s for s in starts[lo:hi] if s + self.duration > t]
        return sorted(out)

    def event_at(self, t: float) -> float | None:
        """The start of the latest event that covers t (None when none does)."""
        if not self.enabled:
            return None
        covering = self.covering(t)
        return covering[-1] if covering else None

    def active(self, t: float) -> bool:
        return self.event_at(t) is not None

    def end_of_outage(self, t: float) -> float:
        """When the events around t are over: t itself when no event covers it, else the end of the union of the
        overlapping events that contains t (at most ``HORIZON_S`` later)."""
        if not self.enabled:
            return t
        lo, hi = self._outage
        if lo <= t < hi:                 # inside the outage found last time (times come in order): the same end
            return hi
        end = t
        while end < t + HORIZON_S:
            covering = self.covering(end)
            if not covering:
                break
            end = covering[-1] + self.duration
        end = min(end, t + HORIZON_S)
        if end > t:
            self._outage = (t, end)
        return end


def sector_mask(angles: np.ndarray, sectors_deg) -> np.ndarray:
    """Beams (angles in the laser frame [rad]) inside any [centre, width] sector [deg]; a sector covers
    |wrap(angle - centre)| <= width / 2."""
    mask = np.zeros(len(angles), bool)
    for centre, width in sectors_deg:
        d = np.angle(np.exp(1j * (np.asarray(angles, float) - math.radians(centre))))
        mask |= np.abs(d) <= 0.5 * math.radians(width) + 1e-12
    return mask


class LidarFaults:
    """Scan dropout (a scan whose stamp falls in a dropout event is never delivered) and blanked sectors (their
    beams read inf, REP 117's "no return")."""

    def __init__(self, dropout: EventSchedule, sectors_deg, rng: np.random.Generator, angles: np.ndarray):
        self.dropout = EventProcess(dropout, rng)
        self.sectors_deg = tuple(sectors_deg)
        self.mask = sector_mask(angles, self.sectors_deg) if self.sectors_deg else None

    def dropped(self, t: float) -> bool:
        return self.dropout.active(t)

    def apply(self, scan: LaserScan) -> LaserScan:
        """The scan with the blanked sectors' beams at inf."""
        if self.mask is None:
            return scan
        scan.ranges[self.mask] = np.inf
        return scan


__all__ = ["EventProcess", "LidarFaults", "sector_mask", "HORIZON_S"]
