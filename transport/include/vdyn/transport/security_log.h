// What DDS Security refuses, counted. Cyclone DDS 0.10.2 tells the application nothing about a
// remote participant its security plugins refuse - no status, listener or builtin-topic entry -
// except lines in its log (category warning). A SecurityLog replaces Cyclone's log sink for the
// process: it counts each such line in a DropCounters by kind ("DDS Security: ..."), with the
// line's detail (the refused certificate's subject, the plugin's reason), and hands every other
// line on to stderr as Cyclone's default sink does. The counters log each kind once, then at most
// every 10 s, so a peer retrying its handshake every second cannot flood the log.
// docs/topics.md, "Only permitted participants drive", lists what is and is not visible.
#pragma once

#include <mutex>
#include <optional>
#include <string>
#include <string_view>

#include "vdyn/transport/drops.h"

namespace vdyn::transport {

// A refusal recognised in one line of Cyclone's log.
struct SecurityRefusal {
  std::string_view kind;  // a DropCounters kind, "DDS Security: ..."
  std::string detail;     // the subject or the plugin's reason, cut to one line
};

// The refusal a log line reports, or nothing when it reports none.
std::optional<SecurityRefusal> ClassifySecurityLogLine(std::string_view line);

class SecurityLog {
 public:
  // Installs the sink; one SecurityLog at a time in a process (Cyclone has one log sink).
  explicit SecurityLog(DropCounters& drops);
  ~SecurityLog();  // restores Cyclone's default sink; no call reaches this object afterwards
  SecurityLog(const SecurityLog&) = delete;
  SecurityLog& operator=(const SecurityLog&) = delete;

  // One message from Cyclone: counted when it reports a refusal, else written to stderr.
  void OnLine(std::string_view header, std::string_view message);

 private:
  DropCounters& drops_;
  std::mutex mu_;  // Cyclone may log from several threads at once: one line at a time to stderr
};

}  // namespace vdyn::transport
