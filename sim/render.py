"""Render the simulated hand to an image strip (offscreen, no display needed).

Uses MuJoCo's offscreen renderer with ``MUJOCO_GL=egl`` (or ``osmesa``); where
neither works, :func:`render_strip` raises :class:`RenderUnavailable` with the
reason, and callers say so plainly. ``make render-deps`` installs the system
libraries (Debian: libegl1, libgl1-mesa-dri, libosmesa6).

Every frame given is one tile, up to :data:`MAX_TILES` (beyond that, that many
evenly spaced frames: :func:`picked`), labelled with its time (or its number
when no times are given).
The camera looks from ahead of the fingers on the thumb's side, a little above
the back of the hand, and follows the hand. The thumb is drawn in its own
colour (:data:`THUMB_RGBA`), the other fingers in skin tones, the palm and
forearm darker, on a light background.

With ``model`` (a robot rig's MJCF file, e.g. the LEAP hand) the robot is drawn
instead: its joints are named by the rig's servos. The geom groups MuJoCo's own
viewer shows by default (0, 1 and 2) are drawn, as in the live view: the LEAP and
ORCA presets' meshes (group 2), not their collision geoms (group 3). Thumb bodies
(``th_*``) are in the thumb colour, white geoms (e.g. fingertip pads) light, the
rest in :data:`ROBOT_RGBA`.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from handrig.errors import HandrigError

MAX_TILES = 12
COLUMNS = 3
THUMB_RGBA = (0.93, 0.45, 0.16, 1.0)
FINGER_RGBA = (0.87, 0.72, 0.62, 1.0)
PALM_RGBA = (0.72, 0.55, 0.46, 1.0)
FOREARM_RGBA = (0.58, 0.47, 0.42, 1.0)
ROBOT_RGBA = (0.30, 0.32, 0.36, 1.0)
TIP_RGBA = (0.92, 0.92, 0.90, 1.0)
BACKGROUND = '<texture type="skybox" builtin="gradient" rgb1="0.96 0.96 0.97" ' \
             'rgb2="0.78 0.81 0.86" width="64" height="64"/>'


class RenderUnavailable(HandrigError):
    """Offscreen rendering does not work on this machine."""


def _renderer_backend() -> None:
    os.environ.setdefault("MUJOCO_GL", "egl")


def picked(n_frames: int) -> list[int]:
    """Indices of the frames drawn out of ``n_frames``: all of them up to
    :data:`MAX_TILES`, else that many evenly spaced, first and last included."""
    if n_frames <= MAX_TILES:
        return list(range(n_frames))
    return [round(i * (n_frames - 1) / (MAX_TILES - 1)) for i in range(MAX_TILES)]


def tile_labels(n_frames: int, times_s: Sequence[float] | None) -> list[str]:
    """The label of each tile drawn (:func:`picked`): the frame's time, or its number
    without times."""
    if times_s is not None and len(times_s) != n_frames:
        raise RenderUnavailable(f"{len(times_s)} times for {n_frames} frames: give one "
                                "time per frame")
    if times_s is None:
        return [f"frame {i + 1}/{n_frames}" for i in picked(n_frames)]
    return [f"t = {times_s[i]:.2f} s" for i in picked(n_frames)]


def render_strip(
    frames_deg: Sequence[np.ndarray],
    joint_names: Sequence[str],
    out: str | Path,
    *,
    times_s: Sequence[float] | None = None,
    size: tuple[int, int] = (320, 240),
    model: str | Path | None = None,
    view: tuple[float, float, float] | None = None,
    labels: Sequence[str] | None = None,
) -> Path:
    """Pose the puppet hand at each of ``frames_deg`` and save the tiles as one PNG.

    ``frames_deg``: joint angles in degrees, one array per frame, in
    ``joint_names`` order (the rig's servo order); other joints stay at zero.
    ``len(picked(len(frames_deg)))`` tiles are drawn. ``times_s``: each frame's
    time, written on its tile. ``model``: an MJCF file to draw instead of the puppet
    hand (a robot rig's ``[robot].model``). ``view``: the camera's distance (m),
    azimuth and elevation (degrees) around the hand, instead of the default.
    ``labels``: what each drawn tile says instead of its time (one per tile).
    """
    _renderer_backend()
    if not frames_deg:
        raise RenderUnavailable("nothing to render: no frames were captured")
    tiles = tile_labels(len(frames_deg), times_s)
    if labels is not None and len(labels) != len(tiles):
        raise RenderUnavailable(f"{len(labels)} labels for {len(tiles)} tiles")
    labels = list(labels) if labels is not None else tiles
    try:
        import mujoco
    except Exception as exc:  # a GL backend without its library fails at import
        raise RenderUnavailable(
            f"mujoco does not load with MUJOCO_GL={os.environ.get('MUJOCO_GL')}: {exc!r}; "
            "`make render-deps` installs the EGL/OSMesa libraries") from None
    two_hands = model is None and any(name.startswith("le") for name in joint_names)
    if model is None:
        from sim.hand_model import hand_model_xml, two_hands_xml

        xml = two_hands_xml() if two_hands else hand_model_xml("ri")
    else:
        try:
            xml = _with_absolute_meshdir(Path(model))
        except OSError as exc:
            raise RenderUnavailable(f"cannot read the robot model {model}: {exc}") from None
    xml = xml.replace("<worldbody>", f"<asset>{BACKGROUND}</asset><worldbody>", 1)
    try:
        mj_model = mujoco.MjModel.from_xml_string(xml)
    except ValueError as exc:
        raise RenderUnavailable(f"MuJoCo cannot load {model or 'the hand model'}: {exc}"
                                ) from None
    data = mujoco.MjData(mj_model)
    if model is None:
        _colour(mj_model, mujoco)
        thumb_coloured = True
        hand_bodies = []
        for prefix in ("ri", "le") if two_hands else ("ri",):
            palm = mujoco.mj_name2id(mj_model, mujoco.mjtObj.mjOBJ_BODY, f"{prefix}Palm")
            hand_bodies += [i for i in range(palm, mj_model.nbody) if palm > 0 and (
                mujoco.mj_id2name(mj_model, mujoco.mjtObj.mjOBJ_BODY, i) or ""
            ).startswith(prefix)]
        # both hands side by side (sim.hand_model.TWO_HANDS_APART_M) fit a wider view
        distance, azimuth, elevation = (0.55, -150.0, -30.0) if two_hands else (
            0.30, -150.0, -20.0)
    else:
        thumb_coloured = _colour_robot(mj_model, mujoco)
        hand_bodies = list(range(1, mj_model.nbody))
        distance, azimuth, elevation = 0.40, 150.0, -35.0
    return _draw(mj_model, data, mujoco, frames_deg, joint_names, labels, hand_bodies,
                 view or (distance, azimuth, elevation), size, Path(out),
                 thumb_label=thumb_coloured)


def _draw(model: object, data: object, mujoco: object, frames_deg: Sequence[np.ndarray],
          joint_names: Sequence[str], labels: list[str], hand_bodies: list[int],
          view: tuple[float, float, float], size: tuple[int, int], out: Path, *,
          thumb_label: bool = True) -> Path:
    """Pose ``model`` at each picked frame, draw it from ``view`` (distance, azimuth,
    elevation) looking at the mean of ``hand_bodies``, and save the strip (MuJoCo's
    default geom groups 0-2); ``thumb_label``: say which colour is the thumb."""
    m: Any = model
    d: Any = data
    mj: Any = mujoco
    qadr = []
    for name in joint_names:
        jid = mj.mj_name2id(m, mj.mjtObj.mjOBJ_JOINT, name)
        qadr.append(int(m.jnt_qposadr[jid]) if jid >= 0 else -1)
    width, height = size
    try:
        renderer = mj.Renderer(m, height, width)
    except Exception as exc:
        raise RenderUnavailable(
            f"offscreen rendering is not available (MUJOCO_GL={os.environ.get('MUJOCO_GL')}): "
            f"{exc}; `make render-deps` installs the EGL/OSMesa libraries"
        ) from None
    cam = mj.MjvCamera()
    cam.distance, cam.azimuth, cam.elevation = view
    opt = scene_option(mj)
    m.vis.headlight.ambient[:] = (0.42, 0.42, 0.42)
    m.vis.headlight.diffuse[:] = (0.62, 0.62, 0.62)
    m.vis.headlight.specular[:] = (0.1, 0.1, 0.1)
    images = []
    try:
        for i in picked(len(frames_deg)):
            frame = frames_deg[i]
            d.qpos[:] = 0.0
            for adr, value in zip(qadr, frame, strict=True):
                if adr >= 0 and np.isfinite(value):
                    d.qpos[adr] = np.radians(value)
            mj.mj_forward(m, d)
            cam.lookat[:] = d.xpos[hand_bodies].mean(axis=0)
            renderer.update_scene(d, camera=cam, scene_option=opt)
            images.append(renderer.render().copy())
    finally:
        renderer.close()
    return _save(images, labels, out, thumb_label=thumb_label)


def scene_option(mujoco: Any) -> Any:
    """What a render draws: MuJoCo's default ``MjvOption``, whose geom groups 0-2 are
    on and 3-5 off (a robot model's visual meshes, not its collision geoms in group 3),
    the groups the live view draws too (``handrig.app.view.scene.VISIBLE_GROUPS``)."""
    return mujoco.MjvOption()


def _with_absolute_meshdir(path: Path) -> str:
    """The model's XML with its ``<compiler meshdir>`` made absolute: loaded from a
    string, MuJoCo would look for the meshes relative to the working directory."""
    import xml.etree.ElementTree as ET

    text = path.read_text()
    root = ET.fromstring(text)
    compiler = root.find("compiler")
    if compiler is None or compiler.get("meshdir") is None:
        return text
    compiler.set("meshdir", str((path.parent / compiler.get("meshdir", "")).resolve()))
    return ET.tostring(root, encoding="unicode")


def _colour_robot(model: object, mujoco: object) -> bool:
    """A robot model's thumb bodies (``th_*``) in the thumb colour, white geoms (the
    fingertips) light, everything else dark grey. True when a geom got the thumb
    colour (a model whose bodies are named otherwise, e.g. ORCA's, has none)."""
    m: Any = model
    thumb = False
    for g in range(m.ngeom):
        body = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY,  # type: ignore[attr-defined]
                                 int(m.geom_bodyid[g])) or ""
        white = bool(np.all(m.geom_rgba[g][:3] > 0.95))
        if m.geom_matid[g] >= 0:
            white = bool(np.all(m.mat_rgba[m.geom_matid[g]][:3] > 0.95))
        rgba = THUMB_RGBA if body.startswith("th_") else TIP_RGBA if white else ROBOT_RGBA
        m.geom_rgba[g] = rgba
        m.geom_matid[g] = -1
        thumb = thumb or rgba is THUMB_RGBA
    return thumb


def _colour(model: object, mujoco: object) -> None:
    """Thumb, fingers, palm and forearm in their colours (geoms named by their body)."""
    m = model
    for g in range(m.ngeom):  # type: ignore[attr-defined]
        body = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY,  # type: ignore[attr-defined]
                                 int(m.geom_bodyid[g])) or ""  # type: ignore[attr-defined]
        rgba = (THUMB_RGBA if "Thumb" in body else PALM_RGBA if body.endswith("Palm")
                else FOREARM_RGBA if body.endswith("Forearm") else FINGER_RGBA)
        m.geom_rgba[g] = rgba  # type: ignore[attr-defined]


def _save(images: list[np.ndarray], labels: list[str], out: Path, *,
          thumb_label: bool = True) -> Path:
    """Tiles in rows of :data:`COLUMNS`, each labelled, as one PNG."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure  # no pyplot: no backend switch in the caller

    h, w = images[0].shape[:2]
    cols = min(COLUMNS, len(images))
    rows = -(-len(images) // cols)
    dpi = 100
    fig = Figure(figsize=(cols * w / dpi, rows * h / dpi), dpi=dpi, facecolor="white")
    FigureCanvasAgg(fig)
    for i, (img, label) in enumerate(zip(images, labels, strict=True)):
        r, c = divmod(i, cols)
        ax = fig.add_axes((c / cols, 1 - (r + 1) / rows, 1 / cols, 1 / rows))
        ax.imshow(img, interpolation="nearest")
        ax.set_axis_off()
        ax.text(0.03, 0.95, label, transform=ax.transAxes, ha="left", va="top",
                fontsize=11, family="monospace", color="black",
                bbox={"facecolor": "white", "alpha": 0.75, "edgecolor": "none", "pad": 2})
        if i == 0 and thumb_label:
            ax.text(0.97, 0.05, "thumb", transform=ax.transAxes, ha="right", va="bottom",
                    fontsize=9, color=THUMB_RGBA, fontweight="bold")
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=dpi, facecolor="white")
    fig.clear()
    return out
