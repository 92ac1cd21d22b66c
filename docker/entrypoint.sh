#!/bin/sh
# The vdyn image's entrypoint: sets CYCLONEDDS_URI from the lab's settings, then runs the command.
#   VDYN_DDS             single (default: one host, loopback), peers (static peers across hosts,
#                        VDYN_PEER_1..4, VDYN_DDS_INTERFACE) or the absolute path of a Cyclone
#                        DDS XML file
#   VDYN_SECURITY        on: DDS Security with the identity VDYN_SECURITY_NAME from the material
#                        lab-pki.sh made in VDYN_SECURITY_DIR (default /security); default off
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
  # peers.xml: an interface given by name replaces Cyclone's own choice.
  if [ -n "${VDYN_DDS_INTERFACE:-}" ]; then export VDYN_DDS_AUTODETERMINE=false; fi
  uri="file://$config"
  case "${VDYN_SECURITY:-off}" in
    off) ;;
    on)
      dir=${VDYN_SECURITY_DIR:-/security}
      name=${VDYN_SECURITY_NAME:-}
      if [ -z "$name" ] || [ ! -r "$dir/$name.pem" ] || [ ! -r "$dir/$name.permissions.p7s" ]; then
        echo "vdyn: VDYN_SECURITY=on needs VDYN_SECURITY_NAME, an identity lab-pki.sh made in $dir (got '$name'; there: $(ls "$dir" 2>/dev/null | grep '\.pem$' | tr '\n' ' '))" >&2
        exit 2
      fi
      uri="$uri,$(lab-pki.sh --config "$dir" "$name" | tr -d '\n')" ;;
    *) echo "vdyn: VDYN_SECURITY='$VDYN_SECURITY': use on or off" >&2; exit 2 ;;
  esac
  export CYCLONEDDS_URI="$uri"
fi
exec "$@"
