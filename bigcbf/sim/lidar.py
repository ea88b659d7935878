"""A simulated 2-D LiDAR: one ``mujoco.mj_multiRay`` call per scan, output shaped like sensor_msgs/LaserScan."""
from __future__ import annotations

from dataclasses import dataclass, fields

import mujoco
import numpy as np

from ..params.robot import LidarModel
from ..types import LaserScan

#: geom groups the LiDAR sees: 1 (walls, static obstacles) and 2 (pedestrians); not the floor (0), not the robot.
LIDAR_GEOMGROUP = np.array([0, 1, 1, 0, 0, 0], dtype=np.uint8)


@dataclass(frozen=True)
class LidarConfig(LidarModel):
    """The LiDAR model of the robot profile (``bigcbf.params.robot.LidarModel``: beams, rate, range limits, range
    noise) plus the MJCF site it is mounted at."""

    site: str = "lidar"

    def steps_per_scan(self, dt: float) -> int:
        """Physics steps of ``dt`` seconds between two scans: 1 / rate_hz rounded, at least 1 (the documented rate
        range, at most 100 Hz, keeps it >= 5 at the 2 ms physics step; a scan period below one step is one step,
        never a division by zero)."""
        return max(1, int(round(1.0 / (self.rate_hz * dt))))

    @classmethod
    def from_model(cls, model: LidarModel, site: str = "lidar") -> "LidarConfig":
        return cls(**{f.name: getattr(model, f.name) for f in fields(LidarModel)}, site=site)


class Lidar:
    """n_beams beams over 360 degrees in the laser frame (x forward, counter-clockwise), angle_min = -pi.

    Beams that hit nothing within range_max, or closer than range_min, report inf (REP 117). Range noise: Gaussian
    with std ``range_noise_std_m + range_noise_frac * r`` (``LidarModel``), drawn from the LiDAR's own stream.
    """

    def __init__(self, model: mujoco.MjModel, config: LidarConfig = LidarConfig(), rng: np.random.Generator | None = None):
        self.model = model
        self.config = config
        self.rng = rng if rng is not None else np.random.default_rng(0)
        self.site_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, config.site)
        if self.site_id < 0:
            raise ValueError(f"the model has no site named {config.site!r} for the LiDAR")
        n = config.n_beams
        self.angle_increment = 2 * np.pi / n
        self.angle_min = -np.pi
        a = self.angle_min + self.angle_increment * np.arange(n)
        self.angles = a                                     # beam angles in the laser frame [rad]
        self._local = np.stack([np.cos(a), np.sin(a), np.zeros(n)], axis=1)   # unit vectors in the laser frame
        self._vec = np.zeros(3 * n)
        self._geomid = np.zeros(n, dtype=np.int32)
        self._dist = np.zeros(n)

    def scan(self, data: mujoco.MjData, stamp: float | None = None) -> LaserScan:
        cfg = self.config
        pnt = data.site_xpos[self.site_id].copy()
        R = data.site_xmat[self.site_id].reshape(3, 3)
        self._vec[:] = (self._local @ R.T).ravel()          # unit directions in the world: distances in metres
        mujoco.mj_multiRay(self.model, data, pnt, self._vec, LIDAR_GEOMGROUP, 1, -1, self._geomid, self._dist,
                           None, cfg.n_beams, cfg.range_max_m)
        r = self._dist.copy()
        if cfg.range_noise_std_m > 0 or cfg.range_noise_frac > 0:
            r = r + self.rng.standard_normal(r.shape) * cfg.range_sigma(np.maximum(r, 0.0))
        bad = (self._geomid < 0) | (self._dist < 0) | (r > cfg.range_max_m) | (r < cfg.range_min_m)
        r[bad] = np.inf
        return LaserScan(stamp=float(data.time if stamp is None else stamp), angle_min=self.angle_min,
                         angle_increment=self.angle_increment, range_min=cfg.range_min_m,
                         range_max=cfg.range_max_m, ranges=r.astype(np.float32), frame_id="laser",
                         scan_time=1.0 / cfg.rate_hz)
