"""The dashboard's keepout paint tool in headless Chromium: a rectangle dragged on the map
reaches ``/keepout_filter_mask`` through the keepout mask server, "Clear keepout" empties it,
a read-only page cannot paint, and without a mask server the page says so."""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from test_dashboard_browser import CHROMIUM, World, browser, client_xy, open_page, wait_js
from websockets.sync.client import connect

from eddiebot.core import SingleThreadedExecutor
from eddiebot.maps import OccupancyMap, map_from_msg, save_map
from eddiebot.msgs.nav_msgs import OccupancyGrid
from eddiebot.nav.nodes.costmap_filters import FilterMaskServer
from eddiebot.viz.dashboard import start_dashboard

pytestmark = pytest.mark.skipif(not Path(CHROMIUM).exists(),
                                reason=f"{CHROMIUM} is absent (Debian package 'chromium')")
__all__ = ["browser"]  # the module-scoped Chromium fixture, shared


class MaskServer:
    """``keepout_filter_mask_server`` with an empty mask shaped as the World's map."""

    def __init__(self, world: World, tmp_path: Path) -> None:
        empty = OccupancyMap(np.zeros((300, 400), np.int8), 0.05, (-10.0, -7.5, 0.0), "map")
        path = save_map(empty, tmp_path / "empty_keepout")
        self.node = FilterMaskServer("keepout_filter_mask_server", context=world.context,
                                     parameter_overrides={"yaml_filename": str(path),
                                                          "topic_name": "/keepout_filter_mask"})
        self.node.trigger_configure()
        self.node.trigger_activate()
        self.executor = SingleThreadedExecutor(context=world.context)
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()

    def close(self) -> None:
        self.executor.shutdown()
        self.thread.join(5)


@pytest.fixture
def world() -> Iterator[World]:
    w = World()
    yield w
    w.close()


def _masks(world: World) -> list[OccupancyMap]:
    return [map_from_msg(m) for _, m in list(world.masks)]


def _wait(pred: Any, timeout: float = 5.0) -> bool:
    deadline = time.monotonic() + timeout
    while not pred() and time.monotonic() < deadline:
        time.sleep(0.02)
    return bool(pred())


def _drag(page: Any, a: tuple[float, float], b: tuple[float, float]) -> None:
    x0, y0 = client_xy(page, *a)
    x1, y1 = client_xy(page, *b)
    page.mouse.move(x0, y0)
    page.mouse.down()
    page.mouse.move((x0 + x1) / 2, (y0 + y1) / 2)
    page.mouse.move(x1, y1)
    page.mouse.up()


def test_paint_and_clear_a_keepout_zone(browser: Any, world: World, tmp_path: Path) -> None:
    server = MaskServer(world, tmp_path)
    world.masks = world.record(OccupancyGrid, "/keepout_filter_mask")
    try:
        with start_dashboard(world.context, "127.0.0.1", 0, token="paint-token",
                             print_url=False) as dash:
            page = open_page(browser, dash.url)
            page.click("#mode-keepout")
            _drag(page, (2.0, -3.0), (4.0, -1.0))
            assert _wait(lambda: any((m.data == 100).any() for m in _masks(world)))
            mask = next(m for m in _masks(world) if (m.data == 100).any())
            jj, ii = np.nonzero(mask.data == 100)
            xs, ys = -10.0 + (ii + 0.5) * 0.05, -7.5 + (jj + 0.5) * 0.05
            # a 2 m x 2 m square at 0.05 m: 40 x 40 cells, give or take a pixel at each edge
            assert 38 * 38 <= len(ii) <= 42 * 42, len(ii)
            assert xs.min() > 1.9 and xs.max() < 4.1 and ys.min() > -3.1 and ys.max() < -0.9
            assert (mask.width, mask.height, mask.resolution) == (400, 300, 0.05)
            wait_js(page, "window.eddie.state.lastAck && window.eddie.state.lastAck.op === 'keepout'")
            assert "cells kept out" in page.evaluate("window.eddie.state.lastAck.msg")
            # a second zone adds to the first
            page.click("#mode-keepout")
            _drag(page, (-8.0, 4.0), (-7.0, 5.0))
            assert _wait(lambda: int((_masks(world)[-1].data == 100).sum()) > len(ii) + 300)
            page.click("#clear-keepout")
            assert _wait(lambda: len(_masks(world)) >= 3 and not (_masks(world)[-1].data == 100).any())
            page.context.close()
    finally:
        server.close()


def test_read_only_page_cannot_paint(browser: Any, world: World, tmp_path: Path) -> None:
    server = MaskServer(world, tmp_path)
    world.masks = world.record(OccupancyGrid, "/keepout_filter_mask")
    try:
        with start_dashboard(world.context, "127.0.0.1", 0, read_only=True, print_url=False) as d:
            page = open_page(browser, d.url)
            # the page hides its controls, the paint tool with them
            assert not page.is_visible("#mode-keepout") and not page.is_visible("#clear-keepout")
            page.context.close()
            # a script talking to the socket directly is refused as well
            url = d.url.split("?")[0].replace("http://", "ws://") + "ws"
            with connect(url, origin=d.url.split("?")[0].rstrip("/")) as ws:
                ws.send(json.dumps({"op": "keepout", "x0": 2, "y0": -3, "x1": 4, "y1": -1}))
                deadline = time.monotonic() + 3
                reply: dict[str, Any] = {}
                while time.monotonic() < deadline:
                    frame = ws.recv(timeout=3)
                    if isinstance(frame, str) and json.loads(frame)["t"] == "error":
                        reply = json.loads(frame)
                        break
            assert reply.get("op") == "keepout" and "read-only" in reply["msg"]
        assert not [m for m in _masks(world) if (m.data == 100).any()]
    finally:
        server.close()


def test_without_a_mask_server_the_page_says_so(browser: Any, world: World) -> None:
    with start_dashboard(world.context, "127.0.0.1", 0, print_url=False) as dash:
        page = open_page(browser, dash.url)
        page.click("#mode-keepout")
        _drag(page, (2.0, -3.0), (4.0, -1.0))
        wait_js(page, "window.eddie.state.lastError && window.eddie.state.lastError.op === 'keepout'")
        text = page.evaluate("window.eddie.state.lastError.msg")
        assert "no keepout mask server" in text and "/keepout_filter_mask_server/load_map" in text
        page.context.close()
