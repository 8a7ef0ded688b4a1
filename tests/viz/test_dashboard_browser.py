"""Dashboard in headless Chromium: offline page load and map drawing, goal by click-and-drag,
keyboard teleop, e-stop, refusal of a wrong token, and each layer: metric grid, scale bar and
cursor readout, footprint from the URDF, TF frames, AMCL particles, plans and lookahead,
costmaps and the legend, /rosout, the velocity mux's source, the vSLAM graph, the 3D cloud."""

from __future__ import annotations

import math
import os
import time
from collections.abc import Iterator
from typing import Any

import pytest

from eddiebot.core import Context, Node, SingleThreadedExecutor, qos_profile_latched
from eddiebot.core.tf import make_transform_2d
from eddiebot.maps import OccupancyMap, map_to_msg
from eddiebot.msgs.geometry_msgs import PoseStamped, Twist
from eddiebot.msgs.nav_msgs import OccupancyGrid
from eddiebot.msgs.std_msgs import Bool
from eddiebot.msgs.tf2_msgs import TFMessage
from eddiebot.viz.dashboard import DashboardHandle, start_dashboard

CHROMIUM = "/usr/bin/chromium"
pytestmark = pytest.mark.skipif(not os.path.exists(CHROMIUM),
                                reason=f"{CHROMIUM} is absent (Debian package 'chromium')")
ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
        "--disable-component-update", "--disable-sync"]


class World:
    def __init__(self) -> None:
        import threading

        import numpy as np

        self.context = Context()
        self.node = Node("browser_test_pub", context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()
        self.lock = threading.Lock()
        cells = np.zeros((300, 400), np.int8)  # 20 x 15 m at 0.05 m
        cells[:, :40] = -1
        cells[100:140, 100:160] = 100  # a wall block around x = -4.5 .. -2, y = -2.5 .. -0.5
        grid = OccupancyMap(data=cells, resolution=0.05, origin=(-10.0, -7.5, 0.0))
        self.node.create_publisher(OccupancyGrid, "/map", qos_profile_latched).publish(
            map_to_msg(grid, frame_id="map"))
        tf_pub = self.node.create_publisher(TFMessage, "/tf", 100)

        def tick() -> None:
            now = self.node.get_clock().now().nanoseconds
            tf_pub.publish(TFMessage(transforms=[
                make_transform_2d("map", "odom", now, 0.0, 0.0, 0.0),
                make_transform_2d("odom", "base_footprint", now, 1.0, 2.0, 0.5)]))

        tick()
        self.node.create_timer(0.05, tick)

    def record(self, cls: Any, topic: str) -> list[tuple[float, Any]]:
        out: list[tuple[float, Any]] = []
        self.node.create_subscription(cls, topic, lambda m: out.append((time.monotonic(), m)), 100)
        return out

    def close(self) -> None:
        self.executor.shutdown()
        self.context.shutdown()
        self.thread.join(5)


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=ARGS, headless=True)
        yield b
        b.close()


@pytest.fixture
def world() -> Iterator[World]:
    w = World()
    yield w
    w.close()


@pytest.fixture
def dash(world: World) -> Iterator[DashboardHandle]:
    with start_dashboard(world.context, "127.0.0.1", 0, print_url=False) as handle:
        yield handle


def open_page(browser: Any, url: str) -> Any:
    ctx = browser.new_context(viewport={"width": 1200, "height": 800}, bypass_csp=True)
    page = ctx.new_page()
    outside: list[str] = []
    page.on("request", lambda r: outside.append(r.url) if not r.url.startswith(url.split("?")[0]) else None)
    page.goto(url)
    page.wait_for_function("() => window.eddie && window.eddie.state.tilesDrawn >= 35 && !!window.eddie.state.pose",
                           timeout=10000)
    page.evaluate("() => new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))")
    page.outside_requests = outside
    return page


