// vdyn-foxglove: a Foxglove WebSocket server for a running vdyn session. Foxglove or Lichtblick
// connect to ws://HOST:8765 and see every vehicle (the car, its force arrows, the terrain), plot
// any field of its states and change its parameters; http://HOST:8765/ is a page that shows the
// same in any browser (clients/foxglove/README.md).
//
//   vdyn-foxglove [--domain N] [--port 8765] [--state-hz 0] [--scene-hz 60] [--allow-input]
//                 [--tls-cert CERT.pem --tls-key KEY.pem]
//
// Exit codes: 0 done (SIGINT, SIGTERM, --duration), 1 transport or network failure, 2 bad
// command line.
#include <atomic>
#include <csignal>
#include <cstdio>
#include <iostream>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>

#include <CLI/CLI.hpp>

#include "vdyn/base/limits.h"
#include "vdyn/base/time.h"
#include "vdyn/cli/options.h"
#include "vdyn/foxglove/bridge.h"
#include "vdyn/foxglove/server.h"
#include "vdyn/transport/dds.h"

namespace {

std::atomic<bool> g_stop{false};
extern "C" void OnSignal(int) {
  g_stop.store(true);
}

std::mutex g_out;
void Print(const std::string& line) {
  std::lock_guard lock(g_out);
  std::printf("%s\n", line.c_str());
  std::fflush(stdout);
}

std::string Fixed(double v, int digits) {
  char b[64];
  std::snprintf(b, sizeof b, "%.*f", digits, v);
  return b;
}

namespace fx = vdyn::foxglove;

// The status line: the last second's rates.
std::string StatusLine(const fx::Bridge::Counters& c, const fx::Bridge::Counters& last,
                       std::uint64_t bytes, const fx::LatencyHistogram& latency,
                       vdyn::base::Nanos cpu) {
  return "vdyn-foxglove: " + std::to_string(c.clients) + " clients, " +
         std::to_string(c.subscriptions) + " subscriptions, " + std::to_string(c.vehicles) +
         " vehicles | states in " + std::to_string(c.states_in - last.states_in) + "/s (DDS lost " +
         std::to_string(c.dds_lost) + ") | out " +
         std::to_string(c.messages_out - last.messages_out) + " msg/s, " +
         Fixed(static_cast<double>(bytes) / 1e6, 2) + " MB/s | dropped " +
         std::to_string(c.dropped_messages) + " | state latency p50 " +
         Fixed(latency.PercentileMs(50), 2) + " ms p99 " + Fixed(latency.PercentileMs(99), 2) +
         " ms | CPU " + Fixed(100.0 * cpu.seconds(), 1) + " %";
}

// Where Foxglove and a browser connect.
void PrintListening(const fx::Server& server, const std::string& host, std::uint32_t domain,
                    bool allow_input) {
  const std::string shown = host == "0.0.0.0" ? "127.0.0.1" : host;
  const std::string s = server.tls() ? "s" : "";
  const std::string port = std::to_string(server.port());
  Print("vdyn-foxglove: listening on ws" + s + "://" + shown + ":" + port +
        " (Foxglove/Lichtblick), the page at http" + s + "://" + shown + ":" + port + "/ (domain " +
        std::to_string(domain) + ", " + (allow_input ? "input allowed" : "input off") + ")");
}

// What was refused or failed in the last second, said in the log (the totals were only in the
// summary at the end).
void PrintRefusals(const fx::Server::Stats& st, const fx::Server::Stats& last,
                   std::uint32_t max_clients) {
  if (st.refused > last.refused || st.protocol_errors > last.protocol_errors) {
    Print("vdyn-foxglove: in the last second " + std::to_string(st.refused - last.refused) +
          " connection(s) refused (a bad upgrade, or --max-clients " + std::to_string(max_clients) +
          " reached: HTTP 400/503) and " + std::to_string(st.protocol_errors - last.protocol_errors) +
          " client(s) closed for a WebSocket protocol error");
  }
  if (st.accept_errors > last.accept_errors) {
    Print("vdyn-foxglove: " + std::to_string(st.accept_errors - last.accept_errors) +
          " connection(s) could not be accepted in the last second: " + st.last_accept_error +
          " (out of file descriptors? ulimit -n; tried again every 100 ms)");
  }
}

// The summary at the end: the whole run.
std::string Summary(const fx::Bridge::Counters& c, const fx::Server::Stats& st,
                    const fx::LatencyHistogram& latency, double wall_s, double cpu_s) {
  return "vdyn-foxglove summary: " + std::to_string(st.connections) + " WebSocket clients, " +
         std::to_string(st.http_requests) + " HTTP requests, " + std::to_string(st.refused) +
         " refused, " + std::to_string(st.protocol_errors) + " closed for protocol errors\n" +
         "  states in " + std::to_string(c.states_in) + " (DDS lost " + std::to_string(c.dds_lost) +
         " samples; " + std::to_string(c.states_refused) + " not drawable" +
         (c.last_refusal.empty() ? "" : ": " + c.last_refusal) + "), messages out " +
         std::to_string(c.messages_out) + ", dropped " + std::to_string(c.dropped_messages) + " (" +
         Fixed(static_cast<double>(c.dropped_bytes) / 1e6, 1) + " MB) by slow clients' queues\n" +
         "  bad client messages " + std::to_string(c.bad_messages) + ", inputs " +
         std::to_string(c.inputs) + " (" + std::to_string(c.input_clamped) + " clamped; " +
         std::to_string(c.input_refused) + " refused), parameters " + std::to_string(c.params_accepted) + " set, " +
         std::to_string(c.params_refused) + " refused\n" +
         "  state latency (source stamp to written) p50 " + Fixed(latency.PercentileMs(50), 3) +
         " ms, p99 " + Fixed(latency.PercentileMs(99), 3) + " ms over " +
         std::to_string(latency.count()) + " states\n  process CPU " +
         Fixed(wall_s > 0 ? 100.0 * cpu_s / wall_s : 0.0, 1) + " % of one core over " +
         Fixed(wall_s, 1) + " s";
}

}  // namespace

