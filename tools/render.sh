#!/usr/bin/env bash
# Renders a surface file of amps_replay --surface (deformed boundary triangles, cut faces
# included) as a PNG with gnuplot: a top view of the upper faces, edges coloured by |u|, so the
# opened cut shows as a gap. Skipped, with a note, when gnuplot is not installed.
set -u
in=$1; out=$2
if ! command -v gnuplot >/dev/null; then
  echo "render: gnuplot not installed, no PNG (sudo apt-get install -y gnuplot-nox)"; exit 0
fi
zmax=$(awk 'NF == 4 && ($3 > m || m == "") { m = $3 } END { print m }' "$in")
zmin=$(awk 'NF == 4 && ($3 < m || m == "") { m = $3 } END { print m }' "$in")
# keep the triangles whose three corners lie in the top 3% of the height
awk -v lim="$(awk -v a="$zmin" -v b="$zmax" 'BEGIN { print b - 0.03 * (b - a) }')" '
  NF == 4 { buf[++n] = $0; if ($3 < lim) low = 1; next }
  { if (n == 4 && !low) { for (i = 1; i <= 4; i++) print buf[i]; print "" } n = 0; low = 0 }' "$in" > "$in.top"
gnuplot <<GP
set terminal pngcairo size 1000,900 noenhanced
set output "$out"
set size ratio -1
unset key
set palette rgb 33,13,10
set cblabel "|displacement|"
set xlabel "x (deformed)"; set ylabel "y (deformed)"
set title "top view after the cut: the incision opens where the pins pull"
plot "$in.top" using 1:2:4 with lines lw 1.2 lc palette
GP
rm -f "$in.top"
[ -f "$out" ] && echo "picture: $out"
