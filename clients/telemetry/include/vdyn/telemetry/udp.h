// UDP destinations for the telemetry: "HOST:PORT" with an IPv4 address in dotted form or a host
// name (resolved once, at start, to its first IPv4 address), and a sender that writes a datagram
// to each of them without ever blocking (a full socket buffer is a counted error, not a stall).
#pragma once

#include <netinet/in.h>

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <mutex>
#include <optional>
#include <span>
#include <string>
#include <vector>

namespace vdyn::telemetry {

struct Endpoint {
  std::string text;  // as the user wrote it
  sockaddr_in addr{};
};

// Parses and resolves "HOST:PORT" (port 1..65535). On failure returns nullopt and says why in
// `error` ("'10.0.0.300:4444': '10.0.0.300' is not an IPv4 address"). Text that looks like a
// dotted address (digits and dots only) is never sent to the resolver.
std::optional<Endpoint> ResolveEndpoint(const std::string& text, std::string& error);

class UdpSender {
 public:
  explicit UdpSender(std::vector<Endpoint> destinations);  // throws std::runtime_error
  ~UdpSender();
  UdpSender(const UdpSender&) = delete;
  UdpSender& operator=(const UdpSender&) = delete;

  // Sends the datagram to every destination; returns how many took it.
  int Send(std::span<const std::uint8_t> datagram);

  // Counters and the newest error may be read from another thread (the status line).
  std::uint64_t sent() const { return sent_.load(); }      // datagrams handed to the network
  std::uint64_t errors() const { return errors_.load(); }  // datagrams refused (sendto failed)
  // The newest error, "127.0.0.1:4444: Network is unreachable" (empty when none yet).
  std::string last_error() const;
  const std::vector<Endpoint>& destinations() const { return destinations_; }

 private:
  int fd_ = -1;
  std::vector<Endpoint> destinations_;
  std::atomic<std::uint64_t> sent_{0}, errors_{0};
  mutable std::mutex error_mu_;
  std::string last_error_;
};

}  // namespace vdyn::telemetry
