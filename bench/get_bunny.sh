#!/usr/bin/env bash
# Fetches the Stanford bunny surface (npm package "bunny") and tetrahedralizes it with TetGen.
# Writes bench/data/bunny.poly and bench/data/bunny{20k,50k}.1.{node,ele}. Needs node, npm, tetgen:
# missing ones are installed when run as root, otherwise named with the command to install them.
set -eu
here=$(cd "$(dirname "$0")" && pwd)
data="$here/data"
mkdir -p "$data"
need=""
command -v node >/dev/null || need="$need nodejs"
command -v npm >/dev/null || need="$need npm"
command -v tetgen >/dev/null || need="$need tetgen"
if [ -n "$need" ]; then
  if [ "$(id -u)" = 0 ]; then
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq && apt-get install -y -qq $need >/dev/null
  else
    echo "get_bunny: missing Debian packages:$need (sudo apt-get install -y$need)"; exit 1
  fi
fi
if [ ! -f "$data/bunny.poly" ]; then
  tmp=$(mktemp -d)
  (cd "$tmp" && npm pack bunny --silent >/dev/null 2>&1 && tar xzf bunny-*.tgz)
  node -e '
    const b = require(process.argv[1]);
    let s = "# Stanford bunny surface (npm package bunny)\n" + b.positions.length + " 3 0 0\n";
    b.positions.forEach((p, i) => { s += i + " " + p[0] + " " + p[1] + " " + p[2] + "\n"; });
    s += b.cells.length + " 0\n";
    b.cells.forEach(c => { s += "1\n3 " + c[0] + " " + c[1] + " " + c[2] + "\n"; });
    s += "0\n0\n";
    require("fs").writeFileSync(process.argv[2], s);' "$tmp/package/index.js" "$data/bunny.poly"
  rm -rf "$tmp"
fi
# maximum tet volume for about 20,000 and 50,000 nodes (quality bound 1.5)
for spec in 20k:0.015 50k:0.0027; do
  name=${spec%%:*}; a=${spec#*:}
  if [ ! -f "$data/bunny$name.1.ele" ]; then
    cp "$data/bunny.poly" "$data/bunny$name.poly"
    tetgen -pq1.5a"$a" -Q "$data/bunny$name.poly" >/dev/null
    rm -f "$data/bunny$name.1.face" "$data/bunny$name.1.edge" "$data/bunny$name.1.smesh"
  fi
  nodes=$(head -1 "$data/bunny$name.1.node" | awk '{print $1}')
  echo "bunny$name: $nodes nodes, $(head -1 "$data/bunny$name.1.ele" | awk '{print $1}') tets"
done
