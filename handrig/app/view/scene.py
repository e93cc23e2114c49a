"""The rig's MuJoCo model as the page draws it: geometry once, body poses per frame.

The geometry (each body's geoms: type, size, place in the body, colour, and the
vertices and faces of meshes) is read from the ``MjModel`` the puppet builds
(:func:`handrig.app.simulator.view_models`); a frame is where every body is (world
position and quaternion) after MuJoCo's forward kinematics at the given joint angles.
The page only places bodies: it never computes kinematics itself.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

# mjtGeom: what the page can draw (planes and height fields are left out)
GEOM_KINDS = {2: "sphere", 3: "capsule", 4: "ellipsoid", 5: "cylinder", 6: "box", 7: "mesh"}
VISIBLE_GROUPS = (0, 1, 2)  # the groups MuJoCo's own viewer shows by default


def _round(values: Any, nd: int = 5) -> list[float]:
    out: list[float] = np.round(np.asarray(values, dtype=np.float64).ravel(), nd).tolist()
    return out


class ModelScene:
    """One MuJoCo model (one hand of the puppet, or a robot) for the view: its geometry
    as JSON-able data and its bodies' poses for joint angles in degrees (the
    vocabulary convention: the joint's qpos in degrees)."""

    def __init__(self, model: Any) -> None:
        import mujoco

        self._mujoco = mujoco
        self.model = model
        self.data = mujoco.MjData(model)
        self.qpos_of: dict[str, int] = {}
        for j in range(model.njnt):
            name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j)
            if name and int(model.jnt_type[j]) in (2, 3):  # slide, hinge
                self.qpos_of[name] = int(model.jnt_qposadr[j])
        self._tips = self._tip_geoms()

    def geometry(self) -> dict[str, Any]:
        """Bodies (name, parent) and their visible geoms, meshes once by id."""
        m, mj = self.model, self._mujoco
        bodies = [{"name": mj.mj_id2name(m, mj.mjtObj.mjOBJ_BODY, b) or f"body{b}",
                   "parent": int(m.body_parentid[b])} for b in range(m.nbody)]
        geoms: list[dict[str, Any]] = []
        meshes: dict[str, dict[str, Any]] = {}
        for g in range(m.ngeom):
            kind = GEOM_KINDS.get(int(m.geom_type[g]))
            if kind is None or int(m.geom_group[g]) not in VISIBLE_GROUPS:
                continue
            mat = int(m.geom_matid[g])
            rgba = m.mat_rgba[mat] if mat >= 0 else m.geom_rgba[g]
            if rgba[3] <= 0.0:
                continue
            geom = {"body": int(m.geom_bodyid[g]), "kind": kind, "size": _round(m.geom_size[g]),
                    "pos": _round(m.geom_pos[g]), "quat": _round(m.geom_quat[g]),
                    "rgba": _round(rgba, 3)}
            if kind == "mesh":
                mesh = int(m.geom_dataid[g])
                geom["mesh"] = str(mesh)
                if str(mesh) not in meshes:
                    v0, nv = int(m.mesh_vertadr[mesh]), int(m.mesh_vertnum[mesh])
                    f0, nf = int(m.mesh_faceadr[mesh]), int(m.mesh_facenum[mesh])
                    meshes[str(mesh)] = {"vertices": _round(m.mesh_vert[v0:v0 + nv], 6),
                                         "faces": [int(i) for i in
                                                   m.mesh_face[f0:f0 + nf].ravel()]}
            geoms.append(geom)
        return {"bodies": bodies, "geoms": geoms, "meshes": meshes}

    def _tip_geoms(self) -> list[int]:
        """For each leaf body (no children), its first capsule/cylinder geom (or -1)."""
        m = self.model
        parents = {int(p) for p in m.body_parentid[1:]}
        tips = []
        for b in range(1, m.nbody):
            if b in parents:
                continue
            found = -1
            for g in range(int(m.body_geomadr[b]), int(m.body_geomadr[b] + m.body_geomnum[b])):
                if int(m.geom_type[g]) in (3, 5):
                    found = g
                    break
            tips.append(found)
        return tips

    def pose(self, angles_deg: Mapping[str, float]) -> dict[str, list[float]]:
        """World positions (metres) and quaternions (w, x, y, z) of every body, flat,
        with the named joints at ``angles_deg`` and the others at the model's rest."""
        m, d = self.model, self.data
        d.qpos[:] = m.qpos0
        for name, deg in angles_deg.items():
            adr = self.qpos_of.get(name)
            if adr is not None and math.isfinite(deg):
                d.qpos[adr] = math.radians(deg)
        self._mujoco.mj_kinematics(m, d)
        return {"pos": _round(d.xpos, 4), "quat": _round(d.xquat, 4)}

    def skeleton(self, angles_deg: Mapping[str, float]) -> list[float]:
        """Bone segments, six numbers each (from, to): each body to its parent (bodies
        under the world's first body only), and each leaf body to the far end of its
        capsule or cylinder (the fingertip)."""
        self.pose(angles_deg)
        m, d = self.model, self.data
        segs: list[np.ndarray] = []
        for b in range(2, m.nbody):
            p = int(m.body_parentid[b])
            if p > 0:
                segs.append(np.concatenate([d.xpos[p], d.xpos[b]]))
        for g in self._tips:
            if g >= 0:
                axis = d.geom_xmat[g].reshape(3, 3)[:, 2]
                b = int(m.geom_bodyid[g])
                segs.append(np.concatenate([d.xpos[b], d.geom_xpos[g] + axis * m.geom_size[g][1]]))
        return _round(np.asarray(segs), 4) if segs else []
