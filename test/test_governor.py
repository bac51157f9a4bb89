"""The governor (walker/governor.py) alone: driven by a stand-in of the CPG's command filters (first-order
lags), it reaches a request inside the envelope at its rates (ζ first, then α), caps α to the envelope,
brings α down before ζ slows, reverses through a stop (α 0, then ζ, then α ramping), lets α fall at most
fall_rate per s, stands below the envelope's slowest ζ; the packaged config loads and a broken one names
the problem."""

from __future__ import annotations

import math
from itertools import pairwise

import pytest

from cpg_walker.errors import InputError
from cpg_walker.walker.governor import Envelope, Governor, GovernorConfig

DT = 0.002
ENV = Envelope(forward=((0.3, 0.5), (0.7, 1.0), (1.5, 1.2)), backward=((0.3, 0.5), (1.5, 1.0)))
CFG = GovernorConfig(ENV, fall_rate=0.5, ramp_rate=0.25, rise_rate=0.5, zeta_rate=0.5, reverse_alpha=0.05,
                     reverse_zeta_tolerance=0.1)


class Lagged:
    """The CPG's applied ζ, α: first-order lags (0.25 s) of the commands."""

    def __init__(self, zeta: float, alpha: float) -> None:
        self.zeta, self.alpha = zeta, alpha

    def step(self, zc: float, ac: float) -> None:
        k = 1 - math.exp(-DT / 0.25)
        self.zeta += k * (zc - self.zeta)
        self.alpha += k * (ac - self.alpha)


def _run(gov: Governor, cpg: Lagged, seconds: float) -> list[tuple[float, float, float, float, str]]:
    """(ζ cmd, α cmd, applied ζ, applied α, state) per step."""
    out = []
    for _ in range(round(seconds / DT)):
        z, a = gov.update(DT, cpg.zeta, cpg.alpha)
        cpg.step(z, a)
        out.append((z, a, cpg.zeta, cpg.alpha, gov.state))
    return out


def test_a_request_inside_the_envelope_is_reached_at_the_rates():
    gov, cpg = Governor(CFG, 1.0, 1.0), Lagged(1.0, 1.0)
    gov.request(1.3, 1.1)
    trace = _run(gov, cpg, 3.0)
    zetas = [z for z, *_ in trace]
    assert all(abs(z1 - z0) <= CFG.zeta_rate * DT + 1e-12 for z0, z1 in pairwise(zetas))
    first_alpha_rise = next(i for i, (_, a, *_rest) in enumerate(trace) if a > 1.0)
    assert abs(trace[first_alpha_rise][2] - 1.3) <= 0.1 * 1.3  # zeta first, then alpha (accelerating)
    assert trace[0][4] == "accelerating"
    assert trace[-1][:2] == (1.3, pytest.approx(1.1)) and gov.state == "following" and gov.reason == ""


def test_alpha_is_capped_to_the_envelope_with_the_reason():
    gov, cpg = Governor(CFG, 1.0, 1.0), Lagged(1.0, 1.0)
    gov.request(1.5, 2.0)
    trace = _run(gov, cpg, 4.0)
    assert trace[-1][1] == pytest.approx(1.2) and gov.state == "limited" and "1.2" in gov.reason


def test_slowing_down_brings_alpha_down_before_zeta():
    gov, cpg = Governor(CFG, 1.0, 1.0), Lagged(1.0, 1.0)
    gov.request(0.3, 1.0)
    trace = _run(gov, cpg, 4.0)
    for z, _, _, applied_alpha, _ in trace:
        if z == 0.3:  # zeta moves only once the applied alpha fits the slow envelope
            assert applied_alpha <= 0.5 + 0.02 + 1e-9
    assert trace[0][4] == "slowing" and trace[-1][0] == 0.3 and trace[-1][1] == pytest.approx(0.5)
    alphas = [a for _, a, *_ in trace]
    assert all(a0 - a1 <= 0.5 * DT + 1e-12 for a0, a1 in pairwise(alphas))  # fall rate


def test_a_reversal_goes_through_a_stop_and_ramps_up():
    gov, cpg = Governor(CFG, 1.0, 1.0), Lagged(1.0, 1.0)
    gov.request(-1.0, 0.8)
    trace = _run(gov, cpg, 12.0)
    flip = next(i for i, (z, *_rest) in enumerate(trace) if z < 0)
    assert trace[flip][3] <= 0.05 + 1e-9  # the applied alpha had stopped stepping when zeta flipped
    assert all(s == "reversing" for *_, s in trace[:flip])
    stepping = next(i for i, (_, a, *_rest) in enumerate(trace) if i > flip and a > 0)
    assert abs(trace[stepping][2] + 1.0) <= 0.1  # alpha rises once the applied zeta is near the new one
    assert trace[stepping][4] == "ramping"
    ramp = [a for _, a, *_ in trace[stepping:]]
    assert all(a1 - a0 <= 0.25 * DT + 1e-12 for a0, a1 in pairwise(ramp))
    a_max = ENV.alpha_max(-1.0)  # 0.79: the backward envelope caps the requested 0.8
    assert trace[-1][:2] == (-1.0, pytest.approx(a_max)) and gov.state == "limited"


