#!/usr/bin/env bash
# The dynamics benchmark (bench/dynamics.c, issue 20): the blunt dissection of the fissure cube,
# the brain scene with force feedback and the bunny at 50k nodes with an incision, amps.h beside
# CHOLMOD re-factorization and Jacobi-PCG. Writes <out>/dyn_<scene>.csv, dynamics_summary.csv,
# dynamics_<scene>.png (step time and removed tets against step) and dynamics.md (the RESULTS.md
# section, which bench/summarize.sh includes); run alone (make bench-dynamics) it also puts that
# section into bench/RESULTS.md.
#   bench/dynamics.sh [full|quick] [out]   full: cube 300 steps, brain 100, bunny 30 (about 15
#                                          minutes on 2 idle cores); quick: 30, 20, 5
set -u
cd "$(dirname "$0")/.."
mode=${1:-full}
out=${2:-bench/out}
alone=${3:-}
mkdir -p "$out" build/bench
bash bench/make_fissure.sh || exit 1
bash bench/get_bunny.sh || exit 1
CC=${CC:-cc}
$CC -std=c99 -O2 -fopenmp -I. -I/usr/include/suitesparse -Wall -Wextra -pedantic -Werror \
  -o build/bench/dynamics bench/dynamics.c -lcholmod -lm || exit 1
if [ "$mode" = quick ]; then runs="cube:30 brain:20 bunny:5"; else runs="cube:300 brain:100 bunny:30"; fi
runs=${BENCH_RUNS:-$runs} # e.g. BENCH_RUNS="cube:60 brain:20"
rm -f "$out"/dyn_*.csv "$out"/dynamics_summary.csv "$out"/dynamics_*.png
load0=$(cut -d' ' -f1-3 /proc/loadavg)
for r in $runs; do
  scene=${r%%:*}; steps=${r#*:}
  echo "+ build/bench/dynamics $scene $steps"
  build/bench/dynamics "$scene" "$steps" "$out/dyn_$scene.csv" "$out/dynamics_summary.csv" || exit 1
done
if command -v gnuplot >/dev/null; then
  for r in $runs; do
    scene=${r%%:*}; f="$out/dyn_$scene.csv"
    gnuplot -e "set term pngcairo size 900,700; set out '$out/dynamics_$scene.png'; set datafile separator ',';
      set multiplot layout 2,1 title '$scene: time per step (paper 003 Fig. 15-16)';
      set ylabel 'time (ms)'; set logscale y; set key outside right;
      plot '< grep ,amps, $f' u 2:(1e3*\$5) w l t 'amps.h step', \
           '< grep ,chol_refactor, $f' u 2:(1e3*\$5) w l t 'CHOLMOD re-factorization', \
           '< grep ,chol_solve, $f' u 2:(1e3*\$5) w l t 'CHOLMOD solve', \
           '< grep ,cg_jacobi,1e-08, $f' u 2:(1e3*\$5) w l t 'Jacobi-PCG 1e-8';
      unset logscale y; set xlabel 'step'; set ylabel 'tets removed'; set ytics nomirror; set y2tics;
      plot '< grep ,amps, $f' u 2:9 w impulses t 'in the step', '< grep ,amps, $f' u 2:10 w l axes x1y2 t 'total (right axis)';
      unset multiplot" 2>/dev/null || echo "gnuplot failed for $scene"
  done
fi
s="$out/dynamics_summary.csv"
{
  cat <<EOF
## 8e. Dynamics, removal and fracture (\`bench/dynamics\`, issue 20)

Implicit dynamics (paper "GPU-accelerated surgery simulation for opening a brain fissure", Eq. 27,
dt = 0.02, alpha = 1, beta = 0.01, gravity on), meshes of \`bench/make_fissure.sh\` and the
bunny. cube: the blunt dissection, two spatulas (77 pinned wall nodes) pushed apart at 0.025 per
second each, fracture in the fissure at sigma_max = 100 (the fissure's Young's modulus, the
paper's choice: the gravity stresses stay below it, the tissue between the spatulas tears from
step 15 on); brain: one spatula (61 wall nodes) pushing, 20 haptic calls
(\`amps_scene_solve_reactions\`) between steps; bunny: 2 cuts of the advancing planar cut before
every step. Per step, the same system assembled from scratch is solved by CHOLMOD (re-factorized
whenever a removal or cut changed it) and by Jacobi-PCG warm-started from the last velocities;
the error is against CHOLMOD + 2 refinement steps in quad precision. amps.h step: pin moves,
cuts, \`amps_scene_step\` (its fracture pass and removal included). Load average at the start:
$load0 (the machine is shared: the times are noisy, the ratios are side by side in one run).
Plots: $(for r in $runs; do printf '`%sdynamics_%s.png` ' "${PRE:-out/}" "${r%%:*}"; done)

| scene | steps | nodes | tets | equations | amps.h step (median) | CHOLMOD solve | ratio (target <= 1.25) | steps with a removal / cut | amps.h on them | CHOLMOD re-factorization | speed-up (target >= 30) | haptic rate (target >= 1 kHz) | removed tets | worst error | worst residual | load |
|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|
EOF
  awk -F, 'NR > 1 { printf "| %s | %d | %d | %d | %d | %.2f ms | %.2f ms | %.2f | %d | %.2f ms | %.1f ms | %.0fx | %s | %d | %.1e | %.1e | %.1f |\n", $1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $12, $13, ($14 > 0 ? sprintf("%.0f Hz", $14) : "-"), $15, $16, $17, $18 }' "$s"
  echo
  echo "Jacobi-PCG (median time and iterations per step):"
  echo
  echo "| scene | tol 1e-6 | 1e-8 | 1e-10 |"
  echo "|---|---|---|---|"
  for r in $runs; do
    scene=${r%%:*}
    printf '| %s |' "$scene"
    for t in 1e-06 1e-08 1e-10; do
      grep ",cg_jacobi,$t," "$out/dyn_$scene.csv" | awk -F, '{ print $5, $6 }' | sort -g | awk '{ a[NR] = $1; b[NR] = $2 } END { m = int((NR + 1) / 2); printf " %.1f ms (%d it.) |", 1e3 * a[m], b[m] }'
    done
    echo
  done
  echo
} > "$out/dynamics.md"
if [ -n "$alone" ] && [ -f bench/RESULTS.md ]; then
  # replace the section, or insert it before section 9
  has=$(grep -c '^## 8e\. ' bench/RESULTS.md)
  awk -v sec="$out/dynamics.md" -v has="$has" '
    function put(  l) { while ((getline l < sec) > 0) print l }
    has > 0 && /^## 8e\. / { skip = 1; put(); next }
    skip && /^## / { skip = 0 }
    has == 0 && /^## 9\. / { put() }
    !skip { print }' bench/RESULTS.md > bench/RESULTS.md.tmp && mv bench/RESULTS.md.tmp bench/RESULTS.md
fi
cat "$out/dynamics.md"