def pixel(page: Any, x: float, y: float) -> list[int]:
    return list(page.evaluate(
        """([x, y]) => { const [sx, sy] = window.eddie.worldToScreen(x, y);
             const c = document.getElementById('view');
             return Array.from(c.getContext('2d').getImageData(Math.round(sx), Math.round(sy), 1, 1).data); }""",
        [x, y]))


def settled_pixel(page: Any, x: float, y: float, ok: Any, wait_s: float = 10.0) -> list[int]:
    """`pixel` once `ok(pixel)` holds, or the last one read after `wait_s` (a loaded machine
    may not have drawn the newest state within two animation frames)."""
    deadline = time.monotonic() + wait_s
    color = pixel(page, x, y)
    while not ok(color) and time.monotonic() < deadline:
        page.wait_for_timeout(100)
        color = pixel(page, x, y)
    return color


def client_xy(page: Any, x: float, y: float) -> tuple[float, float]:
    sx, sy, left, top = page.evaluate(
        """([x, y]) => { const [sx, sy] = window.eddie.worldToScreen(x, y);
             const r = document.getElementById('view').getBoundingClientRect();
             return [sx, sy, r.left, r.top]; }""", [x, y])
    return left + sx, top + sy


def test_page_loads_offline_and_draws_the_map(browser: Any, dash: DashboardHandle) -> None:
    page = open_page(browser, dash.url)
    assert page.outside_requests == []  # nothing but the dashboard itself
    occupied = pixel(page, -3.0, -1.5)
    free = pixel(page, 4.5, -4.5)  # off the metric grid's lines
    unknown = pixel(page, -9.5, 5.0)
    assert max(occupied[:3]) < 40, occupied
    assert min(free[:3]) > 230, free
    assert all(100 < v < 160 for v in unknown[:3]), unknown
    robot = pixel(page, 1.0 - 0.15 * math.sin(0.5), 2.0 + 0.15 * math.cos(0.5))
    assert robot[2] > robot[0] + 40, robot  # the blue footprint
    page.context.close()


def test_goal_by_click_and_drag(browser: Any, world: World, dash: DashboardHandle) -> None:
    goals = world.record(PoseStamped, "/goal_pose")
    page = open_page(browser, dash.url)
    page.click("#mode-goal")
    gx, gy, yaw = 3.0, -2.0, math.radians(40)
    x0, y0 = client_xy(page, gx, gy)
    x1, y1 = client_xy(page, gx + 1.5 * math.cos(yaw), gy + 1.5 * math.sin(yaw))
    page.mouse.move(x0, y0)
    page.mouse.down()
    page.mouse.move((x0 + x1) / 2, (y0 + y1) / 2)
    page.mouse.move(x1, y1)
    page.mouse.up()
    deadline = time.monotonic() + 5
    while not goals and time.monotonic() < deadline:
        time.sleep(0.02)
    assert len(goals) == 1
    p = goals[0][1].pose
    got_yaw = 2 * math.atan2(p.orientation.z, p.orientation.w)
    assert math.hypot(p.position.x - gx, p.position.y - gy) < 0.05
    assert abs(math.remainder(got_yaw - yaw, 2 * math.pi)) < math.radians(5)
    page.context.close()


def test_held_keys_teleop_then_stop(browser: Any, world: World, dash: DashboardHandle) -> None:
    cmd = world.record(Twist, "/cmd_vel_teleop")
    page = open_page(browser, dash.url)
    page.click("#view")
    page.keyboard.down("ArrowUp")
    t0 = time.monotonic()
    time.sleep(1.0)
    page.keyboard.up("ArrowUp")
    t1 = time.monotonic()
    time.sleep(0.4)
    moving = [(t, m) for t, m in cmd if m.linear.x > 0 and t0 <= t <= t1 + 0.05]
    assert len(moving) >= 8, len(moving)
    span = moving[-1][0] - moving[0][0]
    assert (len(moving) - 1) / span >= 8.0
    assert until(lambda: cmd[-1][1].linear.x == 0.0 and cmd[-1][1].angular.z == 0.0)
    assert not [m for t, m in cmd if t > t1 + 0.2 and m.linear.x != 0.0]
    page.context.close()


