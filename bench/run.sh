#!/usr/bin/env bash
# Benchmarks of amps.h against CHOLMOD (refactor, update/downdate), CG and the GMRES method of
# [Interactive cutting] (Yeung, Crouch, Pothen, "Interactively cutting and constraining vertices
# in meshes using augmented matrices"): builds every bench/*.c into build/bench/, fetches and
# meshes the bunny, runs the factorization benchmark and the harness over every experiment.
#   bench/run.sh          full run (budget: under 30 minutes on 2 cores): the tracked results
#                         bench/out/*.csv, the plots bench/out/*.png and bench/RESULTS.md
#                         (bench/summarize.sh)
#   bench/run.sh quick    representative subset (under 3 minutes), all of it in build/bench/quick/
#   bench/run.sh solvers  the full run's solver comparison only (factor, harness, guard, accuracy:
#                         RESULTS.md sections 1-6b, about 35 minutes); its summary goes to
#                         bench/out/RESULTS_solvers.md, to be merged into RESULTS.md by hand
set -u
cd "$(dirname "$0")/.."
mode=${1:-full}
bash tools/deps.sh bench || exit 1
bash bench/get_bunny.sh || exit 1
out=bench/out
[ "$mode" = quick ] && out=build/bench/quick
mkdir -p $out build/bench
CC=${CC:-cc}
FLAGS="-std=c99 -O2 -fopenmp -I. -I/usr/include/suitesparse"
# build <program> [flags and libraries]: bench/<program>.c -> build/bench/<program>, warning-free
build() {
  local p=$1; shift
  $CC $FLAGS -Wall -Wextra -pedantic -Werror -o "build/bench/$p" "bench/$p.c" "$@" -lm || exit 1
}
build factor -lcholmod
build harness -lcholmod -lumfpack
for b in haptic watch refactor refine_cost avalanche; do build $b; done
build corot -lcholmod
build frameloop -lpthread
bash bench/make_liver.sh >/dev/null || exit 1
build order_metis -DAMPS_USE_METIS -lcholmod -lmetis
log=$out/log_$mode.txt
: > "$log"
if [ "$mode" = solvers ]; then # only what sections 1-6b are made of
  rm -f $out/factor.csv $out/h_*.csv $out/rate_*.png $out/tradeoff_*.png $out/scaling.png $out/steps.png $out/summary.csv
else rm -f $out/factor.csv $out/h_*.csv $out/*.png $out/summary.csv; fi
run() { echo "+ $*" | tee -a "$log"; "$@" 2>&1 | tee -a "$log"; }
# the METIS build of amps.h (AMPS_USE_METIS): its ordering against CHOLMOD's METIS
run build/bench/order_metis 12
B20=bench/data/bunny20k.1.node
B50=bench/data/bunny50k.1.node
# harness runs: mesh:experiment:steps:every:cg_maxit:tmax (every: the sampled steps for the
# reference, CHOLMOD refactor, CG and GMRES; amps.h and CHOLMOD update/downdate run every step;
# tmax: wall-clock seconds after which a run takes no new step, a guard for the time budget)
if [ "$mode" = quick ]; then
  meshes_factor="beam:64 brick:8"
  runs="brick:8:cut:20:5:1000:30 beam:64:cut:20:10:1000:30 $B20:cut:10:10:300:60 brick:8:deform:20:10:1000:30"
else
  meshes_factor="beam:64 beam:256 beam:1024 brick:8 brick:14 brick:20 $B20 $B50"
  runs=""
  for m in beam:4 beam:16 beam:64 brick:4 brick:8 brick:12; do
    runs="$runs $m:cut:50:5:2000:60 $m:deform:50:5:2000:60"
  done
  for m in beam:256 brick:16; do runs="$runs $m:cut:50:10:2000:75 $m:deform:50:10:2000:75"; done
  for m in beam:1024 brick:20 $B20; do runs="$runs $m:cut:50:25:1000:120 $m:deform:50:25:1000:120"; done
  runs="$runs $B50:cut:50:25:500:150 $B50:deform:50:50:500:120 beam:128:cut:500:50:1000:120"
fi
for m in $meshes_factor; do run build/bench/factor "$m" $out/factor.csv; done
for r in $runs; do
  IFS=: read -r -a f <<< "$r"
  n=${#f[@]}
  mesh=$(IFS=:; echo "${f[*]:0:n-5}"); kind=${f[n-5]}; steps=${f[n-4]}; every=${f[n-3]}; cgmax=${f[n-2]}; tmax=${f[n-1]}
  name=$(basename "$mesh" | sed 's/\.1\.node$//; s/:/_/')
  [ "$steps" -gt 50 ] && name="${name}_long"
  BENCH_CG_MAXIT=$cgmax BENCH_TMAX=$tmax \
    run build/bench/harness "$mesh" "$kind" "$steps" "$every" "$out/h_${kind}_${name}.csv"
done
# machine.txt: where and how this run was made
machine() {
  cpu=$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ *//')
  echo "machine: $(uname -m), $(nproc) cores, $cpu, $(free -g | awk '/Mem:/{print $2}') GiB"
  echo "date: $(date -u '+%Y-%m-%d %H:%M UTC')"
  echo "blas: $(readlink -f /usr/lib/x86_64-linux-gnu/libblas.so.3 2>/dev/null)"
  echo "compiler: $($CC --version | head -1), flags: $FLAGS"
  echo "mode: $mode"
}
if [ "$mode" != quick ]; then
  # the accuracy guard (opt-in) on the worst-conditioned beam, amps.h only
  BENCH_GUARD=1e-12 BENCH_AMPS=p2 BENCH_ITER=0 BENCH_TMAX=60 \
    run build/bench/harness beam:1024 cut 50 25 $out/h_cut_beam_1024_guard.csv
  # the stress suite's cases under the engine variants (Eq. 3.20, refinement, guard)
  run bash bench/accuracy.sh $out/accuracy.csv
