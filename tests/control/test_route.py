"""The route layer (bigcbf/control/route.py, issue 25 item 2): the map from hand-made scans, the path and its
look-ahead point, the [route] table of the run configuration, and real episodes in a concave trap deeper than the
1.5 s look-ahead, where methods stuck without the layer reach the goal with it."""
import math

import numpy as np
import pytest

from bigcbf.cli import main
from bigcbf.config import RunConfig, config_from_toml, config_toml, load_run_config
from bigcbf.control.route import OccupancyGrid, RouteLayer, RouteParams, cell_costs, shortest_path
from bigcbf.episode import Episode
from bigcbf.errors import FieldError, UserError
from bigcbf.scenario import load_scenario
from bigcbf.types import LaserScan, Obstacles, RobotState

N_BEAMS = 360


def wall_scan(x_wall: float, half_len: float, extra=()) -> LaserScan:
    """A 360-beam scan from the origin (heading 0) of a wall x = x_wall, |y| <= half_len; ``extra``: circles
    (cx, cy, r) in front of it. Other beams return nothing (inf)."""
    ang = -math.pi + 2 * math.pi / N_BEAMS * np.arange(N_BEAMS)
    c, s = np.cos(ang), np.sin(ang)
    r = np.full(N_BEAMS, np.inf)
    with np.errstate(divide="ignore"):
        t = np.where(c > 1e-9, x_wall / c, np.inf)
    r = np.where(np.abs(t * s) <= half_len, t, r)
    for cx, cy, rad in extra:
        b = c * cx + s * cy
        disc = b * b - (cx * cx + cy * cy - rad * rad)
        tc = b - np.sqrt(np.maximum(disc, 0.0))
        r = np.where((disc >= 0) & (tc > 0), np.minimum(r, tc), r)
    return LaserScan(0.0, -math.pi, 2 * math.pi / N_BEAMS, 0.15, 12.0, r.astype(np.float32))


def layer(**kw) -> RouteLayer:
    rl = RouteLayer(RouteParams(enabled=True, **kw), r_robot_m=0.15, d0_m=0.10)
    rl.reset((0.0, 0.0), (4.0, 0.0))
    return rl


def test_a_scan_marks_its_returns_clears_the_beams_and_leaves_the_rest_unknown():
    rl = layer()
    rl.scan(wall_scan(2.05, 1.0), (0.0, 0.0, 0.0))
    g, p = rl.grid, rl.params
    occ = g.occupied(p)
    wall = g.cell((2.05, 0.0))
    assert occ[wall] and occ[g.cell((2.05, 0.8))]
    assert not occ[g.cell((2.05, 1.5))] and not g.seen[g.cell((2.05, 1.5))]   # beyond the wall's end: no return
    before = g.cell((1.0, 0.0))
    assert g.seen[before] and g.logodds[before] == pytest.approx(-p.l_free)    # crossed once: free
    behind = g.cell((3.0, 0.0))
    assert not g.seen[behind] and g.unknown()[behind]                          # behind the wall: never seen
    assert not g.seen[g.cell((-1.0, 0.0))]                                     # a beam without a return clears nothing
    for _ in range(10):                                                        # clamped
        rl.scan(wall_scan(2.05, 1.0), (0.0, 0.0, 0.0))
    assert g.logodds[wall] == pytest.approx(p.l_max) and g.logodds[before] == pytest.approx(p.l_min)


def test_the_grid_is_in_odom_and_uses_the_laser_mount():
    rl = RouteLayer(RouteParams(enabled=True), 0.15, 0.10, laser_mount=(0.5, 0.0, 0.0))
    rl.reset((0.0, 0.0), (4.0, 4.0))
    # robot at (1, 1) facing +y: the laser sits at (1, 1.5), its +x axis points along odom +y
    rl.scan(wall_scan(2.05, 0.3), (1.0, 1.0, math.pi / 2))
    occ = rl.grid.occupied(rl.params)
    assert occ[rl.grid.cell((1.0, 3.52))]
    assert occ.sum() == pytest.approx(7, abs=2)


