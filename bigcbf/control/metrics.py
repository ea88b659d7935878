"""The per-step metrics of Sec. IV: E_CBF (Eq. 20), CBF activity, QP infeasibility, timings; and the diagnostics of
the shared-uncertainty ablation: the margins kappa_l m_i each layer used (Eqs. 14-15) and the part of E_CBF spent on
steps whose QP was infeasible."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..params.stack import StackParams
from .cbf import FilterInfo
from .planner import PlanInfo


def cbf_energy(u_safe, u_in, R_u) -> float:
    """Eq. (20): E_CBF = sum_k (u_safe,k - u_in,k)^T R_u (u_safe,k - u_in,k).

    ``u_safe``, ``u_in``: (3,) for one step or (K, 3) for a sequence; ``R_u``: (3,) diagonal or (3, 3).
    """
    du = np.atleast_2d(np.asarray(u_safe, float) - np.asarray(u_in, float))
    R = np.asarray(R_u, float)
    R = np.diag(R) if R.ndim == 1 else R
    return float(np.einsum("ki,ij,kj->", du, R, du))


def margin_stats(samples) -> tuple[float | None, float | None]:
    """(mean, 90th percentile) [m] of margin samples kappa_l m_i (any shape; pooled); (None, None) when empty."""
    x = np.asarray(samples, float).ravel()
    if x.size == 0:
        return None, None
    return float(x.mean()), float(np.percentile(x, 90))


@dataclass
class StepMetrics:
    """One control step's contribution to the Sec. IV metrics."""

    e_cbf: float          # the Eq. (20) term of this step
    active: bool          # at least one CBF constraint was active (the filter changed the command)
    infeasible: bool      # the hard QP was infeasible
    fallback: str | None  # the filter's fallback, if any
    mode: str             # the planner's mode
    planned: bool         # a planning cycle ran
    planner_ms: float
    filter_ms: float
    margins_exec: np.ndarray | None = None   # kappa_exec m_i of the CBF rows (FilterInfo.margins) [m]
    margins_img: np.ndarray | None = None    # kappa_img m_i of the selected rollout (PlanInfo.margins_img) [m]


def step_metrics(u_in, u_safe, plan: PlanInfo, filt: FilterInfo, params: StackParams) -> StepMetrics:
    """The metrics of one control step (E_CBF with the fixed R_u of ``params``)."""
    return StepMetrics(e_cbf=cbf_energy(u_safe, u_in, params.R_u_diag), active=bool(filt.active),
                       infeasible=bool(filt.infeasible), fallback=filt.fallback, mode=plan.mode,
                       planned=bool(plan.planned), planner_ms=float(plan.planner_ms), filter_ms=float(filt.solve_ms),
                       margins_exec=filt.margins, margins_img=plan.margins_img)


@dataclass
class EpisodeSummary:
    """Sec. IV aggregates over an episode's control steps."""

    steps: int
    e_cbf: float                 # Eq. (20) summed over the steps
    active_ratio: float          # fraction of steps with an active CBF constraint
    infeasible_ratio: float      # fraction of steps with an infeasible QP
    planner_p95_ms: float        # P95 over planning cycles (steps with planned=True; all steps if none)
    filter_p95_ms: float         # P95 of the filter time over all steps
    mode_counts: dict[str, int]  # steps per mode
    e_cbf_infeasible: float = 0.0            # the part of e_cbf from steps with an infeasible QP
    m_img_mean_m: float | None = None        # margin_stats of the imagination layer's margins (None: no imagination)
    m_img_p90_m: float | None = None
    m_exec_mean_m: float | None = None       # margin_stats of the CBF rows' margins (None: no row at all)
    m_exec_p90_m: float | None = None


def summarize(steps: list[StepMetrics]) -> EpisodeSummary:
    """Aggregate per-step metrics (an empty list gives zeros)."""
    n = len(steps)
    if n == 0:
        return EpisodeSummary(0, 0.0, 0.0, 0.0, 0.0, 0.0, {})
    planned = [s.planner_ms for s in steps if s.planned] or [s.planner_ms for s in steps]
    counts: dict[str, int] = {}
    for s in steps:
        counts[s.mode] = counts.get(s.mode, 0) + 1
    img = [s.margins_img for s in steps if s.margins_img is not None]
    exe = [s.margins_exec for s in steps if s.margins_exec is not None]
    m_img = margin_stats(np.concatenate(img)) if img else (None, None)
    m_exec = margin_stats(np.concatenate(exe)) if exe else (None, None)
    return EpisodeSummary(
        steps=n, e_cbf=float(sum(s.e_cbf for s in steps)),
        active_ratio=sum(s.active for s in steps) / n, infeasible_ratio=sum(s.infeasible for s in steps) / n,
        planner_p95_ms=float(np.percentile(planned, 95)),
        filter_p95_ms=float(np.percentile([s.filter_ms for s in steps], 95)), mode_counts=counts,
        e_cbf_infeasible=float(sum(s.e_cbf for s in steps if s.infeasible)),
        m_img_mean_m=m_img[0], m_img_p90_m=m_img[1], m_exec_mean_m=m_exec[0], m_exec_p90_m=m_exec[1])
