"""The docs agree with the code: every ROS topic, node parameter and TF frame that README.md, CHANGELOG.md
and docs/*.md name exists in the nodes.

What is read from the docs (``Doc``): inline code spans (also across a line break) and fenced code
blocks; in them, topic-like names (``/a/b``, ``/foot_load/*``, ``/foot_load/{left,right}``; filesystem
paths and file names left out), ``/NODE.NAME`` (a parameter as Foxglove names it), the parameters of
``param set|get|describe /NODE NAME``, ``ros2 run cpg_walker EXE ... -p NAME:=`` and ``graph -p
NODE:NAME=``; the parameters of the parameter tables, of the "Parameters ..." paragraphs and their bullet
lists (the names outside parentheses: inside are values and remarks) and of "parameter(s) `a`, `b`";
frames after "frame(s)"/"child", both ends of "`a` -> `b`" when one is a frame, and the frame-names
paragraph. ROS_INTERFACE.md's node table and per-node topic tables are checked row by row against each
node's own publishers and subscriptions, both ways, and the README's Mermaid graph must name every topic a
node publishes or subscribes (test_readme.py checks the same from the source, without ROS).

What is read from the code: every node class built in-process (one rclpy context on the test's own
domain; sim_node loads MuJoCo, cpg_node its learned CPG: ~8 s in all), from its packaged parameters file:
``Node.publishers`` / ``subscriptions`` / ``services`` topic names, the declared parameters, foxglove_node's
channels; the frames are robot/hoap2.urdf's links plus ``frames.ODOM_FRAME``. Each failure names the
mention as file:line."""

from __future__ import annotations

import itertools
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from cpg_walker.nodes import interface as ifc

REPO = Path(__file__).resolve().parent.parent
#: Every doc a reader gets (the topic pages too: text moved out of the README stays checked); the
#: generated per-node reference under docs/reference/ is its generator's business.
DOCS = ("README.md", "CHANGELOG.md",
        *sorted(p.relative_to(REPO).as_posix() for p in (REPO / "docs").glob("*.md")))

#: Names the docs rightly use that are no topic, service or node of ours (prefix match at a '/').
ALLOWED = {
    ifc.TF: "robot_state_publisher's (walk.launch.py); sim_node creates it only where tf2_msgs imports (not "
           "on PyPI); the recorder writes it into bags",
    ifc.TF_STATIC: "robot_state_publisher's; the recorder writes it into bags",
    "/rosout": "rcl's logging publisher of every node, not among rclpy's Node.publishers",
    "/nonexistent": "the absent node of an error example",
    "/x": "placeholder in a quoted error message",
    "/node": "placeholder in '/node: ros__parameters:' (param dump's layout)",
    "/cpg_walker": "SROS2 enclave names (--enclave /cpg_walker/sim)",
}
#: Topics that every node has and no doc table has to list.
INFRA = {ifc.PARAMETER_EVENTS, ifc.ROSOUT}

#: First components of filesystem paths (/tmp/..., /path/to/python3): no topics.
FS_ROOTS = {"dev", "proc", "sys", "tmp", "opt", "usr", "etc", "home", "lib", "work", "var", "root", "mnt",
            "path"}
FILE_EXT = re.compile(r"\.(?:ya?ml|bash|sh|cpp|py|json|md|mcap|urdf|xml|png|txt|csv)\b")
TOPIC = re.compile(r"(?<![\w./~:$)\-])/[A-Za-z_]\w*(?:/(?:\w+|\*|\{[\w,]+\}))*")
IDENT = re.compile(r"[a-z_][a-z0-9_]*(?:\.(?:[a-z0-9_]+|<\w+>|\*))*")
SPAN = re.compile(r"(?<!`)`([^`\n]+(?:\n[^`\n]+)?)`(?!`)")
FENCE = re.compile(r"^```.*?^```", re.S | re.M)


@dataclass
class Mention:
    name: str
    where: str
    node: str | None = None  # the node it is said to belong to (None: any)


