"""Robot-side LiDAR perception (paper Sec. V): clusters, circle fits, CV Kalman tracks with static/dynamic
hysteresis, wall points. No simulator import: this package runs on a robot (numpy and scipy only).

``Perception(params).update(scan, pose) -> Obstacles`` is the entry point; ``ground_truth_obstacles`` is the
clearly flagged ground-truth mode for debugging and ablations.
"""
from ..params.perception import PerceptionParams
from .ground_truth import ground_truth_obstacles, rectangle_segments, segment_points
from .pipeline import Perception, wall_obstacles
from .tracker import Tracker

__all__ = ["Perception", "PerceptionParams", "Tracker", "ground_truth_obstacles", "rectangle_segments",
           "segment_points", "wall_obstacles"]
