"""Issue 24, item 3: every baseline plans with the task's clearance r_R + r_i + d0 (eq:true_safety_requirement (6)),
and Backup-CBF / PL-CBF act where braking alone does not certify, so that they differ from CBF-only in the static
scenes (real episodes)."""
import dataclasses

import numpy as np
import pytest

from bigcbf.control.baselines.apf import ApfPlanner
from bigcbf.control.baselines.backup_cbf import BackupCbfPlanner
from bigcbf.control.baselines.common import Geometry, predict
from bigcbf.control.baselines.dwa import DwaPlanner
from bigcbf.control.baselines.mppi import MppiPlanner
from bigcbf.control.baselines.pl_cbf import PlCbfPlanner
from bigcbf.episode import Episode
from bigcbf.params import SIMULATION
from bigcbf.scenario import load_scenario
from bigcbf.types import Obstacles, RobotState

P = SIMULATION
P_NO_D0 = dataclasses.replace(P, uncertainty=dataclasses.replace(P.uncertainty, d0_m=0.0))
R_OBS = 0.3
BASE = P.uncertainty.r_robot_m + R_OBS                      # r_R + r_i = 0.45 m
D0 = P.uncertainty.d0_m                                     # 0.10 m
IN_BAND = BASE + 0.5 * D0                                   # between r_R + r_i and r_R + r_i + d0
GOAL = np.array([4.0, 0.0])                                 # behind the obstacle


def obstacle_ahead(dist=IN_BAND):
    return Obstacles.from_lists([[dist, 0.0]], r=R_OBS)


def test_geometry_includes_d0():
    assert D0 > 0
    assert Geometry().radius(R_OBS, P) == pytest.approx(BASE + D0)
    assert Geometry(0.1, 1.01).radius(R_OBS, P) == pytest.approx(1.01 * BASE + D0 + 0.1)
    assert Geometry().radius(R_OBS, P_NO_D0) == pytest.approx(BASE)


@pytest.mark.parametrize("cls", [BackupCbfPlanner, PlCbfPlanner])
def test_shields_move_out_of_the_band(cls):
    """At rest inside the band, braking does not certify (h < 0 from the start): the shield moves away from the
    obstacle; without d0 the same state is safe and the goal command passes."""
    u, info = cls(P).plan(0.0, RobotState(0, 0, 0), obstacle_ahead(), GOAL)
    assert info.mode != "NOMINAL" and u[0] < 0.0, (info.mode, u)
    u, info = cls(P_NO_D0).plan(0.0, RobotState(0, 0, 0), obstacle_ahead(), GOAL)
    assert u[0] > 0.0, (info.mode, u)


def test_dwa_does_not_move_deeper_into_the_band():
    u, info = DwaPlanner(P).plan(0.0, RobotState(0, 0, 0), obstacle_ahead(), GOAL)
    assert u[0] <= 1e-12, (info.mode, u)
    u, info = DwaPlanner(P_NO_D0).plan(0.0, RobotState(0, 0, 0), obstacle_ahead(), GOAL)
    assert u[0] > 0.0 and info.mode == "DWA", (info.mode, u)


def test_mppi_penalizes_the_band():
    """A resting sequence d0/2 inside r_R + r_i + d0 + margin pays the collision penalty at every step; without
    d0 the same state is outside the radius and the cost is lower by at least that penalty."""
    state = RobotState(0, 0, 0)
    margin = MppiPlanner(P).mppi.margin_m
    obs = obstacle_ahead(IN_BAND + margin)
    S = {}
    for key, params in (("d0", P), ("none", P_NO_D0)):
        pl = MppiPlanner(params)
        Vs = np.zeros((1, params.N, 2))
        S[key] = pl.costs(Vs, np.zeros_like(Vs), state, predict(obs, params), GOAL)[0][0]
    assert S["d0"] - S["none"] >= pl.mppi.w_coll * P.dt_s * P.N, S


def test_apf_influence_distance_starts_at_d0():
    """rho is measured from r_R + r_i + d0: a robot rho_0 + d0/2 beyond r_R + r_i is inside the influence distance
    (pushed away from the obstacle), and outside it without d0."""
    rho0 = ApfPlanner(P).apf.rho0_m
    obs = Obstacles.from_lists([[BASE + rho0 + 0.5 * D0, 0.0]], r=R_OBS)
    goal = np.array([0.0, 4.0])                         # attraction along +y only
    u, _ = ApfPlanner(P).plan(0.0, RobotState(0, 0, 0), obs, goal)
    assert u[0] < -1e-6
    u, _ = ApfPlanner(P_NO_D0).plan(0.0, RobotState(0, 0, 0), obs, goal)
    assert u[0] == 0.0


SCENES = ("double_squeeze", "multi_static_clutter", "required_sidestepping")


@pytest.mark.parametrize("scene", SCENES)
@pytest.mark.parametrize("seed", [0, 1])
def test_shields_differ_from_cbf_only_in_static_scenes(scene, seed):
    """The issue: Backup-CBF and PL-CBF were bit-identical to CBF-only in every static scene. Real episodes, cut
    short (6 s, long enough to reach the obstacles)."""
    res = {m: Episode(load_scenario(scene, seed), m, seed, time_limit_s=6.0).run()
           for m in ("cbf-only", "backup-cbf", "pl-cbf")}
    base = res["cbf-only"]
    assert base.e_cbf > 0.0, "CBF-only met no obstacle within the time limit: the test would prove nothing"
    for m in ("backup-cbf", "pl-cbf"):
        r = res[m]
        assert (r.e_cbf, r.cbf_active_ratio, r.min_clearance_m) != (base.e_cbf, base.cbf_active_ratio,
                                                                     base.min_clearance_m), m
        assert abs(r.e_cbf - base.e_cbf) > 1e-6 * max(1.0, base.e_cbf), (m, r.e_cbf, base.e_cbf)
