"""``nav2_mppi_controller::MPPIController`` parameters: names and code defaults of Jazzy
(``optimizer.cpp``, ``path_handler.cpp``, ``controller.cpp``, ``noise_generator.cpp``)."""

from __future__ import annotations

from dataclasses import dataclass

from eddiebot.nav.params import require

#: Nav2's motion models; eddiebot drives a differential base and integrates only DiffDrive
MOTION_MODELS = ("DiffDrive", "Omni", "Ackermann")


@dataclass(frozen=True)
class TrajectoryVisualizerConfig:
    """``<controller>.TrajectoryVisualizer``: every ``trajectory_step``-th candidate and every
    ``time_step``-th point of it are kept for display when ``visualize`` is on."""

    trajectory_step: int = 5
    time_step: int = 3

    def validate(self, where: str) -> None:
        require(self.trajectory_step >= 1, where, "trajectory_step", self.trajectory_step,
                "must be >= 1")
        require(self.time_step >= 1, where, "time_step", self.time_step, "must be >= 1")


@dataclass(frozen=True)
class AckermannConstraintsConfig:
    """``<controller>.AckermannConstraints`` (read by the Ackermann model only)."""

    min_turning_r: float = 0.2

    def validate(self, where: str) -> None:
        require(self.min_turning_r >= 0.0, where, "min_turning_r", self.min_turning_r,
                "must be >= 0")


@dataclass(frozen=True)
class MPPIConfig:
    """The controller's own parameters (``max_robot_pose_search_dist`` < 0 means half the
    costmap's larger side, upstream's computed default). ``critics`` has no default
    upstream: a controller without critics drives its noise's mean."""

    motion_model: str = "DiffDrive"
    critics: tuple[str, ...] = ()
    iteration_count: int = 1
    batch_size: int = 1000
    time_steps: int = 56
    model_dt: float = 0.05
    vx_std: float = 0.2
    vy_std: float = 0.2
    wz_std: float = 0.4
    vx_max: float = 0.5
    vx_min: float = -0.35
    vy_max: float = 0.5
    wz_max: float = 1.9
    ax_max: float = 3.0
    ax_min: float = -3.0
    ay_max: float = 3.0
    ay_min: float = -3.0
    az_max: float = 3.5
    temperature: float = 0.3
    gamma: float = 0.015
    visualize: bool = False
    retry_attempt_limit: int = 1
    regenerate_noises: bool = False
    open_loop: bool = False
    max_robot_pose_search_dist: float = -1.0
    prune_distance: float = 1.5
    transform_tolerance: float = 0.1
    enforce_path_inversion: bool = False
    inversion_xy_tolerance: float = 0.2
    inversion_yaw_tolerance: float = 0.4

    def validate(self, where: str = "controller_server") -> None:
        require(self.motion_model in MOTION_MODELS, where, "motion_model", self.motion_model,
                "is not valid; valid options are DiffDrive, Omni, or Ackermann")
        require(self.motion_model == "DiffDrive", where, "motion_model", self.motion_model,
                "not supported: eddiebot's MPPI integrates DiffDrive only (a differential "
                "base); Omni and Ackermann are Nav2 models it does not carry")
        require(self.iteration_count >= 1, where, "iteration_count", self.iteration_count,
                "must be >= 1")
        require(self.batch_size >= 1, where, "batch_size", self.batch_size, "must be >= 1")
        require(self.time_steps >= 2, where, "time_steps", self.time_steps, "must be >= 2")
        require(self.model_dt > 0.0, where, "model_dt", self.model_dt, "must be > 0")
        for key in ("vx_std", "wz_std", "vy_std"):
            require(getattr(self, key) > 0.0, where, key, getattr(self, key), "must be > 0")
        require(self.temperature > 0.0, where, "temperature", self.temperature, "must be > 0")
        require(self.vx_min <= self.vx_max, where, "vx_min", self.vx_min,
                "must be <= vx_max")
        require(self.wz_max >= 0.0, where, "wz_max", self.wz_max, "must be >= 0")
        require(self.az_max >= 0.0, where, "az_max", self.az_max, "must be >= 0")
        require(self.retry_attempt_limit >= 0, where, "retry_attempt_limit",
                self.retry_attempt_limit, "must be >= 0")
        require(self.prune_distance > 0.0, where, "prune_distance", self.prune_distance,
                "must be > 0")

    def normalized(self) -> MPPIConfig:
        """Upstream's sign fixes: ``ax_max`` taken as |ax_max|, a positive ``ax_min`` or
        ``ay_min`` negated (upstream warns, then drives with the negated value)."""
        from dataclasses import replace

        return replace(self, ax_max=abs(self.ax_max),
                       ax_min=-self.ax_min if self.ax_min > 0.0 else self.ax_min,
                       ay_min=-self.ay_min if self.ay_min > 0.0 else self.ay_min)


__all__ = [
    "MOTION_MODELS",
    "AckermannConstraintsConfig",
    "MPPIConfig",
    "TrajectoryVisualizerConfig",
]
