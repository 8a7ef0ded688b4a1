"""A private Zenoh router per test session (random loopback port) and peer processes."""

from __future__ import annotations

import sys
from collections.abc import Iterator

import pytest
from _procs import PEER, Proc, private_router


@pytest.fixture(scope="session")
def zenoh_env() -> Iterator[dict[str, str]]:
    """Environment of every process of the session: its own router on a random port."""
    with private_router() as env:
        yield env


@pytest.fixture
def spawn(zenoh_env: dict[str, str]) -> Iterator[object]:
    """``spawn(role, *args, timeout=20)`` starts ``_peer.py`` roles; all are reaped after."""
    procs: list[Proc] = []

    def _spawn(role: str, *args: str, timeout: float = 20.0) -> Proc:
        env = {**zenoh_env, "PEER_TIMEOUT": str(timeout)}
        p = Proc([sys.executable, str(PEER), role, *args], env)
        procs.append(p)
        return p

    yield _spawn
    for p in procs:
        if p.popen.poll() is None:
            p.finish(timeout=5)


@pytest.fixture
def zenoh_config(zenoh_env: dict[str, str]) -> object:
    from eddiebot.transport import ZenohConfig

    return ZenohConfig.from_env(zenoh_env)


@pytest.fixture(scope="session")
def hub(zenoh_env: dict[str, str]) -> Iterator[Proc]:
    """One long-lived peer process (``_peer.py hub``) shared by the tests of the session."""
    p = Proc([sys.executable, str(PEER), "hub"], {**zenoh_env, "PEER_TIMEOUT": "300"})
    if not p.wait_for("READY", timeout=30):
        p.finish(timeout=5)
        pytest.fail(f"the hub process did not start: {p.stderr}")
    yield p
    p.finish(timeout=10)


@pytest.fixture(autouse=True)
def _transport_on(monkeypatch: pytest.MonkeyPatch) -> None:
    """tests/conftest.py turns the transport off for everyone else; these tests need it."""
    monkeypatch.delenv("EDDIE_TRANSPORT", raising=False)
