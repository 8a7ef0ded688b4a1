"""A second process for the transport tests: ``python _peer.py ROLE [ARGS...]``.

Every role gives up after ``PEER_TIMEOUT`` seconds (default 20), so a failing test never
hangs; ``READY`` on stdout means its endpoints are declared.
"""

from __future__ import annotations

import os
import sys
import time
from typing import Any

TIMEOUT = float(os.environ.get("PEER_TIMEOUT", "20"))


def _setup(name: str) -> tuple[Any, Any, Any]:
    from eddiebot.core import Context, Node, SingleThreadedExecutor
    from eddiebot.transport import connect

    context = Context()
    node = Node(name, context=context)
    connect(context, required=True)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    return context, node, executor


def _ready() -> None:
    print("READY", flush=True)


def _spin_until(executor: Any, done: Any) -> bool:
    deadline = time.monotonic() + TIMEOUT
    while time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
        if done():
            return True
    return False


def talker(topic: str, text: str) -> int:
    from eddiebot.msgs.std_msgs import String

    context, node, _ex = _setup("talker")
    pub = node.create_publisher(String, topic, 10)
    _ready()
    deadline = time.monotonic() + TIMEOUT
    while pub.get_subscription_count() < 1:
        if time.monotonic() > deadline:
            return 1
        time.sleep(0.01)
    pub.publish(String(data=text))
    time.sleep(0.3)
    context.shutdown()
    return 0


def listener(topic: str, count: str, transient_local: str = "0") -> int:
    from eddiebot.core import qos_profile_latched
    from eddiebot.msgs.std_msgs import String

    context, node, ex = _setup("listener")
    got: list[str] = []

    def on_msg(msg: Any) -> None:
        got.append(msg.data)
        print(f"GOT {msg.data}", flush=True)

    qos = qos_profile_latched if transient_local == "1" else 10
    node.create_subscription(String, topic, on_msg, qos)
    _ready()
    ok = _spin_until(ex, lambda: len(got) >= int(count))
    context.shutdown()
    return 0 if ok else 1


def _serve(ex: Any) -> None:
    import threading

    stop = threading.Event()

    def wait_stdin() -> None:
        sys.stdin.readline()
        stop.set()

    threading.Thread(target=wait_stdin, daemon=True).start()
    deadline = time.monotonic() + TIMEOUT
    while not stop.is_set() and time.monotonic() < deadline:
        ex.spin_once(timeout_sec=0.05)


def hub() -> int:
    """One process with a bit of everything, so tests pay for one interpreter start.

    Node ``/hub``: service ``/ping`` (std_srvs/Trigger), parameters ``speed`` and
    ``label``, action ``/wait_here`` (nav2_msgs/Wait), a latched ``/latched_map``
    published at start, and String listeners on ``/chatter`` and ``/mixed`` printing
    ``GOT <topic> <data>``.
    """
    from eddiebot.core import qos_profile_latched
    from eddiebot.msgs.std_msgs import String
    from eddiebot.msgs.std_srvs import Trigger

    context, node, ex = _setup("hub")

    def cb(_req: Any, res: Any) -> Any:
        res.success = True
        res.message = f"pong from {os.getpid()}"
        return res

    node.create_service(Trigger, "/ping", cb)
    node.declare_parameter("speed", 0.5)
    node.declare_parameter("label", "eddie")
    latched_pub = node.create_publisher(String, "/latched_map", qos_profile_latched)
    latched_pub.publish(String(data="the map"))
    for topic in ("/chatter", "/mixed"):
        node.create_subscription(
            String, topic, lambda m, t=topic: print(f"GOT {t} {m.data}", flush=True), 10)
    try:
        from eddiebot.core.action import ActionServer
        from eddiebot.msgs.nav2_msgs import Wait

        def execute(handle: Any) -> Any:
            fb = Wait.Feedback()
            fb.time_left.sec = 1
            # several over a second: on a loaded machine the caller's feedback subscription
            # may reach this process only after the goal (a sample before it is lost, as in DDS)
            for _ in range(10):
                handle.publish_feedback(fb)
                time.sleep(0.1)
            handle.succeed()
            result = Wait.Result()
            result.total_elapsed_time.sec = int(handle.request.time.sec)
            result.error_msg = "done"
            return result

        ActionServer(node, Wait, "/wait_here", execute)
    except ImportError:
        pass
    _ready()
    _serve(ex)
    context.shutdown()
    return 0


if __name__ == "__main__":
    role, *rest = sys.argv[1:]
    sys.exit(globals()[role](*rest))
