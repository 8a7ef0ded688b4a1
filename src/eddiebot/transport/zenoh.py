"""Topics and services between processes and machines over Zenoh, in rmw_zenoh's layout.

``ZenohTransport(context)`` implements the context's ``Transport`` protocol:

- every node, publisher, subscription, service (and client) of the context announces a
  liveliness token under ``@ros2_lv/<domain>/...``; a liveliness subscriber fills a
  ``GraphCache`` with everyone else's, which answers graph queries (``graph()``);
- a publisher forwards a sample only while some remote subscription exists on its topic
  (in-process delivery stays by reference); payloads are ROS 2 CDR with an attachment of
  sequence number, source timestamp and 16-byte GID;
- one Zenoh subscriber per subscribed topic listens to every type on it, so a remote
  publisher of another type is reported (topic and both types, once) and dropped; a sample
  whose key carries our type name with another RIHS01 hash (another definition of the type)
  is not decoded either: counted in ``undecoded`` and reported once, as rmw_zenoh matches
  on the hash;
- transient-local publishers keep their last ``depth`` samples in a Zenoh publication
  cache (the advanced publisher), which late-joining subscribers query, as in rmw_zenoh;
- reliable QoS is Zenoh reliable; as in rmw_zenoh, a publisher blocks on congestion only
  when it is reliable *and* KEEP_ALL, every other one drops (a KEEP_LAST queue is allowed
  to lose the oldest samples; a slow link must not stall the publishing callback);
- every entity's GID is the XXH3-128 hash of its liveliness key, as rmw_zenoh computes it
  (``keys.entity_gid``); each service client has its own, sent in its calls' attachment;
- services are queryables; a call is a ``get`` whose reply completes the client's future.

Opening and closing the session run in a helper thread that the caller waits for: inside
Zenoh's native code the main thread runs no Python signal handler, so Ctrl-C would wait for
the call to return (closing waits up to Zenoh's 10 s handshake timeout for links still being
opened to a peer that does not answer: a stopped or stalled process in the graph).
``config.close_timeout_s`` bounds that wait; `sessions_still_closing` tells a process about
to exit that it should not wait for them (``os._exit`` after flushing, as ``eddie`` does).
"""

from __future__ import annotations

import itertools
import logging
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import zenoh

from eddiebot.core.errors import ServiceCallTimeoutError, TopicTypeMismatchError
from eddiebot.core.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy, duration_ns
from eddiebot.msgs import deserialize, serialize
from eddiebot.transport._session_thread import (
    _call_in_thread,
    _close_quietly,
    sessions_still_closing,
)
from eddiebot.transport.config import ZenohConfig
from eddiebot.transport.errors import RemoteServiceError
from eddiebot.transport.graph import GraphCache
from eddiebot.transport.keys import (
    ATTACHMENT,
    UNKNOWN_TYPE_HASH,
    GraphEntity,
    decode_attachment,
    entity_gid,
    liveliness_key,
    liveliness_prefix,
    message_type_hash,
    node_liveliness_key,
    parse_liveliness_key,
    ros_type_name,
    topic_key,
    topic_wildcard_key,
)

if TYPE_CHECKING:
    from collections.abc import Callable

    from eddiebot.core.context import Context
    from eddiebot.core.node import Node, Publisher, Service, Subscription

__all__ = ["ZenohTransport", "publisher_congestion_control", "sessions_still_closing"]

log = logging.getLogger("eddiebot.transport")

#: A call that finds no queryable within this time of its start is retried, not failed.
_QUERYABLE_GRACE_S = 3.0


@dataclass
class _PubState:
    zpub: Any
    token: Any
    gid: bytes
    transient_local: bool
    topic: str
    #: Zenoh's own view: some remote subscriber's declaration reached this session.
    matching: bool = False
    listener: Any = None


@dataclass
class _TopicSub:
    zsub: Any
    transient_local: bool
    count: int
    depth: int = 1
    #: transient-local topics: publisher GID → its last ``depth`` samples (CDR bytes, type,
    #: expiry), for subscriptions of this process that come after the Zenoh subscriber
    #: fetched the publishers' history
    history: dict[bytes, deque[tuple[bytes, str, int | None]]] = field(default_factory=dict)


