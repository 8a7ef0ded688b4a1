"""The exploration panel in headless Chromium: "Map this floor" resumes a paused explore node,
Pause / Resume toggles it, the known area is shown, and the chart draws the history."""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from typing import Any

import pytest
from test_dashboard_explore import Bus, status

from eddiebot.core import qos_profile_latched
from eddiebot.core.qos import QoSProfile
from eddiebot.msgs.diagnostic_msgs import DiagnosticStatus
from eddiebot.viz.dashboard import DashboardHandle, start_dashboard

CHROMIUM = "/usr/bin/chromium"
pytestmark = pytest.mark.skipif(not os.path.exists(CHROMIUM),
                                reason=f"{CHROMIUM} is absent (Debian package 'chromium')")
ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
        "--disable-component-update", "--disable-sync"]
#: generous: a loaded 2-core runner can take seconds to bring a message to the browser
WAIT_MS = 30000


@pytest.fixture(scope="module")
def browser() -> Iterator[Any]:
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=CHROMIUM, args=ARGS, headless=True)
        yield b
        b.close()


def open_page(browser: Any, dash: DashboardHandle) -> Any:
    ctx = browser.new_context(viewport={"width": 1200, "height": 900})
    page = ctx.new_page()
    page.goto(dash.url)
    page.wait_for_function("() => window.eddie && window.eddie.state.explore", timeout=WAIT_MS)
    return page


def text_is(page: Any, selector: str, text: str) -> None:
    page.wait_for_function("([s, t]) => document.querySelector(s).textContent === t",
                           arg=[selector, text], timeout=WAIT_MS)


