# Compile options shared by every vdyn target, through the interface library vdyn_options.
#  - warnings are errors (the C++-only ones for C++ only: a few C sources are compiled too);
#  - -ffp-contract=off: no fused multiply-add contraction, so a trajectory does not depend on
#    which expressions the compiler happened to fuse (determinism, see docs/architecture.md);
#  - VDYN_SANITIZE=ON adds AddressSanitizer + UndefinedBehaviorSanitizer (with float-cast-overflow,
#    which -fsanitize=undefined leaves out), which CI runs the tests under.
add_library(vdyn_options INTERFACE)
target_compile_options(vdyn_options INTERFACE
  -Wall -Wextra -Wpedantic -Wshadow
  $<$<COMPILE_LANGUAGE:CXX>:-Wnon-virtual-dtor> $<$<COMPILE_LANGUAGE:CXX>:-Wold-style-cast>
  -Wcast-align -Wunused $<$<COMPILE_LANGUAGE:CXX>:-Woverloaded-virtual> -Wnull-dereference -Wdouble-promotion -Wformat=2
  -Wimplicit-fallthrough -Werror
  -ffp-contract=off -fno-fast-math)
# clang's -Wdouble-promotion also flags a float passed where a double is expected (GCC's does not):
# GCC's reading is the project's, checked in the release build.
if(CMAKE_CXX_COMPILER_ID MATCHES "Clang")
  target_compile_options(vdyn_options INTERFACE -Wno-double-promotion)
else()
  # GCC warns when a class defined outside the main file has a member of a file-local type: in a
  # unity build every source is "outside the main file", while each stays one file's own.
  target_compile_options(vdyn_options INTERFACE $<$<COMPILE_LANGUAGE:CXX>:-Wno-subobject-linkage>)
endif()
if(VDYN_SANITIZE)
  target_compile_options(vdyn_options INTERFACE
    -fsanitize=address,undefined,float-cast-overflow -fno-sanitize-recover=undefined,float-cast-overflow
    -fno-omit-frame-pointer)
  target_link_options(vdyn_options INTERFACE -fsanitize=address,undefined,float-cast-overflow)
endif()
# VDYN_FUZZ (clang): coverage for libFuzzer in the parsers' libraries only; tests/fuzz/CMakeLists.txt.
