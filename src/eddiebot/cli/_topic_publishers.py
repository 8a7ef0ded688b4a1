"""What the publishers of a topic tell ``eddie topic``: their QoS (so a subscription
matches them) and, through ``~/get_type_description``, a type nothing here describes."""

from __future__ import annotations

from typing import Any

from eddiebot.cli._common import CliSession


def _publisher_qos_hint(s: CliSession, topic: str) -> tuple[bool, bool]:
    """(all publishers transient-local, any publisher best-effort) — so echo matches them."""
    from eddiebot.core.qos import DurabilityPolicy, ReliabilityPolicy
    from eddiebot.transport.keys import qos_from_keyexpr

    qos = []
    cache = s.remote()
    if cache is not None:
        qos = [qos_from_keyexpr(e.qos) for e in cache.publishers(topic)]
    entry = s.context.topics.get(topic)
    if entry is not None:
        qos += [p.qos for p in entry.publishers]
    tl = bool(qos) and all(q.durability == DurabilityPolicy.TRANSIENT_LOCAL for q in qos)
    be = any(q.reliability == ReliabilityPolicy.BEST_EFFORT for q in qos)
    return tl, be


#: How long echo waits for a publisher's ``~/get_type_description`` to appear, and to answer.
TYPE_DESCRIPTION_WAIT_S = 2.0
TYPE_DESCRIPTION_TIMEOUT_S = 5.0


def _type_from_publishers(s: CliSession, topic: str, type_name: str) -> Any:
    """The class of ``type_name`` as the publishers of ``topic`` describe it: each publishing
    node's ``~/get_type_description`` is asked for the type by name and RIHS01 hash (with its
    sources), and the first answer that hashes to that hash is registered. Else a string to
    append to the one-line error, saying what each publisher answered."""
    from eddiebot.msgs import get_message, get_service, register_type_description

    cache = s.remote()
    publishers = sorted({(e.node, e.type_hash) for e in (cache.publishers(topic) if cache else [])
                         if e.type_name == type_name and e.type_hash.startswith("RIHS01_")})
    if not publishers:
        return ""
    srv_type = get_service("type_description_interfaces/srv/GetTypeDescription")
    answers: list[str] = []
    for node, rihs01 in publishers:
        name = f"{node}/get_type_description"
        client = s.node.create_client(srv_type, name)
        try:
            if not client.wait_for_service(timeout_sec=TYPE_DESCRIPTION_WAIT_S):
                answers.append(f"{node} does not serve ~/get_type_description")
                continue
            request = srv_type.Request(type_name=type_name, type_hash=rihs01,
                                       include_type_sources=True)
            try:
                response = client.call(request, timeout_sec=TYPE_DESCRIPTION_TIMEOUT_S)
            except Exception as exc:  # timeout, unavailable, remote error
                answers.append(f"{name}: {exc}")
                continue
            if not response.successful:
                answers.append(f"{name}: {response.failure_reason or 'not successful'}")
                continue
            try:
                register_type_description(type_name, rihs01, response.type_description,
                                          response.type_sources)
            except ValueError as exc:
                answers.append(f"{name} refused: {exc}")
                continue
            return get_message(type_name)
        finally:
            s.node.destroy_client(client)
    return f"; asked the publisher{'s' if len(answers) > 1 else ''}: {'; '.join(answers)}"
