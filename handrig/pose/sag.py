"""Passive sag at runtime: the baked relaxed-hand grid, looked up by forearm orientation.

The grid (``config/sag_grid.npz``, baked by ``handrig bake`` from the MuJoCo model
in ``sim/``) holds the 23 DOF values of the relaxed hand at each sampled forearm
orientation. :meth:`SagGrid.lookup` interpolates bilinearly on the stored actual
coordinates (Neff & Seidel, section 4.2); :meth:`SagGrid.offsets` returns values
minus the rest pose, which the realtime loop adds to the active pose. Pure numpy:
no MuJoCo here.

Coordinates (degrees): ``inclination`` -90 hanging straight down .. +90 pointing up;
``rotation`` about the forearm axis, **anatomical and the same for both hands**:
0 palm down, +90 palm vertical thumb up, 180 (= -180) palm up. Rotation wraps; at
inclination +-90 the grid rows do not depend on rotation, so the singularity needs
no special case. Because the convention is anatomical, the left hand uses the same
table: a mirrored forearm (left thumb up) has rotation +90 too, and
:class:`handrig.pose.orientation.ForearmOrientation` (``hand="le"``) is where the mirror
is taken into account (its rotation sign flips relative to the right-handed IMU
geometry). :meth:`SagGrid.for_hand` only renames the DOFs.

The shipped grid is step 2.5 deg, refined to 1 deg where the pose bends fastest
(palm up, forearm 0..45 deg up; the axes are rectilinear but not uniform, which
the lookup handles by bisection). The model has one stable equilibrium per
orientation (``sim/passive.py``, "Raised hand": the fully relaxed fingers of the
paper would buckle palm up with the forearm raised, so the gains rise above the
horizontal); ``python -m bench sag`` prints how closely lookups agree with a direct
solve over random orientations of the whole sphere (``docs/measurements.md``).
"""

from __future__ import annotations

import bisect
import json
import math
import zipfile
import zlib
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from handrig.config.bounded import check_size, excerpt
from handrig.config.loading import CONFIG_DIR
from handrig.errors import DataError
from handrig.hand import DOF_NAMES, Hand, dof_limits_deg

SAG_GRID = CONFIG_DIR / "sag_grid.npz"
MAX_GRID_BYTES = 256 << 20
"""A baked grid is about 2.6 MB unpacked (a finer bake: tens of MB); a file or its
arrays over this are refused."""
_AXIS_TOL_DEG = 1e-6
_POLE_TOL_DEG = 1e-3
_LIMIT_TOL_DEG = 1.0  # slack for the solver's equilibria at a joint's end stop


def default_grid_path() -> Path:
    """The grid read by default: the user's baked ``sag_grid.npz``
    (:func:`handrig.config.paths.user_data`, where ``handrig bake`` writes) when there is one,
    else the installed ``config/sag_grid.npz``."""
    from handrig.config.paths import user_data

    mine = user_data(SAG_GRID.name)
    return mine if mine.is_file() else SAG_GRID


@dataclass(frozen=True)
class SagTables:
    """A grid's lookup tables in the layout the compiled servo step reads
    (``handrig.pose.kernels.servo_targets``). Read-only; shared, never copied.

    ``inclination_axis_deg`` (n_inc,); ``rotation_axis_deg`` (n_rot + 1,): the
    rotation samples with the first repeated one turn up (rotation wraps);
    ``rotation0_deg``: the first rotation sample; ``cell_offsets_deg``
    (n_inc - 1, n_rot, 4, 23): for each cell its four corners' sag offsets (values
    minus the rest pose), corners ordered (i, j), (i, j + 1), (i + 1, j), (i + 1, j + 1).
    """

    inclination_axis_deg: NDArray[np.float64]
    rotation_axis_deg: NDArray[np.float64]
    rotation0_deg: float
    cell_offsets_deg: NDArray[np.float64]

    @classmethod
    def empty(cls, n_dofs: int = 23) -> SagTables:
        """Tables that add no sag (no cells)."""
        return cls(np.array([-90.0, 90.0]), np.array([0.0, 360.0]), 0.0,
                   np.zeros((0, 1, 4, n_dofs)))


