"""Helpers of the cross-process tests: a private router, peer processes with captured output."""

from __future__ import annotations

import contextlib
import os
import queue
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

PEER = Path(__file__).with_name("_peer.py")
SRC = Path(__file__).resolve().parents[2] / "src"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _reachable(port: int) -> bool:
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=0.2):
            return True
    except OSError:
        return False


class Proc:
    """A child process whose stdout lines are collected by a thread."""

    def __init__(self, args: list[str], env: dict[str, str]) -> None:
        self.popen = subprocess.Popen(
            args, env=env, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
            text=True,
        )
        self.lines: list[str] = []
        self._q: queue.Queue[str] = queue.Queue()
        self._err: list[str] = []
        threading.Thread(target=self._pump, daemon=True).start()
        threading.Thread(target=self._pump_err, daemon=True).start()

    def _pump(self) -> None:
        assert self.popen.stdout is not None
        for line in self.popen.stdout:
            self.lines.append(line.rstrip("\n"))
            self._q.put(line.rstrip("\n"))

    def _pump_err(self) -> None:
        assert self.popen.stderr is not None
        for line in self.popen.stderr:
            self._err.append(line)

    @property
    def stderr(self) -> str:
        return "".join(self._err)

    def wait_for(self, text: str, timeout: float = 15.0) -> bool:
        deadline = time.monotonic() + timeout
        if any(text in line for line in self.lines):
            return True
        while time.monotonic() < deadline:
            try:
                line = self._q.get(timeout=max(0.01, deadline - time.monotonic()))
            except queue.Empty:
                break
            if text in line:
                return True
        return False

    def finish(self, timeout: float = 15.0) -> int:
        """Close stdin (peers stop on that) and wait for the exit code."""
        try:
            if self.popen.stdin is not None and not self.popen.stdin.closed:
                self.popen.stdin.close()
        except OSError:
            pass
        try:
            return self.popen.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.popen.kill()
            self.popen.wait(timeout=5)
            return -9

    def send(self, line: str) -> None:
        assert self.popen.stdin is not None
        try:
            self.popen.stdin.write(line + "\n")
            self.popen.stdin.flush()
        except (BrokenPipeError, ValueError):
            pass




def session_env(port: int) -> dict[str, str]:
    """Environment of every process of a test session: its own router on ``port``."""
    env = {
        **os.environ,
        "EDDIE_ZENOH_ROUTER": f"tcp/127.0.0.1:{port}",
        "EDDIE_ROUTER_AUTOSTART": "0",
        "EDDIE_NETWORK": "loopback",
        "PYTHONPATH": os.pathsep.join(filter(None, [str(SRC), os.environ.get("PYTHONPATH")])),
        "PYTHONUNBUFFERED": "1",
    }
    env.pop("EDDIE_TRANSPORT", None)
    for name in ("EDDIE_ZENOH_CONFIG", "ZENOH_SESSION_CONFIG_URI", "ZENOH_CONFIG_OVERRIDE"):
        env.pop(name, None)
    return env


def start_router(env: dict[str, str], port: int, timeout: float = 15.0) -> subprocess.Popen[bytes] | None:
    """A router process on ``port``; None if it did not come up."""
    router = subprocess.Popen(
        [sys.executable, "-m", "eddiebot.transport.router", "--endpoint", str(port)],
        env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )
    deadline = time.monotonic() + timeout
    while not _reachable(port):
        if time.monotonic() > deadline or router.poll() is not None:
            router.kill()
            return None
        time.sleep(0.05)
    return router


def stop(proc: subprocess.Popen[bytes]) -> None:
    proc.terminate()
    try:
        proc.wait(timeout=5)
    except subprocess.TimeoutExpired:
        proc.kill()


@contextlib.contextmanager
def private_router() -> Iterator[dict[str, str]]:
    """A Zenoh router of its own on a random loopback port, for as long as the block runs;
    yields the environment that points processes at it (skips the test if it cannot start)."""
    import pytest

    port = free_port()
    env = session_env(port)
    router = start_router(env, port)
    if router is None:
        pytest.skip("could not start a Zenoh router")
    try:
        yield env
    finally:
        stop(router)
