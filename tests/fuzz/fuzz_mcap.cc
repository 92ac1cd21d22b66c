// Fuzz target: the MCAP reader of vdyn-recorder (clients/recorder/src/mcap.cc). Any bytes, as a
// file: the reader opens it or refuses it with McapError; strict and lenient scans, the summary,
// the chunk list and every chunk's messages either work or throw McapError; never a crash, never
// a read outside the file.
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "vdyn/recorder/mcap.h"

namespace {
// One scratch file per process, removed when it ends.
struct ScratchFile {
  std::filesystem::path path = std::filesystem::temp_directory_path() /
                               ("vdyn-fuzz-mcap-" + std::to_string(getpid()) + ".mcap");
  ~ScratchFile() {
    std::error_code ec;
    std::filesystem::remove(path, ec);
  }
};
const std::filesystem::path& Scratch() {
  static const ScratchFile f;
  return f.path;
}
}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  namespace mcap = vdyn::mcap;
  {
    std::FILE* f = std::fopen(Scratch().c_str(), "wb");
    if (f == nullptr) std::abort();
    if (size > 0 && std::fwrite(data, 1, size, f) != size) std::abort();
    std::fclose(f);
  }
  try {
    const mcap::Reader reader(Scratch());
    std::uint64_t seen = 0;
    mcap::Visitor v;
    v.on_message = [&seen, size](const mcap::Message& m, std::uint64_t offset) {
      if (offset >= size) std::abort();  // a record the file cannot hold
      seen += m.data.size();
    };
    try {
      reader.Scan(v);
    } catch (const mcap::McapError&) {
    }
    const mcap::ScanResult lenient = reader.Scan(v, /*lenient=*/true);
    if (lenient.good_until > size) std::abort();
    try {
      (void)reader.ReadSummary();
      std::vector<std::uint8_t> scratch;
      for (const mcap::ChunkIndex& c : reader.Chunks()) {
        try {
          reader.ReadChunk(c, [&seen](const mcap::Message& m) { seen += m.data.size(); }, scratch);
        } catch (const mcap::McapError&) {
        }
      }
    } catch (const mcap::McapError&) {
    }
  } catch (const mcap::McapError&) {
  }
  return 0;
}