@dataclass
class Doc:
    """A markdown file: its text with fenced blocks blanked (``prose``) and the blocks (``fences``)."""

    path: str
    text: str
    prose: str = ""
    fences: list[tuple[int, str]] = field(default_factory=list)  # (offset, block text)
    heads: list[tuple[int, str]] = field(default_factory=list)  # (offset, first word) of the '## ' headings

    def __post_init__(self):
        self.prose = FENCE.sub(lambda m: re.sub(r"[^\n]", " ", m.group(0)), self.text)
        self.fences = [(m.start(), m.group(0)) for m in FENCE.finditer(self.text)]
        self.heads = [(m.start(), m.group(1)) for m in re.finditer(r"^## (\w+)", self.prose, re.M)]

    def where(self, offset: int) -> str:
        return f"{self.path}:{self.text.count(chr(10), 0, offset) + 1}"

    def spans(self, start: int = 0, end: int | None = None):
        """(offset, content) of the inline code spans of prose[start:end]."""
        for m in SPAN.finditer(self.prose, start, len(self.prose) if end is None else end):
            yield m.start(1), m.group(1)

    def code(self):
        """Every piece of code: the inline spans and the fenced blocks' lines."""
        yield from self.spans()
        for offset, block in self.fences:
            pos = offset
            for line in block.split("\n"):
                yield pos, line
                pos += len(line) + 1

    def section_node(self, offset: int) -> str | None:
        """The node whose `## <exe> ...` section holds ``offset`` (sub-sections included)."""
        from cpg_walker.nodes.interface import NODE_NAMES

        heads = [name for start, name in self.heads if start <= offset]
        return NODE_NAMES.get(heads[-1]) if heads else None

    def paragraphs(self):
        """(offset, text) of the prose's paragraphs and list items."""
        for m in re.finditer(r"(?:^(?!\s*$).*\n?)+", self.prose, re.M):
            block, base = m.group(0), m.start()
            items = [i.start() for i in re.finditer(r"^\s*[*-] ", block, re.M)]
            cuts = sorted({0, *items, len(block)})
            for a, b in itertools.pairwise(cuts):
                yield base + a, block[a:b]


def read_docs() -> list[Doc]:
    return [Doc(p, (REPO / p).read_text()) for p in DOCS]


def read_doc(path: str) -> Doc:
    return next(d for d in read_docs() if d.path == path)


def expand(name: str) -> list[str]:
    m = re.search(r"\{([\w,]+)\}", name)
    return [name[:m.start()] + alt + name[m.end():] for alt in m.group(1).split(",")] if m else [name]


def topic_mentions(doc: Doc) -> list[Mention]:
    out = []
    for offset, code in doc.code():
        for m in TOPIC.finditer(code):
            name = m.group(0)
            if name.split("/")[1] in FS_ROOTS or FILE_EXT.match(code, m.end()):
                continue
            out += [Mention(n, doc.where(offset + m.start())) for n in expand(name)]
    return out


def outside_parens(text: str, offset: int, before_colon: bool = False) -> list[tuple[int, str]]:
    """The code spans of ``text`` at parenthesis depth 0 (``before_colon``: up to the first ': ' there);
    plus those of a parenthesis that holds nothing but a list of code spans."""
    out, depth, i = [], 0, 0
    while i < len(text):
        c = text[i]
        if c == "`":
            j = text.find("`", i + 1)
            if j < 0:
                break
            if depth == 0:
                out.append((offset + i + 1, text[i + 1:j]))
            i = j + 1
            continue
        if c == "(":
            close = text.find(")", i)
            inner = text[i + 1:close] if close > 0 else ""
            if close > 0 and re.fullmatch(r"\s*`[^`]+`(?:\s*(?:,|/|and|or)\s*`[^`]+`)*\s*", inner):
                out += [(offset + i + 1 + s.start(1), s.group(1)) for s in re.finditer(r"`([^`]+)`", inner)]
                i = close + 1
                continue
            depth += 1
        elif c == ")":
            depth = max(0, depth - 1)
        elif before_colon and depth == 0 and text.startswith(": ", i):
            break
        i += 1
    return out


