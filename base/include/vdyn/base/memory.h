// The C library's handling of freed memory, for processes that move DDS traffic at a high rate.
#pragma once

#include <cstddef>

namespace vdyn::base {

// Keeps freed heap memory in the process instead of giving it back to the kernel. By default
// glibc serves a block of 128 KiB or more (a DDS receive buffer, a reassembled 200 KB vdyn/states
// sample) from a fresh mapping, or trims the heap's top when such a block is freed, so the next one
// faults its pages in again: at 128 vehicles a recorder spent about a fifth of its time in page
// faults. After this call only blocks of `mmap_from` bytes or more are mapped (glibc accepts at
// most 32 MiB), and the heap is trimmed only when `trim_above` bytes are free at its top: memory
// stays at the peak it reached. Returns false when the C library refused (the process then runs
// as before).
bool KeepFreedMemory(std::size_t mmap_from = std::size_t{32} << 20,
                     std::size_t trim_above = std::size_t{1} << 30);

}  // namespace vdyn::base
