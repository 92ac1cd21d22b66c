#!/usr/bin/env bash
# A client binary links no physics: no Embree or Assimp among its shared libraries and no
# simulator, session or world-loading code among its symbols. vdyn-viewer may link Assimp (it
# reads a car model given on the command line, its own code in the viewer), never the world loader.
# Usage: check_links.sh BINARY [--allow-assimp]
set -eu
bin="$1"
forbidden="embree assimp"
if [ "${2:-}" = "--allow-assimp" ]; then forbidden="embree"; fi
needed=$(readelf -d "$bin" | grep NEEDED || true)
for lib in $forbidden; do
  if grep -qi "$lib" <<<"$needed"; then echo "$bin links $lib:"; echo "$needed"; exit 1; fi
done
syms=$(nm -C "$bin" | grep -E "vdyn::(Simulator|Session|Terrain|ServerNode)::|vdyn::(LoadWorld|LoadWorldFromBytes|WorldFromDescription|WorldFromMesh|BuildBuiltinWorld)\(" || true)
if [ -n "$syms" ]; then echo "$bin holds physics or server code:"; head <<<"$syms"; exit 1; fi
echo "$bin: no Embree, no $( [ "$forbidden" = embree ] && echo "world loader" || echo Assimp), no simulator or session code"
