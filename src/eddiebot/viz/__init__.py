"""Seeing and keeping what the robot did: rosbag2 recording and playback, and PNG snapshots.

``eddiebot.viz.bag`` records topics to rosbag2 MCAP (``RecorderNode``, ``BagWriter``), plays
bags back on the graph with their original timing (``Player``), summarises them
(``bag_info``) and recovers the readable part of truncated or damaged bags.
``eddiebot.viz.snapshot`` renders maps, trajectories, paths, scans and the robot footprint to
PNG (``render_map``, ``render_bag``). Submodules are imported on use so that importing the
package stays cheap.
"""

__all__ = ["bag", "snapshot"]
