"""handrig's tests: a package, so that ``tests.helpers`` is ours even where an installed
distribution ships a top-level ``tests`` package of its own (LeRobot's draccus does)."""
