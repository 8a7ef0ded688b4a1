"""ROS 2 ``rtabmap_msgs`` interfaces: ``from eddiebot.msgs.rtabmap_msgs import Name``."""

from typing import Any

from eddiebot.msgs._store import package_namespace

_NAMES = package_namespace("rtabmap_msgs")
__all__ = sorted(_NAMES)


def __getattr__(name: str) -> Any:
    try:
        return _NAMES[name]
    except KeyError:
        raise AttributeError(f"module {__name__!r} has no interface {name!r}") from None
