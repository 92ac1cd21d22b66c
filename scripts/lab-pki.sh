#!/usr/bin/env bash
# Makes a lab's DDS Security material (Cyclone DDS's built-in plugins: PKI authentication, access
# control, AES-GCM encryption): a lab CA, an identity per participant, the governance (who may do
# what on the vdyn topics: everything authenticated, access-controlled, data encrypted) and a
# signed permissions document per participant by its role.
#
#   scripts/lab-pki.sh OUT_DIR NAME:ROLE [NAME:ROLE ...]
#
# Roles (docs/topics.md, "Only permitted participants drive"):
#   server    runs vehicles: reads input and requests, writes states, params, world, events, ...
#   rig       drives: writes driver input and control requests, reads the rest
#   operator  changes parameters: writes control requests, reads everything (a viewer's panel)
#   observer  reads everything, writes nothing (recorders, viewers without the panel)
#   player    replays recordings: writes states, params, world, diagnostics and driver input
# Then `scripts/lab-pki.sh --config OUT_DIR NAME` prints the CYCLONEDDS_URI fragment for NAME.
set -euo pipefail

plugins=/usr/lib/x86_64-linux-gnu/libddsc0debian
if [ "${1:-}" = "--config" ]; then
  dir=$(cd "$2" && pwd)
  name=$3
  cat <<XML
<Security>
  <Authentication>
    <Library initFunction="init_authentication" finalizeFunction="finalize_authentication" path="$plugins/libdds_security_auth.so"/>
    <IdentityCA>file:$dir/ca.pem</IdentityCA>
    <IdentityCertificate>file:$dir/$name.pem</IdentityCertificate>
    <PrivateKey>file:$dir/$name.key</PrivateKey>
  </Authentication>
  <Cryptographic>
    <Library initFunction="init_crypto" finalizeFunction="finalize_crypto" path="$plugins/libdds_security_crypto.so"/>
  </Cryptographic>
  <AccessControl>
    <Library initFunction="init_access_control" finalizeFunction="finalize_access_control" path="$plugins/libdds_security_ac.so"/>
    <PermissionsCA>file:$dir/ca.pem</PermissionsCA>
    <Governance>file:$dir/governance.p7s</Governance>
    <Permissions>file:$dir/$name.permissions.p7s</Permissions>
  </AccessControl>
</Security>
XML
  exit 0
fi

if [ $# -lt 2 ]; then
  echo "usage: $0 OUT_DIR NAME:ROLE [NAME:ROLE ...]   |   $0 --config OUT_DIR NAME" >&2
  exit 2
fi
out=$1
shift
mkdir -p "$out"
cd "$out"
subject() { echo "/O=vdyn lab/CN=$1"; }

# The lab CA: it signs the identities, the governance and the permissions.
if [ ! -f ca.pem ]; then
  openssl req -x509 -newkey rsa:2048 -nodes -sha256 -days 3650 -keyout ca.key -out ca.pem \
    -subj "$(subject "vdyn lab CA")" 2>/dev/null
fi

cat > governance.xml <<'XML'
<?xml version="1.0" encoding="utf-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" xsi:noNamespaceSchemaLocation="https://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_governance.xsd">
  <domain_access_rules>
    <domain_rule>
      <domains><id_range><min>0</min><max>230</max></id_range></domains>
      <allow_unauthenticated_participants>false</allow_unauthenticated_participants>
      <enable_join_access_control>true</enable_join_access_control>
      <discovery_protection_kind>SIGN</discovery_protection_kind>
      <liveliness_protection_kind>SIGN</liveliness_protection_kind>
      <rtps_protection_kind>NONE</rtps_protection_kind>
      <topic_access_rules>
        <topic_rule>
          <topic_expression>vdyn/*</topic_expression>
          <enable_discovery_protection>true</enable_discovery_protection>
          <enable_liveliness_protection>true</enable_liveliness_protection>
          <enable_read_access_control>true</enable_read_access_control>
          <enable_write_access_control>true</enable_write_access_control>
          <metadata_protection_kind>SIGN</metadata_protection_kind>
          <data_protection_kind>ENCRYPT</data_protection_kind>
        </topic_rule>
      </topic_access_rules>
    </domain_rule>
  </domain_access_rules>
</dds>
XML
openssl smime -sign -in governance.xml -text -out governance.p7s -signer ca.pem -inkey ca.key

topics() { for t in "$@"; do printf '<topic>vdyn/%s</topic>' "$t"; done; }
# The default partition, and each vehicle's own states partition (docs/topics.md, "Partitions"):
# without it a client that follows one vehicle would fall back to reading every vehicle's states.
parts='<partitions><partition></partition><partition>vdyn.vehicle.*</partition></partitions>'

all=(state states input control control_reply params world events diagnostics)
for spec in "$@"; do
  name=${spec%%:*}
  role=${spec#*:}
  case "$role" in
    server) pub=(state states params world events diagnostics control_reply)
            sub=(input control world diagnostics state) ;;
    rig) pub=(input control); sub=(state params world control_reply diagnostics) ;;
    operator) pub=(control); sub=("${all[@]}") ;;
    observer) pub=(); sub=("${all[@]}") ;;
    player) pub=(state states params world diagnostics input events); sub=(control "${all[@]}") ;;
    *) echo "$0: unknown role '$role' for $name (server, rig, operator, observer, player)" >&2; exit 2 ;;
  esac
  if [ ! -f "$name.pem" ]; then
    openssl req -newkey rsa:2048 -nodes -sha256 -keyout "$name.key" -out "$name.csr" \
      -subj "$(subject "$name")" 2>/dev/null
    openssl x509 -req -in "$name.csr" -CA ca.pem -CAkey ca.key -CAcreateserial -days 3650 \
      -sha256 -out "$name.pem" 2>/dev/null
    rm -f "$name.csr"
  fi
  subject_name=$(openssl x509 -noout -subject -nameopt RFC2253 -in "$name.pem" | sed 's/^subject=//')
  publish=""
  [ ${#pub[@]} -gt 0 ] && publish="<publish><topics>$(topics "${pub[@]}")</topics>$parts</publish>"
  cat > "$name.permissions.xml" <<XML
<?xml version="1.0" encoding="utf-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" xsi:noNamespaceSchemaLocation="https://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_permissions.xsd">
  <permissions>
    <grant name="$name-$role">
      <subject_name>$subject_name</subject_name>
      <validity><not_before>2020-01-01T00:00:00</not_before><not_after>2120-01-01T00:00:00</not_after></validity>
      <allow_rule>
        <domains><id_range><min>0</min><max>230</max></id_range></domains>
        $publish
        <subscribe><topics>$(topics "${sub[@]}")</topics>$parts</subscribe>
      </allow_rule>
      <default>DENY</default>
    </grant>
  </permissions>
</dds>
XML
  openssl smime -sign -in "$name.permissions.xml" -text -out "$name.permissions.p7s" -signer ca.pem -inkey ca.key
  echo "$name: $role"
done
