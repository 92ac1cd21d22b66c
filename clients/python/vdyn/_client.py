"""Connect to a vdyn server: world, vehicles, control requests, lockstep, real time, driving."""

import math
import numbers
import os
import time

from . import _vdyn
from . import control_pb2, input_pb2, vehicle_params_pb2, world_pb2, exact_pb2
from ._states import States

DEFAULT_TIMEOUT = 10.0


def _whole(name, value, limit=None):
    """A whole number argument (not a bool, a float or a string), within the named limit of the
    table of limits (base/limits.h) when one is given."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise TypeError(f"{name} must be a whole number, got {value!r} ({type(value).__name__})")
    value = int(value)
    if limit is not None:
        why = _vdyn.check_limit(limit, float(value))
        if why:
            raise ValueError(f"{name}: {why}")
    return value


def _real(name, value):
    """A number argument (an int or a float, not a bool or a string)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} must be a number, got {value!r} ({type(value).__name__})")
    return float(value)


def _text(name, value):
    if not isinstance(value, str):
        raise TypeError(f"{name} must be a str, got {value!r} ({type(value).__name__})")
    return value


def _id(name, value):
    """An id a server reads (client, server, source): text of at most MAX_ID_BYTES in UTF-8."""
    value = _text(name, value)
    if len(value.encode()) > _vdyn.MAX_ID_BYTES:
        raise ValueError(f"{name} must be at most {_vdyn.MAX_ID_BYTES} bytes in UTF-8, got "
                         f"{len(value.encode())} (a server ignores a longer one)")
    return value


def _check_input(msg):
    """Raises ValueError with a server's reason when it would not apply this input."""
    why = _vdyn.why_input_refused(msg.SerializeToString())
    if why:
        raise ValueError(f"an input the server would not apply: {why}")
    return msg


def _warn_discarded(notes):
    """One vdyn.DiscardedStepsWarning per vehicle whose steps the server discarded."""
    if not notes:
        return
    import warnings
    from ._errors import DiscardedStepsWarning
    for note in notes:
        warnings.warn(note, DiscardedStepsWarning, stacklevel=3)


def make_input(steer=0.0, throttle=0.0, brake=0.0, *, gear=0, buttons=0, clutch=0.0,
               handbrake=0.0, cruise_kmh=None, steer_mode="road_wheel", vehicle_id=0,
               source_id=""):
    """A driver input (vdyn.pb.DriverInput): steer in rad (the road-wheel angle, or the
    hand-wheel angle with steer_mode="hand_wheel"), throttle [-1, 1], brake [0, 1], gear (0
    automatic, -1 reverse, 1..N), buttons (vdyn.pb.Button bits), cruise_kmh (a set speed switches
    the speed control on). An input a server would not apply (a value outside the table of
    limits, not a number, a source id over 64 bytes) raises ValueError with the server's reason."""
    modes = {"road_wheel": input_pb2.STEER_ROAD_WHEEL, "hand_wheel": input_pb2.STEER_HAND_WHEEL,
             "hands_off": input_pb2.STEER_HANDS_OFF}
    if steer_mode not in modes:
        raise ValueError(f"steer_mode must be one of {sorted(modes)}, got {steer_mode!r}")
    for name, value, top in (("buttons", buttons, 0xFFFFFFFF), ("vehicle_id", vehicle_id, 0xFFFFFFFF)):
        if not 0 <= _whole(name, value) <= top:
            raise ValueError(f"{name} must be in [0, {top}], got {value}")
    msg = input_pb2.DriverInput(
        vehicle_id=_whole("vehicle_id", vehicle_id), source_id=_text("source_id", source_id),
        steer=_real("steer", steer), throttle=_real("throttle", throttle),
        brake=_real("brake", brake), gear=_whole("gear", gear), buttons=_whole("buttons", buttons),
        clutch=_real("clutch", clutch), handbrake=_real("handbrake", handbrake),
        steer_mode=modes[steer_mode])
    if cruise_kmh is not None:
        msg.cruise_on = True
        msg.cruise_set_kmh = _real("cruise_kmh", cruise_kmh)
    return _check_input(msg)