class ZenohTransport:
    """Links one ``Context`` to the rest of the graph through a Zenoh session."""

    def __init__(self, context: Context, config: ZenohConfig | None = None) -> None:
        self.context = context
        self.config = config or ZenohConfig.from_env()
        self.domain = int(context.domain_id)
        session_config = self.config.session_config()
        _, self.session = _call_in_thread(lambda: zenoh.open(session_config), "open", None,
                                          on_late_result=_close_quietly)
        try:
            self._start()
        except BaseException:
            # Ctrl-C or a failure half-way: never leave a session (and Zenoh's callback
            # threads, which Python waits for at exit) behind
            self._close_session()
            raise

    def _start(self) -> None:
        self.zid = str(self.session.zid())
        self.cache = GraphCache()
        self.cache.listeners.append(self._on_graph_change)
        self._lock = threading.RLock()
        self._ids = itertools.count()
        self._node_ids: dict[int, int] = {}
        self._tokens: dict[int, Any] = {}
        self._token_keys: dict[int, str] = {}
        self._pubs: dict[int, _PubState] = {}
        self._pub_topics: dict[str, int] = {}
        self._topic_subs: dict[str, _TopicSub] = {}
        self._queryables: dict[int, Any] = {}
        self._warned: set[tuple[str, str, str]] = set()
        #: topic → samples received but not decoded: their key carries the type we
        #: subscribed to with another RIHS01 hash (another definition of it)
        self.undecoded: dict[str, int] = {}
        #: topic → the hash whose samples raw subscriptions of an undescribed type take
        self._raw_hashes: dict[str, str] = {}
        #: id(client) → (its GID, its request sequence numbers), as rmw_zenoh's clients
        self._clients: dict[int, tuple[bytes, itertools.count[int]]] = {}
        #: calls from no announced client (a transport used directly)
        self._anonymous_client = (entity_gid(f"{self.zid}/anonymous client"), itertools.count(1))
        self._closed = False
        lv = self.session.liveliness()
        prefix = liveliness_prefix(self.domain)
        self._wait_for_router(self.config.router_wait_s)
        self._lv_sub = lv.declare_subscriber(prefix, self._on_token, history=True)
        # The initial view of the graph, synchronously (as rmw_zenoh's liveliness_get).
        initial_graph(self.session, prefix, self._on_token, timeout_s=3.0)

    def _wait_for_router(self, timeout_s: float) -> bool:
        """Give the session a moment to link up with a router (or, in LAN mode, a peer)."""
        deadline = time.monotonic() + timeout_s
        info = self.session.info
        while True:
            open_mesh = self.config.lan or self.config.customised
            if list(info.routers_zid()) or (open_mesh and list(info.peers_zid())):
                return True
            if time.monotonic() >= deadline:
                log.warning("no Zenoh router at %s yet; the graph fills in once one answers "
                            "(eddie daemon)", self.config.router)
                return False
            time.sleep(0.01)

    # -- graph ----------------------------------------------------------------------
    def _on_token(self, sample: Any) -> None:
        try:
            key = str(sample.key_expr)
            entity = parse_liveliness_key(key)
            if entity is None or entity.zid == self.zid or entity.domain != self.domain:
                return
            if sample.kind == zenoh.SampleKind.DELETE:
                self.cache.remove(key)
            else:
                self.cache.add(entity)
        except Exception:  # never let a malformed token kill the zenoh thread
            log.exception("bad liveliness token")

    def _on_graph_change(self, entity: GraphEntity, alive: bool) -> None:
        if alive and entity.kind == "MP":
            entry = self.context.topics.get(entity.name)
            if entry is not None and entry.subscriptions and entry.type_name not in (
                None, entity.type_name
            ):
                self._warn_mismatch(entity.name, entry.type_name or "", entity.type_name)

    def _warn_mismatch(self, topic: str, local: str, remote: str) -> None:
        key = (topic, local, remote)
        if key in self._warned:
            return
        self._warned.add(key)
        err = TopicTypeMismatchError(topic, local, remote)
        log.error(
            "type mismatch on topic %s: subscribed as %s but a remote publisher sends %s; "
            "its samples are dropped (%s)", topic, local, remote, err,
        )

    def _reachable_subscriptions(self) -> dict[str, int]:
        """Remote subscriptions per topic; on a topic this process publishes, only once
        Zenoh routes to them (the token can arrive before the subscriber's declaration)."""
        counts = self.cache.sub_counts
        if not self._pub_topics:
            return counts
        matching: set[str] = {s.topic for s in list(self._pubs.values())
                              if s.matching or s.transient_local}
        return {t: n for t, n in counts.items() if t not in self._pub_topics or t in matching}

    def graph(self) -> dict[str, Any]:
        """Remote entities: ``remote_subscriptions``/``remote_publishers`` (topic → count),
        ``cache`` (the ``GraphCache``) and this session's ``zid``."""
        return {
            "remote_subscriptions": self._reachable_subscriptions(),
            "remote_publishers": self.cache.pub_counts,
            "cache": self.cache,
            "zid": self.zid,
        }

    # -- nodes ----------------------------------------------------------------------
    def _node_id(self, node: Node) -> int:
        with self._lock:
            nid = self._node_ids.get(id(node))
            if nid is None:
                nid = self._node_ids[id(node)] = next(self._ids)
            return nid

    def _declare_token(self, owner: Any, key: str) -> Any:
        token = self.session.liveliness().declare_token(key)
        with self._lock:
            old = self._tokens.pop(id(owner), None)
            self._tokens[id(owner)] = token
            self._token_keys[id(owner)] = key
        if old is not None:
            _undeclare(old)
        return token

    def entity_gid_of(self, owner: Any) -> bytes | None:
        """The GID of a local node, publisher, subscription, service or client (XXH3-128
        of the liveliness key it announced), None if it announced none."""
        key = self._token_keys.get(id(owner))
        return entity_gid(key) if key is not None else None

    def _drop_token(self, owner: Any) -> None:
        with self._lock:
            self._token_keys.pop(id(owner), None)
            token = self._tokens.pop(id(owner), None)
        if token is not None:
            _undeclare(token)

    def on_node_added(self, node: Node) -> None:
        if self._closed:
            return
        key = node_liveliness_key(self.domain, self.zid, self._node_id(node),
                                  node.get_namespace(), node.get_name())
        self._declare_token(node, key)

    def on_node_removed(self, node: Node) -> None:
        self._drop_token(node)
        with self._lock:
            self._node_ids.pop(id(node), None)

    def _entity_key(self, node: Node, kind: str, name: str, type_name: str,
                    qos: QoSProfile | None, type_hash: str | None = None) -> str:
        return liveliness_key(self.domain, self.zid, self._node_id(node), next(self._ids), kind,
                              node.get_namespace(), node.get_name(), name, type_name, qos,
                              type_hash)

    # -- publishers -----------------------------------------------------------------
    def on_publisher_added(self, pub: Publisher) -> None:
        if self._closed:
            return
        key = topic_key(self.domain, pub.topic_name, pub.type_name)
        reliable = pub.qos.reliability != ReliabilityPolicy.BEST_EFFORT
        rel = zenoh.Reliability.RELIABLE if reliable else zenoh.Reliability.BEST_EFFORT
        cc = publisher_congestion_control(pub.qos)
        tl = pub.qos.transient_local
        zpub: Any
        if tl:
            import zenoh.ext as zext

            zpub = zext.declare_advanced_publisher(
                self.session, key, congestion_control=cc, reliability=rel,
                cache=zext.CacheConfig(max_samples=max(1, pub.qos.depth)),
                publisher_detection=True, allowed_destination=zenoh.Locality.REMOTE,
            )
        else:
            zpub = self.session.declare_publisher(
                key, congestion_control=cc, reliability=rel,
                allowed_destination=zenoh.Locality.REMOTE,
            )
        lkey = self._entity_key(pub.node, "MP", pub.topic_name, pub.type_name, pub.qos)
        token = self._declare_token(pub, lkey)
        state = _PubState(zpub, token, entity_gid(lkey), tl, pub.topic_name)
        if not tl:
            def on_matching(status: Any) -> None:
                state.matching = bool(getattr(status, "matching", status))

            state.listener = zpub.declare_matching_listener(on_matching)
            state.matching = bool(getattr(zpub.matching_status, "matching", zpub.matching_status))
        with self._lock:
            self._pubs[id(pub)] = state
            self._pub_topics[pub.topic_name] = self._pub_topics.get(pub.topic_name, 0) + 1
        for msg in list(pub.latched):  # published before the transport was attached
            self._put(pub, state, msg)

    def on_publisher_removed(self, pub: Publisher) -> None:
        with self._lock:
            state = self._pubs.pop(id(pub), None)
        self._drop_token(pub)
        if state is not None:
            with self._lock:
                n = self._pub_topics.get(state.topic, 1) - 1
                if n > 0:
                    self._pub_topics[state.topic] = n
                else:
                    self._pub_topics.pop(state.topic, None)
            if state.listener is not None:
                _undeclare(state.listener)
            _undeclare(state.zpub)

    def publish(self, pub: Publisher, msg: Any) -> None:
        state = self._pubs.get(id(pub))
        if state is None:
            return
        if not state.transient_local and not state.matching:
            return  # nobody outside listens: in-process delivery only
        self._put(pub, state, msg)

    def _put(self, pub: Publisher, state: _PubState, msg: Any) -> None:
        try:
            payload = serialize(msg, pub.type_name)
            att = ATTACHMENT.pack(pub.sequence, self.context.system_clock.now_ns(), 16, state.gid)
            state.zpub.put(payload, attachment=att)
        except zenoh.ZError as exc:
            if not self._closed:
                log.warning("publish on %s failed: %s", pub.topic_name, exc)

    # -- subscriptions --------------------------------------------------------------
    def on_subscription_added(self, sub: Subscription) -> None:
        if self._closed:
            return
        topic = sub.topic_name
        tl = sub.qos.transient_local
        with self._lock:
            ts = self._topic_subs.get(topic)
            if ts is None or (tl and not ts.transient_local):
                if ts is not None:
                    _undeclare(ts.zsub)
                # in place before the declaration: the publishers' history may arrive during it
                ts = self._topic_subs[topic] = _TopicSub(None, tl, ts.count if ts else 0,
                                                         max(1, sub.qos.depth))
                try:
                    ts.zsub = self._declare_subscriber(topic, tl, sub.qos.depth)
                except BaseException:
                    del self._topic_subs[topic]
                    raise
            elif tl:
                self._replay_history(sub, ts)
            ts.count += 1
        # a raw subscription of a type nothing here describes announces the hash it was
        # made for (learnt from the publishers' tokens)
        learnt = getattr(sub.msg_type, "__rihs01__", None)
        self._declare_token(sub, self._entity_key(sub.node, "MS", topic, sub.type_name, sub.qos,
                                                  learnt))
        for e in self.cache.publishers(topic):
            self._on_graph_change(e, True)

    def _replay_history(self, sub: Subscription, ts: _TopicSub) -> None:
        """Give a late transient-local subscription the samples the process's Zenoh
        subscriber got from live publishers' history and since (Zenoh fetched it once, for
        the first subscription)."""
        live = {e.gid for e in self.cache.publishers(sub.topic_name)}
        now = self.context.system_clock.now_ns()
        for gid, samples in list(ts.history.items()):
            if gid not in live:
                del ts.history[gid]
                continue
            for data, remote, expires in list(samples):
                if expires is not None and now > expires:
                    continue
                try:
                    sub.deliver(data if getattr(sub, "raw", False) else deserialize(data, remote),
                                expires)
                except Exception:
                    log.exception("dropping a sample on %s", sub.topic_name)

    def _declare_subscriber(self, topic: str, transient_local: bool, depth: int) -> Any:
        key = topic_wildcard_key(self.domain, topic)
        handler = self._sample_handler(topic)
        if transient_local:
            import zenoh.ext as zext

            return zext.declare_advanced_subscriber(
                self.session, key, handler, allowed_origin=zenoh.Locality.REMOTE,
                history=zext.HistoryConfig(detect_late_publishers=True,
                                           max_samples=max(1, depth)),
            )
        return self.session.declare_subscriber(key, handler,
                                               allowed_origin=zenoh.Locality.REMOTE)

    def _sample_handler(self, topic: str) -> Callable[[Any], None]:
        # (dds type, hash chunk) of a key → the ROS type its samples decode as, or None when
        # they are not ours to decode (another type, or the same type of another definition)
        verdicts: dict[tuple[str, str, str], str | None] = {}
        context = self.context

        def verdict(entry_type: str, dds: str, remote_hash: str) -> str | None:
            remote = ros_type_name(dds)
            if remote != entry_type:
                self._warn_mismatch(topic, entry_type, remote)
                return None
            ours = message_type_hash(remote)
            if ours == UNKNOWN_TYPE_HASH:
                # nothing here describes the type: raw subscriptions take the bytes of the
                # definition they were made for (learnt from the graph), else of the first
                # one seen; a second one on the same topic would mix two layouts
                entry = context.topics.get(topic)
                wanted = [h for sub in (entry.subscriptions if entry else [])
                          if (h := getattr(sub.msg_type, "__rihs01__", None))]
                ours = self._raw_hashes.setdefault(topic, wanted[0] if wanted else remote_hash)
            if remote_hash != ours:
                self._warn_definition(topic, remote, remote_hash)
                return None
            return remote

        # publisher GID → last sequence number (gaps are lost samples, as rmw_zenoh counts
        # them) and → its QoS lifespan in ns (from its liveliness token's QoS)
        last_seq: dict[bytes, int] = {}
        lifespans: dict[bytes, int | None] = {}
        cache_version = [-1]

        def lifespan_of(gid: bytes) -> int | None:
            if gid not in lifespans and cache_version[0] != self.cache.version:
                cache_version[0] = self.cache.version
                for e in self.cache.publishers(topic):
                    lifespans[e.gid] = duration_ns(e.qos_profile.lifespan)
            return lifespans.get(gid)

        def track(entry: Any, sample: Any) -> tuple[int | None, bytes | None]:
            """Count lost samples; the system time this sample expires (None: never) and
            its publisher's GID."""
            att = sample.attachment
            decoded = decode_attachment(att.to_bytes()) if att is not None else None
            if decoded is None:
                return None, None
            seq, stamp, gid = decoded
            previous = last_seq.get(gid)
            last_seq[gid] = seq
            if previous is not None and seq > previous + 1:
                for sub in list(entry.subscriptions):
                    if sub.events is not None:
                        sub.events.on_messages_lost(seq - previous - 1)
            lifespan = lifespan_of(gid)
            return (None if lifespan is None else stamp + lifespan), gid

        def handler(sample: Any) -> None:
            try:
                entry = context.topics.get(topic)
                if entry is None or entry.type_name is None:
                    return
                dds, remote_hash = str(sample.key_expr).rsplit("/", 2)[-2:]
                key = (entry.type_name, dds, remote_hash)
                if key in verdicts:
                    remote = verdicts[key]
                else:
                    remote = verdicts[key] = verdict(entry.type_name, dds, remote_hash)
                if remote is None:
                    if ros_type_name(dds) == entry.type_name:  # same name, other definition
                        self.undecoded[topic] = self.undecoded.get(topic, 0) + 1
                    return
                expires, gid = track(entry, sample)
                if expires is not None and context.system_clock.now_ns() > expires:
                    return  # outlived the publisher's lifespan on the way
                data = sample.payload.to_bytes()
                ts = self._topic_subs.get(topic)
                if ts is not None and ts.transient_local and gid is not None:
                    kept = ts.history.get(gid)
                    if kept is None:
                        kept = ts.history[gid] = deque(maxlen=ts.depth)
                    kept.append((data, remote, expires))
                subs = list(entry.subscriptions)
                if any(getattr(sub, "raw", False) for sub in subs):
                    # raw subscriptions (the recorder, hz, bw) take the CDR bytes as they came
                    cooked = []
                    for sub in subs:
                        if getattr(sub, "raw", False):
                            sub.deliver(data, expires)
                        else:
                            cooked.append(sub)
                    if cooked:
                        msg = deserialize(data, remote)
                        for sub in cooked:
                            sub.deliver(msg, expires)
                    return
                context.deliver_remote(topic, remote, deserialize(data, remote), expires)
            except Exception:
                log.exception("dropping a sample on %s", topic)

        return handler

    def _warn_definition(self, topic: str, type_name: str, remote_hash: str) -> None:
        key = (topic, type_name, remote_hash)
        if key in self._warned:
            return
        self._warned.add(key)
        log.error("%s: a publisher of %s with another definition (%s); its samples are not "
                  "decoded", topic, type_name, remote_hash)

    def on_subscription_removed(self, sub: Subscription) -> None:
        self._drop_token(sub)
        with self._lock:
            ts = self._topic_subs.get(sub.topic_name)
            if ts is None:
                return
            ts.count -= 1
            if ts.count <= 0:
                del self._topic_subs[sub.topic_name]
                self._raw_hashes.pop(sub.topic_name, None)
                _undeclare(ts.zsub)

    # -- services -------------------------------------------------------------------
    def on_service_added(self, srv: Service) -> None:
        if self._closed:
            return
        key = topic_key(self.domain, srv.srv_name, srv.srv_type.name, service=True)
        queryable = self.session.declare_queryable(
            key, self._query_handler(srv), complete=True, allowed_origin=zenoh.Locality.REMOTE
        )
        with self._lock:
            self._queryables[id(srv)] = queryable
        self._declare_token(srv, self._entity_key(srv.node, "SS", srv.srv_name,
                                                  srv.srv_type.name, None))

    def on_service_removed(self, srv: Service) -> None:
        self._drop_token(srv)
        with self._lock:
            q = self._queryables.pop(id(srv), None)
        if q is not None:
            _undeclare(q)

    def _query_handler(self, srv: Service) -> Callable[[Any], None]:
        req_type = srv.srv_type.Request.__msgtype__

        def handler(query: Any) -> None:
            try:
                payload = query.payload
                request = deserialize(payload.to_bytes() if payload is not None else b"", req_type)
                att = query.attachment
                att_bytes = att.to_bytes() if att is not None else None
            except Exception as exc:
                query.reply_err(f"bad request for {srv.srv_name}: {exc}")
                query.drop()
                return

            def done(response: Any, error: BaseException | None) -> None:
                try:
                    if error is not None:
                        query.reply_err(f"{type(error).__name__}: {error}")
                    else:
                        reply_att = att_bytes
                        if reply_att is not None and len(reply_att) >= ATTACHMENT.size:
                            seq, _, n, gid = ATTACHMENT.unpack_from(reply_att)
                            reply_att = ATTACHMENT.pack(
                                seq, self.context.system_clock.now_ns(), n, gid)
                        query.reply(query.key_expr, serialize(response), attachment=reply_att)
                except Exception as exc:
                    log.warning("could not answer a call of %s: %s", srv.srv_name, exc)
                finally:
                    query.drop()

            executor = srv.node.executor
            if executor is None or not executor.is_spinning():
                # nobody runs this node's callbacks: answer here, as a local call would
                srv.handle_async(request, done)
            else:
                srv.enqueue(request, done)

        return handler

    def on_client_added(self, client: Any) -> None:
        """Announce a service client (``SC`` token) — call from ``Node.create_client``."""
        if self._closed:
            return
        key = self._entity_key(client.node, "SC", client.srv_name, client.srv_type.name, None)
        with self._lock:
            self._clients[id(client)] = (entity_gid(key), itertools.count(1))
        self._declare_token(client, key)

    def on_client_removed(self, client: Any) -> None:
        self._drop_token(client)
        with self._lock:
            self._clients.pop(id(client), None)

    def service_is_ready(self, name: str) -> bool:
        return self.cache.has_service(name)

    def call_service(
        self, name: str, srv_type: Any, request: Any,
        done: Callable[[Any, BaseException | None], None], *, client: Any = None,
    ) -> bool:
        servers = self.cache.services(name)
        if not servers or self._closed:
            return False
        if all(s.type_name != srv_type.name for s in servers):
            done(None, TopicTypeMismatchError(name, servers[0].type_name, srv_type.name))
            return True
        key = topic_key(self.domain, name, srv_type.name, service=True)
        timeout = (self.config.result_timeout_s if name.endswith("/_action/get_result")
                   else self.config.service_timeout_s)
        resp_type = srv_type.Response.__msgtype__
        lock = threading.Lock()
        state = {"answered": False}

        def finish(response: Any, error: BaseException | None) -> None:
            with lock:
                if state["answered"]:
                    return
                state["answered"] = True
            done(response, error)

        def on_reply(reply: Any) -> None:
            try:
                if reply.ok is not None:
                    finish(deserialize(reply.ok.payload.to_bytes(), resp_type), None)
                else:
                    finish(None, RemoteServiceError(
                        f"service {name!r} failed: {reply.err.payload.to_string()}"))
            except Exception as exc:
                finish(None, exc)

        payload = serialize(request, srv_type.Request.__msgtype__)
        gid, seq = self._clients.get(id(client), self._anonymous_client)
        att = ATTACHMENT.pack(next(seq), self.context.system_clock.now_ns(), 16, gid)
        started = time.monotonic()

        def on_end() -> None:
            if state["answered"]:
                return
            waited = time.monotonic() - started
            if waited < min(timeout, _QUERYABLE_GRACE_S) and not self._closed:
                # The server's token can arrive before its queryable is routed: ask again.
                retry = threading.Timer(0.05, send)
                retry.daemon = True
                retry.start()
                return
            finish(None, ServiceCallTimeoutError(
                f"service {name!r} gave no answer within {waited:.3g} s"))

        def send() -> None:
            try:
                remaining = max(0.05, timeout - (time.monotonic() - started))
                self.session.get(
                    key, zenoh.handlers.Callback(on_reply, on_end), payload=payload,
                    attachment=att, target=zenoh.QueryTarget.ALL_COMPLETE, timeout=remaining,
                )
            except Exception as exc:
                finish(None, exc)

        send()
        return True

    # -- life -----------------------------------------------------------------------
    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        with self._lock:
            handles = [*self._tokens.values(),
                       *(s.listener for s in self._pubs.values() if s.listener is not None),
                       *(s.zpub for s in self._pubs.values()),
                       *(t.zsub for t in self._topic_subs.values()), *self._queryables.values()]
            self._tokens.clear()
            self._pubs.clear()
            self._topic_subs.clear()
            self._queryables.clear()
        for h in [*handles, getattr(self, "_lv_sub", None)]:
            if h is not None:
                _undeclare(h)
        self._close_session()

    def _close_session(self) -> None:
        """Close the session, waiting at most ``config.close_timeout_s`` (interruptibly)."""
        self._closed = True
        finished, _ = _call_in_thread(lambda: _close_quietly(self.session), "close",
                                      self.config.close_timeout_s)
        if not finished:
            log.debug("the Zenoh session is still closing after %.3g s (a peer does not "
                      "answer); not waiting for it", self.config.close_timeout_s)

    def __repr__(self) -> str:
        return f"<ZenohTransport zid={self.zid} domain={self.domain} router={self.config.router}>"


