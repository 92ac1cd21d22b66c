// input_bench: vdyn-input's rig loop measured against the real-time server over loopback DDS
// (issue: drive it with a wheel, pedals and keyboard through SDL2). One run, one machine:
//  - a wheel (an SDL virtual joystick with the G29's ids, its steering swept every sample) read by
//    the rig loop at 1 kHz in this process, its force feedback played on a recording device;
//  - SDL sample -> the first state that applied it, as a client sees it (the input's stamp is the
//    sample's monotonic time and travels back in the state, as in net_bench);
//  - SDL sample -> its DDS write;
//  - state -> the haptic update that played it (the server's wall-clock source timestamp to the
//    update, same machine);
//  - CPU, each client alone with the server, one after another (several 1 kHz processes on few
//    cores make each other's wake-ups dearer): the rig loop's own thread and its whole process
//    (the wheel client), then `vdyn-input keyboard` with its window on an Xvfb display (when
//    Xvfb is installed), `vdyn-input play demo` at 1 kHz (the maneuver player), and two floors as
//    peers: a bare 1 kHz sleep loop (any 1 kHz process on this machine) and a bare 1 kHz input
//    writer (a process that does nothing but the publishing: one DriverInput written on
//    DDS a millisecond, no state read, no SDL).
//
// Usage: input_bench [seconds=30] [--breakdown]
//   Latency over `seconds`, then each client's CPU over half as long (at least 5 s).
//   --breakdown also splits the rig thread's CPU into writing, taking states and the rest (it reads
//   the thread's CPU clock around each part, a system call each: the totals grow a little).
#include <signal.h>
#include <time.h>
#include <unistd.h>

#include <SDL2/SDL.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <mutex>
#include <numbers>
#include <string>
#include <vector>

#include <fmt/format.h>

#include "child.h"
#include "vdyn/base/time.h"
#include "vdyn/client/driver_input.h"
#include "vdyn/client/loop.h"
#include "vdyn/state.pb.h"
#include "vdyn/transport/dds.h"
#include "vdyn/wheel_input/dds_link.h"
#include "vdyn/wheel_input/devices.h"
#include "vdyn/wheel_input/ffb.h"
#include "vdyn/wheel_input/latency.h"
#include "vdyn/wheel_input/rig.h"

namespace {

namespace wi = vdyn::wheel_input;
using vdyn::base::MonotonicNow;
using vdyn::bench::ProcessCpuSeconds;
using vdyn::bench::Spawn;
using vdyn::bench::WaitPid;

double ThreadCpuSeconds() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + static_cast<double>(t.tv_nsec) * 1e-9;
}

// The floor: a process that only wakes up every millisecond.
int SleepLoop(double seconds) {
  vdyn::client::FixedRateLoop loop(vdyn::base::Milliseconds(1));
  const auto end = MonotonicNow() + vdyn::base::Nanos{static_cast<std::int64_t>(seconds * 1e9)};
  while (MonotonicNow() < end) loop.Wait();
  return 0;
}

// The floor of the publishing the issue asks for: one input written on vdyn/input every
// millisecond (vehicle 1, the weakest strength so it never drives), nothing read, no SDL.
int WriterLoop(double seconds, std::uint32_t domain) {
  vdyn::transport::Participant participant(domain);
  vdyn::client::InputPublisher writer(participant, 1, "floor-writer", 1);
  vdyn::pb::DriverInput msg;
  msg.set_steer_mode(vdyn::pb::STEER_ROAD_WHEEL);
  vdyn::client::FixedRateLoop loop(vdyn::base::Milliseconds(1));
  const auto end = MonotonicNow() + vdyn::base::Nanos{static_cast<std::int64_t>(seconds * 1e9)};
  std::uint64_t failed = 0;
  while (MonotonicNow() < end) {
    loop.Wait();
    if (!writer.Publish(msg)) ++failed;
  }
  std::printf("floor writer: %llu written, %llu failed\n",
              static_cast<unsigned long long>(writer.sent()),
              static_cast<unsigned long long>(failed));
  return failed == 0 ? 0 : 1;
}

// Decorators that add up the rig thread's CPU time spent writing inputs and taking states.
class TimedSink : public wi::InputSink {
 public:
  explicit TimedSink(wi::InputSink& s) : s_(s) {}
  // Reading the thread's CPU clock is a system call: only with --breakdown (otherwise the
  // measurement would be charged to the rig thread it measures).
  bool Publish(vdyn::pb::DriverInput& msg, vdyn::base::MonoTime sampled) override {
    if (!on) return s_.Publish(msg, sampled);
    const double t = ThreadCpuSeconds();
    const bool ok = s_.Publish(msg, sampled);
    cpu += ThreadCpuSeconds() - t;
    return ok;
  }
  std::string last_error() const override { return s_.last_error(); }
  bool on = false;
  double cpu = 0;

