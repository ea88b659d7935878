"""A sensor of one's own (docs/extending.md): a second, coarser and noisier LiDAR on the robot's LiDAR mount,
sampled at every control step by an episode observer and written as its own topic into the episode's MCAP log.

    python docs/examples/extra_lidar.py [OUT.mcap]
"""
from __future__ import annotations

import sys

import numpy as np

from bigcbf.episode import Episode
from bigcbf.logio.episode_log import EpisodeLogger
from bigcbf.scenario import load_scenario
from bigcbf.sim.lidar import Lidar, LidarConfig


def run(out: str = "renders/extra_lidar.mcap", time_limit_s: float | None = None) -> dict:
    ep = Episode(load_scenario("crowd_crossing", 0), "big-cbf", 0, time_limit_s=time_limit_s)
    logger = EpisodeLogger(ep, out)                     # the standard topics (/scan, /odom, /tf, ...)
    coarse = Lidar(ep.world.model, LidarConfig(n_beams=90, rate_hz=20.0, range_max_m=4.0, range_noise_std_m=0.02),
                   rng=np.random.default_rng(7))        # its own noise stream: the episode's draws stay the same
    hits = []

    def sample(rec):                                    # an observer: called at every control step (T_C)
        scan = coarse.scan(ep.world.data, rec.t)        # frame "laser", already in the log's /tf_static
        logger.writer.scan(rec.t, scan, topic="/scan_coarse")
        hits.append(int(np.isfinite(scan.ranges).sum()))

    ep.observers.append(sample)
    try:
        result = ep.run()
    finally:
        logger.close()
    return {"success": result.success, "control_steps": result.control_steps, "scans": len(hits),
            "mean_hits": float(np.mean(hits)) if hits else 0.0, "log": str(logger.path)}


if __name__ == "__main__":
    print(run(*sys.argv[1:2]))
