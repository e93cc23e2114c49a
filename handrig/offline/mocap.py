"""Motion capture to the 50 paper curves: joint-mapping profiles, glitches, resampling.

A **profile** (``config/profiles/<name>.toml``) says which BVH joint and channel holds
each of the 25 curves per hand of Jörg & O'Sullivan, and how a raw channel angle
becomes a value in handrig's vocabulary convention (``vocabulary = sign * raw +
offset_deg``; see :mod:`handrig.hand`). ``convention="raw"`` gives the channel angle
unchanged, as the mocap README defines the curves (what the paper's analysis uses).

Real captures have glitches: NaN or absurd values and single-frame spikes of 100
degrees and more. :func:`find_glitches` reports them (curve, frame, value);
``despike=True`` repairs them by linear interpolation from the neighbouring good
frames; :meth:`MocapCurves.require_clean` refuses unrepaired data for learning.

A profile's ``[calibration]`` table holds the per-curve offsets of a capture's
calibration (found by :func:`handrig.offline.conditioning.find_offsets`, with how and on
which capture); vocabulary curves are loaded with them added (``condition=False`` to see
the capture as it is). Raw curves never get them.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from handrig import hand
from handrig.config.loading import CONFIG_DIR, load
from handrig.errors import ConfigError, DataError
from handrig.offline.bvh import Bvh, read_bvh

Convention = Literal["vocabulary", "raw"]
PROFILE_DIR = CONFIG_DIR / "profiles"
REPO_DATA_DIR = CONFIG_DIR.parent / "data" / "mocap"
REFERENCE_BVH = REPO_DATA_DIR / "pn_gestures_reference.bvh"
"""The shipped reference capture (Perception Neuron, LGPL-2.1, see data/mocap/README.md)."""

REFERENCE_CLIPS: tuple[tuple[str, int, int], ...] = (
    ("bigger", 0, 78), ("inclusivity", 79, 151), ("me", 152, 239), ("me2", 240, 313),
    ("negation", 314, 381), ("point_centre", 382, 439), ("point_here", 440, 503),
    ("point_left", 504, 592), ("point_right", 593, 655), ("question", 656, 725),
    ("stop", 726, 783), ("us", 784, 844), ("we", 845, 923), ("you", 924, 989),
    ("you2", 990, 1062),
)
"""Clip frame ranges of the reference file (0-based, inclusive), from its README."""

REFERENCE_KINDS: dict[str, str] = {
    "point_centre": "pointing", "point_here": "pointing", "point_left": "pointing",
    "point_right": "pointing", "you": "pointing", "you2": "pointing",
    "me": "self", "me2": "self", "us": "self", "we": "self",
    "bigger": "shaping", "inclusivity": "shaping", "negation": "shaping",
    "question": "shaping", "stop": "shaping",
}
"""Kind of gesture of each reference clip: pointing at a place or the listener, pointing
at oneself or one's group, and shaping an idea (size, negation, a question, stop)."""


def reference_clip_labels() -> NDArray[np.intp]:
    """Per frame of the reference file, the index of its clip in :data:`REFERENCE_CLIPS`."""
    labels = np.zeros(REFERENCE_CLIPS[-1][2] + 1, dtype=np.intp)
    for i, (_, a, b) in enumerate(REFERENCE_CLIPS):
        labels[a:b + 1] = i
    return labels

SPIKE_DEG = 45.0
"""A frame that jumps this far from both neighbours, the same way, is a single-frame spike."""
ABSURD_DEG = 360.0
"""A joint angle beyond +-360 degrees is not a joint angle."""

_SIDES = ("ri", "le")
MAX_OFFSET_DEG = 90.0
"""A calibration offset beyond this is refused: it would be a convention error."""


