#!/usr/bin/env bash
# Creates a self-signed site CA and the certificates AVE's channels use (issue 8), with the openssl
# command-line tool:
#   ca.pem / ca.key          the site CA (keep ca.key offline in production)
#   server.pem / server.key  ave-server, for the names in AVE_CERT_NAMES (default localhost,127.0.0.1)
#   sensor-<id>.pem / .key   a client certificate per sensor node (mutual TLS), CN = <id>
#   viewer.pem / viewer.key  a client certificate for viewers and administrators (optional use)
# Usage: deploy/make-certs.sh OUT_DIR [SENSOR_ID ...]     (existing files in OUT_DIR are replaced)
set -euo pipefail
out=${1:?usage: make-certs.sh OUT_DIR [SENSOR_ID ...]}
shift
sensors=("$@")
[ ${#sensors[@]} -gt 0 ] || sensors=(cam1 cam2 cam3)
names=${AVE_CERT_NAMES:-localhost,127.0.0.1}
days=${AVE_CERT_DAYS:-825}
mkdir -p "$out"
cd "$out"
umask 077

san=""
IFS=, read -ra parts <<<"$names"
for n in "${parts[@]}"; do
  if [[ $n =~ ^[0-9.]+$ || $n == *:* ]]; then san+="IP:$n,"; else san+="DNS:$n,"; fi
done
san=${san%,}

# EC P-256 keys: small and fast to handshake.
key() { openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:P-256 -out "$1" 2>/dev/null; }

key ca.key
openssl req -x509 -new -key ca.key -sha256 -days "$days" -subj "/O=AVE/CN=AVE site CA" \
  -addext "basicConstraints=critical,CA:TRUE" -addext "keyUsage=critical,keyCertSign,cRLSign" -out ca.pem

# sign NAME CN EXTENSIONS
sign() {
  local name=$1 cn=$2 ext=$3
  key "$name.key"
  openssl req -new -key "$name.key" -subj "/O=AVE/CN=$cn" -out "$name.csr"
  printf '%s\n' "$ext" >"$name.ext"
  openssl x509 -req -in "$name.csr" -CA ca.pem -CAkey ca.key -CAcreateserial -sha256 -days "$days" \
    -extfile "$name.ext" -out "$name.pem" 2>/dev/null
  rm -f "$name.csr" "$name.ext"
}

sign server "${parts[0]}" "basicConstraints=CA:FALSE
keyUsage=critical,digitalSignature,keyEncipherment
extendedKeyUsage=serverAuth
subjectAltName=$san"
for id in "${sensors[@]}"; do
  sign "sensor-$id" "$id" "basicConstraints=CA:FALSE
keyUsage=critical,digitalSignature
extendedKeyUsage=clientAuth"
done
sign viewer viewer "basicConstraints=CA:FALSE
keyUsage=critical,digitalSignature
extendedKeyUsage=clientAuth"
rm -f ca.srl
chmod 644 ./*.pem
echo "make-certs: CA, server ($names) and client certificates for ${sensors[*]} and viewer in $out"
