"""Nav2's selector nodes (controller, planner, goal checker, progress checker, smoother):
the last ``std_msgs/String`` on ``topic_name``, else the default, written to the output
port.
"""

from __future__ import annotations

from typing import Any, ClassVar

from eddiebot.nav.bt.core import LeafNode, Status, input_port, output_port

__all__ = ["SELECTOR_NODES"]

S, F, R = Status.SUCCESS, Status.FAILURE, Status.RUNNING


class _Selector(LeafNode):
    """Nav2's selector nodes: the last ``std_msgs/String`` on ``topic_name``, else the
    default, written to the output port."""

    KIND: ClassVar[str] = ""

    def __init__(self, *args: Any) -> None:
        super().__init__(*args)
        if getattr(self.context, "node", None) is not None:
            from eddiebot.msgs.std_msgs import String

            self.context.latest(str(self.get_input("topic_name")), String)

    def tick(self) -> Status:
        from eddiebot.msgs.std_msgs import String

        topic = str(self.get_input("topic_name"))
        last = self.context.latest(topic, String)
        value = last.data if last is not None else self.get_input(f"default_{self.KIND}")
        if value is not None:
            self.set_output(f"selected_{self.KIND}", str(value))
        return S


def _selector(kind: str, topic: str) -> type:
    ports = {
        f"default_{kind}": input_port(str, description=f"the default {kind} to use"),
        "topic_name": input_port(str, topic, f"the input topic name to select the {kind}"),
        f"selected_{kind}": output_port(str, f"Selected {kind} by subscription"),
    }
    cls_name = "".join(p.capitalize() for p in kind.split("_")) + "Selector"
    return type(cls_name, (_Selector,), {"KIND": kind, "PORTS": ports})


SELECTOR_NODES: tuple[type, ...] = (
    _selector("controller", "controller_selector"),
    _selector("planner", "planner_selector"),
    _selector("goal_checker", "goal_checker_selector"),
    _selector("progress_checker", "progress_checker_selector"),
    _selector("smoother", "smoother_selector"),
)
