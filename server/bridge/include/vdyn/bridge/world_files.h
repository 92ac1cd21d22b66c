// Worlds from names and files: the built-in worlds, meshes through Assimp (OBJ, STL, glTF/GLB,
// FBX, ...) and height-map images through stb_image. Every failure names the file and the reason.
#pragma once

#include <memory>
#include <string>

#include "vdyn/physics/world.h"

namespace vdyn {

// Options for terrain files.
struct WorldFileOptions {
  double scale = 1.0;              // file units to metres
  char up_axis = 'z';              // the file's up axis: 'y' (glTF, most OBJ) or 'z'
  double heightmap_cell = 1.0;     // height-map images: metres per pixel
  double heightmap_height = 10.0;  // height-map images: metres for full white
};

// "facility", "flat", or a file: OBJ, STL, glTF/GLB, FBX (Assimp) or a height-map image
// (PNG, PGM, ...). Throws WorldError naming the file and the reason.
std::unique_ptr<World> LoadWorld(const std::string& name_or_path, const WorldFileOptions& options);

// The same from a file's bytes held in memory; `name` gives the format by its extension and names
// the data in errors. (A glTF whose buffers are separate files needs LoadWorld.)
std::unique_ptr<World> LoadWorldFromBytes(const std::string& bytes, const std::string& name,
                                          const WorldFileOptions& options);

}  // namespace vdyn