def test_estop_publishes_zero_and_locks(browser: Any, world: World, dash: DashboardHandle) -> None:
    cmd = world.record(Twist, "/cmd_vel_teleop")
    lock = world.record(Bool, "/e_stop")
    page = open_page(browser, dash.url)
    page.click("#estop")
    page.wait_for_function("window.eddie.state.estop === true", timeout=5000)
    # the server published before it told the page; the world's executor thread may not
    # have run the recording callbacks yet on a loaded runner
    assert until(lambda: bool(lock) and lock[-1][1].data is True)
    assert until(lambda: bool(cmd)) and cmd[-1][1].linear.x == 0.0 and cmd[-1][1].angular.z == 0.0
    assert "ENGAGED" in page.inner_text("#estop")
    page.click("#estop")
    page.wait_for_function("window.eddie.state.estop === false", timeout=5000)
    assert until(lambda: lock[-1][1].data is False)
    page.context.close()


def test_wrong_token_and_foreign_origin_refused(browser: Any, world: World) -> None:
    with start_dashboard(world.context, "127.0.0.1", 0, token="right-token", print_url=False) as d:
        ctx = browser.new_context(bypass_csp=True)
        page = ctx.new_page()
        resp = page.goto(d.url.replace("right-token", "wrong-token"))
        assert resp.status == 401
        resp = page.goto(d.url)
        assert resp.status == 200  # token exchanged for a cookie, then the page
        page.wait_for_function("window.eddie && window.eddie.state.connected", timeout=5000)
        # a page from another origin cannot open the dashboard's WebSocket
        ws_url = d.url.split("?")[0].replace("http://", "ws://") + "ws"
        page.goto("data:text/html,<title>other</title>")
        state = page.evaluate("""(u) => new Promise(r => { const w = new WebSocket(u);
            w.onopen = () => r('open'); w.onerror = () => r('refused'); })""", ws_url)
        assert state == "refused"
        ctx.close()


# -- layers ------------------------------------------------------------------------------
def publish(world: World, cls: Any, topic: str, msg: Any, qos: Any = 10) -> Any:
    pub = world.node.create_publisher(cls, topic, qos)
    pub.publish(msg)
    return pub


def until(cond: Any, timeout: float = 5.0) -> bool:
    """True once ``cond()`` holds (it reads what the world's executor thread records), False
    after ``timeout`` s."""
    deadline = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.02)
    return True


def wait_js(page: Any, expr: str, timeout: int = 20000) -> None:
    """Wait until `expr` holds in the page; generous, as a loaded 2-core runner can take seconds
    to deliver a message through the dashboard to the browser."""
    page.wait_for_function(expr, timeout=timeout)


def test_grid_scale_bar_and_cursor_readout(browser: Any, dash: DashboardHandle) -> None:
    page = open_page(browser, dash.url)
    page.uncheck("#follow")
    x, y = client_xy(page, 3.0, -2.0)
    page.mouse.move(x, y)
    wait_js(page, "document.getElementById('cursor').textContent.includes('(map)')")
    assert page.inner_text("#cursor") == "3.00, -2.00 m (map)"
    scale = page.evaluate("window.eddie.state.view.scale")
    step = page.evaluate("window.eddie.state.drawn.gridStep")
    assert step == 2  # 40 px/m: the first of 1, 2, 5 m at least 60 px apart
    px, metres = page.inner_text("#scale").split(" px = ")
    assert metres == "2 m" and abs(float(px) - 2 * scale) < 1.0
    on_line, off_line = pixel(page, 4.0, -4.5), pixel(page, 4.5, -4.5)
    assert off_line[:3] == [255, 255, 255], off_line
    assert on_line[0] < 240 and on_line[2] > on_line[0] + 20, on_line  # a bluish grid line
    page.context.close()


