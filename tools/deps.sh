#!/usr/bin/env bash
# Makes sure what amps.h's tests (or, with "bench", benchmarks; with "demo", the demo) need is
# there. As root it installs what is missing from Debian; otherwise it names the packages and
# the command, and fails.
set -u
pkgs="build-essential libsuitesparse-dev"
cmds=""
case "${1:-}" in
  bench) pkgs="$pkgs libmetis-dev libopenblas0-pthread"; cmds="tetgen:tetgen gmsh:gmsh gnuplot:gnuplot-nox node:nodejs npm:npm" ;;
  demo) pkgs="build-essential"; cmds="gnuplot:gnuplot-nox" ;;
esac
missing=""
for p in $pkgs; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing="$missing $p"
done
for c in $cmds; do
  command -v "${c%%:*}" >/dev/null 2>&1 || missing="$missing ${c#*:}"
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
[ "${1:-}" = demo ] && exit 0
exit 1
