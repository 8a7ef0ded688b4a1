"""Transport benchmarks: in-process delivery and Zenoh between two processes on loopback.

    .venv/bin/python benchmarks/bench_transport.py [--quick]

Prints a table and writes ``benchmarks/results/transport.json``. Figures:

- in-process publish → callback, geometry_msgs/Twist (target ≤ 10 µs median), with and
  without the Zenoh transport attached (no remote subscriber: nothing is serialized);
- in-process publish → callback, 640×480 uint16 sensor_msgs/Image (target ≤ 20 µs, the
  callback gets the very same object: no copy);
- Zenoh, two processes: Twist round trip (ping → echo → pong, target ≤ 0.5 ms median);
- Zenoh, two processes: 614,400-byte images sustained, reliable (target ≥ 300 msg/s, no loss).

The two-process figures run against a private router on a random loopback port.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import socket
import statistics
import subprocess
import sys
import time
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))
sys.path.insert(0, str(ROOT / "benchmarks"))
from _common import write_json  # noqa: E402

IMAGE_W, IMAGE_H = 640, 480


def _image(seq: int = 0) -> Any:
    import numpy as np

    from eddiebot.msgs.sensor_msgs import Image

    img = Image(height=IMAGE_H, width=IMAGE_W, encoding="mono16", step=IMAGE_W * 2)
    img.data = np.full(IMAGE_W * IMAGE_H * 2, seq % 251, dtype=np.uint8)
    img.header.frame_id = "camera"
    return img


def _stats_us(samples_ns: list[int]) -> dict[str, float]:
    s = sorted(samples_ns)
    return {
        "median_us": statistics.median(s) / 1e3,
        "p90_us": s[int(0.9 * (len(s) - 1))] / 1e3,
        "p99_us": s[int(0.99 * (len(s) - 1))] / 1e3,
        "n": len(s),
    }


# -- in-process ------------------------------------------------------------------------------
def bench_in_process(msg_factory: Any, n: int, with_transport: bool, env: dict[str, str]) -> dict[str, Any]:
    from eddiebot.core import Context, Node, SingleThreadedExecutor

    ctx = Context()
    node = Node("bench_local", context=ctx, start_parameter_services=False)
    if with_transport:
        from eddiebot.transport import ZenohConfig, connect

        connect(ctx, ZenohConfig.from_env(env), required=True)
    msg = msg_factory()
    stamp = [0]
    lat: list[int] = []
    same = [True]

    def cb(m: Any) -> None:
        lat.append(time.perf_counter_ns() - stamp[0])
        same[0] = same[0] and m is msg

    pub = node.create_publisher(type(msg), "/bench_local", 10)
    node.create_subscription(type(msg), "/bench_local", cb, 10)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    for i in range(n + 200):
        stamp[0] = time.perf_counter_ns()
        pub.publish(msg)
        ex.spin_once(timeout_sec=0)
        if i == 199:
            lat.clear()
    ctx.shutdown()
    return {**_stats_us(lat), "same_object": same[0]}


# -- two processes ---------------------------------------------------------------------------
def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _peer(role: str, env: dict[str, str], *args: str) -> subprocess.Popen[str]:
    return subprocess.Popen([sys.executable, __file__, "--role", role, *args], env=env,
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)


def _wait_line(proc: subprocess.Popen[str], prefix: str) -> str:
    assert proc.stdout is not None
    for line in proc.stdout:
        if line.startswith(prefix):
            return line.strip()
    raise RuntimeError(f"peer exited before printing {prefix!r}")


def _setup_remote(name: str, env: dict[str, str]) -> tuple[Any, Any, Any]:
    from eddiebot.core import Context, Node, SingleThreadedExecutor
    from eddiebot.transport import ZenohConfig, connect

    ctx = Context()
    node = Node(name, context=ctx, start_parameter_services=False)
    connect(ctx, ZenohConfig.from_env(env), required=True)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    return ctx, node, ex


def role_echo() -> None:
    """Republish every /bench_ping Twist on /bench_pong until stdin closes."""
    import threading

    from eddiebot.msgs.geometry_msgs import Twist

    ctx, node, ex = _setup_remote("bench_echo", dict(os.environ))
    pong = node.create_publisher(Twist, "/bench_pong", 10)
    node.create_subscription(Twist, "/bench_ping", pong.publish, 10)
    stop = threading.Event()

    def wait_stdin() -> None:
        sys.stdin.readline()
        stop.set()

    threading.Thread(target=wait_stdin, daemon=True).start()
    print("READY", flush=True)
    while not stop.is_set():
        ex.spin_once(timeout_sec=0.05)
    ctx.shutdown()


def role_sink(expected: str) -> None:
    """Count /bench_images until ``expected`` arrived (or 60 s), then print the figures."""
    from eddiebot.core import HistoryPolicy, QoSProfile
    from eddiebot.msgs.sensor_msgs import Image

    n = int(expected)
    ctx, node, ex = _setup_remote("bench_sink", dict(os.environ))
    times: list[float] = []
    sizes = [0]
    def on_image(m: Any) -> None:
        times.append(time.perf_counter())
        sizes[0] = len(m.data)

    node.create_subscription(Image, "/bench_images", on_image,
                             QoSProfile(depth=n, history=HistoryPolicy.KEEP_ALL))
    print("READY", flush=True)
    deadline = time.monotonic() + 60
    while len(times) < n and time.monotonic() < deadline:
        ex.spin_once(timeout_sec=0.1)
    # a little longer, to see anything beyond the expected count
    end = time.monotonic() + 0.3
    while time.monotonic() < end:
        ex.spin_once(timeout_sec=0.05)
    rate = (len(times) - 1) / (times[-1] - times[0]) if len(times) > 1 else 0.0
    print(f"RESULT {json.dumps({'received': len(times), 'rate_hz': rate, 'bytes': sizes[0]})}",
          flush=True)
    ctx.shutdown()


def ping_pong(ping: Any, msg: Any, got: list[int], ex: Any, n: int,
              warm_up: int = 100) -> tuple[list[int], int]:
    """Publish ``msg`` (its ``linear.x`` numbering the round) and spin until the echo's
    answer lands in ``got`` (perf_counter_ns), up to 1 s; ``warm_up`` first rounds are not
    counted. Returns the round trips (ns) and how many answers never came."""
    rtts: list[int] = []
    lost = 0
    for i in range(n + warm_up):
        msg.linear.x = float(i)
        before = len(got)
        t0 = time.perf_counter_ns()
        ping.publish(msg)
        t_end = time.monotonic() + 1.0
        while len(got) == before and time.monotonic() < t_end:
            ex.spin_once(timeout_sec=0.01)
        if len(got) == before:
            lost += 1
            continue
        if i >= warm_up:
            rtts.append(got[-1] - t0)
    return rtts, lost


def bench_round_trip(env: dict[str, str], n: int) -> dict[str, Any]:
    from eddiebot.msgs.geometry_msgs import Twist

    echo = _peer("echo", env)
    _wait_line(echo, "READY")
    ctx, node, ex = _setup_remote("bench_ping", env)
    got: list[int] = []
    ping = node.create_publisher(Twist, "/bench_ping", 10)
    node.create_subscription(Twist, "/bench_pong", lambda m: got.append(time.perf_counter_ns()), 10)
    deadline = time.monotonic() + 20
    while ping.get_subscription_count() < 1 and time.monotonic() < deadline:
        time.sleep(0.01)
    # the echo's pong publisher must also see us
    msg = Twist()
    rtts, lost = ping_pong(ping, msg, got, ex, n)
    echo.stdin.close()  # type: ignore[union-attr]
    echo.wait(timeout=10)
    ctx.shutdown()
    return {**_stats_us(rtts), "median_ms": statistics.median(rtts) / 1e6, "lost": lost}


def bench_images(env: dict[str, str], n: int) -> dict[str, Any]:
    from eddiebot.msgs.sensor_msgs import Image

    sink = _peer("sink", env, str(n))
    _wait_line(sink, "READY")
    ctx, node, _ex = _setup_remote("bench_camera", env)
    pub = node.create_publisher(Image, "/bench_images", 10)
    deadline = time.monotonic() + 20
    while pub.get_subscription_count() < 1 and time.monotonic() < deadline:
        time.sleep(0.01)
    images = [_image(i) for i in range(4)]
    t0 = time.perf_counter()
    for i in range(n):
        pub.publish(images[i % 4])
    t_pub = time.perf_counter() - t0
    result = json.loads(_wait_line(sink, "RESULT").split(" ", 1)[1])
    sink.stdin.close()  # type: ignore[union-attr]
    sink.wait(timeout=10)
    ctx.shutdown()
    return {**result, "sent": n, "publish_rate_hz": n / t_pub,
            "payload_bytes": len(images[0].data), "lost": n - result["received"]}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="fewer samples")
    parser.add_argument("--role", default=None, help=argparse.SUPPRESS)
    parser.add_argument("rest", nargs="*", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.role == "echo":
        role_echo()
        return 0
    if args.role == "sink":
        role_sink(*args.rest)
        return 0

    from eddiebot.msgs.geometry_msgs import Twist

    n_local = 2000 if args.quick else 20000
    n_rtt = 300 if args.quick else 2000
    n_img = 300 if args.quick else 1000
    port = _free_port()
    env = {**os.environ, "EDDIE_ZENOH_ROUTER": f"tcp/127.0.0.1:{port}",
           "EDDIE_ROUTER_AUTOSTART": "0", "PYTHONPATH": str(ROOT / "src")}
    env.pop("EDDIE_TRANSPORT", None)
    router = subprocess.Popen([sys.executable, "-m", "eddiebot.transport.router",
                               "--endpoint", str(port)], env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        from eddiebot.transport.config import ZenohConfig
        from eddiebot.transport.router import wait_reachable

        if not wait_reachable(ZenohConfig.from_env(env), 15):
            print("could not start a Zenoh router", file=sys.stderr)
            return 1
        results: dict[str, Any] = {
            "in_process_twist": bench_in_process(Twist, n_local, False, env),
            "in_process_twist_with_zenoh": bench_in_process(Twist, n_local, True, env),
            "in_process_image_640x480_u16": bench_in_process(_image, n_local, False, env),
            "zenoh_twist_round_trip": bench_round_trip(env, n_rtt),
            "zenoh_images_614400B": bench_images(env, n_img),
        }
    finally:
        router.terminate()
        router.wait(timeout=10)

    from importlib.metadata import version

    meta = {
        "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "machine": platform.machine(),
        "processor": platform.processor() or platform.machine(),
        "cpus": os.cpu_count(),
        "python": platform.python_version(),
        "zenoh": version("eclipse-zenoh"),
        "platform": platform.platform(),
        "command": "python benchmarks/bench_transport.py" + (" --quick" if args.quick else ""),
        "load_average": list(os.getloadavg()),
    }
    targets = {
        "in_process_twist": ("median_us", "<=", 10.0),
        "in_process_twist_with_zenoh": ("median_us", "<=", 10.0),
        "in_process_image_640x480_u16": ("median_us", "<=", 20.0),
        "zenoh_twist_round_trip": ("median_ms", "<=", 0.5),
        "zenoh_images_614400B": ("rate_hz", ">=", 300.0),
    }
    print(f"{'benchmark':34s} {'figure':>12s} {'target':>10s}  ok   detail")
    for name, (key, op, target) in targets.items():
        r = results[name]
        value = r[key]
        ok = value <= target if op == "<=" else value >= target
        if name == "zenoh_images_614400B":
            ok = ok and r["lost"] == 0
            detail = f"received {r['received']}/{r['sent']}, publisher {r['publish_rate_hz']:.0f}/s"
        elif name == "zenoh_twist_round_trip":
            detail = f"p90 {r['p90_us']:.0f} µs, p99 {r['p99_us']:.0f} µs, lost {r['lost']}"
        else:
            detail = f"p90 {r['p90_us']:.1f} µs, same object: {r['same_object']}"
        r["target"] = f"{op} {target}"
        r["meets_target"] = bool(ok)
        print(f"{name:34s} {value:10.3f} {key.split('_')[-1]:>2s} {op}{target:>7g}  "
              f"{'yes' if ok else 'NO ':3s}  {detail}")
    out = write_json("transport", {"meta": meta, "results": results})
    print(f"wrote {out.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
