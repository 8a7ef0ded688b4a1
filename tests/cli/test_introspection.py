"""``eddie topic|node|param|service|action|interface`` against a real graph on loopback."""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "transport"))
from _procs import PEER, Proc, private_router

from eddiebot.cli._common import (
    get_field,
    message_from_yaml,
    message_to_dict,
    message_to_yaml,
)
from eddiebot.cli.main import main


@pytest.fixture(scope="module")
def graph_env() -> Iterator[dict[str, str]]:
    """A router on a random port and a hub process; this process's env points at them."""
    with private_router() as env:
        hub = Proc([sys.executable, str(PEER), "hub"], {**env, "PEER_TIMEOUT": "300"})
        saved = {k: os.environ.get(k) for k in ("EDDIE_ZENOH_ROUTER", "EDDIE_ROUTER_AUTOSTART",
                                                 "EDDIE_TRANSPORT", "EDDIE_DISCOVERY_WAIT")}
        os.environ.update({"EDDIE_ZENOH_ROUTER": env["EDDIE_ZENOH_ROUTER"],
                           "EDDIE_ROUTER_AUTOSTART": "0", "EDDIE_DISCOVERY_WAIT": "0.3"})
        os.environ.pop("EDDIE_TRANSPORT", None)
        try:
            if not hub.wait_for("READY", timeout=30):
                pytest.fail(f"the hub process did not start: {hub.stderr}")
            yield env
        finally:
            hub.finish(timeout=10)
            for k, v in saved.items():
                if v is None:
                    os.environ.pop(k, None)
                else:
                    os.environ[k] = v


def eddie(capsys: Any, *argv: str) -> tuple[int, str]:
    capsys.readouterr()
    code = main(list(argv))
    return code, capsys.readouterr().out


# -- no graph needed ----------------------------------------------------------------------
def test_interface_show_twist(capsys: Any) -> None:
    code, out = eddie(capsys, "interface", "show", "geometry_msgs/msg/Twist")
    assert code == 0
    lines = out.splitlines()
    assert lines[0] == "Vector3 linear"
    assert "\tfloat64 x" in lines
    assert "Vector3 angular" in lines


def test_interface_show_service_and_action(capsys: Any) -> None:
    code, out = eddie(capsys, "interface", "show", "std_srvs/srv/SetBool")
    assert code == 0
    assert out.split() == ["bool", "data", "---", "bool", "success", "string", "message"]
    code, out = eddie(capsys, "interface", "show", "nav2_msgs/action/Wait")
    assert code == 0
    assert out.count("---") == 2
    assert eddie(capsys, "interface", "show", "no_such/msg/Thing")[0] == 1


def test_interface_show_from_the_search_path(capsys: Any, tmp_path: Path,
                                            monkeypatch: pytest.MonkeyPatch) -> None:
    folder = tmp_path / "shown_msgs" / "srv"
    folder.mkdir(parents=True)
    (folder / "Scale.srv").write_text("float64 factor\n---\nbool ok\n")
    monkeypatch.setenv("EDDIE_INTERFACE_PATH", str(tmp_path))
    code, out = eddie(capsys, "interface", "show", "shown_msgs/srv/Scale")
    assert code == 0
    assert out.split() == ["float64", "factor", "---", "bool", "ok"]
    capsys.readouterr()
    assert main(["interface", "show", "shown_msgs/msg/Absent"]) == 1
    err = capsys.readouterr().err
    assert "shown_msgs/msg/Absent.msg" in err
    assert "EDDIE_INTERFACE_PATH" in err


def test_interface_list(capsys: Any) -> None:
    code, out = eddie(capsys, "interface", "list")
    assert code == 0
    for name in ("geometry_msgs/msg/Twist", "std_srvs/srv/Trigger", "nav2_msgs/action/Wait",
                 "eddiebot_msgs/msg/Encoders"):
        assert f"    {name}" in out


