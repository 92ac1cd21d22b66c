// The server and its clients as real processes over loopback DDS (issue: the simulation server
// over DDS). Each test has its own domain id; Cyclone DDS is restricted to `lo`. Every wait is
// on an event (DDS data, a child's exit) with a generous bound.
#include <fcntl.h>
#include <signal.h>
#include <sys/file.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <thread>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "dds_wait.h"
#include "process.h"
#include "test_support.h"
#include "vdyn/base/deadline.h"
#include "vdyn/base/limits.h"
#include "vdyn/bridge/convert.h"
#include "vdyn/client/session_view.h"
#include "vdyn/diagnostics.pb.h"
#include "vdyn/replay/resim.h"
#include "vdyn/runtime/state_outbox.h"
#include "vdyn/transport/control_client.h"
#include "vdyn/transport/dds.h"
#include "vdyn/transport/state_writers.h"
#include "vdyn/world.pb.h"
#include "vdyn_envelope.h"

namespace vdyn {
namespace {

using ::testing::HasSubstr;
using namespace std::chrono_literals;
using testing::Process;
using transport::TopicId;

// Who drives, as the states say: the step of the primary's last new sample, the first step the
// backup drove, and whether the safe state showed once `watching`.
struct Handover {
  std::string source;
  std::uint64_t last_sequence = 0, step_of_last_new_sample = 0, first_backup_step = 0;
  std::int64_t first_backup_sim_time_ns = 0;
  bool watching = false, braked = false;
  void See(const pb::VehicleState& s) {
    source = s.input().source_id();
    if (source == "primary" && s.input().sequence() != last_sequence) {
      last_sequence = s.input().sequence();
      step_of_last_new_sample = s.step();
    }
    if (watching && s.control().watchdog_safe_state()) braked = true;
    if (source == "backup" && first_backup_step == 0) {
      first_backup_step = s.step();
      first_backup_sim_time_ns = s.sim_time_ns();
    }
  }
  std::uint64_t failover_ms() const { return first_backup_step - step_of_last_new_sample; }
};

using testing::ReadUntil;
using testing::SendUntil;

class Net : public ::testing::Test {
 protected:
  void SetUp() override {
    testing::UseLoopbackDds();
    domain_ = testing::FreshDomain();
  }

  std::vector<std::string> ServerArgv(const std::vector<std::string>& extra) const {
    std::vector<std::string> argv = {testing::ServerBinary(), "--domain", std::to_string(domain_),
                                     "--no-status"};
    argv.insert(argv.end(), extra.begin(), extra.end());
    if (std::find(extra.begin(), extra.end(), "--world") == extra.end()) {
      argv.insert(argv.end(), {"--world", "flat"});
    }
    return argv;
  }

  std::unique_ptr<Process> StartServer(const std::vector<std::string>& extra,
                                       const std::string& log = "server.log") {
    return std::make_unique<Process>(ServerArgv(extra), dir_ / log);
  }

  std::unique_ptr<Process> StartInput(const std::vector<std::string>& extra,
                                      const std::string& log) {
    std::vector<std::string> argv = {testing::InputBinary(), "--domain", std::to_string(domain_)};
    argv.insert(argv.end(), extra.begin(), extra.end());
    return std::make_unique<Process>(argv, dir_ / log);
  }

  // A rig driving vehicle 1 at a constant throttle for 600 s of wall-clock time as `source`.
  std::unique_ptr<Process> StartRig(const std::string& source, const std::string& throttle,
                                    int strength, const std::string& log = "") {
    const auto csv = dir_ / (source + ".csv");
    testing::WriteFile(csv, "t_s,steer_deg,throttle,brake\n0,0," + throttle + ",0\n600,0," +
                                throttle + ",0\n");
    return StartInput({"--maneuver", csv.string(), "--clock", "wall", "--source-id", source,
                       "--strength", std::to_string(strength)},
                      log.empty() ? source + ".log" : log);
  }

  // A server with `watchdog_ms`, a backup rig (throttle 0.2, strength 5) and a primary (0.5,
  // strength 20) on vehicle 1, and a subscriber that follows who drives.
  struct Failover {
    std::unique_ptr<Process> server, backup, primary;
    std::unique_ptr<transport::Participant> p;
    transport::DropCounters drops;
    std::unique_ptr<transport::Reader<pb::VehicleState>> states;
    Handover h;
    // Reads states until `want` drives, handing each to `on` as well.
    bool UntilSource(const std::string& want, std::chrono::milliseconds timeout,
                     const std::function<void(const pb::VehicleState&)>& on = nullptr) {
      return ReadUntil<pb::VehicleState>(
          *states, timeout,
          [&](const pb::VehicleState& s) {
            h.See(s);
            if (on) on(s);
          },
          [&] { return h.source == want; });
    }
    // The server's count of steps it ran late to catch up since it started, from its first
    // diagnostics (one a second) that reports a simulated time at or after `sim_time_ns`.
    std::optional<std::uint64_t> StepsCaughtUp(std::int64_t sim_time_ns) {
      std::optional<std::uint64_t> caught;
      (void)ReadUntil<pb::Diagnostics>(
          *diagnostics, 10s,
          [&](const pb::Diagnostics& d) {
            if (!caught && d.sim_time_ns() >= sim_time_ns) caught = d.steps_caught_up();
          },
          [&] { return caught.has_value(); });
      return caught;
    }
    std::unique_ptr<transport::Reader<pb::Diagnostics>> diagnostics;
  };
  std::unique_ptr<Failover> StartFailover(const std::string& watchdog_ms) {
    auto f = std::make_unique<Failover>();
    f->server = StartServer({"--watchdog-ms", watchdog_ms});
    f->backup = StartRig("backup", "0.2", 5);
    f->primary = StartRig("primary", "0.5", 20);
    f->p = std::make_unique<transport::Participant>(domain_);
    f->states =
        std::make_unique<transport::Reader<pb::VehicleState>>(*f->p, TopicId::kState, &f->drops);
    f->diagnostics = std::make_unique<transport::Reader<pb::Diagnostics>>(
        *f->p, TopicId::kDiagnostics, &f->drops);
    return f;
  }

