"""Wire formats, pure code: bytes to values and back. No I/O, no clock.

Imports neither ``handrig`` nor ``sim``.
"""
