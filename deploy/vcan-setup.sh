#!/usr/bin/env bash
# Create (or with --delete remove) the virtual CAN interfaces vcan0 ... vcan{N-1} on a kernel
# with SocketCAN (laptops, robots), for the hardware-in-the-loop tests. Run as root.
#   deploy/vcan-setup.sh [N]          N defaults to 9 (robots 1..8 use vcan1..vcan8)
#   deploy/vcan-setup.sh --delete [N]
set -euo pipefail
delete=0
if [ "${1:-}" = "-h" ] || [ "${1:-}" = "--help" ]; then
  sed -n '2,5p' "$0" | sed 's/^# \{0,1\}//'
  exit 0
fi
if [ "${1:-}" = "--delete" ]; then delete=1; shift; fi
count="${1:-9}"
case "$count" in ''|*[!0-9]*) echo "vcan-setup: expected a number of interfaces, got '$count'" >&2; exit 2;; esac
if [ "$(id -u)" -ne 0 ]; then echo "vcan-setup: run as root (sudo $0 $*)" >&2; exit 2; fi
if [ "$delete" -eq 0 ]; then
  modprobe vcan || { echo "vcan-setup: no vcan module in this kernel; use 'heft vcan' (User-Mode Linux) instead" >&2; exit 1; }
fi
for ((i = 0; i < count; i++)); do
  name="vcan$i"
  if [ "$delete" -eq 1 ]; then
    if ip link show "$name" >/dev/null 2>&1; then
      ip link delete "$name" || { echo "vcan-setup: cannot delete $name" >&2; exit 1; }
      echo "deleted $name"
    fi
  elif ! ip link show "$name" >/dev/null 2>&1; then
    ip link add dev "$name" type vcan || { echo "vcan-setup: cannot create $name" >&2; exit 1; }
    ip link set "$name" up || { echo "vcan-setup: cannot bring $name up" >&2; exit 1; }
    echo "created $name"
  fi
done