def test_yaml_to_message_and_back() -> None:
    msg = message_from_yaml("std_msgs/msg/String", "{data: hi}")
    assert msg.data == "hi"
    twist = message_from_yaml("geometry_msgs/Twist", "{linear: {x: 0.5}, angular: {z: -1}}")
    assert (twist.linear.x, twist.angular.z) == (0.5, -1.0)
    assert get_field(twist, "linear.x") == 0.5
    img = message_from_yaml("sensor_msgs/msg/Image",
                            "{height: 1, width: 3, encoding: mono8, data: [1, 2, 3]}")
    assert img.data.dtype == np.uint8
    assert img.data.tolist() == [1, 2, 3]
    back = yaml.safe_load(message_to_yaml(img))
    assert back["data"] == [1, 2, 3]
    assert back["header"]["stamp"] == {"sec": 0, "nanosec": 0}
    path = message_from_yaml("nav_msgs/msg/Path",
                             "{poses: [{pose: {position: {x: 1.0}}}, {}]}")
    assert len(path.poses) == 2 and path.poses[0].pose.position.x == 1.0
    assert message_to_dict(np.arange(200), truncate=128)[-1] == "..."
    with pytest.raises(ValueError, match="no field"):
        message_from_yaml("std_msgs/msg/String", "{text: hi}")
    with pytest.raises(ValueError):
        message_from_yaml("std_msgs/msg/Int32", "{data: hi}")


