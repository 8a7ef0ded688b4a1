"""``eddie bridge dds``: join a ROS 2 system on DDS (Fast DDS or Cyclone DDS peers).

The process joins our graph through the Zenoh transport and DDS domain ``--domain`` (default
``ROS_DOMAIN_ID``) through Cyclone DDS, and mirrors topics both ways as a ROS 2 node on
``rmw_cyclonedds`` sees them (``rt/<name>``, ``<pkg>::msg::dds_::<Type>_``, raw CDR); see
`eddiebot.transport.dds`. Loopback only unless ``EDDIE_NETWORK=lan``: a ROS 2 node on the
same machine then needs ``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``. Services of our graph
are offered to ROS 2 clients on Cyclone DDS, services on Cyclone DDS to our clients (not Fast
DDS ones either way: a call says why); ``ros2 node list`` shows our nodes, ``eddie node list``
theirs. Ctrl-C (or SIGTERM) stops it cleanly.
"""

from __future__ import annotations

import argparse
import os
import re
import signal
import sys
import time
from typing import Any

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="kind", metavar="KIND")
    p = sub.add_parser("dds", help="mirror topics to and from a DDS domain (ROS 2 on DDS)")
    p.add_argument("--domain", type=int, default=None,
                   help="DDS domain id (default: ROS_DOMAIN_ID, else 0)")
    p.add_argument("--allow", default=None, metavar="REGEX",
                   help="bridge only topics whose name matches REGEX (e.g. '^/(odom|cmd_vel)$')")
    p.add_argument("--deny", default=None, metavar="REGEX",
                   help="never bridge topics whose name matches REGEX")
    p.add_argument("--topics", default=None, metavar="NAME:TYPE,...",
                   help="bridge exactly these topics both ways, without discovery "
                        "(e.g. /chatter:std_msgs/msg/String)")
    p.add_argument("--stats", type=float, default=0.0, metavar="S",
                   help="print the samples carried per topic every S seconds (0: never)")
    parser.set_defaults(_parser=parser)


def _parse_topics(text: str | None) -> dict[str, str] | None:
    if not text:
        return None
    out: dict[str, str] = {}
    for item in text.split(","):
        name, sep, type_name = item.strip().partition(":")
        if not sep or not name or not type_name:
            raise ValueError(f"--topics wants NAME:TYPE items, got {item!r}")
        out[name if name.startswith("/") else "/" + name] = type_name
    return out


def run(args: argparse.Namespace) -> int:
    if getattr(args, "kind", None) != "dds":
        args._parser.print_help()
        return 0 if getattr(args, "kind", None) is None else 2
    for flag in ("allow", "deny"):
        pattern = getattr(args, flag)
        if pattern is not None:
            try:
                re.compile(pattern)
            except re.error as exc:
                print(f"eddie bridge dds: --{flag}: bad regular expression: {exc}",
                      file=sys.stderr)
                return 2
    try:
        topics = _parse_topics(args.topics)
    except ValueError as exc:
        print(f"eddie bridge dds: {exc}", file=sys.stderr)
        return 2
    return _bridge(args, topics)


def _bridge(args: argparse.Namespace, topics: dict[str, str] | None) -> int:
    from eddiebot.core.context import Context
    from eddiebot.transport import ZenohConfig, connect
    from eddiebot.transport.dds import DdsBridge, DdsBridgeConfig

    domain = args.domain if args.domain is not None else int(os.environ.get("ROS_DOMAIN_ID", "0"))
    zenoh_config = ZenohConfig.from_env()
    context = Context()
    previous = _stop_on_sigterm()
    bridge: Any = None
    try:
        transport = connect(context, zenoh_config, required=True)
        assert transport is not None  # required=True raises instead
        config = DdsBridgeConfig(domain_id=domain, network=zenoh_config.network,
                                 allow=args.allow, deny=args.deny, topics=topics)
        bridge = DdsBridge(context, transport, config)
        bridge.start()
        print(f"eddie bridge dds: domain {domain} ({zenoh_config.network}) <-> graph of domain "
              f"{context.domain_id} at {zenoh_config.router}", flush=True)
        seen: set[tuple[str, str, str]] = set()
        next_stats = time.monotonic() + args.stats if args.stats > 0 else None
        while context.ok():
            time.sleep(0.1)
            now_routes = {(r.topic, r.type_name, r.direction) for r in bridge.routes()}
            for topic, type_name, direction in sorted(now_routes - seen):
                print(f"bridged {_describe(topic, type_name, direction)}", flush=True)
            for topic, type_name, direction in sorted(seen - now_routes):
                print(f"unbridged {topic} [{type_name}] ({direction})", flush=True)
            seen = now_routes
            if next_stats is not None and time.monotonic() >= next_stats:
                next_stats += args.stats
                for (topic, direction), n in sorted(bridge.counts().items()):
                    print(f"{topic} {direction}: {n} samples", flush=True)
    except KeyboardInterrupt:
        pass
    finally:
        if bridge is not None:
            bridge.close()
        context.shutdown()
        signal.signal(signal.SIGTERM, previous)
    return 0


def _describe(name: str, type_name: str, direction: str) -> str:
    """One route as the bridge prints it: ``/odom [nav_msgs/msg/Odometry] -> dds``."""
    return {
        "to_dds": f"{name} [{type_name}] -> dds",
        "from_dds": f"{name} [{type_name}] <- dds",
        "service": f"service {name} [{type_name}] -> dds",
        "dds_service": f"service {name} [{type_name}] <- dds",
        "unreachable_service": f"service {name} [{type_name}] <- dds (not callable: "
                               "served by another DDS vendor only)",
    }.get(direction, f"{name} [{type_name}] ({direction})")


def _stop_on_sigterm() -> Any:
    def handler(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt

    try:
        return signal.signal(signal.SIGTERM, handler)
    except ValueError:  # not the main thread
        return signal.getsignal(signal.SIGTERM)
