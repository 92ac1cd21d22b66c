// The page vdyn-foxglove serves at `/` (web/index.html, web/app.js), built into the program.
#pragma once

#include <string_view>

namespace vdyn::foxglove::web {

std::string_view IndexHtml();
std::string_view AppJs();

}  // namespace vdyn::foxglove::web
