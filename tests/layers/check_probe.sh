#!/usr/bin/env bash
# Builds one probe target and checks the outcome: "fail HEADER" expects the compiler to stop
# because HEADER is not on that layer's include path; "pass" expects a clean build.
# Usage: check_probe.sh BUILD_DIR TARGET fail|pass [HEADER]
set -u
out=$(cmake --build "$1" --target "$2" 2>&1)
rc=$?
if [ "$3" = pass ]; then
  [ $rc -eq 0 ] && exit 0
  echo "$out"; echo "probe $2 should have compiled"; exit 1
fi
# GCC says "HEADER: No such file or directory", clang "'HEADER' file not found".
if [ $rc -ne 0 ] && grep -qF -e "$4: No such file or directory" -e "'$4' file not found" <<<"$out"; then
  echo "probe $2 refused, as it must: $4 is not visible"; exit 0
fi
echo "$out"; echo "probe $2 should have failed for want of $4"; exit 1
