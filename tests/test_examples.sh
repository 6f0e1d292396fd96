#!/usr/bin/env bash
# Smoke run of examples/haptic_loop (1 s, and 1 s writing VTU frames): exit 0, both loops ran
# at a positive rate, frames written, the haptic period reported; -w 0 (no job system) runs.
# at a positive rate, frames written; examples/frame_loop for 20 frames.
B=${AMPS_BUILD:-build/default}
pass=0; fail=0
ok() { pass=$((pass+1)); }
bad() { fail=$((fail+1)); echo "FAIL test_examples: $*"; }
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
if "$B/haptic_loop" -t 1 -o "$tmp" > "$tmp/out" 2>&1; then ok; else bad "haptic_loop exited nonzero: $(tail -3 "$tmp/out")"; fi
for loop in haptic visual; do
  hz=$(sed -n "s/^$loop: .* = \([0-9.]*\) Hz.*/\1/p" "$tmp/out")
  if [ -n "$hz" ] && awk -v r="$hz" 'BEGIN{exit !(r > 0)}'; then ok; else bad "$loop rate '$hz': $(tail -3 "$tmp/out")"; fi
done
grep -q '^frame ' "$tmp/out" && ok || bad "no frame lines"
p99=$(sed -n 's/^haptic period: median [0-9.]* ms, p99 \([0-9.]*\) ms.*/\1/p' "$tmp/out")
if [ -n "$p99" ] && awk -v r="$p99" 'BEGIN{exit !(r > 0)}'; then ok; else bad "haptic period line: $(tail -3 "$tmp/out")"; fi
"$B/haptic_loop" -t 0.3 -w 0 > "$tmp/out0" 2>&1 && grep -q '^haptic period: .* on 0 job-system workers' "$tmp/out0" && ok \
  || bad "haptic_loop -w 0: $(tail -3 "$tmp/out0")"
[ -s "$tmp/frame_0000.vtu" ] && ok || bad "frame_0000.vtu not written"
"$B/haptic_loop" -x > /dev/null 2>&1; [ $? -eq 2 ] && ok || bad "bad option: exit code not 2"
# examples/frame_loop: 20 frames of strokes, grasper and haptic thread; watched = full solve
if "$B/frame_loop" -f 20 > "$tmp/fl.out" 2>&1; then ok; else bad "frame_loop exited nonzero: $(tail -3 "$tmp/fl.out")"; fi
grep -q '^frames 20, nodes cut [1-9]' "$tmp/fl.out" && ok || bad "frame_loop: $(tail -1 "$tmp/fl.out")"
echo "test_examples: $pass passed, $fail failed"
[ $fail -eq 0 ]
