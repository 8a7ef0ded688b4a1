"""The keepout command as the dashboard validates it: a rectangle with area on the map, or
a clear."""

from __future__ import annotations

import json

import pytest

from eddiebot.viz.dashboard.core import parse_command
from eddiebot.viz.dashboard.errors import CommandError

BOUNDS = (-10.0, -7.5, 10.0, 7.5)


def _cmd(**obj: object) -> str:
    return json.dumps({"op": "keepout", **obj})


def test_rectangle_and_clear() -> None:
    c = parse_command(_cmd(x0=4.0, y0=-1.0, x1=2.0, y1=-3.0), BOUNDS)
    assert (c.op, c.x, c.y, c.x1, c.y1, c.clear) == ("keepout", 4.0, -1.0, 2.0, -3.0, False)
    # partly off the map is fine: the cells on it are painted
    assert parse_command(_cmd(x0=9.0, y0=0.0, x1=12.0, y1=1.0), BOUNDS).x1 == 12.0
    assert parse_command(_cmd(clear=True), BOUNDS).clear is True


@pytest.mark.parametrize(("obj", "words"), [
    ({"x0": 1.0, "y0": 1.0, "x1": 1.0, "y1": 2.0}, "no area"),
    ({"x0": 11.0, "y0": 0.0, "x1": 12.0, "y1": 1.0}, "outside the map"),
    ({"x0": "1", "y0": 0.0, "x1": 2.0, "y1": 1.0}, "'x0' must be a number"),
    ({"x0": 0.0, "y0": 0.0, "x1": float("inf"), "y1": 1.0}, "'x1' must be finite"),
    ({"y0": 0.0, "x1": 2.0, "y1": 1.0}, "'x0' must be a number"),
    ({"clear": "yes"}, "'clear' must be true or false"),
])
def test_bad_rectangles_are_refused(obj: dict, words: str) -> None:
    with pytest.raises(CommandError) as exc:
        parse_command(json.dumps({"op": "keepout", **obj}).replace("Infinity", "1e999"), BOUNDS)
    assert words in str(exc.value) and exc.value.op == "keepout"
