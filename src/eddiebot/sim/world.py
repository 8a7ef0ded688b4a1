"""The 2.5-D world model and its YAML file format.

A world is a set of *prisms*: vertical extrusions of a convex quadrilateral or a circle
between a bottom and a top height (m), each with a procedural texture (`eddiebot.sim.textures`).
Walls (polylines with thickness), boxes, cylinders, tables on legs (a top slab and four
legs: a low obstacle a scan at Kinect height misses) and doors (closed: a leaf filling the
doorway; open: the leaf swung 90° about its hinge) all compile to prisms. A nav2 map
(``.yaml`` + image) can be imported: its occupied cells become wall prisms. Floor and
ceiling are planes at z = 0 and z = ``ceiling.height``. People (scripted moving cylinders)
are listed separately; `eddiebot.sim.physics` moves them.

World file (all lengths in metres, angles in radians, colours as [r, g, b] 0..255)::

    name: office
    description: rooms and a corridor
    floor: {texture: carpet}
    ceiling: {height: 2.6, texture: ceiling}
    start: {x: 1.0, y: 1.0, theta: 0.0}
    walls:
      - {points: [[0, 0], [20, 0], [20, 15]], thickness: 0.15, height: 2.6, texture: plaster}
    boxes:
      - {name: desk, center: [3, 4], size: [1.6, 0.8], height: 0.75, yaw: 0.0, bottom: 0.0, texture: wood}
    cylinders:
      - {center: [5, 5], radius: 0.2, height: 1.2, texture: metal}
    tables:
      - {center: [8, 4], size: [1.4, 0.8], height: 0.74, top_thickness: 0.04, leg_size: 0.05}
    doors:
      - {from: [10, 3], to: [10, 3.9], open: false, thickness: 0.05, height: 2.05, swing: left}
    maps:
      - {yaml: my_map.yaml, height: 2.0, texture: plaster}
    people:
      - {path: [[2, 7], [18, 7]], speed: 0.8, radius: 0.25, height: 1.7, loop: true}

Errors (`WorldFileError`) name the file, line, object and field. A start pose where the
robot's footprint (radius 0.2245 m) overlaps an obstacle below robot height is rejected.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import yaml

from eddiebot.sim.errors import WorldFileError
from eddiebot.sim.textures import TEXTURES

__all__ = [
    "FOOTPRINT_TOP",
    "GROUND_CLEARANCE",
    "ROBOT_HEIGHT",
    "ROBOT_RADIUS",
    "Person",
    "Prism",
    "World",
    "WorldArrays",
    "load_world_file",
    "parse_world",
    "world_from_nav2_map",
    "world_from_occupancy",
]

ROBOT_RADIUS = 0.2245
"""Eddie's footprint radius (URDF base_link cylinder), m."""
ROBOT_HEIGHT = 0.65
"""Height with the Kinect (24.5 in), m: obstacles below this can be hit."""
GROUND_CLEARANCE = 0.02
"""Things no taller than this are driven over, m."""
FOOTPRINT_TOP = ROBOT_HEIGHT


