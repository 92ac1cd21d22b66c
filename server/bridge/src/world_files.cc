// Terrain from files: meshes through Assimp (OBJ, STL, glTF/GLB, FBX, ...) and height-map images
// through stb_image. Every failure names the file and the reason.
#include <algorithm>
#include <cctype>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>

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

unsigned ImportFlags() {
  // No aiProcess_FindInvalidData: it removes a whole mesh for one NaN vertex ("No meshes
  // remaining"). Non-finite and degenerate triangles are dropped one by one, and counted, by
  // Terrain::AddMesh; the rest of the mesh stays. aiProcess_JoinIdenticalVertices runs apart,
  // after the vertices are checked (JoinIdenticalVertices below).
  return aiProcess_Triangulate | aiProcess_PreTransformVertices | aiProcess_FindDegenerates |
         aiProcess_ValidateDataStructure | aiProcess_SortByPType;
}

// Assimp's vertex joining compares positions by distance: a NaN or infinite coordinate makes it
// join the vertex with an unrelated one (issue 20: `v nan 0 0` in an OBJ became a real triangle
// through a real vertex). So first every vertex with a coordinate that is not finite is moved
// far beyond what a terrain may hold (1e10 m: Terrain::AddMesh drops, and counts, every triangle
// that uses it), then vertices are joined: in Assimp's own order of steps joining is the last
// of ours, so a clean file gives what one ReadFile with every step gave.
const aiScene* JoinIdenticalVertices(Assimp::Importer& importer, const aiScene* scene) {
  if (scene == nullptr) return nullptr;
  constexpr float kFar = 1e10f;
  for (unsigned m = 0; m < scene->mNumMeshes; ++m) {
    aiMesh* am = scene->mMeshes[m];
    for (unsigned v = 0; v < am->mNumVertices; ++v) {
      aiVector3D& p = am->mVertices[v];
      if (!std::isfinite(p.x) || !std::isfinite(p.y) || !std::isfinite(p.z)) p = {kFar, kFar, kFar};
    }
  }
  return importer.ApplyPostProcessing(aiProcess_JoinIdenticalVertices);
}

void ConfigureImporter(Assimp::Importer& importer) {
  importer.SetPropertyBool(AI_CONFIG_FBX_CONVERT_TO_M, true);
  importer.SetPropertyBool(AI_CONFIG_PP_FD_REMOVE, true);
}

