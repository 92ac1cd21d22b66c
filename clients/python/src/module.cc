// The extension module vdyn._vdyn: the C++ side of the Python package (clients/python/vdyn). Every
// blocking call releases the GIL; errors become vdyn.TimeoutError, vdyn.RefusedError,
// vdyn.RecordingError (vdyn/_errors.py) or ValueError.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <signal.h>
#include <atomic>
#include <thread>
#include <map>
#include <memory>
#include <optional>

#include "client.h"
#include "recording_reader.h"
#include "state_columns.h"
#include "vdyn/base/deadline.h"
#include "vdyn/base/limits.h"
#include "vdyn/io/maneuver.h"
#include "vdyn/io/vehicle_params.h"
#include "vdyn/messages/input_checks.h"
#include "vdyn/recorder/mcap.h"

namespace py = pybind11;
using namespace vdyn;
using namespace vdyn::python;

namespace {

// Ctrl-C while a call of the main thread waits with the GIL released: the call sets a C handler
// of SIGINT of its own for its length (restoring Python's after), whose flag the waits check
// between their slices (base::PollUntil's hook, 20-50 ms) and end with Interrupted, raised in
// Python as KeyboardInterrupt (through Python's own handler). The hook takes no GIL and runs no
// Python: a hook that took the GIL while a client lock was held deadlocked with a thread that held
// the GIL and wanted that lock, and a Python signal handler could re-enter the client.
std::atomic<bool> g_sigint{false};
std::thread::id g_main_thread;  // the interpreter's main thread: the one Python signals

extern "C" void OnSigint(int) { g_sigint.store(true); }

struct Interrupted : std::exception {
  const char* what() const noexcept override { return "interrupted (Ctrl-C)"; }
};

class WaitReleased {
 public:
  WaitReleased() {
    if (std::this_thread::get_id() != g_main_thread || base::ThreadWaitHook() != nullptr) return;
    g_sigint.store(false);
    struct sigaction sa {};
    sa.sa_handler = OnSigint;
    sigemptyset(&sa.sa_mask);
    if (sigaction(SIGINT, &sa, &python_) != 0) return;
    installed_ = true;
    base::ThreadWaitHook() = &Check;
  }
  ~WaitReleased() {
    if (!installed_) return;
    base::ThreadWaitHook() = nullptr;
    sigaction(SIGINT, &python_, nullptr);
    // A Ctrl-C that came as the call ended goes to Python as if it came now (callable without
    // the GIL).
    if (g_sigint.exchange(false)) PyErr_SetInterrupt();
  }
  WaitReleased(const WaitReleased&) = delete;
  WaitReleased& operator=(const WaitReleased&) = delete;

