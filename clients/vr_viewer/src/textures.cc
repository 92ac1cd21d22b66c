#include "vdyn/viewer/textures.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <stdexcept>

namespace vdyn::viewer {

// Integer hash of a lattice point, in [0, 1).
double LatticeHash(std::int64_t i, std::int64_t j, std::uint64_t seed) {
  std::uint64_t h = seed * 0xD6E8FEB86659FD93ull ^
                    (static_cast<std::uint64_t>(i) * 0x9E3779B97F4A7C15ull) ^
                    (static_cast<std::uint64_t>(j) * 0xC2B2AE3D27D4EB4Full);
  h ^= h >> 33;
  h *= 0xFF51AFD7ED558CCDull;
  h ^= h >> 33;
  h *= 0xC4CEB9FE1A85EC53ull;
  h ^= h >> 33;
  return static_cast<double>(h >> 11) * (1.0 / 9007199254740992.0);
}

double SmoothStep(double e0, double e1, double x) {
  const double t = std::clamp((x - e0) / (e1 - e0), 0.0, 1.0);
  return t * t * (3 - 2 * t);
}

namespace {

std::int64_t Wrap(std::int64_t i, std::int64_t period) {
  const std::int64_t m = i % period;
  return m < 0 ? m + period : m;
}

// Value noise with a lattice of `period` cells across the tile (x, y in [0, 1)): tileable.
double Noise(double x, double y, int period, std::uint64_t seed) {
  const double fx = x * period, fy = y * period;
  const double x0 = std::floor(fx), y0 = std::floor(fy);
  const auto i = static_cast<std::int64_t>(x0), j = static_cast<std::int64_t>(y0);
  double tx = fx - x0, ty = fy - y0;
  tx = tx * tx * (3 - 2 * tx);
  ty = ty * ty * (3 - 2 * ty);
  const std::int64_t p = period;
  const double a = LatticeHash(Wrap(i, p), Wrap(j, p), seed), b = LatticeHash(Wrap(i + 1, p), Wrap(j, p), seed);
  const double c = LatticeHash(Wrap(i, p), Wrap(j + 1, p), seed);
  const double d = LatticeHash(Wrap(i + 1, p), Wrap(j + 1, p), seed);
  return (a + (b - a) * tx) * (1 - ty) + (c + (d - c) * tx) * ty;
}

// Fractal sum of octaves from `period` cells up, each twice as fine and half as strong; [0, 1].
double Fbm(double x, double y, int period, int octaves, std::uint64_t seed) {
  double sum = 0, weight = 0, w = 1;
  for (int o = 0; o < octaves; ++o) {
    sum += w * Noise(x, y, period << o, seed + static_cast<std::uint64_t>(o) * 101);
    weight += w;
    w *= 0.5;
  }
  return sum / weight;
}

struct Lin {
  double r = 0, g = 0, b = 0;
};
Lin L(Rgb8 c) {
  return {ToLinear(c.r), ToLinear(c.g), ToLinear(c.b)};
}
Lin Mix(const Lin& a, const Lin& b, double t) {
  return {a.r + (b.r - a.r) * t, a.g + (b.g - a.g) * t, a.b + (b.b - a.b) * t};
}
Lin Scale(const Lin& a, double s) {
  return {a.r * s, a.g * s, a.b * s};
}

// Small stones scattered over the tile: per cell of a grid, one stone at a hashed place with a
// hashed radius and brightness. Returns the stone's brightness factor at a pixel, or 0.
double Stones(double x, double y, int cells, double radius_cells, std::uint64_t seed,
              double* shade) {
  const double fx = x * cells, fy = y * cells;
  const auto ci = static_cast<std::int64_t>(std::floor(fx));
  const auto cj = static_cast<std::int64_t>(std::floor(fy));
  double best = 0;
  for (std::int64_t dj = -1; dj <= 1; ++dj) {
    for (std::int64_t di = -1; di <= 1; ++di) {
      const std::int64_t i = Wrap(ci + di, cells), j = Wrap(cj + dj, cells);
      const double sx = static_cast<double>(ci + di) + LatticeHash(i, j, seed);
      const double sy = static_cast<double>(cj + dj) + LatticeHash(i, j, seed + 7);
      const double r = radius_cells * (0.5 + LatticeHash(i, j, seed + 13));
      const double d = std::hypot(fx - sx, fy - sy) / r;
      if (d < 1.0) {
        const double cover = 1.0 - d * d;
        if (cover > best) {
          best = cover;
          *shade = LatticeHash(i, j, seed + 29);
        }
      }
    }
  }
  return best;
}

Lin Grass(double x, double y) {
  const double patches = Fbm(x, y, 4, 4, 11);
  const double fine = Fbm(x, y, 64, 2, 12);
  const double blades =
      LatticeHash(static_cast<std::int64_t>(x * 4096), static_cast<std::int64_t>(y * 4096), 13);
  Lin c = Mix(L({58, 88, 34}), L({112, 138, 58}), SmoothStep(0.25, 0.75, patches));
  // Dry, yellowish patches and clover-dark spots.
  const double dry = SmoothStep(0.62, 0.8, Fbm(x + 0.37, y + 0.11, 3, 3, 14));
  c = Mix(c, L({138, 134, 74}), 0.45 * dry);
  c = Scale(c, 0.7 + 0.45 * fine + 0.25 * (blades - 0.5));
  return c;
}

Lin Asphalt(double x, double y) {
  const double patches = Fbm(x, y, 3, 4, 21);
  const double grain =
      LatticeHash(static_cast<std::int64_t>(x * 2048), static_cast<std::int64_t>(y * 2048), 22);
  Lin c = Scale(L({72, 72, 75}), 0.88 + 0.24 * patches + 0.22 * (grain - 0.5));
  double shade = 0;
  const double stone = Stones(x, y, 96, 0.22, 23, &shade);
  if (stone > 0) c = Mix(c, Scale(L({150, 148, 142}), 0.6 + 0.6 * shade), std::min(1.0, 2 * stone));
  return c;
}

Lin Concrete(double x, double y) {
  const double mottle = Fbm(x, y, 4, 5, 31);
  const double grain =
      LatticeHash(static_cast<std::int64_t>(x * 2048), static_cast<std::int64_t>(y * 2048), 32);
  Lin c = Scale(L({164, 161, 154}), 0.86 + 0.24 * mottle + 0.08 * (grain - 0.5));
  double shade = 0;
  if (Stones(x, y, 64, 0.12, 33, &shade) > 0.2) c = Scale(c, 0.72);  // pores
  return c;
}

Lin Dirt(double x, double y) {
  const double patches = Fbm(x, y, 4, 5, 41);
  const double grain =
      LatticeHash(static_cast<std::int64_t>(x * 2048), static_cast<std::int64_t>(y * 2048), 42);
  Lin c = Mix(L({96, 76, 56}), L({146, 122, 92}), SmoothStep(0.2, 0.8, patches));
  c = Scale(c, 0.9 + 0.2 * (grain - 0.5));
  double shade = 0;
  const double stone = Stones(x, y, 48, 0.3, 43, &shade);
  if (stone > 0) {
    // A pebble: lit on top, its shadow towards the lower right.
    const Lin pebble = Scale(Mix(L({120, 112, 100}), L({190, 182, 168}), shade), 0.7 + 0.5 * stone);
    c = Mix(c, pebble, SmoothStep(0.0, 0.25, stone));
  }
  return c;
}

// A 5 x 7 pixel font: the letters the poster needs, rows top down, '#' set.
struct Glyph {
  char c;
  const char* rows[7];
};
constexpr Glyph kFont[] = {
    {'V', {"#...#", "#...#", "#...#", "#...#", "#...#", ".#.#.", "..#.."}},
    {'D', {"####.", "#...#", "#...#", "#...#", "#...#", "#...#", "####."}},
    {'Y', {"#...#", "#...#", ".#.#.", "..#..", "..#..", "..#..", "..#.."}},
    {'N', {"#...#", "##..#", "#.#.#", "#..##", "#...#", "#...#", "#...#"}},
    {'P', {"####.", "#...#", "#...#", "####.", "#....", "#....", "#...."}},
    {'R', {"####.", "#...#", "#...#", "####.", "#.#..", "#..#.", "#...#"}},
    {'O', {".###.", "#...#", "#...#", "#...#", "#...#", "#...#", ".###."}},
    {'I', {".###.", "..#..", "..#..", "..#..", "..#..", "..#..", ".###."}},
    {'G', {".###.", "#...#", "#....", "#.###", "#...#", "#...#", ".###."}},
    {'U', {"#...#", "#...#", "#...#", "#...#", "#...#", "#...#", ".###."}},
};

// Whether a point (x right, y down, in font pixels from the text's top left, slanted by `slant`
// per pixel of height) is inside a letter of `text` (6 font pixels per letter: 5 and a gap).
bool InText(const char* text, double x, double y, double slant) {
  if (y < 0 || y >= 7) return false;
  x -= slant * (7 - y);
  if (x < 0) return false;
  const auto letter = static_cast<std::size_t>(x / 6);
  const auto col = static_cast<int>(x - 6.0 * static_cast<double>(letter));
  for (std::size_t i = 0; text[i] != 0; ++i) {
    if (i != letter) continue;
    if (col >= 5) return false;
    for (const Glyph& g : kFont) {
      if (g.c == text[i]) return g.rows[static_cast<int>(y)][col] == '#';
    }
    return false;
  }
  return false;
}

// The billboard's poster at (x, y) in [0, 1)^2 (y down) of a face kPosterAspect : 1: a deep blue
// ground, red and white chevrons on the right, "VDYN" large in white and "PROVING GROUND" in
// yellow below it, a red band along the bottom. Each pixel is the mean of 4 x 4 samples (the
// letters' edges smooth).
Lin Poster(double x, double y, int size) {
  Lin sum;
  for (int sj = 0; sj < 4; ++sj) {
    for (int si = 0; si < 4; ++si) {
      const double u = (x + (si - 1.5) / (4.0 * size)) * kPosterAspect;  // 0 .. 3 across
      const double v = y + (sj - 1.5) / (4.0 * size);                    // 0 .. 1 down
      Lin c = Mix(L({18, 52, 128}), L({8, 26, 74}), v);
      // Chevrons pointing right, from u = 2.05 on.
      const double chevron = u - 2.05 - 0.45 * std::abs(v - 0.45);
      if (chevron > 0 && v < 0.86) {
        const double k = std::fmod(chevron / 0.16, 2.0);
        c = k < 1.0 ? L({214, 30, 36}) : L({240, 240, 236});
      }
      if (v > 0.88) c = L({200, 24, 30});
      if (v > 0.86 && v <= 0.88) c = L({240, 240, 236});
      // "VDYN": 7 font pixels 0.42 high; "PROVING GROUND" 0.13 high.
      const double big = 0.42 / 7, small = 0.13 / 7;
      if (InText("VDYN", (u - 0.16) / big, (v - 0.1) / big, 0.25)) c = L({248, 248, 244});
      if (InText("PROVING GROUND", (u - 0.18) / small, (v - 0.61) / small, 0.25)) {
        c = L({252, 206, 40});
      }
      sum.r += c.r / 16;
      sum.g += c.g / 16;
      sum.b += c.b / 16;
    }
  }
  return sum;
}

}  // namespace

namespace {

// The sRGB curve's two directions as the formulas (IEC 61966-2-1).
double DecodeSrgb(double c) {
  return c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4);
}
std::uint8_t EncodeSrgbByte(double linear) {
  const double c = std::clamp(linear, 0.0, 1.0);
  const double v = c <= 0.0031308 ? 12.92 * c : 1.055 * std::pow(c, 1.0 / 2.4) - 0.055;
  return static_cast<std::uint8_t>(std::lround(v * 255.0));
}

// Both once, as tables: a texture decodes constant colours and encodes three channels per texel,
// and the pow calls were most of the viewer's start (a quarter of its CPU for ten frames).
struct SrgbTables {
  std::array<double, 256> linear{};  // each byte decoded
  // rise[k - 1]: the least linear value encoded to byte k or above (k = 1..255). The encoding is
  // non-decreasing, so a value's byte is the number of these at or below it - the formula's own
  // answer: each is found by bisecting the doubles of [0, 1] (ordered as their bit patterns).
  std::array<double, 255> rise{};
  SrgbTables() {
    for (int i = 0; i < 256; ++i) linear[static_cast<std::size_t>(i)] = DecodeSrgb(i / 255.0);
    for (int k = 1; k < 256; ++k) {
      std::uint64_t lo = 0, hi = std::bit_cast<std::uint64_t>(1.0);  // byte(lo) < k <= byte(hi)
      while (hi - lo > 1) {
        const std::uint64_t mid = lo + (hi - lo) / 2;
        (EncodeSrgbByte(std::bit_cast<double>(mid)) >= k ? hi : lo) = mid;
      }
      rise[static_cast<std::size_t>(k - 1)] = std::bit_cast<double>(hi);
    }
  }
};
const SrgbTables& Tables() {
  static const SrgbTables tables;
  return tables;
}

}  // namespace

