"""``nav2_mppi_controller::MPPIController``: plugin API, parameter loading and the audit of
an upstream parameter block.

Parameters arrive as Nav2 writes them under the controller's instance name: flat optimiser
keys, ``critics: [...]`` and one block per critic (``CostCritic: {cost_weight: ...}``), plus
``TrajectoryVisualizer`` and ``AckermannConstraints`` blocks. Dotted keys
(``CostCritic.cost_weight``) are accepted as well.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from eddiebot.nav.controllers.mppi.config import (
    AckermannConstraintsConfig,
    MPPIConfig,
    TrajectoryVisualizerConfig,
)
from eddiebot.nav.controllers.mppi.critics import CRITICS, Critic
from eddiebot.nav.controllers.mppi.optimizer import Optimizer
from eddiebot.nav.controllers.mppi.path_handler import MPPIPathHandler
from eddiebot.nav.costmap.layered import LayeredCostmap
from eddiebot.nav.errors import UnsupportedPlugin
from eddiebot.nav.params import from_params
from eddiebot.nav.types import Twist2D, as_path, as_pose

F64 = npt.NDArray[np.float64]

_BLOCKS: dict[str, type[Any]] = {
    "TrajectoryVisualizer": TrajectoryVisualizerConfig,
    "AckermannConstraints": AckermannConstraintsConfig,
}


def _fields(cls: type[Any]) -> set[str]:
    return {f.name for f in dataclasses.fields(cls)}


def _nested(params: Mapping[str, Any]) -> dict[str, Any]:
    """Dotted keys (``CostCritic.cost_weight``) folded into blocks."""
    out: dict[str, Any] = {}
    for key, value in params.items():
        head, dot, tail = str(key).partition(".")
        if dot:
            block = out.setdefault(head, {})
            if isinstance(block, dict):
                block.update(_nested({tail: value}))
        elif isinstance(value, Mapping):
            block = out.setdefault(head, {})
            if isinstance(block, dict):
                block.update(_nested(value))
        else:
            out[head] = value
    return out


def _critic_names(value: Any) -> list[str]:
    if isinstance(value, str):
        return value.replace(",", " ").split()
    if isinstance(value, (list, tuple)):
        return [str(v) for v in value]
    return []


def mppi_known_keys(params: Mapping[str, Any]) -> tuple[set[str], dict[str, set[str]]]:
    """What an MPPI block may hold: its flat keys (``plugin`` included) and, per nested block
    (the visualiser, the Ackermann constraints, each critic listed in ``critics`` that
    eddiebot has), the keys of that block. Anything else nothing reads."""
    flat = _fields(MPPIConfig) | {"plugin"}
    nested = {name: _fields(cls) for name, cls in _BLOCKS.items()}
    for name in _critic_names(params.get("critics", [])):
        cls = CRITICS.get(name)
        if cls is not None:
            nested[name] = _fields(cls.Config)
    return flat, nested


@dataclasses.dataclass(frozen=True)
class MPPIParams:
    """A loaded MPPI block: the controller's config, the visualiser's and the critics'."""

    config: MPPIConfig
    visualizer: TrajectoryVisualizerConfig
    ackermann: AckermannConstraintsConfig
    critic_configs: tuple[tuple[str, Any], ...]


def mppi_params(params: Mapping[str, Any] | None = None, server: str = "controller_server",
                name: str = "FollowPath") -> MPPIParams:
    """Typed MPPI parameters from a plugin block; errors name ``<name>.<key>``. A critic
    eddiebot does not have is an :class:`UnsupportedPlugin` on ``<name>.critics``."""
    tree = _nested(params or {})
    flat = {k: v for k, v in tree.items() if not isinstance(v, dict)}
    if isinstance(flat.get("critics"), str):
        flat["critics"] = _critic_names(flat["critics"])
    where = f"{server}.{name}" if server else name
    cfg = from_params(MPPIConfig, flat, server=where)
    blocks = {b: from_params(cls, tree.get(b) if isinstance(tree.get(b), dict) else {},
                             server=f"{where}.{b}") for b, cls in _BLOCKS.items()}
    critics: list[tuple[str, Any]] = []
    for critic in cfg.critics:
        cls = CRITICS.get(critic)
        if cls is None:
            raise UnsupportedPlugin(server, f"{name}.critics", critic,
                                    f"unknown MPPI critic; available: {sorted(CRITICS)}")
        sub = tree.get(critic)
        ccfg = from_params(cls.Config, sub if isinstance(sub, dict) else {},
                           server=f"{where}.{critic}")
        critics.append((critic, ccfg))
    return MPPIParams(cfg, blocks["TrajectoryVisualizer"], blocks["AckermannConstraints"],
                      tuple(critics))


