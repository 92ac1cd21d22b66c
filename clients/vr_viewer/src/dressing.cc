#include "vdyn/viewer/dressing.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <utility>

#include "vdyn/viewer/textures.h"

namespace vdyn::viewer {
namespace {

constexpr double kBig = std::numeric_limits<double>::max();
constexpr double kTreeBandFromM = 10.0;  // trees from this far beyond the barrier's outer face
constexpr double kSignOutM = kDressingClearanceM + 0.3;
constexpr double kTreeCellM = 9.0;     // one tree at most per cell of this side
constexpr double kChunkCellM = 120.0;  // trees and signs drawn (or left out of view) in cells

// Value noise in [0, 1) on a lattice of unit cells.
double Noise(double x, double y, std::uint64_t seed) {
  const double fx = std::floor(x), fy = std::floor(y);
  const auto i = static_cast<std::int64_t>(fx), j = static_cast<std::int64_t>(fy);
  const double tx = SmoothStep(0, 1, x - fx), ty = SmoothStep(0, 1, y - fy);
  const double a = LatticeHash(i, j, seed), b = LatticeHash(i + 1, j, seed);
  const double c = LatticeHash(i, j + 1, seed), d = LatticeHash(i + 1, j + 1, seed);
  return (a + (b - a) * tx) * (1 - ty) + (c + (d - c) * tx) * ty;
}

Rgb8 Shade(Rgb8 c, double f) {
  auto s = [&](std::uint8_t v) {
    return static_cast<std::uint8_t>(std::clamp(std::lround(v * f), 0L, 255L));
  };
  return {s(c.r), s(c.g), s(c.b)};
}

// One side of the barrier's bounds: its middle on the outer face, the way out, the way along
// (so that along, out, up is right-handed), half its length.
struct Side {
  Vec3 mid_W, out_W, along_W;
  double half_length = 0;
  // A point `u` along, `w` out, `z` up.
  Vec3 At(double u, double w, double z) const {
    return mid_W + along_W * u + out_W * w + Vec3{0, 0, z};
  }
  Pose Frame() const {
    Pose p;
    p.R.c[0] = along_W;
    p.R.c[1] = out_W;
    p.R.c[2] = {0, 0, 1};
    p.t = mid_W;
    return p;
  }
};

std::array<Side, 4> SidesOf(const Vec3& lo, const Vec3& hi, double z) {
  const double cx = 0.5 * (lo.x + hi.x), cy = 0.5 * (lo.y + hi.y);
  const double hx = 0.5 * (hi.x - lo.x), hy = 0.5 * (hi.y - lo.y);
  return {Side{{cx, lo.y, z}, {0, -1, 0}, {1, 0, 0}, hx},   // south
          Side{{cx, hi.y, z}, {0, 1, 0}, {-1, 0, 0}, hx},   // north
          Side{{lo.x, cy, z}, {-1, 0, 0}, {0, -1, 0}, hy},  // west
          Side{{hi.x, cy, z}, {1, 0, 0}, {0, 1, 0}, hy}};   // east
}

// A footprint in a side's frame: [u0, u1] along, [w0, w1] out.
struct Footprint {
  double u0, u1, w0, w1;
  bool Near(double u, double w, double margin) const {
    return u > u0 - margin && u < u1 + margin && w > w0 - margin && w < w1 + margin;
  }
};

// A low-poly ellipsoid: `rings` bands from the bottom to the top, `segments` around, faces flat.
void Blob(DrawList& list, const Vec3& c, const Vec3& r, Rgb8 colour, int segments, int rings) {
  auto at = [&](int i, int k) {
    const double az = 2 * kPi * i / segments, el = -0.5 * kPi + kPi * k / rings;
    return Vec3{std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el)};
  };
  for (int k = 0; k < rings; ++k) {
    for (int i = 0; i < segments; ++i) {
      const Vec3 d[4] = {at(i, k), at(i + 1, k), at(i + 1, k + 1), at(i, k + 1)};
      Vec3 p[4];
      for (int q = 0; q < 4; ++q) p[q] = c + Vec3{d[q].x * r.x, d[q].y * r.y, d[q].z * r.z};
      const Vec3 n = Normalized(d[0] + d[1] + d[2] + d[3], {0, 0, 1});
      // Lower bands a little darker: the crown shades itself.
      const Rgb8 col = Shade(colour, 0.8 + 0.3 * k / rings);
      if (k > 0) list.Triangle(p[0], p[1], p[2], n, col);
      if (k + 1 < rings) list.Triangle(p[0], p[2], p[3], n, col);
    }
  }
}

struct Tree {
  Vec3 base_W;
  double height = 8, hash = 0;
};

void AppendTree(DrawList& list, const Tree& t, bool full) {
  const Vec3& b = t.base_W;
  const double h = t.height;
  const Rgb8 bark = Shade({92, 70, 52}, 0.85 + 0.3 * t.hash);
  const int seg = full ? 7 : 5;
  if (t.hash < 0.45) {
    // A conifer: a short trunk, two cones.
    const Rgb8 needles = Shade({44, 74, 42}, 0.8 + 0.4 * LatticeHash(std::lround(b.x), 3, 9));
    list.Cylinder(b, b + Vec3{0, 0, 0.25 * h}, 0.04 * h + 0.1, bark, true, 5);
    const double r = 0.22 * h;
    list.Cone(b + Vec3{0, 0, 0.15 * h}, b + Vec3{0, 0, 0.75 * h}, r, needles, true, seg);
    list.Cone(b + Vec3{0, 0, 0.45 * h}, b + Vec3{0, 0, h}, 0.7 * r, Shade(needles, 1.08), true,
              seg);
  } else {
    // A broadleaf tree: a trunk, a round crown.
    const Rgb8 leaves = Shade({78, 106, 46}, 0.75 + 0.45 * LatticeHash(std::lround(b.y), 5, 11));
    list.Cylinder(b, b + Vec3{0, 0, 0.5 * h}, 0.035 * h + 0.12, bark, true, 5);
    const double r = 0.3 * h;
    Blob(list, b + Vec3{0, 0, 0.62 * h}, {r, r * (0.85 + 0.3 * t.hash), 0.42 * h}, leaves,
         full ? 8 : 6, full ? 4 : 3);
  }
}

// Tiers of seats rising away from the facility, a back wall, side walls and a roof.
void AppendGrandstand(DrawList& list, const Side& s, const Footprint& f) {
  const Pose P = s.Frame();
  const Rgb8 concrete{168, 165, 158}, wall{140, 138, 134};
  const Rgb8 seats[3] = {{30, 70, 150}, {200, 40, 40}, {230, 230, 225}};
  constexpr int kTiers = 8;
  const double depth = (f.w1 - f.w0 - 0.5) / kTiers, rise = 0.55;
  for (int k = 0; k < kTiers; ++k) {
    const double w = f.w0 + k * depth, top = 0.6 + rise * k;
    list.Box(P, {f.u0, w, 0}, {f.u1, f.w1, top}, Shade(concrete, 0.92 + 0.04 * (k % 2)));
    // The seats: a row of coloured backs along the tier's front.
    const Rgb8 c = seats[(k / 2) % 3];
    for (double u = f.u0 + 0.5; u + 3.6 < f.u1; u += 4.0) {
      list.Box(P, {u, w + 0.25, top}, {u + 3.6, w + 0.75, top + 0.45}, c);
    }
  }
  const double top = 0.6 + rise * kTiers;
  list.Box(P, {f.u0, f.w1 - 0.5, 0}, {f.u1, f.w1, top + 4.0}, wall);  // back wall
  list.Box(P, {f.u0 - 0.4, f.w0, 0}, {f.u0, f.w1, top + 4.0}, wall);  // side walls
  list.Box(P, {f.u1, f.w0, 0}, {f.u1 + 0.4, f.w1, top + 4.0}, wall);
  list.Box(P, {f.u0 - 0.6, f.w0 - 2.0, top + 4.0}, {f.u1 + 0.6, f.w1 + 0.3, top + 4.4},
           {222, 224, 226});  // the roof
  list.Box(P, {f.u0 - 0.6, f.w0 - 2.05, top + 3.6}, {f.u1 + 0.6, f.w0 - 1.9, top + 4.4},
           {180, 30, 30});  // its red fascia
}

// Two storeys: garages below, a glass band above, a control room on the roof at one end.
void AppendPitBuilding(DrawList& list, const Side& s, const Footprint& f) {
  const Pose P = s.Frame();
  const Rgb8 white{214, 214, 210}, glass{52, 66, 82}, door{70, 72, 76};
  list.Box(P, {f.u0, f.w0, 0}, {f.u1, f.w1, 7.0}, white);
  for (double u = f.u0 + 1.5; u + 4.5 < f.u1; u += 6.0) {
    list.Box(P, {u, f.w0 - 0.06, 0}, {u + 4.5, f.w0, 3.6}, door);
  }
  list.Box(P, {f.u0 + 0.5, f.w0 - 0.08, 4.2}, {f.u1 - 0.5, f.w0, 6.2}, glass);
  list.Box(P, {f.u0 - 0.1, f.w0 - 0.15, 6.6}, {f.u1 + 0.1, f.w1 + 0.1, 7.1}, {190, 32, 32});
  const double c0 = f.u1 - 10.0;
  list.Box(P, {c0, f.w0 + 1.0, 7.0}, {f.u1 - 2.0, f.w0 + 8.0, 9.6}, white);
  list.Box(P, {c0 - 0.05, f.w0 + 0.95, 7.6}, {f.u1 - 1.95, f.w0 + 8.05, 9.2}, glass);
  list.Box(P, {c0 - 0.3, f.w0 + 0.7, 9.6}, {f.u1 - 1.7, f.w0 + 8.3, 9.9}, {60, 60, 64});
}

// A board on two posts, its face towards the facility: a colour, a white band, a stripe.
void AppendSign(DrawList& list, const Side& s, double u, double width, int palette) {
  const Pose P = s.Frame();
  static constexpr Rgb8 kMain[4] = {{200, 36, 36}, {28, 78, 160}, {240, 196, 30}, {30, 120, 70}};
  static constexpr Rgb8 kStripe[4] = {
      {250, 250, 250}, {250, 200, 40}, {30, 30, 30}, {250, 250, 250}};
  const Rgb8 main = kMain[palette % 4], stripe = kStripe[palette % 4];
  const double w = kSignOutM, h0 = 1.0, h1 = 3.0;
  for (double x : {u - 0.4 * width, u + 0.4 * width}) {
    list.Box(P, {x - 0.06, w + 0.1, 0}, {x + 0.06, w + 0.22, h1}, {120, 122, 126});
  }
  list.Box(P, {u - 0.5 * width, w, h0}, {u + 0.5 * width, w + 0.1, h1}, main);
  list.Box(P, {u - 0.5 * width, w - 0.02, h0 + 0.15}, {u + 0.5 * width, w, h0 + 0.55}, stripe);
  list.Box(P, {u - 0.45 * width, w - 0.02, h1 - 0.55}, {u + 0.1 * width, w, h1 - 0.35}, stripe);
}

// The hills: a ring around the facility's centre from r0 to r1, low at its inner edge, its
// ridge-line varying with the azimuth. In sectors (chunks of their own, for culling).
void AppendHills(Dressing& d, const Vec3& centre, double r0, double r1, double z,
                 std::vector<std::pair<std::uint32_t, std::uint32_t>>& spans) {
  constexpr int segments = 120, rings = 6, per_sector = 10;
  auto height = [&](double az, double t) {
    const double ridge = 60 + 35 * std::sin(3 * az + 0.7) + 20 * std::sin(7 * az + 2.1) +
                         10 * std::sin(13 * az + 0.4) + 6 * std::sin(29 * az + 1.3);
    const double rough = 0.8 + 0.4 * Noise(az * 12.0, t * 3.0, 71);
    return std::max(ridge, 12.0) * rough * SmoothStep(0.0, 0.7, t);
  };
  auto point = [&](int i, int k) {
    const double az = 2 * kPi * i / segments, t = static_cast<double>(k) / rings;
    const double r = r0 + (r1 - r0) * t;
    return Vec3{centre.x + r * std::cos(az), centre.y + r * std::sin(az), z - 0.5 + height(az, t)};
  };
  for (int s0 = 0; s0 < segments; s0 += per_sector) {
    const auto first = static_cast<std::uint32_t>(d.list.vertices().size());
    for (int i = s0; i < std::min(s0 + per_sector, segments); ++i) {
      for (int k = 0; k < rings; ++k) {
        const Vec3 a = point(i, k), b = point(i + 1, k), c = point(i + 1, k + 1),
                   e = point(i, k + 1);
        // Greener low, browner and paler on the ridges.
        const double up = std::clamp((0.5 * (a.z + c.z) - z) / 90.0, 0.0, 1.0);
        const Rgb8 col = {static_cast<std::uint8_t>(58 + 40 * up),
                          static_cast<std::uint8_t>(84 + 14 * up),
                          static_cast<std::uint8_t>(46 + 24 * up)};
        const Vec3 n1 = Normalized(Cross(b - a, c - a), {0, 0, 1});
        const Vec3 n2 = Normalized(Cross(c - a, e - a), {0, 0, 1});
        d.list.Triangle(a, b, c, n1.z < 0 ? -n1 : n1, col);
        d.list.Triangle(a, c, e, n2.z < 0 ? -n2 : n2, col);
      }
    }
    spans.emplace_back(first, static_cast<std::uint32_t>(d.list.vertices().size()) - first);
  }
}

}  // namespace

