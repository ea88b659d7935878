"""Parameters of the BIG-CBF navigation stack (paper Table I and Sec. V), loadable from TOML.

Every field carries its unit in its name or its comment. The defaults are the simulation profile of
Table I (``SIMULATION``); ``PHYSICAL`` is the hardware profile of Sec. V. A TOML file may give any subset of
keys; missing keys keep the default (or the ``base`` preset passed to :func:`load_stack_params`), unknown keys
are an error naming the file and the key. A calibrated *uncertainty profile* written by the digital twin is
simply a StackParams TOML holding only the ``[uncertainty]`` and ``[uncertainty.execution]`` tables::

    [uncertainty]
    tau95_s = 0.12
    e_zoh_m = 0.03

    [uncertainty.execution]
    A = [[0.92, 0.0, 0.0], [0.0, 0.88, 0.0], [0.0, 0.0, 0.97]]
    d = [0.01, 0.0, 0.0]
    residual_speed_mps = [0.0, 0.4, 0.8]
    residual_bound_mps = [0.02, 0.03, 0.05]
    residual_horizon_s = 0.15
    residual_coverage = 0.95

The calibration adds informational keys the stack does not use (it reads them back, and ``bigcbf replay --profile``
uses the limits): ``wheel_speed_max_mps``, ``wheel_yaw_lever_m``, ``wheel_accel_max_mps2`` in
``[uncertainty.execution]`` (the robot's wheel limits: eq:execution (1) holds below them), and the table
``[uncertainty.tau95_parts]`` (what tau95 is made of).

Equations are cited as ``eq:label (N)``, the paper's LaTeX label and printed number (``bigcbf/control/__init__.py``).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import FieldError
from .checks import check_field_ranges, ranged
from .robot import IDENTITY3, Mat3, Vec3
from .toml_io import from_dict, load_toml, save, to_dict

__all__ = ["ExecutionModel", "Tau95Parts", "UncertaintyParams", "StackParams", "PlusRules", "PAPER_RULES", "SIMULATION", "PHYSICAL",
           "load_stack_params", "save_stack_params", "default_stack_params", "stack_profile_path", "read_provenance"]


#: caps that keep any parameter file from hanging or exhausting the machine: imagination steps, the control
#: period (the simulator's 2 ms physics step is the shortest), residual-bound knots
MAX_N = 500
MIN_T_C_S = 0.002
MAX_KNOTS = 100


def _finite(name: str, *values: float) -> None:
    if not all(math.isfinite(v) for v in values):
        raise ValueError(f"{name} must be finite")


@dataclass(frozen=True)
class ExecutionModel:
    """The execution model eq:execution (1) and the execution-residual term e_exec(u) of eq:uncertainty_margin (21).

    The realized body twist is ``A u + d + r``; eq:execution (1) uses the translational rows (vx, vy) of A and d,
    the yaw row propagates the heading in the imagination.

    ``e_exec(u) = residual_horizon_s * bound(||u_xy||)`` [m], with ``bound`` the piecewise-linear interpolation
    of ``residual_bound_mps`` over the knots ``residual_speed_mps`` (clamped beyond the last knot).

    Why this horizon: the residual r is an unmodelled *velocity* error. Odometry observes its effect once it
    has happened, so the displacement it causes that no controller decision has accounted for accumulates only
    from the moment a command is issued until the next command takes effect, i.e. over one control period plus
    the perception-to-actuation delay: T_C + tau95 = 0.05 s + 0.10 s = 0.15 s in the simulation profile.
    """

    A: Mat3 = ranged(IDENTITY3, -5, 5)  # gain over (vx, vy, wz) [-]
    d: Vec3 = ranged((0.0, 0.0, 0.0), -5, 5)  # bias (m/s, m/s, rad/s)
    residual_speed_mps: tuple[float, ...] = ranged((0.0, 0.8), 0, 10)  # knots of ||u_xy|| [m/s], increasing, first 0
    residual_bound_mps: tuple[float, ...] = ranged((0.02, 0.04), 0, 10)  # bound on ||r_xy|| at each knot [m/s]
    residual_horizon_s: float = ranged(0.15, 0, 10)  # see the class docstring [s]
    residual_coverage: float = ranged(0.95, 0, 1, lo_open=True)  # stated coverage of the bound (informational) [-]
    identified: tuple[bool, bool, bool] = (True, True, True)  # axes the calibration identified (informational)
    wheel_speed_max_mps: float | None = ranged(None, 0, 100)  # the robot's wheel rim-speed limit (informational) [m/s]
    wheel_yaw_lever_m: float | None = ranged(None, 0, 10)  # its yaw lever arm (informational) [m]
    wheel_accel_max_mps2: float | None = ranged(None, 0, 1000)  # its wheel rim-acceleration limit (informational) [m/s^2]

    def __post_init__(self):
        check_field_ranges(self)
        _finite("A", *(x for row in self.A for x in row))
        _finite("d", *self.d)
        ks, bs = self.residual_speed_mps, self.residual_bound_mps
        if len(ks) == 0 or len(ks) != len(bs) or len(ks) > MAX_KNOTS:
            raise ValueError(f"residual_speed_mps and residual_bound_mps must be non-empty, of equal length and at "
                             f"most {MAX_KNOTS} long")
        _finite("residual knots", *ks, *bs)
        if ks[0] != 0.0:
            raise FieldError("residual_speed_mps", "must start at 0")
        if any(b <= a for a, b in zip(ks, ks[1:])):
            raise FieldError("residual_speed_mps", "must be strictly increasing")
        if any(b < 0 for b in bs):
            raise FieldError("residual_bound_mps", "must be >= 0")
        if not (self.residual_horizon_s >= 0 and math.isfinite(self.residual_horizon_s)):
            raise FieldError("residual_horizon_s", "must be >= 0")
        if not (0.0 < self.residual_coverage <= 1.0):
            raise FieldError("residual_coverage", "must be in (0, 1]")
        for name in ("wheel_speed_max_mps", "wheel_yaw_lever_m", "wheel_accel_max_mps2"):
            v = getattr(self, name)
            if v is not None and not (math.isfinite(v) and v >= 0):
                raise FieldError(name, "must be a finite number >= 0")


@dataclass(frozen=True)
class Tau95Parts:
    """What tau95 is made of, as ``bigcbf calibrate`` measured it (informational; the stack uses tau95_s)."""

    latency_s: float = ranged(0.0, 0, 60)  # command-to-wheel latency (largest over the axes of tau95) [s]
    actuation_median_s: float = ranged(0.0, 0, 60)  # median half-way response delay of the clean command steps [s]
    actuation95_s: float = ranged(0.0, 0, 60)  # their 95th percentile [s]
    perception95_s: float = ranged(0.0, 0, 60)  # 95th percentile of the scan's age when a command is sent [s]

    def __post_init__(self):
        check_field_ranges(self)
        _finite("tau95_parts", self.latency_s, self.actuation_median_s, self.actuation95_s, self.perception95_s)


@dataclass(frozen=True)
class UncertaintyParams:
    """The shared uncertainty of eq:relative_position_error (15) to eq:uncertainty_margin (21):
    D_i = r_R + r_i + d0 + kappa_l m_i.

    ``q_sigma_m2_per_s`` is the covariance-growth intensity of eq:cov_prop (3) for dynamic obstacles. Choice: a
    walking person's velocity drifts by a few tenths of m/s within a second, which puts the constant-velocity prediction
    error at about 0.12 m (1 sigma) after the 1.5 s horizon: q = 0.12^2 / 1.5 ~= 0.01 m^2/s, i.e. a
    beta * sigma = 0.24 m prediction radius at the end of the horizon. Static obstacles and wall points do not
    move, so their covariance does not grow (``q_sigma_static_m2_per_s`` = 0).

    ``kappa_img_static``: kappa_img used when no dynamic obstacle is tracked (Sec. V uses kappa_img = 0.8 *in
    dynamic scenes* and the full profile otherwise); None means "same as kappa_img".
    """

    r_robot_m: float = ranged(0.15, 0, 5)  # robot footprint radius r_R [m]
    d0_m: float = ranged(0.10, 0, 5)  # base clearance d0 [m]
    tau95_s: float = ranged(0.10, 0, 10)  # perception-to-actuation delay tau95 [s]
    beta: float = ranged(2.0, 0, 10)  # covariance scale beta [-]
    e_zoh_m: float = ranged(0.025, 0, 5)  # sampled-data (zero-order-hold) displacement e_ZOH [m]
    kappa_img: float = ranged(1.0, 0, 10)  # layer scaling of m_i in the imagination [-]
    kappa_exec: float = ranged(1.0, 0, 10)  # layer scaling of m_i in the CBF filter [-]
    kappa_img_static: float | None = ranged(None, 0, 10)  # kappa_img when no dynamic obstacle is tracked [-]
    q_sigma_m2_per_s: float = ranged(0.01, 0, 100)  # eq:cov_prop (3) growth, dynamic obstacles [m^2/s]
    q_sigma_static_m2_per_s: float = ranged(0.0, 0, 100)  # eq:cov_prop (3) growth, static obstacles, walls [m^2/s]
    execution: ExecutionModel = field(default_factory=ExecutionModel)
    tau95_parts: Tau95Parts | None = None   # informational (written by bigcbf calibrate)

    def __post_init__(self):
        check_field_ranges(self)
        vals = dict(r_robot_m=self.r_robot_m, d0_m=self.d0_m, tau95_s=self.tau95_s, beta=self.beta,
                    e_zoh_m=self.e_zoh_m, kappa_img=self.kappa_img, kappa_exec=self.kappa_exec,
                    q_sigma_m2_per_s=self.q_sigma_m2_per_s, q_sigma_static_m2_per_s=self.q_sigma_static_m2_per_s)
        if self.kappa_img_static is not None:
            vals["kappa_img_static"] = self.kappa_img_static
        for k, v in vals.items():
            if not (math.isfinite(v) and v >= 0):
                raise FieldError(k, f"must be a finite number >= 0, got {v}")


#: StackParams.cbf_last_resort's choices (bigcbf.control.cbf)
LAST_RESORTS = ("slack", "brake", "evade", "passive")


def check_one_of(field: str, value, choices: tuple[str, ...]) -> None:
    """A named choice of a parameter dataclass: ``value`` one of ``choices``, else a FieldError naming ``field``."""
    if value not in choices:
        raise FieldError(field, f"must be one of {', '.join(choices)}, got {str(value)[:40]!r}")


def check_last_resort(field: str, value) -> None:
    """A last resort's name (StackParams.cbf_last_resort, PlusRules.last_resort): one of LAST_RESORTS."""
    check_one_of(field, value, LAST_RESORTS)


