"""The shipped .msg/.srv/.action interfaces: names, split types, references, wire bytes, hashes."""

from __future__ import annotations

import re
import struct
from importlib import resources

import numpy as np
import pytest
from _msgtools import constants, fields
from rosbags.interfaces import Nodetype

from eddiebot.msgs import (
    ACTIONS,
    SERVICES,
    TYPESTORE,
    ActionType,
    ServiceType,
    deserialize,
    get_action,
    get_service,
    serialize,
    type_hash,
)

HDR = b"\x00\x01\x00\x00"  # CDR little-endian encapsulation header

EXPECTED_SERVICES = {
    "std_srvs": ["Empty", "SetBool", "Trigger"],
    "rcl_interfaces": [
        "DescribeParameters",
        "GetParameters",
        "GetParameterTypes",
        "ListParameters",
        "SetParameters",
        "SetParametersAtomically",
    ],
    "lifecycle_msgs": ["ChangeState", "GetState", "GetAvailableStates", "GetAvailableTransitions"],
    "action_msgs": ["CancelGoal"],
    "nav_msgs": ["GetMap", "GetPlan", "SetMap", "LoadMap"],
    "nav2_msgs": [
        "ClearEntireCostmap",
        "ClearCostmapAroundRobot",
        "ClearCostmapExceptRegion",
        "GetCostmap",
        "LoadMap",
        "SaveMap",
        "ManageLifecycleNodes",
        "IsPathValid",
    ],
    "slam_toolbox": [
        "Pause",
        "Reset",
        "Clear",
        "ClearQueue",
        "SaveMap",
        "SerializePoseGraph",
        "DeserializePoseGraph",
        "LoopClosure",
        "ToggleInteractive",
        "MergeMaps",
        "AddSubmap",
    ],
    "eddiebot_msgs": [
        "Accelerate",
        "DriveWithDistance",
        "DriveWithPower",
        "DriveWithSpeed",
        "GetDistance",
        "GetHeading",
        "GetSpeed",
        "GetStatus",
        "ResetEncoder",
        "Rotate",
        "StopAtDistance",
    ],
}
EXPECTED_ACTIONS = {
    "nav2_msgs": [
        "NavigateToPose",
        "NavigateThroughPoses",
        "ComputePathToPose",
        "ComputePathThroughPoses",
        "FollowPath",
        "SmoothPath",
        "FollowWaypoints",
        "Spin",
        "BackUp",
        "DriveOnHeading",
        "Wait",
        "AssistedTeleop",
    ],
}
EXPECTED_MESSAGES = {
    "nav2_msgs": [
        "Costmap",
        "CostmapMetaData",
        "CostmapFilterInfo",
        "SpeedLimit",
        "CollisionMonitorState",
        "Particle",
        "ParticleCloud",
        "BehaviorTreeLog",
        "BehaviorTreeStatusChange",
        "VoxelGrid",
        "MissedWaypoint",
    ],
}
ACTION_SUFFIXES = (
    "_Goal",
    "_Result",
    "_Feedback",
    "_SendGoal_Request",
    "_SendGoal_Response",
    "_GetResult_Request",
    "_GetResult_Response",
    "_FeedbackMessage",
)
SRV_NAMES = [f"{p}/srv/{n}" for p, names in EXPECTED_SERVICES.items() for n in names]
ACTION_NAMES = [f"{p}/action/{n}" for p, names in EXPECTED_ACTIONS.items() for n in names]


# --- presence and splitting -------------------------------------------------------------


@pytest.mark.parametrize("name", SRV_NAMES)
def test_service_split(name: str) -> None:
    srv = SERVICES[name]
    assert isinstance(srv, ServiceType)
    assert srv is get_service(name) is get_service(name.replace("/srv/", "/"))
    assert srv.Request is TYPESTORE.types[f"{name}_Request"]
    assert srv.Response is TYPESTORE.types[f"{name}_Response"]
    assert srv.Request.__msgtype__ == f"{name}_Request"
    assert srv.Response.__msgtype__ == f"{name}_Response"