@dataclass(frozen=True)
class Prism:
    """A vertical extrusion. ``quad`` is (4, 2) counter-clockwise vertices (m, world frame)
    for a convex quadrilateral; or ``circle`` is (x, y, radius)."""

    bottom: float
    top: float
    texture: str
    source: str
    """The world-file object it came from, e.g. ``boxes[3] 'desk'``."""
    quad: tuple[tuple[float, float], ...] | None = None
    circle: tuple[float, float, float] | None = None

    def distance(self, points: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """Signed distance from (N, 2) points to the outline (negative inside). Exact inside
        and at edges; near a quad's corners outside it under-estimates (conservative)."""
        if self.circle is not None:
            cx, cy, r = self.circle
            return np.hypot(points[:, 0] - cx, points[:, 1] - cy) - r
        q = np.asarray(self.quad, dtype=np.float64)
        e = np.roll(q, -1, axis=0) - q
        n = np.column_stack([e[:, 1], -e[:, 0]]) / np.linalg.norm(e, axis=1)[:, None]
        d = (points[:, None, :] - q[None, :, :]) * n[None, :, :]
        return d.sum(axis=2).max(axis=1)

    def bbox(self) -> tuple[float, float, float, float]:
        if self.circle is not None:
            cx, cy, r = self.circle
            return cx - r, cy - r, cx + r, cy + r
        q = np.asarray(self.quad)
        return float(q[:, 0].min()), float(q[:, 1].min()), float(q[:, 0].max()), float(q[:, 1].max())


@dataclass(frozen=True)
class Person:
    """A scripted moving obstacle: a cylinder walking ``path`` at ``speed`` (m/s), looping
    (back to the first point) or, with ``loop`` false, walking back and forth."""

    path: tuple[tuple[float, float], ...]
    speed: float = 0.8
    radius: float = 0.25
    height: float = 1.7
    loop: bool = True
    texture: str = "person"
    source: str = "people[0]"


@dataclass(frozen=True)
class WorldArrays:
    """Flat arrays of a world's prisms for the numba casters (world frame, m)."""

    quads: npt.NDArray[np.float64]  # (Nq, 4, 2)
    quad_z: npt.NDArray[np.float64]  # (Nq, 2) bottom, top
    quad_tex: npt.NDArray[np.int64]  # (Nq,)
    quad_toff: npt.NDArray[np.float64]  # (Nq,) texture offset along faces, m
    circles: npt.NDArray[np.float64]  # (Nc, 3) x, y, r
    circle_z: npt.NDArray[np.float64]  # (Nc, 2)
    circle_tex: npt.NDArray[np.int64]  # (Nc,)
    circle_toff: npt.NDArray[np.float64]  # (Nc,)


def _texture_offset(source: str) -> float:
    """A per-object shift of the texture along its faces (m), so walls sharing a texture
    do not repeat the same posters in the same places."""
    return (zlib.crc32(source.encode()) % 997) * 0.0101


@dataclass(frozen=True)
class World:
    """A loaded world. Poses are (x, y, theta) in the world (= map) frame."""

    name: str
    prisms: tuple[Prism, ...]
    start: tuple[float, float, float] = (0.0, 0.0, 0.0)
    floor_texture: str = "carpet"
    ceiling_texture: str = "ceiling"
    ceiling_height: float = 2.6
    people: tuple[Person, ...] = ()
    description: str = ""
    source: str = "<memory>"
    meta: dict[str, Any] = field(default_factory=dict, compare=False)

    @cached_property
    def arrays(self) -> WorldArrays:
        quads = [p for p in self.prisms if p.quad is not None]
        circles = [p for p in self.prisms if p.circle is not None]
        tex = {n: i for i, n in enumerate(TEXTURES)}
        return WorldArrays(
            quads=np.array([p.quad for p in quads], dtype=np.float64).reshape(-1, 4, 2),
            quad_z=np.array([(p.bottom, p.top) for p in quads], dtype=np.float64).reshape(-1, 2),
            quad_tex=np.array([tex[p.texture] for p in quads], dtype=np.int64),
            quad_toff=np.array([_texture_offset(p.source) for p in quads], dtype=np.float64),
            circles=np.array([p.circle for p in circles], dtype=np.float64).reshape(-1, 3),
            circle_z=np.array([(p.bottom, p.top) for p in circles], dtype=np.float64).reshape(-1, 2),
            circle_tex=np.array([tex[p.texture] for p in circles], dtype=np.int64),
            circle_toff=np.array([_texture_offset(p.source) for p in circles], dtype=np.float64),
        )

    @cached_property
    def bounds(self) -> tuple[float, float, float, float]:
        """(xmin, ymin, xmax, ymax) of all prisms and people paths (m)."""
        boxes = [p.bbox() for p in self.prisms]
        for person in self.people:
            xs = [q[0] for q in person.path]
            ys = [q[1] for q in person.path]
            boxes.append((min(xs), min(ys), max(xs), max(ys)))
        if not boxes:
            return (-1.0, -1.0, 1.0, 1.0)
        b = np.array(boxes)
        return float(b[:, 0].min()), float(b[:, 1].min()), float(b[:, 2].max()), float(b[:, 3].max())

    def prisms_between(self, z_low: float, z_high: float) -> tuple[Prism, ...]:
        """Prisms with some part strictly between heights ``z_low`` and ``z_high``."""
        return tuple(p for p in self.prisms if p.bottom < z_high and p.top > z_low)

    def obstacles(self) -> tuple[Prism, ...]:
        """What the robot can hit: prisms between the ground clearance and robot height."""
        return self.prisms_between(GROUND_CLEARANCE, ROBOT_HEIGHT)

    def overlapping(self, x: float, y: float, radius: float = ROBOT_RADIUS) -> list[Prism]:
        """Obstacles a robot of ``radius`` standing at (x, y) would overlap."""
        pt = np.array([[x, y]], dtype=np.float64)
        return [p for p in self.obstacles() if p.distance(pt)[0] < radius]


# --------------------------------------------------------------------------------- YAML
class _Map(dict[str, Any]):
    line: int = 0
    key_lines: dict[str, int]


class _Seq(list[Any]):
    line: int = 0
    item_lines: list[int]


class _MarkLoader(yaml.SafeLoader):
    """SafeLoader keeping 1-based line numbers on mappings, their keys and sequence items."""


def _construct_map(loader: _MarkLoader, node: yaml.MappingNode) -> _Map:
    loader.flatten_mapping(node)
    out = _Map()
    out.line = node.start_mark.line + 1
    out.key_lines = {}
    for k_node, v_node in node.value:
        key = loader.construct_object(k_node, deep=True)
        out[str(key)] = loader.construct_object(v_node, deep=True)
        out.key_lines[str(key)] = k_node.start_mark.line + 1
    return out


def _construct_seq(loader: _MarkLoader, node: yaml.SequenceNode) -> _Seq:
    out = _Seq(loader.construct_object(n, deep=True) for n in node.value)
    out.line = node.start_mark.line + 1
    out.item_lines = [n.start_mark.line + 1 for n in node.value]
    return out


_MarkLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _construct_map)
_MarkLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_SEQUENCE_TAG, _construct_seq)


