"""Pushes (issue 24), in-process through the governor, the default feedback pathways (with the ankle
strategy and the free leg): walking at ζ 1 recovers the target 1.6 N·s lateral push to either side and
standing (α 0) the target 3 N·s. Measured (`cpg-walker pushes`, docs/results/pushes/: the bisection of
experiments/pushes.py, 0.06 N·s resolution): walking 1.75 left / 2.00 right, standing 3.56 / 3.31
(without the free_leg pathway 3.00 / 2.81, without the ankle pathway too 3.13 / 2.94)."""

from __future__ import annotations

import pytest

from cpg_walker.experiments.pushes import AFTER_S, AT_S, DURATION_S
from cpg_walker.experiments.walk_runs import Push, WalkSpec, run_many, run_walk

pytestmark = pytest.mark.slow

#: (α, impulse N·s) recovered to both sides: the issue's targets (measured: walking 1.75 and standing 3.31
#: on the weaker side).
CASES = ((1.0, 1.6), (0.0, 3.0))


def _walk(args: tuple[float, float, float]) -> dict:
    alpha, impulse, direction = args
    r = run_walk(WalkSpec(zeta=1.0, alpha=alpha, duration_after_s=AT_S + AFTER_S, governed=True,
                          push=Push(AT_S, impulse, DURATION_S, direction)))
    return {"alpha": alpha, "impulse": impulse, "direction": direction, "fell": r["fell"],
            "fall_time_s": r["fall_time_s"]}


def test_walking_and_standing_recover_lateral_pushes_to_both_sides():
    runs = run_many(_walk, [(a, i, d) for a, i in CASES for d in (1.0, -1.0)], jobs=2)
    assert not [r for r in runs if r["fell"]], runs