@dataclass(frozen=True)
class StackParams:
    """Everything the BIG-CBF stack needs (Table I defaults; choices not in the paper documented here).

    Choices the paper leaves open:
    - ``alpha_per_s``: CBF gain of the unlabelled display (23) (gamma) and of eq:cbf_condition (25). With
      h = |q|^2 - D^2, the constraint allows an approach speed of alpha (|q|^2 - D^2) / (2 |q|); 1.5 1/s lets the robot
      close in at ~0.4 m/s when 0.3 m outside a 0.5 m inflated radius and brakes smoothly to zero at the boundary;
      alpha * T_C = 0.075 << 1 keeps the sampled filter close to its continuous-time design.
    - ``d_pass_min_m``: d_pass of eq:behavior_subgoals (10), "the minimum lateral passing offset", a constant
      (paper silent on its value): 0.30 m. The paper's max(d_pass, r_R + r_i + 0.35) then never takes it
      (r_R + 0.35 = 0.50 m > 0.30 m): PASS passes at r_R + r_i + 0.35 from the goal line. The locally relevant
      obstacle is defined in ``bigcbf.control.behaviors`` (paper silent; look-ahead v_max N dt, no band).
    - ``dwell_s``, ``switch_rel``, ``switch_abs``: the paper's "minimum dwell time and a relative
      switching-improvement threshold" (values paper silent): a regular behavior is kept at least ``dwell_s`` after a
      switch (unless it is rejected) and is replaced only by a candidate with J < J_cur - switch_rel |J_cur| -
      switch_abs (the absolute part keeps the rule meaningful when J_cur is near 0).
    - ``v_release_mps``, ``release_range_m``: the reverse-release fallback (no regular behavior accepted):
      move away from obstacles closer than r_R + r_i + d0 + release_range_m, else straight back from the goal.
    - ``u_min``/``u_max``: actuator box of the QP (eq:hard_cbf_qp (26)); must contain 0 (the braking fallback).
    - ``H_diag``, ``R_u_diag``: diagonal weights of eq:hard_cbf_qp (26) and of E_CBF (eq:sim_cbf_energy (27));
      identity (all channels in their SI units; the behaviors do not command yaw, so the yaw channel rarely matters).
    - ``max_obstacle_constraints``, ``wall_sectors``: the CBF uses every tracked obstacle (ids >= 0; the
      ``max_obstacle_constraints`` with smallest h if more) and, of the wall points (ids < 0), the nearest one in
      each of ``wall_sectors`` equal bearing sectors around the robot, so walls on both sides of a corridor are
      always represented. The imagination uses the same selection (from the initial state).
    - ``w_eps``: the regularizer epsilon of eq:analytic_workload (24), in the units of |grad_u gamma|^2 [m^2].
    - Our rules beyond the paper (the PASS rules, the side commitment, the release fan, the speed governor) are
      not here: they are :class:`PlusRules`, the parameters of the method ``big-cbf-plus`` (``[methods.big-cbf-plus]``
      of a run configuration); ``big-cbf`` and ``big-cbf-noshared`` run the paper's rules (docs/fidelity.md).
    - ``cbf_velocity_rows`` (default false: the paper's filter), ``cbf_velocity_horizon_s``,
      ``cbf_velocity_min_speed_mps``: the velocity-aware barrier of the common filter (issue 23), one collision-cone
      row (C3BF's set with the shared D_i^exec as radius, truncated at the horizon tau) per tracked obstacle moving
      at least that fast, beside its distance row (``bigcbf.control.velocity_barrier``; docs/fidelity.md, "The
      velocity-aware barrier").
    - ``cbf_last_resort``: what the filter commands when no command satisfies every row (``bigcbf.control.cbf``):
      ``slack`` (default, the least worst-case violation, then minimum intervention), ``brake`` (u = 0) or
      ``evade`` (a full-speed sidestep across the path of the obstacle of the worst row, if it moves, projected on
      the other rows by the same least-violation QP) or ``passive`` (the least-violation command without its
      approach toward every body the robot is already inside D_i^exec of: passive safety, the robot does not move
      into what it is too close to).
    - ``cbf_slowdown`` (default false: the paper's filter): when no command satisfies every row with D_i^exec
      evaluated at u_in, the filter evaluates the margins at the slower commands s u_in, s in ``SLOWDOWN_SCALES``
      (0.5, 0.25, 0), and takes the first s at which the QP is feasible, minimum intervention from s u_in
      (``bigcbf.control.cbf``, "The slowdown"); the last resort only when none is.
    """

    T_B_s: float = ranged(0.5, 0.002, 60)  # behavior-selection period [s]
    T_C_s: float = ranged(0.05, 0.002, 1)  # execution / CBF period [s]
    N: int = ranged(15, 1, 500)  # imagination steps [-]
    dt_s: float = ranged(0.1, 0.001, 1)  # imagination step [s]
    eps_g_m: float = ranged(0.15, 0, 10, lo_open=True)  # goal tolerance [m]
    v_freeze_mps: float = ranged(0.05, 0, 5)  # freeze threshold [m/s]
    eps_h_m2: float = ranged(0.10, 0, 100)  # barrier-acceptance tolerance [m^2]
    w_W: float = ranged(1.0, 0, 1000)  # weight of the CBF-compatibility surrogate W~
    w_P: float = ranged(1.5, 0, 1000)  # weight of progress P [1/m]
    w_F: float = ranged(3.0, 0, 1000)  # weight of freezing F
    w_sw: float = ranged(0.5, 0, 1000)  # weight of switching C_sw
    w_S: float = ranged(0.05, 0, 1000)  # weight of smoothness S [s^2/m^2]
    alpha_per_s: float = ranged(1.5, 0, 1000, lo_open=True)  # CBF gain alpha [1/s]
    w_eps: float = ranged(1e-3, 0, 1000, lo_open=True)  # epsilon of eq:analytic_workload (24) [m^2]
    v_max_mps: float = ranged(0.8, 0, 5, lo_open=True)  # translational speed limit (GOAL, PASS) [m/s]
    v_side_mps: float = ranged(0.55, 0, 5, lo_open=True)  # SIDE-L/R speed limit [m/s]
    v_release_mps: float = ranged(0.3, 0, 5, lo_open=True)  # reverse-release fallback speed [m/s]
    release_range_m: float = ranged(0.5, 0, 10)  # obstacles within D0_i + this push the fallback [m]
    d_pass_min_m: float = ranged(0.30, 0, 10)  # minimum lateral passing offset [m]
    u_min: Vec3 = ranged((-0.8, -0.8, -1.0), -10, 0)  # actuator box, lower (m/s, m/s, rad/s)
    u_max: Vec3 = ranged((0.8, 0.8, 1.0), 0, 10)  # actuator box, upper (m/s, m/s, rad/s)
    H_diag: Vec3 = ranged((1.0, 1.0, 1.0), 0, 1000000.0, lo_open=True)  # H of eq:hard_cbf_qp (26) (diagonal)
    R_u_diag: Vec3 = ranged((1.0, 1.0, 1.0), 0, 1000000.0)  # R_u of eq:sim_cbf_energy (27) (diagonal)
    dwell_s: float = ranged(1.0, 0, 60)  # minimum dwell time of a selected behavior [s]
    switch_rel: float = ranged(0.10, 0, 100)  # relative switching-improvement threshold [-]
    switch_abs: float = ranged(0.05, 0, 1000)  # absolute part of the switching threshold [-]
    noshared_margin_m: float = ranged(0.30, 0, 10)  # BIG-CBF-NoShared imagination margin [m]
    max_obstacle_constraints: int = ranged(12, 0, 1000)  # tracked obstacles in the CBF at most [-]
    wall_sectors: int = ranged(8, 0, 360)  # bearing sectors for wall-point constraints [-]
    cbf_velocity_rows: bool = False     # opt-in: a collision-cone row per moving obstacle in the common filter
    cbf_velocity_horizon_s: float = ranged(1.0, 0.1, 60)  # time horizon tau of the collision cone [s]
    cbf_velocity_min_speed_mps: float = ranged(0.2, 0, 5)  # slower tracked obstacles get no cone row [m/s]
    cbf_last_resort: str = "slack"      # the filter when no command satisfies every row: slack, brake or evade
    cbf_slowdown: bool = False          # opt-in: an infeasible step's margins evaluated at slower commands first
    uncertainty: UncertaintyParams = field(default_factory=UncertaintyParams)

    def __post_init__(self):
        check_field_ranges(self)
        pos = dict(T_B_s=self.T_B_s, T_C_s=self.T_C_s, dt_s=self.dt_s, eps_g_m=self.eps_g_m,
                   alpha_per_s=self.alpha_per_s, w_eps=self.w_eps, v_max_mps=self.v_max_mps,
                   v_side_mps=self.v_side_mps, v_release_mps=self.v_release_mps)
        for k, v in pos.items():
            if not (math.isfinite(v) and v > 0):
                raise FieldError(k, f"must be a finite number > 0, got {v}")
        nonneg = dict(v_freeze_mps=self.v_freeze_mps, eps_h_m2=self.eps_h_m2, w_W=self.w_W, w_P=self.w_P,
                      w_F=self.w_F, w_sw=self.w_sw, w_S=self.w_S, release_range_m=self.release_range_m,
                      d_pass_min_m=self.d_pass_min_m, dwell_s=self.dwell_s, switch_rel=self.switch_rel,
                      switch_abs=self.switch_abs, noshared_margin_m=self.noshared_margin_m)
        for k, v in nonneg.items():
            if not (math.isfinite(v) and v >= 0):
                raise FieldError(k, f"must be a finite number >= 0, got {v}")
        if not 1 <= self.N <= MAX_N:
            raise FieldError("N", f"must be in [1, {MAX_N}]")
        if not MIN_T_C_S <= self.T_C_s <= 1.0:
            raise FieldError("T_C_s", f"must be in [{MIN_T_C_S:g}, 1] s (the simulator steps at 2 ms)")
        if not self.T_C_s <= self.T_B_s <= 60.0:
            raise FieldError("T_B_s", "must be in [T_C_s, 60] s")
        if self.dt_s > 1.0:
            raise FieldError("dt_s", "must be <= 1 s")
        if not (0 <= self.max_obstacle_constraints <= 1000 and 0 <= self.wall_sectors <= 360):
            raise ValueError("max_obstacle_constraints must be in [0, 1000] and wall_sectors in [0, 360]")
        _finite("u_min/u_max", *self.u_min, *self.u_max)
        if not all(lo <= 0.0 <= hi for lo, hi in zip(self.u_min, self.u_max)):
            raise ValueError("the actuator box u_min <= u <= u_max must contain 0 on every axis")
        if not all(h > 0 and math.isfinite(h) for h in self.H_diag):
            raise FieldError("H_diag", "must be > 0 (H positive definite)")
        if not all(r >= 0 and math.isfinite(r) for r in self.R_u_diag):
            raise FieldError("R_u_diag", "must be >= 0")
        check_last_resort("cbf_last_resort", self.cbf_last_resort)
        for k in ("cbf_velocity_rows", "cbf_slowdown"):
            if not isinstance(getattr(self, k), bool):
                raise FieldError(k, f"must be true or false, got {getattr(self, k)!r}")

    @property
    def weights(self) -> tuple[float, float, float, float, float]:
        """(w_W, w_P, w_F, w_sw, w_S) of eq:behavior_cost (14)."""
        return (self.w_W, self.w_P, self.w_F, self.w_sw, self.w_S)


