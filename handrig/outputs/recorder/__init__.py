"""Record a performance (the full pose per frame) as CSV or BVH, read it back, play it back.

* :mod:`~handrig.outputs.recorder.formats`: what every format shares
  (:class:`TakeFormat`, names, ``<take>.partial``);
* :mod:`~handrig.outputs.recorder.csv_take`, :mod:`~handrig.outputs.recorder.bvh_take`:
  one class per format;
* :mod:`~handrig.outputs.recorder.writer`: :class:`Recorder` streams the take to
  ``<path>.partial`` while the show runs and renames it at :meth:`Recorder.close`;
* :mod:`~handrig.outputs.recorder.loading`: :func:`load_performance`;
* :mod:`~handrig.outputs.recorder.repair`: :func:`repair` makes a take cut short by a
  crash or a power cut readable and finds damage (every frame checked, the whole ones
  before any damage kept, the rest moved to ``<take>.damaged``, the BVH frame count
  set), glove takes too;
* :mod:`~handrig.outputs.recorder.playback`: :class:`Playback` at the recorded times.
"""

from handrig.outputs.recorder.bvh_take import (
    BVH_CHANNELS,
    BVH_PROFILE,
    FRAMES_FIELD,
    FRAMES_WIDTH,
    BvhTake,
)
from handrig.outputs.recorder.csv_take import CsvTake
from handrig.outputs.recorder.formats import (
    FORMATS,
    PARTIAL_SUFFIX,
    Format,
    Performance,
    TakeFormat,
    check_new_take,
    csv_header,
    format_of,
    free_path,
    partial_path,
)
from handrig.outputs.recorder.loading import FORMAT_CLASSES, load_performance
from handrig.outputs.recorder.playback import Playback
from handrig.outputs.recorder.repair import Repaired, repair
from handrig.outputs.recorder.writer import Recorder

__all__ = [
    "BVH_CHANNELS", "BVH_PROFILE", "FORMATS", "FORMAT_CLASSES", "FRAMES_FIELD", "FRAMES_WIDTH",
    "PARTIAL_SUFFIX", "BvhTake", "CsvTake", "Format", "Performance", "Playback", "Recorder",
    "Repaired", "TakeFormat", "check_new_take", "csv_header", "format_of", "free_path",
    "load_performance", "partial_path", "repair",
]
