"""Bad input to any `cpg-walker` sub-command: exactly one line on stderr naming the problem (the option, the
file, ROS_DOMAIN_ID), exit status 2, no traceback — and no work started. Property tests (hypothesis) fuzz
every sub-command's options and input files with values that are invalid by construction, in-process
through ``cli.main.main``; a few runs of the console script prove the end-to-end behaviour. A bug (an
exception other than InputError) is not swallowed."""

from __future__ import annotations

import argparse
import json
import math
import os
import string
import subprocess
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cpg_walker.cli.main import build_parser, main
from cpg_walker.nodes import interface as ifc
from cpg_walker.walker.controller import ALPHA_RANGE, ZETA_RANGE

FUZZ = settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
EXE = Path(__file__).resolve().parent.parent / ".venv" / "bin" / "cpg-walker"


def one_line_error(capsys, argv: list[str], needle: str) -> str:
    """Run ``argv``; assert status 2 and one stderr line holding ``needle``; return the line."""
    status = main(argv)
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert status == 2, (argv, status, err)
    assert "Traceback" not in err and len(lines) == 1, (argv, err)
    assert lines[0].startswith("cpg-walker") and ": error: " in lines[0], lines[0]
    assert needle in lines[0], (needle, lines[0])
    return lines[0]


def _parses(text: str, kind: type) -> bool:
    try:
        kind(text)
    except ValueError:
        return False
    return True


def not_a_number(kind: type = float) -> st.SearchStrategy[str]:
    """Text that ``kind`` does not parse."""
    return st.text(max_size=12).filter(lambda s: not _parses(s, kind))


def floats_outside(low: float, high: float) -> st.SearchStrategy[str]:
    """Numbers (as text) outside [low, high], and the non-finite ones."""
    return st.one_of(st.floats(max_value=low, exclude_max=True, allow_nan=False),
                     st.floats(min_value=high, exclude_min=True, allow_nan=False),
                     st.sampled_from([math.nan, math.inf, -math.inf])).map(repr)


def not_positive() -> st.SearchStrategy[str]:
    return st.one_of(st.floats(max_value=0.0, allow_nan=False).map(repr),
                     st.sampled_from(["nan", "inf", "-inf", "NaN", "Infinity"]), not_a_number())


def negative() -> st.SearchStrategy[str]:
    return st.one_of(st.floats(max_value=-1e-9, allow_nan=False).map(repr),
                     st.sampled_from(["nan", "inf", "-inf"]), not_a_number())


def ints_below(low: int) -> st.SearchStrategy[str]:
    return st.one_of(st.integers(max_value=low - 1).map(str), not_a_number(int))


def ints_outside(low: int, high: int) -> st.SearchStrategy[str]:
    return st.one_of(st.integers(max_value=low - 1).map(str), st.integers(min_value=high + 1).map(str),
                     not_a_number(int))


@pytest.fixture
def place(tmp_path: Path) -> dict[str, str]:
    """Paths the commands need besides the fuzzed one: a fresh output dir, a file, a CSV, a bag dir."""
    (tmp_path / "file").write_text("x\n")
    (tmp_path / "ok.csv").write_text("time,sig\n" + "".join(f"{i * 0.01},{i % 7}\n" for i in range(50)))
    (tmp_path / "bag").mkdir()
    return {"out": str(tmp_path / "out"), "file": str(tmp_path / "file"), "csv": str(tmp_path / "ok.csv"),
            "bag": str(tmp_path / "bag"), "tmp": str(tmp_path)}


