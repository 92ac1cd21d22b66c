// Fuzz target: terrain files - meshes through Assimp and height-map images through stb_image
// (bridge). The first byte picks the format; the rest is the file. A world or a WorldError, never
// a crash or a read of memory nobody wrote.
#include <cstdint>
#include <string>

#include "vdyn/bridge/world_files.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  static const char* const kNames[] = {"f.obj", "f.stl", "f.ply", "f.gltf", "f.glb", "f.fbx",
                                       "f.png", "f.pgm", "f.bmp", "f.tga",  "f.jpg", "f.off"};
  if (size == 0) return 0;
  const std::string name = kNames[data[0] % (sizeof kNames / sizeof kNames[0])];
  const std::string bytes(reinterpret_cast<const char*>(data) + 1, size - 1);
  try {
    vdyn::WorldFileOptions o;
    o.heightmap_cell = 0.5;
    const auto world = vdyn::LoadWorldFromBytes(bytes, name, o);
    (void)world->terrain.triangle_count();
  } catch (const vdyn::WorldError&) {
  } catch (const std::bad_alloc&) {
  }
  return 0;
}
