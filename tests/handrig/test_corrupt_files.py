"""Every loader turns a damaged file into a HandrigError naming the file, never a traceback.

Each shipped file (or a small recording made here) is cut at many points, has bits
flipped at random places and values of the wrong type put in; each variant is either
read (a flip in a comment or a digit can leave a valid file) or refused with a
message that names the file.
"""

from __future__ import annotations

import io
import random
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from handrig.config.loading import CONFIG_DIR, load_joint_limits
from handrig.config.rig import load_rig_config
from handrig.devices.glove_calibration import load_glove_config
from handrig.devices.glove_recording import read_glove_recording
from handrig.errors import HandrigError
from handrig.offline.bvh import read_bvh
from handrig.outputs.recorder import Recorder, load_performance
from handrig.pose.sag import SagGrid

MUTATIONS = 40  # of each kind per file


def _take(tmp: Path, suffix: str) -> bytes:
    path = tmp / f"src{suffix}"
    rng = np.random.default_rng(0)
    with Recorder(path, rate_hz=100.0) as rec:
        for i in range(6):
            rec.add(i / 100.0, rng.uniform(-5, 40, 50), rng.uniform(-10, 10, 4))
    return path.read_bytes()


def _glove_recording(tmp: Path) -> bytes:
    lines = (CONFIG_DIR / "recordings" / "demo_glove.csv").read_bytes().splitlines()[:40]
    return b"\n".join(lines) + b"\n"


LOADERS: dict[str, tuple[str, Callable[[Path], object], Callable[[Path], bytes]]] = {
    "rig": (".toml", load_rig_config, lambda t: (CONFIG_DIR / "rig.toml").read_bytes()),
    "glove": (".toml", load_glove_config, lambda t: (CONFIG_DIR / "glove.toml").read_bytes()),
    "opengloves": (".toml", load_glove_config,
                   lambda t: (CONFIG_DIR / "glove_opengloves.toml").read_bytes()),
    "joint_limits": (".toml", load_joint_limits,
                     lambda t: (CONFIG_DIR / "joint_limits.toml").read_bytes()),
    "glove_recording": (".csv", read_glove_recording, _glove_recording),
    "bvh_reader": (".bvh", read_bvh, lambda t: _take(t, ".bvh")),
    "performance_bvh": (".bvh", load_performance, lambda t: _take(t, ".bvh")),
    "performance_csv": (".csv", load_performance, lambda t: _take(t, ".csv")),
    "sag_grid": (".npz", SagGrid.load, lambda t: (CONFIG_DIR / "sag_grid.npz").read_bytes()),
}


def _refused_or_read(loader: Callable[[Path], object], path: Path, data: bytes) -> bool:
    path.write_bytes(data)
    try:
        loader(path)
    except HandrigError as exc:
        assert path.name in str(exc), f"message does not name the file: {exc}"
        return False
    return True


def _truncations(data: bytes, rng: random.Random) -> list[bytes]:
    cuts = {0, 1, len(data) // 2, len(data) - 1, *(rng.randrange(len(data))
                                                   for _ in range(MUTATIONS))}
    return [data[:c] for c in sorted(cuts)]


def _bit_flips(data: bytes, rng: random.Random) -> list[bytes]:
    out = []
    for _ in range(MUTATIONS):
        b = bytearray(data)
        for _ in range(rng.choice((1, 1, 2, 8))):
            b[rng.randrange(len(b))] ^= 1 << rng.randrange(8)
        out.append(bytes(b))
    return out


@pytest.mark.parametrize("name", sorted(LOADERS))
def test_truncated_and_bit_flipped_files_get_a_message(tmp_path: Path, name: str) -> None:
    suffix, loader, source = LOADERS[name]
    data = source(tmp_path)
    rng = random.Random(name)
    path = tmp_path / f"damaged{suffix}"
    assert _refused_or_read(loader, path, data)  # the original reads
    variants = _truncations(data, rng) + _bit_flips(data, rng)
    refused = sum(not _refused_or_read(loader, path, v) for v in variants)
    assert refused >= len(variants) // 4  # most damage is seen, and none escapes


