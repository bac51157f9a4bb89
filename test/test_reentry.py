"""cpg_node's re-entry path in process (CPGGaitSource.reenter, docs/ROS_INTERFACE.md "Faults"): a source
re-entered at t0 > 0 starts at the standing crouch pid_node holds (no jump), with alpha ramping up from 0,
and is the CPG at the commanded alpha once the cross-fade and the filter have settled."""

from __future__ import annotations

import numpy as np


def test_reentry_starts_at_the_crouch_and_ramps_alpha_up():
    from cpg_walker.robot.hoap2 import default_standing_posture
    from cpg_walker.walker.gait_source import CPGGaitSource
    from cpg_walker.walker.learning import load_controller

    ctrl, _, _ = load_controller("cpg_humanoid.yaml")
    src = CPGGaitSource(ctrl)
    t0 = 40.0
    src.reenter(t0, 1.0, 1.0)
    q, _ = src.targets(t0)
    crouch = default_standing_posture()
    assert np.max(np.abs(q - crouch)) < 0.02, np.max(np.abs(q - crouch))  # no jump from the crouch
    assert ctrl.alpha < 0.01
    steps = []
    for t in np.arange(t0, t0 + 4.0, src.h):
        q_prev = q
        q, _ = src.targets(float(t))
        steps.append(np.max(np.abs(q - q_prev)))
    assert ctrl.alpha > 0.9, ctrl.alpha
    assert max(steps) < 0.02, max(steps)  # continuous: no tick moves a joint target by more than this
