"""Every file handrig reads is read with bounded memory and bounded messages (issue 41):
100 MB of NULs (a sparse file), of one long line and of random bytes, given to each
reader under each name it takes, is refused within seconds, allocating a few megabytes
at most, with a message of a line that names the file.

The three files are made once for the module and reached through symlinks with each
reader's suffix, so the test writes 200 MB once and takes a few seconds."""

from __future__ import annotations

import os
import time
import tracemalloc
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from handrig.app.takes import load_play_take
from handrig.config.bounded import excerpt
from handrig.config.loading import load_joint_limits
from handrig.config.rig import load_rig_config
from handrig.config.show import load_show
from handrig.devices.glove_calibration import load_glove_config
from handrig.devices.glove_recording import MAGIC, read_glove_recording
from handrig.errors import ConfigError, HandrigError
from handrig.offline.bvh import read_bvh
from handrig.outputs.recorder import load_performance
from handrig.outputs.recorder.repair import repair
from handrig.pose.maps import LinearMap
from handrig.pose.sag import SagGrid

SIZE = 100 * 1000 * 1000
MAX_SECONDS = 5.0  # "within seconds"; each takes milliseconds on an idle machine
MAX_PEAK_BYTES = 8 << 20  # what a reader may allocate at once (tracemalloc's peak)
MAX_MESSAGE_CHARS = 600  # besides the file's name (twice at most)


@pytest.fixture(scope="module")
def huge(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("huge")
    made = {}
    nuls = folder / "nuls"
    with nuls.open("wb") as f:  # sparse: no blocks written
        f.truncate(SIZE)
    made["nuls"] = nuls
    line = folder / "line"
    line.write_bytes(b"7" * SIZE)
    made["line"] = line
    noise = folder / "noise"
    noise.write_bytes(np.random.default_rng(41).bytes(SIZE))
    made["noise"] = noise
    # the same after a valid first line: the readers get past the header
    glove = folder / "glove_nuls"
    with glove.open("wb") as f:
        f.write(f"{MAGIC}\n".encode())
        f.truncate(SIZE)
    made["glove_nuls"] = glove
    return made


def _glove_take(p: Path) -> object:
    return load_play_take(p, load_glove_config())


READERS: dict[str, tuple[str, Callable[[Path], object]]] = {
    "take_csv": (".csv", load_performance),
    "take_bvh": (".bvh", load_performance),
    "take_csv_partial": (".csv.partial", lambda p: load_performance(p, "csv")),
    "play": (".csv", _glove_take),
    "mocap_bvh": (".bvh", read_bvh),
    "glove_take": (".csv", read_glove_recording),
    "repair_csv": (".csv", repair),
    "repair_bvh_partial": (".bvh.partial", repair),
    "map": (".toml", LinearMap.load),
    "grid": (".npz", SagGrid.load),
    "rig": (".toml", load_rig_config),
    "glove": (".toml", load_glove_config),
    "show": (".toml", load_show),
    "joint_limits": (".toml", load_joint_limits),
}


@pytest.mark.parametrize("content", ["nuls", "line", "noise", "glove_nuls"])
@pytest.mark.parametrize("reader", sorted(READERS))
def test_huge_file_refused_fast_small_and_short(huge: dict[str, Path], tmp_path: Path,
                                                reader: str, content: str) -> None:
    suffix, read = READERS[reader]
    path = tmp_path / f"huge{suffix}"
    path.symlink_to(huge[content])
    tracemalloc.start()
    t0 = time.perf_counter()
    try:
        with pytest.raises(HandrigError) as refused:
            read(path)
        took_s = time.perf_counter() - t0
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    message = str(refused.value)
    assert str(path) in message or (isinstance(refused.value, ConfigError)
                                    and refused.value.file == str(path)), message
    assert len(message.replace(str(path), "")) <= MAX_MESSAGE_CHARS, message[:2000]
    assert took_s < MAX_SECONDS, f"{took_s:.1f} s: {message}"
    assert peak < MAX_PEAK_BYTES, f"{peak / 1e6:.0f} MB at the peak: {message}"
    assert os.path.getsize(huge[content]) == SIZE  # a refused file is left as it was


def test_excerpt_is_short_and_escaped() -> None:
    shown = excerpt(b"\x00" * 10**6)
    assert shown.startswith("'\\x00") and shown.endswith("... (1000000 bytes)")
    assert len(shown) < 200
    assert excerpt("abc") == "'abc'"
    assert excerpt(b"\xff\xfe") == "'\\\\xff\\\\xfe'"
