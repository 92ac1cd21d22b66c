"""The vdyn package against a real vdyn-server: connect, control, lockstep, real time, driving."""

import math
import os
import subprocess
import sys
import threading
import time
import warnings

import numpy as np
import pytest

import vdyn
from conftest import SERVER


def test_connect_gives_the_world_and_the_vehicles(lockstep_server, domain):
    sim = vdyn.Client(domain=domain, timeout=30)
    assert sim.server_id == "vdyn"
    assert sim.world_name == "facility"
    assert sim.world_hash != 0
    assert sim.step_s == pytest.approx(1e-3)
    assert sim.vehicles == [1]
    assert sim.params(1).mass > 0
    # The server id named explicitly finds the same server; another one is not there.
    assert vdyn.Client(domain=domain, server_id="vdyn", timeout=30).world_hash == sim.world_hash


def test_a_wait_with_no_server_raises_within_its_timeout(domain):
    t0 = time.monotonic()
    with pytest.raises(vdyn.TimeoutError, match=f"^no vdyn server on DDS domain {domain} answered"):
        vdyn.Client(domain=domain, timeout=1.0)
    assert time.monotonic() - t0 < 6.0  # 1 s, and generous room for a loaded machine


def test_ctrl_c_ends_a_wait(domain):
    # Every wait runs with the GIL released; Ctrl-C (SIGINT) came only when the call returned: a
    # wait without end (timeout 1e10 s) could not be stopped. Now a KeyboardInterrupt ends it.
    script = (
        "import os, signal, sys, threading, time\n"
        "import vdyn\n"
        "threading.Timer(1.0, lambda: os.kill(os.getpid(), signal.SIGINT)).start()\n"
        "try:\n"
        f"    vdyn.Client(domain={domain}, timeout=1e10)\n"
        "except KeyboardInterrupt:\n"
        "    print('interrupted')\n")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=120)
    assert done.stdout.strip() == "interrupted", done.stdout + done.stderr


def test_a_small_socket_buffer_cap_is_said_once(monkeypatch):
    # On a fresh Debian (rmem_max 208 KiB) a step() whose reader fell 0.1 s behind lost states and
    # timed out with nothing said of why.
    import io
    from vdyn import _client
    monkeypatch.setattr(_client, "_said_receive_buffer", False)
    monkeypatch.setattr(_client, "open", lambda *a, **k: io.StringIO("212992\n"), raising=False)
    with pytest.warns(UserWarning, match="net.core.rmem_max is 212992 bytes"):
        _client._say_receive_buffer()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _client._say_receive_buffer()  # once a process


def test_a_thread_reading_counts_while_another_steps_does_not_deadlock(lockstep_server, domain):
    # The Ctrl-C check between waits once took the GIL while the stepping thread held the client's
    # lock; a thread holding the GIL and asking for states_received (that lock) then waited for
    # ever, and so did the stepping thread. Run in a process of its own, bounded.
    script = (
        "import threading, vdyn\n"
        f"c = vdyn.Client(domain={domain}, timeout=30)\n"
        "def steps():\n"
        "    for _ in range(100):\n"
        "        c.step(5)\n"
        "t = threading.Thread(target=steps)\n"
        "t.start()\n"
        "n = 0\n"
        "while t.is_alive():\n"
        "    n += len(c.states_received) + len(c.state_readers)\n"
        "t.join()\n"
        "print('done', c.states_received[1] >= 500)\n")
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=120)
    assert done.stdout.strip() == "done True", done.stdout + done.stderr


def test_a_named_server_that_is_absent_raises(lockstep_server, domain):
    # Said as what happened: no server of that id answered (the one there is named).
    with pytest.raises(vdyn.TimeoutError,
                       match=f"^no vdyn server with the id 'elsewhere' on DDS domain {domain} "
                       r"answered within 2 s: .*\(worlds seen: vdyn\)"):
        vdyn.Client(domain=domain, server_id="elsewhere", timeout=2.0)


def test_lockstep_returns_every_state_of_the_steps_with_the_input_applied(lockstep_server, domain):
    sim = vdyn.Client(domain=domain, timeout=30)
    inp = vdyn.make_input(steer=0.02, throttle=0.4, vehicle_id=1)
    s = sim.step(1000, inp)[1]
    assert len(s) == 1000
    assert np.array_equal(s.step, np.arange(1000, dtype=np.uint64))
    assert np.allclose(s.t, s.step * 1e-3)
    assert np.all(s["steer_in_rad"] == 0.02) and np.all(s["throttle_in"] == 0.4)
    # The car accelerates from rest under throttle: the speed grows.
    assert s.speed_kmh[-1] > s.speed_kmh[0] + 1.0
    # The next call continues where this one ended, one state per step (batches of one too).
    for k in range(5):
        one = sim.step(1)[1]
        assert list(one.step) == [1000 + k]
    assert s.wheel("Fp_N").shape == (1000, 4)
    assert np.all(s.state_hash != 0)


