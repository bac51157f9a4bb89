"""The README stays a newcomer's guide: at most 250 lines, with a Mermaid ``flowchart`` of the node graph that
names every topic the nodes publish or subscribe (nodes/interface.py's INTERFACES, which test_reference.py
checks against the running nodes both ways; relay_node's topics from config/relay.yaml); and every relative
link of the docs (README.md, CHANGELOG.md, docs/*.md) points at a file or directory that exists."""

from __future__ import annotations

import re
from pathlib import Path

import yaml

from cpg_walker.nodes.interface import INTERFACES

REPO = Path(__file__).resolve().parent.parent
README = REPO / "README.md"
MAX_LINES = 250

#: A topic in the graph's text: /a/b, not the '/' of 'br/' or a path's inner slash.
TOPIC = re.compile(r"(?<![\w./~:$)\-])/[A-Za-z_]\w*(?:/\w+)*")
MERMAID = re.compile(r"^```mermaid\n(.*?)^```", re.S | re.M)

#: Links to a page that may not exist yet (checked as soon as it exists).
PENDING: set[str] = set()


def graph_topics(readme: str) -> set[str]:
    """The topics named in the README's Mermaid flowchart (AssertionError when there is none)."""
    blocks = MERMAID.findall(readme)
    graphs = [b for b in blocks if b.lstrip().startswith("flowchart")]
    assert len(graphs) == 1, f"README.md: expected one ```mermaid flowchart block, found {len(graphs)}"
    return set(TOPIC.findall(graphs[0]))


def code_topics() -> set[str]:
    """Every topic a node of the package publishes or subscribes: the interface, and the relay's (data)."""
    topics = {t for i in INTERFACES.values() for t in (*i.subscribes, *i.publishes)}
    relay = yaml.safe_load((REPO / "config/relay.yaml").read_text())["relay"]["ros__parameters"]
    topics |= set(relay["topics"]) | {relay["prefix"] + t for t in relay["topics"]}
    return topics


def test_readme_is_short():
    n = len(README.read_text(encoding="utf-8").splitlines())
    assert n <= MAX_LINES, f"README.md has {n} lines (at most {MAX_LINES}: move details to docs/)"


def test_the_scan_finds_the_nodes_topics():
    """The interface still names the graph's topics (a refactor that loses them must fail here)."""
    assert code_topics() >= {"/clock", "/joint_states", "/joint_torques", "/joint_targets",
                             "/joint_trajectory", "/imu", "/foot_load/left", "/foot_load/right",
                             "/odom/ground_truth", "/cmd_vel",
                             "/sim/servo_hold", "/sim/fallen", "/cpg/state", "/diagnostics", "/tf",
                             "/robot_description", "/net/joint_states", "/net/joint_targets", "/net/imu"}


def test_readme_graph_names_every_topic():
    said = graph_topics(README.read_text(encoding="utf-8"))
    missing = code_topics() - said
    assert not missing, f"README.md's Mermaid graph lacks {sorted(missing)}"


LINK = re.compile(r"(?<!\\)\[[^\]\n]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")


def _docs() -> list[Path]:
    return [README, REPO / "CHANGELOG.md", *sorted((REPO / "docs").glob("*.md"))]


def test_relative_links_resolve():
    """Every relative markdown link (and image) of the docs points at an existing file or directory (the
    part before '#'); links inside code spans and fenced blocks are text, not links."""
    bad = []
    for doc in _docs():
        text = re.sub(r"^```.*?^```", "", doc.read_text(encoding="utf-8"), flags=re.S | re.M)
        text = re.sub(r"`[^`\n]*`", "", text)
        for m in LINK.finditer(text):
            target = m.group(1).split("#")[0]
            if not target or re.match(r"[a-z][a-z0-9+.-]*:", target):  # anchors only, http:, mailto:
                continue
            path = (doc.parent / target).resolve()
            rel = path.relative_to(REPO).as_posix() if path.is_relative_to(REPO) else str(path)
            if not path.exists() and rel.rstrip("/") not in PENDING:
                bad.append(f"{doc.relative_to(REPO)}: {m.group(0)}")
    assert not bad, "links to nothing:\n" + "\n".join(bad)


def test_the_link_check_sees_links():
    text = README.read_text(encoding="utf-8")
    assert len(LINK.findall(text)) >= 15