 private:
  static void Check() {
    if (g_sigint.exchange(false)) throw Interrupted();
  }
  py::gil_scoped_release release_;  // first: released before the handler is set
  bool installed_ = false;
  struct sigaction python_ {};
};

template <class M>
M Parse(const py::bytes& bytes, const char* what) {
  M m;
  const std::string s = bytes;
  if (!m.ParseFromString(s)) {
    throw py::value_error(std::string("not a serialised ") + M::descriptor()->full_name() + ": " +
                          what);
  }
  return m;
}

template <class T>
py::array_t<T> Array(std::vector<T>&& v) {
  auto* heap = new std::vector<T>(std::move(v));
  py::capsule owner(heap, [](void* p) { delete static_cast<std::vector<T>*>(p); });
  return py::array_t<T>({heap->size()}, {sizeof(T)}, heap->data(), owner);
}

// A table as a dict of arrays: "values" (rows x columns, float64), "step", "state_hash" (uint64),
// "sim_time_ns" (int64), "log_time_ns" (uint64, recordings).
py::dict Table(StateTable&& t) {
  const std::size_t rows = t.rows(), cols = StateColumns().size();
  py::dict d;
  auto* values = new std::vector<double>(std::move(t.values));
  py::capsule owner(values, [](void* p) { delete static_cast<std::vector<double>*>(p); });
  d["values"] = py::array_t<double>({rows, cols}, {cols * sizeof(double), sizeof(double)},
                                    values->data(), owner);
  d["step"] = Array(std::move(t.step));
  d["state_hash"] = Array(std::move(t.state_hash));
  d["sim_time_ns"] = Array(std::move(t.sim_time_ns));
  d["log_time_ns"] = Array(std::move(t.log_time_ns));
  d["malformed"] = t.malformed;
  d["runs"] = t.runs;
  return d;
}

py::dict Reply(const ReplyInfo& r) {
  py::dict d;
  d["server_id"] = r.server_id;
  d["applied_step"] = r.applied_step;
  d["sim_time_ns"] = r.sim_time_ns;
  return d;
}

pb::Pose2 Pose(double x, double y, double yaw) {
  pb::Pose2 p;
  p.set_x(x);
  p.set_y(y);
  p.set_yaw(yaw);
  return p;
}

void BindErrors() {
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const vdyn::python::TimeoutError& e) {
      py::object cls = py::module_::import("vdyn._errors").attr("TimeoutError");
      PyErr_SetObject(cls.ptr(), py::str(e.what()).ptr());
    } catch (const RefusedError& e) {
      py::object cls = py::module_::import("vdyn._errors").attr("RefusedError");
      PyErr_SetObject(cls.ptr(), py::make_tuple(e.what(), e.reason()).ptr());
    } catch (const mcap::McapError& e) {
      py::object cls = py::module_::import("vdyn._errors").attr("RecordingError");
      PyErr_SetObject(cls.ptr(), py::str(e.what()).ptr());
    } catch (const ManeuverError& e) {
      PyErr_SetString(PyExc_ValueError, e.what());
    } catch (const transport::TransportError& e) {
      py::object cls = py::module_::import("vdyn._errors").attr("TransportError");
      PyErr_SetObject(cls.ptr(), py::str(e.what()).ptr());
    } catch (const Interrupted&) {
      // Through Python's handler of SIGINT (KeyboardInterrupt, or the program's own).
      PyErr_SetInterrupt();
      if (PyErr_CheckSignals() == 0 && !PyErr_Occurred()) PyErr_SetNone(PyExc_KeyboardInterrupt);
    }
  });
}

// The limits a Python call checks its arguments against, by the argument's name: the table of
// limits (base/limits.h) the server checks them with.
const limits::Range* NamedLimit(const std::string& name) {
  static const std::map<std::string, const limits::Range*> kByName = {
      {"vehicle_id", &limits::kVehicleId}, {"domain", &limits::kDomainId},
      {"strength", &limits::kStrength},    {"duration", &limits::kDurationS},
      {"rate_hz", &limits::kRateHz},
  };
  const auto it = kByName.find(name);
  return it == kByName.end() ? nullptr : it->second;
}

void BindChecks(py::module_& m) {
  m.def("state_columns", &StateColumns, "The state columns (the vehicle CSV's, in order).");
  m.attr("MAX_ID_BYTES") = limits::kMaxIdBytes;  // a server's, client's or source's id
  m.attr("MAX_STEPS") = limits::kMaxStepsPerRequest;  // of one step() call
  m.def(
      "check_limit",
      [](const std::string& name, double value) {
        const limits::Range* r = NamedLimit(name);
        if (r == nullptr) throw py::value_error("no limit named " + name);
        return limits::Check(*r, value);
      },
      "Empty when value is within the named limit, else the reason (base/limits.h).");
  m.def(
      "merge_vehicle_params",
      [](const py::bytes& base, const py::bytes& update) {
        return py::bytes(MergeVehicleParams(Parse<pb::VehicleParams>(base, "vehicle parameters"),
                                            Parse<pb::VehicleParams>(update, "vehicle parameters"))
                             .SerializeAsString());
      },
      "The serialised VehicleParams `update` merged over `base` as a server merges a change.");
  m.def(
      "why_input_refused",
      [](const py::bytes& input) {
        return messages::WhyInputRefused(Parse<pb::DriverInput>(input, "driver input"));
      },
      "Empty when a server applies this serialised DriverInput, else its reason.");
}

using Release = py::call_guard<WaitReleased>;

