"""``ros2 node list|info`` and ``ros2 topic info`` without ros2cli: the core of ``cpg-walker node`` and
``cpg-walker topic info``, in ros2cli's output formats (Jazzy). There is no ros2 daemon holding the
graph: each answer waits, within a deadline, until what this process discovers stops changing."""

from __future__ import annotations

from typing import Any

from cpg_walker.errors import ToolError
from cpg_walker.graph.ros2cli import Session, node_name

HIDDEN_PREFIX = "_"  # rclpy's HIDDEN_NODE_PREFIX: hidden nodes, topics and services


def is_hidden(name: str) -> bool:
    """A name with a part starting with ``_`` (``/_action/...``, ``/_cpg_walker_tool_12``)."""
    return any(part.startswith(HIDDEN_PREFIX) for part in name.split("/"))


def full_name(name: str, namespace: str) -> str:
    return namespace + ("" if namespace.endswith("/") else "/") + name


def split_name(full: str) -> tuple[str, str]:
    """``/ns/cpg`` -> (``cpg``, ``/ns``); ``/cpg`` -> (``cpg``, ``/``)."""
    namespace, base = node_name(full).rsplit("/", 1)
    return base, namespace or "/"


def node_names(s: Session, include_hidden: bool = False) -> list[str]:
    """The fully qualified names of the graph's nodes as this process sees them now (sorted; duplicates
    kept; this tool's own node never)."""
    own = full_name(s.node.get_name(), s.node.get_namespace())
    names = [full_name(n, ns) for n, ns in s.node.get_node_names_and_namespaces()]
    return sorted(n for n in names if n != own and (include_hidden or not n.rsplit("/", 1)[1].startswith(
        HIDDEN_PREFIX)))


#: Wall s a listing must stay unchanged to be taken as complete: a node process announces its name a moment
#: after its DDS participant is found (~1.7 s after a tool starts on an idle machine), nodes one by one.
SETTLE_S = 1.0


def list_nodes(s: Session, include_hidden: bool = False, settle: float = SETTLE_S, timeout: float = 5.0
               ) -> list[str]:
    """``ros2 node list``: the node names once discovery has settled (at most ``timeout`` wall s). With no
    ros2 daemon holding the graph, a node found later than that is missed: list again."""
    return s.settled(lambda: node_names(s, include_hidden), bool, settle, timeout)


def endpoints_seen(s: Session) -> bool:
    """Whether some other node is known and each known node's endpoints have been discovered too (every
    rclpy node publishes at least /parameter_events): node names and endpoints arrive separately."""
    others = [n for n in s.node.get_node_names_and_namespaces()
              if (n[0], n[1]) != (s.node.get_name(), s.node.get_namespace())]
    try:
        return bool(others) and all(s.node.get_publisher_names_and_types_by_node(*n) for n in others)
    except Exception:  # a node that left between the two calls (rclpy's NodeNameNonExistentError)
        return False


SECTIONS = ("Subscribers", "Publishers", "Service Servers", "Service Clients", "Action Servers",
            "Action Clients")


Endpoints = dict[str, list[tuple[str, list[str]]]]  # section -> [(name, types)]


def node_endpoints(s: Session, node: str, include_hidden: bool = False) -> Endpoints:
    """Section -> [(name, types)] of ``node`` (``ros2 node info``'s sections, names sorted)."""
    from rclpy.action import graph

    name, namespace = split_name(node)
    n = s.node
    found = {
        "Subscribers": n.get_subscriber_names_and_types_by_node(name, namespace),
        "Publishers": n.get_publisher_names_and_types_by_node(name, namespace),
        "Service Servers": n.get_service_names_and_types_by_node(name, namespace),
        "Service Clients": n.get_client_names_and_types_by_node(name, namespace),
        "Action Servers": graph.get_action_server_names_and_types_by_node(n, name, namespace),
        "Action Clients": graph.get_action_client_names_and_types_by_node(n, name, namespace),
    }
    return {sec: sorted((t, list(types)) for t, types in found[sec] if include_hidden or not is_hidden(t))
            for sec in SECTIONS}


