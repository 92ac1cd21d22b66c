#!/bin/sh
# Functions longer than $1 lines (default 150) in the tree's C++ sources, outside tests, bench and generated code.
lim=${1:-150}
git ls-files '*.cc' '*.h' '*.cpp' | grep -v '^tests/\|^bench/' | xargs ctags --fields=+ne --c++-kinds=f --language-force=C++ -o - 2>/dev/null |
awk -F'\t' -v lim=$lim '{l=0;e=0;for(i=1;i<=NF;i++){if($i ~ /^line:/)l=substr($i,6); if($i ~ /^end:/)e=substr($i,5)} if(e-l+1>lim) print e-l+1, $2, $1}' | sort -rn
