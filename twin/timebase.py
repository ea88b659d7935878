"""Logs as they come: the odometry's time base and twist, the command stream's publication, gaps.

A robot log's receive times are when the recorder got each message, not when the robot measured it: over Wi-Fi or
a busy computer, odometry arrives in bursts (several messages within a millisecond, then a pause). Differences
over such intervals are noise (a pose change over 1 ms of receive time is a velocity of metres per second), and
delays measured on them carry the transport's jitter. So, for the odometry (:func:`odometry_timing`):

1. header stamps, when they are the robot's measurement times on the log's clock: strictly increasing, and the
   median of (receive time - stamp) within [``-0.05``, ``max_stamp_offset_s``] s (a transport latency);
2. header stamps on a *second clock* (the robot's own, not synchronised with the recorder; or simulation time
   against wall time): mapped onto the log clock by t = a stamp + b, a and b by least squares of the receive times
   on the stamps, then b lowered to the 2nd percentile of the residuals (the mapped stamp is the earliest a message
   could have been received: the measurement time plus the smallest transport latency);
3. no usable stamps and bursty receive times (more than 1 % of the intervals shorter than a fifth of the nominal
   period): a robust time base, the lower envelope of the receive times at the nominal period, t_i =
   min over j in [i - 25, i + 25] of (r_j - (j - i) P) within stretches without gaps (messages are produced every
   P and none is received before it was produced: each r_j - (j - i) P bounds message i's production time from
   above), P the median over the stretch of (r_(i+50) - r_i) / 50;
4. otherwise the receive times.

Twist (:func:`odometry_twist`): the odometry message's own twist when it has one; when every twist is zero while
the pose moves (a publisher that leaves it empty), the body twist from pose differences on the time base above,
over at least 60 ms (central differences, rotated into the body frame at the mid heading).

Commands (:func:`command_publication`): a driver holds the last command, so the held command is the input
whatever the publication; "periodic" when at least half of the intervals lie within 25 % of their median and that
median is under 0.5 s (a controller's rate), else "on change" (a teleoperation tool or a planner publishing only
new commands): the log then has no control period, and e_ZOH uses the stack's T_C (twin.calibrate).

Every choice is reported as a note, and so are odometry gaps (intervals over ``gap_s`` on the chosen time base).

Order (:func:`order_by_stamps`, :func:`command_order`). A log's times per topic must run forwards: a recorder writes
messages as it receives them, with their receive time as the log time. A replayed, merged or re-written log can
break that, and a reader that sorts on the log time then scrambles the series (an independent test found tau95
0.49-0.61 s instead of 0.098 s, said nowhere). Each topic is therefore checked against a second witness of its
order, and repaired only when the witnesses make the order unambiguous:

- stamped topics (odometry, scans): the header stamps. A message whose stamp is below an earlier message's (in
  log-time order) is out of order. When the stamps are distinct, the messages are taken in stamp order and the
  log times (sorted) re-assigned in that order: exact when the log times were permuted, within the size of the
  disorder otherwise. Equal stamps with different contents leave the order undecidable: refused (UserError naming
  the file and the topic).
- commands (geometry_msgs/Twist has no header): the order of the messages in the file (MCAP only: twin.calibrate
  .read_log reads it), and the MCAP publish times and sequence numbers where they are set. Log times that go back
  in the file's order while the publish times or sequence numbers run forwards: the file's order, the log times
  re-assigned in it. Log times that go back in a few long stretches that do not overlap in time (bags merged one
  after the other): sorted on the log time. Anything else (scattered reversals with no witness, stretches that
  overlap, equal log times with different commands where the order matters): refused.

Every repair is a note: how many messages were out of order, which clock was used.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from bigcbf.logio import LogData

ENVELOPE_WINDOW = 50


@dataclass(frozen=True)
class TimebaseOptions:
    max_stamp_offset_s: float = 0.3    # stamps this much older than their receive times are still the log's clock [s]
    burst_fraction: float = 0.01       # more than this fraction of very short intervals: bursty receive times [-]
    gap_s: float = 0.25                # odometry intervals longer than this are gaps [s]
    min_diff_s: float = 0.06           # pose differences span at least this [s]


@dataclass
class OdomTiming:
    t: np.ndarray          # the analysis time of each odometry sample (log clock) [s]
    source: str            # "receive times", "header stamps", "header stamps (second clock)", "robust time base"
    period_s: float        # the nominal period [s]
    notes: list[str]


def _mean_period(t: np.ndarray) -> float:
    dt = np.diff(t)
    dt = dt[dt > 0]
    if len(dt) == 0:
        return float("nan")
    # the median of intervals above a fifth of the mean: robust to bursts and to a few long gaps
    m = float(np.mean(dt))
    return float(np.median(dt[dt > 0.2 * m])) if np.any(dt > 0.2 * m) else m


def bursty(t_recv: np.ndarray, period_s: float, fraction: float = 0.01) -> float:
    """The fraction of receive intervals shorter than a fifth of the nominal period (0 when not bursty)."""
    dt = np.diff(np.asarray(t_recv, float))
    return float(np.mean(dt < 0.2 * period_s)) if len(dt) else 0.0


def lower_envelope(t_recv: np.ndarray, gap_s: float, window: int = ENVELOPE_WINDOW) -> np.ndarray:
    """The robust time base of rule 3 (module docstring): within each stretch without gaps longer than ``gap_s``,
    t_i = min over j within window / 2 of i of (r_j - (j - i) P), P = the stretch's median period over ``window``
    messages."""
    r = np.asarray(t_recv, float)
    out = r.copy()
    cuts = np.flatnonzero(np.diff(r) > gap_s) + 1
    for a, b in zip(np.r_[0, cuts], np.r_[cuts, len(r)]):
        n = b - a
        if n < 3:
            continue
        K = min(window, n - 1)
        P = float(np.median((r[a + K:b] - r[a:b - K]) / K))
        idx = np.arange(n)
        z = r[a:b] - idx * P
        w = window // 2
        zpad = np.concatenate([np.full(w, np.inf), z, np.full(w, np.inf)])
        from numpy.lib.stride_tricks import sliding_window_view
        out[a:b] = sliding_window_view(zpad, 2 * w + 1).min(axis=1) + idx * P
    return out


def _stamps_usable(stamp: np.ndarray) -> bool:
    s = np.asarray(stamp, float)
    return bool(len(s) > 2 and np.all(np.isfinite(s)) and np.all(s > 0) and np.mean(np.diff(s) > 0) > 0.99)


def odometry_timing(t_recv, stamp, opt: TimebaseOptions = TimebaseOptions(), topic: str = "odometry") -> OdomTiming:
    """The odometry's time base (rules 1-4 of the module docstring)."""
    r = np.asarray(t_recv, float)
    s = np.asarray(stamp, float)
    notes: list[str] = []
    P_recv = _mean_period(r)
    burst = bursty(r, P_recv, opt.burst_fraction)
    if _stamps_usable(s):
        off = r - s
        med = float(np.median(off))
        if -0.05 <= med <= opt.max_stamp_offset_s:
            t, source = s.copy(), "header stamps"
            notes.append(f"{topic}: times from the header stamps (on the log's clock, median receive - stamp "
                         f"{med * 1e3:+.0f} ms" + (f"; receive times are bursty, {burst:.1%} of intervals under a "
                                                    f"fifth of the period" if burst > opt.burst_fraction else "")
                         + ")")
        else:
            a, b = np.polyfit(s - s[0], r, 1)
            resid = r - (a * (s - s[0]) + b)
            b += float(np.quantile(resid, 0.02))
            t, source = a * (s - s[0]) + b, "header stamps (second clock)"
            rate = f"; that clock runs {abs(a - 1):.2%} {'fast' if a < 1 else 'slow'}" if abs(a - 1) > 1e-3 else ""
            notes.append(f"{topic}: the header stamps are on a second clock (median receive - stamp {med:+.3f} s); "
                         f"mapped onto the log's clock by their lowest transport latency{rate}")
    elif burst > opt.burst_fraction:
        t, source = lower_envelope(r, max(opt.gap_s, 5 * P_recv)), "robust time base"
        notes.append(f"{topic}: bursty receive times ({burst:.1%} of intervals under a fifth of the "
                     f"{P_recv * 1e3:.0f} ms period) and no usable header stamps: times from the lower envelope of "
                     "the receive times at the nominal period")
    else:
        t, source = r.copy(), "receive times"
    # keep the order (a stamp out of order by less than a period is a tie, not a reversal)
    t = np.maximum.accumulate(t)
    P = _mean_period(t)
    dt = np.diff(t)
    gaps = dt[dt > max(opt.gap_s, 3 * P)]
    if len(gaps):
        notes.append(f"{topic}: {len(gaps)} gaps in the odometry (longest {gaps.max():.2f} s, on the "
                     f"{source}); nothing is interpolated across them")
    return OdomTiming(t, source, P, notes)


