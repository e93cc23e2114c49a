"""The rendered strip: one labelled tile per frame, the thumb in its own colour.

Rendering needs EGL or OSMesa (``make render-deps``); where neither works the
drawing test skips with the renderer's reason."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sim.render import (
    MAX_TILES,
    THUMB_RGBA,
    RenderUnavailable,
    picked,
    render_strip,
    tile_labels,
)

DRAW = """
import json, sys
import numpy as np
from handrig.config.rig import load_rig_config
from sim.render import RenderUnavailable, render_strip
rig = load_rig_config()
names = [s.joint for s in rig.servos]
frames = [np.array([0.0 if "Wrist" in n else k / 4 * (s.max_deg if "Thumb" in n else
          0.6 * s.max_deg) for n, s in zip(names, rig.servos)]) for k in range(5)]
try:
    path = render_strip(frames, names, sys.argv[1], times_s=[0.0, 0.5, 1.0, 1.5, 2.0])
except RenderUnavailable as exc:
    print(json.dumps({"unavailable": str(exc)}))
    sys.exit(0)
# rendering works here: the LEAP preset as the demo draws it must draw too (any error fails)
from handrig.pose.robot_rig import load_rig
leap = load_rig("leap")
frames = [np.array([s.min_deg + k * (s.max_deg - s.min_deg) for s in leap.servos])
          for k in (0.2, 0.5)]
render_strip(frames, [s.joint for s in leap.servos], sys.argv[2], model=leap.robot.model)
# the two-hand puppet (both hands' joints: the two-hand model, both hands in view)
both = load_rig("puppet_two_hands")
frames = [np.array([k / 4 * (s.max_deg if "Thumb" in s.joint else 0.6 * s.max_deg)
                    if "Wrist" not in s.joint else 0.0 for s in both.servos]) for k in (1, 3)]
render_strip(frames, [s.joint for s in both.servos], sys.argv[3])
print(json.dumps({"path": str(path)}))
"""


def test_labels_are_times_or_numbers() -> None:
    assert tile_labels(2, [0.0, 1.25]) == ["t = 0.00 s", "t = 1.25 s"]
    assert tile_labels(3, None) == ["frame 1/3", "frame 2/3", "frame 3/3"]
    with pytest.raises(RenderUnavailable, match="one time per frame"):
        tile_labels(3, [0.0])


def test_many_frames_give_evenly_spaced_tiles_that_say_which() -> None:
    assert picked(5) == [0, 1, 2, 3, 4]
    many = picked(100)
    assert len(many) == MAX_TILES and many[0] == 0 and many[-1] == 99
    labels = tile_labels(100, [i / 10 for i in range(100)])
    assert len(labels) == MAX_TILES and labels[-1] == "t = 9.90 s"
    assert tile_labels(100, None)[-1] == "frame 100/100"


def test_no_frames_is_refused(tmp_path: Path) -> None:
    with pytest.raises(RenderUnavailable, match="no frames"):
        render_strip([], ["riIndexMCPy"], tmp_path / "x.png")


@pytest.fixture(scope="module")
def strips(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The puppet hand's strip and the LEAP preset's, drawn by one fresh process (MuJoCo
    picks its GL backend when it is first imported); skips where rendering cannot work."""
    tmp = tmp_path_factory.mktemp("strips")
    out = {"hand": tmp / "strip.png", "leap": tmp / "leap.png", "two": tmp / "two.png"}
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    res = subprocess.run([sys.executable, "-c", DRAW, str(out["hand"]), str(out["leap"]),
                          str(out["two"])],
                         capture_output=True, text=True, timeout=120, env=env)
    assert res.returncode == 0, res.stderr
    said = json.loads(res.stdout.strip().splitlines()[-1])
    if "unavailable" in said:
        pytest.skip(said["unavailable"])
    return out


@pytest.mark.slow
def test_one_tile_per_frame_with_the_thumb_in_colour(strips: dict[str, Path]) -> None:
    from matplotlib.image import imread

    img = imread(strips["hand"])[..., :3]
    assert img.shape == (2 * 240, 3 * 320, 3)  # 5 tiles in rows of 3
    thumb = np.array(THUMB_RGBA[:3])
    for i in range(6):
        r, c = divmod(i, 3)
        tile = img[r * 240:(r + 1) * 240, c * 320:(c + 1) * 320]
        # shaded thumb: the hue of THUMB_RGBA at some brightness
        near = np.abs(tile / np.maximum(tile.max(axis=2, keepdims=True), 1e-6)
                      - thumb / thumb.max()).max(axis=2) < 0.12
        lit = tile.max(axis=2) > 0.3
        if i < 5:
            assert (near & lit).sum() > 150, f"tile {i}: no thumb"
            assert tile[8:20, 10:60].mean() > 0.8  # the label's white box
        else:
            assert np.all(tile > 0.99)  # the empty sixth place is blank


@pytest.mark.slow
def test_the_two_hand_puppet_draws_both_hands_side_by_side(strips: dict[str, Path]) -> None:
    from matplotlib.image import imread

    img = imread(strips["two"])[..., :3]
    assert img.shape == (240, 2 * 320, 3)  # two tiles
    thumb = np.array(THUMB_RGBA[:3])
    for c in range(2):
        tile = img[:, c * 320:(c + 1) * 320]
        near = np.abs(tile / np.maximum(tile.max(axis=2, keepdims=True), 1e-6)
                      - thumb / thumb.max()).max(axis=2) < 0.12
        thumbs = near & (tile.max(axis=2) > 0.3)
        hand = tile.min(axis=2) < 0.75  # not the pale background
        # a hand (and its thumb) in each half of the tile: both hands are in view
        for half in (slice(0, 160), slice(160, 320)):
            assert hand[:, half].sum() > 1500, f"tile {c}: a hand missing"
        assert thumbs.sum() > 100, f"tile {c}: no thumb"


@pytest.mark.parametrize("robot", ["leap_hand", "orca_hand"])
def test_a_robot_is_drawn_from_its_meshes_not_its_collision_geoms(robot: str) -> None:
    """The scene a render draws (built without GL) holds every visual mesh of the robot
    and none of its collision geoms."""
    import mujoco

    from sim.render import scene_option

    path = Path(__file__).resolve().parents[2] / "data" / "robots" / robot / "right_hand.xml"
    model = mujoco.MjModel.from_xml_path(str(path))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    scene = mujoco.MjvScene(model, maxgeom=2 * model.ngeom)
    mujoco.mjv_updateScene(model, data, scene_option(mujoco), None, mujoco.MjvCamera(),
                           mujoco.mjtCatBit.mjCAT_ALL, scene)
    drawn = {int(scene.geoms[i].objid) for i in range(scene.ngeom)
             if scene.geoms[i].objtype == mujoco.mjtObj.mjOBJ_GEOM}
    meshes = {g for g in range(model.ngeom) if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH}
    assert len(meshes) >= 20 and drawn == meshes



@pytest.mark.slow
def test_the_leap_strip_shows_the_robot_from_its_mesh_files(strips: dict[str, Path]) -> None:
    """The preset's model loaded as the render loads it (its mesh directory made
    absolute): dark shells, white pads, the thumb in its colour."""
    from matplotlib.image import imread

    from sim.render import ROBOT_RGBA, TIP_RGBA

    img = imread(strips["leap"])[..., :3]
    assert img.shape == (240, 2 * 320, 3)
    for rgba in (THUMB_RGBA, ROBOT_RGBA, TIP_RGBA):  # lit or shaded: within 0.2
        near = np.abs(img - np.array(rgba[:3])).max(axis=2) < 0.2
        assert near.mean() > 0.002, rgba