def _check_param_types(d, descriptor, path):
    """A number where a number goes, a bool where a bool goes: protobuf's JSON mapping also takes
    "1800" for a number, which Python's users do not mean (TypeError names the field)."""
    from google.protobuf.descriptor import FieldDescriptor as F
    numeric = {F.TYPE_DOUBLE, F.TYPE_FLOAT, F.TYPE_INT32, F.TYPE_INT64, F.TYPE_UINT32,
               F.TYPE_UINT64, F.TYPE_SINT32, F.TYPE_SINT64, F.TYPE_FIXED32, F.TYPE_FIXED64,
               F.TYPE_SFIXED32, F.TYPE_SFIXED64}
    for key, value in d.items():
        field = descriptor.fields_by_name.get(key) or next(
            (f for f in descriptor.fields if f.json_name == key), None)
        where = f"{path}[{key!r}]"
        if field is None:
            # protobuf's JSON parser lists the camelCase names; users write the fields' own.
            import difflib
            names = sorted(f.name for f in descriptor.fields)
            close = difflib.get_close_matches(str(key), names, n=3)
            raise ValueError(f"{where}: no such parameter"
                             + (f" (did you mean {', '.join(close)}?)" if close else "")
                             + f"; the parameters here: {', '.join(names)}")
        items = (enumerate(value) if field.label == F.LABEL_REPEATED and
                 isinstance(value, (list, tuple)) else [(None, value)])
        for i, v in items:
            at = where if i is None else f"{where}[{i}]"
            if field.type == F.TYPE_MESSAGE and isinstance(v, dict):
                _check_param_types(v, field.message_type, at)
            elif field.type in numeric and (isinstance(v, (str, bool)) or
                                            not isinstance(v, numbers.Real)):
                raise TypeError(f"{at} must be a number, got {v!r} ({type(v).__name__})")
            elif field.type in numeric and not math.isfinite(v):
                # Said as the server says it (protobuf's parser asked for a quoted "NaN").
                raise ValueError(f"{at} must be a finite number, got {v!r}")
            elif field.type == F.TYPE_BOOL and not isinstance(v, bool):
                raise TypeError(f"{at} must be True or False, got {v!r} ({type(v).__name__})")


def _params_message(params):
    """VehicleParams from a message or a dict of its fields (nested dicts for wheels)."""
    if params is None:
        return None
    if isinstance(params, vehicle_params_pb2.VehicleParams):
        return params
    if isinstance(params, dict):
        from google.protobuf import json_format
        _check_param_types(params, vehicle_params_pb2.VehicleParams.DESCRIPTOR, "params")
        try:
            return json_format.ParseDict(params, vehicle_params_pb2.VehicleParams())
        except json_format.ParseError as e:
            raise ValueError(f"bad vehicle parameters: {e}") from None
    raise TypeError("params must be a vdyn.pb.VehicleParams or a dict of its fields")


def _input_message(inp, vehicle_id, source_id):
    if inp is None:
        return None
    if isinstance(inp, dict):
        inp = make_input(**inp)
    if not isinstance(inp, input_pb2.DriverInput):
        raise TypeError("input must be a vdyn.pb.DriverInput (vdyn.make_input) or a dict")
    msg = input_pb2.DriverInput()
    msg.CopyFrom(inp)
    if vehicle_id is not None:
        vehicle_id = _whole("vehicle_id", vehicle_id, "vehicle_id")
        if msg.vehicle_id not in (0, vehicle_id):
            raise ValueError(f"the input names vehicle {msg.vehicle_id}, but it goes to vehicle "
                             f"{vehicle_id} (vehicle_id=, or the driver's): give one of them")
        msg.vehicle_id = vehicle_id
    if not msg.source_id:
        msg.source_id = source_id
    return msg


_said_receive_buffer = False


def _say_receive_buffer():
    """Once a process: a warning when the kernel caps socket buffers below what step() needs."""
    global _said_receive_buffer
    if _said_receive_buffer:
        return
    _said_receive_buffer = True
    try:
        with open("/proc/sys/net/core/rmem_max") as f:
            cap = int(f.read().split()[0])
    except (OSError, ValueError, IndexError):
        return
    if cap < 16 << 20:
        import warnings
        warnings.warn(f"net.core.rmem_max is {cap} bytes: step() asks for 16 MiB of socket buffer "
                      "for the states of its steps (best effort), and one that falls ~0.1 s "
                      "behind loses some and times out naming them; as root: sysctl -w "
                      "net.core.rmem_max=16777216", stacklevel=3)


