"""handrig: a realtime hand driver for puppets and robot hands.

A minimal glove (thumb, two MCP flexions, forearm IMU) is expanded into two full
hands with linear maps learnt from motion capture (Jörg & O'Sullivan), given
passive sag from a baked grid (Neff & Seidel), and streamed to Dynamixel servos
or a simulated MuJoCo puppet.
"""

__version__ = "0.1.0"
