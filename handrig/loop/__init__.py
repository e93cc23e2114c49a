"""The realtime loop's parts; :class:`handrig.loop.rig.Rig` puts them together.

``trigger`` (when a cycle runs), ``modes`` (what the puppet does: waiting, running,
relaxing, resuming, stopping), ``cycle`` (one glove sample to one Sync Write and
what follows it), ``easing`` (to the relaxed pose and back to the glove),
``stats`` (fixed-size figures),
``profile`` (per-stage timing, for the benchmark), ``ports`` (what the loop needs
from the glove, the bus and the control path), ``settings`` (what a loop is built
from, as data: :class:`~handrig.loop.settings.LoopParts` and
:class:`~handrig.loop.settings.RigSettings`), ``telemetry`` (the typed snapshot
readers get, built from the cycle's typed
:class:`~handrig.loop.telemetry.CycleView`).
"""
