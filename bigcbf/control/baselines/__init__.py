"""The comparison methods of the paper (Sec. IV-A), each a Planner feeding the common hard CBF filter:
``apf`` (Khatib 1986), ``dwa`` (Fox et al. 1997), ``mppi`` (Williams et al. 2017), ``backup-cbf``
(Chen et al. 2021) and ``pl-cbf`` (Kim et al. 2026). ``cbf-only``, ``big-cbf`` and ``big-cbf-noshared`` live in
``bigcbf.control.methods``. All use the same obstacle estimates and the same prediction (eq:obs_prop, eq:cov_prop);
each plans with its own published collision geometry (robot and obstacle radii plus the method's own safety margin,
documented in its module), and the common hard CBF applies the shared uncertainty D_i (eq:shared_barrier,
eq:uncertainty_margin) to all of them. numpy only (robot-side, no MuJoCo)."""
from __future__ import annotations

from .apf import ApfParams, ApfPlanner
from .backup_cbf import BackupCbfParams, BackupCbfPlanner
from .dwa import DwaParams, DwaPlanner
from .mppi import MppiParams, MppiPlanner
from .pl_cbf import PlCbfParams, PlCbfPlanner

#: name -> planner class (constructed as cls(params: StackParams))
BASELINES = {
    "backup-cbf": BackupCbfPlanner,
    "pl-cbf": PlCbfPlanner,
    "apf": ApfPlanner,
    "dwa": DwaPlanner,
    "mppi": MppiPlanner,
}


def register(methods) -> None:
    """Add the five baselines to a method Registry (``bigcbf.control.methods.METHODS``)."""
    for name, cls in BASELINES.items():
        methods.register(name, cls)


__all__ = ["ApfParams", "ApfPlanner", "BackupCbfParams", "BackupCbfPlanner", "DwaParams", "DwaPlanner",
           "MppiParams", "MppiPlanner", "PlCbfParams", "PlCbfPlanner", "BASELINES", "register"]
