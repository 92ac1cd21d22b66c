#include "vdyn/viewer/world_mesh.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>

#include "vdyn/base/limits.h"
#include "vdyn/viewer/mesh_util.h"
#include "vdyn/viewer/textures.h"

namespace vdyn::viewer {

std::string CheckWorld(const pb::WorldDescription& world) {
  std::size_t triangles = 0;
  for (int m = 0; m < world.meshes_size(); ++m) {
    const pb::Mesh& mesh = world.meshes(m);
    const std::string where = "mesh '" + mesh.name() + "' (" + std::to_string(m) + ")";
    if (mesh.vertices_size() % 3 != 0) {
      return where + ": " + std::to_string(mesh.vertices_size()) +
             " vertex coordinates, not a multiple of 3";
    }
    if (mesh.indices_size() % 3 != 0) {
      return where + ": " + std::to_string(mesh.indices_size()) +
             " indices, not a multiple of 3 (three per triangle)";
    }
    const auto vertices = static_cast<std::uint64_t>(mesh.vertices_size() / 3);
    // The server leaves out every triangle with a vertex beyond the terrain's bound (issue 33: a
    // vertex at 1e30 overflowed the viewer's grid cells): a description holding one is foreign.
    for (int i = 0; i < mesh.vertices_size(); ++i) {
      if (std::string why = limits::Check(limits::kWorldCoordinateM, mesh.vertices(i));
          !why.empty()) {
        return where + ": vertex " + std::to_string(i / 3) + ": " + why;
      }
    }
    for (int i = 0; i < mesh.indices_size(); ++i) {
      if (mesh.indices(i) >= vertices) {
        return where + ": index " + std::to_string(mesh.indices(i)) + " of triangle " +
               std::to_string(i / 3) + " points past the last of " + std::to_string(vertices) +
               " vertices";
      }
    }
    triangles += static_cast<std::size_t>(mesh.indices_size() / 3);
  }
  if (triangles == 0) return "world '" + world.name() + "' holds no triangle";
  for (const pb::VehicleGeometry& g : world.vehicles()) {
    std::string why = CheckGeometry(g);
    if (!why.empty()) return why;
  }
  return {};
}

StripFrame FrameOf(const std::vector<Vec3>& points_W) {
  StripFrame f;
  if (points_W.empty()) return f;
  // The long axis: the principal axis of the points' spread in XY.
  double mx = 0, my = 0;
  for (const Vec3& p : points_W) {
    mx += p.x;
    my += p.y;
  }
  const auto n = static_cast<double>(points_W.size());
  mx /= n;
  my /= n;
  double sxx = 0, syy = 0, sxy = 0;
  for (const Vec3& p : points_W) {
    sxx += (p.x - mx) * (p.x - mx);
    syy += (p.y - my) * (p.y - my);
    sxy += (p.x - mx) * (p.y - my);
  }
  const double angle = 0.5 * std::atan2(2 * sxy, sxx - syy);
  f.along_W = {std::cos(angle), std::sin(angle), 0};
  const Vec3 across{-f.along_W.y, f.along_W.x, 0};
  constexpr double kBig = std::numeric_limits<double>::max();
  double a0 = kBig, a1 = -kBig, c0 = kBig, c1 = -kBig;
  for (const Vec3& p : points_W) {
    const Vec3 d{p.x - mx, p.y - my, 0};
    a0 = std::min(a0, Dot(d, f.along_W));
    a1 = std::max(a1, Dot(d, f.along_W));
    c0 = std::min(c0, Dot(d, across));
    c1 = std::max(c1, Dot(d, across));
  }
  f.centre_W = Vec3{mx, my, 0} + f.along_W * (0.5 * (a0 + a1)) + across * (0.5 * (c0 + c1));
  f.half_length_m = 0.5 * (a1 - a0);
  f.half_width_m = 0.5 * (c1 - c0);
  f.strip = f.half_length_m >= 3 * f.half_width_m && f.half_width_m <= 20.0 && f.half_width_m > 0.5;
  return f;
}

SurfaceStyle StyleOf(pb::SurfaceKind kind, const StripFrame& frame) {
  switch (kind) {
    case pb::SURFACE_ROAD:
      return SurfaceStyle::kAsphalt;
    case pb::SURFACE_OBSTACLE:
      // A bump across a lane is short; a long stretch (the washboard) is a concrete surface.
      return std::min(frame.half_length_m, frame.half_width_m) <= 1.25 ? SurfaceStyle::kHazard
                                                                       : SurfaceStyle::kConcrete;
    case pb::SURFACE_ROUGH:
      return SurfaceStyle::kDirt;
    case pb::SURFACE_RAMP:
      return SurfaceStyle::kConcrete;
    case pb::SURFACE_BARRIER:
      return SurfaceStyle::kGlass;
    case pb::SURFACE_PROP:
      return SurfaceStyle::kPainted;
    case pb::SURFACE_GROUND:
    default:
      return SurfaceStyle::kGrass;
  }
}

namespace {

constexpr double kChunkM = 32.0;
constexpr std::size_t kLodMinTriangles = 4000;       // smaller meshes have one level
constexpr double kMaxEdgeM = 16.0;                   // longer edges are split (for the chunks)
constexpr std::size_t kMaxSplitTriangles = 1 << 18;  // ... while a mesh stays under this

double LongestEdge(const std::vector<Vec3>& p, std::uint32_t a, std::uint32_t b, std::uint32_t c) {
  return std::max({Norm(p[a] - p[b]), Norm(p[b] - p[c]), Norm(p[c] - p[a])});
}

// Splits every triangle with an edge longer than kMaxEdgeM in four (the same surface: the
// ground's 50 m tiles become chunks small enough to leave out of view and out of the shadow),
// round by round while the mesh stays under kMaxSplitTriangles (a 40 km plane in 1 km tiles
// stops at 125 m tiles instead of growing to 50 million triangles).
void SplitLongEdges(std::vector<Vec3>& points, std::vector<std::uint32_t>& indices) {
  for (int round = 0; round < 12; ++round) {
    std::size_t to_split = 0;
    for (std::size_t t = 0; t + 2 < indices.size(); t += 3) {
      if (LongestEdge(points, indices[t], indices[t + 1], indices[t + 2]) > kMaxEdgeM) ++to_split;
    }
    if (to_split == 0 || indices.size() / 3 + 3 * to_split > kMaxSplitTriangles) return;
    std::vector<std::uint32_t> out;
    out.reserve(indices.size() + 9 * to_split);
    bool split = false;
    for (std::size_t t = 0; t + 2 < indices.size(); t += 3) {
      const std::uint32_t a = indices[t], b = indices[t + 1], c = indices[t + 2];
      if (LongestEdge(points, a, b, c) <= kMaxEdgeM) {
        out.insert(out.end(), {a, b, c});
        continue;
      }
      split = true;
      const auto ab = static_cast<std::uint32_t>(points.size());
      points.push_back(0.5 * (points[a] + points[b]));
      points.push_back(0.5 * (points[b] + points[c]));
      points.push_back(0.5 * (points[c] + points[a]));
      const std::uint32_t bc = ab + 1, ca = ab + 2;
      out.insert(out.end(), {a, ab, ca, ab, b, bc, ca, bc, c, ab, bc, ca});
    }
    indices = std::move(out);
    if (!split) return;
  }
}

// Splits a mesh's triangles into chunks of kChunkM by their centroid (one chunk for a small
// mesh) and orders its indices by chunk; a large mesh gets its coarser levels after them.
void Chunk(TerrainMesh& m) {
  const std::size_t triangles = m.indices.size() / 3;
  const bool large = triangles >= kLodMinTriangles;
  const bool wide = std::max(m.max_W.x - m.min_W.x, m.max_W.y - m.min_W.y) > 2 * kChunkM;
  auto pos = [&](std::uint32_t i) {
    const TerrainVertex& v = m.vertices[i];
    return Vec3{v.p[0], v.p[1], v.p[2]};
  };
  std::map<std::pair<std::int64_t, std::int64_t>, std::vector<std::uint32_t>> cells;
  for (std::size_t t = 0; t < triangles; ++t) {
    std::pair<std::int64_t, std::int64_t> cell{0, 0};
    if (large || wide) {
      const Vec3 c =
          (pos(m.indices[3 * t]) + pos(m.indices[3 * t + 1]) + pos(m.indices[3 * t + 2])) / 3.0;
      cell = {static_cast<std::int64_t>(std::floor(c.x / kChunkM)),
              static_cast<std::int64_t>(std::floor(c.y / kChunkM))};
    }
    cells[cell].push_back(static_cast<std::uint32_t>(t));
  }
  // The coarser levels' vertices: per cell of the level (over the whole mesh, so neighbouring
  // chunks share them), the mean of the vertices in it.
  std::array<std::vector<std::uint32_t>, kTerrainLods> merged;
  if (large) {
    const std::size_t n = m.vertices.size();
    for (int lod = 1; lod < kTerrainLods; ++lod) {
      const double cell = kLodCellM[lod];
      std::map<std::array<std::int64_t, 3>, std::uint32_t> rep_of_cell;
      std::vector<Vec3> sum_p, sum_n;
      std::vector<double> count;
      auto& map = merged[static_cast<std::size_t>(lod)];
      map.resize(n);
      for (std::size_t i = 0; i < n; ++i) {
        const Vec3 p = pos(static_cast<std::uint32_t>(i));
        const std::array<std::int64_t, 3> key = {static_cast<std::int64_t>(std::floor(p.x / cell)),
                                                 static_cast<std::int64_t>(std::floor(p.y / cell)),
                                                 static_cast<std::int64_t>(std::floor(p.z / cell))};
        const auto [it, added] =
            rep_of_cell.try_emplace(key, static_cast<std::uint32_t>(sum_p.size()));
        if (added) {
          sum_p.emplace_back();
          sum_n.emplace_back();
          count.push_back(0);
        }
        const TerrainVertex& v = m.vertices[i];
        sum_p[it->second] += p;
        sum_n[it->second] += Vec3{v.n[0], v.n[1], v.n[2]};
        count[it->second] += 1;
        map[i] = it->second;
      }
      const auto base = static_cast<std::uint32_t>(m.vertices.size());
      for (std::size_t c = 0; c < sum_p.size(); ++c) {
        const Vec3 p = sum_p[c] / count[c], nn = Normalized(sum_n[c], {0, 0, 1});
        m.vertices.push_back(
            {{static_cast<float>(p.x), static_cast<float>(p.y), static_cast<float>(p.z)},
             {static_cast<float>(nn.x), static_cast<float>(nn.y), static_cast<float>(nn.z)}});
      }
      for (std::uint32_t& r : map) r += base;
    }
  }
  std::vector<std::uint32_t> ordered;
  ordered.reserve(m.indices.size() * (large ? 2 : 1));
  constexpr double kBig = std::numeric_limits<double>::max();
  for (const auto& [cell, tris] : cells) {
    TerrainChunk c;
    c.min_W = {kBig, kBig, kBig};
    c.max_W = {-kBig, -kBig, -kBig};
    for (int lod = 0; lod < (large ? kTerrainLods : 1); ++lod) {
      TerrainChunk::Range& r = c.lods[static_cast<std::size_t>(lod)];
      r.first = static_cast<std::uint32_t>(ordered.size());
      for (std::uint32_t t : tris) {
        std::uint32_t v[3];
        for (int k = 0; k < 3; ++k) {
          const std::uint32_t i = m.indices[3 * t + static_cast<std::size_t>(k)];
          v[k] = lod == 0 ? i : merged[static_cast<std::size_t>(lod)][i];
          if (lod == 0) {
            const Vec3 p = pos(i);
            c.min_W = {std::min(c.min_W.x, p.x), std::min(c.min_W.y, p.y),
                       std::min(c.min_W.z, p.z)};
            c.max_W = {std::max(c.max_W.x, p.x), std::max(c.max_W.y, p.y),
                       std::max(c.max_W.z, p.z)};
          }
        }
        if (v[0] == v[1] || v[1] == v[2] || v[0] == v[2]) continue;  // merged away
        ordered.insert(ordered.end(), {v[0], v[1], v[2]});
      }
      r.count = static_cast<std::uint32_t>(ordered.size()) - r.first;
    }
    if (!large) c.lods[1] = c.lods[2] = c.lods[0];
    m.chunks.push_back(c);
  }
  m.indices = std::move(ordered);
}

}  // namespace

TerrainData TerrainFromWorld(const pb::WorldDescription& world) {
  TerrainData t;
  t.name = world.name();
  constexpr double kBig = std::numeric_limits<double>::max();
  t.min_W = t.ground_min_W = {kBig, kBig, kBig};
  t.max_W = t.ground_max_W = {-kBig, -kBig, -kBig};
  t.meshes.reserve(static_cast<std::size_t>(world.meshes_size()));
  for (const pb::Mesh& mesh : world.meshes()) {
    if (mesh.indices_size() == 0) continue;
    TerrainMesh& m = t.meshes.emplace_back();
    m.name = mesh.name();
    m.kind = mesh.kind();
    std::vector<Vec3> points(static_cast<std::size_t>(mesh.vertices_size() / 3));
    for (std::size_t i = 0; i < points.size(); ++i) {
      const int k = static_cast<int>(3 * i);
      points[i] = {mesh.vertices(k), mesh.vertices(k + 1), mesh.vertices(k + 2)};
    }
    std::vector<std::uint32_t> indices(mesh.indices().begin(), mesh.indices().end());
    // Only the vertices triangles use count for the frame and the bounds.
    std::vector<Vec3> used;
    {
      std::vector<bool> seen(points.size(), false);
      for (std::uint32_t i : indices) {
        if (!seen[i]) {
          seen[i] = true;
          used.push_back(points[i]);
        }
      }
    }
    m.frame = FrameOf(used);
    m.style = StyleOf(m.kind, m.frame);
    SplitLongEdges(points, indices);
    const SmoothedMesh s = SmoothNormals(points, indices, {}, 40.0);
    m.min_W = {kBig, kBig, kBig};
    m.max_W = {-kBig, -kBig, -kBig};
    m.vertices.reserve(s.positions.size());
    for (std::size_t i = 0; i < s.positions.size(); ++i) {
      const Vec3& p = s.positions[i];
      const Vec3& n = s.normals[i];
      TerrainVertex v{};
      v.p[0] = static_cast<float>(p.x);
      v.p[1] = static_cast<float>(p.y);
      v.p[2] = static_cast<float>(p.z);
      v.n[0] = static_cast<float>(n.x);
      v.n[1] = static_cast<float>(n.y);
      v.n[2] = static_cast<float>(n.z);
      m.vertices.push_back(v);
      m.min_W = {std::min(m.min_W.x, p.x), std::min(m.min_W.y, p.y), std::min(m.min_W.z, p.z)};
      m.max_W = {std::max(m.max_W.x, p.x), std::max(m.max_W.y, p.y), std::max(m.max_W.z, p.z)};
    }
    m.indices = s.indices;
    Chunk(m);
    t.triangles += m.indices.size() / 3;
    t.min_W = {std::min(t.min_W.x, m.min_W.x), std::min(t.min_W.y, m.min_W.y),
               std::min(t.min_W.z, m.min_W.z)};
    t.max_W = {std::max(t.max_W.x, m.max_W.x), std::max(t.max_W.y, m.max_W.y),
               std::max(t.max_W.z, m.max_W.z)};
    if (m.style == SurfaceStyle::kGrass) {
      t.has_ground = true;
      t.ground_min_W = {std::min(t.ground_min_W.x, m.min_W.x),
                        std::min(t.ground_min_W.y, m.min_W.y),
                        std::min(t.ground_min_W.z, m.min_W.z)};
      t.ground_max_W = {std::max(t.ground_max_W.x, m.max_W.x),
                        std::max(t.ground_max_W.y, m.max_W.y),
                        std::max(t.ground_max_W.z, m.max_W.z)};
    }
  }
  if (t.meshes.empty()) t.min_W = t.max_W = Vec3{};
  if (!t.has_ground) t.ground_min_W = t.ground_max_W = Vec3{};
  const Vec3 middle = 0.5 * (t.min_W + t.max_W);
  for (TerrainMesh& m : t.meshes) {
    if (m.style == SurfaceStyle::kPainted) m.poster = PosterFaceOf(m.vertices, m.indices, middle);
  }
  return t;
}

PosterFace PosterFaceOf(const std::vector<TerrainVertex>& vertices,
                        const std::vector<std::uint32_t>& indices, const Vec3& towards_W,
                        double min_area_m2) {
  // The vertical triangles grouped by their plane (the normal's heading in whole degrees, the
  // plane's offset in centimetres): each group's area and members.
  struct Group {
    double area = 0;
    Vec3 n;
    std::vector<std::uint32_t> corners;
  };
  std::map<std::pair<std::int64_t, std::int64_t>, Group> groups;
  auto pos = [&](std::uint32_t i) {
    const TerrainVertex& v = vertices[i];
    return Vec3{v.p[0], v.p[1], v.p[2]};
  };
  for (std::size_t k = 0; k + 2 < indices.size(); k += 3) {
    const Vec3 a = pos(indices[k]), b = pos(indices[k + 1]), c = pos(indices[k + 2]);
    const Vec3 cr = Cross(b - a, c - a);
    const double area = 0.5 * Norm(cr);
    if (area < 1e-9) continue;
    const Vec3 n = cr / (2 * area);
    if (std::abs(n.z) > 0.05) continue;  // not vertical
    // Only faces whose outside (by their winding, as the shader tells front from back) looks
    // towards the middle of the world: the panel's back is plain.
    if (Dot(n, towards_W - a) <= 0) continue;
    const double heading = std::atan2(n.y, n.x);
    const std::pair<std::int64_t, std::int64_t> key{std::llround(Deg(heading)),
                                                    std::llround(Dot(n, a) * 100)};
    Group& g = groups[key];
    g.area += area;
    g.n = n;
    g.corners.insert(g.corners.end(), {indices[k], indices[k + 1], indices[k + 2]});
  }
  const Group* best = nullptr;
  for (const auto& [key, g] : groups) {
    if (best == nullptr || g.area > best->area) best = &g;
  }
  PosterFace f;
  if (best == nullptr || best->area < min_area_m2) return f;
  // Seen from the front (looking along -n, up is z), right is -n x z.
  f.right_W = Normalized(Vec3{-best->n.y, best->n.x, 0});
  constexpr double kBig = std::numeric_limits<double>::max();
  double u0 = kBig, u1 = -kBig, z0 = kBig, z1 = -kBig;
  Vec3 any;
  for (std::uint32_t i : best->corners) {
    const Vec3 p = pos(i);
    any = p;
    u0 = std::min(u0, Dot(p, f.right_W));
    u1 = std::max(u1, Dot(p, f.right_W));
    z0 = std::min(z0, p.z);
    z1 = std::max(z1, p.z);
  }
  // The lower left corner: on the plane, at u0 along right, z0 up.
  const double offset = Dot(best->n, any);
  f.origin_W = best->n * offset + f.right_W * u0;
  f.origin_W.z = z0;
  f.width_m = u1 - u0;
  f.height_m = z1 - z0;
  f.present = true;
  return f;
}

SurfaceLook LookOf(pb::SurfaceKind kind) {
  switch (kind) {
    case pb::SURFACE_ROAD:
      return {MeanColour(TextureLayer::kAsphalt), 1.0f};
    case pb::SURFACE_OBSTACLE:
      return {{130, 105, 25}, 1.0f};  // yellow and black paint, from afar
    case pb::SURFACE_ROUGH:
      return {MeanColour(TextureLayer::kDirt), 1.0f};
    case pb::SURFACE_RAMP:
      return {MeanColour(TextureLayer::kConcrete), 1.0f};
    case pb::SURFACE_BARRIER:
      return {{150, 200, 215}, 0.3f};
    case pb::SURFACE_PROP:
      return {{196, 198, 200}, 1.0f};
    case pb::SURFACE_GROUND:
    default:
      return {MeanColour(TextureLayer::kGrass), 1.0f};
  }
}

}  // namespace vdyn::viewer
