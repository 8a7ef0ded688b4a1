"""rmw_zenoh's configuration variables carry over; our EDDIE_* names stay as aliases."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from eddiebot.transport.config import ZenohConfig, parse_config_override


def test_override_pairs_split_on_semicolons_outside_brackets_and_quotes() -> None:
    text = 'mode="client";connect/endpoints=["tcp/10.0.0.2:7447";"tcp/10.0.0.3:7447"];' \
           'scouting/multicast/enabled=false;'
    assert parse_config_override(text) == [
        ("mode", '"client"'),
        ("connect/endpoints", '["tcp/10.0.0.2:7447";"tcp/10.0.0.3:7447"]'),
        ("scouting/multicast/enabled", "false"),
    ]
    assert parse_config_override('metadata={"a": "x;y"}') == [("metadata", '{"a": "x;y"}')]
    assert parse_config_override("") == []


def test_an_override_item_without_a_value_is_named() -> None:
    with pytest.raises(ValueError, match=r"item 2 \('connect/endpoints'\) is not key=value"):
        parse_config_override('mode="client";connect/endpoints')


def test_defaults_stay_on_loopback() -> None:
    cfg = ZenohConfig.from_env({})
    session, router = cfg.session_settings(), cfg.router_settings()
    assert session["listen/endpoints"] == ["tcp/127.0.0.1:0"]
    assert router["listen/endpoints"] == ["tcp/127.0.0.1:7447"]
    assert session["scouting/multicast/enabled"] is False
    assert cfg.overrides == [] and not cfg.customised


def test_rmw_zenoh_variables_win_over_their_aliases(tmp_path: Path) -> None:
    ours, theirs = tmp_path / "ours.json5", tmp_path / "theirs.json5"
    cfg = ZenohConfig.from_env({
        "EDDIE_ZENOH_CONFIG": str(ours), "ZENOH_SESSION_CONFIG_URI": str(theirs),
        "EDDIE_ZENOH_ROUTER_CONFIG": str(ours),
    })
    assert cfg.config_file == str(theirs)
    assert cfg.router_config_file == str(ours)  # the alias alone still works
    assert ZenohConfig.from_env({"ZENOH_ROUTER_CONFIG_URI": str(theirs)}).router_config_file \
        == str(theirs)


def test_overrides_apply_to_the_built_in_session_and_router_configs() -> None:
    cfg = ZenohConfig.from_env({
        "ZENOH_CONFIG_OVERRIDE": 'mode="client";connect/endpoints=["tcp/192.168.1.20:7447"]',
    })
    assert cfg.customised
    session = cfg.session_config()
    assert json.loads(session.get_json("mode")) == "client"
    assert json.loads(session.get_json("connect/endpoints")) == ["tcp/192.168.1.20:7447"]
    # everything not overridden keeps our loopback defaults
    assert json.loads(session.get_json("listen/endpoints")) == ["tcp/127.0.0.1:0"]
    router = cfg.router_config()
    assert json.loads(router.get_json("connect/endpoints")) == ["tcp/192.168.1.20:7447"]
    assert cfg.effective_settings()["mode"] == "client"


def test_overrides_apply_on_top_of_a_config_file(tmp_path: Path) -> None:
    file = tmp_path / "session.json5"
    file.write_text('{ mode: "peer", listen: { endpoints: ["tcp/127.0.0.1:0"] } }')
    cfg = ZenohConfig.from_env({"ZENOH_SESSION_CONFIG_URI": str(file),
                                "ZENOH_CONFIG_OVERRIDE": "scouting/multicast/enabled=false"})
    session = cfg.session_config()
    assert json.loads(session.get_json("mode")) == "peer"
    assert json.loads(session.get_json("scouting/multicast/enabled")) is False


def test_bad_override_and_missing_file_say_what_and_where(tmp_path: Path) -> None:
    cfg = ZenohConfig.from_env({"ZENOH_CONFIG_OVERRIDE": "no/such/key=1"})
    with pytest.raises(ValueError, match="ZENOH_CONFIG_OVERRIDE: cannot set no/such/key to 1"):
        cfg.session_config()
    missing = tmp_path / "nope.json5"
    cfg = ZenohConfig.from_env({"ZENOH_SESSION_CONFIG_URI": str(missing)})
    with pytest.raises(ValueError, match=f"ZENOH_SESSION_CONFIG_URI: no Zenoh config file at {missing}"):
        cfg.session_config()
