"""The metrics of an episode, all accumulated in one place (:class:`EpisodeMetrics`): the per-step metrics of
Sec. IV (E_CBF ``eq:sim_cbf_energy``, CBF activity, QP infeasibility, timings), the robot's stopped time and true
clearance, the scans that never arrived and the steps the filter braked on implausible estimates, the chatter and
stall metrics of ``control/liveness.py``, and the diagnostics of the shared-uncertainty ablation: the margins
kappa_l m_i each layer used (``eq:shared_barrier``, ``eq:uncertainty_margin``) and the part of E_CBF spent on steps
whose QP was infeasible.

One percentile rule for every P95 (and the margins' P90) of the project: :func:`percentile`.

Robot-side code: the accumulator takes numbers, states and the planner's and filter's info records; the episode
(bigcbf/episode.py) feeds it what the simulator measured (true speed and clearance). No MuJoCo here.
"""
from __future__ import annotations

import math

import numpy as np

from ..params.stack import StackParams
from .cbf import PERCEPTION_FAULT, FilterInfo
from .liveness import LivenessRecorder
from .planner import PlanInfo


def percentile(samples, q: float) -> float:
    """The project's one percentile rule: the q-th percentile (0-100) of the pooled samples (any shape) by linear
    interpolation between the order statistics (``numpy.percentile``'s default, Hyndman & Fan's type 7: with the
    n samples sorted, x_(1) <= ... <= x_(n), the position h = (n - 1) q / 100, the result
    x_(floor h + 1) + (h - floor h) (x_(floor h + 2) - x_(floor h + 1))). No samples: 0.0.

    Every P95 (timings of episodes, of ``bigcbf perf``) and the margins' P90 use it. (The twin's calibrated bounds
    are a different statistic on purpose: ``twin.signals.quantile_upper`` returns a sample, as a bound read off data
    should be.)"""
    x = np.asarray(samples, float).ravel()
    return float(np.percentile(x, q)) if x.size else 0.0


def p95(samples) -> float:
    """The 95th percentile of the samples by :func:`percentile`'s rule (0.0 for none)."""
    return percentile(samples, 95)


def cbf_energy(u_safe, u_in, R_u) -> float:
    """``eq:sim_cbf_energy`` (27): E_CBF = sum_k (u_safe,k - u_in,k)^T R_u (u_safe,k - u_in,k).

    ``u_safe``, ``u_in``: (3,) for one step or (K, 3) for a sequence; ``R_u``: (3,) diagonal or (3, 3).
    """
    du = np.atleast_2d(np.asarray(u_safe, float) - np.asarray(u_in, float))
    R = np.asarray(R_u, float)
    R = np.diag(R) if R.ndim == 1 else R
    return float(np.einsum("ki,ij,kj->", du, R, du))


def margin_stats(samples) -> tuple[float | None, float | None]:
    """(mean, 90th percentile by :func:`percentile`) [m] of margin samples kappa_l m_i (any shape; pooled);
    (None, None) when empty."""
    x = np.asarray(samples, float).ravel()
    if x.size == 0:
        return None, None
    return float(x.mean()), percentile(x, 90)


