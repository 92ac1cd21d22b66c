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
if(VDYN_SANITIZE)
  target_compile_options(vdyn_options INTERFACE
    -fsanitize=address,undefined,float-cast-overflow -fno-sanitize-recover=undefined,float-cast-overflow
    -fno-omit-frame-pointer)
  target_link_options(vdyn_options INTERFACE -fsanitize=address,undefined,float-cast-overflow)
endif()
if(VDYN_FUZZ)
  # Coverage for libFuzzer in every library; clang's warnings differ from GCC's, so they are not
  # errors in this configuration (the GCC builds keep -Werror).
  target_compile_options(vdyn_options INTERFACE -fsanitize=fuzzer-no-link -Wno-error)
endif()
