#!/usr/bin/env bash
# amps_replay on every shipped scenario (exit 0, residuals small, outputs written), the README
# example, and malformed scenarios (each stops with "file:line: message" and a nonzero exit).
B=${AMPS_BUILD:-build/default}
R="$B/amps_replay"
pass=0; fail=0
ok() { pass=$((pass+1)); }
bad() { fail=$((fail+1)); echo "FAIL test_replay: $*"; }
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
for s in examples/*.scn; do
  name=$(basename "$s" .scn)
  if (cd "$tmp" && "$OLDPWD/$R" "$OLDPWD/$s") > "$tmp/$name.out" 2>&1; then ok; else bad "$s exited nonzero: $(tail -3 "$tmp/$name.out")"; continue; fi
  grep -q '^summary:' "$tmp/$name.out" && ok || bad "$s: no summary line"
  worst=$(sed -n 's/.*worst residual \([0-9.e+-]*\).*/\1/p' "$tmp/$name.out" | tail -1)
  if [ -n "$worst" ] && awk -v r="$worst" 'BEGIN{exit !(r < 1e-9)}'; then ok; else bad "$s: worst residual '$worst'"; fi
  for f in $(sed -n 's/^\(dump\|write\) \([^ #]*\).*/\2/p' "$s"); do [ -s "$tmp/$f" ] && ok || bad "$s: $f not written"; done
  if [ -f "$tmp/$name.csv" ]; then
    n=$(($(wc -l < "$tmp/$name.csv") - 1)); m=$(sed -n 's/^dump: .* (\([0-9]*\) nodes)/\1/p' "$tmp/$name.out")
    [ "$n" = "$m" ] && ok || bad "$s: csv has $n rows, replay said $m nodes"
    head -1 "$tmp/$name.csv" | grep -q '^node,ux,uy,uz$' && ok || bad "$s: csv header"
  fi
done
"$B/readme_example" > "$tmp/readme.out" 2>&1 && grep -q "top centre node moved" "$tmp/readme.out" && ok || bad "readme example: $(cat "$tmp/readme.out")"
# malformed scenarios: name|content|expected line|expected text
while IFS='|' read -r name line want text; do
  [ -z "$name" ] && continue
  printf '%b' "$line" > "$tmp/$name.scn"
  out=$("$R" "$tmp/$name.scn" 2>&1); rc=$?
  if [ $rc -ne 0 ] && printf '%s' "$out" | grep -q "$name.scn:$want: .*$text"; then ok; else bad "$name: rc=$rc out=$out"; fi
done <<'CASES'
unknown|mesh beam 4\nfix z lt 0.5\nfrobnicate 3\n|3|unknown command
badnum|mesh beam 4\nforce 3 1 x 0\n|2|bad number
range|mesh beam 4\nfix z lt 0.5\npin 100000 0 0 0\n|3|out of range
nomesh|solve\n|1|no mesh
matlate|mesh beam 4\nfix z lt 0.5\nsolve\nmaterial 10 0.3\n|4|only before the first solve
badaxis|mesh beam 4\nfix w lt 0.5\n|2|bad axis
pinfixed|mesh beam 4\nfix z lt 0.5\npin 0 0 0 0\n|3|fixed
missing|mesh nosuchfile.node\n|1|
badmat|mesh beam 4\nmaterial -1 0.3\n|2|material
bigidx|mesh beam 4\nfix z lt 0.5\nforce 4294967299 0 1 0\n|3|usage: force
bigstep|mesh beam 4\nfix z lt 0.5\ndynamics 0.01 0 0\nstep 99999999999999999999\n|4|usage: step
args|mesh beam 4\ncut 3 0 0 0\n|2|usage
unspd|mesh beam 4\nsolve\n|2|solve
stepstatic|mesh beam 4\nfix z lt 0.5\nstep\n|3|needs dynamics
solvedyn|mesh beam 4\nfix z lt 0.5\ndynamics 0.1 0 0\nsolve\n|4|dynamic
dynlate|mesh beam 4\nfix z lt 0.5\nsolve\ndynamics 0.1 0 0\n|4|only before
regionunknown|mesh beam 4\nregion 5 1 0.3\n|2|no tetrahedron
regionneg|mesh beam 4\nregion -5 1 0.3\n|2|no tetrahedron has region -5
densityneg|mesh beam 4\ndensity -1\n|2|density
removetwice|mesh beam 4\nfix z lt 0.5\ndynamics 0.1 0 0\nremove 3\nremove 3\n|5|already removed
removerange|mesh beam 4\nremove 100000\n|2|out of range
fracturebad|mesh beam 4\nfracture x\n|2|usage
stepnan|mesh beam 4\ndynamics nan 0 0\n|2|bad number
corotstatic|mesh beam 4\nfix z lt 0.5\ncorotational on\n|3|needs dynamics
corotlate|mesh beam 4\nfix z lt 0.5\ndynamics 0.1 0 0\nstep\ncorotational on\n|5|only before the first step
corotbad|mesh beam 4\nfix z lt 0.5\ndynamics 0.1 0 0\ncorotational yes\n|4|usage
CASES
# the dynamic examples dump displacements and velocities
head -1 "$tmp/cantilever_drop_state.csv" 2>/dev/null | grep -q '^node,ux,uy,uz,vx,vy,vz$' && ok || bad "dynamic dump header"
grep -q 'tore' "$tmp/tissue_tear.out" && ok || bad "tissue_tear: no tet torn by fracture"
# --refactor count: the tearing example's dump has the same bits on 1 and 2 threads
for t in 1 2; do
  mkdir -p "$tmp/det$t"
  (cd "$tmp/det$t" && "$OLDPWD/$R" -q --refactor count --threads $t "$OLDPWD/examples/tissue_tear.scn") > /dev/null 2>&1 || bad "tissue_tear --refactor count --threads $t"
