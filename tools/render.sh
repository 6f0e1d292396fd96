#!/usr/bin/env bash
# Renders a surface file of amps_replay --surface to a PNG with gnuplot (skipped without it).
set -u
in=$1; out=$2
if ! command -v gnuplot >/dev/null; then
  echo "render: gnuplot not installed, no PNG (sudo apt-get install -y gnuplot-nox)"; exit 0
fi
gnuplot <<GP
set terminal pngcairo size 1000,800 noenhanced
set output "$out"
set view 35, 25, 1.3
set view equal xyz
unset border; unset tics; unset key
set palette rgb 33,13,10
set cblabel "|displacement|"
set title "deformed surface after the cut (cut faces open where the pins pull)"
set pm3d depthorder border lc rgb "#303030" lw 0.3
splot "$in" using 1:2:3:4 with polygons fillcolor palette
GP
[ -f "$out" ] && echo "picture: $out"
