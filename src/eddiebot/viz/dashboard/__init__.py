"""Web dashboard: the live map, robot, sensors and plans in a browser, with goals and teleop.

`start_dashboard(context, host, port)` serves one page (a plain ``<canvas>``, shipped here,
no external resources; three.js vendored for the 3D view) and one WebSocket from background
threads; a `DashboardNode` in the given context subscribes to the map, costmaps, the vSLAM
grid and graph, TF, scan, ranges, plans and the controller's lookahead, AMCL's particles,
images, point clouds (only while a 3D view is open), odometry, battery, collisions, the
velocity mux's inputs, ``/rosout`` and the explore node's ``explore/status``, and publishes
goals, initial poses, teleop and the e-stop lock, and starts, pauses and resumes exploring
(``explore/resume``: "Map this floor"). Occupancy grids travel as tiles and only changed tiles are re-sent. Loopback by
default; other binds need a token (see `eddiebot.viz.dashboard.server`).
"""

from eddiebot.viz.dashboard.core import Command, GridMeta, TileCache, TokenBucket, parse_command
from eddiebot.viz.dashboard.errors import CommandError, DashboardError, RateLimitedError
from eddiebot.viz.dashboard.hub import Hub
from eddiebot.viz.dashboard.node import DashboardNode, DashboardTopics
from eddiebot.viz.dashboard.server import (
    DashboardConfig,
    DashboardHandle,
    create_app,
    is_loopback,
    start_dashboard,
)

__all__ = [
    "Command",
    "CommandError",
    "DashboardConfig",
    "DashboardError",
    "DashboardHandle",
    "DashboardNode",
    "DashboardTopics",
    "GridMeta",
    "Hub",
    "RateLimitedError",
    "TileCache",
    "TokenBucket",
    "create_app",
    "is_loopback",
    "parse_command",
    "start_dashboard",
]