done
cmp -s "$tmp/det1/tissue_tear_state.csv" "$tmp/det2/tissue_tear_state.csv" && ok || bad "tissue_tear: --refactor count differs between 1 and 2 threads"
"$R" --refactor sometimes "$tmp/ok.scn" > /dev/null 2>&1; [ $? = 2 ] && ok || bad "unknown --refactor policy accepted"
# comments and blank lines anywhere; release of an unpinned node does nothing
printf 'mesh beam 4 # comment\n\n# whole-line comment\nfix z lt 0.5\nrelease 60\nforce 99 0 0 1 # tip\nsolve\n' > "$tmp/ok.scn"
"$R" "$tmp/ok.scn" > "$tmp/ok.out" 2>&1 && ok || bad "comments: $(cat "$tmp/ok.out")"
# selection, watch, haptic and boundary commands: the fixed counts, the OBJ's faces, errors
printf 'mesh brick 3\nfixbox -1 -1 -1 2 2 0.1\nfixsphere 0 0 2 0.2\nfixnodes 1 2 3\nwatch 60 61\npin 61 0 0 0.1\ncut 60 0.5 0.5 1 0 0 1\nsolve_watched\nhaptic 50\nsolve\nboundary b.obj\nboundary b.surf\n' > "$tmp/sel.scn"
if (cd "$tmp" && "$OLDPWD/$R" sel.scn) > "$tmp/sel.out" 2>&1; then ok; else bad "selection commands: $(cat "$tmp/sel.out")"; fi
grep -q '^fixbox: 16 nodes' "$tmp/sel.out" && grep -q '^fixsphere: 1 nodes' "$tmp/sel.out" && grep -q '^haptic: 50 steps' "$tmp/sel.out" && grep -q '^solve_watched: 3 nodes' "$tmp/sel.out" && ok || bad "selection output: $(cat "$tmp/sel.out")"
n=$(sed -n 's/^boundary: b.obj (\([0-9]*\) triangles)/\1/p' "$tmp/sel.out")
[ -n "$n" ] && [ "$(grep -c '^f ' "$tmp/b.obj")" = "$n" ] && [ "$(grep -c . "$tmp/b.surf")" = "$((4 * n))" ] && ok || bad "boundary files ($n triangles)"
while IFS='|' read -r name line want text; do
  printf '%b' "$line" > "$tmp/$name.scn"
  out=$("$R" "$tmp/$name.scn" 2>&1); rc=$?
  if [ $rc -ne 0 ] && printf '%s' "$out" | grep -q "$name.scn:$want: .*$text"; then ok; else bad "$name: rc=$rc out=$out"; fi