def test_a_step_the_server_discards_is_said_not_waited_for(lockstep_server, domain):
    # A car that rolls over (mu 3, the road wheels at 30 degrees at 60 km/h) falls through the
    # ground, which this model has no body contact for: the server discards that step, puts the
    # car back on its wheels and publishes no state for it. step() waited its whole timeout for
    # that state and raised TimeoutError; the server's reply now says which step went, and why.
    sim = vdyn.Client(domain=domain, timeout=30)
    sim.set_params(1, {"mu": 3.0})
    sim.teleport(1, 0.0, 0.0, 0.0, speed=60 / 3.6)
    inp = vdyn.make_input(steer=0.52, cruise_kmh=60, vehicle_id=1)
    said = []
    got = []
    for _ in range(10):  # it rolls over within some 1.3 s
        with warnings.catch_warnings(record=True) as w:
            warnings.simplefilter("always")
            got.append(sim.step(500, inp, timeout=30)[1])
        said += [x for x in w if issubclass(x.category, vdyn.DiscardedStepsWarning)]
        if said:
            break
    assert len(said) == 1, [str(x.message) for x in said]
    text = str(said[0].message)
    assert text.startswith("vehicle 1: 1 step(s) discarded by server 'vdyn', the first its step ")
    assert "it fell through the ground (its wheels off the ground" in text
    assert "): put back on its wheels where it was" in text
    gone = int(text.split("the first its step ")[1].split(" ")[0])
    # That call's states: every step but the discarded one; the car on its wheels after it.
    last = got[-1]
    assert len(last) == 499
    steps = [int(k) for k in last.step]
    assert gone not in steps and gone - 1 in steps and gone + 1 in steps
    assert abs(float(last["roll_rad"][steps.index(gone + 1)])) < 0.2
    # And the session goes on: the next call has every state.
    assert len(sim.step(100, inp, timeout=30)[1]) == 100