def node_info(s: Session, node: str, include_hidden: bool = False, timeout: float = 10.0,
              settle: float = SETTLE_S) -> tuple[Endpoints, int]:
    """``ros2 node info``: the sections of ``node`` once discovered and settled, and how many nodes
    share its name (ToolError when it does not show up within ``timeout`` wall s)."""
    node = node_name(node)
    s.settled(lambda: node in node_names(s, True), bool, 0.0, timeout)
    count = node_names(s, True).count(node)
    if not count:
        raise ToolError(f"Unable to find node '{node}' in domain {s.domain} within {timeout:g} s")

    def snapshot() -> Any:
        try:
            return node_endpoints(s, node, include_hidden)
        except Exception:  # rclpy's NodeNameNonExistentError while it is still being discovered
            return None

    endpoints = s.settled(snapshot, lambda e: e is not None, settle, timeout)
    if endpoints is None:
        raise ToolError(f"Unable to find node '{node}' in domain {s.domain}")
    return endpoints, count


def format_node_info(node: str, endpoints: Endpoints) -> str:
    """ros2's layout: the name, then each section at 2 spaces and its ``name: types`` at 4 (an empty
    section leaves an empty line, as ros2 prints it)."""
    lines = [node_name(node)]
    for sec in SECTIONS:
        lines.append(f"  {sec}:")
        rows = [f"    {t}: {', '.join(types)}" for t, types in endpoints[sec]]
        lines.append("\n".join(rows))
    return "\n".join(lines)


def nonunique_warning(node: str, count: int) -> str:
    return (f'There are {count} nodes in the graph with the exact name "{node}". You are seeing '
            "information about only one of them.")


def topic_info(s: Session, topic: str, timeout: float = 10.0, settle: float = SETTLE_S
               ) -> tuple[list[str], list[Any], list[Any]]:
    """``ros2 topic info``: (types, publishers' and subscriptions' TopicEndpointInfo) of ``topic`` once
    discovered and settled, this tool's own endpoints left out (ToolError when the topic does not show
    up within ``timeout`` wall s)."""
    topic = node_name(topic)
    own = (s.node.get_name(), s.node.get_namespace())

    def snapshot() -> Any:
        types = dict(s.node.get_topic_names_and_types()).get(topic)
        if not types:
            return None
        pubs = [i for i in s.node.get_publishers_info_by_topic(topic)
                if (i.node_name, i.node_namespace) != own]
        subs = [i for i in s.node.get_subscriptions_info_by_topic(topic)
                if (i.node_name, i.node_namespace) != own]
        key = (tuple(types), tuple(_endpoint_key(i) for i in pubs), tuple(_endpoint_key(i) for i in subs))
        return key, list(types), pubs, subs

    def keyed() -> Any:
        snap = snapshot()
        return None if snap is None else (snap[0], tuple(node_names(s, True)))

    s.settled(keyed, lambda k: k is not None and endpoints_seen(s), settle, timeout)
    snap = snapshot()
    if snap is None:
        raise ToolError(f"Unknown topic '{topic}' in domain {s.domain} (not seen within {timeout:g} s)")
    return snap[1], snap[2], snap[3]


def _endpoint_key(info: Any) -> tuple:
    return (info.node_name, info.node_namespace, bytes(info.endpoint_gid), str(info))


def format_topic_info(types: list[str], pubs: list[Any], subs: list[Any], verbose: bool = False) -> str:
    """ros2's layout: ``Type:``, ``Publisher count:``, ``Subscription count:`` lines; with ``verbose``
    each followed by an empty line and the endpoints' blocks (rclpy's TopicEndpointInfo text: node,
    type, GID, QoS profile), blank-line separated."""
    end = "\n\n" if verbose else "\n"
    out = "Type: " + (types[0] if len(types) == 1 else str(types)) + end
    out += f"Publisher count: {len(pubs)}" + end
    if verbose:
        out += "".join(str(i) + end for i in pubs)
    out += f"Subscription count: {len(subs)}" + end
    if verbose:
        out += "".join(str(i) + end for i in subs)
    return out
