#!/usr/bin/env bash
# Runs every test program given, AMPS_TEST_JOBS (default: the number of cores) at a time, then
# prints each one's summary in the order given and the total as the last line:
# "N passed, N failed".
jobs=${AMPS_TEST_JOBS:-$(nproc 2>/dev/null || echo 2)}
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
i=0
for t in "$@"; do
  while [ "$(jobs -rp | wc -l)" -ge "$jobs" ]; do wait -n 2>/dev/null || sleep 0.1; done
  ( "$t" > "$tmp/$i.out" 2>&1; echo $? > "$tmp/$i.rc" ) &
  i=$((i+1))
done
wait
pass=0; fail=0
i=0
for t in "$@"; do
  out=$(cat "$tmp/$i.out"); rc=$(cat "$tmp/$i.rc" 2>/dev/null || echo 255)
  i=$((i+1))
  printf '%s\n' "$out" | grep -E '^(FAIL|[a-z_0-9]+: [0-9]+ passed)' | tail -n 40
  line=$(printf '%s\n' "$out" | grep -E '^[a-z_0-9]+: [0-9]+ passed, [0-9]+ failed' | tail -n 1)
  if [ -z "$line" ]; then
    echo "$t: crashed or ended early (exit $rc)"; printf '%s\n' "$out" | tail -n 15; fail=$((fail+1)); continue
  fi
  p=$(printf '%s' "$line" | sed -E 's/.*: ([0-9]+) passed, ([0-9]+) failed.*/\1/')
  f=$(printf '%s' "$line" | sed -E 's/.*: ([0-9]+) passed, ([0-9]+) failed.*/\2/')
  pass=$((pass+p)); fail=$((fail+f))
  if [ "$rc" -ne 0 ] && [ "$f" -eq 0 ]; then echo "$t: exit $rc"; fail=$((fail+1)); fi
done
echo "$pass passed, $fail failed"
[ "$fail" -eq 0 ]