class Client:
    """A connection to one vdyn server on a DDS domain.

    ``Client(domain=0, server_id=None, timeout=10.0)`` waits up to ``timeout`` seconds for a
    server (the one named, or the first whose world arrives) and raises vdyn.TimeoutError saying
    what did not arrive. Every later wait is bounded by ``timeout`` too unless a call is given its
    own. A refused request raises vdyn.RefusedError with the server's reason.
    """

    def __init__(self, domain=0, server_id=None, timeout=DEFAULT_TIMEOUT, client_id=None):
        self.timeout = DEFAULT_TIMEOUT
        self.timeout = self._t(timeout)
        self.client_id = (_id("client_id", client_id) if client_id is not None
                          else f"python-{os.getpid()}-{id(self):x}")
        server_id = "" if server_id is None else _id("server_id", server_id)
        _say_receive_buffer()
        self._c = _vdyn.Client(_whole("domain", domain, "domain"), server_id, self.timeout,
                               self.client_id)
        self._world = None
        self._world_version = None

    # --- the world and the vehicles -----------------------------------------------------------
    @property
    def server_id(self):
        return self._c.server_id

    @property
    def domain(self):
        return self._c.domain

    @property
    def world(self):
        """The server's world description (vdyn.pb.WorldDescription): name, terrain_hash,
        step_ns, meshes, landmarks, spawn, the vehicles' geometry."""
        # Read again when a world arrived since (the server restarted, on another world perhaps:
        # the first one was kept for ever).
        version = self._c.world_version()
        if self._world is None or version != self._world_version:
            self._world = world_pb2.WorldDescription.FromString(self._c.world_bytes())
            self._world_version = version
        return self._world

    @property
    def world_name(self):
        return self.world.name

    @property
    def world_hash(self):
        """The terrain hash (docs/hash.md), an int."""
        return self.world.terrain_hash

    @property
    def step_s(self):
        return self.world.step_ns * 1e-9

    @property
    def vehicles(self):
        """Vehicle ids: the world's, plus this client's spawns and restores, minus its removals,
        plus any whose states a step delivered."""
        return self._c.vehicles()

    @property
    def state_readers(self):
        """What states this client receives, one string per reader it holds: none until
        latest() (that vehicle's, in its partition: the others' are not sent here) or step()
        (every vehicle's) asks. A Subscription reads on its own."""
        return self._c.state_readers

    def params(self, vehicle_id, timeout=None):
        """The vehicle's parameters in effect (vdyn.pb.VehicleParams, complete)."""
        data = self._c.params_bytes(_whole("vehicle_id", vehicle_id, "vehicle_id"),
                                    self._t(timeout))
        return vehicle_params_pb2.VehicleParams.FromString(data)

    # --- control ------------------------------------------------------------------------------
    def _request(self, req, what, timeout):
        return self._c.request(req.SerializeToString(), what, self._t(timeout))

    def spawn(self, vehicle_id, x, y, yaw=0.0, speed=0.0, params=None, timeout=None):
        """Creates a vehicle at (x, y) m in the world frame, heading yaw rad (counter-clockwise
        from the world's x axis), moving forward at speed m/s, with parameters (partial: merged
        over the server's defaults). Returns the reply (applied_step, sim_time_ns)."""
        vehicle_id = _whole("vehicle_id", vehicle_id, "vehicle_id")
        p = _params_message(params)
        data = _vdyn.pose_request("spawn", vehicle_id, _real("x", x), _real("y", y),
                                  _real("yaw", yaw), _real("speed", speed),
                                  None if p is None else p.SerializeToString())
        req = control_pb2.ControlRequest.FromString(data)
        reply = self._request(req, f"spawn of vehicle {vehicle_id}", timeout)
        self._wait_params(vehicle_id, p or vehicle_params_pb2.VehicleParams(), timeout)
        return reply

    def despawn(self, vehicle_id, timeout=None):
        """Removes a vehicle."""
        req = control_pb2.ControlRequest(vehicle_id=_whole("vehicle_id", vehicle_id, "vehicle_id"))
        req.remove.SetInParent()
        return self._request(req, f"removal of vehicle {vehicle_id}", timeout)

    def reset(self, vehicle_id, timeout=None):
        """Back to the spawn pose, at rest."""
        req = control_pb2.ControlRequest(vehicle_id=_whole("vehicle_id", vehicle_id, "vehicle_id"))
        req.reset.SetInParent()
        return self._request(req, f"reset of vehicle {vehicle_id}", timeout)

    def teleport(self, vehicle_id, x, y, yaw=0.0, speed=0.0, timeout=None):
        """Moves a vehicle to (x, y) m in the world frame, heading yaw rad (counter-clockwise from
        the world's x axis), moving forward at speed m/s, on the ground there."""
        data = _vdyn.pose_request("teleport", _whole("vehicle_id", vehicle_id, "vehicle_id"),
                                  _real("x", x), _real("y", y), _real("yaw", yaw),
                                  _real("speed", speed), None)
        req = control_pb2.ControlRequest.FromString(data)
        return self._request(req, f"teleport of vehicle {vehicle_id}", timeout)

    def pause(self, timeout=None):
        req = control_pb2.ControlRequest()
        req.pause.SetInParent()
        return self._request(req, "pause", timeout)

    def resume(self, timeout=None):
        req = control_pb2.ControlRequest()
        req.resume.SetInParent()
        return self._request(req, "resume", timeout)

    def set_params(self, vehicle_id, params, timeout=None):
        """Changes parameters (a vdyn.pb.VehicleParams or a dict: partial, merged over the
        vehicle's current ones at a step boundary). Returns once the server accepted them and
        publishes them on vdyn/params (so params() shows them)."""
        want = _params_message(params)
        req = control_pb2.ControlRequest(vehicle_id=_whole("vehicle_id", vehicle_id, "vehicle_id"))
        req.set_params.params.CopyFrom(want)
        reply = self._request(req, f"parameter change of vehicle {vehicle_id}", timeout)
        self._wait_params(vehicle_id, want, timeout)
        return reply

    def _wait_params(self, vehicle_id, want, timeout):
        """Waits until vdyn/params shows the change `want` (the server publishes it a moment
        after its reply): until `want` merged over them, as the server merges it (an empty
        tyre message removes the tyre), changes nothing."""
        from ._errors import TimeoutError
        t = self._t(timeout)
        deadline = time.monotonic() + t
        want_bytes = want.SerializeToString()
        seen = set()
        while True:
            current = self.params(vehicle_id, max(0.0, deadline - time.monotonic()))
            current_bytes = current.SerializeToString()
            seen.add(current_bytes)
            merged = vehicle_params_pb2.VehicleParams.FromString(
                _vdyn.merge_vehicle_params(current_bytes, want_bytes))
            if merged == current:
                return current
            if time.monotonic() >= deadline:
                raise TimeoutError(
                    f"the parameters of vehicle {vehicle_id} the server accepted did not appear "
                    f"on vdyn/params within {t:g} s"
                    + ("; they changed meanwhile to others (another client's change after this "
                       "one replaced it?): params() gives what the vehicle holds now"
                       if len(seen) > 1 else ""))
            time.sleep(0.005)  # vdyn/params has no per-change event to wait on

    def restore(self, vehicle_id, state, params=None, input=None, branched_from="", timeout=None):
        """Brings a vehicle back to an exact state (vdyn.pb.ExactState, e.g. from a recording's
        checkpoint event), with parameters and the input to hold until a live input arrives
        (vdyn.pb.InputSample)."""
        req = control_pb2.ControlRequest(vehicle_id=_whole("vehicle_id", vehicle_id, "vehicle_id"))
        req.restore.state.CopyFrom(state)
        if params is not None:
            req.restore.params.CopyFrom(_params_message(params))
        if input is not None:
            req.restore.input.CopyFrom(input)
        req.restore.branched_from = branched_from
        return self._request(req, f"restore of vehicle {vehicle_id}", timeout)

    # --- lockstep -----------------------------------------------------------------------------
    def step(self, n=1, input=None, vehicle_id=None, source_id="python", timeout=None):
        """Advances the server n steps (lockstep; a real-time server pauses its clock for them
        and stays paused after them until resume())
        with ``input`` (vdyn.make_input(...) or a dict; for ``vehicle_id``, else the input's own)
        applied first, and returns {vehicle_id: States} with every vehicle's state at each of
        those steps. An input for a vehicle the server does not have, or one it would not apply
        (out of range, not a number), raises ValueError with the reason before anything is
        stepped. Raises vdyn.TimeoutError naming what did not arrive. A step the server
        discarded (a state gone non-finite, a car that rolled over and fell through the ground:
        put back at rest) has no state: its row is missing, and a vdyn.DiscardedStepsWarning says
        whose, how many and why."""
        n = _whole("n", n)
        if not 1 <= n <= _vdyn.MAX_STEPS:
            raise ValueError(f"n must be in [1, {_vdyn.MAX_STEPS}] steps (ten simulated minutes "
                             f"at 1 kHz: call step() again for more), got {n}")
        if input is None and vehicle_id is not None:
            raise ValueError("vehicle_id names the vehicle an input is for; without an input, "
                             "step() advances every vehicle and returns each one's states "
                             "(give input=, or leave vehicle_id out)")
        msg = _input_message(input, vehicle_id, _text("source_id", source_id))
        if msg is not None and msg.vehicle_id == 0:
            raise ValueError("the input names no vehicle: give vehicle_id=")
        tables, discarded = self._c.step(n, None if msg is None else msg.SerializeToString(),
                                         self._t(timeout))
        _warn_discarded(discarded)
        return {vid: States(vid, t) for vid, t in tables.items()}

    def run_maneuver(self, maneuver, vehicle_id=1, duration=None, source_id="python",
                     timeout=None):
        """A batch run in lockstep: the maneuver (a CSV file with the header
        t_s,steer_deg,throttle,brake,cruise_kmh, or "demo") applied step by step from the
        vehicle's present step for ``duration`` s (default: to its last row), the input at each
        step exactly as ``vdyn-server --batch`` applies it. Returns {vehicle_id: States}. Reset or
        spawn the vehicle first for a run from rest. A bad file raises ValueError naming the file,
        line and column; a duration outside (0, 1e7] s raises ValueError."""
        if not isinstance(maneuver, (str, os.PathLike)):
            raise TypeError(f"maneuver must be a file name or \"demo\", got {maneuver!r}")
        tables, discarded = self._c.run_maneuver(
            os.fspath(maneuver), _whole("vehicle_id", vehicle_id, "vehicle_id"),
            None if duration is None else _real("duration", duration),
            _text("source_id", source_id), self._t(timeout))
        _warn_discarded(discarded)
        return {vid: States(vid, t) for vid, t in tables.items()}

    # --- real time ----------------------------------------------------------------------------
    def latest(self, vehicle_id, timeout=None):
        """The newest state of a vehicle (States of one row)."""
        vehicle_id = _whole("vehicle_id", vehicle_id, "vehicle_id")
        return States(vehicle_id, self._c.latest(vehicle_id, self._t(timeout)))

    @property
    def states_received(self):
        """{vehicle_id: states this client's readers have taken} (latest() and step() take them;
        a Subscription counts its own): which states arrived here."""
        return self._c.states_received

    def subscribe(self, vehicle_id, capacity=10000):
        """Every state of a vehicle from now on (vdyn.Subscription: iterate, or take())."""
        return Subscription(self, vehicle_id, capacity)

    def driver(self, vehicle_id, source_id="python", strength=10):
        """A driver publishing input for a vehicle (vdyn.Driver)."""
        return Driver(self, vehicle_id, source_id, strength)

    def _t(self, timeout):
        t = self.timeout if timeout is None else _real("timeout", timeout)
        if not math.isfinite(t) or t < 0:
            raise ValueError(f"a timeout must be a finite number of seconds >= 0, got {timeout!r}")
        return t

    def __repr__(self):
        return (f"<vdyn.Client domain {self.domain} server {self.server_id!r} "
                f"world {self.world_name!r}>")