def test_one_client_stepped_from_two_threads_gives_each_its_own_steps(lockstep_server, domain):
    # Two threads stepping one Client crashed it (both made the step reader at once: SIGSEGV) or,
    # once made, one thread took the other's states and timed out. Its steps now run one at a time.
    sim = vdyn.Client(domain=domain, timeout=30)
    got, errors = [], []

    def run():
        try:
            for _ in range(3):
                got.append([int(k) for k in sim.step(700)[1].step])
        except Exception as e:  # noqa: BLE001  (any error fails the test below)
            errors.append(e)

    threads = [threading.Thread(target=run) for _ in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(120)
    assert not errors, errors
    assert len(got) == 6 and all(len(g) == 700 for g in got)
    # Each call has 700 consecutive steps; together every step of the 4200 once.
    assert all(g == list(range(g[0], g[0] + 700)) for g in got)
    assert sorted(k for g in got for k in g) == list(range(4200))


def test_vehicles_removed_or_spawned_by_another_client_do_not_stall_steps(lockstep_server,
                                                                          domain):
    # A vehicle another client removed stayed in this client's list: every later step() waited its
    # whole timeout for that vehicle's states and raised TimeoutError.
    a = vdyn.Client(domain=domain, timeout=30)
    b = vdyn.Client(domain=domain, timeout=30)
    b.spawn(14, 60.0, 40.0)
    assert sorted(a.step(10, timeout=30)) == [1, 14]
    b.despawn(14)
    t0 = time.monotonic()
    for _ in range(3):
        assert sorted(a.step(10, timeout=30)) == [1]
    assert time.monotonic() - t0 < 25  # no step waited out its 30 s (generous for a loaded machine)
    assert 14 not in a.vehicles
    # Driving the removed vehicle is refused with the reason, before anything is stepped.
    with pytest.raises(ValueError, match="vehicle 14"):
        a.step(1, vdyn.make_input(), vehicle_id=14)


def test_a_vehicle_removed_during_a_step_call_says_how_far_the_call_got(lockstep_server, domain):
    # Removed by another client while a long step() drove it: the error said "50 steps ran
    # without it" (the last request's) where thousands had run, their states thrown away unsaid.
    a = vdyn.Client(domain=domain, timeout=60)
    b = vdyn.Client(domain=domain, timeout=60)
    a.spawn(21, 60.0, 40.0)
    errors = []

    def remove_once_stepping():
        try:
            b.latest(21, timeout=60)  # a lockstep server publishes states only while it steps
            b.despawn(21)
        except Exception as e:  # noqa: BLE001  (any error fails the test below)
            errors.append(e)

    t = threading.Thread(target=remove_once_stepping)
    t.start()
    with pytest.raises(ValueError, match=r"no vehicle 21 on server 'vdyn': \d+ steps ran without "
                                         r"it .*; it went during this step\(\) call, \d+ of its "
                                         r"200000 steps after the start"):
        a.step(200000, vdyn.make_input(throttle=0.1), vehicle_id=21, timeout=120)
    t.join(60)
    assert not errors, errors


def test_a_removed_vehicle_is_gone_for_clients_that_join_later(lockstep_server, domain):
    # The server kept a removed vehicle's parameters on vdyn/params (a transient-local history):
    # a client joining later counted it as there (params() answered, step() ran without it).
    b = vdyn.Client(domain=domain, timeout=30)
    b.spawn(7, 60.0, 40.0)
    assert b.params(7).mass > 0
    b.despawn(7)
    late = vdyn.Client(domain=domain, timeout=30)
    assert late.vehicles == [1]
    with pytest.raises(vdyn.TimeoutError):
        late.params(7, timeout=2)
    with pytest.raises(ValueError, match="vehicle 7"):
        late.step(1, vdyn.make_input(), vehicle_id=7)
    # A vehicle spawned again under that id has its parameters again.
    b.spawn(7, 60.0, 40.0, params={"mass": 1234.0})
    assert vdyn.Client(domain=domain, timeout=30).params(7).mass == 1234.0


def test_a_client_of_one_server_does_not_answer_with_anothers_vehicle(start, domain):
    # Two servers on one domain: a client of 'ls' (vehicle 2) asked for vehicle 1 got 'rt''s
    # vehicle 1 from latest() and subscribe(), with no word of the other server.
    start([SERVER, "--server-id", "rt", "--domain", str(domain), "--duration", "60"], "rt")
    start([SERVER, "--lockstep", "--lockstep-timeout", "60", "--server-id", "ls",
           "--vehicle-ids", "2", "--domain", str(domain)], "ls")
    rt = vdyn.Client(domain=domain, server_id="rt", timeout=30)
    assert rt.latest(1).step.size == 1  # rt's vehicle 1 is there and live
    ls = vdyn.Client(domain=domain, server_id="ls", timeout=30)
    sub = ls.subscribe(1)
    with pytest.raises(vdyn.TimeoutError):
        ls.latest(1, timeout=2)
    with pytest.raises(vdyn.TimeoutError):
        sub.next(timeout=1)
    sub.close()
    assert list(ls.step(3)) == [2]
    assert int(ls.latest(2).step[0]) == 2


def test_the_world_of_a_restarted_server_is_read_again(start, domain):
    # A client kept the first world it read for ever: after its server restarted on facility it
    # still said 'flat' while latest() gave positions on facility.
    first = start([SERVER, "--lockstep", "--lockstep-timeout", "60", "--world", "flat",
                   "--domain", str(domain)], "flat")
    sim = vdyn.Client(domain=domain, timeout=30)
    assert sim.world_name == "flat"
    flat_hash = sim.world_hash
    first.stop()
    start([SERVER, "--lockstep", "--lockstep-timeout", "60", "--world", "facility",
           "--domain", str(domain)], "facility")
    deadline = time.monotonic() + 60
    while sim.world_name != "facility" and time.monotonic() < deadline:
        time.sleep(0.05)  # the world arrives on DDS: no event this test can wait on
    assert sim.world_name == "facility"
    assert sim.world_hash != flat_hash


def test_a_subscription_counts_the_restarts_of_its_server(start, domain):
    # A subscription ran straight across a server restart (step 3999 then 0, x jumping 250 m)
    # with nothing to tell it: it counts them.
    first = start([SERVER, "--lockstep", "--lockstep-timeout", "60", "--domain", str(domain)],
                  "first")
    a = vdyn.Client(domain=domain, timeout=30)
    sub = a.subscribe(1)
    a.step(300)
    first.stop()
    start([SERVER, "--lockstep", "--lockstep-timeout", "60", "--domain", str(domain)], "second")
    b = vdyn.Client(domain=domain, timeout=30)
    b.step(200)
    deadline = time.monotonic() + 60
    while sub.restarts < 1 and time.monotonic() < deadline:
        time.sleep(0.05)  # the states arrive on DDS: no event this test can wait on
    assert sub.restarts == 1
    # The states of the two starts follow one another: the steps go back once, where it restarted.
    steps = [int(k) for k in sub.take().step]
    assert sum(1 for p, q in zip(steps, steps[1:]) if q < p) == 1, steps
    sub.close()


def test_small_api_edges_answer_rightly(lockstep_server, domain):
    sim = vdyn.Client(domain=domain, timeout=30)
    s = sim.step(5)[1]
    # Per-wheel columns whose wheel tag is not second (kappa_t_LF, alpha_t_LF_rad) were a KeyError.
    assert s.wheel("kappa_t").shape == (5, 4)
    assert np.array_equal(s.wheel("alpha_t_rad")[:, 0], s["alpha_t_LF_rad"])
    with pytest.raises(KeyError, match="no per-wheel column 'nope'"):
        s.wheel("nope")
    # A closed subscription's next() waited its whole timeout, then said no state arrived.
    sub = sim.subscribe(1)
    sub.close()
    t0 = time.monotonic()
    with pytest.raises(vdyn.TimeoutError, match="is closed"):
        sub.next(timeout=30)
    assert time.monotonic() - t0 < 10
    # Closed from another thread while next() waits: next() raises then, not at its timeout.
    sub = sim.subscribe(1)
    t0 = time.monotonic()
    closer = threading.Timer(0.5, sub.close)
    closer.start()
    with pytest.raises(vdyn.TimeoutError, match="is closed"):
        sub.next(timeout=60)
    closer.join()
    assert time.monotonic() - t0 < 30
    # A capacity the queue cannot hold (reserved up front) was a bad_alloc.
    with pytest.raises(ValueError, match=r"capacity must be in \[1, 10000000\] states"):
        sim.subscribe(1, capacity=2 ** 40)


def test_a_wait_for_a_vehicle_the_server_does_not_have_says_so(lockstep_server, domain):
    # latest() and params() of vehicle 999 timed out saying a lockstep server publishes states
    # only while it steps (or nothing), though the server has no vehicle 999: now they name the
    # vehicles it has. A first step() with timeout 0 blamed the world for not arriving.
    sim = vdyn.Client(domain=domain, timeout=30)
    with pytest.raises(vdyn.TimeoutError,
                       match=r"within 0 s \(a new reader takes some milliseconds to be matched"):
        sim.step(1, timeout=0)
    with pytest.raises(vdyn.TimeoutError,
                       match=r"no state of vehicle 999 arrived on vdyn/state within 0.5 s "
                             r"\(server 'vdyn' has no vehicle 999: its vehicle is 1\)"):
        sim.latest(999, timeout=0.5)
    with pytest.raises(vdyn.TimeoutError,
                       match=r"no parameters of vehicle 999 arrived on vdyn/params within 0.5 s "
                             r"\(server 'vdyn' has no vehicle 999: its vehicle is 1\)"):
        sim.params(999, timeout=0.5)
    # A vehicle that is there but sends nothing (lockstep, not stepping) keeps the old reason.
    with pytest.raises(vdyn.TimeoutError, match="publishes states only while it steps"):
        sim.latest(1, timeout=0.5)


def test_a_removed_vehicle_has_no_parameters(lockstep_server, domain):
    # params() of a vehicle this client removed answered with its old parameters (the reader kept
    # the instance its server disposed); another client's view forgets them as well.
    sim = vdyn.Client(domain=domain, timeout=30)
    other = vdyn.Client(domain=domain, timeout=30)
    sim.spawn(7, 0.0, 20.0, params={"mass": 1234.0})
    assert sim.params(7).mass == 1234.0 and other.params(7).mass == 1234.0
    sim.despawn(7)
    with pytest.raises(vdyn.TimeoutError, match=r"server 'vdyn' has no vehicle 7"):
        sim.params(7, timeout=0.5)
    # The other client hears the disposal on its own reader, some time after the reply.
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        try:
            other.params(7, timeout=0)
        except vdyn.TimeoutError:
            break
        time.sleep(0.05)  # the disposal arrives on DDS: no event this test can wait on
    with pytest.raises(vdyn.TimeoutError, match=r"no parameters of vehicle 7"):
        other.params(7, timeout=0.5)


def test_latest_waiting_in_one_thread_does_not_hold_up_step_in_another(lockstep_server, domain):
    # latest() held the client's lock for its whole wait: a step() in another thread, which would
    # bring the state it waited for, could not run until latest() timed out.
    sim = vdyn.Client(domain=domain, timeout=60)
    result = {}

    def wait_latest():
        try:
            result["state"] = sim.latest(1, timeout=60)
        except Exception as e:  # noqa: BLE001
            result["error"] = e

    t = threading.Thread(target=wait_latest)
    t.start()
    sim.step(50, timeout=60)
    t.join(90)
    assert "error" not in result, result.get("error")
    assert len(result["state"]) == 1 and int(result["state"].step[0]) < 50


def test_control_requests_and_refusals_carry_the_servers_reason(lockstep_server, domain):
    sim = vdyn.Client(domain=domain, timeout=30)
    with pytest.raises(vdyn.RefusedError) as refused:
        sim.spawn(1, 0.0, 0.0)
    assert "exists" in refused.value.reason
    with pytest.raises(vdyn.RefusedError, match="lockstep"):
        sim.resume()
    sim.pause()
    # Spawn with partial parameters, step, see it move, teleport it, reset it, remove it.
    reply = sim.spawn(2, 0.0, 10.0, yaw=0.0, speed=5.0, params={"mass": 1234.0})
    assert reply["server_id"] == "vdyn"
    assert sim.params(2).mass == 1234.0
    assert 2 in sim.vehicles
    both = sim.step(50)
    assert set(both) == {1, 2}
    assert both[2].vx_mps[-1] > 3.0
    sim.teleport(2, 20.0, 30.0, yaw=math.pi / 2)
    moved = sim.step(1)[2]
    assert moved.x_m[0] == pytest.approx(20.0, abs=0.05)
    assert moved.y_m[0] == pytest.approx(30.0, abs=0.05)
    assert moved.yaw_rad[0] == pytest.approx(math.pi / 2, abs=0.01)
    sim.set_params(2, {"mass": 1500.0})
    assert sim.params(2).mass == 1500.0  # set_params returns once vdyn/params shows it
    with pytest.raises(vdyn.RefusedError, match="mass"):
        sim.set_params(2, {"mass": -1.0})
    with pytest.raises(vdyn.RefusedError) as nan:
        sim.set_params(2, vdyn.pb.VehicleParams(mass=float("nan")))
    assert nan.value.reason
    with pytest.raises(ValueError, match="massive"):
        sim.set_params(2, {"massive": 1.0})
    sim.reset(2)
    back = sim.step(1)[2]
    assert back.x_m[0] == pytest.approx(0.0, abs=0.05)
    assert back.y_m[0] == pytest.approx(10.0, abs=0.05)
    sim.despawn(2)
    assert sim.vehicles == [1]
    assert set(sim.step(3)) == {1}
    # A restore to a state behind the vehicle's step is refused with the reason.
    with pytest.raises(vdyn.RefusedError) as behind:
        sim.restore(1, vdyn.pb.ExactState())
    assert behind.value.reason


def test_bad_arguments_are_refused_before_sending(lockstep_server, domain):
    sim = vdyn.Client(domain=domain, timeout=30)
    with pytest.raises(ValueError):
        sim.step(0)
    with pytest.raises(ValueError):
        sim.step(1, timeout=float("nan"))
    with pytest.raises(ValueError, match="steer_mode"):
        vdyn.make_input(steer_mode="sideways")
    with pytest.raises(ValueError, match=r"buttons must be in \[0, 4294967295\], got -1"):
        vdyn.make_input(buttons=-1)  # protobuf said "Value out of range: -1", naming nothing


def test_a_driver_drives_and_the_subscription_loses_no_state(realtime_server, domain):
    sim = vdyn.Client(domain=domain, timeout=30)
    weak = sim.driver(1, source_id="py-backup", strength=5)
    with sim.driver(1, source_id="py-rig", strength=20) as drv, weak, sim.subscribe(1) as sub:
        drv.wait_for_server()
        weak.wait_for_server()
        weak.start(1000.0, vdyn.make_input(throttle=0.1))

        def until(throttle, limit=30000):
            for k, s in enumerate(sub):  # each wait bounded by the client's timeout
                assert k < limit, f"throttle {throttle} never reached the states"
                if s.throttle_in[0] == throttle:
                    return s
            raise AssertionError("the states stopped")

        # The weaker source drives alone; the stronger one takes the vehicle when it starts (with
        # equal strengths the current source would keep it).
        until(0.1)
        drv.start(1000.0, vdyn.make_input(throttle=0.3))
        first = until(0.3, limit=2000)
        newest = sim.latest(1)
        assert newest.throttle_in[0] == 0.3 and newest.step[0] >= first.step[0]
        states = [sub.next()]
        while sum(len(s) for s in states) < 1500:
            states.append(sub.take() if sub.queued else sub.next())
        steps = np.concatenate([s.step for s in states])
        assert np.array_equal(steps, np.arange(steps[0], steps[0] + len(steps), dtype=np.uint64))
        # The stronger source drives. On a loaded machine its 1 kHz sender may stall past the lease
        # (75 ms): the backup drives meanwhile (0.1) and the stronger one takes the vehicle back at
        # its next sample (2026-12-05, beside two builds); were both stalled, the watchdog's safe
        # state (no throttle). Nothing else is ever applied.
        throttle = np.concatenate([s.throttle_in for s in states])
        assert np.all((throttle == 0.3) | (throttle == 0.1) | (throttle == 0.0)), np.unique(throttle)
        assert np.count_nonzero(throttle == 0.3) >= 0.9 * len(throttle) and throttle[-1] == 0.3
        assert sub.missing_steps == 0 and sub.overflowed == 0 and sub.dds_lost == 0
        # When it stops, the weaker one takes the vehicle after the lease (docs/topics.md).
        drv.stop()
        until(0.1)
        assert drv.sent > 0 and drv.failed == 0 and weak.failed == 0


def test_a_client_receives_only_the_states_it_asks_for(realtime_server, domain):
    """Which states arrive at a client: none while it connects, spawns and reads parameters;
    latest(v) brings vehicle v's states only (read in its partition: the server sends the
    others' elsewhere); latest(w) then brings w's too. (Before, every client took every state
    from its start: beside 128 vehicles, 13.5 % of a core and 350 MB of history while idle.)"""
    sim = vdyn.Client(domain=domain, timeout=30)
    spawn = sim.world.spawn
    sim.spawn(2, spawn.x, spawn.y, spawn.yaw)
    assert sim.params(2).mass > 0
    assert sim.states_received == {}

    def until(vehicle, count):
        """latest(vehicle) until `count` of its states have arrived (about count ms at 1 kHz)."""
        for _ in range(10000):
            sim.latest(vehicle)
            if sim.states_received.get(vehicle, 0) >= count:
                return
            time.sleep(0.005)
        raise AssertionError(f"{count} states of vehicle {vehicle} never arrived: "
                             f"{sim.states_received}")

    until(2, 200)
    assert set(sim.states_received) == {2}, sim.states_received  # nothing of vehicle 1
    seen_2 = sim.states_received[2]
    until(1, 200)
    assert set(sim.states_received) == {1, 2}
    until(2, seen_2 + 100)  # vehicle 2's keep arriving


def test_the_first_lockstep_step_gets_its_states_from_a_reader_made_for_it(lockstep_server, domain):
    """The reader of every vehicle's states is made by the first step(), and the server knows it
    before it steps: not one state of that first step is missing, and none arrived before."""
    for _ in range(3):
        sim = vdyn.Client(domain=domain, timeout=30)
        assert sim.states_received == {}
        first = sim.step(1)[1]
        assert len(first) == 1
        assert sim.states_received == {1: 1}


def test_an_input_the_server_would_not_apply_raises_before_stepping(lockstep_server, domain):
    """Out of range, not a number, or for a vehicle the server does not have: a ValueError with
    the server's own reason (its table of limits), and not one step is run. (Before, the steps ran
    with the previous input and returned normally; only the server's log said why.)"""
    sim = vdyn.Client(domain=domain, timeout=30)
    before = sim.step(1, vdyn.make_input(throttle=0.3), vehicle_id=1)[1].step[0]

    def refused(inp, match, vehicle_id=1):
        with pytest.raises(ValueError, match=match):
            sim.step(10, inp, vehicle_id=vehicle_id)

    refused(vdyn.pb.DriverInput(throttle=2.0), r"throttle must be in \[-1, 1\], got 2")
    refused(vdyn.pb.DriverInput(steer=1.6),
            r"steer \(front road-wheel angle, rad\) must be in \[-1.5, 1.5\], got 1.6")
    refused(vdyn.pb.DriverInput(brake=float("nan")), r"brake must be a finite number, got nan")
    refused({"gear": 11}, r"gear must be in \[-1, 10\], got 11")
    refused(vdyn.pb.DriverInput(source_id="s" * 65, throttle=0.1),
            r"source_id is 65 bytes long; a server takes at most 64 bytes")
    refused(vdyn.make_input(throttle=0.1), r"no vehicle 999 on server 'vdyn' \(its vehicle is 1\)",
            vehicle_id=999)
    # make_input refuses at once, with the same reason.
    with pytest.raises(ValueError, match=r"throttle must be in \[-1, 1\], got 2"):
        vdyn.make_input(throttle=2.0)
    with pytest.raises(ValueError, match=r"steer \(front road-wheel angle, rad\)"):
        vdyn.make_input(steer=1.6)
    # Nothing was stepped: the next step is the one after the last good one, with its input.
    after = sim.step(1)[1]
    assert after.step[0] == before + 1 and after.throttle_in[0] == 0.3
    # A vehicle spawned by another client is there (its parameters say so)...
    other = vdyn.Client(domain=domain, timeout=30)
    other.spawn(3, 0.0, 20.0)
    assert sim.params(3).mass > 0
    assert sim.step(5, vdyn.make_input(throttle=0.2), vehicle_id=3)[3].throttle_in[-1] == 0.2
    refused(vdyn.make_input(), r"no vehicle 998 on server 'vdyn' \(its vehicles are 1, 3\)",
            vehicle_id=998)
    # ... and one it removed behind this client's back is found missing by the steps themselves.
    other.despawn(3)
    with pytest.raises(ValueError, match=r"no vehicle 3 on server 'vdyn': 5 steps ran without it"):
        sim.step(5, vdyn.make_input(throttle=0.2), vehicle_id=3)


def test_a_driver_the_server_would_refuse_raises(lockstep_server, domain):
    sim = vdyn.Client(domain=domain, timeout=30)
    with pytest.raises(ValueError, match="source_id is 100 bytes long; a server takes at most 64"):
        sim.driver(1, source_id="d" * 100)
    with pytest.raises(ValueError, match=r"vehicle id must be in \[1, 4294967295\], got 0"):
        sim.driver(0)
    with pytest.raises(ValueError, match=r"ownership strength must be in \[0, 1000000\]"):
        sim.driver(1, strength=-1)
    drv = sim.driver(1, source_id="ok")
    with pytest.raises(ValueError, match=r"throttle must be in \[-1, 1\], got 5"):
        drv.send(vdyn.pb.DriverInput(throttle=5.0))
    with pytest.raises(ValueError, match=r"clutch must be a finite number"):
        drv.set(vdyn.pb.DriverInput(clutch=float("inf")))
    drv.send(vdyn.pb.DriverInput(throttle=0.5))
    assert drv.sent == 1 and drv.failed == 0
    # A refused start changes nothing: the input it carried is not set (it was, before the
    # refusal: a second start raised and its input was sent from then on).
    drv.start(1000.0, vdyn.make_input(throttle=0.2))
    try:
        with pytest.raises(RuntimeError, match="already running"):
            drv.start(500.0, vdyn.make_input(throttle=0.9))
    finally:
        drv.stop()
    with pytest.raises(ValueError, match=r"rate_hz must be in \[1/60, 10000\] \(at least one "
                                         r"input a minute\), got 0"):
        drv.start(0, vdyn.make_input(throttle=0.9))
    # 1e-10 Hz overflowed the period and aborted Python (SIGABRT).
    with pytest.raises(ValueError, match=r"rate_hz must be in \[1/60, 10000\]"):
        drv.start(1e-10, vdyn.make_input(throttle=0.9))
    assert not drv.running
    # stop() waited out the period (for ever at 1e-6 Hz, Ctrl-C or not): a minute's period ends
    # at once.
    slow = sim.driver(1, source_id="slow")
    slow.start(1.0 / 60.0, vdyn.make_input(throttle=0.1))
    t0 = time.monotonic()
    slow.stop()
    assert time.monotonic() - t0 < 30, "stop() waited out its period"
    assert not slow.running
    # What the driver holds now is what the first start set: a send() goes out with it.
    sent = drv.sent
    drv.start(1000.0)
    try:
        t0 = time.monotonic()
        while drv.sent < sent + 10 and time.monotonic() - t0 < 10:
            time.sleep(0.01)
    finally:
        drv.stop()
    s = sim.step(1)[1]  # lockstep: the newest input latched at the step
    assert s.throttle_in[0] == 0.2, s.throttle_in[0]


def test_parameters_and_steps_that_would_answer_wrongly_are_refused_or_answered_right(start, domain):
    tire = os.path.join(os.path.dirname(__file__), "..", "..", "..", "tires",
                        "vdyn_synthetic_205_55R16_mf61.tir")
    start([SERVER, "--lockstep", "--lockstep-timeout", "60", "--domain", str(domain),
           "--world", "flat", "--tire", tire], "server")
    sim = vdyn.Client(domain=domain, timeout=30)
    assert sim.params(1).lf.HasField("magic_formula")
    # The documented way back to the brush law: an empty tyre message. It returns once the
    # change shows (it waited its whole timeout, comparing a protobuf merge that cannot remove).
    t0 = time.monotonic()
    sim.set_params(1, {"lf": {"magic_formula": {}}}, timeout=20)
    assert time.monotonic() - t0 < 10
    assert not sim.params(1).lf.HasField("magic_formula")
    assert sim.params(1).rf.HasField("magic_formula")
    # A string where a number goes (protobuf's JSON mapping took "1800").
    with pytest.raises(TypeError, match=r"params\['mass'\] must be a number, got '1800' \(str\)"):
        sim.set_params(1, {"mass": "1800"})
    with pytest.raises(TypeError, match=r"params\['lf'\]\['radius'\] must be a number"):
        sim.set_params(1, {"lf": {"radius": "0.3"}})
    with pytest.raises(TypeError, match=r"params\['abs'\] must be True or False, got 0"):
        sim.set_params(1, {"abs": 0})
    # A NaN got protobuf's 'use quoted "NaN"' and an unknown name a list of camelCase names.
    with pytest.raises(ValueError, match=r"params\['mass'\] must be a finite number, got nan"):
        sim.set_params(1, {"mass": float("nan")})
    with pytest.raises(ValueError, match=r"params\['lf'\]\['radus'\]: no such parameter \(did "
                                         r"you mean radius\?\)"):
        sim.set_params(1, {"lf": {"radus": 0.3}})
    with pytest.raises(ValueError, match=r"params\['masss'\]: no such parameter \(did you mean "
                                         r"mass"):
        sim.set_params(1, {"masss": 1800.0})
    # vehicle_id without an input stepped every vehicle and ignored it (also one not there).
    with pytest.raises(ValueError, match="vehicle_id names the vehicle an input is for"):
        sim.step(1, None, vehicle_id=99)
    # The README said up to 2^32 - 1; a call takes at most 600,000 (the client said "steps must
    # be at most 600000" without naming n).
    for n in (-1, 0, 600_001, 2 ** 40):
        with pytest.raises(ValueError, match=rf"n must be in \[1, 600000\] steps .*, got {n}"):
            sim.step(n)
    # An id a server would ignore (over 64 bytes) is refused here; it timed out after the whole
    # wait saying no server answered.
    with pytest.raises(ValueError, match="client_id must be at most 64 bytes in UTF-8, got 65"):
        vdyn.Client(domain=domain, client_id="x" * 65, timeout=30)
    # An input naming one vehicle sent to another was sent to the other without a word.
    with pytest.raises(ValueError, match="the input names vehicle 2, but it goes to vehicle 1"):
        sim.step(1, vdyn.make_input(vehicle_id=2), vehicle_id=1)
    with pytest.raises(ValueError, match="the input names vehicle 2, but it goes to vehicle 1"):
        sim.driver(1).send(vdyn.make_input(vehicle_id=2))
    # latest() right after a lockstep step: the newest state the step brought (a reader made
    # after it had nothing, and the server sends nothing until the next step: it timed out).
    fresh = vdyn.Client(domain=domain, timeout=30)
    last = fresh.step(5)[1]
    newest = fresh.latest(1, timeout=2)
    assert newest.step[0] == last.step[-1]


def test_timeouts_of_any_length_and_durations_beyond_the_limit(lockstep_server, domain):
    """A timeout of 1e10 s or more waits (it failed at once: "no server answered", the deadline
    wrapped round into the past); a duration beyond the table's limit is refused at once (1e300
    ran for ever)."""
    for timeout in (1e10, 1e12, 1e300):
        sim = vdyn.Client(domain=domain, timeout=timeout)
        assert sim.params(1, timeout=timeout).mass > 0
        assert len(sim.step(2, timeout=timeout)[1]) == 2
    for duration, match in ((1e300, r"duration, s must be in \(0, 1e7\], got 1e300"),
                            (0.0, r"got 0"), (-1.0, r"got -1"), (float("nan"), "finite")):
        t0 = time.monotonic()
        with pytest.raises(ValueError, match=match):
            sim.run_maneuver("demo", duration=duration)
        assert time.monotonic() - t0 < 5.0  # refused before anything is sent


def test_arguments_of_the_wrong_type_are_refused(lockstep_server, domain):
    sim = vdyn.Client(domain=domain, timeout=30)
    bad = [
        (lambda: sim.step("10"), r"n must be a whole number, got '10' \(str\)"),
        (lambda: sim.step(2.5), r"n must be a whole number, got 2.5 \(float\)"),
        (lambda: sim.step(True), r"n must be a whole number, got True \(bool\)"),
        (lambda: sim.step(1, timeout="5"), r"timeout must be a number, got '5'"),
        (lambda: sim.step(1, vdyn.make_input(), vehicle_id="1"), "vehicle_id must be a whole"),
        (lambda: sim.spawn("2", 0.0, 0.0), "vehicle_id must be a whole number"),
        (lambda: sim.spawn(2, "0", 0.0), r"x must be a number, got '0' \(str\)"),
        (lambda: sim.teleport(1, 0.0, None), "y must be a number, got None"),
        (lambda: sim.latest(1.0), "vehicle_id must be a whole number"),
        (lambda: sim.params([1]), "vehicle_id must be a whole number"),
        (lambda: sim.run_maneuver(42), "maneuver must be a file name"),
        (lambda: sim.run_maneuver("demo", duration="1"), "duration must be a number"),
        (lambda: sim.driver(1, strength=2.5), "strength must be a whole number"),
        (lambda: sim.driver(1, source_id=7), "source_id must be a str"),
        (lambda: sim.subscribe(1, capacity="10"), "capacity must be a whole number"),
        (lambda: vdyn.make_input(throttle="0.5"), "throttle must be a number"),
        (lambda: vdyn.make_input(gear=1.5), "gear must be a whole number"),
        (lambda: vdyn.Client(domain="0"), "domain must be a whole number"),
        (lambda: vdyn.Client(domain=domain, server_id=1), "server_id must be a str"),
    ]
    for call, match in bad:
        with pytest.raises(TypeError, match=match):
            call()
    for call, match in [
            (lambda: sim.latest(0), r"vehicle id must be in \[1, 4294967295\], got 0"),
            (lambda: sim.spawn(-1, 0.0, 0.0), r"vehicle id must be in \[1, 4294967295\]"),
            (lambda: vdyn.Client(domain=999), r"DDS domain id must be in \[0, 232\], got 999"),
            (lambda: sim.subscribe(1, capacity=0), r"capacity must be in \[1, 10000000\] states")]:
        with pytest.raises(ValueError, match=match):
            call()
    # numpy's numbers are numbers.
    assert len(sim.step(np.int64(2), timeout=np.float64(30))[1]) == 2


def test_a_networked_server_starts_its_vehicles_at_the_speed_it_was_given(start, domain):
    # --speed-kmh: the start vehicles move along their heading from the first step (before, a
    # networked server took the option and started them at rest).
    start([SERVER, "--lockstep", "--lockstep-timeout", "60", "--domain", str(domain),
           "--vehicle-ids", "1,2", "--speed-kmh", "36"], "server")
    sim = vdyn.Client(domain=domain, timeout=30)
    first = sim.step(1)
    for v in (1, 2):
        assert first[v].vx_mps[0] == pytest.approx(10.0, abs=0.2), v
        assert first[v].speed_kmh[0] == pytest.approx(36.0, abs=0.7), v
