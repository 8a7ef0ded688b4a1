"""``eddie nav --map FILE.yaml [--world NAME]``: autonomous navigation.

With ``--world`` the simulator, Eddie's base, localization and Nav2's servers run in one
process on the sim clock (launch ``nav_sim``); without it the navigation alone joins the real
robot's graph through the transport (launch ``nav``). The parameters file (``--params``,
default config/nav2.yaml; config/nav2_report.yaml holds the report's values) is resolved
into ``<run dir>/nav2_params.yaml`` with the costmaps folded into their servers, plus the
initial pose for AMCL (``--initial-pose``; with ``--world`` the world's start pose by
default, which is right for maps in the world frame; a map made by SLAM from the start pose
needs ``--initial-pose 0 0 0``). Send goals with ``eddie goal X Y YAW``.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import yaml

from eddiebot.cli._stack import add_run_arguments, check_world, run_nodes, run_stack
from eddiebot.cli.errors import CliError

__all__ = ["HELP", "add_arguments", "resolve_params", "run"]

HELP = "navigate on a map: the simulator with --world, else the real robot"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--map", required=True, type=Path, help="nav2 map YAML (or a SLAM "
                        "session with --localization slam)")
    parser.add_argument("--world", default=None, help="run in the simulator in this world")
    parser.add_argument("--params", type=Path, default=None,
                        help="Nav2 parameters file (default config/nav2.yaml)")
    parser.add_argument("--localization", choices=("amcl", "slam"), default="amcl")
    parser.add_argument("--initial-pose", type=float, nargs=3, metavar=("X", "Y", "YAW"),
                        default=None, help="AMCL's initial pose in the map frame")
    parser.add_argument("--camera", default="160x120@5",
                        help="simulated Kinect WxH@HZ (default 160x120@5: enough for the scan)")
    parser.add_argument("--run-dir", type=Path, default=None,
                        help="where the resolved parameters are written (default a temp dir)")
    add_run_arguments(parser)


def default_params() -> Path:
    from eddiebot.core.launch import package_share

    return package_share() / "config" / "nav2.yaml"


def resolve_params(source: Path, out_dir: Path, initial_pose: tuple[float, float, float] | None
                   ) -> Path:
    """Write the Nav2 parameters with the costmaps folded in (and AMCL's initial pose).

    A Nav2 user's file drops in: each section of a server eddiebot does not run and each key
    no server or plugin reads is named once on stderr (``not supported: …``, ``ignored: …``)
    and left out. Raises `eddiebot.cli.errors.ParamsFileError` (``FILE:LINE: ...``) for a
    file that is not YAML, and `eddiebot.nav.errors.UnsupportedPlugin` (server, key,
    plugin) for a plugin that cannot be configured.
    """
    from eddiebot.cli._params import load_params_file
    from eddiebot.cli.errors import ParamsFileError
    from eddiebot.nav.nodes._common import nest_nav2_params
    from eddiebot.nav.nodes.params_audit import audit_nav2_params

    doc, _ = load_params_file(source)
    if doc is None:
        doc = {}
    if not isinstance(doc, dict):
        raise ParamsFileError(f"{source}: top level must map node names to "
                              "{ros__parameters: {...}}")
    audit = audit_nav2_params(doc)
    for warning in audit.warnings:
        print(f"eddie nav: {source}: {warning}", file=sys.stderr)
    doc = nest_nav2_params(audit.supported)
    if initial_pose is not None:
        amcl = doc.setdefault("amcl", {}).setdefault("ros__parameters", {})
        amcl["set_initial_pose"] = True
        amcl["initial_pose"] = {"x": initial_pose[0], "y": initial_pose[1], "z": 0.0,
                                "yaw": initial_pose[2]}
    out_dir.mkdir(parents=True, exist_ok=True)
    out = out_dir / "nav2_params.yaml"
    tmp = out.with_suffix(".yaml.tmp")
    tmp.write_text(f"# resolved from {source}\n" + yaml.safe_dump(doc, sort_keys=False))
    tmp.replace(out)
    return out


def check_map(path: Path, localization: str) -> None:
    """Raise a typed error naming the file unless ``path`` is a usable map: a nav2 map YAML
    whose image exists (AMCL), or an existing SLAM session (``--localization slam``)."""
    if not path.exists():
        raise CliError(f"{path}: no such map file")
    if localization == "amcl":
        from eddiebot.maps import MapFormatError, read_map_yaml

        meta = read_map_yaml(path)
        if not meta.image.is_file():
            raise MapFormatError(f"{path}: key 'image': file {meta.image} not found")


def run(args: argparse.Namespace) -> int:
    from eddiebot.cli.sim import camera_args

    if args.world is not None:
        check_world(args.world)
    check_map(args.map, args.localization)
    params = args.params or default_params()
    pose = tuple(args.initial_pose) if args.initial_pose else None
    if pose is None and args.world is not None and args.localization == "amcl":
        from eddiebot.sim.worlds import load_world

        pose = tuple(load_world(args.world).start)
    run_dir = args.run_dir or Path(tempfile.mkdtemp(prefix="eddie_nav_"))
    resolved = resolve_params(params, run_dir, pose)  # type: ignore[arg-type]
    print(f"parameters: {resolved}", flush=True)
    launch_args = {"map": str(args.map.resolve()), "params_file": str(resolved),
                   "localization": args.localization}
    if args.world is None:
        return _run_real(args, launch_args)
    launch_args.update({"world": args.world, "seed": str(args.seed), **camera_args(args.camera)})
    return run_stack(args, "nav_sim", launch_args)


def _run_real(args: argparse.Namespace, launch_args: dict[str, str]) -> int:
    """The navigation alone, on the wall clock, joined to the robot's graph."""
    from eddiebot.core.context import Context
    from eddiebot.core.launch import build_nodes, find_launch_file, parse_launch_file
    from eddiebot.registry import NODES

    context = Context(use_sim_time=False)
    return run_nodes(args, context, lambda: build_nodes(
        parse_launch_file(find_launch_file("nav"), launch_args), context, NODES))
