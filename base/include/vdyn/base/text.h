// Numbers and strings as a person reads and writes them: parsing that refuses what is not a
// finite number, formatting without 17-digit noise, and log-safe quoting of untrusted text.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>

namespace vdyn::base {

// Parses the whole of `text` (surrounding blanks allowed, a leading '+' allowed) as a decimal or
// hexadecimal floating-point number. A value too small for a double underflows to (signed) zero,
// as it would on paper; too large, "nan", "inf" or trailing characters give nullopt.
std::optional<double> ParseNumber(std::string_view text);

// The shortest form that reads back to the same double, with the exponent as a person writes it:
// 100000, 0.25, 1e9, 1.5e-7, -3, 2147483647. Never 17 significant digits of noise.
std::string FormatNumber(double v);

// A computed quantity to `digits` significant digits, exponent as a person writes it:
// 14094.8275... -> "14095", 3.0864e-07 -> "3.086e-7", 0.29 -> "0.29".
std::string FormatApprox(double v, int digits = 4);

// `v` with `decimals` digits after the point, as a display shows a reading: "12.3", and "0.0",
// never "-0.0", for a value that rounds to zero from below; `plus` writes "+" before a positive
// value (and before zero).
std::string FormatFixed(double v, int decimals, bool plus = false);

// `v` in hexadecimal as a hash or a CRC is quoted: "0x" and `digits` digits, zero-padded
// (FormatHex(0xbeef, 8) = "0x0000beef"; all of them when `v` needs more).
std::string FormatHex(std::uint64_t v, int digits);

// Untrusted text made safe for one log line or reply: at most `max_bytes` bytes of it, printable
// ASCII kept, everything else escaped (\n, \x1b, ...), and "... (N bytes)" when cut.
std::string Quote(std::string_view text, std::size_t max_bytes = 80);

// `text` in at most `max_bytes` bytes: whole when it fits, else cut at a UTF-8 character's start
// (a string field of a message must stay valid UTF-8) with " ..." after it to say so.
std::string CutText(std::string_view text, std::size_t max_bytes);
// The same without the " ...": at most `max_bytes` bytes, cut where a character starts.
std::string_view CutUtf8(std::string_view text, std::size_t max_bytes);

// Strips a leading UTF-8 byte-order mark.
std::string_view StripBom(std::string_view text);

}  // namespace vdyn::base