def test_legend_lists_the_layers_and_costmap_overlay(browser: Any, world: World,
                                                     dash: DashboardHandle) -> None:
    import numpy as np

    cells = np.zeros((60, 60), np.int8)  # 3 x 3 m around (1, 2) in odom
    cells[10:20, 10:20] = 100
    cells[30:40, 30:40] = 99
    publish(world, OccupancyGrid, "/local_costmap/costmap", map_to_msg(
        OccupancyMap(data=cells, resolution=0.05, origin=(-0.5, 0.5, 0.0)), frame_id="odom"),
        qos_profile_latched)
    page = open_page(browser, dash.url)
    wait_js(page, "window.eddie.state.grids.local_costmap && window.eddie.state.tilesDrawn >= 36")
    page.evaluate("() => new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))")
    rows = page.eval_on_selector_all(".legend-row", "els => els.map(e => e.textContent)")
    names = [r.split("\n")[0] for r in rows]
    for want in ("map (/map)", "vSLAM map", "global costmap", "local costmap", "metric grid",
                 "laser scan", "AMCL particles", "plans", "footprint", "vSLAM graph", "TF frames"):
        assert any(r.startswith(want) for r in names), (want, names)
    costs = next(r for r in names if r.startswith("local costmap"))
    assert "lethal" in costs and "inscribed" in costs
    lethal = pixel(page, -0.5 + 0.75, 0.5 + 0.75)
    inscribed = pixel(page, -0.5 + 1.75, 0.5 + 1.75)
    assert lethal[0] > 200 and lethal[2] > 200 and lethal[1] < 120, lethal  # magenta
    assert inscribed[1] > 200 and inscribed[2] > 200 and inscribed[0] < 120, inscribed  # cyan
    page.uncheck("#show-local_costmap")
    page.evaluate("() => new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))")
    assert min(pixel(page, -0.5 + 0.75, 0.5 + 0.75)[:3]) > 230  # the free map below
    page.context.close()


def test_particles_drawn_match_the_cloud(browser: Any, world: World, dash: DashboardHandle) -> None:
    from eddiebot.msgs.geometry_msgs import Point, Pose, Quaternion
    from eddiebot.msgs.nav2_msgs import Particle, ParticleCloud
    from eddiebot.msgs.std_msgs import Header

    page = open_page(browser, dash.url)
    parts = [Particle(pose=Pose(position=Point(x=-6.0 + 0.01 * i, y=4.0, z=0.0),
                                orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)),
                      weight=1.0 / 345) for i in range(345)]
    publish(world, ParticleCloud, "/particle_cloud",
            ParticleCloud(header=Header(frame_id="map"), particles=parts))
    wait_js(page, "window.eddie.state.drawn.particles === 345")
    assert page.evaluate("window.eddie.state.particles.head.total") == 345
    teal = pixel(page, -5.0, 4.0)
    assert teal[1] > 180 and teal[2] > 120 and teal[0] < 120, teal
    page.context.close()