# (command argv prefix, option, strategy of bad values). The prefix holds valid values of the other
# required options; {out} etc. are filled from ``place``.
NUMBERS = [
    (["walk", "--out", "{out}"], "--duration", not_positive),
    (["walk", "--out", "{out}"], "--zeta", lambda: floats_outside(*ZETA_RANGE) | not_a_number()),
    (["walk", "--out", "{out}"], "--alpha", lambda: floats_outside(*ALPHA_RANGE) | not_a_number()),
    (["cpg-walk", "--out", "{out}"], "--duration", not_positive),
    (["cpg-walk", "--out", "{out}"], "--zeta", lambda: floats_outside(*ZETA_RANGE)),
    (["cpg-walk", "--out", "{out}"], "--alpha", lambda: floats_outside(*ALPHA_RANGE)),
    (["cpg-walk", "--out", "{out}"], "--oscillators", lambda: ints_below(1)),
    (["cpg-walk", "--out", "{out}"], "--blend", negative),
    (["demo", "--out", "{out}"], "--duration", not_positive),
    (["demo", "--out", "{out}"], "--domain-id", lambda: ints_outside(0, 232)),
    (["graph"], "--duration", negative),
    (["graph"], "--zeta", lambda: floats_outside(*ZETA_RANGE)),
    (["graph"], "--alpha", lambda: floats_outside(*ALPHA_RANGE)),
    (["graph"], "--domain-id", lambda: ints_outside(0, 232)),
    (["faults", "--out", "{out}"], "--zeta", lambda: floats_outside(*ZETA_RANGE)),
    (["faults", "--out", "{out}"], "--warm", negative),
    (["faults", "--out", "{out}"], "--away", not_positive),
    (["replay", "--out", "{out}"], "--duration", not_positive),
    (["margins", "--out", "{out}"], "--duration", not_positive),
    (["soak", "--out", "{out}"], "--minutes", not_positive),
    (["soak", "--out", "{out}"], "--period", not_positive),
    (["sweep", "--out", "{out}"], "--duration", not_positive),
    (["sweep", "--out", "{out}"], "--jobs", lambda: ints_below(1)),
    (["learn", "--out", "{out}"], "--oscillators", lambda: ints_below(1)),
    (["fit", "--csv", "{csv}", "--out", "{out}"], "--oscillators", lambda: ints_below(1)),
    (["record", "--out", "{out}"], "--duration", negative),
    (["transport", "--out", "{out}"], "--duration", not_positive),
    (["transport", "--out", "{out}"], "--zetas", lambda: floats_outside(*ZETA_RANGE)),
    (["transport", "--out", "{out}"], "--seed", lambda: ints_outside(0, 2**32 - 1)),
    (["two-hosts", "--out", "{out}"], "--duration", not_positive),
    (["cmd-vel-map", "--out", "{out}"], "--jobs", lambda: ints_below(1)),
    (["cmd-vel-map", "--out", "{out}"], "--window", not_positive),
    (["drive-check", "--out", "{out}"], "--jobs", lambda: ints_below(1)),
    (["drive-check", "--out", "{out}", "--graph"], "--domain-id", lambda: ints_outside(0, 232)),
    (["teach", "--gait", "walk", "--out", "{out}"], "--rate", not_positive),
    (["teach", "--gait", "walk", "--out", "{out}"], "--speed", not_positive),
    (["teach", "--gait", "walk", "--out", "{out}"], "--duration", not_positive),
    (["teach", "--gait", "walk", "--out", "{out}"], "--alpha",
     lambda: floats_outside(0.0, 1.0) | not_a_number()),
    (["feedback-search", "--out", "{out}"], "--generations", lambda: ints_below(1)),
    (["feedback-search", "--out", "{out}"], "--popsize", lambda: ints_below(2)),
    (["feedback-search", "--out", "{out}"], "--jobs", lambda: ints_below(1)),
    (["feedback-search", "--out", "{out}"], "--seed", lambda: ints_outside(0, 2**32 - 1)),
    (["worker", "--storage", "sqlite:///{tmp}/s.db", "--study", "s"], "--jobs", lambda: ints_below(1)),
    (["worker", "--storage", "sqlite:///{tmp}/s.db", "--study", "s"], "--wait", negative),
    (["scaleout", "--out", "{out}"], "--jobs", lambda: ints_below(1)),
    (["transitions", "--out", "{out}"], "--jobs", lambda: ints_below(1)),
    (["random-walks", "--out", "{out}"], "--jobs", lambda: ints_below(1)),
    (["node", "list"], "--wait", negative),
    (["node", "info", "/cpg"], "--timeout", negative),
    (["param", "list", "/cpg"], "--timeout", negative),
    (["topic", "list"], "--wait", negative),
    (["topic", "echo", ifc.CLOCK], "--count", lambda: ints_below(1)),
    (["topic", "echo", ifc.CLOCK], "--timeout", negative),
    (["topic", "hz", ifc.CLOCK], "--window", lambda: ints_below(2)),
    (["topic", "hz", ifc.CLOCK], "--duration", not_positive),
    (["topic", "pub", "/x", "std_msgs/msg/Empty"], "--rate", not_positive),
    (["topic", "pub", "/x", "std_msgs/msg/Empty"], "--qos-depth", lambda: ints_below(0)),
]


