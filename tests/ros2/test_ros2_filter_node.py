"""The filter node on its own (no simulator): a feeder participant plays the robot on loopback; the node answers
/odom with /cmd_vel, and its watchdog zeroes the command on a stale scan (stamps), a stale /odom (wall clock) and
its own overrun."""
import math
import time

import numpy as np
import pytest

from bigcbf.logio import convert, msgdefs
from bigcbf.params.stack import default_stack_params
from bigcbf.ros2 import transport
from bigcbf.ros2.filter_node import FilterNode, FilterOptions
from bigcbf.ros2.stack import SafetyStack
from bigcbf.types import LaserScan, RobotState


def _scan(t, near=False):
    r = np.full(360, np.inf, np.float32)
    r[262:278] = 0.35 if near else 1.2                    # a post to the robot's left (beam 270: +90 deg)
    return LaserScan(stamp=t, angle_min=-math.pi, angle_increment=2 * math.pi / 360, range_min=0.05,
                     range_max=12.0, ranges=r, frame_id="laser", scan_time=0.1)


class Robot:
    """The feeder: publishes like a robot driver, collects what the node sends back."""

    def __init__(self, domain_id, node):
        self.n = transport.Node("robot", domain_id, loopback=True)
        self.scan = self.n.publisher("/scan", msgdefs.LASER_SCAN, transport.DEFAULT)
        self.odom = self.n.publisher("/odom", msgdefs.ODOMETRY, transport.DEFAULT)
        self.tf = self.n.publisher("/tf_static", msgdefs.TF_MESSAGE, transport.LATCHED)
        self.cmds, self.status = [], []
        self.n.subscribe("/cmd_vel", msgdefs.TWIST, lambda m, t: self.cmds.append(convert.twist_u(m)),
                         transport.DEFAULT)
        self.n.subscribe("/filter/status", msgdefs.STRING, lambda m, t: self.status.append(m.data),
                         transport.DEFAULT)
        self.tf(convert.static_tf_msg(0.0, [("base_link", "laser", (0.05, 0.0, 0.2), 0.0)]))
        deadline = time.monotonic() + 5
        while min(self.n.matched(self.scan), self.n.matched(self.odom)) == 0 and time.monotonic() < deadline:
            node.node.spin_once(0.01)

    def tick(self, node, t, scan=True, state=RobotState(0.0, 0.0, 0.0, 0.2, 0.0, 0.0)):
        if scan:
            self.scan(convert.laser_scan_msg(_scan(t)))
        self.odom(convert.odometry_msg(t, state))
        n = len(self.cmds)
        deadline = time.monotonic() + 5
        while len(self.cmds) == n and time.monotonic() < deadline:
            node.node.spin_once(0.01)
            self.n.spin_once(0.01)
        return self.cmds[-1]

    def drain(self, node, seconds):
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            node.node.spin_once(0.01)
            node.watchdog()
            self.n.spin_once(0.01)


@pytest.fixture
def setup(domain_id):
    stack = SafetyStack("big-cbf", default_stack_params())
    stack.warm_up()
    node = FilterNode(transport.Node("filter", domain_id, loopback=True), stack,
                      FilterOptions(goal=(3.0, 0.0), odom_timeout_s=0.3, scan_timeout_s=0.5, overrun_ms=1000,
                                    markers=True))
    robot = Robot(domain_id, node)
    yield node, robot
    robot.n.close()
    node.node.close()


def test_commands_then_watchdog(setup):
    node, robot = setup
    u = robot.tick(node, 0.0)
    assert u[0] > 0.05                                     # toward the goal, free ahead
    assert node.stack.perception_params.laser_x_m == pytest.approx(0.05)      # the mount from /tf_static
    assert robot.tick(node, 0.05, scan=False)[0] > 0.05
    # no scan for 0.55 s at the odometry's stamps: the scan is stale, the command zero
    assert robot.tick(node, 0.6, scan=False) == (0.0, 0.0, 0.0)
    assert robot.status[-1].startswith("stale /scan")
    assert robot.tick(node, 0.65)[0] > 0.05                # a fresh scan: commands again
    # /odom stops: within its timeout (wall clock) the node sends zero and says why
    robot.cmds.clear()
    robot.drain(node, 0.6)
    assert robot.cmds and robot.cmds[-1] == (0.0, 0.0, 0.0)
    assert any(s.startswith("stale /odom") for s in robot.status)
    # its own overrun: a budget no step can meet gives a zero command
    node.budget_ms = 1e-6
    assert robot.tick(node, 0.7) == (0.0, 0.0, 0.0)
    assert robot.status[-1].startswith("overrun")
    assert node.stats.zero_commands["overrun"] == 1 and node.stats.zero_commands["stale /scan"] == 1


def test_filter_alone_filters_cmd_vel_in(domain_id):
    stack = SafetyStack("filter", default_stack_params())
    node = FilterNode(transport.Node("filter", domain_id, loopback=True), stack, FilterOptions())
    robot = Robot(domain_id, node)
    cmd_in = robot.n.publisher("/cmd_vel_in", msgdefs.TWIST)
    deadline = time.monotonic() + 5
    while robot.n.matched(cmd_in) == 0 and time.monotonic() < deadline:
        node.node.spin_once(0.01)
    robot.scan(convert.laser_scan_msg(_scan(0.0, near=True)))
    robot.odom(convert.odometry_msg(0.0, RobotState(0.0, 0.0, 0.0, 0.0, 0.0, 0.0)))
    for _ in range(20):
        node.node.spin_once(0.01)
    cmd_in(convert.twist_msg((0.0, 0.6, 0.0)))             # straight at the post on the left
    while not robot.cmds and time.monotonic() < deadline:
        node.node.spin_once(0.01)
        robot.n.spin_once(0.01)
    assert robot.cmds and robot.cmds[-1][1] < 0.6          # the CBF slowed the approach
    robot.n.close()
    node.node.close()


def test_overrun_budget_is_real_time_only_unless_given(domain_id):
    """The overrun valve's budget: T_C by default; in lock-step none (the twin's time waits for the answer), unless
    --overrun-ms is given. A lock-step node with no budget answers a slow step with its command, not zero."""
    stack = SafetyStack("big-cbf", default_stack_params())
    made = []
    for opts in (FilterOptions(), FilterOptions(lockstep=True), FilterOptions(lockstep=True, overrun_ms=20.0),
                 FilterOptions(overrun_ms=20.0)):
        made.append(FilterNode(transport.Node("filter", domain_id, loopback=True), stack, opts))
    assert [n.budget_ms for n in made] == [pytest.approx(1e3 * stack.params.T_C_s), None, 20.0, 20.0]
    lock = made[1]
    lock.stack.set_goal(3.0, 0.0)
    lock.stack.scan(_scan(0.0), RobotState(0.0, 0.0, 0.0))
    lock._odom = [(0.0, RobotState(0.0, 0.0, 0.0))]
    sent = []
    lock._publish_cmd = lambda u, stamp: sent.append(tuple(u))
    lock._step(0.0, convert.time_msg(0.0), None, time.perf_counter() - 10.0)     # a message 10 s old
    assert sent[-1][0] > 0.05 and not lock.stats.zero_commands
    for n in made:
        n.node.close()
