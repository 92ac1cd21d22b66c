// A read-only mapping of a file that another program may truncate while we read it. A read past
// the file's new end raises SIGBUS; the guard turns that page into zeroes and notes the offset,
// so the reader can throw an error naming the file and the offset instead of the process dying
// (issue 33, item 3). The zero page only lets the read that faulted finish: the reader checks
// `fault()` before it trusts or hands on anything it read.
#pragma once

#include <cstdint>
#include <optional>

namespace vdyn::mcap {

class MappedFile {
 public:
  MappedFile() = default;
  ~MappedFile();
  MappedFile(const MappedFile&) = delete;
  MappedFile& operator=(const MappedFile&) = delete;

  // Maps `size` bytes of `fd` (the descriptor may be closed afterwards). False with errno set
  // when the kernel refuses.
  bool Map(int fd, std::uint64_t size);
  const std::uint8_t* data() const { return data_; }
  // The lowest offset a read could not reach since Map (the file shrank under it), if any.
  std::optional<std::uint64_t> fault() const;

 private:
  const std::uint8_t* data_ = nullptr;
  std::uint64_t size_ = 0;
  int slot_ = -1;  // in the guard's table; -1: the table was full (unguarded)
};

}  // namespace vdyn::mcap
