#include "terrain.h"

#include <cmath>
#include <limits>
#include <stdexcept>

#include <Eigen/Geometry>
#include <embree3/rtcore.h>
#include <spdlog/spdlog.h>

namespace vdyn {

struct Terrain::Impl {
  RTCDevice device = nullptr;
  RTCScene scene = nullptr;
};

namespace {
void EmbreeError(void* /*user*/, RTCError code, const char* str) {
  spdlog::error("embree error {}: {}", static_cast<int>(code), str ? str : "");
}
}  // namespace

Terrain::Terrain() : impl_(std::make_unique<Impl>()) {
  impl_->device = rtcNewDevice("threads=1");
  if (impl_->device == nullptr) throw std::runtime_error("cannot create the Embree device");
  rtcSetDeviceErrorFunction(impl_->device, EmbreeError, nullptr);
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
  std::vector<Plane> planes;
  std::vector<std::uint32_t> kept;
  std::vector<std::array<std::uint32_t, 3>> kept_tris;
  planes.reserve(mesh.triangles.size());
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
    if (!a.allFinite() || !b.allFinite() || !c.allFinite() || !(len > 1e-12)) {
      ++dropped_triangles_;
      continue;
    }
    const Eigen::Vector3d un = n / len;
    planes.push_back({un, un.dot(a)});
    kept.push_back(static_cast<std::uint32_t>(t));
    kept_tris.push_back(tri);
  }
  if (!kept_tris.empty()) {
    RTCGeometry geom = rtcNewGeometry(impl_->device, RTC_GEOMETRY_TYPE_TRIANGLE);
    // Embree reads vertices as 16-byte vectors: one float of padding per vertex (stride 16 bytes).
    auto* vb = static_cast<float*>(rtcSetNewGeometryBuffer(
        geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 4 * sizeof(float), nv));
    auto* ib = static_cast<std::uint32_t*>(rtcSetNewGeometryBuffer(
        geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(std::uint32_t),
        kept_tris.size()));
    if (vb == nullptr || ib == nullptr) {
      rtcReleaseGeometry(geom);
      throw std::runtime_error("Embree could not allocate buffers for mesh '" + mesh.name + "'");
    }
    for (std::size_t i = 0; i < nv; ++i) {
      const Eigen::Vector3d& v = mesh.vertices_W[i];
      const bool ok = v.allFinite();
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
    if (geom_to_mesh_.size() <= id) geom_to_mesh_.resize(id + 1, 0);
    geom_to_mesh_[id] = static_cast<std::uint32_t>(meshes_.size());
  }
  triangle_count_ += kept_tris.size();
  planes_.push_back(std::move(planes));
  kept_to_source_.push_back(std::move(kept));
  meshes_.push_back(std::move(mesh));
}

void Terrain::Commit() {
  if (committed_) return;
  rtcCommitScene(impl_->scene);
  committed_ = true;
}

TraceHit Terrain::Trace(const Eigen::Vector3d& origin_W, const Eigen::Vector3d& dir_W,
                       double t_max) const {
  TraceHit out;
  // A non-finite ray (from a diverging state) finds nothing; Embree must never see one.
  if (!origin_W.allFinite() || !dir_W.allFinite() || !(t_max >= 0.0)) return out;
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
  // A little beyond t_max in float; the exact bound is applied in double below.
  rh.ray.tfar = static_cast<float>(t_max) * 1.0001f + 1e-3f;
  rh.ray.time = 0.0f;
  rh.ray.mask = 0xFFFFFFFFu;
  rh.ray.id = 0;
  rh.ray.flags = 0;
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.primID = RTC_INVALID_GEOMETRY_ID;
  rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(impl_->scene, &context, &rh);
  if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return out;

  const std::uint32_t mesh = geom_to_mesh_[rh.hit.geomID];
  const Plane& plane = planes_[mesh][rh.hit.primID];
  const double denom = plane.n.dot(dir_W);
  double t = static_cast<double>(rh.ray.tfar);
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
  out.mesh = mesh;
  out.triangle = kept_to_source_[mesh][rh.hit.primID];
  return out;
}

}  // namespace vdyn
