"""Running a launch description in the foreground: executor, /clock, transport, dashboard.

Shared by ``eddie sim``, ``eddie slam``, ``eddie vslam`` and ``eddie nav``. The process
joins the graph before it builds anything: one that would publish ``/clock`` (it runs the
simulator) refuses to start when another process on the same ROS_DOMAIN_ID publishes it
already (`eddiebot.cli._attach`). Whatever stops
the start (a misspelt world, a parameter file error, a busy dashboard port, a lifecycle
manager that cannot bring its nodes up) is raised as a typed error after every node built
so far is destroyed; ``eddie``'s main prints it as one line.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from typing import Any

from eddiebot.cli._common import connect_transport
from eddiebot.cli.errors import BringUpError
from eddiebot.core.context import Context
from eddiebot.core.launch import (
    LaunchDescription,
    build_nodes,
    find_launch_file,
    parse_launch_file,
    spin_nodes,
)
from eddiebot.core.node import Node
from eddiebot.registry import NODES

__all__ = ["add_run_arguments", "check_world", "run_nodes", "run_stack"]

#: How often a lifecycle manager's bring-up is checked (node clock), s.
_BRING_UP_CHECK_S = 0.2


def add_run_arguments(parser: argparse.ArgumentParser) -> None:
    """Options every simulated run shares."""
    pace = parser.add_mutually_exclusive_group()
    pace.add_argument("--rate", type=float, default=1.0,
                      help="real-time factor (default 1: real time; 5: five times faster)")
    pace.add_argument("--fast", action="store_true", help="as fast as the CPU allows")
    parser.add_argument("--seed", type=int, default=0, help="seed of every random process")
    parser.add_argument("--duration", type=float, default=None,
                        help="stop after this many simulated seconds")
    parser.add_argument("--dashboard", action="store_true", help="serve the web dashboard")
    parser.add_argument("--dashboard-port", type=int, default=8080)
    parser.add_argument("--no-transport", action="store_true",
                        help="do not open the graph to other processes")


def build_description(launch: str, launch_args: dict[str, str]) -> LaunchDescription:
    return parse_launch_file(find_launch_file(launch), launch_args)


def check_world(world: str) -> None:
    """Raise `eddiebot.sim.errors.SimError` (naming the built-in worlds) unless ``world`` is
    a built-in world or a readable world file — before anything is built."""
    from eddiebot.sim.worlds import load_world

    load_world(world)


def run_stack(args: argparse.Namespace, launch: str, launch_args: dict[str, str]) -> int:
    """Build ``launch`` on a sim clock this process owns and spin it until interrupted."""
    if "world" in launch_args:
        check_world(launch_args["world"])
    context = Context(use_sim_time=True)
    return run_nodes(args, context, lambda: build_nodes(
        build_description(launch, launch_args), context, NODES),
        real_time_factor=None if args.fast else args.rate, owns_sim_clock=True)


def run_nodes(args: argparse.Namespace, context: Context, build: Callable[[], list[Node]], *,
              real_time_factor: float | None = None, owns_sim_clock: bool | None = None,
              connected: bool = False) -> int:
    """Join the graph (unless ``--no-transport`` or ``connected``: the caller joined it),
    build the nodes, serve the dashboard (``--dashboard``), and spin until interrupted or
    ``--duration`` is over. With ``owns_sim_clock`` the run stops first, with a
    `CliError`, when another process on the domain publishes ``/clock``.

    Nothing is left running when a step fails: the nodes are destroyed and the context
    shut down before the error propagates.
    """
    dashboard = None
    try:
        if getattr(args, "dashboard", False):
            _check_port_free(args.dashboard_port)  # before minutes of start-up, not after
        if not args.no_transport and not connected:
            connect_transport(context)
            if owns_sim_clock:
                from eddiebot.cli._attach import refuse_second_simulator

                refuse_second_simulator(context, f"eddie {getattr(args, 'command', None) or 'sim'}")
        nodes = build()
        if getattr(args, "dashboard", False):
            dashboard = _start_dashboard(context, args.dashboard_port)
        for node in nodes:
            _watch_bring_up(node)
        return spin_nodes(nodes, context, real_time_factor=real_time_factor,
                          duration_s=args.duration, owns_sim_clock=owns_sim_clock)
    except _BringUpFailed as exc:
        raise BringUpError(str(exc)) from None
    finally:
        if dashboard is not None:
            dashboard.stop()
        context.shutdown()


def _start_dashboard(context: Context, port: int) -> Any:
    try:
        from eddiebot.viz.dashboard import start_dashboard
    except ImportError:
        print("eddie: the dashboard is not installed", file=sys.stderr)
        return None
    from eddiebot.viz.dashboard.errors import DashboardBindError

    try:
        return start_dashboard(context, "127.0.0.1", port)
    except DashboardBindError as exc:
        raise DashboardBindError(f"{exc} (choose another with --dashboard-port)") from exc


def _check_port_free(port: int) -> None:
    """Raise `DashboardBindError` when the dashboard could not listen on ``port``."""
    import socket

    from eddiebot.viz.dashboard.errors import DashboardBindError

    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind(("127.0.0.1", port))
        except OSError as exc:
            raise DashboardBindError(
                f"cannot serve the dashboard on 127.0.0.1:{port}: {exc.strerror or exc} "
                "(choose another with --dashboard-port)") from exc


class _BringUpFailed(BaseException):
    """Raised from a timer callback to stop the spin: a BaseException, so that the node's
    callback guard (which logs an ``Exception`` and carries on) lets it through."""


def _watch_bring_up(node: Node) -> None:
    """Stop the run when ``node``, an autostarting lifecycle manager, fails to bring its
    nodes up (Nav2's manager logs the error and idles; a user at a terminal is left with a
    stack that never starts)."""
    from eddiebot.core.lifecycle import LifecycleManager

    if not isinstance(node, LifecycleManager) or not node.get_parameter("autostart").value:
        return
    timer: Any = None

    def check() -> None:
        if node.system_active:
            timer.cancel()
        elif node.last_error and not _running(LifecycleManager.startup):
            timer.cancel()
            raise _BringUpFailed(f"{node.get_name()} could not bring its nodes up: "
                                 f"{node.last_error}{_reason(node)}")

    timer = node.create_timer(_BRING_UP_CHECK_S, check)


def _reason(manager: Any) -> str:
    """``: <why>`` from the managed node that failed (Nav2 servers keep their last
    transition error), else nothing."""
    for other in list(manager.context.nodes):
        why = getattr(other, "last_error", "")
        if other is not manager and other.get_name() in manager.node_names and why:
            return f": {why}"
    return ""


def _running(function: Any) -> bool:
    """True when ``function`` is on this thread's stack: a service call inside the manager's
    start-up spins the executor, which may run the check half-way through it."""
    code = function.__code__
    frame = sys._getframe(1)
    while frame is not None:
        if frame.f_code is code:
            return True
        frame = frame.f_back  # type: ignore[assignment]
    return False
