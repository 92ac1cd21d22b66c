# Sourced by the tests' shell scripts: sets $domain to a DDS domain of 100..229 that no other test
# holds, through the lock files the C++ tests (tests/process.cc) and Python's conftest take too.
# The lock is held while the sourcing shell runs (its file descriptor stays open).
domain=""
for i in $(seq 0 129); do
  d=$((100 + ($$ + i) % 130))
  exec {fd}>"/tmp/vdyn-test-domain-$d.lock" || continue
  if flock -n "$fd"; then domain=$d; break; fi
  exec {fd}>&-
done
[ -n "$domain" ] || { echo "$0: no free DDS domain among 100..229" >&2; exit 1; }
