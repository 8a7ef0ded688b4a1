"""Package surface: every exported name exists."""

from __future__ import annotations

import importlib

import pytest


@pytest.mark.parametrize("name", ["eddiebot.sim", "eddiebot.sim.worlds", "eddiebot.perception"])
def test_all_names_resolve(name):
    mod = importlib.import_module(name)
    assert mod.__doc__
    missing = [n for n in mod.__all__ if not hasattr(mod, n)]
    assert not missing
