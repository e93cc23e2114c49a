"""Make the LEAP hand's shipped meshes (meshes/*.stl) from the published visual meshes.

Not part of handrig: a one-off preparation step, kept so the shipped files can be
made again and checked. NOTICE.md beside this file names the source and the changes.

    python -m venv /tmp/leapmesh
    /tmp/leapmesh/bin/pip install numpy scipy pymeshlab==2025.7.post1
    /tmp/leapmesh/bin/python data/robots/leap_hand/make_meshes.py SRC_DIR

SRC_DIR holds the source OBJ files (dexsuite/dex-urdf
``robots/hands/leap_hand/meshes/visual/``). Each OBJ is split at its ``usemtl``
lines into one part per material (the fingertips are a black shell and a white
pad); each part is decimated by MeshLab's quadric edge collapse (pymeshlab; a tool
only, nothing of it is shipped) to :data:`TRIANGLES` triangles (the palm, the
largest part, to :data:`PALM_TRIANGLES`) and written as binary STL. The table
printed for NOTICE.md gives the source and shipped triangle counts and how far the
shipped surface lies from the source's (99th percentile and largest distance
between points sampled on each, in mm). Vertex coordinates are kept as they are
(metres, the source's frame), so the model's geom poses apply unchanged.
"""

from __future__ import annotations

import struct
import sys
from pathlib import Path

import numpy as np

TRIANGLES = 2400
PALM_TRIANGLES = 4800
OUT = Path(__file__).resolve().parent / "meshes"
# source OBJ -> {material in the OBJ: shipped STL}
PARTS = {
    "palm_lower.obj": {"black_metal": "palm.stl"},
    "mcp_joint.obj": {"black_metal": "base.stl"},
    "pip.obj": {"black_metal": "proximal.stl"},
    "dip.obj": {"black_metal": "medial.stl"},
    "fingertip.obj": {"black_metal": "distal.stl", "White_tip": "distal_pad.stl"},
    "thumb_pip.obj": {"black_metal": "thumb_base.stl"},
    "thumb_dip.obj": {"black_metal": "thumb_proximal.stl"},
    "thumb_fingertip.obj": {"black_metal": "thumb_distal.stl",
                            "White_tip": "thumb_distal_pad.stl"},
}


def read_obj(path: Path) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Vertices and, per material, triangles (polygons fanned) as 0-based indices.
    Faces before any ``usemtl`` line count as the first material named after them."""
    verts: list[list[float]] = []
    faces: dict[str | None, list[list[int]]] = {}
    material: str | None = None
    for line in path.read_text().splitlines():
        word, _, rest = line.partition(" ")
        if word == "v":
            verts.append([float(x) for x in rest.split()[:3]])
        elif word == "usemtl":
            material = rest.strip()
        elif word == "f":
            idx = [int(tok.split("/")[0]) for tok in rest.split()]
            idx = [i - 1 if i > 0 else len(verts) + i for i in idx]
            tris = faces.setdefault(material, [])
            tris.extend([idx[0], idx[k], idx[k + 1]] for k in range(1, len(idx) - 1))
    unnamed = faces.pop(None, [])
    if unnamed:
        first = next(iter(faces), None)
        if first is None:
            raise SystemExit(f"{path}: faces but no usemtl line")
        faces[first] = unnamed + faces[first]
    return np.array(verts), {k: np.array(v, dtype=np.int64) for k, v in faces.items()
                             if k is not None}


def compact(verts: np.ndarray, tris: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Only the vertices ``tris`` uses, those at the same place (to 0.1 um) welded into
    one (the export splits them along sharp edges, which decimation would keep as
    open seams), reindexed; triangles left with a repeated corner dropped."""
    key = np.round(verts / 1e-7).astype(np.int64)
    _, first, weld = np.unique(key, axis=0, return_index=True, return_inverse=True)
    tris = weld.reshape(-1)[tris]
    tris = tris[(tris[:, 0] != tris[:, 1]) & (tris[:, 1] != tris[:, 2])
                & (tris[:, 0] != tris[:, 2])]
    used, inverse = np.unique(tris, return_inverse=True)
    return verts[first][used], inverse.reshape(tris.shape)


