"""``eddie posegraph``: pose-graph tools.

    eddie posegraph optimize FILE [--optimizer lm|isam2] [--robust KERNEL] [--gate P|none]
                                  [-o OUT.g2o]

``optimize`` reads a 2D g2o (``VERTEX_SE2``/``EDGE_SE2``) or TORO (``VERTEX2``/``EDGE2``) file,
initialises from its vertices (or by chaining odometry edges when there are none), optimises
with GTSAM and prints the initial and final ½χ² and the time taken. With ``--robust``, loop edges
(j != i + 1) are treated as possibly false: χ²-gated at ``--gate`` (see
`eddiebot.slam.pose_graph`) and given the kernel; the number rejected is printed.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

__all__ = ["HELP", "add_arguments", "run"]

HELP = "pose-graph tools (optimize g2o/TORO files)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="posegraph_command", required=True)
    opt = sub.add_parser("optimize", help="optimise a g2o or TORO file and print ½χ² and time")
    opt.add_argument("file", type=Path)
    opt.add_argument(
        "--optimizer",
        choices=("lm", "isam2"),
        default="lm",
        help="lm: batch Levenberg–Marquardt (default); isam2: node by node",
    )
    opt.add_argument(
        "--robust",
        choices=("none", "huber", "cauchy", "dcs"),
        default="none",
        help="robust kernel on loop edges (j != i + 1)",
    )
    opt.add_argument("--kernel-width", type=float, default=1.0)
    opt.add_argument(
        "--gate",
        default="0.999",
        help="χ² gate probability for robust loop edges, or 'none' (default 0.999)",
    )
    opt.add_argument(
        "-o", "--output", type=Path, default=None, help="write the optimised graph (g2o)"
    )


def _write_g2o(path: Path, data, poses) -> None:  # type: ignore[no-untyped-def]
    lines = [
        f"VERTEX_SE2 {int(i)} {p[0]:.9g} {p[1]:.9g} {p[2]:.9g}\n" for i, p in zip(data.ids, poses)
    ]
    for (i, j), z, info in zip(data.edge_index, data.measurements, data.information):
        tri = [info[0, 0], info[0, 1], info[0, 2], info[1, 1], info[1, 2], info[2, 2]]
        lines.append(
            f"EDGE_SE2 {int(data.ids[i])} {int(data.ids[j])} {z[0]:.9g} {z[1]:.9g} {z[2]:.9g} "
            + " ".join(f"{v:.9g}" for v in tri)
            + "\n"
        )
    path.write_text("".join(lines), encoding="utf-8")


def run(args: argparse.Namespace) -> int:
    if args.posegraph_command != "optimize":
        print(f"eddie posegraph: unknown sub-command {args.posegraph_command!r}", file=sys.stderr)
        return 2

    from eddiebot.slam import PoseGraphFormatError
    from eddiebot.slam.io import build_pose_graph, read_pose_graph

    try:
        data = read_pose_graph(args.file)
    except PoseGraphFormatError as exc:
        print(f"eddie posegraph: {exc}", file=sys.stderr)
        return 1
    optimizer = "levenberg_marquardt" if args.optimizer == "lm" else "isam2"
    try:
        gate = None if str(args.gate).lower() == "none" else float(args.gate)
        if gate is not None and not 0.0 < gate < 1.0:
            raise ValueError
    except ValueError:
        print(
            f"eddie posegraph: --gate must be in (0, 1) or 'none', got {args.gate!r}",
            file=sys.stderr,
        )
        return 2
    t0 = time.perf_counter()
    graph = build_pose_graph(
        data,
        optimizer=optimizer,
        robust_kernel=args.robust,
        kernel_width=args.kernel_width,
        robust_loops=args.robust != "none",
        gate_probability=gate,
    )
    initial = graph.half_chi2()
    t1 = time.perf_counter()
    graph.optimize()
    t2 = time.perf_counter()
    final = graph.half_chi2()
    init_note = "vertices" if data.had_vertices else "chained odometry"
    print(
        f"{args.file.name}: {len(data.poses)} poses, {len(data.edge_index)} edges, initialised from {init_note}"
    )
    print(f"initial 1/2 chi2: {initial:.6g}")
    print(f"final   1/2 chi2: {final:.6g}")
    print(f"optimize time:    {t2 - t1:.3f} s ({optimizer}; load+build {t1 - t0:.3f} s)")
    if graph.rejected:
        print(
            f"rejected loops:   {len(graph.rejected)} (1/2 chi2 of the rest {graph.half_chi2(include_rejected=False):.6g})"
        )
    if args.output is not None:
        _write_g2o(args.output, data, graph.poses)
        print(f"written {args.output}")
    return 0