def _fill(argv: list[str], place: dict[str, str]) -> list[str]:
    return [a.format(**place) for a in argv]


@FUZZ
@given(data=st.data())
def test_a_bad_number_is_one_line_naming_the_option(capsys, place, data):
    prefix, option, bad = data.draw(st.sampled_from(NUMBERS), label="option")
    value = data.draw(bad(), label="value")
    # argparse names the option with its short form where it has one ("-r/--rate")
    one_line_error(capsys, [*_fill(prefix, place), f"{option}={value}"], option)


def test_an_infinite_rate_or_wait_is_refused_not_run_for_ever(capsys):
    """`topic pub -r inf` was accepted and published until interrupted (the fuzz above drew it now and then,
    and the suite hung there)."""
    for option in ("--rate", "--max-wait-time-secs", "--keep-alive"):
        for value in ("inf", "Infinity", "-inf"):
            one_line_error(capsys, ["topic", "pub", "/x", "std_msgs/msg/Empty", f"{option}={value}"], option)


# Every command writing into a directory, with the other required options (valid) before --out.
OUT_COMMANDS = {
    "bench": [], "cmd-vel-map": [], "cpg-walk": [], "demo": [], "drive-check": [], "envelope": [],
    "faults": [], "feedback-search": [], "fit": ["--csv", "{csv}"], "learn": [], "margins": [],
    "plot": ["{bag}"], "record": [], "replay": [], "section2": [], "soak": [], "sweep": [], "transport": [],
    "results": [], "two-hosts": [], "walk": [], "random-walks": [], "pushes": [], "transitions": [],
    "teach": ["--gait", "walk"], "scaleout": [],
}
OUT_OPTIONS = [(cmd, "--out") for cmd in OUT_COMMANDS] + [("graph", "--log-dir"), ("graph", "--record")]


def test_every_output_option_is_fuzzed():
    """The tables above cover every sub-command's --out (a new command must be added to them)."""
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    with_out = {name for name, p in sub.choices.items()
                if any("--out" in a.option_strings for a in p._actions)}
    assert with_out == set(OUT_COMMANDS) | {"urdf"}


@FUZZ
@given(data=st.data(), name=st.text(string.ascii_letters + string.digits + "._-", min_size=1, max_size=8))
def test_an_unusable_output_directory_is_one_line(capsys, place, data, name):
    cmd, option = data.draw(st.sampled_from(OUT_OPTIONS), label="command")
    kind = data.draw(st.sampled_from(["a file", "under a file", "empty", "nul"]), label="kind")
    file = Path(place["tmp"]) / f"f_{name}"
    file.write_text("not a directory\n")
    path = {"a file": str(file), "under a file": str(file / "sub" / name), "empty": "",
            "nul": f"{place['tmp']}/a\x00{name}"}[kind]
    one_line_error(capsys, [cmd, *_fill(OUT_COMMANDS.get(cmd, []), place), f"{option}={path}"],
                   f"argument {option}")