double ToLinear(std::uint8_t srgb) {
  return Tables().linear[srgb];
}
std::uint8_t ToSrgb(double linear) {
  if (!(linear > 0.0)) return 0;  // also NaN
  const std::array<double, 255>& rise = Tables().rise;
  const auto above = std::upper_bound(rise.begin(), rise.end(), linear);
  return static_cast<std::uint8_t>(above - rise.begin());
}

Rgb8 MeanColour(TextureLayer layer) {
  switch (layer) {
    case TextureLayer::kGrass:
      return {92, 118, 54};
    case TextureLayer::kAsphalt:
      return {78, 78, 80};
    case TextureLayer::kConcrete:
      return {168, 165, 158};
    case TextureLayer::kDirt:
      return {128, 106, 80};
    case TextureLayer::kMacro:
      return {128, 128, 128};
    case TextureLayer::kClouds:
      return {255, 255, 255};
    case TextureLayer::kPoster:
      return {40, 60, 120};
  }
  return {128, 128, 128};
}

double TileMetres(TextureLayer layer) {
  switch (layer) {
    case TextureLayer::kGrass:
      return 4.0;
    case TextureLayer::kAsphalt:
      return 3.0;
    case TextureLayer::kConcrete:
      return 3.0;
    case TextureLayer::kDirt:
      return 3.0;
    case TextureLayer::kMacro:
      return 61.0;  // not a multiple of the others: their tiling does not line up with it
    case TextureLayer::kClouds:
      return 2400.0;
    case TextureLayer::kPoster:
      return 1.0;  // over its face once
  }
  return 1.0;
}