def _wrap(a):
    return np.arctan2(np.sin(a), np.cos(a))


def twist_from_poses(t: np.ndarray, pose: np.ndarray, min_span_s: float = 0.06) -> np.ndarray:
    """Body twist (N, 3) from poses (N, 3) at times t: central differences over the nearest samples at least
    ``min_span_s`` apart (one-sided at the ends), in the body frame at the mid heading."""
    t = np.asarray(t, float)
    n = len(t)
    i = np.arange(n)
    hi = np.clip(np.searchsorted(t, t + min_span_s / 2, side="left"), 0, n - 1)
    lo = np.clip(np.searchsorted(t, t - min_span_s / 2, side="right") - 1, 0, n - 1)
    hi = np.maximum(hi, np.minimum(i + 1, n - 1))
    lo = np.minimum(lo, np.maximum(i - 1, 0))
    h = t[hi] - t[lo]
    dth = _wrap(pose[hi, 2] - pose[lo, 2])
    mid = pose[lo, 2] + 0.5 * dth
    dx, dy = pose[hi, 0] - pose[lo, 0], pose[hi, 1] - pose[lo, 1]
    c, s = np.cos(mid), np.sin(mid)
    ok = h > 0
    out = np.zeros((n, 3))
    out[ok] = np.column_stack([(c * dx + s * dy)[ok] / h[ok], (-s * dx + c * dy)[ok] / h[ok], dth[ok] / h[ok]])
    return out


