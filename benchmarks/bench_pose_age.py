"""How old the robot pose gets in the full stack: odometry samples, board polls and stops.

One goal through the ``nav_sim`` launch of `bench_nav_worlds.py` (simulator, firmware emulator
with the serial wire's timing, board node, odometry, AMCL, Nav2's servers), from a given start
pose, recording on the sim clock:

* every ``/joint_states`` stamp (the board's ``DIST`` sample time, hence the stamp of
  ``odom → base_footprint``): the gaps between samples and the pose's age at each 20 Hz
  controller cycle (time since the newest sample received), which the controller server
  compares with the local costmap's ``transform_tolerance`` (0.3 s);
* every board transaction (``DIST``, ``PING``, ``ADC``, ``GOSPD``, ``STOP``, …): how many were
  abandoned for a stop;
* the controller server's aborts.

``--abandon-polls`` runs the board queue as it was before polls were rerun after a stop (a
poll a stop abandoned failed and its sample was lost), for the comparison in
docs/benchmarks/nav.md#pose-age.

    .venv/bin/python benchmarks/bench_pose_age.py --controller mppi \\
        --start 3.38 8.16 1.09 --goal 1.36 12.35 -3.04 --seconds 40 [--abandon-polls]
"""

from __future__ import annotations

import argparse
import collections
import json
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_nav_worlds as bnw
from _common import RESULTS, machine

CONTROLLER_PERIOD_S = 0.05


def run(world: str, controller: str, start: tuple[float, float, float],
        goal: tuple[float, float, float], seconds: float, abandon_polls: bool) -> dict[str, Any]:
    from eddiebot.core.time import stamp_to_ns
    from eddiebot.msgs.sensor_msgs import JointState

    with tempfile.TemporaryDirectory(prefix="bench_pose_age_") as td:
        tmp = Path(td)
        world_file = bnw.with_start(bnw.world_variant(world, tmp, people=False), start, tmp)
        setup = bnw.truth_setup(world, tmp)
        params, _ = bnw.controller_params(controller, tmp / "params")
        nav = bnw.NavRun(world_file, setup.yaml, start, tmp / "run", params=params)
        samples: list[tuple[int, int]] = []  # (received, stamp) ns
        ops: list[list[Any]] = []  # [name, error]
        aborts: list[tuple[float, str]] = []

        def now() -> int:
            return nav.context.sim_clock.now_ns()

        nav.client_node.create_subscription(
            JointState, "/joint_states",
            lambda m: samples.append((now(), stamp_to_ns(m.header.stamp))), 50)
        board = next(n for n in nav.nodes if type(n).__name__ == "BoardNode")
        server = next(n for n in nav.nodes if type(n).__name__ == "ControllerServer")
        submit = board.io.submit

        def counted_submit(op: Any) -> None:
            if abandon_polls:
                op.rerun_after_stop = False
            rec = [op.name, None]
            ops.append(rec)
            done = op.done

            def counted_done(result: Any, error: BaseException | None) -> None:
                rec[1] = type(error).__name__ if error is not None else None
                if done is not None:
                    done(result, error)
            op.done = counted_done
            submit(op)

        board.io.submit = counted_submit
        abort = server._abort

        def counted_abort(handle: Any, result: Any, err: Any) -> Any:
            aborts.append((now() / 1e9, str(err)))
            return abort(handle, result, err)

        server._abort = counted_abort
        try:
            nav.spin(3.0)
            record = bnw.GoalRecord(0, goal, start)
            nav.navigate(goal, seconds, record)
        finally:
            nav.close()
    received = np.array([s[0] for s in samples], dtype=np.int64) / 1e9
    stamps = np.array([s[1] for s in samples], dtype=np.int64) / 1e9
    gaps = np.diff(stamps)
    checks = np.arange(received[0], received[-1], CONTROLLER_PERIOD_S)
    newest = np.searchsorted(received, checks, side="right") - 1
    age = checks - stamps[newest]
    polls = collections.Counter(name for name, _ in ops)
    abandoned = collections.Counter(name for name, err in ops if err == "BoardInterrupted")
    return {
        "world": world, "controller": controller, "start": start, "goal": goal,
        "abandon_polls": abandon_polls, "status": record.status, "error_code": record.error_code,
        "driven_m": record.driven_m, "sim_s": float(received[-1] - received[0]),
        "samples": len(stamps), "gap_median_s": float(np.median(gaps)),
        "gap_p99_s": float(np.percentile(gaps, 99)), "gap_max_s": float(gaps.max()),
        "age_max_s": float(age.max()), "age_over_0_3_s": int((age > 0.3).sum()),
        "checks": len(age), "ops": dict(polls), "abandoned": dict(abandoned),
        "aborts": aborts,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--world", default="office", choices=bnw.WORLDS)
    ap.add_argument("--controller", default="mppi", choices=bnw.CONTROLLERS)
    ap.add_argument("--start", nargs=3, type=float, required=True, metavar=("X", "Y", "YAW"))
    ap.add_argument("--goal", nargs=3, type=float, required=True, metavar=("X", "Y", "YAW"))
    ap.add_argument("--seconds", type=float, default=40.0, help="sim time allowed for the goal")
    ap.add_argument("--abandon-polls", action="store_true",
                    help="a poll a stop abandons fails (the board queue before the rerun)")
    ap.add_argument("--out", type=Path, default=RESULTS / "pose_age.json")
    args = ap.parse_args(argv)
    r = run(args.world, args.controller, tuple(args.start), tuple(args.goal), args.seconds,
            args.abandon_polls)
    print(f"{r['controller']} {'abandoned polls' if r['abandon_polls'] else 'polls rerun'}: "
          f"{r['status']} ({r['error_code']}), {r['samples']} samples in {r['sim_s']:.1f} s, "
          f"DIST abandoned {r['abandoned'].get('DIST', 0)} of {r['ops'].get('DIST', 0)}; gap "
          f"median {r['gap_median_s']:.3f} p99 {r['gap_p99_s']:.3f} max {r['gap_max_s']:.3f} s; "
          f"pose age max {r['age_max_s']:.3f} s, over 0.3 s at {r['age_over_0_3_s']} of "
          f"{r['checks']} cycles; aborts {[a[1] for a in r['aborts']]}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps({"machine": machine(), "result": r}, indent=1) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
