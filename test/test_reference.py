"""docs/reference (one page per node, from nodes/interface.py and nodes/specs.py) is what the generator
writes now, and every parameter and topic it names is one the running node has: the seven nodes built
in-process once per session (test_docs_match_code's ``real``). Every node declares exactly its specs
(name, type, range, read-only, description). Also the ParamSpec checks and the graph's lockstep rule."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from test_docs_match_code import INFRA, real  # noqa: F401 (the fixture)

from cpg_walker.graph.reference import RCLPY_PARAMETERS, pages
from cpg_walker.nodes import interface as ifc
from cpg_walker.nodes.params import ParamSpec, boolean, check, double, integer, strings
from cpg_walker.nodes.specs import SPECS

REPO = Path(__file__).resolve().parent.parent
REFERENCE = REPO / "docs" / "reference"
REGENERATE = "regenerate: python -m cpg_walker.graph.reference --out docs/reference"


def page_params(text: str) -> list[str]:
    return re.findall(r"^\| `([^`]+)` \| [a-z_]+ \|", text, re.M)


def page_topics(text: str) -> dict[str, set[str]]:
    out: dict[str, set[str]] = {"subscribes": set(), "publishes": set()}
    for what, topic in re.findall(r"^\| (subscribes|publishes) \| `([^`]+)` \|", text, re.M):
        out[what].add(topic)
    return out


@pytest.mark.ros
def test_committed_reference_is_what_the_generator_writes(real):  # noqa: F811
    want = pages()
    have = {p.name: p.read_text(encoding="utf-8") for p in REFERENCE.glob("*.md")}
    assert set(have) == set(want) == {f"{exe}.md" for exe in ifc.NODE_NAMES}, REGENERATE
    stale = [name for name in want if have[name] != want[name]]
    assert not stale, f"{stale} differ from the specs: {REGENERATE}"


@pytest.mark.ros
def test_reference_names_only_what_the_nodes_have(real):  # noqa: F811
    """Both ways: the page's parameters are the node's declared ones; its topics are the node's
    subscriptions and publishers (and all of them, but for a node whose topics are chosen at run time)."""
    problems = []
    for exe, name in ifc.NODE_NAMES.items():
        text = (REFERENCE / f"{exe}.md").read_text(encoding="utf-8")
        declared = real.params[name] - set(RCLPY_PARAMETERS)
        listed = set(page_params(text))
        problems += [f"{exe}.md: parameter {p} is not declared by /{name}" for p in sorted(listed - declared)]
        problems += [f"{exe}.md: /{name}'s parameter {p} is missing" for p in sorted(declared - listed)]
        topics = page_topics(text)
        for what, have in (("subscribes", real.subs[name]), ("publishes", real.pubs[name])):
            absent = topics[what] - have
            if exe in (ifc.SIM_NODE, ifc.ODOM_NODE) and what == "publishes":
                absent -= {ifc.TF}  # only where tf2_msgs imports (a ROS install)
            problems += [f"{exe}.md: /{name} {what} no {t}" for t in sorted(absent)]
            if not ifc.INTERFACES[exe].runtime_topics:
                extra = have - topics[what] - INFRA
                problems += [f"{exe}.md: /{name} also {what} {t}" for t in sorted(extra)]
    assert not problems, "\n".join(problems)


@pytest.mark.ros
def test_nodes_declare_exactly_their_specs(real):  # noqa: F811
    for exe, specs in SPECS.items():
        declared = {s.name: s for s in real.specs[ifc.NODE_NAMES[exe]]}
        assert declared == {s.name: s for s in specs}, exe


def test_check_names_the_parameter_and_the_reason():
    rate = double("real_time_factor", "speed", 0.01, 100.0)
    assert check(rate, 1.0) is None and check(rate, 3) is None
    assert check(rate, 200.0) == "real_time_factor must be in [0.01, 100], got 200.0"
    assert check(rate, float("nan")) == "real_time_factor must be finite, got nan"
    assert check(rate, "1") == "real_time_factor must be a number, got '1'"
    assert check(rate, True) == "real_time_factor must be a number, got True"
    port = integer("port", "tcp port", 0, 65535)
    assert check(port, 8765) is None
    assert check(port, 1.5) == "port must be an integer, got 1.5"
    assert check(port, -1) == "port must be in [0, 65535], got -1"
    assert check(boolean("lockstep", "x"), 1) == "lockstep must be true or false, got 1"
    assert check(strings("topics", "x"), ["/a", 2]) == "topics must be a list of strings, got ['/a', 2]"


def test_param_spec_refuses_an_incoherent_spec():
    with pytest.raises(ValueError, match="both ends"):
        ParamSpec("x", "double", "d", lo=0.0)
    with pytest.raises(ValueError, match="only a double or integer"):
        ParamSpec("x", "string", "d", lo=0, hi=1)
    with pytest.raises(ValueError, match="needs a range"):
        ParamSpec("x", "integer", "d")
    with pytest.raises(ValueError, match="type must be"):
        ParamSpec("x", "float", "d")


def test_the_lockstep_rule_and_the_graphs():
    assert [p for p in ifc.PACINGS if ifc.controllers_lockstep(p)] == ["lockstep"]
    assert ifc.graph_nodes() == ("sim_node", "pid_node", "cpg_node")
    assert ifc.graph_nodes(ifc.PLAYER_NODE)[-1] == "target_player_node"
    with pytest.raises(ValueError):
        ifc.graph_nodes("relay_node")
    assert set(ifc.INTERFACES) == set(ifc.NODE_NAMES)
    assert all(t in ifc.TOPICS for i in ifc.INTERFACES.values() for t in (*i.subscribes, *i.publishes))


def test_foot_load_sides_are_the_frames_sides():
    from cpg_walker.robot.frames import FOOT_LOAD_FRAMES

    assert tuple(side for side, _ in FOOT_LOAD_FRAMES) == ifc.FOOT_LOAD_SIDES
