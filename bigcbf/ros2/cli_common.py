"""Options and set-up shared by ``bigcbf sim --ros2`` and ``bigcbf filter --ros2`` (no simulator imports)."""
from __future__ import annotations

import os

from ..errors import UserError
from .transport import MAX_DOMAIN_ID, check_domain_id


def add_dds_arguments(p) -> None:
    p.add_argument("--ros2", action="store_true", required=True,
                   help="speak ROS 2 over DDS (cyclonedds, pip install 'bigcbf[ros2]'); the only transport, required")
    p.add_argument("--domain-id", type=_domain_id, default=None, metavar="N",
                   help=f"DDS domain, as ROS_DOMAIN_ID (0..{MAX_DOMAIN_ID}; default: $ROS_DOMAIN_ID, else 0)")
    p.add_argument("--loopback", action="store_true",
                   help="DDS on the loopback interface only, multicast off, unicast discovery of 127.0.0.1: nothing "
                        "leaves this machine (both nodes on one host; a ROS 2 stack on it needs the same "
                        "CYCLONEDDS_URI)")
    p.add_argument("--lockstep", action="store_true",
                   help="lock-step between 'bigcbf sim --ros2' and 'bigcbf filter --ros2' (both need it): the twin "
                        "waits for the filter's stamped answer at each control tick")


def _domain_id(s: str) -> int:
    """--domain-id's type: a whole number, checked by the transport's own rule (``transport.check_domain_id``)."""
    import argparse
    try:
        return check_domain_id(int(s))
    except (ValueError, UserError):
        raise argparse.ArgumentTypeError(f"expected a whole number in [0, {MAX_DOMAIN_ID}], got {s!r}") from None


def domain_id(args) -> int:
    """--domain-id, else $ROS_DOMAIN_ID (checked: a bad value is one line naming it), else 0."""
    if args.domain_id is not None:
        return args.domain_id
    env = os.environ.get("ROS_DOMAIN_ID", "").strip()
    if not env:
        return 0
    try:
        return _domain_id(env)
    except Exception as exc:
        raise UserError(f"ROS_DOMAIN_ID: {exc}") from None
