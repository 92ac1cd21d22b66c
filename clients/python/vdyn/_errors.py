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


class DiscardedStepsWarning(UserWarning):
    """A lockstep step() or run_maneuver() ran steps the server discarded: a vehicle's state
    became non-finite, or the car fell through the ground (it rolled over), and the server put it
    back at rest. Those steps have no state (their rows are not in the States); the message names
    the vehicle, how many, the first step and why."""


class SeveralRunsWarning(UserWarning):
    """A recording's vehicle was stepped by more than one start of its server (it restarted
    while recording: each start counts its steps from 0). Recording.states() gives the runs one
    after another, each sorted by step, never merged by step; ``run=K`` takes one. The message
    lists the runs."""