void BindClient(py::module_& m) {
  py::class_<Client>(m, "Client")
      .def(py::init<std::uint32_t, const std::string&, double, const std::string&>(),
           py::arg("domain"), py::arg("server_id"), py::arg("timeout"), py::arg("client_id"),
           Release())
      .def_property_readonly("server_id", &Client::server_id)
      .def_property_readonly("domain", &Client::domain)
      .def("world_bytes", [](Client& c) { return py::bytes(c.WorldBytes()); })
      .def("world_version", &Client::WorldVersion)
      .def("vehicles", &Client::Vehicles, Release())
      .def_property_readonly("state_readers", &Client::StateReaders)
      .def_property_readonly("states_received", &Client::StatesReceived)
      .def("params_bytes",
           [](Client& c, std::uint32_t id, double timeout) {
             std::string s;
             {
               WaitReleased release;
               s = c.ParamsBytes(id, timeout);
             }
             return py::bytes(s);
           })
      .def("request",
           [](Client& c, const py::bytes& request, const std::string& what, double timeout) {
             auto r = Parse<pb::ControlRequest>(request, "control request");
             ReplyInfo info;
             {
               WaitReleased release;
               info = c.Request(std::move(r), what, timeout);
             }
             return Reply(info);
           })
      .def("step",
           [](Client& c, std::uint32_t steps, const py::object& input, double timeout) {
             std::optional<pb::DriverInput> in;
             if (!input.is_none()) in = Parse<pb::DriverInput>(input, "driver input");
             std::map<std::uint32_t, StateTable> out;
             std::vector<std::string> discarded;
             {
               WaitReleased release;
               out = c.Step(steps, in ? &*in : nullptr, timeout, &discarded);
             }
             py::dict d;
             for (auto& [id, t] : out) d[py::int_(id)] = Table(std::move(t));
             return py::make_tuple(d, discarded);
           })
      .def("run_maneuver",
           [](Client& c, const std::string& maneuver, std::uint32_t id,
              std::optional<double> duration, const std::string& source_id, double timeout) {
             std::map<std::uint32_t, StateTable> out;
             std::vector<std::string> discarded;
             {
               WaitReleased release;
               out = c.RunManeuver(maneuver, id, duration, source_id, timeout, &discarded);
             }
             py::dict d;
             for (auto& [vid, t] : out) d[py::int_(vid)] = Table(std::move(t));
             return py::make_tuple(d, discarded);
           })
      .def("latest", [](Client& c, std::uint32_t id, double timeout) {
        StateTable t;
        {
          WaitReleased release;
          t = c.Latest(id, timeout);
        }
        return Table(std::move(t));
      });

  // Builds the requests whose fields are plain numbers here; the rest arrive serialised.
  m.def("pose_request", [](const std::string& kind, std::uint32_t id, double x, double y,
                           double yaw, double speed, const py::object& params) {
    pb::ControlRequest r;
    r.set_vehicle_id(id);
    if (kind == "spawn") {
      auto* s = r.mutable_spawn();
      *s->mutable_pose() = Pose(x, y, yaw);
      s->set_speed(speed);
      if (!params.is_none()) *s->mutable_params() = Parse<pb::VehicleParams>(params, "parameters");
    } else if (kind == "teleport") {
      auto* t = r.mutable_teleport();
      *t->mutable_pose() = Pose(x, y, yaw);
      t->set_speed(speed);
    } else {
      throw py::value_error("unknown request kind " + kind);
    }
    return py::bytes(r.SerializeAsString());
  });
}

void BindDriver(py::module_& m) {
  py::class_<Driver>(m, "Driver")
      .def(py::init<Client&, std::uint32_t, const std::string&, std::int32_t>(), py::arg("client"),
           py::arg("vehicle_id"), py::arg("source_id"), py::arg("strength"), py::keep_alive<1, 2>())
      .def("send",
           [](Driver& d, const py::bytes& input) {
             auto in = Parse<pb::DriverInput>(input, "driver input");
             WaitReleased release;
             d.Send(in);
           })
      .def("set",
           [](Driver& d, const py::bytes& input) {
             auto in = Parse<pb::DriverInput>(input, "driver input");
             WaitReleased release;
             d.Set(in);
           })
      .def("start", &Driver::Start, py::arg("rate_hz"), Release())
      .def("stop", &Driver::Stop, Release())
      .def("wait_for_server", &Driver::WaitForServer, py::arg("timeout"), Release())
      .def_property_readonly("running", &Driver::running)
      .def_property_readonly("sent", &Driver::sent)
      .def_property_readonly("failed", &Driver::failed)
      .def_property_readonly("skipped_ticks", &Driver::skipped_ticks);
}

