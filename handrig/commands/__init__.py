"""Subcommands of the ``handrig`` CLI; each module provides ``register(subparsers)``."""
