"""Dashboard in headless Chromium: offline page load and map drawing, goal by click-and-drag,
keyboard teleop, e-stop, and refusal of a wrong token."""

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
    free = pixel(page, 4.0, -5.0)
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
    last_t, last = cmd[-1]
    assert last.linear.x == 0.0 and last.angular.z == 0.0
    assert not [m for t, m in cmd if t > t1 + 0.2 and m.linear.x != 0.0]
    page.context.close()


def test_estop_publishes_zero_and_locks(browser: Any, world: World, dash: DashboardHandle) -> None:
    cmd = world.record(Twist, "/cmd_vel_teleop")
    lock = world.record(Bool, "/e_stop")
    page = open_page(browser, dash.url)
    page.click("#estop")
    page.wait_for_function("window.eddie.state.estop === true", timeout=5000)
    assert lock and lock[-1][1].data is True
    assert cmd and cmd[-1][1].linear.x == 0.0 and cmd[-1][1].angular.z == 0.0
    assert "ENGAGED" in page.inner_text("#estop")
    page.click("#estop")
    page.wait_for_function("window.eddie.state.estop === false", timeout=5000)
    assert lock[-1][1].data is False
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