def twist_is_empty(twist: np.ndarray, pose: np.ndarray) -> bool:
    """Whether the odometry messages carry no twist although the pose moves (more than 0.1 m or 0.2 rad)."""
    if len(pose) == 0:
        return False
    moved = np.ptp(pose[:, 0]) > 0.1 or np.ptp(pose[:, 1]) > 0.1 or np.ptp(np.unwrap(pose[:, 2])) > 0.2
    return bool(moved and np.all(np.abs(twist) < 1e-9))


def command_publication(t_cmd: np.ndarray) -> tuple[str, float]:
    """("periodic" or "on change", median interval [s]) of a command stream (module docstring)."""
    dt = np.diff(np.asarray(t_cmd, float))
    dt = dt[dt > 1e-4]
    if len(dt) < 3:
        return "on change", float(np.median(dt)) if len(dt) else float("nan")
    med = float(np.median(dt))
    regular = np.mean(np.abs(dt - med) <= 0.25 * med)
    return ("periodic" if regular >= 0.5 and med < 0.5 else "on change"), med


def out_of_order(x) -> int:
    """How many samples lie below an earlier sample (0 for a non-decreasing sequence)."""
    x = np.asarray(x, float)
    if len(x) < 2:
        return 0
    return int(np.sum(x[1:] < np.maximum.accumulate(x)[:-1]))


def _differ(values: np.ndarray, key: np.ndarray) -> int:
    """How many groups of equal ``key`` hold rows of ``values`` that differ."""
    order = np.argsort(key, kind="stable")
    k, v = key[order], values.reshape(len(key), -1)[order]
    same = np.flatnonzero(k[1:] == k[:-1])
    return int(np.sum(np.any(np.abs(v[same + 1] - v[same]) > 1e-12, axis=1)))


def order_by_stamps(t_recv, stamp, values, topic: str, path: str) -> tuple[np.ndarray | None, np.ndarray, str | None]:
    """Check a stamped topic's log times against its header stamps (module docstring, Order).

    ``t_recv`` in log-time order, ``stamp`` and ``values`` (N, k) in the same order. Returns (order, t, note):
    ``order`` the permutation that puts the messages in stamp order (None: nothing to repair), ``t`` the log times
    to use in that order, and the note; raises UserError when the order cannot be decided."""
    from bigcbf.errors import UserError
    r = np.asarray(t_recv, float)
    s = np.asarray(stamp, float)
    n = len(s)
    set_ = np.isfinite(s) & (s != 0)
    if n < 3 or set_.sum() < 0.99 * n:
        return None, r, None            # no stamps to tell the order by (the log-time order is all there is)
    late = out_of_order(np.where(set_, s, -np.inf))
    if late == 0:
        return None, r, None
    dup = _differ(np.asarray(values, float), s)
    if dup:
        raise UserError(f"{topic}: {late} of {n} messages are out of order in log time against their header stamps, "
                        f"and {dup} header stamps are shared by messages with different contents: the true order "
                        "cannot be decided (a merged or replayed log?); give a log whose times run forwards",
                        file=path, field=topic)
    order = np.argsort(np.where(set_, s, -np.inf), kind="stable")
    return order, np.sort(r), (f"{topic}: {late} of {n} messages were out of order in log time against their header "
                               "stamps (a replayed or merged log?); repaired: the messages ordered on the header "
                               "stamps, the log times re-assigned in that order")