@pytest.mark.parametrize("name", ACTION_NAMES)
def test_action_split(name: str) -> None:
    for suffix in ACTION_SUFFIXES:
        assert f"{name}{suffix}" in TYPESTORE.types, suffix
    act = ACTIONS[name]
    assert isinstance(act, ActionType)
    assert act is get_action(name) is get_action(name.replace("/action/", "/"))
    assert act.Goal is TYPESTORE.types[f"{name}_Goal"]
    assert act.Result is TYPESTORE.types[f"{name}_Result"]
    assert act.Feedback is TYPESTORE.types[f"{name}_Feedback"]
    assert act.FeedbackMessage is TYPESTORE.types[f"{name}_FeedbackMessage"]
    assert act.SendGoal.Request is TYPESTORE.types[f"{name}_SendGoal_Request"]
    assert act.SendGoal.Response is TYPESTORE.types[f"{name}_SendGoal_Response"]
    assert act.GetResult.Request is TYPESTORE.types[f"{name}_GetResult_Request"]
    assert act.GetResult.Response is TYPESTORE.types[f"{name}_GetResult_Response"]
    # the wrapper types carry the goal id and the right sub-types, as rosidl generates them
    assert fields(f"{name}_SendGoal_Request") == [
        ("goal_id", (Nodetype.NAME, "unique_identifier_msgs/msg/UUID")),
        ("goal", (Nodetype.NAME, f"{name}_Goal")),
    ]
    assert fields(f"{name}_SendGoal_Response") == [
        ("accepted", (Nodetype.BASE, ("bool", 0))),
        ("stamp", (Nodetype.NAME, "builtin_interfaces/msg/Time")),
    ]
    assert fields(f"{name}_GetResult_Request") == [
        ("goal_id", (Nodetype.NAME, "unique_identifier_msgs/msg/UUID")),
    ]
    assert fields(f"{name}_GetResult_Response") == [
        ("status", (Nodetype.BASE, ("int8", 0))),
        ("result", (Nodetype.NAME, f"{name}_Result")),
    ]
    assert fields(f"{name}_FeedbackMessage") == [
        ("goal_id", (Nodetype.NAME, "unique_identifier_msgs/msg/UUID")),
        ("feedback", (Nodetype.NAME, f"{name}_Feedback")),
    ]


@pytest.mark.parametrize(
    "name", [f"{p}/msg/{n}" for p, names in EXPECTED_MESSAGES.items() for n in names]
)
def test_messages_present(name: str) -> None:
    assert name in TYPESTORE.types


def test_every_shipped_file_is_registered() -> None:
    root = resources.files("eddiebot.msgs") / "interfaces"
    count = 0
    for pkg in root.iterdir():
        if not pkg.is_dir():
            continue
        for kind, registry in (("msg", TYPESTORE.types), ("srv", SERVICES), ("action", ACTIONS)):
            folder = pkg / kind
            if not folder.is_dir():
                continue
            for f in folder.iterdir():
                assert f.name.endswith(f".{kind}"), f.name
                assert f"{pkg.name}/{kind}/{f.name[: -len(kind) - 1]}" in registry
                count += 1
    assert count == sum(1 for n in [*SERVICES, *ACTIONS] if _is_shipped(n)) + sum(
        1 for t in TYPESTORE.types if _is_shipped_msg(t)
    )


def _is_shipped(typename: str) -> bool:
    """A service or action of a shipped file (others come from the interface search path)."""
    pkg, kind, name = typename.split("/")
    folder = resources.files("eddiebot.msgs") / "interfaces" / pkg / kind
    return (folder / f"{name}.{kind}").is_file()


def _is_shipped_msg(typename: str) -> bool:
    pkg, kind, name = typename.split("/")
    folder = resources.files("eddiebot.msgs") / "interfaces" / pkg / "msg"
    return kind == "msg" and (folder / f"{name}.msg").is_file()


