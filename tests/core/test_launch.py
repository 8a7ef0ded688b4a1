"""Launch files: arguments, substitutions, parameter files and their errors."""

import logging
import textwrap

import pytest

from eddiebot.core import Context, SingleThreadedExecutor
from eddiebot.core.errors import ParameterFileError
from eddiebot.core.launch import LaunchError, build_nodes, parse_cli_args, parse_launch_file
from eddiebot.core.parameters import load_parameter_file
from eddiebot.registry import NODES


def write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(textwrap.dedent(text))
    return p


def test_launch_with_args_params_and_remaps(tmp_path):
    params = write(tmp_path, "p.yaml", """
        talker:
          ros__parameters:
            text: from-file
        """)
    launch = write(tmp_path, "demo.yaml", f"""
        launch:
          - arg: {{name: period, default: "0.5"}}
          - arg: {{name: ns, default: robot}}
          - node:
              type: eddiebot.demo.talker
              namespace: $(var ns)
              param:
                - {{from: {params}}}
                - {{name: period, value: $(var period)}}
              remap:
                - {{from: chatter, to: /shared}}
          - node:
              pkg: eddiebot
              exec: demo.listener
              remap:
                - {{from: chatter, to: /shared}}
        """)
    desc = parse_launch_file(launch, parse_cli_args(["period:=0.25"]))
    assert desc.args == {"period": "0.25", "ns": "robot"}
    ctx = Context(use_sim_time=True)
    talker, listener = build_nodes(desc, ctx, NODES)
    assert talker.fully_qualified_name == "/robot/talker"
    assert talker.get_parameter("period").value == 0.25
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(talker)
    ex.add_node(listener)
    ex.spin_for(1.0)
    assert listener.received == [f"from-file: {i}" for i in range(1, 5)]
    ctx.shutdown()


def test_unknown_key_names_file_line_node_and_key(tmp_path):
    params = write(tmp_path, "p.yaml", """
        talker:
          ros__parameters:
            period: 0.5
            perod: 0.1
        """)
    launch = write(tmp_path, "l.yaml", f"""
        launch:
          - node: {{type: eddiebot.demo.talker, param: [{{from: {params}}}]}}
        """)
    with pytest.raises(LaunchError) as err:
        build_nodes(parse_launch_file(launch), Context(), NODES)
    msg = str(err.value)
    assert f"{params}:5" in msg and "/talker" in msg and "perod" in msg


def test_wrong_type_and_unknown_node(tmp_path, caplog):
    params = write(tmp_path, "p.yaml", """
        talker:
          ros__parameters:
            period: fast
        """)
    launch = write(tmp_path, "l.yaml", f"""
        launch:
          - node: {{type: eddiebot.demo.talker, param: [{{from: {params}}}]}}
        """)
    with pytest.raises(LaunchError) as err:
        build_nodes(parse_launch_file(launch), Context(), NODES)
    assert f"{params}:4" in str(err.value) and "period" in str(err.value)
    other = write(tmp_path, "o.yaml", """
        talker:
          ros__parameters: {period: 1.0}
        plannr_server:
          ros__parameters: {x: 1}
        """)
    launch2 = write(tmp_path, "l2.yaml", f"""
        launch:
          - node: {{type: eddiebot.demo.talker, param: [{{from: {other}}}]}}
        """)
    # a section for a node this launch does not run is named, not fatal (a Nav2 user's file
    # carries sections for servers the launch may not run)
    with caplog.at_level(logging.WARNING, logger="eddiebot.core.launch"):
        nodes = build_nodes(parse_launch_file(launch2), Context(), NODES)
    assert [n.get_name() for n in nodes] == ["talker"]
    named = [r.getMessage() for r in caplog.records if "plannr_server" in r.getMessage()]
    assert len(named) == 1 and f"{other}:5" in named[0] and "not launched" in named[0]


def test_malformed_yaml_and_bad_entries(tmp_path):
    bad = write(tmp_path, "bad.yaml", "talker:\n  ros__parameters: {period: [1, 2\n")
    with pytest.raises(ParameterFileError, match=str(bad)):
        load_parameter_file(bad)
    launch = write(tmp_path, "l.yaml", """
        launch:
          - node: {type: eddiebot.nope}
        """)
    with pytest.raises(LaunchError, match="unknown node type"):
        build_nodes(parse_launch_file(launch), Context(), NODES)
    launch = write(tmp_path, "l3.yaml", """
        launch:
          - arg: {name: port}
        """)
    with pytest.raises(LaunchError, match="port:=VALUE"):
        parse_launch_file(launch)
    with pytest.raises(LaunchError, match="unknown launch arguments"):
        parse_launch_file(write(tmp_path, "l4.yaml", "launch:\n  - arg: {name: a, default: 1}\n"),
                          {"b": "2"})


def test_wildcard_and_nested_parameters(tmp_path):
    f = write(tmp_path, "p.yaml", """
        /**:
          ros__parameters:
            use_sim_time: true
        controller_server:
          ros__parameters:
            FollowPath:
              desired_linear_vel: 0.4
        """)
    pf = load_parameter_file(f)
    names = {(o.node_pattern, o.name, o.value) for o in pf.overrides}
    assert ("/**", "use_sim_time", True) in names
    assert ("controller_server", "FollowPath.desired_linear_vel", 0.4) in names
