"""Shared helpers for benchmark scripts: machine description and JSON output."""

from __future__ import annotations

import datetime as _dt
import json
import os
import platform
import time
from pathlib import Path
from typing import Any

RESULTS = Path(__file__).resolve().parent / "results"
DATASETS = Path(os.environ.get("EDDIE_DATASETS", Path(__file__).resolve().parents[1].parent / "shared" / "datasets"))


def cpu_reference_ms(repeats: int = 7) -> float:
    """CPU time (ms, the median of ``repeats``) of a fixed single-threaded workload: Python
    loops over small numpy arrays, as the SLAM and navigation code runs. A shared or throttled
    host runs it slower, and every CPU figure of the same run with it: results files carry it
    (``machine.cpu_reference_ms``) so that runs made at different times can be compared."""
    import numpy as np

    rng = np.random.default_rng(0)
    points = rng.normal(size=(300, 2))
    mats = rng.normal(size=(64, 3, 3)) + 4.0 * np.eye(3)
    times = []
    for _ in range(repeats + 1):  # the first run warms numpy up and is dropped
        t = time.process_time()
        acc = 0.0
        for k in range(400):
            c, s = np.cos(0.01 * k), np.sin(0.01 * k)
            moved = points @ np.array([[c, s], [-s, c]]) + 0.001 * k
            cells = np.floor(moved / 0.05).astype(np.int64)
            acc += float(np.unique(cells[:, 0] * 1000 + cells[:, 1]).size)
            acc += float(np.linalg.solve(mats[k % 64], moved[:3, :1].repeat(3, 1))[0, 0])
        total = 0
        for i in range(60000):
            total += (i * i) % 7
        times.append(time.process_time() - t)
        del acc, total
    return 1e3 * float(np.median(times[1:]))


def machine() -> dict[str, Any]:
    return {
        "python": platform.python_version(),
        "machine": platform.machine(),
        "processor": platform.processor() or platform.machine(),
        "cpus": os.cpu_count(),
        "date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "cpu_reference_ms": round(cpu_reference_ms(), 2),
    }


def write_results(name: str, rows: list[dict[str, Any]]) -> Path:
    return write_json(name, {"machine": machine(), "results": rows})


def write_json(name: str, payload: dict[str, Any]) -> Path:
    """``results/<name>.json``, replaced atomically (a rerun overwrites its file)."""
    RESULTS.mkdir(parents=True, exist_ok=True)
    path = RESULTS / f"{name}.json"
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(payload, indent=2) + "\n")
    tmp.replace(path)
    return path


def print_table(rows: list[dict[str, Any]], columns: list[str]) -> None:
    widths = [max([len(c), *(len(_fmt(r.get(c))) for r in rows)]) for c in columns]
    print("  ".join(c.ljust(w) for c, w in zip(columns, widths)))
    print("  ".join("-" * w for w in widths))
    for r in rows:
        print("  ".join(_fmt(r.get(c)).ljust(w) for c, w in zip(columns, widths)))


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    return "" if v is None else str(v)
