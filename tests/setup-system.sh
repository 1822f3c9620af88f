#!/usr/bin/env bash
# System packages the tests need: Debian's chromium (browser tests, driven by Playwright
# with this executable -- no browser download), nftables + iproute2 (network fault
# injection) and gcc (the C reference of the car link, firmware/carlink/). Installed when
# missing and we are root (as in CI); otherwise say what is missing: the browser and
# firmware tests then fail with that message, the fault tests skip.
set -euo pipefail
missing=()
command -v chromium >/dev/null 2>&1 || missing+=(chromium)
command -v nft >/dev/null 2>&1 || missing+=(nftables)
command -v ip >/dev/null 2>&1 || missing+=(iproute2)
command -v cc >/dev/null 2>&1 || missing+=(gcc libc6-dev)
if [ ${#missing[@]} -eq 0 ]; then
  exit 0
fi
if [ "$(id -u)" -eq 0 ] && command -v apt-get >/dev/null 2>&1; then
  echo "installing ${missing[*]} (apt-get) ..." >&2
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq >/dev/null
  apt-get install -y -qq "${missing[@]}" >/dev/null
else
  echo "note: ${missing[*]} missing and cannot be installed here (not root, or no apt-get)" >&2
fi
