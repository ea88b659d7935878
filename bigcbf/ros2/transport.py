"""DDS for ROS 2 nodes without ROS: a participant on a chosen domain, ROS 2's QoS profiles, publishers and
subscriptions on ROS 2 topic names, and a wait on all subscriptions at once.

The cyclonedds binding (``pip install 'bigcbf[ros2]'``) speaks RTPS, which a stock ROS 2 (Humble or Jazzy, with
rmw_cyclonedds or rmw_fastrtps) reads on the same domain. Configuration:

- ``loopback=True``: Cyclone is configured to the loopback interface, multicast off, with 127.0.0.1 as its unicast
  discovery peer: nothing leaves the machine (the tests; two processes of one host). ``loopback=False``: Cyclone's
  own configuration (``CYCLONEDDS_URI`` if set, else its defaults: every interface, multicast discovery, as a
  stock ROS 2 with rmw_cyclonedds).
- ``domain_id``: ROS_DOMAIN_ID (0..232).

QoS profiles (rmw's ``rmw_qos_profile_*``): ``SENSOR_DATA`` (best effort, volatile, keep last 5: /scan, /odom,
/imu as drivers publish them), ``DEFAULT`` (reliable, volatile, keep last 10: /cmd_vel, /tf), ``LATCHED``
(reliable, transient local, keep last 1: /tf_static, as tf2's static broadcaster), ``CLOCK`` (best effort, keep
last 1: /clock, as rclcpp's ClockQoS). Every writer sends XCDR1 (``DataRepresentation`` CDR v0), as ROS 2 does.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

from ..errors import UserError
from . import wire


@dataclass(frozen=True)
class QosProfile:
    name: str
    reliable: bool
    transient_local: bool
    depth: int


SENSOR_DATA = QosProfile("sensor_data", reliable=False, transient_local=False, depth=5)
DEFAULT = QosProfile("default", reliable=True, transient_local=False, depth=10)
LATCHED = QosProfile("latched", reliable=True, transient_local=True, depth=1)
CLOCK = QosProfile("clock", reliable=False, transient_local=False, depth=1)
#: lock-step between our own nodes (the twin's /scan and /odom, the filter's readers of them): nothing may be lost
#: (reliable), the whole exchange kept, and what was written before a reader matched the writer is delivered on the
#: match (transient local: with volatile durability a reader that matched the twin's writers after the writers
#: matched it lost the first scans, and the filter answered "no scan yet" for the first ticks on a loaded machine)
LOCKSTEP = QosProfile("lockstep", reliable=True, transient_local=True, depth=100)

#: the largest ROS_DOMAIN_ID (ROS 2's rule for the default port mapping)
MAX_DOMAIN_ID = 232

LOOPBACK_CONFIG = """<CycloneDDS xmlns="https://cdds.io/config"><Domain Id="any">
  <General><Interfaces><NetworkInterface address="127.0.0.1"/></Interfaces>
    <AllowMulticast>false</AllowMulticast></General>
  <Discovery><ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>30</MaxAutoParticipantIndex>
    <Peers><Peer Address="127.0.0.1"/></Peers></Discovery>
