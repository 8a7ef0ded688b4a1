"""Fixtures of the explore node's tests."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from eddiebot.core.context import Context
from eddiebot.explore.node import ExploreNode


@pytest.fixture
def node() -> Iterator[ExploreNode]:
    """An explore node with its defaults, on a context of its own (no simulator)."""
    context = Context()
    n = ExploreNode(context=context)
    yield n
    n.destroy_node()
    context.shutdown()
