"""Offscreen rendering of the simulated HOAP-2: frames from the side camera, a PNG filmstrip and a GIF.

Set ``MUJOCO_GL=egl`` (the Makefile does) before MuJoCo is first imported for headless rendering; this
module sets it if it is unset.
"""

from __future__ import annotations

import os

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
