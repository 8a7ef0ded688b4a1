"""``eddie teleop`` in its own process drives the base; killing it stops the robot."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from typing import Any

from eddiebot.core import Context, SingleThreadedExecutor
from eddiebot.core.launch import build_nodes, find_launch_file, parse_launch_file
from eddiebot.registry import NODES
from eddiebot.transport import connect


def _spin(ex: SingleThreadedExecutor, seconds: float) -> None:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        ex.spin_once(timeout_sec=0.02)


def test_killed_teleop_stops_the_robot(zenoh_env: dict[str, str], zenoh_config: Any) -> None:
    ctx = Context()
    try:
        desc = parse_launch_file(find_launch_file("bringup"), {"port": "emulator:1.1"})
        nodes = build_nodes(desc, ctx, NODES)
        connect(ctx, zenoh_config, required=True)
        ex = SingleThreadedExecutor(context=ctx)
        for n in nodes:
            ex.add_node(n)
        emulator = ctx.resources["emulator"]
        teleop = subprocess.Popen(
            [sys.executable, "-m", "eddiebot.cli.main", "teleop", "--rate", "15"],
            env=zenoh_env, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
        )
        try:
            assert teleop.stdin is not None
            moving = False
            deadline = time.monotonic() + 25
            while time.monotonic() < deadline and not moving:
                teleop.stdin.write(b"i")  # forward, teleop_twist_keyboard's key
                teleop.stdin.flush()
                _spin(ex, 0.5)
                moving = emulator.plant.wheel_velocities[0] > 1.0
            assert moving, teleop.stderr.read1(4000) if teleop.stderr else ""
            os.kill(teleop.pid, signal.SIGKILL)  # no chance to send a last zero
            teleop.wait(5)
            _spin(ex, 1.5)  # mux timeout 0.5 s, then the STOP 0 ramp (≤ 0.32 s)
            assert abs(emulator.plant.wheel_velocities[0]) < 1e-6
        finally:
            if teleop.poll() is None:
                teleop.kill()
    finally:
        ctx.shutdown()
