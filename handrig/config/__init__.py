"""Configuration: loading and checking TOML into frozen dataclasses, the rig file,
and the user directories."""