def test_every_reference_resolves() -> None:
    """Every nested type named anywhere in the store is itself registered."""

    def refs(desc: tuple) -> list[str]:
        kind, detail = desc
        if kind == Nodetype.NAME:
            return [detail]
        if kind in (Nodetype.ARRAY, Nodetype.SEQUENCE):
            return refs(detail[0])
        return []

    missing = {
        (owner, ref)
        for owner, (_, flds) in TYPESTORE.fielddefs.items()
        for _, desc in flds
        for ref in refs(desc)
        if ref not in TYPESTORE.fielddefs
    }
    assert not missing


def test_relative_names_resolve_to_msg_folder() -> None:
    """A bare ``Name`` inside a .srv/.action resolves as ``pkg/msg/Name`` (rosidl rule)."""
    assert dict(fields("rcl_interfaces/srv/GetParameters_Response"))["values"] == (
        Nodetype.SEQUENCE,
        ((Nodetype.NAME, "rcl_interfaces/msg/ParameterValue"), 0),
    )
    assert dict(fields("nav2_msgs/action/FollowWaypoints_Result"))["missed_waypoints"] == (
        Nodetype.SEQUENCE,
        ((Nodetype.NAME, "nav2_msgs/msg/MissedWaypoint"), 0),
    )
    assert dict(fields("lifecycle_msgs/srv/ChangeState_Request"))["transition"] == (
        Nodetype.NAME,
        "lifecycle_msgs/msg/Transition",
    )
    assert dict(fields("action_msgs/srv/CancelGoal_Response"))["goals_canceling"] == (
        Nodetype.SEQUENCE,
        ((Nodetype.NAME, "action_msgs/msg/GoalInfo"), 0),
    )
    assert dict(fields("nav_msgs/srv/GetPlan_Response"))["plan"] == (
        Nodetype.NAME,
        "nav_msgs/msg/Path",
    )


def test_empty_sections_get_placeholder_member() -> None:
    placeholder = [("structure_needs_at_least_one_member", (Nodetype.BASE, ("uint8", 0)))]
    for name in (
        "std_srvs/srv/Empty_Request",
        "std_srvs/srv/Empty_Response",
        "std_srvs/srv/Trigger_Request",
        "lifecycle_msgs/srv/GetState_Request",
        "slam_toolbox/srv/Clear_Response",
        "eddiebot_msgs/srv/ResetEncoder_Request",
        "eddiebot_msgs/srv/Rotate_Response",
        "nav2_msgs/action/ComputePathToPose_Feedback",
        "nav2_msgs/action/SmoothPath_Feedback",
    ):
        assert fields(name) == placeholder, name


# --- definitions checked field by field ---------------------------------------------------

# eddiebot_msgs exactly as ../shared/reference/eddie_hardware.md §2 lists them
EDDIEBOT = {
    "msg/ADC": [("status", "string"), ("value", "uint16[]")],
    "msg/Ping": [("status", "string"), ("value", "uint16[]")],
    "msg/BatteryLevel": [("value", "float64")],
    "msg/Distances": [("value", "uint16[]")],
    "msg/Encoders": [("left", "int32"), ("right", "int32")],
    "msg/KeyStroke": [("keycode", "uint8")],
    "msg/Speech": [("text", "string")],
    "msg/Velocity": [("linear", "float32"), ("angular", "float32")],
    "msg/Voltages": [("value", "float64[]")],
    "srv/Accelerate_Request": [("rate", "uint16")],
    "srv/DriveWithDistance_Request": [("distance", "int16"), ("speed", "uint16")],
    "srv/DriveWithPower_Request": [("left", "int8"), ("right", "int8")],
    "srv/DriveWithSpeed_Request": [("left", "int16"), ("right", "int16")],
    "srv/GetDistance_Response": [("left", "int32"), ("right", "int32")],
    "srv/GetHeading_Response": [("heading", "uint16")],
    "srv/GetSpeed_Response": [("left", "int16"), ("right", "int16")],
    "srv/GetStatus_Response": [("okay", "bool")],
    "srv/Rotate_Request": [("angle", "int16"), ("speed", "uint16")],
    "srv/StopAtDistance_Request": [("distance", "uint16")],
}

