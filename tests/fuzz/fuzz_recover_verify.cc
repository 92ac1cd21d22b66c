// Fuzz target: `vdyn-recorder recover` and `verify` on damaged recordings (clients/recorder/src/
// recover.cc, verify.cc), not only the reader. Any bytes, as a file: recover either refuses it
// (McapError: not MCAP at all, or no message in it reads; then no copy is written) or writes a copy that is a valid, closed MCAP file - a strict scan
// of it passes, `info` describes it - and `verify` of the copy re-simulates what it can and
// accounts for every state it saw, listing as verified only states that matched and are intact;
// never a crash, never a read outside the file.
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <sstream>
#include <string>

#include "vdyn/recorder/commands.h"
#include "vdyn/recorder/mcap.h"
#include "vdyn/recorder/output_file.h"
#include "vdyn/recorder/recording.h"
#include "vdyn/recorder/verify.h"

namespace {
namespace fs = std::filesystem;
// Scratch files per process, removed when it ends.
struct Scratch {
  fs::path dir = fs::temp_directory_path() / ("vdyn-fuzz-recover-" + std::to_string(getpid()));
  Scratch() { fs::create_directories(dir); }
  ~Scratch() {
    std::error_code ec;
    fs::remove_all(dir, ec);
  }
};
const Scratch& Files() {
  static const Scratch s;
  return s;
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  namespace mcap = vdyn::mcap;
  namespace rec = vdyn::recorder;
  const fs::path in = Files().dir / "damaged.mcap", out = Files().dir / "recovered.mcap";
  {
    std::FILE* f = std::fopen(in.c_str(), "wb");
    if (f == nullptr) std::abort();
    if (size > 0 && std::fwrite(data, 1, size, f) != size) std::abort();
    std::fclose(f);
  }
  std::error_code ec;
  fs::remove(out, ec);
  std::ostringstream log;
  rec::RecoverOptions ro;
  ro.file = in;
  ro.out = out;
  try {
    if (rec::RunRecover(ro, log) != 0) std::abort();
  } catch (const mcap::McapError&) {
    if (fs::exists(out)) std::abort();  // refused (empty, not MCAP, nothing to recover): no copy
    return 0;
  }
  // The copy is whole: every CRC and the summary check out, and info reads it.
  std::uint64_t states = 0;
  try {
    const mcap::Reader copy(out);
    rec::RecordingVisitor v;
    v.on_message = [&states](const rec::RecordedMessage& m) {
      states += m.topic == vdyn::transport::TopicId::kState ? 1 : 0;
    };
    if (!rec::ScanRecording(copy, v).complete) std::abort();
    std::ostringstream info;
    rec::RunInfo(out, info);
  } catch (const mcap::McapError& e) {
    std::fprintf(stderr, "the recovered copy is not a valid file: %s\n", e.what());
    std::abort();
  }
  // Verify re-simulates what it can and accounts for every state: compared, not verified, or
  // before a start. (A world or parameters the physics refuses is a reason, not a crash.)
  try {
    rec::VerifyOptions vo;
    vo.file = out;
    const rec::VerifyResult r = rec::Verify(vo);
    if (r.resimulated && r.compared + r.unverified + r.not_resimulated > states) std::abort();
    // The stretches it lists as verified hold exactly the states that matched and are intact:
    // never one that differs from its re-simulation or is damaged.
    std::uint64_t listed = 0;
    for (const auto& [vehicle, runs] : r.runs) {
      for (const rec::StepRun& run : runs) listed += run.why.empty() ? run.count : 0;
    }
    if (listed != r.compared - r.mismatched - r.damaged) {
      std::fprintf(stderr,
                   "verify lists %llu states as verified, %llu compared, %llu differ, "
                   "%llu damaged\n",
                   static_cast<unsigned long long>(listed),
                   static_cast<unsigned long long>(r.compared),
                   static_cast<unsigned long long>(r.mismatched),
                   static_cast<unsigned long long>(r.damaged));
      std::abort();
    }
  } catch (const mcap::McapError& e) {
    std::fprintf(stderr, "verify refused the recovered copy: %s\n", e.what());
    std::abort();
  } catch (const std::exception&) {
  }
  return 0;
}
