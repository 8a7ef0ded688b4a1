"""Inter-process transport: the same graph across processes and machines, over Zenoh.

In-process delivery is the context's own (by reference, zero copy). ``connect(context)``
attaches a :class:`~eddiebot.transport.zenoh.ZenohTransport` so that topics, services and
the graph reach other ``eddie`` processes — and, since keys and liveliness tokens are laid
out as ``rmw_zenoh`` lays them out, later ROS 2 nodes on ``rmw_zenoh_cpp`` through the same
router.

Discovery: every process opens a Zenoh *peer* session that connects to the router at
``EDDIE_ZENOH_ROUTER`` (default ``tcp/127.0.0.1:7447``, as rmw_zenoh) and listens on a
loopback port of its own; the router gossips those endpoints so processes then exchange
data directly. When no router answers, ``connect`` starts ``eddie daemon`` detached (as the
ros2 CLI starts its daemon) unless ``EDDIE_ROUTER_AUTOSTART=0``; peers keep retrying the
router, so a router started later still joins everyone. ``EDDIE_NETWORK=lan`` (or
``EDDIE_ZENOH_CONFIG=file.json5``) opens to the LAN; ``EDDIE_TRANSPORT=none`` disables it.
"""

from __future__ import annotations

import logging
import os
from typing import TYPE_CHECKING

from eddiebot.transport.config import DEFAULT_ROUTER, ZenohConfig
from eddiebot.transport.errors import RemoteServiceError, RouterError, TransportError

if TYPE_CHECKING:
    from eddiebot.core.context import Context
    from eddiebot.transport.zenoh import ZenohTransport

__all__ = [
    "DEFAULT_ROUTER",
    "RemoteServiceError",
    "RouterError",
    "TransportError",
    "ZenohConfig",
    "ZenohTransport",
    "connect",
    "transport_enabled",
]

log = logging.getLogger("eddiebot.transport")


def __getattr__(name: str) -> object:
    # ``ZenohTransport`` imports zenoh: only when asked for
    if name == "ZenohTransport":
        from eddiebot.transport.zenoh import ZenohTransport

        return ZenohTransport
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def transport_enabled() -> bool:
    """False when ``EDDIE_TRANSPORT`` is ``none`` (or ``off``/``0``)."""
    return os.environ.get("EDDIE_TRANSPORT", "zenoh").strip().lower() not in (
        "none", "off", "0", "false", "no")


def connect(
    context: Context | None = None,
    config: ZenohConfig | None = None,
    *,
    required: bool = False,
) -> ZenohTransport | None:
    """Attach the Zenoh transport to ``context`` (default: the default context).

    Returns the transport (the existing one if already attached), or None when the
    transport is disabled or cannot start (with a warning; ``required=True`` raises).
    """
    from eddiebot.core.context import get_default_context

    if not transport_enabled():
        return None
    ctx = context or get_default_context()
    from eddiebot.transport.zenoh import ZenohTransport

    for t in ctx.transports:
        if isinstance(t, ZenohTransport):
            return t
    try:
        cfg = config or ZenohConfig.from_env()
        if cfg.config_file is None and cfg.autostart_router:
            from eddiebot.transport.router import router_reachable, start_detached

            if not router_reachable(cfg):
                try:
                    pid = start_detached(cfg)
                    log.info("started the Zenoh router at %s (pid %d)", cfg.router, pid)
                except RouterError as exc:
                    log.warning("%s; peers will keep retrying the router", exc)
        transport = ZenohTransport(ctx, cfg)
    except Exception as exc:
        if required:
            raise TransportError(f"cannot start the Zenoh transport: {exc}") from exc
        log.warning("no inter-process transport: %s", exc)
        return None
    try:
        ctx.attach_transport(transport)
    except BaseException:  # Ctrl-C half-way: leave no open session behind
        transport.close()
        raise
    # other processes' viewers read every node's log lines on /rosout, as with rcl
    from eddiebot.core.clock_node import enable_rosout

    enable_rosout(ctx)
    return transport
