"""What runs already on this ROS_DOMAIN_ID: one simulator per graph, attaching to a robot.

From the transport's graph view (liveliness tokens, `eddiebot.transport.graph.GraphCache`):

- `refuse_second_simulator` — a process about to publish ``/clock`` stops when another
  publishes it already (two simulators on one graph cross-wire every topic); `publishes_clock`
  tells from a launch's node types whether it would (``eddie launch`` / ``eddie run``);
- `wait_for_robot` — ``eddie slam`` / ``nav`` / ``vslam`` without ``--world`` wait for the
  simulator (a ``/clock`` publisher) or a real robot's bring-up (an ``/odom`` publisher).

With ``EDDIE_TRANSPORT=none`` (or ``--no-transport``) there is no graph: nothing to check,
nothing to attach to.
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from eddiebot.cli.errors import CliError

if TYPE_CHECKING:
    from eddiebot.core.context import Context
    from eddiebot.transport.graph import GraphCache
    from eddiebot.transport.keys import GraphEntity

__all__ = ["ATTACH_WAIT_S", "Robot", "graph_cache", "publishes_clock", "refuse_second_simulator",
           "wait_for_robot"]

#: The node class whose process drives the sim clock and publishes ``/clock``
#: (`eddiebot.core.launch.spin_nodes` owns the clock when it is in the context).
_CLOCK_OWNER = "eddiebot.sim.node:SimulatorNode"

#: How long ``eddie slam`` / ``nav`` / ``vslam`` without ``--world`` wait for a robot, s.
ATTACH_WAIT_S = 10.0
#: Once ``/odom`` is seen, how long a ``/clock`` publisher of the same start may lag, s.
_CLOCK_GRACE_S = 1.0


#: how long a start-up check lets the graph's liveliness tokens arrive
_SETTLE_S = 0.5


def graph_cache(context: Context) -> GraphCache | None:
    """The graph view of the context's transport, or None when it has none."""
    for transport in context.transports:
        graph = getattr(transport, "graph", None)
        if graph is not None:
            cache = graph().get("cache")
            if cache is not None:
                return cache  # type: ignore[no-any-return]
    return None


def _process(cache: GraphCache, entity: GraphEntity) -> str:
    """``/simulator, /eddie_odom, … in process 1a2b3c4d``: the nodes beside ``entity``."""
    names = sorted({e.node for e in cache.nodes() if e.zid == entity.zid} - {entity.node},
                   key=lambda name: (name != "/simulator", name))
    shown = ", ".join(names[:3]) + (", …" if len(names) > 3 else "")
    beside = f" beside {shown}" if shown else ""
    return f"{entity.node}{beside}, process {entity.zid[:8]}"


@dataclass(frozen=True)
class Robot:
    """What ``eddie slam`` / ``nav`` / ``vslam`` attach to."""

    domain: int
    clock: GraphEntity | None
    """The ``/clock`` publisher (a simulator), or None (a real robot on the wall clock)."""
    odom: GraphEntity | None
    """The ``/odom`` publisher (the base's odometry), or None when not seen yet."""
    what: str
    """One phrase naming it, for the ``attached to …`` line."""

    @property
    def simulated(self) -> bool:
        return self.clock is not None

    @property
    def odom_session(self) -> str | None:
        """The running odometry's identity: its process and node (`eddiebot.maps.MapAnchor`)."""
        return None if self.odom is None else f"{self.odom.zid}{self.odom.node}"


def publishes_clock(node_types: Iterable[str], use_sim_time: bool,
                    registry: Mapping[str, str]) -> bool:
    """Whether a process running nodes of these registered types would publish ``/clock``:
    on sim time, with the simulator among them (decided before anything is built)."""
    return use_sim_time and any(registry.get(t) == _CLOCK_OWNER for t in node_types)


def refuse_second_simulator(context: Context, command: str) -> None:
    """Raise `CliError` (one line: who publishes ``/clock`` and how to run beside it) when
    another process on this domain publishes ``/clock`` already."""
    cache = graph_cache(context)
    if cache is None:
        return
    # liveliness tokens may still be arriving on a loaded machine: let the graph settle
    cache.wait_for(lambda: bool(cache.publishers("/clock")), _SETTLE_S)
    clocks = cache.publishers("/clock")
    if not clocks:
        return
    domain = int(context.domain_id)
    raise CliError(
        f"{command}: a simulator already runs on ROS_DOMAIN_ID {domain} (/clock from "
        f"{_process(cache, clocks[0])}); attach to it (eddie slam / nav / vslam "
        f"without --world), stop it, or run beside it on another domain: "
        f"ROS_DOMAIN_ID={domain + 1} {command} …")


def wait_for_robot(context: Context, command: str, timeout_s: float = ATTACH_WAIT_S) -> Robot:
    """Wait up to ``timeout_s`` for a ``/clock`` or ``/odom`` publisher on this domain.

    Raises `CliError` (what was looked for, the domain, the two ways out) when none shows,
    or when the transport is off."""
    domain = int(context.domain_id)
    ways_out = (f"start one first (eddie sim --world office, or the robot's bring-up on "
                f"ROS_DOMAIN_ID {domain}) or let {command} bring its own with --world office")
    cache = graph_cache(context)
    if cache is None:
        raise CliError(f"{command}: no graph to attach to (the transport is off: "
                       f"EDDIE_TRANSPORT=none or --no-transport); {ways_out}")
    deadline = time.monotonic() + timeout_s
    found = cache.wait_for(lambda: bool(cache.publishers("/clock") or cache.publishers("/odom")),
                           timeout_s)
    if not found:
        raise CliError(f"{command}: no simulator or robot on ROS_DOMAIN_ID {domain} (no /clock "
                       f"or /odom publisher within {timeout_s:g} s); {ways_out}")
    if not cache.publishers("/clock"):
        cache.wait_for(lambda: bool(cache.publishers("/clock")),
                       max(0.0, min(_CLOCK_GRACE_S, deadline - time.monotonic())))
    if cache.publishers("/clock") and not cache.publishers("/odom"):
        cache.wait_for(lambda: bool(cache.publishers("/odom")),
                       max(0.0, min(_CLOCK_GRACE_S, deadline - time.monotonic())))
    clocks = cache.publishers("/clock")
    odoms = cache.publishers("/odom")
    clock = clocks[0] if clocks else None
    odom = odoms[0] if odoms else None
    if clock is not None:
        what = f"the simulator on ROS_DOMAIN_ID {domain} ({_process(cache, clock)})"
    else:
        assert odom is not None
        what = f"the robot on ROS_DOMAIN_ID {domain} (/odom from {_process(cache, odom)})"
    return Robot(domain, clock, odom, what)


def odom_pose(context: Context, timeout_s: float = 5.0) -> tuple[float, float, float] | None:
    """The robot's pose in the odom frame from one ``/odom`` message (x, y, yaw), or None."""
    import math

    from eddiebot.core.node import Node
    from eddiebot.msgs.nav_msgs import Odometry

    got: list[Any] = []
    node = Node("_eddie_attach_probe", context=context)
    try:
        node.create_subscription(Odometry, "/odom", got.append, 1)
        from eddiebot.core.executors import SingleThreadedExecutor

        executor = SingleThreadedExecutor(context=context, drive_sim_time=False)
        executor.add_node(node)
        deadline = time.monotonic() + timeout_s
        while not got and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        executor.remove_node(node)
    finally:
        node.destroy_node()
    if not got:
        return None
    pose = got[-1].pose.pose
    q = pose.orientation
    yaw = math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
    return float(pose.position.x), float(pose.position.y), yaw
