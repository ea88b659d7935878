"""Robot-side BIG-CBF stack: obstacle prediction, shared uncertainty, behaviors, imagination, selection and the
hard CBF filter. numpy / scipy / numba only: no MuJoCo here (this package must run on a robot).

Equations are cited as ``eq:label (N)``: the paper's LaTeX label, then the number the paper prints (every
numbered display counted, unlabelled ones included; tests/test_equation_refs.py checks every reference):
eq:execution (1) execution model; eq:obs_prop (2), eq:cov_prop (3), eq:predicted_obstacles (4) obstacle
prediction; eq:goal_region (5) goal region; eq:true_safety_requirement (6) physical clearance;
eq:behavior_set (7) the six behaviors; eq:online_behavior_command (8) policy regenerated every tick;
eq:goal_basis (9) goal basis d_g, n_g; eq:behavior_subgoals (10) subgoals; eq:behavior_feedback (11) bounded
feedback; eq:behavior_rollout (12) closed-loop rollout; eq:behavior_terms (13) scoring terms P, F, S, C_sw;
eq:behavior_cost (14) cost J; eq:relative_position_error (15) q_i and eps_rel; the unlabelled display (16) true
relative position; eq:relative_error_bound (17) error bound; the unlabelled display (18) reverse triangle
inequality; eq:robust_distance_condition (19) robust distance condition; eq:shared_barrier (20) D_i and h_i;
eq:uncertainty_margin (21) uncertainty radius m_i; eq:behavior_acceptance (22) barrier acceptance; the unlabelled
display (23) scalar CBF margin gamma; eq:analytic_workload (24) surrogate W~; eq:cbf_condition (25) CBF condition;
eq:hard_cbf_qp (26) minimum-intervention QP; eq:sim_cbf_energy (27) E_CBF.

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
