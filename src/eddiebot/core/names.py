"""ROS 2 name resolution: namespaces, private names (``~``) and remapping."""

from __future__ import annotations

import re

from eddiebot.core.errors import InvalidNameError

_NODE_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_TOKEN = re.compile(r"^[A-Za-z_~{][A-Za-z0-9_{}]*$")


def validate_node_name(name: str) -> str:
    if not _NODE_NAME.match(name):
        raise InvalidNameError(
            f"invalid node name {name!r}: use letters, digits and underscores, not starting with a digit"
        )
    return name


def normalize_namespace(namespace: str) -> str:
    """'' or 'ns' or '/ns/' → '/' or '/ns'."""
    ns = namespace.strip()
    if not ns or ns == "/":
        return "/"
    if not ns.startswith("/"):
        ns = "/" + ns
    ns = ns.rstrip("/")
    for token in ns.split("/")[1:]:
        if not _TOKEN.match(token):
            raise InvalidNameError(f"invalid namespace {namespace!r} (token {token!r})")
    return ns


def resolve_name(name: str, namespace: str, node_name: str) -> str:
    """Expand a topic or service name to its fully qualified form, as rcl does."""
    if not name:
        raise InvalidNameError("empty topic or service name")
    ns = normalize_namespace(namespace)
    if name.startswith("~"):
        base = f"{ns.rstrip('/')}/{node_name}"
        rest = name[1:].lstrip("/")
        full = f"{base}/{rest}" if rest else base
    elif name.startswith("/"):
        full = name
    else:
        full = f"{ns.rstrip('/')}/{name}"
    full = re.sub("/+", "/", full)
    if len(full) > 1:
        full = full.rstrip("/")
    for token in full.split("/")[1:]:
        if not token or not re.match(r"^[A-Za-z_][A-Za-z0-9_]*$", token):
            raise InvalidNameError(f"invalid topic or service name {name!r} (token {token!r})")
    return full


def apply_remaps(full_name: str, remaps: dict[str, str], namespace: str, node_name: str) -> str:
    """Apply ``from:=to`` rules; both sides may be relative (resolved in the node's namespace)."""
    for src, dst in remaps.items():
        if resolve_name(src, namespace, node_name) == full_name:
            return resolve_name(dst, namespace, node_name)
    return full_name
