"""Python client benchmarks (issue 18): lockstep from Python with the states returned, in batches
of 1, 10 and 1000 steps, and the single-step round trip; the peer, in the same run and process,
is the same step request sent through the module without collecting any state. Then real time:
every state of one vehicle at 1 kHz into Python for S seconds (none lost, memory flat). Then
reading a recording into arrays against `vdyn-recorder export` to CSV plus pandas.read_csv.

    PYTHONPATH=build/release/clients/python/package /usr/bin/python3 bench/python_bench.py \
        build/release [REALTIME_S=60] [RECORDING_S=600]
"""

import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

import vdyn
from vdyn import control_pb2

BUILD = sys.argv[1] if len(sys.argv) > 1 else "build/release"
REALTIME_S = float(sys.argv[2]) if len(sys.argv) > 2 else 60.0
RECORDING_S = float(sys.argv[3]) if len(sys.argv) > 3 else 600.0
SERVER = os.path.join(BUILD, "server", "vdyn-server")
RECORDER = os.path.join(BUILD, "clients", "recorder", "vdyn-recorder")


def fresh_domain():
    """A DDS domain among 100..229 that no test or benchmark on this machine holds (the lock
    files of tests/process.cc)."""
    import fcntl
    for k in range(130):
        domain = 100 + (os.getpid() + k) % 130
        fd = os.open(f"/tmp/vdyn-test-domain-{domain}.lock", os.O_CREAT | os.O_RDWR, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            return domain  # fd stays open: the lock is held until this process ends
        except OSError:
            os.close(fd)
    raise RuntimeError("no free DDS domain among 100..229")


DOMAIN = fresh_domain()
os.environ.setdefault(
    "CYCLONEDDS_URI", '<General><Interfaces><NetworkInterface name="lo"/></Interfaces></General>'
    "<Discovery><MaxAutoParticipantIndex>120</MaxAutoParticipantIndex></Discovery>")


def start(args, log):
    return subprocess.Popen(args, stdout=open(log, "wb"), stderr=subprocess.STDOUT)


def stop(p, sig=2):
    p.send_signal(sig)
    p.wait(60)


def rss_mb():
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    return float("nan")


def lockstep(tmp):
    server = start([SERVER, "--lockstep", "--lockstep-timeout", "60", "--world", "flat",
                    "--domain", str(DOMAIN)], os.path.join(tmp, "lockstep.log"))
    try:
        sim = vdyn.Client(domain=DOMAIN, timeout=30)
        inp = vdyn.make_input(throttle=0.3, vehicle_id=1)
        sim.step(2000, inp)  # warm up
        print("lockstep from Python, states returned (median of 5 runs of >= 2 s):")
        for batch in (1, 10, 1000):
            rates = []
            for _ in range(5):
                n, t0 = 0, time.perf_counter()
                while time.perf_counter() - t0 < 2.0 / 5 * (5 if batch == 1000 else 1):
                    got = sim.step(batch)[1]
                    assert len(got) == batch
                    n += batch
                rates.append(n / (time.perf_counter() - t0))
            print(f"  batch {batch:5d}: {statistics.median(rates):9.0f} steps/s "
                  f"(runs {min(rates):.0f}..{max(rates):.0f})")
        rtt, bare = [], []
        req = control_pb2.ControlRequest()
        req.step.steps = 1
        raw = req.SerializeToString()
        for _ in range(3000):
            t0 = time.perf_counter_ns()
            sim.step(1)
            rtt.append(time.perf_counter_ns() - t0)
            t0 = time.perf_counter_ns()
            sim._c.request(raw, "step", 10.0)  # the peer: the same request, no state collected
            bare.append(time.perf_counter_ns() - t0)
        p = lambda v, q: np.percentile(v, q) / 1e3  # noqa: E731
        print(f"  single step round trip with its state: p50 {p(rtt, 50):.0f} us, p99 "
              f"{p(rtt, 99):.0f} us; peer (the step request alone): p50 {p(bare, 50):.0f} us, "
              f"p99 {p(bare, 99):.0f} us")
    finally:
        stop(server)


def realtime(tmp):
    server = start([SERVER, "--world", "flat", "--domain", str(DOMAIN), "--duration",
                    str(REALTIME_S + 30)], os.path.join(tmp, "realtime.log"))
    try:
        sim = vdyn.Client(domain=DOMAIN, timeout=30)
        with sim.subscribe(1) as sub:
            sub.next()
            rss0, n, t0 = rss_mb(), 0, time.monotonic()
            first = last = None
            rss_mid = None
            while time.monotonic() - t0 < REALTIME_S:
                s = sub.take() if sub.queued else sub.next()
                if len(s):
                    first = s.step[0] if first is None else first
                    last = s.step[-1]
                    n += len(s)
                if rss_mid is None and time.monotonic() - t0 > REALTIME_S / 2:
                    rss_mid = rss_mb()
            span = int(last - first + 1)
            print(f"real time: {n} states of vehicle 1 in {REALTIME_S:g} s into Python, steps "
                  f"{first}..{last} ({span} steps): missing {sub.missing_steps} (DDS reports "
                  f"{sub.dds_lost} dropped by the reader), queue overflow {sub.overflowed}; RSS {rss0:.1f} MB at the start, {rss_mid:.1f} MB halfway, "
                  f"{rss_mb():.1f} MB at the end")
    finally:
        stop(server)


def recording(tmp):
    path = os.path.join(tmp, "long.mcap")
    rec = start([RECORDER, "record", path, "--domain", str(DOMAIN), "--status"],
                os.path.join(tmp, "rec.log"))
    server = start([SERVER, "--lockstep", "--lockstep-timeout", "120", "--world", "flat",
                    "--domain", str(DOMAIN)], os.path.join(tmp, "rec-server.log"))
    deadline = time.monotonic() + 60
    while "hearing 1 writer(s) on vdyn/state" not in open(os.path.join(tmp, "rec.log")).read():
        assert time.monotonic() < deadline, "the recorder did not hear the server"
        time.sleep(0.1)
    sim = vdyn.Client(domain=DOMAIN, timeout=60)
    steps = int(RECORDING_S * 1000)
    for k in range(steps // 1000):
        sim.step(1000, vdyn.make_input(steer=0.02 * np.sin(k / 10), cruise_kmh=50, vehicle_id=1))
    stop(server, 15)
    stop(rec)
    size = os.path.getsize(path) / 1e6
    t0 = time.perf_counter()
    states = vdyn.Recording(path).states(1)
    t_py = time.perf_counter() - t0
    csv = os.path.join(tmp, "long.csv")
    t0 = time.perf_counter()
    subprocess.run([RECORDER, "export", path, "--csv", csv], check=True, capture_output=True)
    t_export = time.perf_counter() - t0
    import pandas as pd
    t0 = time.perf_counter()
    df = pd.read_csv(csv)
    t_pandas = time.perf_counter() - t0
    assert len(df) == len(states)
    print(f"recording of {RECORDING_S:g} s ({len(states)} states, {size:.0f} MB): "
          f"vdyn.Recording(...).states(1) {t_py:.2f} s; vdyn-recorder export {t_export:.2f} s + "
          f"pandas.read_csv {t_pandas:.2f} s = {t_export + t_pandas:.2f} s "
          f"({(t_export + t_pandas) / t_py:.1f}x)")


def main():
    with tempfile.TemporaryDirectory() as tmp:
        lockstep(tmp)
        if REALTIME_S > 0:
            realtime(tmp)
        if RECORDING_S > 0:
            recording(tmp)


if __name__ == "__main__":
    main()
