"""cpg/teaching.py's rules: seeds, the phase reference, non-harmonic flags, the step guard, the settings."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from cpg_walker.cpg import teaching as tch
from cpg_walker.cpg.network import CPGParams
from cpg_walker.experiments import section2 as s2
from cpg_walker.experiments.fit import load_config, params_from


@pytest.fixture(scope="module")
def settings() -> tch.TeachingSettings:
    return tch.settings_from_dict(load_config()["teaching"])


def test_settings_live_in_the_yaml_only(settings):
    """TeachingSettings has no code defaults (one home: config/cpg_section2.yaml `teaching:`); a section
    that misses or misspells a field is one clear error."""
    assert all(f.default is dataclasses.MISSING for f in dataclasses.fields(tch.TeachingSettings))
    with pytest.raises(TypeError):
        tch.TeachingSettings()  # type: ignore[call-arg]
    d = dict(load_config()["teaching"])
    del d["spread_low"]
    with pytest.raises(ValueError, match=r"missing teaching setting.*spread_low"):
        tch.settings_from_dict(d)
    with pytest.raises(ValueError, match=r"unknown teaching setting.*sped_factor"):
        tch.settings_from_dict({**load_config()["teaching"], "sped_factor": 1.0})
    with pytest.raises(ValueError, match="harmonic_tolerance must be a finite number"):
        tch.settings_from_dict({**load_config()["teaching"], "harmonic_tolerance": -1})


@pytest.mark.parametrize(
    "component, spacing, expected",
    [
        ([1.0, 2.0, 3.0], 0.0, [False, False, False]),
        ([1.0, 2.5, 4.25], 0.0, [False, True, True]),  # 0.4, 1.0, 1.7 Hz
        ([7.0, 11.0, 19.0], 0.0, [False, True, True]),
        ([1.0, 2.004], 0.01, [False, False]),  # within the peaks' location uncertainty 3·0.01/2
        ([1.0, 2.04], 0.01, [False, True]),
        ([1.0, 2.0, np.nan], 0.0, [False, False, False]),  # harmonic signal: a spread oscillator keeps eq 8
        ([1.0, 2.5, np.nan], 0.0, [False, True, True]),  # non-harmonic signal: flagged too
        ([1.0, 0.5], 0.0, [False, True]),  # a component below oscillator 0's (ρ < 1)
    ],
)
def test_nonharmonic_mask(component, spacing, expected):
    got = tch.nonharmonic_mask(np.array(component), 0.02, spacing)
    assert got.tolist() == expected


def test_phase_reference_is_the_lowest_significant_component(settings):
    """A weak component below the significant ones gets an oscillator, but not oscillator 0."""
    s = dataclasses.replace(settings, seed_factor=1.0)
    om, comp = tch.spectral_seed_omegas(np.array([30.0, 15.0]), 3, s, np.array([5.0]))
    assert om.tolist() == [15.0, 5.0, 30.0] and comp.tolist() == [15.0, 5.0, 30.0]
    om, comp = tch.spectral_seed_omegas(np.array([15.0, 30.0]), 4, s)
    assert om[0] == 15.0 and np.all(np.diff(om[1:]) > 0) and np.isnan(comp).sum() == 2


def _plan(t, v, n, settings, params=None):
    return tch.plan_teaching(t, v, n, settings, params or CPGParams())


def test_removed_mean_is_not_a_weak_component(settings):
    """Two components, three oscillators: the third goes to no low-frequency leakage of the mean (the
    window-weighted mean is removed; the plain mean's residual leaked into the lowest bins, was seeded as a
    weak component at 0.38 rad/s and became oscillator 0, the reference: free-run error 31 %)."""
    t = np.arange(0, 40, 0.01)
    plan = _plan(t, np.sin(4 * t) + 0.6 * np.sin(4 * np.sqrt(2) * t + 2), 3, settings)
    physical = plan.omega0[0] * plan.time_scale[0]
    assert physical.min() > 0.9 * 4.0
    assert physical[0] == pytest.approx(settings.seed_factor * 4.0, rel=0.01)
    assert plan.nonharmonic[0].tolist() == [False, True, True]


def test_harmonic_signals_are_not_flagged(settings):
    """Harmonic content keeps the printed eq 8 (bit-identical behaviour): Section II's square wave with
    up to 12 oscillators (weak harmonics included) and a three-harmonic signal, short and long records."""
    cfg = load_config()
    t, v = s2.smoothed_square(cfg)
    for n in cfg["beyond"]["oscillators"]:
        assert not _plan(t, v, int(n), settings).nonharmonic.any(), n
    for periods in (4, 10, 40):
        t = np.linspace(0, periods * 2 * np.pi / 3.0, periods * 400)
        v = 1.0 + np.sin(3 * t) + 0.4 * np.cos(12 * t + 1) + 0.8 * np.sin(27 * t + 2)
        plan = _plan(t, v, 3, settings)
        assert not plan.nonharmonic.any(), periods


def test_step_respects_the_networks_radial_rate(settings):
    """The plan's dt obeys CPGNetwork.check_step for the network's own γμ (it assumed γμ = 8)."""
    t = np.arange(0, 20, 0.01)
    v = np.sin(2 * t) + 0.5 * np.sin(4 * t)
    for gamma in (8.0, 40.0, 200.0):
        plan = _plan(t, v, 2, settings, CPGParams(gamma=gamma))
        net = tch.make_network(plan)
        assert net.params.gamma == gamma
        net.check_step(plan.dt)  # raised "too large" for γ = 40 before
        assert plan.dt * 2 * gamma * plan.time_scale.max() <= 0.5
    assert _plan(t, v, 2, settings, CPGParams(gamma=200.0)).dt < _plan(t, v, 2, settings).dt


def test_section2_config_sets_every_teaching_field():
    """Every teaching field is set in the YAML (the fit and the square-wave sweep build from it)."""
    cfg = load_config()
    assert set(cfg["teaching"]) == {f.name for f in dataclasses.fields(tch.TeachingSettings)}
    assert params_from(cfg).gamma == cfg["cpg"]["gamma"]
