"""Cues from a show controller: OSC (:mod:`~handrig.app.cues.osc`, the port in
:mod:`~handrig.app.cues.receiver`) and MIDI (:mod:`~handrig.app.cues.midi`), read as the
show's actions (:mod:`~handrig.app.cues.dispatch`), the takes they start
(:mod:`~handrig.app.cues.takes`), a live session's part (:mod:`~handrig.app.cues.live`).
The vocabulary and the show file's tables are :mod:`handrig.config.cues`'."""
