#!/usr/bin/env bash
# Makes sure the Debian packages amps.h's tests (or, with "bench", benchmarks) need are there.
# As root it installs what is missing; otherwise it names the packages and the command, and fails.
set -u
pkgs="build-essential libsuitesparse-dev"
[ "${1:-}" = bench ] && pkgs="$pkgs libmetis-dev libopenblas0-pthread tetgen gnuplot-nox nodejs npm"
missing=""
for p in $pkgs; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing="$missing $p"
done
[ -z "$missing" ] && exit 0
if [ "$(id -u)" = 0 ]; then
  echo "installing:$missing"
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq && apt-get install -y -qq $missing >/dev/null && exit 0
  echo "apt-get install failed"; exit 1
fi
echo "missing Debian packages:$missing"
echo "install them with:  sudo apt-get update && sudo apt-get install -y$missing"
exit 1
