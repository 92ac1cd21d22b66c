#include "vdyn/telemetry/udp.h"

#include <arpa/inet.h>
#include <netdb.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <stdexcept>

namespace vdyn::telemetry {

std::optional<Endpoint> ResolveEndpoint(const std::string& text, std::string& error) {
  auto fail = [&](const std::string& why) -> std::optional<Endpoint> {
    error = "'" + text + "': " + why;
    return std::nullopt;
  };
  const auto colon = text.rfind(':');
  if (colon == std::string::npos) return fail("expected HOST:PORT");
  const std::string host = text.substr(0, colon), port = text.substr(colon + 1);
  if (host.empty()) return fail("no host");
  if (port.empty() || port.size() > 5 ||
      port.find_first_not_of("0123456789") != std::string::npos) {
    return fail("'" + port + "' is not a port number (1 to 65535)");
  }
  const long port_n = std::stol(port);
  if (port_n < 1 || port_n > 65535) return fail("port " + port + " is not in 1 to 65535");

  Endpoint e;
  e.text = text;
  e.addr.sin_family = AF_INET;
  e.addr.sin_port = htons(static_cast<std::uint16_t>(port_n));
  if (host.find_first_not_of("0123456789.") == std::string::npos) {
    if (inet_pton(AF_INET, host.c_str(), &e.addr.sin_addr) != 1) {
      return fail("'" + host + "' is not an IPv4 address");
    }
    return e;
  }
  addrinfo hints{};
  hints.ai_family = AF_INET;
  hints.ai_socktype = SOCK_DGRAM;
  addrinfo* found = nullptr;
  const int rc = getaddrinfo(host.c_str(), nullptr, &hints, &found);
  if (rc != 0 || found == nullptr) {
    return fail("cannot resolve '" + host + "' to an IPv4 address: " + gai_strerror(rc));
  }
  e.addr.sin_addr = reinterpret_cast<const sockaddr_in*>(found->ai_addr)->sin_addr;
  freeaddrinfo(found);
  return e;
}

UdpSender::UdpSender(std::vector<Endpoint> destinations) : destinations_(std::move(destinations)) {
  fd_ = socket(AF_INET, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
  if (fd_ < 0)
    throw std::runtime_error(std::string("cannot open a UDP socket: ") + strerror(errno));
  // Broadcast addresses (a dashboard on every host of a lab's subnet) need SO_BROADCAST.
  const int one = 1;
  setsockopt(fd_, SOL_SOCKET, SO_BROADCAST, &one, sizeof one);
}

UdpSender::~UdpSender() {
  if (fd_ >= 0) close(fd_);
}

std::string UdpSender::last_error() const {
  std::lock_guard<std::mutex> lock(error_mu_);
  return last_error_;
}

int UdpSender::Send(std::span<const std::uint8_t> datagram) {
  int ok = 0;
  for (const Endpoint& d : destinations_) {
    const ssize_t n = sendto(fd_, datagram.data(), datagram.size(), MSG_DONTWAIT,
                             reinterpret_cast<const sockaddr*>(&d.addr), sizeof d.addr);
    if (n == static_cast<ssize_t>(datagram.size())) {
      ++sent_;
      ++ok;
    } else {
      const std::string why = n < 0 ? strerror(errno) : "short write";
      ++errors_;
      std::lock_guard<std::mutex> lock(error_mu_);
      last_error_ = d.text + ": " + why;
    }
  }
  return ok;
}

}  // namespace vdyn::telemetry