def command_order(t_file_ns, publish_ns, sequence, topic: str, path: str) -> tuple[str, str | None]:
    """How to order a command topic whose log times ``t_file_ns`` (int, in the file's order) may go back (module
    docstring, Order): ("as is" | "file order" | "log time", note); raises UserError when it cannot be decided.
    ``publish_ns`` and ``sequence``: the MCAP publish times and sequence numbers in the file's order."""
    from bigcbf.errors import UserError
    t = np.asarray(t_file_ns, np.int64)
    n = len(t)
    late = out_of_order(t)
    if late == 0:
        return "as is", None
    witnesses = []
    p = np.asarray(publish_ns, np.int64)
    if len(p) == n and np.any(p != t) and np.any(p > 0) and np.all(np.diff(p) > 0):
        witnesses.append("publish times")
    q = np.asarray(sequence, np.int64)
    if len(q) == n and np.all(np.diff(q) > 0) and np.ptp(q) > 0:
        witnesses.append("sequence numbers")
    if witnesses:
        if len(np.unique(t)) < n:
            raise UserError(f"{topic}: {late} of {n} messages are out of order in log time, and some share a log time: "
                            "the true times cannot be re-assigned; give a log whose times run forwards",
                            file=path, field=topic)
        return "file order", (f"{topic}: {late} of {n} messages were out of order in log time against the file's "
                              f"order and its {' and '.join(witnesses)} (a replayed or re-written log?); repaired: the "
                              "messages taken in the file's order, the log times re-assigned in that order")
    cuts = np.flatnonzero(np.diff(t) < 0) + 1
    runs = [t[a:b] for a, b in zip(np.r_[0, cuts], np.r_[cuts, n])]
    spans = sorted((int(r.min()), int(r.max())) for r in runs)
    disjoint = all(b0 > a1 for (_, a1), (b0, _) in zip(spans, spans[1:]))
    if len(runs) <= 4 and min(len(r) for r in runs) >= 20 and disjoint:
        return "log time", (f"{topic}: its log times go back {len(cuts)} time(s) in the file's order, in "
                            f"{len(runs)} stretches that do not overlap in time (recordings merged one after the "
                            f"other?); sorted on the log time ({late} of {n} messages had been out of order)")
    why = ("in stretches that overlap in time (the same topic recorded twice?)" if len(runs) <= 4 else
           f"at {len(cuts)} places")
    raise UserError(f"{topic}: its log times go back {why} in the file's order ({late} of {n} messages out of "
                    "order), and it has no header stamps, publish times or sequence numbers to tell the true order "
                    "by; give a log whose times run forwards", file=path, field=topic)


def prepare(data: LogData, opt: TimebaseOptions = TimebaseOptions()) -> tuple[LogData, OdomTiming, list[str]]:
    """The log with its odometry on the chosen time base (``odom.t``; the receive times stay in ``odom.stamp``'s
    place only if the stamps are unusable) and twist; returns (log, timing, notes)."""
    o = data.odom
    order = np.argsort(o.t, kind="stable")
    t_recv, stamp, pose, twist = o.t[order], o.stamp[order], o.pose[order], o.twist[order]
    reorder, t_recv, note = order_by_stamps(t_recv, stamp, np.column_stack([pose, twist]), o.topic, str(data.path))
    order_notes = [note] if note else []
    if reorder is not None:
        stamp, pose, twist = stamp[reorder], pose[reorder], twist[reorder]
    if data.scan is not None and len(data.scan.t):
        sc = data.scan
        so = np.argsort(sc.t, kind="stable")
        sreorder, st, snote = order_by_stamps(sc.t[so], sc.stamp[so], sc.stamp[so], sc.topic, str(data.path))
        if sreorder is not None:
            data = dataclasses.replace(data, scan=dataclasses.replace(sc, t=st, stamp=sc.stamp[so][sreorder]))
            order_notes.append(snote)
    timing = odometry_timing(t_recv, stamp, opt, topic=o.topic)
    notes = order_notes + list(timing.notes)
    order = np.argsort(timing.t, kind="stable")
    t = timing.t[order]
    pose, twist = pose[order], twist[order]
    if twist_is_empty(twist, pose):
        twist = twist_from_poses(t, pose, opt.min_diff_s)
        notes.append(f"{o.topic}: the messages carry no twist; the body twist is taken from pose differences over "
                     f"at least {opt.min_diff_s * 1e3:.0f} ms on the {timing.source}")
    odom = dataclasses.replace(o, t=t, stamp=stamp[order], pose=pose, twist=twist)
    return dataclasses.replace(data, odom=odom), timing, notes
