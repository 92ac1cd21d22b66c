// A small text file read whole, with a bound: what the readers of parameter, tyre and mapping
// files need. The bound holds for what cannot be sized beforehand too (a device, a pipe).
#pragma once

#include <cstddef>
#include <filesystem>
#include <string>

namespace vdyn::base {

struct FileText {
  std::string text;
  std::string error;  // empty when the file was read; else why not, for "<file>: <error>"
};

// Reads `path` whole if it holds at most `max_bytes`. Reads in blocks and stops after
// `max_bytes` + 1, so a file that never ends (/dev/zero, whose size is 0 to stat) is refused like
// a large one instead of filling the memory. `what` names the file's kind in the errors:
// "cannot open the tyre file (No such file or directory)", "more than 4194304 bytes, more than a
// tyre file may have", "cannot read the tyre file (Input/output error)".
FileText ReadFileBounded(const std::filesystem::path& path, std::size_t max_bytes,
                         const std::string& what);

}  // namespace vdyn::base
