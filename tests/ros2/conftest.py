"""Shared by the ROS 2 tests: skip where the cyclonedds binding is not installed (the ``ros2`` extra), and a DDS
domain id per test process (pytest-xdist workers do not hear each other)."""
import os

import pytest

pytest.importorskip("cyclonedds", reason="the ros2 extra (cyclonedds) is not installed")


@pytest.fixture
def domain_id():
    """A domain of this test process: 100 + pid mod 100 (tests on loopback only, see bigcbf/ros2/transport.py)."""
    return 100 + os.getpid() % 100