class MPPIController:
    """Nav2's MPPI controller over a DiffDrive model (see :mod:`.optimizer`).

    ``critics`` defaults to ``config.critics`` with each critic's default parameters.
    ``seed`` fixes the noise generator. With ``visualize`` the downsampled candidate
    trajectories (``candidates``, (n, m, 3)) and the optimal one (``optimal``,
    (time_steps, 3)) of the last cycle are kept, in the costmap's global frame.
    """

    def __init__(self, config: MPPIConfig | None = None, critics: Sequence[Critic] | None = None,
                 name: str = "FollowPath", controller_frequency: float = 20.0,
                 seed: int | None = None, visualizer: TrajectoryVisualizerConfig | None = None,
                 server: str = "controller_server") -> None:
        self.config = config or MPPIConfig()
        self.config.validate(f"{server}.{name}")
        self.name = name
        if critics is None:
            critics = [CRITICS[c](None, self.config, c) for c in self.config.critics]
        self.optimizer = Optimizer(self.config, critics, controller_frequency, seed,
                                   f"{server}.{name}")
        self.visualizer = visualizer or TrajectoryVisualizerConfig()
        c = self.config
        self.path_handler = MPPIPathHandler(c.max_robot_pose_search_dist, c.prune_distance,
                                            c.enforce_path_inversion, c.inversion_xy_tolerance,
                                            c.inversion_yaw_tolerance)
        self._plan_src: object = None
        self.goal_dist_tol: float | None = None
        self.transformed_plan = np.zeros((0, 3))
        self.candidates = np.zeros((0, 0, 3))
        self.optimal = np.zeros((0, 3))

    @classmethod
    def from_params(cls, params: Mapping[str, Any] | None = None, name: str = "FollowPath",
                    controller_frequency: float = 20.0, server: str = "controller_server",
                    seed: int | None = None) -> MPPIController:
        p = mppi_params(params, server, name)
        critics = [CRITICS[n](cfg, p.config, n) for n, cfg in p.critic_configs]
        return cls(p.config, critics, name, controller_frequency, seed, p.visualizer, server)

    # --- plugin API --------------------------------------------------------------------
    @property
    def critics(self) -> list[Critic]:
        return self.optimizer.critics

    def set_plan(self, path: npt.ArrayLike) -> None:
        self.path_handler.set_path(as_path(path))

    def reset(self) -> None:
        """A new goal: the optimiser starts over; zone speed limits are kept."""
        self.optimizer.reset(reset_speed_limits=False)

    def set_speed_limit(self, speed_limit: float, percentage: bool) -> None:
        self.optimizer.set_speed_limit(speed_limit, percentage)

    def set_goal_tolerance(self, xy_tolerance: float) -> None:
        self.goal_dist_tol = xy_tolerance

    def compute_velocity_commands(self, pose: npt.ArrayLike, velocity: Twist2D,
                                  path: npt.ArrayLike | None, costmap: LayeredCostmap,
                                  dt: float | None = None) -> Twist2D:
        """One control cycle; ``path`` (when given and new) replaces the plan."""
        if path is not None and path is not self._plan_src:
            self.set_plan(path)
            self._plan_src = path
        p = as_pose(pose)
        goal = self.path_handler.goal()
        plan = self.path_handler.transform_path(p, costmap)
        self.transformed_plan = plan
        cmd = self.optimizer.eval_control(p, velocity, plan, goal, costmap, self.goal_dist_tol)
        if self.config.visualize:
            o = self.optimizer
            v = self.visualizer
            sel = (slice(None, None, v.trajectory_step), slice(None, None, v.time_step))
            self.candidates = np.stack([o.traj_x[sel], o.traj_y[sel], o.traj_yaw[sel]], axis=2)
            self.optimal = o.optimal_trajectory(p)
        return cmd


__all__ = ["MPPIController", "MPPIParams", "mppi_known_keys", "mppi_params"]