def test_urdf_out_naming_a_directory_or_a_path_under_a_file(capsys, place):
    one_line_error(capsys, ["urdf", "--out", place["tmp"]], "is a directory")
    one_line_error(capsys, ["urdf", "--out", f"{place['file']}/x.urdf"], "is not a directory")


# File options whose content the command reads before any work: (argv prefix, option, needs --out).
FILE_OPTIONS = [
    (["fit", "--out", "{out}"], "--csv"),
    (["replay", "--out", "{out}", "--duration", "0.05", "--no-render"], "--data"),
    (["cpg-walk", "--out", "{out}", "--duration", "0.05", "--no-render"], "--cpg"),
    (["sweep", "--out", "{out}"], "--config"),
    (["envelope", "--out", "{out}"], "--config"),
    (["feedback-search", "--out", "{out}"], "--config"),
    (["drive-check", "--out", "{out}"], "--speed-map"),
    (["urdf", "--out", "{tmp}/x.urdf"], "--model"),
    (["bench", "--out", "{out}"], "--from-json"),
]
# Texts that are no valid file of any of these formats: no digit (so no CSV number and no learned
# value), and none of the letters of nan/inf.
TEXT = st.text(st.characters(exclude_characters="0123456789nNaAiIfF\x00", exclude_categories=("Cs",)),
               max_size=80)


@FUZZ
@given(data=st.data())
def test_a_bad_input_file_is_one_line_naming_it(capsys, place, data):
    prefix, option = data.draw(st.sampled_from(FILE_OPTIONS), label="option")
    kind = data.draw(st.sampled_from(["text", "binary", "missing", "directory"]), label="kind")
    path = Path(place["tmp"]) / "input.data"
    path.unlink(missing_ok=True)  # the fixture's directory is shared by the examples
    if kind == "text":
        path.write_text(data.draw(TEXT, label="text"), encoding="utf-8")
    elif kind == "binary":
        path.write_bytes(b"\xff\xfe" + data.draw(st.binary(max_size=60), label="bytes"))
    elif kind == "directory":
        path = Path(place["bag"])
    line = one_line_error(capsys, [*_fill(prefix, place), option, str(path)], str(path))
    if kind in ("missing", "directory", "binary"):
        assert f"argument {option}" in line


@pytest.mark.parametrize("text, needle", [
    ("[1, 2]", "expected a JSON object"),
    ("{}", "no 'machine' object"),
    ('{"machine": {}}', "no benchmark section"),
    ('{"machine": {}, "cpg": 3}', "must be JSON objects"),
    ('{"machine": {},\n "cpg": }', ":2:"),
])
def test_bench_from_json_names_what_is_wrong(capsys, place, text, needle):
    bad = Path(place["tmp"]) / "bench.json"
    bad.write_text(text)
    line = one_line_error(capsys, ["bench", "--out", place["out"], "--from-json", str(bad)], str(bad))
    assert needle in line
    assert not Path(place["out"]).exists()  # nothing written


@pytest.mark.parametrize("option", ["--doc", "--readme"])  # --readme: the former name
def test_bench_doc_without_the_block_fails_before_the_benchmarks(capsys, place, option):
    doc = Path(place["tmp"]) / "benchmarks.md"
    doc.write_text("# no generated block\n")
    one_line_error(capsys, ["bench", "--out", place["out"], "--only", "cpg", "--quick", option, str(doc)],
                   "no '<!-- bench-table:begin")


def test_results_docs_without_the_blocks_fails_before_any_run(capsys, place):
    """--docs ROOT: each block's doc (readme_blocks.BLOCKS) under ROOT is checked before anything runs."""
    one_line_error(capsys, ["results", "--out", place["out"], "--only", "headline", "--docs", place["tmp"]],
                   "README.md")
    Path(place["tmp"], "README.md").write_text("# no generated block\n")
    one_line_error(capsys, ["results", "--out", place["out"], "--only", "headline", "--docs", place["tmp"]],
                   "no '<!-- results-table:begin")
    assert not Path(place["out"]).exists()  # nothing run


