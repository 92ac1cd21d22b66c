"""The exceptions of vdyn."""

import builtins


class Error(Exception):
    """Base of every vdyn error."""


class TimeoutError(Error, builtins.TimeoutError):
    """A bounded wait ended: the message says what did not arrive."""


class RefusedError(Error):
    """A server refused a request; ``reason`` is the server's reason."""

    def __init__(self, message, reason=""):
        super().__init__(message)
        self.reason = reason


class RecordingError(Error):
    """A recording is truncated, corrupted or not a recording: the message names the file, the
    byte offset and the reason."""


class TransportError(Error):
    """DDS refused to create an entity (a bad domain id, a configuration error)."""
