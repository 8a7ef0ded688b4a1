"""``nav2_smoother::SavitzkyGolaySmoother``: filter output on a zig-zag, refinement, segments."""

from __future__ import annotations

import math

import numpy as np
import pytest

from eddiebot.nav.errors import ParameterError, UnsupportedPlugin
from eddiebot.nav.smoother import (
    SavitzkyGolaySmoother,
    SavitzkyGolaySmootherConfig,
    build_smoother,
)


def _zigzag(n: int) -> np.ndarray:
    i = np.arange(n)
    # 0.1 m steps, 0.05 m teeth (a 90° zig-zag would split into cusp segments on rounding)
    return np.stack([0.1 * i, 0.05 * (i % 2), np.zeros(n)], axis=1)


def test_one_pass_on_a_zigzag() -> None:
    path = _zigzag(30)
    out = SavitzkyGolaySmoother(SavitzkyGolaySmootherConfig(do_refinement=False)).smooth(path).path
    # Interior: (-2, 3, 6, 7, 6, 3, -2)/21 over 0/0.05 alternating heights.
    assert out[10, 1] == pytest.approx(0.05 * 8 / 21)
    assert out[11, 1] == pytest.approx(0.05 * 13 / 21)
    np.testing.assert_allclose(out[3:27, 0], path[3:27, 0], atol=1e-12)  # lines are kept
    # Pose 1's window is padded with pose 0 three times: x (0.7+1.2+0.9-0.8)/21, y 0.5/21.
    assert out[1, 0] == pytest.approx(2.0 / 21) and out[1, 1] == pytest.approx(0.5 / 21)
    np.testing.assert_array_equal(out[0, :2], path[0, :2])
    np.testing.assert_array_equal(out[-1, :2], path[-1, :2])
    # Headings face the next point; the last keeps its own.
    d = out[11, :2] - out[10, :2]
    assert out[10, 2] == pytest.approx(math.atan2(d[1], d[0]))
    assert out[-1, 2] == 0.0


def test_refinement_passes_attenuate_the_zigzag() -> None:
    path = _zigzag(30)
    out = SavitzkyGolaySmoother().smooth(path).path  # do_refinement, refinement_num 2
    # Three passes; the alternating part is scaled by 5/21 per pass about its mean 0.025.
    assert out[14, 1] == pytest.approx(0.025 - 0.025 * (5 / 21) ** 3)
    assert out[15, 1] == pytest.approx(0.025 + 0.025 * (5 / 21) ** 3)
    once = SavitzkyGolaySmoother(SavitzkyGolaySmootherConfig(refinement_num=0)).smooth(path)
    assert once.path[14, 1] == pytest.approx(0.025 - 0.025 * 5 / 21)
    assert once.converged


def test_segments_split_at_cusps_and_short_ones_untouched() -> None:
    fwd = _zigzag(15)
    back = fwd[-2::-1].copy()
    back[:, 2] = 0.0  # reversing: heading stays +x while moving -x
    short = np.concatenate([fwd[:6], fwd[4::-1]])
    out = SavitzkyGolaySmoother().smooth(np.concatenate([fwd, back])).path
    assert out.shape == (29, 3)
    np.testing.assert_array_equal(out[14, :2], fwd[14, :2])  # the cusp is a fixed end
    assert abs(out[7, 1] - 0.025) < 0.005 and abs(out[21, 1] - 0.025) < 0.005
    # The reversing segment faces backwards: +x heading while it moves towards -x.
    assert abs(math.remainder(out[20, 2], 2 * math.pi)) < 0.5
    np.testing.assert_array_equal(SavitzkyGolaySmoother().smooth(short).path, short)


def test_built_from_nav2_params() -> None:
    sg = build_smoother("sg", {"plugin": "nav2_smoother/SavitzkyGolaySmoother",
                               "do_refinement": False, "refinement_num": 5})
    assert isinstance(sg, SavitzkyGolaySmoother)
    assert sg.config == SavitzkyGolaySmootherConfig(do_refinement=False, refinement_num=5)
    with pytest.raises(ParameterError, match="refinement_num"):
        build_smoother("sg", {"plugin": "nav2_smoother::SavitzkyGolaySmoother",
                              "refinement_num": -1})
    with pytest.raises(UnsupportedPlugin, match="NoSuchSmoother"):
        build_smoother("c", {"plugin": "nav2_smoother::NoSuchSmoother"})
