"""A compiled forward-kinematics step over a tree of hinged bodies (numba).

One frame of :class:`handrig.pose.openxr_hand.OpenXrHand` is one call: a dozen small
numpy products per digit cost a few hundred microseconds on a loaded machine, one
compiled loop a few. The tree is data (:func:`chain_poses`' arguments), so the kernel
knows nothing of hands: bodies in parent-before-child order, each with its parent, its
offset in the parent's frame and up to three hinge joints applied in order (intrinsic,
about axes in the body's own frame, MuJoCo's convention); points are (body, offset).
``cache=True`` keeps the machine code in ``__pycache__``; :func:`warm_up` compiles (or
loads) it before a loop starts. numpy's error model: a NaN or infinite angle gives NaN
joints, never an exception on the loop's thread.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, error_model="numpy")
def _mat_to_quat(m: Any, out: Any) -> None:  # pragma: no cover - compiled
    """A rotation matrix -> unit quaternion (x, y, z, w) into ``out``, w >= 0 (Shepperd's
    method: the largest of the four squared components is the pivot)."""
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0.0:
        s = math.sqrt(tr + 1.0) * 2.0
        w, x, y, z = 0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, \
            (m[1, 0] - m[0, 1]) / s
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2]) * 2.0
        w, x, y, z = (m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, \
            (m[0, 2] + m[2, 0]) / s
    elif m[1, 1] > m[2, 2]:
        s = math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2]) * 2.0
        w, x, y, z = (m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, \
            (m[1, 2] + m[2, 1]) / s
    else:
        s = math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1]) * 2.0
        w, x, y, z = (m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, \
            (m[1, 2] + m[2, 1]) / s, 0.25 * s
    n = math.sqrt(w * w + x * x + y * y + z * z)
    if w < 0.0:
        n = -n
    out[0] = x / n
    out[1] = y / n
    out[2] = z / n
    out[3] = w / n


@njit(cache=True, nogil=True, error_model="numpy")
def chain_poses(angles_rad: Any, axes: Any, parent: Any, offset: Any, joints: Any,
                root_rot: Any, root_pos: Any, point_body: Any, point_local: Any,
                frame: Any, rot: Any, pos: Any, hinge: Any, tmp: Any, out: Any
                ) -> None:  # pragma: no cover - compiled
    """Pose every body, then every point, into ``out`` (points, 7): position, then the
    body's orientation times ``frame`` as a quaternion (x, y, z, w).

    ``angles_rad`` (J,) and ``axes`` (J, 3) unit: the hinges; ``parent`` (B,) (-1: the
    root), ``offset`` (B, 3), ``joints`` (B, 3) hinge indices (-1: none); ``root_rot``
    (3, 3) and ``root_pos`` (3,): the root's frame in the output space; ``point_body``
    (P,), ``point_local`` (P, 3); ``frame`` (3, 3): each point's frame in its body's.
    ``rot`` (B, 3, 3), ``pos`` (B, 3), ``hinge`` and ``tmp`` (3, 3): scratch.
    """
    for b in range(parent.shape[0]):
        p = parent[b]
        for i in range(3):
            acc = 0.0
            for k in range(3):
                pr = root_rot[i, k] if p < 0 else rot[p, i, k]
                acc += pr * offset[b, k]
                rot[b, i, k] = pr
            pos[b, i] = (root_pos[i] if p < 0 else pos[p, i]) + acc
        for slot in range(3):
            j = joints[b, slot]
            if j < 0:
                continue
            # Rodrigues: R = I + sin(a) K + (1 - cos(a)) K^2, K the axis' cross matrix
            ax, ay, az = axes[j, 0], axes[j, 1], axes[j, 2]
            s, c = math.sin(angles_rad[j]), math.cos(angles_rad[j])
            t = 1.0 - c
            hinge[0, 0] = c + t * ax * ax
            hinge[0, 1] = t * ax * ay - s * az
            hinge[0, 2] = t * ax * az + s * ay
            hinge[1, 0] = t * ax * ay + s * az
            hinge[1, 1] = c + t * ay * ay
            hinge[1, 2] = t * ay * az - s * ax
            hinge[2, 0] = t * ax * az - s * ay
            hinge[2, 1] = t * ay * az + s * ax
            hinge[2, 2] = c + t * az * az
            for i in range(3):
                for k in range(3):
                    tmp[i, k] = (rot[b, i, 0] * hinge[0, k] + rot[b, i, 1] * hinge[1, k]
                                 + rot[b, i, 2] * hinge[2, k])
            for i in range(3):
                for k in range(3):
                    rot[b, i, k] = tmp[i, k]
    for q in range(point_body.shape[0]):
        b = point_body[q]
        for i in range(3):
            out[q, i] = pos[b, i] + (rot[b, i, 0] * point_local[q, 0]
                                     + rot[b, i, 1] * point_local[q, 1]
                                     + rot[b, i, 2] * point_local[q, 2])
            for k in range(3):
                tmp[i, k] = (rot[b, i, 0] * frame[0, k] + rot[b, i, 1] * frame[1, k]
                             + rot[b, i, 2] * frame[2, k])
        _mat_to_quat(tmp, out[q, 3:])


def warm_up() -> None:
    """Compile (or load from the cache) the kernel with the types the hand uses."""
    z = np.zeros(1)
    chain_poses(z, np.array([[0.0, 0.0, 1.0]]), np.array([-1], np.intp), np.zeros((1, 3)),
                np.array([[0, -1, -1]], np.intp), np.eye(3), np.zeros(3),
                np.zeros(1, np.intp), np.zeros((1, 3)), np.eye(3), np.zeros((1, 3, 3)),
                np.zeros((1, 3)), np.zeros((3, 3)), np.zeros((3, 3)), np.zeros((1, 7)))
