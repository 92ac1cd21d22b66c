// The protobuf wire format read directly, without parsing into a message: a payload's top-level
// fields one by one (https://protobuf.dev/programming-guides/encoding/). The recorder reads a
// state's step and an event's sequence at 64 kHz this way; the checks walk whole messages with it.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string_view>
#include <vector>

namespace vdyn::messages::wire {

struct Field {
  std::uint32_t number = 0;
  int type = 0;                         // 0 varint, 1 fixed64, 2 length-delimited, 5 fixed32
  std::uint64_t value = 0;              // varint, fixed64 or fixed32
  std::span<const std::uint8_t> bytes;  // length-delimited
};

// Calls fn(const Field&) for each top-level field until fn returns false; false when the bytes
// are not a well-formed sequence of fields (a truncated varint, a length past the end, field
// number 0, a wire type proto3 does not use).
template <class F>
bool ForEachField(std::span<const std::uint8_t> p, F&& fn) {
  std::size_t i = 0;
  auto varint = [&](std::uint64_t& out) {
    out = 0;
    for (int shift = 0; shift < 64; shift += 7) {
      if (i >= p.size()) return false;
      const std::uint8_t b = p[i++];
      out |= static_cast<std::uint64_t>(b & 0x7f) << shift;
      if ((b & 0x80) == 0) return true;
    }
    return false;
  };
  auto fixed = [&](int n, std::uint64_t& out) {
    if (p.size() - i < static_cast<std::size_t>(n)) return false;
    out = 0;
    for (int k = 0; k < n; ++k) {
      out |= static_cast<std::uint64_t>(p[i + static_cast<std::size_t>(k)]) << (8 * k);
    }
    i += static_cast<std::size_t>(n);
    return true;
  };
  while (i < p.size()) {
    std::uint64_t tag = 0;
    if (!varint(tag)) return false;
    Field f;
    f.number = static_cast<std::uint32_t>(tag >> 3);
    f.type = static_cast<int>(tag & 7);
    if (f.number == 0) return false;
    switch (f.type) {
      case 0:
        if (!varint(f.value)) return false;
        break;
      case 1:
        if (!fixed(8, f.value)) return false;
        break;
      case 2: {
        std::uint64_t n = 0;
        if (!varint(n) || n > p.size() - i) return false;
        f.bytes = p.subspan(i, static_cast<std::size_t>(n));
        i += static_cast<std::size_t>(n);
        break;
      }
      case 5:
        if (!fixed(4, f.value)) return false;
        break;
      default:
        return false;  // groups (3, 4) are not used by proto3; anything else is not protobuf
    }
    if (!fn(f)) return true;
  }
  return true;
}

// The first occurrence of a varint or fixed field, or a length-delimited field's bytes.
inline std::optional<std::uint64_t> Number(std::span<const std::uint8_t> p, std::uint32_t field) {
  std::optional<std::uint64_t> out;
  ForEachField(p, [&](const Field& f) {
    if (f.number == field && f.type != 2) {
      out = f.value;
      return false;
    }
    return true;
  });
  return out;
}

inline std::optional<std::string_view> Bytes(std::span<const std::uint8_t> p, std::uint32_t field) {
  std::optional<std::string_view> out;
  ForEachField(p, [&](const Field& f) {
    if (f.number == field && f.type == 2) {
      out = std::string_view(reinterpret_cast<const char*>(f.bytes.data()), f.bytes.size());
      return false;
    }
    return true;
  });
  return out;
}

// Writing: a length-delimited field (tag, varint length, the bytes) appended to `out`, e.g. an
// encoded message as an element of a repeated message field; and how many bytes that takes.
inline std::size_t VarintSize(std::uint64_t v) {
  std::size_t n = 1;
  for (; v >= 0x80; v >>= 7) ++n;
  return n;
}

inline std::size_t BytesFieldSize(std::uint32_t field, std::size_t n) {
  return VarintSize((static_cast<std::uint64_t>(field) << 3) | 2) + VarintSize(n) + n;
}

inline void AppendVarint(std::vector<std::uint8_t>& out, std::uint64_t v) {
  for (; v >= 0x80; v >>= 7) out.push_back(static_cast<std::uint8_t>((v & 0x7F) | 0x80));
  out.push_back(static_cast<std::uint8_t>(v));
}

inline void AppendBytesField(std::vector<std::uint8_t>& out, std::uint32_t field,
                             std::span<const std::uint8_t> bytes) {
  AppendVarint(out, (static_cast<std::uint64_t>(field) << 3) | 2);
  AppendVarint(out, bytes.size());
  out.insert(out.end(), bytes.begin(), bytes.end());
}

}  // namespace vdyn::messages::wire
