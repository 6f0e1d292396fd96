#!/usr/bin/env bash
# Builds the libFuzzer targets (the mesh readers, the scenario parser of tools/amps_replay.c and
# the update engine's API) and runs each for the given number of seconds (default 60) on its seed
# corpus tests/fuzz/corpus/<target>/. With 0 seconds it only replays the committed corpus
# (regression check). New corpus entries go to build/fuzz/corpus/<target>/, crashers to
# build/fuzz/crash-<target>-*.
#   bash tests/fuzz/run.sh [seconds] [target ...]     targets: tetgen gmsh medit replay update
# Environment: CC (default clang), MAX_LEN (largest input, default 4096).
set -euo pipefail
cd "$(dirname "$0")/../.."
secs=${1:-60}
shift || true
readers=${*:-tetgen gmsh medit replay update}
CC=${CC:-clang}
out=build/fuzz
mkdir -p "$out"
status=0
# build every target first, as many at a time as there are cores (the compiles dominate short runs)
jobs=$(nproc 2>/dev/null || echo 2)
pids=()
for r in $readers; do
  $CC -std=c99 -g -O1 -I. -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=undefined \
      -o "$out/fuzz_$r" "tests/fuzz/fuzz_$r.c" -lm &
  pids+=($!)
  if [ ${#pids[@]} -ge "$jobs" ]; then wait "${pids[0]}" || exit 1; pids=("${pids[@]:1}"); fi
done
for p in "${pids[@]}"; do wait "$p" || exit 1; done
for r in $readers; do
  bin=$out/fuzz_$r
  dict=""
  [ -f "tests/fuzz/$r.dict" ] && dict="-dict=tests/fuzz/$r.dict"
  if [ "$secs" = 0 ]; then
    echo "== $r: replaying tests/fuzz/corpus/$r"
    "$bin" -runs=0 $dict "tests/fuzz/corpus/$r" 2>&1 | tail -n 2 || status=1
  else
    mkdir -p "$out/corpus/$r"
    echo "== $r: fuzzing for $secs s"
    "$bin" -max_total_time="$secs" -max_len="${MAX_LEN:-4096}" -timeout=10 -rss_limit_mb=2048 -print_final_stats=1 \
        -artifact_prefix="$out/crash-$r-" $dict "$out/corpus/$r" "tests/fuzz/corpus/$r" 2>&1 \
      | grep -E "stat::number_of_executed_units|stat::new_units_added|ERROR|SUMMARY|Test unit written|DONE" || true
    if ls "$out"/crash-"$r"-* >/dev/null 2>&1; then echo "$r: crashers in $out/crash-$r-*"; status=1; fi
  fi
done
exit $status
