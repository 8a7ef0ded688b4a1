"""World files: built-ins load, errors name file/line/object/field, nav2 map import."""

from __future__ import annotations

import numpy as np
import pytest

from eddiebot.maps import OccupancyMap, save_map
from eddiebot.sim import WorldFileError, list_worlds, load_world, load_world_file
from eddiebot.sim.worlds import preview_path

BUILT_IN = ["corridor", "depot", "house", "maze", "office", "warehouse"]


def test_built_in_worlds_load_with_previews():
    assert list_worlds() == BUILT_IN
    for name in BUILT_IN:
        w = load_world(name)
        assert w.name == name
        assert len(w.prisms) > 5
        assert preview_path(name).stat().st_size > 500
        assert not w.overlapping(w.start[0], w.start[1])


def test_sizes_as_documented():
    def size(name):
        x0, y0, x1, y1 = load_world(name).bounds
        return x1 - x0, y1 - y0

    assert size("office") == pytest.approx((20.2, 15.2), abs=0.3)
    assert size("warehouse") == pytest.approx((30.25, 20.25), abs=0.3)
    w, h = size("corridor")
    assert w > 35 and h < 3


def _write(tmp_path, text):
    p = tmp_path / "bad.yaml"
    p.write_text(text)
    return p


def test_error_names_file_line_object_field(tmp_path):
    p = _write(tmp_path, """name: bad
start: {x: 0, y: 0}
boxes:
  - {center: [3, 3], size: [1, 1], height: 1}
  - name: desk
    center: [5, 5]
    size: [1, oops]
    height: 0.7
""")
    with pytest.raises(WorldFileError) as err:
        load_world_file(p)
    msg = str(err.value)
    assert msg.startswith(f"{p}:7: boxes[1] 'desk': field 'size'")
    assert err.value.line == 7 and err.value.field == "size" and err.value.obj == "boxes[1] 'desk'"


@pytest.mark.parametrize(
    ("text", "line", "obj", "field"),
    [
        ("start: {x: 0, y: 0}\nwalls:\n  - {points: [[0, 0]], thickness: 0.1}\n", 3, "walls[0]", "points"),
        ("start: {x: 0, y: 0}\ncylinders:\n  - {center: [2, 2], radius: -1, height: 1}\n", 3, "cylinders[0]", "radius"),
        ("start: {x: 0, y: 0}\nboxes:\n  - center: [2, 2]\n    size: [1, 1]\n    height: 1\n    colour: red\n", 6, "boxes[0]", "colour"),
        ("start: {x: 0, y: 0}\ntables:\n  - center: [2, 2]\n    size: [1, 1]\n    texture: marble\n", 5, "tables[0]", "texture"),
        ("start: {x: 0, y: 0}\ndoors:\n  - {from: [1, 1], to: [2, 1], open: maybe}\n", 3, "doors[0]", "open"),
        ("start: {x: 0}\n", 1, "start", "y"),
    ],
)
def test_field_errors(tmp_path, text, line, obj, field):
    with pytest.raises(WorldFileError) as err:
        load_world_file(_write(tmp_path, text))
    assert (err.value.line, err.value.obj, err.value.field) == (line, obj, field), str(err.value)
    assert str(tmp_path / "bad.yaml") in str(err.value)


def test_yaml_syntax_error_has_line(tmp_path):
    with pytest.raises(WorldFileError, match=r"bad.yaml:3: world: invalid YAML"):
        load_world_file(_write(tmp_path, "name: x\nboxes:\n  - {center: [1, 2}\n"))


def test_start_inside_obstacle_rejected(tmp_path):
    p = _write(tmp_path, """start: {x: 2.1, y: 2.0, theta: 0}
boxes:
  - {name: crate, center: [2, 2], size: [0.5, 0.5], height: 0.4}
""")
    with pytest.raises(WorldFileError, match=r"start: field 'x'.*inside boxes\[0\] 'crate'"):
        load_world_file(p)
    # overlapping by the footprint radius, not only the centre
    p = _write(tmp_path, """start: {x: 2.4, y: 2.0}
boxes:
  - {name: crate, center: [2, 2], size: [0.5, 0.5], height: 0.4}
""")
    with pytest.raises(WorldFileError):
        load_world_file(p)
    # a table top above robot height does not block; a shelf below ground clearance neither
    p = _write(tmp_path, """start: {x: 2.0, y: 2.0}
boxes:
  - {center: [2, 2], size: [1.5, 1.5], height: 1.2, bottom: 0.9}
  - {center: [2, 2], size: [1.5, 1.5], height: 0.01}
""")
    assert load_world_file(p).start[:2] == (2.0, 2.0)


def test_tables_doors_expand(tmp_path):
    p = _write(tmp_path, """start: {x: 0, y: 0}
tables:
  - {center: [3, 0], size: [1.2, 0.8], height: 0.75, top_thickness: 0.05, leg_size: 0.05}
doors:
  - {from: [5, -1], to: [5, 0], open: false}
  - {from: [6, -1], to: [6, 0], open: true, swing: left}
""")
    w = load_world_file(p)
    tops = [q for q in w.prisms if q.source.endswith("top")]
    legs = [q for q in w.prisms if "leg" in q.source]
    assert len(tops) == 1 and tops[0].bottom == pytest.approx(0.70)
    assert len(legs) == 4 and all(q.top == pytest.approx(0.70) for q in legs)
    closed, opened = (q for q in w.prisms if q.source.startswith("doors"))
    assert np.ptp(np.array(closed.quad)[:, 1]) == pytest.approx(1.0)
    # swung 90° about the hinge at (6, -1): now along -x
    assert np.ptp(np.array(opened.quad)[:, 0]) == pytest.approx(1.0)


def test_nav2_map_import(tmp_path):
    data = np.zeros((40, 60), np.int8)
    data[0, :] = data[-1, :] = 100
    data[:, 0] = data[:, -1] = 100
    data[10:20, 30:32] = 100
    save_map(OccupancyMap(data=data, resolution=0.1, origin=(-1.0, -2.0, 0.0)), tmp_path / "m")
    p = tmp_path / "w.yaml"
    p.write_text("start: {x: 0.5, y: 0.0}\nmaps:\n  - {yaml: m.yaml, height: 2.0, texture: brick}\n")
    w = load_world_file(p)
    assert 4 <= len(w.prisms) <= 8  # merged rectangles, not one per cell
    x0, y0, x1, y1 = w.bounds
    assert (x0, y0, x1, y1) == pytest.approx((-1.0, -2.0, 5.0, 2.0))
    assert w.overlapping(2.05, -0.5, 0.05)
    assert not w.overlapping(1.0, 0.0, 0.2)
    p.write_text("start: {x: 0.5, y: 0.0}\nmaps:\n  - {yaml: missing.yaml}\n")
    with pytest.raises(WorldFileError, match=r"w.yaml:3: maps\[0\]: field 'yaml': cannot load"):
        load_world_file(p)


def test_load_world_accepts_a_nav2_map(tmp_path):
    data = np.zeros((40, 60), np.int8)
    data[0, :] = data[-1, :] = data[:, 0] = data[:, -1] = 100
    save_map(OccupancyMap(data=data, resolution=0.1, origin=(0.0, 0.0, 0.0)), tmp_path / "room")
    w = load_world(tmp_path / "room.yaml")
    assert w.name == "room" and len(w.prisms) == 4
    # farthest from the walls: on the room's long axis, ≥ 1.9 m from every wall
    assert w.start[1] == pytest.approx(2.0, abs=0.1) and 1.85 <= w.start[0] <= 4.15
    assert not w.overlapping(w.start[0], w.start[1])
