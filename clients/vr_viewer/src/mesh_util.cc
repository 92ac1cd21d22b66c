#include "vdyn/viewer/mesh_util.h"

#include <cmath>
#include <cstddef>
#include <unordered_map>

namespace vdyn::viewer {
namespace {

// A position (and group) quantised to 0.1 mm, for welding.
struct WeldKey {
  std::int64_t x, y, z;
  std::uint32_t group;
  bool operator==(const WeldKey& o) const {
    return x == o.x && y == o.y && z == o.z && group == o.group;
  }
};
struct WeldHash {
  std::size_t operator()(const WeldKey& k) const {
    std::uint64_t h = static_cast<std::uint64_t>(k.x) * 0x9E3779B97F4A7C15ull;
    h ^= static_cast<std::uint64_t>(k.y) * 0xC2B2AE3D27D4EB4Full + (h << 6) + (h >> 2);
    h ^= static_cast<std::uint64_t>(k.z) * 0x165667B19E3779F9ull + (h << 6) + (h >> 2);
    h ^= k.group;
    return static_cast<std::size_t>(h);
  }
};
std::int64_t Quantise(double v) {
  return static_cast<std::int64_t>(std::llround(v * 1e4));
}

// A welded vertex with a normal, quantised, for sharing output vertices.
struct OutKey {
  std::uint32_t vertex;
  std::int32_t nx, ny, nz;
  bool operator==(const OutKey& o) const {
    return vertex == o.vertex && nx == o.nx && ny == o.ny && nz == o.nz;
  }
};
struct OutHash {
  std::size_t operator()(const OutKey& k) const {
    std::uint64_t h = k.vertex * 0x9E3779B97F4A7C15ull;
    h ^= static_cast<std::uint64_t>(static_cast<std::uint32_t>(k.nx)) * 0xC2B2AE3D27D4EB4Full;
    h ^= static_cast<std::uint64_t>(static_cast<std::uint32_t>(k.ny)) << 21;
    h ^= static_cast<std::uint64_t>(static_cast<std::uint32_t>(k.nz)) << 42;
    return static_cast<std::size_t>(h);
  }
};

}  // namespace

SmoothedMesh SmoothNormals(const std::vector<Vec3>& positions,
                           const std::vector<std::uint32_t>& indices,
                           const std::vector<std::uint32_t>& triangle_group, double crease_deg) {
  const std::size_t triangles = indices.size() / 3;
  auto group_of = [&](std::size_t t) { return t < triangle_group.size() ? triangle_group[t] : 0u; };
  // 1. Weld: one id per distinct (position, group) of the corners in use.
  std::unordered_map<WeldKey, std::uint32_t, WeldHash> weld;
  weld.reserve(positions.size());
  std::vector<std::uint32_t> corner(indices.size());
  std::vector<Vec3> welded;
  std::vector<std::uint32_t> welded_group;
  for (std::size_t t = 0; t < triangles; ++t) {
    for (int k = 0; k < 3; ++k) {
      const Vec3& p = positions[indices[3 * t + static_cast<std::size_t>(k)]];
      const WeldKey key{Quantise(p.x), Quantise(p.y), Quantise(p.z), group_of(t)};
      const auto [it, added] = weld.try_emplace(key, static_cast<std::uint32_t>(welded.size()));
      if (added) {
        welded.push_back(p);
        welded_group.push_back(group_of(t));
      }
      corner[3 * t + static_cast<std::size_t>(k)] = it->second;
    }
  }
  // 2. Face normals (length: twice the area) and the faces at each welded vertex.
  std::vector<Vec3> face(triangles);
  std::vector<bool> keep(triangles);
  for (std::size_t t = 0; t < triangles; ++t) {
    const Vec3 &a = welded[corner[3 * t]], &b = welded[corner[3 * t + 1]],
               &c = welded[corner[3 * t + 2]];
    face[t] = Cross(b - a, c - a);
    keep[t] = Norm(face[t]) > 1e-12 && corner[3 * t] != corner[3 * t + 1] &&
              corner[3 * t + 1] != corner[3 * t + 2] && corner[3 * t] != corner[3 * t + 2];
  }
  std::vector<std::uint32_t> start(welded.size() + 1, 0);
  for (std::size_t t = 0; t < triangles; ++t) {
    if (!keep[t]) continue;
    for (int k = 0; k < 3; ++k) ++start[corner[3 * t + static_cast<std::size_t>(k)] + 1];
  }
  for (std::size_t v = 0; v < welded.size(); ++v) start[v + 1] += start[v];
  std::vector<std::uint32_t> faces_at(start.back());
  std::vector<std::uint32_t> fill(start.begin(), start.end() - 1);
  for (std::size_t t = 0; t < triangles; ++t) {
    if (!keep[t]) continue;
    for (int k = 0; k < 3; ++k) {
      faces_at[fill[corner[3 * t + static_cast<std::size_t>(k)]]++] = static_cast<std::uint32_t>(t);
    }
  }
  // 3. Each corner's normal: the area-weighted sum over the faces at its vertex that lie within
  // the crease angle of its own face; corners with the same vertex and normal share one output.
  const double cos_crease = std::cos(Rad(crease_deg));
  SmoothedMesh out;
  out.positions.reserve(welded.size());
  out.normals.reserve(welded.size());
  out.indices.reserve(indices.size());
  std::unordered_map<OutKey, std::uint32_t, OutHash> shared;
  shared.reserve(welded.size() * 2);
  for (std::size_t t = 0; t < triangles; ++t) {
    if (!keep[t]) continue;
    const Vec3 own = Normalized(face[t], {0, 0, 1});
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t v = corner[3 * t + static_cast<std::size_t>(k)];
      Vec3 sum;
      for (std::uint32_t i = start[v]; i < start[v + 1]; ++i) {
        const Vec3& other = face[faces_at[i]];
        if (Dot(Normalized(other, own), own) >= cos_crease) sum += other;
      }
      const Vec3 n = Normalized(sum, own);
      const OutKey key{v, static_cast<std::int32_t>(std::lround(n.x * 32767)),
                       static_cast<std::int32_t>(std::lround(n.y * 32767)),
                       static_cast<std::int32_t>(std::lround(n.z * 32767))};
      const auto [it, added] =
          shared.try_emplace(key, static_cast<std::uint32_t>(out.positions.size()));
      if (added) {
        out.positions.push_back(welded[v]);
        out.normals.push_back(n);
        out.group.push_back(welded_group[v]);
      }
      out.indices.push_back(it->second);
    }
    out.source_triangle.push_back(static_cast<std::uint32_t>(t));
  }
  return out;
}

}  // namespace vdyn::viewer
