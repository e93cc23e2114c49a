"""The one error hierarchy of handrig.

Every error handrig raises on purpose derives from :class:`HandrigError`; the
command line prints its message (never a traceback) and exits with status 2.
Messages say what failed, where, how many attempts were made and what to do.
"""

from __future__ import annotations

_SHOWN_CHARS = 80


def _shown(value: object) -> str:
    """``value``'s repr, cut to a line (a value read from a file may be any size): its
    start and its end, where a path's file name is."""
    text = repr(value)
    if len(text) <= _SHOWN_CHARS:
        return text
    half = (_SHOWN_CHARS - 20) // 2
    return f"{text[:half]}...{text[-half:]} ({len(text)} characters)"


class HandrigError(Exception):
    """Root of every error handrig raises on purpose."""


class ConfigError(HandrigError):
    """A configuration file is missing, malformed or holds a value that is not allowed."""

    def __init__(
        self,
        message: str,
        *,
        file: str | None = None,
        key: str | None = None,
        value: object = None,
        allowed: str | None = None,
    ) -> None:
        self.file = file
        self.key = key
        self.value = value
        self.allowed = allowed
        self.detail = message
        super().__init__(self._format())

    def _format(self) -> str:
        if self.file is None and self.key is not None and self.key.startswith("-"):
            text = self.key  # a command-line flag: named as typed
            if self.value is not None:
                text += f" {_shown(self.value)}"
            text += f": {self.detail}"
        elif self.file is None and self.key is not None:
            text = self.key  # an argument or a name in a call: no file to name
            if self.value is not None:
                text += f" = {self.value!r}"
            text += f": {self.detail}"
        elif self.key is not None:
            text = f"{self.file}: key '{self.key}'"
            if self.value is not None:
                text += f" = {_shown(self.value)}"
            text += f": {self.detail}"
        else:
            text = f"{self.file}: {self.detail}" if self.file else self.detail
        if self.allowed:
            text += f" (allowed: {self.allowed})"
        return text

    def located(self, file: str) -> ConfigError:
        """The same error, naming ``file`` as where it happened."""
        return ConfigError(
            self.detail, file=file, key=self.key, value=self.value, allowed=self.allowed
        )


class DataError(HandrigError):
    """Input data (motion capture, recordings, grids, maps) is malformed or implausible."""


class ProtocolError(HandrigError):
    """Bytes on a wire do not form a valid packet or frame (bad CRC, length, header)."""


class DeviceError(HandrigError):
    """A device (servo bus, glove port) cannot be opened, does not answer, or went away."""


class DeviceTimeoutError(DeviceError):
    """A device did not answer before its deadline, after the stated number of attempts."""


class TorqueOffError(DeviceError):
    """Servos did not acknowledge the torque-off writes at exit (named in the message).
    The broadcast went out first: a read-back may still find their torque off, and then
    it was the acknowledgement that was lost (a starved host), not the torque-off."""


class ServoFault(DeviceError):
    """A servo reported a hardware error (overload, overheating, ...) or a protocol error."""

    def __init__(self, message: str, *, servo_id: int | None = None, bits: int = 0) -> None:
        self.servo_id = servo_id
        self.bits = bits
        super().__init__(message)


class SafetyStop(HandrigError):
    """The realtime loop stopped on purpose for safety (e-stop, lost port, glove silent)."""
