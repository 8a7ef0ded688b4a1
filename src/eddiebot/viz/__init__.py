"""Seeing what the robot did: the web dashboard, the Foxglove bridge and PNG snapshots.

``eddiebot.viz.snapshot`` renders maps, trajectories, paths, scans and the robot footprint to
PNG (``render_map``, ``render_bag``; bags are read with ``eddiebot.bag``).
``eddiebot.viz.dashboard`` serves the browser dashboard and ``eddiebot.viz.foxglove_bridge``
speaks the Foxglove WebSocket protocol. Submodules are imported on use so that importing the
package stays cheap.
"""

__all__ = ["snapshot"]