def test_plans_lookahead_and_footprint(browser: Any, world: World, dash: DashboardHandle) -> None:
    from eddiebot.msgs.geometry_msgs import Point32, PointStamped, PolygonStamped
    from eddiebot.msgs.nav_msgs import Path
    from eddiebot.msgs.std_msgs import Header, String

    def path(pts: list[tuple[float, float]]) -> Any:
        poses = []
        for x, y in pts:
            ps = PoseStamped(header=Header(frame_id="map"))
            ps.pose.position.x, ps.pose.position.y = x, y
            poses.append(ps)
        return Path(header=Header(frame_id="map"), poses=poses)

    publish(world, Path, "/plan", path([(1.0, 2.0), (1.0, -4.0), (6.0, -4.0)]))
    publish(world, Path, "/local_plan", path([(1.0, 2.0), (1.0, 0.5)]))
    la = PointStamped(header=Header(frame_id="map"))
    la.point.x, la.point.y = 1.0, 0.5
    publish(world, PointStamped, "/lookahead_point", la)
    poly = PolygonStamped(header=Header(frame_id="odom"))
    poly.polygon.points = [Point32(x=1.0 + 0.3 * math.cos(a), y=2.0 + 0.3 * math.sin(a), z=0.0)
                           for a in [k * math.pi / 4 for k in range(8)]]
    publish(world, PolygonStamped, "/local_costmap/published_footprint", poly)
    urdf = ('<robot name="r"><link name="base_link"><collision><geometry>'
            '<cylinder radius="0.31" length="0.1"/></geometry></collision></link></robot>')
    publish(world, String, "/robot_description", String(data=urdf), qos_profile_latched)
    page = open_page(browser, dash.url)
    # published before the dashboard knew map → odom: placed once TF arrives
    wait_js(page, "window.eddie.state.lookahead && window.eddie.state.paths.plan "
                  "&& window.eddie.state.footprint === 0.31 && window.eddie.state.footprintPoly")
    assert page.evaluate("window.eddie.state.paths.plan.length") == 3
    page.uncheck("#follow")
    page.evaluate("() => { window.eddie.state.view.cx = 2; window.eddie.state.view.cy = -1; }")
    page.evaluate("() => new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))")
    green = settled_pixel(page, 3.5, -4.0, lambda c: c[1] > 150 and c[0] < 120)  # global path
    assert green[1] > 150 and green[0] < 120, green
    ring = pixel(page, 1.0 + 6 / 40, 0.5)  # the lookahead's ring, 6 px around it
    assert ring[0] > 200 and ring[1] > 200 and ring[2] < 150, ring
    inside = pixel(page, 1.0 + 0.28 * math.cos(2.0), 2.0 + 0.28 * math.sin(2.0))
    assert inside[2] > inside[0] + 40, inside  # the URDF's 0.31 m disc reaches 0.28 m
    page.context.close()


def test_tf_frames_on_request_read_only(browser: Any, world: World) -> None:
    with start_dashboard(world.context, "127.0.0.1", 0, read_only=True, print_url=False) as d:
        page = open_page(browser, d.url)
        assert page.evaluate("window.eddie.state.tf") is None  # nothing until asked
        page.check("#show-tf")
        wait_js(page, "window.eddie.state.drawn.tfFrames >= 3")
        frames = {f[0]: f[1:] for f in page.evaluate("window.eddie.state.tf")}
        assert frames["base_footprint"][:2] == [1.0, 2.0] and abs(frames["base_footprint"][2] - 0.5) < 1e-3
        assert set(frames) >= {"map", "odom", "base_footprint"}
        page.context.close()


def test_log_pane_shows_rosout(browser: Any, world: World, dash: DashboardHandle) -> None:
    from eddiebot.core.clock_node import ROSOUT_QOS
    from eddiebot.msgs.rcl_interfaces import Log

    page = open_page(browser, dash.url)
    pub = world.node.create_publisher(Log, "/rosout", ROSOUT_QOS)
    pub.publish(Log(level=30, name="amcl", msg="particle filter diverged at 3.2 m"))
    pub.publish(Log(level=10, name="amcl", msg="a debug line"))
    wait_js(page, "document.getElementById('log').textContent.includes('diverged')")
    assert "[WARN] [amcl] particle filter diverged at 3.2 m" in page.inner_text("#log")
    assert "debug line" not in page.inner_text("#log")  # below the shown level
    page.select_option("#log-level", "10")
    assert "[DEBUG] [amcl] a debug line" in page.inner_text("#log")
    page.context.close()


def test_mux_active_source(browser: Any, world: World, dash: DashboardHandle) -> None:
    page = open_page(browser, dash.url)
    nav = world.node.create_publisher(Twist, "/cmd_vel_safe", 10)
    timer = world.node.create_timer(0.05, lambda: nav.publish(Twist()))
    wait_js(page, "document.getElementById('mux').textContent === 'navigation (/cmd_vel_safe)'")
    teleop = world.node.create_publisher(Twist, "/cmd_vel_teleop", 10)
    timer2 = world.node.create_timer(0.05, lambda: teleop.publish(Twist()))
    wait_js(page, "document.getElementById('mux').textContent === 'teleop (/cmd_vel_teleop)'")
    world.node.destroy_timer(timer2)
    wait_js(page, "document.getElementById('mux').textContent === 'navigation (/cmd_vel_safe)'")
    publish(world, Bool, "/e_stop", Bool(data=True))
    wait_js(page, "document.getElementById('mux').textContent === 'none: locked by e_stop'")
    world.node.destroy_timer(timer)
    page.context.close()


