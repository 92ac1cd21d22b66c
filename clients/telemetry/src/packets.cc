#include "vdyn/telemetry/packets.h"

#include <cstring>
#include <stdexcept>

namespace vdyn::telemetry {
namespace {

template <class P>
std::size_t EncodeImage(const P& p, std::size_t size, std::span<std::uint8_t> out) {
  if (out.size() < size) throw std::invalid_argument("telemetry packet buffer too small");
  std::memcpy(out.data(), &p, size);  // packed and little-endian: the struct is the wire image
  return size;
}

}  // namespace

std::size_t Encode(const OutSimPack& p, bool with_id, std::span<std::uint8_t> out) {
  return EncodeImage(p, with_id ? kOutSimSize + kIdSize : kOutSimSize, out);
}

std::size_t Encode(const OutGaugePack& p, bool with_id, std::span<std::uint8_t> out) {
  return EncodeImage(p, with_id ? kOutGaugeSize + kIdSize : kOutGaugeSize, out);
}

void SetText(char* field, std::size_t n, const char* text, bool terminate) {
  std::memset(field, 0, n);
  const std::size_t room = terminate ? n - 1 : n;
  const std::size_t len = std::min(std::strlen(text), room);
  std::memcpy(field, text, len);
}

}  // namespace vdyn::telemetry
