"""Recordings: a lockstep run recorded by vdyn-recorder, read by vdyn.Recording, equals both the
recorder's own CSV export and the states the lockstep calls returned."""

import subprocess

import numpy as np
import pytest

import vdyn
from conftest import RECORDER


def read_csv(path):
    import pandas as pd
    return pd.read_csv(path, float_precision="round_trip")


def test_a_recording_equals_the_recorders_export_and_the_lockstep_states(recorded_run, tmp_path):
    out, got = recorded_run
    rec = vdyn.Recording(out)
    assert rec.complete
    assert rec.vehicle_ids == [1]
    assert rec.gaps == {1: 0}
    topics = {c["topic"] for c in rec.channels}
    assert "vdyn/state/1" in topics and "vdyn/events/1" in topics
    # A vehicle id as the client's methods take it (1.7, '1' and True were read as vehicle 1).
    for bad, error in ((1.7, TypeError), ("1", TypeError), (True, TypeError), (0, ValueError)):
        with pytest.raises(error, match="vehicle_id"):
            rec.states(bad)
    events = rec.events()
    assert any(e.HasField("spawned") for _, e in events)
    assert any(e.HasField("input_batch") for _, e in events)

    csv = tmp_path / "export.csv"
    subprocess.run([RECORDER, "export", str(out), "--csv", str(csv)], check=True, timeout=120)
    exported = read_csv(csv)
    df = rec.dataframe(1)
    assert list(exported.columns) == list(vdyn.COLUMNS)
    assert len(df) == len(exported) >= 2000
    np.testing.assert_array_equal(df[list(vdyn.COLUMNS)].to_numpy(), exported.to_numpy())

    # The lockstep calls' states are the recorded ones, bit for bit.
    mine = np.concatenate([s.values for s in got])
    steps = np.concatenate([s.step for s in got])
    same = exported[exported["step"].isin(steps.astype(float))].sort_values("step")
    assert len(same) == len(steps) == 2000
    np.testing.assert_array_equal(mine, same.to_numpy())
    hashes = rec.states(1)
    by_step = dict(zip(hashes.step.tolist(), hashes.state_hash.tolist()))
    assert all(by_step[st] == h for st, h in zip(steps.tolist(),
                                                  np.concatenate([s.state_hash for s in got]).tolist()))


def test_a_broken_recording_raises_naming_the_file(tmp_path):
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"not a recording at all")
    with pytest.raises(vdyn.RecordingError, match="bad.mcap"):
        vdyn.Recording(bad)
    with pytest.raises(vdyn.RecordingError):
        vdyn.Recording(tmp_path / "missing.mcap")
