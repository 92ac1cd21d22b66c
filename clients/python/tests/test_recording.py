"""Recordings: a lockstep run recorded by vdyn-recorder, read by vdyn.Recording, equals both the
recorder's own CSV export and the states the lockstep calls returned."""

import subprocess

import numpy as np
import pytest

import vdyn
from conftest import RECORDER, SERVER


def read_csv(path):
    import pandas as pd
    return pd.read_csv(path, float_precision="round_trip")


@pytest.fixture
def recorded_run(start, domain, tmp_path):
    out = tmp_path / "run.mcap"
    rec = start([RECORDER, "record", str(out), "--domain", str(domain), "--status"], "recorder")
    server = start([SERVER, "--lockstep", "--lockstep-timeout", "60", "--domain", str(domain)],
                   "server")
    assert rec.wait_for(["recording world", "hearing 1 writer(s) on vdyn/state",
                         "hearing 1 writer(s) on vdyn/events"]), rec.log()
    sim = vdyn.Client(domain=domain, timeout=30)
    sim.reset(1)
    got = []
    for k in range(20):  # a driver who changes the input every 100 steps
        inp = vdyn.make_input(steer=0.01 * (k % 5), throttle=0.2 + 0.02 * k, vehicle_id=1)
        got.append(sim.step(100, inp)[1])
    assert server.stop(15) == 0, server.log()
    assert rec.stop(2) == 0, rec.log()
    return out, got


def test_a_recording_equals_the_recorders_export_and_the_lockstep_states(recorded_run, tmp_path):
    out, got = recorded_run
    rec = vdyn.Recording(out)
    assert rec.complete
    assert rec.vehicle_ids == [1]
    assert rec.gaps == {1: 0}
    topics = {c["topic"] for c in rec.channels}
    assert "vdyn/state/1" in topics and "vdyn/events/1" in topics
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
