#!/usr/bin/env bash
# Set-up for the emulated-board (PIL) route on Debian bookworm, idempotent and quiet when done:
#  - qemu-system-arm >= 10 (netduinoplus2 with a working USART1 and TCG plugins; bookworm's 7.2
#    lacks what is needed) from bookworm-backports, on the same mirror as apt's existing entries;
#  - the TCG plugin that counts instructions between two marker functions
#    (tools/qemu-plugin/insn_between.so), rebuilt with gcc when missing or older than its source.
set -euo pipefail
cd "$(dirname "$0")/.."

qemu_major() {
  command -v qemu-system-arm >/dev/null 2>&1 || { echo 0; return; }
  qemu-system-arm --version | sed -n 's/^QEMU emulator version \([0-9]*\).*/\1/p' | head -n1
}

if [ "$(qemu_major)" -lt 10 ]; then
  sudo=""
  [ "$(id -u)" -eq 0 ] || sudo="sudo"
  list=/etc/apt/sources.list.d/bookworm-backports.sources
  if ! grep -rqs 'bookworm-backports' /etc/apt/sources.list /etc/apt/sources.list.d/ 2>/dev/null; then
    # The mirror of the existing `bookworm` entry (deb822 .sources first, then one-line lists).
    mirror=$(awk '/^URIs:/ {u = $2} /^Suites:/ {for (i = 2; i <= NF; i++) if ($i == "bookworm") {print u; exit}}' \
      /etc/apt/sources.list.d/*.sources 2>/dev/null || true)
    if [ -z "$mirror" ]; then
      mirror=$(awk '$1 == "deb" && $3 == "bookworm" {print $2; exit}' /etc/apt/sources.list /etc/apt/sources.list.d/*.list 2>/dev/null || true)
    fi
    mirror=${mirror:-http://deb.debian.org/debian}
    printf 'Types: deb\nURIs: %s\nSuites: bookworm-backports\nComponents: main\nSigned-By: /usr/share/keyrings/debian-archive-keyring.gpg\n' \
      "$mirror" | $sudo tee "$list" >/dev/null
  fi
  echo "== installing qemu-system-arm from bookworm-backports"
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq -t bookworm-backports --no-install-recommends qemu-system-arm >/dev/null
  if [ "$(qemu_major)" -lt 10 ]; then
    echo "setup-qemu: qemu-system-arm is still older than 10: $(qemu-system-arm --version | head -n1)" >&2
    exit 1
  fi
fi

plugin_src=tools/qemu-plugin/insn_between.c
plugin_so=tools/qemu-plugin/insn_between.so
if [ -f "$plugin_src" ] && { [ ! -f "$plugin_so" ] || [ "$plugin_src" -nt "$plugin_so" ]; }; then
  gcc -O2 -Wall -Wextra -shared -fPIC -o "$plugin_so" "$plugin_src"
fi
