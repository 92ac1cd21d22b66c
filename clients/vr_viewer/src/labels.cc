#include "vdyn/viewer/labels.h"

#include <algorithm>
#include <numeric>

namespace vdyn::viewer {

bool Overlap(const LabelBox& a, const LabelBox& b) {
  return a.x0 < b.x1 && b.x0 < a.x1 && a.y0 < b.y1 && b.y0 < a.y1;
}

std::vector<PlacedLabel> LayoutLabels(const std::vector<LabelRequest>& requests, float width,
                                      float height, const std::vector<LabelBox>& blocked,
                                      const LabelStyle& style) {
  std::vector<std::size_t> order(requests.size());
  std::iota(order.begin(), order.end(), std::size_t{0});
  std::stable_sort(order.begin(), order.end(), [&](std::size_t i, std::size_t j) {
    const LabelRequest& a = requests[i];
    const LabelRequest& b = requests[j];
    if (a.priority != b.priority) return a.priority > b.priority;
    return a.distance_m < b.distance_m;
  });
  std::vector<PlacedLabel> placed;
  placed.reserve(requests.size());
  for (std::size_t i : order) {
    const LabelRequest& r = requests[i];
    float alpha = 1;
    if (r.distance_m > style.fade_start_m) {
      const double t =
          (r.distance_m - style.fade_start_m) / (style.fade_end_m - style.fade_start_m);
      alpha = static_cast<float>(std::clamp(1.0 - t, 0.0, 1.0));
    }
    if (alpha < 0.05f) continue;  // faded out
    const float p = style.padding_px, g = style.gap_px;
    const float w = r.width + 2 * p, h = r.height + 2 * p;
    const float ax = r.anchor_x, ay = r.anchor_y;
    // Above, right, left, below the anchor.
    const LabelBox candidates[] = {
        {ax - w / 2, ay - g - h, ax + w / 2, ay - g},
        {ax + g, ay - h / 2, ax + g + w, ay + h / 2},
        {ax - g - w, ay - h / 2, ax - g, ay + h / 2},
        {ax - w / 2, ay + g, ax + w / 2, ay + g + h},
    };
    for (const LabelBox& c : candidates) {
      if (c.x0 < 0 || c.y0 < 0 || c.x1 > width || c.y1 > height) continue;
      const bool free = std::none_of(placed.begin(), placed.end(),
                                     [&](const PlacedLabel& o) { return Overlap(c, o.box); }) &&
                        std::none_of(blocked.begin(), blocked.end(),
                                     [&](const LabelBox& b) { return Overlap(c, b); });
      if (!free) continue;
      placed.push_back({i, c, alpha});
      break;
    }
  }
  return placed;
}

}  // namespace vdyn::viewer
