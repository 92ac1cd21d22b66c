"""What a Python client costs beside a busy real-time server: a vdyn.Client that only connects
(idle), then one that polls client.latest(5) at 100 Hz; its CPU (% of one core, os.times) and
peak RSS, with a vdyn-server of VEHICLES vehicles on `flat` at 1 kHz over loopback.

    PYTHONPATH=build/release/clients/python/package \\
        python3 bench/python_reader_cost.py build/release [VEHICLES=128] [RUNS=3] [PEER_PACKAGE]

With PEER_PACKAGE (another build's clients/python/package directory), each run measures the peer
and this build one after the other against the same server (each in a process of its own)."""

import os
import random
import subprocess
import sys
import time

CHILD = r"""
import os, resource, sys, time
import vdyn
def cpu():
    t = os.times()
    return t.user + t.system
client = vdyn.Client(domain=int(sys.argv[1]), timeout=30)
time.sleep(2.0)
a, t0 = cpu(), time.monotonic()
time.sleep(6.0)
idle = 100 * (cpu() - a) / (time.monotonic() - t0)
idle_rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
a, t0 = cpu(), time.monotonic()
for _ in range(400):
    client.latest(5)
    time.sleep(0.01)
polling = 100 * (cpu() - a) / (time.monotonic() - t0)
rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
readers = getattr(client, "state_readers", "(not reported)")
print(f"idle {idle:.1f} % of a core, peak RSS {idle_rss:.0f} MB; latest(5) at 100 Hz "
      f"{polling:.1f} %, peak RSS {rss:.0f} MB; state readers {readers}")
"""


def main():
    build = sys.argv[1] if len(sys.argv) > 1 else "build/release"
    vehicles = int(sys.argv[2]) if len(sys.argv) > 2 else 128
    runs = int(sys.argv[3]) if len(sys.argv) > 3 else 3
    peer = sys.argv[4] if len(sys.argv) > 4 else None
    env = dict(os.environ)
    env.setdefault("CYCLONEDDS_URI",
                   '<General><Interfaces><NetworkInterface name="lo"/></Interfaces></General>')
    domain = 150 + random.randrange(60)
    ids = ",".join(str(i) for i in range(1, vehicles + 1))
    server = subprocess.Popen(
        [os.path.join(build, "server", "vdyn-server"), "--domain", str(domain), "--world", "flat",
         "--no-status", "--max-vehicles", str(vehicles), "--vehicle-ids", ids],
        env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        time.sleep(2.0)
        this = os.path.join(build, "clients", "python", "package")
        print(f"python_reader_cost: {vehicles} vehicles, {runs} runs; load average "
              f"{os.getloadavg()[0]:.2f}", flush=True)
        for run in range(1, runs + 1):
            for name, package in ([("peer", peer)] if peer else []) + [("this build", this)]:
                child_env = dict(env, PYTHONPATH=package)
                out = subprocess.run([sys.executable, "-c", CHILD, str(domain)], env=child_env,
                                     capture_output=True, text=True, timeout=120)
                line = out.stdout.strip() or out.stderr.strip().splitlines()[-1]
                print(f"run {run}, {name}: {line}", flush=True)
    finally:
        server.terminate()
        server.wait(timeout=30)


if __name__ == "__main__":
    main()