@dataclass(frozen=True)
class CurveSource:
    """Where one curve comes from: BVH joint and channel; raw -> vocabulary sign and offset.

    ``sign`` and ``offset_deg`` are a number or a table ``{ri = .., le = ..}``.
    In a ``[template]`` entry ``joint`` may contain ``{side}`` (replaced by the side name).
    """

    joint: str
    channel: Literal["Xrotation", "Yrotation", "Zrotation"]
    sign: float | dict[str, float] = 1.0
    offset_deg: float | dict[str, float] = 0.0

    def check(self) -> None:
        for key in ("sign", "offset_deg"):
            val = getattr(self, key)
            if isinstance(val, dict):
                bad = sorted(set(val) - set(_SIDES))
                if bad or set(val) != set(_SIDES):
                    raise ConfigError(
                        "a per-hand table needs exactly the keys ri and le", key=key, value=val
                    )
        for s in self._values("sign"):
            if s not in (1.0, -1.0):
                raise ConfigError("sign must be 1 or -1", key="sign", value=s)

    def _values(self, key: str) -> list[float]:
        val = getattr(self, key)
        return list(val.values()) if isinstance(val, dict) else [float(val)]

    def for_side(self, side: str, key: str) -> float:
        val = getattr(self, key)
        return float(val[side]) if isinstance(val, dict) else float(val)


@dataclass(frozen=True)
class Calibration:
    """Per-curve offsets (deg, vocabulary convention) of a capture's calibration, added to
    the vocabulary curves on load; ``found_on`` and ``how`` say where they come from."""

    offsets_deg: dict[str, float] = field(default_factory=dict)
    found_on: str = ""
    how: str = ""

    def check(self) -> None:
        for name, v in self.offsets_deg.items():
            if name not in hand.CURVE_NAMES:
                raise ConfigError("unknown curve", key=f"calibration.offsets_deg.{name}",
                                  allowed="a curve name, e.g. riIndexPIPy")
            if not np.isfinite(v) or abs(v) > MAX_OFFSET_DEG:
                raise ConfigError(
                    "not a calibration offset", key=f"calibration.offsets_deg.{name}",
                    value=v, allowed=f"a finite offset within +-{MAX_OFFSET_DEG:g} deg")
        if self.offsets_deg and not self.how:
            raise ConfigError("offsets need a note of how they were found",
                              key="calibration.how")

    def vector(self) -> NDArray[np.float64]:
        """The offsets as a (50,) array in canonical curve order (0 where none)."""
        return np.array([self.offsets_deg.get(n, 0.0) for n in hand.CURVE_NAMES],
                        dtype=np.float64)


@dataclass(frozen=True)
class Profile:
    """A joint-mapping profile: BVH skeleton -> the 50 curves (see the module docstring)."""

    name: str
    description: str = ""
    prefix: str = ""
    sides: dict[str, str] = field(default_factory=lambda: {"ri": "Right", "le": "Left"})
    template: dict[str, CurveSource] = field(default_factory=dict)
    curves: dict[str, CurveSource] = field(default_factory=dict)
    calibration: Calibration = field(default_factory=Calibration)
    source: str = "<profile>"

    def check(self) -> None:
        if set(self.sides) != set(_SIDES):
            raise ConfigError("sides needs exactly ri and le", key="sides", value=self.sides)
        per_hand = {n[2:] for n in hand.CURVE_NAMES}
        for key in self.template:
            if key not in per_hand:
                raise ConfigError(
                    "unknown per-hand curve", key=f"template.{key}",
                    allowed="curve names without ri/le, e.g. IndexMCPy",
                )
        for key in self.curves:
            if key not in hand.CURVE_NAMES:
                raise ConfigError(
                    "unknown curve", key=f"curves.{key}", allowed="e.g. riIndexMCPy"
                )
        missing = [n for n in hand.CURVE_NAMES if n not in self.curves and n[2:] not in
                   self.template]
        if missing:
            raise ConfigError(
                f"no mapping for {len(missing)} curve(s), first {missing[0]!r}",
                key="template", allowed="an entry for every curve in [template] or [curves]",
            )

    def resolve(self) -> list[tuple[str, str, float, float]]:
        """For each curve in canonical order: (joint, channel, sign, offset_deg)."""
        out: list[tuple[str, str, float, float]] = []
        for name in hand.CURVE_NAMES:
            side = name[:2]
            src = self.curves.get(name) or self.template[name[2:]]
            joint = self.prefix + src.joint.replace("{side}", self.sides[side])
            out.append((joint, src.channel, src.for_side(side, "sign"),
                        src.for_side(side, "offset_deg")))
        return out


