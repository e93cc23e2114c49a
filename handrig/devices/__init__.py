"""Devices the loop talks to: glove sources and the servo bus package."""
