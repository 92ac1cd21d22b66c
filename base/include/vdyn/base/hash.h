// The one hash of vdyn (docs/hash.md gives the algorithm so that any language can re-compute it).
//
//   Fnv1a64(bytes)   standard FNV-1a, 64 bit, over bytes (published test vectors apply);
//   WordHash         "vdyn-hash64": FNV-1a's xor-multiply applied to whole 64-bit words, then the
//                    fmix64 finaliser of MurmurHash3, so that every input bit reaches every output
//                    bit. A double enters as its IEEE-754 bits, an integer as its two's complement
//                    (sign-extended to 64 bits), in the order the caller gives them.
//
// Users: the state hash (physics), the terrain hash (a re-simulation checks it) and the envelope
// key of a server's own topics.
#pragma once

#include <cstdint>
#include <cstring>
#include <string_view>

namespace vdyn::base {

inline constexpr std::uint64_t kFnvOffset64 = 14695981039346656037ull;
inline constexpr std::uint64_t kFnvPrime64 = 1099511628211ull;

// FNV-1a-64 over bytes.
constexpr std::uint64_t Fnv1a64(std::string_view bytes) {
  std::uint64_t h = kFnvOffset64;
  for (char c : bytes) {
    h ^= static_cast<unsigned char>(c);
    h *= kFnvPrime64;
  }
  return h;
}

// MurmurHash3's 64-bit finaliser.
constexpr std::uint64_t Fmix64(std::uint64_t h) {
  h ^= h >> 33;
  h *= 0xff51afd7ed558ccdull;
  h ^= h >> 33;
  h *= 0xc4ceb9fe1a85ec53ull;
  h ^= h >> 33;
  return h;
}

// vdyn-hash64 over a sequence of 64-bit words. No allocation; a few cycles per word.
class WordHash {
 public:
  constexpr void Word(std::uint64_t w) {
    h_ ^= w;
    h_ *= kFnvPrime64;
  }
  void Double(double v) {
    std::uint64_t u;
    std::memcpy(&u, &v, sizeof u);
    Word(u);
  }
  constexpr void Int(std::int64_t v) { Word(static_cast<std::uint64_t>(v)); }
  constexpr std::uint64_t Final() const { return Fmix64(h_); }

 private:
  std::uint64_t h_ = kFnvOffset64;
};

// The 32-bit envelope key of a server's own topics (world, diagnostics): FNV-1a-64 of the server
// id's bytes, folded to 32 bits by xor of its halves.
constexpr std::uint32_t ServerKey(std::string_view server_id) {
  const std::uint64_t h = Fnv1a64(server_id);
  return static_cast<std::uint32_t>(h ^ (h >> 32));
}

}  // namespace vdyn::base
