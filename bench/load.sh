#!/usr/bin/env bash
# amps.h under load (bench/load.c): median step times of each configuration under each load,
# and the ratios of issue 17's targets, measured in one run.
#   bench/load.sh [full|quick] [outdir]   (full: bench/out/load.csv; quick: build/bench/load_quick)
#   bench/load.sh summary [outdir]        the table again from outdir/load.csv (a run cut short)
# Loads, each started before and stopped after its runs:
#   idle; spin1, spin2: one / two `yes > /dev/null` processes; tick: bench/load tick (a 1 kHz
#   loop working 0.3 ms per period, a haptic thread).
# Configurations: 1 (one thread), thr2 (two participants on amps' own workers: the default on 2
# cores), omp2 (two OpenMP threads, AMPS_BACKEND_OPENMP), jobs2 (two workers of examples/jobs.h
# through ctx->enqueue_task/finish_task). Cases: the cut and
# deformation sequences of bench/harness on bunny20k and bunny50k (amps.h alone, bench/load run),
# 12 steps each, and a bunny incision (bunny9k, 20 cuts) through tools/amps_replay (its
# --jobs option for jobs2). The configurations of a case alternate within each load, so drift of
# the machine hits them alike; the whole process set is pinned to cpus 0-1 (taskset).
# Output: $out/load.csv (case,load,conf,step,time), $out/load_summary.txt (medians, ratios).
set -u
cd "$(dirname "$0")/.."
mode=${1:-full}
out=${2:-}
if [ "$mode" = summary ]; then # bench/load.sh summary <dir>: the table of <dir>/load.csv again
  only_summary=1
  mode=full
fi
[ -z "$out" ] && { [ "$mode" = quick ] && out=build/bench/load_quick || out=bench/out; }
mkdir -p "$out" build/bench
CC=${CC:-cc}
FLAGS="-std=c99 -O2 -fopenmp -I. -I/usr/include/suitesparse -Wall -Wextra -pedantic -Werror"
$CC $FLAGS -o build/bench/load bench/load.c -lpthread -lm || exit 1
$CC $FLAGS -o build/bench/amps_replay tools/amps_replay.c -lpthread -lm || exit 1
TS="taskset -c 0,1"
command -v taskset > /dev/null || TS=""
csv=$out/load.csv
if [ "$mode" = quick ]; then
  runs="brick:6:cut:4 brick:6:deform:4"
  scn=$PWD/examples/brick_incision.scn
  loads="idle spin2"
else
  bash bench/get_bunny.sh || exit 1
  d=bench/data
  if [ ! -f $d/bunny9k.1.node ]; then # about 9,800 nodes
    cp $d/bunny.poly $d/bunny9k.poly && (cd $d && tetgen -pq1.5a0.2 -Q bunny9k.poly > /dev/null) || exit 1
    rm -f $d/bunny9k.1.face $d/bunny9k.1.edge $d/bunny9k.1.smesh
  fi
  build/bench/load scn $d/bunny9k.1.node 24 > $d/bunny9k_incision.scn || exit 1
  runs="$d/bunny20k.1.node:cut:12 $d/bunny50k.1.node:cut:12 $d/bunny20k.1.node:deform:12 $d/bunny50k.1.node:deform:12"
  scn=$PWD/$d/bunny9k_incision.scn
  loads="idle spin1 spin2 tick"
fi
pids=""
start_load() {
  pids=""
  case $1 in
    spin1) $TS yes > /dev/null & pids=$! ;;
    spin2) $TS yes > /dev/null & pids=$!; $TS yes > /dev/null & pids="$pids $!" ;;
    tick) $TS build/bench/load tick & pids=$! ;;
  esac
  sleep 0.5
}
stop_load() {
  local p
  for p in $pids; do kill "$p" 2> /dev/null; wait "$p" 2> /dev/null; done
  pids=""
}
trap 'stop_load' EXIT
# medians per case, load, conf; the target ratios
summary() {
awk -F, 'NR > 1 { k = $1 "," $2 "," $3; v[k, ++n[k]] = $5; keys[k] = 1 }
  function med(k,   m, i, j, a, t) { m = n[k]; for (i = 1; i <= m; i++) a[i] = v[k, i]
    for (i = 2; i <= m; i++) { t = a[i]; for (j = i - 1; j >= 1 && a[j] > t; j--) a[j + 1] = a[j]; a[j + 1] = t }
    return m % 2 ? a[(m + 1) / 2] : 0.5 * (a[m / 2] + a[m / 2 + 1]) }
  END {
    for (k in keys) { split(k, p, ","); M[p[1], p[2], p[3]] = 1e3 * med(k); C[p[1]] = 1; L[p[2]] = 1 }
    printf "%-18s %-6s %9s %9s %9s %9s %8s %8s %8s\n", "case", "load", "1 (ms)", "thr2", "omp2", "jobs2", "thr2/1", "omp2/1", "jobs2/1"
    nl = split("idle spin1 spin2 tick", lo, " ")
    for (c in C) for (i = 1; i <= nl; i++) { l = lo[i]; if (!((c, l, "1") in M)) continue
      one = M[c, l, "1"]; printf "%-18s %-6s %9.2f", c, l, one
      for (q = 1; q <= 3; q++) { cf = q == 1 ? "thr2" : q == 2 ? "omp2" : "jobs2"; printf " %9s", ((c, l, cf) in M) ? sprintf("%.2f", M[c, l, cf]) : "-" }
      for (q = 1; q <= 3; q++) { cf = q == 1 ? "thr2" : q == 2 ? "omp2" : "jobs2"; printf " %8s", ((c, l, cf) in M) ? sprintf("%.2f", M[c, l, cf] / one) : "-" }
      printf "\n" }
  }' "$csv" | { read -r h; echo "$h"; sort; } | tee "$out/load_summary.txt"
echo "targets: under spin1/spin2/tick the default (thr2) at most 1.1x the 1-thread step; idle thr2/1 at most 0.7 on cut_bunny50k"
}
if [ -n "${only_summary:-}" ]; then summary; exit 0; fi
echo "case,load,conf,step,time" > "$csv"
# replay <load> <conf>: one row per solve after the first (its step time, from the step lines)
replay() {
  local t="--threads 1"
  [ "$2" = thr2 ] && t="--threads 2"
  [ "$2" = omp2 ] && t="--threads 2 --openmp"
  [ "$2" = jobs2 ] && t="--threads 1 --jobs 2"
  (cd build/bench && $TS ./amps_replay $t "$scn" 2> /dev/null) | # dump/write lines write here
    awk -v l="$1" -v c="$2" '/^step / && $2 > 1 { for (k = 1; k < NF; k++) if ($(k+1) == "ms") print "incision," l "," c "," $2 "," $k / 1000 }' >> "$csv"
}
# case by case (the incision first), each under every load: a run cut short still has every
# load of the cases it finished
for load in $loads; do
  start_load $load
  for conf in 1 thr2 omp2 jobs2 1 thr2 omp2 jobs2; do replay $load $conf; done
  stop_load
done
for r in $runs; do
  IFS=: read -r -a f <<< "$r"
  n=${#f[@]}
  mesh=$(IFS=:; echo "${f[*]:0:n-2}")
  for load in $loads; do
    start_load $load
    for conf in 1 thr2 omp2 jobs2; do $TS build/bench/load run "$mesh" "${f[n-2]}" "${f[n-1]}" $conf $load "$csv" || exit 1; done
    stop_load
  done
done
summary
