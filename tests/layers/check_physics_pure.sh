#!/usr/bin/env bash
# The physics library logs nothing, reads and writes no files, and knows no protobuf: none of
# their symbols is referenced by its object code. Usage: check_physics_pure.sh LIBRARY
set -eu
refs=$(nm -C --undefined-only "$1" | grep -E "spdlog|fmt::|google::protobuf|\b(fopen|fwrite|fprintf|printf|puts|write|open)\b|std::basic_[io]?fstream|std::cout|std::cerr|std::clog" || true)
if [ -n "$refs" ]; then echo "$1 refers to logging, files or protobuf:"; sort -u <<<"$refs" | head -20; exit 1; fi
echo "$1: no logging, no file I/O, no protobuf"