void BindSubscription(py::module_& m) {
  py::class_<Subscription>(m, "Subscription")
      .def(py::init<Client&, std::uint32_t, std::size_t>(), py::arg("client"),
           py::arg("vehicle_id"), py::arg("capacity"), py::keep_alive<1, 2>())
      .def("next",
           [](Subscription& s, double timeout) {
             StateTable t;
             {
               WaitReleased release;
               t = s.Next(timeout);
             }
             return Table(std::move(t));
           })
      .def("take_all",
           [](Subscription& s) {
             StateTable t;
             {
               WaitReleased release;
               t = s.TakeAll();
             }
             return Table(std::move(t));
           })
      .def("close", &Subscription::Close, Release())
      .def_property_readonly("received", &Subscription::received)
      .def_property_readonly("overflowed", &Subscription::overflowed)
      .def_property_readonly("missing_steps", &Subscription::missing_steps)
      .def_property_readonly("restarts", &Subscription::restarts)
      .def_property_readonly("dds_lost", &Subscription::dds_lost)
      .def_property_readonly("queued", &Subscription::queued);
}

void BindRecording(py::module_& m) {
  py::class_<RecordingReader>(m, "RecordingReader")
      .def(py::init([](const std::string& path) {
             WaitReleased release;
             return std::make_unique<RecordingReader>(path);
           }),
           py::arg("path"))
      .def_property_readonly("start_ns", &RecordingReader::start_ns)
      .def_property_readonly("end_ns", &RecordingReader::end_ns)
      .def_property_readonly("messages", &RecordingReader::messages)
      .def_property_readonly("complete", &RecordingReader::complete)
      .def("channels",
           [](const RecordingReader& r) {
             py::list out;
             for (const auto& c : r.channels()) {
               py::dict d;
               d["topic"] = c.topic;
               d["dds_topic"] = c.dds_topic;
               d["key"] = c.key;
               d["messages"] = c.messages;
               d["bytes"] = c.bytes;
               d["first_log_time_ns"] = c.first_log_time_ns;
               d["last_log_time_ns"] = c.last_log_time_ns;
               out.append(d);
             }
             return out;
           })
      .def("vehicles",
           [](const RecordingReader& r) {
             py::list out;
             for (const auto& v : r.vehicles()) {
               py::dict d;
               d["vehicle_id"] = v.vehicle_id;
               d["states"] = v.states;
               d["first_step"] = v.first_step;
               d["last_step"] = v.last_step;
               d["missing"] = v.missing;
               d["jumps"] = v.jumps;
               d["largest_gap"] = v.largest_gap;
               d["largest_gap_from"] = v.largest_gap_from;
               out.append(d);
             }
             return out;
           })
      .def("events",
           [](const RecordingReader& r) {
             py::list out;
             for (const auto& e : r.events()) {
               out.append(py::make_tuple(e.log_time_ns, py::bytes(e.bytes)));
             }
             return out;
           })
      .def("metadata",
           [](const RecordingReader& r) {
             py::list out;
             for (const auto& md : r.metadata()) out.append(py::make_tuple(md.name, md.values));
             return out;
           })
      .def("states", [](const RecordingReader& r, std::uint32_t id, int run) {
        StateTable t;
        {
          WaitReleased release;
          t = r.States(id, run);
        }
        return Table(std::move(t));
      });
}

}  // namespace

PYBIND11_MODULE(_vdyn, m) {
  m.doc() = "vdyn's client layer for Python (use the package vdyn, not this module)";
  g_main_thread = std::this_thread::get_id();  // imported on the main thread (WaitReleased)
  BindErrors();
  BindChecks(m);
  BindClient(m);
  BindDriver(m);
  BindSubscription(m);
  BindRecording(m);
}