bool BarrierEncloses(const TerrainData& t, Vec3* min_W, Vec3* max_W) {
  Vec3 lo{kBig, kBig, kBig}, hi{-kBig, -kBig, -kBig};
  bool any = false;
  for (const TerrainMesh& m : t.meshes) {
    if (m.style != SurfaceStyle::kGlass) continue;
    any = true;
    lo = {std::min(lo.x, m.min_W.x), std::min(lo.y, m.min_W.y), std::min(lo.z, m.min_W.z)};
    hi = {std::max(hi.x, m.max_W.x), std::max(hi.y, m.max_W.y), std::max(hi.z, m.max_W.z)};
  }
  if (!any || hi.x - lo.x < 1.0 || hi.y - lo.y < 1.0) return false;
  *min_W = lo;
  *max_W = hi;
  // Each side: the union of the intervals it is covered over by triangles lying within 1 m of it.
  for (int side = 0; side < 4; ++side) {
    const bool along_x = side < 2;  // south, north run along x
    const double line = side == 0 ? lo.y : side == 1 ? hi.y : side == 2 ? lo.x : hi.x;
    const double a0 = along_x ? lo.x : lo.y, a1 = along_x ? hi.x : hi.y;
    std::vector<std::pair<double, double>> spans;
    for (const TerrainMesh& m : t.meshes) {
      if (m.style != SurfaceStyle::kGlass) continue;
      for (const TerrainChunk& c : m.chunks) {
        const TerrainChunk::Range& r = c.lods[0];
        for (std::uint32_t k = r.first; k + 2 < r.first + r.count; k += 3) {
          double s0 = kBig, s1 = -kBig;
          bool near = true;
          for (std::uint32_t q = 0; q < 3; ++q) {
            const TerrainVertex& v = m.vertices[m.indices[k + q]];
            const double across = along_x ? v.p[1] : v.p[0], along = along_x ? v.p[0] : v.p[1];
            near = near && std::abs(across - line) <= 1.0;
            s0 = std::min(s0, along);
            s1 = std::max(s1, along);
          }
          if (near) spans.emplace_back(s0, s1);
        }
      }
    }
    std::sort(spans.begin(), spans.end());
    double covered = 0, reach = a0;
    for (const auto& [s0, s1] : spans) {
      const double from = std::max(s0, reach), to = std::min(s1, a1);
      if (to > from) covered += to - from;
      reach = std::max(reach, s1);
    }
    if (covered < 0.98 * (a1 - a0)) return false;
  }
  for (const TerrainMesh& m : t.meshes) {
    if (m.style == SurfaceStyle::kGlass || m.style == SurfaceStyle::kGrass) continue;
    if (m.min_W.x < lo.x || m.min_W.y < lo.y || m.max_W.x > hi.x || m.max_W.y > hi.y) return false;
  }
  return true;
}

