"""The dashboard's web server: one page, one WebSocket, loopback by default.

Security model:

- bound to 127.0.0.1 unless told otherwise; any other bind needs a token (random unless
  given), printed with the URL. ``GET /?token=...`` trades it for an HttpOnly, SameSite=Strict
  session cookie;
- on a loopback bind the ``Host`` header must name the loopback (no DNS rebinding);
- a WebSocket is refused when its ``Origin`` is not the page's own origin, or, when a token
  is in force, when it carries no valid session (cookie, or ``?token=`` for scripts);
- ``read_only`` refuses every command that acts on the robot; opening or closing a view
  (``{"op": "view"}``: TF frames, the 3D cloud) only changes what the page receives and stays
  allowed. Commands, views included, are rate-limited per connection; malformed, oversized or
  out-of-range commands are answered with an error and the connection stays.

Static files are the page's own and the vendored three.js (``static/vendor/``, MIT, its
licence beside it), which the page loads only when the 3D view is first opened.
"""

from __future__ import annotations

import asyncio
import ipaddress
import secrets
import socket
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from importlib import resources
from typing import Any
from urllib.parse import urlsplit

from starlette.applications import Starlette
from starlette.requests import Request
from starlette.responses import HTMLResponse, RedirectResponse, Response
from starlette.routing import Route, WebSocketRoute
from starlette.websockets import WebSocket, WebSocketDisconnect

from eddiebot.core.context import Context
from eddiebot.core.executors import SingleThreadedExecutor
from eddiebot.viz.dashboard.core import (
    MAX_COMMAND_BYTES,
    TokenBucket,
    parse_command,
    text_frame,
)
from eddiebot.viz.dashboard.errors import CommandError, DashboardBindError, RateLimitedError
from eddiebot.viz.dashboard.hub import Hub
from eddiebot.viz.dashboard.node import DashboardNode

__all__ = ["DashboardConfig", "DashboardHandle", "create_app", "is_loopback", "start_dashboard"]

COOKIE = "eddie_dashboard_session"
_STATIC = {"app.js": "text/javascript", "style.css": "text/css", "index.html": "text/html",
           "view3d.js": "text/javascript", "vendor/three.module.min.js": "text/javascript",
           "vendor/three.LICENSE": "text/plain; charset=utf-8"}
_CSP = ("default-src 'self'; img-src 'self' blob: data:; connect-src 'self'; "
        "style-src 'self'; script-src 'self'; frame-ancestors 'none'; base-uri 'none'")


