"""Reading teaching signals from CSV files: which column is time, and errors that name the line."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from cpg_walker.experiments.fit import pick_time_column, read_csv


@pytest.mark.parametrize(
    ("header", "expected"),
    [
        (["time", "x"], 0),
        (["x", "time_s", "y"], 1),
        (["angle", "Timestamp"], 1),
        (["a", "Time [s]"], 1),
        (["a", "t"], 1),
        (["a", "b"], 0),  # nothing names time: the first column
    ],
)
def test_time_column_is_found_by_name(header: list[str], expected: int) -> None:
    assert pick_time_column(header) == expected


def test_time_column_given_by_the_user(tmp_path: Path) -> None:
    path = tmp_path / "s.csv"
    t = np.arange(0.0, 1.0, 0.1)
    rows = ["sig,clock,other"] + [f"{np.sin(v)},{v},{2 * v}" for v in t]
    path.write_text("\n".join(rows) + "\n")
    times, values, names = read_csv(path, None, "clock")
    np.testing.assert_allclose(times, t)
    assert names == ["sig", "other"]
    np.testing.assert_allclose(values[:, 0], np.sin(t))
    with pytest.raises(ValueError, match="no time column named 'nope'"):
        read_csv(path, None, "nope")


def test_time_column_in_the_middle_is_not_learned_as_a_signal(tmp_path: Path) -> None:
    path = tmp_path / "m.csv"
    t = np.arange(0.0, 2.0, 0.01)
    rows = ["a,time,b"] + [f"{np.sin(3 * v)},{v},{np.cos(v)}" for v in t]
    path.write_text("\n".join(rows) + "\n")
    times, values, names = read_csv(path, None)
    np.testing.assert_allclose(times, t)
    assert names == ["a", "b"]
    assert values.shape == (len(t), 2)


def test_non_increasing_time_names_the_line(tmp_path: Path) -> None:
    path = tmp_path / "bad.csv"
    path.write_text("x,time\n1,0.0\n2,0.1\n3,0.1\n")
    with pytest.raises(ValueError, match=r"bad.csv:4: time 0.1 does not increase"):
        read_csv(path, None)
