"""Managed (lifecycle) nodes and Nav2's lifecycle manager.

``LifecycleNode`` follows the ROS 2 managed-node state machine (lifecycle_msgs ids)::

    unconfigured --configure--> inactive --activate--> active
         ^  <--cleanup--           ^   <--deactivate--    |
         |                                                 |
         +------ shutdown (from any primary state) -----> finalized

Each transition runs a callback (``on_configure`` …) answering
``TransitionCallbackReturn.SUCCESS`` / ``FAILURE`` (stay) / ``ERROR`` (→ ``on_error``:
SUCCESS back to unconfigured, otherwise finalized); an exception counts as ERROR.
The node serves ``<node>/change_state``, ``get_state``, ``get_available_states``,
``get_available_transitions`` and publishes ``<node>/transition_event``. Lifecycle
publishers stay silent until the node is active. While active the node keeps a bond as
bondcpp does, so a real ``nav2_lifecycle_manager`` can manage it: ``bond/msg/Status`` on the
relative ``bond`` topic (id = node name, a fresh instance id per bond, ``active``, the
heartbeat timeout and period) every ``bond_heartbeat_period`` seconds (0.1 s, as nav2_util),
and one ``active: false`` when the bond is broken on deactivation.

``LifecycleManager`` is Nav2's lifecycle_manager: it configures then activates
``node_names`` in order, takes them down in reverse, serves ``<manager>/manage_nodes``
(nav2_msgs/ManageLifecycleNodes) and ``<manager>/is_active`` (std_srvs/Trigger), and
takes the group down when an active node's heartbeat stops for ``bond_timeout`` or the node
says its bond is broken. Its own side of each bond beats every 0.1 s with its own instance
id, so nodes of a real Nav2 (bondcpp) see their bond formed too.
"""

from eddiebot.core.lifecycle.bond import bond_status as bond_status
from eddiebot.core.lifecycle.manager import LifecycleManager
from eddiebot.core.lifecycle.manager import ManagerCommand as ManagerCommand
from eddiebot.core.lifecycle.node import LifecycleNode, LifecyclePublisher
from eddiebot.core.lifecycle.states import LifecycleState, State, TransitionCallbackReturn

__all__ = [
    "LifecycleManager",
    "LifecycleNode",
    "LifecyclePublisher",
    "LifecycleState",
    "State",
    "TransitionCallbackReturn",
]