def wait_until(pred: Any, timeout_s: float = 30.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while not pred() and time.monotonic() < deadline:
        time.sleep(0.05)
    return bool(pred())


def test_map_this_floor_then_pause_and_resume(browser: Any) -> None:
    bus = Bus(explore=True)
    try:
        node = bus.explore
        assert node is not None and node.paused
        with start_dashboard(bus.context, "127.0.0.1", 0, print_url=False) as dash:
            page = open_page(browser, dash)
            text_is(page, "#explore-known", "50.0 m² known, 30.0 m² free")
            text_is(page, "#explore-state", "paused (waiting)")
            assert page.is_enabled("#explore-start")
            page.click("#explore-start")
            assert wait_until(lambda: not node.paused)
            text_is(page, "#explore-state", "waiting")
            assert page.is_disabled("#explore-start")  # it is mapping already
            assert page.inner_text("#explore-pause") == "Pause"
            page.click("#explore-pause")
            assert wait_until(lambda: node.paused)
            text_is(page, "#explore-pause", "Resume")
            page.click("#explore-pause")
            assert wait_until(lambda: not node.paused)
            text_is(page, "#explore-pause", "Pause")
            page.context.close()
    finally:
        bus.close()


def test_progress_chart_and_a_finished_run(browser: Any) -> None:
    bus = Bus(explore=False)
    try:
        pub = bus.node.create_publisher(DiagnosticStatus, "/explore/status", QoSProfile(
            depth=20, durability=qos_profile_latched.durability))
        with start_dashboard(bus.context, "127.0.0.1", 0, print_url=False) as dash:
            # known area 20 → 50 m² and frontiers 9 → 3 over a minute
            for k in range(7):
                pub.publish(status("exploring", 10.0 * k, 20.0 + 5.0 * k, 9 - k))
            page = open_page(browser, dash)
            text_is(page, "#explore-time", "60 s")
            text_is(page, "#explore-frontiers", "3 left · 4 reached · 1 abandoned")
            text_is(page, "#explore-known", "50.0 m² known, 25.0 m² free")
            # at the right edge (t = 60 s) the known area is at its top (white, y ≈ 2) and
            # the frontiers at a third of theirs (blue, y = 62 - 60/3 = 42)
            px = page.evaluate("""() => {
                const c = document.getElementById('explore-chart');
                const d = c.getContext('2d').getImageData(c.width - 5, 0, 3, c.height).data;
                const rows = [];
                for (let y = 0; y < c.height; y++) rows.push(Array.from(d.slice(y * 12, y * 12 + 4)));
                return rows; }""")
            white = [y for y, (r, g, b, a) in enumerate(px) if a > 150 and min(r, g, b) > 200]
            blue = [y for y, (r, g, b, a) in enumerate(px) if a > 150 and b > 200 and r < 160]
            assert white and min(white) <= 4 and max(white) <= 6
            assert blue and min(blue) >= 38 and max(blue) <= 46
            pub.publish(status("done", 75.0, 52.0, 0, reason="no reachable frontier left",
                               returned_home="false"))
            text_is(page, "#explore-state", "done")
            assert page.is_disabled("#explore-start") and page.is_disabled("#explore-pause")
            page.context.close()
    finally:
        bus.close()


def test_frontiers_drawn_on_the_map(browser: Any) -> None:
    from eddiebot.core.tf import make_transform_2d
    from eddiebot.msgs.geometry_msgs import Point
    from eddiebot.msgs.tf2_msgs import TFMessage
    from eddiebot.msgs.visualization_msgs import Marker, MarkerArray

    bus = Bus(explore=False)
    try:
        tf_pub = bus.node.create_publisher(TFMessage, "/tf", 100)

        def tick() -> None:
            now = bus.node.get_clock().now().nanoseconds
            tf_pub.publish(TFMessage(transforms=[
                make_transform_2d("map", "odom", now, 0.0, 0.0, 0.0),
                make_transform_2d("odom", "base_footprint", now, 1.0, 2.0, 0.5)]))

        bus.node.create_timer(0.05, tick)
        row = Marker(ns="frontiers", id=0, type=Marker.POINTS, action=Marker.ADD)
        row.header.frame_id = "map"
        row.pose.orientation.w = 1.0
        row.color.b, row.color.a = 1.0, 1.0
        row.points = [Point(x=3.3, y=1.0 + 0.05 * k, z=0.0) for k in range(20)]  # x = 3.3, y 1..2
        dot = Marker(ns="frontiers", id=1, type=Marker.SPHERE, action=Marker.ADD)
        dot.header.frame_id = "map"
        dot.pose.position.x, dot.pose.position.y = 2.3, 3.3
        dot.pose.orientation.w = 1.0
        pub = bus.node.create_publisher(MarkerArray, "/explore/frontiers", 10)
        with start_dashboard(bus.context, "127.0.0.1", 0, print_url=False) as dash:
            ctx = browser.new_context(viewport={"width": 1200, "height": 900})
            page = ctx.new_page()
            page.goto(dash.url)
            page.wait_for_function("() => window.eddie && window.eddie.state.pose && "
                                   "window.eddie.state.tilesDrawn >= 8", timeout=WAIT_MS)
            pub.publish(MarkerArray(markers=[row, dot]))
            page.wait_for_function("() => window.eddie.state.frontiers && "
                                   "window.eddie.state.frontiers.open.length === 40", timeout=WAIT_MS)

            def pixel(x: float, y: float) -> list[int]:
                page.evaluate("() => new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))")
                return list(page.evaluate(
                    """([x, y]) => { const [sx, sy] = window.eddie.worldToScreen(x, y);
                         const c = document.getElementById('view');
                         return Array.from(c.getContext('2d').getImageData(Math.round(sx), Math.round(sy), 1, 1).data); }""",
                    [x, y]))

            # off the metric grid's lines (every metre)
            blue, green, free = pixel(3.3, 1.5), pixel(2.3, 3.3), pixel(2.3, 1.3)
            assert blue[2] > 200 and blue[0] < 100, blue
            assert green[1] > 200 and green[0] < 100 and green[2] < 100, green
            assert min(free[:3]) > 230, free  # the free map where no frontier is
            page.uncheck("#show-frontiers")
            assert min(pixel(2.3, 3.3)[:3]) > 230
            ctx.close()
    finally:
        bus.close()
