#!/bin/sh
# The vdyn image's entrypoint: sets CYCLONEDDS_URI from the lab's settings, then runs the command.
#   VDYN_DDS             single (default: one host, loopback), peers (static peers across hosts,
#                        VDYN_PEER_1..4) or the absolute path of a Cyclone DDS XML file
#   VDYN_SECURITY_DIR    with VDYN_SECURITY_NAME: DDS Security with that identity from the
#                        material lab-pki.sh made in that directory (off when unset)
# A CYCLONEDDS_URI given to the container is used as it is.
set -eu
if [ -z "${CYCLONEDDS_URI:-}" ]; then
  dds=${VDYN_DDS:-single}
  case "$dds" in
    single | peers) config=/etc/vdyn/cyclonedds/$dds.xml ;;
    /*) config=$dds ;;
    *) echo "vdyn: VDYN_DDS='$dds': use single, peers or the absolute path of a Cyclone DDS XML file" >&2
       exit 2 ;;
  esac
  if [ ! -r "$config" ]; then
    echo "vdyn: cannot read the Cyclone DDS configuration $config" >&2
    exit 2
  fi
  uri="file://$config"
  if [ -n "${VDYN_SECURITY_DIR:-}" ]; then
    name=${VDYN_SECURITY_NAME:-}
    if [ -z "$name" ] || [ ! -r "$VDYN_SECURITY_DIR/$name.pem" ]; then
      echo "vdyn: VDYN_SECURITY_DIR=$VDYN_SECURITY_DIR needs VDYN_SECURITY_NAME, an identity made there by lab-pki.sh (got '$name')" >&2
      exit 2
    fi
    uri="$uri,$(lab-pki.sh --config "$VDYN_SECURITY_DIR" "$name" | tr -d '\n')"
  fi
  export CYCLONEDDS_URI="$uri"
fi
exec "$@"