# A sample of the upstream Jazzy definitions (field name, type), in order.
UPSTREAM = {
    "std_srvs/srv/SetBool_Request": [("data", "bool")],
    "std_srvs/srv/SetBool_Response": [("success", "bool"), ("message", "string")],
    "std_srvs/srv/Trigger_Response": [("success", "bool"), ("message", "string")],
    "rcl_interfaces/srv/ListParameters_Request": [("prefixes", "string[]"), ("depth", "uint64")],
    "rcl_interfaces/srv/ListParameters_Response": [
        ("result", "rcl_interfaces/msg/ListParametersResult")
    ],
    "rcl_interfaces/srv/GetParameterTypes_Request": [("names", "string[]")],
    "rcl_interfaces/srv/GetParameterTypes_Response": [("types", "uint8[]")],
    "rcl_interfaces/srv/SetParameters_Response": [
        ("results", "rcl_interfaces/msg/SetParametersResult[]")
    ],
    "rcl_interfaces/srv/SetParametersAtomically_Response": [
        ("result", "rcl_interfaces/msg/SetParametersResult")
    ],
    "lifecycle_msgs/srv/ChangeState_Response": [("success", "bool")],
    "lifecycle_msgs/srv/GetState_Response": [("current_state", "lifecycle_msgs/msg/State")],
    "action_msgs/srv/CancelGoal_Response": [
        ("return_code", "int8"),
        ("goals_canceling", "action_msgs/msg/GoalInfo[]"),
    ],
    "nav_msgs/srv/GetPlan_Request": [
        ("start", "geometry_msgs/msg/PoseStamped"),
        ("goal", "geometry_msgs/msg/PoseStamped"),
        ("tolerance", "float32"),
    ],
    "nav_msgs/srv/LoadMap_Response": [("map", "nav_msgs/msg/OccupancyGrid"), ("result", "uint8")],
    "nav2_msgs/action/NavigateToPose_Goal": [
        ("pose", "geometry_msgs/msg/PoseStamped"),
        ("behavior_tree", "string"),
    ],
    "nav2_msgs/action/NavigateToPose_Result": [("error_code", "uint16"), ("error_msg", "string")],
    "nav2_msgs/action/NavigateToPose_Feedback": [
        ("current_pose", "geometry_msgs/msg/PoseStamped"),
        ("navigation_time", "builtin_interfaces/msg/Duration"),
        ("estimated_time_remaining", "builtin_interfaces/msg/Duration"),
        ("number_of_recoveries", "int16"),
        ("distance_remaining", "float32"),
    ],
    "nav2_msgs/action/FollowPath_Goal": [
        ("path", "nav_msgs/msg/Path"),
        ("controller_id", "string"),
        ("goal_checker_id", "string"),
        ("progress_checker_id", "string"),
    ],
    "nav2_msgs/action/FollowPath_Result": [
        ("result", "std_msgs/msg/Empty"),
        ("error_code", "uint16"),
        ("error_msg", "string"),
    ],
    "nav2_msgs/action/ComputePathToPose_Result": [
        ("path", "nav_msgs/msg/Path"),
        ("planning_time", "builtin_interfaces/msg/Duration"),
        ("error_code", "uint16"),
        ("error_msg", "string"),
    ],
    "nav2_msgs/action/Spin_Goal": [
        ("target_yaw", "float32"),
        ("time_allowance", "builtin_interfaces/msg/Duration"),
    ],
    "nav2_msgs/action/BackUp_Goal": [
        ("target", "geometry_msgs/msg/Point"),
        ("speed", "float32"),
        ("time_allowance", "builtin_interfaces/msg/Duration"),
    ],
    "nav2_msgs/action/FollowWaypoints_Goal": [
        ("number_of_loops", "uint32"),
        ("goal_index", "uint32"),
        ("poses", "geometry_msgs/msg/PoseStamped[]"),
    ],
    "nav2_msgs/msg/Costmap": [
        ("header", "std_msgs/msg/Header"),
        ("metadata", "nav2_msgs/msg/CostmapMetaData"),
        ("data", "uint8[]"),
    ],
    "nav2_msgs/msg/CostmapMetaData": [
        ("map_load_time", "builtin_interfaces/msg/Time"),
        ("update_time", "builtin_interfaces/msg/Time"),
        ("layer", "string"),
        ("resolution", "float32"),
        ("size_x", "uint32"),
        ("size_y", "uint32"),
        ("origin", "geometry_msgs/msg/Pose"),
    ],
    "nav2_msgs/msg/SpeedLimit": [
        ("header", "std_msgs/msg/Header"),
        ("percentage", "bool"),
        ("speed_limit", "float64"),
    ],
    "nav2_msgs/srv/ManageLifecycleNodes_Request": [("command", "uint8")],
    "nav2_msgs/srv/SaveMap_Request": [
        ("map_topic", "string"),
        ("map_url", "string"),
        ("image_format", "string"),
        ("map_mode", "string"),
        ("free_thresh", "float32"),
        ("occupied_thresh", "float32"),
    ],
    "slam_toolbox/srv/SaveMap_Request": [("name", "std_msgs/msg/String")],
    "slam_toolbox/srv/SerializePoseGraph_Request": [("filename", "string")],
    "slam_toolbox/srv/DeserializePoseGraph_Request": [
        ("filename", "string"),
        ("match_type", "int8"),
        ("initial_pose", "geometry_msgs/msg/Pose2D"),
    ],
    "slam_toolbox/srv/Pause_Response": [("status", "bool")],
    "slam_toolbox/srv/Reset_Request": [("pause_new_measurements", "bool")],
}

