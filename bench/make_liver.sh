#!/usr/bin/env bash
# A liver-like model for bench/frameloop: a bumpy ellipsoid (semi-axes 1.6 x 1.0 x 0.7, radius
# modulated by 1 + 0.08 sin(3 theta) cos(2 phi) + 0.05 sin(5 phi)), its surface a latitude-
# longitude triangulation (20 x 40), tetrahedralized by TetGen (quality 1.5, volume 2e-3):
# about 10,000 nodes. Writes bench/data/liver.poly and bench/data/liver.1.{node,ele}.
set -eu
data="$(cd "$(dirname "$0")" && pwd)/data"
mkdir -p "$data"
command -v tetgen >/dev/null || { echo "make_liver: needs tetgen (apt-get install -y tetgen)"; exit 1; }
[ -f "$data/liver.1.ele" ] && exit 0
awk -v nlat=20 -v nlon=40 'BEGIN {
  pi = 3.14159265358979; nv = 2 + nlat * nlon
  printf "# bumpy ellipsoid (bench/make_liver.sh)\n%d 3 0 0\n", nv
  for (i = 0; i <= nlat + 1; i++) {
    th = pi * i / (nlat + 1)
    for (j = 0; j < ((i == 0 || i == nlat + 1) ? 1 : nlon); j++) {
      ph = 2 * pi * j / nlon
      r = 1 + 0.08 * sin(3 * th) * cos(2 * ph) + 0.05 * sin(5 * ph) * sin(th)
      printf "%d %.9f %.9f %.9f\n", k++, 1.6 * r * sin(th) * cos(ph), 1.0 * r * sin(th) * sin(ph), 0.7 * r * cos(th)
    }
  }
  nf = 2 * nlon + 2 * nlon * (nlat - 1)
  printf "%d 0\n", nf
  for (j = 0; j < nlon; j++) {
    printf "1\n3 0 %d %d\n", 1 + j, 1 + (j + 1) % nlon
    s = nv - 1; b = 1 + (nlat - 1) * nlon
    printf "1\n3 %d %d %d\n", s, b + (j + 1) % nlon, b + j
  }
  for (i = 0; i < nlat - 1; i++)
    for (j = 0; j < nlon; j++) {
      a = 1 + i * nlon + j; b = 1 + i * nlon + (j + 1) % nlon; c = a + nlon; d = b + nlon
      printf "1\n3 %d %d %d\n1\n3 %d %d %d\n", a, c, b, b, c, d
    }
  printf "0\n0\n"
}' > "$data/liver.poly"
tetgen -pq1.5a0.002 -Q "$data/liver.poly" >/dev/null
rm -f "$data/liver.1.face" "$data/liver.1.edge" "$data/liver.1.smesh"
head -1 "$data/liver.1.node"
