// foxglove_bench: what vdyn-foxglove costs and what a stalled client does to the session.
//
// For each vehicle count N (1, 16, 64) and each run: a real-time vdyn-server on `flat` with
// vehicles 1..N, and vdyn-foxglove with one WebSocket client (a Beast client in this process,
// subprotocol foxglove.websocket.v1) subscribed to every channel (every state at 1 kHz, the
// transforms and scenes at 60 Hz, the world, diagnostics, events), reading all the time:
//  - the bridge's CPU (user + system, /proc/PID/stat) over `seconds` after a 3 s warm-up, and the
//    messages and bytes the client received;
//  - the peer, alone with the server afterwards: `vdyn-recorder record` of everything (every
//    state, read and written to MCAP), its CPU over the same window;
//  - the state latency from the bridge's own summary: a state's DDS source stamp (the server's
//    wall clock when it wrote the state) to the end of its WebSocket write, p50 and p99.
// Then, once, at 16 vehicles: the server's tick lateness (its vdyn/diagnostics, per second p99 and
// max) with the bridge and a reading client for `seconds`, and in the same run with a second
// client that subscribes to everything and stops reading for 10 s; the reading client's message
// rate in both windows.
//
// Usage: foxglove_bench [seconds=10] [runs=3] [counts=1,16,64]
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <filesystem>
#include <regex>
#include <sstream>
#include <string>
#include <thread>
#include <utility>  // before Boost 1.74's asio/awaitable.hpp, which uses std::exchange without it
#include <vector>

#include <fmt/format.h>
#include <boost/asio.hpp>
#include <boost/beast/core.hpp>
#include <boost/beast/websocket.hpp>
#include <nlohmann/json.hpp>

#include "child.h"
#include "vdyn/base/time.h"
#include "vdyn/diagnostics.pb.h"
#include "vdyn/transport/dds.h"

namespace {

namespace asio = boost::asio;
namespace beast = boost::beast;
namespace websocket = beast::websocket;
using tcp = asio::ip::tcp;
using vdyn::bench::Median;
using vdyn::bench::ProcessCpuSeconds;
using vdyn::bench::Spawn;
using vdyn::bench::WaitPid;

void Sleep(double s) {
  std::this_thread::sleep_for(std::chrono::duration<double>(s));
}

// A Foxglove client that subscribes to every channel it is told of and counts what arrives.
// stall_after_s >= 0: it stops reading that long after its first message, for stall_s.
class Client {
 public:
  Client(std::uint16_t port, double stall_after_s = -1, double stall_s = 0)
      : thread_([this, port, stall_after_s, stall_s] { Run(port, stall_after_s, stall_s); }) {}
  ~Client() {
    stop_ = true;
    thread_.join();
  }
  std::atomic<std::uint64_t> messages{0}, bytes{0};
  std::atomic<bool> stalled{false};
  std::string error;

