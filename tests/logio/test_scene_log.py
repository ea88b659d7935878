"""The static scene in a log: /scene/markers (walls, boxes, cylinders at their true poses and sizes) and /map (an
occupancy grid: occupied exactly where the simulator's own geometry says so, free elsewhere in the scenario's area,
unknown around it), written by LogWriter and read back with rosbags."""
import math

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from bigcbf.logio import LogWriter
from bigcbf.logio.scene_msgs import MAX_CELLS, UNKNOWN_MARGIN_M, grid_resolution, rasterize
from bigcbf.scenario import load_scenario
from bigcbf.sim.scene import SceneSpec, Wall
from bigcbf.sim.truth import Clearance


@pytest.fixture(scope="module")
def scene_log(tmp_path_factory):
    """mixed_dense_traffic's scene (2 walls, 2 boxes, 1 cylinder) written as a log's latched topics."""
    sc = load_scenario("mixed_dense_traffic", 0)
    scene = sc.scene()
    path = tmp_path_factory.mktemp("scene") / "scene.mcap"
    with LogWriter(path) as w:
        w.scene_markers(0.0, scene)
        w.occupancy_grid(0.0, scene)
    msgs = {}
    with AnyReader([path]) as reader:
        for con, _, raw in reader.messages():
            msgs[con.topic] = (con.msgtype, reader.deserialize(raw, con.msgtype))
    return sc, scene, msgs


def test_scene_markers_are_the_scenarios_geometry(scene_log):
    sc, _, msgs = scene_log
    msgtype, arr = msgs["/scene/markers"]
    assert msgtype == "visualization_msgs/msg/MarkerArray"
    assert arr.markers[0].action == 3                                   # DELETEALL first
    by_ns = {}
    for m in arr.markers[1:]:
        assert m.header.frame_id == "map" and m.action == 0
        by_ns.setdefault(m.ns, []).append(m)
    assert {k: len(v) for k, v in by_ns.items()} == {"walls": len(sc.walls), "boxes": len(sc.boxes),
                                                     "cylinders": len(sc.cylinders)}
    for w, m in zip(sc.walls, by_ns["walls"]):                         # a CUBE from start to end, ends capped
        (x0, y0), (x1, y1) = w.start, w.end
        assert m.type == 1 and (m.pose.position.x, m.pose.position.y) == pytest.approx(((x0 + x1) / 2, (y0 + y1) / 2))
        assert m.scale.x == pytest.approx(math.hypot(x1 - x0, y1 - y0) + w.thickness_m)
        assert (m.scale.y, m.scale.z, m.pose.position.z) == pytest.approx((w.thickness_m, w.height_m, w.height_m / 2))
        q = m.pose.orientation
        assert 2 * math.atan2(q.z, q.w) == pytest.approx(math.atan2(y1 - y0, x1 - x0))
    for b, m in zip(sc.boxes, by_ns["boxes"]):
        assert m.type == 1 and (m.pose.position.x, m.pose.position.y) == pytest.approx(tuple(b.center))
        assert (m.scale.x, m.scale.y, m.scale.z) == pytest.approx((2 * b.half_size[0], 2 * b.half_size[1], b.height_m))
    for c, m in zip(sc.cylinders, by_ns["cylinders"]):
        assert m.type == 3 and (m.pose.position.x, m.pose.position.y) == pytest.approx(tuple(c.center))
        assert (m.scale.x, m.scale.z) == pytest.approx((2 * c.radius_m, c.height_m))


def test_map_is_occupied_where_the_simulator_has_geometry(scene_log):
    """Each cell against the simulator's own signed distances (bigcbf.sim.truth.Clearance): a cell whose centre is
    inside a wall, box or cylinder is 100, one at least half a cell from all of them is 0 (inside the area) or -1
    (the margin); the cells in between overlap an obstacle with their inscribed disc and are 100."""
    _, scene, msgs = scene_log
    msgtype, grid = msgs["/map"]
    assert msgtype == "nav_msgs/msg/OccupancyGrid" and grid.header.frame_id == "map"
    assert grid.info.resolution == pytest.approx(0.05)
    res = 0.05                                          # (the message's float32 is 0.05 + 7e-10)
    data = np.array(grid.data, np.int8).reshape(grid.info.height, grid.info.width)
    ox, oy = grid.info.origin.position.x, grid.info.origin.position.y
    truth = Clearance(scene)
    rows, cols = np.meshgrid(np.arange(0, data.shape[0], 3), np.arange(0, data.shape[1], 3), indexing="ij")
    n_occ = n_free = 0
    for r, c in zip(rows.ravel(), cols.ravel()):
        p = np.array([ox + (c + 0.5) * res, oy + (r + 0.5) * res])
        d = min([*truth.rect_distances(p)] + [math.hypot(*(p - cc)) - rr for cc, rr in zip(truth.circ_c, truth.circ_r)])
        v = data[r, c]
        if d <= 0:
            assert v == 100, (p, d)
            n_occ += 1
        elif d >= res / 2 - 1e-9:
            assert v in (0, -1), (p, d)
            n_free += v == 0
        else:
            assert v == 100, (p, d)
    assert n_occ > 50 and n_free > 1000
    assert np.all(data[0] == -1) and np.all(data[-1] == -1) and np.all(data[:, 0] == -1)
    margin = int(UNKNOWN_MARGIN_M / res)
    assert np.all(data[margin + 1:-margin - 1, margin + 1:-margin - 1] != -1)   # the area itself is known


def test_rasterize_by_hand_and_the_resolution_of_large_scenes():
    """A 4 m wall along y = 0, 0.1 m thick (its box spans x in [-2.05, 2.05], y in [-0.05, 0.05]) in a 2 m area:
    the grid is aligned with the box's ends, so exactly the cells inside it are occupied (their neighbours only
    share an edge with it)."""
    scene = SceneSpec(walls=(Wall(-2.0, 0.0, 2.0, 0.0, thickness=0.1),), extent=2.0)
    grid, (ox, oy), res = rasterize(scene)
    assert res == 0.05 and (ox, oy) == pytest.approx((-2.05 - UNKNOWN_MARGIN_M, -2.0 - UNKNOWN_MARGIN_M))
    ys = oy + (np.arange(grid.shape[0]) + 0.5) * res
    xs = ox + (np.arange(grid.shape[1]) + 0.5) * res
    occ_rows = ys[np.any(grid == 100, axis=1)]
    assert occ_rows == pytest.approx([-0.025, 0.025])
    occ_cols = xs[np.any(grid == 100, axis=0)]
    assert occ_cols.min() == pytest.approx(-2.025) and occ_cols.max() == pytest.approx(2.025)
    assert len(occ_cols) == 82 and np.count_nonzero(grid == 100) == 2 * 82
    assert set(np.unique(grid)) == {-1, 0, 100}
    assert grid_resolution(40.0, 40.0) == 0.05                           # 800 x 800 cells
    assert grid_resolution(60.0, 60.0) == 0.1                            # 0.05 would be 1200 x 1200
    big, _, big_res = rasterize(SceneSpec(extent=400.0))
    assert big_res == 1.0 and big.size <= MAX_CELLS