def profile_names() -> tuple[str, ...]:
    """Names of the shipped profiles (``config/profiles/*.toml``)."""
    return tuple(sorted(p.stem for p in PROFILE_DIR.glob("*.toml")))


def load_profile(name_or_path: str | Path = "perception_neuron") -> Profile:
    """Load a profile by shipped name (``perception_neuron``, ``common``) or TOML path."""
    p = Path(name_or_path)
    if p.suffix != ".toml":
        p = PROFILE_DIR / f"{name_or_path}.toml"
        if not p.exists():
            raise ConfigError(
                f"no profile {str(name_or_path)!r}", file=str(p),
                allowed=", ".join(profile_names()) + " or a path to a .toml profile",
            )
    prof = load(p, Profile)
    return replace(prof, source=str(p))


@dataclass(frozen=True)
class Glitch:
    """One bad sample: ``kind`` is ``nan`` (NaN/inf), ``absurd`` (beyond +-360) or ``spike``."""

    curve: str
    frame: int
    value: float
    kind: str

    def __str__(self) -> str:
        return f"{self.curve} frame {self.frame}: {self.value:.1f} deg ({self.kind})"


@dataclass(frozen=True)
class MocapCurves:
    """The 50 curves of a capture: ``curves`` (frames x 50, degrees) in ``convention``.

    ``glitches`` lists what was found in the file (raw values, frame numbers of the file);
    ``repaired`` says whether they were interpolated away (``despike=True``).
    """

    curves: NDArray[np.float64]
    fps: float
    convention: Convention
    profile: str
    source: str
    glitches: tuple[Glitch, ...] = ()
    repaired: bool = False
    names: tuple[str, ...] = hand.CURVE_NAMES
    offsets_deg: NDArray[np.float64] | None = field(default=None, compare=False)
    """The calibration offsets added on load (:class:`Calibration`), None when none were."""

    @property
    def n_frames(self) -> int:
        return int(self.curves.shape[0])

    def require_clean(self, what: str = "learning") -> None:
        """Raise DataError if unrepaired glitches remain (never learn from them silently)."""
        if self.glitches and not self.repaired:
            shown = "; ".join(str(g) for g in self.glitches[:5])
            more = f" and {len(self.glitches) - 5} more" if len(self.glitches) > 5 else ""
            raise DataError(
                f"{self.source}: {len(self.glitches)} glitch(es) found: {shown}{more}."
                f" Refusing to use them for {what}; pass --despike to repair them by"
                " interpolating from neighbouring frames"
            )

    def frames(self, start: int, stop: int) -> MocapCurves:
        """Frames ``start`` .. ``stop - 1`` (same fps)."""
        return replace(self, curves=self.curves[start:stop])