@settings(max_examples=15, deadline=None)
@given(cut=st.floats(min_value=0.0, max_value=0.99))
def test_a_truncated_recording_in_a_bag_directory_is_one_line(tmp_path_factory, cut):
    """A rosbag2 directory (metadata.yaml + recording.mcap) whose .mcap was cut off."""
    import io
    from contextlib import redirect_stderr

    bag = tmp_path_factory.mktemp("bag")
    _write_bag(bag)
    mcap = bag / "recording.mcap"
    data = mcap.read_bytes()
    mcap.write_bytes(data[: int(cut * len(data))])
    err = io.StringIO()
    with redirect_stderr(err):
        status = main(["plot", str(bag), "--out", str(bag / "plots")])
    lines = err.getvalue().strip().splitlines()
    assert status == 2 and len(lines) == 1 and "Traceback" not in err.getvalue(), err.getvalue()
    assert lines[0].startswith(f"cpg-walker plot: error: {bag}: not a readable rosbag2 recording"), lines


def test_a_recording_cut_in_its_header_is_one_line(tmp_path):
    """Every cut in the first 64 bytes (the MCAP magic and header record: hypothesis found 8 bytes, the
    magic alone, on which rosbags fails with a TypeError)."""
    import io
    from contextlib import redirect_stderr

    _write_bag(tmp_path)
    mcap = tmp_path / "recording.mcap"
    data = mcap.read_bytes()
    for n in range(64):
        mcap.write_bytes(data[:n])
        err = io.StringIO()
        with redirect_stderr(err):
            status = main(["plot", str(tmp_path), "--out", str(tmp_path / "plots")])
        lines = err.getvalue().strip().splitlines()
        assert status == 2 and len(lines) == 1 and "not a readable rosbag2 recording" in lines[0], (n, lines)