def param_mentions(doc: Doc) -> list[Mention]:
    from cpg_walker.nodes.interface import NODE_NAMES

    found: list[tuple[int, str, str | None]] = []  # (offset, name, node)

    def add(offset: int, name: str, node: str | None) -> None:
        name = name.strip()
        if IDENT.fullmatch(name):
            found.append((offset, name, node))

    # parameter tables: the first column (node: the section's), and the parameters files' table
    for m in re.finditer(r"^\|([^|\n]*)\|.*\n\|[-| ]+\|\n((?:\|.*\n?)+)", doc.prose, re.M):
        head, rows = m.group(1).strip().lower(), m.group(2)
        base = m.start(2)
        for row in re.finditer(r"^\|(.*)$", rows, re.M):
            cells = row.group(1).split("|")
            if head.startswith("parameter"):
                node = doc.section_node(m.start())
                for s in re.finditer(r"`([^`]+)`", cells[0]):
                    add(base + row.start(1) + s.start(1), s.group(1), node)
            elif head == "file" and len(cells) >= 3:
                node = re.search(r"\(`?(\w+)`?\)", cells[1])
                start = base + row.start(1) + len(cells[0]) + len(cells[1]) + 2
                for off, name in outside_parens(cells[2], start):
                    add(off, name, node and node.group(1))
    # "Parameters ..." paragraphs and the list items after one ending in ':'
    in_list = None
    for offset, para in doc.paragraphs():
        node = doc.section_node(offset)
        is_item = bool(re.match(r"\s*[*-] ", para))
        if re.match(r"\s*Parameters\b", para):
            for off, name in outside_parens(para, offset):
                add(off, name, node)
            in_list = para.rstrip().endswith(":")
        elif is_item and in_list:
            for off, name in outside_parens(para, offset, before_colon=True):
                add(off, name, node)
        elif not is_item:
            in_list = False
    # "parameter `a`", "parameters `a` (...), `b` and `c`", "Parameters: config/x.yaml (`a`, `b`)"
    sep = r"(?:\s*\([^()]*\))?\s*(?:,\s*(?:and\s+)?|\s+and\s+|\s*/\s*|\s+or\s+)"
    for m in re.finditer(rf"\b[Pp]arameters?:?\s+(?:config/[\w.]+\s+\()?(`[^`\n]+`(?:{sep}`[^`\n]+`)*)",
                         doc.prose):
        for s in re.finditer(r"`([^`]+)`", m.group(1)):
            add(m.start(1) + s.start(1), s.group(1), doc.section_node(m.start()))
    # commands
    for offset, code in doc.code():
        for m in re.finditer(r"param\s+(?:set|get)\s+/(\w+)\s+([\w.]+)", code):
            add(offset + m.start(2), m.group(2), m.group(1))
        for m in re.finditer(r"param\s+describe\s+/(\w+)((?:\s+[a-z][\w.]*)+)", code):
            for s in re.finditer(r"[a-z][\w.]*", m.group(2)):
                add(offset + m.start(2) + s.start(), s.group(0), m.group(1))
        exe = re.search(r"(?:ros2 run cpg_walker |cpg_walker\.nodes\.)(\w+)", code)
        node = NODE_NAMES.get(exe.group(1)) if exe else doc.section_node(offset)
        for m in re.finditer(r"(?<!\w)-p\s+([\w.]+):=", code):
            add(offset + m.start(1), m.group(1), node)
        for m in re.finditer(r"(?<!\w)-p\s+(sim|pid|cpg|player):([\w.]+)=", code):
            add(offset + m.start(2), m.group(2), "target_player" if m.group(1) == "player" else m.group(1))
        for m in TOPIC.finditer(code):  # Foxglove's /NODE.NAME
            dotted = re.match(r"\.([a-z_][\w.]*[a-z0-9_])", code[m.end():])
            if dotted and m.group(0).count("/") == 1 and m.group(0)[1:] in NODE_NAMES.values():
                add(offset + m.end() + 1, dotted.group(1), m.group(0)[1:])
    seen, out = set(), []
    for offset, name, node in sorted(found):
        if (offset, name) not in seen:
            seen.add((offset, name))
            out.append(Mention(name, doc.where(offset), node))
    return out


