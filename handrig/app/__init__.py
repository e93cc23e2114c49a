"""The application layer: the factory that builds a rig from configs, one live
session, its summary and panel, robot rig files, and the one door to ``sim/``."""