Dressing MakeDressing(const TerrainData& t, bool full) {
  Dressing d;
  Vec3 lo, hi;
  if (!BarrierEncloses(t, &lo, &hi)) return d;
  if (hi.x - lo.x > kMaxDressedSideM || hi.y - lo.y > kMaxDressedSideM) return d;
  d.enclosed = true;
  d.reach_min_W = lo;
  d.reach_max_W = hi;
  const double z = lo.z;
  const std::array<Side, 4> sides = SidesOf(lo, hi, z);
  const Vec3 centre{0.5 * (lo.x + hi.x), 0.5 * (lo.y + hi.y), z};

  // The buildings face the longest road, on the side nearest its middle.
  const TerrainMesh* road = nullptr;
  for (const TerrainMesh& m : t.meshes) {
    if (m.style == SurfaceStyle::kAsphalt &&
        (road == nullptr || m.frame.half_length_m > road->frame.half_length_m)) {
      road = &m;
    }
  }
  std::size_t stand_side = 0;
  double stand_u = 0;
  if (road != nullptr) {
    const Vec3 c = road->frame.centre_W;
    const double gaps[4] = {c.y - lo.y, hi.y - c.y, c.x - lo.x, hi.x - c.x};
    stand_side = static_cast<std::size_t>(std::min_element(gaps, gaps + 4) - gaps);
    stand_u = Dot(c - sides[stand_side].mid_W, sides[stand_side].along_W);
  }
  const Side& ss = sides[stand_side];
  const double w0 = kDressingClearanceM + 3.0;
  auto clamp_u = [&](double u0, double u1) {
    const double shift =
        std::max(-ss.half_length + 5 - u0, 0.0) + std::min(ss.half_length - 5 - u1, 0.0);
    return std::pair{u0 + shift, u1 + shift};
  };
  const auto [g0, g1] = clamp_u(stand_u - 75, stand_u - 15);
  const auto [p0, p1] = clamp_u(stand_u + 10, stand_u + 60);
  const Footprint stand{g0, g1, w0, w0 + 14.0}, pits{p0, p1, w0, w0 + 12.0};

  std::vector<std::pair<std::uint32_t, std::uint32_t>> spans;  // (first, count) of each chunk
  auto chunk = [&](auto&& append) {
    const auto first = static_cast<std::uint32_t>(d.list.vertices().size());
    append();
    spans.emplace_back(first, static_cast<std::uint32_t>(d.list.vertices().size()) - first);
  };
  chunk([&] { AppendGrandstand(d.list, ss, stand); });
  chunk([&] { AppendPitBuilding(d.list, ss, pits); });

  // Signs every 48 m along each side, clear of the buildings; trees in clumps beyond them, in
  // cells of kChunkCellM.
  struct SignAt {
    std::size_t side;
    int palette;
    double u;
  };
  std::map<std::pair<std::int64_t, std::int64_t>, std::vector<SignAt>> signs;
  std::map<std::pair<std::int64_t, std::int64_t>, std::vector<Tree>> trees;
  auto cell_of = [](const Vec3& p) {
    return std::pair{static_cast<std::int64_t>(std::floor(p.x / kChunkCellM)),
                     static_cast<std::int64_t>(std::floor(p.y / kChunkCellM))};
  };
  const double band = full ? 70.0 : 40.0;
  for (std::size_t si = 0; si < 4; ++si) {
    const Side& s = sides[si];
    const bool buildings = si == stand_side;
    int n = 0;
    for (double u = -s.half_length + 20; u <= s.half_length - 20; u += 48.0, ++n) {
      if (buildings && (stand.Near(u, kSignOutM, 5) || pits.Near(u, kSignOutM, 5))) continue;
      signs[cell_of(s.At(u, kSignOutM, 0))].push_back({si, static_cast<int>(si) + n, u});
    }
    // The south and north sides' bands reach past the corners; the west and east ones stop there.
    const double reach_u = si < 2 ? s.half_length + band : s.half_length;
    const auto cells_u = static_cast<std::int64_t>(std::ceil(reach_u / kTreeCellM));
    const auto cells_w = static_cast<std::int64_t>(std::ceil((band - kTreeBandFromM) / kTreeCellM));
    for (std::int64_t i = -cells_u; i < cells_u; ++i) {
      for (std::int64_t j = 0; j < cells_w; ++j) {
        const auto seed = static_cast<std::uint64_t>(si) * 1000 + 17;
        const double u = (static_cast<double>(i) + LatticeHash(i, j, seed)) * kTreeCellM;
        const double w =
            kTreeBandFromM + (static_cast<double>(j) + LatticeHash(i, j, seed + 1)) * kTreeCellM;
        if (std::abs(u) > reach_u || w > band) continue;
        const Vec3 p = s.At(u, w, z - 0.1);
        // Clumps: woods where a coarse noise is high, a scattered tree elsewhere.
        const double clump = SmoothStep(0.4, 0.7, Noise(p.x / 80.0, p.y / 80.0, 5));
        const double keep = 0.06 + 0.6 * clump;
        if (LatticeHash(i, j, seed + 2) >= keep) continue;
        if (!full && LatticeHash(i, j, seed + 3) >= 0.3) continue;
        const double height = 6.0 + 9.0 * LatticeHash(i, j, seed + 4) * (0.6 + 0.4 * clump);
        if (buildings &&
            (stand.Near(u, w, 0.35 * height + 3) || pits.Near(u, w, 0.35 * height + 3))) {
          continue;
        }
        trees[cell_of(p)].push_back({p, height, LatticeHash(i, j, seed + 5)});
      }
    }
  }
  // (By entry: a lambda may not capture a structured binding, clang 14.)
  for (const auto& entry : signs) {
    const std::vector<SignAt>& list = entry.second;
    chunk([&] {
      for (const SignAt& a : list) AppendSign(d.list, sides[a.side], a.u, 6.0, a.palette);
    });
  }
  for (const auto& entry : trees) {
    const std::vector<Tree>& list = entry.second;
    chunk([&] {
      for (const Tree& tr : list) AppendTree(d.list, tr, full);
    });
    d.trees += list.size();
  }
  const double r0 = Norm(Vec3{hi.x - lo.x, hi.y - lo.y, 0}) * 0.5 + 180.0;
  // (Low: none; the sky's band of far hills stands for them.)
  if (full) AppendHills(d, centre, r0, r0 + 600.0, z, spans);

  for (const auto& [first, count] : spans) {
    if (count == 0) continue;
    DressingChunk c{first, count, {kBig, kBig, kBig}, {-kBig, -kBig, -kBig}};
    for (std::uint32_t k = first; k < first + count; ++k) {
      const Vertex& v = d.list.vertices()[k];
      c.min_W = {std::min<double>(c.min_W.x, v.p[0]), std::min<double>(c.min_W.y, v.p[1]),
                 std::min<double>(c.min_W.z, v.p[2])};
      c.max_W = {std::max<double>(c.max_W.x, v.p[0]), std::max<double>(c.max_W.y, v.p[1]),
                 std::max<double>(c.max_W.z, v.p[2])};
    }
    d.chunks.push_back(c);
  }
  return d;
}

}  // namespace vdyn::viewer
