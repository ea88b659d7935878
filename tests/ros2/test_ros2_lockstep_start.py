"""The start of a lock-step exchange (a CI run of tests/ros2/test_ros2_loopback.py once had the filter answer "no
scan yet" for the twin's first 20 ticks, where the in-process episode drives from the first one):

- what the twin wrote on /scan and /odom before the filter's readers matched its writers reaches the filter on the
  match (transport.LOCKSTEP is transient local; volatile, those scans were lost);
- a step whose /odom comes before the first /scan waits for it (up to FIRST_SCAN_WAIT_S on the wall clock), then
  answers with the stack's command, not zero; with no scan at all it answers zero after the wait.
"""
import math
import time

import numpy as np
import pytest

from bigcbf.logio import convert, msgdefs
from bigcbf.params.stack import default_stack_params
from bigcbf.ros2 import filter_node, transport
from bigcbf.ros2.filter_node import FilterNode, FilterOptions
from bigcbf.ros2.stack import SafetyStack
from bigcbf.types import LaserScan, RobotState

MOVING = RobotState(0.0, 0.0, 0.0, 0.2, 0.0, 0.0)


def _scan(t):
    r = np.full(360, np.inf, np.float32)
    r[262:278] = 1.2                                       # a post to the robot's left
    return LaserScan(stamp=t, angle_min=-math.pi, angle_increment=2 * math.pi / 360, range_min=0.05,
                     range_max=12.0, ranges=r, frame_id="laser", scan_time=0.1)


class Twin:
    """Writes like ``bigcbf sim --lockstep`` (its QoS), collects the stamped answers."""

    def __init__(self, domain_id):
        self.n = transport.Node("twin", domain_id, loopback=True)
        self.scan = self.n.publisher("/scan", msgdefs.LASER_SCAN, transport.LOCKSTEP)
        self.odom = self.n.publisher("/odom", msgdefs.ODOMETRY, transport.LOCKSTEP)
        self.tf = self.n.publisher("/tf_static", msgdefs.TF_MESSAGE, transport.LATCHED)
        self.answers = {}
        self.n.subscribe("/cmd_vel", msgdefs.TWIST_STAMPED, self._on_cmd, transport.DEFAULT)
        self.tf(convert.static_tf_msg(0.0, [("base_link", "laser", (0.05, 0.0, 0.2), 0.0)]))

    def _on_cmd(self, m, t_in):
        self.answers[m.header.stamp.sec * 10 ** 9 + m.header.stamp.nanosec] = convert.twist_u(m.twist)

    def wait_answer(self, node, t, seconds=8.0):
        ns = round(t * 1e9)
        deadline = time.monotonic() + seconds
        while ns not in self.answers and time.monotonic() < deadline:
            node.spin(iter([False, True]).__next__, period_s=0.01)        # one turn of the node's loop
            self.n.spin_once(0.01)
        return self.answers.get(ns)


def _filter(domain_id):
    stack = SafetyStack("big-cbf", default_stack_params())
    stack.warm_up()
    return FilterNode(transport.Node("filter", domain_id, loopback=True), stack,
                      FilterOptions(goal=(3.0, 0.0), lockstep=True))


def test_what_was_written_before_the_match_arrives(domain_id):
    twin = Twin(domain_id)
    twin.scan(convert.laser_scan_msg(_scan(0.0)))          # the first tick, before the filter exists
    twin.odom(convert.odometry_msg(0.0, MOVING))
    node = _filter(domain_id)
    try:
        u = twin.wait_answer(node, 0.0)
        assert u is not None and u[0] > 0.05               # the stack's command toward the goal
        assert node.stats.zero_commands == {} and node.stats.scans == 1
    finally:
        twin.n.close()
        node.node.close()


def test_a_step_ahead_of_the_first_scan_waits_for_it(domain_id):
    node = _filter(domain_id)
    twin = Twin(domain_id)
    try:
        deadline = time.monotonic() + 5
        while min(twin.n.matched(twin.scan), twin.n.matched(twin.odom)) == 0 and time.monotonic() < deadline:
            node.node.spin_once(0.01)
        twin.odom(convert.odometry_msg(0.0, MOVING))       # the odometry first
        assert twin.wait_answer(node, 0.0, seconds=0.5) is None        # no answer: the step waits
        assert node._deferred is not None
        twin.scan(convert.laser_scan_msg(_scan(0.0)))      # then the tick's scan: the step is answered
        u = twin.wait_answer(node, 0.0)
        assert u is not None and u[0] > 0.05
        assert node.stats.zero_commands == {} and node.stats.steps == 1
    finally:
        twin.n.close()
        node.node.close()


def test_no_scan_at_all_answers_zero_after_the_wait(domain_id, monkeypatch):
    monkeypatch.setattr(filter_node, "FIRST_SCAN_WAIT_S", 0.3)
    node = _filter(domain_id)
    twin = Twin(domain_id)
    try:
        twin.odom(convert.odometry_msg(0.0, MOVING))
        t0 = time.monotonic()
        u = twin.wait_answer(node, 0.0)
        assert u == (0.0, 0.0, 0.0) and time.monotonic() - t0 >= 0.3
        assert node.stats.zero_commands == {"no scan yet": 1}
    finally:
        twin.n.close()
        node.node.close()
