"""Find the topics an analysis needs by message type when their names differ from ours; the user can name them.

Rules, for a role (commands, odometry, scans, IMU):
1. a topic the user named must exist and have an accepted type, else UserError;
2. else our own name (e.g. /cmd_vel) if the log has it with an accepted type;
3. else the topics of an accepted type, minus those whose name says they are something else (/cmd_vel_in is the
   planner's input, not what the robot was sent; /ground_truth/odom is not what the robot measured); if one is
   left it is used; if several, those whose name contains the role's keyword (cmd_vel, odom, scan, imu); if that
   leaves one it is used, otherwise UserError listing the candidates and the option to name one;
4. nothing of an accepted type: UserError (for a required role) listing every topic the log has.
"""
from __future__ import annotations

from dataclasses import dataclass

from ..errors import UserError
from . import msgdefs
from .reader import RobotLog, TopicInfo, describe_topics


@dataclass(frozen=True)
class Role:
    name: str                       # "commands", ...
    types: tuple[str, ...]          # accepted message types (ROS 2 names)
    default: str                    # our topic name
    keyword: str                    # a name containing this is preferred among several candidates
    exclude: tuple[str, ...]        # name fragments that disqualify a topic
    option: str                     # the command-line option that names it


CMD = Role("commands", (msgdefs.TWIST, msgdefs.TWIST_STAMPED), "/cmd_vel", "cmd_vel",
           ("cmd_vel_in", "_in/", "ground_truth", "teleop", "joy", "nav_vel", "raw"), "--cmd-topic")
ODOM = Role("odometry", (msgdefs.ODOMETRY,), "/odom", "odom",
            ("ground_truth", "groundtruth", "gt/", "truth", "filtered", "global"), "--odom-topic")
SCAN = Role("laser scans", (msgdefs.LASER_SCAN,), "/scan", "scan", (), "--scan-topic")
IMU = Role("IMU", (msgdefs.IMU,), "/imu", "imu", (), "--imu-topic")


def find_topic(log: RobotLog, role: Role, named: str | None = None, required: bool = True) -> str | None:
    """The topic of ``log`` that plays ``role`` (rules in the module docstring); None if optional and absent."""
    topics = log.topics
    if named is not None:
        info = topics.get(named)
        if info is None:
            raise UserError(f"no topic {named} ({role.option}); the log has: {describe_topics(topics)}",
                            file=str(log.path))
        if info.msgtype not in role.types:
            raise UserError(f"topic {named} ({role.option}) is {info.msgtype}, expected {' or '.join(role.types)}",
                            file=str(log.path))
        return named
    d = topics.get(role.default)
    if d is not None and d.msgtype in role.types:
        return role.default
    typed = [t for t in topics.values() if t.msgtype in role.types]
    cands = [t for t in typed if not any(x in t.name.lower() for x in role.exclude)]
    if len(cands) == 1:
        return cands[0].name
    if len(cands) > 1:
        keyed = [t for t in cands if role.keyword in t.name.lower()]
        if len(keyed) == 1:
            return keyed[0].name
        raise UserError(f"several topics could be the {role.name}: {_names(keyed or cands)}; name one with "
                        f"{role.option}", file=str(log.path))
    if not required:
        return None
    why = f" (not used: {_names(typed)}, name one with {role.option} to use it)" if typed else ""
    raise UserError(f"no {role.name} topic ({' or '.join(role.types)}){why}; the log has: "
                    f"{describe_topics(topics)}", file=str(log.path))


def _names(infos: list[TopicInfo]) -> str:
    return ", ".join(sorted(t.name for t in infos))
