// Terrain from files: meshes through Assimp (OBJ, STL, glTF/GLB, FBX, ...) and height-map images
// through stb_image. Every failure names the file and the reason.
#include <algorithm>
#include <cctype>
#include <filesystem>
#include <fstream>

#include <assimp/Importer.hpp>
#include <assimp/postprocess.h>
#include <assimp/scene.h>
#include <stb/stb_image.h>

#include "vdyn/bridge/world_files.h"

#include <cmath>

namespace vdyn {
namespace {

namespace fs = std::filesystem;

std::string Lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return s;
}

bool IsImage(const std::string& ext) {
  return ext == ".png" || ext == ".pgm" || ext == ".ppm" || ext == ".jpg" || ext == ".jpeg" ||
         ext == ".bmp" || ext == ".tga";
}

// File up axis to world: Z-up files pass through; Y-up files map (x, y, z) -> (x, -z, y).
Eigen::Vector3d ToWorld(double x, double y, double z, const WorldFileOptions& o) {
  const Eigen::Vector3d v = o.up_axis == 'y' ? Eigen::Vector3d(x, -z, y) : Eigen::Vector3d(x, y, z);
  return o.scale * v;
}

std::vector<TriangleMesh> LoadMeshFile(const fs::path& path, const WorldFileOptions& o) {
  Assimp::Importer importer;
  importer.SetPropertyBool(AI_CONFIG_FBX_CONVERT_TO_M, true);
  importer.SetPropertyBool(AI_CONFIG_PP_FD_REMOVE, true);
  const unsigned flags = aiProcess_Triangulate | aiProcess_JoinIdenticalVertices |
                         aiProcess_PreTransformVertices | aiProcess_FindDegenerates |
                         aiProcess_FindInvalidData | aiProcess_ValidateDataStructure |
                         aiProcess_SortByPType;
  const aiScene* scene = importer.ReadFile(path.string(), flags);
  if (scene == nullptr) {
    throw WorldError(path.string() + ": cannot read the mesh: " + importer.GetErrorString());
  }
  if ((scene->mFlags & AI_SCENE_FLAGS_INCOMPLETE) != 0u) {
    throw WorldError(path.string() + ": the mesh file is incomplete");
  }
  std::vector<TriangleMesh> meshes;
  for (unsigned m = 0; m < scene->mNumMeshes; ++m) {
    const aiMesh* am = scene->mMeshes[m];
    if ((am->mPrimitiveTypes & aiPrimitiveType_TRIANGLE) == 0u) continue;
    TriangleMesh mesh;
    mesh.name = am->mName.length > 0 ? am->mName.C_Str() : "mesh_" + std::to_string(m);
    mesh.kind = SurfaceKind::kGround;
    mesh.vertices_W.reserve(am->mNumVertices);
    for (unsigned v = 0; v < am->mNumVertices; ++v) {
      const aiVector3D& p = am->mVertices[v];
      mesh.vertices_W.push_back(ToWorld(p.x, p.y, p.z, o));
    }
    for (unsigned f = 0; f < am->mNumFaces; ++f) {
      const aiFace& face = am->mFaces[f];
      if (face.mNumIndices != 3) continue;
      mesh.triangles.push_back({face.mIndices[0], face.mIndices[1], face.mIndices[2]});
    }
    if (!mesh.triangles.empty()) meshes.push_back(std::move(mesh));
  }
  return meshes;
}

TriangleMesh LoadHeightmap(const fs::path& path, const WorldFileOptions& o) {
  const std::string name = path.string();
  int w = 0, h = 0, channels = 0;
  std::vector<double> heights;
  if (stbi_is_16_bit(name.c_str()) != 0) {
    stbi_us* px = stbi_load_16(name.c_str(), &w, &h, &channels, 1);
    if (px == nullptr) {
      throw WorldError(name + ": cannot read the height map: " + stbi_failure_reason());
    }
    heights.assign(px, px + static_cast<std::size_t>(w) * static_cast<std::size_t>(h));
    for (double& v : heights) v /= 65535.0;
    stbi_image_free(px);
  } else {
    stbi_uc* px = stbi_load(name.c_str(), &w, &h, &channels, 1);
    if (px == nullptr) {
      throw WorldError(name + ": cannot read the height map: " + stbi_failure_reason());
    }
    heights.assign(px, px + static_cast<std::size_t>(w) * static_cast<std::size_t>(h));
    for (double& v : heights) v /= 255.0;
    stbi_image_free(px);
  }
  if (w < 2 || h < 2) {
    throw WorldError(name + ": a height map needs at least 2 x 2 pixels, got " +
                     std::to_string(w) + " x " + std::to_string(h));
  }
  // Pixel (i, j) -> x = (i - (w-1)/2) * cell, y = ((h-1)/2 - j) * cell: image up is north (+Y).
  TriangleMesh mesh;
  mesh.name = path.filename().string();
  mesh.kind = SurfaceKind::kGround;
  const double cx = 0.5 * (w - 1), cy = 0.5 * (h - 1);
  for (int j = 0; j < h; ++j) {
    for (int i = 0; i < w; ++i) {
      mesh.vertices_W.emplace_back((i - cx) * o.heightmap_cell, (cy - j) * o.heightmap_cell,
                                   heights[static_cast<std::size_t>(j) * w + i] *
                                       o.heightmap_height);
    }
  }
  const auto uw = static_cast<std::uint32_t>(w);
  for (std::uint32_t j = 0; j + 1 < static_cast<std::uint32_t>(h); ++j) {
    for (std::uint32_t i = 0; i + 1 < uw; ++i) {
      const std::uint32_t a = j * uw + i, b = a + 1, c = a + uw + 1, d = a + uw;
      mesh.triangles.push_back({a, c, b});
      mesh.triangles.push_back({a, d, c});
    }
  }
  return mesh;
}

}  // namespace