def test_a_moving_track_is_not_burned_in_and_a_departed_static_one_is_cleared():
    rl = layer()
    walker = (1.0, 0.0, 0.25)
    scan = wall_scan(2.05, 1.0, [walker])
    moving = Obstacles.from_lists([[1.0, 0.0]], v=[[0.0, 0.8]], r=0.25, static=False, ids=[3])
    rl.scan(scan, (0.0, 0.0, 0.0), moving)
    g, p = rl.grid, rl.params
    assert not g.occupied(p)[g.cell((0.76, 0.0))]
    assert g.occupied(p)[g.cell((2.05, 0.6))]                     # the wall beside it is marked
    # the same walker reported static (standing still): marked; once gone, the beams through it clear it
    rl2 = layer()
    standing = Obstacles.from_lists([[1.0, 0.0]], r=0.25, static=True, ids=[3])
    for _ in range(3):
        rl2.scan(scan, (0.0, 0.0, 0.0), standing)
    cell = rl2.grid.cell((0.76, 0.0))
    assert rl2.grid.occupied(rl2.params)[cell]
    for _ in range(8):
        rl2.scan(wall_scan(2.05, 1.0), (0.0, 0.0, 0.0), Obstacles.empty())
    assert not rl2.grid.occupied(rl2.params)[cell]


def test_costs_inflate_occupied_cells_and_grade_unknown_ones():
    occ = np.zeros((40, 20), bool)
    occ[20, :] = True
    unknown = np.zeros_like(occ)
    unknown[:, :5] = True
    p = RouteParams(enabled=True)
    cost, d = cell_costs(occ, unknown, 0.1, 0.25, p)
    assert np.isinf(cost[20, 10])
    assert cost[18, 10] == pytest.approx(1 + p.lethal_cost)                          # 0.2 m < r_R + d0
    assert cost[17, 10] == pytest.approx(1 + p.inflation_cost * math.exp(-p.cost_scaling_per_m * 0.05))
    assert cost[5, 10] == pytest.approx(1.0) and cost[5, 2] == pytest.approx(1 + p.unknown_cost)
    assert d[5, 10] == pytest.approx(1.5)


def test_the_path_goes_round_a_wall_and_none_through_a_closed_one():
    cost = np.ones((50, 50))
    cost[25, 0:40] = np.inf
    path = shortest_path(cost, (10, 10), (40, 10))
    assert tuple(path[0]) == (10, 10) and tuple(path[-1]) == (40, 10)
    assert not np.isinf(cost[path[:, 0], path[:, 1]]).any()
    assert path[:, 1].max() >= 40                                           # round the wall's open end
    steps = np.abs(np.diff(path, axis=0))
    assert steps.max() == 1 and (steps.sum(axis=1) >= 1).all()              # 8-connected
    cost[25, 40:] = np.inf                                                  # closed: no path
    assert len(shortest_path(cost, (10, 10), (40, 10))) == 0
    diag = np.ones((3, 3))
    diag[0, 1] = diag[1, 0] = np.inf
    assert len(shortest_path(diag, (0, 0), (1, 1))) == 0                   # past two corners: no path


def test_the_local_goal_is_the_look_ahead_point_in_sight_and_the_goal_within_reach():
    rl = layer()
    rl.scan(wall_scan(2.05, 1.0), (0.0, 0.0, 0.0))
    state = RobotState(0.0, 0.0, 0.0)
    lg = rl.local_goal(0.0, state, np.array([4.0, 0.0]))
    path = rl.path
    assert np.allclose(path[-1], [4.0, 0.0]) and abs(path[:, 1]).max() > 1.0   # round the wall
    assert np.linalg.norm(lg) <= rl.params.lookahead_m + 1e-9
    assert np.linalg.norm(lg) > 1.0                                      # far along the path, not next to the robot
    assert rl._visible(np.zeros(2), lg)
    assert rl.plans == 1
    rl.local_goal(0.2, state, np.array([4.0, 0.0]))                     # between replans: the same path
    assert rl.plans == 1
    rl.local_goal(0.5, state, np.array([4.0, 0.0]))                     # replan_hz 2
    assert rl.plans == 2
    near = RobotState(3.2, 0.4, 0.0)
    assert np.array_equal(rl.local_goal(0.6, near, np.array([4.0, 0.0])), [4.0, 0.0])