def test_vslam_graph_and_loop_closures(browser: Any, world: World, dash: DashboardHandle) -> None:
    from eddiebot.msgs.geometry_msgs import Point
    from eddiebot.msgs.std_msgs import Header
    from eddiebot.msgs.visualization_msgs import Marker, MarkerArray

    def marker(ns: str, kind: int, pts: list[tuple[float, float]], rgb: tuple[float, float, float]) -> Any:
        m = Marker(header=Header(frame_id="map"), ns=ns, id=0, type=kind, action=Marker.ADD)
        m.pose.orientation.w = 1.0
        m.color.r, m.color.g, m.color.b, m.color.a = (*rgb, 1.0)
        m.points = [Point(x=x, y=y, z=0.0) for x, y in pts]
        return m

    nodes = [(-6.0, 5.0), (-4.0, 5.0), (-2.0, 5.0), (-2.0, 6.5), (-6.0, 6.5)]
    links = [p for a, b in zip(nodes, nodes[1:], strict=False) for p in (a, b)]
    publish(world, MarkerArray, "/rtabmap/mapGraph", MarkerArray(markers=[
        marker("rtabmap_nodes", Marker.SPHERE_LIST, nodes, (1.0, 0.5, 0.0)),
        marker("rtabmap_neighbor_links", Marker.LINE_LIST, links, (0.0, 0.6, 1.0)),
        marker("rtabmap_loop_links", Marker.LINE_LIST, [nodes[4], nodes[0]], (1.0, 0.0, 0.0))]),
        qos_profile_latched)
    page = open_page(browser, dash.url)
    wait_js(page, "window.eddie.state.drawn.graphNodes === 5 && window.eddie.state.drawn.loops === 1")
    assert page.inner_text("#graph-count") == "5 nodes, 1 loop closures"
    loop = pixel(page, -6.0, 5.75)
    assert loop[0] > 200 and loop[1] < 80 and loop[2] < 80, loop
    page.context.close()


def test_3d_view_draws_the_cloud_on_demand(browser: Any, world: World, dash: DashboardHandle) -> None:
    import numpy as np

    from eddiebot.msgs.sensor_msgs import PointCloud2, PointField
    from eddiebot.msgs.std_msgs import Header

    n = 1234
    rng = np.random.default_rng(0)
    pts = np.zeros((n, 4), np.float32)
    pts[:, :3] = rng.uniform(-3, 3, (n, 3))
    pts[:, 3] = np.full(n, (200 << 16) | (30 << 8) | 30, np.uint32).view(np.float32)
    fields = [PointField(name=k, offset=4 * i, datatype=PointField.FLOAT32, count=1)
              for i, k in enumerate(("x", "y", "z", "rgb"))]
    publish(world, PointCloud2, "/rtabmap/cloud_map", PointCloud2(
        header=Header(frame_id="map"), height=1, width=n, fields=fields, is_bigendian=False,
        point_step=16, row_step=16 * n, data=pts.view(np.uint8).reshape(-1), is_dense=True),
        qos_profile_latched)
    page = open_page(browser, dash.url)
    time.sleep(0.5)
    assert page.evaluate("Object.keys(window.eddie.state.clouds).length") == 0  # closed: nothing sent
    page.click("#open-3d")
    wait_js(page, "window.eddie.state.view3d && window.eddie.state.view3d.drawn() === 1234", 10000)
    assert page.evaluate("window.eddie.state.view3d.error()") is None
    assert page.outside_requests == []  # three.js came from the dashboard
    page.click("#open-3d")
    assert page.evaluate("window.eddie.state.view3d") is None
    page.context.close()
