"""The exploration report: report.json (figures), report.md and a picture of the map with
the driven path, the frontiers visited (green) and abandoned (red)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from eddiebot.explore.mission import ExploreResult

__all__ = ["write_report"]

_VISITED = (60, 170, 40)  # BGR
_ABANDONED = (40, 40, 220)


def _atomic_text(path: Path, text: str) -> Path:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(text)
    tmp.replace(path)
    return path


def _picture(result: ExploreResult, out: Path) -> str:
    """Draw ``exploration.png``; the Markdown that shows it (or why there is none)."""
    if result.grid is None:
        return "(no map)\n"
    try:
        import cv2

        from eddiebot.demo.report import world_to_map
        from eddiebot.viz.snapshot import render_map

        driven = world_to_map(result.truth, result.map_to_world) if len(result.truth) else None
        snap = render_map(result.grid, trajectories={"driven (ground truth)": driven}
                          if driven is not None else None,
                          title=f"exploration of {result.world} (map frame)")
        img = snap.image
        radius = max(3, snap.pixels_per_cell * 3)
        for g in result.goals:
            if g["outcome"] != "reached":
                continue
            p = snap.world_to_pixel(np.array(g["centroid"]))
            cv2.circle(img, (int(p[0]), int(p[1])), radius, _VISITED, 2, cv2.LINE_AA)
        for a in result.abandoned:
            p = snap.world_to_pixel(np.array(a["point"]))
            c, r = int(p[0]), int(p[1])
            cv2.line(img, (c - radius, r - radius), (c + radius, r + radius), _ABANDONED, 2)
            cv2.line(img, (c - radius, r + radius), (c + radius, r - radius), _ABANDONED, 2)
        snap.save(out / "exploration.png")
        return ("![exploration](exploration.png)\n\nGreen circles: frontiers reached; red "
                "crosses: frontiers abandoned; the line: the path driven (ground truth).\n")
    except Exception as exc:  # a picture must not lose the numbers
        return f"(no picture: {exc})\n"


def _fmt(value: Any, unit: str = "", pct: bool = False) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "n/a"
    if pct:
        return f"{100 * value:.1f} %"
    if isinstance(value, float):
        return f"{value:.3f}{unit}"
    return f"{value}{unit}"


def write_report(result: ExploreResult, out: Path) -> tuple[Path, Path]:
    """Write ``out/report.json`` and ``out/report.md`` (with ``exploration.png``)."""
    out.mkdir(parents=True, exist_ok=True)
    summary = result.summary()
    json_path = _atomic_text(out / "report.json", json.dumps(summary, indent=2) + "\n")
    rows = [
        ("finished because", result.reason),
        ("coverage of the reachable free floor", _fmt(result.coverage, pct=True)),
        ("... with the map placed by ATE's fit, not the start pose",
         _fmt(result.coverage_aligned, pct=True)),
        ("map agreement (cells both call known)", _fmt(result.map_agreement, pct=True)),
        ("map agreement, walls within one cell", _fmt(result.map_agreement_tolerant, pct=True)),
        ("ATE of the SLAM poses (aligned RMSE)", _fmt(result.ate_m, " m")),
        ("distance driven", _fmt(result.distance_m, " m")),
        ("sim time (exploring / in all)", f"{result.explore_time_s:.0f} s / {result.sim_time_s:.0f} s"),
        ("wall time", f"{result.wall_time_s:.0f} s"),
        ("share of the time turning in place", _fmt(result.turning_share, pct=True)),
        ("share of the time standing still", _fmt(result.waiting_share, pct=True)),
        ("coverage after exploring 1, 2, 5, 10, 15, 20, 30 min",
         " / ".join(_fmt(c, pct=True) for t, c in result.coverage_curve
                    if round(t) in (60, 120, 300, 600, 900, 1200, 1800)) or "n/a"),
        ("collisions", str(result.collisions)),
        ("returned home", f"{result.returned_home} ({_fmt(result.home_error_m, ' m')} from the start)"
         + (f": {result.home_failure}" if result.home_failure else "")),
        ("frontier goals sent / reached / abandoned",
         f"{result.goals_sent} / {result.frontiers_visited} / {result.frontiers_abandoned}"),
        ("reachable free floor (ground truth)", f"{result.reachable_area_m2:.1f} m²"),
        ("map → world", ", ".join(f"{v:.3f}" for v in result.map_to_world)),
    ]
    table = "| measure | value |\n|---|---|\n" + "\n".join(f"| {k} | {v} |" for k, v in rows)
    abandoned = "\n".join(f"- ({a['point'][0]:.2f}, {a['point'][1]:.2f}): {a['reason']}"
                          for a in result.abandoned) or "- none"
    text = (f"# Exploration of `{result.world}` (seed {result.seed})\n\n{table}\n\n"
            f"{_picture(result, out)}\n## Frontiers abandoned (map frame)\n\n{abandoned}\n\n"
            "Map: `map.yaml` + `map.pgm` (nav2 map_server files, map frame = the start pose).\n")
    md_path = _atomic_text(out / "report.md", text)
    return json_path, md_path
