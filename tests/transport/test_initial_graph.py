"""A new session's first view of the graph when the graph is large.

Zenoh answers liveliness tokens its session already knows inside ``liveliness().get``
itself. Read through the default bounded channel, a graph of more tokens than the channel
holds made that call wait forever for its own reader: `eddie record -a` and `eddie topic
echo` started beside a running simulator, SLAM and teleop sometimes never got past
connecting.
"""

from __future__ import annotations

import json
import threading
import time
from collections.abc import Iterator
from typing import Any

import pytest
import zenoh
from _procs import free_port

from eddiebot.transport.zenoh import initial_graph

#: more tokens than Zenoh's default reply channel holds (256)
TOKENS = 600


def _config(listen: str | None = None, connect: str | None = None) -> Any:
    config = zenoh.Config()
    config.insert_json5("mode", '"peer"')
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("listen/endpoints", json.dumps([listen] if listen else []))
    config.insert_json5("connect/endpoints", json.dumps([connect] if connect else []))
    return config


@pytest.fixture
def known_graph() -> Iterator[Any]:
    """A session that already holds ``TOKENS`` tokens of another session, on a link of
    their own (loopback, a private port, no scouting)."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    other = zenoh.open(_config(listen=endpoint))
    tokens = [other.liveliness().declare_token(f"eddietest/lv/{i}") for i in range(TOKENS)]
    session = zenoh.open(_config(connect=endpoint))
    seen: set[str] = set()
    sub = session.liveliness().declare_subscriber(
        "eddietest/lv/**", lambda sample: seen.add(str(sample.key_expr)), history=True)
    deadline = time.monotonic() + 20.0
    while len(seen) < TOKENS and time.monotonic() < deadline:
        time.sleep(0.01)
    assert len(seen) == TOKENS, f"the subscriber learnt {len(seen)} of {TOKENS} tokens"
    yield session
    sub.undeclare()
    for token in tokens:
        token.undeclare()
    session.close()
    other.close()


def test_initial_graph_of_hundreds_of_known_tokens_returns(known_graph: Any) -> None:
    got: list[str] = []
    result: list[bool] = []
    # in a thread: the old reading of the reply channel never returned
    worker = threading.Thread(target=lambda: result.append(initial_graph(
        known_graph, "eddietest/lv/**", lambda s: got.append(str(s.key_expr)), 3.0)),
        daemon=True)
    worker.start()
    worker.join(15.0)
    assert not worker.is_alive(), "initial_graph did not return"
    assert result == [True]
    assert len(set(got)) == TOKENS
