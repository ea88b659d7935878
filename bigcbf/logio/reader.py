"""Read robot logs: ROS 1 bags, ROS 2 bags (sqlite3 or MCAP storage) and MCAP files, through rosbags.

The format is recognised from the content, not the name: a ROS 2 bag folder named ``*.bag`` or a ROS 1 bag
without the ``.bag`` suffix open as what they are. Every problem with the file is a UserError naming it: missing,
empty, not a log (an MCAP of other encodings than ROS 2 CDR is named as such), truncated or corrupt. A truncated
MCAP file (no footer, e.g. the recorder crashed) is read up to its last complete chunk, and an MCAP with a damaged
chunk up to that chunk, with a warning in ``RobotLog.warnings``: the messages recovered are whole and in time
order, so using them is sound; what was lost is only the rest of the recording.

Times: ``t`` is the log (receive) time in seconds, which is what the analyses use. Header stamps are returned
separately; they can be on another clock than the log.
"""
from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator, Sequence

import numpy as np

from ..errors import UserError
from . import convert, msgdefs

ROS1_MAGIC = b"#ROSBAG V2.0\n"
MCAP_MAGIC = b"\x89MCAP0\r\n"
SQLITE_MAGIC = b"SQLite format 3\x00"


@dataclass(frozen=True)
class TopicInfo:
    name: str
    msgtype: str      # ROS 2 name, e.g. "nav_msgs/msg/Odometry" (ROS 1 types are reported the same way)
    count: int


def describe_topics(topics: dict[str, TopicInfo]) -> str:
    """One line listing topics: "/odom (nav_msgs/msg/Odometry, 2741), /scan (...)" or "no topics"."""
    if not topics:
        return "no topics"
    return ", ".join(f"{t.name} ({t.msgtype}, {t.count})" for t in sorted(topics.values(), key=lambda t: t.name))


def sniff(path: Path) -> str:
    """The log format of ``path`` from its content: "ros1", "ros2" (bag folder) or "mcap"; UserError otherwise."""
    if not path.exists():
        raise UserError("file not found", file=str(path))
    if path.is_dir():
        if (path / "metadata.yaml").is_file():
            return "ros2"
        raise UserError("is a folder without metadata.yaml: not a ROS 2 bag folder", file=str(path))
    try:
        with open(path, "rb") as fh:
            head = fh.read(16)
    except OSError as exc:
        raise UserError(f"cannot read: {exc.strerror}", file=str(path)) from None
    if not head:
        raise UserError("the file is empty", file=str(path))
    if _magic(head, ROS1_MAGIC):
        return "ros1"
    if _magic(head, MCAP_MAGIC):
        return "mcap"
    if head.startswith(SQLITE_MAGIC):
        raise UserError("is a sqlite3 database: give the ROS 2 bag folder that holds it and its metadata.yaml",
                        file=str(path))
    raise UserError("not a robot log: expected a ROS 1 bag, a ROS 2 bag folder or an MCAP file", file=str(path))


def _magic(head: bytes, magic: bytes) -> bool:
    """Whether the file starts with ``magic`` (or is a cut-short prefix of it)."""
    return head.startswith(magic) if len(head) >= len(magic) else magic.startswith(head)


