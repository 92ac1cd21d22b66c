#include "vdyn/physics/mesh.h"

namespace vdyn {

void TriangleMesh::AddQuad(const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                           const Eigen::Vector3d& c, const Eigen::Vector3d& d) {
  const auto i = static_cast<std::uint32_t>(vertices_W.size());
  vertices_W.insert(vertices_W.end(), {a, b, c, d});
  triangles.push_back({i, i + 1, i + 2});
  triangles.push_back({i, i + 2, i + 3});
}

void TriangleMesh::AddBox(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) {
  using V = Eigen::Vector3d;
  const V p000(lo.x(), lo.y(), lo.z()), p100(hi.x(), lo.y(), lo.z());
  const V p010(lo.x(), hi.y(), lo.z()), p110(hi.x(), hi.y(), lo.z());
  const V p001(lo.x(), lo.y(), hi.z()), p101(hi.x(), lo.y(), hi.z());
  const V p011(lo.x(), hi.y(), hi.z()), p111(hi.x(), hi.y(), hi.z());
  AddQuad(p001, p101, p111, p011);  // top (+Z)
  AddQuad(p000, p010, p110, p100);  // bottom (-Z)
  AddQuad(p000, p100, p101, p001);  // -Y
  AddQuad(p110, p010, p011, p111);  // +Y
  AddQuad(p010, p000, p001, p011);  // -X
  AddQuad(p100, p110, p111, p101);  // +X
}

void TriangleMesh::Append(const TriangleMesh& other) {
  const auto base = static_cast<std::uint32_t>(vertices_W.size());
  vertices_W.insert(vertices_W.end(), other.vertices_W.begin(), other.vertices_W.end());
  for (const auto& t : other.triangles) triangles.push_back({t[0] + base, t[1] + base, t[2] + base});
}

}  // namespace vdyn
