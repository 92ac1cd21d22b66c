// Terrain files: meshes through Assimp (written here by Assimp's own exporters, and by hand) and
// height-map images; broken input ends in an error naming the file and the reason.
#include <cmath>

#include <assimp/Exporter.hpp>
#include <assimp/scene.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "test_support.h"
#include "vdyn/bridge/convert.h"
#include "vdyn/bridge/world_files.h"
#include "vdyn/physics/world.h"

namespace vdyn {
namespace {

using Eigen::Vector3d;
using ::testing::HasSubstr;
using testing::ReadFile;
using testing::TempDir;
using testing::WriteFile;

// A 20 m x 10 m quad at height 3 in a Y-up file: x in [0, 20], "up" y = 3, z in [-10, 0].
std::unique_ptr<aiScene> YUpQuadScene() {
  auto scene = std::make_unique<aiScene>();
  scene->mRootNode = new aiNode();
  scene->mRootNode->mNumMeshes = 1;
  scene->mRootNode->mMeshes = new unsigned[1]{0};
  scene->mMaterials = new aiMaterial*[1]{new aiMaterial()};
  scene->mNumMaterials = 1;
  auto* mesh = new aiMesh();
  mesh->mMaterialIndex = 0;
  mesh->mPrimitiveTypes = aiPrimitiveType_TRIANGLE;
  mesh->mNumVertices = 4;
  mesh->mVertices = new aiVector3D[4]{{0, 3, 0}, {20, 3, 0}, {20, 3, -10}, {0, 3, -10}};
  mesh->mNumFaces = 2;
  mesh->mFaces = new aiFace[2];
  const unsigned idx[2][3] = {{0, 1, 2}, {0, 2, 3}};
  for (int f = 0; f < 2; ++f) {
    mesh->mFaces[f].mNumIndices = 3;
    mesh->mFaces[f].mIndices = new unsigned[3]{idx[f][0], idx[f][1], idx[f][2]};
  }
  scene->mMeshes = new aiMesh*[1]{mesh};
  scene->mNumMeshes = 1;
  return scene;
}

double GroundZ(const World& w, double x, double y) {
  const TraceHit h = w.terrain.Trace(Vector3d(x, y, 100.0), -Vector3d::UnitZ(), 200.0);
  EXPECT_TRUE(h.hit) << "no ground at " << x << ", " << y;
  return 100.0 - h.distance;
}

class AssimpFormats : public ::testing::TestWithParam<std::pair<const char*, const char*>> {};

TEST_P(AssimpFormats, YUpFileWithScaleLandsWhereExpected) {
  TempDir dir;
  const auto [format, ext] = GetParam();
  const auto path = dir / (std::string("quad.") + ext);
  Assimp::Exporter exporter;
  const auto scene = YUpQuadScene();
  ASSERT_EQ(exporter.Export(scene.get(), format, path.string()), AI_SUCCESS)
      << exporter.GetErrorString();
  WorldFileOptions o;
  o.up_axis = 'y';
  o.scale = 2.0;
  const auto world = LoadWorld(path.string(), o);
  EXPECT_EQ(world->terrain.triangle_count(), 2u);
  // File (x, y-up, z) -> world (x, -z, y), times 2: x in [0, 40], y in [0, 20], height 6.
  EXPECT_NEAR(GroundZ(*world, 30.0, 15.0), 6.0, 1e-5);
  EXPECT_FALSE(world->terrain.Trace(Vector3d(30, -5, 100), -Vector3d::UnitZ(), 200).hit);
  EXPECT_NEAR(world->spawn.x, 20.0, 1e-5);
  EXPECT_NEAR(world->spawn.y, 10.0, 1e-5);
}

INSTANTIATE_TEST_SUITE_P(Files, AssimpFormats,
                         ::testing::Values(std::make_pair("obj", "obj"),
                                           std::make_pair("stlb", "stl"),
                                           std::make_pair("gltf2", "gltf"),
                                           std::make_pair("glb2", "glb"),
                                           std::make_pair("fbxa", "fbx")));

TEST(WorldFiles, HandWrittenObjZUp) {
  TempDir dir;
  WriteFile(dir / "ground.obj",
            "# two triangles, Z up\nv -5 -5 1\nv 5 -5 1\nv 5 5 2\nv -5 5 2\nf 1 2 3\nf 1 3 4\n");
  const auto world = LoadWorld((dir / "ground.obj").string(), WorldFileOptions{});
  EXPECT_NEAR(GroundZ(*world, 0.0, 0.0), 1.5, 1e-9);
  EXPECT_NEAR(GroundZ(*world, 0.0, 2.5), 1.75, 1e-9);
}

TEST(WorldFiles, HeightMapImage) {
  TempDir dir;
  // 3 x 2 binary PGM: top row (north) 0 128 255, bottom row 0 0 0.
  std::string pgm = "P5\n3 2\n255\n";
  pgm += std::string{'\x00', '\x80', '\xff', '\x00', '\x00', '\x00'};
  WriteFile(dir / "hm.pgm", pgm);
  WorldFileOptions o;
  o.heightmap_cell = 10.0;
  o.heightmap_height = 5.1;
  const auto world = LoadWorld((dir / "hm.pgm").string(), o);
  // Pixels span x in [-10, 10], y in [-5, 5]; pixel (2, 0) is at (10, 5) with 5.1 m.
  EXPECT_NEAR(GroundZ(*world, 9.999, 4.999), 5.1, 0.01);
  EXPECT_NEAR(GroundZ(*world, -9.9, -4.9), 0.0, 1e-9);
  EXPECT_NEAR(GroundZ(*world, 0.0, 4.999), 5.1 * 128.0 / 255.0, 0.01);
}

struct BrokenCase {
  const char* name;
  const char* content;  // nullptr: do not create the file
  const char* reason;
};

class BrokenWorldFiles : public ::testing::TestWithParam<BrokenCase> {};

TEST_P(BrokenWorldFiles, EndWithAMessageNamingFileAndReason) {
  TempDir dir;
  const auto path = dir / GetParam().name;
  if (GetParam().content != nullptr) WriteFile(path, GetParam().content);
  try {
    LoadWorld(path.string(), WorldFileOptions{});
    FAIL() << "expected WorldError";
  } catch (const WorldError& e) {
    EXPECT_THAT(e.what(), HasSubstr(path.string()));
    EXPECT_THAT(e.what(), HasSubstr(GetParam().reason));
  }
}

INSTANTIATE_TEST_SUITE_P(
    Files, BrokenWorldFiles,
    ::testing::Values(
        BrokenCase{"missing.obj", nullptr, "no such file"},
        BrokenCase{"empty.stl", "", "the file is empty"},
        BrokenCase{"garbage.fbx", "this is not an FBX file at all\n", "cannot read the mesh"},
        BrokenCase{"garbage.gltf", "{ not json", "cannot read the mesh"},
        BrokenCase{"flat.obj", "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n", "no usable triangles"},
        BrokenCase{"broken.png", "\x89PNG\r\n\x1a\nxxxx", "cannot read the height map"},
        BrokenCase{"tiny.pgm", "P5\n1 1\n255\n\x10", "at least 2 x 2 pixels"},
        // A PNM's maximum value is 1 to 65535: 0 would divide every height by 0.
        BrokenCase{"maxval0.pgm", "P5\n2 2\n0\n\x10\x20\x30\x40",
                   "the maximum value is 0: a PGM or PPM needs 1 to 65535"},
        BrokenCase{"maxval0.ppm", "P6 2 2 0\n123456789012",
                   "the maximum value is 0: a PGM or PPM needs 1 to 65535"},
        BrokenCase{"maxval70000.pgm", "P5\n2 2\n70000\n\x10\x20\x30\x40\x10\x20\x30\x40",
                   "the maximum value is 70000: a PGM or PPM needs 1 to 65535"}));

std::string Le(std::uint32_t v, int bytes) {
  std::string out;
  for (int i = 0; i < bytes; ++i) out += static_cast<char>((v >> (8 * i)) & 0xff);
  return out;
}

// Short pixel data is refused with what is missing (stb_image would build a terrain from memory it
// never wrote; valgrind saw it).
TEST(WorldFiles, ImagesWithShortPixelDataAreRefused) {
  TempDir dir;
  struct Case {
    std::string name, bytes, reason;
  };
  std::string bmp = "BM" + Le(0, 4) + Le(0, 4) + Le(54, 4) + Le(40, 4) + Le(64, 4) + Le(64, 4) +
                    Le(1, 2) + Le(8, 2) + Le(0, 4) + Le(0, 4) + Le(0, 4) + Le(0, 4) + Le(0, 4) +
                    Le(0, 4);
  bmp += std::string(100, '\x20');
  std::string tga = std::string(2, '\0') + '\3' + std::string(9, '\0') + Le(64, 2) + Le(64, 2) +
                    '\x08' + '\0';
  tga += std::string(100, '\x20');
  const Case cases[] = {
      {"short.pgm", "P5\n64 64\n255\n" + std::string(100, '\x40'),
       "64 x 64 pixels need 4096 bytes of pixels, the file holds 100"},
      {"short16.pgm", "P5 # a comment\n4 4\n65535\n" + std::string(31, '\x40'),
       "4 x 4 pixels need 32 bytes of pixels, the file holds 31"},
      {"short.ppm", "P6\n8 8\n255\n" + std::string(100, '\x40'), "need 192 bytes"},
      {"short.bmp", bmp, "the BMP's rows need 4096 bytes of pixels, the file holds 100"},
      {"short.tga", tga, "the TGA's 64 x 64 pixels need 4096 bytes, the file holds 100"},
  };
  for (const Case& c : cases) {
    WriteFile(dir / c.name, c.bytes);
    try {
      LoadWorld((dir / c.name).string(), WorldFileOptions{});
      ADD_FAILURE() << c.name << " was accepted";
    } catch (const WorldError& e) {
      EXPECT_THAT(e.what(), HasSubstr((dir / c.name).string() + ": the image data is cut short"));
      EXPECT_THAT(e.what(), HasSubstr(c.reason));
    }
  }
  // The same formats complete load (the checks do not refuse good files).
  WriteFile(dir / "full.pgm", "P5\n2 2\n255\n\x10\x20\x30\x40");
  EXPECT_NO_THROW(LoadWorld((dir / "full.pgm").string(), WorldFileOptions{}));
  // Plain-text PGM is refused with what to do instead.
  WriteFile(dir / "ascii.pgm", "P2\n2 2\n255\n1 2\n3 4\n");
  try {
    LoadWorld((dir / "ascii.pgm").string(), WorldFileOptions{});
    ADD_FAILURE() << "a plain-text PGM was accepted";
  } catch (const WorldError& e) {
    EXPECT_THAT(e.what(), HasSubstr("save the height map as binary PGM (P5)"));
  }
}

// One NaN vertex costs its triangles, not the mesh (Assimp's FindInvalidData would drop it all).
TEST(WorldFiles, ANonFiniteVertexDropsItsTrianglesOnly) {
  TempDir dir;
  WriteFile(dir / "nan.obj",
            "v -50 -50 0\nv 50 -50 0\nv 50 50 0\nv -50 50 0\nv nan 0 1\nv 1 1 1\n"
            "f 1 2 3\nf 1 3 4\nf 5 6 1\n");
  const auto world = LoadWorld((dir / "nan.obj").string(), WorldFileOptions{});
  EXPECT_EQ(world->terrain.triangle_count(), 2u);
  EXPECT_EQ(world->terrain.dropped_triangles(), 1u);
  EXPECT_NEAR(GroundZ(*world, 10.0, -20.0), 0.0, 1e-9);
}

// Whichever coordinate is not finite (x, y or z; NaN or an infinity), every triangle that uses the
// vertex is dropped and counted, and the rest is the world: no terrain appears where the file has
// none (issue 20: `v nan 0 0` became a real triangle).
class NonFiniteVertex : public ::testing::TestWithParam<std::string> {};

TEST_P(NonFiniteVertex, DropsEveryTriangleThatUsesIt) {
  TempDir dir;
  // Two ground triangles (the square z = 0 from -50 to 50), and two triangles over the square
  // x, y in [100, 110] at z = 5 that both use the bad vertex 5.
  WriteFile(dir / "bad.obj", "v -50 -50 0\nv 50 -50 0\nv 50 50 0\nv -50 50 0\nv " + GetParam() +
                                 "\nv 100 100 5\nv 110 100 5\nv 110 110 5\nv 100 110 5\n"
                                 "f 1 2 3\nf 1 3 4\nf 6 7 5\nf 5 8 9\n");
  const auto world = LoadWorld((dir / "bad.obj").string(), WorldFileOptions{});
  EXPECT_EQ(world->terrain.triangle_count(), 2u) << GetParam();
  EXPECT_EQ(world->terrain.dropped_triangles(), 2u) << GetParam();
  EXPECT_NEAR(GroundZ(*world, 10.0, -20.0), 0.0, 1e-9);
  // Nothing where only the dropped triangles were; the bounds are the kept ones'.
  EXPECT_FALSE(world->terrain.Trace(Vector3d(105.0, 101.0, 100.0), -Vector3d::UnitZ(), 200.0).hit)
      << GetParam();
  EXPECT_TRUE(world->terrain.bounds_min().allFinite() && world->terrain.bounds_max().allFinite());
  // The world description clients draw holds exactly the terrain traced: the two kept triangles
  // and their four vertices, nothing of the bad vertex (issue 33: a viewer drew `v nan 0 0` as a
  // slab 1e10 m high; a vertex at 1e30 overflowed its grid).
  const pb::WorldDescription d = DescribeWorld(*world, "s", 1'000'000);
  int triangles = 0;
  for (const pb::Mesh& m : d.meshes()) {
    triangles += m.indices_size() / 3;
    EXPECT_EQ(m.vertices_size(), 3 * 4) << GetParam();
    for (double v : m.vertices()) EXPECT_LE(std::abs(v), 50.0) << GetParam();
    for (std::uint32_t i : m.indices()) EXPECT_LT(i, 4u) << GetParam();
  }
  EXPECT_EQ(triangles, 2) << GetParam();
}

// The file: Assimp's vertex joining made the NaN vertex (50, 50, 0), so the triangle became
// real ground where the file has none.
TEST(WorldFiles, ANanVertexIsNotJoinedWithARealOne) {
  TempDir dir;
  WriteFile(dir / "nan.obj",
            "v -50 -50 0\nv 50 -50 0\nv 50 50 0\nv -50 50 0\nv nan 0 0\nv 60 0 0\nv 60 10 0\n"
            "f 1 2 3\nf 1 3 4\nf 5 6 7\n");
  const auto world = LoadWorld((dir / "nan.obj").string(), WorldFileOptions{});
  EXPECT_EQ(world->terrain.triangle_count(), 2u);
  EXPECT_EQ(world->terrain.dropped_triangles(), 1u);
  EXPECT_FALSE(world->terrain.Trace(Vector3d(58.0, 5.0, 100.0), -Vector3d::UnitZ(), 200.0).hit);
  // The same from memory (a world description's bytes).
  const auto again = LoadWorldFromBytes(ReadFile(dir / "nan.obj"), "nan.obj", WorldFileOptions{});
  EXPECT_EQ(again->terrain.dropped_triangles(), 1u);
  EXPECT_FALSE(again->terrain.Trace(Vector3d(58.0, 5.0, 100.0), -Vector3d::UnitZ(), 200.0).hit);
}

INSTANTIATE_TEST_SUITE_P(WorldFiles, NonFiniteVertex,
                         ::testing::Values("nan 0 0", "0 nan 0", "0 0 nan", "inf 0 0", "0 -inf 0",
                                           "0 0 inf", "nan nan nan", "1e30 0 0"));

// A PNG's size is read from its header and refused before anything is decoded (issue 33: a
// 389 KB PNG took 3.5 GB before its pixel limit was checked). Here the
// file is a header alone: the size is all there is to read.
TEST(WorldFiles, AHugeHeightMapIsRefusedFromItsHeader) {
  auto be32 = [](std::uint32_t v) {
    return std::string{static_cast<char>(v >> 24), static_cast<char>(v >> 16),
                       static_cast<char>(v >> 8), static_cast<char>(v)};
  };
  auto crc32 = [](const std::string& bytes) {
    std::uint32_t c = 0xffffffffu;
    for (unsigned char b : bytes) {
      c ^= b;
      for (int k = 0; k < 8; ++k) c = (c >> 1) ^ (0xedb88320u & (0u - (c & 1u)));
    }
    return c ^ 0xffffffffu;
  };
  auto chunk = [&](const std::string& type, const std::string& data) {
    return be32(static_cast<std::uint32_t>(data.size())) + type + data + be32(crc32(type + data));
  };
  // IHDR: width, height, bit depth 8, colour type 0 (grey), compression, filter, interlace 0.
  const std::string ihdr = be32(30000) + be32(30000) + std::string{8, 0, 0, 0, 0};
  const std::string png = std::string("\x89PNG\r\n\x1a\n", 8) + chunk("IHDR", ihdr) + chunk("IEND", "");
  try {
    (void)LoadWorldFromBytes(png, "huge.png", WorldFileOptions{});
    ADD_FAILURE() << "accepted";
  } catch (const WorldError& e) {
    EXPECT_THAT(e.what(), ::testing::HasSubstr(
                              "huge.png: a 30000 x 30000 height map is larger than 64 million "
                              "pixels"));
  }
}

TEST(WorldFiles, BadOptionsAreRefused) {
  TempDir dir;
  WriteFile(dir / "g.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
  WorldFileOptions o;
  o.scale = -1.0;
  EXPECT_THROW(LoadWorld((dir / "g.obj").string(), o), WorldError);
}

}  // namespace
}  // namespace vdyn