 private:
  void Run(std::uint16_t port, double stall_after_s, double stall_s) {
    try {
      asio::io_context io;
      websocket::stream<tcp::socket> ws(io);
      ws.next_layer().connect({asio::ip::make_address("127.0.0.1"), port});
      ws.set_option(websocket::stream_base::decorator([](websocket::request_type& req) {
        req.set(beast::http::field::sec_websocket_protocol, "foxglove.websocket.v1");
      }));
      ws.read_message_max(256u << 20);
      ws.handshake("127.0.0.1:" + std::to_string(port), "/");
      std::uint32_t next = 1;
      double first = -1;
      beast::flat_buffer b;
      while (!stop_) {
        b.clear();
        ws.read(b);
        if (ws.got_text()) {
          const auto j = nlohmann::json::parse(beast::buffers_to_string(b.data()));
          if (j.value("op", "") != "advertise") continue;
          nlohmann::json subs = nlohmann::json::array();
          for (const auto& c : j["channels"])
            subs.push_back({{"id", next++}, {"channelId", c["id"]}});
          ws.text(true);
          ws.write(
              asio::buffer(nlohmann::json{{"op", "subscribe"}, {"subscriptions", subs}}.dump()));
          continue;
        }
        ++messages;
        bytes += b.size();
        const double now = vdyn::base::MonotonicNow().ns * 1e-9;
        if (first < 0) first = now;
        if (stall_after_s >= 0 && now - first > stall_after_s) {
          stalled = true;
          Sleep(stall_s);  // reads nothing: the kernel's buffers fill, then the bridge's queue
          stalled = false;
          stall_after_s = -1;
        }
      }
      ws.next_layer().close();
    } catch (const std::exception& e) {
      if (!stop_) error = e.what();
    }
  }
  std::atomic<bool> stop_{false};
  std::thread thread_;
};

struct Processes {
  std::vector<pid_t> pids;
  ~Processes() {
    for (pid_t p : pids) {
      kill(p, SIGINT);
      WaitPid(p);
    }
  }
};

std::uint16_t BridgePort(const std::filesystem::path& log) {
  for (int i = 0; i < 400; ++i) {
    std::smatch m;
    const std::string text = vdyn::bench::Slurp(log);
    if (std::regex_search(text, m, std::regex("listening on ws://127\\.0\\.0\\.1:(\\d+)"))) {
      return static_cast<std::uint16_t>(std::stoi(m[1]));
    }
    Sleep(0.05);
  }
  std::fprintf(stderr, "foxglove_bench: the bridge did not start (%s)\n", log.c_str());
  std::exit(1);
}

std::string Ids(int n) {
  std::string s;
  for (int i = 1; i <= n; ++i) s += (i > 1 ? "," : "") + std::to_string(i);
  return s;
}

pid_t StartServer(const std::filesystem::path& dir, std::uint32_t domain, int n) {
  return Spawn(
      {VDYN_SERVER_BINARY, "--domain", std::to_string(domain), "--world", "flat", "--vehicle-ids",
       Ids(n), "--max-vehicles", std::to_string(std::max(n, 1)), "--no-status"},
      dir / fmt::format("server-{}.log", n));
}

pid_t StartBridge(const std::filesystem::path& log, std::uint32_t domain) {
  return Spawn({VDYN_FOXGLOVE_BINARY, "--domain", std::to_string(domain), "--host", "127.0.0.1",
                "--port", "0", "--no-status"},
               log);
}

struct Result {
  double bridge_cpu = 0, recorder_cpu = 0, msgs = 0, mbytes = 0, p50 = 0, p99 = 0;
};

Result Measure(const std::filesystem::path& dir, std::uint32_t domain, int n, double seconds) {
  Result r;
  Processes server;
  server.pids.push_back(StartServer(dir, domain, n));
  {
    const auto log = dir / fmt::format("bridge-{}.log", n);
    const pid_t bridge = StartBridge(log, domain);
    {
      Client c(BridgePort(log));
      Sleep(3);
      const double cpu0 = ProcessCpuSeconds(bridge);
      const std::uint64_t m0 = c.messages, b0 = c.bytes;
      Sleep(seconds);
      r.bridge_cpu = 100 * (ProcessCpuSeconds(bridge) - cpu0) / seconds;
      r.msgs = static_cast<double>(c.messages - m0) / seconds;
      r.mbytes = static_cast<double>(c.bytes - b0) / seconds / 1e6;
      if (!c.error.empty()) std::fprintf(stderr, "client: %s\n", c.error.c_str());
    }
    kill(bridge, SIGINT);
    WaitPid(bridge);
    std::smatch m;
    const std::string text = vdyn::bench::Slurp(log);
    if (std::regex_search(text, m, std::regex("p50 ([0-9.]+) ms, p99 ([0-9.]+) ms"))) {
      r.p50 = std::stod(m[1]);
      r.p99 = std::stod(m[2]);
    }
  }
  const pid_t rec = Spawn({VDYN_RECORDER_BINARY, "record", (dir / "peer.mcap").string(), "--domain",
                           std::to_string(domain), "--no-status"},
                          dir / fmt::format("recorder-{}.log", n));
  Sleep(3);
  const double cpu0 = ProcessCpuSeconds(rec);
  Sleep(seconds);
  r.recorder_cpu = 100 * (ProcessCpuSeconds(rec) - cpu0) / seconds;
  kill(rec, SIGINT);
  WaitPid(rec);
  std::filesystem::remove(dir / "peer.mcap");
  return r;
}

// The server's per-second lateness p99 and max (us) over a window, from vdyn/diagnostics.
struct Lateness {
  std::vector<double> p99, max;
};
void Collect(vdyn::transport::Reader<vdyn::pb::Diagnostics>& r, double seconds, Lateness& out) {
  const auto end = vdyn::base::MonotonicNow() + vdyn::base::FromSeconds(seconds);
  while (vdyn::base::MonotonicNow() < end) {
    if (!r.Wait(std::chrono::milliseconds(200))) continue;
    (void)r.Take([&](const vdyn::pb::Diagnostics& d, const vdyn::transport::SampleInfo&) {
      out.p99.push_back(d.lateness_p99_us());
      out.max.push_back(d.lateness_max_us());
    });
  }
}

void Stall(const std::filesystem::path& dir, std::uint32_t domain, double seconds) {
  const int n = 16;
  Processes ps;
  ps.pids.push_back(StartServer(dir, domain, n));
  const auto log = dir / "bridge-stall.log";
  ps.pids.push_back(StartBridge(log, domain));
  const std::uint16_t port = BridgePort(log);
  vdyn::transport::Participant participant(domain);
  vdyn::transport::DropCounters drops;
  vdyn::transport::Reader<vdyn::pb::Diagnostics> diag(
      participant, vdyn::transport::TopicId::kDiagnostics, &drops);
  Client reader(port);
  Sleep(3);
  Lateness none, stalled;
  std::uint64_t m0 = reader.messages;
  Collect(diag, seconds, none);
  const double rate_none = static_cast<double>(reader.messages - m0) / seconds;
  {
    Client slow(port, 0.5, 10);
    while (!slow.stalled) Sleep(0.01);
    m0 = reader.messages;
    Collect(diag, 9.5, stalled);
    const double rate_stalled = static_cast<double>(reader.messages - m0) / 9.5;
    std::printf(
        "stall (16 vehicles, same run): server tick lateness p99 per second, median %.0f us "
        "without, %.0f us with a client that stopped reading for 10 s (ratio %.2f); worst "
        "second's max %.0f us / %.0f us; the reading client's messages %.0f/s / %.0f/s\n",
        Median(none.p99), Median(stalled.p99),
        Median(stalled.p99) / std::max(Median(none.p99), 1.0),
        *std::max_element(none.max.begin(), none.max.end()),
        *std::max_element(stalled.max.begin(), stalled.max.end()), rate_none, rate_stalled);
  }
  std::fflush(stdout);
}

}  // namespace

