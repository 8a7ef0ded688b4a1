"""The demo report: Markdown with tables and PNG pictures under ``out/demo/``."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from eddiebot.geometry import se2_compose, se2_inverse

__all__ = ["Report", "world_to_map"]


def world_to_map(poses: np.ndarray, start: Sequence[float]) -> np.ndarray:
    """World-frame poses (N, 3) in the SLAM map frame, whose origin is the start pose."""
    if len(poses) == 0:
        return np.zeros((0, 3))
    inv = se2_inverse(np.asarray(start, dtype=float))
    return se2_compose(np.broadcast_to(inv, poses.shape), poses)


@dataclass
class Report:
    out_dir: Path
    sections: list[str] = field(default_factory=list)
    #: stage → whether it met its targets, for the verdict at the top
    verdicts: dict[str, bool] = field(default_factory=dict)

    def add(self, text: str) -> None:
        self.sections.append(text.rstrip() + "\n")

    def table(self, rows: list[tuple[str, Any]]) -> str:
        lines = ["| measure | value |", "|---|---|"]
        for name, value in rows:
            if isinstance(value, float):
                value = "n/a" if math.isnan(value) else f"{value:.3f}"
            lines.append(f"| {name} | {value} |")
        return "\n".join(lines) + "\n"

    def verdict(self) -> str:
        """One line for the top of the report: every stage met its targets, or which did not."""
        short = [stage for stage, ok in self.verdicts.items() if not ok]
        if not self.verdicts:
            return "No stage ran."
        if not short:
            return f"**Every stage met its targets** ({', '.join(self.verdicts)})."
        return f"**Fell short: {', '.join(short)}** — see the stage sections below."

    def write(self) -> Path:
        path = self.out_dir / "report.md"
        tmp = path.with_suffix(".md.tmp")
        tmp.write_text("# eddiebot demo report\n\n" + self.verdict() + "\n\n"
                       + "\n".join(self.sections))
        tmp.replace(path)
        return path
