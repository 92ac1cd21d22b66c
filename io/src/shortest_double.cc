#include "vdyn/io/shortest_double.h"

#include <array>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <iterator>

namespace vdyn {
namespace {

__extension__ typedef unsigned __int128 U128;  // GCC and Clang on 64-bit targets

struct Pow10 {
  std::uint64_t hi, lo;
};
// g(e10) = floor(10^e10 * 2^-r) + 1, 2^127 <= 10^e10 * 2^-r < 2^128 (gen_pow10_table.py).
constexpr int kE10Min = -292;
static_assert(std::endian::native == std::endian::little, "the digit words are little-endian");
constexpr Pow10 kPow10[] = {
#include "pow10_table.inc"
};
static_assert(std::size(kPow10) == 324 - kE10Min + 1);

// Exact on the exponents a double has (checked against exact arithmetic when the table was made):
// floor(log10(2^q)), floor(log10(3/4 * 2^q)) and floor(log2(10^e)).
constexpr int FloorLog10Pow2(int q) {
  return static_cast<int>((static_cast<std::int64_t>(q) * 661971961083) >> 41);
}
constexpr int FloorLog10ThreeQuartersPow2(int q) {
  return static_cast<int>((static_cast<std::int64_t>(q) * 661971961083 - 274743187321) >> 41);
}
constexpr int FloorLog2Pow10(int e) {
  return static_cast<int>((static_cast<std::int64_t>(e) * 913124641741) >> 38);
}

// floor(g * cp / 2^128), its lowest bit set when the dropped part is not (almost) zero: the
// "round to odd" of the paper, which keeps enough of the product to decide every comparison.
inline std::uint64_t RoundToOdd(const Pow10& g, std::uint64_t cp) {
  const U128 x = static_cast<U128>(g.lo) * cp;
  const U128 y = static_cast<U128>(g.hi) * cp + (x >> 64);
  return static_cast<std::uint64_t>(y >> 64) | (static_cast<std::uint64_t>(y) > 1 ? 1u : 0u);
}

struct Decimal {
  std::uint64_t digits;  // without trailing zeros
  int exponent;          // of the last digit: v = digits * 10^exponent
};

// v = c * 2^q, c > 0.
Decimal ToDecimal(std::uint64_t c, int q, bool lower_boundary_closer) {
  const std::uint64_t out = c & 1;  // an odd c's interval excludes its bounds
  const std::uint64_t cb = c << 2;
  const std::uint64_t cbr = cb + 2;
  std::uint64_t cbl;
  int k;
  if (lower_boundary_closer) {
    cbl = cb - 1;
    k = FloorLog10ThreeQuartersPow2(q);
  } else {
    cbl = cb - 2;
    k = FloorLog10Pow2(q);
  }
  const int h = q + FloorLog2Pow10(-k) + 1;  // 1 .. 4
  const Pow10& g = kPow10[-k - kE10Min];
  const std::uint64_t vb = RoundToOdd(g, cb << h);
  const std::uint64_t vbl = RoundToOdd(g, cbl << h);
  const std::uint64_t vbr = RoundToOdd(g, cbr << h);
  const std::uint64_t lower = vbl + out;
  const std::uint64_t upper = vbr - out;
  const std::uint64_t s = vb >> 2;
  // Branch-free choice: which candidate wins depends on the data (about 1 ns a value faster).
  const std::uint64_t sp = s / 10;  // one digit fewer, when exactly one of its neighbours is inside
  const bool up_inside = lower <= 40 * sp;
  const bool wp_inside = 40 * sp + 40 <= upper;
  const bool shorter = (s >= 10) & (up_inside != wp_inside);
  const bool u_inside = lower <= 4 * s;
  const bool w_inside = 4 * s + 4 <= upper;
  const std::uint64_t mid = 4 * s + 2;  // both inside: the closer, the even one on a tie
  const bool round_up = (vb > mid) | ((vb == mid) & ((s & 1) != 0));
  const bool up = (u_inside != w_inside) ? w_inside : round_up;
  const std::uint64_t longer_digits = s + static_cast<std::uint64_t>(up);
  const std::uint64_t shorter_digits = sp + static_cast<std::uint64_t>(wp_inside);
  Decimal d{shorter ? shorter_digits : longer_digits, k + static_cast<int>(shorter)};
  while (d.digits % 10 == 0) {
    d.digits /= 10;
    ++d.exponent;
  }
  return d;
}

constexpr auto kPow10U64 = [] {  // 10^0 .. 10^19
  std::array<std::uint64_t, 20> t{};
  std::uint64_t p = 1;
  for (std::uint64_t& x : t) {
    x = p;
    p *= 10;  // wraps after the last, unused
  }
  return t;
}();

// Decimal digits of v > 0: log10(2) ~ 1233 / 4096 gives the count or one less.
int DigitCount(std::uint64_t v) {
  const int guess = (std::bit_width(v) * 1233) >> 12;  // floor(log10(2^bits)) <= digits - 1
  return guess + (v >= kPow10U64[guess] ? 1 : 0);
}

constexpr char kPairs[] =
    "00010203040506070809101112131415161718192021222324252627282930313233343536373839"
    "40414243444546474849505152535455565758596061626364656667686970717273747576777879"
    "8081828384858687888990919293949596979899";

// x < 10^8 as 8 ASCII digits (leading zeros) in one word, the first digit in the lowest byte:
// split into two 4-digit lanes, each into two 2-digit lanes, each into two digits, every lane at
// once (multiply by a reciprocal and shift: exact for these ranges).
inline std::uint64_t Digits8(std::uint32_t x) {
  std::uint64_t v = (x / 10000) | (static_cast<std::uint64_t>(x % 10000) << 32);
  std::uint64_t q = ((v * 10486) >> 20) & 0x0000007F0000007Fu;  // / 100 in 32-bit lanes
  v = q | ((v - q * 100) << 16);
  q = ((v * 103) >> 10) & 0x000F000F000F000Fu;  // / 10 in 16-bit lanes
  v = q | ((v - q * 10) << 8);
  return v + 0x3030303030303030u;
}

// The n <= 17 digits of v < 10^n, in registers: the first 16 in `first16` (digit i in byte i,
// zero bytes after the last) and the 17th in `tail` when n is 17. Written by storing the words:
// no digit is stored and loaded back (a load across several fresh stores stalls).
struct DigitString {
  U128 first16;
  char tail;
};

inline DigitString Digits(std::uint64_t v, int n) {
  const std::uint64_t top = v / 100000000;
  const U128 s = static_cast<U128>(Digits8(static_cast<std::uint32_t>(top % 100000000))) |
                 (static_cast<U128>(Digits8(static_cast<std::uint32_t>(v % 100000000))) << 64);
  if (n == 17) {
    const auto first = static_cast<char>('0' + top / 100000000);
    return {static_cast<U128>(static_cast<unsigned char>(first)) | (s << 8),
            static_cast<char>(s >> 120)};
  }
  return {s >> (8 * (16 - n)), 0};
}

inline void Store16(char* p, U128 x) {
  std::memcpy(p, &x, 16);
}

// Stores the digits at p (17 bytes; the bytes after the n-th are scratch).
inline void StoreDigits(char* p, const DigitString& d) {
  Store16(p, d.first16);
  p[16] = d.tail;
}

// The exact value of an integer c * 2^q < 10^24 (q > 0) as digits at p; returns the end.
char* WriteExactInteger(char* p, std::uint64_t c, int q) {
  const U128 m = static_cast<U128>(c) << q;
  const auto top = static_cast<std::uint64_t>(m / 10000000000000000u);  // < 10^8
  const auto low = static_cast<std::uint64_t>(m % 10000000000000000u);
  const std::uint64_t words[3] = {Digits8(static_cast<std::uint32_t>(top)),
                                  Digits8(static_cast<std::uint32_t>(low / 100000000)),
                                  Digits8(static_cast<std::uint32_t>(low % 100000000))};
  char digits[24];
  std::memcpy(digits, words, 24);
  int first = 0;
  while (first < 23 && digits[first] == '0') ++first;
  std::memcpy(p, digits + first, static_cast<std::size_t>(24 - first));
  return p + (24 - first);
}

}  // namespace

char* WriteShortestDouble(char* p, double v) {
  const auto bits = std::bit_cast<std::uint64_t>(v);
  const auto ieee_exponent = static_cast<int>((bits >> 52) & 0x7ff);
  const std::uint64_t ieee_significand = bits & ((std::uint64_t{1} << 52) - 1);
  if (ieee_exponent == 0x7ff) return std::to_chars(p, p + kShortestDoubleBytes, v).ptr;
  if ((bits >> 63) != 0) *p++ = '-';
  if (ieee_exponent == 0 && ieee_significand == 0) {
    *p++ = '0';
    return p;
  }
  Decimal d;
  const int q = ieee_exponent - 1075;
  const std::uint64_t c = ieee_significand | (std::uint64_t{1} << 52);
  if (ieee_exponent != 0 && q <= 0 && q > -53 && (c & ((std::uint64_t{1} << -q) - 1)) == 0) {
    // A whole number below 2^53 (a step count, a flag, a gear): its digits are the shortest form.
    d = {c >> -q, 0};
    while (d.digits % 10 == 0) {
      d.digits /= 10;
      ++d.exponent;
    }
  } else if (ieee_exponent != 0) {
    d = ToDecimal(c, q, ieee_significand == 0 && ieee_exponent > 1);
  } else {
    d = ToDecimal(ieee_significand, -1074, false);
  }

  const int n = DigitCount(d.digits);
  const int e = d.exponent + n - 1;  // v = d.ddd * 10^e
  const int abs_e = e < 0 ? -e : e;
  const int scientific_length = n + (n > 1 ? 1 : 0) + 2 + (abs_e >= 100 ? 3 : 2);
  const int fixed_length = e >= 0 ? (e + 1 >= n ? e + 1 : n + 1) : n + 1 - e;
  const DigitString digits = Digits(d.digits, n);
  // Whole-word stores (at most 34 bytes with the sign); past the end is scratch, overwritten in
  // order.
  if (fixed_length <= scientific_length) {
    if (e < 0) {  // 0.000ddd, at most 4 zeros
      std::memcpy(p, "0.0000", 6);
      StoreDigits(p + 1 - e, digits);
    } else if (e + 1 >= n) {  // ddd000, at most 5 zeros
      if (q > 0) {
        // A whole number of 2^q: written exactly, as std::to_chars does (q > 0: v >= 2^53)
        return WriteExactInteger(p, c, q);
      }
      StoreDigits(p, digits);
      std::memcpy(p + n, "000000", 6);
    } else {  // dd.ddd: the digits, then those after the point again one place on
      Store16(p, digits.first16);
      // (e + 1 is 16 only for 17 digits with one after the point: the tail, below.)
      Store16(p + e + 2, e + 1 < 16 ? digits.first16 >> (8 * (e + 1)) : U128{0});
      if (n == 17) p[17] = digits.tail;  // the 17th digit, one place on
      p[e + 1] = '.';
    }
    return p + fixed_length;
  }
  Store16(p + 1, digits.first16);  // d.ddde+XX: the digits one place on, the first moved back
  p[17] = digits.tail;
  p[0] = static_cast<char>(digits.first16);
  p[1] = '.';
  p += n > 1 ? n + 1 : 1;
  *p++ = 'e';
  *p++ = e < 0 ? '-' : '+';
  if (abs_e >= 100) {
    *p++ = static_cast<char>('0' + abs_e / 100);
    std::memcpy(p, kPairs + 2 * (abs_e % 100), 2);
  } else {
    std::memcpy(p, kPairs + 2 * abs_e, 2);
  }
  return p + 2;
}

}  // namespace vdyn