int main(int argc, char** argv) {
  const double seconds = argc > 1 ? std::stod(argv[1]) : 10;
  const int runs = argc > 2 ? std::stoi(argv[2]) : 3;
  std::vector<int> counts = {1, 16, 64};
  if (argc > 3) {
    counts.clear();
    std::stringstream s(argv[3]);
    for (std::string x; std::getline(s, x, ',');) counts.push_back(std::stoi(x));
  }
  const std::uint32_t domain = 200 + static_cast<std::uint32_t>(getpid() % 30);
  const auto dir =
      std::filesystem::temp_directory_path() / fmt::format("foxglove_bench-{}", getpid());
  std::filesystem::create_directories(dir);
  std::printf("foxglove_bench: %.0f s windows, %d runs, domain %u, logs in %s\n", seconds, runs,
              domain, dir.c_str());
  std::vector<std::vector<Result>> all(counts.size());
  for (int run = 0; run < runs; ++run) {
    for (std::size_t i = 0; i < counts.size(); ++i) {
      const Result r = Measure(dir, domain, counts[i], seconds);
      double load = 0;
      if (std::FILE* f = std::fopen("/proc/loadavg", "r")) {
        if (std::fscanf(f, "%lf", &load) != 1) load = 0;
        std::fclose(f);
      }
      std::printf(
          "run %d, %3d vehicles: bridge %.1f %% (recorder %.1f %%), %.0f msg/s, %.2f MB/s, "
          "latency p50 %.2f ms p99 %.2f ms (load %.2f)\n",
          run + 1, counts[i], r.bridge_cpu, r.recorder_cpu, r.msgs, r.mbytes, r.p50, r.p99, load);
      std::fflush(stdout);
      all[i].push_back(r);
    }
  }
  std::printf(
      "\nmedians over %d runs (one client subscribed to everything; CPU in %% of one core)\n",
      runs);
  std::printf(
      "vehicles  bridge CPU  recorder CPU (peer)  ratio  client msg/s  MB/s  latency p50  p99\n");
  for (std::size_t i = 0; i < counts.size(); ++i) {
    auto med = [&](double Result::*f) {
      std::vector<double> v;
      for (const Result& r : all[i]) v.push_back(r.*f);
      return Median(v);
    };
    std::printf("%8d  %9.1f  %19.1f  %5.2f  %11.0f  %4.1f  %8.2f ms  %.2f ms\n", counts[i],
                med(&Result::bridge_cpu), med(&Result::recorder_cpu),
                med(&Result::bridge_cpu) / std::max(med(&Result::recorder_cpu), 0.1),
                med(&Result::msgs), med(&Result::mbytes), med(&Result::p50), med(&Result::p99));
  }
  Stall(dir, domain, seconds);
  return 0;
}