std::vector<TriangleMesh> MeshesFromScene(const aiScene* scene, const Assimp::Importer& importer,
                                          const std::string& name, const WorldFileOptions& o) {
  if (scene == nullptr) {
    throw WorldError(name + ": cannot read the mesh: " + importer.GetErrorString());
  }
  if ((scene->mFlags & AI_SCENE_FLAGS_INCOMPLETE) != 0u) {
    throw WorldError(name + ": the mesh file is incomplete");
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

std::vector<TriangleMesh> LoadMeshFile(const fs::path& path, const WorldFileOptions& o) {
  // From the file (not from memory): a glTF's buffers and an OBJ's materials are found beside it.
  Assimp::Importer importer;
  ConfigureImporter(importer);
  const aiScene* scene =
      JoinIdenticalVertices(importer, importer.ReadFile(path.string(), ImportFlags()));
  return MeshesFromScene(scene, importer, path.string(), o);
}

std::vector<TriangleMesh> LoadMeshBytes(const std::string& bytes, const std::string& name,
                                        const std::string& ext, const WorldFileOptions& o) {
  Assimp::Importer importer;
  ConfigureImporter(importer);
  const std::string hint = ext.empty() ? std::string() : ext.substr(1);
  const aiScene* scene = JoinIdenticalVertices(
      importer,
      importer.ReadFileFromMemory(bytes.data(), bytes.size(), ImportFlags(), hint.c_str()));
  return MeshesFromScene(scene, importer, name, o);
}

// Image formats whose decoder would read past short data: the header says how many bytes the
// pixels take; fewer than that is refused with what is missing (stb_image would otherwise build a
// terrain from memory it never wrote). PNG and JPEG carry their own checks.
std::uint32_t Le16(const std::string& b, std::size_t at) {
  return static_cast<std::uint32_t>(static_cast<unsigned char>(b[at])) |
         static_cast<std::uint32_t>(static_cast<unsigned char>(b[at + 1])) << 8;
}
std::uint32_t Le32(const std::string& b, std::size_t at) { return Le16(b, at) | Le16(b, at + 2) << 16; }

// A height map's size: at least 2 x 2 pixels, at most 64 million.
void CheckHeightMapSize(const std::string& name, int w, int h) {
  if (w < 2 || h < 2) {
    throw WorldError(name + ": a height map needs at least 2 x 2 pixels, got " +
                     std::to_string(w) + " x " + std::to_string(h));
  }
  if (static_cast<std::uint64_t>(w) * static_cast<std::uint64_t>(h) > 64'000'000) {
    throw WorldError(name + ": a " + std::to_string(w) + " x " + std::to_string(h) +
                     " height map is larger than 64 million pixels");
  }
}

void CheckImageData(const std::string& name, const std::string& b) {
  auto short_data = [&](std::uint64_t need, std::uint64_t have, const std::string& what) {
    throw WorldError(name + ": the image data is cut short: " + what + " need " +
                     std::to_string(need) + " bytes of pixels, the file holds " +
                     std::to_string(have));
  };
  if (b.size() >= 2 && b[0] == 'P' && b[1] >= '1' && b[1] <= '6') {
    // PNM: magic, then width, height (and maxval, except P1/P4), separated by blanks or comments.
    std::size_t i = 2;
    std::uint64_t nums[3] = {0, 0, 1};
    const int n_nums = (b[1] == '1' || b[1] == '4') ? 2 : 3;
    for (int k = 0; k < n_nums; ++k) {
      while (i < b.size() && (std::isspace(static_cast<unsigned char>(b[i])) || b[i] == '#')) {
        if (b[i] == '#') {
          while (i < b.size() && b[i] != '\n') ++i;
        } else {
          ++i;
        }
      }
      std::uint64_t v = 0;
      std::size_t digits = 0;
      while (i < b.size() && std::isdigit(static_cast<unsigned char>(b[i])) && digits < 9) {
        v = v * 10 + static_cast<std::uint64_t>(b[i] - '0');
        ++i;
        ++digits;
      }
      if (digits == 0) throw WorldError(name + ": not a valid PNM header");
      nums[k] = v;
    }
    ++i;  // the one blank after the header
    const std::uint64_t w = nums[0], h = nums[1], maxval = nums[2];
    if (n_nums == 3 && (maxval == 0 || maxval > 65535)) {
      // Heights are pixel / maxval: 0 would divide by zero (stb_image reads it as NaN terrain).
      throw WorldError(name + ": the maximum value is " + std::to_string(maxval) +
                       ": a PGM or PPM needs 1 to 65535");
    }
    const std::uint64_t channels = (b[1] == '3' || b[1] == '6') ? 3 : 1;
    const std::uint64_t have = b.size() > i ? b.size() - i : 0;
    if (b[1] == '5' || b[1] == '6') {
      const std::uint64_t need = w * h * channels * (maxval > 255 ? 2 : 1);
      if (have < need) {
        short_data(need, have, std::to_string(w) + " x " + std::to_string(h) + " pixels");
      }
    } else {
      throw WorldError(name + ": plain-text and bitmap PNM (P1 to P4) is not read; save the " +
                       "height map as binary PGM (P5) or PPM (P6)");
    }
  } else if (b.size() >= 2 && b[0] == 'B' && b[1] == 'M') {
    if (b.size() < 34) throw WorldError(name + ": the BMP header is cut short");
    const std::uint64_t offset = Le32(b, 10);
    const auto w = static_cast<std::int32_t>(Le32(b, 18));
    const auto h = static_cast<std::int32_t>(Le32(b, 22));
    const std::uint64_t bpp = Le16(b, 28), compression = Le32(b, 30);
    if (w > 1'000'000 || h > 1'000'000 || h < -1'000'000) {
      throw WorldError(name + ": a " + std::to_string(w) + " x " + std::to_string(h) +
                       " BMP is larger than a height map may be");
    }
    if (compression == 0 && w > 0 && h != 0) {
      const std::uint64_t row = (bpp * static_cast<std::uint64_t>(w) + 31) / 32 * 4;
      const std::uint64_t need = row * static_cast<std::uint64_t>(h < 0 ? -static_cast<std::int64_t>(h) : h);
      const std::uint64_t have = b.size() > offset ? b.size() - offset : 0;
      if (have < need) short_data(need, have, "the BMP's rows");
    }
  } else {
    // TGA has no magic; an uncompressed one is recognised by its extension only (caller).
  }
}

void CheckTgaData(const std::string& name, const std::string& b) {
  if (b.size() < 18) throw WorldError(name + ": the TGA header is cut short");
  const std::uint64_t id_len = static_cast<unsigned char>(b[0]);
  const std::uint64_t type = static_cast<unsigned char>(b[2]);
  const std::uint64_t cmap_len = Le16(b, 5), cmap_bits = static_cast<unsigned char>(b[7]);
  const std::uint64_t w = Le16(b, 12), h = Le16(b, 14), bpp = static_cast<unsigned char>(b[16]);
  if (type == 1 || type == 2 || type == 3) {  // uncompressed
    const std::uint64_t header = 18 + id_len + cmap_len * ((cmap_bits + 7) / 8);
    const std::uint64_t need = w * h * ((bpp + 7) / 8);
    const std::uint64_t have = b.size() > header ? b.size() - header : 0;
    if (have < need) {
      throw WorldError(name + ": the image data is cut short: the TGA's " + std::to_string(w) +
                       " x " + std::to_string(h) + " pixels need " + std::to_string(need) +
                       " bytes, the file holds " + std::to_string(have));
    }
  }
}

TriangleMesh HeightmapFromBytes(const std::string& bytes, const std::string& name,
                                const std::string& ext, const WorldFileOptions& o) {
  if (bytes.size() > static_cast<std::size_t>(std::numeric_limits<int>::max())) {
    throw WorldError(name + ": a height-map image may hold at most 2 GB");
  }
  CheckImageData(name, bytes);
  if (ext == ".tga") CheckTgaData(name, bytes);
  const auto* data = reinterpret_cast<const stbi_uc*>(bytes.data());
  const int size = static_cast<int>(bytes.size());
  int w = 0, h = 0, channels = 0;
  // The size from the header first: the pixel limit is checked before anything is decoded
  // (issue 33: a 389 KB PNG of 40000 x 40000 pixels took 3.5 GB before it was refused).
  if (stbi_info_from_memory(data, size, &w, &h, &channels) != 0) CheckHeightMapSize(name, w, h);
  std::vector<double> heights;
  if (stbi_is_16_bit_from_memory(data, size) != 0) {
    stbi_us* px = stbi_load_16_from_memory(data, size, &w, &h, &channels, 1);
    if (px == nullptr) {
      throw WorldError(name + ": cannot read the height map: " + stbi_failure_reason());
    }
    heights.assign(px, px + static_cast<std::size_t>(w) * static_cast<std::size_t>(h));
    for (double& v : heights) v /= 65535.0;
    stbi_image_free(px);
  } else {
    stbi_uc* px = stbi_load_from_memory(data, size, &w, &h, &channels, 1);
    if (px == nullptr) {
      throw WorldError(name + ": cannot read the height map: " + stbi_failure_reason());
    }
    heights.assign(px, px + static_cast<std::size_t>(w) * static_cast<std::size_t>(h));
    for (double& v : heights) v /= 255.0;
    stbi_image_free(px);
  }
  CheckHeightMapSize(name, w, h);
  // Pixel (i, j) -> x = (i - (w-1)/2) * cell, y = ((h-1)/2 - j) * cell: image up is north (+Y).
  TriangleMesh mesh;
  mesh.name = fs::path(name).filename().string();
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

namespace {

void CheckOptions(const std::string& name, const WorldFileOptions& options) {
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
}

std::unique_ptr<World> Finish(std::unique_ptr<World> world, const std::string& name,
                              std::vector<TriangleMesh> meshes) {
  const std::size_t added = meshes.size();
  for (TriangleMesh& m : meshes) world->terrain.AddMesh(std::move(m));
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

}  // namespace

std::unique_ptr<World> LoadWorldFromBytes(const std::string& bytes, const std::string& name,
                                          const WorldFileOptions& options) {
  CheckOptions(name, options);
  if (bytes.empty()) throw WorldError(name + ": the file is empty");
  auto world = std::make_unique<World>();
  world->name = fs::path(name).filename().string();
  const std::string ext = Lower(fs::path(name).extension().string());
  std::vector<TriangleMesh> meshes;
  if (IsImage(ext)) {
    meshes.push_back(HeightmapFromBytes(bytes, name, ext, options));
  } else {
    meshes = LoadMeshBytes(bytes, name, ext, options);
  }
  return Finish(std::move(world), name, std::move(meshes));
}

std::unique_ptr<World> LoadWorld(const std::string& name_or_path, const WorldFileOptions& options) {
  for (const std::string& builtin : BuiltinWorldNames()) {
    if (name_or_path == builtin) return BuildBuiltinWorld(builtin);
  }
  const fs::path path(name_or_path);
  const std::string name = path.string();
  CheckOptions(name, options);
  std::error_code ec;
  if (!fs::exists(path, ec)) {
    throw WorldError(name + ": no such file (and not a built-in world: facility, flat)");
  }
  if (!fs::is_regular_file(path, ec)) throw WorldError(name + ": not a regular file");
  if (fs::file_size(path, ec) == 0) throw WorldError(name + ": the file is empty");
  const std::string ext = Lower(path.extension().string());
  auto world = std::make_unique<World>();
  world->name = path.filename().string();
  if (!IsImage(ext)) return Finish(std::move(world), name, LoadMeshFile(path, options));
  std::ifstream in(path, std::ios::binary);
  if (!in) throw WorldError(name + ": cannot open the file for reading");
  std::ostringstream ss;
  ss << in.rdbuf();
  if (in.bad()) throw WorldError(name + ": cannot read the height map");
  std::vector<TriangleMesh> meshes;
  meshes.push_back(HeightmapFromBytes(ss.str(), name, ext, options));
  return Finish(std::move(world), name, std::move(meshes));
}

}  // namespace vdyn
