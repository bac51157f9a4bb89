"""`cpg-walker fit` end to end, CSV errors, and learning of random multi-sines."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, example, given, settings
from hypothesis import strategies as st

from cpg_walker.cli.main import main
from cpg_walker.experiments.fit import fit_signal


def _write(path, t, v, header="time,sig"):
    np.savetxt(path, np.c_[t, v], delimiter=",", header=header, comments="", fmt="%.8f")


@pytest.mark.slow
def test_fit_cli_end_to_end(tmp_path, capsys):
    t = np.arange(0, 25, 1 / 250)
    v = 2.0 + 0.7 * np.sin(2 * np.pi * 1.3 * t + 0.4) + 0.3 * np.cos(2 * np.pi * 2.6 * t) \
        + 0.5 * np.sin(2 * np.pi * 5.2 * t + 1)
    _write(tmp_path / "s.csv", t, v)
    assert main(["fit", "--csv", str(tmp_path / "s.csv"), "--out", str(tmp_path / "o")]) == 0
    r = json.loads((tmp_path / "o" / "fit.json").read_text())
    true = 2 * np.pi * np.array([1.3, 2.6, 5.2])
    np.testing.assert_allclose(sorted(r["learned_frequencies"]), true, rtol=0.01)
    assert r["free_run_rms_error"] < 0.05 * r["teaching_rms"]
    assert r["offset"] == pytest.approx(2.0, abs=0.02)
    assert (tmp_path / "o" / "fit.png").stat().st_size > 10_000


@pytest.mark.parametrize(
    "content, message",
    [
        ("time,sig\n", "no data rows"),
        ("", "empty"),
        ("time,sig\n0,1\n0.1,x\n", ":3: column 'sig'"),
        ("time,sig\n0,1\n0.1,2\n0.1,3\n0.3,1\n0.4,2\n", ":4: time"),
        ("time,sig\n0,1\n0.1,nan\n", "not a finite number"),
        ("time,sig\n0,1\n0.1\n", ":3: 1 fields"),
    ],
)
def test_fit_bad_csv_one_line_error(tmp_path, capsys, content, message):
    p = tmp_path / "bad.csv"
    p.write_text(content)
    assert main(["fit", "--csv", str(p), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_fit_missing_column_and_zero_oscillators(tmp_path, capsys):
    t = np.arange(0, 5, 0.01)
    _write(tmp_path / "s.csv", t, np.sin(3 * t))
    assert main(["fit", "--csv", str(tmp_path / "s.csv"), "--column", "nope", "--out", str(tmp_path)]) == 2
    assert "no column named 'nope'" in capsys.readouterr().err
    assert main(["fit", "--csv", str(tmp_path / "s.csv"), "--oscillators", "0", "--out", str(tmp_path)]) == 2
    assert "argument --oscillators: must be >= 1" in capsys.readouterr().err


#: components at least this many periodogram bins 2π/T apart (T the record length) are told apart
RESOLVED_BINS = 3.0


@pytest.mark.slow
@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    base=st.floats(0.5, 40.0),
    harmonics=st.lists(st.integers(1, 5), min_size=1, max_size=3, unique=True),
    amps=st.lists(st.floats(0.3, 2.0), min_size=3, max_size=3),
    phases=st.lists(st.floats(0, 6.28), min_size=3, max_size=3),
    offset=st.floats(-5, 5),
    scale=st.floats(0.01, 100.0),
    periods=st.floats(8.0, 40.0),
)
# found by CI: learning stopped while the weak fifth harmonic still moved (4e-4 off: 17 % error over the
# free run), and a 0.16-of-the-largest fifth harmonic had not locked within 300 internal seconds
@example(base=28.0, harmonics=[2, 3, 5], amps=[1.9375, 1.125, 0.71875], phases=[3.25, 1.0, 0.875], offset=0.0,
         scale=1.0, periods=8.0)
@example(base=1.0, harmonics=[1, 2, 5], amps=[1.87, 1.625, 0.3], phases=[0.0, 2.0, 0.0], offset=0.0,
         scale=1.0, periods=15.0)
def test_random_multisines_learn_frequencies_and_waveform(base, harmonics, amps, phases, offset, scale,
                                                              periods):
    """Random multi-sines on harmonics 1-5 of a base frequency (so a component need not be a whole multiple
    of the lowest one): any base frequency (0.5-40 rad/s), scale (0.01-100), offset, record of 8-40 base
    periods (so the loop is needed), ~40 samples per fastest period."""
    hs = sorted(harmonics)
    w = base * np.array(hs, dtype=float)
    T = periods * 2 * np.pi / w.min()
    # the plan's Hann periodogram merges components closer than ~2.25 bins 2π/T (harmonics 4 and 5 in 8
    # periods of the 4th are 2 bins apart: one peak seen, the fit fails; docs/results.md): ask for 3
    assume(np.all(np.diff(w) * T / (2 * np.pi) >= RESOLVED_BINS))
    t = np.linspace(0, T, int(T * w.max() / (2 * np.pi) * 40))
    v = offset + scale * sum(a * np.sin(wi * t + p) for a, wi, p in zip(amps, w, phases, strict=False))
    r = fit_signal(t, v, len(hs))
    got = np.sort(r.net.frequencies()[0])
    np.testing.assert_allclose(got, w, rtol=0.01)
    # the waveform too, also when a component is not a whole multiple of the lowest one (e.g. 2 and 3 rad/s:
    # eq 8's wrap correction, network.py "Non-harmonic oscillators"); harmonic ones keep the printed eq 8
    assert r.free_run_rms_error[0] < 0.1 * r.teaching_rms[0]
    assert r.net.nonharmonic[0].any() == (not all(h % hs[0] == 0 for h in hs))
