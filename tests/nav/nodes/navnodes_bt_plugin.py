"""A behaviour-tree node library as a user's package would ship it: ``plugin_lib_names``
names this module and its ``register_bt_nodes(factory)`` registers the nodes."""

from typing import ClassVar

from eddiebot.nav.bt import LeafNode, Status, input_port


class CountTicks(LeafNode):
    """RUNNING until ticked ``limit`` times, then SUCCESS."""

    PORTS: ClassVar = {"limit": input_port(int, 1)}

    def __init__(self, *args):
        super().__init__(*args)
        self.count = 0

    def tick(self):
        self.count += 1
        return Status.SUCCESS if self.count >= int(self.get_input("limit")) else Status.RUNNING


def register_bt_nodes(factory):
    factory.register_node_type("CountTicks", CountTicks)