def find_glitches(
    raw: NDArray[np.float64], *, spike_deg: float = SPIKE_DEG, absurd_deg: float = ABSURD_DEG,
    max_run: int = 3,
) -> list[Glitch]:
    """NaN/inf, absurd values and short spikes in ``raw`` (frames x 50) curves.

    A spike is a frame that differs from both neighbours by at least ``spike_deg`` in
    the same direction (first and last frames are checked against their one neighbour
    and the next one: they spike if they jump ``spike_deg`` while the next step is small),
    or a run of up to ``max_run`` frames that jumps away by at least ``spike_deg`` and
    comes back to within ``spike_deg / 2`` of where it left.
    """
    out: list[Glitch] = []
    bad = ~np.isfinite(raw)
    for f, c in zip(*np.nonzero(bad), strict=True):
        out.append(Glitch(hand.CURVE_NAMES[c], int(f), float(raw[f, c]), "nan"))
    with np.errstate(invalid="ignore"):
        absurd = np.isfinite(raw) & (np.abs(raw) > absurd_deg)
    for f, c in zip(*np.nonzero(absurd), strict=True):
        out.append(Glitch(hand.CURVE_NAMES[c], int(f), float(raw[f, c]), "absurd"))
    flagged = bad | absurd
    if raw.shape[0] >= 3:
        x = np.where(flagged, np.nan, raw)
        with np.errstate(invalid="ignore"):
            up = x[1:-1] - x[:-2]
            down = x[1:-1] - x[2:]
            mid = (np.abs(up) >= spike_deg) & (np.abs(down) >= spike_deg) & (up * down > 0)
            first = (np.abs(x[0] - x[1]) >= spike_deg) & (np.abs(x[1] - x[2]) < spike_deg / 4)
            last = (np.abs(x[-1] - x[-2]) >= spike_deg) & (
                np.abs(x[-2] - x[-3]) < spike_deg / 4
            )
        spikes = np.zeros_like(flagged)
        spikes[1:-1] = mid
        spikes[0] = first
        spikes[-1] = last
        _mark_runs(x, spikes, spike_deg, max_run)
        for f, c in zip(*np.nonzero(spikes), strict=True):
            out.append(Glitch(hand.CURVE_NAMES[c], int(f), float(raw[f, c]), "spike"))
    out.sort(key=lambda g: (g.frame, hand.curve_index(g.curve)))
    return out


def _mark_runs(x: NDArray[np.float64], spikes: NDArray[np.bool_], spike_deg: float,
               max_run: int) -> None:
    """Mark runs of 2..max_run frames that leave by a jump and come back (see find_glitches)."""
    with np.errstate(invalid="ignore"):
        jumps = np.abs(np.diff(x, axis=0)) >= spike_deg
    n = x.shape[0]
    for i, c in zip(*np.nonzero(jumps), strict=True):  # jump between frames i and i + 1
        before = x[i, c]
        for end in range(i + 2, min(i + 1 + max_run, n - 1) + 1):  # run = i+1 .. end-1
            if abs(x[end, c] - before) < spike_deg / 2 and np.all(
                np.abs(x[i + 1:end, c] - before) >= spike_deg
            ):
                spikes[i + 1:end, c] = True
                break


def repair(raw: NDArray[np.float64], glitches: list[Glitch]) -> NDArray[np.float64]:
    """Replace every glitch by linear interpolation between the nearest good frames."""
    out = raw.copy()
    if not glitches:
        return out
    mask = np.zeros(raw.shape, dtype=bool)
    for g in glitches:
        mask[g.frame, hand.curve_index(g.curve)] = True
    frames = np.arange(raw.shape[0], dtype=np.float64)
    for c in np.nonzero(mask.any(axis=0))[0]:
        good = ~mask[:, c]
        if not good.any():
            raise DataError(f"{hand.CURVE_NAMES[c]}: every frame is a glitch; cannot repair")
        out[~good, c] = np.interp(frames[~good], frames[good], raw[good, c])
    return out


def resample(curves: NDArray[np.float64], fps_in: float, fps_out: float) -> NDArray[np.float64]:
    """Linear resampling of (frames x k) ``curves`` from ``fps_in`` to ``fps_out``.

    The first frame is kept; the new frames cover the same duration (the paper used 30 fps).
    """
    if not fps_out > 0:
        raise DataError(f"frame rate must be positive, got {fps_out}")
    n = curves.shape[0]
    if n < 2 or fps_in == fps_out:
        return curves.copy()
    duration_s = (n - 1) / fps_in
    t_new = np.arange(0.0, duration_s + 1e-9, 1.0 / fps_out)
    pos = t_new * fps_in
    i0 = np.minimum(np.floor(pos).astype(np.intp), n - 2)
    w = (pos - i0)[:, None]
    out: NDArray[np.float64] = curves[i0] * (1.0 - w) + curves[i0 + 1] * w
    return out


