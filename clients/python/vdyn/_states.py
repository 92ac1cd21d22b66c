"""States as arrays: one row per state, the columns of the vehicle CSV (docs/formats.md)."""

import numpy as np

from . import _vdyn

COLUMNS = tuple(_vdyn.state_columns())
_COLUMN_SET = frozenset(COLUMNS)
_INDEX = {name: i for i, name in enumerate(COLUMNS)}


class States:
    """The states of one vehicle, one row each, in step order.

    ``values`` is an (n, len(COLUMNS)) float64 array; ``s["yaw_rad"]`` (or ``s.yaw_rad``) is a
    column. Exact integers beside it: ``step`` and ``state_hash`` (uint64), ``sim_time_ns``
    (int64), and for recordings ``log_time_ns`` (uint64, when the recorder took the state).
    """

    __slots__ = ("vehicle_id", "values", "step", "state_hash", "sim_time_ns", "log_time_ns",
                 "malformed")

    def __init__(self, vehicle_id, table):
        self.vehicle_id = int(vehicle_id)
        self.values = table["values"]
        self.step = table["step"]
        self.state_hash = table["state_hash"]
        self.sim_time_ns = table["sim_time_ns"]
        self.log_time_ns = table["log_time_ns"] if len(table["log_time_ns"]) else None
        self.malformed = int(table.get("malformed", 0))

    columns = COLUMNS

    def __len__(self):
        return self.values.shape[0]

    def __getitem__(self, name):
        try:
            return self.values[:, _INDEX[name]]
        except KeyError:
            raise KeyError(f"no state column {name!r} (vdyn.COLUMNS lists them)") from None

    def __getattr__(self, name):
        if name in _INDEX:
            return self.values[:, _INDEX[name]]
        raise AttributeError(f"States has no attribute or column {name!r}")

    @property
    def t(self):
        """Simulation time of each state, s (the column t_s)."""
        return self["t_s"]

    @property
    def yaw_rate(self):
        """Yaw rate about the body z axis, rad/s (the column wz_radps)."""
        return self["wz_radps"]

    def wheel(self, prefix):
        """The four wheels' column of a per-wheel quantity as an (n, 4) array, LF RF LR RR:
        ``s.wheel("Fy_N")`` is Fy_LF_N, Fy_RF_N, Fy_LR_N, Fy_RR_N."""
        parts = prefix.split("_")
        # The wheel's tag goes where the column has it: Fy_LF_N, kappa_t_LF, alpha_t_LF_rad.
        for at in range(1, len(parts) + 1):
            names = ["_".join(parts[:at] + [w] + parts[at:]) for w in ("LF", "RF", "LR", "RR")]
            if all(n in _COLUMN_SET for n in names):
                return np.stack([self[n] for n in names], axis=1)
        raise KeyError(f"no per-wheel column {prefix!r}: the four wheels' columns are named with "
                       f"LF, RF, LR, RR inside, e.g. Fy_N for Fy_LF_N or kappa_t for kappa_t_LF")

    def to_dataframe(self):
        """A pandas DataFrame of every column (plus step, state_hash, sim_time_ns and, for a
        recording, log_time_ns). Needs pandas (python3-pandas)."""
        try:
            import pandas as pd
        except ImportError as e:  # pragma: no cover - depends on the machine
            raise ImportError("States.to_dataframe needs pandas (Debian: python3-pandas)") from e
        df = pd.DataFrame(self.values, columns=list(COLUMNS))
        df["step"] = self.step
        df["state_hash"] = self.state_hash
        df["sim_time_ns"] = self.sim_time_ns
        if self.log_time_ns is not None:
            df["log_time_ns"] = self.log_time_ns
        return df

    def __repr__(self):
        if len(self) == 0:
            return f"<States of vehicle {self.vehicle_id}: none>"
        return (f"<States of vehicle {self.vehicle_id}: {len(self)} from step {self.step[0]} "
                f"to {self.step[-1]}>")