def decimate(verts: np.ndarray, tris: np.ndarray, target: int) -> tuple[np.ndarray, np.ndarray]:
    """Quadric edge collapse to ``target`` triangles (the mesh as it is when it has
    no more); worked in millimetres, MeshLab's thresholds being absolute."""
    import pymeshlab

    if len(tris) <= target:
        return verts, tris
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=verts * 1000.0, face_matrix=tris.astype(np.int32)))
    ms.meshing_decimation_quadric_edge_collapse(targetfacenum=target, preservenormal=True,
                                                planarquadric=True)
    out = ms.current_mesh()
    return np.asarray(out.vertex_matrix()) / 1000.0, np.asarray(out.face_matrix())


def _surface_points(verts: np.ndarray, tris: np.ndarray, n: int) -> np.ndarray:
    """``n`` points spread evenly by area over the triangles (fixed seed)."""
    rng = np.random.default_rng(0)
    corners = verts[tris]
    area = np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0],
                                   corners[:, 2] - corners[:, 0]), axis=1)
    pick = rng.choice(len(tris), n, p=area / area.sum())
    r1, r2 = np.sqrt(rng.random(n))[:, None], rng.random(n)[:, None]
    c = corners[pick]
    return c[:, 0] * (1 - r1) + c[:, 1] * (r1 * (1 - r2)) + c[:, 2] * (r1 * r2)


def deviation_mm(source: tuple[np.ndarray, np.ndarray],
                 shipped: tuple[np.ndarray, np.ndarray]) -> tuple[float, float]:
    """99th percentile and largest distance (mm) between points sampled on one
    surface and the nearest sampled on the other, both ways."""
    from scipy.spatial import cKDTree

    a, b = _surface_points(*source, 100_000), _surface_points(*shipped, 100_000)
    d = np.concatenate([cKDTree(b).query(a)[0], cKDTree(a).query(b)[0]]) * 1000.0
    return float(np.percentile(d, 99)), float(d.max())


def write_stl(path: Path, verts: np.ndarray, tris: np.ndarray, name: str) -> None:
    """Binary STL: facet normals from the winding, vertices in float32."""
    v = verts[tris].astype(np.float32)
    n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    length = np.linalg.norm(n, axis=1, keepdims=True)
    n = np.where(length > 0, n / np.where(length > 0, length, 1.0), 0.0).astype(np.float32)
    header = f"handrig LEAP hand {name}".encode()[:80].ljust(80, b" ")
    rows = np.zeros(len(tris), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
    rows["n"], rows["v"] = n, v
    path.write_bytes(header + struct.pack("<I", len(tris)) + rows.tobytes())


def main(src: Path) -> None:
    OUT.mkdir(exist_ok=True)
    print("| source (material) | source triangles | shipped file | shipped triangles "
          "| distance p99 / max (mm) |")
    print("| --- | --- | --- | --- | --- |")
    for obj, parts in PARTS.items():
        verts, by_material = read_obj(src / obj)
        if set(by_material) != set(parts):
            raise SystemExit(f"{obj}: materials {sorted(by_material)}, expected {sorted(parts)}")
        for material, stl in parts.items():
            v, t = compact(verts, by_material[material])
            dv, dt = decimate(v, t, PALM_TRIANGLES if stl == "palm.stl" else TRIANGLES)
            write_stl(OUT / stl, dv, dt, stl)
            p99, worst = deviation_mm((v, t), (dv, dt))
            print(f"| {obj} ({material}) | {len(t)} | {stl} | {len(dt)} "
                  f"| {p99:.2f} / {worst:.2f} |")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        raise SystemExit(__doc__)
    main(Path(sys.argv[1]))
