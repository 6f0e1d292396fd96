#!/usr/bin/env bash
# The meshes of the dynamics benchmark (bench/dynamics.c), after the two scenes of "GPU-accelerated
# surgery simulation for opening a brain fissure" (Sase et al.), as TetGen files with the region
# as the tet attribute (region 1: body, region 2: the fissure's connective tissue):
#   fissure_cube: the unit cube [0,1]^3 with the fissure slab 0.48 < x < 0.52 through its whole
#     height and depth (walls x = 0.48 and x = 0.52); TetGen -pq2.0Aa0.00012 on a .poly with the
#     two walls as internal facets: about 4,480 nodes and 20,600 tets (the paper: 4,807 and 19,600).
#   brain: a hemisphere z >= 0 stretched to semi-axes 0.6 x 0.8 x 0.6 (x, y, z), with the fissure
#     slab |x| < 0.02, z > 0.24 (walls x = -0.02 and x = 0.02, from the dome down to z = 0.24);
#     Gmsh (OpenCASCADE, Delaunay, one thread, fixed seed) on the unit hemisphere with a mesh size
#     of 0.043 at the surface and the walls growing inward, then scaled: about 8,770 nodes and
#     32,300 tets (the paper: 8,647 and 32,639).
# Both are deterministic for fixed tool versions. Writes bench/data/{fissure_cube,brain}.1.{node,ele}
# (and their .poly / .geo). Needs tetgen and gmsh (tools/deps.sh bench: installed when run as root).
set -eu
data="$(cd "$(dirname "$0")" && pwd)/data"
mkdir -p "$data"
bash "$(dirname "$0")/../tools/deps.sh" bench || exit 1
if [ ! -f "$data/fissure_cube.1.ele" ]; then
  # 16 corners (x in 0, 0.48, 0.52, 1), the outer faces split at the walls, the two walls, and a
  # region point in each of the three boxes
  awk 'BEGIN {
    split("0 0.48 0.52 1", X, " ")
    print "# unit cube with the fissure slab 0.48 < x < 0.52 (bench/make_fissure.sh)"
    print "16 3 0 0"
    for (k = 0; k < 2; k++) for (j = 0; j < 2; j++) for (i = 0; i < 4; i++) print 8 * k + 4 * j + i, X[i + 1], j, k
    print "16 0"
    for (k = 0; k < 2; k++) for (i = 0; i < 3; i++) print "1\n4", 8 * k + i, 8 * k + i + 1, 8 * k + i + 5, 8 * k + i + 4
    for (j = 0; j < 2; j++) for (i = 0; i < 3; i++) print "1\n4", 4 * j + i, 4 * j + i + 1, 4 * j + i + 9, 4 * j + i + 8
    for (i = 0; i < 4; i++) print "1\n4", i, i + 4, i + 12, i + 8
    print "0"
    print "3\n1 0.25 0.5 0.5 1 0\n2 0.5 0.5 0.5 2 0\n3 0.75 0.5 0.5 1 0"
  }' > "$data/fissure_cube.poly"
  tetgen -pq2.0Aa0.00012 -Q "$data/fissure_cube.poly" >/dev/null
  rm -f "$data/fissure_cube.1.face" "$data/fissure_cube.1.edge" "$data/fissure_cube.1.smesh"
fi
if [ ! -f "$data/brain.1.ele" ]; then
  cat > "$data/brain.geo" <<'EOF'
// unit hemisphere z >= 0 with the fissure slab |x| < w/2, z > z0 (bench/make_fissure.sh scales it)
SetFactory("OpenCASCADE");
Geometry.OCCBoundsUseStl = 1;
General.NumThreads = 1;
Mesh.RandomSeed = 1;
Mesh.Algorithm = 6;
Mesh.Algorithm3D = 1;
Mesh.Optimize = 1;
Sphere(1) = {0, 0, 0, 1, 0, Pi/2, 2*Pi};
Box(2) = {-w/2, -1.1, z0, w, 2.2, 1.2};
BooleanIntersection(3) = { Volume{1}; }{ Volume{2}; Delete; };
BooleanFragments{ Volume{1}; Delete; }{ Volume{3}; Delete; }
slab() = Volume In BoundingBox{-w, -1.2, z0 - 0.01, w, 1.2, 1.2};
body() = Volume{:};
body() -= slab();
Physical Volume(1) = {body()};
Physical Volume(2) = {slab()};
// mesh size h at the surfaces and the fissure walls, growing by k per unit distance, at most H
Field[1] = MathEval;
Field[1].F = Sprintf("%g + %g * (1 - Sqrt(x^2 + y^2 + z^2))", h, k);
Field[2] = MathEval;
Field[2].F = Sprintf("%g + %g * z", h, k);
Field[3] = MathEval;
Field[3].F = Sprintf("%g + %g * Fabs(Fabs(x) - %g)", h, k, w / 2);
Field[4] = MathEval;
Field[4].F = Sprintf("%g", H);
Field[5] = Min;
Field[5].FieldsList = {1, 2, 3, 4};
Background Field = 5;
Mesh.MeshSizeExtendFromBoundary = 0;
Mesh.MeshSizeFromPoints = 0;
Mesh.MeshSizeFromCurvature = 0;
EOF
  # unit-hemisphere slab |x| < 0.02 / 0.6, z > 0.24 / 0.6 (after the scaling by 0.6, 0.8, 0.6)
  gmsh -3 -setnumber w 0.0666666666667 -setnumber z0 0.4 -setnumber h 0.043 -setnumber k 1.5 -setnumber H 0.2 \
    -format msh22 -o "$data/brain.msh" "$data/brain.geo" >/dev/null
  # Gmsh 2.2 -> TetGen: the nodes of the tets (in node-tag order, from 0), scaled; the physical
  # tag as the tet attribute
  awk -v out="$data/brain.1" '
    /^\$Nodes/ { sec = 1; getline; next }
    /^\$EndNodes/ { sec = 0; next }
    /^\$Elements/ { sec = 2; getline; next }
    /^\$EndElements/ { sec = 0; next }
    sec == 1 { x[$1] = $2 * 0.6; y[$1] = $3 * 0.8; z[$1] = $4 * 0.6; tag[++nn] = $1 }
    sec == 2 && $2 == 4 { nt++; k = 3 + $3; for (a = 0; a < 4; a++) { t[nt, a] = $(k + 1 + a); used[$(k + 1 + a)] = 1 }; reg[nt] = $4 }
    END {
      for (i = 1; i <= nn; i++) if (used[tag[i]]) id[tag[i]] = nu++
      f = out ".node"; printf "%d 3 0 0\n", nu > f
      for (i = 1; i <= nn; i++) if (used[tag[i]]) printf "%d %.12g %.12g %.12g\n", id[tag[i]], x[tag[i]], y[tag[i]], z[tag[i]] > f
      f = out ".ele"; printf "%d 4 1\n", nt > f
      for (e = 1; e <= nt; e++) printf "%d %d %d %d %d %d\n", e - 1, id[t[e, 0]], id[t[e, 1]], id[t[e, 2]], id[t[e, 3]], reg[e] > f
    }' "$data/brain.msh"
  rm -f "$data/brain.msh"
fi
for name in fissure_cube brain; do
  echo "$name: $(head -1 "$data/$name.1.node" | awk '{print $1}') nodes, $(head -1 "$data/$name.1.ele" | awk '{print $1}') tets," \
    "$(awk 'NR > 1 && $1 !~ /^#/ && $6 == 2 { n++ } END { print n }' "$data/$name.1.ele") in the fissure (region 2)"
done
