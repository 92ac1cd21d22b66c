// The viewer's textures, generated in code at start-up (no image files: nothing to license):
// tileable grass, asphalt, concrete and dirt with gravel, a large-scale variation map that breaks
// up the tiling, clouds, and the billboard's poster (drawn with a small pixel font of our own).
// Each is a square RGBA8 image in sRGB, made from integer-hashed value noise, so it is the same on
// every machine. A surface texture's mean colour (averaged in linear light) is exactly its kind's
// colour in LookOf (world_mesh.h): from far away, or on the map, a surface has that colour.
#pragma once

#include <cstdint>
#include <vector>

#include "vdyn/viewer/scene.h"

namespace vdyn::viewer {

enum class TextureLayer { kGrass, kAsphalt, kConcrete, kDirt, kMacro, kClouds, kPoster };
inline constexpr int kTextureLayers = 7;
// The poster is drawn for a face kPosterAspect times as wide as high (the square image is
// stretched over it).
inline constexpr double kPosterAspect = 3.0;

struct TextureImage {
  int size = 0;                    // width = height, pixels
  std::vector<std::uint8_t> rgba;  // rows top down, sRGB
};

// The layer's image, `size` pixels square (a power of two, at least 16); one tile covers
// TileMetres(layer) on the ground.
TextureImage MakeTexture(TextureLayer layer, int size);
double TileMetres(TextureLayer layer);

// The mean colour a surface layer is made to have (grass, asphalt, concrete, dirt), sRGB.
Rgb8 MeanColour(TextureLayer layer);

// sRGB <-> linear light (the sRGB curve, as the GPU decodes textures and the shaders encode).
double ToLinear(std::uint8_t srgb);
// An integer hash of the lattice point (i, j) for a seed, in [0, 1): the procedural textures'
// and the dressing's noise.
double LatticeHash(std::int64_t i, std::int64_t j, std::uint64_t seed);
// 0 below e0, 1 above e1, the cubic 3t^2 - 2t^3 between.
double SmoothStep(double e0, double e1, double x);
std::uint8_t ToSrgb(double linear);

}  // namespace vdyn::viewer
