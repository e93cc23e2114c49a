"""Render the simulated hand to an image strip (offscreen, no display needed).

Uses MuJoCo's offscreen renderer with ``MUJOCO_GL=egl`` (or ``osmesa``); where
neither works, :func:`render_strip` raises :class:`RenderUnavailable` with the
reason, and callers say so plainly. ``make render-deps`` installs the system
libraries (Debian: libegl1, libgl1-mesa-dri, libosmesa6).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from handrig.errors import HandrigError


class RenderUnavailable(HandrigError):
    """Offscreen rendering does not work on this machine."""


def _renderer_backend() -> None:
    os.environ.setdefault("MUJOCO_GL", "egl")


def render_strip(
    frames_deg: Sequence[np.ndarray],
    joint_names: Sequence[str],
    out: str | Path,
    *,
    n_images: int = 6,
    size: tuple[int, int] = (320, 240),
) -> Path:
    """Pose the puppet hand at up to ``n_images`` of ``frames_deg`` and save a PNG strip.

    ``frames_deg``: joint angles in degrees, one array per frame, in ``joint_names``
    order (the rig's servo order); other joints stay at zero.
    """
    _renderer_backend()
    if not frames_deg:
        raise RenderUnavailable("nothing to render: no frames were captured")
    try:
        import mujoco
    except ImportError as exc:  # pragma: no cover - mujoco is a core dependency
        raise RenderUnavailable(f"mujoco is not importable: {exc}") from None
    from sim.hand_model import hand_model_xml

    model = mujoco.MjModel.from_xml_string(hand_model_xml("ri"))
    data = mujoco.MjData(model)
    qadr = []
    for name in joint_names:
        jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, name)
        qadr.append(int(model.jnt_qposadr[jid]) if jid >= 0 else -1)
    width, height = size
    try:
        renderer = mujoco.Renderer(model, height, width)
    except Exception as exc:
        raise RenderUnavailable(
            f"offscreen rendering is not available (MUJOCO_GL={os.environ.get('MUJOCO_GL')}): "
            f"{exc}; `make render-deps` installs the EGL/OSMesa libraries"
        ) from None
    mujoco.mj_forward(model, data)
    cam = mujoco.MjvCamera()
    # look at the middle of the fingers from the thumb side, a little from above
    tips = [i for i in range(model.nbody) if model.body_parentid[i] > 0]
    cam.lookat[:] = data.xpos[tips].mean(axis=0)
    cam.distance = 0.32
    cam.azimuth = 120.0
    cam.elevation = -25.0
    model.vis.headlight.ambient[:] = (0.45, 0.45, 0.45)
    model.vis.headlight.diffuse[:] = (0.7, 0.7, 0.7)
    picks = np.linspace(0, len(frames_deg) - 1, min(n_images, len(frames_deg))).astype(int)
    images = []
    for i in picks:
        data.qpos[:] = 0.0
        for adr, value in zip(qadr, frames_deg[i], strict=True):
            if adr >= 0 and np.isfinite(value):
                data.qpos[adr] = np.radians(value)
        mujoco.mj_forward(model, data)
        renderer.update_scene(data, camera=cam)
        images.append(renderer.render().copy())
    renderer.close()
    cols = min(3, len(images))
    while len(images) % cols:
        images.append(np.zeros_like(images[0]))
    rows = [np.concatenate(images[r:r + cols], axis=1) for r in range(0, len(images), cols)]
    strip = np.concatenate(rows, axis=0)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    from matplotlib.image import imsave  # no pyplot: no backend switch in the caller

    imsave(out, strip)
    return out