TextureImage MakeTexture(TextureLayer layer, int size) {
  if (size < 16 || (size & (size - 1)) != 0) {
    throw std::invalid_argument("texture size must be a power of two >= 16");
  }
  TextureImage img;
  img.size = size;
  const auto n = static_cast<std::size_t>(size) * static_cast<std::size_t>(size);
  img.rgba.resize(n * 4);
  std::vector<Lin> lin(n);
  std::vector<double> alpha(n, 1.0);
  for (int j = 0; j < size; ++j) {
    for (int i = 0; i < size; ++i) {
      const double x = (i + 0.5) / size, y = (j + 0.5) / size;
      const std::size_t k = static_cast<std::size_t>(j) * static_cast<std::size_t>(size) +
                            static_cast<std::size_t>(i);
      switch (layer) {
        case TextureLayer::kGrass:
          lin[k] = Grass(x, y);
          break;
        case TextureLayer::kAsphalt:
          lin[k] = Asphalt(x, y);
          break;
        case TextureLayer::kConcrete:
          lin[k] = Concrete(x, y);
          break;
        case TextureLayer::kDirt:
          lin[k] = Dirt(x, y);
          break;
        case TextureLayer::kMacro: {
          const double v = Fbm(x, y, 3, 4, 51);
          lin[k] = {v, v, v};
          break;
        }
        case TextureLayer::kClouds: {
          const double f = Fbm(x, y, 4, 6, 61);
          const double cover = SmoothStep(0.48, 0.78, f);
          const double lum = 1.0 - 0.35 * SmoothStep(0.6, 0.95, f);  // denser: greyer underneath
          lin[k] = {lum, lum, lum * 1.02};
          alpha[k] = cover;
          break;
        }
        case TextureLayer::kPoster:
          lin[k] = Poster(x, y, size);
          break;
      }
    }
  }
  if (layer != TextureLayer::kMacro && layer != TextureLayer::kClouds &&
      layer != TextureLayer::kPoster) {
    // Scale each channel (in linear light) so the mean is the layer's colour; clamping moves it
    // a little, so repeat.
    const Lin target = L(MeanColour(layer));
    for (int pass = 0; pass < 4; ++pass) {
      Lin mean;
      for (const Lin& c : lin) {
        mean.r += c.r / static_cast<double>(n);
        mean.g += c.g / static_cast<double>(n);
        mean.b += c.b / static_cast<double>(n);
      }
      for (Lin& c : lin) {
        c.r = std::min(1.0, c.r * target.r / std::max(mean.r, 1e-9));
        c.g = std::min(1.0, c.g * target.g / std::max(mean.g, 1e-9));
        c.b = std::min(1.0, c.b * target.b / std::max(mean.b, 1e-9));
      }
    }
  }
  // Every layer is stored sRGB-encoded (the GPU decodes it while filtering, so far-away mip
  // levels average in linear light); the macro map and the clouds then read back as they were.
  for (std::size_t k = 0; k < n; ++k) {
    std::uint8_t* p = img.rgba.data() + 4 * k;
    p[0] = ToSrgb(lin[k].r);
    p[1] = ToSrgb(lin[k].g);
    p[2] = ToSrgb(lin[k].b);
    p[3] = static_cast<std::uint8_t>(std::lround(std::clamp(alpha[k], 0.0, 1.0) * 255));
  }
  return img;
}

}  // namespace vdyn::viewer
