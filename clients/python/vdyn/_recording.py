"""Recordings (MCAP files of vdyn-recorder), read through the recorder's own reader."""

import warnings

from . import _vdyn
from . import session_pb2
from ._states import States
from ._client import _whole
from ._errors import SeveralRunsWarning


class Recording:
    """A vdyn recording. Opening scans the file once (a bad file raises vdyn.RecordingError with
    the file, the offset and the reason).

    ``channels`` and ``vehicles`` are lists of dicts (per vehicle: states, first_step,
    last_step and the gaps: missing, jumps, largest_gap, largest_gap_from, as
    ``vdyn-recorder info`` counts them); ``states(vehicle_id)`` every state as States (sorted by
    step, ``log_time_ns`` when the recorder took each); ``dataframe(vehicle_id)`` the same as a
    pandas DataFrame; ``events()`` the session events as (log_time_ns, vdyn.pb.SessionEvent).
    """

    def __init__(self, path):
        self.path = str(path)
        self._r = _vdyn.RecordingReader(self.path)

    @property
    def channels(self):
        return self._r.channels()

    @property
    def vehicles(self):
        return self._r.vehicles()

    @property
    def vehicle_ids(self):
        return [v["vehicle_id"] for v in self._r.vehicles()]

    @property
    def gaps(self):
        """{vehicle_id: states missing} (holes in a vehicle's steps not explained by a spawn,
        reset or restore)."""
        return {v["vehicle_id"]: v["missing"] for v in self._r.vehicles()}

    @property
    def duration_s(self):
        return (self._r.end_ns - self._r.start_ns) * 1e-9

    @property
    def complete(self):
        """True when the file was closed properly (summary and footer)."""
        return self._r.complete

    @property
    def metadata(self):
        return self._r.metadata()

    def states(self, vehicle_id=None, run=None):
        """Every state of the vehicle, sorted by step. A vehicle stepped by several starts of its
        server (a restart while recording) has a run per start: they come one after another,
        each sorted by step, with a vdyn.SeveralRunsWarning that lists them; ``run=K`` (from 0)
        takes one alone."""
        vid = self._one(vehicle_id)
        k = -1 if run is None else _whole("run", run)
        if not -1 <= k < 2 ** 31 or (run is not None and k < 0):
            raise ValueError(f"run counts the server's starts from 0, got {run!r}")
        table = self._r.states(vid, k)
        runs = list(table.get("runs", []))
        if run is None and len(runs) > 1:
            warnings.warn(SeveralRunsWarning(
                f"{self.path}: vehicle {vid} was stepped by {len(runs)} starts of its server: "
                + "; ".join(f"run {i}: {r}" for i, r in enumerate(runs))
                + f". Their states follow one run after another (each by step), not merged: "
                f"states({vid}, run=K) takes one"), stacklevel=2)
        return States(vid, table)

    def dataframe(self, vehicle_id=None, run=None):
        return self.states(vehicle_id, run).to_dataframe()

    def events(self):
        return [(t, session_pb2.SessionEvent.FromString(b)) for t, b in self._r.events()]

    def _one(self, vehicle_id):
        if vehicle_id is not None:
            # As the client's methods take ids: a whole number in range (1.7, '1' and True were
            # read as vehicle 1).
            return _whole("vehicle_id", vehicle_id, "vehicle_id")
        ids = self.vehicle_ids
        if len(ids) != 1:
            raise ValueError(f"{self.path} holds vehicles {ids}: name one")
        return ids[0]

    def __repr__(self):
        return (f"<vdyn.Recording {self.path!r}: {self.duration_s:.3f} s, "
                f"vehicles {self.vehicle_ids}>")