UPSTREAM_CONSTANTS = {
    "rcl_interfaces/srv/ListParameters_Request": {"DEPTH_RECURSIVE": 0},
    "action_msgs/srv/CancelGoal_Response": {
        "ERROR_NONE": 0,
        "ERROR_REJECTED": 1,
        "ERROR_UNKNOWN_GOAL_ID": 2,
        "ERROR_GOAL_TERMINATED": 3,
    },
    "nav2_msgs/srv/ManageLifecycleNodes_Request": {
        "STARTUP": 0,
        "PAUSE": 1,
        "RESUME": 2,
        "RESET": 3,
        "SHUTDOWN": 4,
        "CONFIGURE": 5,
        "CLEANUP": 6,
    },
    "nav2_msgs/action/ComputePathToPose_Result": {
        "NONE": 0,
        "UNKNOWN": 200,
        "INVALID_PLANNER": 201,
        "TF_ERROR": 202,
        "START_OUTSIDE_MAP": 203,
        "GOAL_OUTSIDE_MAP": 204,
        "START_OCCUPIED": 205,
        "GOAL_OCCUPIED": 206,
        "TIMEOUT": 207,
        "NO_VALID_PATH": 208,
    },
    "nav2_msgs/action/FollowPath_Result": {
        "NONE": 0,
        "UNKNOWN": 100,
        "INVALID_CONTROLLER": 101,
        "TF_ERROR": 102,
        "INVALID_PATH": 103,
        "PATIENCE_EXCEEDED": 104,
        "FAILED_TO_MAKE_PROGRESS": 105,
        "NO_VALID_CONTROL": 106,
        "CONTROLLER_TIMED_OUT": 107,
    },
    "nav2_msgs/msg/CollisionMonitorState": {
        "DO_NOTHING": 0,
        "STOP": 1,
        "SLOWDOWN": 2,
        "APPROACH": 3,
        "LIMIT": 4,
    },
    "slam_toolbox/srv/DeserializePoseGraph_Request": {
        "UNSET": 0,
        "START_AT_FIRST_NODE": 1,
        "START_AT_GIVEN_POSE": 2,
        "LOCALIZE_AT_POSE": 3,
    },
}


def _type_str(desc: tuple) -> str:
    kind, detail = desc
    if kind == Nodetype.BASE:
        return str(detail[0])
    if kind == Nodetype.NAME:
        return str(detail)
    inner, size = detail
    suffix = f"[{size}]" if kind == Nodetype.ARRAY else (f"[<={size}]" if size else "[]")
    return _type_str(inner) + suffix