@pytest.mark.parametrize("arrive_m, want_goal", [(0.0, False), (0.15, True)])
def test_a_look_ahead_point_within_the_arrival_tolerance_gives_way_to_the_goal(arrive_m, want_goal):
    """A cell still marked 0.1 m beyond the goal (a person who stood there and left while no beam came back through
    it) hides the goal from the visibility test; the look-ahead point is then the path point before the goal. With
    the robot within the arrival tolerance eps_g of that point a method stops there as arrived, short of the goal,
    until the time limit (dev world doorway_00004, route on: every method 0.2-0.35 m short): the layer hands the
    goal instead. Without a tolerance (arrive_m 0) the point stays."""
    rl = RouteLayer(RouteParams(enabled=True), r_robot_m=0.15, d0_m=0.10, arrive_m=arrive_m)
    goal = np.array([4.09, 0.0])                                        # off the cells' centres, as a goal is
    rl.reset((0.0, 0.0), goal)
    g = rl.grid
    g.logodds[g.cell((4.05, -0.1))] = rl.params.l_max                   # the stale cell beside the goal
    pos = np.array([3.84, 0.05])
    lg = rl.local_goal(0.0, RobotState(*pos, 0.0), goal)
    assert not rl._visible(pos, goal) and np.allclose(rl.path[-2], [3.95, 0.05])
    if want_goal:
        assert np.array_equal(lg, goal)
    else:                                                               # the path point 0.11 m away: "arrived"
        assert np.allclose(lg, [3.95, 0.05]) and np.linalg.norm(lg - pos) <= 0.15
    far = rl.local_goal(0.1, RobotState(2.0, 0.0, 0.0), goal)            # farther away: the usual look-ahead point
    assert np.linalg.norm(far - [2.0, 0.0]) > 1.0 and not np.array_equal(far, goal)


def test_a_walled_off_goal_hands_the_goal_itself():
    rl = layer()
    g = rl.grid
    ix, iy = g.cell((4.0, 0.0))
    box = np.zeros(g.shape, bool)
    box[ix - 5:ix + 6, iy - 5:iy + 6] = True
    box[ix - 4:ix + 5, iy - 4:iy + 5] = False
    g.logodds[box] = rl.params.l_max
    assert np.array_equal(rl.local_goal(0.0, RobotState(0.0, 0.0, 0.0), np.array([4.0, 0.0])), [4.0, 0.0])
    assert rl.path is None and rl.failed_plans == 1


def test_a_faulty_pose_maps_nothing_and_gets_the_goal_itself():
    rl = layer()
    rl.scan(wall_scan(2.05, 1.0), (float("nan"), 0.0, 0.0))
    assert not rl.grid.seen.any()
    goal = np.array([4.0, 0.0])
    assert np.array_equal(rl.local_goal(0.0, RobotState(float("nan"), 0.0, 0.0), goal), goal) and rl.plans == 0


def test_grid_size_is_bounded_by_max_cells():
    g = OccupancyGrid((0.0, 0.0), (100.0, 100.0), 0.05, 10_000)
    assert g.nx * g.ny <= 10_000 and g.res > 0.9


def test_route_params_are_checked():
    with pytest.raises(FieldError, match="resolution_m"):
        RouteParams(resolution_m=0.0)
    with pytest.raises(FieldError, match="mark_range_m") as err:
        RouteParams(mark_range_m=5.0, clear_range_m=4.0)
    assert err.value.field == "clear_range_m"


def test_the_route_table_of_a_run_configuration(tmp_path):
    assert "route" not in config_toml(RunConfig())                     # the paper's keys do not change
    on = RunConfig(route=RouteParams(enabled=True, lookahead_m=2.0))
    assert "[route]" in config_toml(on) and config_from_toml(config_toml(on)).route == on.route
    f = tmp_path / "run.toml"
    f.write_text("[route]\nenabled = true\nreplan_hz = 1.0\n")
    assert load_run_config(f).route == RouteParams(enabled=True, replan_hz=1.0)
    f.write_text("[route]\nlookahead = 2.0\n")
    with pytest.raises(UserError, match=r"run\.toml.*route\.lookahead"):
        load_run_config(f)
    f.write_text("[route]\nlookahead_m = -1.0\n")
    with pytest.raises(UserError, match=r"route\.lookahead_m"):
        load_run_config(f)


TRAP = """
name = "deep_trap"
description = "A U-shaped pocket on the goal line, open toward the robot, 2.4 m deep (the look-ahead: 1.2 m)."
time_limit_s = 14.0
extent_m = 4.0

[robot]
start = [0.0, 0.0, 0.0]
goal = [6.5, 0.0]

[[boxes]]
center = [4.2, 0.0]
half_size = [0.1, 1.6]

[[boxes]]
center = [3.1, 1.5]
half_size = [1.2, 0.1]

[[boxes]]
center = [3.1, -1.5]
half_size = [1.2, 0.1]
"""


