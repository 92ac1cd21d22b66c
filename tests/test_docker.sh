#!/usr/bin/env bash
# ctest test_docker: builds the lab image (docker/Dockerfile) and runs a containerised vdyn-server
# and, when the image holds it, vdyn-recorder on a private DDS domain over the host's loopback;
# checks that the states reach a subscriber on the host and that the recording exists and holds
# messages. Skipped (exit 77, ctest's SKIP_RETURN_CODE) where no container engine is usable.
#   tests/test_docker.sh SOURCE_DIR STATE_SUBSCRIBER_BINARY
# VDYN_TEST_IMAGE=NAME runs an image already built instead of building docker/Dockerfile.
set -euo pipefail
src=$1
subscriber=$2

if ! command -v docker >/dev/null 2>&1; then
  echo "test_docker SKIPPED: no container engine here (no 'docker' command); the lab image is not built"
  exit 77
fi
if ! info=$(timeout 20 docker info 2>&1); then
  echo "test_docker SKIPPED: 'docker info' fails, no usable container engine: $(tail -n 1 <<<"$info")"
  exit 77
fi

image=${VDYN_TEST_IMAGE:-vdyn:test}
work=$(mktemp -d /tmp/vdyn-test-docker.XXXXXX)
name=vdyn-test-$$
cleanup() {
  docker rm -f "$name-server" "$name-recorder" >/dev/null 2>&1 || true
  rm -rf "$work"
}
trap cleanup EXIT

# A domain no other test uses right now (the lock files tests/process.cc's FreshDomain takes).
for i in $(seq 0 129); do
  domain=$((100 + ($$ + i) % 130))
  exec {lock}>"/tmp/vdyn-test-domain-$domain.lock"
  if flock -n "$lock"; then break; fi
  exec {lock}>&-
done

if [ -z "${VDYN_TEST_IMAGE:-}" ]; then
  echo "test_docker: building the image (docker/Dockerfile; cached layers make this quick after the first time)"
  start=$(date +%s)
  if ! docker build -f "$src/docker/Dockerfile" -t "$image" "$src" >"$work/build.log" 2>&1; then
    tail -n 40 "$work/build.log"
    echo "test_docker: the image build failed"
    exit 1
  fi
  echo "test_docker: image built in $(( $(date +%s) - start )) s"
fi
echo "test_docker: image $image, $(docker image inspect -f '{{.Size}}' "$image" | awk '{printf "%.0f MB", $1 / 1e6}')"
programs=$(docker run --rm --entrypoint sh "$image" -c 'ls /usr/local/bin | grep "^vdyn-" | tr "\n" " "')
echo "test_docker: programs in the image: $programs"

# The server in a container on the host network, the single-host Cyclone configuration.
docker run -d --name "$name-server" --network host -e VDYN_DDS=single "$image" \
  vdyn-server --domain "$domain" --world flat --no-status --duration 120 >/dev/null

recorder=no
if grep -qw vdyn-recorder <<<"$programs"; then
  recorder=yes
  mkdir -p "$work/recordings"
  docker run -d --name "$name-recorder" --network host -v "$work/recordings:/recordings" "$image" \
    vdyn-recorder record /recordings/session.mcap --domain "$domain" --duration 8 --no-status >/dev/null
fi

# States from the container reach a subscriber on the host (loopback, as the containers use).
export CYCLONEDDS_URI='<General><Interfaces><NetworkInterface name="lo"/></Interfaces></General><Discovery><MaxAutoParticipantIndex>120</MaxAutoParticipantIndex></Discovery>'
got=$("$subscriber" "$domain" 500 60 | sed -n 's/^received //p')
if [ "${got:-0}" -lt 500 ]; then
  echo "test_docker: the host received ${got:-0} of 500 states from the containerised server"
  docker logs "$name-server" 2>&1 | tail -n 20
  exit 1
fi
echo "test_docker: the host received $got states from the containerised server on domain $domain"

if [ "$recorder" = yes ]; then
  if ! rc=$(timeout 60 docker wait "$name-recorder"); then
    echo "test_docker: the recorder did not finish within 60 s"; docker logs "$name-recorder" 2>&1 | tail -n 20; exit 1
  fi
  if [ "$rc" != 0 ] || [ ! -s "$work/recordings/session.mcap" ]; then
    echo "test_docker: the recorder exited with $rc; recording: $(ls -l "$work/recordings" 2>&1)"
    docker logs "$name-recorder" 2>&1 | tail -n 20
    exit 1
  fi
  summary=$(docker run --rm -v "$work/recordings:/recordings" "$image" vdyn-recorder info /recordings/session.mcap)
  messages=$(sed -n 's/.*; \([0-9]*\) messages;.*/\1/p' <<<"$summary" | head -n 1)
  if [ "${messages:-0}" -lt 100 ]; then
    echo "test_docker: the recording holds ${messages:-no} messages"; echo "$summary"; exit 1
  fi
  echo "test_docker: the containerised recorder wrote $(stat -c %s "$work/recordings/session.mcap") bytes, $messages messages"
else
  echo "test_docker: no vdyn-recorder in the image yet: checked the server only"
fi
echo "test_docker: passed"
