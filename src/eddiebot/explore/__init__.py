"""Autonomous exploration (explore_lite's role): frontiers, their costs, and the node.

The pure core finds frontiers on an occupancy grid (`search_frontiers`: vectorised
extraction, a wavefront for path lengths, a Kinect-shaped information gain, turning),
follows them across map updates (`FrontierTracker`), gives up on the ones that do not pay
(`Blacklist`, `ProgressMonitor`) and picks the next (`choose_frontier`); `ExploreConfig`
carries explore_lite's parameter names and defaults. `eddiebot.explore.node.ExploreNode`
drives it from ``/map`` and TF through ``navigate_to_pose``; `eddiebot.explore.mission`
runs a whole exploration in the simulator and judges it against the world.
"""

from eddiebot.explore.config import EDDIE_EXPLORE_PARAMS, ExploreConfig
from eddiebot.explore.errors import ExploreConfigError, ExploreError, NoWorldError
from eddiebot.explore.frontiers import (
    Frontier,
    FrontierSearch,
    distance_field,
    frontier_cells,
    frontier_cost,
    group_frontier_cells,
    information_gain,
    looked_mask,
    reachable_mask,
    search_frontiers,
)
from eddiebot.explore.tracking import (
    Blacklist,
    BlacklistEntry,
    FrontierTracker,
    ProgressMonitor,
    Track,
    choose_frontier,
)

__all__ = [
    "EDDIE_EXPLORE_PARAMS",
    "Blacklist",
    "BlacklistEntry",
    "ExploreConfig",
    "ExploreConfigError",
    "ExploreError",
    "Frontier",
    "FrontierSearch",
    "FrontierTracker",
    "NoWorldError",
    "ProgressMonitor",
    "Track",
    "choose_frontier",
    "distance_field",
    "frontier_cells",
    "frontier_cost",
    "group_frontier_cells",
    "information_gain",
    "looked_mask",
    "reachable_mask",
    "search_frontiers",
]
