"""Nav2's default behaviour trees, shipped as Nav2 writes them (``behavior_trees/``).

``default_nav_to_pose_bt_xml`` defaults to ``navigate_to_pose_w_replanning_and_recovery.xml``
and ``default_nav_through_poses_bt_xml`` to
``navigate_through_poses_w_replanning_and_recovery.xml``, as in Nav2 Jazzy. A tree path
that is not absolute and not found from the working directory is looked up here, so
``behavior_tree: navigate_to_pose_w_replanning_and_recovery.xml`` in a goal works too.
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
    exist and is not absolute (the caller reports a missing file)."""
    p = Path(path).expanduser()
    if p.is_file() or p.is_absolute():
        return p
    shipped = TREES_DIR / p.name
    return shipped if shipped.is_file() else p