def _toml_with(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


WRONG_TYPES = [
    ("rig", "[bus]\nbaud = \"fast\"\n", "bus.baud"),
    ("rig", "[loop]\nrate_hz = [200]\n", "loop.rate_hz"),
    ("rig", "servos = 3\n", "servos"),
    ("rig", "[[servos]]\nid = 1\njoint = 7\n", "servos[0].joint"),
    ("rig", "[bus]\nport = \"sim\"\n", "no [[servos]]"),
    ("rig", "", "no [[servos]]"),
    ("glove", "[glove]\nbaud = 1e400\n", "glove.baud"),
    ("glove", "[[channels]]\ncurve = \"riIndexMCPy\"\nindex = 0\nraw_open = 1e12\n"
     "raw_closed = 2\nopen_deg = 0\nclosed_deg = 80\n", "channels[0].raw_open"),
    ("glove", "[[channels]]\ncurve = \"riIndexMCPy\"\nindex = 0\nraw_open = nan\n"
     "raw_closed = 2\nopen_deg = 0\nclosed_deg = 80\n", "finite"),
    ("joint_limits", "[limits]\nriIndexMCPy = \"low\"\n", "limits.riIndexMCPy"),
    ("joint_limits", "limits = [1, 2]\n", "limits"),
]


@pytest.mark.parametrize(("name", "text", "says"), WRONG_TYPES)
def test_wrong_types_name_the_file_and_key(tmp_path: Path, name: str, text: str,
                                           says: str) -> None:
    _, loader, _ = LOADERS[name]
    path = _toml_with(tmp_path / "wrong.toml", text)
    with pytest.raises(HandrigError) as exc:
        loader(path)
    assert "wrong.toml" in str(exc.value) and says in str(exc.value), str(exc.value)


def _grid_arrays() -> dict[str, np.ndarray]:
    with np.load(CONFIG_DIR / "sag_grid.npz", allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def _save_grid(path: Path, arrays: dict[str, np.ndarray]) -> Path:
    buf = io.BytesIO()
    np.savez(buf, **arrays)  # type: ignore[arg-type]
    path.write_bytes(buf.getvalue())
    return path


@pytest.mark.parametrize(("change", "says"), [
    (lambda a: a.update(dofs_deg=a["dofs_deg"] * 1000.0), "outside its limits"),
    (lambda a: a.update(rest_deg=a["rest_deg"] * 1000.0), "rest_deg puts"),
    (lambda a: a.update(dofs_deg=a["dofs_deg"] * 1000.0, rest_deg=a["rest_deg"] * 1000.0),
     "outside its limits"),
    (lambda a: a.update(limits_deg=a["limits_deg"] * 1000.0), "beyond the anatomical"),
    (lambda a: a.update(dofs_deg=np.radians(a["dofs_deg"]) * 1e4), "outside its limits"),
    (lambda a: a.update(dofs_deg=a["dofs_deg"].astype(str)), "not numbers"),
    (lambda a: a.update(limits_deg=a["limits_deg"][:5]), "limits_deg has shape"),
    (lambda a: a.update(rest_deg=a["rest_deg"][:5]), "rest_deg"),
    (lambda a: a.pop("dofs_deg"), "missing arrays"),
    (lambda a: a.update(metadata=np.array("[1, 2]")), "not a JSON object"),
])
def test_an_implausible_sag_grid_is_refused(tmp_path: Path, change: Callable[[dict], object],
                                            says: str) -> None:
    arrays = _grid_arrays()
    change(arrays)
    path = _save_grid(tmp_path / "odd_grid.npz", arrays)
    with pytest.raises(HandrigError) as exc:
        SagGrid.load(path)
    assert "odd_grid.npz" in str(exc.value) and says in str(exc.value), str(exc.value)


def test_a_sag_grid_that_is_a_folder_or_text(tmp_path: Path) -> None:
    (tmp_path / "dir.npz").mkdir()
    with pytest.raises(HandrigError, match=r"dir\.npz: is a folder"):
        SagGrid.load(tmp_path / "dir.npz")
    (tmp_path / "text.npz").write_text("hello")
    with pytest.raises(HandrigError, match=r"text\.npz: not a readable \.npz"):
        SagGrid.load(tmp_path / "text.npz")
