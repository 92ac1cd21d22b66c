#!/usr/bin/env bash
# A client binary links no physics: no Embree or Assimp among its shared libraries and no
# simulator or session code among its symbols. Usage: check_links.sh BINARY
set -eu
bin="$1"
needed=$(readelf -d "$bin" | grep NEEDED || true)
for lib in embree assimp; do
  if grep -qi "$lib" <<<"$needed"; then echo "$bin links $lib:"; echo "$needed"; exit 1; fi
done
syms=$(nm -C "$bin" | grep -E "vdyn::(Simulator|Session|Terrain|ServerNode)::" || true)
if [ -n "$syms" ]; then echo "$bin holds physics or server code:"; head <<<"$syms"; exit 1; fi
echo "$bin: no Embree, no Assimp, no simulator or session code"