  std::uint32_t domain_ = 0;
  testing::TempDir dir_;
};

pb::DriverInput Input(std::uint32_t vehicle, double throttle, const std::string& source) {
  pb::DriverInput in;
  in.set_vehicle_id(vehicle);
  in.set_source_id(source);
  in.set_throttle(throttle);
  return in;
}

TEST_F(Net, LateJoiningSubscriberGetsWorldAndParamsAtOnce) {
  auto server = StartServer({"--vehicle-ids", "1,2"});
  transport::Participant p(domain_);
  transport::DropCounters drops;
  {
    // Wait until the server runs (its state arrives), then join late.
    transport::Reader<pb::VehicleState> states(p, TopicId::kState, &drops);
    bool running = false;
    ASSERT_TRUE(ReadUntil<pb::VehicleState>(states, 20s, [&](const auto& s) { running = s.step() > 500; },
                                            [&] { return running; }))
        << server->Log();
  }
  transport::Participant late(domain_);
  transport::Reader<pb::WorldDescription> world(late, TopicId::kWorld, &drops);
  transport::Reader<pb::VehicleParams> params(late, TopicId::kParams, &drops);
  std::optional<pb::WorldDescription> w;
  ASSERT_TRUE(ReadUntil<pb::WorldDescription>(world, 10s, [&](const auto& m) { w = m; },
                                              [&] { return w.has_value(); }));
  EXPECT_EQ(w->name(), "flat");
  EXPECT_EQ(w->server_id(), "vdyn");
  EXPECT_GT(w->meshes_size(), 0);
  EXPECT_EQ(w->vehicles_size(), 2);
  EXPECT_EQ(w->terrain_hash(), TerrainHash(testing::SharedWorld("flat")->terrain));
  int n_params = 0;
  ASSERT_TRUE(ReadUntil<pb::VehicleParams>(params, 10s, [&](const auto& m) {
    EXPECT_TRUE(ValidateVehicleParams(m).empty());
    ++n_params;
  }, [&] { return n_params >= 2; }));
  EXPECT_EQ(drops.Total(), 0u);
}

// A client that follows one vehicle reads in the vehicle's partition: it receives that vehicle's
// states and no other's (counted at the reader, as they arrive), while a reader of every vehicle
// still gets all of them.
TEST_F(Net, AOneVehicleReaderReceivesThatVehicleOnly) {
  auto server = StartServer({"--vehicle-ids", "1,2,3"});
  transport::Participant p(domain_);
  transport::DropCounters drops;
  transport::Reader<pb::VehicleState> all(p, TopicId::kState, &drops);
  transport::Reader<pb::VehicleState> own(
      p, TopicId::kState, &drops, transport::ReaderRole::kDefault, transport::VehiclePartition(2));
  client::SessionView view(p, {.states = true,
                               .params = false,
                               .world = false,
                               .diagnostics = false,
                               .inputs = false,
                               .only_vehicle = 3, .only_server = {}});
  ASSERT_EQ(view.one_vehicle_fallback(), "");
  std::map<std::uint32_t, std::uint64_t> at_all, at_own, at_view;
  view.on_state = [&](const pb::VehicleState&, const transport::SampleInfo& info) {
    ++at_view[info.key];
  };
  auto count = [](const std::map<std::uint32_t, std::uint64_t>& m, std::uint32_t k) {
    const auto it = m.find(k);
    return it == m.end() ? std::uint64_t{0} : it->second;
  };
  (void)base::PollUntil(
      base::Deadline::After(base::Seconds(60)), base::Milliseconds(20),
      [&] {
        (void)all.Take(
            [&](const pb::VehicleState&, const transport::SampleInfo& i) { ++at_all[i.key]; });
        (void)own.Take(
            [&](const pb::VehicleState&, const transport::SampleInfo& i) { ++at_own[i.key]; });
        view.Poll();
        return at_all.size() == 3 && count(at_own, 2) >= 500 && count(at_view, 3) >= 500;
      },
      [&](base::Nanos slice) { (void)all.Wait(base::Chrono(slice)); });
  EXPECT_EQ(at_all.size(), 3u) << server->Log();
  EXPECT_GE(count(at_own, 2), 500u) << server->Log();
  EXPECT_GE(count(at_view, 3), 500u) << server->Log();
  // Nothing of any other vehicle reached the one-vehicle readers.
  EXPECT_EQ(at_own.size(), 1u);
  EXPECT_EQ(at_view.size(), 1u);
  EXPECT_EQ(view.vehicles().size(), 1u);
  EXPECT_EQ(drops.Total(), 0u);
}

// --max-vehicles 256: a server starts 256 vehicles and publishes every one's states (functional,
// not timed: on a loaded machine some steps may be late).
TEST_F(Net, AServerRuns256VehiclesAndPublishesEach) {
  auto server = StartServer({"--max-vehicles", "256", "--vehicle-ids", "1..256"});
  transport::Participant p(domain_);
  transport::DropCounters drops;
  {
    transport::Reader<pb::VehicleState> states(p, TopicId::kState, &drops);
    std::map<std::uint32_t, std::uint64_t> steps;  // the highest step seen of each vehicle
    const bool all = ReadUntil<pb::VehicleState>(
        states, 120s, [&](const pb::VehicleState& s) { steps[s.vehicle_id()] = s.step(); },
        [&] {
          return steps.size() == 256 &&
                 std::all_of(steps.begin(), steps.end(),
                             [](const auto& kv) { return kv.second >= 100; });
        });
    ASSERT_TRUE(all) << steps.size() << " vehicles seen\n" << server->Log();
    EXPECT_EQ(steps.begin()->first, 1u);
    EXPECT_EQ(steps.rbegin()->first, 256u);
  }
  // The diagnostics name every vehicle (issue 32: a report held room for 64, and the vehicles past
  // the 64th were left out of the diagnostics and the status line without a word). The states'
  // reader is gone first: 256,000 states a second into this participant left no room for the
  // diagnostics' fragments on a loaded machine (none arrived in 20 s beside other tests' builds).
  transport::Reader<pb::Diagnostics> diag(p, TopicId::kDiagnostics, &drops);
  std::set<std::uint32_t> diagnosed;
  ASSERT_TRUE(ReadUntil<pb::Diagnostics>(
      diag, 60s,
      [&](const pb::Diagnostics& d) {
        diagnosed.clear();
        for (const auto& v : d.vehicles()) diagnosed.insert(v.vehicle_id());
      },
      [&] { return diagnosed.size() == 256; }))
      << diagnosed.size() << " vehicles diagnosed";
  EXPECT_EQ(*diagnosed.begin(), 1u);
  EXPECT_EQ(*diagnosed.rbegin(), 256u);
  EXPECT_EQ(drops.Total(), 0u);
}

// The nice value of a server's state writer thread (vdyn-states) in /proc/PID/task/TID/stat
// (field 19), if it has one.
std::optional<int> StateWriterNice(pid_t pid) {
  std::optional<int> nice;
  for (const auto& t :
       std::filesystem::directory_iterator("/proc/" + std::to_string(pid) + "/task")) {
    std::ifstream comm(t.path() / "comm");
    std::string name;
    std::getline(comm, name);
    if (name != "vdyn-states") continue;
    std::ifstream stat(t.path() / "stat");
    std::string line;
    std::getline(stat, line);
    // After the command name's closing parenthesis: field 3 (state) onwards; nice is field 19.
    std::istringstream rest(line.substr(line.rfind(')') + 2));
    std::string field;
    for (int k = 3; k < 19; ++k) rest >> field;
    int value = 0;
    rest >> value;
    nice = value;
  }
  return nice;
}

// The server's log up to its "state writer nice N" (the start line), polled for at most 30 s.
std::string LogWithWriterNice(Process& server) {
  std::string log;
  for (int i = 0; i < 600 && log.find("state writer nice") == std::string::npos; ++i) {
    std::this_thread::sleep_for(50ms);
    log = server.Log();
  }
  return log;
}

// Asked to, the real-time server's state writer runs ahead of the machine's ordinary threads
// (nice -10), or says why not; what it says is what the thread has. Not asked, it says what the
// thread inherited: a server started under `nice -n 5` says 5 more than this process has.
TEST_F(Net, TheStateWriterRunsAtTheNiceValueTheServerReports) {
  {
    auto server = StartServer({"--vehicle-ids", "1", "--state-writer-nice", "-10"});
    const std::string log = LogWithWriterNice(*server);
    const auto at = log.find("state writer nice ");
    ASSERT_NE(at, std::string::npos) << log;
    const int reported = std::atoi(log.c_str() + at + std::strlen("state writer nice "));
    if (log.find("refused: ", at) == std::string::npos) {
      EXPECT_EQ(reported, -10) << log;
    }
    const std::optional<int> nice = StateWriterNice(server->pid());
    ASSERT_TRUE(nice.has_value()) << "no vdyn-states thread";
    EXPECT_EQ(*nice, reported) << log;
  }
  errno = 0;
  const int own = getpriority(PRIO_PROCESS, 0);
  ASSERT_EQ(errno, 0);
  std::vector<std::string> argv = {"/usr/bin/nice", "-n", "5"};
  for (const std::string& a : ServerArgv({"--vehicle-ids", "1"})) argv.push_back(a);
  Process niced(argv, dir_ / "niced.log");  // nice runs the server in its own process
  const std::string log = LogWithWriterNice(niced);
  const int expected = std::min(own + 5, 19);
  EXPECT_THAT(log, HasSubstr("state writer nice " + std::to_string(expected) + "\n"));
  const std::optional<int> nice = StateWriterNice(niced.pid());
  ASSERT_TRUE(nice.has_value()) << "no vdyn-states thread\n" << log;
  EXPECT_EQ(*nice, expected) << log;
}

// A peer that matches a client's request writer and reply reader but answers nothing (as a
// recorder's reader of requests matches it): WaitForServer says so within its timeout, instead of
// letting the first request go to no server.
TEST_F(Net, WaitForServerSaysWhenAMatchedPeerAnswersNoHello) {
  transport::Participant peer(domain_);
  transport::DropCounters drops;
  transport::Reader<pb::ControlRequest> requests(peer, TopicId::kControl, &drops);
  transport::Writer<pb::ControlReply> replies(peer, TopicId::kControlReply);
  transport::Participant p(domain_);
  transport::ControlClient control(p, "test");
  const auto t0 = std::chrono::steady_clock::now();
  EXPECT_FALSE(control.WaitForServer(1500ms));
  EXPECT_LT(std::chrono::steady_clock::now() - t0, 30s);  // bounded (generous on a loaded machine)
  EXPECT_THAT(control.last_error(), HasSubstr("answered none of this client's"));
  EXPECT_THAT(control.last_error(), HasSubstr("within 1500 ms"));
}

// A hello that reaches no one (the server had not discovered the client's writer yet: here, a
// peer that ignores the first) is sent again until one is answered, and only the named server's
// answer counts.
TEST_F(Net, WaitForServerSendsHelloAgainUntilTheNamedServerAnswers) {
  transport::Participant peer(domain_);
  transport::DropCounters drops;
  transport::Reader<pb::ControlRequest> requests(peer, TopicId::kControl, &drops);
  transport::Writer<pb::ControlReply> replies(peer, TopicId::kControlReply);
  std::atomic<bool> stop{false};
  std::atomic<int> hellos{0};
  std::thread answerer([&] {
    (void)ReadUntil(
        requests, 60s,
        [&](const pb::ControlRequest& r) {
          if (!r.has_hello() || r.server_id() != "lab-b") return;
          if (hellos.fetch_add(1) == 0) return;  // the first is lost
          pb::ControlReply other;                // another server's answer does not count
          other.set_request_id(r.request_id());
          other.set_client_id(r.client_id());
          other.set_server_id("lab-a");
          other.set_accepted(true);
          (void)replies.Write(0, other);
          pb::ControlReply reply = other;
          reply.set_server_id("lab-b");
          (void)replies.Write(0, reply);
        },
        [&] { return stop.load(); });
  });
  transport::Participant p(domain_);
  transport::ControlClient control(p, "test");
  const bool answered = control.WaitForServer(30s, "lab-b");
  stop.store(true);
  answerer.join();
  ASSERT_TRUE(answered) << control.last_error();
  EXPECT_GE(hellos.load(), 2);
  EXPECT_EQ(control.answering_server(), "lab-b");
}

// The participant that created a domain in this process (with its configuration: a receive
// buffer) may go first: the others on it keep working. Deleting the domain with its creator took
// every other participant of the process with it (a Python script's second client could not read).
TEST_F(Net, AParticipantOutlivesTheOneThatCreatedItsDomain) {
  auto first = std::make_unique<transport::Participant>(domain_, std::size_t{1} << 20);
  transport::Participant second(domain_);
  first.reset();
  transport::DropCounters drops;
  transport::Reader<pb::Diagnostics> reader(second, TopicId::kDiagnostics, &drops);
  transport::Writer<pb::Diagnostics> writer(second, TopicId::kDiagnostics);
  pb::Diagnostics d;
  d.set_server_id("alive");
  int got = 0;
  for (int i = 0; i < 200 && got == 0; ++i) {  // written until read: at most 200 x 50 ms
    ASSERT_TRUE(writer.Write(0, d)) << writer.last_error();
    (void)reader.Wait(50ms);
    (void)reader.Take([&](const pb::Diagnostics& m, const transport::SampleInfo&) {
      got += m.server_id() == "alive";
    });
  }
  EXPECT_GT(got, 0);
}

// A server sends a step's states of every vehicle as one vdyn/states sample (what a recorder
// reads): each sample holds one state of each vehicle, all of the same step.
TEST_F(Net, AServerSendsAStepsStatesOfEveryVehicleAsOneSample) {
  auto server = StartServer({"--vehicle-ids", "1,2,3", "--server-id", "batcher"});
  transport::Participant p(domain_);
  transport::DropCounters drops;
  transport::Reader<pb::VehicleStates> batches(p, TopicId::kStates, &drops,
                                               transport::ReaderRole::kRecorder);
  // Every sample holds whole steps: each step's states of vehicles 1, 2, 3 in that order, steps
  // rising within a sample and from one sample to the next. (A state writer that falls behind
  // hands several steps over in one sample; a step is never split, being far below 1 MiB.)
  int samples = 0, whole = 0;
  std::optional<std::uint64_t> last_step;  // the first state may be step 0
  const bool got = ReadUntil<pb::VehicleStates>(
      batches, 60s,
      [&](const pb::VehicleStates& b) {
        ++samples;
        bool ok = b.states_size() > 0 && b.states_size() % 3 == 0;
        for (int i = 0; ok && i < b.states_size(); ++i) {
          const pb::VehicleState& s = b.states(i);
          EXPECT_EQ(s.server_id(), "batcher");
          ok = s.vehicle_id() == static_cast<std::uint32_t>(i % 3 + 1) &&
               (i % 3 == 0 ? !last_step || s.step() > *last_step
                           : s.step() == b.states(i - 1).step());
          last_step = s.step();
        }
        if (ok) {
          ++whole;
        } else {
          std::string list;
          for (const pb::VehicleState& s : b.states()) {
            list += " " + std::to_string(s.vehicle_id()) + "@" + std::to_string(s.step());
          }
          ADD_FAILURE() << "sample " << samples << " is not whole steps:" << list;
        }
      },
      [&] { return samples >= 500; });
  ASSERT_TRUE(got) << samples << " samples\n" << server->Log();
  EXPECT_EQ(whole, samples);
  EXPECT_EQ(drops.Total(), 0u);
}

// The writers' side, in this process: a round's states go out as one sample on vdyn/states; a
// round larger than a sample may be is split over several; vdyn/state in the default partition
// is written only while someone reads it there.
TEST_F(Net, StateWritersBatchAStepAndWriteVdynStateOnlyWhileRead) {
  transport::Participant p(domain_);
  transport::DropCounters drops;
  transport::StateWriters writers(p, drops, transport::StateWriters::Options{.states_key = 77});
  transport::Reader<pb::VehicleStates> batches(p, TopicId::kStates, &drops,
                                               transport::ReaderRole::kRecorder);
  std::vector<std::string> encoded;
  auto round = [&](std::uint64_t step, int vehicles, int wheels) {
    for (int v = 1; v <= vehicles; ++v) {
      pb::VehicleState s;
      s.set_vehicle_id(static_cast<std::uint32_t>(v));
      s.set_step(step);
      for (int w = 0; w < wheels; ++w) {
        pb::WheelState* ws = s.add_wheels();
        ws->set_fp(1000.0 + v);
        ws->set_omega(0.5 * w + 0.25);
      }
      const std::string b = s.SerializeAsString();
      ASSERT_TRUE(writers.WriteBytes(
          static_cast<std::uint32_t>(v),
          {reinterpret_cast<const std::uint8_t*>(b.data()), b.size()}));
    }
    ASSERT_TRUE(writers.Flush());
  };
  // Until the reader has matched: rounds of 3 vehicles.
  std::vector<pb::VehicleStates> got;
  std::vector<std::uint32_t> got_keys;
  auto take = [&] {
    (void)batches.Take([&](const pb::VehicleStates& b, const transport::SampleInfo& i) {
      got.push_back(b);
      got_keys.push_back(i.key);
    });
  };
  std::uint64_t next_step = 1;
  (void)SendUntil(
      batches, 30s, [&] { round(next_step++, 3, 4); },
      [&] {
        take();
        return !got.empty();
      });
  ASSERT_FALSE(got.empty());
  ASSERT_EQ(got.back().states_size(), 3);
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(got.back().states(i).vehicle_id(), static_cast<std::uint32_t>(i + 1));
    EXPECT_EQ(got.back().states(i).step(), got.back().states(0).step());
    EXPECT_EQ(got.back().states(i).wheels_size(), 4);
  }
  EXPECT_EQ(got_keys.back(), 77u);
  // Nobody reads vdyn/state in the default partition: not one state was written there.
  EXPECT_EQ(writers.all_states_written(), 0u);