def is_loopback(host: str) -> bool:
    """True for 127.0.0.0/8, ::1 and ``localhost``."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


@dataclass
class DashboardConfig:
    """Where and how the dashboard serves (``host``/``port`` as uvicorn's)."""

    host: str = "127.0.0.1"
    port: int = 8080
    token: str | None = None
    read_only: bool = False
    #: commands per second (burst) per connection; teleop has its own, higher limit
    command_rate: float = 5.0
    command_burst: float = 10.0
    teleop_rate: float = 25.0
    teleop_burst: float = 25.0

    def __post_init__(self) -> None:
        if self.token is None and not is_loopback(self.host):
            self.token = secrets.token_urlsafe(24)


@dataclass
class _Auth:
    token: str | None
    sessions: set[str] = field(default_factory=set)

    def check_token(self, given: str | None) -> bool:
        return self.token is not None and given is not None and secrets.compare_digest(
            given.encode(), self.token.encode())

    def new_session(self) -> str:
        if len(self.sessions) > 1000:
            self.sessions.clear()
        sid = secrets.token_urlsafe(24)
        self.sessions.add(sid)
        return sid

    def has_session(self, cookies: dict[str, str], query_token: str | None) -> bool:
        if self.token is None:
            return True
        sid = cookies.get(COOKIE)
        return (sid is not None and sid in self.sessions) or self.check_token(query_token)


def _static(name: str) -> bytes:
    path = resources.files("eddiebot.viz.dashboard") / "static"
    for part in name.split("/"):
        path = path / part
    return path.read_bytes()


def create_app(node: DashboardNode, hub: Hub, config: DashboardConfig,
               bound_port: Callable[[], int] | None = None) -> Starlette:
    """The Starlette application serving the page and the WebSocket of ``node``."""
    auth = _Auth(config.token)
    loopback = is_loopback(config.host)
    files: dict[str, bytes] = {}

    def file(name: str) -> bytes:
        if name not in files:  # read on first use: three.js is large and often never asked for
            files[name] = _static(name)
        return files[name]

    def host_ok(host_header: str) -> bool:
        if not loopback:
            return True
        hostname = urlsplit(f"//{host_header}").hostname or ""
        return is_loopback(hostname)

    def security_headers(resp: Response) -> Response:
        resp.headers["Content-Security-Policy"] = _CSP
        resp.headers["X-Content-Type-Options"] = "nosniff"
        resp.headers["Referrer-Policy"] = "no-referrer"
        resp.headers["Cache-Control"] = "no-store"
        return resp

    def refuse(status: int, text: str) -> Response:
        return security_headers(HTMLResponse(
            f"<!doctype html><title>eddie dashboard</title><p>{text}</p>", status_code=status))

    async def index(request: Request) -> Response:
        if not host_ok(request.headers.get("host", "")):
            return refuse(400, "unexpected Host header")
        token = request.query_params.get("token")
        if auth.token is not None:
            if token is not None:
                if not auth.check_token(token):
                    return refuse(401, "wrong token")
                resp = RedirectResponse("/", status_code=303)
                resp.set_cookie(COOKIE, auth.new_session(), httponly=True, samesite="strict")
                return security_headers(resp)
            if not auth.has_session(dict(request.cookies), None):
                return refuse(401, "this dashboard needs its token: open the URL printed by "
                                   "<code>eddie dashboard</code>")
        return security_headers(Response(file("index.html"), media_type="text/html"))

    async def static(request: Request) -> Response:
        name = request.path_params["name"]
        if name not in _STATIC or name == "index.html":
            return refuse(404, "not found")
        if not host_ok(request.headers.get("host", "")):
            return refuse(400, "unexpected Host header")
        if not auth.has_session(dict(request.cookies), None):
            return refuse(401, "no session")
        return security_headers(Response(file(name), media_type=_STATIC[name]))

    async def ws_endpoint(ws: WebSocket) -> None:
        host_header = ws.headers.get("host", "")
        origin = ws.headers.get("origin")
        if not host_ok(host_header):
            await ws.close(code=4400, reason="unexpected Host header")
            return
        if origin is not None and urlsplit(origin).netloc != host_header:
            await ws.close(code=4403, reason="foreign origin")
            return
        if not auth.has_session(dict(ws.cookies), ws.query_params.get("token")):
            await ws.close(code=4401, reason="no valid session")
            return
        await ws.accept()
        await _serve_connection(ws, node, hub, config)

    async def favicon(request: Request) -> Response:
        return Response(status_code=204)

    routes = [
        Route("/", index),
        Route("/favicon.ico", favicon),
        Route("/static/{name:path}", static),
        WebSocketRoute("/ws", ws_endpoint),
    ]
    return Starlette(routes=routes)


async def _serve_connection(ws: WebSocket, node: DashboardNode, hub: Hub,
                            config: DashboardConfig) -> None:
    loop = asyncio.get_running_loop()
    box = hub.attach(loop)
    commands = TokenBucket(config.command_rate, config.command_burst)
    teleops = TokenBucket(config.teleop_rate, config.teleop_burst)
    teleop_active = [False]

    async def send(frame: str | bytes) -> None:
        if isinstance(frame, bytes):
            await ws.send_bytes(frame)
        else:
            await ws.send_text(frame)

    errors = TokenBucket(10.0, 10.0)
    suppressed = [0]

    async def reply_error(op: str | None, text: str) -> None:
        try:
            errors.take(time.monotonic())
        except RateLimitedError:
            suppressed[0] += 1  # a flood: answer at most ten errors a second
            return
        n, suppressed[0] = suppressed[0], 0
        await send(text_frame("error", op=op, msg=text, suppressed=n))

    def reply_threadsafe(frame: str) -> None:
        def go() -> None:
            task = loop.create_task(send(frame))
            task.add_done_callback(lambda t: t.exception() if not t.cancelled() else None)
        loop.call_soon_threadsafe(go)

    async def sender() -> None:
        while True:
            for frame in await box.next_batch():
                await send(frame)

    async def handle(raw: str | bytes) -> None:
        op: str | None = None
        try:
            if len(raw) > MAX_COMMAND_BYTES:
                raise CommandError(f"message of {len(raw)} bytes refused (limit {MAX_COMMAND_BYTES})")
            cmd = parse_command(raw, node.map_bounds())
            op = cmd.op
            if cmd.op == "ping":
                await send(text_frame("pong"))
                return
            if cmd.op == "view":
                commands.take(time.monotonic(), "view")
                opened = hub.set_view(box, cmd.name, bool(cmd.engage))
                node.view_changed(cmd.name, opened)
                await send(text_frame("ack", op=op, msg=f"{cmd.name} view {'opened' if cmd.engage else 'closed'}"))
                return
            if config.read_only:
                raise CommandError(f"{cmd.op} refused: the dashboard is read-only")
            now = time.monotonic()
            if cmd.op == "teleop":
                teleops.take(now, "teleop")
            elif not (cmd.op == "estop" and cmd.engage is not False):
                commands.take(now, cmd.op)  # engaging the e-stop is never rate-limited
            if cmd.op == "teleop":
                node.teleop(cmd.linear, cmd.angular)
                teleop_active[0] = bool(cmd.linear or cmd.angular)
                return
            if cmd.op == "goal":
                via = node.send_goal(cmd.x, cmd.y, cmd.yaw)
                await send(text_frame("ack", op=op, msg=f"goal sent via {via}"))
            elif cmd.op == "initialpose":
                node.set_initial_pose(cmd.x, cmd.y, cmd.yaw)
                await send(text_frame("ack", op=op, msg="initial pose published"))
            elif cmd.op == "estop":
                locked = node.estop(cmd.engage)
                await send(text_frame("ack", op=op, msg="e-stop engaged" if locked else "e-stop released"))
            elif cmd.op == "cancel":
                ok = node.cancel_navigation()
                await send(text_frame("ack", op=op, msg="cancel sent" if ok else "no navigation server"))
            elif cmd.op == "save_map":
                node.save_map(cmd.name, lambda ok, text: reply_threadsafe(
                    text_frame("ack" if ok else "error", op="save_map", msg=text)))
            elif cmd.op == "slam":
                node.slam_command(cmd.action, lambda ok, text: reply_threadsafe(
                    text_frame("ack" if ok else "error", op="slam", action=cmd.action, msg=text)),
                    node=cmd.node, x=cmd.x, y=cmd.y, yaw=cmd.yaw, path=cmd.path)
            elif cmd.op == "explore":
                node.explore_command(cmd.action, lambda ok, text: reply_threadsafe(
                    text_frame("ack" if ok else "error", op="explore", action=cmd.action, msg=text)))
            elif cmd.op == "keepout":
                node.paint_keepout(None if cmd.clear else (cmd.x, cmd.y, cmd.x1, cmd.y1),
                                   lambda ok, text: reply_threadsafe(
                                       text_frame("ack" if ok else "error", op="keepout", msg=text)))
        except CommandError as exc:
            await reply_error(op or exc.op, str(exc))

    await send(text_frame("hello", read_only=config.read_only, footprint=node.footprint_radius,
                          topics={"cmd_vel": node.topics.cmd_vel, "e_stop": node.topics.e_stop}))
    send_task = asyncio.create_task(sender())
    try:
        while True:
            message = await ws.receive()
            if message["type"] == "websocket.disconnect":
                break
            raw = message.get("text")
            if raw is None:
                raw = message.get("bytes") or b""
            await handle(raw)
    except (WebSocketDisconnect, RuntimeError):
        pass
    finally:
        send_task.cancel()
        hub.detach(box)
        if teleop_active[0]:
            node.teleop(0.0, 0.0)


class DashboardHandle:
    """A running dashboard: ``url`` to open, ``stop()`` to end it."""

    def __init__(self, url: str, config: DashboardConfig, node: DashboardNode,
                 server: Any, threads: list[threading.Thread], executor: SingleThreadedExecutor) -> None:
        self.url = url
        self.config = config
        self.node = node
        self._server = server
        self._threads = threads
        self._executor = executor

    @property
    def port(self) -> int:
        return self.config.port

    @property
    def token(self) -> str | None:
        return self.config.token

    def is_alive(self) -> bool:
        """True while the web server and the node's executor both run."""
        return all(t.is_alive() for t in self._threads)

    def stop(self, timeout_s: float = 5.0) -> None:
        """Stop the web server and the node's executor; the context stays up."""
        self._server.should_exit = True
        self._executor.shutdown()
        for t in self._threads:
            t.join(timeout_s)
        self.node.destroy_node()

    def __enter__(self) -> DashboardHandle:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


def _url(host: str, port: int, token: str | None) -> str:
    shown = host
    if host in ("0.0.0.0", "::", ""):
        shown = socket.gethostname()
    elif ":" in host:
        shown = f"[{host}]"
    base = f"http://{shown}:{port}/"
    return f"{base}?token={token}" if token else base


def start_dashboard(context: Context, host: str = "127.0.0.1", port: int = 8080,
                    token: str | None = None, read_only: bool = False, *,
                    print_url: bool = True, ready_timeout_s: float = 10.0) -> DashboardHandle:
    """Serve the dashboard for ``context`` from background threads.

    A ``DashboardNode`` joins ``context`` with its own executor (wall clock; it never
    drives a sim clock). ``port`` 0 picks a free port. Any ``host`` that is not loopback
    gets a random token unless one is given. With ``print_url`` the URL (with the token)
    is printed to stdout. Raises `DashboardBindError` when the address cannot be bound.
    """
    import uvicorn

    config = DashboardConfig(host=host, port=port, token=token, read_only=read_only)
    hub = Hub()
    node = DashboardNode(hub, context=context)
    executor = SingleThreadedExecutor(context=context, drive_sim_time=False)
    executor.add_node(node)
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
    except OSError as exc:
        sock.close()
        node.destroy_node()
        raise DashboardBindError(
            f"cannot serve the dashboard on {host}:{port}: {exc.strerror or exc}") from exc
    config.port = sock.getsockname()[1]
    app = create_app(node, hub, config)
    uv_config = uvicorn.Config(app, log_level="warning", access_log=False, ws_max_size=1 << 20,
                               ws_per_message_deflate=False,
                               ws_ping_interval=20.0, lifespan="off")
    server = uvicorn.Server(uv_config)

    def serve() -> None:
        asyncio.run(server.serve(sockets=[sock]))

    def spin() -> None:
        executor.spin()

    threads = [threading.Thread(target=spin, name="eddie-dashboard-node", daemon=True),
               threading.Thread(target=serve, name="eddie-dashboard-http", daemon=True)]
    for t in threads:
        t.start()
    deadline = time.monotonic() + ready_timeout_s
    while not server.started and time.monotonic() < deadline and threads[1].is_alive():
        time.sleep(0.01)
    url = _url(host, config.port, config.token)
    if print_url:
        print(url, flush=True)
        sys.stdout.flush()
    return DashboardHandle(url, config, node, server, threads, executor)


