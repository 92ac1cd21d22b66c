// Labels on the screen (landmark names, vehicle numbers) that never overlap. Each label asks for
// a place beside its anchor (the projected point it names); the most important first (the
// followed vehicle, other vehicles, then landmarks, nearer before farther) take theirs, and a
// label whose places are all taken is left out (decluttered). Labels fade with distance (fully
// drawn up to fade_start_m, gone at fade_end_m), so the far ones near the horizon thin out.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace vdyn::viewer {

struct LabelBox {
  float x0 = 0, y0 = 0, x1 = 0, y1 = 0;  // pixels, y down; [x0, x1) x [y0, y1)
};
bool Overlap(const LabelBox& a, const LabelBox& b);

struct LabelRequest {
  std::string text;
  float anchor_x = 0, anchor_y = 0;  // the point it names, pixels
  float width = 0, height = 0;       // of the text, pixels
  double distance_m = 0;             // from the eye (0: orthographic, never faded)
  int priority = 0;                  // larger first
};

struct PlacedLabel {
  std::size_t request = 0;  // index into the requests
  LabelBox box;             // where the text goes (its padding included)
  float alpha = 1;          // 0..1 from the fade
};

struct LabelStyle {
  double fade_start_m = 80, fade_end_m = 250;
  float padding_px = 2;  // kept free around each text
  float gap_px = 4;      // between the anchor and the text
};

// Places the labels on a screen of `width` x `height` pixels: no two returned boxes overlap, none
// overlaps a `blocked` box (the HUD's panels), each lies on the screen, and each is one of its
// anchor's four places (above, right, left, below).
std::vector<PlacedLabel> LayoutLabels(const std::vector<LabelRequest>& requests, float width,
                                      float height, const std::vector<LabelBox>& blocked = {},
                                      const LabelStyle& style = {});

}  // namespace vdyn::viewer
