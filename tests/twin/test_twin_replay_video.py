"""What the replay video draws on a frame: for each path (logged, nominal, calibrated) its trail and the robot's
current pose marker in its colour, a scale bar in metres, and a legend naming each colour."""
import numpy as np
import pytest

from twin.replay import PATH_RGB, draw_scale_bar, legend_items, overlay, scale_bar_length


@pytest.mark.parametrize("max_m, length", [(1.6, 1.0), (0.3, 0.2), (7.0, 5.0), (2.0, 2.0), (0.09, 0.05)])
def test_scale_bar_length(max_m, length):
    assert scale_bar_length(max_m) == pytest.approx(length)


def _near(img, uv, rgb, r=6):
    u, v = uv
    patch = img[v - r:v + r + 1, u - r:u + r + 1].reshape(-1, 3).astype(int)
    return bool(np.any(np.abs(patch - np.array(rgb)).sum(axis=1) < 30))


def test_overlay_marks_each_robot_pose_and_a_scale_bar():
    H, W, px_per_m = 480, 640, 100.0
    img = np.full((H, W, 3), 40, np.uint8)
    def to_px(xy):
        xy = np.asarray(xy, float).reshape(-1, 2)
        return np.column_stack([W / 2 + xy[:, 0] * px_per_m, H / 2 - xy[:, 1] * px_per_m]).round().astype(np.int32)
    # three straight drives along x from the origin, ending 1 m apart in y (so the markers do not overlap)
    xs = np.linspace(-2.0, 1.0, 30)
    paths = [(name, np.column_stack([xs, np.full(30, y), np.zeros(30)]))
             for name, y in (("logged", 1.0), ("nominal", 0.0), ("model", -1.0))]
    overlay(img, to_px, px_per_m, paths)
    for name, poses in paths:
        end = to_px(poses[-1:, :2])[0]
        assert _near(img, end, PATH_RGB[name])                              # the marker's footprint
        assert _near(img, end + (int(0.15 * px_per_m) + 12, 0), PATH_RGB[name])   # its heading arrow, ahead (+x)
        assert not _near(img, end + (60, 0), PATH_RGB[name])                # nothing beyond it
        mid = to_px(poses[15:16, :2])[0]
        assert _near(img, mid, PATH_RGB[name], r=2)                         # the trail
    # the scale bar: 1 m (100 px of at most a quarter of 640) in white at the bottom left
    bar = img[H - 20:H - 12, 10:130]
    assert (np.all(bar > 240, axis=2).sum(axis=1) >= 100).any()
    assert draw_scale_bar(np.zeros((480, 640, 3), np.uint8), 33.0) == 2.0  # 160 px at most: 2 m
    labels = [lab for lab, _, _ in legend_items("calibrated")]
    assert labels[:3] == ["logged (odometry)", "calibrated model", "nominal model"]
    assert [tuple(round(c * 255) for c in rgba[:3]) for _, rgba, _ in legend_items("calibrated")[:3]] == \
        [PATH_RGB["logged"], PATH_RGB["model"], PATH_RGB["nominal"]]
