"""Fixtures of the vdyn Python tests: a fresh DDS domain (the same lock files as the C++ tests,
tests/process.cc), DDS on loopback only, and real vdyn-server / vdyn-recorder processes.

Run by ctest (clients/python/CMakeLists.txt), which sets VDYN_BUILD_DIR and PYTHONPATH."""

import fcntl
import os
import subprocess
import time

import pytest

import vdyn

BUILD = os.environ.get("VDYN_BUILD_DIR", "")
SERVER = os.path.join(BUILD, "server", "vdyn-server")
RECORDER = os.path.join(BUILD, "clients", "recorder", "vdyn-recorder")

os.environ["CYCLONEDDS_URI"] = (
    '<General><Interfaces><NetworkInterface name="lo"/></Interfaces></General>'
    "<Discovery><MaxAutoParticipantIndex>120</MaxAutoParticipantIndex></Discovery>")
os.environ.setdefault("MPLBACKEND", "Agg")

_held = []


def fresh_domain():
    """A DDS domain among 100..229 no other test process on this machine uses now."""
    start = os.getpid() % 130
    for k in range(130):
        domain = 100 + (start + k) % 130
        fd = os.open(f"/tmp/vdyn-test-domain-{domain}.lock", os.O_CREAT | os.O_RDWR, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            continue
        _held.append(fd)
        return domain
    raise RuntimeError("no free DDS domain among 100..229 for this test")


class Proc:
    """A child process with its output in a log file; stopped (bounded) at the end."""

    def __init__(self, args, log_path):
        self.log_path = log_path
        self._log = open(log_path, "wb")
        self.p = subprocess.Popen(args, stdout=self._log, stderr=subprocess.STDOUT)

    def log(self):
        with open(self.log_path, "rb") as f:
            return f.read().decode(errors="replace")

    def wait_for(self, text, timeout=60):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if all(t in self.log() for t in ([text] if isinstance(text, str) else text)):
                return True
            if self.p.poll() is not None:
                return False
            time.sleep(0.05)  # polls a log file: there is no event to wait on
        return False

    def stop(self, sig=2, timeout=60):
        if self.p.poll() is None:
            self.p.send_signal(sig)
            try:
                self.p.wait(timeout)
            except subprocess.TimeoutExpired:
                self.p.kill()
                self.p.wait(10)
        self._log.close()
        return self.p.returncode


@pytest.fixture
def domain():
    return fresh_domain()


@pytest.fixture
def start(tmp_path):
    """start(args, name) runs a program of the build for the test's duration."""
    procs = []

    def run(args, name):
        p = Proc(args, str(tmp_path / f"{name}.log"))
        procs.append(p)
        return p

    yield run
    for p in reversed(procs):
        p.stop()


@pytest.fixture
def lockstep_server(start, domain):
    return start([SERVER, "--lockstep", "--lockstep-timeout", "60", "--domain", str(domain)],
                 "server")


@pytest.fixture
def realtime_server(start, domain):
    return start([SERVER, "--domain", str(domain), "--duration", "60"], "server")


@pytest.fixture(scope="session")
def recorded_run(tmp_path_factory):
    """A lockstep run of 2000 steps recorded by vdyn-recorder: (file, the States each step
    call returned). Made once for the tests that read it."""
    tmp_path = tmp_path_factory.mktemp("recorded")
    domain = fresh_domain()
    out = tmp_path / "run.mcap"
    rec = Proc([RECORDER, "record", str(out), "--domain", str(domain), "--status"],
               str(tmp_path / "recorder.log"))
    server = Proc([SERVER, "--lockstep", "--lockstep-timeout", "60", "--domain", str(domain)],
                  str(tmp_path / "server.log"))
    try:
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
    finally:
        server.stop()
        rec.stop()
    return out, got