def extract_raw(bvh: Bvh, profile: Profile) -> NDArray[np.float64]:
    """The 50 curves (frames x 50) as raw channel angles; DataError names missing joints."""
    table = profile.resolve()
    names = set(bvh.joint_names)
    missing = list(dict.fromkeys(j for j, *_ in table if j not in names))  # curve order
    if missing:
        example = next(c for c, (j, *_) in zip(hand.CURVE_NAMES, table, strict=True)
                       if j == missing[0])
        raise DataError(
            f"{bvh.source}: joint {missing[0]!r} (curve {example}) not found; profile"
            f" {profile.name!r} ({profile.source}) needs it"
            + (f", and {len(missing) - 1} more missing: {', '.join(missing[1:4])}"
               if len(missing) > 1 else "")
            + f". Pick another --profile ({', '.join(profile_names())}) or write one"
        )
    cols = np.array([bvh.column(j, ch) for j, ch, _, _ in table], dtype=np.intp)
    return np.ascontiguousarray(bvh.motion[:, cols])


def to_vocabulary(raw: NDArray[np.float64], profile: Profile) -> NDArray[np.float64]:
    """Raw channel angles -> vocabulary convention (``sign * raw + offset_deg`` per curve)."""
    sign, offset = profile_affine(profile)
    out: NDArray[np.float64] = raw * sign + offset
    return out


def profile_affine(profile: Profile) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(sign, offset_deg), each shape (50,), of the raw -> vocabulary map of ``profile``."""
    table = profile.resolve()
    sign = np.array([s for _, _, s, _ in table], dtype=np.float64)
    offset = np.array([o for _, _, _, o in table], dtype=np.float64)
    return sign, offset


def load_curves(
    path: str | Path,
    profile: str | Path | Profile = "perception_neuron",
    convention: Convention = "vocabulary",
    fps: float | None = None,
    despike: bool = False,
    *,
    spike_deg: float = SPIKE_DEG,
    condition: bool = True,
) -> MocapCurves:
    """Read a BVH file into the 50 curves (degrees).

    ``convention``: ``"vocabulary"`` (handrig's signs, flexion positive) or ``"raw"``
    (the channel angles as the profile's table defines them). ``fps``: resample to this
    rate (None keeps the file's). ``despike``: interpolate glitches away (they are still
    listed in ``glitches``). Glitch frame numbers refer to the file's own frames.
    ``condition``: add the profile's calibration offsets to vocabulary curves (raw
    curves never get them).
    """
    prof = profile if isinstance(profile, Profile) else load_profile(profile)
    if convention not in ("vocabulary", "raw"):
        raise DataError(f"unknown convention {convention!r}; use 'vocabulary' or 'raw'")
    bvh = read_bvh(path)
    raw = extract_raw(bvh, prof)
    glitches = find_glitches(raw, spike_deg=spike_deg)
    if despike:
        raw = repair(raw, glitches)
    curves = to_vocabulary(raw, prof) if convention == "vocabulary" else raw
    offsets = None
    if convention == "vocabulary" and condition and prof.calibration.offsets_deg:
        offsets = prof.calibration.vector()
        curves = curves + offsets
    rate = bvh.fps
    if fps is not None:
        if glitches and not despike:
            # interpolating across NaN would smear it; keep frames as they are
            bad = [g for g in glitches if g.kind == "nan"]
            if bad:
                raise DataError(
                    f"{bvh.source}: cannot resample with NaN/inf values ({bad[0]});"
                    " pass --despike"
                )
        curves = resample(curves, bvh.fps, fps)
        rate = float(fps)
    return MocapCurves(
        curves=np.ascontiguousarray(curves, dtype=np.float64), fps=rate, convention=convention,
        profile=prof.name, source=str(path), glitches=tuple(glitches), repaired=despike,
        offsets_deg=offsets,
    )


def load_reference(convention: Convention = "vocabulary", *, condition: bool = True
                   ) -> MocapCurves:
    """The shipped reference capture at its own 24 fps (conditioned, see load_curves)."""
    return load_curves(REFERENCE_BVH, "perception_neuron", convention, condition=condition)
