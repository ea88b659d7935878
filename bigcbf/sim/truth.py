"""Ground truth from the simulator: true clearances, physical contact, and obstacles for the truth mode.

Clearance (paper Eq. (6), left-hand side minus r_R + r_i): the distance from the robot's true centre to each
obstacle's true surface, minus the robot's footprint radius r_R. Walls and boxes are oriented rectangles,
cylinders and pedestrians circles (pedestrian capsules seen from above).
"""
from __future__ import annotations

import mujoco
import numpy as np

from ..perception.ground_truth import ground_truth_obstacles, rectangle_segments
from ..types import Obstacles
from .scene import SceneSpec


class GroundTruth:
    def __init__(self, model: mujoco.MjModel, scene: SceneSpec, r_robot: float = 0.15):
        self.r_robot = r_robot
        rects = []
        for w in scene.walls:
            a, b = np.array([w.x0, w.y0]), np.array([w.x1, w.y1])
            L = np.linalg.norm(b - a)
            rects.append(((a + b) / 2, (L / 2 + w.thickness / 2, w.thickness / 2), np.arctan2(*(b - a)[::-1])))
        for o in scene.boxes:
            rects.append(((o.x, o.y), (o.half_x, o.half_y), o.yaw))
        self.rect_c = np.array([r[0] for r in rects], float).reshape(-1, 2)
        self.rect_h = np.array([r[1] for r in rects], float).reshape(-1, 2)
        yaw = np.array([r[2] for r in rects], float)
        self.rect_cos, self.rect_sin = np.cos(yaw), np.sin(yaw)
        self.segments = np.array([rectangle_segments(*c, *h, y) for c, h, y in
                                  zip(self.rect_c, self.rect_h, yaw)]).reshape(-1, 4)
        self.circ_c = np.array([(c.x, c.y) for c in scene.cylinders], float).reshape(-1, 2)
        self.circ_r = np.array([c.radius for c in scene.cylinders], float)
        self.ped_r = np.array([p.radius for p in scene.pedestrians], float)
        # physical contact: robot geoms against obstacle geoms (not the floor)
        body_root = model.body_rootid[model.geom_bodyid]
        base = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "base_link")
        self.robot_geom = body_root == base
        self.obstacle_geom = (~self.robot_geom) & (model.geom_group >= 1) & (model.geom_group <= 2)

    def obstacles(self, p, ped_p: np.ndarray, ped_v: np.ndarray) -> Obstacles:
        """Truth-mode obstacle estimates (debugging and ablations only, flagged as such): pedestrians and
        cylinders as exact circles, walls and boxes as wall points, laid out as the LiDAR pipeline does."""
        centers = np.concatenate([ped_p.reshape(-1, 2), self.circ_c])
        vels = np.concatenate([ped_v.reshape(-1, 2), np.zeros_like(self.circ_c)])
        radii = np.concatenate([self.ped_r, self.circ_r])
        static = np.concatenate([np.zeros(len(self.ped_r), bool), np.ones(len(self.circ_r), bool)])
        return ground_truth_obstacles(np.asarray(p, float), centers, vels, radii, segments=self.segments,
                                      static=static)

    def rect_distances(self, p: np.ndarray) -> np.ndarray:
        d = p - self.rect_c
        lx = self.rect_cos * d[:, 0] + self.rect_sin * d[:, 1]
        ly = -self.rect_sin * d[:, 0] + self.rect_cos * d[:, 1]
        qx = np.maximum(np.abs(lx) - self.rect_h[:, 0], 0)
        qy = np.maximum(np.abs(ly) - self.rect_h[:, 1], 0)
        return np.hypot(qx, qy)

    def clearance(self, p, ped_p: np.ndarray) -> float:
        """min over obstacles of (distance from the robot centre to the obstacle surface) - r_R."""
        x, y = float(p[0]), float(p[1])
        best = np.inf
        if len(self.rect_c):
            best = min(best, self.rect_distances(np.array([x, y])).min())
        if len(self.circ_c):
            best = min(best, (np.hypot(self.circ_c[:, 0] - x, self.circ_c[:, 1] - y) - self.circ_r).min())
        if len(ped_p):
            best = min(best, (np.hypot(ped_p[:, 0] - x, ped_p[:, 1] - y) - self.ped_r).min())
        return float(best - self.r_robot)

    def in_contact(self, data: mujoco.MjData) -> bool:
        """Physical contact between the robot and any obstacle, wall or pedestrian (MuJoCo's contacts)."""
        n = data.ncon
        if n == 0:
            return False
        g = data.contact.geom[:n]
        a, b = g[:, 0], g[:, 1]
        hit = (self.robot_geom[a] & self.obstacle_geom[b]) | (self.robot_geom[b] & self.obstacle_geom[a])
        return bool(hit.any())
