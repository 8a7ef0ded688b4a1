"""UMBmark recovers the wheel-diameter ratio and separation error of a simulated robot."""

import math

import pytest

from eddiebot.base.calibration import umbmark
from eddiebot.base.odometry import integrate_arc


def run_square(direction: int, side: float, b_true: float, b_nominal: float, ed: float) -> tuple[float, float]:
    """Where a robot with true separation/diameter ratio ends after a square commanded with
    nominal values (dead-reckoned by its controller), in the start frame."""
    x = y = th = 0.0
    dl_scale = 2 / (ed + 1)
    dr_scale = 2 / (1 / ed + 1)
    for _ in range(4):
        # straight: both wheels command `side` (nominal), true travels differ
        for _ in range(100):
            x, y, th = integrate_arc(x, y, th, side / 100 * dl_scale, side / 100 * dr_scale, b_true)
        # turn 90° in place as computed with the nominal separation
        arc = direction * math.pi / 2 * b_nominal / 2
        for _ in range(100):
            x, y, th = integrate_arc(x, y, th, -arc / 100 * dl_scale, arc / 100 * dr_scale, b_true)
    return x, y


def test_recovers_separation_and_diameter_ratio():
    side, b_nom, b_true, ed_true = 2.0, 0.39, 0.394, 1.004
    cw = [run_square(-1, side, b_true, b_nom, ed_true)]
    ccw = [run_square(+1, side, b_true, b_nom, ed_true)]
    r = umbmark(cw, ccw, side, b_nom)
    assert r.eb == pytest.approx(b_true / b_nom, rel=2e-3)
    assert r.ed == pytest.approx(ed_true, rel=2e-3)
    assert r.left_wheel_radius_multiplier * r.ed == pytest.approx(r.right_wheel_radius_multiplier)


def test_perfect_robot_and_bad_input():
    side = 1.0
    cw = [run_square(-1, side, 0.39, 0.39, 1.0)]
    ccw = [run_square(+1, side, 0.39, 0.39, 1.0)]
    r = umbmark(cw, ccw, side, 0.39)
    assert r.eb == pytest.approx(1.0, abs=1e-6) and r.ed == pytest.approx(1.0, abs=1e-6)
    with pytest.raises(ValueError, match="at least one"):
        umbmark([], ccw, side, 0.39)


def test_calibrate_refines_the_existing_file_for_odometry_and_driver(tmp_path):
    import argparse

    import yaml

    from eddiebot.cli import calibrate

    errors = tmp_path / "errors.yaml"
    errors.write_text("cw: [[0.05, -0.08]]\nccw: [[0.04, 0.06]]\n")
    out = tmp_path / "calibration.yaml"
    out.write_text(yaml.safe_dump({"eddie_odom": {"ros__parameters": {
        "wheel_separation_multiplier": 1.02, "left_wheel_radius_multiplier": 0.99,
        "right_wheel_radius_multiplier": 1.01}}}))
    args = argparse.Namespace(errors=errors, side=2.0, output=out, port="/dev/null")
    assert calibrate.run(args) == 0
    first = yaml.safe_load(out.read_text())
    fresh = tmp_path / "fresh.yaml"
    args.output = fresh
    assert calibrate.run(args) == 0
    alone = yaml.safe_load(fresh.read_text())["eddie_odom"]["ros__parameters"]
    refined = first["eddie_odom"]["ros__parameters"]
    assert first["eddie"] == first["eddie_odom"]  # the driver gets the same factors
    assert refined["wheel_separation_multiplier"] == pytest.approx(
        1.02 * alone["wheel_separation_multiplier"], rel=1e-5)
    assert refined["left_wheel_radius_multiplier"] == pytest.approx(
        0.99 * alone["left_wheel_radius_multiplier"], rel=1e-5)


def test_calibrate_names_a_missing_port_before_asking_anything(tmp_path, capsys):
    import argparse

    from eddiebot.cli import calibrate

    args = argparse.Namespace(errors=None, side=2.0, output=tmp_path / "c.yaml",
                              port=str(tmp_path / "ttyUSB9"), runs=1, speed=0.2)
    assert calibrate.run(args) == 2
    err = capsys.readouterr().err
    assert "ttyUSB9" in err and "Traceback" not in err
