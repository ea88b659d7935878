"""Perception parameters: LiDAR clustering, circle fitting, tracking (CV Kalman filter), static/dynamic
hysteresis, wall representation and the laser's mounting on the robot.

Every key is optional in a TOML table (``from_dict(PerceptionParams, table)``); the defaults suit the 360-beam,
10 Hz RPLIDAR A1M8-class LiDAR of the Rosmaster X3 (its datasheet; ``bigcbf/profiles/x3_sim.toml``). Units are in the field names (``_m``, ``_s``, ``_rad``,
``_mps``, ``_m2``). What each group does is documented in ``bigcbf/perception/`` next to the code that uses it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields

from .checks import check_field_ranges, ranged

#: The laser frame's pose in base_link on the Rosmaster X3 model: x [m], y [m], yaw [rad] (URDF ``laser_joint``;
#: bigcbf/assets/rosmaster_x3/README.md). The robot's MJCF ``lidar`` site is the source (bigcbf/robots.py reads
#: every robot's mount from its model; tests/test_lidar.py checks the X3's equals this); the perception's default
#: mounting below and the synthetic scans (perception/synthetic.py) use it, and an episode replaces this default by
#: its robot's mount (``Robot.perception_params``).
X3_LASER_MOUNT = (0.0435, 0.0, 0.0)


@dataclass(frozen=True)
class PerceptionParams:
    """Parameters of :class:`bigcbf.perception.Perception` (see the module docstring for the file format)."""

    # --- laser mounting: pose of the laser frame in base_link -------------------------------------------------
    laser_x_m: float = ranged(X3_LASER_MOUNT[0], -2, 2)
    laser_y_m: float = ranged(X3_LASER_MOUNT[1], -2, 2)
    laser_yaw_rad: float = ranged(X3_LASER_MOUNT[2], -2 * math.pi, 2 * math.pi)

    # --- clustering (scan-order segmentation) -------------------------------------------------------------------
    #: Consecutive valid beams belong to one cluster when their points are closer than
    #: max(cluster_dist_m, adaptive breakpoint distance) -- Borges & Aldon (2004): r * sin(dphi) / sin(lambda - dphi)
    #: + 3 * range_sigma_m, with lambda = cluster_lambda_rad (the shallowest incidence still joined).
    cluster_dist_m: float = ranged(0.15, 0, 5, lo_open=True)
    cluster_lambda_rad: float = ranged(0.1745, 0, math.pi / 2, lo_open=True, hi_open=True)
    #: The LiDAR's range noise, standard deviation range_sigma_m + range_sigma_frac * range [m]; set it to match the
    #: sensor. Defaults: the RPLIDAR A1M8 class of the X3 (datasheet: < 1 % of the distance, taken as 2 sigma, plus a
    #: 5 mm floor; bigcbf/profiles/x3_sim.toml). Used by the clustering (3 sigma), the circle fit's tie tolerance and
    #: the wall points' covariance.
    range_sigma_m: float = ranged(0.005, 0, 1)
    range_sigma_frac: float = ranged(0.005, 0, 0.5)
    #: Clusters with fewer points are not objects (single returns of grazing surfaces, thin things): they become
    #: wall points. So does a compact cluster that is not a clean arc and whose median point spacing exceeds
    #: grazing_spacing_factor times the beam spacing at its range (a surface seen at a grazing angle, e.g. a piece
    #: of wall, whose apparent centre slides as the robot moves).
    min_points: int = ranged(3, 2, 1000)
    grazing_spacing_factor: float = ranged(3.0, 0, 100, lo_open=True)
    #: Clusters longer than this (largest distance between two of their points) are walls / extended structure.
    compact_max_extent_m: float = ranged(0.9, 0, 20, lo_open=True)
    #: A compact cluster cut at one of its ends by a nearer return on the adjacent beam (partly hidden) is kept
    #: as a track measurement only when it is a clean arc (the circle fit is accepted); otherwise (e.g. a piece of
    #: wall visible between pedestrians, whose apparent centre would slide) it becomes wall points.

    #: Free-space carving (``bigcbf/perception/freespace.py``): points of an extended cluster that lie where up to
    #: three earlier scans, from free_space_history_s ago and two in between, saw beyond them by more than
    #: free_space_margin_m (plus three range-noise sigmas) are split out as objects of their own (a walker against a
    #: wall). free_space_history_s 0 switches it off.
    free_space_history_s: float = ranged(1.0, 0, 10)
    free_space_margin_m: float = ranged(0.15, 0, 5)

    # --- circle fit ------------------------------------------------------------------------------------------------
    radius_min_m: float = ranged(0.05, 0, 5, lo_open=True)
    radius_max_m: float = ranged(0.6, 0, 5, lo_open=True)
    #: A compact cluster is a circle (algebraic fit; radius clamped to [radius_min_m, radius_max_m]) when that fits
    #: at least as well as a rectangle (L-shape fit) and the points span at least fit_min_arc_rad around its centre.
    fit_min_arc_rad: float = ranged(0.5, 0, 2 * math.pi)
    #: ...and, for a cluster not partly hidden, at least this fraction of the arc that the beams sample on a circle
    #: of radius r at distance d (see ``geometry.measure_compact``).
    fit_span_ratio: float = ranged(0.5, 0, 10)
    #: Track radius: exponential smoothing factor of the measured radius (1 = last measurement only).
    radius_smoothing: float = ranged(0.3, 0, 1, lo_open=True)
    #: Track shape: exponential smoothing factor of the share of its clusters the circle model explained; a track
    #: is round while that share is at least 1/2. A static track that is not round (a box, a wall end, a corner)
    #: is reported as points on its surface, not as its circumscribed circle (``tracker.Tracker.report``).
    shape_smoothing: float = ranged(0.3, 0, 1, lo_open=True)
    #: A compact cluster whose best model (circle or rectangle) leaves an RMS residual above fit_rms_ratio_max
    #: times the range noise's std at its range is not one simple object (two objects merged into one cluster):
    #: it becomes wall points, not a track measurement. Single posts and boxes on recorded scans: at most 1.3 and
    #: 2.2 times.
    fit_rms_ratio_max: float = ranged(3.0, 0, 1000, lo_open=True)
    #: ...likewise a compact cluster whose outline dents away from the sensor by more than concavity_ratio_max
    #: times that std (``geometry.concavity``: a convex object bulges toward the sensor; two objects in one cluster
    #: leave a dent between them). Single posts, boxes and walkers on recorded scans: at most 4.3 times; with the
    #: RMS test this catches 59 % of the clusters that hold two or more objects.
    concavity_ratio_max: float = ranged(5.0, 0, 1000, lo_open=True)

    # --- association and track management ---------------------------------------------------------------------------
    #: A cluster may update a track when its Mahalanobis distance squared is below gate_chi2 (2 dof; 9.21 = 99 %)
    #: or its centre is within gate_min_m of the prediction, and never when farther than gate_max_m.
    gate_chi2: float = ranged(9.21, 0, 1000, lo_open=True)
    gate_min_m: float = ranged(0.3, 0, 20)
    gate_max_m: float = ranged(1.0, 0, 20, lo_open=True)
    #: ...and only when the cluster's radius is within gate_radius_m of the track's.
    gate_radius_m: float = ranged(0.15, 0, 5, lo_open=True)
    #: Track-aided segmentation (``pipeline.Perception._segment``): a scan point lies on a confirmed track's object
    #: when it is within merge_tol_m plus twice the track's position std of its predicted circle
    #: (``tracker.Tracker.surface_owner``); a cluster holding two known objects is split along them.
    merge_tol_m: float = ranged(0.05, 0, 5, lo_open=True)
    #: At most max_tracks confirmed tracks are returned (nearest first); up to max_candidates are maintained.
    max_tracks: int = ranged(8, 0, 200)
    max_candidates: int = ranged(32, 0, 1000)
    #: A tentative track is confirmed after confirm_hits measurements, deleted after tentative_max_misses misses.
    confirm_hits: int = ranged(3, 1, 100)
    tentative_max_misses: int = ranged(1, 0, 100)
    #: A confirmed track without measurement coasts (constant velocity, growing covariance) for coast_s, then is
    #: deleted (e.g. a pedestrian hidden behind a wall or another pedestrian).
    coast_s: float = ranged(1.0, 0, 60, lo_open=True)
    #: While a track coasts its reported position covariance is bounded by physics (``tracker.coast_bound``): a
    #: static object does not move (its covariance stays that of its last update); a dynamic one is a walking
    #: person, who cannot deviate from the constant-velocity prediction by more than
    #: min((walk_speed_max_mps + |v|) tau, walk_accel_max_mps2 tau^2 / 2 + sigma_v tau) after tau seconds.
    #: 2.0 m/s: above brisk walking (free walking speed 1.34 +- 0.26 m/s, Weidmann 1993); 2.5 m/s^2: a walker
    #: starting at 1.3 m/s within the social-force relaxation time 0.5 s (Helbing & Molnar 1995).
    walk_speed_max_mps: float = ranged(2.0, 0, 10, lo_open=True)
    walk_accel_max_mps2: float = ranged(2.5, 0, 50, lo_open=True)

    # --- constant-velocity Kalman filter ----------------------------------------------------------------------------
    #: A cluster centre's measurement covariance is its fit's own (from the range noise and the beam spacing at its
    #: points, ``geometry.circle_fit_covariance`` / ``rectangle_covariance``: a far post seen by four beams is a
    #: poorer measurement than a near one seen by thirty) plus this model error squared, per axis [m] (the object is
    #: not exactly a circle or a box, the scan not instantaneous). 0.01 m: on recorded scans of posts the fitted
    #: centres' normalised squared errors then average 2.0-2.3 (chi-square, 2 dof: 2) from 5 to 20 points.
    fit_model_sigma_m: float = ranged(0.01, 0, 1)
    #: Power spectral density of the white-noise acceleration (m^2/s^3).
    accel_psd_m2ps3: float = ranged(0.5, 0, 100)
    #: Initial velocity standard deviation of a new track (velocity starts at 0).
    init_vel_sigma_mps: float = ranged(1.5, 0, 10, lo_open=True)
    #: Static tracks report the estimate of a constant-position Kalman filter run beside the CV filter: the position
    #: is a random walk of this power spectral density [m^2/s] (the fitted centre of a post wanders as the viewpoint
    #: changes: 1e-3 m^2/s gives a steady-state std of ~2 cm at 10 Hz with a 5 cm measurement std). When its estimate
    #: and the CV filter's disagree beyond gate_chi2 (the object moves), it restarts from the CV filter's.
    static_pos_psd_m2ps: float = ranged(1e-3, 0, 10)

    # --- static / dynamic hysteresis --------------------------------------------------------------------------------
    #: A static track becomes dynamic after n_dynamic consecutive updates with speed > v_dynamic_mps and speed >
    #: dynamic_sigma standard deviations of the speed estimate (``classify``: the speed must be significant); a
    #: dynamic one becomes static after n_static consecutive updates with speed < v_static_mps. New tracks start
    #: static.
    v_dynamic_mps: float = ranged(0.3, 0, 10, lo_open=True)
    v_static_mps: float = ranged(0.15, 0, 10, lo_open=True)
    n_dynamic: int = ranged(3, 1, 100)
    n_static: int = ranged(5, 1, 100)
    dynamic_sigma: float = ranged(2.0, 0, 100)
    #: The classification starts once a track's velocity rests on more than this many measurements. 1: from the
    #: second measurement on. 3 (= confirm_hits) suppressed phantom dynamic tracks of small far objects (a new track's
    #: first velocities are differences of two or three noisy centres) but delayed a pedestrian who appears near the
    #: robot, who is reported static (v = 0) until classified: with 3, BIG-CBF collided in 2 of 60 dynamic episodes
    #: (crowd_crossing seed 0, blind_corner seed 18; none with 1); see docs/fidelity.md.
    classify_after_hits: int = ranged(1, 1, 100)

    # --- walls ------------------------------------------------------------------------------------------------------
    #: Each wall cluster contributes its point nearest to the robot and points spaced wall_spacing_m along the
    #: cluster from there; of those within wall_range_m of the robot the wall_max_points nearest are returned.
    wall_spacing_m: float = ranged(0.2, 0, 10, lo_open=True)
    wall_range_m: float = ranged(3.0, 0, 100, lo_open=True)
    wall_max_points: int = ranged(24, 0, 1000)
    #: A wall point's covariance comes from the scan (``geometry.wall_point_covariance``): range noise along the
    #: beam, the beam's angular resolution across it. This fixed isotropic covariance [m^2] is for the ground-truth
    #: mode's wall points only.
    wall_cov_m2: float = ranged(1e-4, 0, 1)

    # --- ground-truth mode (debugging and ablations only) -----------------------------------------------------------
    #: Position covariance given to objects in ground-truth mode (isotropic, m^2).
    ground_truth_cov_m2: float = ranged(1e-4, 0, 1)

    def __post_init__(self):
        check_field_ranges(self)
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, float) and not math.isfinite(v):
                raise ValueError(f"{f.name} must be finite")
        positive = ("cluster_dist_m", "grazing_spacing_factor", "compact_max_extent_m",
                    "radius_min_m", "gate_chi2", "gate_max_m", "gate_radius_m", "coast_s",
                    "init_vel_sigma_mps", "v_static_mps", "wall_spacing_m", "wall_range_m", "walk_speed_max_mps",
                    "walk_accel_max_mps2", "fit_rms_ratio_max", "merge_tol_m",
                    "concavity_ratio_max")
        for name in positive:
            if getattr(self, name) <= 0:
                raise ValueError(f"{name} must be > 0")
        non_negative = ("range_sigma_m", "range_sigma_frac", "fit_span_ratio", "fit_min_arc_rad", "gate_min_m",
                        "accel_psd_m2ps3", "static_pos_psd_m2ps", "fit_model_sigma_m", "dynamic_sigma", "wall_cov_m2",
                        "ground_truth_cov_m2")
        for name in non_negative:
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must be >= 0")
        if not 0 < self.cluster_lambda_rad < math.pi / 2:
            raise ValueError("cluster_lambda_rad must be in (0, pi/2)")
        if self.radius_max_m < self.radius_min_m:
            raise ValueError("radius_max_m must be >= radius_min_m")
        if not 0 < self.radius_smoothing <= 1:
            raise ValueError("radius_smoothing must be in (0, 1]")
        if not 0 < self.shape_smoothing <= 1:
            raise ValueError("shape_smoothing must be in (0, 1]")
        if self.gate_min_m > self.gate_max_m:
            raise ValueError("gate_min_m must be <= gate_max_m")
        if self.min_points < 2:
            raise ValueError("min_points must be >= 2")
        if self.max_tracks < 0 or self.wall_max_points < 0:
            raise ValueError("max_tracks and wall_max_points must be >= 0")
        if self.max_candidates < self.max_tracks:
            raise ValueError("max_candidates must be >= max_tracks")
        if self.confirm_hits < 1 or self.tentative_max_misses < 0:
            raise ValueError("confirm_hits must be >= 1 and tentative_max_misses >= 0")
        if self.classify_after_hits < 1:
            raise ValueError("classify_after_hits must be >= 1")
        if self.n_dynamic < 1 or self.n_static < 1:
            raise ValueError("n_dynamic and n_static must be >= 1")
        if not self.v_static_mps < self.v_dynamic_mps:
            raise ValueError("v_static_mps must be < v_dynamic_mps (hysteresis band)")
