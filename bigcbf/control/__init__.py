"""Robot-side BIG-CBF stack: obstacle prediction, shared uncertainty, behaviors, imagination, selection and the
hard CBF filter. numpy / scipy / numba only: no MuJoCo here (this package must run on a robot).

Equation numbers in docstrings follow issue 3 (the paper's LaTeX labels in brackets):
(1) execution model [eq:execution]; (2)-(4) obstacle prediction [eq:obs_prop, eq:cov_prop,
eq:predicted_obstacles]; (5) online behavior command [eq:online_behavior_command]; (6) goal basis
[eq:goal_basis]; (7) behavior subgoals [eq:behavior_subgoals]; (8) bounded feedback [eq:behavior_feedback];
(9) closed-loop rollout [eq:behavior_rollout]; (10) scoring terms P, F, S, C_sw and cost J [eq:behavior_terms,
eq:behavior_cost]; (11) relative position q_i and error [eq:relative_position_error]; (12) error bound
[eq:relative_error_bound]; (13) robust distance condition [eq:robust_distance_condition]; (14) D_i and h_i
[eq:shared_barrier]; (15) uncertainty radius m_i [eq:uncertainty_margin]; (16) barrier acceptance
[eq:behavior_acceptance]; (17) CBF margin gamma and surrogate W~ [eq:analytic_workload]; (18) CBF condition
[eq:cbf_condition]; (19) minimum-intervention QP [eq:hard_cbf_qp]; (20) E_CBF [eq:sim_cbf_energy].

Frames: the state is odometry (pose in odom, twist in base_link); u is a body twist (vx, vy, wz); R(theta) maps
body to odom.
"""
from .behaviors import BEHAVIORS, MODES, REVERSE, behavior_command
from .big_cbf import BigCbfPlanner
from .cbf import CbfFilter, CbfRows, FilterInfo, cbf_rows, select_constraints
from .imagination import Imagination, imagine
from .methods import METHODS, CbfOnlyPlanner
from .metrics import EpisodeMetrics, cbf_energy, p95, percentile
from .planner import PlanInfo, Planner
from .prediction import age_obstacles, predict_obstacles, q_sigma_for
from .selection import BehaviorSelector, Selection
from .uncertainty import barrier, e_exec, inflated_radius, nominal_velocity, uncertainty_radius

__all__ = ["BEHAVIORS", "MODES", "REVERSE", "behavior_command", "BigCbfPlanner", "CbfFilter", "CbfRows",
           "FilterInfo", "cbf_rows", "select_constraints", "Imagination", "imagine", "METHODS", "CbfOnlyPlanner",
           "EpisodeMetrics", "cbf_energy", "p95", "percentile", "PlanInfo", "Planner",
           "age_obstacles", "predict_obstacles", "q_sigma_for", "BehaviorSelector", "Selection", "barrier", "e_exec",
           "inflated_radius", "nominal_velocity", "uncertainty_radius"]
