"""Navigation in every built-in world: seeded random reachable goals through the real stack.

Each run is the ``nav_sim`` launch (simulator with the Kinect at 320 × 240, Eddie's base stack
against the firmware emulator, depth → scan and depth → cloud, AMCL, Nav2's servers and the
BT navigator) in one process on the sim clock, as ``eddie nav --world W --map M`` runs it.
The map is the world's **ground-truth footprint map** (`eddiebot.sim.ground_truth`: every
prism between the ground clearance and the robot's height, 0.05 m) served by the map server,
with AMCL started at the world's start pose. Goals go to ``navigate_to_pose`` one after
another, each from wherever the robot stopped.

Goals: uniform in free space with ≥ 0.35 m clearance, in the connected component of the
start in free space eroded by the robot radius plus one cell, ≥ 1 m from the previous goal;
yaw uniform. The reference length of each goal is the shortest path from the robot's true
pose to the goal through the free space eroded by the robot radius (0.2245 m) of the
footprint map (16-connected Dijkstra, then line-of-sight shortcuts). A goal is *reached*
when the navigator reports success and the true final pose is within 0.35 m (the goal
checker's 0.25 m on the AMCL estimate + 0.10 m for localisation) and 0.35 rad.

Runs:
* ``static``: every world without its people, ``--goals`` goals (50 by default).
* ``person``: the worlds that script a walking person (who waits and steps aside when the
  robot blocks them), ``--person-goals`` goals.
* ``door``: the office with the kitchen door (x 16.0–16.9 on y = 8.5) closed after
  mapping (open in the map, closed in the world); from the corridor, a goal in the kitchen
  must be reached another way (there is none) or aborted with a typed reason within 60 s.
  The house with its door at (7.0, 2.0–2.9) closed has another way, through the hall.

* ``unreachable`` (with ``static``: sent after its goals): a goal deep inside an obstacle and,
  where the world has one, a goal in a room behind closed doors; ``unknown`` (SLAM map only):
  a goal reachable in the world but deepest in the SLAM map's unknown space. Expected: aborted
  with an error code within 60 s of sim time, without contact (``passed``).

Maps (``--maps``, static runs): ``truth``, the footprint map above, and ``slam``, the map the
SLAM node makes first on the demo's scripted drive (`eddiebot.demo.mapping.run_mapping` along
``SLAM_ROUTES``: the office and the warehouse), saved as map_server files and served instead.
The SLAM map's frame is the robot's start pose: AMCL starts at the identity there, goals are
drawn and judged in the world and sent in the map frame. With ``slam`` (or ``--slam-goals``)
random goals are drawn only where the SLAM map is known with ≥ 0.35 m clearance, so both maps
get the same goals.

Controllers (``--controllers``, static runs): the controller the navigator's trees call
``FollowPath`` — ``rpp`` (config/nav2.yaml), ``dwb`` (config/nav2.yaml's DWB section) or
``mppi`` (Nav2 Jazzy's sample section with Eddie's limits, `MPPI_EDDIE`) or ``mppi_shim``
(that MPPI behind Nav2's rotation shim controller, `SHIM_EDDIE`) — on the same goals.
Each goal's time is reported beside an oracle time: the reference length at the
controller's desired speed (0.4 m/s for all three). ``--params FILE`` runs a user's whole
Nav2 parameters file instead (as ``eddie nav --params FILE``; its ``FollowPath`` as written),
labelled with the file's stem; the oracle speed is its ``FollowPath``'s top speed.

Collisions are the simulator's contacts (the robot's own motion blocked by an obstacle or a
person); contacts with a person near are counted apart.

    .venv/bin/python benchmarks/bench_nav_worlds.py                      # everything
    .venv/bin/python benchmarks/bench_nav_worlds.py --goals 5 --worlds office maze --runs static
    .venv/bin/python benchmarks/bench_nav_worlds.py --runs door
    .venv/bin/python benchmarks/bench_nav_worlds.py --worlds office --goals 6 \
        --runs static unreachable unknown --maps truth slam --controllers rpp mppi dwb

Prints a table per run and writes ``benchmarks/results/nav_worlds.json`` (``--out`` to change).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from scipy import ndimage

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, machine, print_table

from eddiebot.maps import OccupancyMap, save_map
from eddiebot.sim.world import ROBOT_RADIUS, World

WORLDS = ("office", "maze", "warehouse", "depot", "corridor", "house")
GOAL_CLEARANCE = 0.35
REACH_XY = 0.35
REACH_YAW = 0.35
DOOR_LIMIT_S = 60.0


# --------------------------------------------------------------------------- geometry
@dataclass
class FreeSpace:
    """The footprint map's free space: clearance (m) per cell and the grid frame."""

    clearance: np.ndarray
    resolution: float
    origin: tuple[float, float]

    @classmethod
    def of(cls, grid: OccupancyMap) -> FreeSpace:
        free = grid.data == 0
        # distance from each free cell centre to the nearest occupied cell's outline
        dist = ndimage.distance_transform_edt(free) * grid.resolution - grid.resolution / 2
        return cls(np.where(free, dist, 0.0), grid.resolution, (grid.origin[0], grid.origin[1]))

    def cell(self, x: float, y: float) -> tuple[int, int]:
        return (math.floor((y - self.origin[1]) / self.resolution),
                math.floor((x - self.origin[0]) / self.resolution))

    def centre(self, r: int, c: int) -> tuple[float, float]:
        return (self.origin[0] + (c + 0.5) * self.resolution,
                self.origin[1] + (r + 0.5) * self.resolution)


_NEIGHBOURS = [(dr, dc) for dr in range(-2, 3) for dc in range(-2, 3)
               if (dr, dc) != (0, 0) and math.gcd(abs(dr), abs(dc)) == 1]


def _crossed(dr: int, dc: int) -> list[tuple[int, int]]:
    """Cells (relative) a move of (dr, dc) crosses besides its ends."""
    sr, sc = (dr > 0) - (dr < 0), (dc > 0) - (dc < 0)
    if abs(dr) == 2:
        return [(sr, 0), (sr, dc)]
    if abs(dc) == 2:
        return [(0, sc), (dr, sc)]
    if dr and dc:
        return [(dr, 0), (0, dc)]
    return []


def _line_free(mask: np.ndarray, a: tuple[int, int], b: tuple[int, int]) -> bool:
    n = int(max(abs(b[0] - a[0]), abs(b[1] - a[1])) * 3) + 1
    rs = np.linspace(a[0], b[0], n + 1)
    cs = np.linspace(a[1], b[1], n + 1)
    # every cell the segment between the two centres touches (both roundings near halves)
    return bool(np.all(mask[np.floor(rs + 0.5).astype(int), np.floor(cs + 0.5).astype(int)])
                and np.all(mask[np.ceil(rs - 0.5).astype(int), np.ceil(cs - 0.5).astype(int)]))