class _Obj:
    """One world-file object being read: knows its file, name and lines for error messages."""

    def __init__(self, file: str, name: str, data: Any, line: int | None):
        self.file, self.name, self.line = file, name, line
        if not isinstance(data, dict):
            raise WorldFileError(file, line, name, None, f"expected a mapping, got {data!r}")
        self.data: dict[str, Any] = data
        label = data.get("name")
        if isinstance(label, str):
            self.name = f"{name} '{label}'"
        self.used: set[str] = {"name"}

    def fail(self, key: str | None, problem: str) -> WorldFileError:
        lines = getattr(self.data, "key_lines", {})
        return WorldFileError(self.file, lines.get(key, self.line), self.name, key, problem)

    def get(self, key: str, default: Any = ...) -> Any:
        self.used.add(key)
        if key not in self.data:
            if default is ...:
                raise self.fail(key, "is required")
            return default
        return self.data[key]

    def num(self, key: str, default: Any = ..., *, positive: bool = False,
            nonneg: bool = False) -> float:
        v = self.get(key, default)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise self.fail(key, f"expected a number, got {v!r}")
        if positive and v <= 0:
            raise self.fail(key, f"must be > 0, got {v!r}")
        if nonneg and v < 0:
            raise self.fail(key, f"must be >= 0, got {v!r}")
        return float(v)

    def flag(self, key: str, default: bool) -> bool:
        v = self.get(key, default)
        if not isinstance(v, bool):
            raise self.fail(key, f"expected true or false, got {v!r}")
        return v

    def text(self, key: str, default: Any = ..., choices: Iterable[str] | None = None) -> str:
        v = self.get(key, default)
        if not isinstance(v, str):
            raise self.fail(key, f"expected a string, got {v!r}")
        if choices is not None and v not in set(choices):
            raise self.fail(key, f"unknown value {v!r} (choose from {', '.join(choices)})")
        return v

    def texture(self, default: str) -> str:
        return self.text("texture", default, TEXTURES)

    def point(self, key: str, default: Any = ...) -> tuple[float, float]:
        v = self.get(key, default)
        if not _is_point(v):
            raise self.fail(key, f"expected [x, y] numbers, got {v!r}")
        return float(v[0]), float(v[1])

    def points(self, key: str, minimum: int = 2) -> tuple[tuple[float, float], ...]:
        v = self.get(key)
        if not isinstance(v, list) or len(v) < minimum or not all(_is_point(p) for p in v):
            raise self.fail(key, f"expected a list of at least {minimum} [x, y] points, got {v!r}")
        return tuple((float(p[0]), float(p[1])) for p in v)

    def finish(self) -> None:
        extra = [k for k in self.data if k not in self.used]
        if extra:
            raise self.fail(extra[0], f"unknown field (known: {', '.join(sorted(self.used - {'name'}))})")