 private:
  wi::InputSink& s_;
};

class TimedFeed : public wi::VehicleFeed {
 public:
  explicit TimedFeed(wi::VehicleFeed& f) : f_(f) {}
  void Poll() override {
    if (!on) return f_.Poll();
    const double t = ThreadCpuSeconds();
    f_.Poll();
    cpu += ThreadCpuSeconds() - t;
  }
  const vdyn::pb::VehicleState* state() const override { return f_.state(); }
  vdyn::base::MonoTime state_received() const override { return f_.state_received(); }
  std::int64_t state_source_wall_ns() const override { return f_.state_source_wall_ns(); }
  const vdyn::pb::VehicleParams* params() const override { return f_.params(); }
  bool on = false;
  double cpu = 0;

 private:
  wi::VehicleFeed& f_;
};

}  // namespace

int main(int argc, char** argv) {
  if (argc >= 3 && std::string(argv[1]) == "--sleep-loop") return SleepLoop(std::atof(argv[2]));
  if (argc >= 4 && std::string(argv[1]) == "--writer-loop") {
    return WriterLoop(std::atof(argv[2]), static_cast<std::uint32_t>(std::atoi(argv[3])));
  }
  const double seconds = argc > 1 ? std::atof(argv[1]) : 30.0;
  const bool breakdown = argc > 2 && std::string(argv[2]) == "--breakdown";
  if (std::getenv("CYCLONEDDS_URI") == nullptr) {
    setenv("CYCLONEDDS_URI",
           "<General><Interfaces><NetworkInterface name=\"lo\"/></Interfaces></General>"
           "<Discovery><MaxAutoParticipantIndex>64</MaxAutoParticipantIndex></Discovery>",
           1);
  }
  setenv("VDYN_CONFIG_DIR", "/nonexistent-vdyn-input-bench", 1);  // the table's G29, no user file
  const std::uint32_t domain = 150 + static_cast<std::uint32_t>(getpid()) % 60;
  const std::string tmp = fmt::format("/tmp/vdyn-input-bench-{}", getpid());
  const std::string dom = std::to_string(domain);
  // Latency for `seconds`, then each client's CPU alone with the server for half as long.
  const double warmup = 3.0, settle = 1.0, peer_warmup = 3.0;
  const double cpu_seconds = std::max(5.0, seconds / 2);
  const double server_seconds =
      warmup + seconds + settle + cpu_seconds + 4 * (peer_warmup + cpu_seconds + 2) + 30;
  auto secs = [](double s) { return vdyn::base::Nanos{static_cast<std::int64_t>(s * 1e9)}; };

  const pid_t server = Spawn({VDYN_SERVER_BINARY, "--domain", dom, "--world", "flat", "--no-status",
                              "--duration", std::to_string(server_seconds)},
                             tmp + "-server.log");
  const pid_t xvfb = vdyn::bench::StartXvfb(tmp + "-xvfb.log", "800x600x24");

  // The rig in this process: a virtual G29, DDS, a recording force-feedback device.
  wi::SdlContext sdl(false);
  SDL_VirtualJoystickDesc d{};
  d.version = SDL_VIRTUAL_JOYSTICK_DESC_VERSION;
  d.type = SDL_JOYSTICK_TYPE_WHEEL;
  d.naxes = 4;
  d.nbuttons = 25;
  d.vendor_id = 0x046d;
  d.product_id = 0xc24f;
  d.name = "virtual G29";
  const int index = SDL_JoystickAttachVirtualEx(&d);
  SDL_Joystick* wheel = SDL_JoystickOpen(index);
  if (wheel == nullptr) {
    std::fprintf(stderr, "input_bench: no virtual joystick: %s\n", SDL_GetError());
    return 1;
  }
  SDL_JoystickSetVirtualAxis(wheel, 1, 32767);  // clutch released
  SDL_JoystickSetVirtualAxis(wheel, 2, 0);      // half throttle
  SDL_JoystickSetVirtualAxis(wheel, 3, 32767);  // brake released
  auto participant = std::make_unique<vdyn::transport::Participant>(domain);
  auto link = std::make_unique<wi::DdsLink>(*participant, 1, "input_bench", 30);
  if (!link->WaitForParams(std::chrono::seconds(30))) {
    std::fprintf(stderr, "input_bench: no server\n");
    return 1;
  }
  wi::RigConfig cfg;
  cfg.source = wi::RigConfig::Source::kWheel;
  cfg.window = false;
  cfg.source_id = "input_bench";
  cfg.ffb_rate_hz = 500;
  wi::RecordingHaptic* haptic = nullptr;
  TimedSink sink(*link);
  TimedFeed feed(*link);
  auto rig = std::make_unique<wi::RigLoop>(
      cfg, sdl, sink, feed, link.get(),
      [&](const wi::WheelDevice&, std::string*) -> std::unique_ptr<wi::HapticDevice> {
        auto h = std::make_unique<wi::RecordingHaptic>();
        haptic = h.get();
        return h;
      });
  rig->Start();

  // The measuring subscriber: a participant of its own, taking on DDS's receive thread. It runs
  // for the latency phase only.
  auto observer = std::make_unique<vdyn::transport::Participant>(domain);
  vdyn::transport::DropCounters drops;
  auto states = std::make_unique<vdyn::transport::Reader<vdyn::pb::VehicleState>>(
      *observer, vdyn::transport::TopicId::kState, &drops);
  std::mutex mu;
  wi::LatencyHistogram sample_to_state;
  std::uint64_t last_seq = 0;
  bool measuring = false;
  states->OnDataAvailable([&] {
    (void)states->Take([&](const vdyn::pb::VehicleState& s, const vdyn::transport::SampleInfo&) {
      const std::int64_t now = MonotonicNow().ns;
      if (s.vehicle_id() != 1 || s.input().source_id() != "input_bench") return;
      std::lock_guard<std::mutex> lock(mu);
      if (!measuring || s.input().sequence() <= last_seq) return;
      last_seq = s.input().sequence();
      sample_to_state.Add(vdyn::base::Nanos{now - s.input().stamp_ns()});
    });
  });

  // The rig's ticks until `to`, with a hand on the wheel: +-90 degrees at 0.5 Hz, a new value
  // every sample; `at_from` runs once, at the first tick at or after `from`.
  const auto t0 = MonotonicNow();
  std::uint64_t skipped = 0;
  double tick_cpu = 0;
  bool time_ticks = false;
  auto run_rig = [&](vdyn::base::MonoTime from, vdyn::base::MonoTime to, auto&& at_from) {
    vdyn::client::FixedRateLoop clock(vdyn::base::Milliseconds(1));
    bool started = false;
    while (true) {
      const auto tick = clock.Wait();
      if (tick.now >= to) break;
      const double t = (tick.now - t0).seconds();
      SDL_JoystickSetVirtualAxis(
          wheel, 0,
          static_cast<Sint16>(std::lround(-6553.5 * std::sin(2 * std::numbers::pi * 0.5 * t))));
      if (!started && tick.now >= from) {
        started = true;
        at_from();
      }
      if (started && time_ticks) {
        const double before = ThreadCpuSeconds();
        rig->Tick(tick.now);
        tick_cpu += ThreadCpuSeconds() - before;
      } else {
        rig->Tick(tick.now);
      }
    }
    skipped += clock.skipped_total();
  };

  // 1. Latency, with the measuring subscriber.
  std::uint64_t haptic_before = 0, haptic_updates = 0;
  const auto latency_from = t0 + secs(warmup);
  run_rig(latency_from, latency_from + secs(seconds), [&] {
    std::lock_guard<std::mutex> lock(mu);
    measuring = true;
    haptic_before = haptic ? haptic->calls.size() : 0;
  });
  {
    std::lock_guard<std::mutex> lock(mu);
    measuring = false;
  }
  haptic_updates = haptic ? haptic->calls.size() - haptic_before : 0;
  states.reset();
  observer.reset();

  // 2. CPU: the rig alone with the server (this process is then the whole wheel client: the rig
  // thread and its participant's DDS threads).
  double thread0 = 0, self0 = 0;
  const auto rig_from = MonotonicNow() + secs(settle);
  run_rig(rig_from, rig_from + secs(cpu_seconds), [&] {
    thread0 = ThreadCpuSeconds();
    self0 = ProcessCpuSeconds(getpid());
    sink.on = feed.on = time_ticks = breakdown;
  });
  const double rig_cpu = ThreadCpuSeconds() - thread0;
  const double self_cpu = ProcessCpuSeconds(getpid()) - self0;
  const wi::LatencyHistogram ffb = rig->ffb()->state_to_haptic();
  const wi::LatencyHistogram to_write = rig->sample_to_write();
  rig.reset();
  link.reset();
  participant.reset();

  // 3. CPU: each peer alone with the server, one after another.
  struct Peer {
    std::string what;
    std::vector<std::string> argv;
    bool ends_itself = false;
    double cpu = -1;
    int code = 0;
  };
  const std::string peer_total = std::to_string(static_cast<int>(peer_warmup + cpu_seconds + 2));
  std::vector<Peer> peers;
  if (xvfb > 0) {
    peers.push_back({"vdyn-input keyboard with its window on Xvfb (whole process)",
                     {VDYN_INPUT_BINARY, "--domain", dom, "--strength", "20", "--source-id", "kbd",
                      "--wait", "30", "keyboard", "--duration", peer_total}});
  }
  peers.push_back({"peer: vdyn-input play demo at 1 kHz (whole process)",
                   {VDYN_INPUT_BINARY, "--domain", dom, "--strength", "5", "--wait", "30", "play",
                    "demo", "--clock", "wall", "--loop"}});
  peers.push_back({"peer: a bare 1 kHz sleep loop (whole process)",
                   {argv[0], "--sleep-loop", peer_total},
                   true});
  peers.push_back(
      {"peer: a bare 1 kHz input writer (one DDS write a millisecond, nothing else; whole process)",
       {argv[0], "--writer-loop", peer_total, dom},
       true});
  for (Peer& peer : peers) {
    const pid_t pid = Spawn(peer.argv, fmt::format("{}-peer-{}.log", tmp, &peer - peers.data()));
    vdyn::base::SleepUntil(MonotonicNow() + secs(peer_warmup));
    const double c0 = ProcessCpuSeconds(pid);
    vdyn::base::SleepUntil(MonotonicNow() + secs(cpu_seconds));
    peer.cpu = ProcessCpuSeconds(pid) - c0;
    if (!peer.ends_itself) kill(pid, SIGTERM);
    peer.code = WaitPid(pid);
  }
  kill(server, SIGTERM);
  const int server_code = WaitPid(server);
  if (xvfb > 0) {
    kill(xvfb, SIGTERM);
    WaitPid(xvfb);
  }

  std::printf(
      "input_bench: the rig loop at 1 kHz with a virtual G29 (steering swept every sample), force "
      "feedback at 500 Hz on a recording device; server on flat, exit %d\n",
      server_code);
  std::printf("latency, over %.0f s with a measuring subscriber:\n", seconds);
  std::printf(
      "  SDL sample -> first state applying it, seen by a client (%llu inputs): p50 %.0f us, "
      "p99 %.0f us, max %.0f us\n",
      static_cast<unsigned long long>(sample_to_state.count()), sample_to_state.PercentileUs(50),
      sample_to_state.PercentileUs(99), sample_to_state.MaxUs());
  std::printf(
      "  SDL sample -> DDS write (%llu inputs, whole run): p50 %.0f us, p99 %.0f us, max %.0f "
      "us\n",
      static_cast<unsigned long long>(to_write.count()), to_write.PercentileUs(50),
      to_write.PercentileUs(99), to_write.MaxUs());
  std::printf(
      "  state -> haptic update (%llu states played, whole run): p50 %.0f us, p99 %.0f us, "
      "max %.0f us; %llu updates in the measured seconds\n",
      static_cast<unsigned long long>(ffb.count()), ffb.PercentileUs(50), ffb.PercentileUs(99),
      ffb.MaxUs(), static_cast<unsigned long long>(haptic_updates));
  std::printf(
      "CPU, %% of one core, each client alone with the server for %.0f s, one after another:\n",
      cpu_seconds);
  std::printf(
      "  rig loop thread (wheel read, input built and written, states taken, FFB): %.2f %%\n",
      100.0 * rig_cpu / cpu_seconds);
  if (breakdown) {
    std::printf("    inside the ticks %.2f %% (the rest: sleeping and waking at 1 kHz)\n",
                100.0 * tick_cpu / cpu_seconds);
    std::printf(
        "    inside the ticks: writing the input (DDS) %.2f %%, taking states and parameters "
        "(500 Hz) %.2f %%, the rest (SDL, input, force feedback) %.2f %%\n",
        100.0 * sink.cpu / cpu_seconds, 100.0 * feed.cpu / cpu_seconds,
        100.0 * (tick_cpu - sink.cpu - feed.cpu) / cpu_seconds);
  }
  std::printf("  the wheel client: this process (the rig thread and its DDS threads): %.2f %%\n",
              100.0 * self_cpu / cpu_seconds);
  if (xvfb <= 0) std::printf("  vdyn-input keyboard: not measured (no Xvfb)\n");
  for (const Peer& peer : peers) {
    std::printf(
        "  %s: %.2f %%%s\n", peer.what.c_str(), 100.0 * peer.cpu / cpu_seconds,
        peer.ends_itself && peer.code != 0 ? fmt::format(" (exit {})", peer.code).c_str() : "");
  }
  std::printf("drops seen by the subscriber: %llu; rig ticks skipped: %llu\n",
              static_cast<unsigned long long>(drops.Total()),
              static_cast<unsigned long long>(skipped));
  return server_code;
}
