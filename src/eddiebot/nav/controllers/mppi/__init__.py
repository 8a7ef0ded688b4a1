"""Nav2's MPPI controller (``nav2_mppi_controller::MPPIController``, Jazzy) for a DiffDrive
base: the optimiser vectorised with numpy (sequential loops compiled with numba), the eleven
upstream critics with their parameter names and defaults, and the path handler.
"""

from eddiebot.nav.controllers.mppi.config import (
    AckermannConstraintsConfig,
    MPPIConfig,
    TrajectoryVisualizerConfig,
)
from eddiebot.nav.controllers.mppi.controller import (
    MPPIController,
    MPPIParams,
    mppi_known_keys,
    mppi_params,
)
from eddiebot.nav.controllers.mppi.critics import CRITICS, Critic, CriticData
from eddiebot.nav.controllers.mppi.optimizer import Optimizer

__all__ = [
    "CRITICS",
    "AckermannConstraintsConfig",
    "Critic",
    "CriticData",
    "MPPIConfig",
    "MPPIController",
    "MPPIParams",
    "Optimizer",
    "TrajectoryVisualizerConfig",
    "mppi_known_keys",
    "mppi_params",
]