def initial_graph(session: Any, prefix: str, on_token: Callable[[Any], None],
                  timeout_s: float) -> bool:
    """Give ``on_token`` every liveliness token under ``prefix`` alive now; False if the
    query had not ended within ``timeout_s`` (tokens arriving later still reach it).

    The replies go to a callback, never to a channel this thread reads afterwards: Zenoh
    answers tokens its session already knows inside ``get`` itself, and once they outnumber
    a bounded channel's capacity (a graph of a few hundred entities) the call waited
    forever for a reader that was itself.
    """
    done = threading.Event()

    def on_reply(reply: Any) -> None:
        if reply.ok is not None:
            on_token(reply.ok)

    try:
        session.liveliness().get(prefix, zenoh.handlers.Callback(on_reply, done.set),
                                 timeout=timeout_s)
    except Exception as exc:  # pragma: no cover - a session without routes
        log.debug("liveliness get failed: %s", exc)
        return False
    return done.wait(timeout_s + 1.0)


def publisher_congestion_control(qos: QoSProfile) -> Any:
    """rmw_zenoh's rule: BLOCK only for reliable KEEP_ALL publishers, else DROP."""
    if qos.reliability != ReliabilityPolicy.BEST_EFFORT and qos.history == HistoryPolicy.KEEP_ALL:
        return zenoh.CongestionControl.BLOCK
    return zenoh.CongestionControl.DROP


def _undeclare(handle: Any) -> None:
    try:
        handle.undeclare()
    except Exception:
        pass
