"""Speed of log I/O, calibration, recording and replay (figures for ``bigcbf perf``)."""
from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np


#: a ROS 1 bag of another robot (tests/data of the repository; absent from an installed wheel)
TURTLEBOT_BAG = Path(__file__).resolve().parents[1] / "tests" / "data" / "turtlebot3.bag"


def bench(quick: bool = False) -> dict:
    from bigcbf.logio import LogWriter, open_log, read_series
    from bigcbf.params.robot import RobotProfile
    from bigcbf.types import RobotState

    from .calibrate import calibrate_series, read_log
    from .record import record_calibration
    from .replay import simulate

    out: dict = {}
    with tempfile.TemporaryDirectory(prefix="bigcbf-perf-") as tmp:
        tmp = Path(tmp)
        n = 2000 if quick else 10000
        t0 = time.perf_counter()
        with LogWriter(tmp / "w.mcap") as w:
            for k in range(n):
                w.odom(0.02 * k, RobotState(0.01 * k, 0.0, 0.0, 0.5, 0.0, 0.1))
        out["logio_write_odom_msgs_per_s"] = round(n / (time.perf_counter() - t0), 1)
        t0 = time.perf_counter()
        with open_log(tmp / "w.mcap") as log:
            read_series(log, odom="/odom")
        out["logio_read_odom_msgs_per_s"] = round(n / (time.perf_counter() - t0), 1)

        bag = TURTLEBOT_BAG
        if not bag.is_file():
            out["turtlebot3_skipped"] = (f"{bag} not found: the TurtleBot3 bag is test data of the repository, not "
                                         "part of the installed package; run bigcbf perf in a checkout for it")
        else:
            t0 = time.perf_counter()
            data = read_log(bag)
            t1 = time.perf_counter()
            calibrate_series(data)
            t2 = time.perf_counter()
            out["turtlebot3_read_s"] = round(t1 - t0, 3)
            out["turtlebot3_calibrate_s"] = round(t2 - t1, 3)

        dur = 5.0 if quick else 20.0
        profile = RobotProfile(latency_s=0.08, latency_jitter_s=0.02, gain=((0.9, 0, 0), (0, 0.85, 0), (0, 0, 0.95)),
                               bias=(0.02, 0.0, 0.0), residual_max=(0.03, 0.03, 0.05))
        t0 = time.perf_counter()
        record_calibration(profile, tmp / "drive.mcap", seed=0, duration_s=dur)
        out["record_calibration_realtime_factor"] = round(dur / (time.perf_counter() - t0), 2)
        data = read_log(tmp / "drive.mcap", use_scan=False)
        t0 = time.perf_counter()
        simulate(data.cmd.t, data.cmd.u, data.odom, profile)
        out["replay_realtime_factor"] = round(float(data.odom.t[-1] - data.cmd.t[0]) / (time.perf_counter() - t0), 2)
        if not quick:
            t0 = time.perf_counter()
            calibrate_series(read_log(tmp / "drive.mcap"))
            out["calibrate_20s_drive_s"] = round(time.perf_counter() - t0, 3)
    return {k: float(v) if isinstance(v, (float, np.floating)) else v for k, v in out.items()}