class SagGrid:
    """A baked sag grid ready for allocation-free lookups.

    Attributes: ``hand``; ``dof_names`` (23 names of ``hand``, vocabulary order);
    ``rest_deg`` (23,); ``limits_deg`` (23, 2); ``inclination_axis_deg`` (n_inc,);
    ``rotation_axis_deg`` (n_rot,); ``metadata`` (dict); ``source`` (path or "").
    """

    def __init__(
        self,
        inclination_deg: NDArray[np.float64],
        rotation_deg: NDArray[np.float64],
        dofs_deg: NDArray[np.float64],
        rest_deg: NDArray[np.float64],
        *,
        limits_deg: NDArray[np.float64] | None = None,
        metadata: dict[str, Any] | None = None,
        hand: Hand = "ri",
        source: str = "",
    ) -> None:
        where = source or "<sag grid>"
        inc = np.asarray(inclination_deg, dtype=np.float64)
        rot = np.asarray(rotation_deg, dtype=np.float64)
        vals = np.asarray(dofs_deg, dtype=np.float64)
        if inc.ndim != 2 or inc.shape != rot.shape or vals.shape != (*inc.shape, 23):
            raise DataError(
                f"{where}: expected inclination/rotation (n_inc, n_rot) and dofs (n_inc, n_rot,"
                f" 23), got {inc.shape}, {rot.shape}, {vals.shape}; re-run `handrig bake`")
        n_inc, n_rot = inc.shape
        if n_inc < 2 or n_rot < 2:
            raise DataError(f"{where}: a grid needs at least 2 x 2 samples, got {inc.shape}")
        for name, arr in (("inclination_deg", inc), ("rotation_deg", rot), ("dofs_deg", vals)):
            if not np.all(np.isfinite(arr)):
                raise DataError(f"{where}: {name} holds NaN or infinite values")
        inc_axis, rot_axis = inc[:, 0], rot[0, :]
        # Bilinear interpolation on the actual coordinates needs them rectilinear.
        if (np.max(np.abs(inc - inc_axis[:, None])) > _AXIS_TOL_DEG
                or np.max(np.abs(rot - rot_axis[None, :])) > _AXIS_TOL_DEG):
            raise DataError(f"{where}: sample coordinates are not on a rectilinear grid")
        if np.any(np.diff(inc_axis) <= 0) or np.any(np.diff(rot_axis) <= 0):
            raise DataError(f"{where}: grid axes must increase strictly")
        if abs(inc_axis[0] + 90.0) > _AXIS_TOL_DEG or abs(inc_axis[-1] - 90.0) > _AXIS_TOL_DEG:
            raise DataError(f"{where}: inclination must span -90..90, got"
                            f" {inc_axis[0]:g}..{inc_axis[-1]:g}")
        if rot_axis[-1] - rot_axis[0] >= 360.0:
            raise DataError(f"{where}: rotation samples must lie within one turn")
        for row in (0, n_inc - 1):
            if np.max(np.abs(vals[row] - vals[row, :1])) > _POLE_TOL_DEG:
                raise DataError(f"{where}: the row at inclination {inc_axis[row]:g} must not"
                                " depend on rotation (gravity along the forearm)")
        rest = np.asarray(rest_deg, dtype=np.float64)
        if rest.shape != (23,):
            raise DataError(f"{where}: rest_deg must have 23 values, got {rest.shape}")
        self.hand: Hand = hand
        self.dof_names: Sequence[str] = DOF_NAMES[hand]  # a tuple
        self.rest_deg = rest
        self.limits_deg = (np.asarray(limits_deg, dtype=np.float64) if limits_deg is not None
                           else dof_limits_deg(hand))
        self.metadata = dict(metadata or {})
        self.source = source
        self.inclination_axis_deg = inc_axis.copy()
        self.rotation_axis_deg = rot_axis.copy()
        self.dofs_deg = vals
        # Python lists: bisect on them is faster than numpy for one query.
        self._inc = [float(x) for x in inc_axis]
        self._rot = [float(x) for x in rot_axis] + [float(rot_axis[0]) + 360.0]
        self._rot0 = float(rot_axis[0])
        self._inc_arr = np.array(self._inc)  # the same axes, for kernel_tables()
        self._rot_arr = np.array(self._rot)
        # Cell tables: for cell (i, j) the 4 corner vectors, contiguous, rotation wrapped.
        wrapped = np.concatenate([vals, vals[:, :1]], axis=1)
        cells = np.stack([wrapped[:-1, :-1], wrapped[:-1, 1:], wrapped[1:, :-1],
                          wrapped[1:, 1:]], axis=2)
        self._cells = np.ascontiguousarray(cells)
        self._cells_off = np.ascontiguousarray(cells - rest)
        self._tables = SagTables(self._inc_arr, self._rot_arr, self._rot0, self._cells_off)
        self._w = np.zeros(4)

    # -- construction

    @classmethod
    def load(cls, path: str | Path | None = None, *, hand: Hand = "ri") -> SagGrid:
        """Load a baked grid (default :func:`default_grid_path`)."""
        p = Path(path) if path is not None else default_grid_path()
        fix = f"re-bake it with `handrig bake --out {p}` or restore the shipped file"
        try:
            if p.is_file():
                check_size(p, MAX_GRID_BYTES, "a .npz sag grid")
            with zipfile.ZipFile(p) as archive:  # what the arrays take once unpacked
                unpacked = sum(i.file_size for i in archive.infolist())
            if unpacked > MAX_GRID_BYTES:
                raise DataError(f"{p}: its arrays take {unpacked / 1e6:.0f} MB unpacked, and"
                                f" a sag grid at most {MAX_GRID_BYTES / 1e6:.0f} MB; {fix}")
            with np.load(p, allow_pickle=False) as z:
                data = {k: z[k] for k in z.files}
        except FileNotFoundError:
            raise DataError(f"{p}: sag grid not found; bake one with `handrig bake --out {p}`"
                            ) from None
        except IsADirectoryError:
            raise DataError(f"{p}: is a folder, not a .npz sag grid") from None
        except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error,
                NotImplementedError, KeyError, TypeError) as exc:
            # a cut file (EOFError, BadZipFile), flipped bits (zlib.error, a CRC-32 check
            # in zipfile), an array header numpy cannot parse (ValueError)
            raise DataError(f"{p}: not a readable .npz sag grid, the file is damaged"
                            f" ({type(exc).__name__}: {excerpt(str(exc), 80)}); {fix}"
                            ) from None
        missing = [k for k in ("inclination_deg", "rotation_deg", "dofs_deg", "rest_deg",
                               "dof_names") if k not in data]
        if missing:
            raise DataError(f"{p}: missing arrays {missing}; re-run `handrig bake`")
        for k, arr in data.items():
            if k not in ("dof_names", "metadata") and arr.dtype.kind not in "fiu":
                raise DataError(f"{p}: array {k!r} holds {arr.dtype}, not numbers; {fix}")
        names = tuple(str(n) for n in np.ravel(data["dof_names"]))
        if names != DOF_NAMES["ri"]:
            raise DataError(f"{p}: dof_names differ from the vocabulary's 23 ri DOFs")
        meta: dict[str, Any] = {}
        if "metadata" in data:
            try:
                meta = json.loads(str(data["metadata"]))
            except json.JSONDecodeError as exc:
                raise DataError(f"{p}: metadata is not JSON ({exc})") from None
            if not isinstance(meta, dict):
                raise DataError(f"{p}: metadata is not a JSON object")
        limits = data.get("limits_deg")
        if limits is not None and limits.shape != (23, 2):
            raise DataError(f"{p}: limits_deg has shape {limits.shape}, expected (23, 2); {fix}")
        grid = cls(data["inclination_deg"], data["rotation_deg"], data["dofs_deg"],
                   data["rest_deg"], limits_deg=limits, metadata=meta,
                   hand="ri", source=str(p))
        grid._check_plausible(fix)
        return grid if hand == "ri" else grid.for_hand(hand)

    def _check_plausible(self, fix: str) -> None:
        """Refuse a grid whose limits exceed the anatomical ones, or whose poses or rest
        pose lie outside its limits (a grid in the wrong unit or scaled)."""
        where = self.source or "<sag grid>"
        anatomical = dof_limits_deg("ri")
        lim = self.limits_deg
        if not np.all(np.isfinite(lim)) or np.any(lim[:, 0] >= lim[:, 1]):
            raise DataError(f"{where}: limits_deg must be finite with low < high; {fix}")
        wide = np.flatnonzero((lim[:, 0] < anatomical[:, 0] - _LIMIT_TOL_DEG)
                              | (lim[:, 1] > anatomical[:, 1] + _LIMIT_TOL_DEG))
        if wide.size:
            i = int(wide[0])
            raise DataError(
                f"{where}: limits of {DOF_NAMES['ri'][i]} are {lim[i, 0]:g}..{lim[i, 1]:g} deg,"
                f" beyond the anatomical {anatomical[i, 0]:g}..{anatomical[i, 1]:g}; {fix}")
        for what, values in (("rest_deg", self.rest_deg[None, :]),
                             ("dofs_deg", self.dofs_deg.reshape(-1, 23))):
            below = values < lim[:, 0] - _LIMIT_TOL_DEG
            above = values > lim[:, 1] + _LIMIT_TOL_DEG
            bad = np.argwhere(below | above)
            if bad.size:
                k, i = (int(v) for v in bad[0])
                raise DataError(
                    f"{where}: {what} puts {DOF_NAMES['ri'][i]} at {values[k, i]:g} deg,"
                    f" outside its limits {lim[i, 0]:g}..{lim[i, 1]:g}"
                    f" ({int(np.count_nonzero(below | above))} values outside): not a sag"
                    f" grid in degrees (scaled, or another unit); {fix}")

    def for_hand(self, hand: Hand) -> SagGrid:
        """The same grid for ``hand`` (shared tables; DOF names of that hand). Rotation is
        anatomical, so the values are the same (see the module docstring)."""
        if hand not in ("ri", "le"):
            raise ValueError(f"hand must be 'ri' or 'le', got {hand!r}")
        other = object.__new__(SagGrid)
        other.__dict__.update(self.__dict__)
        other.hand = hand
        other.dof_names = DOF_NAMES[hand]
        other._w = np.zeros(4)
        return other

    # -- lookups

    def lookup(self, inclination_deg: float, rotation_deg: float,
               out: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
        """The 23 DOF values (degrees, vocabulary convention) at this forearm orientation.
        Allocation-free when ``out`` (23,) float64 is given."""
        return self._interp(self._cells, inclination_deg, rotation_deg, out)

    def offsets(self, inclination_deg: float, rotation_deg: float,
                out: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
        """Sag offsets = :meth:`lookup` minus ``rest_deg`` (23,), degrees."""
        return self._interp(self._cells_off, inclination_deg, rotation_deg, out)

    def kernel_tables(self) -> SagTables:
        """The lookup tables for the compiled servo step (shared with this grid)."""
        return self._tables

    @staticmethod
    def checked_inclination(inc: float, rot: float) -> float:
        """``inc`` clamped to -90..90 (rounding slack); DataError for NaN, a value
        outside, or a non-finite rotation."""
        if not (-90.0 <= inc <= 90.0):
            if inc != inc:
                raise DataError("sag lookup: inclination is NaN")
            if abs(inc) > 90.0 + 1e-6:
                raise DataError(f"sag lookup: inclination {inc} deg outside -90..90")
            inc = 90.0 if inc > 0 else -90.0
        if not math.isfinite(rot):
            raise DataError(f"sag lookup: rotation {rot} is not finite")
        return inc

    def _interp(self, cells: NDArray[np.float64], inc: float, rot: float,
                out: NDArray[np.float64] | None) -> NDArray[np.float64]:
        inc = self.checked_inclination(inc, rot)
        incs, rots = self._inc, self._rot
        i = bisect.bisect_right(incs, inc) - 1
        if i > len(incs) - 2:
            i = len(incs) - 2
        r = (rot - self._rot0) % 360.0 + self._rot0
        j = bisect.bisect_right(rots, r) - 1
        if j > len(rots) - 2:
            j = len(rots) - 2
        ti = (inc - incs[i]) / (incs[i + 1] - incs[i])
        tj = (r - rots[j]) / (rots[j + 1] - rots[j])
        w = self._w
        w[0] = (1.0 - ti) * (1.0 - tj)
        w[1] = (1.0 - ti) * tj
        w[2] = ti * (1.0 - tj)
        w[3] = ti * tj
        if out is None:
            return np.dot(w, cells[i, j])
        return np.dot(w, cells[i, j], out=out)

    def lookup_many(self, inclination_deg: NDArray[np.float64],
                    rotation_deg: NDArray[np.float64]) -> NDArray[np.float64]:
        """Vectorised :meth:`lookup` for plots and tests: (n,) and (n,) -> (n, 23)."""
        incs = np.atleast_1d(np.asarray(inclination_deg, dtype=np.float64))
        rots = np.atleast_1d(np.asarray(rotation_deg, dtype=np.float64))
        res = np.empty((len(incs), 23))
        for k, (a, b) in enumerate(zip(incs, rots, strict=True)):
            self.lookup(float(a), float(b), out=res[k])
        return res