std::unique_ptr<World> LoadWorld(const std::string& name_or_path, const WorldFileOptions& options) {
  for (const std::string& builtin : BuiltinWorldNames()) {
    if (name_or_path == builtin) return BuildBuiltinWorld(builtin);
  }
  const fs::path path(name_or_path);
  const std::string name = path.string();
  if (!(options.scale > 0.0) || !std::isfinite(options.scale)) {
    throw WorldError(name + ": scale must be a positive number");
  }
  if (options.up_axis != 'y' && options.up_axis != 'z') {
    throw WorldError(name + ": up axis must be 'y' or 'z'");
  }
  if (!(options.heightmap_cell > 0.0) || !(options.heightmap_height > 0.0) ||
      !std::isfinite(options.heightmap_cell) || !std::isfinite(options.heightmap_height)) {
    throw WorldError(name + ": height-map cell size and height must be positive numbers");
  }
  std::error_code ec;
  if (!fs::exists(path, ec)) {
    throw WorldError(name + ": no such file (and not a built-in world: facility, flat)");
  }
  if (!fs::is_regular_file(path, ec)) throw WorldError(name + ": not a regular file");
  if (fs::file_size(path, ec) == 0) throw WorldError(name + ": the file is empty");
  {
    std::ifstream probe(path, std::ios::binary);
    if (!probe) throw WorldError(name + ": cannot open the file for reading");
  }

  auto world = std::make_unique<World>();
  world->name = path.filename().string();
  const std::string ext = Lower(path.extension().string());
  std::size_t added = 0;
  if (IsImage(ext)) {
    world->terrain.AddMesh(LoadHeightmap(path, options));
    added = 1;
  } else {
    for (TriangleMesh& m : LoadMeshFile(path, options)) {
      world->terrain.AddMesh(std::move(m));
      ++added;
    }
  }
  if (added == 0 || world->terrain.triangle_count() == 0) {
    throw WorldError(name + ": contains no usable triangles" +
                     (world->terrain.dropped_triangles() > 0
                          ? " (" + std::to_string(world->terrain.dropped_triangles()) +
                                " degenerate or non-finite triangles dropped)"
                          : std::string()));
  }
  world->terrain.Commit();
  const Eigen::Vector3d lo = world->terrain.bounds_min(), hi = world->terrain.bounds_max();
  world->spawn = {0.5 * (lo.x() + hi.x()), 0.5 * (lo.y() + hi.y()), 0.0};
  world->landmarks = {{"bounds_min", lo}, {"bounds_max", hi}};
  return world;
}

}  // namespace vdyn