@pytest.mark.parametrize(("name", "expected"), sorted(EDDIEBOT.items()))
def test_eddiebot_msgs_match_hardware_reference(name: str, expected: list) -> None:
    full = f"eddiebot_msgs/{name}"
    assert [(n, _type_str(d)) for n, d in fields(full)] == expected


@pytest.mark.parametrize(("name", "expected"), sorted(UPSTREAM.items()))
def test_upstream_definitions(name: str, expected: list) -> None:
    assert [(n, _type_str(d)) for n, d in fields(name)] == expected


@pytest.mark.parametrize(("name", "expected"), sorted(UPSTREAM_CONSTANTS.items()))
def test_upstream_constants(name: str, expected: dict) -> None:
    assert {c: v for c, _, v in constants(name)} == expected
    cls = TYPESTORE.types[name]
    for const, value in expected.items():
        assert getattr(cls, const) == value


def test_jazzy_action_results_carry_error_code_and_msg() -> None:
    for name in ACTION_NAMES:
        names = [n for n, _ in fields(f"{name}_Result")]
        assert names[-2:] == ["error_code", "error_msg"], name


_DEFAULT_LINE = re.compile(
    r"^\s*([A-Za-z][\w/]*(?:\[[^\]]*\])?)\s+([a-z]\w*)\s+([^#=\s][^#]*?)\s*(#.*)?$"
)


def test_field_default_values_in_files_are_honoured() -> None:
    """Fields written with a default (e.g. ``uint32 goal_index 0``) get that value."""
    root = resources.files("eddiebot.msgs") / "interfaces"
    checked = 0
    for pkg in root.iterdir():
        for kind in ("msg", "srv", "action"):
            folder = pkg / kind
            if not folder.is_dir():
                continue
            for f in folder.iterdir():
                base = f"{pkg.name}/{kind}/{f.name.rsplit('.', 1)[0]}"
                sections = {"msg": [""], "srv": ["_Request", "_Response"]}.get(
                    kind, ["_Goal", "_Result", "_Feedback"]
                )
                part = 0
                for line in f.read_text().splitlines():
                    if line.strip() == "---":
                        part += 1
                        continue
                    m = _DEFAULT_LINE.match(line)
                    if not m:
                        continue
                    typename = base + sections[part]
                    value = getattr(TYPESTORE.types[typename](), m.group(2))
                    literal = m.group(3).strip()
                    expected = {"true": True, "false": False}.get(literal.lower())
                    if expected is None:
                        expected = float(literal) if "." in literal else int(literal, 0)
                    assert value == expected, (typename, m.group(2))
                    checked += 1
    assert checked >= 2  # FollowWaypoints goal_index, slam_toolbox Reset


# --- byte-exact encodings -----------------------------------------------------------------


def test_encoders_bytes() -> None:
    from eddiebot.msgs.eddiebot_msgs import Encoders

    assert serialize(Encoders(left=1, right=-1)) == HDR + struct.pack("<ii", 1, -1)
    assert deserialize(HDR + struct.pack("<ii", 7, -9), "eddiebot_msgs/msg/Encoders").right == -9


def test_empty_request_is_five_bytes() -> None:
    from eddiebot.msgs.std_srvs import Empty

    assert serialize(Empty.Request()) == HDR + b"\x00"
    assert serialize(Empty.Response()) == HDR + b"\x00"
    assert serialize(SERVICES["eddiebot_msgs/srv/ResetEncoder"].Request()) == HDR + b"\x00"


def test_trigger_response_bytes() -> None:
    from eddiebot.msgs.std_srvs import Trigger

    data = serialize(Trigger.Response(success=True, message="ok"))
    # bool, 3 pad bytes, uint32 length incl. NUL, chars, NUL
    assert data == HDR + b"\x01\x00\x00\x00" + b"\x03\x00\x00\x00" + b"ok\x00"


