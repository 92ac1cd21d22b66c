// The network side of vdyn-foxglove: one port, HTTP and WebSocket (plain, or TLS with a
// certificate and key: https and wss), on one thread of its own (Boost.Asio). HTTP GET serves the
// page (`/`, `/app.js`) and three.js from Debian's libjs-three; a WebSocket upgrade that offers
// foxglove.websocket.v1 or foxglove.sdk.v1 becomes a Foxglove client, its chosen subprotocol
// echoed. A client's frames are read, checked and handed to the ClientHandler; what it is sent
// comes from its Outbox, whole frames written many at a time, never waited for by anyone else.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <span>
#include <string>
#include <string_view>

#include "vdyn/foxglove/outbox.h"

namespace vdyn::foxglove {

using ClientId = std::uint64_t;

// What the server tells about its clients, on its thread.
class ClientHandler {
 public:
  virtual ~ClientHandler() = default;
  virtual void OnOpen(ClientId id, const std::shared_ptr<Outbox>& outbox,
                      const std::string& subprotocol, const std::string& peer) = 0;
  virtual void OnText(ClientId id, std::string_view text) = 0;
  virtual void OnBinary(ClientId id, std::span<const std::uint8_t> message) = 0;
  virtual void OnClose(ClientId id, const std::string& why) = 0;
};

struct ServerOptions {
  std::string host = "0.0.0.0";
  std::uint16_t port = 8765;  // 0: any free port (port() says which)
  // Both or neither: https and wss with this PEM certificate (chain) and private key.
  std::filesystem::path tls_cert, tls_key;
  // three.js as Debian's libjs-three installs it (served at /three.min.js).
  std::filesystem::path three_js = "/usr/share/javascript/three/three.min.js";
  Outbox::Limits limits;
  std::size_t max_clients = 64;
  std::size_t max_client_message_bytes = 1u << 20;
  // The kernel's send buffer per client: what a stalled client still gets late once it reads
  // again is at most this plus its own receive buffer.
  int socket_send_bytes = 256 * 1024;
  std::size_t write_batch_bytes = 256 * 1024;
};

// Latencies of the data messages written (a message's source stamp, the DDS writer's wall clock,
// to the end of its write to the socket): a histogram in 10 us bins up to 10 s.
class LatencyHistogram {
 public:
  void Add(std::int64_t ns);
  std::uint64_t count() const { return count_; }
  double PercentileMs(double p) const;  // 0 when empty
  void Merge(const LatencyHistogram& o);
  void Clear();

 private:
  static constexpr std::size_t kBins = 1'000'000;
  std::unique_ptr<std::uint32_t[]> bins_;
  std::uint64_t count_ = 0;
};

class Server {
 public:
  // Binds and listens; throws std::runtime_error naming the address, file or reason.
  Server(const ServerOptions& options, ClientHandler& handler);
  ~Server();
  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;

  std::uint16_t port() const;
  bool tls() const;
  // Serves on the calling thread until Stop().
  void Run();
  // Any thread.
  void Stop();
  // Closes a client with a status error saying why (any thread).
  void Close(ClientId id, const std::string& reason);

  struct Stats {
    std::uint64_t connections = 0;  // WebSocket clients since start
    std::uint64_t http_requests = 0;
    std::uint64_t refused = 0;  // upgrades refused (no Foxglove subprotocol, too many clients)
    std::uint64_t protocol_errors = 0;  // clients closed for a framing error
    std::uint64_t bytes_written = 0;
    std::uint64_t accept_errors = 0;  // accepts that failed (e.g. out of file descriptors)
    std::string last_accept_error;
    int clients = 0;  // open now
  };
  Stats stats() const;
  // The latencies measured since the last call (thread-safe).
  void TakeLatencies(LatencyHistogram& into);

  struct Impl;

 private:
  std::unique_ptr<Impl> impl_;
};

}  // namespace vdyn::foxglove
