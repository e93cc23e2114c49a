"""Outputs besides the servo bus: VMC (OSC) to virtual puppets, and recording/playback."""