def frame_mentions(doc: Doc, frames: set[str]) -> list[Mention]:
    out = []
    sep = r"(?:\s*,\s*(?:and\s+)?|\s+and\s+|\s*/\s*)"
    for m in re.finditer(rf"\b(?:frames?|child)\s+(`[^`\n]+`(?:{sep}`[^`\n]+`)*)", doc.prose):
        out += [Mention(s.group(1), doc.where(m.start(1) + s.start(1)))
                for s in re.finditer(r"`([^`]+)`", m.group(1))]
    pairs = [(m.start(), m.group(1), m.group(2))
             for m in re.finditer(r"`([\w<> ]+)`\s*->\s*`([\w<> ]+)`", doc.prose)]
    pairs += [(off, *code.split("->")) for off, code in doc.spans() if code.count("->") == 1]
    for off, a, b in pairs:
        a, b = a.strip(), b.strip()
        if "<" not in a + b and (a in frames or b in frames):
            out += [Mention(a, doc.where(off)), Mention(b, doc.where(off))]
    for offset, para in doc.paragraphs():
        if para.startswith("Frame names"):
            out += [Mention(n, doc.where(o)) for o, n in outside_parens(para, offset) if IDENT.fullmatch(n)]
    return out


def allowed(name: str) -> bool:
    return any(name == a or name.startswith(a + "/") for a in ALLOWED)


# ------------------------------------------------------------------------------------------ the code

@dataclass
class Real:
    pubs: dict[str, set[str]]  # node name -> topics
    subs: dict[str, set[str]]
    services: set[str]
    params: dict[str, set[str]]
    channels: set[str]  # foxglove_node's channels (Foxglove topics, not ROS)
    specs: dict[str, tuple] = field(default_factory=dict)  # node name -> its declared parameters (ParamSpec)

    def names(self) -> set[str]:
        """Every topic, service, node and namespace of ours, and the Foxglove channels."""
        full = set(self.services) | self.channels | {f"/{n}" for n in self.params}
        for d in (self.pubs, self.subs):
            for topics in d.values():
                full |= topics
        spaces = {"/".join(n.split("/")[:k]) for n in full for k in range(2, n.count("/") + 1)}
        return full | spaces

    def has_param(self, node: str | None, name: str) -> bool:
        from cpg_walker.robot.pid import gain_owner

        nodes = [node] if node in self.params else list(self.params) if node is None else []
        pattern = re.compile(re.sub(r"<\w+>", r"[^.]+", re.escape(name).replace(r"\*", ".+"))
                             .replace(r"\<", "<").replace(r"\>", ">"))
        for n in nodes:
            if any(pattern.fullmatch(p) for p in self.params[n]):
                return True
            if n == "pid":  # per-joint gains, declared when given at start-up
                try:
                    gain_owner(name)
                    return True
                except ValueError:
                    pass
        return False


