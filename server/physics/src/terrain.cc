#include "vdyn/physics/terrain.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <stdexcept>

#include <Eigen/Geometry>
#include <embree3/rtcore.h>

#include "vdyn/base/limits.h"

namespace vdyn {

struct Terrain::Impl {
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
  // Embree's errors are counted, not logged: the physics has no I/O. The caller that built the
  // terrain reads them (embree_errors()).
  std::atomic<std::uint64_t> errors{0};
  std::atomic<int> last_error{0};
};

namespace {
void EmbreeError(void* user, RTCError code, const char* /*str*/) {
  auto* impl = static_cast<Terrain::Impl*>(user);
  impl->errors.fetch_add(1, std::memory_order_relaxed);
  impl->last_error.store(static_cast<int>(code), std::memory_order_relaxed);
}

// Embree stores single precision: a vertex out of float range, or not finite, is unusable. Each
// coordinate is tested on its own: a NaN compares false, and a reduction such as maxCoeff() may
// skip it (vectorised max returns the other operand), so `v nan 0 0` must not pass as 0.
bool UsableVertex(const Eigen::Vector3d& v) {
  constexpr double kFar = limits::kWorldCoordinateM.hi;
  return std::abs(v.x()) < kFar && std::abs(v.y()) < kFar && std::abs(v.z()) < kFar;
}
}  // namespace

Terrain::Terrain() : impl_(std::make_unique<Impl>()) {
  impl_->device = rtcNewDevice("threads=1");
  if (impl_->device == nullptr) throw std::runtime_error("cannot create the Embree device");
  rtcSetDeviceErrorFunction(impl_->device, EmbreeError, impl_.get());
  impl_->scene = rtcNewScene(impl_->device);
  rtcSetSceneFlags(impl_->scene, RTC_SCENE_FLAG_ROBUST);
  rtcSetSceneBuildQuality(impl_->scene, RTC_BUILD_QUALITY_HIGH);
}

Terrain::~Terrain() {
  if (impl_->scene) rtcReleaseScene(impl_->scene);
  if (impl_->device) rtcReleaseDevice(impl_->device);
}

void Terrain::AddMesh(TriangleMesh mesh) {
  if (committed_) throw std::logic_error("Terrain::AddMesh after Commit");
  const std::size_t nv = mesh.vertices_W.size();
  const auto mesh_index = static_cast<std::uint32_t>(meshes_.size());
  const auto base = static_cast<std::uint32_t>(planes_.size());
  std::vector<std::array<std::uint32_t, 3>> kept_tris;
  std::vector<bool> vertex_used(nv, false);
  for (std::size_t t = 0; t < mesh.triangles.size(); ++t) {
    const auto& tri = mesh.triangles[t];
    for (std::uint32_t i : tri) {
      if (i >= nv) {
        throw std::invalid_argument("mesh '" + mesh.name + "': triangle " + std::to_string(t) +
                                    " refers to vertex " + std::to_string(i) + " of " +
                                    std::to_string(nv));
      }
    }
    const Eigen::Vector3d& a = mesh.vertices_W[tri[0]];
    const Eigen::Vector3d& b = mesh.vertices_W[tri[1]];
    const Eigen::Vector3d& c = mesh.vertices_W[tri[2]];
    const Eigen::Vector3d n = (b - a).cross(c - a);
    const double len = n.norm();
    if (!UsableVertex(a) || !UsableVertex(b) || !UsableVertex(c) || !(len > 1e-12)) {
      ++dropped_triangles_;
      continue;
    }
    const Eigen::Vector3d un = n / len;
    planes_.push_back({un, un.dot(a), mesh_index, static_cast<std::uint32_t>(kept_tris.size())});
    kept_tris.push_back(tri);
    for (std::uint32_t i : tri) vertex_used[i] = true;
  }
  // The mesh kept is the terrain traced: the dropped triangles, and the vertices only they used,
  // leave it, so a world description (convert.cc) holds exactly what the traces can hit (issue 33:
  // a viewer drew `v nan 0 0` as a slab 1e10 m high, and a vertex at 1e30 overflowed its floats).
  if (kept_tris.size() != mesh.triangles.size()) {
    std::vector<std::uint32_t> new_index(nv, 0);
    std::vector<Eigen::Vector3d> kept_vertices;
    for (std::size_t i = 0; i < nv; ++i) {
      if (!vertex_used[i]) continue;
      new_index[i] = static_cast<std::uint32_t>(kept_vertices.size());
      kept_vertices.push_back(mesh.vertices_W[i]);
    }
    for (auto& tri : kept_tris) {
      for (std::uint32_t& i : tri) i = new_index[i];
    }
    mesh.vertices_W = std::move(kept_vertices);
    mesh.triangles = kept_tris;
  }
  const std::size_t n_kept_vertices = mesh.vertices_W.size();
  if (!kept_tris.empty()) {
    RTCGeometry geom = rtcNewGeometry(impl_->device, RTC_GEOMETRY_TYPE_TRIANGLE);
    // Embree reads vertices as 16-byte vectors: one float of padding per vertex (stride 16 bytes).
    auto* vb = static_cast<float*>(rtcSetNewGeometryBuffer(
        geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 4 * sizeof(float), n_kept_vertices));
    auto* ib = static_cast<std::uint32_t*>(rtcSetNewGeometryBuffer(
        geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(std::uint32_t),
        kept_tris.size()));
    if (vb == nullptr || ib == nullptr) {
      rtcReleaseGeometry(geom);
      throw std::runtime_error("Embree could not allocate buffers for mesh '" + mesh.name + "'");
    }
    for (std::size_t i = 0; i < n_kept_vertices; ++i) {
      const Eigen::Vector3d& v = mesh.vertices_W[i];
      const bool ok = UsableVertex(v);
      vb[4 * i + 0] = ok ? static_cast<float>(v.x()) : 0.0f;
      vb[4 * i + 1] = ok ? static_cast<float>(v.y()) : 0.0f;
      vb[4 * i + 2] = ok ? static_cast<float>(v.z()) : 0.0f;
      vb[4 * i + 3] = 0.0f;
      if (ok) {
        bounds_min_ = bounds_min_.cwiseMin(v);
        bounds_max_ = bounds_max_.cwiseMax(v);
      }
    }
    for (std::size_t t = 0; t < kept_tris.size(); ++t) {
      for (int k = 0; k < 3; ++k) ib[3 * t + k] = kept_tris[t][k];
    }
    rtcCommitGeometry(geom);
    const unsigned id = rtcAttachGeometry(impl_->scene, geom);
    rtcReleaseGeometry(geom);
    if (geom_base_.size() <= id) geom_base_.resize(id + 1, 0);
    geom_base_[id] = base;
  }
  triangle_count_ += kept_tris.size();
  meshes_.push_back(std::move(mesh));
}

std::uint64_t Terrain::embree_errors() const {
  return impl_->errors.load(std::memory_order_relaxed);
}
int Terrain::last_embree_error() const { return impl_->last_error.load(std::memory_order_relaxed); }

void Terrain::Commit() {
  if (committed_) return;
  rtcCommitScene(impl_->scene);
  BuildSteepGrid();
  committed_ = true;
}

void Terrain::BuildSteepGrid() {
  if (triangle_count_ == 0) return;
  const Eigen::Vector3d ext = bounds_max_ - bounds_min_;
  // 4 m cells, coarser for huge worlds so the grid stays within ~1M cells.
  grid_cell_ = std::max({4.0, ext.x() / 1024.0, ext.y() / 1024.0});
  grid_x0_ = bounds_min_.x();
  grid_y0_ = bounds_min_.y();
  grid_nx_ = static_cast<int>(std::floor(ext.x() / grid_cell_)) + 1;
  grid_ny_ = static_cast<int>(std::floor(ext.y() / grid_cell_)) + 1;
  steep_cells_.assign(static_cast<std::size_t>(grid_nx_) * static_cast<std::size_t>(grid_ny_), 0);
  for (const Plane& plane : planes_) {
    {
      if (std::abs(plane.n.z()) >= kSteepNormalZ) continue;
      const TriangleMesh& mesh = meshes_[plane.mesh];
      const auto& tri = mesh.triangles[plane.triangle];
      Eigen::Vector3d lo = mesh.vertices_W[tri[0]], hi = lo;
      for (int i = 1; i < 3; ++i) {
        lo = lo.cwiseMin(mesh.vertices_W[tri[i]]);
        hi = hi.cwiseMax(mesh.vertices_W[tri[i]]);
      }
      const int i0 = std::clamp(static_cast<int>((lo.x() - grid_x0_) / grid_cell_), 0, grid_nx_ - 1);
      const int i1 = std::clamp(static_cast<int>((hi.x() - grid_x0_) / grid_cell_), 0, grid_nx_ - 1);
      const int j0 = std::clamp(static_cast<int>((lo.y() - grid_y0_) / grid_cell_), 0, grid_ny_ - 1);
      const int j1 = std::clamp(static_cast<int>((hi.y() - grid_y0_) / grid_cell_), 0, grid_ny_ - 1);
      for (int j = j0; j <= j1; ++j) {
        for (int i = i0; i <= i1; ++i) {
          steep_cells_[static_cast<std::size_t>(j) * grid_nx_ + i] = 1;
        }
      }
    }
  }
}

bool Terrain::SteepSurfaceNear(double x, double y, double radius) const {
  if (steep_cells_.empty()) return false;
  // Out of any world (or not finite): no cell to look at, and no float-to-int overflow.
  if (!(std::abs(x) < 1e9) || !(std::abs(y) < 1e9) || !(radius >= 0.0 && radius < 1e9)) {
    return false;
  }
  const int i0 = std::max(0, static_cast<int>(std::floor((x - radius - grid_x0_) / grid_cell_)));
  const int i1 = std::min(grid_nx_ - 1, static_cast<int>(std::floor((x + radius - grid_x0_) / grid_cell_)));
  const int j0 = std::max(0, static_cast<int>(std::floor((y - radius - grid_y0_) / grid_cell_)));
  const int j1 = std::min(grid_ny_ - 1, static_cast<int>(std::floor((y + radius - grid_y0_) / grid_cell_)));
  for (int j = j0; j <= j1; ++j) {
    for (int i = i0; i <= i1; ++i) {
      if (steep_cells_[static_cast<std::size_t>(j) * grid_nx_ + i] != 0) return true;
    }
  }
  return false;
}

TraceHit Terrain::Refine(const Eigen::Vector3d& origin_W, const Eigen::Vector3d& dir_W,
                         double t_max, unsigned geom_id, unsigned prim_id, float t_float) const {
  TraceHit out;
  if (geom_id == RTC_INVALID_GEOMETRY_ID) return out;
  const Plane& plane = planes_[geom_base_[geom_id] + prim_id];
  const double denom = plane.n.dot(dir_W);
  double t = static_cast<double>(t_float);
  // Refine in double against the triangle's plane unless the ray grazes it.
  if (std::abs(denom) > 1e-6) {
    const double t_plane = (plane.offset - plane.n.dot(origin_W)) / denom;
    // The float hit bounds how far the plane answer may stray (grazing or precision limits).
    if (std::abs(t_plane - t) < 1e-3 + 1e-5 * std::abs(t)) t = t_plane;
  }
  if (t < 0.0) t = 0.0;
  if (t > t_max) return out;
  out.hit = true;
  out.distance = t;
  out.normal_W = denom > 0.0 ? Eigen::Vector3d(-plane.n) : plane.n;
  out.mesh = plane.mesh;
  out.triangle = plane.triangle;
  return out;
}

namespace {
// A ray Embree may see: finite also in single precision (a diverging state can hold 1e300,
// which is finite in double and infinite as a float) and within a range where floats still mean
// something. Embree asserts on anything else.
bool FiniteRay(const Eigen::Vector3d& o, const Eigen::Vector3d& d, double t_max) {
  constexpr double kLimit = 1e9;  // m
  return o.allFinite() && d.allFinite() && o.cwiseAbs().maxCoeff() < kLimit &&
         d.cwiseAbs().maxCoeff() <= 1.0 + 1e-6 && d.squaredNorm() > 0.5 && t_max >= 0.0 &&
         t_max < kLimit;
}
// A little beyond t_max in float; the exact bound is applied in double by Refine.
float FloatFar(double t_max) { return static_cast<float>(t_max) * 1.0001f + 1e-3f; }
}  // namespace

TraceHit Terrain::GroundBelow(double x, double y) const {
  const double top = above_all_z();
  return Trace({x, y, top}, -Eigen::Vector3d::UnitZ(), top - bounds_min_.z() + 10.0);
}

TraceHit Terrain::Trace(const Eigen::Vector3d& origin_W, const Eigen::Vector3d& dir_W,
                       double t_max) const {
  // A non-finite ray (from a diverging state) finds nothing; Embree must never see one.
  if (!FiniteRay(origin_W, dir_W, t_max)) return TraceHit{};
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  RTCRayHit rh;
  rh.ray.org_x = static_cast<float>(origin_W.x());
  rh.ray.org_y = static_cast<float>(origin_W.y());
  rh.ray.org_z = static_cast<float>(origin_W.z());
  rh.ray.dir_x = static_cast<float>(dir_W.x());
  rh.ray.dir_y = static_cast<float>(dir_W.y());
  rh.ray.dir_z = static_cast<float>(dir_W.z());
  rh.ray.tnear = 0.0f;
  rh.ray.tfar = FloatFar(t_max);
  rh.ray.time = 0.0f;
  rh.ray.mask = 0xFFFFFFFFu;
  rh.ray.id = 0;
  rh.ray.flags = 0;
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.primID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(impl_->scene, &context, &rh);
  return Refine(origin_W, dir_W, t_max, rh.hit.geomID, rh.hit.primID, rh.ray.tfar);
}

void Terrain::Trace4(const std::array<Eigen::Vector3d, 4>& origin_W,
                     const std::array<Eigen::Vector3d, 4>& dir_W,
                     const std::array<double, 4>& t_max, std::array<TraceHit, 4>& hits) const {
  alignas(16) int valid[4];
  alignas(16) RTCRayHit4 rh;
  for (int i = 0; i < 4; ++i) {
    valid[i] = FiniteRay(origin_W[i], dir_W[i], t_max[i]) ? -1 : 0;
    rh.ray.org_x[i] = static_cast<float>(origin_W[i].x());
    rh.ray.org_y[i] = static_cast<float>(origin_W[i].y());
    rh.ray.org_z[i] = static_cast<float>(origin_W[i].z());
    rh.ray.dir_x[i] = static_cast<float>(dir_W[i].x());
    rh.ray.dir_y[i] = static_cast<float>(dir_W[i].y());
    rh.ray.dir_z[i] = static_cast<float>(dir_W[i].z());
    if (valid[i] == 0) {  // Embree must not see non-finite values even in an inactive lane
      rh.ray.org_x[i] = rh.ray.org_y[i] = rh.ray.org_z[i] = 0.0f;
      rh.ray.dir_x[i] = rh.ray.dir_y[i] = 0.0f;
      rh.ray.dir_z[i] = -1.0f;
    }
    rh.ray.tnear[i] = 0.0f;
    rh.ray.tfar[i] = valid[i] != 0 ? FloatFar(t_max[i]) : 0.0f;
    rh.ray.time[i] = 0.0f;
    rh.ray.mask[i] = 0xFFFFFFFFu;
    rh.ray.id[i] = static_cast<unsigned>(i);
    rh.ray.flags[i] = 0;
    rh.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;
    rh.hit.primID[i] = RTC_INVALID_GEOMETRY_ID;
    rh.hit.instID[0][i] = RTC_INVALID_GEOMETRY_ID;
  }
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  context.flags = RTC_INTERSECT_CONTEXT_FLAG_COHERENT;
  rtcIntersect4(valid, impl_->scene, &context, &rh);
  for (int i = 0; i < 4; ++i) {
    hits[i] = valid[i] != 0 ? Refine(origin_W[i], dir_W[i], t_max[i], rh.hit.geomID[i],
                                     rh.hit.primID[i], rh.ray.tfar[i])
                            : TraceHit{};
  }
}

}  // namespace vdyn