class EpisodeMetrics:
    """Every metric of one episode, accumulated as it runs; :meth:`results` gives them under EpisodeResult's names.

    The episode calls :meth:`scan` for every scan that was due (its perception time, or None when it never
    arrived), :meth:`control_step` at every control step (after the command left), and :meth:`physics` after every
    block of physics steps (the true clearance measured then). Definitions:

    - ``e_cbf``: ``eq:sim_cbf_energy`` (27) summed over the control steps with the fixed R_u;
      ``e_cbf_infeasible``: its part from steps whose hard QP was infeasible.
    - ``cbf_active_ratio``, ``qp_infeasible_ratio``: fractions of the control steps whose filter had an active
      constraint / an infeasible QP (0 with no step); ``velocity_relaxed_ratio``: of the steps whose distance rows
      held but not every velocity-aware row (``FilterInfo.velocity_relaxed``; 0 with the switch off).
    - ``planner_p95_ms`` over the calls that ran a planning cycle (``PlanInfo.planned``), ``cbf_p95_ms`` over every
      filter call, ``perception_p95_ms`` over the scans processed: :func:`p95` (0 with no sample).
    - ``stopped_time_s``: simulated time whose last control step saw a true planar speed below ``v_freeze_mps``.
    - ``min_clearance_m``: the smallest true clearance over the physics blocks (+inf with none).
    - ``perception_faults``: control steps whose filter braked on implausible estimates (``PERCEPTION_FAULT``);
      ``missed_scans``: scans that never arrived.
    - ``mode_history``: [(t rounded to 1 ms, mode)] at each change of the planner's mode.
    - the margins' (mean, P90) of each layer by :func:`margin_stats`, pooled over the episode (None: no sample).
    - the chatter and stall metrics of :class:`~bigcbf.control.liveness.LivenessRecorder`.
    - contacts and near misses with people (``bigcbf/sim/contacts.py`` measures them): ``contact`` (the classified
      first contact as a dict, None without one), ``at_fault_collision`` (the robot moved into the body faster than
      ``v_freeze_mps``), ``passive_collision`` (a contact that is not at fault); ``min_time_to_contact_s``: the
      smallest constant-velocity time to contact with a pedestrian over the control steps (+inf when none ever
      closed on the robot); ``personal_space_s``: simulated time whose last control step saw a pedestrian's body
      closer than 0.5 m to the robot's outline (``PERSONAL_SPACE_M``), counted like ``stopped_time_s``.
    """

    def __init__(self, R_u_diag, v_freeze_mps: float, T_C_s: float):
        self.R_u = R_u_diag
        self.v_freeze_mps = float(v_freeze_mps)
        self.steps = 0
        self.e_cbf = 0.0
        self.e_cbf_infeasible = 0.0
        self.active = 0
        self.infeasible = 0
        self.velocity_relaxed = 0
        self.perception_faults = 0
        self.missed_scans = 0
        self.stopped_s = 0.0
        self.min_clearance_m = math.inf
        self.planner_ms: list[float] = []
        self.filter_ms: list[float] = []
        self.perception_ms: list[float] = []
        self.margins_img: list[np.ndarray] = []
        self.margins_exec: list[np.ndarray] = []
        self.mode_history: list[tuple[float, str]] = []
        self.liveness = LivenessRecorder(T_C_s)
        self._stopped_now = False        # the last control step saw the robot below v_freeze
        self.contact: dict | None = None
        self.min_ttc_s = math.inf
        self.personal_space_s = 0.0
        self._intruding_now = False      # the last control step saw a pedestrian within the personal space

    @classmethod
    def for_params(cls, params: StackParams) -> "EpisodeMetrics":
        """An accumulator with the stack's R_u, v_freeze and control period T_C."""
        return cls(params.R_u_diag, params.v_freeze_mps, params.T_C_s)

    def scan(self, perception_ms: float | None) -> None:
        """A scan was due: its perception time [ms], or None when it never arrived (a fault)."""
        if perception_ms is None:
            self.missed_scans += 1
        else:
            self.perception_ms.append(perception_ms)

    def control_step(self, t: float, state, true_state, goal, u_in, u_safe, plan: PlanInfo,
                     filt: FilterInfo) -> None:
        """One control step at time ``t`` [s]: the controller's state (odometry), the true state, the goal, the
        planner's u_in and the filtered u_safe with their info records."""
        if plan.planned:
            self.planner_ms.append(plan.planner_ms)
        self.filter_ms.append(filt.solve_ms)
        e_step = cbf_energy(u_safe, u_in, self.R_u)
        self.e_cbf += e_step
        self.active += bool(filt.active)
        self.infeasible += bool(filt.infeasible)
        self.velocity_relaxed += bool(filt.velocity_relaxed)
        self.perception_faults += filt.fallback == PERCEPTION_FAULT
        if filt.infeasible:
            self.e_cbf_infeasible += e_step
        self.margins_exec.append(filt.margins)
        if plan.margins_img is not None:
            self.margins_img.append(plan.margins_img)
        self.steps += 1
        if not self.mode_history or self.mode_history[-1][1] != plan.mode:
            self.mode_history.append((round(t, 3), plan.mode))
        self.liveness.add(t, state, u_safe, goal, (true_state.px, true_state.py))
        self._stopped_now = bool(np.hypot(true_state.vx, true_state.vy) < self.v_freeze_mps)   # until the next step

    def near_miss(self, ttc_s: float, ped_clearance_m: float, personal_space_m: float) -> None:
        """At a control step: the constant-velocity time to contact with the pedestrians [s] and the clearance to
        the nearest pedestrian's body [m] (``bigcbf.sim.contacts.near_miss``); closer than ``personal_space_m``
        intrudes until the next control step."""
        self.min_ttc_s = min(self.min_ttc_s, float(ttc_s))
        self._intruding_now = bool(ped_clearance_m < personal_space_m)

    def contacted(self, contact: dict) -> None:
        """The episode's first contact, classified (``bigcbf.sim.contacts.Contact.as_dict``); later ones are
        ignored."""
        if self.contact is None:
            self.contact = dict(contact)

    def physics(self, n_steps: int, dt: float, clearance_m: float) -> None:
        """A block of ``n_steps`` physics steps of ``dt`` [s] ran; the true clearance after it [m]."""
        if self._stopped_now:
            self.stopped_s += n_steps * dt
        if self._intruding_now:
            self.personal_space_s += n_steps * dt
        self.min_clearance_m = min(self.min_clearance_m, clearance_m)

    def results(self, duration_s: float) -> dict:
        """The metrics so far under EpisodeResult's field names (``duration_s``: the episode's time so far)."""
        n = max(self.steps, 1)
        m_img = margin_stats(np.concatenate(self.margins_img)) if self.margins_img else (None, None)
        m_exec = margin_stats(np.concatenate(self.margins_exec)) if self.margins_exec else (None, None)
        return dict(
            min_clearance_m=float(self.min_clearance_m), e_cbf=self.e_cbf,
            cbf_active_ratio=self.active / n, qp_infeasible_ratio=self.infeasible / n,
            planner_p95_ms=p95(self.planner_ms), cbf_p95_ms=p95(self.filter_ms),
            perception_p95_ms=p95(self.perception_ms), stopped_time_s=round(self.stopped_s, 4),
            control_steps=self.steps, perception_faults=self.perception_faults, missed_scans=self.missed_scans,
            mode_history=list(self.mode_history),
            **self.liveness.metrics(self.mode_history, duration_s),
            e_cbf_infeasible=self.e_cbf_infeasible, m_img_mean_m=m_img[0], m_img_p90_m=m_img[1],
            m_exec_mean_m=m_exec[0], m_exec_p90_m=m_exec[1],
            contact=None if self.contact is None else dict(self.contact),
            at_fault_collision=bool(self.contact is not None and self.contact["at_fault"]),
            passive_collision=bool(self.contact is not None and not self.contact["at_fault"]),
            min_time_to_contact_s=self.min_ttc_s, personal_space_s=round(self.personal_space_s, 4),
            velocity_relaxed_ratio=self.velocity_relaxed / n)
