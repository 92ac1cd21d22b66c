// The shortest decimal form of a double that reads back exactly, written as std::to_chars(first,
// last, value) writes it (the plain overload: fixed or scientific, whichever is shorter, fixed on a
// tie; "-0" for minus zero), about twice as fast as libstdc++'s. The digits come from Giulietti's
// Schubfach ("The Schubfach way to render doubles", 2020): the closest of the shortest decimals
// inside the value's rounding interval, round-half-even between two. Tests compare it with
// std::to_chars over millions of values.
#pragma once

namespace vdyn {

inline constexpr int kShortestDoubleBytes = 40;

// Writes v at p and returns the end. Needs kShortestDoubleBytes at p: the longest form, e.g.
// "-2.2250738585072014e-308", is 24; it stores whole 16-byte words and the rest is scratch.
// Infinities and NaN are written by std::to_chars ("inf", "nan").
char* WriteShortestDouble(char* p, double v);

}  // namespace vdyn