int main(int argc, char** argv) {
  namespace limits = vdyn::limits;
  namespace cli = vdyn::cli;
  CLI::App app{
      "vdyn-foxglove: a Foxglove WebSocket server for a running session (Foxglove, Lichtblick) and "
      "a page for any browser, on one port"};
  std::uint32_t domain = 0, port = 8765, max_clients = 64;
  std::string host = "0.0.0.0", tls_cert, tls_key;
  std::string three_js = "/usr/share/javascript/three/three.min.js";
  double state_hz = 0, scene_hz = 60, arrow_scale = 0.5, queue_kb = 4096, queue_ms = 250;
  double vehicle_timeout_s = 3, duration_s = 0;
  std::int32_t strength = 10;
  bool allow_input = false, no_status = false;
  app.add_option("--domain", domain, "DDS domain id")
      ->check(cli::WholeInRange(limits::kDomainId))
      ->capture_default_str();
  app.add_option("--host", host, "Address to listen on")->capture_default_str();
  app.add_option("--port", port, "TCP port for WebSocket and HTTP (0: any free port)")
      ->check(cli::WholeInRange(limits::kPort))
      ->capture_default_str();
  app.add_option("--state-hz", state_hz, "States per second on each state channel (0: every state)")
      ->check(cli::InRange(limits::kFoxgloveStateHz))
      ->capture_default_str();
  app.add_option("--scene-hz", scene_hz, "Scene and transforms per second (latest only)")
      ->check(cli::InRange(limits::kFoxgloveSceneHz))
      ->capture_default_str();
  app.add_option("--arrow-scale", arrow_scale, "Force arrows: metres per kN (as vdyn-viewer's)")
      ->check(cli::InRange(limits::kArrowScale))
      ->capture_default_str();
  app.add_flag("--allow-input", allow_input,
               "Let clients drive (client publish on /vehicle/<id>/input); off by default");
  app.add_option("--input-strength", strength, "Ownership strength of the clients' input")
      ->check(cli::WholeInRange(limits::kStrength))
      ->capture_default_str();
  app.add_option("--tls-cert", tls_cert, "PEM certificate: serve wss:// and https://");
  app.add_option("--tls-key", tls_key, "PEM private key of --tls-cert");
  app.add_option("--three-js", three_js, "three.js for the page (Debian's libjs-three)")
      ->capture_default_str();
  app.add_option("--queue-kb", queue_kb,
                 "A client's send queue: data beyond this is dropped, oldest first")
      ->check(cli::InRange(limits::kFoxgloveQueueKb))
      ->capture_default_str();
  app.add_option("--queue-ms", queue_ms, "A client's send queue: data older than this is dropped")
      ->check(cli::InRange(limits::kFoxgloveQueueMs))
      ->capture_default_str();
  app.add_option("--max-clients", max_clients, "WebSocket clients at once")
      ->check(cli::WholeInRange(limits::kFoxgloveClients))
      ->capture_default_str();
  app.add_option("--vehicle-timeout", vehicle_timeout_s,
                 "Unadvertise a vehicle's channels after this long without a state, s")
      ->check(cli::InRange(limits::kVehicleTimeoutS))
      ->capture_default_str();
  app.add_option("--duration", duration_s, "Stop after this many seconds (default: run on)")
      ->check(cli::InRange(limits::kDurationS));
  app.add_flag("--no-status", no_status, "No status line every second");
  if (const int rc = cli::Parse(app, argc, argv); rc >= 0) return rc;
  if (tls_cert.empty() != tls_key.empty()) {
    std::cerr << "vdyn-foxglove: --tls-cert and --tls-key go together\n";
    return 2;
  }

  fx::ServerOptions so;
  so.host = host;
  so.port = static_cast<std::uint16_t>(port);
  so.tls_cert = tls_cert;
  so.tls_key = tls_key;
  so.three_js = three_js;
  so.limits.data_bytes = static_cast<std::size_t>(queue_kb * 1024);
  so.limits.data_age = vdyn::base::FromSeconds(queue_ms / 1000.0);
  so.max_clients = max_clients;
  fx::BridgeConfig bc;
  bc.state_hz = state_hz;
  bc.scene_hz = scene_hz;
  bc.scene.arrow_m_per_kn = arrow_scale;
  bc.allow_input = allow_input;
  bc.input_strength = strength;
  bc.vehicle_timeout = vdyn::base::FromSeconds(vehicle_timeout_s);

  std::signal(SIGINT, OnSignal);
  std::signal(SIGTERM, OnSignal);
  std::signal(SIGPIPE, SIG_IGN);
  try {
    vdyn::transport::Participant participant(domain);
    fx::Bridge bridge(participant, bc);
    bridge.SetLog([](const std::string& line) { Print("vdyn-foxglove: " + line); });
    std::unique_ptr<fx::Server> server;
    try {
      server = std::make_unique<fx::Server>(so, bridge);
    } catch (const std::runtime_error& e) {
      std::cerr << "vdyn-foxglove: " << e.what() << "\n";
      return 1;
    }
    bridge.SetCloser(
        [&server](fx::ClientId id, const std::string& why) { server->Close(id, why); });
    PrintListening(*server, host, domain, allow_input);
    std::thread net([&] { server->Run(); });
    const vdyn::base::MonoTime start = vdyn::base::MonotonicNow();
    const vdyn::base::Nanos cpu0 = vdyn::base::ProcessCpuTime();
    std::atomic<bool> stop{false};
    fx::LatencyHistogram total, second;
    std::thread watch([&] {
      // The status line once a second; turns a signal or the end of --duration into stop.
      vdyn::base::MonoTime next = start + vdyn::base::Seconds(1);
      fx::Bridge::Counters last;
      fx::Server::Stats last_st;
      std::uint64_t last_bytes = 0;
      vdyn::base::Nanos last_cpu = cpu0;
      while (!g_stop &&
             (duration_s <= 0 || (vdyn::base::MonotonicNow() - start).seconds() < duration_s)) {
        vdyn::base::SleepUntil(
            std::min(next, vdyn::base::MonotonicNow() + vdyn::base::Milliseconds(20)));
        if (vdyn::base::MonotonicNow() < next) continue;
        next = next + vdyn::base::Seconds(1);
        const fx::Bridge::Counters c = bridge.counters();
        const fx::Server::Stats st = server->stats();
        second.Clear();
        server->TakeLatencies(second);
        total.Merge(second);
        const vdyn::base::Nanos cpu = vdyn::base::ProcessCpuTime();
        if (!no_status) {
          Print(StatusLine(c, last, st.bytes_written - last_bytes, second, cpu - last_cpu));
        }
        PrintRefusals(st, last_st, max_clients);
        last_st = st;
        last = c;
        last_bytes = st.bytes_written;
        last_cpu = cpu;
      }
      stop = true;
    });
    bridge.Run(stop);
    g_stop = true;
    watch.join();
    server->Stop();
    net.join();
    bridge.CloseAll();
    second.Clear();
    server->TakeLatencies(second);
    total.Merge(second);
    const double wall = (vdyn::base::MonotonicNow() - start).seconds();
    const double cpu = (vdyn::base::ProcessCpuTime() - cpu0).seconds();
    Print(Summary(bridge.counters(), server->stats(), total, wall, cpu));
  } catch (const std::exception& e) {
    std::cerr << "vdyn-foxglove: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