def test_adc_bytes_with_alignment() -> None:
    from eddiebot.msgs.eddiebot_msgs import ADC

    msg = ADC(status="ok", value=np.array([1, 515], dtype=np.uint16))
    data = serialize(msg)
    expected = HDR + struct.pack("<I", 3) + b"ok\x00" + b"\x00" + struct.pack("<IHH", 2, 1, 515)
    assert data == expected
    back = deserialize(data, "eddiebot_msgs/msg/ADC")
    assert back.value.dtype == np.uint16
    assert back.value.tolist() == [1, 515]


def test_velocity_and_battery_bytes() -> None:
    from eddiebot.msgs.eddiebot_msgs import BatteryLevel, Velocity

    assert serialize(Velocity(linear=0.5, angular=-0.25)) == HDR + struct.pack("<ff", 0.5, -0.25)
    assert serialize(BatteryLevel(value=12.5)) == HDR + struct.pack("<d", 12.5)


def test_drive_with_power_request_bytes() -> None:
    req = SERVICES["eddiebot_msgs/srv/DriveWithPower"].Request(left=-100, right=100)
    assert serialize(req) == HDR + struct.pack("<bb", -100, 100)


def test_get_result_request_bytes() -> None:
    act = ACTIONS["nav2_msgs/action/NavigateToPose"]
    goal_id = np.arange(16, dtype=np.uint8)
    req = act.GetResult.Request()
    req.goal_id.uuid = goal_id
    assert serialize(req) == HDR + bytes(range(16))


def test_navigate_to_pose_result_bytes() -> None:
    res = ACTIONS["nav2_msgs/action/NavigateToPose"].Result(error_code=9, error_msg="x")
    assert serialize(res) == HDR + b"\x09\x00" + b"\x00\x00" + struct.pack("<I", 2) + b"x\x00"


# --- type hashes --------------------------------------------------------------------------


def test_twist_type_hash_matches_jazzy() -> None:
    # As reported by `ros2 topic info --verbose` on a Jazzy system for geometry_msgs/msg/Twist.
    assert (
        type_hash("geometry_msgs/msg/Twist")
        == "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a"
    )
    assert (
        type_hash("std_msgs/msg/Header")
        == "RIHS01_f49fb3ae2cf070f793645ff749683ac6b06203e41c891e17701b1cb597ce6a01"
    )


def test_shipped_types_hash() -> None:
    for name in ("nav2_msgs/msg/Costmap", "eddiebot_msgs/msg/Encoders", "nav2_msgs/msg/SpeedLimit"):
        h = type_hash(name)
        assert re.fullmatch(r"RIHS01_[0-9a-f]{64}", h), name


# --- per-package modules ------------------------------------------------------------------


def test_package_modules() -> None:
    from eddiebot.msgs import action_msgs, lifecycle_msgs, nav2_msgs, nav_msgs, rcl_interfaces
    from eddiebot.msgs import slam_toolbox as st
    from eddiebot.msgs.nav2_msgs import Costmap, NavigateToPose

    assert isinstance(NavigateToPose, ActionType)
    assert NavigateToPose.name == "nav2_msgs/action/NavigateToPose"
    assert Costmap.__msgtype__ == "nav2_msgs/msg/Costmap"
    assert isinstance(nav2_msgs.ClearEntireCostmap, ServiceType)
    assert isinstance(st.Pause, ServiceType)
    assert isinstance(rcl_interfaces.GetParameters, ServiceType)
    assert rcl_interfaces.Parameter.__msgtype__ == "rcl_interfaces/msg/Parameter"
    assert isinstance(lifecycle_msgs.ChangeState, ServiceType)
    assert lifecycle_msgs.Transition.__msgtype__ == "lifecycle_msgs/msg/Transition"
    assert isinstance(action_msgs.CancelGoal, ServiceType)
    assert isinstance(nav_msgs.GetMap, ServiceType)
    assert nav_msgs.OccupancyGrid.__msgtype__ == "nav_msgs/msg/OccupancyGrid"
    # nav2_msgs/LoadMap and nav_msgs/LoadMap are distinct types
    assert nav2_msgs.LoadMap.name != nav_msgs.LoadMap.name
    assert "NavigateToPose" in nav2_msgs.__all__
    with pytest.raises(AttributeError):
        _ = nav2_msgs.NoSuchThing
