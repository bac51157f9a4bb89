"""What foxglove_node shows, as plain conversions from ROS messages (no rclpy node, no server): the
address option, the Foxglove channels and their schemas, and the message contents.

Encodings Foxglove decodes without plug-ins: its well-known schemas (protobuf, from ``foxglove.messages``)
for the robot (``/tf``: FrameTransforms of every link, posed by robot/frames.py from /joint_states and
/odom/ground_truth) and the joints (``/joint_states``, ``/joint_targets``: JointStates); JSON with a JSON
schema for the rest (``/cpg/state`` keyed by DOF name, ``/contact``, ``/contact/touchdown``,
``/diagnostics``, and ``/robot_description`` as a ``std_msgs/msg/String``-shaped ``{"data": URDF}``).
"""

from __future__ import annotations

import ipaddress
import math
import re
import struct

import mujoco
import numpy as np

from cpg_walker.errors import InputError
from cpg_walker.robot.contact import SIDES, TouchdownDetector
from cpg_walker.robot.frames import body_transforms, odom_transform, set_pose, site_transforms
from cpg_walker.robot.hoap2 import MODEL_PATH

#: ``--foxglove`` without a value, and the node's defaults (config/foxglove.yaml holds the node's own).
DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8765
#: The WebSocket subprotocol foxglove-sdk 0.30 speaks (the Foxglove WebSocket protocol).
SUBPROTOCOL = "foxglove.sdk.v1"
#: Log line of foxglove_node once its server listens (followed by the ws:// URL).
READY = "Foxglove live view: open"


def parse_address(text: str | None) -> tuple[str, int]:
    """``--foxglove``'s ``[HOST:]PORT`` (None or '': the default address) -> (host, port); ValueError
    naming the problem. Port 0: any free port (the node logs the one it got)."""
    if not text:
        return DEFAULT_HOST, DEFAULT_PORT
    host, sep, port_text = text.rpartition(":")
    if not sep:
        host = DEFAULT_HOST
    host = host.strip("[]") or DEFAULT_HOST
    if not re.fullmatch(r"\d{1,5}", port_text) or int(port_text) > 65535:
        raise InputError(f"--foxglove expects [HOST:]PORT with PORT in 0..65535, got {text!r}")
    if host != "localhost":
        try:
            ipaddress.ip_address(host)
        except ValueError:
            if not re.fullmatch(r"[A-Za-z0-9.-]+", host):
                raise InputError(f"--foxglove: {host!r} is not a host name or IP address") from None
    return host, int(port_text)