class RobotLog:
    """An open log. ``topics`` (name -> TopicInfo), ``messages(topics)`` yields (topic, t_s, decoded message).

    Use as a context manager, or call close().
    """

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.format = sniff(self.path)
        self.warnings: list[str] = []
        self.recovered = False
        self._tmp: tempfile.TemporaryDirectory | None = None
        self._reader = None
        self._raw: list[tuple[str, int, bytes]] | None = None
        self._types: dict[str, str] = {}
        self._typestore = None
        try:
            self._open_rosbags()
        except UserError:
            raise
        except Exception as exc:          # noqa: BLE001 - the file is bad in some way; say which file
            if self.format == "mcap":
                self._recover_mcap(exc)
            else:
                self._cleanup()
                raise UserError(f"cannot read the {self.format} log (corrupt or truncated?): {_reason(exc)}",
                                file=str(self.path)) from None
        self.topics: dict[str, TopicInfo] = self._topic_infos()
        if self._count_messages() == 0:
            self.close()
            raise UserError(f"the log has no messages (topics: {describe_topics(self.topics)})", file=str(self.path))

    # --- opening ---------------------------------------------------------------------------------------------
    def _link(self, suffix: str) -> Path:
        """A path to the log that rosbags' AnyReader classifies right (it decides ROS 1 vs 2 by the suffix)."""
        want_ros1 = self.format == "ros1"
        if (self.path.suffix == ".bag") == want_ros1 and (self.format != "mcap" or self.path.suffix == ".mcap"):
            return self.path
        self._tmp = tempfile.TemporaryDirectory(prefix="bigcbf-log-")
        link = Path(self._tmp.name) / f"log{suffix}"
        os.symlink(self.path.resolve(), link)
        return link

    def _open_rosbags(self) -> None:
        from rosbags.highlevel import AnyReader

        suffix = {"ros1": ".bag", "mcap": ".mcap", "ros2": ""}[self.format]
        path = self._link(suffix)
        reader = AnyReader([path], default_typestore=msgdefs.typestore())
        reader.open()
        self._reader = reader

    def _recover_mcap(self, first_error: Exception) -> None:
        """Read a damaged MCAP record by record up to the first bad one (whole chunks only)."""
        from mcap.records import Channel, Message, Schema
        from mcap.stream_reader import StreamReader
        from rosbags.typesys import Stores, get_types_from_msg, get_typestore

        schemas: dict[int, Schema] = {}
        channels: dict[int, Channel] = {}
        raw: list[tuple[str, int, bytes]] = []
        error = None
        try:
            with open(self.path, "rb") as fh:
                for rec in StreamReader(fh, skip_magic=False, emit_chunks=False, validate_crcs=True).records:
                    if isinstance(rec, Schema):
                        schemas[rec.id] = rec
                    elif isinstance(rec, Channel):
                        channels[rec.id] = rec
                    elif isinstance(rec, Message) and rec.channel_id in channels:
                        ch = channels[rec.channel_id]
                        raw.append((ch.topic, rec.log_time, rec.data))
        except Exception as exc:          # noqa: BLE001 - the damage ends the readable part
            error = exc
        if not raw:
            self._cleanup()
            raise UserError(f"corrupt or truncated MCAP, no complete message could be read ({_reason(first_error)})",
                            file=str(self.path)) from None
        store = get_typestore(Stores.EMPTY)
        types: dict[str, str] = {}
        foreign = set()
        for ch in channels.values():
            sc = schemas.get(ch.schema_id)
            if sc is None or sc.encoding != "ros2msg" or ch.message_encoding != "cdr":
                foreign.add(f"{ch.message_encoding} messages"
                            + (f" with {sc.encoding or 'no'} schemas" if sc is not None else ""))
                continue
            try:
                store.register(get_types_from_msg(sc.data.decode(), sc.name))
            except Exception as exc:      # noqa: BLE001
                self.warnings.append(f"topic {ch.topic}: its schema {sc.name} cannot be parsed ({_reason(exc)})")
                continue
            types[ch.topic] = sc.name
        raw = [r for r in raw if r[0] in types]
        if not raw and foreign:
            self._cleanup()
            raise UserError(f"not a ROS 2 log: this MCAP holds {', '.join(sorted(foreign))}; bigcbf reads ROS 2 "
                            "MCAP (ros2msg schemas, CDR messages), ROS 1 bags and ROS 2 bags", file=str(self.path))
        raw.sort(key=lambda r: r[1])
        self._raw, self._types, self._typestore = raw, types, store
        self.recovered = True
        end = raw[-1][1] * 1e-9 if raw else float("nan")
        self.warnings.append(
            f"{self.path}: damaged MCAP ({_reason(first_error)}); read {len(raw)} messages up to t = {end:.3f} s"
            + (f", then: {_reason(error)}" if error is not None else ""))

    # --- contents --------------------------------------------------------------------------------------------
    def _topic_infos(self) -> dict[str, TopicInfo]:
        out: dict[str, TopicInfo] = {}
        if self._reader is not None:
            for c in self._reader.connections:
                prev = out.get(c.topic)
                out[c.topic] = TopicInfo(c.topic, c.msgtype, c.msgcount + (prev.count if prev else 0))
        else:
            counts: dict[str, int] = {}
            for topic, _, _ in self._raw:
                counts[topic] = counts.get(topic, 0) + 1
            out = {t: TopicInfo(t, self._types[t], n) for t, n in counts.items()}
        return out

    def _count_messages(self) -> int:
        return sum(t.count for t in self.topics.values())

    @property
    def start_s(self) -> float:
        if self._reader is not None:
            return self._reader.start_time * 1e-9
        return self._raw[0][1] * 1e-9

    @property
    def end_s(self) -> float:
        if self._reader is not None:
            return self._reader.end_time * 1e-9
        return self._raw[-1][1] * 1e-9

    def messages(self, topics: Sequence[str]) -> Iterator[tuple[str, float, object]]:
        """(topic, log time [s], decoded message) of the given topics, in log-time order."""
        unknown = [t for t in topics if t not in self.topics]
        if unknown:
            raise UserError(f"no topic {', '.join(unknown)} in the log; it has: {describe_topics(self.topics)}",
                            file=str(self.path))
        last = None
        if self._reader is not None:
            conns = [c for c in self._reader.connections if c.topic in set(topics)]
            try:
                for c, t, raw in self._reader.messages(connections=conns):
                    msg = self._reader.deserialize(raw, c.msgtype)
                    last = t
                    yield c.topic, t * 1e-9, msg
                return
            except UserError:
                raise
            except Exception as exc:      # noqa: BLE001
                if self.format != "mcap":
                    hint = {"ros1": " (rosbag reindex may repair it)", "ros2": " (ros2 bag reindex may repair it)"}
                    raise UserError(f"corrupt log, a message cannot be read: {_reason(exc)}"
                                    f"{hint.get(self.format, '')}", file=str(self.path)) from None
                # a damaged chunk inside an MCAP whose index is intact: go on record by record up to the damage
                self._reader.close()
                self._reader = None
                self._recover_mcap(exc)
        want = set(topics)
        for topic, t, data in self._raw:
            if topic in want and (last is None or t > last):
                try:
                    msg = self._typestore.deserialize_cdr(data, self._types[topic])
                except Exception as exc:  # noqa: BLE001
                    raise UserError(f"corrupt log, a message on {topic} cannot be decoded: {_reason(exc)}",
                                    file=str(self.path)) from None
                yield topic, t * 1e-9, msg

    # --- life cycle ------------------------------------------------------------------------------------------
    def _cleanup(self) -> None:
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None

    def close(self) -> None:
        if self._reader is not None:
            self._reader.close()
            self._reader = None
        self._raw = None
        self._cleanup()

    def __enter__(self) -> "RobotLog":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def open_log(path: str | Path) -> RobotLog:
    """Open a ROS 1 bag, a ROS 2 bag folder or an MCAP file (see the module docstring)."""
    return RobotLog(path)


