"""The one compiled part of handrig: the bus emulator's packet path (sim/_dxl_c.c).

Optional: where no C compiler is found, the install goes on without it and the
emulator answers in pure Python, byte for byte the same (sim/dxl_fast.py), only
slower. Everything else is in pyproject.toml.
"""

from setuptools import Extension, setup

setup(ext_modules=[Extension("sim._dxl_c", ["sim/_dxl_c.c"], optional=True)])
