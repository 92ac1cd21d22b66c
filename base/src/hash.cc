// The hash is header-only (constexpr); this file checks the published FNV-1a test vectors at
// compile time, so a build with a broken hash does not link at all.
#include "vdyn/base/hash.h"

namespace vdyn::base {
static_assert(Fnv1a64("") == 0xcbf29ce484222325ull);
static_assert(Fnv1a64("a") == 0xaf63dc4c8601ec8cull);
static_assert(Fnv1a64("foobar") == 0x85944171f73967e8ull);
}  // namespace vdyn::base
