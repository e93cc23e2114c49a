"""Read a recorded performance back, whatever its format."""

from __future__ import annotations

from pathlib import Path

from handrig.errors import DataError
from handrig.outputs.recorder.bvh_take import BvhTake
from handrig.outputs.recorder.csv_take import CsvTake
from handrig.outputs.recorder.formats import Format, Performance, TakeFormat, format_of

FORMAT_CLASSES: dict[Format, type[TakeFormat]] = {"csv": CsvTake, "bvh": BvhTake}
"""The class that reads and writes each format."""


def load_performance(path: str | Path, fmt: str | None = None) -> Performance:
    """Read a recorded performance: (t_s (n,), poses (n, 50), wrist (n, 4) or None).

    CSV: the columns are found by name (any order; the wrist columns all or none);
    BVH: any file whose skeleton has the ``perception_neuron`` profile's joints (this
    package's recordings, Perception Neuron captures); wrist DOFs when ``RightHand``
    and ``LeftHand`` carry rotation channels. DataError names the file and the line
    (CSV) or frame (BVH) of anything malformed or truncated.
    """
    p = Path(path)
    kind = format_of(p, fmt)
    if not p.exists():
        raise DataError(f"{p}: recording not found")
    return FORMAT_CLASSES[kind].load(p)