def _build() -> Real:
    import os
    import tempfile

    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    import cpg_walker.nodes.sim_node as sim_module
    from cpg_walker.graph.processes import random_domain_id
    from cpg_walker.graph.reference import declared_specs
    from cpg_walker.nodes.cpg_node import CPGNode
    from cpg_walker.nodes.foxglove_node import FoxgloveNode
    from cpg_walker.nodes.odom_node import OdomNode
    from cpg_walker.nodes.params import params_file
    from cpg_walker.nodes.pid_node import PidNode
    from cpg_walker.nodes.recorder_node import RecorderNode
    from cpg_walker.nodes.relay_node import RelayNode
    from cpg_walker.nodes.target_player_node import TargetPlayerNode

    ctx = rclpy.Context()
    domain = int(os.environ.get("ROS_DOMAIN_ID") or random_domain_id())
    rclpy.init(context=ctx, domain_id=domain, signal_handler_options=SignalHandlerOptions.NO)
    real = Real({}, {}, set(), {}, set())
    saved = sim_module.SingleThreadedExecutor  # sim_node makes its executor in the default context
    sim_module.SingleThreadedExecutor = lambda: SingleThreadedExecutor(context=ctx)
    try:
        with tempfile.TemporaryDirectory() as tmp:
            for cls, extra in ((sim_module.SimNode, []), (PidNode, []), (CPGNode, []), (TargetPlayerNode, []),
                               (RelayNode, []), (OdomNode, []), (FoxgloveNode, ["-p", "port:=0"]),
                               (RecorderNode, ["-p", f"out_dir:={tmp}/bag"])):
                name = cls.__name__  # the node's name below, once built
                node = cls(context=ctx, cli_args=["--ros-args", "--params-file",
                                                  str(params_file(_NAME[name])), *extra])
                try:
                    n = node.get_name()
                    real.pubs[n] = {p.topic_name for p in node.publishers}
                    # the recorder subscribes to whatever it finds: nothing of its own
                    real.subs[n] = set() if n == "recorder" else {s.topic_name for s in node.subscriptions}
                    real.services |= {"/" + (s.srv_name.replace("~", n) if s.srv_name.startswith("~")
                                             else s.srv_name).lstrip("/") for s in node.services}
                    real.params[n] = set(node._parameters)
                    real.specs[n] = declared_specs(node)
                    taker = getattr(node, "taker", None)  # foxglove_node's hidden subscriber node
                    if taker is not None:
                        real.subs[n] |= {s.topic_name for s in taker.subscriptions}
                        real.channels = {ch.topic() for ch in vars(node).values()
                                         if hasattr(ch, "schema_name")}
                finally:
                    if n == "foxglove":
                        node.on_exit()
                    node.destroy_node()
    finally:
        sim_module.SingleThreadedExecutor = saved
        rclpy.try_shutdown(context=ctx)
    return real


_NAME = {"SimNode": "sim", "PidNode": "pid", "CPGNode": "cpg", "TargetPlayerNode": "target_player",
         "RelayNode": "relay", "FoxgloveNode": "foxglove", "RecorderNode": "recorder", "OdomNode": "odom"}
_REAL: list[Real] = []


@pytest.fixture
def real(ros_domain) -> Real:
    """The nodes' interfaces, built once per session (inside the first ``ros`` test's domain)."""
    if not _REAL:
        _REAL.append(_build())
    return _REAL[0]


def real_frames() -> set[str]:
    from cpg_walker.robot.frames import ODOM_FRAME

    urdf = ET.parse(REPO / "cpg_walker/robot/hoap2.urdf").getroot()
    return {link.get("name") for link in urdf.iter("link")} | {ODOM_FRAME}


def report(kind: str, bad: list[Mention]) -> str:
    return f"{len(bad)} {kind} named in the docs that the code does not have:\n" + "\n".join(
        f"  {m.where}: {m.name}" + (f" (node {m.node})" if m.node else "") for m in bad)


# ------------------------------------------------------------------------------------------ tests

@pytest.mark.ros
def test_every_topic_the_docs_name_exists(real):
    names = real.names()
    mentions = [m for d in read_docs() for m in topic_mentions(d)]
    assert len(mentions) > 300  # the extraction still finds the docs' topics
    bad = []
    for m in mentions:
        if allowed(m.name):
            continue
        pattern = re.compile(re.escape(m.name).replace(r"\*", "[^/]+"))
        if not any(pattern.fullmatch(n) for n in names):
            bad.append(m)
    assert not bad, report("topics/services/nodes", bad)


@pytest.mark.ros
def test_every_parameter_the_docs_name_exists(real):
    mentions = [m for d in read_docs() for m in param_mentions(d)]
    assert len(mentions) > 120
    assert {m.node for m in mentions} >= {"sim", "pid", "cpg", "foxglove", "recorder", "relay", None}
    bad = [m for m in mentions if not allowed(f"/{m.node}") and not real.has_param(m.node, m.name)]
    assert not bad, report("parameters", bad)


def test_every_frame_the_docs_name_exists():
    frames = real_frames()
    mentions = [m for d in read_docs() for m in frame_mentions(d, frames)]
    assert {m.name for m in mentions} >= {"odom", "base_link", "imu", "l_sole", "r_sole"}
    bad = [m for m in mentions if m.name not in frames]
    assert not bad, report("frames", bad)


def _topics(cell: str) -> set[str]:
    return {n for m in TOPIC.finditer(cell) for n in expand(m.group(0))}


