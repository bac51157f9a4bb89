"""The Foxglove layout of the live view (docs/foxglove_layout.json), built with foxglove-sdk's layout types
so it follows the app's layout format: regenerate it with

    python -m cpg_walker.graph.foxglove_layout > docs/foxglove_layout.json

(test/test_foxglove.py fails when the shipped file differs from a fresh generation). Panels: the 3D view
(the URDF from /robot_description posed by /tf, following base_link), the CPG phases and amplitudes of the
left leg's DOFs, the targets against the measured joint angles, the sole loads with the feet's contact
states, the parameter panel (/cpg.zeta, /cpg.alpha) and the diagnostics.
"""

from __future__ import annotations

from foxglove import layouts as fl

from cpg_walker.nodes import interface as ifc
from cpg_walker.robot.contact import SIDES
from cpg_walker.walker.controller import DOFS

#: The DOFs plotted (the left leg; the right one is the same at half a period).
PLOTTED = tuple(d for d in DOFS if d.startswith("lleg"))


def _series(path: str, label: str) -> fl.PlotSeries:
    return fl.PlotSeries(value=path, label=label, enabled=True, timestamp_method="receiveTime")


def _plot(title: str, series: list[fl.PlotSeries], y_label: str) -> fl.PlotPanel:
    config = fl.PlotConfig(paths=series, show_legend=True, y_axis_label=y_label, following_view_width=10.0)
    return fl.PlotPanel(title=title, config=config)


def layout() -> fl.Layout:
    """The live view's layout."""
    three_d = fl.ThreeDeePanel(title="HOAP-2 (URDF posed by /tf)", config=fl.ThreeDeeConfig(
        follow_tf="base_link", follow_mode="follow-position",
        camera_state=fl.ThreeDeeCameraState(distance=1.2, perspective=True, phi=70.0, theta_offset=45.0,
                                            target=(0.0, 0.0, 0.0)),
        layers={
            "grid": fl.BaseRendererGridLayerSettings(instance_id="grid", label="floor", frame_id="odom",
                                                     size=10.0, divisions=20.0, visible=True),
            "hoap2": fl.BaseRendererUrdfLayerSettings(
                instance_id="hoap2", label="HOAP-2", source_type="topic", topic=ifc.ROBOT_DESCRIPTION,
                control_mode="transforms", display_mode="visual", visible=True),
        }))
    cpg = lambda field: f"/cpg/state.dofs.{{}}.{field}[0]"  # noqa: E731
    phases = _plot("CPG phase (first oscillator per DOF)",
                   [_series(cpg("phase_rad").format(d), d) for d in PLOTTED], "rad")
    amplitudes = _plot("CPG amplitude (first oscillator per DOF, gain x alpha)",
                       [_series(cpg("amplitude_rad").format(d), d) for d in PLOTTED], "rad")
    joints = _plot("left knee: target vs measured", [
        _series('/joint_targets.joints[:]{name=="lleg_joint_4"}.position', "target"),
        _series('/joint_states.joints[:]{name=="lleg_joint_4"}.position', "measured")], "rad")
    loads = _plot("sole loads", [_series(f"/contact.{s}_load_n", s) for s in SIDES], "N")
    contact = fl.StateTransitionsPanel(title="feet on the ground", config=fl.StateTransitionsConfig(
        paths=[fl.StateTransitionsSeries(value=f"/contact.{s}_down", label=s, timestamp_method="receiveTime")
               for s in SIDES]))
    params = fl.ParametersPanel(title="zeta (speed), alpha (step length)")
    diagnostics = fl.DiagnosticsSummaryPanel(title="diagnostics")
    teaching = _plot("live teaching: learned frequency (first oscillator per DOF)",
                     [_series(f"/cpg/teach/state.dofs.{d}.learned_frequency_hz", d) for d in PLOTTED], "Hz")

    def column(*panels, weights=None) -> fl.SplitContainer:
        weights = weights or [1] * len(panels)
        return fl.SplitContainer(direction="column", items=[
            fl.SplitItem(content=p, proportion=w) for p, w in zip(panels, weights, strict=True)])

    return fl.Layout(content=fl.SplitContainer(direction="row", items=[
        fl.SplitItem(proportion=1.2, content=column(three_d, params, weights=[3, 1])),
        fl.SplitItem(proportion=1.0, content=column(phases, amplitudes, joints)),
        fl.SplitItem(proportion=0.8, content=column(loads, contact, teaching, diagnostics)),
    ]))


def layout_json() -> str:
    """The layout as the app imports it (indented JSON, one trailing newline)."""
    import json

    return json.dumps(json.loads(layout().to_json()), indent=2, sort_keys=True) + "\n"


if __name__ == "__main__":
    import sys

    sys.stdout.write(layout_json())