  // A round larger than one sample may be: split, every state delivered once, in order.
  got.clear();
  const std::uint64_t before = writers.batches_written();
  const int many = 1500;  // ~1 KB each with 40 wheels: about 1.5 MB in all
  round(1'000'000, many, 40);
  EXPECT_GE(writers.batches_written() - before, 2u);
  int states = 0;
  bool in_order = true;
  (void)base::PollUntil(
      base::Deadline::After(base::Seconds(30)), base::Milliseconds(10),
      [&] {
        got.clear();
        take();
        for (const pb::VehicleStates& b : got) {
          EXPECT_LE(b.ByteSizeLong(), vdyn::limits::kMaxStatesBytes);
          for (const pb::VehicleState& s : b.states()) {
            in_order = in_order && s.vehicle_id() == static_cast<std::uint32_t>(states + 1);
            ++states;
          }
        }
        return states >= many;
      },
      [&](base::Nanos slice) { (void)batches.Wait(base::Chrono(slice)); });
  EXPECT_EQ(states, many);
  EXPECT_TRUE(in_order);

  // Once a reader of vdyn/state (a DDS tool) has matched, states go there as well.
  transport::Reader<pb::VehicleState> single(p, TopicId::kState, &drops);
  int singles = 0;
  next_step = 2'000'000;
  (void)SendUntil(
      single, 30s, [&] { round(next_step++, 3, 4); },
      [&] {
        singles += single.Take([](const pb::VehicleState&, const transport::SampleInfo&) {});
        return singles > 0;
      });
  EXPECT_GT(singles, 0);
  EXPECT_GT(writers.all_states_written(), 0u);
  EXPECT_EQ(drops.Total(), 0u);
}

// A server's state writer that fell behind (a loaded machine, a sanitizer build) has many steps
// waiting when it wakes. It sends them as several vdyn/states samples of whole steps, each closed
// once it holds StateWriters::Options::sample_bytes, not as one sample of everything waiting: a
// best-effort sample is lost whole when one of its datagrams is, and a 1 MB sample of three
// vehicles is 200 steps (a multihost run lost 500 steps of vdyn/states that way).
TEST_F(Net, ALaggingStateWriterSendsWholeStepsInSamplesOfBoundedSize) {
  transport::Participant p(domain_);
  transport::DropCounters drops;
  StateOutbox outbox(p, drops, 77);
  transport::Reader<pb::VehicleStates> batches(p, TopicId::kStates, &drops,
                                               transport::ReaderRole::kRecorder);
  constexpr int kVehicles = 3;
  std::size_t largest_state = 0;
  auto push_step = [&](std::uint64_t step) {
    const std::size_t open = outbox.Open(kVehicles);
    for (std::size_t i = 0; i < open; ++i) {
      pb::VehicleState s;
      s.set_vehicle_id(static_cast<std::uint32_t>(i + 1));
      s.set_step(step);
      for (int w = 0; w < 40; ++w) s.add_wheels()->set_fp(1000.0 + w);  // about 1 KB
      const std::span<std::uint8_t> buffer = outbox.Buffer(i);
      const std::size_t size = s.ByteSizeLong();
      ASSERT_LE(size, buffer.size());
      ASSERT_TRUE(s.SerializeToArray(buffer.data(), static_cast<int>(buffer.size())));
      largest_state = std::max(largest_state, size);
      outbox.Fill(i, s.vehicle_id(), size, false);
    }
    outbox.Close(kVehicles);
  };
  std::vector<pb::VehicleStates> got;
  auto take = [&] {
    (void)batches.Take(
        [&](const pb::VehicleStates& b, const transport::SampleInfo&) { got.push_back(b); });
  };
  // Until the writer knows the reader: a step at a time, as a server that keeps up.
  std::uint64_t step = 1;
  (void)SendUntil(
      batches, 30s,
      [&] {
        push_step(step++);
        outbox.Send();
      },
      [&] {
        take();
        return !got.empty();
      });
  ASSERT_FALSE(got.empty());
  ASSERT_TRUE(outbox.Drain(base::Seconds(30)));
  (void)batches.Wait(100ms);
  take();
  got.clear();

  // 150 steps handed over before the writer is woken: about 450 KB waiting.
  const std::uint64_t first = step;
  constexpr int kSteps = 150;
  for (int k = 0; k < kSteps; ++k) push_step(step++);
  outbox.Send();
  ASSERT_TRUE(outbox.Drain(base::Seconds(30)));
  int states = 0;
  (void)base::PollUntil(
      base::Deadline::After(base::Seconds(30)), base::Milliseconds(10),
      [&] {
        const std::size_t had = got.size();
        take();
        for (std::size_t b = had; b < got.size(); ++b) states += got[b].states_size();
        return states >= kSteps * kVehicles;
      },
      [&](base::Nanos slice) { (void)batches.Wait(base::Chrono(slice)); });
  ASSERT_EQ(states, kSteps * kVehicles) << drops.Total() << " drops";
  const std::size_t bound = 64 * 1024 + kVehicles * (largest_state + 4);
  EXPECT_GE(got.size(), 4u);  // 450 KB in samples of 64 KB and one step at most
  int n = 0;
  for (const pb::VehicleStates& b : got) {
    EXPECT_LE(b.ByteSizeLong(), bound);
    EXPECT_EQ(b.states_size() % kVehicles, 0) << "a sample holds whole steps";
    for (const pb::VehicleState& s : b.states()) {
      EXPECT_EQ(s.step(), first + static_cast<std::uint64_t>(n / kVehicles));
      EXPECT_EQ(s.vehicle_id(), static_cast<std::uint32_t>(n % kVehicles + 1));
      ++n;
    }
  }
  EXPECT_EQ(outbox.refused(), 0u);
  EXPECT_EQ(drops.Total(), 0u);
}

// A client's view of every vehicle (the viewer's) reads a step as one sample, on vdyn/states and
// nowhere else: it has no reader of vdyn/state, so the writers send it nothing there.
TEST_F(Net, AViewOfEveryVehicleReadsBatchesAndCostsTheWriterNoSingleStates) {
  transport::Participant p(domain_);
  transport::DropCounters drops;
  transport::StateWriters writers(p, drops, transport::StateWriters::Options{.states_key = 5});
  client::SessionView view(p, client::SessionView::Topics{.params = false, .world = false,
                                                          .diagnostics = false,
                                                          .only_vehicle = std::nullopt, .only_server = {}});
  std::uint64_t step = 1;
  auto round = [&] {
    for (std::uint32_t v = 1; v <= 4; ++v) {
      pb::VehicleState s;
      s.set_vehicle_id(v);
      s.set_step(step);
      const std::string b = s.SerializeAsString();
      ASSERT_TRUE(writers.WriteBytes(v, {reinterpret_cast<const std::uint8_t*>(b.data()), b.size()}));
    }
    ASSERT_TRUE(writers.Flush());
    ++step;
  };
  auto all_seen = [&](std::uint64_t after) {
    for (std::uint32_t v = 1; v <= 4; ++v) {
      const client::SessionView::Vehicle* seen = view.vehicle(v);
      if (!seen || seen->state.step() <= after) return false;
    }
    return true;
  };
  // Rounds until the view has matched the writers and seen a step of every vehicle.
  (void)SendUntil(view, 30s, round, [&] {
    view.Poll();
    return all_seen(0);
  });
  ASSERT_TRUE(all_seen(0));
  // The view's readers live in this participant: every one of them matched the writers when it
  // was made. None reads vdyn/state.
  EXPECT_EQ(writers.state_readers(), 0u);
  const std::uint64_t from = step;
  for (int i = 0; i < 20; ++i) round();
  (void)base::PollUntil(
      base::Deadline::After(base::Seconds(30)), base::Milliseconds(10),
      [&] {
        view.Poll();
        return all_seen(from);
      },
      [&](base::Nanos slice) { (void)view.Wait(base::Chrono(slice)); });
  EXPECT_TRUE(all_seen(from));
  EXPECT_EQ(writers.all_states_written(), 0u);
  EXPECT_EQ(drops.Total() + view.drops().Total(), 0u);
}

TEST_F(Net, InputDrivesTheVehicleAndTheWatchdogBrakesWhenItStops) {
  auto server = StartServer({});
  transport::Participant p(domain_);
  transport::DropCounters drops;
  transport::Writer<pb::DriverInput> input(p, TopicId::kInput, 10);
  transport::Reader<pb::VehicleState> states(p, TopicId::kState, &drops);
  pb::VehicleState last;
  // Drive: throttle 1, each sample numbered, written whenever states arrive until the car goes
  // faster than 10 m/s. A state names the input it applied (its sequence).
  std::uint64_t sequence = 0;
  auto drive = [&] {
    bool fast = false;
    return ReadUntil<pb::VehicleState>(
        states, 20s,
        [&](const auto& s) {
          last = s;
          fast = s.v_wt_b().x() > 10.0;
        },
        [&] {
          pb::DriverInput in = Input(1, 1.0, "test-rig");
          in.set_sequence(++sequence);
          EXPECT_TRUE(input.Write(1, in)) << input.last_error();
          return fast;
        });
  };
  ASSERT_TRUE(drive()) << server->Log();
  EXPECT_EQ(last.input().source_id(), "test-rig");
  EXPECT_DOUBLE_EQ(last.control().throttle(), 1.0);
  EXPECT_FALSE(last.control().watchdog_safe_state());
  // Stop writing: the last sample written is `sequence`, after state `last` was read. It is live
  // for the watchdog's 100 ms, counted in simulated steps from the step boundary it arrived at,
  // whatever the wall clock does (a loaded machine delays its arrival, not the count). Then the
  // server brakes; the speed falls.
  std::optional<std::uint64_t> first_final;  // the first state read that applied the last sample
  std::uint64_t before_final = 0;             // the last state read before it
  std::uint64_t last_final = 0;               // the last state read that applied it
  std::optional<std::uint64_t> safe_step;     // the first safe state read after it
  // The reader keeps the newest state: a reader stalled for the sample's 100 steps (a loaded
  // machine) sees none of the states that applied it, and the stop is tried again.
  for (int attempt = 1; attempt <= 3; ++attempt) {
    if (attempt > 1) {
      std::printf("  attempt %d: no state read showed the last sample (the reader stalled)\n",
                  attempt - 1);
      ASSERT_TRUE(drive()) << server->Log();
    }
    const std::uint64_t final_sequence = sequence;
    const double v_stop = last.v_wt_b().x();
    first_final.reset();
    last_final = 0;
    safe_step.reset();
    before_final = last.step();
    double v_later = v_stop;
    // A safe state before the last sample arrives (the samples before it late on a loaded
    // machine) ends when it arrives; a second after one with no state showing the sample read,
    // the try ends.
    std::optional<std::uint64_t> early_safe;
    std::uint64_t newest = 0;
    ASSERT_TRUE(ReadUntil<pb::VehicleState>(states, 20s, [&](const auto& s) {
      const bool safe = s.control().watchdog_safe_state();
      newest = std::max(newest, s.step());
      if (!first_final) {
        if (!safe && s.input().sequence() == final_sequence) {
          first_final = s.step();
        } else {
          before_final = std::max(before_final, s.step());
          if (safe && !early_safe) early_safe = s.step();
        }
      }
      if (first_final && !safe_step && safe) safe_step = s.step();
      if (first_final && !safe_step) last_final = std::max(last_final, s.step());
      if (safe_step && s.step() > *safe_step + 1000) v_later = s.v_wt_b().x();
    }, [&] {
      return (safe_step && v_later < v_stop - 2.0) ||
             (!first_final && early_safe && newest > *early_safe + 1000);
    })) << "the last sample (" << final_sequence << ") applied: " << first_final.has_value()
        << "\n" << server->Log();
    if (first_final) break;
  }
  ASSERT_TRUE(first_final.has_value()) << "in three tries, no state read showed the last sample";
  ASSERT_TRUE(safe_step.has_value());
  // The reader misses states (it keeps the newest), so both ends are bracketed by the states it
  // read: the sample arrived after state `before_final` and by `first_final`; the safe state
  // began after `last_final` and by `safe_step`. Live for the 100 steps after the boundary it
  // arrived at, the sample shows in at most 101 states and the safe state comes more than 100
  // after the state before it. Reading every state, these are 101 and 102.
  EXPECT_GT(*safe_step - before_final, 100u);
  EXPECT_LE(last_final - *first_final, 100u);
  // The figure the README quotes: from the first state that applied the last input.
  std::printf("  watchdog: safe state %llu ms (simulated) after the first state that applied the "
              "last input, %llu ms after the last state before it (watchdog 100 ms; states "
              "missed around it: %llu)\n",
              static_cast<unsigned long long>(*safe_step - *first_final),
              static_cast<unsigned long long>(*safe_step - before_final),
              static_cast<unsigned long long>(*safe_step - last_final - 1));
  transport::Reader<pb::Diagnostics> diag(p, TopicId::kDiagnostics, &drops);
  bool said = false;
  ASSERT_TRUE(ReadUntil<pb::Diagnostics>(diag, 5s, [&](const auto& d) {
    for (const auto& v : d.vehicles()) said = said || (v.vehicle_id() == 1 && v.watchdog_safe_state());
  }, [&] { return said; }));
}

TEST_F(Net, OwnershipPassesFromPrimaryToBackupAndBack) {
  auto f = StartFailover("1000");
  Handover& h = f->h;
  auto until_source = [&](const std::string& want, std::chrono::milliseconds t) {
    return f->UntilSource(want, t, [&](const pb::VehicleState& s) {
      if (h.source == want) {
        EXPECT_DOUBLE_EQ(s.input().throttle(), want == "primary" ? 0.5 : 0.2);
      }
    });
  };
  ASSERT_TRUE(until_source("primary", 20s)) << h.source << "\n" << f->server->Log();
  // The primary rig dies without a goodbye: its input stops and after the lease the backup drives.
  h.first_backup_step = 0;
  f->primary->Signal(SIGKILL);
  f->primary->Wait(5s);
  ASSERT_TRUE(until_source("backup", 10s)) << h.source;
  const std::uint64_t failover_ms = h.failover_ms();
  std::printf("  failover: the backup drives %llu ms (simulated) after the primary's last sample "
              "(lease 200 ms)\n",
              static_cast<unsigned long long>(failover_ms));
  // The lease is 200 ms of wall-clock time at the server; counted here in simulated steps, which
  // a loaded machine's server loop may fall behind on (CI saw 188). Without the lease the backup
  // would drive within a few steps of the primary's death, so half the lease still tells them apart.
  EXPECT_GE(failover_ms, 100u);
  EXPECT_LE(failover_ms, 1000u);
  // It comes back and takes over again.
  f->primary = StartRig("primary", "0.5", 20, "primary2.log");
  ASSERT_TRUE(until_source("primary", 20s)) << h.source;
}

// With a watchdog shorter than the DDS lease the ownership lease follows the watchdog (three
// quarters of it): a primary that dies hands the vehicle to the live backup with no braking in
// between. (A watchdog of 150 ms here, lease 112.5 ms: 37.5 ms to spare for a loaded machine;
// with the fixed 200 ms lease of before, the vehicle braked from 150 ms to 200 ms.)
//
// The lease runs on the server's wall clock (whether a device lives is a matter of real time),
// the watchdog and this test's count on simulated steps (deterministic). A server that runs late
// and catches up runs more simulated than wall-clock time: each step it caught up inside the
// failover stretches the failover, counted here in steps, by one step (CI's sanitizer build on a
// busy 2-core machine counted 225 ms). The server's diagnostics count those steps, so the test
// holds the server to what it can keep: the lease plus the steps caught up.
TEST_F(Net, ABackupTakesOverBeforeTheWatchdogBrakes) {
  auto f = StartFailover("150");
  Handover& h = f->h;
  ASSERT_TRUE(f->UntilSource("primary", 20s)) << h.source << "\n" << f->server->Log();
  // Steps caught up before the primary dies (diagnostics of a time before the kill).
  const std::optional<std::uint64_t> caught_before = f->StepsCaughtUp(0);
  ASSERT_TRUE(caught_before.has_value()) << "no diagnostics from the server";
  h.first_backup_step = 0;
  h.watching = true;
  f->primary->Signal(SIGKILL);
  f->primary->Wait(5s);
  ASSERT_TRUE(f->UntilSource("backup", 10s)) << h.source;
  const std::uint64_t failover_ms = h.failover_ms();
  const std::optional<std::uint64_t> caught_after = f->StepsCaughtUp(h.first_backup_sim_time_ns);
  ASSERT_TRUE(caught_after.has_value()) << "no diagnostics from the server after the failover";
  // Counted from before the kill to up to a second after the failover: never fewer than inside it.
  const std::uint64_t caught = *caught_after - *caught_before;
  std::printf("  failover with a 150 ms watchdog: the backup drives %llu ms (simulated) after the "
              "primary's last sample (lease 112.5 ms); safe state in between: %s; steps the server "
              "caught up around it: %llu\n",
              static_cast<unsigned long long>(failover_ms), h.braked ? "yes" : "no",
              static_cast<unsigned long long>(caught));
  // Before the watchdog, in the server's real time: the simulated failover less the steps caught up.
  EXPECT_LT(failover_ms, 150u + caught);
  // With the server keeping time (fewer steps caught up than the 37.5 ms to spare) no braking.
  if (caught < 37) {
    EXPECT_FALSE(h.braked) << "the vehicle braked in the watchdog's safe state before the backup "
                              "drove, with the server keeping time";
  }
  // Not at once (without the lease the backup drives within a few steps): a quarter of the lease.
  EXPECT_GE(failover_ms, 28u);
}

TEST_F(Net, MalformedPayloadsAndInvalidRequestsAreRefusedAndCounted) {
  auto server = StartServer({});
  transport::Participant p(domain_);
  transport::DropCounters drops;
  transport::ControlClient control(p, "tester");
  ASSERT_TRUE(control.WaitForServer(20s)) << control.last_error() << server->Log();

  // One raw writer (the input topic has exclusive ownership: a second writer of equal strength
  // could be ignored), one instance (key) per bad sample (the reader keeps the last per key).
  dds_qos_t* q = transport::WriterQos(TopicId::kInput, 1);
  const dds_entity_t raw = dds_create_writer(p.handle(), p.Topic(TopicId::kInput), q, nullptr);
  dds_delete_qos(q);
  ASSERT_GT(raw, 0);
  auto write_raw = [&](std::uint32_t key, const char* type, const std::string& payload) {
    vdyn_dds_Envelope env{};
    env.key = key;
    std::strcpy(env.type_name, type);
    std::string bytes = payload;
    env.payload._buffer = reinterpret_cast<std::uint8_t*>(bytes.data());
    env.payload._length = env.payload._maximum = static_cast<std::uint32_t>(bytes.size());
    ASSERT_EQ(dds_write(raw, &env), DDS_RETCODE_OK);
  };
  // A payload that is not a protobuf message, and a type nobody knows.
  write_raw(11, "vdyn.pb.DriverInput", std::string("\xff\xff\xff\xff\x0f", 5));
  write_raw(12, "acme.Joystick", "joystick");
  // A NaN and an out-of-range value in well-formed messages.
  pb::DriverInput nan_input = Input(13, 0.5, "bad");
  nan_input.set_steer(std::numeric_limits<double>::quiet_NaN());
  write_raw(13, "vdyn.pb.DriverInput", nan_input.SerializeAsString());
  write_raw(1, "vdyn.pb.DriverInput", Input(1, 7.0, "bad").SerializeAsString());
  // Button bits no button has: the input is taken, the unknown bits counted and named.
  pb::DriverInput odd = Input(14, 0.1, "odd-buttons");
  odd.set_buttons(pb::BUTTON_HORN | 0x10000u);
  write_raw(14, "vdyn.pb.DriverInput", odd.SerializeAsString());
  // Invalid parameters: rejected with field and reason.
  pb::ControlRequest req;
  req.set_vehicle_id(1);
  req.mutable_set_params()->mutable_params()->set_mass(-1.0);
  const auto reply = control.Call(req, 10s);
  ASSERT_TRUE(reply.has_value()) << control.last_error();
  EXPECT_FALSE(reply->accepted());
  EXPECT_THAT(reply->reason(), HasSubstr("mass"));
  req.mutable_set_params()->mutable_params()->set_mass(1700.0);
  const auto good = control.Call(req, 10s);
  ASSERT_TRUE(good.has_value() && good->accepted());

  // The diagnostics count each kind; the server lives on.
  transport::Reader<pb::Diagnostics> diag(p, TopicId::kDiagnostics, &drops);
  std::map<std::string, std::uint64_t> counts;
  auto has = [&](const std::string& kind) { return counts.count(kind) != 0; };
  ASSERT_TRUE(ReadUntil<pb::Diagnostics>(
      diag, 10s,
      [&](const auto& d) {
        counts.clear();
        for (const auto& dc : d.drops()) counts[dc.kind()] = dc.count();
      },
      [&] {
        return has("malformed payload on vdyn/input") && has("unknown type on vdyn/input") &&
               has("non-finite value on vdyn/input") && has("out-of-range input on vdyn/input") &&
               has("rejected control request") &&
               has("unknown button bits on vdyn/input (ignored)");
      }))
      << server->Log();
  EXPECT_THAT(server->Log(), HasSubstr("non-finite value on vdyn/input: steer"));
  EXPECT_THAT(server->Log(),
              HasSubstr("unknown button bits on vdyn/input (ignored): 'odd-buttons' on vehicle 14 "
                        "set 0x10000"));
  EXPECT_TRUE(server->running());
  dds_delete(raw);
}

TEST_F(Net, LockstepAnswersWhenTheStepsAreDoneAndTimesOutWithoutAClient) {
  auto server = StartServer({"--lockstep", "--lockstep-timeout", "3"});
  transport::Participant p(domain_);
  transport::DropCounters drops;
  transport::ControlClient control(p, "lockstep-client");
  transport::Reader<pb::VehicleState> states(p, TopicId::kState, &drops);
  ASSERT_TRUE(control.WaitForServer(20s)) << control.last_error() << server->Log();
  pb::ControlRequest step;
  step.set_vehicle_id(1);
  step.mutable_step()->set_steps(250);
  *step.mutable_step()->mutable_input() = Input(1, 1.0, "lockstep-client");
  for (int round = 1; round <= 2; ++round) {
    const auto reply = control.Call(step, 20s);
    ASSERT_TRUE(reply.has_value()) << control.last_error();
    EXPECT_TRUE(reply->accepted()) << reply->reason();
    EXPECT_EQ(reply->applied_step(), 250u * round);  // answered when all steps are done
  }
  // Nothing more ran: the server's own count (reliable diagnostics, once a second) stays at 500.
  transport::Reader<pb::Diagnostics> diag(p, TopicId::kDiagnostics, &drops);
  int reports = 0;
  ASSERT_TRUE(ReadUntil<pb::Diagnostics>(diag, 10s, [&](const auto& d) {
    EXPECT_EQ(d.steps(), 500u);
    ++reports;
  }, [&] { return reports >= 2; }));
  pb::ControlRequest resume;
  resume.set_vehicle_id(1);
  resume.mutable_resume();
  const auto refused = control.Call(resume, 10s);
  ASSERT_TRUE(refused.has_value());
  EXPECT_FALSE(refused->accepted());
  // No more requests: the server gives up with a clear message, exit code 3.
  const auto code = server->Wait(20s);
  ASSERT_TRUE(code.has_value()) << "the lockstep server hung";
  EXPECT_EQ(*code, 3);
  EXPECT_THAT(server->Log(), HasSubstr("no control request for 3 s"));
  // And a client without a server times out cleanly too.
  const auto none = control.Call(step, 500ms);
  EXPECT_FALSE(none.has_value());
  EXPECT_THAT(control.last_error(), HasSubstr("no reply"));
}

// A live change past what the model resolves (springs 3000 times stiffer while compressed): the
// steps whose state runs away are discarded; the step request's reply lists them with the reason,
// and the server's diagnostics count them per vehicle by kind (they counted only non-finite ones).
TEST_F(Net, DiscardedStepsAreRepliedAndCountedInTheDiagnosticsByKind) {
  auto server = StartServer({"--lockstep"});
  transport::Participant p(domain_);
  transport::DropCounters drops;
  transport::ControlClient control(p, "stiff-client");
  ASSERT_TRUE(control.WaitForServer(20s)) << control.last_error() << server->Log();
  pb::ControlRequest step;
  step.set_vehicle_id(1);
  step.mutable_step()->set_steps(200);
  *step.mutable_step()->mutable_input() = Input(1, 0.0, "stiff-client");
  const auto settled = control.Call(step, 20s);
  ASSERT_TRUE(settled.has_value()) << control.last_error();
  ASSERT_TRUE(settled->accepted()) << settled->reason();
  ASSERT_EQ(settled->discarded_size(), 0);
  pb::ControlRequest stiff;
  stiff.set_vehicle_id(1);
  auto* params = stiff.mutable_set_params()->mutable_params();
  for (auto* w : {params->mutable_lf(), params->mutable_rf(), params->mutable_lr(),
                  params->mutable_rr()}) {
    w->set_spring_stiffness(1e8);
  }
  const auto changed = control.Call(stiff, 20s);
  ASSERT_TRUE(changed.has_value()) << control.last_error();
  ASSERT_TRUE(changed->accepted()) << changed->reason();
  const auto reply = control.Call(step, 20s);
  ASSERT_TRUE(reply.has_value()) << control.last_error();
  ASSERT_TRUE(reply->accepted()) << reply->reason();
  ASSERT_EQ(reply->discarded_size(), 1) << server->Log();
  const pb::DiscardedSteps& d = reply->discarded(0);
  EXPECT_EQ(d.vehicle_id(), 1u);
  EXPECT_GE(d.count(), 1u);
  EXPECT_THAT(d.reason(), HasSubstr("its state ran away (faster than 1000 m/s"));
  EXPECT_THAT(d.reason(), HasSubstr(": put back at rest where it was"));
  // The diagnostics (reliable, once a second) count every discarded step by its kind.
  transport::Reader<pb::Diagnostics> diag(p, TopicId::kDiagnostics, &drops);
  std::optional<pb::VehicleDiagnostics> seen;
  ASSERT_TRUE(ReadUntil<pb::Diagnostics>(diag, 10s, [&](const auto& m) {
    for (const auto& v : m.vehicles()) {
      if (v.vehicle_id() == 1) seen = v;
    }
  }, [&] { return seen.has_value(); }));
  EXPECT_GE(seen->runaway_steps(), 1u);
  EXPECT_EQ(seen->runaway_steps() + seen->nonfinite_steps() + seen->under_ground_steps(),
            d.count())
      << seen->DebugString();
  EXPECT_THAT(server->Log(), HasSubstr("its state ran away"));
}

TEST_F(Net, LockstepKeepsAClientWhoseStepsTakeLongerThanTheTimeout) {
  // 600,000 steps (100,000 under the sanitizers, 20-30 times slower) take well over the 1 s
  // timeout (checked below); the client's next request is still answered.
  auto server = StartServer({"--lockstep", "--lockstep-timeout", "1"});
  transport::Participant p(domain_);
  transport::ControlClient control(p, "slow-steps");
  ASSERT_TRUE(control.WaitForServer(20s)) << control.last_error() << server->Log();
  pb::ControlRequest step;
  step.set_vehicle_id(1);
  const std::uint32_t n = testing::kSanitized ? 100'000 : 600'000;
  step.mutable_step()->set_steps(n);
  const auto t0 = std::chrono::steady_clock::now();
  const auto first = control.Call(step, 300s);
  ASSERT_TRUE(first.has_value()) << control.last_error();
  EXPECT_EQ(first->applied_step(), n);
  EXPECT_GT(std::chrono::steady_clock::now() - t0, 1s);  // the case this test is about
  step.mutable_step()->set_steps(10);
  const auto second = control.Call(step, 20s);
  ASSERT_TRUE(second.has_value()) << control.last_error() << server->Log();
  EXPECT_EQ(second->applied_step(), n + 10);
}

TEST_F(Net, StepRepliesAreAnsweredEachAtItsOwnStepsOrCancelled) {
  auto server = StartServer({});
  transport::Participant p(domain_);
  transport::ControlClient a(p, "client-a"), b(p, "client-b");
  ASSERT_TRUE(a.WaitForServer(20s)) << a.last_error() << server->Log();
  ASSERT_TRUE(b.WaitForServer(20s));
  pb::ControlRequest pause;
  pause.set_vehicle_id(1);
  pause.mutable_pause();
  ASSERT_TRUE(a.Call(pause, 10s).value_or(pb::ControlReply()).accepted());
  // In real time, paused: a's 50 steps run first (50 ms), b's 100 after them.
  pb::ControlRequest step;
  step.set_vehicle_id(1);
  step.mutable_step()->set_steps(50);
  const auto ra = a.Call(step, 10s);
  step.mutable_step()->set_steps(100);
  const auto rb = b.Call(step, 10s);
  ASSERT_TRUE(ra.has_value() && rb.has_value());
  EXPECT_EQ(rb->applied_step() - ra->applied_step(), 100u);
  // A step request still running when a pause comes is answered: cancelled, with the reason.
  step.mutable_step()->set_steps(500'000);  // 500 s at real time
  std::optional<pb::ControlReply> long_reply;
  std::thread waiter([&] { long_reply = a.Call(step, 20s); });
  // b's pause must come after a's step request: wait until the server runs a's steps.
  transport::DropCounters drops;
  transport::Reader<pb::VehicleState> states(p, TopicId::kState, &drops);
  std::uint64_t seen = 0;
  ASSERT_TRUE(ReadUntil<pb::VehicleState>(states, 10s, [&](const auto& s) { seen = s.step(); },
                                          [&] { return seen > rb->applied_step() + 20; }));
  ASSERT_TRUE(b.Call(pause, 10s).value_or(pb::ControlReply()).accepted());
  waiter.join();
  ASSERT_TRUE(long_reply.has_value()) << a.last_error();
  EXPECT_FALSE(long_reply->accepted());
  EXPECT_THAT(long_reply->reason(), HasSubstr("cancelled by a pause"));
}

// In real time a pause lasts while the client that paused is there: when it leaves without a
// resume, the server resumes (issue 33: the session stayed paused for good). A pause whose client
// stays holds.
TEST_F(Net, APauseEndsWhenTheClientThatPausedLeaves) {
  auto server = StartServer({});
  transport::Participant p(domain_);
  transport::DropCounters drops;
  transport::Reader<pb::VehicleState> states(p, TopicId::kState, &drops);
  pb::ControlRequest pause;
  pause.set_vehicle_id(1);
  pause.mutable_pause();
  std::uint64_t seen = 0;
  auto advancing = [&](std::chrono::seconds within) {
    const std::uint64_t from = seen;
    return ReadUntil<pb::VehicleState>(states, within, [&](const auto& s) { seen = s.step(); },
                                       [&] { return seen > from + 200; });
  };
  // Paused at step `at`: for a second of wall time, no state past it arrives (those already sent
  // may, however slowly the machine delivers them: the judgement is by step, not by time).
  auto paused_at = [&](std::uint64_t at) {
    std::uint64_t newest = 0;
    (void)ReadUntil<pb::VehicleState>(states, 1s, [&](const auto& s) {
      newest = std::max<std::uint64_t>(newest, s.step());
    }, [] { return false; });
    seen = std::max(seen, newest);
    return newest <= at + 1;
  };
  std::uint64_t at = 0;
  {
    transport::Participant client_p(domain_);
    transport::ControlClient client(client_p, "pauser");
    ASSERT_TRUE(client.WaitForServer(20s)) << client.last_error() << server->Log();
    ASSERT_TRUE(advancing(20s));
    const pb::ControlReply reply = client.Call(pause, 10s).value_or(pb::ControlReply());
    ASSERT_TRUE(reply.accepted()) << reply.reason();
    at = reply.applied_step();
    ASSERT_GT(at, 0u);
    ASSERT_TRUE(paused_at(at)) << "not paused at step " << at;
    // Still there: still paused, a second later.
    ASSERT_TRUE(paused_at(at)) << "resumed while the client that paused is there";
  }  // the client leaves without a resume
  seen = at;
  EXPECT_TRUE(advancing(20s)) << "still paused after its client left\n" << server->Log();
  EXPECT_THAT(server->Log(), HasSubstr("the client that paused the session left; resuming"));
}

TEST_F(Net, AHungPrimaryRigHandsOverToTheBackup) {
  auto server = StartServer({"--watchdog-ms", "2000"});
  auto backup = StartRig("backup", "0.2", 5);
  transport::Participant p(domain_);
  transport::DropCounters drops;
  transport::Writer<pb::DriverInput> primary(p, TopicId::kInput, 20);
  transport::Reader<pb::VehicleState> states(p, TopicId::kState, &drops);
  std::string source;
  // The primary drives while it writes...
  ASSERT_TRUE(ReadUntil<pb::VehicleState>(
      states, 20s, [&](const auto& s) { source = s.input().source_id(); },
      [&] {
        EXPECT_TRUE(primary.Write(1, Input(1, 0.5, "primary"))) << primary.last_error();
        return source == "primary";
      }))
      << source << server->Log();
  // ...then its loop hangs: the writer is alive but silent. After the 200 ms lease the backup
  // drives; the vehicle never falls back to the watchdog's safe state (2 s here).
  bool safe = false;
  ASSERT_TRUE(ReadUntil<pb::VehicleState>(states, 10s, [&](const auto& s) {
    source = s.input().source_id();
    safe = safe || s.control().watchdog_safe_state();
  }, [&] { return source == "backup"; })) << source;
  EXPECT_FALSE(safe);
}

TEST_F(Net, ResimulatingACapturedSessionReproducesItsStateHashes) {
  auto server = StartServer({"--world", "facility", "--vehicle-ids", "1,2"});
  transport::Participant p(domain_);
  transport::DropCounters drops;
  transport::Reader<pb::SessionEvent> events(p, TopicId::kEvents, &drops);
  transport::Reader<pb::VehicleState> states(p, TopicId::kState, &drops);
  transport::ControlClient control(p, "recorder-test");
  ASSERT_TRUE(control.WaitForServer(20s)) << control.last_error() << server->Log();
  // Start from a clean slate we have seen all events of: reset both vehicles.
  std::vector<pb::SessionEvent> captured;
  std::map<std::uint32_t, std::map<std::uint64_t, std::uint64_t>> hashes;
  for (std::uint32_t v : {1u, 2u}) {
    pb::ControlRequest reset;
    reset.set_vehicle_id(v);
    reset.mutable_reset();
    ASSERT_TRUE(control.Call(reset, 10s).has_value());
  }
  auto player = StartInput({"--maneuver", "demo"}, "player.log");
  pb::ControlRequest params;
  params.set_vehicle_id(2);
  params.mutable_set_params()->mutable_params()->set_mu(0.6);
  bool params_sent = false;
  std::uint64_t params_step = 0;
  std::size_t n_states = 0;
  // A loop of its own: the request goes out from here, between the waits. The state topic keeps
  // the newest state of each vehicle, so a reader takes at most two per pass: on a loaded machine
  // under the sanitizers a pass can take 25 ms (2,300 states in 60 s in CI). The figures below
  // ask for what such a machine gives in about a minute, with twice that as the bound.
  const base::Deadline deadline = base::Deadline::After(base::Seconds(120));
  while (n_states < 1500 && !deadline.Passed()) {
    (void)states.Wait(base::Chrono(std::min(base::Milliseconds(20), deadline.Left())));
    (void)events.Take([&](const pb::SessionEvent& e, const transport::SampleInfo&) { captured.push_back(e); });
    (void)states.Take([&](const pb::VehicleState& s, const transport::SampleInfo&) {
      hashes[s.vehicle_id()][s.step()] = s.state_hash();
      ++n_states;
    });
    if (!params_sent && n_states > 500) {
      const auto reply = control.Call(params, 10s);
      ASSERT_TRUE(reply.has_value());
      params_step = reply->applied_step();
      params_sent = true;
    }
  }
  ASSERT_GE(n_states, 1500u) << server->Log();
  server->Signal(SIGTERM);
  ASSERT_TRUE(server->Wait(20s).has_value());
  (void)events.Take([&](const pb::SessionEvent& e, const transport::SampleInfo&) { captured.push_back(e); });
  // Keep the events from the resets on (the first Spawned of each vehicle after them).
  std::sort(captured.begin(), captured.end(),
            [](const auto& x, const auto& y) { return x.sequence() < y.sequence(); });
  std::vector<pb::SessionEvent> session;
  bool started = false;
  for (const auto& e : captured) {
    if (!started && e.has_spawned() && e.vehicle_id() == 1) started = true;
    if (started) session.push_back(e);
  }
  ASSERT_FALSE(session.empty());
  std::map<std::uint32_t, std::uint64_t> end;
  for (const auto& [v, h] : hashes) end[v] = h.rbegin()->first + 1;
  const ResimResult res = Resimulate(testing::SharedWorld("facility"), session, end);
  ASSERT_TRUE(res.ok) << res.error;
  std::size_t compared = 0;
  std::size_t compared_after_params = 0;
  for (const auto& [v, h] : hashes) {
    for (const auto& [step, hash] : h) {
      const auto& rh = res.hashes.at(v);
      const auto it = rh.find(step);
      if (it == rh.end()) continue;  // a state from before the reset
      ASSERT_EQ(it->second, hash) << "vehicle " << v << " step " << step;
      ++compared;
      if (v == 2 && step > params_step) ++compared_after_params;
    }
  }
  EXPECT_GT(compared, 1200u);
  EXPECT_GT(compared_after_params, 300u);  // the parameter change re-simulated too
  int input_changes = 0;
  for (const auto& e : session) if (e.has_input_batch() && e.vehicle_id() == 1) input_changes += e.input_batch().samples_size();
  EXPECT_GT(input_changes, 1);  // the player's input really varied
}

TEST_F(Net, SubscriberKeepsReceivingAfterTheServerRestarts) {
  transport::Participant p(domain_);
  transport::DropCounters drops;
  transport::Reader<pb::VehicleState> states(p, TopicId::kState, &drops);
  for (int run = 0; run < 2; ++run) {
    auto server = StartServer({}, "server" + std::to_string(run) + ".log");
    std::uint64_t n = 0;
    ASSERT_TRUE(ReadUntil<pb::VehicleState>(states, 20s, [&](const auto&) { ++n; },
                                            [&] { return n >= 200; }))
        << "run " << run << "\n" << server->Log();
    server->Signal(SIGTERM);
    const auto code = server->Wait(20s);
    ASSERT_TRUE(code.has_value());
    EXPECT_EQ(*code, 0);
  }
}

TEST_F(Net, TwoServersShareADomainWithDistinctVehicles) {
  auto a = StartServer({"--server-id", "lab-a", "--vehicle-ids", "1,2"}, "a.log");
  auto b = StartServer({"--server-id", "lab-b", "--vehicle-ids", "3"}, "b.log");
  transport::Participant p(domain_);
  transport::DropCounters drops;
  transport::Reader<pb::VehicleState> states(p, TopicId::kState, &drops);
  transport::Writer<pb::DriverInput> input(p, TopicId::kInput, 10);
  std::map<std::uint32_t, pb::VehicleState> latest;
  ASSERT_TRUE(ReadUntil<pb::VehicleState>(
      states, 20s, [&](const auto& s) { latest[s.vehicle_id()] = s; },
      [&] {
        EXPECT_TRUE(input.Write(3, Input(3, 1.0, "rig-3"))) << input.last_error();
        return latest.count(3) && latest[3].v_wt_b().x() > 5.0 && latest.count(1) &&
               latest.count(2);
      }))
      << a->Log() << b->Log();
  EXPECT_EQ(latest[1].server_id(), "lab-a");
  EXPECT_EQ(latest[3].server_id(), "lab-b");
  EXPECT_LT(latest[1].v_wt_w().x(), 0.1);  // only vehicle 3 was driven
  EXPECT_LT(latest[2].v_wt_w().x(), 0.1);
}

// --- the edge: bad input of every kind is refused with a reason (issue: nothing gets past the edge)

TEST_F(Net, ASpawnOrTeleportInsideAWallIsRefusedWithTheReason) {
  auto server = StartServer({"--world", "facility"});
  transport::Participant p(domain_);
  transport::ControlClient control(p, "wall-test");
  ASSERT_TRUE(control.WaitForServer(20s)) << control.last_error() << server->Log();
  pb::ControlRequest tp;
  tp.set_vehicle_id(1);
  tp.mutable_teleport()->mutable_pose()->set_x(290.15);  // inside the 0.3 m glass barrier
  tp.mutable_teleport()->set_speed(20.0);
  auto reply = control.Call(tp, 10s);
  ASSERT_TRUE(reply.has_value()) << control.last_error();
  EXPECT_FALSE(reply->accepted());
  EXPECT_THAT(reply->reason(), HasSubstr("the body would start inside 'glass_barrier'"));
  pb::ControlRequest spawn;
  spawn.set_vehicle_id(7);
  spawn.set_server_id("vdyn");
  spawn.mutable_spawn()->mutable_pose()->set_x(3.5);
  spawn.mutable_spawn()->mutable_pose()->set_y(170.1);  // on the billboard's east post
  reply = control.Call(spawn, 10s);
  ASSERT_TRUE(reply.has_value()) << control.last_error();
  EXPECT_FALSE(reply->accepted());
  EXPECT_THAT(reply->reason(), HasSubstr("inside 'billboard'"));
  // Beside the wall, clear of it, is fine.
  tp.mutable_teleport()->mutable_pose()->set_x(280.0);
  reply = control.Call(tp, 10s);
  ASSERT_TRUE(reply.has_value() && reply->accepted()) << (reply ? reply->reason() : "no reply");
}

TEST_F(Net, ASecondServerWithAVehicleOrAnIdInUseIsRefused) {
  auto a = StartServer({"--server-id", "lab-a", "--vehicle-ids", "1"}, "a.log");
  transport::Participant p(domain_);
  transport::DropCounters drops;
  transport::Reader<pb::VehicleState> states(p, TopicId::kState, &drops);
  bool running = false;
  ASSERT_TRUE(ReadUntil<pb::VehicleState>(states, 20s, [&](const auto&) { running = true; },
                                          [&] { return running; })) << a->Log();
  auto b = StartServer({"--server-id", "lab-b", "--vehicle-ids", "2,1"}, "b.log");
  const auto b_code = b->Wait(60s);
  ASSERT_TRUE(b_code.has_value()) << "the second server did not stop\n" << b->Log();
  EXPECT_EQ(*b_code, 2);
  EXPECT_THAT(b->Log(), HasSubstr("vehicle 1 is already run by server 'lab-a' on domain"));
  auto c = StartServer({"--server-id", "lab-a", "--vehicle-ids", "5"}, "c.log");
  const auto c_code = c->Wait(60s);
  ASSERT_TRUE(c_code.has_value()) << c->Log();
  EXPECT_EQ(*c_code, 2);
  EXPECT_THAT(c->Log(), HasSubstr("another server with the id 'lab-a' runs on domain"));
  // A server that starts cleanly beside it refuses to spawn lab-a's vehicle.
  auto d = StartServer({"--server-id", "lab-d", "--vehicle-ids", "3"}, "d.log");
  bool d_running = false;
  ASSERT_TRUE(ReadUntil<pb::VehicleState>(states, 20s, [&](const auto& s) {
    d_running = d_running || s.server_id() == "lab-d";
  }, [&] { return d_running; })) << d->Log();
  transport::ControlClient control(p, "clash-test");
  ASSERT_TRUE(control.WaitForServer(20s)) << control.last_error() << d->Log();
  pb::ControlRequest spawn;
  spawn.set_vehicle_id(1);
  spawn.set_server_id("lab-d");
  spawn.mutable_spawn()->mutable_pose()->set_y(20.0);
  const auto reply = control.Call(spawn, 10s);
  ASSERT_TRUE(reply.has_value()) << control.last_error() << d->Log();
  EXPECT_FALSE(reply->accepted());
  EXPECT_THAT(reply->reason(), HasSubstr("vehicle 1 is run by server 'lab-a'"));
  EXPECT_TRUE(a->running());
  EXPECT_TRUE(d->running());
}

// A wait that fails is counted with the reason, not dropped (issue 19). DDS refuses a negative
// timeout: the one error a test can cause on demand.
TEST_F(Net, AFailedWaitIsCountedNotDiscarded) {
  testing::ExpectLogs logged;  // the drop counters log each kind once
  transport::Participant p(domain_);
  transport::DropCounters drops;
  transport::Reader<pb::VehicleState> states(p, TopicId::kState, &drops);
  transport::Waitset waitset(p, &drops);
  waitset.Attach(states);
  EXPECT_FALSE(waitset.Wait(std::chrono::nanoseconds(-1)));
  EXPECT_FALSE(waitset.Wait(std::chrono::nanoseconds(-1)));
  EXPECT_EQ(waitset.errors(), 2u);
  EXPECT_EQ(drops.Of("DDS error in a waitset"), 2u);
  EXPECT_THAT(waitset.last_error(), HasSubstr("dds_waitset_wait: Bad Parameter"));
  EXPECT_FALSE(states.Wait(std::chrono::nanoseconds(-1)));
  EXPECT_EQ(drops.Of("DDS error on vdyn/state"), 1u);
  EXPECT_FALSE(waitset.Wait(1ms));  // a good wait: no data, no error
  EXPECT_EQ(waitset.errors(), 2u);
  EXPECT_GE(logged.count(), 1);
}

// Starts processes in one instant: each waits on a shared lock of a file this test holds
// exclusively (flock(1)), and all go together when it lets go, once the kernel shows every one of
// them waiting (/proc/locks).
class StartGate {
 public:
  explicit StartGate(std::filesystem::path path) : path_(std::move(path)) {
    fd_ = open(path_.c_str(), O_CREAT | O_RDWR | O_CLOEXEC, 0644);
    EXPECT_GE(fd_, 0) << path_;
    EXPECT_EQ(flock(fd_, LOCK_EX), 0);
    struct stat st {};
    fstat(fd_, &st);
    inode_ = ':';  // "...:INODE " in /proc/locks (appended: GCC 12 warns on "literal" + string)
    inode_ += std::to_string(st.st_ino);
    inode_ += ' ';
  }
  ~StartGate() {
    if (fd_ >= 0) close(fd_);
  }
  // argv run once the gate opens (exec'd in place: the process is the program itself).
  std::vector<std::string> Wrap(std::vector<std::string> argv) const {
    std::vector<std::string> out = {"/bin/sh", "-c", "flock -s \"$0\" true && exec \"$@\"",
                                    path_.string()};
    out.insert(out.end(), argv.begin(), argv.end());
    return out;
  }
  // Lets every waiting process go once `n` wait; false when they did not within the timeout.
  bool Open(int n, std::chrono::milliseconds timeout) {
    // The kernel's lock table is no event to wait on: it is polled, bounded.
    if (!base::PollUntil(
            base::Deadline::After(base::FromChrono(timeout)), base::Milliseconds(2),
            [&] { return Waiting() >= n; },
            [](base::Nanos slice) { base::SleepUntil(base::MonotonicNow() + slice); })) {
      return false;
    }
    return flock(fd_, LOCK_UN) == 0;
  }

 private:
  int Waiting() const {
    std::ifstream locks("/proc/locks");
    std::string line;
    int n = 0;
    while (std::getline(locks, line)) {
      if (line.find("->") != std::string::npos && line.find(inode_) != std::string::npos) ++n;
    }
    return n;
  }
  std::filesystem::path path_;
  int fd_ = -1;
  std::string inode_;
};

// Three servers started in one instant, A={1}, B={2}, C={1,2}: every vehicle is run, each by one
// server, whatever the GUIDs' order (issue 33: a vehicle was left unserved in 6 of 12 trials, B
// giving way to C, which gave way to A). Repeated: a race.
TEST_F(Net, ThreeServersStartedInOneInstantLeaveNoVehicleUnserved) {
  transport::Participant p(domain_);
  transport::DropCounters drops;
  transport::Reader<pb::VehicleState> states(p, TopicId::kState, &drops);
  constexpr int kTrials = 4;
  for (int trial = 0; trial < kTrials; ++trial) {
    SCOPED_TRACE("trial " + std::to_string(trial));
    StartGate gate(dir_ / ("gate3-" + std::to_string(trial)));
    const std::string n = std::to_string(trial);
    std::vector<std::unique_ptr<Process>> servers;
    // Started in a different order each trial (participant GUIDs tend to follow it): C between A
    // and B is the order the old rule failed in.
    std::vector<std::pair<const char*, const char*>> order = {{"a", "1"}, {"c", "1,2"}, {"b", "2"}};
    std::rotate(order.begin(), order.begin() + trial % 3, order.end());
    if (trial >= 3) std::swap(order[0], order[2]);
    for (const auto& [id, vehicles] : order) {
      servers.push_back(std::make_unique<Process>(
          gate.Wrap(ServerArgv({"--server-id", id, "--vehicle-ids", vehicles})),
          dir_ / (std::string(id) + n + ".log")));
    }
    ASSERT_TRUE(gate.Open(3, 20s)) << "the servers never reached the gate";
    std::map<std::uint32_t, std::set<std::string>> runners;  // vehicle -> servers publishing it
    std::map<std::uint32_t, int> counts;
    const bool both = ReadUntil<pb::VehicleState>(
        states, 30s,
        [&](const pb::VehicleState& st) {
          runners[st.vehicle_id()].insert(st.server_id());
          ++counts[st.vehicle_id()];
        },
        [&] { return counts[1] >= 300 && counts[2] >= 300; });
    std::string logs;
    for (const auto& s : servers) logs += s->Log();
    ASSERT_TRUE(both) << "vehicle 1: " << counts[1] << " states, vehicle 2: " << counts[2] << "\n"
                      << logs;
    EXPECT_EQ(runners[1].size(), 1u) << logs;
    EXPECT_EQ(runners[2].size(), 1u) << logs;
    for (auto& s : servers) {
      if (s->running()) {
        s->Signal(SIGTERM);
        EXPECT_EQ(s->Wait(20s), 0) << s->Log();
      } else {
        EXPECT_EQ(s->Wait(1s), 2) << s->Log();  // gave way, with the reason
      }
    }
    while (states.Wait(200ms)) {
      (void)states.Take([](const pb::VehicleState&, const transport::SampleInfo&) {});
    }
  }
}

// Two servers started in one instant with a vehicle (or the id) in common: exactly one runs it,
// the other stops with the reason before it publishes anything, whichever way the tie goes
// (issue 20: both ran vehicle 1 in 6 of 8 trials). Repeated: a race, tried several times.
TEST_F(Net, TwoServersStartedInOneInstantNeverBothRunAVehicle) {
  transport::Participant p(domain_);
  transport::DropCounters drops;
  transport::Reader<pb::VehicleState> states(p, TopicId::kState, &drops);
  constexpr int kTrials = 5;
  int ties = 0;
  for (int trial = 0; trial < kTrials; ++trial) {
    SCOPED_TRACE("trial " + std::to_string(trial));
    // The last trial: the same server id, no vehicle in common.
    const bool same_id = trial == kTrials - 1;
    const std::string id_a = same_id ? "lab" : "lab-a", id_b = same_id ? "lab" : "lab-b";
    StartGate gate(dir_ / ("gate" + std::to_string(trial)));
    const std::string n = std::to_string(trial);
    Process a(gate.Wrap(ServerArgv({"--server-id", id_a, "--vehicle-ids", "1,2"})),
              dir_ / ("a" + n + ".log"));
    Process b(gate.Wrap(ServerArgv({"--server-id", id_b, "--vehicle-ids", same_id ? "3" : "3,1"})),
              dir_ / ("b" + n + ".log"));
    ASSERT_TRUE(gate.Open(2, 20s)) << "the servers never reached the gate";
    // Every state seen from here: which servers published which vehicles.
    std::map<std::string, std::set<std::uint32_t>> published;
    auto take = [&] {
      (void)states.Take([&](const pb::VehicleState& st, const transport::SampleInfo&) {
        published[st.server_id()].insert(st.vehicle_id());
      });
    };
    (void)base::PollUntil(
        base::Deadline::After(base::Seconds(30)), base::Milliseconds(20),
        [&] {
          take();
          return !a.running() || !b.running();
        },
        [&](base::Nanos slice) { (void)states.Wait(base::Chrono(slice)); });
    ASSERT_NE(a.running(), b.running()) << "both still run or both stopped\n" << a.Log() << b.Log();
    Process& loser = a.running() ? b : a;
    Process& winner = a.running() ? a : b;
    const std::string winner_id = a.running() ? id_a : id_b;
    ASSERT_EQ(loser.Wait(1s), 2) << loser.Log();
    const std::string why = loser.Log();
    if (same_id) {
      EXPECT_THAT(why, HasSubstr("another server with the id 'lab'")) << why;
    } else {
      EXPECT_THAT(why, HasSubstr("vehicle 1 is")) << why;
      EXPECT_THAT(why, HasSubstr("server '" + winner_id + "'")) << why;
    }
    if (why.find("started at the same moment") != std::string::npos) ++ties;
    // The winner runs on, and is the only server whose states arrive: the loser published none.
    std::uint64_t n_winner = 0;
    ASSERT_TRUE(ReadUntil<pb::VehicleState>(
        states, 20s,
        [&](const pb::VehicleState& st) {
          published[st.server_id()].insert(st.vehicle_id());
          n_winner += st.server_id() == winner_id;
        },
        [&] { return n_winner >= 300; }))
        << winner.Log();
    EXPECT_EQ(published.size(), 1u) << "states from more than one server";
    EXPECT_EQ(published.count(winner_id), 1u);
    EXPECT_TRUE(winner.running());
    winner.Signal(SIGTERM);
    EXPECT_EQ(winner.Wait(20s), 0) << winner.Log();
    // States still in flight from this trial are not the next one's.
    while (states.Wait(200ms)) take();
  }
  std::printf("  %d of %d trials met in the claim phase (a tie); the rest found a running server\n",
              ties, kTrials);
  // The gate makes the starts simultaneous: the tie itself was exercised.
  EXPECT_GE(ties, 1);
}

// A live rig whose input is refused loses the vehicle to a valid backup within the lease, and the
// diagnostics name it and say why.
TEST_F(Net, ARigSendingBadInputLosesTheVehicleToAValidBackup) {
  auto server = StartServer({"--watchdog-ms", "2000"});
  auto backup = StartRig("backup", "0.2", 5);
  transport::Participant p(domain_);
  transport::DropCounters drops;
  transport::Writer<pb::DriverInput> primary(p, TopicId::kInput, 20);
  transport::Writer<pb::DriverInput> strong(p, TopicId::kInput, 30);
  transport::Reader<pb::VehicleState> states(p, TopicId::kState, &drops);
  transport::Reader<pb::Diagnostics> diag(p, TopicId::kDiagnostics, &drops);
  std::string source;
  bool safe = false;
  ASSERT_TRUE(ReadUntil<pb::VehicleState>(
      states, 20s, [&](const auto& s) { source = s.input().source_id(); },
      [&] {
        EXPECT_TRUE(primary.Write(1, Input(1, 0.5, "primary"))) << primary.last_error();
        return source == "primary";
      }))
      << source << server->Log();
  // The primary goes on writing, but NaN steering: refused, it no longer counts as live.
  pb::DriverInput nan_input = Input(1, 0.5, "primary");
  nan_input.set_steer(std::numeric_limits<double>::quiet_NaN());
  const auto t0 = std::chrono::steady_clock::now();
  ASSERT_TRUE(ReadUntil<pb::VehicleState>(
      states, 10s,
      [&](const auto& s) {
        source = s.input().source_id();
        safe = safe || s.control().watchdog_safe_state();
      },
      [&] {
        EXPECT_TRUE(primary.Write(1, nan_input)) << primary.last_error();
        return source == "backup";
      }))
      << source << server->Log();
  std::printf("  a primary sending NaN lost the vehicle to the backup after %.0f ms (wall clock)\n",
              std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  EXPECT_FALSE(safe);
  // A stronger rig (30) with throttle 5: refused too; the backup keeps driving.
  pb::DriverInput wild = Input(1, 5.0, "rig30");
  bool rig30_drove = false;
  int n = 0;
  ASSERT_TRUE(ReadUntil<pb::VehicleState>(
      states, 10s,
      [&](const auto& s) { rig30_drove = rig30_drove || s.input().source_id() == "rig30"; },
      [&] {
        EXPECT_TRUE(strong.Write(1, wild)) << strong.last_error();
        EXPECT_TRUE(primary.Write(1, nan_input)) << primary.last_error();
        return ++n > 100;
      }));
  EXPECT_FALSE(rig30_drove);
  // The diagnostics say who was refused, and why.
  std::map<std::string, pb::InputSourceDiagnostics> seen;
  ASSERT_TRUE(ReadUntil<pb::Diagnostics>(
      diag, 10s,
      [&](const auto& d) {
        for (const auto& v : d.vehicles()) {
          for (const auto& src : v.sources()) seen[src.source_id()] = src;
        }
      },
      [&] {
        EXPECT_TRUE(strong.Write(1, wild)) << strong.last_error();
        EXPECT_TRUE(primary.Write(1, nan_input)) << primary.last_error();
        return seen.count("primary") && seen.count("rig30") && seen.count("backup") &&
               seen["primary"].refused() > 0 && seen["rig30"].refused() > 0;
      }))
      << server->Log();
  EXPECT_THAT(seen["primary"].last_refusal(), HasSubstr("non-finite value on vdyn/input: steer"));
  EXPECT_EQ(seen["primary"].strength(), 20);
  EXPECT_FALSE(seen["primary"].driving());
  EXPECT_THAT(seen["rig30"].last_refusal(), HasSubstr("throttle must be in [-1, 1], got 5"));
  EXPECT_FALSE(seen["rig30"].driving());
  EXPECT_TRUE(seen["backup"].driving());
  EXPECT_EQ(seen["backup"].strength(), 5);
}

// Every request is answered, also one the server refuses before it could apply it.
TEST_F(Net, EveryRequestIsAnsweredWithAReason) {
  auto server = StartServer({});
  transport::Participant p(domain_);
  transport::DropCounters drops;
  transport::ControlClient control(p, "answers");
  ASSERT_TRUE(control.WaitForServer(20s)) << control.last_error() << server->Log();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  pb::ControlRequest tp;
  tp.set_vehicle_id(1);
  tp.mutable_teleport()->mutable_pose()->set_x(nan);
  auto reply = control.Call(tp, 10s);
  ASSERT_TRUE(reply.has_value()) << control.last_error();
  EXPECT_FALSE(reply->accepted());
  EXPECT_THAT(reply->reason(), HasSubstr("teleport.pose.x must be a finite number"));
  pb::ControlRequest mass;
  mass.set_vehicle_id(1);
  mass.mutable_set_params()->mutable_params()->set_mass(nan);
  reply = control.Call(mass, 10s);
  ASSERT_TRUE(reply.has_value()) << control.last_error();
  EXPECT_THAT(reply->reason(), HasSubstr("set_params.params.mass must be a finite number"));

  // Raw writes: an envelope key that is not the vehicle id, an id too long to be an id.
  transport::Writer<pb::ControlRequest> raw(p, TopicId::kControl);
  transport::Reader<pb::ControlReply> replies(p, TopicId::kControlReply, &drops);
  pb::ControlRequest reset;
  reset.set_vehicle_id(1);
  reset.set_request_id(77);
  reset.set_client_id("raw");
  reset.mutable_reset();
  ASSERT_TRUE(raw.Write(5, reset));
  pb::ControlRequest long_id = reset;
  long_id.set_request_id(78);
  long_id.set_client_id(std::string(100, 'x'));
  ASSERT_TRUE(raw.Write(1, long_id));
  std::map<std::uint64_t, pb::ControlReply> got;
  ASSERT_TRUE(ReadUntil<pb::ControlReply>(replies, 10s, [&](const auto& r) {
    got[r.request_id()] = r;
  }, [&] { return got.count(77) && got.count(78); })) << server->Log();
  EXPECT_FALSE(got[77].accepted());
  EXPECT_THAT(got[77].reason(), HasSubstr("envelope key 5 does not match vehicle_id 1"));
  EXPECT_FALSE(got[78].accepted());
  EXPECT_THAT(got[78].reason(), HasSubstr("client_id is longer than 64 bytes"));
  EXPECT_EQ(got[78].client_id(), std::string(64, 'x'));

  // A 10 MB request is not even parsed: dropped and counted, and the server goes on answering.
  pb::ControlRequest huge = reset;
  huge.set_request_id(79);
  huge.set_client_id(std::string(10'000'000, 'y'));
  EXPECT_FALSE(raw.Write(1, huge));  // our own writer refuses it...
  dds_qos_t* q = transport::WriterQos(TopicId::kControl);
  const dds_entity_t w = dds_create_writer(p.handle(), p.Topic(TopicId::kControl), q, nullptr);
  dds_delete_qos(q);
  ASSERT_GT(w, 0);
  std::string bytes = huge.SerializeAsString();
  vdyn_dds_Envelope env{};
  env.key = 1;
  std::strcpy(env.type_name, "vdyn.pb.ControlRequest");
  env.payload._buffer = reinterpret_cast<std::uint8_t*>(bytes.data());
  env.payload._length = env.payload._maximum = static_cast<std::uint32_t>(bytes.size());
  ASSERT_EQ(dds_write(w, &env), DDS_RETCODE_OK);  // ...a foreign one need not
  reply = control.Call(mass, 10s);
  ASSERT_TRUE(reply.has_value()) << control.last_error();
  transport::Reader<pb::Diagnostics> diag(p, TopicId::kDiagnostics, &drops);
  bool counted = false;
  ASSERT_TRUE(ReadUntil<pb::Diagnostics>(diag, 10s, [&](const auto& d) {
    for (const auto& dc : d.drops()) counted = counted || dc.kind() == "oversized payload on vdyn/control";
  }, [&] { return counted; })) << server->Log();
  dds_delete(w);

  // A vehicle command for a vehicle no server owns: the client library says so, bounded.
  pb::ControlRequest nobody;
  nobody.set_vehicle_id(99);
  nobody.mutable_reset();
  EXPECT_FALSE(control.Call(nobody, 1500ms).has_value());
  EXPECT_THAT(control.last_error(), HasSubstr("is a server running that owns vehicle 99?"));
  EXPECT_TRUE(server->running());
}

// Writes every request of a burst as fast as the writer takes them (a write the writer refuses is
// tried again, bounded), then reads replies until each has one, or the timeout.
struct Burst {
  transport::Writer<pb::ControlRequest>& writer;
  transport::Reader<pb::ControlReply>& replies;
  std::string client_id;  // the burst's requests': other replies (a hello's) are not counted
  std::map<std::uint64_t, pb::ControlReply> got;
  std::uint64_t duplicates = 0;
  void Send(const pb::ControlRequest& r) {
    for (int tries = 0; !writer.Write(r.vehicle_id(), r); ++tries) {
      ASSERT_LT(tries, 5000) << writer.last_error();
      std::this_thread::sleep_for(1ms);  // the writer's history is full: the server is reading
      (void)replies.Take([&](const pb::ControlReply& reply, const auto&) { Note(reply); });
    }
  }
  void Note(const pb::ControlReply& reply) {
    if (reply.client_id() != client_id) return;
    if (!got.emplace(reply.request_id(), reply).second) ++duplicates;
  }
  bool AllAnswered(std::size_t n, std::chrono::milliseconds timeout) {
    return ReadUntil<pb::ControlReply>(
        replies, timeout, [&](const auto& r) { Note(r); }, [&] { return got.size() >= n; });
  }
};

// Every request of a burst gets exactly one reply (issue 20: 2,000 resets gave 1,474 replies and
// 10,000 spawns 7,980, and no counter said so), and the diagnostics' request counters agree with
// what the client counted.
TEST_F(Net, EveryRequestOfABurstGetsExactlyOneReply) {
  auto server = StartServer({"--server-id", "burst"});
  transport::Participant p(domain_);
  transport::DropCounters drops;
  transport::Writer<pb::ControlRequest> writer(p, TopicId::kControl);
  transport::Reader<pb::ControlReply> replies(p, TopicId::kControlReply, &drops);
  transport::Reader<pb::Diagnostics> diag(p, TopicId::kDiagnostics, &drops);
  transport::ControlClient control(p, "burst-probe");
  ASSERT_TRUE(control.WaitForServer(20s)) << control.last_error() << server->Log();
  Burst burst{writer, replies, "burst", {}, 0};
  constexpr int kResets = 2000, kSpawns = 10000;
  std::uint64_t id = 0;
  for (int i = 0; i < kResets; ++i) {
    pb::ControlRequest r;
    r.set_request_id(++id);
    r.set_client_id("burst");
    r.set_vehicle_id(1);
    r.mutable_reset();
    burst.Send(r);
  }
  for (int i = 0; i < kSpawns; ++i) {
    pb::ControlRequest r;
    r.set_request_id(++id);
    r.set_client_id("burst");
    r.set_server_id("burst");
    r.set_vehicle_id(static_cast<std::uint32_t>(1000 + i));
    // Every other one where there is no ground (the flat world ends at 20 km).
    r.mutable_spawn()->mutable_pose()->set_x(i % 2 == 0 ? 10.0 * (i / 2 % 100) : 1e5);
    r.mutable_spawn()->mutable_pose()->set_y(i % 2 == 0 ? 6.0 * (i / 200) : 0.0);
    burst.Send(r);
  }
  ASSERT_TRUE(burst.AllAnswered(kResets + kSpawns, 120s))
      << burst.got.size() << " of " << kResets + kSpawns << " answered\n"
      << server->Log();
  EXPECT_EQ(burst.duplicates, 0u);
  int resets_accepted = 0, spawned = 0, full = 0, off_ground = 0;
  for (const auto& [request_id, reply] : burst.got) {
    if (request_id <= kResets) {
      resets_accepted += reply.accepted();
      continue;
    }
    spawned += reply.accepted();
    full += reply.reason().find("maximum of 64 vehicles") != std::string::npos;
    off_ground += reply.reason().find("no terrain below") != std::string::npos;
  }
  EXPECT_EQ(resets_accepted, kResets);
  // Applied in order: the first 63 spawns on the ground fill the server (64 with vehicle 1), the
  // 62 off the ground between them are refused for that, and every later one because it is full.
  EXPECT_EQ(spawned, 63);
  EXPECT_EQ(off_ground, 62);
  EXPECT_EQ(full, kSpawns - 63 - 62);
  for (int i = 0; i < 63; ++i) {
    EXPECT_TRUE(burst.got[kResets + 1 + 2 * static_cast<std::uint64_t>(i)].accepted()) << i;
  }
  // The server's own count: every request received, every one answered, none unanswered, and
  // no event lost on the way. A report may fall between a request's receipt and its reply (the
  // probe's retry: 12,002 received and 12,001 sent in one, 2026-12-05): the counts must meet in
  // a later one.
  pb::Diagnostics last;
  ASSERT_TRUE(ReadUntil<pb::Diagnostics>(
      diag, 20s, [&](const auto& d) { last = d; },
      [&] {
        return last.replies_sent() >= kResets + kSpawns &&
               last.requests_received() == last.replies_sent();
      }))
      << last.ShortDebugString();
  EXPECT_EQ(last.requests_received(), last.replies_sent()) << last.ShortDebugString();
  EXPECT_EQ(last.requests_unanswered(), 0u);
  for (const auto& dc : last.drops()) {
    EXPECT_THAT(dc.kind(), ::testing::Not(HasSubstr("event queue full"))) << dc.count();
    EXPECT_THAT(dc.kind(), ::testing::Not(HasSubstr("request queue full"))) << dc.count();
    EXPECT_THAT(dc.kind(), ::testing::Not(HasSubstr("unanswered"))) << dc.count();
  }
  EXPECT_TRUE(server->running());
}

// A burst of 16 spawns is answered in full and every new vehicle runs (issue 19).
TEST_F(Net, ABurstOf16SpawnsIsAnsweredInFullAndEveryVehicleRuns) {
  auto server = StartServer({"--server-id", "lab", "--world", "facility"});
  transport::Participant p(domain_);
  transport::DropCounters drops;
  transport::Writer<pb::ControlRequest> writer(p, TopicId::kControl);
  transport::Reader<pb::ControlReply> replies(p, TopicId::kControlReply, &drops);
  transport::Reader<pb::VehicleState> states(p, TopicId::kState, &drops);
  transport::ControlClient control(p, "burst-probe");
  ASSERT_TRUE(control.WaitForServer(30s)) << control.last_error() << server->Log();
  Burst burst{writer, replies, "spawner", {}, 0};
  for (std::uint32_t i = 0; i < 16; ++i) {
    pb::ControlRequest r;
    r.set_request_id(i + 1);
    r.set_client_id("spawner");
    r.set_server_id("lab");
    r.set_vehicle_id(10 + i);
    r.mutable_spawn()->mutable_pose()->set_x(-200.0 + 8.0 * i);  // along the test road
    r.mutable_spawn()->mutable_pose()->set_y(0.0);
    burst.Send(r);
  }
  ASSERT_TRUE(burst.AllAnswered(16, 30s)) << burst.got.size() << "\n" << server->Log();
  for (const auto& [request_id, reply] : burst.got) {
    EXPECT_TRUE(reply.accepted()) << request_id << ": " << reply.reason();
  }
  std::set<std::uint32_t> running;
  ASSERT_TRUE(ReadUntil<pb::VehicleState>(
      states, 20s, [&](const pb::VehicleState& s) { running.insert(s.vehicle_id()); },
      [&] { return running.size() >= 17; }))
      << running.size();
}

// Steps asked for by a client that then leaves are not run for nobody: the server publishes its
// diagnostics while it steps, and drops the remaining steps when the client is gone.
TEST_F(Net, TheStepsOfAClientThatLeavesAreDropped) {
  auto server = StartServer({"--lockstep", "--lockstep-timeout", "60"});
  transport::Participant p(domain_);
  transport::DropCounters drops;
  transport::Reader<pb::Diagnostics> diag(p, TopicId::kDiagnostics, &drops);
  std::vector<std::uint64_t> steps;
  std::uint64_t cancelled = 0, unanswered = 0;
  auto on_diag = [&](const pb::Diagnostics& d) {
    steps.push_back(d.steps());
    unanswered = d.requests_unanswered();
    for (const auto& dc : d.drops()) {
      if (dc.kind() ==
          "control request unanswered: its client went away before its steps were done") {
        cancelled = dc.count();
      }
    }
  };
  {
    auto leaving = std::make_unique<transport::Participant>(domain_);
    transport::ControlClient client(*leaving, "leaver");
    ASSERT_TRUE(client.WaitForServer(20s)) << client.last_error() << server->Log();
    pb::ControlRequest step;
    step.set_vehicle_id(1);
    step.mutable_step()->set_steps(600'000);
    EXPECT_FALSE(client.Call(step, 100ms).has_value());  // running: no answer yet
    // The server publishes its diagnostics while it steps.
    ASSERT_TRUE(ReadUntil<pb::Diagnostics>(diag, 30s, on_diag, [&] {
      return !steps.empty() && steps.back() > 0;
    })) << server->Log();
  }  // the client's participant goes away, its steps unfinished
  steps.clear();
  ASSERT_TRUE(ReadUntil<pb::Diagnostics>(diag, 30s, on_diag, [&] {
    return steps.size() >= 3 && steps[steps.size() - 1] == steps[steps.size() - 2];
  })) << server->Log();
  EXPECT_LT(steps.back(), 600'000u);
  EXPECT_EQ(cancelled, 1u);
  EXPECT_EQ(unanswered, 1u);
  // Said in the operator's terms (issue 21: "a control client is gone; its pending steps are
  // dropped" spoke the server's internals).
  const std::string log = server->Log();
  EXPECT_THAT(log, HasSubstr("client 'leaver' went away before the 600000 steps it asked for "
                             "were done: the "));
  EXPECT_THAT(log, HasSubstr(" still to run are cancelled, and the simulation stays paused at "));
  EXPECT_THAT(log, ::testing::Not(HasSubstr("pending steps")));
}

}  // namespace
}  // namespace vdyn