def _is_point(v: Any) -> bool:
    return (isinstance(v, list) and len(v) == 2
            and all(isinstance(c, (int, float)) and not isinstance(c, bool) and math.isfinite(c)
                    for c in v))


def _rect(cx: float, cy: float, sx: float, sy: float, yaw: float) -> tuple[tuple[float, float], ...]:
    c, s = math.cos(yaw), math.sin(yaw)
    out = []
    for dx, dy in ((-sx / 2, -sy / 2), (sx / 2, -sy / 2), (sx / 2, sy / 2), (-sx / 2, sy / 2)):
        out.append((cx + c * dx - s * dy, cy + s * dx + c * dy))
    return tuple(out)


def _segment_quad(p0: tuple[float, float], p1: tuple[float, float], thickness: float,
                  extend: float) -> tuple[tuple[float, float], ...] | None:
    dx, dy = p1[0] - p0[0], p1[1] - p0[1]
    length = math.hypot(dx, dy)
    if length < 1e-9:
        return None
    yaw = math.atan2(dy, dx)
    mx, my = (p0[0] + p1[0]) / 2, (p0[1] + p1[1]) / 2
    return _rect(mx, my, length + 2 * extend, thickness, yaw)


def _walls(o: _Obj, ceiling: float) -> list[Prism]:
    pts = o.points("points")
    thickness = o.num("thickness", 0.15, positive=True)
    height = o.num("height", ceiling, positive=True)
    bottom = o.num("bottom", 0.0, nonneg=True)
    tex = o.texture("plaster")
    o.finish()
    out = []
    for i in range(len(pts) - 1):
        q = _segment_quad(pts[i], pts[i + 1], thickness, thickness / 2)
        if q is not None:
            out.append(Prism(bottom, height, tex, f"{o.name} segment {i}", quad=q))
    return out


def _box(o: _Obj) -> list[Prism]:
    cx, cy = o.point("center")
    sx, sy = o.point("size")
    if sx <= 0 or sy <= 0:
        raise o.fail("size", f"sizes must be > 0, got [{sx}, {sy}]")
    height = o.num("height", positive=True)
    bottom = o.num("bottom", 0.0, nonneg=True)
    yaw = o.num("yaw", 0.0)
    tex = o.texture("wood")
    o.finish()
    if height <= bottom:
        raise o.fail("height", f"top {height} must be above bottom {bottom}")
    return [Prism(bottom, height, tex, o.name, quad=_rect(cx, cy, sx, sy, yaw))]


def _cylinder(o: _Obj) -> list[Prism]:
    cx, cy = o.point("center")
    r = o.num("radius", positive=True)
    height = o.num("height", positive=True)
    bottom = o.num("bottom", 0.0, nonneg=True)
    tex = o.texture("metal")
    o.finish()
    if height <= bottom:
        raise o.fail("height", f"top {height} must be above bottom {bottom}")
    return [Prism(bottom, height, tex, o.name, circle=(cx, cy, r))]


def _table(o: _Obj) -> list[Prism]:
    cx, cy = o.point("center")
    sx, sy = o.point("size")
    height = o.num("height", 0.74, positive=True)
    yaw = o.num("yaw", 0.0)
    top_t = o.num("top_thickness", 0.04, positive=True)
    leg = o.num("leg_size", 0.05, positive=True)
    tex = o.texture("wood")
    leg_tex = o.text("leg_texture", "metal", TEXTURES)
    o.finish()
    if top_t >= height:
        raise o.fail("top_thickness", f"{top_t} is not below the table height {height}")
    if sx <= 2 * leg or sy <= 2 * leg:
        raise o.fail("size", f"[{sx}, {sy}] leaves no room for legs of {leg}")
    out = [Prism(height - top_t, height, tex, f"{o.name} top", quad=_rect(cx, cy, sx, sy, yaw))]
    c, s = math.cos(yaw), math.sin(yaw)
    for i, (fx, fy) in enumerate(((-1, -1), (1, -1), (1, 1), (-1, 1))):
        dx, dy = fx * (sx / 2 - leg / 2), fy * (sy / 2 - leg / 2)
        lx, ly = cx + c * dx - s * dy, cy + s * dx + c * dy
        out.append(Prism(0.0, height - top_t, leg_tex, f"{o.name} leg {i}",
                         quad=_rect(lx, ly, leg, leg, yaw)))
    return out