# -- two CLI processes ----------------------------------------------------------------------
def test_topic_pub_once_and_echo_once_in_two_processes(graph_env: dict[str, str]) -> None:
    cli = [sys.executable, "-m", "eddiebot.cli.main", "topic"]
    echo = subprocess.Popen([*cli, "echo", "--once", "/cli_chatter", "--timeout", "30"],
                            env=graph_env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    pub = subprocess.run([*cli, "pub", "--once", "--max-wait-time-secs", "30", "/cli_chatter",
                          "std_msgs/msg/String", "{data: hi}"],
                         env=graph_env, capture_output=True, text=True, timeout=60)
    assert pub.returncode == 0, pub.stderr
    assert "publishing #1" in pub.stdout
    out, err = echo.communicate(timeout=30)
    assert echo.returncode == 0, err
    assert out == "data: hi\n---\n"


# -- introspection of the hub -------------------------------------------------------------
def test_topic_list_info_and_node_list(graph_env: Any, capsys: Any) -> None:
    code, out = eddie(capsys, "topic", "list", "-t")
    assert code == 0
    assert "/chatter [std_msgs/msg/String]" in out.splitlines()
    assert "/latched_map [std_msgs/msg/String]" in out.splitlines()
    code, out = eddie(capsys, "topic", "info", "/chatter", "-v")
    assert code == 0
    assert "Type: std_msgs/msg/String" in out
    assert "Subscription count: 1" in out
    assert "Node name: hub" in out
    code, out = eddie(capsys, "topic", "type", "/latched_map")
    assert (code, out) == (0, "std_msgs/msg/String\n")
    code, out = eddie(capsys, "topic", "find", "std_msgs/String")
    assert code == 0 and {"/chatter", "/latched_map"} <= set(out.splitlines())
    assert "/latched_map" not in eddie(capsys, "topic", "find", "std_msgs/msg/Bool")[1]
    code, out = eddie(capsys, "node", "list")
    assert code == 0
    assert "/hub" in out.splitlines()
    assert not any("_eddie_" in line for line in out.splitlines())


def test_topic_echo_gets_latched_message(graph_env: Any, capsys: Any) -> None:
    code, out = eddie(capsys, "topic", "echo", "--once", "/latched_map", "--timeout", "10")
    assert code == 0
    assert out == "data: the map\n---\n"


def test_service_list_and_call(graph_env: Any, capsys: Any) -> None:
    code, out = eddie(capsys, "service", "list", "-t")
    assert code == 0
    assert "/ping [std_srvs/srv/Trigger]" in out.splitlines()
    assert "/hub/get_parameters [rcl_interfaces/srv/GetParameters]" in out.splitlines()
    code, out = eddie(capsys, "service", "find", "std_srvs/Trigger")
    assert code == 0 and "/ping" in out.splitlines()
    code, out = eddie(capsys, "service", "find", "std_srvs/srv/Trigger", "-c")
    assert code == 0 and int(out) >= 1
    code, out = eddie(capsys, "service", "call", "/ping", "std_srvs/srv/Trigger")
    assert code == 0
    response = yaml.safe_load(out.split("response:\n", 1)[1])
    assert response["success"] is True
    assert response["message"].startswith("pong from ")


def test_param_list_get_set(graph_env: Any, capsys: Any) -> None:
    code, out = eddie(capsys, "param", "list", "/hub")
    assert code == 0
    assert {"label", "speed", "use_sim_time"} <= {line.strip() for line in out.splitlines()}
    code, out = eddie(capsys, "param", "get", "/hub", "label")
    assert (code, out.strip()) == (0, "String value is: eddie")
    code, out = eddie(capsys, "param", "set", "/hub", "speed", "2.0")
    assert (code, out.strip()) == (0, "Set parameter successful")
    code, out = eddie(capsys, "param", "get", "/hub", "speed")
    assert (code, out.strip()) == (0, "Double value is: 2.0")
    code, _ = eddie(capsys, "param", "set", "/hub", "speed", "fast")
    assert code == 1
    code, out = eddie(capsys, "param", "describe", "/hub", "speed")
    assert code == 0 and out.splitlines()[:2] == ["Parameter name: speed", "  Type: double"]
    assert eddie(capsys, "param", "describe", "/hub", "no_such")[0] == 1


def test_param_load_sets_the_nodes_section(graph_env: Any, capsys: Any, tmp_path: Path) -> None:
    params = tmp_path / "hub.yaml"
    params.write_text("/hub:\n  ros__parameters:\n    speed: 3.5\n"
                      "other:\n  ros__parameters:\n    speed: 9.0\n")
    code, out = eddie(capsys, "param", "load", "/hub", str(params))
    assert (code, out.strip()) == (0, "Set parameter speed successful")
    code, out = eddie(capsys, "param", "get", "/hub", "speed")
    assert (code, out.strip()) == (0, "Double value is: 3.5")


def test_action_list_and_send_goal(graph_env: Any, capsys: Any) -> None:
    pytest.importorskip("eddiebot.core.action", reason="needs core.action")
    code, out = eddie(capsys, "action", "list", "-t")
    assert code == 0
    assert "/wait_here [nav2_msgs/action/Wait]" in out.splitlines()
    code, out = eddie(capsys, "action", "info", "/wait_here")
    assert code == 0
    lines = out.splitlines()
    assert lines[0] == "Action: /wait_here" and "Action servers: 1" in lines
    assert "    /hub" in lines
    code, out = eddie(capsys, "action", "send_goal", "/wait_here", "nav2_msgs/action/Wait",
                      "{time: {sec: 2}}", "--feedback", "--timeout", "20")
    assert code == 0, out
    assert "Goal accepted with ID:" in out
    assert "Feedback:" in out
    assert "Goal finished with status: SUCCEEDED" in out
    result = yaml.safe_load(out.split("Result:\n", 1)[1].split("\n\n", 1)[0])
    assert result["total_elapsed_time"]["sec"] == 2


def test_lifecycle_nodes_get_list_set(graph_env: Any, capsys: Any) -> None:
    import threading

    from eddiebot.core import Context, SingleThreadedExecutor
    from eddiebot.core.lifecycle import LifecycleNode
    from eddiebot.transport import connect

    ctx = Context()
    assert connect(ctx, required=True) is not None
    node = LifecycleNode("lc_talker", context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    spinner = threading.Thread(target=ex.spin, daemon=True)
    spinner.start()
    try:
        code, out = eddie(capsys, "lifecycle", "nodes")
        assert code == 0 and "/lc_talker" in out.splitlines()
        assert eddie(capsys, "lifecycle", "get", "/lc_talker") == (0, "unconfigured [1]\n")
        code, out = eddie(capsys, "lifecycle", "list", "lc_talker")
        assert code == 0 and "- configure [1]" in out.splitlines()
        code, out = eddie(capsys, "lifecycle", "set", "/lc_talker", "configure")
        assert (code, out) == (0, "Transitioning successful\n")
        assert eddie(capsys, "lifecycle", "get", "/lc_talker") == (0, "inactive [2]\n")
        assert eddie(capsys, "lifecycle", "set", "/lc_talker", "configure")[0] == 1
    finally:
        ex.shutdown()
        ctx.shutdown()
        spinner.join(5.0)