done <<'CASES'
fixrange|mesh beam 4\nfixnodes 1 100000\n|2|bad node
fixlate|mesh beam 4\nfix z lt 0.5\nsolve\nfixnodes 3\n|4|already factored
boxinv|mesh beam 4\nfixbox 1 0 0 0 1 1\n|2|lo\[0\]
spherenan|mesh beam 4\nfixsphere 0 0 0 nan\n|2|bad number
hapticarg|mesh beam 4\nhaptic 0\n|2|usage
fracneg|mesh beam 4\nfix z lt 0.5\ndynamics 0.01 0 0\nfracture -5\n|4|sigma_max must be > 0
regrho0|mesh beam 4\nregion 0 1000 0.3 0\n|2|density 0 is not > 0
dthuge|mesh beam 4\nfix z lt 0.5\ndynamics 1e300 0 0\n|3|out of range
bndwrite|mesh beam 4\nfix z lt 0.5\nsolve\nboundary /nonexistent/dir/b.obj\n|4|cannot write
CASES
# a UTF-8 byte order mark at the start; a comment line of 100,000 characters; a fixnodes line of
# 30,000 nodes (no limit of the line's length)
printf '\xEF\xBB\xBFmesh beam 4 # bom\n# %s\nfix z lt 0.5\nfixnodes %s\nsolve\n' "$(head -c 100000 /dev/zero | tr '\0' x)" \
  "$(for i in $(seq 1 1000); do printf '1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16 17 18 19 20 21 22 23 24 25 26 27 28 29 30 '; done)" > "$tmp/long.scn"
"$R" "$tmp/long.scn" > "$tmp/long.out" 2>&1 && grep -q '^fixnodes: 30000 nodes' "$tmp/long.out" && ok || bad "bom, long lines: $(tail -3 "$tmp/long.out")"
# --frames: a VTU per step and the .pvd of them (times k dt); a remove line of 100 tets (no limit
# of arguments below the line length)
printf 'mesh beam 12\nfix z lt 0.5\ndynamics 0.02 0 0\ngravity 0 0 -1\nstep 3\nremove %s\nstep 2\n' "$(seq -s ' ' 200 299)" > "$tmp/fr.scn"
if (cd "$tmp" && "$OLDPWD/$R" --frames fr/f fr.scn) > "$tmp/fr.out" 2>&1; then bad "frames into a missing folder succeeded"; else ok; fi
mkdir -p "$tmp/fr"
if (cd "$tmp" && "$OLDPWD/$R" --frames fr/f fr.scn) > "$tmp/fr.out" 2>&1; then ok; else bad "frames: $(cat "$tmp/fr.out")"; fi
[ "$(ls "$tmp"/fr/f_*.vtu 2>/dev/null | wc -l)" = 5 ] && [ "$(grep -c '<DataSet timestep=' "$tmp/fr/f.pvd")" = 5 ] &&
  grep -q 'timestep="0.10000000000000001" group="" part="0" file="f_00005.vtu"' "$tmp/fr/f.pvd" && ok || bad "frames: $(ls "$tmp/fr"; cat "$tmp/fr/f.pvd")"
n=$(sed -n 's/^remove: \([0-9]*\) tetrahedra.*/\1/p' "$tmp/fr.out"); [ "${n:-0}" -ge 100 ] && ok || bad "remove of 100 tets: $(cat "$tmp/fr.out")"
# a batch of cuts, pins and removals in dynamics: committed, it gives the dump of the same
# changes one by one; cancelled, the dump of a run without it
base='mesh beam 6\nfix z lt 0.5\ndynamics 0.05 0.1 0.01\ngravity 0 0 -1\nstep 2\n'
chg='cut 87 2 2 3.5 0.2 1 0.1\nremove 118 120 148\npin 130 0.01 0 0.02\nremove 40\n'
printf "$base$chg"'step 3\ndump one.csv\n' > "$tmp/b1.scn"
printf "$base"'batch\n'"$chg"'commit\nstep 3\ndump bat.csv\n' > "$tmp/b2.scn"
printf "$base"'step 3\ndump none.csv\n' > "$tmp/b3.scn"
printf "$base"'batch\n'"$chg"'cancel\nstep 3\ndump can.csv\n' > "$tmp/b4.scn"
for k in 1 2 3 4; do (cd "$tmp" && "$OLDPWD/$R" b$k.scn) > "$tmp/b$k.out" 2>&1 || bad "batch scenario $k: $(tail -3 "$tmp/b$k.out")"; done
csvdiff() { paste -d, "$1" "$2" | awk -F, 'NR > 1 { n = NF / 2; for (i = 2; i <= n; i++) { d = $i - $(i + n); if (d < 0) d = -d; if (d > m) m = d } } END { exit !(m < 1e-12 && NR > 1) }'; }
csvdiff "$tmp/one.csv" "$tmp/bat.csv" && ok || bad "a committed batch differs from the changes one by one"
csvdiff "$tmp/none.csv" "$tmp/can.csv" && [ "$(wc -l < "$tmp/none.csv")" = "$(wc -l < "$tmp/can.csv")" ] && ok || bad "a cancelled batch changed the run"
echo "test_replay: $pass passed, $fail failed"
[ $fail -eq 0 ]
