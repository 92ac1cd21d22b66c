#include "vdyn/base/text.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>

namespace vdyn::base {

std::optional<double> ParseNumber(std::string_view text) {
  while (!text.empty() && (text.front() == ' ' || text.front() == '\t')) text.remove_prefix(1);
  while (!text.empty() && (text.back() == ' ' || text.back() == '\t' || text.back() == '\r' ||
                           text.back() == '\n')) {
    text.remove_suffix(1);
  }
  if (text.empty()) return std::nullopt;
  bool negative = false;
  std::string_view body = text;
  if (body.front() == '+' || body.front() == '-') {
    negative = body.front() == '-';
    body.remove_prefix(1);
  }
  if (body.empty() || body.front() == '+' || body.front() == '-') return std::nullopt;
  std::chars_format fmt = std::chars_format::general;
  if (body.size() > 2 && body[0] == '0' && (body[1] == 'x' || body[1] == 'X')) {
    body.remove_prefix(2);
    fmt = std::chars_format::hex;
  }
  double v = 0.0;
  const auto [ptr, ec] = std::from_chars(body.data(), body.data() + body.size(), v, fmt);
  if (ptr != body.data() + body.size()) return std::nullopt;
  if (ec == std::errc::result_out_of_range) {
    // Underflow or overflow: strtod tells which (0 for underflow, HUGE_VAL for overflow).
    const std::string copy(fmt == std::chars_format::hex ? "0x" + std::string(body)
                                                         : std::string(body));
    const double r = std::strtod(copy.c_str(), nullptr);
    if (std::isinf(r)) return std::nullopt;
    v = 0.0;
  } else if (ec != std::errc()) {
    return std::nullopt;
  }
  if (!std::isfinite(v)) return std::nullopt;
  return negative ? -v : v;
}

std::string FormatNumber(double v) {
  if (std::isnan(v)) return "nan";
  if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
  if (v == 0.0) return "0";
  char buf[64];
  // Plain decimals for ordinary magnitudes, scientific beyond; both shortest round trip.
  const double a = std::abs(v);
  const auto fmt = (a >= 1e-4 && a < 1e7) ? std::chars_format::fixed : std::chars_format::scientific;
  auto [ptr, ec] = std::to_chars(buf, buf + sizeof buf, v, fmt);
  if (ec != std::errc()) return "?";
  std::string s(buf, ptr);
  // "1e+09" -> "1e9", "1.5e-07" -> "1.5e-7".
  const std::size_t e = s.find('e');
  if (e != std::string::npos) {
    std::string mant = s.substr(0, e);
    std::string exp = s.substr(e + 1);
    bool neg = false;
    if (!exp.empty() && (exp[0] == '+' || exp[0] == '-')) {
      neg = exp[0] == '-';
      exp.erase(0, 1);
    }
    while (exp.size() > 1 && exp[0] == '0') exp.erase(0, 1);
    s = mant + "e" + (neg ? "-" : "") + exp;
    // A large number is written out when that is shorter: 2147483647, not 2.147483647e9.
    if (!neg && a < 1e17) {
      auto [fptr, fec] = std::to_chars(buf, buf + sizeof buf, v, std::chars_format::fixed);
      if (fec == std::errc() && fptr - buf < static_cast<std::ptrdiff_t>(s.size())) {
        s.assign(buf, fptr);
      }
    }
  }
  return s;
}

std::string FormatApprox(double v, int digits) {
  if (!std::isfinite(v)) return FormatNumber(v);
  // Whole numbers up to seven digits stay whole (14095, not 1.409e4).
  if (std::abs(v) >= std::pow(10.0, digits) && std::abs(v) < 1e7) return FormatNumber(std::round(v));
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*g", digits, v);
  // Read back and print shortest: drops trailing zeros; then the exponent as a person writes it.
  const auto parsed = ParseNumber(buf);
  return parsed ? FormatNumber(*parsed) : std::string(buf);
}

std::string FormatHex(std::uint64_t v, int digits) {
  char buf[24];
  std::snprintf(buf, sizeof buf, "0x%0*llx", std::clamp(digits, 1, 16),
                static_cast<unsigned long long>(v));
  return buf;
}

std::string FormatFixed(double v, int decimals, bool plus) {
  char buf[64];
  std::snprintf(buf, sizeof buf, plus ? "%+.*f" : "%.*f", std::clamp(decimals, 0, 17), v);
  std::string s = buf;
  // A reading that shows no digit but zero has no sign but the one asked for.
  if (!s.empty() && s[0] == '-' && s.find_first_of("123456789") == std::string::npos &&
      std::isfinite(v)) {
    if (plus) {
      s[0] = '+';
    } else {
      s.erase(0, 1);
    }
  }
  return s;
}

std::string Quote(std::string_view text, std::size_t max_bytes) {
  std::string out;
  const std::size_t n = std::min(text.size(), max_bytes);
  out.reserve(n + 16);
  for (std::size_t i = 0; i < n; ++i) {
    const auto c = static_cast<unsigned char>(text[i]);
    switch (c) {
      case '\n': out += "\\n"; break;
      case '\r': out += "\\r"; break;
      case '\t': out += "\\t"; break;
      case '\\': out += "\\\\"; break;
      default:
        if (c >= 0x20 && c < 0x7f) {
          out += static_cast<char>(c);
        } else {
          char buf[8];
          std::snprintf(buf, sizeof buf, "\\x%02x", c);
          out += buf;
        }
    }
  }
  if (text.size() > n) out += "... (" + std::to_string(text.size()) + " bytes)";
  return out;
}

std::string_view CutUtf8(std::string_view text, std::size_t max_bytes) {
  if (text.size() <= max_bytes) return text;
  std::size_t end = max_bytes;
  // Back to the start of a character: continuation bytes are 10xxxxxx.
  while (end > 0 && (static_cast<unsigned char>(text[end]) & 0xC0) == 0x80) --end;
  return text.substr(0, end);
}

std::string CutText(std::string_view text, std::size_t max_bytes) {
  if (text.size() <= max_bytes) return std::string(text);
  constexpr std::string_view kMore = " ...";
  if (max_bytes < kMore.size()) return std::string(kMore.substr(0, max_bytes));
  return std::string(CutUtf8(text, max_bytes - kMore.size())) + std::string(kMore);
}

std::string_view StripBom(std::string_view text) {
  if (text.size() >= 3 && text.substr(0, 3) == "\xEF\xBB\xBF") text.remove_prefix(3);
  return text;
}

}  // namespace vdyn::base