def test_below_the_slowest_zeta_it_stands_and_keeps_its_direction():
    gov, cpg = Governor(CFG, -1.0, 1.0), Lagged(-1.0, 1.0)
    gov.request(0.0, 1.0)
    trace = _run(gov, cpg, 4.0)
    assert trace[-1][1] == 0.0 and trace[-1][0] < 0 and gov.state == "standing"
    gov.request(-0.1, 1.0)
    assert _run(gov, cpg, 0.1)[-1][1] == 0.0


@pytest.mark.parametrize("start, wanted", [(-1.0, 0.01), (1.0, 0.05), (1.0, -0.2)])
def test_a_request_slower_than_the_envelope_stands_with_the_slowest_rhythm(start, wanted):
    """|ζ| below the envelope's first point: α 0, and the oscillators turn at that point's ζ in the requested
    direction (not near 0, where the learned network's phase relations drift), with the reason."""
    gov, cpg = Governor(CFG, start, 1.0), Lagged(start, 1.0)
    gov.request(wanted, 0.8)
    trace = _run(gov, cpg, 12.0)
    slowest = math.copysign(ENV.slowest(wanted), wanted)
    assert trace[-1][:2] == (slowest, 0.0) and gov.state == "standing"
    assert f"zeta {wanted:g}: stands" in gov.reason and f"{slowest:g}" in gov.reason
    assert all(a == 0.0 or abs(z) >= 0.3 for z, a, *_ in trace)  # never stepping below the slowest


def test_the_packaged_config_loads_and_a_broken_one_names_the_problem(tmp_path):
    cfg = GovernorConfig.load()
    assert cfg.envelope.alpha_max(1.0) > 0 and cfg.envelope.alpha_max(0.0) == 0.0
    bad = tmp_path / "g.yaml"
    bad.write_text("envelope: {forward: [[0.5, 1.0], [0.3, 0.5]], backward: [[0.3, 0.5]]}\n")
    with pytest.raises(InputError, match="strictly increasing"):
        GovernorConfig.load(bad)
    bad.write_text("envelope: {forward: [[0.3, 0.5]], backward: [[0.3, 0.5]]}\nfall_rat: 1\n")
    with pytest.raises(InputError, match="fall_rat"):
        GovernorConfig.load(bad)


def test_a_scheduled_value_out_of_range_is_refused_recorded_and_the_walk_goes_on():
    from cpg_walker.experiments.cpg_walk import walk
    from cpg_walker.walker.learning import cpg_defaults, load_controller

    ctrl = load_controller(cpg_defaults()["cpg_file"])[0]
    m = walk(ctrl, 8.0, schedule=[(7.0, 3.0, 1.0), (7.5, 1.2, 0.8)])
    assert m["refused"] == [{"t_s": 7.0, "zeta": 3.0, "alpha": 1.0, "reason": m["refused"][0]["reason"]}]
    assert "zeta" in m["refused"][0]["reason"] and "[-2" in m["refused"][0]["reason"]
    assert m["schedule"] == [[7.5, 1.2, 0.8]] and not m["fell"] and "governed" not in m  # on: the default


def test_the_declared_alpha_range_is_the_longest_step_that_walked():
    """cpg_node's alpha range with the governor tells the truth: up to the envelopes' largest alpha_max
    (longer steps fell at every zeta), refused above with that reason; without it, the raw CPG's range."""
    from cpg_walker.walker.controller import ALPHA_RANGE, ZETA_RANGE
    from cpg_walker.walker.governor import command_error, command_range

    assert CFG.alpha_limit == 1.2  # ENV's largest alpha_max
    wider = GovernorConfig(ENV, open_loop=Envelope(forward=((0.3, 1.4),), backward=((0.3, 0.2),)))
    assert wider.alpha_limit == 1.4 and GovernorConfig(Envelope(((0.3, 9.0),), ((0.3, 9.0),))).alpha_limit \
        == ALPHA_RANGE[1]  # never beyond what the CPG takes
    assert command_range("alpha", CFG) == (0.0, 1.2) and command_range("zeta", CFG) == ZETA_RANGE
    assert command_range("alpha", None) == ALPHA_RANGE
    why = command_error("alpha", 1.3, CFG)
    assert why.startswith("alpha must be in [0, 1.2], got 1.3") and "longer steps fell" in why
    assert command_error("alpha", 1.2, CFG) is None and command_error("alpha", 1.3, None) is None
    assert "finite" in command_error("alpha", math.inf, CFG) and command_error("zeta", 2.5, CFG)
    packaged = GovernorConfig.load()
    assert packaged.alpha_limit == max(a for env in (packaged.envelope, packaged.open_loop, packaged.ankle)
                                       for pts in (env.forward, env.backward) for _, a in pts)


