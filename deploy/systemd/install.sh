#!/usr/bin/env bash
# Install the car processes as systemd services on a car computer (run as root).
#
#   deploy/systemd/install.sh --venv DIR --user NAME --config FILE [--dry-run]
#
#   --venv DIR     the virtual environment trustfg is installed in (DIR/bin/trustfg)
#   --user NAME    the account the car processes run as (created if missing; no login)
#   --config FILE  the fleet config they run (written to /etc/trustfg/car.env as
#                  TRUSTFG_CONFIG; change it there later, then systemctl restart)
#   --dry-run      print the unit and the environment file instead of installing them
#
# Then: systemctl enable --now trustfg-car@N   (N: this computer's car id)
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
venv="" user="" config="" dry=0
while [ $# -gt 0 ]; do
  case $1 in
    --venv) venv=${2:?--venv needs a folder}; shift 2;;
    --user) user=${2:?--user needs a name}; shift 2;;
    --config) config=${2:?--config needs a file}; shift 2;;
    --dry-run) dry=1; shift;;
    *) echo "install.sh: unknown argument '$1' (see the header of this script)" >&2; exit 2;;
  esac
done
[ -n "$venv" ] && [ -n "$user" ] && [ -n "$config" ] || {
  echo "install.sh: --venv, --user and --config are required (see the header of this script)" >&2; exit 2; }
case $venv$config in (*[[:space:]]*) echo "install.sh: paths with spaces are not supported" >&2; exit 2;; esac
venv=$(cd "$venv" 2>/dev/null && pwd) || { echo "install.sh: no folder $venv" >&2; exit 2; }
[ -x "$venv/bin/trustfg" ] || { echo "install.sh: $venv/bin/trustfg not found (pip install trustfg there first)" >&2; exit 2; }
[ -f "$config" ] || { echo "install.sh: no config file $config" >&2; exit 2; }
config=$(realpath "$config")
unit=$(sed -e "s|@VENV@|$venv|g" -e "s|@USER@|$user|g" "$here/trustfg-car@.service")
env="TRUSTFG_CONFIG=$config"
if [ $dry -eq 1 ]; then
  printf '%s\n' "$unit"
  printf '# /etc/trustfg/car.env\n%s\n' "$env"
  exit 0
fi
[ "$(id -u)" -eq 0 ] || { echo "install.sh: run as root (it writes /etc/systemd/system)" >&2; exit 2; }
id "$user" >/dev/null 2>&1 || useradd --system --no-create-home --shell /usr/sbin/nologin "$user"
install -d -m 0755 /etc/trustfg
printf '%s\n' "$env" > /etc/trustfg/car.env
printf '%s\n' "$unit" > /etc/systemd/system/trustfg-car@.service
systemctl daemon-reload
echo "installed trustfg-car@.service (runs $venv/bin/trustfg as $user with $config)"
echo "its key files in /etc/trustfg must belong to $user (as the lines trustfg keys prints install them)"
echo "next: systemctl enable --now trustfg-car@N (N: this computer's car id)"
