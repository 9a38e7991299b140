#!/bin/sh
# Generates a test PKI and signed DDS Security documents for pvcgel on one
# domain, and Cyclone DDS configurations (loopback only) that use them:
#   make-test-pki.sh OUTDIR [DOMAIN]
# OUTDIR/daemon.xml and OUTDIR/client.xml are the `[dds] config` of pvcgeld and
# the `--dds-config` of pvcgel; OUTDIR/observer.xml is a read-only client
# (status, watch, record; its commands are refused by access control). For a lab: replace the CA with your own, keep
# private keys readable only by their user, and set the interface in the XML.
# Test certificates only: one CA signs identities and permissions, 1-day validity.
set -eu
out=${1:?usage: make-test-pki.sh OUTDIR [DOMAIN]}
domain=${2:-0}
plugins=${PVCGEL_DDS_SECURITY_PLUGINS:-/usr/lib/x86_64-linux-gnu/libddsc0debian}
mkdir -p "$out"
cd "$out"
umask 077

openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -days 1 \
  -subj "/C=DE/O=pvcgel test/CN=pvcgel test CA" -keyout ca.key -out ca.pem 2>/dev/null
for who in daemon client observer; do
  openssl req -new -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes \
    -subj "/C=DE/O=pvcgel test/CN=pvcgel $who" -keyout $who.key -out $who.csr 2>/dev/null
  openssl x509 -req -in $who.csr -CA ca.pem -CAkey ca.key -CAcreateserial -days 1 -out $who.pem 2>/dev/null
done

cat > governance.xml <<XML
<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
     xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_governance.xsd">
  <domain_access_rules>
    <domain_rule>
      <domains><id>$domain</id></domains>
      <allow_unauthenticated_participants>false</allow_unauthenticated_participants>
      <enable_join_access_control>true</enable_join_access_control>
      <discovery_protection_kind>ENCRYPT</discovery_protection_kind>
      <liveliness_protection_kind>ENCRYPT</liveliness_protection_kind>
      <rtps_protection_kind>ENCRYPT</rtps_protection_kind>
      <topic_access_rules>
        <topic_rule>
          <topic_expression>pvcgel_v1_*</topic_expression>
          <enable_discovery_protection>true</enable_discovery_protection>
          <enable_liveliness_protection>true</enable_liveliness_protection>
          <enable_read_access_control>true</enable_read_access_control>
          <enable_write_access_control>true</enable_write_access_control>
          <metadata_protection_kind>ENCRYPT</metadata_protection_kind>
          <data_protection_kind>ENCRYPT</data_protection_kind>
        </topic_rule>
      </topic_access_rules>
    </domain_rule>
  </domain_access_rules>
</dds>
XML

grant() {  # name, subject, publish topics, subscribe topics
  pub=""; for t in $3; do pub="$pub<topic>$t</topic>"; done
  sub=""; for t in $4; do sub="$sub<topic>$t</topic>"; done
  [ -n "$pub" ] && pub="<publish><topics>$pub</topics></publish>"
  cat <<XML
    <grant name="$1">
      <subject_name>$2</subject_name>
      <validity><not_before>2020-01-01T00:00:00</not_before><not_after>2100-01-01T00:00:00</not_after></validity>
      <allow_rule>
        <domains><id>$domain</id></domains>
        $pub
        <subscribe><topics>$sub</topics></subscribe>
      </allow_rule>
      <default>DENY</default>
    </grant>
XML
}
{
  echo '<?xml version="1.0" encoding="UTF-8"?>'
  echo '<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_permissions.xsd">'
  echo '  <permissions>'
  grant daemon "CN=pvcgel daemon,O=pvcgel test,C=DE" \
    "pvcgel_v1_Telemetry pvcgel_v1_CommandReply pvcgel_v1_Status" "pvcgel_v1_Trajectory pvcgel_v1_Command"
  grant client "CN=pvcgel client,O=pvcgel test,C=DE" \
    "pvcgel_v1_Trajectory pvcgel_v1_Command" "pvcgel_v1_Telemetry pvcgel_v1_CommandReply pvcgel_v1_Status"
  # Read-only: may watch and record, may not command the rig.
  grant observer "CN=pvcgel observer,O=pvcgel test,C=DE" "" "pvcgel_v1_Telemetry pvcgel_v1_CommandReply pvcgel_v1_Status"
  echo '  </permissions>'
  echo '</dds>'
} > permissions.xml

openssl smime -sign -in governance.xml -text -out governance.p7s -signer ca.pem -inkey ca.key
openssl smime -sign -in permissions.xml -text -out permissions.p7s -signer ca.pem -inkey ca.key

here=$(pwd)
for who in daemon client observer; do
  cat > $who.xml <<XML
<?xml version="1.0" encoding="UTF-8" ?>
<!-- Loopback only (as config/cyclonedds-loopback.xml), plus DDS Security for the $who. -->
<CycloneDDS xmlns="https://cdds.io/config">
  <Domain Id="any">
    <General>
      <Interfaces><NetworkInterface name="lo" /></Interfaces>
      <AllowMulticast>false</AllowMulticast>
    </General>
    <Discovery>
      <ParticipantIndex>auto</ParticipantIndex>
      <MaxAutoParticipantIndex>20</MaxAutoParticipantIndex>
      <Peers><Peer address="127.0.0.1" /></Peers>
    </Discovery>
    <Security>
      <Authentication>
        <Library path="$plugins/libdds_security_auth.so" initFunction="init_authentication" finalizeFunction="finalize_authentication" />
        <IdentityCA>file:$here/ca.pem</IdentityCA>
        <IdentityCertificate>file:$here/$who.pem</IdentityCertificate>
        <PrivateKey>file:$here/$who.key</PrivateKey>
      </Authentication>
      <AccessControl>
        <Library path="$plugins/libdds_security_ac.so" initFunction="init_access_control" finalizeFunction="finalize_access_control" />
        <PermissionsCA>file:$here/ca.pem</PermissionsCA>
        <Governance>file:$here/governance.p7s</Governance>
        <Permissions>file:$here/permissions.p7s</Permissions>
      </AccessControl>
      <Cryptographic>
        <Library path="$plugins/libdds_security_crypto.so" initFunction="init_crypto" finalizeFunction="finalize_crypto" />
      </Cryptographic>
    </Security>
  </Domain>
</CycloneDDS>
XML
done
chmod 644 ./*.xml ./*.pem ./*.p7s
echo "test PKI and secured Cyclone DDS configurations in $here (daemon.xml, client.xml; domain $domain)"
