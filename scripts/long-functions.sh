#!/bin/sh
# The functions (lambdas included) longer than a limit, default 150 lines, in the tree's C++
# sources outside tests, bench and generated code, longest first: "lines file function".
#   scripts/long-functions.sh [LIMIT]           list them
#   scripts/long-functions.sh --check [LIMIT]   list them and fail when there is one (a ctest)
# Lines are counted from a function's first line to its last, as Universal Ctags finds them.
set -eu
check=0
if [ "${1:-}" = "--check" ]; then check=1; shift; fi
lim=${1:-150}
cd "$(dirname "$0")/.."
if ! command -v ctags >/dev/null 2>&1 || ! ctags --version 2>/dev/null | grep -q Universal; then
  echo "long-functions: needs Universal Ctags (scripts/install-deps.sh installs universal-ctags)" >&2
  exit 2
fi
found=$(git ls-files '*.cc' '*.h' '*.cpp' | grep -v '^tests/\|^bench/' |
  xargs ctags --fields=+ne --c++-kinds=f --language-force=C++ -o - 2>/dev/null |
  awk -F'\t' -v lim="$lim" '{l=0; e=0
    for (i = 1; i <= NF; i++) { if ($i ~ /^line:/) l = substr($i, 6); if ($i ~ /^end:/) e = substr($i, 5) }
    if (e - l + 1 > lim) print e - l + 1, $2, $1}' | sort -rn)
[ -n "$found" ] && echo "$found"
if [ "$check" = 1 ] && [ -n "$found" ]; then
  echo "long-functions: $(echo "$found" | wc -l) function(s) over $lim lines: split them into named stages" >&2
  exit 1
fi
exit 0
