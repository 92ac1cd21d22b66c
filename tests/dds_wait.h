// Test helper over the transport layer: a bounded wait on a DDS reader.
#pragma once

#include <chrono>

#include "vdyn/transport/dds.h"

namespace vdyn::testing {

// Waits on a reader until `done` says so or the timeout passes, handing every sample to `on`.
template <class M, class On, class Done>
bool ReadUntil(transport::Reader<M>& reader, std::chrono::milliseconds timeout, On on, Done done) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (!done()) {
    if (std::chrono::steady_clock::now() >= deadline) return false;
    (void)reader.Wait(std::chrono::milliseconds(50));
    (void)reader.Take([&](const M& m, const transport::SampleInfo&) { on(m); });
  }
  return true;
}

}  // namespace vdyn::testing