</Domain></CycloneDDS>"""


#: the loopback-configured Cyclone domains this process created (a domain's configuration is set once)
_LOOPBACK_DOMAINS: dict[int, object] = {}


def check_domain_id(domain_id) -> int:
    if isinstance(domain_id, bool) or not isinstance(domain_id, int) or not 0 <= domain_id <= MAX_DOMAIN_ID:
        raise UserError(f"--domain-id: expected a whole number in [0, {MAX_DOMAIN_ID}] (ROS_DOMAIN_ID), got "
                        f"{domain_id!r}")
    return domain_id


def _qos(profile: QosProfile, writer: bool):
    from cyclonedds.qos import Policy, Qos

    policies = [Policy.Reliability.Reliable(max_blocking_time=100_000_000) if profile.reliable
                else Policy.Reliability.BestEffort,
                Policy.Durability.TransientLocal if profile.transient_local else Policy.Durability.Volatile,
                Policy.History.KeepLast(profile.depth)]
    if writer:
        policies.append(Policy.DataRepresentation(use_cdrv0_representation=True))
    return Qos(*policies)


def import_cyclonedds():
    """The cyclonedds binding, or a UserError saying how to install it."""
    try:
        import cyclonedds.domain  # noqa: F401
    except ImportError as exc:
        raise UserError(f"ROS 2 needs the cyclonedds binding ({exc}): pip install 'bigcbf[ros2]'") from None


class Node:
    """One DDS participant for one of our ROS 2 nodes. ``publisher(topic, msgtype, qos)`` returns a function that
    publishes a dict (or an IDL object); ``subscribe(topic, msgtype, qos)`` a reader whose messages ``spin_once``
    hands to its callback."""

    def __init__(self, name: str, domain_id: int = 0, *, loopback: bool = False):
        import_cyclonedds()
        from cyclonedds.core import WaitSet
        from cyclonedds.domain import Domain, DomainParticipant

        self.name, self.domain_id = name, check_domain_id(domain_id)
        if loopback and domain_id not in _LOOPBACK_DOMAINS:      # one per process and id; outlives participants
            _LOOPBACK_DOMAINS[domain_id] = Domain(domain_id, LOOPBACK_CONFIG)
        self.dp = DomainParticipant(domain_id)
        self._topics: dict[tuple[str, str], object] = {}
        self._waitset = WaitSet(self.dp)
        self._readers: list[tuple[object, object, object]] = []    # (reader, condition, callback)
        self.last_wake_cpu = 0.0

    def _topic(self, topic: str, msgtype: str):
        from cyclonedds.topic import Topic

        key = (topic, msgtype)
        if key not in self._topics:
            self._topics[key] = Topic(self.dp, wire.dds_topic(topic), wire.idl_class(msgtype))
        return self._topics[key]

    def publisher(self, topic: str, msgtype: str, qos: QosProfile = DEFAULT):
        from cyclonedds.pub import DataWriter

        w = DataWriter(self.dp, self._topic(topic, msgtype), qos=_qos(qos, writer=True))
        cls = wire.idl_class(msgtype)

        def publish(message) -> None:
            w.write(message if isinstance(message, cls) else wire.from_dict(msgtype, message))
        publish.writer = w
        return publish

    def subscribe(self, topic: str, msgtype: str, callback, qos: QosProfile = SENSOR_DATA):
        """``callback(msg, t_in)`` for every message (``t_in``: time.perf_counter() when the wait woke)."""
        from cyclonedds.core import ReadCondition, SampleState, ViewState, InstanceState
        from cyclonedds.sub import DataReader

        r = DataReader(self.dp, self._topic(topic, msgtype), qos=_qos(qos, writer=False))
        cond = ReadCondition(r, SampleState.NotRead | ViewState.Any | InstanceState.Any)
        self._waitset.attach(cond)
        self._readers.append((r, cond, callback))
        return r

    def spin_once(self, timeout_s: float) -> int:
        """Wait up to ``timeout_s`` for messages, then hand every waiting one to its callback, in the order the
        subscriptions were made. Returns how many were handled.

        The readers are taken from the last subscription to the first and handed on from the first: a message that
        lands while the readers are taken is then either handed on with the ones written before it on an earlier
        subscription's topic, or waits for the next call with them (one writer, in order: the twin's /scan before
        its /odom). Taken first to last, a /scan landing after its reader was taken went after its /odom."""
        from cyclonedds.util import duration

        n = self._waitset.wait(duration(seconds=max(0.0, timeout_s)))
        if n <= 0:
            return 0
        from cyclonedds.internal import InvalidSample

        t_in = time.perf_counter()
        self.last_wake_cpu = time.thread_time()      # this thread's CPU time at the wake (latency in CPU time)
        handled = 0
        taken = [reader.take(N=64, condition=cond) for reader, cond, _ in reversed(self._readers)][::-1]
        for (_, _, callback), msgs in zip(self._readers, taken):
            for msg in msgs:
                if isinstance(msg, InvalidSample):     # a writer's end (unregister, dispose): no data
                    continue
                callback(msg, t_in)
                handled += 1
        return handled

    def matched(self, publish) -> int:
        """How many subscriptions a publisher (from :meth:`publisher`) has matched."""
        return len(publish.writer.get_matched_subscriptions())

    def close(self) -> None:
        for _, cond, _ in self._readers:
            self._waitset.detach(cond)
        self._readers.clear()
        self.dp = None
