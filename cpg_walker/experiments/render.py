"""Offscreen rendering of the simulated HOAP-2: frames from the side camera, a PNG filmstrip and a GIF, and
a video of a recording (``render_recording``: the model posed from /odom/ground_truth + /joint_states).

Set ``MUJOCO_GL=egl`` (the Makefile does) before MuJoCo is first imported for headless rendering; this
module sets it if it is unset.
"""

from __future__ import annotations

import os
from collections.abc import Callable

os.environ.setdefault("MUJOCO_GL", "egl")

from pathlib import Path

import mujoco
import numpy as np


class FrameGrabber:
    """Keeps a frame from the model's tracking ``side`` camera every ``every_s`` of sim time."""

    def __init__(self, model: mujoco.MjModel, every_s: float = 0.1, width: int = 480, height: int = 360,
                 camera: str = "side"):
        self.renderer = mujoco.Renderer(model, height, width)
        self.every_s = every_s
        self.camera = camera
        self.frames: list[np.ndarray] = []
        self.times: list[float] = []
        self._next = 0.0

    def __call__(self, sim) -> None:
        """Use as ``on_log`` of a replay: renders when the next frame time is reached."""
        if sim.time + 1e-9 < self._next:
            return
        self.renderer.update_scene(sim.data, camera=self.camera)
        self.frames.append(self.renderer.render().copy())
        self.times.append(sim.time)
        self._next = sim.time + self.every_s

    def close(self) -> None:
        self.renderer.close()


def _annotated(frame: np.ndarray, text: str):
    from PIL import Image, ImageDraw

    img = Image.fromarray(frame)
    ImageDraw.Draw(img).text((8, 6), text, fill=(20, 20, 20))
    return img


def write_filmstrip(frames: list[np.ndarray], times: list[float], path: str | Path, count: int = 8,
                    columns: int = 4, title: str = "") -> Path:
    """A grid of ``count`` evenly spaced frames, each labelled with its sim time, as one PNG."""
    from PIL import Image, ImageDraw

    if not frames:
        raise ValueError("no frames to write")
    idx = np.linspace(0, len(frames) - 1, min(count, len(frames))).round().astype(int)
    h, w = frames[0].shape[:2]
    rows = (len(idx) + columns - 1) // columns
    top = 22 if title else 0
    sheet = Image.new("RGB", (w * min(columns, len(idx)), h * rows + top), (255, 255, 255))
    if title:
        ImageDraw.Draw(sheet).text((8, 5), title, fill=(0, 0, 0))
    for k, i in enumerate(idx):
        where = ((k % columns) * w, top + (k // columns) * h)
        sheet.paste(_annotated(frames[i], f"t = {times[i]:.1f} s"), where)
    out = Path(path)
    sheet.save(out)
    return out


def write_gif(frames: list[np.ndarray], times: list[float], path: str | Path, speedup: float = 2.0,
              max_frames: int = 300, scale: float = 0.75) -> Path:
    """An animated GIF of the frames played ``speedup`` times faster than sim time."""
    from PIL import Image

    if not frames:
        raise ValueError("no frames to write")
    step = max(1, int(np.ceil(len(frames) / max_frames)))
    picked = list(range(0, len(frames), step))
    dt = (times[picked[1]] - times[picked[0]]) if len(picked) > 1 else 0.1
    images = []
    for i in picked:
        img = _annotated(frames[i], f"t = {times[i]:.1f} s")
        if scale != 1.0:
            img = img.resize((int(img.width * scale), int(img.height * scale)))
        images.append(img.convert("P", palette=Image.Palette.ADAPTIVE, colors=64))
    out = Path(path)
    images[0].save(out, save_all=True, append_images=images[1:], duration=max(20, int(1000 * dt / speedup)),
                   loop=0, optimize=True)
    return out


def recorded_poses(bag: str | Path, every_s: float) -> list[tuple[float, tuple, tuple, list]]:
    """(sim s, base position, base quaternion wxyz, [(joint, angle)]) every ``every_s`` of a recording
    (nodes/recording.py): each /odom/ground_truth sample due with the /joint_states of the same stamp (the
    pairing the recording's /tf is computed from)."""
    from cpg_walker.nodes.recording import JOINT_STATES_TOPIC, ODOM_TOPIC, read_topics

    if not every_s > 0:
        raise ValueError(f"the frame interval must be > 0 s, got {every_s}")
    topics = read_topics(bag, [ODOM_TOPIC, JOINT_STATES_TOPIC])
    joints = {ns: m for ns, m in topics.get(JOINT_STATES_TOPIC, []) if len(m.position)}
    out: list[tuple[float, tuple, tuple, list]] = []
    next_ns = 0
    for ns, odom in topics.get(ODOM_TOPIC, []):
        js = joints.get(ns)
        if ns < next_ns or js is None:
            continue
        p, o = odom.pose.pose.position, odom.pose.pose.orientation
        out.append((ns / 1e9, (p.x, p.y, p.z), (o.w, o.x, o.y, o.z),
                    list(zip(js.name, js.position, strict=False))))
        next_ns = ns + round(every_s * 1e9)
    return out


def render_recording(bag: str | Path, path: str | Path, fps: float = 12.5, every_s: float | None = None,
                     width: int = 480, height: int = 360, caption: Callable[[float], str] | None = None,
                     camera: str = "side") -> Path:
    """A video of a recording: the model posed from /odom/ground_truth and /joint_states (robot/frames.py
    ``set_pose``) every ``every_s`` sim s (default 1/fps: sim speed), played at ``fps``, seen from the
    tracking ``side`` camera; ``caption(t)`` is written on each frame (default: the sim time). ``.mp4``
    (H.264, imageio-ffmpeg) or ``.gif``. MuJoCo renders on the CPU here (EGL without a GPU): ~0.1-0.5 s
    a 480x360 frame on a loaded 2-core machine."""
    from cpg_walker.robot import frames
    from cpg_walker.robot.hoap2 import MODEL_PATH

    out = Path(path)
    if out.suffix not in (".mp4", ".gif"):
        raise ValueError(f"{out}: the video must be a .mp4 or .gif file")
    poses = recorded_poses(bag, every_s or 1.0 / fps)
    if not poses:
        raise ValueError(f"{bag}: no /odom/ground_truth with /joint_states of the same stamp to render")
    model = mujoco.MjModel.from_xml_path(str(MODEL_PATH))
    data = mujoco.MjData(model)
    caption = caption or (lambda t: f"t = {t:.1f} s")
    renderer = mujoco.Renderer(model, height, width)
    images = []
    try:
        for t, pos, quat, joints in poses:
            frames.set_pose(model, data, pos, quat, joints)
            mujoco.mj_forward(model, data)  # transforms and the tracking camera
            renderer.update_scene(data, camera=camera)
            images.append(np.asarray(_annotated(renderer.render(), caption(t))))
    finally:
        renderer.close()
    if out.suffix == ".gif":
        return write_gif(images, [p[0] for p in poses], out, speedup=(every_s or 1.0 / fps) * fps,
                         max_frames=len(images))
    import imageio.v2 as imageio

    with imageio.get_writer(out, fps=fps, codec="libx264", macro_block_size=8) as writer:
        for image in images:
            writer.append_data(image)
    return out
