"""The vdyn package against a real vdyn-server: connect, control, lockstep, real time, driving."""

import math
import subprocess
import time

import numpy as np
import pytest

import vdyn


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
    with pytest.raises(vdyn.TimeoutError, match=f"domain {domain}"):
        vdyn.Client(domain=domain, timeout=1.0)
    assert time.monotonic() - t0 < 6.0  # 1 s, and generous room for a loaded machine


def test_a_named_server_that_is_absent_raises(lockstep_server, domain):
    with pytest.raises(vdyn.TimeoutError, match="'elsewhere'"):
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
        assert np.all(np.concatenate([s.throttle_in for s in states]) == 0.3)
        assert sub.missing_steps == 0 and sub.overflowed == 0 and sub.dds_lost == 0
        # When it stops, the weaker one takes the vehicle after the lease (docs/topics.md).
        drv.stop()
        until(0.1)
        assert drv.sent > 0 and drv.failed == 0 and weak.failed == 0


def test_a_client_receives_only_the_states_it_asks_for(realtime_server, domain):
    """A client that connects, spawns and reads parameters receives no state; latest(v) reads
    vehicle v's states in its partition (the server sends the others' elsewhere); the first
    step() reads every vehicle's, from then on. (Before, every client read every state from its
    start: beside 128 vehicles, 13.5 % of a core and 350 MB of history while idle.)"""
    sim = vdyn.Client(domain=domain, timeout=30)
    assert sim.state_readers == []
    spawn = sim.world.spawn
    sim.spawn(2, spawn.x, spawn.y, spawn.yaw)
    assert sim.params(2).mass > 0
    assert sim.state_readers == []
    assert len(sim.latest(2)) == 1
    assert sim.state_readers == ["vehicle 2 (its partition)"]
    assert len(sim.latest(1)) == 1
    assert sim.state_readers == ["vehicle 1 (its partition)", "vehicle 2 (its partition)"]


def test_the_first_lockstep_step_gets_its_states_from_a_reader_made_for_it(lockstep_server, domain):
    """The reader of every vehicle's states is made by the first step(), and the server knows it
    before it steps: not one state of that first step is missing."""
    for _ in range(3):
        sim = vdyn.Client(domain=domain, timeout=30)
        assert sim.state_readers == []
        first = sim.step(1)[1]
        assert len(first) == 1
        assert sim.state_readers == ["every vehicle (steps)"]