def _door(o: _Obj) -> list[Prism]:
    p0 = o.point("from")
    p1 = o.point("to")
    is_open = o.flag("open", False)
    thickness = o.num("thickness", 0.05, positive=True)
    height = o.num("height", 2.05, positive=True)
    swing = o.text("swing", "left", ("left", "right"))
    tex = o.texture("door")
    o.finish()
    if is_open:
        dx, dy = p1[0] - p0[0], p1[1] - p0[1]
        sign = 1.0 if swing == "left" else -1.0
        p1 = (p0[0] - sign * dy, p0[1] + sign * dx)
    q = _segment_quad(p0, p1, thickness, 0.0)
    if q is None:
        raise o.fail("to", "door has zero width")
    return [Prism(0.0, height, tex, o.name, quad=q)]


def _rectangles(occupied: npt.NDArray[np.bool_]) -> list[tuple[int, int, int, int]]:
    """Cover occupied cells with rectangles (row0, col0, row1, col1 exclusive): runs along
    rows merged downwards when identical."""
    rects: list[tuple[int, int, int, int]] = []
    open_runs: dict[tuple[int, int], int] = {}
    h, _ = occupied.shape
    for r in range(h + 1):
        runs: set[tuple[int, int]] = set()
        if r < h:
            row = np.concatenate([[False], occupied[r], [False]])
            d = np.flatnonzero(np.diff(row.astype(np.int8)))
            runs = {(int(a), int(b)) for a, b in zip(d[::2], d[1::2])}
        for run in list(open_runs):
            if run not in runs:
                rects.append((open_runs.pop(run), run[0], r, run[1]))
        for run in runs:
            open_runs.setdefault(run, r)
    return rects


def world_from_occupancy(grid: Any, *, height: float = 2.0, texture: str = "plaster",
                         source: str = "map", threshold: int = 65) -> list[Prism]:
    """Extrude an `eddiebot.maps.OccupancyMap`'s occupied cells (value >= ``threshold``)
    into wall prisms from the floor to ``height``."""
    occ = np.asarray(grid.data) >= threshold
    res = float(grid.resolution)
    ox, oy, oyaw = (float(v) for v in grid.origin)
    c, s = math.cos(oyaw), math.sin(oyaw)
    out = []
    for i, (r0, c0, r1, c1) in enumerate(_rectangles(occ)):
        corners = []
        for mx, my in ((c0, r0), (c1, r0), (c1, r1), (c0, r1)):
            x, y = mx * res, my * res
            corners.append((ox + c * x - s * y, oy + s * x + c * y))
        out.append(Prism(0.0, height, texture, f"{source} block {i}", quad=tuple(corners)))
    return out


def _maps(o: _Obj, base: Path) -> list[Prism]:
    from eddiebot.maps import MapError, load_map

    rel = o.text("yaml")
    height = o.num("height", 2.0, positive=True)
    tex = o.texture("plaster")
    o.finish()
    path = (base / rel) if not Path(rel).is_absolute() else Path(rel)
    try:
        grid = load_map(path)
    except (MapError, OSError) as exc:
        raise o.fail("yaml", f"cannot load nav2 map {path}: {exc}") from None
    return world_from_occupancy(grid, height=height, texture=tex, source=o.name)


def _person(o: _Obj) -> Person:
    path = o.points("path", minimum=2)
    p = Person(
        path=path,
        speed=o.num("speed", 0.8, positive=True),
        radius=o.num("radius", 0.25, positive=True),
        height=o.num("height", 1.7, positive=True),
        loop=o.flag("loop", True),
        texture=o.texture("person"),
        source=o.name,
    )
    o.finish()
    return p


_SECTIONS: dict[str, Callable[[_Obj], list[Prism]]] = {
    "boxes": _box,
    "cylinders": _cylinder,
    "tables": _table,
    "doors": _door,
}


