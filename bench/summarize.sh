#!/usr/bin/env bash
# Markdown table of bench/out/update_*.csv: per run the median AMPS step, the medians of
# CHOLMOD analyze+factor+solve and of CHOLMOD's plain solve (same steps), their ratios, the worst
# residuals, and the median share of Steps 1-6 in the AMPS step.
cd "$(dirname "$0")/out" || exit 1
med() { sort -g | awk '{a[NR]=$1} END {if (NR) print a[int((NR+1)/2)]; else print "nan"}'; }
echo "| run | steps | final dim | final \|S u C\| | AMPS step (median) | CHOLMOD refactor+solve | ratio | CHOLMOD solve | AMPS / solve | worst residual (AMPS / CHOLMOD) | Steps 1 / 2 / 3+4+5 / 6 (median share) |"
echo "|---|---|---|---|---|---|---|---|---|---|---|"
for f in update_*.csv; do
  [ -f "$f" ] || continue
  name=${f#update_}; name=${name%.csv}
  n=$(($(wc -l < "$f") - 1)); [ "$n" -gt 0 ] || continue
  last=$(tail -1 "$f")
  dim=$(echo "$last" | cut -d, -f2); ns=$(echo "$last" | cut -d, -f3)
  ta=$(tail -n +2 "$f" | cut -d, -f4 | med)
  tc=$(tail -n +2 "$f" | awk -F, '$12 > 0 {print $12}' | med)
  ts=$(tail -n +2 "$f" | awk -F, '$13 > 0 {print $13}' | med)
  ra=$(tail -n +2 "$f" | awk -F, 'BEGIN{m=0} $11 > m {m=$11} END{printf "%.1e", m}')
  rc=$(tail -n +2 "$f" | awk -F, 'BEGIN{m=0} $14 > m {m=$14} END{printf "%.1e", m}')
  s1=$(tail -n +2 "$f" | awk -F, '{print $5/$4}' | med); s2=$(tail -n +2 "$f" | awk -F, '{print $6/$4}' | med)
  s345=$(tail -n +2 "$f" | awk -F, '{print ($7+$8+$9)/$4}' | med); s6=$(tail -n +2 "$f" | awk -F, '{print $10/$4}' | med)
  awk -v name="$name" -v n="$n" -v dim="$dim" -v ns="$ns" -v ta="$ta" -v tc="$tc" -v ts="$ts" -v ra="$ra" -v rc="$rc" \
      -v s1="$s1" -v s2="$s2" -v s345="$s345" -v s6="$s6" 'BEGIN {
    printf "| %s | %d | %d | %d | %.2f ms | %.1f ms | %.1fx | %.2f ms | %.2f | %s / %s | %.0f%% / %.0f%% / %.0f%% / %.0f%% |\n",
      name, n, dim, ns, 1e3*ta, 1e3*tc, tc/ta, 1e3*ts, ta/ts, ra, rc, 100*s1, 100*s2, 100*s345, 100*s6 }'
done

# factor.csv: one row per mesh
if [ -f factor.csv ]; then
  echo
  echo "| mesh | n | nnz(L) ours AMD / CHOLMOD AMD | nnz(L) ours ND / METIS | ordering ND (s) | analyze (s) ours / CHOLMOD | factor (s) ours / simplicial / supernodal | ratio simpl / super | solve (ms) ours / simpl / super | ours / best | 1-index forward solve (us), closure/n | residual ours / simpl / super |"
  echo "|---|---|---|---|---|---|---|---|---|---|---|---|"
  tail -n +2 factor.csv | awk -F, '{
    m = $1; sub(/.*\//, "", m); sub(/\.1\.node$/, "", m)
    printf "| %s | %d | %.2fM / %.2fM (%.3f) | %.2fM / %.2fM (%.3f) | %.3f | %.3f / %.3f | %.3f / %.3f / %.3f | %.2f / %.2f | %.2f / %.2f / %.2f | %.2f | %.0f, %.3f | %.1e / %.1e / %.1e |\n",
      m, $3, $5/1e6, $6/1e6, $7, $8/1e6, $9/1e6, $10, $13, $17, $18, $21, $22, $23, $24, $25, 1e3*$26, 1e3*$27, 1e3*$28, $29, 1e6*$30, $32, $34, $35, $36 }'
fi
