"""The README stays a newcomer's guide: at most 250 lines, with a Mermaid ``flowchart`` of the node graph that
names every topic the nodes publish or subscribe, read from the nodes' source (no ROS needed: the
``create_publisher`` / ``create_subscription`` calls of cpg_walker/nodes/*_node.py, relay_node's topics from
config/relay.yaml); and every relative link of the docs (README.md, CHANGELOG.md, docs/*.md) points at a
file or directory that exists. test_docs_match_code.py checks the graph against the built nodes too."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parent.parent
README = REPO / "README.md"
MAX_LINES = 250

#: A topic in the graph's text: /a/b, not the '/' of 'br/' or a path's inner slash.
TOPIC = re.compile(r"(?<![\w./~:$)\-])/[A-Za-z_]\w*(?:/\w+)*")
MERMAID = re.compile(r"^```mermaid\n(.*?)^```", re.S | re.M)

#: Nodes whose topics are not literals in their source: the recorder subscribes to whatever it finds, the
#: relay's are data (config/relay.yaml, read below). A dynamic topic in any other node fails the scan.
DYNAMIC = {"recorder_node.py", "relay_node.py"}

#: Links to a page another piece of work is adding (checked as soon as it exists): the generated per-node
#: parameter reference (docs/reference/<node>.md, issue 23).
PENDING = {"docs/reference"}


def graph_topics(readme: str) -> set[str]:
    """The topics named in the README's Mermaid flowchart (AssertionError when there is none)."""
    blocks = MERMAID.findall(readme)
    graphs = [b for b in blocks if b.lstrip().startswith("flowchart")]
    assert len(graphs) == 1, f"README.md: expected one ```mermaid flowchart block, found {len(graphs)}"
    return set(TOPIC.findall(graphs[0]))


def _sides() -> tuple[str, ...]:
    """The sole-load topics' suffixes (robot/frames.py's FOOT_LOAD_FRAMES, read without importing MuJoCo)."""
    tree = ast.parse((REPO / "cpg_walker/robot/frames.py").read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and any(getattr(t, "id", "") == "FOOT_LOAD_FRAMES"
                                                 for t in node.targets):
            return tuple(pair.elts[0].value for pair in node.value.elts)
    raise AssertionError("robot/frames.py: FOOT_LOAD_FRAMES not found")


def _topic_args(path: Path) -> tuple[set[str], list[str]]:
    """(topics, unresolved) of the create_publisher / create_subscription calls in one node's source: a
    string literal; an f-string (only the sole loads use one: each placeholder is a FOOT_LOAD_FRAMES side);
    a name bound by the enclosing comprehension over a literal tuple (foxglove_node's list)."""
    tree = ast.parse(path.read_text())
    parents = {child: node for node in ast.walk(tree) for child in ast.iter_child_nodes(node)}
    topics, unresolved = set(), []
    for call in ast.walk(tree):
        if not (isinstance(call, ast.Call) and isinstance(call.func, ast.Attribute)
                and call.func.attr in ("create_publisher", "create_subscription") and len(call.args) >= 2):
            continue
        arg = call.args[1]
        if isinstance(arg, ast.Constant) and isinstance(arg.value, str):
            topics.add(arg.value)
        elif isinstance(arg, ast.JoinedStr):
            head = "".join(v.value for v in arg.values if isinstance(v, ast.Constant))
            assert head == "/foot_load/" and len(arg.values) == 2, (path.name, ast.unparse(arg))
            topics |= {head + side for side in _sides()}
        elif isinstance(arg, ast.Name):
            node, found = call, None
            while node in parents and found is None:
                node = parents[node]
                if isinstance(node, (ast.ListComp, ast.GeneratorExp, ast.SetComp)):
                    found = {c.value for g in node.generators for c in ast.walk(g.iter)
                             if isinstance(c, ast.Constant) and isinstance(c.value, str)
                             and c.value.startswith("/")}
            if found:
                topics |= found
            else:
                unresolved.append(ast.unparse(arg))
        else:
            unresolved.append(ast.unparse(arg))
    return topics, unresolved


def code_topics() -> set[str]:
    """Every topic a node of the package publishes or subscribes, from the source."""
    topics = set()
    for path in sorted((REPO / "cpg_walker/nodes").glob("*_node.py")):
        found, unresolved = _topic_args(path)
        assert not unresolved or path.name in DYNAMIC, \
            f"{path.name}: a topic not read from the source: {unresolved}"
        topics |= found
    relay = yaml.safe_load((REPO / "config/relay.yaml").read_text())["relay"]["ros__parameters"]
    topics |= set(relay["topics"]) | {relay["prefix"] + t for t in relay["topics"]}
    return topics


def test_readme_is_short():
    n = len(README.read_text(encoding="utf-8").splitlines())
    assert n <= MAX_LINES, f"README.md has {n} lines (at most {MAX_LINES}: move details to docs/)"


def test_the_scan_finds_the_nodes_topics():
    """The source scan still sees the graph (a refactor that hides the topics from it must fail here)."""
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