class Driver:
    """Driver input for one vehicle from one source (``source_id``) with an ownership strength:
    the strongest live source drives (docs/topics.md). ``send(input)`` publishes once;
    ``start(rate_hz)`` publishes the input set by ``set(input)`` at a fixed rate from a
    background thread until ``stop()`` (also a context manager)."""

    def __init__(self, client, vehicle_id, source_id="python", strength=10):
        self.vehicle_id = _whole("vehicle_id", vehicle_id, "vehicle_id")
        self.source_id = _text("source_id", source_id)
        self.strength = _whole("strength", strength, "strength")
        self._client = client
        self._d = _vdyn.Driver(client._c, self.vehicle_id, self.source_id, self.strength)

    def _bytes(self, inp):
        return _input_message(inp, self.vehicle_id, self.source_id).SerializeToString()

    def wait_for_server(self, timeout=None):
        """Waits until the server reads this driver's input; raises vdyn.TimeoutError."""
        from ._errors import TimeoutError
        t = self._client._t(timeout)
        if not self._d.wait_for_server(t):
            raise TimeoutError(f"no reader of vdyn/input matched driver '{self.source_id}' of "
                               f"vehicle {self.vehicle_id} within {t:g} s")

    def send(self, input):
        self._d.send(self._bytes(input))

    def set(self, input):
        self._d.set(self._bytes(input))

    def start(self, rate_hz=1000.0, input=None):
        """Sends the input at rate_hz in the background. A refused start (running already, a
        rate out of range, an input the server would not apply) changes nothing: the input
        sent stays as it was."""
        rate_hz = _real("rate_hz", rate_hz)
        if self._d.running:
            raise RuntimeError("the driver is already running (stop() it first, or set() a new "
                               "input)")
        if not (1.0 / 60.0 <= rate_hz <= 10000.0):
            raise ValueError(f"rate_hz must be in [1/60, 10000] (at least one input a minute), "
                             f"got {rate_hz:g}")
        data = None if input is None else self._bytes(input)
        if data is not None:
            self._d.set(data)
        self._d.start(rate_hz)
        return self

    def stop(self):
        self._d.stop()

    @property
    def running(self):
        return self._d.running

    @property
    def sent(self):
        return self._d.sent

    @property
    def failed(self):
        return self._d.failed

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.stop()


