#!/usr/bin/env bash
# The stress suite's cases (tests/test_stress.c, short mode) under engine variants: default,
# noacc (refine_tol = 0: no default refinement), xs_from_dense (x_S from the small system, [AMPS]
# Eq. 3.20), norefine (no local refinement step), guard (accuracy guard at 1e-12); the bunny case
# is left out (time). The fwd_* rows: errors against the __float128-refined reference (CHOLMOD's:
# its plain solve). "warn": solves that returned AMPS_WARN_INACCURATE (guard: the tolerance out of
# reach of CHOLMOD's plain solve too, which the suite checks). Writes one row per case and
# variant to <out.csv>.
#   bench/accuracy.sh <out.csv>
set -u
cd "$(dirname "$0")/.."
out=${1:-bench/out/accuracy.csv}
make -s build/default/test_stress >/dev/null || exit 1
echo "variant,case,neq,steps,cuts,cond0,res,res_chol,be_eps,be_chol_eps,err,err_chol,piv_min,fails,warn" > "$out"
for v in default noacc xs_from_dense norefine guard; do
  echo "+ AMPS_STRESS_VARIANT=$v build/default/test_stress"
  AMPS_BUNNY=none AMPS_STRESS_VARIANT=$v AMPS_STRESS_TABLE="$out" build/default/test_stress \
    > "build/accuracy_$v.log" 2>&1
  tail -1 "build/accuracy_$v.log"
done