def test_a_start_from_standing_ramps_to_the_envelope_and_the_walk_reports_it():
    """From standing at a request beyond the envelope (α 1 at ζ 0.5, open loop): the start-up ramps α to
    the envelope's α_max at once, not to the request (it overshot to 0.91 before the governor took over
    at the blend's end and fell at 2.49 s; the raw controller falls so too); walk.json's applied_at_end
    says what was walked and why."""
    from cpg_walker.experiments.cpg_walk import walk
    from cpg_walker.walker.learning import cpg_defaults, load_controller

    ctrl = load_controller(cpg_defaults()["cpg_file"])[0]
    cap = GovernorConfig.load().open_loop.alpha_max(0.5)
    assert cap < 1.0
    m = walk(ctrl, 12.0, zeta=0.5, alpha=1.0, transition="standing")
    end = m["applied_at_end"]
    assert not m["fell"], m["fall_time_s"]
    assert end["zeta"] == pytest.approx(0.5, abs=1e-3) and end["alpha"] == pytest.approx(cap, abs=1e-3), end
    assert end["governor"] == "limited" and "envelope" in end["reason"], end
    raw = walk(load_controller(cpg_defaults()["cpg_file"])[0], 12.0, zeta=0.5, alpha=1.0,
               transition="standing", governed=False)
    assert raw["fell"] and raw["applied_at_end"] == {"zeta": 0.5, "alpha": raw["applied_at_end"]["alpha"],
                                                     "governor": "off", "reason": ""}


ANKLE = Envelope(forward=((0.3, 0.5), (0.7, 1.0), (1.5, 1.2), (1.7, 1.5)), backward=((0.3, 0.5), (1.5, 1.0)))
CFG_ANKLE = GovernorConfig(ENV, ankle=ANKLE, fall_rate=0.5, ramp_rate=0.25, rise_rate=0.5, zeta_rate=0.5,
                           reverse_alpha=0.05, reverse_zeta_tolerance=0.1)


def _run_ankle(gov: Governor, cpg: Lagged, seconds: float, ankle: bool, pending: bool = False) -> list:
    out = []
    for _ in range(round(seconds / DT)):
        z, a = gov.update(DT, cpg.zeta, cpg.alpha, ankle=ankle, ankle_pending=pending)
        cpg.step(z, a)
        out.append((z, a, cpg.zeta, cpg.alpha, gov.state))
    return out


def test_longer_steps_need_the_ankle_envelope_and_say_so():
    """The ``ankle`` envelope (the ankle pathway closed) walks steps the plain one does not: a request in
    it is reached with the ankle pathway, limited to the plain envelope without it, held where it is while
    the pathway fades in; ``needs_ankle`` says when the request or the applied steps need it."""
    gov, cpg = Governor(CFG_ANKLE, 1.5, 1.2), Lagged(1.5, 1.2)
    assert not gov.needs_ankle(cpg.zeta, cpg.alpha)  # inside the plain envelope
    gov.request(1.7, 1.5)
    assert gov.needs_ankle(cpg.zeta, cpg.alpha)
    held = _run_ankle(gov, cpg, 1.0, ankle=False, pending=True)
    assert {s for *_, s in held} == {"waiting"} and "ankle" in gov.reason
    assert max(abs(z - 1.5) for z, *_ in held) == 0.0 and max(abs(a - 1.2) for _, a, *_ in held) == 0.0
    trace = _run_ankle(gov, cpg, 4.0, ankle=True)
    assert trace[-1][:2] == (1.7, pytest.approx(1.5)) and gov.state == "following"
    assert gov.needs_ankle(cpg.zeta, cpg.alpha)
    gov.request(1.0, 1.0)  # back inside the plain envelope: needed while the applied steps are longer
    assert gov.needs_ankle(cpg.zeta, cpg.alpha)
    _run_ankle(gov, cpg, 6.0, ankle=True)
    assert not gov.needs_ankle(cpg.zeta, cpg.alpha) and gov.state == "following"
    plain, cpg = Governor(CFG_ANKLE, 1.5, 1.2), Lagged(1.5, 1.2)  # the ankle pathway never comes
    plain.request(1.7, 1.5)
    trace = _run_ankle(plain, cpg, 6.0, ankle=False)
    assert trace[-1][1] == pytest.approx(ENV.alpha_max(1.7)) and plain.state == "limited"
    assert not Governor(CFG, 1.5, 1.2).needs_ankle(1.5, 1.5)  # no ankle envelope: never
    assert CFG_ANKLE.alpha_limit == 1.5