@pytest.fixture(scope="module")
def trap(tmp_path_factory):
    path = tmp_path_factory.mktemp("route") / "deep_trap.toml"
    path.write_text(TRAP)
    return path


@pytest.mark.parametrize("method", ["cbf-only", "big-cbf"])
def test_a_deep_trap_holds_the_method_without_the_route_and_not_with_it(trap, method):
    sc = load_scenario(trap, 0)
    off = Episode.from_config(sc, method, 0, RunConfig()).run()
    assert off.timeout and not off.success and off.final_goal_dist_m > 2.0     # held at the pocket's back wall
    ep = Episode.from_config(sc, method, 0, RunConfig(route=RouteParams(enabled=True)))
    on = ep.run()
    assert on.success and not on.collision, on
    assert ep.route.plans >= 10 and ep.route.failed_plans == 0
    assert on.final_goal_dist_m <= 0.3          # judged on the real goal (eps_g), not on the look-ahead point


def test_run_route_flag(trap, capsys):
    import json
    assert main(["run", str(trap), "--method", "cbf-only", "--route", "on", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["success"] is True
    assert main(["run", str(trap), "--route", "maybe"]) == 2


def test_bench_route_flag_is_part_of_the_key(trap, tmp_path):
    from bigcbf.bench.runner import plan
    from bigcbf.cli import build_parser
    from bigcbf.cli.bench import config_from_args

    def tasks(*extra):
        args = build_parser().parse_args(["bench", "--out", str(tmp_path / "b"), "--methods", "cbf-only",
                                          "--scenarios", str(trap), "--seeds", "1", *extra])
        bc = config_from_args(args)
        return bc.config.route.enabled, plan(bc)[0][0]

    (on, t_on), (off, t_off), (default, t_default) = tasks("--route", "on"), tasks("--route", "off"), tasks()
    assert on and not off and not default
    assert t_off.params_hash == t_default.params_hash != t_on.params_hash
    assert "[route]" in t_on.params_toml and "[route]" not in t_off.params_toml
    cfg = tmp_path / "run.toml"
    cfg.write_text("[route]\nenabled = true\n")
    assert tasks("--config", str(cfg))[1].params_hash == t_on.params_hash
    assert not tasks("--config", str(cfg), "--route", "off")[0]


def test_perf_figures_of_the_route_layer():
    from bigcbf.control.perf import _route
    from bigcbf.params import SIMULATION
    out = _route(True, SIMULATION)
    for key in ("route_scan_p95_ms", "route_plan_p95_ms", "route_plan_median_ms", "route_goal_p95_ms",
                "route_scan_median_ms", "route_tick_mean_ms"):
        assert 0 < out[key] < 1e3, key
    assert out["route_plan_median_ms"] > out["route_scan_median_ms"]     # a replan (inflation + A*) costs more


def _wall_with_openings(rl: RouteLayer, openings) -> None:
    """The whole grid seen and free but for a wall x in [2.0, 2.2) with ``openings`` ((y_lo, y_hi), ...)."""
    g, p = rl.grid, rl.params
    g.seen[:] = True
    g.logodds[:] = p.l_min
    x = g.x0 + (np.arange(g.nx) + 0.5) * g.res
    y = g.y0 + (np.arange(g.ny) + 0.5) * g.res
    wall = ((x >= 2.0) & (x < 2.2))[:, None] & np.ones(g.ny, bool)[None, :]
    for lo, hi in openings:
        wall &= ~((y >= lo) & (y <= hi))[None, :]
    g.logodds[wall] = p.l_max


def _crossing_y(path) -> float:
    """Where a path crosses x = 2.1."""
    i = int(np.argmin(np.abs(path[:, 0] - 2.1)))
    return float(path[i, 1])


def test_a_stall_sends_the_route_another_way_where_there_is_one():
    """Step 5 (Nav2's progress checker): a robot that stays within progress_radius_m for progress_time_s makes the
    path ahead costly; with a second opening the new path takes it, with the gap the only way the path stays."""
    still = RobotState(1.5, 0.0, 0.0)
    for openings, far_way in ((((-0.25, 0.25), (2.0, 3.0)), True), (((-0.25, 0.25),), False)):
        for progress in (0.0, 5.0):
            rl = layer(progress_time_s=progress)
            _wall_with_openings(rl, openings)
            rl.local_goal(0.0, still, (4.0, 0.0))
            assert abs(_crossing_y(rl.path)) < 0.3                 # first through the near gap
            for k in range(1, 121):                                # 6 s without moving
                rl.local_goal(0.05 * k, still, (4.0, 0.0))
            if progress == 0.0:
                assert not rl.stalls and abs(_crossing_y(rl.path)) < 0.3
                continue
            assert [round(t, 2) for t, _, _ in rl.stalls] == [5.0]
            if far_way:
                assert 2.0 <= _crossing_y(rl.path) <= 3.0          # round by the other opening
            else:
                assert abs(_crossing_y(rl.path)) < 0.3             # no other way: the same gap


def test_moving_counts_as_progress():
    rl = layer(progress_time_s=2.0)
    _wall_with_openings(rl, ((-0.25, 0.25), (2.0, 3.0)))
    for k in range(200):                                           # 10 s at 0.06 m/s: 0.12 m in 2 s
        rl.local_goal(0.05 * k, RobotState(0.003 * k, 0.0, 0.0), (4.0, 0.0))
    assert [round(t, 2) for t, _, _ in rl.stalls] == [2.0, 4.0, 6.0, 8.0]     # a stall every 2 s...
    rl = layer(progress_time_s=2.0)
    _wall_with_openings(rl, ((-0.25, 0.25), (2.0, 3.0)))
    for k in range(200):                                           # ...0.3 m/s moves 0.5 m in 1.7 s: none
        rl.local_goal(0.05 * k, RobotState(-3.0 + 0.015 * k, 0.0, 0.0), (4.0, 0.0))
    assert rl.stalls == []


@pytest.mark.slow
def test_the_progress_check_takes_backup_cbf_round_a_gap_it_cannot_use(tmp_path):
    """Dev world clutter_00015 (two posts 0.71 m apart on the route's first path, wide enough for the footprint at
    rest, not for the common filter's clearance at speed), Backup-CBF, route on, episode seed 0: standing in that gap
    until its time runs out without the progress check; with it (3 s) the stall makes that way costly and the new
    path goes round, to the goal (measured in the dev bench of this change, 2026-11-28)."""
    from bigcbf.worlds.generator import generate
    f = tmp_path / "clutter_00015.toml"
    f.write_text(generate("clutter", 15).toml)
    sc = load_scenario(str(f), 0)
    out = {}
    for progress in (0.0, 3.0):
        cfg = RunConfig()
        cfg = cfg.replace(route=RouteParams(enabled=True, progress_time_s=progress))
        ep = Episode.from_config(sc, "backup-cbf", 0, cfg)
        out[progress] = (ep.run(), ep.route.stalls)
    (off, no_stalls), (on, stalls) = out[0.0], out[3.0]
    assert off.timeout and not off.success and no_stalls == []
    assert on.success and not on.collision and len(stalls) >= 1
    assert stalls[0][0] < 15.0                                     # the first stall in the gap, early


def test_no_stall_while_a_moving_track_is_near():
    """wait_range_m: a robot standing still while a moving track is within that distance waits (people coming
    through the gap), it has not stalled; a static track that near, or a moving one farther, does not count."""
    blank = LaserScan(0.0, -math.pi, 2 * math.pi / N_BEAMS, 0.15, 12.0, np.full(N_BEAMS, np.inf, np.float32))
    still = RobotState(1.5, 0.0, 0.0)
    cases = (([[2.9, 0.0]], False, 2.0, []),                        # edge 1.15 m away, moving: waiting
             ([[2.9, 0.0]], True, 2.0, [3.0]),                      # the same track reported static: a stall
             ([[4.0, 0.0]], False, 2.0, [3.0]),                     # moving but 2.25 m away: a stall
             ([[2.9, 0.0]], False, 0.0, [3.0]))                     # wait_range_m 0: the rule off
    for p, static, wait, stalls in cases:
        rl = layer(progress_time_s=3.0, wait_range_m=wait)
        _wall_with_openings(rl, ((-0.25, 0.25), (2.0, 3.0)))
        track = Obstacles.from_lists(p, v=[[-0.5, 0.0]], r=0.25, static=static, ids=[4])
        for k in range(80):                                        # 4 s standing, a scan every 0.1 s
            if k % 2 == 0:
                rl.scan(blank, (still.px, still.py, still.theta), track)
            rl.local_goal(0.05 * k, still, (4.0, 0.0))
        assert [round(t, 2) for t, _, _ in rl.stalls] == stalls, (p, static, wait)