def _reason(exc: BaseException | None) -> str:
    if exc is None:
        return ""
    text = str(exc).strip() or type(exc).__name__
    return text.splitlines()[0]


# --- series: the data the twin analyses, as numpy arrays ----------------------------------------------------------
@dataclass
class TwistSeries:
    """Commands: log times t (N,) [s] and body twists u (N, 3) (vx [m/s], vy [m/s], wz [rad/s])."""
    topic: str
    t: np.ndarray
    u: np.ndarray


@dataclass
class OdomSeries:
    """Odometry: log times t (N,), header stamps (N,) [s], pose (N, 3) (x, y, yaw) in the odom frame, body
    twist (N, 3)."""
    topic: str
    t: np.ndarray
    stamp: np.ndarray
    pose: np.ndarray
    twist: np.ndarray
    frame_id: str = "odom"
    child_frame_id: str = "base_link"


@dataclass
class StampSeries:
    """Any stamped message: log times t (N,) and header stamps (N,) [s]."""
    topic: str
    t: np.ndarray
    stamp: np.ndarray


@dataclass
class LogData:
    """What :func:`read_series` extracted (None for a role not asked for)."""
    path: Path
    cmd: TwistSeries | None = None
    odom: OdomSeries | None = None
    scan: StampSeries | None = None
    warnings: list[str] = field(default_factory=list)


def read_series(log: RobotLog, cmd: str | None = None, odom: str | None = None, scan: str | None = None) -> LogData:
    """One pass over the log extracting the command, odometry and scan-stamp series of the named topics."""
    wanted = {k: v for k, v in (("cmd", cmd), ("odom", odom), ("scan", scan)) if v is not None}
    role_of = {v: k for k, v in wanted.items()}
    rows: dict[str, list] = {k: [] for k in wanted}
    frames = ("odom", "base_link")
    for topic, t, msg in log.messages(list(wanted.values())):
        role = role_of[topic]
        try:
            if role == "cmd":
                rows[role].append((t, *convert.twist_u(msg)))
            elif role == "odom":
                s = convert.odometry_state(msg)
                rows[role].append((t, convert.stamp_s(msg.header.stamp), s.px, s.py, s.theta, s.vx, s.vy, s.wz))
                frames = (msg.header.frame_id, msg.child_frame_id)
            else:
                rows[role].append((t, convert.stamp_s(msg.header.stamp)))
        except AttributeError as exc:
            raise UserError(f"topic {topic} ({log.topics[topic].msgtype}) does not have the fields of a {role} "
                            f"message: {exc}", file=str(log.path)) from None
    out = LogData(log.path, warnings=list(log.warnings))
    for role, topic in wanted.items():
        a = np.array(rows[role], float).reshape(-1, {"cmd": 4, "odom": 8, "scan": 2}[role])
        finite = np.all(np.isfinite(a), axis=1)
        if not np.all(finite):
            out.warnings.append(f"{topic}: dropped {int((~finite).sum())} messages with NaN or inf values")
            a = a[finite]
        order = np.argsort(a[:, 0], kind="stable")
        a = a[order]
        if role == "cmd":
            out.cmd = TwistSeries(topic, a[:, 0], a[:, 1:4])
        elif role == "odom":
            out.odom = OdomSeries(topic, a[:, 0], a[:, 1], a[:, 2:5], a[:, 5:8], *frames)
        else:
            out.scan = StampSeries(topic, a[:, 0], a[:, 1])
    return out
