#include "vdyn/base/file.h"

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <memory>

namespace vdyn::base {

FileText ReadFileBounded(const std::filesystem::path& path, std::size_t max_bytes,
                         const std::string& what) {
  FileText r;
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> f(std::fopen(path.c_str(), "rb"), &std::fclose);
  if (!f) {
    r.error = "cannot open the " + what + " (" + std::strerror(errno) + ")";
    return r;
  }
  char block[64 * 1024];
  errno = 0;
  while (true) {
    const std::size_t n = std::fread(block, 1, sizeof block, f.get());
    if (r.text.size() + n > max_bytes) {
      r.text.clear();
      r.error = "more than " + std::to_string(max_bytes) + " bytes, more than a " + what +
                " may have";
      return r;
    }
    r.text.append(block, n);
    if (n < sizeof block) break;
  }
  if (std::ferror(f.get())) {
    r.text.clear();
    r.error = "cannot read the " + what + " (" + std::strerror(errno) + ")";
  }
  return r;
}

}  // namespace vdyn::base
