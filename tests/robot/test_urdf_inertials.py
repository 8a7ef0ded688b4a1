"""Eddie's URDF carries a physically valid inertial on every body link."""

from __future__ import annotations

import io

import numpy as np
import pytest

from eddiebot.robot.constants import WHEEL_RADIUS_M
from eddiebot.robot.urdf import FRAME_LINKS, eddie_urdf, link_inertials

yourdfpy = pytest.importorskip("yourdfpy")

#: PLAT "Additional Specifications": weight 11.5 kg
EDDIE_MASS_KG = 11.5


def _links() -> dict[str, object]:
    robot = yourdfpy.URDF.load(io.StringIO(eddie_urdf()), build_scene_graph=False,
                               load_meshes=False, build_collision_scene_graph=False)
    return {link.name: link for link in robot.robot.links}


def test_every_body_link_has_a_valid_inertial():
    links = _links()
    assert links.keys() >= FRAME_LINKS
    bodies = links.keys() - FRAME_LINKS
    assert len(bodies) == 22  # 17 parts and 5 range sensors
    for name in FRAME_LINKS:
        assert links[name].inertial is None, name
    for name in sorted(bodies):
        inertial = links[name].inertial
        assert inertial is not None, name
        assert inertial.mass > 0.0, name
        inertia = np.asarray(inertial.inertia, dtype=float)
        assert np.allclose(inertia, inertia.T), name
        moments = np.linalg.eigvalsh(inertia)
        assert moments.min() > 0.0, name  # positive definite
        a, b, c = moments
        # triangle inequality of the principal moments (with a little float slack)
        assert a + b >= c * (1 - 1e-9) and a + c >= b and b + c >= a, name


def test_total_mass_matches_the_platform_guide():
    total = sum(link.inertial.mass for link in _links().values() if link.inertial is not None)
    assert total == pytest.approx(sum(i.mass for i in link_inertials().values()))
    assert abs(total - EDDIE_MASS_KG) <= 0.1 * EDDIE_MASS_KG
    assert total == pytest.approx(11.37, abs=0.01)


def test_inertia_formulas_with_numbers():
    parts = link_inertials()
    wheel = parts["left_wheel_link"]  # solid cylinder along y
    assert wheel.iyy == pytest.approx(0.45 * WHEEL_RADIUS_M**2 / 2)
    assert wheel.ixx == wheel.izz == pytest.approx(0.45 * (3 * WHEEL_RADIUS_M**2 + 0.0254**2) / 12)
    battery = parts["battery_box"]  # solid box
    assert battery.izz == pytest.approx(4.5 * (0.1778**2 + 0.3366**2) / 12)
    caster = parts["front_caster"]  # solid sphere
    assert caster.ixx == caster.iyy == caster.izz == pytest.approx(0.4 * 0.1 * 0.05**2)
    # the wheel radius flows into the wheels' inertia
    big = link_inertials(wheel_radius=0.1)["right_wheel_link"]
    assert big.iyy == pytest.approx(0.45 * 0.1**2 / 2)
    urdf = eddie_urdf(wheel_radius=0.1)
    assert f'iyy="{0.45 * 0.1**2 / 2:.6g}"' in urdf
