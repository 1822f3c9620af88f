#!/usr/bin/env bash
# Make a fleet certificate authority and one certificate per car (and the operator's),
# for Zenoh's mutual TLS. Run it on a trusted machine, copy each car its own key, its
# certificate and the CA certificate, and keep the CA key offline. Never commit the output.
#
#   deploy/tls/make-certs.sh OUT_DIR CAR_ID [CAR_ID ...]
#
# Writes OUT_DIR/ca.pem (+ ca.key), and per car carN.pem / carN.key (common name "carN");
# also operator.pem / operator.key (common name "operator": trustfg go, dashboard, record).
# Every certificate also names 127.0.0.1 and localhost, for tests on one machine.
set -euo pipefail
out=${1:?usage: make-certs.sh OUT_DIR CAR_ID...}
shift
[ $# -gt 0 ] || { echo "usage: make-certs.sh OUT_DIR CAR_ID..." >&2; exit 2; }
mkdir -p "$out"
cd "$out"
umask 077
openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:P-256 -nodes -days 365 \
  -subj "/CN=trustfg fleet CA" -keyout ca.key -out ca.pem 2>/dev/null
issue() {
  local name=$1
  openssl req -newkey ec -pkeyopt ec_paramgen_curve:P-256 -nodes -subj "/CN=$name" \
    -keyout "$name.key" -out "$name.csr" 2>/dev/null
  printf 'subjectAltName=DNS:%s,DNS:localhost,IP:127.0.0.1\nextendedKeyUsage=serverAuth,clientAuth\n' "$name" > "$name.ext"
  openssl x509 -req -in "$name.csr" -CA ca.pem -CAkey ca.key -CAcreateserial -days 365 \
    -extfile "$name.ext" -out "$name.pem" 2>/dev/null
  rm -f "$name.csr" "$name.ext"
}
for id in "$@"; do
  case $id in (*[!0-9]*|'') echo "car ids are numbers, got '$id'" >&2; exit 2;; esac
  issue "car$id"
done
issue operator
echo "wrote $(ls "$out" | tr '\n' ' ')" >&2