fi
if [ "$mode" = solvers ]; then
  machine > $out/machine.txt
  bash bench/summarize.sh "$out" out/ > $out/RESULTS_solvers.md || exit 1
  echo "done: $out/ (log $log), $out/RESULTS_solvers.md"
  exit 0
fi
# haptic step and watch sets (bench/haptic.c, bench/watch.c)
rm -f $out/haptic.csv $out/watch.csv
if [ "$mode" = quick ]; then hmesh="brick:12 bench/data/bunny20k.1.node"; hsteps=500; wreps=5
else hmesh="brick:14 bench/data/bunny20k.1.node bench/data/bunny50k.1.node"; hsteps=2000; wreps=7; fi
for m in $hmesh; do
  run build/bench/haptic "$m" $hsteps 10 $out/haptic.csv
  run build/bench/watch "$m" $wreps 10 $out/watch.csv
done
# background re-factorization: a long cut with and without (bench/refactor.c)
rm -f $out/refactor.csv
if [ "$mode" = quick ]; then rmesh="beam:64"; rsteps=200
else rmesh="beam:256 bench/data/bunny20k.1.node"; rsteps=1000; fi
# the off runs stop after 60 s of step time (their step time grows without bound); the on runs
# are repeated (run labels "", 2, 3): their end rate depends on where the re-factorization cycle
# stands in the last steps and on machine noise
if [ "$mode" = quick ]; then rreps=""; else rreps="2 3"; fi
for m in $rmesh; do
  run build/bench/refactor "$m" $rsteps on $out/refactor.csv
  run build/bench/refactor "$m" $rsteps off $out/refactor.csv 60
  for r in $rreps; do run build/bench/refactor "$m" $rsteps on $out/refactor.csv 0 $r; done
  run build/bench/refactor "$m" $rsteps paced $out/refactor.csv
done
# the frame loop: strokes, a grasper, one commit a frame, a 1 kHz haptic thread on the published haptic model (bench/frameloop.c)
rm -f $out/frameloop.csv $out/frameloop_frames.csv
if [ "$mode" = quick ]; then fmesh="bench/data/liver.1.node"; fframes=30
else fmesh="bench/data/liver.1.node bench/data/bunny50k.1.node"; fframes=200; fi
for m in $fmesh; do run build/bench/frameloop "$m" $fframes $out/frameloop_frames.csv $out/frameloop.csv; done
if command -v gnuplot >/dev/null; then
  for m in $(cut -d, -f1 $out/refactor.csv | sort -u | grep -v '^mesh$'); do
    gnuplot -e "set term pngcairo size 900,600; set out '$out/refactor_$m.png'; set datafile separator ',';
      set multiplot layout 2,1 title '$m: advancing cut, background re-factorization on / off';
      set ylabel 'step time (ms)'; set logscale y; set key top left;
      plot '< grep ^$m, $out/refactor.csv | grep ,on,' u 3:(1e3*\$4) w l t 'on', \
           '< grep ^$m, $out/refactor.csv | grep ,off,' u 3:(1e3*\$4) w l t 'off';
      unset logscale y; set ylabel '|S u C|'; set xlabel 'step';
      plot '< grep ^$m, $out/refactor.csv | grep ,on,' u 3:5 w l t 'on', \
           '< grep ^$m, $out/refactor.csv | grep ,off,' u 3:5 w l t 'off';
      unset multiplot" 2>/dev/null || echo "gnuplot failed for $m"
  done
fi
# corotational dynamics: amps.h against CHOLMOD re-factorization and Jacobi-PCG (bench/corot.c)
rm -f $out/corot.csv
if [ "$mode" = quick ]; then cruns="beam:20:10"
else cruns="beam:100:25 bunny:30:10 brain:300:50"; fi
for r in $cruns; do
  IFS=: read -r c st ev <<< "$r"
  if [ "$c" = brain ] && [ ! -f bench/data/brain.1.node ]; then echo "corot: no bench/data/brain.1.node (bench/make_fissure.sh)"; continue; fi
  run build/bench/corot "$c" "$st" "$ev" $out/corot.csv
done
# implicit dynamics, removal and fracture (bench/dynamics.c; full: about 5 minutes on 2 idle cores)
# an avalanche-like removal in dynamics (orphans held by rows, out of the dense system; bench/avalanche.c)
run build/bench/avalanche 64 16 40
if [ "$mode" = quick ]; then PRE="" bash bench/dynamics.sh quick $out || exit 1
else PRE=out/ bash bench/dynamics.sh full $out || exit 1; fi
# under load: spinning processes and a 1 kHz loop beside 1 thread, 2 OpenMP threads and the
# example job system (bench/load.sh; full: about 15 minutes, quick: about 1)
bash bench/load.sh $mode $out || exit 1
machine > $out/machine.txt
if [ "$mode" = quick ]; then res=$out/RESULTS.md; pre=""; else res=bench/RESULTS.md; pre=out/; fi
bash bench/summarize.sh "$out" "$pre" > $res.tmp && mv $res.tmp $res || exit 1
echo "done: $out/ (log $log), $res"
