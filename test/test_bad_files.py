"""Bad files given to the CLI: a corrupt learned CPG, a truncated recording, an unknown joint name in a
gait file, a broken configuration YAML. Each is one clear line on stderr naming the file (and the line,
where the parser gives one), exit status 2, no traceback. Run through ``cli.main.main`` in-process."""

from __future__ import annotations

import pytest

from cpg_walker.cli.main import main
from cpg_walker.paths import config_path
from cpg_walker.robot.gait_data import DATA_DIR, PACKAGED


def _one_line_error(capsys, argv: list[str]) -> str:
    status = main(argv)
    err = capsys.readouterr().err.strip()
    assert status == 2, (status, err)
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    return err


@pytest.mark.parametrize("text, where", [
    ("schema_version: 1\ndofs: [1, 2\nnext: {\n", ":3:"),  # not YAML: the parser's line
    ("hello: 3\n", ""),  # YAML, not a learned CPG
    (None, ""),  # the packaged file cut off mid-way
])
def test_a_corrupt_learned_cpg_is_one_line(tmp_path, capsys, text, where):
    bad = tmp_path / "learned.yaml"
    if text is None:
        good = config_path("cpg_humanoid.yaml").read_text()
        text = good[: len(good) // 3]
    bad.write_text(text)
    err = _one_line_error(capsys, ["cpg-walk", "--cpg", str(bad), "--out", str(tmp_path / "o"),
                                   "--duration", "0.05", "--no-render"])
    assert f"{bad}{where}" in err


def test_a_truncated_recording_is_one_line(tmp_path, capsys):
    """An MCAP written by the mcap library with a CDR message, then cut off before its summary."""
    from mcap.writer import Writer

    full = tmp_path / "full.mcap"
    with open(full, "wb") as f:
        w = Writer(f)
        w.start()
        schema = w.register_schema("std_msgs/msg/String", "ros2msg", b"string data")
        channel = w.register_channel("/chatter", "cdr", schema)
        for i in range(50):
            w.add_message(channel, log_time=i, publish_time=i, data=b"\x00\x01\x00\x00\x03\x00\x00\x00hi\x00")
        w.finish()
    data = full.read_bytes()
    for cut in (len(data) // 2, 8, 20):
        bad = tmp_path / f"cut{cut}.mcap"
        bad.write_bytes(data[:cut])
        err = _one_line_error(capsys, ["plot", str(bad), "--out", str(tmp_path / "o")])
        assert str(bad) in err


def test_an_unknown_joint_in_a_gait_file_is_one_line(tmp_path, capsys):
    lines = (DATA_DIR / PACKAGED["walk"]).read_text().splitlines()
    bad = tmp_path / "gait.csv"
    bad.write_text("\n".join([lines[0].replace("lleg_joint_1", "lleg_joint_9"), *lines[1:50]]) + "\n")
    err = _one_line_error(capsys, ["replay", "--data", str(bad), "--out", str(tmp_path / "o"),
                                   "--duration", "0.05", "--no-render"])
    assert f"{bad}:1:" in err and "lleg_joint_9" in err


def test_a_broken_config_yaml_is_one_line(tmp_path, capsys):
    bad = tmp_path / "sweep.yaml"
    bad.write_text("zeta: [1.0, 1.3\nfeedback: {\n")
    err = _one_line_error(capsys, ["sweep", "--config", str(bad), "--out", str(tmp_path / "o")])
    assert f"{bad}:2:" in err and "not valid YAML" in err