#: PlusRules.prediction_cap_scope: the obstacles whose eq:cov_prop growth the cap holds (the others grow as in the
#: paper): every one, or those the robot can back away from, slower than v_max (a tracked estimate's speed)
PREDICTION_CAP_SCOPES = ("all", "escapable")


@dataclass(frozen=True)
class PlusRules:
    """Our rules beyond the paper: the parameters of the method ``big-cbf-plus`` (``[methods.big-cbf-plus]`` of a
    run configuration). Each is a named switch over the one implementation of the behaviors, the imagination and
    the selection (``bigcbf.control.behaviors``, ``imagination``, ``selection``, ``governor``); every switch off
    (:data:`PAPER_RULES`) is ``big-cbf``, the paper as written. The defaults are BIG-CBF as it was before issue 24
    (every switch on, the speed governor off as it was); docs/fidelity.md gives each switch's measured effect.

    - ``in_way_band``: an obstacle is "in the way" (the locally relevant obstacle of eq:behavior_subgoals (10)) when
      the goal line passes within r_R + r_i + d0 + ``in_way_margin_m`` of it (off: within r_R + r_i + d0, the
      clearance of eq:true_safety_requirement (6)).
    - ``fixed_lookahead``: the relevant obstacle is looked for within ``relevant_range_m`` of the robot (off: within
      v_max N dt, the distance the imagination's horizon covers at full speed).
    - ``pass_group_reach``: d_pass = max(d_pass_min, reach of the relevant obstacle's group on side sigma + r_R +
      0.35), the group being the obstacles the footprint cannot pass between (off: the constant d_pass_min).
    - ``pass_forward_beside``: PASS's forward component max(0.85, s_i) for a relevant obstacle alone in its group
      (off: eq:behavior_subgoals's 0.85 m).
    - ``side_commitment``: once left or right was chosen, the opposite side must beat it by the switching
      threshold plus w_sw (off: the dwell and threshold rule alone).
    - ``release_fan``: the reverse release is chosen among a fan of 10 velocities by least barrier deficit (off:
      the push, away from the close obstacles, else straight back from the goal).
    - ``release_sideways``: the push releases from a moving obstacle perpendicular to its velocity (off: along
      p - p_i, as from a static one).
    - ``release_ahead`` (issue 25): an obstacle pushes the release by how deep its closest approach to the robot
      within the imagination's horizon (long_horizon_s with the rule ``long_horizon``, else N dt; constant velocity,
      the robot standing still) comes inside r_R + r_i + d0 + release_range_m (off: where it is now). A walker 2.6 m
      away coming at 1.3 m/s then pushes the robot out of its path (sideways, with ``release_sideways``) before it
      is within 0.5 m of the inflated radius; without it the push is straight back from the goal, along that path.
      Off by default: on 720 dev episodes (route on) 705 successes as without it, passive contacts 6 -> 3, four
      doorway episodes gained and four lost to timeouts (docs/fidelity.md).
    - ``speed_governor``: the liveness option (``bigcbf.control.governor``: GOAL/PASS/SIDE at the speed a model of
      the common CBF admits, with the selection's viability test and the release outlook). Off by default, as it
      was.
    - ``encounter_commitment`` (issue 25): the passing side is kept per encounter (``bigcbf.control.encounters``:
      an obstacle's group being passed, joined across changing track ids) until the encounter is behind the robot
      or every candidate on its side fails ``eq:behavior_acceptance`` (22) at ``commit_release_selections``
      consecutive selections (a selection at which it passes takes one back), or the leaky evidence for the other side (its cost advantage beyond w_sw, summed
      over time) reaches ``commit_evidence_js``; the opposite side's modes are no candidates meanwhile (off:
      ``side_commitment`` alone).
    - ``executed_speed`` (issue 25): a candidate that ``eq:behavior_acceptance`` (22) rejects at its speed limit is
      imagined again at the slower speeds the filter would let it have near obstacles, over the same look-ahead
      distance (the horizon lengthened as the speed falls), and runs at the fastest speed that passes
      (``bigcbf.control.executed_speed``; off: every candidate judged at v_b^max only). On by default since
      2026-11-27, with ``prediction_cap`` (alone it gained nothing on 80 dev worlds; docs/fidelity.md, "Commitment
      per encounter" and "The imagination's growing prediction margin").
    - ``meeting_side`` (issues 23 and 25): the first side taken in front of a person walking along the robot's path
      (head-on or being overtaken) who will meet it within two horizons is the side away from that person's lateral
      offset from the robot's goal line, when a candidate on it passes ``eq:behavior_acceptance`` (22)
      (``bigcbf.control.encounters.meeting_side``; off: the scores alone pick the side, and the horizon of 1.5 s
      ends before the meeting).
    - ``velocity_rows`` (issue 23): the common filter of big-cbf-plus's episodes has its velocity-aware rows on
      (``StackParams.cbf_velocity_rows``, ``bigcbf.control.velocity_barrier``; the same filter every method can run
      with); off: the filter of the run's ``[stack]``. On by default, as issue 23 asks; measured in docs/fidelity.md.
    - ``slowdown`` (issue 25): the common filter of big-cbf-plus's episodes has its slowdown on
      (``StackParams.cbf_slowdown``; the same filter every method can run with, ``--variant cbf_slowdown=off,on``);
      off: the filter of the run's ``[stack]``. Off by default: it freed two dev worlds for big-cbf-plus but none of
      the test split's or francis2023's, lost one route-off test world, and gave three other methods an at-fault
      contact each on the test split (docs/fidelity.md, "The common filter's slowdown").
    - ``long_horizon`` (issue 23): the imagination's rollouts run ``long_horizon_s`` (N = long_horizon_s / dt
      steps of eq:behavior_rollout (12)); the paper's N dt is 1.5 s (Table I), which ``big-cbf`` keeps. Every score
      (eq:behavior_terms (13), eq:behavior_cost (14), eq:analytic_workload (24)), the barrier acceptance
      (eq:behavior_acceptance (22)) and the reverse release stay those of the stack's N steps, to the bit; the
      longer rollout adds one test: a candidate whose rollout comes within D_i of a moving obstacle (tracked,
      dynamic, at least ``cbf_velocity_min_speed_mps``) between the two horizons is rejected too. A person crossing
      the robot's path 2 s ahead is then in the test before the robot walks into that path; at 1.5 s the rollouts
      end before the crossing, the robot keeps going and is caught between the person and whatever is beside it
      (docs/fidelity.md, "The long horizon"). What does not move is judged over the stack's horizon: the behaviors
      re-plan against it at every selection (judged over 2.5 s, a feedback policy's rollout runs into the next row
      of posts it would have passed after the next selection). The meeting side's "two horizons" read this one.
    - ``last_resort`` (issue 23): the common filter's last resort in big-cbf-plus's episodes, one of
      ``LAST_RESORTS`` (``StackParams.cbf_last_resort``; "slack" is the run's default). "passive" by default: on
      the generated test split it removed the one at-fault contact of "slack" (docs/fidelity.md).
    - ``prediction_cap`` (issue 25): in the imagination, the predicted covariance of eq:cov_prop (3) grows only up to
      ``prediction_cap_s`` ahead and is held there (Sigma_{i,k} = Sigma_{i,min(k, k_cap)}); the common filter is
      unchanged (it reads the tracks' own covariances). Off: the paper's growth over the whole horizon. On by
      default since 2026-11-27 at prediction_cap_s 0 with the scope ``escapable`` and ``executed_speed``: on 720
      dev episodes 705 successes against 696, no at-fault contact, passive contacts 3 -> 6 (docs/fidelity.md).
      ``prediction_cap_scope`` says whose growth is held: ``all``, or ``escapable``: the obstacles moving slower
      than v_max, which the robot can back away from at the speed they come (a faster walker keeps the paper's
      growth, so the robot keeps the distance it would need).
    """

    in_way_band: bool = True  # "in the way" within the band in_way_margin_m beyond r_R + r_i + d0 [on/off]
    in_way_margin_m: float = ranged(0.15, 0, 10)  # the band beyond r_R + r_i + d0 (in_way_band) [m]
    fixed_lookahead: bool = True  # the relevant obstacle within relevant_range_m (off: v_max N dt) [on/off]
    relevant_range_m: float = ranged(3.0, 0, 100)  # look-ahead for the relevant obstacle (fixed_lookahead) [m]
    pass_group_reach: bool = True  # d_pass from the relevant obstacle's group reach (off: d_pass_min) [on/off]
    pass_forward_beside: bool = True  # PASS forward max(0.85, s_i) beside a lone obstacle (off: 0.85 m) [on/off]
    side_commitment: bool = True  # the other side must beat the chosen one by threshold + w_sw [on/off]
    release_fan: bool = True  # the reverse release picked from a fan of 10 velocities (off: the push) [on/off]
    release_sideways: bool = True  # release from a moving obstacle across its velocity [on/off]
    release_ahead: bool = False  # the push counts where movers come within the horizon, not where they are [on/off]
    speed_governor: bool = False  # the liveness option (bigcbf.control.governor) [on/off]
    encounter_commitment: bool = True  # keep the passing side per encounter (control/encounters.py) [on/off]
    commit_release_selections: int = ranged(5, 1, 100)  # K: selections with the side infeasible before release [-]
    commit_evidence_js: float = ranged(1.2, 0, 1e6)  # evidence for the other side that releases the side [J s]
    executed_speed: bool = True  # judge a rejected candidate again at slower speeds, same look-ahead [on/off]
    meeting_side: bool = True  # the first side away from a person walking along the path (encounters.py) [on/off]
    velocity_rows: bool = True  # the common filter with its velocity-aware rows (cbf_velocity_rows) [on/off]
    slowdown: bool = False  # the common filter with its slowdown (cbf_slowdown) [on/off]
    long_horizon: bool = True  # rollouts long_horizon_s long; the extra steps test only movers (off: N dt) [on/off]
    long_horizon_s: float = ranged(2.5, 0.1, 10)  # the rollouts' length with long_horizon [s]
    last_resort: str = "passive"  # the common filter's last resort for this method (cbf_last_resort) [-]
    prediction_cap: bool = True  # the imagination's eq:cov_prop growth stops at prediction_cap_s [on/off]
    prediction_cap_s: float = ranged(0.0, 0, 10)  # where the growth stops (prediction_cap) [s]
    prediction_cap_scope: str = "escapable"  # whose growth the cap holds: all, escapable [-]

    def __post_init__(self):
        check_field_ranges(self)
        for f in dataclasses.fields(self):
            if f.type in (bool, "bool") and not isinstance(getattr(self, f.name), bool):
                raise FieldError(f.name, f"must be true or false, got {getattr(self, f.name)!r}")
        check_last_resort("last_resort", self.last_resort)
        check_one_of("prediction_cap_scope", self.prediction_cap_scope, PREDICTION_CAP_SCOPES)
        for k in ("in_way_margin_m", "relevant_range_m", "long_horizon_s", "prediction_cap_s"):
            if not math.isfinite(getattr(self, k)):
                raise FieldError(k, "must be finite")

    def rollout_steps(self, params: "StackParams") -> int:
        """The imagination's rollout length in steps of params.dt_s: long_horizon_s with the rule ``long_horizon``,
        else the stack's N (Table I)."""
        return max(1, int(round(self.long_horizon_s / params.dt_s))) if self.long_horizon else params.N

    @property
    def switches(self) -> dict[str, bool]:
        """The named switches and their states."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)
                if isinstance(getattr(self, f.name), bool)}


#: every switch off: BIG-CBF as the paper writes it (``big-cbf``, ``big-cbf-noshared``)
PAPER_RULES = PlusRules(**{f.name: False for f in dataclasses.fields(PlusRules) if f.type in (bool, "bool")})


#: Table I, the simulation profile.
SIMULATION = StackParams()

#: Sec. V, the physical profile: r_R 0.15 m, d0 0.05 m, beta 1, e_ZOH 0.0716 m, kappa_exec 1, kappa_img 0.8 in
#: dynamic scenes (1.0 when no dynamic obstacle is tracked). Latency and the execution model are calibrated per
#: robot (``bigcbf calibrate``) and overlaid with ``load_stack_params(profile, base=PHYSICAL)``.
PHYSICAL = dataclasses.replace(
    SIMULATION,
    uncertainty=UncertaintyParams(r_robot_m=0.15, d0_m=0.05, beta=1.0, e_zoh_m=0.0716, kappa_img=0.8,
                                  kappa_exec=1.0, kappa_img_static=1.0),
)


def _merge(base: dict, over: dict) -> dict:
    out = dict(base)
    for k, v in over.items():
        out[k] = _merge(base[k], v) if isinstance(v, dict) and isinstance(base.get(k), dict) else v
    return out


def load_stack_params(path: str | Path, base: StackParams | None = None) -> StackParams:
    """Read a StackParams TOML (any subset of keys). Missing keys come from ``base`` (default: the dataclass
    defaults, i.e. SIMULATION). Unknown keys and bad values raise UserError naming the file and the key. A
    ``[provenance]`` table (what made the file, e.g. ``bigcbf profile simulate``) is informational and ignored."""
    data = load_toml(path)
    if isinstance(data.get("provenance"), dict):
        data = {k: v for k, v in data.items() if k != "provenance"}
    if base is not None:
        data = _merge(to_dict(base), data)   # unknown keys can only come from the file: errors still name it
    return from_dict(StackParams, data, file=str(path))


#: the stack uncertainty profiles the twin calibrated for the shipped robot profiles (``bigcbf profile simulate``),
#: by robot profile name: bigcbf/profiles/stack/<robot>.toml
def stack_profile_path(robot: str = "x3_sim") -> Path:
    from .. import PROFILES
    return PROFILES / "stack" / f"{robot}.toml"


def default_stack_params(robot: str = "x3_sim", base: StackParams = SIMULATION) -> StackParams:
    """What ``bigcbf run`` and ``bigcbf bench`` use without ``--profile``: the preset ``base`` (Table I) overlaid
    with the stack profile the twin calibrated for the simulated robot ``robot`` (its tau95 and execution model;
    ``stack_profile_path``)."""
    return load_stack_params(stack_profile_path(robot), base=base)


def read_provenance(path: str | Path) -> dict:
    """The ``[provenance]`` table of a stack profile ({} when it has none)."""
    prov = load_toml(path).get("provenance", {})
    return prov if isinstance(prov, dict) else {}


def save_stack_params(params: StackParams, path: str | Path, *, header: str = "") -> None:
    """Write ``params`` as TOML (every key, so that the file is complete and self-describing)."""
    save(params, path, header=header)
