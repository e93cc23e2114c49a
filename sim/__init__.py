"""Simulation: MuJoCo models, the passive-hand model and grid baking, the
Dynamixel bus emulator, a glove emulator. May import ``handrig``; never the reverse
(except where the user asks for the simulated rig)."""
