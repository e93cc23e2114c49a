"""What the tests share: the one fake bus and fake glove (:mod:`tests.helpers.fakes`),
a loop built on them (:mod:`tests.helpers.loop`), and the bus emulator in a process of
its own (:mod:`tests.helpers.emulator`; the ``sim_bus`` fixture of tests/conftest.py)."""
