"""Velocity smoother: step functions against numbers worked out from Nav2's source."""

from __future__ import annotations

import pytest

from eddiebot.nav.errors import ParameterError
from eddiebot.nav.types import Twist2D
from eddiebot.nav.velocity_smoother import (
    OdomSmoother,
    VelocitySmoother,
    VelocitySmootherConfig,
    apply_constraints,
    find_eta_constraint,
    timing_warnings,
)

F = 20.0


def test_find_eta_constraint_cases() -> None:
    # Accelerating (|cmd| >= |curr|, same sign): band +-accel/f = 0.075.
    assert find_eta_constraint(1.0, 2.0, 1.5, -2.0, F) == 1.5 / F / 1.0
    assert find_eta_constraint(-1.0, -2.0, 1.5, -2.0, F) == (-1.5 / F) / -1.0
    # Feasible -> -1.
    assert find_eta_constraint(1.0, 1.05, 1.5, -2.0, F) == -1.0
    assert find_eta_constraint(0.0, 0.0, 1.5, -2.0, F) == -1.0
    # Decelerating: band +-|decel|/f = 0.1.
    assert find_eta_constraint(1.0, 0.0, 1.5, -2.0, F) == pytest.approx(0.1, abs=0)
    # Sign change counts as decelerating for the whole step.
    assert find_eta_constraint(0.5, -0.5, 1.5, -2.0, F) == (-2.0 / F) / -1.0
    assert find_eta_constraint(-1.0, 2.0, 0.1, -1.0, F) == (1.0 / F) / 3.0
    # Zero band: eta 0 (ignored by the caller).
    assert find_eta_constraint(0.0, 1.0, 0.0, 0.0, F) == 0.0


def test_apply_constraints_cases() -> None:
    assert apply_constraints(1.0, 2.0, 1.5, -2.0, 1.0, F) == 1.0 + 1.5 / F
    assert apply_constraints(1.0, 2.0, 1.5, -2.0, 0.5, F) == 1.0 + 1.5 / F
    assert apply_constraints(1.0, 2.0, 1.5, -2.0, 0.05, F) == 1.0 + 0.05
    assert apply_constraints(1.0, 1.05, 1.5, -2.0, 1.0, F) == 1.0 + (1.05 - 1.0)
    assert apply_constraints(1.0, 0.0, 1.5, -2.0, 1.0, F) == 1.0 + (-2.0 / F)
    assert apply_constraints(0.0, 1.0, 0.0, 0.0, 1.0, F) == 0.0


def test_zero_crossing_uses_decel_then_accel() -> None:
    v = -1.0
    for _ in range(20):
        v = apply_constraints(v, 2.0, 0.1, -1.0, 1.0, F)
    # 20 steps of +0.05 from -1.0 land just above zero (3.19e-16), as upstream's tests rely on.
    assert 0.0 < v < 1e-15
    v2 = apply_constraints(v, 2.0, 0.1, -1.0, 1.0, F)
    assert v2 == pytest.approx(v + 0.005, abs=1e-15)


def test_scale_velocities_keeps_direction() -> None:
    cfg = VelocitySmootherConfig(scale_velocities=True)
    vs = VelocitySmoother(cfg)
    vs.set_command(Twist2D(1.0, 0.0, 1.0), 0)
    out = vs.tick(50_000_000)
    assert out is not None
    # vx clamped to 0.5; eta(vx) = 0.125/0.5 = 0.25, eta(wz) = 0.16/1.0 = 0.16 -> 0.16 wins.
    assert out.vx == pytest.approx(0.08)
    assert out.wz == pytest.approx(0.16)
    assert out.wz / out.vx == pytest.approx(1.0 / 0.5)


def test_timeout_ramps_down_then_goes_silent() -> None:
    vs = VelocitySmoother(VelocitySmootherConfig())
    vs.set_command(Twist2D(0.5, 0.0, 0.0), 0)
    outs = []
    for k in range(1, 30):
        outs.append(vs.tick(k * 50_000_000))
    vx = [o.vx if o is not None else None for o in outs]
    assert vx[:4] == pytest.approx([0.125, 0.25, 0.375, 0.5])
    # Ticks 1..20 are within velocity_timeout (1.0 s); tick 21 (1.05 s) starts the ramp.
    assert vx[19] == pytest.approx(0.5)
    assert vx[20:24] == pytest.approx([0.375, 0.25, 0.125, 0.0])
    assert vx[23] == 0.0
    assert all(v is None for v in vx[24:])


def test_deadband_does_not_feed_back() -> None:
    vs = VelocitySmoother(VelocitySmootherConfig(deadband_velocity=(0.2, 0.0, 0.0)))
    vs.set_command(Twist2D(0.5, 0.0, 0.0), 0)
    out = vs.tick(50_000_000)
    assert out is not None and out.vx == 0.0
    assert vs.last_command.vx == pytest.approx(0.125)
    out = vs.tick(100_000_000)
    assert out is not None and out.vx == pytest.approx(0.25)


def test_nan_command_ignored_and_no_output_before_command() -> None:
    vs = VelocitySmoother()
    assert vs.tick(0) is None
    assert not vs.set_command(Twist2D(float("nan"), 0.0, 0.0), 0)
    assert vs.tick(50_000_000) is None


def test_closed_loop_uses_odometry_average() -> None:
    vs = VelocitySmoother(VelocitySmootherConfig(feedback="CLOSED_LOOP"))
    vs.set_odometry(Twist2D(0.2, 0.0, 0.0), 0)
    vs.set_odometry(Twist2D(0.4, 0.0, 0.0), 50_000_000)
    vs.set_command(Twist2D(0.5, 0.0, 0.0), 50_000_000)
    out = vs.tick(60_000_000)
    assert out is not None and out.vx == pytest.approx(0.3 + 0.125)


def test_odom_smoother_window() -> None:
    od = OdomSmoother(0.3)
    expected = [1.0, 1.5, 2.0, 3.5, 5.0]
    for stamp, v, e in zip([0.0, 0.1, 0.2, 0.45, 1.0], [1.0, 2.0, 3.0, 4.0, 5.0], expected):
        od.add(Twist2D(v, v, v), round(stamp * 1e9))
        assert od.twist.vx == pytest.approx(e)


def test_validation_names_key_and_timing_warning() -> None:
    with pytest.raises(ParameterError) as exc:
        VelocitySmoother(VelocitySmootherConfig(max_decel=(2.5, 0.0, -3.2)))
    assert exc.value.key == "max_decel" and exc.value.server == "velocity_smoother"
    with pytest.raises(ParameterError):
        VelocitySmootherConfig(feedback="SOMETIMES").validate()
    warn = timing_warnings(VelocitySmootherConfig(smoothing_frequency=0.1), 0.5)
    assert any("exceeds the stale-command timeout" in w for w in warn)
    assert timing_warnings(VelocitySmootherConfig(smoothing_frequency=20.0), 0.5) == []
