"""Recordings: a lockstep run recorded by vdyn-recorder, read by vdyn.Recording, equals both the
recorder's own CSV export and the states the lockstep calls returned."""

import subprocess
import time

import numpy as np
import pytest

import vdyn
from conftest import RECORDER, SERVER


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


def test_a_vehicle_of_two_server_starts_comes_run_after_run(start, domain, tmp_path):
    # A server restarted while recording counts its steps from 0 again: states() sorted every row
    # by step and interleaved the two runs (step 992 at y 0 m, step 992 at y 20 m, step 993 ...),
    # with no word. The runs now follow one another, each by step, with a warning naming them.
    out = tmp_path / "two.mcap"
    rec = start([RECORDER, "record", str(out), "--domain", str(domain), "--status"], "recorder")
    steps = {}
    for k, (n, y) in enumerate(((500, 0.0), (300, 20.0))):
        server = start([SERVER, "--lockstep", "--lockstep-timeout", "60", "--domain", str(domain),
                        "--spawn", f"0,{y:g},0"], f"server{k}")
        deadline = time.monotonic() + 60
        while rec.log().count("recording world") <= k and time.monotonic() < deadline:
            time.sleep(0.05)  # polls the recorder's log: no event to wait on
        assert rec.log().count("recording world") > k, rec.log()
        sim = vdyn.Client(domain=domain, timeout=30)
        steps[k] = sim.step(n)[1]
        assert server.stop(15) == 0, server.log()
        del sim
    assert rec.stop(2) == 0, rec.log()
    r = vdyn.Recording(out)
    with pytest.warns(vdyn.SeveralRunsWarning, match=r"vehicle 1 was stepped by 2 starts of its "
                                                     r"server: run 0: server 'vdyn' start 0x"):
        both = r.states(1)
    first, second = r.states(1, run=0), r.states(1, run=1)
    assert len(both) == len(first) + len(second)
    assert np.all(np.diff(first.step.astype(np.int64)) > 0)
    assert np.all(np.diff(second.step.astype(np.int64)) > 0)
    np.testing.assert_array_equal(both.step, np.concatenate([first.step, second.step]))
    # Each run is its own server's: the first at y 0 m, the second at y 20 m, every row.
    assert np.all(np.abs(first["y_m"]) < 5) and np.all(np.abs(second["y_m"] - 20) < 5)
    assert len(first) <= 500 and len(second) <= 300 and len(first) > 400 and len(second) > 200
    with pytest.raises(IndexError, match=r"vehicle 1 has 2 run\(s\) \(server starts\): run 2"):
        r.states(1, run=2)
    with pytest.raises(ValueError, match="run counts the server's starts from 0"):
        r.states(1, run=-1)
