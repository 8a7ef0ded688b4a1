"""The DDS bridge (``eddie bridge dds``): what a ROS 2 system on DDS sees of our graph.

    .venv/bin/python benchmarks/bench_dds_bridge.py [--quick]

Prints a table and writes ``benchmarks/results/dds_bridge.json``. Four processes on loopback:
a private Zenoh router, the bridge (private DDS domain), a ROS 2-like Cyclone DDS peer and
this process as a node of our graph. Figures:

- Twist round trip: our ping → bridge → DDS peer echoing the sample's CDR on ``rt/...pong``
  → bridge → our subscription (compare with the Zenoh-only round trip of
  ``bench_transport.py``);
- 614,400-byte images, reliable, from our publisher through the bridge to a DDS reader
  (compare with Zenoh-only image throughput), with a keep-last 10 publisher (DDS semantics:
  a writer outrunning its reader overwrites) and a keep-all one (the reader's pace is passed
  back to the publisher).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import random
import statistics
import subprocess
import sys
import threading
import time
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))
sys.path.insert(0, str(ROOT / "benchmarks"))

from _common import write_json  # noqa: E402
from bench_transport import _free_port, _image, _stats_us, _wait_line, ping_pong  # noqa: E402

PREFIX = "/bench_dds"


def _qos(depth: int, keep_all: bool = False) -> Any:
    from cyclonedds.qos import Policy, Qos

    return Qos(Policy.Reliability.Reliable(max_blocking_time=1_000_000_000),
               Policy.History.KeepAll if keep_all else Policy.History.KeepLast(depth),
               Policy.DataRepresentation(use_cdrv0_representation=True))


def role_dds_peer(domain: str, expected_images: str) -> None:
    """A ROS 2-like DDS peer: echoes ping → pong (raw CDR) and counts images."""
    from cyclonedds._clayer import ddspy_take, ddspy_write
    from cyclonedds.core import InstanceState, Listener, SampleState, ViewState
    from cyclonedds.domain import Domain, DomainParticipant
    from cyclonedds.pub import DataWriter
    from cyclonedds.sub import DataReader
    from cyclonedds.topic import Topic

    from eddiebot.transport.dds import cyclone_config, idl_type

    mask = SampleState.Any | ViewState.Any | InstanceState.Any
    _domain = Domain(int(domain), cyclone_config("loopback"))
    dp = DomainParticipant(int(domain))
    twist = idl_type("geometry_msgs/msg/Twist")
    image = idl_type("sensor_msgs/msg/Image")
    pong = DataWriter(dp, Topic(dp, f"rt{PREFIX}/pong", twist), qos=_qos(10))
    pong_ref = pong._ref

    def echo(reader: Any) -> None:
        for data, info in ddspy_take(reader._ref, mask, 64):
            if info.valid_data:
                ddspy_write(pong_ref, data)

    _ping = DataReader(dp, Topic(dp, f"rt{PREFIX}/ping", twist), qos=_qos(10),
                       listener=Listener(on_data_available=echo))
    n = int(expected_images)
    runs: dict[str, list[float]] = {}
    sizes = [0]
    readers = []
    for name in ("images_keep_last", "images_keep_all"):
        times = runs[name] = []

        def count(reader: Any, times: list[float] = times) -> None:
            for data, info in ddspy_take(reader._ref, mask, 64):
                if info.valid_data:
                    times.append(time.perf_counter())
                    sizes[0] = len(data)

        readers.append(DataReader(dp, Topic(dp, f"rt{PREFIX}/{name}", image),
                                  qos=_qos(n, keep_all=True),
                                  listener=Listener(on_data_available=count)))
    stop = threading.Event()
    threading.Thread(target=lambda: (sys.stdin.readline(), stop.set()), daemon=True).start()
    print("READY", flush=True)
    reported: set[str] = set()
    while not stop.wait(0.1):
        for name, times in runs.items():
            if name in reported or not times:
                continue
            if len(times) >= n or time.perf_counter() - times[-1] > 3:
                reported.add(name)
                rate = (len(times) - 1) / (times[-1] - times[0]) if len(times) > 1 else 0.0
                out = {"received": len(times), "rate_hz": rate, "bytes": sizes[0]}
                print(f"RESULT {name} {json.dumps(out)}", flush=True)


def bench_round_trip(n: int) -> dict[str, Any]:
    from eddiebot.core import Context, Node, SingleThreadedExecutor
    from eddiebot.msgs.geometry_msgs import Twist
    from eddiebot.transport import connect

    ctx = Context()
    node = Node("bench_dds_ping", context=ctx, start_parameter_services=False)
    transport = connect(ctx, required=True)
    assert transport is not None
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    got: list[int] = []
    ping = node.create_publisher(Twist, f"{PREFIX}/ping", 10)
    node.create_subscription(Twist, f"{PREFIX}/pong", lambda m: got.append(time.perf_counter_ns()),
                             10)
    msg = Twist()
    # until the whole loop carries samples (routes open as discovery goes)
    deadline = time.monotonic() + 30
    while not got and time.monotonic() < deadline:
        ping.publish(msg)
        ex.spin_once(timeout_sec=0.1)
    rtts, lost = ping_pong(ping, msg, got, ex, n)
    ctx.shutdown()
    return {**_stats_us(rtts), "median_ms": statistics.median(rtts) / 1e6, "lost": lost}


def bench_images(peer: subprocess.Popen[str], n: int, keep_all: bool) -> dict[str, Any]:
    from eddiebot.core import Context, HistoryPolicy, Node, QoSProfile
    from eddiebot.msgs.sensor_msgs import Image
    from eddiebot.transport import connect

    ctx = Context()
    node = Node("bench_dds_camera", context=ctx, start_parameter_services=False)
    connect(ctx, required=True)
    qos = QoSProfile(depth=10, history=HistoryPolicy.KEEP_ALL if keep_all
                     else HistoryPolicy.KEEP_LAST)
    name = "images_keep_all" if keep_all else "images_keep_last"
    pub = node.create_publisher(Image, f"{PREFIX}/{name}", qos)
    deadline = time.monotonic() + 30
    while pub.get_subscription_count() < 1 and time.monotonic() < deadline:
        time.sleep(0.01)
    time.sleep(1.0)  # the bridge's DDS writer matches the peer's reader
    images = [_image(i) for i in range(4)]
    t0 = time.perf_counter()
    for i in range(n):
        pub.publish(images[i % 4])
    t_pub = time.perf_counter() - t0
    result = json.loads(_wait_line(peer, f"RESULT {name}").split(" ", 2)[2])
    ctx.shutdown()
    return {**result, "sent": n, "publish_rate_hz": n / t_pub,
            "payload_bytes": len(images[0].data), "lost": n - result["received"]}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="fewer samples")
    parser.add_argument("--role", default=None, help=argparse.SUPPRESS)
    parser.add_argument("rest", nargs="*", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.role == "dds_peer":
        role_dds_peer(*args.rest)
        return 0

    n_rtt = 300 if args.quick else 2000
    n_img = 300 if args.quick else 1000
    port = _free_port()
    domain = random.randint(100, 200)
    env = {**os.environ, "EDDIE_ZENOH_ROUTER": f"tcp/127.0.0.1:{port}",
           "EDDIE_ROUTER_AUTOSTART": "0", "PYTHONPATH": str(ROOT / "src")}
    env.pop("EDDIE_TRANSPORT", None)
    os.environ.update({k: env[k] for k in ("EDDIE_ZENOH_ROUTER", "EDDIE_ROUTER_AUTOSTART")})
    os.environ.pop("EDDIE_TRANSPORT", None)
    procs: list[subprocess.Popen[Any]] = []
    router = subprocess.Popen([sys.executable, "-m", "eddiebot.transport.router",
                               "--endpoint", str(port)], env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    procs.append(router)
    try:
        from eddiebot.transport.config import ZenohConfig
        from eddiebot.transport.router import wait_reachable

        if not wait_reachable(ZenohConfig.from_env(env), 15):
            print("could not start a Zenoh router", file=sys.stderr)
            return 1
        bridge = subprocess.Popen(
            [sys.executable, "-m", "eddiebot.cli.main", "bridge", "dds", "--domain", str(domain),
             "--allow", f"^{PREFIX}/"], env=env, stdout=subprocess.PIPE, text=True)
        procs.append(bridge)
        _wait_line(bridge, "eddie bridge dds")
        threading.Thread(target=lambda: [None for _ in bridge.stdout or []], daemon=True).start()
        peer = subprocess.Popen([sys.executable, __file__, "--role", "dds_peer", str(domain),
                                 str(n_img)], env=env, stdin=subprocess.PIPE,
                                stdout=subprocess.PIPE, text=True)
        procs.append(peer)
        _wait_line(peer, "READY")
        results: dict[str, Any] = {
            "bridge_twist_round_trip": bench_round_trip(n_rtt),
            "bridge_images_614400B_keep_last_10": bench_images(peer, n_img, keep_all=False),
            "bridge_images_614400B_keep_all": bench_images(peer, n_img, keep_all=True),
        }
        peer.stdin.close()  # type: ignore[union-attr]
    finally:
        for p in reversed(procs):
            p.terminate()
            try:
                p.wait(timeout=10)
            except subprocess.TimeoutExpired:
                p.kill()

    from importlib.metadata import version

    meta = {
        "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "machine": platform.machine(),
        "cpus": os.cpu_count(),
        "python": platform.python_version(),
        "zenoh": version("eclipse-zenoh"),
        "cyclonedds": version("cyclonedds"),
        "platform": platform.platform(),
        "command": "python benchmarks/bench_dds_bridge.py" + (" --quick" if args.quick else ""),
        "load_average": list(os.getloadavg()),
    }
    r = results["bridge_twist_round_trip"]
    print(f"Twist round trip through the bridge: median {r['median_ms']:.3f} ms, "
          f"p90 {r['p90_us'] / 1e3:.3f} ms, p99 {r['p99_us'] / 1e3:.3f} ms, lost {r['lost']}")
    for history in ("keep_last_10", "keep_all"):
        r = results[f"bridge_images_614400B_{history}"]
        print(f"614,400-byte images to DDS, {history}: {r['rate_hz']:.0f} msg/s received, "
              f"{r['received']}/{r['sent']}, publisher {r['publish_rate_hz']:.0f} msg/s")
    out = write_json("dds_bridge", {"meta": meta, "results": results})
    print(f"wrote {out.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