def _write_bag(d: Path) -> None:
    """A small rosbag2 MCAP bag (std_msgs/String) into ``d`` as recording.mcap + metadata.yaml."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    from cpg_walker.nodes.recording import typestore

    store = typestore()
    tmp = d / "w"
    with Writer(tmp / "recording", version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conn = w.add_connection("/chatter", "std_msgs/msg/String", typestore=store)
        msg = store.types["std_msgs/msg/String"](data="hi")
        for i in range(40):
            w.write(conn, i * 1_000_000, store.serialize_cdr(msg, "std_msgs/msg/String"))
    for f in (tmp / "recording").iterdir():
        f.replace(d / f.name)


BAD_DOMAIN = st.one_of(st.integers(max_value=-1), st.integers(min_value=233)).map(str) | st.text(
    st.characters(exclude_characters="\x00", exclude_categories=("Cs",)), min_size=1, max_size=8).filter(
    lambda s: s.strip() != "" and not _parses(s, int))
DOMAIN_COMMANDS = [["topic", "list"], ["node", "list"], ["node", "info", "/cpg"], ["param", "dump", "/cpg"],
                   ["record", "--out", "{out}"], ["demo", "--out", "{out}"], ["graph"],
                   ["drive-check", "--out", "{out}", "--graph", "--attach"],
                   ["teach", "--gait", "walk", "--out", "{out}", "--attach"]]


@FUZZ
@given(data=st.data(), value=BAD_DOMAIN)
def test_a_bad_ros_domain_id_is_one_line(capsys, place, monkeypatch, data, value):
    argv = data.draw(st.sampled_from(DOMAIN_COMMANDS), label="command")
    monkeypatch.setenv("ROS_DOMAIN_ID", value)
    one_line_error(capsys, _fill(argv, place), "ROS_DOMAIN_ID")


@pytest.mark.parametrize("value", ["0\x1c", "\x1f0", "0\x1d", "\x1e5", "\u0663", "\U0001d7ce", "-1", "233",
                                   "+5"])
@pytest.mark.parametrize("argv", [["graph"], ["demo", "--out", "{out}"], ["topic", "list"]])
def test_a_domain_only_python_reads_is_refused(capsys, place, monkeypatch, argv, value):
    """What str.strip() + int() take and rcl does not (file/group separators, non-ASCII digits, a sign):
    one line, exit 2, no graph started (hypothesis found "0\x1c" running a whole graph in domain 0)."""
    monkeypatch.setenv("ROS_DOMAIN_ID", value)
    one_line_error(capsys, _fill(argv, place), "ROS_DOMAIN_ID")


@pytest.mark.parametrize("argv, needle", [
    (["walk", "--out", "{out}", "--schedule", "5,nan,1"], "zeta and alpha must be finite"),
    (["walk", "--out", "{out}", "--schedule", "x"], "--schedule"),
    (["random-walks", "--out", "{out}", "--seeds", "3-x"], "argument --seeds"),
    (["random-walks", "--out", "{out}", "--seeds", "-1"], "argument --seeds"),
    (["walk", "--out", "{out}", "--cpg-file", "{tmp}/missing.yaml"], "argument --cpg-file"),
    (["cpg-walk", "--out", "{out}", "--schedule", "1,0.5,inf"], "argument --schedule"),
    (["cpg-walk", "--out", "{out}", "--pathways", "lateral,wings"], "wings"),
    (["cpg-walk", "--out", "{out}", "--set", "gain_scale=-1"], "--set: gain_scale"),
    (["cpg-walk", "--out", "{out}", "--set", "no_such_field=1"], "no_such_field"),
    (["cpg-walk", "--out", "{out}", "--set", "novalue"], "--set"),
    (["faults", "--out", "{out}", "--nodes", "sim_node,brain"], "argument --nodes"),
    (["transport", "--out", "{out}", "--losses", "0.5,2"], "--losses"),
    (["graph", "-p", "nonode:x=1"], "-p expects"),
    (["drive-check", "--out", "{out}", "--graph", "-p", "nonode:x=1"], "-p expects"),
    (["drive-check", "--out", "{out}", "--graph", "--plan", "dance"], "argument --plan"),
    (["teach", "--gait", "run", "--out", "{out}"], "argument --gait"),
    (["teach", "--out", "{out}"], "one of the arguments --gait --csv --bag is required"),
    (["teach", "--gait", "walk", "--csv", "{csv}", "--out", "{out}"], "not allowed with argument"),
    (["teach", "--gait", "walk", "--out", "{out}", "-p", "nonode:x=1"], "-p expects"),
    (["teach", "--csv", "{file}", "--out", "{out}"], "the first header field must be"),
    (["teach", "--bag", "{tmp}/nope", "--out", "{out}"], "argument --bag"),
    (["graph", "--foxglove", "host:99999"], "argument --foxglove"),
    (["walk", "--out", "{out}", "--foxglove", "bad host!:80"], "argument --foxglove"),
    (["bench", "--out", "{out}", "--only", "nothing"], "argument --only"),
    (["plot", "{tmp}/nope", "--out", "{out}"], "argument BAG"),
    (["plot", "{bag}", "--out", "{out}"], "not a recording"),
    (["node", "info", ""], "node name"),
    (["topic", "pub", "/x", "std_msgs/msg/Empty", "[1"], "not YAML"),
    (["topic", "pub", "/x", "geometry_msgs/msg/Twist", "{{linar: {{x: 1}}}}"], "linar"),
    (["topic", "pub", "/x", "std_msgs/msg/Empty", "--qos-profile", "fastest"], "fastest"),
    (["urdf", "--model", "{file}"], "not a loadable MJCF model"),
])
def test_other_bad_values_are_one_line(capsys, place, argv, needle):
    one_line_error(capsys, _fill(argv, place), needle)


@pytest.mark.parametrize("argv", [["walk", "--out"], ["walk"], ["nosuch"], [], ["topic"],
                                  ["urdf", "--no-such-option"], ["replay", "--out", "x", "--gait", "run"]])
def test_argparse_errors_are_one_line(capsys, argv):
    one_line_error(capsys, argv, "error:")


def test_help_still_works(capsys):
    assert main(["--help"]) == 0
    assert "usage: cpg-walker" in capsys.readouterr().out
    assert main(["walk", "--help"]) == 0
    assert "--duration" in capsys.readouterr().out


@pytest.mark.parametrize("exc", [RuntimeError("a bug"), ValueError("a bug, not bad input"), KeyError("x")])
def test_an_unexpected_exception_is_not_swallowed(monkeypatch, tmp_path, exc):
    """Only InputError is a user error: anything else raised by a command propagates (its traceback)."""
    import cpg_walker.robot.urdf

    def broken(*_args, **_kwargs):
        raise exc

    monkeypatch.setattr(cpg_walker.robot.urdf, "generate", broken)
    with pytest.raises(type(exc), match=r"a bug|x"):
        main(["urdf", "--out", str(tmp_path / "x.urdf")])


def _console(argv: list[str], env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([str(EXE), *argv], capture_output=True, text=True, timeout=120,
                          env={**os.environ, **(env or {})}, stdin=subprocess.DEVNULL)


def test_console_script_end_to_end(tmp_path):
    """The installed console script: one line, status 2, for an argparse error, an InputError from a
    file's content and one from the environment; --help is status 0."""
    (tmp_path / "file").write_text("x\n")
    bag = tmp_path / "bag"
    bag.mkdir()
    _write_bag(bag)
    mcap = bag / "recording.mcap"
    mcap.write_bytes(mcap.read_bytes()[:300])
    (tmp_path / "empty.json").write_text("{}")
    cases = [
        (["walk", "--out", str(tmp_path / "file"), "--duration", "1"], None, "argument --out"),
        (["plot", str(bag), "--out", str(tmp_path / "p")], None, str(bag)),
        (["bench", "--out", str(tmp_path / "b"), "--from-json", str(tmp_path / "empty.json")], None,
         "no 'machine' object"),
        (["demo", "--out", str(tmp_path / "d"), "--duration", "1"], {"ROS_DOMAIN_ID": "-3"}, "ROS_DOMAIN_ID"),
        (["faults", "--out", str(tmp_path / "f"), "--zeta", "5"], None, "argument --zeta"),
    ]
    for argv, env, needle in cases:
        done = _console(argv, env)
        lines = done.stderr.strip().splitlines()
        assert done.returncode == 2 and len(lines) == 1 and "Traceback" not in done.stderr, (argv, done)
        assert needle in lines[0], (needle, lines)
    helped = _console(["urdf", "--help"])
    assert helped.returncode == 0 and "usage: cpg-walker urdf" in helped.stdout, helped


def test_console_script_shows_a_bugs_traceback(tmp_path):
    """A bug (here injected into the console script's process through sitecustomize) is not turned into
    a user error: its traceback is printed and the status is Python's 1."""
    shim = tmp_path / "sitecustomize.py"
    shim.write_text("import cpg_walker.robot.urdf as u\n"
                    "def _boom(*a, **k):\n    raise RuntimeError('injected bug')\n"
                    "u.generate = _boom\n")
    done = _console(["urdf"], {"PYTHONPATH": str(tmp_path)})
    assert done.returncode == 1 and "Traceback" in done.stderr and "RuntimeError: injected bug" in done.stderr


def test_bench_results_are_read_as_json_objects(tmp_path):
    """read_results accepts a real bench.json (docs/bench/bench.json) unchanged."""
    from cpg_walker.cli.bench import read_results

    shipped = Path(__file__).resolve().parent.parent / "docs" / "bench" / "bench.json"
    assert read_results(str(shipped)) == json.loads(shipped.read_text())