class PathGraph:
    """16-connected graph of the cells of ``space`` with clearance > ``radius``."""

    def __init__(self, space: FreeSpace, radius: float = ROBOT_RADIUS) -> None:
        from scipy.sparse import coo_matrix

        self.space = space
        self.mask = mask = space.clearance > radius
        h, w = mask.shape
        idx = np.arange(h * w).reshape(h, w)
        rows, cols, vals = [], [], []
        pad = np.zeros((h + 4, w + 4), bool)
        pad[2:-2, 2:-2] = mask
        for dr, dc in _NEIGHBOURS:
            ok = mask & pad[2 + dr:2 + dr + h, 2 + dc:2 + dc + w]
            for cr, cc in _crossed(dr, dc):
                ok &= pad[2 + cr:2 + cr + h, 2 + cc:2 + cc + w]
            r, c = np.nonzero(ok)
            rows.append(idx[r, c])
            cols.append(idx[r + dr, c + dc])
            vals.append(np.full(r.size, math.hypot(dr, dc)))
        self.graph = coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                                shape=(h * w, h * w)).tocsr()

    def snap(self, p: tuple[float, float]) -> tuple[int, int]:
        r, c = self.space.cell(*p)
        h, w = self.mask.shape
        if 0 <= r < h and 0 <= c < w and self.mask[r, c]:
            return r, c
        r0, c0 = max(0, r - 8), max(0, c - 8)
        rr, cc = np.nonzero(self.mask[r0:r + 9, c0:c + 9])
        if rr.size == 0:
            raise ValueError(f"no free cell near {p}")
        k = int(np.argmin((rr + r0 - r) ** 2 + (cc + c0 - c) ** 2))
        return int(rr[k] + r0), int(cc[k] + c0)

    def shortest(self, start: tuple[float, float], goal: tuple[float, float]) -> float:
        """Shortest path (m) from ``start`` to ``goal`` through the eroded free space:
        Dijkstra over 16 neighbours, then the path pulled tight by line-of-sight shortcuts."""
        from scipy.sparse.csgraph import dijkstra

        h, w = self.mask.shape
        s, g = self.snap(start), self.snap(goal)
        si, gi = s[0] * w + s[1], g[0] * w + g[1]
        dist, pred = dijkstra(self.graph, indices=si, return_predecessors=True)
        if not math.isfinite(dist[gi]):
            return math.inf
        chain = [gi]
        while chain[-1] != si:
            chain.append(int(pred[chain[-1]]))
        chain.reverse()
        cells = [(i // w, i % w) for i in chain]
        pts = [cells[0]]
        i = 0
        while i < len(cells) - 1:
            j = len(cells) - 1
            while j > i + 1 and not _line_free(self.mask, cells[i], cells[j]):
                j -= 1
            pts.append(cells[j])
            i = j
        xy = np.array([self.space.centre(*p) for p in pts])
        xy[0], xy[-1] = start, goal
        return float(np.sum(np.hypot(np.diff(xy[:, 0]), np.diff(xy[:, 1]))))


def start_component(space: FreeSpace, start: tuple[float, float]) -> np.ndarray:
    """Cells of free space eroded by the robot radius plus one cell connected to ``start``."""
    reach = space.clearance > ROBOT_RADIUS + space.resolution
    labels, _ = ndimage.label(reach, structure=np.ones((3, 3)))
    r, c = space.cell(*start)
    window = labels[max(0, r - 4):r + 5, max(0, c - 4):c + 5]
    ids = window[window > 0]
    if ids.size == 0:
        raise ValueError(f"start {start} is not in free space")
    return np.asarray(labels == np.bincount(ids).argmax())


def sample_goals(space: FreeSpace, start: tuple[float, float], n: int, seed: int,
                 min_step: float = 1.0,
                 allowed: np.ndarray | None = None) -> list[tuple[float, float, float]]:
    """``n`` seeded random goals, reachable from ``start`` (see the module docstring);
    ``allowed`` (a mask over ``space``'s cells) narrows the cells drawn from."""
    comp = start_component(space, start)
    if allowed is not None:
        comp &= allowed
    rr, cc = np.nonzero(comp & (space.clearance >= GOAL_CLEARANCE))
    if rr.size == 0:
        raise ValueError(f"no goal cell reachable from {start}")
    rng = np.random.default_rng(seed)
    goals: list[tuple[float, float, float]] = []
    prev = start
    while len(goals) < n:
        k = int(rng.integers(rr.size))
        x, y = space.centre(int(rr[k]), int(cc[k]))
        x += float(rng.uniform(-0.5, 0.5)) * space.resolution
        y += float(rng.uniform(-0.5, 0.5)) * space.resolution
        if math.hypot(x - prev[0], y - prev[1]) < min_step:
            continue
        goals.append((x, y, float(rng.uniform(-math.pi, math.pi))))
        prev = (x, y)
    return goals


# --------------------------------------------------------------------------- worlds
def world_variant(name: str, out_dir: Path, *, people: bool, closed_doors: tuple[int, ...] = (),
                  extra_doors: tuple[dict[str, Any], ...] = (),
                  opened_doors: tuple[int, ...] = ()) -> Path:
    """A copy of built-in world ``name`` with or without its people, some doors opened, some
    closed and some added (written to ``out_dir``)."""
    from eddiebot.sim.worlds import world_path

    doc = yaml.safe_load(world_path(name).read_text())
    if not people:
        doc["people"] = []
    doors = list(doc.get("doors") or [])
    for i in opened_doors:
        doors[i] = {**doors[i], "open": True}
    for i in closed_doors:
        doors[i] = {**doors[i], "open": False}
    doors.extend(extra_doors)
    doc["doors"] = doors
    tag = ("" if people else "-nopeople") + "".join(f"-d{i}" for i in closed_doors) + \
        "".join(f"-o{i}" for i in opened_doors) + \
        ("-extra" if extra_doors else "")
    path = out_dir / f"{name}{tag}.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def with_start(world_file: Path, start: tuple[float, float, float], out_dir: Path) -> Path:
    """A copy of a world file whose robot starts at ``start`` (x, y, yaw)."""
    doc = yaml.safe_load(world_file.read_text())
    doc["start"] = {"x": float(start[0]), "y": float(start[1]), "theta": float(start[2])}
    path = out_dir / f"{world_file.stem}-from-{start[0]:.2f}-{start[1]:.2f}.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return path


def map_of(world: World, out_dir: Path) -> tuple[Path, OccupancyMap]:
    from eddiebot.sim.ground_truth import footprint_map

    grid = footprint_map(world)
    stem = out_dir / f"{world.name}-footprint-{abs(hash(world.prisms)) % 10**8}"
    save_map(grid, stem)
    return stem.with_suffix(".yaml"), grid


# --------------------------------------------------------------------------- maps
#: the scripted drive that makes each world's SLAM map (``eddiebot.demo.route``)
SLAM_ROUTES = {"office": "OFFICE_ROUTE", "warehouse": "WAREHOUSE_ROUTE"}


@dataclass
class MapSetup:
    """The map served to the stack: its files, its grid and where its frame is in the world."""

    name: str
    yaml: Path
    grid: OccupancyMap
    world_from_map: tuple[float, float, float] = (0.0, 0.0, 0.0)
    info: dict[str, Any] = field(default_factory=dict)

    def lookup(self, space: FreeSpace) -> tuple[np.ndarray, np.ndarray]:
        """For each cell centre of ``space`` (world frame): this map's row and column, -1
        where the centre falls outside the map."""
        from eddiebot.geometry import se2_inverse, se2_transform_points

        h, w = space.clearance.shape
        rr, cc = np.mgrid[0:h, 0:w]
        world = np.stack([space.origin[0] + (cc + 0.5) * space.resolution,
                          space.origin[1] + (rr + 0.5) * space.resolution], axis=-1)
        pts = se2_transform_points(se2_inverse(self.world_from_map), world.reshape(-1, 2))
        g = self.grid
        r = np.floor((pts[:, 1] - g.origin[1]) / g.resolution).astype(int).reshape(h, w)
        c = np.floor((pts[:, 0] - g.origin[0]) / g.resolution).astype(int).reshape(h, w)
        inside = (r >= 0) & (c >= 0) & (r < g.height) & (c < g.width)
        return np.where(inside, r, -1), np.where(inside, c, -1)

    def free_mask(self, space: FreeSpace, clearance: float) -> np.ndarray:
        """Cells of ``space`` this map calls free with ``clearance`` (unknown counts as
        an obstacle)."""
        r, c = self.lookup(space)
        own = FreeSpace.of(self.grid).clearance
        return np.asarray((r >= 0) & (own[np.maximum(r, 0), np.maximum(c, 0)] >= clearance))

    def unknown_depth(self, space: FreeSpace) -> np.ndarray:
        """For each cell of ``space``: its distance (m) to this map's nearest known cell, 0
        on known cells, +inf outside the map."""
        r, c = self.lookup(space)
        depth = ndimage.distance_transform_edt(self.grid.data < 0) * self.grid.resolution
        return np.where(r >= 0, depth[np.maximum(r, 0), np.maximum(c, 0)], np.inf)


def truth_setup(world_name: str, tmp: Path) -> MapSetup:
    from eddiebot.sim.worlds import load_world

    map_yaml, grid = map_of(load_world(world_name), tmp)
    return MapSetup("truth", map_yaml, grid)


def slam_setup(world_name: str, cache: Path, seed: int) -> MapSetup:
    """The SLAM map of ``world_name`` made on the demo's scripted drive (``eddiebot.demo.
    mapping.run_mapping``), kept in ``cache`` and made again only when missing. Its frame is
    the robot's start pose in the world."""
    from eddiebot.maps import load_map

    map_yaml = cache / f"{world_name}_map.yaml"
    info_path = cache / f"{world_name}_mapping.json"
    if not (map_yaml.exists() and info_path.exists()):
        if world_name not in SLAM_ROUTES:
            raise SystemExit(f"--maps slam: no mapping route for world {world_name!r} "
                             f"(routes for: {', '.join(SLAM_ROUTES)})")
        from eddiebot.demo import route as routes
        from eddiebot.demo.mapping import run_mapping

        cache.mkdir(parents=True, exist_ok=True)
        print(f"mapping {world_name} along {SLAM_ROUTES[world_name]} ...", flush=True)
        t_cpu = time.process_time()
        m = run_mapping(cache, world=world_name, route=getattr(routes, SLAM_ROUTES[world_name]),
                        seed=seed, record=False)
        info = {"route": SLAM_ROUTES[world_name], "finished": m.finished,
                "distance_m": m.distance_m, "sim_s": m.sim_seconds, "wall_s": m.wall_seconds,
                "cpu_s": time.process_time() - t_cpu, "collisions": m.collisions,
                "ate_rmse_m": m.ate_rmse_m, "ate_aligned_rmse_m": m.ate_aligned_rmse_m,
                "aligned_turn_deg": m.aligned_turn_deg, "agreement": m.agreement,
                "agreement_tolerant": m.agreement_tolerant, "start": list(m.start)}
        info_path.write_text(json.dumps(info, indent=1, default=float) + "\n")
        print(f"  {info}", flush=True)
    info = json.loads(info_path.read_text())
    start = tuple(float(v) for v in info["start"])
    return MapSetup("slam", map_yaml, load_map(map_yaml), start, info)  # type: ignore[arg-type]


# --------------------------------------------------------------------------- controllers
CONTROLLERS = ("rpp", "mppi", "mppi_shim", "dwb")
#: Nav2 Jazzy's sample MPPI section (tests/data/nav2/nav2_params_jazzy.yaml) with Eddie's
#: speeds (the velocity smoother's, RPP's and DWB's 0.4 m/s); the batch at MPPI's own default
#: (1000) to keep the whole stack near real time on one core. The accelerations stay the
#: sample's (ax 3.0 / -3.0, az 3.5), which the sample also sets above its velocity smoother's:
#: MPPI clamps each noised control to one model_dt of acceleration from the previous one, and
#: at Eddie's 0.8 m/s^2 (+-0.04 m/s per step) the samples from a standstill barely gain speed,
#: so in the office's 0.9 m kitchen door, where every fast sample that drifts sideways hits the
#: jamb, the weighted mean stayed at 0.01-0.02 m/s -- below one encoder position per second,
#: the base did not move and the progress checker aborted. The velocity smoother downstream
#: holds Eddie's real limits (0.8 / -1.0 m/s^2, 2.0 rad/s^2), as for DWB.
MPPI_EDDIE = {"vx_max": 0.4, "vx_min": -0.3, "wz_max": 1.5, "batch_size": 1000,
              "visualize": False}
#: ``mppi_shim``: Nav2's rotation shim in front of that MPPI section (the shim's keys beside
#: MPPI's in one block), Jazzy's shim defaults but the in-place rate and acceleration of
#: Eddie's RPP section (1.2 rad/s, 3.2 rad/s^2)
SHIM_EDDIE = {"plugin": "nav2_rotation_shim_controller::RotationShimController",
              "primary_controller": "nav2_mppi_controller::MPPIController",
              "rotate_to_heading_angular_vel": 1.2, "max_angular_accel": 3.2}


def controller_params(controller: str, out_dir: Path,
                      params_file: Path | None = None) -> tuple[Path, float]:
    """config/nav2.yaml with ``FollowPath`` (the controller the navigator's trees name) set to
    ``controller``, and that controller's desired speed (m/s) for the oracle time. With
    ``params_file``: that file as it is (``controller`` is only its label)."""
    from eddiebot.cli.nav import default_params

    source = params_file or default_params()
    doc = yaml.safe_load(source.read_text())
    srv = doc["controller_server"]["ros__parameters"]
    if params_file is not None:
        section = srv.get("FollowPath", {})
        speed = float(section.get("desired_linear_vel", section.get("vx_max",
                                                                    section.get("max_vel_x", 0.5))))
        return params_file, speed
    if controller == "dwb":
        srv["FollowPath"] = dict(srv["DWB"])
    elif controller in ("mppi", "mppi_shim"):
        jazzy = yaml.safe_load((Path(__file__).resolve().parents[1] / "tests" / "data" / "nav2"
                                / "nav2_params_jazzy.yaml").read_text())
        srv["FollowPath"] = {**jazzy["controller_server"]["ros__parameters"]["FollowPath"],
                             **MPPI_EDDIE, **(SHIM_EDDIE if controller == "mppi_shim" else {})}
    elif controller != "rpp":
        raise ValueError(f"unknown controller {controller!r} (one of {', '.join(CONTROLLERS)})")
    section = srv["FollowPath"]
    speed = float(section.get("desired_linear_vel", section.get("vx_max",
                                                                section.get("max_vel_x", 0.5))))
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / f"nav2-{controller}.yaml"
    path.write_text(f"# {source} with FollowPath = {controller}\n"
                    + yaml.safe_dump(doc, sort_keys=False))
    return path, speed


# --------------------------------------------------------------------------- special goals
ABORT_LIMIT_S = 60.0
SPECIAL_KINDS = ("unreachable", "unknown")


def special_goals(truth: FreeSpace, start: tuple[float, float], truth_grid: OccupancyMap,
                  slam: MapSetup | None, kinds: list[str]) -> list[tuple[str, tuple[float, float, float]]]:
    """Goals the navigator must give up on, in the world frame:

    * ``obstacle`` (run ``unreachable``): the cell deepest inside an obstacle of the footprint
      map within the start area's bounding box;
    * ``closed_room`` (run ``unreachable``): the free cell with the most clearance (≥ 0.35 m)
      in that box that the robot cannot reach (a room behind closed doors), if any;
    * ``unknown`` (SLAM map only): the cell of the start's free space (reachable in the
      world) deepest in the SLAM map's unknown space."""
    comp = start_component(truth, start)
    rows, cols = np.nonzero(comp)
    box = np.zeros_like(comp)
    box[rows.min():rows.max() + 1, cols.min():cols.max() + 1] = True
    out: list[tuple[str, tuple[float, float, float]]] = []

    def pick(score: np.ndarray, kind: str) -> None:
        if np.isfinite(score).any() and np.nanmax(np.where(np.isfinite(score), score, -1)) > 0:
            k = int(np.argmax(np.where(np.isfinite(score), score, -1)))
            x, y = truth.centre(*divmod(k, score.shape[1]))
            out.append((kind, (x, y, 0.0)))

    if "unreachable" in kinds:
        inside = ndimage.distance_transform_edt(truth_grid.data != 0)
        pick(np.where(box, inside, 0.0), "obstacle")
        pick(np.where(box & ~comp & (truth.clearance >= GOAL_CLEARANCE), truth.clearance, 0.0),
             "closed_room")
    if "unknown" in kinds and slam is not None:
        depth = slam.unknown_depth(truth)
        pick(np.where(comp & (truth.clearance >= GOAL_CLEARANCE) & np.isfinite(depth), depth, 0.0),
             "unknown")
    return out


# --------------------------------------------------------------------------- one run
@dataclass
class GoalRecord:
    index: int
    goal: tuple[float, float, float]
    start: tuple[float, float, float]
    kind: str = "random"
    status: str = "not sent"
    error_code: int = 0
    error_msg: str = ""
    seconds: float = 0.0
    driven_m: float = 0.0
    shortest_m: float = math.nan
    ratio: float = math.nan
    oracle_s: float = math.nan
    """The reference length at the controller's desired speed."""
    time_ratio: float = math.nan
    final_xy_error: float = math.nan
    final_yaw_error: float = math.nan
    amcl_error: float = math.nan
    collisions: int = 0
    max_odom_gap_s: float = math.nan
    """Longest time between two odometry samples (``/odom`` stamps) during the goal: the
    controller refuses a pose older than ``transform_tolerance`` (docs/benchmarks/nav.md#pose-age)."""
    reached: bool = False
    passed: bool = False
    """Special goals: aborted with an error code within ``ABORT_LIMIT_S``, no contact."""


@dataclass
class RunResult:
    name: str
    world: str
    map: str = "truth"
    controller: str = "rpp"
    goals: list[GoalRecord] = field(default_factory=list)
    collisions: int = 0
    person_collisions: int = 0
    collision_points: list[tuple[float, float]] = field(default_factory=list)
    sim_s: float = 0.0
    wall_s: float = 0.0
    cpu_s: float = 0.0

    @property
    def key(self) -> str:
        return "/".join([self.name, self.world, *([self.map, self.controller]
                                                  if (self.map, self.controller) != ("truth", "rpp")
                                                  else [])])

    def summary(self) -> dict[str, Any]:
        goals = [g for g in self.goals if g.kind == "random"]
        n = len(goals)
        reached = [g for g in goals if g.reached]
        ratios = [g.ratio for g in reached if math.isfinite(g.ratio)]
        times = [g.time_ratio for g in reached if math.isfinite(g.time_ratio)]
        amcl = [g.amcl_error for g in goals if math.isfinite(g.amcl_error)]
        special = [g for g in self.goals if g.kind != "random"]
        return {
            "run": self.name, "world": self.world, "map": self.map, "controller": self.controller,
            "goals": n,
            "succeeded": sum(1 for g in goals if g.status == "succeeded"), "reached": len(reached),
            "reached_pct": 100.0 * len(reached) / n if n else math.nan,
            "collisions": self.collisions, "person_collisions": self.person_collisions,
            "mean_ratio": float(np.mean(ratios)) if ratios else math.nan,
            "max_ratio": float(np.max(ratios)) if ratios else math.nan,
            "sum_ratio": (sum(g.driven_m for g in reached) / sum(g.shortest_m for g in reached)
                          if reached else math.nan),
            "mean_time_ratio": float(np.mean(times)) if times else math.nan,
            "max_time_ratio": float(np.max(times)) if times else math.nan,
            "sum_time_ratio": (sum(g.seconds for g in reached) / sum(g.oracle_s for g in reached)
                               if reached else math.nan),
            "special": [{"kind": g.kind, "status": g.status, "error_code": g.error_code,
                         "seconds": g.seconds, "driven_m": g.driven_m, "collisions": g.collisions,
                         "passed": g.passed} for g in special],
            "mean_amcl_err": float(np.mean(amcl)) if amcl else math.nan,
            "max_amcl_err": float(np.max(amcl)) if amcl else math.nan,
            "sim_s": self.sim_s, "wall_s": self.wall_s, "cpu_s": self.cpu_s,
        }


class NavRun:
    """The ``nav_sim`` launch in one process on the sim clock, with a goal client."""

    def __init__(self, world_file: Path, map_yaml: Path, start: tuple[float, float, float],
                 run_dir: Path, seed: int = 0, camera: tuple[int, int] = (320, 240),
                 params: Path | None = None,
                 world_from_map: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> None:
        """``start`` is the world pose; ``world_from_map`` places the served map in the world
        (a SLAM map's frame is the robot's start pose): AMCL starts at ``start`` in the map
        frame, goals given in the world go to the navigator in the map frame."""
        from eddiebot.cli.nav import default_params, resolve_params
        from eddiebot.core.action import ActionClient
        from eddiebot.core.context import Context
        from eddiebot.core.executors import SingleThreadedExecutor
        from eddiebot.core.launch import build_nodes, find_launch_file, parse_launch_file
        from eddiebot.core.node import Node
        from eddiebot.core.time import stamp_to_ns
        from eddiebot.geometry import quaternion_to_yaw, se2_compose, se2_inverse
        from eddiebot.msgs.geometry_msgs import PoseWithCovarianceStamped
        from eddiebot.msgs.nav2_msgs import NavigateToPose
        from eddiebot.msgs.nav_msgs import Odometry
        from eddiebot.msgs.std_msgs import UInt32
        from eddiebot.registry import NODES

        self.world_from_map = np.array(world_from_map, dtype=float)
        self.map_from_world = se2_inverse(self.world_from_map)
        in_map = tuple(float(v) for v in se2_compose(self.map_from_world, start))
        params = resolve_params(params or default_params(), run_dir, in_map)  # type: ignore[arg-type]
        self.context = Context(use_sim_time=True)
        args = {"world": str(world_file), "seed": str(seed), "map": str(map_yaml),
                "params_file": str(params), "camera_width": str(camera[0]),
                "camera_height": str(camera[1])}
        self.nodes = build_nodes(parse_launch_file(find_launch_file("nav_sim"), args),
                                 self.context, NODES)
        self.sim = self.context.resources["simulator"]
        self.sim.publish_rgb = False  # navigation uses depth only
        self.client_node = Node("bench_navigator", context=self.context)
        self.client = ActionClient(self.client_node, NavigateToPose, "navigate_to_pose")
        self.NavigateToPose = NavigateToPose
        self.truth: list[tuple[float, float, float]] = []
        self.amcl: tuple[float, float, float] | None = None
        self.contacts: list[tuple[float, float, bool]] = []
        self.odom_stamps: list[int] = []

        def on_truth(msg: Any) -> None:
            p = msg.pose.pose
            q = p.orientation
            self.truth.append((p.position.x, p.position.y, quaternion_to_yaw(q.x, q.y, q.z, q.w)))

        def on_amcl(msg: Any) -> None:
            p = msg.pose.pose
            q = p.orientation
            self.amcl = tuple(float(v) for v in se2_compose(  # type: ignore[assignment]
                self.world_from_map,
                (p.position.x, p.position.y, quaternion_to_yaw(q.x, q.y, q.z, q.w))))

        def on_contact(msg: Any) -> None:
            st = self.sim.state
            near = False
            people = self.sim.people_now()
            if people is not None and len(people):
                d = np.hypot(people[:, 0] - st.x, people[:, 1] - st.y) - people[:, 2] - ROBOT_RADIUS
                near = bool(np.min(d) < 0.1)
            self.contacts.append((st.x, st.y, near))

        self.client_node.create_subscription(Odometry, "/ground_truth/odom", on_truth, 50)
        self.client_node.create_subscription(PoseWithCovarianceStamped, "/amcl_pose", on_amcl, 10)
        self.client_node.create_subscription(UInt32, "/sim/collisions", on_contact, 10)
        self.client_node.create_subscription(
            Odometry, "/odom", lambda m: self.odom_stamps.append(stamp_to_ns(m.header.stamp)), 50)
        self.executor = SingleThreadedExecutor(context=self.context)
        for n in [*self.nodes, self.client_node]:
            self.executor.add_node(n)

    def now_s(self) -> float:
        return float(self.context.sim_clock.now_ns()) / 1e9

    def spin(self, seconds: float) -> None:
        self.executor.spin_for(seconds)

    def pose(self) -> tuple[float, float, float]:
        st = self.sim.state
        return (st.x, st.y, st.theta)

    def navigate(self, goal: tuple[float, float, float], timeout_s: float,
                 record: GoalRecord) -> None:
        from eddiebot.geometry import se2_compose, yaw_to_quaternion

        msg = self.NavigateToPose.Goal()
        msg.pose.header.frame_id = "map"
        in_map = se2_compose(self.map_from_world, goal)
        msg.pose.pose.position.x, msg.pose.pose.position.y = float(in_map[0]), float(in_map[1])
        q = yaw_to_quaternion(float(in_map[2]))
        o = msg.pose.pose.orientation
        o.x, o.y, o.z, o.w = q
        n0 = len(self.truth)
        c0 = len(self.contacts)
        o0 = len(self.odom_stamps)
        t0 = self.now_s()
        deadline = t0 + timeout_s
        send = self.client.send_goal_async(msg)
        while not send.done() and self.now_s() < deadline:
            self.spin(0.1)
        handle = send.result() if send.done() else None
        if handle is None or not handle.accepted:
            record.status = "rejected"
            return
        res = handle.get_result_async()
        while not res.done() and self.now_s() < deadline:
            self.spin(0.2)
        record.seconds = self.now_s() - t0
        if not res.done():
            record.status = "timed out"
            handle.cancel_goal_async()
            self.spin(1.0)
        else:
            wrapped = res.result()
            status = int(getattr(wrapped, "status", 0))
            r = getattr(wrapped, "result", wrapped)
            record.error_code = int(getattr(r, "error_code", 0))
            record.error_msg = str(getattr(r, "error_msg", ""))
            record.status = {4: "succeeded", 5: "canceled", 6: "aborted"}.get(status, str(status))
        seg = np.array(self.truth[n0:]) if len(self.truth) > n0 else np.array([self.pose()])
        record.driven_m = float(np.sum(np.hypot(np.diff(seg[:, 0]), np.diff(seg[:, 1]))))
        end = self.pose()
        record.final_xy_error = math.hypot(end[0] - goal[0], end[1] - goal[1])
        record.final_yaw_error = abs(math.remainder(end[2] - goal[2], math.tau))
        if self.amcl is not None:
            record.amcl_error = math.hypot(self.amcl[0] - end[0], self.amcl[1] - end[1])
        record.collisions = len(self.contacts) - c0
        stamps = self.odom_stamps[max(o0 - 1, 0):]
        if len(stamps) > 1:
            record.max_odom_gap_s = float(np.max(np.diff(stamps))) / 1e9
        record.reached = (record.status == "succeeded" and record.final_xy_error <= REACH_XY
                          and record.final_yaw_error <= REACH_YAW)

    def close(self) -> None:
        for n in reversed([*self.nodes, self.client_node]):
            n.destroy_node()
        self.context.shutdown()


def goal_timeout(shortest_m: float) -> float:
    return 60.0 + 4.0 * shortest_m / 0.4


def run_goals(name: str, world_name: str, world_file: Path, n_goals: int, seed: int,
              tmp: Path, verbose: bool = True,
              goals: list[tuple[float, float, float]] | None = None,
              checkpoint: Callable[[RunResult], None] | None = None,
              first: int = 0, *, setup: MapSetup | None = None, controller: str = "rpp",
              special: list[tuple[str, tuple[float, float, float]]] | None = None,
              allowed: np.ndarray | None = None, params_file: Path | None = None) -> RunResult:
    """Goals one after another in one launch; ``checkpoint`` sees the result after each goal.

    ``first`` > 0 resumes the seeded sequence at that goal: the robot starts on goal
    ``first - 1`` (its position and yaw), as if the earlier goals had just been driven.
    ``setup``: the map served (default: the world's footprint map); ``controller``: the
    controller run as ``FollowPath``; ``special``: goals to be aborted, sent after the random
    ones; ``allowed``: a mask narrowing the cells random goals are drawn from;
    ``params_file``: a whole Nav2 parameters file run as it is (``controller`` labels it)."""
    from eddiebot.sim.worlds import load_world

    world = load_world(world_file)
    setup = setup or truth_setup(world_name, tmp)
    truth_space = FreeSpace.of(map_of(world, tmp)[1])
    if goals is None:
        goals = sample_goals(truth_space, world.start[:2], n_goals, seed, allowed=allowed)
    start_pose = world.start
    if first > 0:
        start_pose = goals[first - 1]
        world_file = with_start(world_file, start_pose, tmp)
    graph = PathGraph(truth_space)
    result = RunResult(name, world_name, setup.name, controller)
    run_dir = tmp / f"{name}-{world_name}-{setup.name}-{controller}"
    params, speed = controller_params(controller, run_dir, params_file)
    sequence = [("random", g) for g in goals[first:]] + list(special or [])
    t_wall, t_cpu = time.perf_counter(), time.process_time()
    run = NavRun(world_file, setup.yaml, start_pose, run_dir, seed=seed, params=params,
                 world_from_map=setup.world_from_map)
    try:
        run.spin(3.0)
        for i, (kind, goal) in enumerate(sequence, start=first):
            start = run.pose()
            rec = GoalRecord(i, goal, start, kind)
            try:
                rec.shortest_m = graph.shortest(start[:2], goal[:2])
            except ValueError:
                rec.shortest_m = math.nan
            if kind == "random":
                timeout = goal_timeout(rec.shortest_m if math.isfinite(rec.shortest_m) else 30.0)
            else:
                timeout = ABORT_LIMIT_S + 30.0
            run.navigate(goal, timeout, rec)
            if math.isfinite(rec.shortest_m) and rec.shortest_m > 0:
                rec.oracle_s = rec.shortest_m / speed
            if rec.reached and rec.shortest_m > 0:
                rec.ratio = rec.driven_m / rec.shortest_m
                rec.time_ratio = rec.seconds / rec.oracle_s
            if kind != "random":
                rec.passed = (rec.status == "aborted" and rec.error_code != 0
                              and rec.seconds <= ABORT_LIMIT_S and rec.collisions == 0)
            result.goals.append(rec)
            result.sim_s = run.now_s()
            result.collisions = len(run.contacts)
            result.person_collisions = sum(1 for c in run.contacts if c[2])
            result.collision_points = [(c[0], c[1]) for c in run.contacts]
            result.wall_s = time.perf_counter() - t_wall
            result.cpu_s = time.process_time() - t_cpu
            if checkpoint is not None:
                checkpoint(result)
            if verbose:
                print(f"  [{world_name} {setup.name} {controller} {kind} {i:2d}] "
                      f"({start[0]:6.2f},{start[1]:6.2f}) -> "
                      f"({goal[0]:6.2f},{goal[1]:6.2f}) {rec.status:9s} {rec.error_code:3d} "
                      f"{rec.seconds:6.1f}s (oracle {rec.oracle_s:5.1f}s) drove {rec.driven_m:5.2f} m / {rec.shortest_m:5.2f} m "
                      f"err {rec.final_xy_error:.3f} m {rec.final_yaw_error:.2f} rad "
                      f"amcl {rec.amcl_error:.3f} contacts {rec.collisions} "
                      f"odom gap {rec.max_odom_gap_s:.2f} s {rec.error_msg}",
                      flush=True)
        result.sim_s = run.now_s()
        result.collisions = len(run.contacts)
        result.person_collisions = sum(1 for c in run.contacts if c[2])
        result.collision_points = [(c[0], c[1]) for c in run.contacts]
    finally:
        run.close()
    result.wall_s = time.perf_counter() - t_wall
    result.cpu_s = time.process_time() - t_cpu
    return result


# --------------------------------------------------------------------------- door runs
@dataclass(frozen=True)
class DoorCase:
    world: str
    closed: tuple[int, ...]
    extra: tuple[dict[str, Any], ...]
    staging: tuple[float, float, float]
    goal: tuple[float, float, float]
    other_way: bool
    note: str
    opened: tuple[int, ...] = ()


DOOR_CASES = (
    DoorCase("office", (6,), (), (13.5, 7.5, 0.0), (16.45, 11.0, math.pi / 2), False,
             "kitchen door (16.0-16.9, 8.5) closed; the kitchen has no other door"),
    DoorCase("house", (0,), (), (5.6, 2.45, 0.0), (9.5, 2.0, 0.0), True,
             "door (7.0, 2.0-2.9) closed; the other way runs through the doors at "
             "(7.0, 6.5-7.4), open in map and world, and (8.5-9.4, 4.5)", opened=(1,)),
)


def run_door(case: DoorCase, seed: int, tmp: Path) -> dict[str, Any]:
    from eddiebot.sim.worlds import load_world

    world_file = world_variant(case.world, tmp, people=False, closed_doors=case.closed,
                               extra_doors=case.extra, opened_doors=case.opened)
    world = load_world(world_file)
    base = load_world(world_variant(case.world, tmp, people=False, opened_doors=case.opened))
    map_yaml, _ = map_of(base, tmp)  # mapped with the door open
    truth = FreeSpace.of(map_of(world, tmp)[1])
    t_wall, t_cpu = time.perf_counter(), time.process_time()
    run = NavRun(world_file, map_yaml, world.start, tmp / f"door-{case.world}", seed=seed)
    out: dict[str, Any] = {"world": case.world, "note": case.note, "other_way": case.other_way}
    try:
        run.spin(3.0)
        stage = GoalRecord(0, case.staging, run.pose())
        run.navigate(case.staging, 120.0, stage)
        start = run.pose()
        rec = GoalRecord(1, case.goal, start)
        rec.shortest_m = PathGraph(truth).shortest(start[:2], case.goal[:2])
        run.navigate(case.goal, 180.0, rec)
        out.update({"staging_status": stage.status, "status": rec.status,
                    "error_code": rec.error_code, "error_msg": rec.error_msg,
                    "seconds": rec.seconds, "final_xy_error": rec.final_xy_error,
                    "driven_m": rec.driven_m, "shortest_m": rec.shortest_m,
                    "collisions": len(run.contacts), "reached": rec.reached})
        typed_abort = rec.status == "aborted" and rec.error_code != 0 and rec.seconds <= DOOR_LIMIT_S
        out["passed"] = bool((rec.reached if case.other_way else typed_abort or rec.reached)
                             and len(run.contacts) == 0)
        out["sim_s"] = run.now_s()
    finally:
        run.close()
    out["wall_s"] = time.perf_counter() - t_wall
    out["cpu_s"] = time.process_time() - t_cpu
    return out


# --------------------------------------------------------------------------- main
# --------------------------------------------------------------------------- plans only
def plan_ratios(world_name: str, n_goals: int, seed: int,
                overrides: dict[str, Any] | None = None) -> dict[str, Any]:
    """NavFn's plans (not driven) through the seeded goals in sequence on the footprint map,
    with the global costmap of ``config/nav2.yaml`` (static + inflation layers; ``overrides``
    replace ``footprint_padding``, ``inflation_radius``, ``cost_scaling_factor``): plan length
    over the reference, the highest cost on a plan, and whether every goal is in the start's
    connected component of the costmap (cost < INSCRIBED)."""
    from eddiebot.cli.nav import default_params
    from eddiebot.nav.costmap import build_costmap
    from eddiebot.nav.planners.navfn import NavfnPlanner
    from eddiebot.sim.ground_truth import footprint_map
    from eddiebot.sim.worlds import load_world, world_path

    overrides = overrides or {}
    world = load_world(world_path(world_name))
    grid = footprint_map(world)
    space = FreeSpace.of(grid)
    goals = sample_goals(space, world.start[:2], n_goals, seed)
    graph = PathGraph(space)
    doc = yaml.safe_load(default_params().read_text())
    params = dict(doc["global_costmap"]["global_costmap"]["ros__parameters"])
    params["plugins"] = ["static_layer", "inflation_layer"]
    infl = dict(params["inflation_layer"])
    for key in ("inflation_radius", "cost_scaling_factor"):
        if key in overrides:
            infl[key] = overrides[key]
    params["inflation_layer"] = infl
    if "footprint_padding" in overrides:
        params["footprint_padding"] = overrides["footprint_padding"]
    cm = build_costmap(params, "global_costmap")
    cm.set_static_map(grid)
    cm.update_map(np.array([*world.start[:2], 0.0]))
    m = cm.master
    labels, _ = ndimage.label(m.data < 253, structure=np.ones((3, 3)))

    def label(x: float, y: float) -> int:
        c = m.world_to_map(x, y)
        return -1 if c is None else int(labels[c[1], c[0]])

    planner = NavfnPlanner()
    prev = (world.start[0], world.start[1], 0.0)
    ratios, max_cost, cut_off = [], 0, 0
    for g in goals:
        if label(g[0], g[1]) != label(prev[0], prev[1]):
            cut_off += 1
        path = planner.create_plan(np.array(prev), np.array(g), m)
        length = float(np.sum(np.hypot(np.diff(path[:, 0]), np.diff(path[:, 1]))))
        ratios.append(length / graph.shortest(prev[:2], g[:2]))
        cells = [m.world_to_map(x, y) for x, y in path[:, :2]]
        max_cost = max(max_cost, max(int(m.get_cost(*c)) for c in cells if c is not None))
        prev = g
    return {"world": world_name, "goals": n_goals, "overrides": overrides,
            "inscribed_radius": cm.inscribed_radius, "mean_plan_ratio": float(np.mean(ratios)),
            "max_plan_ratio": float(np.max(ratios)), "max_cost_on_plan": max_cost,
            "goals_cut_off": cut_off}


PERSON_WORLDS = ("office", "warehouse", "depot", "house")
COLUMNS = ["run", "world", "map", "controller", "goals", "succeeded", "reached", "collisions",
           "person_collisions", "mean_ratio", "max_ratio", "mean_time_ratio", "mean_amcl_err",
           "sim_s", "wall_s", "cpu_s"]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--worlds", nargs="+", default=list(WORLDS), choices=WORLDS)
    ap.add_argument("--goals", type=int, default=50)
    ap.add_argument("--first", type=int, default=0,
                    help="static runs: start at this goal of the seeded sequence (the robot placed on the goal before it), to split one world's goals over several runs")
    ap.add_argument("--person-goals", type=int, default=10)
    ap.add_argument("--runs", nargs="+", default=["static", "person", "door"],
                    choices=["static", "person", "door", *SPECIAL_KINDS],
                    help="unreachable / unknown: goals to be aborted, sent after the static "
                         "run's goals (alone with --goals 0)")
    ap.add_argument("--maps", nargs="+", default=["truth"], choices=["truth", "slam"],
                    help="static runs: the ground-truth footprint map and/or a SLAM map made "
                         "first on the demo's scripted drive; with slam, random goals are drawn "
                         "where the SLAM map is known and free (the same goals on both maps)")
    ap.add_argument("--controllers", nargs="+", default=["rpp"], choices=list(CONTROLLERS),
                    help="static runs: the controller run as FollowPath, the same goals for each")
    ap.add_argument("--params", type=Path, default=None, metavar="FILE",
                    help="static runs: this Nav2 parameters file as it is instead of "
                         "config/nav2.yaml and --controllers (as eddie nav --params FILE)")
    ap.add_argument("--slam-goals", action="store_true",
                    help="draw random goals where the SLAM map is known and free also when "
                         "only --maps truth runs (the goal set of a --maps slam run)")
    ap.add_argument("--slam-cache", type=Path, default=None,
                    help="directory for the SLAM maps (reused when present; default: temporary)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--door-worlds", nargs="+", default=None,
                    help="only the door cases in these worlds (default: all)")
    ap.add_argument("--out", type=Path, default=RESULTS / "nav_worlds.json")
    ap.add_argument("--quiet", action="store_true")
    ap.add_argument("--merge", nargs="+", type=Path, default=None, metavar="JSON",
                    help="combine the results of earlier runs (e.g. worlds run in parallel) into --out")
    ap.add_argument("--plans-only", action="store_true",
                    help="no simulation: NavFn's plans through the seeded goals (plan_ratios)")
    ap.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE",
                    help="with --plans-only: global costmap footprint_padding, inflation_radius, "
                         "cost_scaling_factor overrides")
    args = ap.parse_args(argv)
    if args.params is not None:
        if not args.params.is_file():
            ap.error(f"--params: {args.params}: no such file")
        args.controllers = [args.params.stem]
    if args.merge:
        return merge(args.merge, args.out)
    if args.plans_only:
        overrides = {k: float(v) for k, v in (kv.split("=", 1) for kv in args.set)}
        plans = [plan_ratios(w, args.goals, args.seed, overrides) for w in args.worlds]
        print_table(plans, ["world", "goals", "inscribed_radius", "mean_plan_ratio",
                            "max_plan_ratio", "max_cost_on_plan", "goals_cut_off"])
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps({"machine": machine(), "overrides": overrides,
                                        "plans": plans}, indent=1) + "\n")
        print(f"wrote {args.out}")
        return 0

    rows: list[dict[str, Any]] = []
    details: dict[str, Any] = {}
    doors: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory(prefix="bench_nav_worlds_") as td:
        tmp = Path(td)
        for kind in args.runs:
            if kind == "door":
                for case in DOOR_CASES:
                    if args.door_worlds and case.world not in args.door_worlds:
                        continue
                    d = run_door(case, args.seed, tmp)
                    print(f"door {case.world}: {d}", flush=True)
                    doors.append(d)
                    _write(args, rows, doors, details)
                continue
            if kind in SPECIAL_KINDS:
                if "static" in args.runs or kind != next(k for k in args.runs
                                                         if k in SPECIAL_KINDS):
                    continue  # sent after the static run's goals, all kinds in one run
                kind = "special"  # a static run of these goals alone
            worlds = [w for w in args.worlds if kind != "person" or w in PERSON_WORLDS]
            for w in worlds:
                wf = world_variant(w, tmp, people=kind == "person")
                n = {"static": args.goals, "special": 0}.get(kind, args.person_goals)
                for setup, allowed, special in _static_setups(args, kind, w, wf, tmp):
                    for controller in (args.controllers if kind != "person" else ["rpp"]):

                        def save(r: RunResult, final: bool = False,
                                 info: dict[str, Any] = setup.info) -> None:
                            # written after every goal, so a run cut short keeps what it measured
                            details[r.key] = {"goals": [asdict(g) for g in r.goals],
                                              "collision_points": r.collision_points,
                                              "complete": final, "map_info": info}
                            partial = [*rows, r.summary()] if not final else rows
                            _write(args, partial, doors, details)

                        r = run_goals(kind, w, wf, n, args.seed, tmp, verbose=not args.quiet,
                                      checkpoint=save, first=args.first if kind == "static" else 0,
                                      setup=setup, controller=controller, special=special,
                                      allowed=allowed, params_file=args.params)
                        s = r.summary()
                        rows.append(s)
                        save(r, final=True)
                        print_table([s], COLUMNS)
    print()
    if rows:
        print_table(rows, COLUMNS)
    for d in doors:
        print(f"door {d['world']}: {d['status']} ({d['error_code']}: {d['error_msg']}) in "
              f"{d['seconds']:.1f} s, passed {d['passed']}")
    _write(args, rows, doors, details)
    print(f"wrote {args.out}")
    return 0


def _static_setups(args: argparse.Namespace, kind: str, world_name: str, world_file: Path,
                   tmp: Path) -> list[tuple[MapSetup, np.ndarray | None,
                                         list[tuple[str, tuple[float, float, float]]]]]:
    """Per map of ``--maps``: the map, the mask random goals are drawn from and the special
    goals (``--runs unreachable unknown``). Person runs: the footprint map alone."""
    from eddiebot.sim.worlds import load_world

    truth = truth_setup(world_name, tmp)
    if kind == "person":
        return [(truth, None, [])]
    slam = None
    if "slam" in args.maps or args.slam_goals:
        slam = slam_setup(world_name, args.slam_cache or tmp / "slam", args.seed)
    world = load_world(world_file)
    space = FreeSpace.of(map_of(world, tmp)[1])
    allowed = slam.free_mask(space, GOAL_CLEARANCE) if slam is not None else None
    kinds = [k for k in SPECIAL_KINDS if k in args.runs]
    out = []
    for name in args.maps:
        setup = slam if name == "slam" and slam is not None else truth
        special = special_goals(space, world.start[:2], truth.grid,
                                slam if setup is slam else None, kinds)
        out.append((setup, allowed, special))
    return out


def _write(args: argparse.Namespace, rows: list[dict[str, Any]], doors: list[dict[str, Any]],
           details: dict[str, Any]) -> None:
    args.out.parent.mkdir(parents=True, exist_ok=True)
    tmp = args.out.with_suffix(".json.tmp")
    tmp.write_text(json.dumps({"machine": machine(), "args": {k: (str(v) if isinstance(v, Path) else v)
                                                              for k, v in vars(args).items()},
                               "results": rows, "doors": doors, "details": details},
                              indent=1, default=float) + "\n")
    tmp.replace(args.out)


def merge(files: list[Path], out: Path) -> int:
    """Combine runs made in parallel or in parts (``--first``): the goals of one run and world
    from several files are joined by goal index and its summary is computed afresh."""
    doors: list[dict[str, Any]] = []
    parts: dict[str, list[tuple[dict[str, Any], dict[str, Any]]]] = {}
    runs: list[dict[str, Any]] = []
    for f in files:
        doc = json.loads(f.read_text())
        doors += doc.get("doors", [])
        details_in = doc.get("details", {})
        for r in doc.get("results", []):
            key = RunResult(r["run"], r["world"], r.get("map", "truth"),
                            r.get("controller", "rpp")).key
            parts.setdefault(key, []).append((r, details_in.get(key, {})))
        runs.append({"file": f.name, "machine": doc.get("machine"), "args": doc.get("args")})
    rows: list[dict[str, Any]] = []
    details: dict[str, Any] = {}
    for key, items in parts.items():
        first_row = items[0][0]
        by_index: dict[int, dict[str, Any]] = {}
        for _, det in items:
            for g in det.get("goals", []):
                by_index[int(g["index"])] = g
        result = RunResult(first_row["run"], first_row["world"], first_row.get("map", "truth"),
                           first_row.get("controller", "rpp"))
        result.goals = [GoalRecord(**{**g, "goal": tuple(g["goal"]), "start": tuple(g["start"])})
                        for _, g in sorted(by_index.items())]
        result.collisions = sum(int(r.get("collisions", 0)) for r, _ in items)
        result.person_collisions = sum(int(r.get("person_collisions", 0)) for r, _ in items)
        result.collision_points = [tuple(p) for _, det in items
                                   for p in det.get("collision_points", [])]
        result.sim_s = sum(float(r.get("sim_s", 0.0)) for r, _ in items)
        result.wall_s = sum(float(r.get("wall_s", 0.0)) for r, _ in items)
        result.cpu_s = sum(float(r.get("cpu_s", 0.0)) for r, _ in items)
        rows.append(result.summary())
        details[key] = {"goals": [asdict(g) for g in result.goals],
                        "collision_points": result.collision_points,
                        "complete": all(det.get("complete", False) for _, det in items),
                        "map_info": items[0][1].get("map_info", {})}
    print_table(rows, COLUMNS)
    for d in doors:
        print(f"door {d['world']}: {d['status']} ({d['error_code']}: {d['error_msg']}) in "
              f"{d['seconds']:.1f} s, passed {d['passed']}")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"machine": machine(), "merged": runs, "results": rows, "doors": doors,
                               "details": details}, indent=1, default=float) + "\n")
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
