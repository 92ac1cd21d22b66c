#include "vdyn/transport/security_log.h"

#include <cstdio>

#include <dds/ddsrt/log.h>

namespace vdyn::transport {
namespace {

// The messages Cyclone DDS 0.10.2 logs when its security plugins refuse a remote participant
// (src/core/ddsi/src/ddsi_handshake.c and ddsi_security_omg.c), and the kind each is counted as.
struct Pattern {
  std::string_view text;
  std::string_view kind;
};
constexpr Pattern kPatterns[] = {
    // Authentication: its identity certificate is not signed by our identity CA, has expired, ...
    {"Validate remote identity failed", "DDS Security: remote identity refused"},
    {"Begin handshake reply failed", "DDS Security: remote identity refused"},
    {"Begin handshake request failed", "DDS Security: remote identity refused"},
    {"Process handshake failed", "DDS Security: remote identity refused"},
    {"Could not authenticate_peer_credential_token", "DDS Security: remote identity refused"},
    // Access control: its permissions are not signed by our permissions CA, or do not let it join.
    {"permissions from plugin", "DDS Security: remote permissions refused"},
    {"Plugin does not allow remote participant", "DDS Security: remote participant may not join"},
    // Endpoints of a participant without security, where the governance lets it be discovered.
    {"Non secure remote writer", "DDS Security: unauthenticated writer refused"},
    {"Non secure remote reader", "DDS Security: unauthenticated reader refused"},
    // Endpoints the remote permissions do not allow (logged as errors only for topics without
    // discovery protection; lab-pki.sh protects the vdyn topics, which makes these trace-only).
    {"Access control does not allow remote writer", "DDS Security: remote writer not permitted"},
    {"Access control does not allow remote reader", "DDS Security: remote reader not permitted"},
    {"Access control does not allow remote topic", "DDS Security: remote topic not permitted"},
};

std::string OneLine(std::string_view s) {
  std::string out;
  for (char c : s) {
    if (c == '\n' || c == '\r') break;
    out.push_back(c);
  }
  while (!out.empty() && out.back() == ' ') out.pop_back();
  return out;
}

void Sink(void* self, const dds_log_data_t* data) {
  // The header (time stamp, domain, thread) precedes the message in the same buffer.
  const char* header = data->message - data->hdrsize;
  static_cast<SecurityLog*>(self)->OnLine(std::string_view(header, data->hdrsize),
                                          std::string_view(data->message, data->size));
}

}  // namespace

std::optional<SecurityRefusal> ClassifySecurityLogLine(std::string_view line) {
  for (const Pattern& p : kPatterns) {
    const auto at = line.find(p.text);
    if (at == std::string_view::npos) continue;
    // The detail: for a certificate the subject it names, otherwise what follows the pattern.
    std::string_view detail = line.substr(at);
    if (const auto subject = line.find("subject: "); subject != std::string_view::npos) {
      detail = line.substr(subject);
    }
    return SecurityRefusal{p.kind, OneLine(detail)};
  }
  return std::nullopt;
}

SecurityLog::SecurityLog(DropCounters& drops) : drops_(drops) {
  dds_set_log_sink(&Sink, this);
}

SecurityLog::~SecurityLog() { dds_set_log_sink(nullptr, nullptr); }

void SecurityLog::OnLine(std::string_view header, std::string_view message) {
  // Cyclone calls the sink once per message, a multi-line one (an OpenSSL error stack) included.
  if (const auto refusal = ClassifySecurityLogLine(message)) {
    drops_.Count(refusal->kind, refusal->detail);
    return;
  }
  // Everything else as Cyclone's default sink writes it.
  std::lock_guard<std::mutex> lock(mu_);
  std::fwrite(header.data(), 1, header.size(), stderr);
  std::fwrite(message.data(), 1, message.size(), stderr);
  std::fputc('\n', stderr);
  std::fflush(stderr);
}

}  // namespace vdyn::transport
