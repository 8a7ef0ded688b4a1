"""Fixtures for the navigation tests."""

from __future__ import annotations

import numpy as np
import pytest
from navtest_helpers import make_costmap

from eddiebot.nav.costmap import LayeredCostmap


@pytest.fixture
def empty_costmap() -> LayeredCostmap:
    return make_costmap(np.zeros((120, 120), dtype=np.int8))