def is_loopback(host: str) -> bool:
    """Whether ``host`` only accepts connections from this machine."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


# ------------------------------------------------------------------------------------------ schemas

def _obj(title: str, properties: dict, description: str = "") -> dict:
    return {"title": title, "type": "object", "description": description, "properties": properties}


_NUM = {"type": "number"}
_NUMS = {"type": "array", "items": _NUM}
_STAMP = {"type": "object", "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}}}

CPG_STATE_SCHEMA = _obj("cpg_walker.CpgState", {
    "timestamp": _STAMP,
    "dofs": {"type": "object", "description": "by DOF (joint) name", "additionalProperties": _obj(
        "cpg_walker.CpgDof", {
            "phase_rad": {**_NUMS, "description": "each oscillator's phase, wrapped to [0, 2 pi)"},
            "frequency_hz": {**_NUMS, "description": "each oscillator's frequency (with zeta)"},
            "amplitude_rad": {**_NUMS, "description": "each oscillator's amplitude (gain * alpha)"},
            "target_rad": _NUM, "target_rads": _NUM, "offset_rad": _NUM})},
}, "cpg_node's /cpg/state by DOF name")
TEACH_STATE_SCHEMA = _obj("cpg_walker.TeachState", {
    "timestamp": _STAMP,
    "dofs": {"type": "object", "description": "by DOF (joint) name", "additionalProperties": _obj(
        "cpg_walker.TeachDof", {
            "learned_frequency_hz": {**_NUM, "description": "the learning network's main oscillator"},
            "amplitude_rad": {**_NUM, "description": "its amplitude (gain * |alpha|)"},
            "error_deg": {**_NUM, "description": "the last stride's RMS teaching error"}})},
}, "cpg_node's /cpg/teach/state (live teaching) by DOF name")
CONTACT_SCHEMA = _obj("cpg_walker.Contact", {
    "timestamp": _STAMP,
    **{f"{s}_load_n": {**_NUM, "description": f"{s} sole load (N)"} for s in SIDES},
    **{f"{s}_down": {"type": "boolean", "description": f"{s} foot on the ground (contact.py hysteresis)"}
       for s in SIDES},
    **{f"{s}_touchdowns": {"type": "integer", "description": f"{s} steps counted so far"} for s in SIDES},
}, "sole loads and touchdowns (robot/contact.py's TouchdownDetector)")
TOUCHDOWN_SCHEMA = _obj("cpg_walker.Touchdown", {
    "timestamp": _STAMP, "side": {"type": "string", "enum": list(SIDES)}, "count": {"type": "integer"}},
    "one touchdown (a step) of a foot")
DIAGNOSTICS_SCHEMA = _obj("cpg_walker.Diagnostics", {
    "timestamp": _STAMP,
    "status": {"type": "object", "description": "by status name", "additionalProperties": _obj(
        "cpg_walker.DiagnosticStatus", {"level": {"type": "integer"}, "message": {"type": "string"},
                                        "hardware_id": {"type": "string"},
                                        "values": {"type": "object", "additionalProperties": {}}})}})
STRING_SCHEMA = _obj("std_msgs/msg/String", {"data": {"type": "string"}})


def stamp_dict(t_ns: int) -> dict:
    return {"sec": int(t_ns // 1_000_000_000), "nsec": int(t_ns % 1_000_000_000)}


# ------------------------------------------------------------------------------------------ contents

def cpg_state(names: list[str], n_osc: int, data, t_ns: int) -> dict:
    """/cpg/state (cpg_node's layout: [dof, oscillator N + output, value 3]) keyed by DOF name."""
    a = np.asarray(data, dtype=float).reshape(len(names), n_osc + 1, 3)
    dofs = {}
    for i, name in enumerate(names):
        osc, out = a[i, :n_osc], a[i, n_osc]
        dofs[name] = {"phase_rad": np.mod(osc[:, 0], 2 * math.pi).tolist(),
                      "frequency_hz": osc[:, 1].tolist(),
                      "amplitude_rad": osc[:, 2].tolist(), "target_rad": float(out[0]),
                      "target_rads": float(out[1]), "offset_rad": float(out[2])}
    return {"timestamp": stamp_dict(t_ns), "dofs": dofs}


def cpg_layout(dims) -> tuple[list[str], int]:
    """(DOF names, oscillators per DOF) from /cpg/state's layout dims; ValueError if it is not cpg_node's."""
    if len(dims) != 3 or not dims[0].label.startswith("dof:") or dims[2].size != 3 or dims[1].size < 2:
        raise ValueError("not cpg_node's /cpg/state layout [dof, oscillator + output, 3]")
    names = dims[0].label[len("dof:"):].split(",")
    if len(names) != dims[0].size:
        raise ValueError(f"/cpg/state names {len(names)} DOFs, its layout {dims[0].size}")
    return names, int(dims[1].size) - 1


def teach_state(dims, data, t_ns: int) -> dict:
    """/cpg/teach/state (cpg_node's layout: [dof, value 3]) keyed by DOF name; ValueError if it is not
    cpg_node's."""
    if len(dims) != 2 or not dims[0].label.startswith("dof:") or dims[1].size != 3:
        raise ValueError("not cpg_node's /cpg/teach/state layout [dof, 3]")
    names = dims[0].label[len("dof:"):].split(",")
    a = np.asarray(data, dtype=float)
    if len(names) != dims[0].size or a.size != 3 * len(names):
        raise ValueError(f"/cpg/teach/state names {len(names)} DOFs, its layout {dims[0].size}, "
                         f"{a.size} values")
    a = a.reshape(len(names), 3)
    return {"timestamp": stamp_dict(t_ns), "dofs": {
        n: {"learned_frequency_hz": float(r[0]), "amplitude_rad": float(r[1]), "error_deg": float(r[2])}
        for n, r in zip(names, a, strict=True)}}


def diagnostics(statuses, t_ns: int) -> dict:
    """A DiagnosticArray's statuses by name (values as numbers where they parse)."""
    def value(v: str) -> object:
        try:
            return float(v)
        except ValueError:
            return v
    return {"timestamp": stamp_dict(t_ns), "status": {
        s.name: {"level": int.from_bytes(s.level, "little") if isinstance(s.level, bytes) else int(s.level),
                 "message": s.message, "hardware_id": s.hardware_id,
                 "values": {kv.key: value(kv.value) for kv in s.values}} for s in statuses}}


def wrench_load(data: bytes) -> tuple[int, float]:
    """(stamp ns, force.z) of a serialized geometry_msgs/WrenchStamped, read straight from its CDR (a few
    microseconds; rclpy's deserialization takes ~50 us, at 1000 loads per sim second). ValueError if the
    bytes are not such a message."""
    if len(data) < 20 or data[0] != 0 or data[1] not in (0, 1):
        raise ValueError("not a CDR message")
    e = "<" if data[1] == 1 else ">"
    sec, nsec, n = struct.unpack_from(e + "iII", data, 4)
    pos = 16 + n  # after frame_id (its length counts the NUL)
    pos = 4 + (pos - 4 + 7) // 8 * 8  # doubles align to 8 from the end of the encapsulation header
    if n < 1 or pos + 48 > len(data):
        raise ValueError(f"a WrenchStamped has 6 doubles after its frame id; {len(data)} bytes")
    return sec * 1_000_000_000 + nsec, struct.unpack_from(e + "d", data, pos + 16)[0]


class Poser:
    """The link transforms of the HOAP-2 posed by joint angles and the floating base (robot/frames.py on
    the MuJoCo model): what /tf would carry, as (parent, child, translation, quaternion wxyz) tuples."""

    def __init__(self) -> None:
        self.model = mujoco.MjModel.from_xml_path(str(MODEL_PATH))
        self.data = mujoco.MjData(self.model)
        hinges = [j for j in range(self.model.njnt) if self.model.jnt_type[j] != mujoco.mjtJoint.mjJNT_FREE]
        self.qpos_of = {self.model.joint(j).name: int(self.model.jnt_qposadr[j]) for j in hinges}

    def transforms(self, position, quat_wxyz, joints) -> list:
        """``joints``: (name, angle) pairs; names the model does not have are skipped."""
        set_pose(self.model, self.data, position, quat_wxyz, ())  # the floating base
        qpos, adr = self.data.qpos, self.qpos_of
        for name, q in joints:
            a = adr.get(name)
            if a is not None:
                qpos[a] = q
        mujoco.mj_kinematics(self.model, self.data)
        return [odom_transform(self.model, self.data), *body_transforms(self.model, self.data),
                *site_transforms(self.model, self.data)]


class Contacts:
    """Pairs /foot_load/left and /right by stamp and runs robot/contact.py's TouchdownDetector on every
    pair (not only on the displayed ones: touchdowns are events)."""

    def __init__(self) -> None:
        self.detector = TouchdownDetector()
        self.pending: dict[int, dict[str, float]] = {}
        self.loads = [0.0, 0.0]
        self.t_ns = -1
        self.touchdowns: list[tuple[str, int]] = []  # (side, t_ns) not yet shown

    def add(self, side: str, t_ns: int, load_n: float) -> None:
        if t_ns <= self.t_ns:
            return
        got = self.pending.setdefault(t_ns, {})
        got[side] = load_n
        if len(got) < 2:
            if len(self.pending) > 8:  # a lost sample: forget the oldest half-pairs
                for old in sorted(self.pending)[:-4]:
                    del self.pending[old]
            return
        for old in [k for k in self.pending if k <= t_ns]:
            del self.pending[old]
        self.t_ns = t_ns
        self.loads = [got["left"], got["right"]]
        events = self.detector.update(t_ns / 1e9, (self.loads[0], self.loads[1]))
        for s, ev in zip(SIDES, events, strict=True):
            if ev:
                self.touchdowns.append((s, t_ns))

    def state(self) -> dict:
        d = self.detector.state or [(False, None), (False, None)]
        return {"timestamp": stamp_dict(max(self.t_ns, 0)),
                **{f"{s}_load_n": self.loads[i] for i, s in enumerate(SIDES)},
                **{f"{s}_down": bool(d[i][0]) for i, s in enumerate(SIDES)},
                **{f"{s}_touchdowns": len(self.detector.events[s]) for s in SIDES}}
