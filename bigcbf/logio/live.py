"""Stream an episode to Foxglove while it runs (``bigcbf run --live``): the same topics as the MCAP log, over
Foxglove's WebSocket protocol (foxglove-sdk, ``pip install 'bigcbf[live]'``).

:class:`LiveWriter` is a :class:`~bigcbf.logio.writer.LogWriter` whose messages go to a WebSocket server instead
of a file: the same topics, ROS 2 types (``ros2msg`` schemas, CDR messages, as in the MCAP), frames and time base.
The server advertises the simulation clock (Foxglove's Time capability) with every /clock message.

Latched topics (/tf_static, /robot_description, /goal_pose, /map, /scene/markers: those the writer marks
``latched``) reach late clients as a transient-local publisher's do: the SDK calls our ``ServerListener``'s
``on_subscribe`` when a client subscribes to a channel, and the last message of a latched topic is then logged
again, so a client that connects seconds after the start still gets the goal, the robot model, the map and the
static transforms. It goes to every subscribed client (a client that already had it gets the same message again,
which a latched topic's reader takes as it is): ``Channel.log`` can target one sink (``sink_id``), but the SDK's
Python ``Client`` carries only the client's id, which is not its sink id (they differ once another sink, an MCAP
writer say, exists: measured with foxglove-sdk 0.30.3, the late client then got nothing).

``wait_for_client(timeout_s)`` holds the start until a client has subscribed (``bigcbf run --live --live-wait
SECONDS``). ``bigcbf run --live`` paces the episode at real time so that it can be watched.
"""
from __future__ import annotations

import math
import threading
import time

from ..errors import UserError
from . import convert, msgdefs
from .writer import EPISODE_TOPICS, TOPIC_CLOCK, LogWriter

DEFAULT_PORT = 8765


class LiveWriter(LogWriter):
    """``with LiveWriter(port=8765) as w: ...`` (or ``EpisodeLogger(episode, writer=w)``); ``w.url`` to connect.
    ``port=0`` picks a free port. ``topics`` (topic -> type, default every topic of an episode log) are advertised
    from the start, so a client sees them all when it connects (a topic first written later is advertised then)."""

    def __init__(self, host: str = "127.0.0.1", port: int = DEFAULT_PORT, *, name: str = "bigcbf",
                 odom_frame: str = "odom", base_frame: str = "base_link", topics: dict[str, str] | None = None):
        import foxglove
        from mcap_ros2._dynamic import serialize_dynamic     # the encoder mcap-ros2-support's writer uses

        self._fg, self._serialize = foxglove, serialize_dynamic
        self.odom_frame, self.base_frame = odom_frame, base_frame
        self.counts: dict[str, int] = {}
        self._channels: dict[str, object] = {}
        self._encoders: dict[str, object] = {}
        self._latched: dict[str, tuple[bytes, int]] = {}
        self._lock = threading.Lock()
        self._subscribed = threading.Condition(self._lock)
        self.subscriptions = 0                     # (client, channel) subscriptions seen so far
        self._last_subscribe = 0.0
        writer = self

        class _Listener(foxglove.ServerListener):
            def on_subscribe(self, client, channel):          # a late subscriber gets the latched message again
                with writer._lock:
                    latched = writer._latched.get(channel.topic)
                    ch = writer._channels.get(channel.topic)
                    writer.subscriptions += 1
                    writer._last_subscribe = time.monotonic()
                    writer._subscribed.notify_all()
                if latched is not None and ch is not None:
                    ch.log(latched[0], log_time=latched[1])

        self.server = foxglove.start_server(name=name, host=host, port=port, server_listener=_Listener(),
                                            capabilities=[foxglove.Capability.Time])
        self.host, self.port = host, self.server.port
        self.url = f"ws://{host}:{self.port}"
        self.path = self.url
        self._closed = False
        for topic, msgtype in (EPISODE_TOPICS if topics is None else topics).items():
            self._channel(topic, msgtype)

    def _channel(self, topic: str, msgtype: str):
        ch = self._channels.get(topic)
        if ch is None:
            schema = self._fg.Schema(name=msgtype, encoding="ros2msg", data=msgdefs.schema_text(msgtype).encode())
            ch = self._fg.Channel(topic, schema=schema, message_encoding="cdr")
            with self._lock:
                self._channels[topic] = ch
        return ch

    def write(self, topic: str, msgtype: str, t: float, message: dict, *, latched: bool = False) -> None:
        enc = self._encoders.get(msgtype)
        if enc is None:
            enc = self._encoders[msgtype] = self._serialize(msgtype, msgdefs.schema_text(msgtype))[msgtype]
        ch = self._channel(topic, msgtype)
        data, ns = enc(message), convert.to_ns(t)
        if latched:
            with self._lock:
                self._latched[topic] = (data, ns)
        ch.log(data, log_time=ns)
        if topic == TOPIC_CLOCK:
            self.server.broadcast_time(ns)
        self.counts[topic] = self.counts.get(topic, 0) + 1

    def wait_for_client(self, timeout_s: float, settle_s: float = 0.5) -> bool:
        """Wait until a client has subscribed to a channel, at most ``timeout_s`` seconds, then until its
        subscriptions have settled (none new for ``settle_s``, at most 2 s more: Foxglove subscribes panel by
        panel). True if a client came; False when the time ran out (the caller goes on without one). A
        ``timeout_s`` that is not a positive number is a UserError (``--live-wait``)."""
        try:
            timeout_s = float(timeout_s)
        except (TypeError, ValueError):
            raise UserError(f"--live-wait: expected a number of seconds, got {timeout_s!r}") from None
        if not (math.isfinite(timeout_s) and timeout_s > 0):
            raise UserError(f"--live-wait: expected a positive number of seconds, got {timeout_s:g}")
        deadline = time.monotonic() + timeout_s
        with self._subscribed:
            while self.subscriptions == 0:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._subscribed.wait(left)
            settle_end = time.monotonic() + 2.0
            while True:
                quiet_until = self._last_subscribe + settle_s
                now = time.monotonic()
                if now >= min(quiet_until, settle_end):
                    return True
                self._subscribed.wait(min(quiet_until, settle_end) - now)

    def finish_partial(self):
        """A stream keeps nothing: closed (see EpisodeLogger.finish_partial)."""
        self.close()
        return None

    def abort(self) -> None:
        self.close()

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            for ch in self._channels.values():
                ch.close()
            self.server.stop()


class RealTimePacer:
    """An episode observer that holds each control step until the wall clock has caught up with the simulation
    (``speed`` times real time), so that a live view runs at the robot's pace."""

    def __init__(self, speed: float = 1.0):
        self.speed = float(speed)
        self._t0: float | None = None

    def __call__(self, rec) -> None:
        now = time.perf_counter()
        if self._t0 is None:
            self._t0 = now - rec.t / self.speed
        wait = self._t0 + rec.t / self.speed - now
        if wait > 0:
            time.sleep(wait)