class Subscription:
    """Every state of one vehicle as it arrives, queued by a thread of its own (up to
    ``capacity`` states; more are counted in ``overflowed``). Iterating yields States of one row
    each and stops when none arrives within the client's timeout; ``take()`` returns every queued
    state at once. ``missing_steps`` counts steps absent from the sequence received."""

    def __init__(self, client, vehicle_id, capacity=10000):
        self.vehicle_id = _whole("vehicle_id", vehicle_id, "vehicle_id")
        self._client = client
        capacity = _whole("capacity", capacity)
        # Reserved up front (185 columns of 8 bytes a state): 10 million states is 15 GB.
        if not 1 <= capacity <= 10_000_000:
            raise ValueError(f"capacity must be in [1, 10000000] states, got {capacity}")
        self._s = _vdyn.Subscription(client._c, self.vehicle_id, capacity)
        self._closed = False

    def next(self, timeout=None):
        """The next state; raises vdyn.TimeoutError when none arrives in time (at once after
        close(): a closed subscription takes no more)."""
        if self._closed:
            from ._errors import TimeoutError
            raise TimeoutError(f"the subscription to vehicle {self.vehicle_id} is closed: no "
                               "state will arrive (take() returns what was queued)")
        return States(self.vehicle_id, self._s.next(self._client._t(timeout)))

    def take(self):
        return States(self.vehicle_id, self._s.take_all())

    def __iter__(self):
        from ._errors import TimeoutError
        while True:
            try:
                yield self.next()
            except TimeoutError:
                return

    @property
    def received(self):
        return self._s.received

    @property
    def overflowed(self):
        return self._s.overflowed

    @property
    def missing_steps(self):
        return self._s.missing_steps

    @property
    def restarts(self):
        """Times the server restarted while this subscription read: the states of each start
        follow the last one's, their steps counting from 0 again (``next()`` and ``take()`` give
        them in the order they came; a drop of the step column marks where)."""
        return self._s.restarts

    @property
    def dds_lost(self):
        """States DDS reports it dropped for this subscription's reader."""
        return self._s.dds_lost

    @property
    def queued(self):
        return self._s.queued

    def close(self):
        self._closed = True
        self._s.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
