#!/usr/bin/env bash
# Benchmarks of amps.h against CHOLMOD: builds bench/*, fetches and meshes the bunny, runs the
# factorization and update benchmarks, writes bench/out/*.csv and the tables of bench/RESULTS.md.
#   bench/run.sh          full run (the meshes of the issues; about 20-30 minutes on 2 cores)
#   bench/run.sh quick    representative subset (a few minutes)
set -u
cd "$(dirname "$0")/.."
mode=${1:-full}
bash tools/deps.sh bench || exit 1
bash bench/get_bunny.sh || exit 1
mkdir -p bench/out build/bench
CC=${CC:-cc}
FLAGS="-std=c99 -O2 -fopenmp -I. -I/usr/include/suitesparse"
for b in update factor; do
  [ -f bench/$b.c ] || continue
  $CC $FLAGS -o build/bench/$b bench/$b.c -lcholmod -lm || exit 1
done
log=bench/out/log_$mode.txt
: > "$log"
run() { echo "+ ${AMPS_GUARD:+AMPS_GUARD=$AMPS_GUARD }${AMPS_DUAL:+AMPS_DUAL=1 }$*" | tee -a "$log"; "$@" 2>&1 | tee -a "$log"; }
if [ "$mode" = quick ]; then
  meshes_factor="beam:64 brick:12 bench/data/bunny20k.1.node"
  updates="brick:12:cut:30 beam:256:cut:30 bench/data/bunny20k.1.node:cut:20 brick:12:deform:30"
else
  meshes_factor="beam:64 beam:256 beam:1024 brick:8 brick:14 brick:20 bench/data/bunny20k.1.node bench/data/bunny50k.1.node"
  updates="beam:64:cut:50 beam:256:cut:50 beam:1024:cut:50 brick:8:cut:50 brick:14:cut:50 brick:20:cut:50 bench/data/bunny20k.1.node:cut:50 bench/data/bunny50k.1.node:cut:50 beam:256:deform:50 brick:14:deform:50 bench/data/bunny20k.1.node:deform:50"
fi
if [ -x build/bench/factor ]; then
  for m in $meshes_factor; do run build/bench/factor "$m" bench/out/factor.csv; done
fi
for u in $updates; do
  mesh=${u%:*:*}; rest=${u#"$mesh":}; kind=${rest%%:*}; steps=${rest#*:}
  name=$(basename "$mesh" | sed 's/\.1\.node$//; s/:/_/')
  run build/bench/update "$mesh" "$kind" "$steps" "bench/out/update_${kind}_${name}.csv" 5
done
if [ "$mode" = full ]; then
  # the accuracy guard on the worst-conditioned beam, and the dual formulation on the bunny
  AMPS_GUARD=1e-12 run build/bench/update beam:1024 cut 50 bench/out/update_cut_beam_1024_guard.csv 5
  AMPS_DUAL=1 run build/bench/update bench/data/bunny20k.1.node cut 50 bench/out/update_cut_bunny20k_dual.csv 5
fi
# haptic step and watch sets (bench/haptic.c, bench/watch.c; results: bench/RESULTS_haptic.md)
for b in haptic watch; do $CC $FLAGS -o build/bench/$b bench/$b.c -lm || exit 1; done
rm -f bench/out/haptic.csv bench/out/watch.csv
if [ "$mode" = quick ]; then hmesh="brick:12 bench/data/bunny20k.1.node"; hsteps=500; wreps=5
else hmesh="brick:14 bench/data/bunny20k.1.node bench/data/bunny50k.1.node"; hsteps=2000; wreps=7; fi
for m in $hmesh; do
  run build/bench/haptic "$m" $hsteps 10 bench/out/haptic.csv
  run build/bench/watch "$m" $wreps 10 bench/out/watch.csv
done
# background re-factorization: a long cut with and without (bench/refactor.c)
$CC $FLAGS -o build/bench/refactor bench/refactor.c -lm || exit 1
rm -f bench/out/refactor.csv
if [ "$mode" = quick ]; then rmesh="beam:64"; rsteps=200
else rmesh="beam:256 bench/data/bunny20k.1.node"; rsteps=1000; fi
for m in $rmesh; do for p in on off; do run build/bench/refactor "$m" $rsteps $p bench/out/refactor.csv; done; done
if command -v gnuplot >/dev/null; then
  for m in $(cut -d, -f1 bench/out/refactor.csv | sort -u | grep -v '^mesh$'); do
    gnuplot -e "set term pngcairo size 900,600; set out 'bench/out/refactor_$m.png'; set datafile separator ',';
      set multiplot layout 2,1 title '$m: advancing cut, background re-factorization on / off';
      set ylabel 'step time (ms)'; set logscale y; set key top left;
      plot '< grep ^$m, bench/out/refactor.csv | grep ,on,' u 3:(1e3*\$4) w l t 'on', '< grep ^$m, bench/out/refactor.csv | grep ,off,' u 3:(1e3*\$4) w l t 'off';
      unset logscale y; set ylabel '|S u C|'; set xlabel 'step';
      plot '< grep ^$m, bench/out/refactor.csv | grep ,on,' u 3:5 w l t 'on', '< grep ^$m, bench/out/refactor.csv | grep ,off,' u 3:5 w l t 'off';
      unset multiplot" 2>/dev/null || echo "gnuplot failed for $m"
  done
fi
{
  echo "machine: $(uname -m), $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ *//'), $(free -g | awk '/Mem:/{print $2}') GiB"
  echo "date: $(date -u '+%Y-%m-%d %H:%M UTC')"
  echo "blas: $(readlink -f /usr/lib/x86_64-linux-gnu/libblas.so.3 2>/dev/null)"
  echo "compiler: $($CC --version | head -1), flags: $FLAGS"
} > bench/out/machine_$mode.txt
echo "done: bench/out/ (log $log)"
