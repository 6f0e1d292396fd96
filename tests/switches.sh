#!/usr/bin/env bash
# make switches: the compile-time switches AMPS_NO_FEM, AMPS_NO_STDIO, AMPS_NO_THREADS (with
# AMPS_NO_SIMD), AMPS_NO_AVX2 (the SSE2 kernels of the factorization on a CPU with AVX2), with and
# without OpenMP. For each combination: the tests that apply build with -Werror and run; the
# header compiles warning-free with clang (C99) and g++ (C++11); amps.h compiled with only
# AMPS_IMPLEMENTATION gives an object whose size is printed. Fails unless AMPS_NO_STDIO pulls
# in no <stdio.h> and no stdio symbol, and AMPS_NO_FEM and AMPS_NO_STDIO objects are smaller.
# The linear algebra is the same code under every switch, so its slow tests (factor, update)
# run in one combination only; tests build at -O0 (fast to compile; `make test` covers -O2)
# except the slow ones. Builds run JOBS (2) at a time.
set -u
cd "$(dirname "$0")/.."
CC=${CC:-cc}
OUT=${AMPS_SW_BUILD:-build/switches}
JOBS=${JOBS:-2}
CFLAGS="-std=c99 -Wall -Wextra -pedantic -Werror -I. -I/usr/include/suitesparse"
SLOW=" factor update scene "
LA="sparse ordering solve alloc fmt"
ALL3="-DAMPS_NO_FEM -DAMPS_NO_STDIO -DAMPS_NO_THREADS"
# name | defines | OpenMP flag | tests to run
CONFS=(
  "default||-fopenmp|$LA"
  "default-noomp|||"
  "nostdio|-DAMPS_NO_STDIO|-fopenmp|$LA fem io scene"
  "nofem|-DAMPS_NO_FEM|-fopenmp|$LA"
  "nofem+nostdio|-DAMPS_NO_FEM -DAMPS_NO_STDIO|-fopenmp|$LA"
  "nothreads|-DAMPS_NO_THREADS -DAMPS_NO_SIMD|-fopenmp|$LA update"
  "noavx2|-DAMPS_NO_AVX2|-fopenmp|factor par"
  "all3|$ALL3|-fopenmp|$LA factor"
  "all3-noomp|$ALL3||$LA"
)
rm -rf "$OUT"
mkdir -p "$OUT"

# every compile as one line of a job list, run JOBS at a time; a failing one shows its log
jobs="$OUT/jobs"
: >"$jobs"
job() { # log-name command...
  local log="$OUT/$1.log"; shift
  printf '%s >%q 2>&1 || { echo "FAILED: %s"; cat %q; exit 1; }\n' "$*" "$log" "$*" "$log" >>"$jobs"
}
impl="$OUT/impl.c"
printf '#define AMPS_IMPLEMENTATION\n#include "amps.h"\n' >"$impl"
printf '#define AMPS_IMPLEMENTATION\n#include "amps.h"\nint main(void) { amps_ctx c; amps_ctx_init(&c); return 0; }\n' >"$OUT/impl.cpp"
for c in "${CONFS[@]}"; do
  IFS='|' read -r name defs omp tests <<<"$c"
  mkdir -p "$OUT/$name"
  job "$name/impl" "$CC $CFLAGS -O2 $defs $omp -c $impl -o $OUT/$name/amps.o"
  for t in $tests; do
    case $SLOW in *" $t "*) opt=-O2 ;; *) opt=-O0 ;; esac
    job "$name/test_$t" "$CC $CFLAGS $opt $defs $omp -o $OUT/$name/test_$t tests/test_$t.c -lcholmod -lm"
  done
  if [ -z "$omp" ]; then
    job "$name/clang" "clang $CFLAGS $defs -fsyntax-only $impl"
    job "$name/cxx" "c++ -std=c++11 -Wall -Wextra -Werror -I. $defs -fsyntax-only $OUT/impl.cpp"
  fi
done
for defs in "-DAMPS_NO_STDIO" "-DAMPS_NO_FEM" "-DAMPS_NO_THREADS"; do
  job "clang$defs" "clang $CFLAGS $defs -fsyntax-only $impl"
  job "cxx$defs" "c++ -std=c++11 -Wall -Wextra -Werror -I. $defs -fsyntax-only $OUT/impl.cpp"
done
echo "== building $(wc -l <"$jobs") objects, tests and header checks ($JOBS at a time)"
tr '\n' '\0' <"$jobs" | xargs -0 -n1 -P "$JOBS" sh -c || { echo "switches: build failed"; exit 1; }

fail=0
for c in "${CONFS[@]}"; do
  IFS='|' read -r name defs omp tests <<<"$c"
  [ -n "$tests" ] || continue
  echo "== $name: $defs $omp"
  bins=""
  for t in $tests; do bins="$bins $OUT/$name/test_$t"; done
  # shellcheck disable=SC2086
  bash tests/run.sh $bins || fail=1
done

echo "== no stdio with AMPS_NO_STDIO"
for name in nostdio all3 all3-noomp; do
  defs=$(printf '%s\n' "${CONFS[@]}" | awk -F'|' -v n="$name" '$1 == n { print $2 }')
  inc=$($CC -std=c99 -I. $defs -E "$impl" | grep -c '/stdio\.h"')
  syms=$(nm -u "$OUT/$name/amps.o" | grep -Ew 'v?s?n?printf|v?fprintf|fopen|fclose|fread|fwrite|fputs|puts|putchar|ferror|vsnprintf|snprintf' | tr -s ' \n' ' ')
  if [ "$inc" != 0 ] || [ -n "$syms" ]; then echo "$name: <stdio.h> included $inc times, stdio symbols: $syms"; fail=1; else echo "$name: none"; fi
done

echo "== object size of amps.h with only AMPS_IMPLEMENTATION ($CC -O2)"
printf '%-15s %9s %7s %5s %9s %7s\n' switches text data bss total "vs default"
size_of() { size -B "$OUT/$1/amps.o" | awk 'NR == 2 { print $1, $2, $3, $4 }'; }
read -r _ _ _ dtot < <(size_of default)
for c in "${CONFS[@]}"; do
  IFS='|' read -r name _ _ _ <<<"$c"
  read -r t d b tot < <(size_of "$name")
  printf '%-15s %9d %7d %5d %9d %6d%%\n' "$name" "$t" "$d" "$b" "$tot" $((100 * tot / dtot))
  case $name in
    nostdio | nofem | nofem+nostdio | all3)
      if [ "$tot" -ge "$dtot" ]; then echo "$name: not smaller than default"; fail=1; fi ;;
  esac
done
[ "$fail" -eq 0 ] && echo "switches: all passed" || echo "switches: FAILED"
exit "$fail"
