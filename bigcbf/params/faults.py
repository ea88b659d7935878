"""Faults set from files: the robot profile's ``[faults]`` table and the pedestrians' ``stop`` and ``turn`` keys.

Every fault is off by default (an empty schedule, no blanked sector); the simulation realises them in
``bigcbf/sim/faults.py`` (the LiDAR, the command link) and ``bigcbf/sim/pedestrians.py``. The stack never sees a
fault as a flag, only through its sensors: a missing scan, beams that read inf, a command that reaches the wheels
late, a drifting odometry, a pedestrian that does something else than its constant-velocity prediction.

Episodic faults share one shape, an *event schedule*: events start at the explicit times ``times_s`` and, at random,
as a Poisson process of ``rate_per_s`` events per second from t = 0 (drawn from the fault's own random stream,
so turning one fault on changes the draws of no other); each event lasts ``duration_s``; overlapping events merge.

Robot profile (all keys optional; a scenario overrides them in ``[robot_profile.faults]``)::

    [faults]
    blanked_sectors_deg = [[45.0, 30.0]]   # LiDAR beams within these [centre, width] sectors of the laser frame
                                           # (x forward, counter-clockwise, degrees) read inf: an occluded or
                                           # dirty window
    [faults.scan_dropout]                  # whole LiDAR scans missing (a USB/serial hiccup, a driver restart):
    rate_per_s = 0.2                       # every scan whose stamp falls in an event is never delivered
    duration_s = 1.0
    times_s = [5.0]
    [faults.latency_spikes]                # the command link stalls (a Wi-Fi / USB hiccup): a command issued
    rate_per_s = 0.2                       # during an event leaves when the event ends, then takes the profile's
    duration_s = 0.5                       # latency; commands keep their order; the wheels hold the last
                                           # command they received meanwhile

Pedestrians (optional keys of a scenario's ``[[pedestrians]]``)::

    stop = { times_s = [4.0], duration_s = 2.0 }            # stands still (its desired velocity 0) for 2 s at 4 s
    turn = { rate_per_s = 0.1, duration_s = 1.5, angle_deg = 180.0, random_side = false }
                                                            # heads angle_deg (counter-clockwise) off its way
                                                            # for duration_s, then walks back onto its path

Ranges (a value outside is a one-line error naming the file and the field): ``rate_per_s`` in [0, 10] 1/s,
``duration_s`` in [0, 60] s and > 0 when the schedule has events, at most 1000 ``times_s`` in [0, 600] s (the
longest episode); sector centre in [-180, 180] deg, width in (0, 360] deg, at most 16 sectors; ``angle_deg`` in
[-180, 180] deg.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from ..errors import FieldError
from .checks import check_field_ranges, ranged

MAX_RATE_PER_S = 10.0          # events per second of a random schedule
MAX_DURATION_S = 60.0          # length of one event [s]
MAX_EVENT_TIME_S = 600.0       # explicit event times (the longest episode a scenario may ask for) [s]
MAX_EVENTS = 1000              # explicit event times per schedule
MAX_SECTORS = 16               # blanked LiDAR sectors


@dataclass(frozen=True)
class EventSchedule:
    """When an episodic fault happens: at ``times_s`` and at random at ``rate_per_s``; each event lasts
    ``duration_s`` (module docstring)."""

    times_s: tuple[float, ...] = ranged((), 0, MAX_EVENT_TIME_S)  # explicit event starts [s]
    rate_per_s: float = ranged(0.0, 0, MAX_RATE_PER_S)  # Poisson rate of random events [1/s]
    duration_s: float = ranged(0.0, 0, MAX_DURATION_S)  # length of each event [s]

    def __post_init__(self):
        check_field_ranges(self)
        if len(self.times_s) > MAX_EVENTS:
            raise FieldError("times_s", f"at most {MAX_EVENTS} event times, got {len(self.times_s)}")
        if not all(0.0 <= t <= MAX_EVENT_TIME_S for t in self.times_s):
            raise FieldError("times_s", f"event times must be in [0, {MAX_EVENT_TIME_S:g}] s")
        if not 0.0 <= self.rate_per_s <= MAX_RATE_PER_S:
            raise FieldError("rate_per_s", f"must be in [0, {MAX_RATE_PER_S:g}] events per second, got "
                                           f"{self.rate_per_s:g}")
        if not 0.0 <= self.duration_s <= MAX_DURATION_S:
            raise FieldError("duration_s", f"must be in [0, {MAX_DURATION_S:g}] s, got {self.duration_s:g}")
        if self.enabled and self.duration_s <= 0.0:
            raise FieldError("duration_s", "the schedule has events: set their duration_s (> 0 s)")

    @property
    def enabled(self) -> bool:
        return bool(self.times_s) or self.rate_per_s > 0.0


@dataclass(frozen=True)
class RobotFaults:
    """The robot profile's ``[faults]`` table (module docstring): LiDAR scan dropout and blanked sectors, command
    latency spikes. Odometry and IMU noise and bias are keys of ``[odometry]`` and ``[imu]`` (the sensor models),
    LiDAR range noise of ``[lidar]``."""

    scan_dropout: EventSchedule = EventSchedule()
    latency_spikes: EventSchedule = EventSchedule()
    blanked_sectors_deg: tuple[tuple[float, float], ...] = ()   # [centre, width] pairs in the laser frame [deg]

    def __post_init__(self):
        if len(self.blanked_sectors_deg) > MAX_SECTORS:
            raise FieldError("blanked_sectors_deg", f"at most {MAX_SECTORS} sectors, got "
                                                    f"{len(self.blanked_sectors_deg)}")
        for centre, width in self.blanked_sectors_deg:
            if not -180.0 <= centre <= 180.0:
                raise FieldError("blanked_sectors_deg", f"a sector's centre must be in [-180, 180] deg, got "
                                                        f"{centre:g}")
            if not 0.0 < width <= 360.0:
                raise FieldError("blanked_sectors_deg", f"a sector's width must be in (0, 360] deg, got {width:g}")

    @property
    def any(self) -> bool:
        return self.scan_dropout.enabled or self.latency_spikes.enabled or bool(self.blanked_sectors_deg)


@dataclass(frozen=True)
class PedestrianTurn(EventSchedule):
    """A pedestrian's sudden turns (``turn`` of ``[[pedestrians]]``): at each event it heads ``angle_deg``
    counter-clockwise off the direction it was walking (180: it turns back), for ``duration_s``; with
    ``random_side`` each turn goes left or right at random (its own stream)."""

    angle_deg: float = ranged(180.0, -180, 180)  # heading change, + counter-clockwise [deg]
    random_side: bool = False

    def __post_init__(self):
        super().__post_init__()
        if not (math.isfinite(self.angle_deg) and -180.0 <= self.angle_deg <= 180.0):
            raise FieldError("angle_deg", f"must be in [-180, 180] deg, got {self.angle_deg:g}")


__all__ = ["EventSchedule", "RobotFaults", "PedestrianTurn", "MAX_RATE_PER_S", "MAX_DURATION_S",
           "MAX_EVENT_TIME_S", "MAX_EVENTS", "MAX_SECTORS"]
