"""Nav2 Jazzy's behaviour trees (the 12 of nav2_bt_navigator's ``behavior_trees/``), shipped
unchanged in ``behavior_trees/``.

``default_nav_to_pose_bt_xml`` defaults to ``navigate_to_pose_w_replanning_and_recovery.xml``
and ``default_nav_through_poses_bt_xml`` to
``navigate_through_poses_w_replanning_and_recovery.xml``, as in Nav2 Jazzy. A tree path
that does not exist is looked up here by its file name when it is relative or points into
a ``nav2_bt_navigator`` folder (a path written for a ROS install), so
``behavior_tree: follow_point.xml`` in a goal works, and so does
``/opt/ros/jazzy/share/nav2_bt_navigator/behavior_trees/follow_point.xml``.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["DEFAULT_TREES", "TREES_DIR", "resolve_tree_path"]

TREES_DIR = Path(__file__).resolve().parent / "behavior_trees"
DEFAULT_TREES = {
    "navigate_to_pose": TREES_DIR / "navigate_to_pose_w_replanning_and_recovery.xml",
    "navigate_through_poses": TREES_DIR / "navigate_through_poses_w_replanning_and_recovery.xml",
}


def resolve_tree_path(path: str) -> Path:
    """``path`` as given, or the shipped tree of that file name when ``path`` does not
    exist and is relative or names a ``nav2_bt_navigator`` folder (the caller reports a
    missing file)."""
    p = Path(path).expanduser()
    if p.is_file():
        return p
    if p.is_absolute() and "nav2_bt_navigator" not in p.parts:
        return p
    shipped = TREES_DIR / p.name
    return shipped if shipped.is_file() else p
