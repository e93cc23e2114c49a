"""Is there a display, or an offscreen renderer? Checked before a command starts, so
a missing one is reported as such, naming the flag and the fix.

MuJoCo picks its OpenGL backend from ``MUJOCO_GL`` when it is imported: ``egl`` and
``osmesa`` render offscreen and need their library (Debian: libegl1, libosmesa6;
``make render-deps``); ``glfw`` (or unset) needs a display. With ``MUJOCO_GL`` naming
a backend whose library is missing, ``import mujoco`` itself fails, in every command
that simulates.
"""

from __future__ import annotations

import ctypes.util
import os

from handrig.errors import ConfigError

LIBRARIES = {"egl": "EGL", "osmesa": "OSMesa"}


def has_display() -> bool:
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def check_display(flag: str) -> None:
    """ConfigError naming ``flag`` when there is no display to show a window on."""
    if not has_display():
        raise ConfigError(
            "needs a display, and DISPLAY and WAYLAND_DISPLAY are unset", key=flag,
            allowed=f"run it in a desktop session (or over ssh -X), or leave out {flag}; "
            "`handrig demo --render FILE.png` draws the simulated hand without a display")


def check_gl_backend(what: str = "the simulated puppet") -> None:
    """ConfigError when ``MUJOCO_GL`` names a backend whose library is not installed
    (MuJoCo would fail on import with ``'NoneType' object has no attribute ...``)."""
    backend = os.environ.get("MUJOCO_GL", "").lower()
    lib = LIBRARIES.get(backend)
    if lib is not None and ctypes.util.find_library(lib) is None:
        raise ConfigError(
            f"the {lib} library is not installed, so MuJoCo cannot load ({what} needs it)",
            file="environment", key="MUJOCO_GL", value=backend,
            allowed="install it (`make render-deps`: libegl1, libgl1-mesa-dri, libosmesa6), "
            "or set MUJOCO_GL to a backend that is installed (egl), or unset it")


def check_renderer(flag: str) -> None:
    """ConfigError naming ``flag`` when offscreen rendering cannot work: the backend
    (``MUJOCO_GL``, egl when unset) has no library installed."""
    backend = os.environ.get("MUJOCO_GL", "").lower() or "egl"
    lib = LIBRARIES.get(backend)
    if lib is None:
        if not has_display():
            raise ConfigError(
                f"MUJOCO_GL={backend} renders through a window and there is no display",
                key=flag, allowed="set MUJOCO_GL=egl (or osmesa) to render offscreen")
        return
    if ctypes.util.find_library(lib) is None:
        raise ConfigError(
            f"offscreen rendering with MUJOCO_GL={backend} needs the {lib} library, which is "
            "not installed", key=flag,
            allowed="install it (`make render-deps`: libegl1, libgl1-mesa-dri, libosmesa6), "
            "or leave out the flag")
