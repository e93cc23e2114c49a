"""What pyproject.toml cannot say statically: the C packet path and the extras.

* The one compiled part of handrig, the bus emulator's packet path (sim/_dxl_c.c).
  Optional: where no C compiler is found, the install goes on without it and the
  emulator answers in pure Python, byte for byte the same (sim/dxl_fast.py), only
  slower.
* The extras (pyproject.toml declares ``optional-dependencies`` dynamic): the
  ``lerobot`` extra names handrig's two LeRobot plugin distributions in ``plugins/``
  by a direct reference to this checkout's folders (``name @ file:///...``). LeRobot
  finds third-party devices by their distribution's name (``lerobot_robot_*``,
  ``lerobot_teleoperator_*``), never inside a distribution called ``handrig``, so
  ``pip install -e '.[lerobot]'`` must install those two for LeRobot to find
  ``handrig_glove``, ``handrig_leap`` and ``handrig_orca`` (docs/lerobot.md). A build
  without ``plugins/`` (an sdist) leaves them out.

Everything else is in pyproject.toml.
"""

from pathlib import Path

from setuptools import Extension, setup

HERE = Path(__file__).resolve().parent
LEROBOT_PLUGINS = ("lerobot_teleoperator_handrig", "lerobot_robot_handrig")

EXTRAS: dict[str, list[str]] = {
    "dev": [
        "pytest>=8.0",
        # pytest-xdist: `make test` runs the patient end-to-end tests two at a time
        # (`-n 2 --dist loadfile`); they wait for conditions, not for a time
        "pytest-xdist>=3.6",
        "hypothesis>=6.100",
        "ruff>=0.5",
        "mypy>=1.10",
        # pexpect: the terminal tests drive `handrig run` in a pseudo-terminal, press its
        # keys and read the panel as a puppeteer sees it
        "pexpect>=4.8",
        # bvh: an outside BVH reader, so the tests check a take's frame count and frame
        # time against a parser that is not ours
        "bvh>=0.3",
        # selenium: the view's tests drive Debian's chromium through chromium-driver
        # (/usr/bin/chromedriver, `make browser-deps`); it never downloads a browser here
        "selenium>=4.20",
        # the show extra's MIDI input, so the tests map mido's messages to cues
        "handrig[show]",
    ],
    # show control: MIDI cues (--midi-in) through mido on python-rtmidi (a compiled
    # binding to ALSA/JACK). Optional: a rig without a MIDI surface needs neither; OSC
    # cues need nothing more than the core (the parser is handrig's own,
    # handrig/app/cues/osc.py).
    "show": [
        "mido>=1.3",
        "python-rtmidi>=1.5",
    ],
    # LeRobot (Hugging Face's robot-learning library: datasets, record, replay, policies)
    # with handrig's glove as its teleoperator and the robot hands as its robots
    # (docs/lerobot.md). Its plugin API moves between minor releases: built and tested
    # against 0.4.4. It brings torch (2.10 the newest it allows: PyPI's CUDA build).
    "lerobot": [
        "lerobot>=0.4.4,<0.5",
        # LeRobot 0.4 takes opencv-python-headless < 4.13; 4.12 caps numpy below 2.3 and
        # so would take the venv's numpy back from 2.4 (and numpy 2.2's stubs fail mypy
        # on our code); 4.11 has no cap (LeRobot uses OpenCV for cameras only)
        "opencv-python-headless>=4.9,<4.12",
        # the plugin distributions LeRobot discovers by name (module docstring)
        *(f"{name} @ {(HERE / 'plugins' / name).as_uri()}" for name in LEROBOT_PLUGINS
          if (HERE / "plugins" / name / "pyproject.toml").is_file()),
    ],
}

setup(ext_modules=[Extension("sim._dxl_c", ["sim/_dxl_c.c"], optional=True)],
      extras_require=EXTRAS)