def parse_world(doc: Any, file: str = "<string>", base_dir: Path | None = None,
                name: str | None = None) -> World:
    """Build a `World` from a parsed YAML document (best loaded with line marks by
    `load_world_file`). Raises `WorldFileError`."""
    top = _Obj(file, "world", doc if doc is not None else {}, 1)
    world_name = name or top.text("name", Path(file).stem)
    description = top.text("description", "")
    base = base_dir or Path(file).parent

    def section(key: str) -> list[tuple[_Obj, int]]:
        items = top.get(key, [])
        if not isinstance(items, list):
            raise top.fail(key, f"expected a list, got {items!r}")
        lines = getattr(items, "item_lines", [None] * len(items))
        return [(_Obj(file, f"{key}[{i}]", it, ln), i) for i, (it, ln) in enumerate(zip(items, lines))]

    floor_doc = top.get("floor", {})
    floor = _Obj(file, "floor", floor_doc, getattr(floor_doc, "line", top.line))
    floor_tex = floor.texture("carpet")
    floor.finish()
    ceiling_doc = top.get("ceiling", {})
    ceiling = _Obj(file, "ceiling", ceiling_doc, getattr(ceiling_doc, "line", 1))
    ceiling_h = ceiling.num("height", 2.6, positive=True)
    ceiling_tex = ceiling.texture("ceiling")
    ceiling.finish()

    prisms: list[Prism] = []
    for o, _ in section("walls"):
        prisms.extend(_walls(o, ceiling_h))
    for key, fn in _SECTIONS.items():
        for o, _ in section(key):
            prisms.extend(fn(o))
    for o, _ in section("maps"):
        prisms.extend(_maps(o, base))
    people = tuple(_person(o) for o, _ in section("people"))

    start_doc = top.get("start", {"x": 0.0, "y": 0.0, "theta": 0.0})
    start_o = _Obj(file, "start", start_doc, getattr(start_doc, "line", top.line))
    start = (start_o.num("x"), start_o.num("y"), start_o.num("theta", 0.0))
    start_o.finish()
    top.finish()

    world = World(
        name=world_name, prisms=tuple(prisms), start=start, floor_texture=floor_tex,
        ceiling_texture=ceiling_tex, ceiling_height=ceiling_h, people=people,
        description=description, source=file,
    )
    hits = world.overlapping(start[0], start[1])
    if hits:
        raise start_o.fail("x", f"start pose ({start[0]:g}, {start[1]:g}) puts the robot "
                                f"(radius {ROBOT_RADIUS} m) inside {hits[0].source}")
    return world


def load_world_file(path: str | Path) -> World:
    """Load a world YAML file. Raises `WorldFileError` (file, line, object, field)."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise WorldFileError(str(path), None, "world", None, f"cannot read: {exc}") from None
    try:
        doc = yaml.load(text, Loader=_MarkLoader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        line = mark.line + 1 if mark is not None else None
        raise WorldFileError(str(path), line, "world", None, f"invalid YAML: {exc}") from None
    return parse_world(doc, str(path), path.parent)


def world_from_nav2_map(yaml_path: str | Path, *, height: float = 2.0, texture: str = "plaster",
                        start: tuple[float, float, float] | None = None) -> World:
    """A world made of a nav2 map (``.yaml`` + image): occupied cells become walls. Without
    ``start`` the robot starts on the free cell farthest from any obstacle."""
    import cv2

    from eddiebot.maps import load_map, map_to_world

    grid = load_map(yaml_path)
    prisms = world_from_occupancy(grid, height=height, texture=texture, source=str(yaml_path))
    if start is None:
        free = (np.asarray(grid.data) == 0).astype(np.uint8)
        dist = cv2.distanceTransform(free, cv2.DIST_L2, 5)
        r, c = np.unravel_index(int(np.argmax(dist)), dist.shape)
        x, y = map_to_world(grid, np.array([[c, r]]))[0]
        start = (float(x), float(y), 0.0)
    world = World(name=Path(yaml_path).stem, prisms=tuple(prisms), start=start,
                  ceiling_height=max(height, 2.2), source=str(yaml_path),
                  description=f"extruded from nav2 map {Path(yaml_path).name}")
    if world.overlapping(start[0], start[1]):
        raise WorldFileError(str(yaml_path), None, "start", None,
                             f"start pose ({start[0]:g}, {start[1]:g}) is inside an obstacle")
    return world
