#!/usr/bin/env bash
# amps.h at another revision against the working tree, side by side in one run, for changes that
# must not change speed (a refactoring, a re-formatting).
#   bench/compare.sh REV [reps] [bunny]
# Builds bench/factor, bench/harness and bench/haptic from REV's tree and from the working tree
# with the same flags, runs them alternately reps times (default 3) on the bunny (default
# bench/data/bunny20k.1.node; bench/get_bunny.sh makes it) and prints the median over the reps of:
# the numeric factorization and one full solve (bench/factor), the cut step of amps.h on one and
# two threads (bench/harness, 30 cuts, no iterative methods) and the haptic step (bench/haptic).
# Scratch files go to build/compare/.
set -eu
cd "$(dirname "$0")/.."
rev=${1:?usage: bench/compare.sh REV [reps] [bunny]}
reps=${2:-3}
mesh=${3:-bench/data/bunny20k.1.node}
[ -f "$mesh" ] || bash bench/get_bunny.sh
out=build/compare
rm -rf "$out"
mkdir -p "$out/old" "$out/new"
git archive "$rev" amps.h bench | tar -x -C "$out/old"
cp amps.h "$out/new/"
cp -r bench "$out/new/"
CC=${CC:-cc}
FLAGS="-std=c99 -O2 -fopenmp -I/usr/include/suitesparse"
for t in old new; do
  for p in factor:-lcholmod harness:"-lcholmod -lumfpack" haptic:; do
    name=${p%%:*}
    # shellcheck disable=SC2086
    $CC $FLAGS -I"$out/$t" -o "$out/$t/$name" "$out/$t/bench/$name.c" ${p#*:} -lm
  done
done
for r in $(seq "$reps"); do
  for t in old new; do
    echo "rep $r: $t"
    "$out/$t/factor" "$mesh" "$out/$t/factor.csv" > /dev/null
    BENCH_AMPS=p1,p2 BENCH_ITER=0 "$out/$t/harness" "$mesh" cut 30 30 "$out/$t/h_$r.csv" > /dev/null
    "$out/$t/haptic" "$mesh" 500 10 "$out/$t/haptic.csv" > /dev/null
  done
done
# median of column c (by name) over the rows of a CSV that pass a filter
med() { # file column [awk condition]
  awk -F, -v col="$2" "NR == 1 { for (i = 1; i <= NF; i++) if (\$i == col) c = i; next } ${3:-1} { print \$c }" "$1" |
    sort -g | awk '{ v[NR] = $1 } END { if (NR) print v[int((NR + 1) / 2)]; else print "-" }'
}
printf '%-34s %14s %14s %8s\n' "median over $reps reps ($(basename "$mesh"))" "$rev" "working tree" "new/old"
row() { # label old new
  printf '%-34s %14.4g %14.4g %8.3f\n' "$1" "$2" "$3" "$(awk -v a="$2" -v b="$3" 'BEGIN { print b / a }')"
}
row "numeric factorization (s)" "$(med $out/old/factor.csv t_factor)" "$(med $out/new/factor.csv t_factor)"
row "full solve (s)" "$(med $out/old/factor.csv t_solve)" "$(med $out/new/factor.csv t_solve)"
for m in p1 p2; do
  cat $out/old/h_*.csv > $out/old/h.csv
  cat $out/new/h_*.csv > $out/new/h.csv
  row "cut step, amps.h $m (s)" "$(med $out/old/h.csv time "\$2 == \"amps_$m\"")" \
    "$(med $out/new/h.csv time "\$2 == \"amps_$m\"")"
done
row "haptic step (ms)" "$(med $out/old/haptic.csv median_ms)" "$(med $out/new/haptic.csv median_ms)"
