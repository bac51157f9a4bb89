"""`cpg-walker fit` on periodic signals whose components are not integer multiples of the lowest one:
the frequencies within 1 % and the waveform too — the free-running CPG within 15 % (RMS) of the
teaching signal (eq 8's wrap correction, network.py "Non-harmonic oscillators")."""

from __future__ import annotations

import json

import numpy as np
import pytest

from cpg_walker.cli.main import main

pytestmark = pytest.mark.slow

TWO_PI = 2 * np.pi

#: name -> (record length s, sample rate Hz, offset, [(ω rad/s, amplitude, phase)], oscillators)
SIGNALS = {
    "0.4/1.0/1.7 Hz": (30.0, 200.0, 0.5, [(TWO_PI * 0.4, 1.0, 0.0), (TWO_PI * 1.0, 0.7, 1.0),
                                          (TWO_PI * 1.7, 0.4, 2.6)], 3),
    "0.4/1.0/1.7 Hz, small, offset, 50 Hz, strongest highest": (
        25.0, 50.0, 10.0, [(TWO_PI * 0.4, 0.003, 2.0), (TWO_PI * 1.0, 0.005, 1.9),
                           (TWO_PI * 1.7, 0.012, -1.0)], 3),
    "7/11/19 rad/s": (20.0, 300.0, -3.0, [(7.0, 2.0, 0.0), (11.0, 1.5, 0.5), (19.0, 1.0, 2.5)], 3),
    "4 and 4√2 rad/s, 3 oscillators": (60.0, 100.0, 0.0, [(4.0, 1.0, 0.0), (4 * np.sqrt(2), 0.6, 2.0)], 3),
    "1 Hz, 2 Hz (harmonic), 2.7 Hz": (20.0, 200.0, 0.0, [(TWO_PI, 1.0, 0.0), (2 * TWO_PI, 0.6, 1.0),
                                                         (TWO_PI * 2.7, 0.5, 2.0)], 3),
    "weak lowest, 1.0/1.6/2.3 Hz": (40.0, 100.0, 0.0, [(TWO_PI, 0.3, 0.0), (TWO_PI * 1.6, 1.0, 1.0),
                                                        (TWO_PI * 2.3, 0.6, 2.0)], 3),
}


@pytest.mark.parametrize("name", list(SIGNALS))
def test_fit_cli_reproduces_nonharmonic_waveforms(name, tmp_path, capsys):
    T, rate, offset, comps, n = SIGNALS[name]
    t = np.arange(0.0, T, 1.0 / rate)
    v = offset + sum(a * np.sin(w * t + p) for w, a, p in comps)
    np.savetxt(tmp_path / "s.csv", np.c_[t, v], delimiter=",", header="time,sig", comments="", fmt="%.10g")
    out = tmp_path / "out"
    assert main(["fit", "--csv", str(tmp_path / "s.csv"), "--oscillators", str(n), "--out", str(out)]) == 0
    r = json.loads((out / "fit.json").read_text())
    learned = np.array(r["learned_frequencies"])
    for w, _, _ in comps:  # every component learned within 1 % by an oscillator
        assert np.min(np.abs(learned - w) / w) < 0.01, (w, learned)
    assert r["free_run_rms_error"] < 0.15 * r["teaching_rms"], r["free_run_rms_error"] / r["teaching_rms"]
    assert any(r["nonharmonic_oscillators"])
    if len(comps) == n:  # one oscillator per component: flagged where the ratio to the lowest is not whole
        rhos = sorted(w / comps[0][0] for w, _, _ in comps)
        assert r["nonharmonic_oscillators"] == [not np.isclose(x, round(x)) for x in rhos]