@pytest.mark.ros
def test_node_table_lists_each_nodes_topics(real):
    """ROS_INTERFACE.md's node table (moved there from the README), row by row, both ways: what a node
    subscribes and publishes, no more, no less; a row for every node (foxglove_node's Foxglove channels are
    not ROS topics)."""
    from cpg_walker.nodes.interface import NODE_NAMES

    doc = read_doc("docs/ROS_INTERFACE.md")
    table = re.search(r"^\| node \| subscribes \| publishes \|\n\|[-|]+\|\n((?:\|.*\n)+)", doc.prose, re.M)
    assert table, f"{doc.path}: the node table (| node | subscribes | publishes |) is gone"
    problems, rows = [], set()
    for row in re.finditer(r"^\| `(\w+)` \|([^|]*)\|(.*)\|$", table.group(1), re.M):
        node, where = NODE_NAMES[row.group(1)], doc.where(table.start(1) + row.start())
        rows.add(node)
        for what, cell, have in (("subscribes", row.group(2), real.subs[node]),
                                 ("publishes", row.group(3), real.pubs[node])):
            said = {t for t in _topics(cell) if not allowed(t) and t not in real.channels - have}
            if said - have:
                problems.append(f"{where}: {row.group(1)} {what} {sorted(said - have)}: the node does not")
            if have - said - INFRA:
                problems.append(f"{where}: {row.group(1)} also {what} {sorted(have - said - INFRA)}")
    missing = set(NODE_NAMES.values()) - rows
    problems += [f"{doc.path}: no row for {sorted(missing)}"] if missing else []
    assert not problems, "\n".join(problems)


@pytest.mark.ros
def test_node_sections_topic_tables_match_the_node(real):
    """docs/ROS_INTERFACE.md's `| topic | type | ...` table of a node's section: a row marked '(sub)' is one
    of its subscriptions, every other row one of its publishers; every publisher has a row, and every
    subscription too where the table has '(sub)' rows."""
    doc = read_doc("docs/ROS_INTERFACE.md")
    problems, nodes = [], set()
    for m in re.finditer(r"^\| topic \|.*\n\|[-|]+\|\n((?:\|.*\n)+)", doc.prose, re.M):
        node = doc.section_node(m.start())
        nodes.add(node)
        said = {True: set(), False: set()}  # (sub) rows, the others
        for row in re.finditer(r"^\|([^|]*)\|", m.group(1), re.M):
            where = doc.where(m.start(1) + row.start())
            sub = "(sub)" in row.group(1)
            for t in _topics(row.group(1)):
                said[sub].add(t)
                if t not in (real.subs[node] if sub else real.pubs[node]) and not allowed(t):
                    kind = "subscription" if sub else "publisher"
                    problems.append(f"{where}: {t} is not a {kind} of {node}")
        for sub, have in ((False, real.pubs[node]), (True, real.subs[node] if said[True] else set())):
            for t in sorted(have - said[sub] - INFRA):
                problems.append(f"{doc.where(m.start())}: {node}'s table has no row for its "
                                f"{'subscription' if sub else 'publisher'} {t}")
    assert nodes >= {"sim", "cpg"}
    assert not problems, "\n".join(problems)


@pytest.mark.ros
def test_readme_graph_names_every_topic_of_the_nodes(real):
    """The README's Mermaid node graph names every topic the built nodes publish or subscribe (their real
    endpoints, relay_node's /net/... included; /rosout is rcl's), and nothing that is not one of ours."""
    from test_readme import graph_topics

    said = graph_topics((REPO / "README.md").read_text(encoding="utf-8"))
    have = set().union(*real.pubs.values(), *real.subs.values()) - {"/rosout"}
    assert not have - said, f"README.md's graph lacks {sorted(have - said)}"
    names = real.names()
    assert not {t for t in said if not allowed(t) and t not in names}, sorted(said - names)


def test_the_allow_list_is_used():
    """Every ALLOWED entry still matches a mention (a stale entry would hide a future mistake)."""
    used = {a for d in read_docs() for m in topic_mentions(d) for a in ALLOWED
            if m.name == a or m.name.startswith(a + "/")}
    assert used == set(ALLOWED), f"unused: {sorted(set(ALLOWED) - used)}"
