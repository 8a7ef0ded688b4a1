"""A service callback that raises, called from another process's session."""

from __future__ import annotations

import logging
from typing import Any

import pytest

from eddiebot.core import Context, Node
from eddiebot.msgs.std_srvs import SetBool
from eddiebot.transport import connect
from eddiebot.transport.errors import RemoteServiceError


def test_remote_caller_gets_the_error_and_the_server_keeps_serving(
    zenoh_config: Any, caplog: pytest.LogCaptureFixture
) -> None:
    server_ctx, client_ctx = Context(), Context()
    try:
        server = Node("raising_server", context=server_ctx)
        connect(server_ctx, zenoh_config, required=True)
        served: list[bool] = []

        def answer(req: Any, res: Any) -> Any:
            served.append(req.data)
            if req.data:
                raise RuntimeError("gripper jammed")
            res.success = True
            return res

        server.create_service(SetBool, "/gripper", answer)
        node = Node("remote_caller", context=client_ctx)
        connect(client_ctx, zenoh_config, required=True)
        client = node.create_client(SetBool, "/gripper")
        assert client.wait_for_service(timeout_sec=10)
        with caplog.at_level(logging.ERROR), pytest.raises(RemoteServiceError, match="gripper jammed"):
            # the service timeout is 60 s: the error comes back with the reply, not late
            client.call(SetBool.Request(data=True), timeout_sec=10)
        assert any("/raising_server" in r.getMessage() and "/gripper" in r.getMessage()
                   for r in caplog.records if r.levelno == logging.ERROR)
        assert client.call(SetBool.Request(data=False), timeout_sec=10).success
        assert served == [True, False]
    finally:
        client_ctx.shutdown()
        server_ctx.shutdown()
