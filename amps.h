/* amps.h - exact real-time solves of finite element models under cuts, pins and forces.
   Augmented Matrix Principal Submatrix updates (AMPS) over a sparse LDL^T factorization.
   Single-file library, MIT license (see end of file).

   USAGE
     In exactly one C or C++ file:
         #define AMPS_IMPLEMENTATION
         #include "amps.h"
     Everywhere else just #include "amps.h".

   OPTIONS (define before the implementation include)
     AMPS_STATIC          all functions static (private copy per translation unit)
     AMPS_INT             index type (default int; e.g. -DAMPS_INT=int64_t for huge models)
     AMPS_MALLOC(sz,u) AMPS_REALLOC(p,sz,u) AMPS_FREE(p,u)
                          custom allocator; define all three or none. u is amps_ctx.alloc_user.
     AMPS_ASSERT(x)       internal assertion (default assert from <assert.h>)
     AMPS_USE_METIS       enable AMPS_ORDER_METIS (link -lmetis)
     AMPS_NO_FEM          leave out the FEM scene (linear algebra only)
     AMPS_NO_STDIO        leave out file readers/writers
     AMPS_NO_THREADS      leave out background threads
     OpenMP kernels are used when compiled with -fopenmp (_OPENMP defined).

   ERRORS
     Every call that can fail takes an amps_ctx* and returns an amps_status (or NULL for
     constructors). On failure ctx->status and ctx->msg say what went wrong, e.g.
     "amps_factorize: zero or negative pivot at column 17 (original numbering)".
     A failed call leaves its objects as they were.

   EXAMPLE
     amps_ctx ctx; amps_ctx_init(&ctx);
     amps_csc *K = amps_csc_from_triplets(&ctx, n, nz, ti, tj, tx, AMPS_UPPER);
     amps_factor *F = amps_analyze(&ctx, K, AMPS_UPPER, NULL);
     if (!F || amps_factorize(&ctx, F, K, AMPS_UPPER)) { puts(ctx.msg); ... }
     amps_solve(&ctx, F, b, x, work);
*/
#ifndef AMPS_H
#define AMPS_H

#include <stddef.h>

#ifdef AMPS_STATIC
#define AMPS_API static
#else
#define AMPS_API extern
#endif

#ifndef AMPS_INT
#define AMPS_INT int
#endif
typedef AMPS_INT amps_int;

#ifdef __cplusplus
extern "C" {
#endif

/* =============================== common types =============================== */

typedef enum amps_status {
    AMPS_OK = 0,
    AMPS_ERR_ARG = -1,              /* invalid argument (NULL, negative count, wrong size)   */
    AMPS_ERR_OOM = -2,              /* allocation failed                                     */
    AMPS_ERR_INDEX = -3,            /* index out of range                                    */
    AMPS_ERR_PATTERN = -4,          /* unsorted / duplicate / inconsistent sparsity pattern  */
    AMPS_ERR_VALUE = -5,            /* NaN or Inf in input                                   */
    AMPS_ERR_NOT_SPD = -6,          /* zero or negative pivot in LDL^T                       */
    AMPS_ERR_SINGULAR_UPDATE = -7,  /* the updated system is singular                        */
    AMPS_ERR_CAPACITY = -8,         /* reserved capacity exhausted and growth not allowed    */
    AMPS_ERR_MESH = -9,             /* invalid mesh (degenerate or inverted element, ...)    */
    AMPS_ERR_IO = -10,              /* file could not be opened / read / written             */
    AMPS_ERR_PARSE = -11,           /* malformed file or scenario                            */
    AMPS_ERR_STATE = -12,           /* call not valid in the object's current state          */
    AMPS_ERR_UNSUPPORTED = -13,     /* feature compiled out (e.g. METIS)                     */
    AMPS_WARN_NOOP = 1              /* success, but nothing was done (e.g. a cut with one empty side) */
} amps_status;

/* Caller-owned context: allocator user pointer, thread count, and the last error. */
typedef struct amps_ctx {
    void *alloc_user;     /* passed as u to AMPS_MALLOC/AMPS_REALLOC/AMPS_FREE */
    int nthreads;         /* OpenMP threads used by amps kernels; 0 = OpenMP default */
    amps_status status;   /* status of the last call that failed or warned */
    char msg[256];        /* human-readable message for status */
} amps_ctx;

AMPS_API void amps_ctx_init(amps_ctx *ctx);
AMPS_API const char *amps_status_str(amps_status s);

/* =============================== sparse matrix =============================== */

/* Which part of a symmetric matrix a CSC array holds. */
typedef enum amps_stype { AMPS_LOWER = -1, AMPS_FULL = 0, AMPS_UPPER = 1 } amps_stype;

/* Compressed sparse column matrix. Column j holds rows i[p[j] .. p[j+1]-1]. */
typedef struct amps_csc {
    amps_int nrow, ncol;
    amps_int *p;          /* ncol+1 column pointers, p[0] = 0 */
    amps_int *i;          /* p[ncol] row indices */
    double *x;            /* p[ncol] values (may be NULL for a pattern) */
} amps_csc;

/* Allocates an nrow x ncol matrix with room for nzmax entries (values if with_values). */
AMPS_API amps_csc *amps_csc_alloc(amps_ctx *ctx, amps_int nrow, amps_int ncol, amps_int nzmax, int with_values);
AMPS_API void amps_csc_free(amps_ctx *ctx, amps_csc *A);
/* Checks a symmetric matrix given as its stype part: square, p monotone, rows in range and
   strictly increasing in each column, entries in the stype triangle only, values finite.
   Returns AMPS_OK or the first violation (with column and row in ctx->msg). */
AMPS_API amps_status amps_csc_check(amps_ctx *ctx, const amps_csc *A, amps_stype stype);
/* Symmetric n x n matrix from nz triplets (ti[k], tj[k], tx[k]); entries of either triangle are
   put in the stype triangle (both for AMPS_FULL), duplicates are summed, columns sorted.
   Rejects out-of-range indices, negative counts and non-finite values. */
AMPS_API amps_csc *amps_csc_from_triplets(amps_ctx *ctx, amps_int n, amps_int nz, const amps_int *ti,
                                          const amps_int *tj, const double *tx, amps_stype stype);
/* y = A x for symmetric A stored as its stype part. */
AMPS_API void amps_csc_symv(const amps_csc *A, amps_stype stype, const double *x, double *y);

/* ================================= ordering ================================= */

typedef enum amps_ordering {
    AMPS_ORDER_AUTO = 0,     /* ND when coordinates are given or METIS built in, else AMD */
    AMPS_ORDER_NATURAL,      /* identity */
    AMPS_ORDER_GIVEN,        /* opts->perm */
    AMPS_ORDER_AMD,          /* our approximate minimum degree */
    AMPS_ORDER_ND,           /* our nested dissection (uses opts->coords when given) */
    AMPS_ORDER_METIS         /* METIS_NodeND (needs AMPS_USE_METIS) */
} amps_ordering;

typedef struct amps_order_opts {
    amps_ordering method;
    const amps_int *perm;    /* GIVEN: perm[k] = original index eliminated k-th */
    amps_int block;          /* DOFs per node (3 for 3D elasticity): order the compressed node graph
                                and expand; 0 = detect identical consecutive columns, 1 = none */
    const double *coords;    /* optional: 3 coordinates per node (per block) for ND */
} amps_order_opts;

/* perm (size n) = fill-reducing ordering of symmetric A (stype part): perm[k] = original index k-th. */
AMPS_API amps_status amps_order(amps_ctx *ctx, const amps_csc *A, amps_stype stype,
                                const amps_order_opts *opts, amps_int *perm);
/* AMD on a symmetric graph given in CSC with both triangles (diagonal entries ignored). */
AMPS_API amps_status amps_amd(amps_ctx *ctx, amps_int n, const amps_int *Ap, const amps_int *Ai, amps_int *perm);
/* Nested dissection on the same kind of graph; xyz (3n, may be NULL) guides the bisections. */
AMPS_API amps_status amps_nd(amps_ctx *ctx, amps_int n, const amps_int *Ap, const amps_int *Ai,
                             const double *xyz, amps_int *perm);

/* ============================ symbolic analysis ============================ */
/* ============================= numeric LDL^T ============================== */

/* K = P L D L^T P^T. Everything in permuted numbering unless said otherwise:
   pivot k is original index perm[k]; L is unit lower triangular, stored strictly below the
   diagonal, column by column, rows ascending; parent is the elimination tree (parent[j] > j,
   -1 at roots), so the ancestors of j are the path j -> root and ascending order is topological. */
typedef struct amps_factor {
    amps_int n;
    amps_int *perm, *iperm;   /* perm[k] = original index of pivot k; iperm[perm[k]] = k */
    amps_int *parent;         /* elimination tree */
    amps_int *Lp, *Li;        /* strictly lower part of L, CSC (n+1, Lp[n]) */
    double *Lx;               /* values of L */
    double *D;                /* n pivots */
    amps_int height;          /* nodes on the longest leaf-to-root path of the elimination tree */
    int is_numeric;           /* 1 after a successful amps_factorize */
    void *priv;               /* implementation data (pattern maps, workspace) */
} amps_factor;

/* Ordering + elimination tree + column counts + Lp for symmetric A (stype part); allocates L.
   opts may be NULL (AMPS_ORDER_AUTO, block detection). */
AMPS_API amps_factor *amps_analyze(amps_ctx *ctx, const amps_csc *A, amps_stype stype, const amps_order_opts *opts);
/* Numeric LDL^T of A, which must have the pattern given to amps_analyze (values may differ).
   AMPS_ERR_NOT_SPD names the failing column in the original numbering; F is then not numeric.
   Allocates nothing. */
AMPS_API amps_status amps_factorize(amps_ctx *ctx, amps_factor *F, const amps_csc *A, amps_stype stype);
AMPS_API void amps_factor_free(amps_ctx *ctx, amps_factor *F);
/* Number of entries of L, counting the unit diagonal. */
AMPS_API double amps_factor_nnz(const amps_factor *F);
/* Counts of positive, negative and zero pivots in D. */
AMPS_API void amps_factor_inertia(const amps_factor *F, amps_int *npos, amps_int *nneg, amps_int *nzero);

/* ===================== triangular solves and closures ===================== */

/* Reusable marker over 0..n-1: j is marked iff mark[j] == stamp; clearing is ++stamp. */
typedef struct amps_marker {
    amps_int n;
    amps_int stamp;
    amps_int *mark;
} amps_marker;
AMPS_API amps_status amps_marker_init(amps_ctx *ctx, amps_marker *m, amps_int n);
AMPS_API void amps_marker_free(amps_ctx *ctx, amps_marker *m);
/* Starts a new marking; all indices become unmarked in O(1) (amortized). */
AMPS_API void amps_marker_next(amps_marker *m);

/* closure_L(idx) = union of the elimination-tree paths from idx[0..nidx-1] (permuted numbering)
   to their roots. Writes it to out (room for n) in ascending (topological) order, returns its
   size. Cost O(closure size + its sort). Uses m (starts a new marking). */
AMPS_API amps_int amps_closure(const amps_factor *F, amps_int nidx, const amps_int *idx, amps_int *out, amps_marker *m);

/* Full solve K x = b in the original numbering; x may equal b; work has n doubles. */
AMPS_API amps_status amps_solve(amps_ctx *ctx, const amps_factor *F, const double *b, double *x, double *work);
/* Permuted-space kernels on a dense n-vector x: x := L^{-1} x, x := D^{-1} x, x := L^{-T} x. */
AMPS_API void amps_lsolve(const amps_factor *F, double *x);
AMPS_API void amps_dsolve(const amps_factor *F, double *x);
AMPS_API void amps_ltsolve(const amps_factor *F, double *x);
/* Sparse-RHS forward solve: x (dense n-vector, zero outside struct(b)) holds b with nonzeros at
   bi[0..nb-1]; on return x = L^{-1} b, computed on closure_L(bi) only, which is written to
   closure (room for n) in ascending order; returns its size. Entries outside stay zero. */
AMPS_API amps_int amps_lsolve_sparse(const amps_factor *F, amps_int nb, const amps_int *bi, double *x,
                                     amps_int *closure, amps_marker *m);
/* Partial backward solve: y (dense n-vector) holds D^{-1} L^{-1} b. Computes x = L^{-T} y only on
   closure_L(req[0..nreq-1]) (written to closure, ascending), in place in y; other entries of y
   are left unchanged (not solved). Returns the closure size. */
AMPS_API amps_int amps_ltsolve_partial(const amps_factor *F, amps_int nreq, const amps_int *req, double *y,
                                       amps_int *closure, amps_marker *m);

/* ============================ augmented updates ============================ */
/* @@API update: owned by engine */

/* ================================ FEM scene ================================ */
#ifndef AMPS_NO_FEM
/* @@API fem: owned by fem */
/* ---- tetrahedral mesh ---- */

/* Tetrahedral mesh in the reference configuration, with the node copies made by cuts.
   Nodes 0..nfile-1 are the nodes given at creation (origin[v] = v); nodes nfile..nnode-1 are
   copies made by amps_mesh_cut, origin[v] = the creation node they descend from. A copy has
   the reference coordinates of its origin. Every tet has 4 distinct nodes and nonzero volume;
   either orientation is allowed. Material: E[t], nu[t] (default E = 1, nu = 0.3).
   Incidence: the tets containing node v are inc[inc_ptr[v] .. inc_ptr[v] + inc_len[v] - 1],
   in ascending order. The slots of all nodes partition inc[0 .. 4*ntet-1]; a cut splits the
   slot of v into the slots of v and its copy, so incidence never needs more memory.
   Fields are read-only for callers: change a mesh only through amps_mesh_* functions. */
typedef struct amps_mesh {
    amps_int nnode;       /* nodes in use */
    amps_int nfile;       /* nodes given at creation */
    amps_int ntet;        /* tetrahedra */
    amps_int node_cap;    /* allocated node capacity (>= nnode) */
    double *xyz;          /* 3 * node_cap: reference coordinates of node v at xyz[3v .. 3v+2] */
    amps_int *tet;        /* 4 * ntet node indices */
    double *E, *nu;       /* ntet: Young's modulus and Poisson ratio */
    amps_int *origin;     /* node_cap */
    amps_int *inc_ptr;    /* node_cap */
    amps_int *inc_len;    /* node_cap */
    amps_int *inc;        /* 4 * ntet tet indices */
} amps_mesh;

/* Mesh with nnode nodes (xyz: 3 per node) and ntet tets (tet: 4 node indices each), copied.
   Errors: AMPS_ERR_INDEX (node index out of range), AMPS_ERR_VALUE (non-finite coordinate),
   AMPS_ERR_MESH (no tets, or a degenerate tet: volume < 1e-12 L^3, L its longest edge). */
AMPS_API amps_mesh *amps_mesh_create(amps_ctx *ctx, amps_int nnode, const double *xyz, amps_int ntet, const amps_int *tet);
AMPS_API void amps_mesh_free(amps_ctx *ctx, amps_mesh *m);
/* Sets the material of all tets / of tet t. Requires E > 0 finite and -1 < nu < 0.5. */
AMPS_API amps_status amps_mesh_set_material(amps_ctx *ctx, amps_mesh *m, double E, double nu);
AMPS_API amps_status amps_mesh_set_tet_material(amps_ctx *ctx, amps_mesh *m, amps_int t, double E, double nu);
/* Structured grid of nx * ny * nz nodes (node (i,j,k) = i + nx (j + ny k) at (i hx, j hy, k hz)),
   each grid cell split into 6 tets around its main diagonal (Kuhn split, conforming).
   amps_mesh_beam(h)  = grid 5 x 5 x h, spacing 1 (z along the beam, h >= 2).
   amps_mesh_brick(R) = 1 x 1 x 2 brick: grid (R+1) x (R+1) x (2R+1), spacing 1/R (R >= 1). */
AMPS_API amps_mesh *amps_mesh_grid(amps_ctx *ctx, amps_int nx, amps_int ny, amps_int nz, double hx, double hy, double hz);
AMPS_API amps_mesh *amps_mesh_beam(amps_ctx *ctx, amps_int h);
AMPS_API amps_mesh *amps_mesh_brick(amps_ctx *ctx, amps_int R);
/* Makes room for node_cap nodes so that cuts up to that many nodes allocate nothing. */
AMPS_API amps_status amps_mesh_reserve(amps_ctx *ctx, amps_mesh *m, amps_int node_cap);
/* Number of tets containing v (0 if v is out of range). */
AMPS_API amps_int amps_mesh_degree(const amps_mesh *m, amps_int v);
/* The tets containing v, ascending; *deg receives their number (NULL and 0 if v is invalid). */
AMPS_API const amps_int *amps_mesh_incident(const amps_mesh *m, amps_int v, amps_int *deg);
/* Verifies the mesh invariants (indices, origins, incidence slots against tet). O(nnode + ntet). */
AMPS_API amps_status amps_mesh_check(amps_ctx *ctx, const amps_mesh *m);

typedef enum amps_cmp { AMPS_LT = 0, AMPS_GT = 1 } amps_cmp;
/* Nodes v (copies included) with xyz[3v+axis] < value (AMPS_LT) or > value (AMPS_GT), ascending,
   written to out (room for nnode; may be NULL to count). Returns their number, -1 if axis is
   not 0, 1, 2 (x, y, z). */
AMPS_API amps_int amps_mesh_select(const amps_mesh *m, int axis, amps_cmp cmp, double value, amps_int *out);
/* Equation numbers in node order: dof[3v+d] = next number, or -1 if fixed[v] (fixed may be NULL)
   or v lies in no tet. dof has 3 * nnode entries. Returns the number of equations. */
AMPS_API amps_int amps_mesh_number_dofs(const amps_mesh *m, const unsigned char *fixed, amps_int *dof);
/* Reference coordinates of the 4 nodes of tet t (X[3a+c]). */
AMPS_API void amps_mesh_tet_coords(const amps_mesh *m, amps_int t, double X[12]);
/* amps_tet_stiffness of tet t with its material; returns its volume. */
AMPS_API double amps_mesh_tet_stiffness(const amps_mesh *m, amps_int t, double Ke[144]);
/* Upper triangle of the stiffness matrix K = sum_t Ke(t) over all tets, in equations: the DOF
   d of node v is equation dof[3v+d] (0 <= dof < ndof) or eliminated (-1; its rows and columns
   are dropped). dof has 3 * nnode entries and uses each equation at most once; an equation
   used by no DOF gives an empty column. Rows are sorted in each column, duplicates summed. */
AMPS_API amps_csc *amps_mesh_assemble(amps_ctx *ctx, const amps_mesh *m, const amps_int *dof, amps_int ndof);
/* Cuts at node v with the plane through p with normal nrm: v gets a copy v' = nnode (same
   reference coordinates, origin[v'] = origin[v]), and every tet containing v whose reference
   centroid c = (x_a + x_b + x_c + x_d) / 4 has sum_k (c_k - p_k) nrm_k < 0 (strictly; a tie
   keeps v) now uses v' instead of v. Element matrices do not change: the rows and columns of v
   in the moved tets' Ke now belong to v'.
   moved (room for amps_mesh_degree(m, v); also used as scratch) receives those tets, ascending;
   *nmoved their number; *new_node = v' (new_node, nmoved may be NULL). Cost O(degree of v);
   allocates only when nnode == node_cap (grows by half; on failure the mesh is unchanged).
   If all or none of the tets would move: nothing changes, *nmoved = 0, *new_node = -1 and
   AMPS_WARN_NOOP is returned. Errors: AMPS_ERR_INDEX (v), AMPS_ERR_VALUE (NaN/Inf in p or nrm),
   AMPS_ERR_ARG (NULL pointer, zero normal), AMPS_ERR_OOM / AMPS_ERR_CAPACITY (growth). */
AMPS_API amps_status amps_mesh_cut(amps_ctx *ctx, amps_mesh *m, amps_int v, const double p[3], const double nrm[3],
                                   amps_int *new_node, amps_int *moved, amps_int *nmoved);
/* Per-tet stress for displacements disp (3 per node): sigma (6 per tet), von_mises (1 per tet),
   principal (3 per tet, descending); each output may be NULL. */
AMPS_API amps_status amps_mesh_stress(amps_ctx *ctx, const amps_mesh *m, const double *disp, double *sigma,
                                      double *von_mises, double *principal);

/* ---- linear tetrahedron (P1) elasticity ----
   X[3a+c]: coordinate c of node a (a = 0..3). Voigt order for strain and stress:
   xx, yy, zz, xy, yz, zx; strains use engineering shear (gamma_xy = du/dy + dv/dx). */

/* G[3a+c] = d N_a / d x_c, the constant gradients of the barycentric coordinates.
   Returns the signed volume det[x1-x0, x2-x0, x3-x0] / 6; 0 (and G = 0) if degenerate. */
AMPS_API double amps_tet_gradients(const double X[12], double G[12]);
/* Strain-displacement matrix B (6 x 12, row-major) from the gradients: eps = B u. */
AMPS_API void amps_tet_B(const double G[12], double B[72]);
/* Isotropic elasticity matrix C (6 x 6): sigma = C eps, lambda = E nu / ((1+nu)(1-2nu)), mu = E / (2(1+nu)). */
AMPS_API void amps_elasticity(double E, double nu, double C[36]);
/* Ke = V B^T C B (12 x 12, row-major, DOF 3a+c), V = |volume|. Returns V; 0 (Ke = 0) if degenerate. */
AMPS_API double amps_tet_stiffness(const double X[12], double E, double nu, double Ke[144]);
/* eps = B u for nodal displacements u[3a+c]. Returns |volume|; 0 (eps = 0) if degenerate. */
AMPS_API double amps_tet_strain(const double X[12], const double u[12], double eps[6]);
/* sigma = C B u, von Mises stress and principal stresses (descending); outputs other than sigma
   may be NULL. Returns |volume|; 0 (outputs 0) if degenerate. */
AMPS_API double amps_tet_stress(const double X[12], double E, double nu, const double u[12], double sigma[6],
                                double *von_mises, double principal[3]);
/* Eigenvalues (descending) of the symmetric matrix [s0 s3 s5; s3 s1 s4; s5 s4 s2] (closed form). */
AMPS_API void amps_sym3_eig(const double s[6], double lam[3]);
#endif /* AMPS_NO_FEM */

/* =================================== I/O =================================== */
#if !defined(AMPS_NO_FEM) && !defined(AMPS_NO_STDIO)
/* @@API io: owned by fem */
/* Mesh readers. Nodes are numbered in file order from 0; tets keep file order. Return NULL on
   failure, with AMPS_ERR_PARSE and "file:line: message" in ctx for malformed input (AMPS_ERR_IO
   if a file cannot be read, AMPS_ERR_MESH "file:line: ..." for a degenerate tet).
   TetGen .node/.ele: index base = first point number in .node (0 or 1), point numbers
     consecutive; attributes and boundary markers ignored; 4 or 10 nodes per tet (first 4 used).
   Gmsh .msh ASCII 2.x and 4.1: tetrahedra are element type 4; other types are skipped; node
     tags may be any distinct integers. Binary files are rejected.
   MEDIT .mesh (ASCII): Dimension 3, Vertices, Tetrahedra; other keywords are skipped.
   amps_mesh_read picks the reader by extension: .node (and the .ele of the same name), .ele
   (and the .node), .msh, .mesh. The *_mem variants parse a buffer of len bytes (no NUL needed);
   name is used in messages. */
AMPS_API amps_mesh *amps_mesh_read(amps_ctx *ctx, const char *path);
AMPS_API amps_mesh *amps_mesh_read_tetgen(amps_ctx *ctx, const char *node_path, const char *ele_path);
AMPS_API amps_mesh *amps_mesh_read_gmsh(amps_ctx *ctx, const char *path);
AMPS_API amps_mesh *amps_mesh_read_medit(amps_ctx *ctx, const char *path);
AMPS_API amps_mesh *amps_mesh_read_tetgen_mem(amps_ctx *ctx, const char *node_buf, size_t node_len, const char *node_name,
                                              const char *ele_buf, size_t ele_len, const char *ele_name);
AMPS_API amps_mesh *amps_mesh_read_gmsh_mem(amps_ctx *ctx, const char *buf, size_t len, const char *name);
AMPS_API amps_mesh *amps_mesh_read_medit_mem(amps_ctx *ctx, const char *buf, size_t len, const char *name);

/* VTK XML UnstructuredGrid (ASCII) of the mesh in its reference configuration (copies are
   separate points, so a cut opens under "Warp By Vector"). Point data: "displacement" (disp,
   3 per node, if given) and "origin". Cell data: "von_mises" (1 per tet, if given),
   "principal_stress" (3 per tet, if given) and "cut" (1 if the tet uses a cut copy node). */
AMPS_API amps_status amps_write_vtu(amps_ctx *ctx, const char *path, const amps_mesh *m, const double *disp,
                                    const double *von_mises, const double *principal);
/* Writers of all nnode nodes and the tets (copies become ordinary nodes; materials are not
   written). TetGen: base.node and base.ele with numbering from first_index (0 or 1).
   Gmsh: version 2 (2.2) or 4 (4.1), ASCII. MEDIT: .mesh, version 2. */
AMPS_API amps_status amps_write_tetgen(amps_ctx *ctx, const char *base, const amps_mesh *m, int first_index);
AMPS_API amps_status amps_write_gmsh(amps_ctx *ctx, const char *path, const amps_mesh *m, int version);
AMPS_API amps_status amps_write_medit(amps_ctx *ctx, const char *path, const amps_mesh *m);
#endif

#ifdef __cplusplus
}
#endif

#endif /* AMPS_H */

/* ========================================================================== */
/* =============================== IMPLEMENTATION ============================ */
/* ========================================================================== */
#ifdef AMPS_IMPLEMENTATION
#ifndef AMPS_IMPLEMENTATION_DONE
#define AMPS_IMPLEMENTATION_DONE

#include <stdlib.h>
#include <string.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#ifdef _OPENMP
#include <omp.h>
#endif

#ifndef AMPS_ASSERT
#include <assert.h>
#define AMPS_ASSERT(x) assert(x)
#endif

#if defined(AMPS_MALLOC) && defined(AMPS_REALLOC) && defined(AMPS_FREE)
/* user allocator */
#elif !defined(AMPS_MALLOC) && !defined(AMPS_REALLOC) && !defined(AMPS_FREE)
#define AMPS_MALLOC(sz, u) ((void)(u), malloc(sz))
#define AMPS_REALLOC(p, sz, u) ((void)(u), realloc((p), (sz)))
#define AMPS_FREE(p, u) ((void)(u), free(p))
#else
#error "amps.h: define all of AMPS_MALLOC, AMPS_REALLOC and AMPS_FREE, or none"
#endif

#ifdef __cplusplus
extern "C" {
#endif

/* compile-time size checks */
typedef char amps__check_int_size[(sizeof(amps_int) >= 4) ? 1 : -1];
typedef char amps__check_int_signed[((amps_int)-1 < 0) ? 1 : -1];

#ifdef __cplusplus
#define AMPS__CAST(T, x) (static_cast<T>(x))
#else
#define AMPS__CAST(T, x) ((T)(x))
#endif

/* =============================== common =============================== */

AMPS_API void amps_ctx_init(amps_ctx *ctx) {
    if (!ctx) return;
    memset(ctx, 0, sizeof(*ctx));
}

AMPS_API const char *amps_status_str(amps_status s) {
    switch (s) {
    case AMPS_OK: return "ok";
    case AMPS_ERR_ARG: return "invalid argument";
    case AMPS_ERR_OOM: return "out of memory";
    case AMPS_ERR_INDEX: return "index out of range";
    case AMPS_ERR_PATTERN: return "invalid sparsity pattern";
    case AMPS_ERR_VALUE: return "NaN or Inf value";
    case AMPS_ERR_NOT_SPD: return "matrix not positive definite";
    case AMPS_ERR_SINGULAR_UPDATE: return "update makes the system singular";
    case AMPS_ERR_CAPACITY: return "capacity exhausted";
    case AMPS_ERR_MESH: return "invalid mesh";
    case AMPS_ERR_IO: return "i/o error";
    case AMPS_ERR_PARSE: return "parse error";
    case AMPS_ERR_STATE: return "invalid state";
    case AMPS_ERR_UNSUPPORTED: return "unsupported in this build";
    case AMPS_WARN_NOOP: return "no-op";
    }
    return "unknown status";
}

/* Records status s and a printf-style message in ctx; returns s. */
static amps_status amps__err(amps_ctx *ctx, amps_status s, const char *fmt, ...) {
    if (ctx) {
        va_list ap;
        ctx->status = s;
        va_start(ap, fmt);
        vsnprintf(ctx->msg, sizeof(ctx->msg), fmt, ap);
        va_end(ap);
    }
    return s;
}

/* n*size bytes, or NULL (with AMPS_ERR_OOM in ctx) on overflow or failure. Never 0 bytes. */
static void *amps__malloc(amps_ctx *ctx, size_t n, size_t size) {
    void *p;
    if (n == 0) n = 1;
    if (size && n > ((size_t)-1) / size) { amps__err(ctx, AMPS_ERR_OOM, "allocation size overflow"); return NULL; }
    p = AMPS_MALLOC(n * size, ctx ? ctx->alloc_user : NULL);
    if (!p) amps__err(ctx, AMPS_ERR_OOM, "out of memory allocating %lu bytes", (unsigned long)(n * size));
    return p;
}

static void *amps__calloc(amps_ctx *ctx, size_t n, size_t size) {
    void *p = amps__malloc(ctx, n, size);
    if (p) memset(p, 0, (n ? n : 1) * size);
    return p;
}

/* Resizes *pp to n*size bytes; on failure *pp is unchanged and AMPS_ERR_OOM is returned. */
static amps_status amps__realloc(amps_ctx *ctx, void **pp, size_t n, size_t size) {
    void *p;
    if (n == 0) n = 1;
    if (size && n > ((size_t)-1) / size) return amps__err(ctx, AMPS_ERR_OOM, "allocation size overflow");
    p = AMPS_REALLOC(*pp, n * size, ctx ? ctx->alloc_user : NULL);
    if (!p) return amps__err(ctx, AMPS_ERR_OOM, "out of memory reallocating %lu bytes", (unsigned long)(n * size));
    *pp = p;
    return AMPS_OK;
}

static void amps__free(amps_ctx *ctx, void *p) {
    if (p) AMPS_FREE(p, ctx ? ctx->alloc_user : NULL);
}

static int amps__isfinite(double v) { return v - v == 0.0; }

/* ============================ sparse matrix impl ============================ */
/* @@SECTION sparse: owned by core */

/* ============================== ordering impl ============================== */
/* @@SECTION ordering: owned by ordering */

/* ==================== symbolic + numeric LDL^T impl ==================== */
/* @@SECTION factor: owned by core */

/* ================= triangular solves and closures impl ================= */
/* @@SECTION solve: owned by core */

/* ============================ augmented updates impl ============================ */
/* @@SECTION update: owned by engine */

/* ================================ FEM scene impl ================================ */
#ifndef AMPS_NO_FEM
/* @@SECTION fem: owned by fem */
/* TEMP: provided by the sparse section */
AMPS_API amps_csc *amps_csc_alloc(amps_ctx *ctx, amps_int nrow, amps_int ncol, amps_int nzmax, int with_values) {
    amps_csc *A;
    if (nrow < 0 || ncol < 0 || nzmax < 0) {
        amps__err(ctx, AMPS_ERR_ARG, "amps_csc_alloc: negative size");
        return NULL;
    }
    A = AMPS__CAST(amps_csc *, amps__calloc(ctx, 1, sizeof(amps_csc)));
    if (!A) return NULL;
    A->nrow = nrow;
    A->ncol = ncol;
    A->p = AMPS__CAST(amps_int *, amps__calloc(ctx, (size_t)ncol + 1, sizeof(amps_int)));
    A->i = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)nzmax, sizeof(amps_int)));
    A->x = with_values ? AMPS__CAST(double *, amps__malloc(ctx, (size_t)nzmax, sizeof(double))) : NULL;
    if (!A->p || !A->i || (with_values && !A->x)) {
        amps_csc_free(ctx, A);
        return NULL;
    }
    return A;
}

/* TEMP: provided by the sparse section */
AMPS_API void amps_csc_free(amps_ctx *ctx, amps_csc *A) {
    if (!A) return;
    amps__free(ctx, A->p);
    amps__free(ctx, A->i);
    amps__free(ctx, A->x);
    amps__free(ctx, A);
}

/* Largest amps_int. */
static amps_int amps__fem_imax(void) {
    return (amps_int)((((unsigned long long)1) << (8 * sizeof(amps_int) - 1)) - 1);
}

/* ---- P1 element ---- */

AMPS_API double amps_tet_gradients(const double X[12], double G[12]) {
    double J[9], det, inv;
    int a, b, c;
    for (a = 0; a < 3; a++)
        for (b = 0; b < 3; b++) J[3 * a + b] = X[3 * (b + 1) + a] - X[a];
    det = J[0] * (J[4] * J[8] - J[5] * J[7]) - J[1] * (J[3] * J[8] - J[5] * J[6]) + J[2] * (J[3] * J[7] - J[4] * J[6]);
    if (det == 0.0 || !amps__isfinite(det)) {
        for (a = 0; a < 12; a++) G[a] = 0.0;
        return 0.0;
    }
    inv = 1.0 / det;
    /* rows 1..3 of G = rows of J^{-1} (cofactors / det); row 0 = -(sum of the others) */
    G[3] = (J[4] * J[8] - J[5] * J[7]) * inv;
    G[4] = (J[2] * J[7] - J[1] * J[8]) * inv;
    G[5] = (J[1] * J[5] - J[2] * J[4]) * inv;
    G[6] = (J[5] * J[6] - J[3] * J[8]) * inv;
    G[7] = (J[0] * J[8] - J[2] * J[6]) * inv;
    G[8] = (J[2] * J[3] - J[0] * J[5]) * inv;
    G[9] = (J[3] * J[7] - J[4] * J[6]) * inv;
    G[10] = (J[1] * J[6] - J[0] * J[7]) * inv;
    G[11] = (J[0] * J[4] - J[1] * J[3]) * inv;
    for (c = 0; c < 3; c++) G[c] = -(G[3 + c] + G[6 + c] + G[9 + c]);
    return det / 6.0;
}

AMPS_API void amps_tet_B(const double G[12], double B[72]) {
    int a, k;
    for (k = 0; k < 72; k++) B[k] = 0.0;
    for (a = 0; a < 4; a++) {
        const double gx = G[3 * a], gy = G[3 * a + 1], gz = G[3 * a + 2];
        B[0 * 12 + 3 * a] = gx;
        B[1 * 12 + 3 * a + 1] = gy;
        B[2 * 12 + 3 * a + 2] = gz;
        B[3 * 12 + 3 * a] = gy;
        B[3 * 12 + 3 * a + 1] = gx;
        B[4 * 12 + 3 * a + 1] = gz;
        B[4 * 12 + 3 * a + 2] = gy;
        B[5 * 12 + 3 * a] = gz;
        B[5 * 12 + 3 * a + 2] = gx;
    }
}

/* Lame parameters of (E, nu). */
static void amps__lame(double E, double nu, double *lam, double *mu) {
    *lam = E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu));
    *mu = E / (2.0 * (1.0 + nu));
}

AMPS_API void amps_elasticity(double E, double nu, double C[36]) {
    double lam, mu;
    int a, b;
    amps__lame(E, nu, &lam, &mu);
    for (a = 0; a < 36; a++) C[a] = 0.0;
    for (a = 0; a < 3; a++) {
        for (b = 0; b < 3; b++) C[6 * a + b] = lam;
        C[6 * a + a] += 2.0 * mu;
        C[6 * (a + 3) + a + 3] = mu;
    }
}

/* Ke[3a+i][3b+k] = V (lam g_a[i] g_b[k] + mu g_a[k] g_b[i] + mu (g_a . g_b) delta_ik),
   which is V B^T C B written out. */
AMPS_API double amps_tet_stiffness(const double X[12], double E, double nu, double Ke[144]) {
    double G[12], vol, lam, mu;
    int a, b, i, k;
    vol = fabs(amps_tet_gradients(X, G));
    if (vol == 0.0) {
        for (a = 0; a < 144; a++) Ke[a] = 0.0;
        return 0.0;
    }
    amps__lame(E, nu, &lam, &mu);
    for (a = 0; a < 4; a++)
        for (b = a; b < 4; b++) {
            const double *ga = G + 3 * a, *gb = G + 3 * b;
            double dot = mu * (ga[0] * gb[0] + ga[1] * gb[1] + ga[2] * gb[2]);
            for (i = 0; i < 3; i++)
                for (k = 0; k < 3; k++) {
                    double v = lam * ga[i] * gb[k] + mu * ga[k] * gb[i];
                    if (i == k) v += dot;
                    v *= vol;
                    Ke[12 * (3 * a + i) + 3 * b + k] = v; /* block (a,b) and its mirror: exactly symmetric */
                    Ke[12 * (3 * b + k) + 3 * a + i] = v;
                }
        }
    return vol;
}

/* eps from gradients G and nodal displacements u. */
static void amps__tet_eps(const double G[12], const double u[12], double eps[6]) {
    int k;
    for (k = 0; k < 6; k++) eps[k] = 0.0;
    for (k = 0; k < 4; k++) {
        const double *g = G + 3 * k, *w = u + 3 * k;
        eps[0] += g[0] * w[0];
        eps[1] += g[1] * w[1];
        eps[2] += g[2] * w[2];
        eps[3] += g[1] * w[0] + g[0] * w[1];
        eps[4] += g[2] * w[1] + g[1] * w[2];
        eps[5] += g[2] * w[0] + g[0] * w[2];
    }
}

AMPS_API double amps_tet_strain(const double X[12], const double u[12], double eps[6]) {
    double G[12], vol = fabs(amps_tet_gradients(X, G));
    amps__tet_eps(G, u, eps);
    return vol;
}

/* Closed form without the accuracy loss of the plain trigonometric formula near a double
   eigenvalue: take the eigenvalue l0 that is well separated from the other two (the largest
   if det(B) >= 0, else the smallest), its eigenvector v from the largest cross product of two
   rows of A - l0 I, and the other two as the eigenvalues of the 2 x 2 restriction of A to the
   plane orthogonal to v. Works on A scaled by its largest entry and shifted by tr(A)/3. */
AMPS_API void amps_sym3_eig(const double s[6], double lam[3]) {
    const double pi = 3.14159265358979323846;
    double a[6], scale = 0.0, q, p, p2, r, phi, l0, l1, l2, t;
    double R[3][3], c[3], v[3] = {0, 0, 0}, u[3], w[3], Au[3], Aw[3], best = 0.0, aa, bb, cc, mid, half;
    int k, i, j;
    for (k = 0; k < 6; k++) {
        if (!amps__isfinite(s[k])) {
            lam[0] = lam[1] = lam[2] = s[k] - s[k]; /* NaN */
            return;
        }
        if (fabs(s[k]) > scale) scale = fabs(s[k]);
    }
    if (s[3] == 0.0 && s[4] == 0.0 && s[5] == 0.0) {
        l0 = s[0]; l1 = s[1]; l2 = s[2];
    } else {
        for (k = 0; k < 6; k++) a[k] = s[k] / scale;
        q = (a[0] + a[1] + a[2]) / 3.0;
        a[0] -= q; a[1] -= q; a[2] -= q;
        p2 = a[0] * a[0] + a[1] * a[1] + a[2] * a[2] + 2.0 * (a[3] * a[3] + a[4] * a[4] + a[5] * a[5]);
        p = sqrt(p2 / 6.0);
        /* B = A / p has trace 0 and |B|_F^2 = 6: eigenvalues 2 cos(phi + 2 pi k / 3), cos(3 phi) = det(B) / 2 */
        r = 0.5 * (a[0] * (a[1] * a[2] - a[4] * a[4]) - a[3] * (a[3] * a[2] - a[4] * a[5]) + a[5] * (a[3] * a[4] - a[1] * a[5])) / (p * p * p);
        phi = r <= -1.0 ? pi / 3.0 : r >= 1.0 ? 0.0 : acos(r) / 3.0;
        l0 = p * (r >= 0.0 ? 2.0 * cos(phi) : 2.0 * cos(phi + 2.0 * pi / 3.0));
        R[0][0] = a[0] - l0; R[0][1] = a[3]; R[0][2] = a[5];
        R[1][0] = a[3]; R[1][1] = a[1] - l0; R[1][2] = a[4];
        R[2][0] = a[5]; R[2][1] = a[4]; R[2][2] = a[2] - l0;
        for (i = 0; i < 3; i++)
            for (j = i + 1; j < 3; j++) {
                double n2;
                c[0] = R[i][1] * R[j][2] - R[i][2] * R[j][1];
                c[1] = R[i][2] * R[j][0] - R[i][0] * R[j][2];
                c[2] = R[i][0] * R[j][1] - R[i][1] * R[j][0];
                n2 = c[0] * c[0] + c[1] * c[1] + c[2] * c[2];
                if (n2 > best) {
                    best = n2;
                    v[0] = c[0]; v[1] = c[1]; v[2] = c[2];
                }
            }
        if (best == 0.0) {
            l1 = l2 = l0;
        } else {
            t = 1.0 / sqrt(best);
            v[0] *= t; v[1] *= t; v[2] *= t;
            if (fabs(v[0]) > fabs(v[1])) {
                t = 1.0 / sqrt(v[0] * v[0] + v[2] * v[2]);
                u[0] = -v[2] * t; u[1] = 0.0; u[2] = v[0] * t;
            } else {
                t = 1.0 / sqrt(v[1] * v[1] + v[2] * v[2]);
                u[0] = 0.0; u[1] = v[2] * t; u[2] = -v[1] * t;
            }
            w[0] = v[1] * u[2] - v[2] * u[1];
            w[1] = v[2] * u[0] - v[0] * u[2];
            w[2] = v[0] * u[1] - v[1] * u[0];
            Au[0] = a[0] * u[0] + a[3] * u[1] + a[5] * u[2];
            Au[1] = a[3] * u[0] + a[1] * u[1] + a[4] * u[2];
            Au[2] = a[5] * u[0] + a[4] * u[1] + a[2] * u[2];
            Aw[0] = a[0] * w[0] + a[3] * w[1] + a[5] * w[2];
            Aw[1] = a[3] * w[0] + a[1] * w[1] + a[4] * w[2];
            Aw[2] = a[5] * w[0] + a[4] * w[1] + a[2] * w[2];
            aa = u[0] * Au[0] + u[1] * Au[1] + u[2] * Au[2];
            bb = u[0] * Aw[0] + u[1] * Aw[1] + u[2] * Aw[2];
            cc = w[0] * Aw[0] + w[1] * Aw[1] + w[2] * Aw[2];
            mid = 0.5 * (aa + cc);
            half = hypot(0.5 * (aa - cc), bb);
            l1 = mid + half;
            l2 = mid - half;
        }
        l0 = (l0 + q) * scale;
        l1 = (l1 + q) * scale;
        l2 = (l2 + q) * scale;
    }
    if (l0 < l1) { t = l0; l0 = l1; l1 = t; }
    if (l1 < l2) { t = l1; l1 = l2; l2 = t; }
    if (l0 < l1) { t = l0; l0 = l1; l1 = t; }
    lam[0] = l0;
    lam[1] = l1;
    lam[2] = l2;
}

AMPS_API double amps_tet_stress(const double X[12], double E, double nu, const double u[12], double sigma[6],
                                double *von_mises, double principal[3]) {
    double G[12], eps[6], lam, mu, tr, vol;
    vol = fabs(amps_tet_gradients(X, G));
    amps__tet_eps(G, u, eps);
    amps__lame(E, nu, &lam, &mu);
    tr = eps[0] + eps[1] + eps[2];
    sigma[0] = lam * tr + 2.0 * mu * eps[0];
    sigma[1] = lam * tr + 2.0 * mu * eps[1];
    sigma[2] = lam * tr + 2.0 * mu * eps[2];
    sigma[3] = mu * eps[3];
    sigma[4] = mu * eps[4];
    sigma[5] = mu * eps[5];
    if (von_mises) {
        double d01 = sigma[0] - sigma[1], d12 = sigma[1] - sigma[2], d20 = sigma[2] - sigma[0];
        *von_mises = sqrt(0.5 * (d01 * d01 + d12 * d12 + d20 * d20) +
                          3.0 * (sigma[3] * sigma[3] + sigma[4] * sigma[4] + sigma[5] * sigma[5]));
    }
    if (principal) amps_sym3_eig(sigma, principal);
    return vol;
}

/* ---- mesh ---- */

AMPS_API void amps_mesh_free(amps_ctx *ctx, amps_mesh *m) {
    if (!m) return;
    amps__free(ctx, m->xyz);
    amps__free(ctx, m->tet);
    amps__free(ctx, m->E);
    amps__free(ctx, m->nu);
    amps__free(ctx, m->origin);
    amps__free(ctx, m->inc_ptr);
    amps__free(ctx, m->inc_len);
    amps__free(ctx, m->inc);
    amps__free(ctx, m);
}

/* Error unless tet t (nodes tv) has volume > 1e-12 L^3, L = longest edge. */
static amps_status amps__mesh_check_tet(amps_ctx *ctx, const char *fn, amps_int t, const amps_int *tv, const double *xyz) {
    double X[12], G[12], L2 = 0.0, vol;
    int a, b, c;
    for (a = 0; a < 4; a++)
        for (c = 0; c < 3; c++) X[3 * a + c] = xyz[3 * tv[a] + c];
    for (a = 0; a < 4; a++)
        for (b = a + 1; b < 4; b++) {
            double d2 = 0.0;
            for (c = 0; c < 3; c++) d2 += (X[3 * a + c] - X[3 * b + c]) * (X[3 * a + c] - X[3 * b + c]);
            if (d2 > L2) L2 = d2;
        }
    vol = fabs(amps_tet_gradients(X, G));
    if (!(vol > 1e-12 * L2 * sqrt(L2)))
        return amps__err(ctx, AMPS_ERR_MESH, "%s: tetrahedron %lld (nodes %lld %lld %lld %lld) is degenerate: volume %g, longest edge %g",
                         fn, (long long)t, (long long)tv[0], (long long)tv[1], (long long)tv[2], (long long)tv[3], vol, sqrt(L2));
    return AMPS_OK;
}

/* Allocates a mesh with room for node_cap nodes and ntet tets (contents uninitialized). */
static amps_mesh *amps__mesh_alloc(amps_ctx *ctx, amps_int node_cap, amps_int ntet) {
    amps_mesh *m = AMPS__CAST(amps_mesh *, amps__calloc(ctx, 1, sizeof(amps_mesh)));
    size_t nc = (size_t)node_cap, nt = (size_t)ntet;
    if (!m) return NULL;
    m->xyz = AMPS__CAST(double *, amps__malloc(ctx, 3 * nc, sizeof(double)));
    m->origin = AMPS__CAST(amps_int *, amps__malloc(ctx, nc, sizeof(amps_int)));
    m->inc_ptr = AMPS__CAST(amps_int *, amps__malloc(ctx, nc, sizeof(amps_int)));
    m->inc_len = AMPS__CAST(amps_int *, amps__malloc(ctx, nc, sizeof(amps_int)));
    m->tet = AMPS__CAST(amps_int *, amps__malloc(ctx, 4 * nt, sizeof(amps_int)));
    m->inc = AMPS__CAST(amps_int *, amps__malloc(ctx, 4 * nt, sizeof(amps_int)));
    m->E = AMPS__CAST(double *, amps__malloc(ctx, nt, sizeof(double)));
    m->nu = AMPS__CAST(double *, amps__malloc(ctx, nt, sizeof(double)));
    if (!m->xyz || !m->origin || !m->inc_ptr || !m->inc_len || !m->tet || !m->inc || !m->E || !m->nu) {
        amps_mesh_free(ctx, m);
        return NULL;
    }
    m->node_cap = node_cap;
    return m;
}

/* amps_mesh_create with the calling function's name fn for messages; *bad (if not NULL)
   receives the tet an AMPS_ERR_INDEX / AMPS_ERR_MESH error is about, else -1. */
static amps_mesh *amps__mesh_new(amps_ctx *ctx, const char *fn, amps_int nnode, const double *xyz, amps_int ntet,
                                 const amps_int *tet, amps_int *bad) {
    amps_mesh *m;
    amps_int v, t, q, k;
    if (bad) *bad = -1;
    if (nnode < 0 || ntet < 0 || (nnode > 0 && !xyz) || (ntet > 0 && !tet)) {
        amps__err(ctx, AMPS_ERR_ARG, "%s: negative count or NULL array", fn);
        return NULL;
    }
    if (ntet == 0) {
        amps__err(ctx, AMPS_ERR_MESH, "%s: the mesh has no tetrahedra", fn);
        return NULL;
    }
    if (nnode > amps__fem_imax() / 3 || ntet > amps__fem_imax() / 4) {
        amps__err(ctx, AMPS_ERR_ARG, "%s: %lld nodes / %lld tetrahedra exceed the index type", fn, (long long)nnode, (long long)ntet);
        return NULL;
    }
    for (k = 0; k < 3 * nnode; k++)
        if (!amps__isfinite(xyz[k])) {
            amps__err(ctx, AMPS_ERR_VALUE, "%s: node %lld has a non-finite coordinate", fn, (long long)(k / 3));
            return NULL;
        }
    for (t = 0; t < ntet; t++) {
        for (q = 0; q < 4; q++) {
            k = tet[4 * t + q];
            if (k < 0 || k >= nnode) {
                if (bad) *bad = t;
                amps__err(ctx, AMPS_ERR_INDEX, "%s: tetrahedron %lld: node index %lld out of range [0, %lld)", fn, (long long)t,
                          (long long)k, (long long)nnode);
                return NULL;
            }
        }
        if (amps__mesh_check_tet(ctx, fn, t, tet + 4 * t, xyz)) {
            if (bad) *bad = t;
            return NULL;
        }
    }
    m = amps__mesh_alloc(ctx, nnode, ntet);
    if (!m) return NULL;
    m->nnode = m->nfile = nnode;
    m->ntet = ntet;
    memcpy(m->xyz, xyz, sizeof(double) * 3 * (size_t)nnode);
    memcpy(m->tet, tet, sizeof(amps_int) * 4 * (size_t)ntet);
    for (t = 0; t < ntet; t++) {
        m->E[t] = 1.0;
        m->nu[t] = 0.3;
    }
    /* incidence by counting sort over tets, so each list is ascending */
    for (v = 0; v < nnode; v++) {
        m->origin[v] = v;
        m->inc_len[v] = 0;
    }
    for (k = 0; k < 4 * ntet; k++) m->inc_len[tet[k]]++;
    for (v = 0, k = 0; v < nnode; v++) {
        m->inc_ptr[v] = k;
        k += m->inc_len[v];
        m->inc_len[v] = 0;
    }
    for (k = 0; k < 4 * ntet; k++) {
        v = tet[k];
        m->inc[m->inc_ptr[v] + m->inc_len[v]++] = k / 4;
    }
    return m;
}

AMPS_API amps_mesh *amps_mesh_create(amps_ctx *ctx, amps_int nnode, const double *xyz, amps_int ntet, const amps_int *tet) {
    return amps__mesh_new(ctx, "amps_mesh_create", nnode, xyz, ntet, tet, NULL);
}

static amps_status amps__check_material(amps_ctx *ctx, const char *fn, double E, double nu) {
    if (!amps__isfinite(E) || !amps__isfinite(nu)) return amps__err(ctx, AMPS_ERR_VALUE, "%s: non-finite material (E %g, nu %g)", fn, E, nu);
    if (!(E > 0.0)) return amps__err(ctx, AMPS_ERR_ARG, "%s: Young's modulus E = %g must be positive", fn, E);
    if (!(nu > -1.0 && nu < 0.5)) return amps__err(ctx, AMPS_ERR_ARG, "%s: Poisson ratio nu = %g must lie in (-1, 0.5)", fn, nu);
    return AMPS_OK;
}

AMPS_API amps_status amps_mesh_set_material(amps_ctx *ctx, amps_mesh *m, double E, double nu) {
    amps_int t;
    amps_status s;
    if (!m) return amps__err(ctx, AMPS_ERR_ARG, "amps_mesh_set_material: NULL mesh");
    s = amps__check_material(ctx, "amps_mesh_set_material", E, nu);
    if (s) return s;
    for (t = 0; t < m->ntet; t++) {
        m->E[t] = E;
        m->nu[t] = nu;
    }
    return AMPS_OK;
}

AMPS_API amps_status amps_mesh_set_tet_material(amps_ctx *ctx, amps_mesh *m, amps_int t, double E, double nu) {
    amps_status s;
    if (!m) return amps__err(ctx, AMPS_ERR_ARG, "amps_mesh_set_tet_material: NULL mesh");
    if (t < 0 || t >= m->ntet)
        return amps__err(ctx, AMPS_ERR_INDEX, "amps_mesh_set_tet_material: tetrahedron %lld out of range [0, %lld)", (long long)t,
                         (long long)m->ntet);
    s = amps__check_material(ctx, "amps_mesh_set_tet_material", E, nu);
    if (s) return s;
    m->E[t] = E;
    m->nu[t] = nu;
    return AMPS_OK;
}

/* Structured grid, see amps_mesh_grid. Kuhn split: the corners of a cell are numbered
   c = bx + 2 by + 4 bz (b = 0/1 offsets along x, y, z). Each of the 6 tets is a monotone
   lattice path 0 -> (one axis) -> (two axes) -> 7, i.e. the 6 permutations of the axes, so all
   share the main diagonal 0-7. Every cell face is then split along its diagonal from the
   lowest to the highest corner, the same way from both sides: the mesh is conforming. */
static amps_mesh *amps__mesh_grid(amps_ctx *ctx, const char *fn, amps_int nx, amps_int ny, amps_int nz, double hx, double hy,
                                  double hz) {
    static const int kt[6][4] = {{0, 1, 3, 7}, {0, 1, 5, 7}, {0, 2, 3, 7}, {0, 2, 6, 7}, {0, 4, 5, 7}, {0, 4, 6, 7}};
    double *xyz;
    amps_int *tet, i, j, k, nn, nt = 0;
    amps_mesh *m;
    int c, q, s;
    if (nx < 2 || ny < 2 || nz < 2) {
        amps__err(ctx, AMPS_ERR_ARG, "%s: need at least 2 nodes per direction (got %lld x %lld x %lld)", fn, (long long)nx,
                  (long long)ny, (long long)nz);
        return NULL;
    }
    if (!(hx > 0.0 && hy > 0.0 && hz > 0.0) || !amps__isfinite(hx + hy + hz)) {
        amps__err(ctx, AMPS_ERR_ARG, "%s: grid spacings must be positive and finite", fn);
        return NULL;
    }
    if ((double)nx * (double)ny * (double)nz * 24.0 > (double)amps__fem_imax()) {
        amps__err(ctx, AMPS_ERR_ARG, "%s: grid %lld x %lld x %lld too large for the index type", fn, (long long)nx, (long long)ny,
                  (long long)nz);
        return NULL;
    }
    nn = nx * ny * nz;
    xyz = AMPS__CAST(double *, amps__malloc(ctx, 3 * (size_t)nn, sizeof(double)));
    tet = AMPS__CAST(amps_int *, amps__malloc(ctx, 24 * (size_t)(nx - 1) * (size_t)(ny - 1) * (size_t)(nz - 1), sizeof(amps_int)));
    if (!xyz || !tet) {
        amps__free(ctx, xyz);
        amps__free(ctx, tet);
        return NULL;
    }
    for (k = 0; k < nz; k++)
        for (j = 0; j < ny; j++)
            for (i = 0; i < nx; i++) {
                amps_int v = i + nx * (j + ny * k);
                xyz[3 * v] = (double)i * hx;
                xyz[3 * v + 1] = (double)j * hy;
                xyz[3 * v + 2] = (double)k * hz;
            }
    for (k = 0; k + 1 < nz; k++)
        for (j = 0; j + 1 < ny; j++)
            for (i = 0; i + 1 < nx; i++) {
                amps_int cn[8];
                for (c = 0; c < 8; c++) cn[c] = (i + (c & 1)) + nx * ((j + ((c >> 1) & 1)) + ny * (k + ((c >> 2) & 1)));
                for (s = 0; s < 6; s++) {
                    for (q = 0; q < 4; q++) tet[4 * nt + q] = cn[kt[s][q]];
                    nt++;
                }
            }
    m = amps__mesh_new(ctx, fn, nn, xyz, nt, tet, NULL);
    amps__free(ctx, xyz);
    amps__free(ctx, tet);
    return m;
}

AMPS_API amps_mesh *amps_mesh_grid(amps_ctx *ctx, amps_int nx, amps_int ny, amps_int nz, double hx, double hy, double hz) {
    return amps__mesh_grid(ctx, "amps_mesh_grid", nx, ny, nz, hx, hy, hz);
}

AMPS_API amps_mesh *amps_mesh_beam(amps_ctx *ctx, amps_int h) {
    if (h < 2) {
        amps__err(ctx, AMPS_ERR_ARG, "amps_mesh_beam: length h = %lld must be at least 2 nodes", (long long)h);
        return NULL;
    }
    return amps__mesh_grid(ctx, "amps_mesh_beam", 5, 5, h, 1.0, 1.0, 1.0);
}

AMPS_API amps_mesh *amps_mesh_brick(amps_ctx *ctx, amps_int R) {
    if (R < 1 || R > amps__fem_imax() / 4) {
        amps__err(ctx, AMPS_ERR_ARG, "amps_mesh_brick: resolution R = %lld must be at least 1", (long long)R);
        return NULL;
    }
    return amps__mesh_grid(ctx, "amps_mesh_brick", R + 1, R + 1, 2 * R + 1, 1.0 / (double)R, 1.0 / (double)R, 1.0 / (double)R);
}

AMPS_API amps_status amps_mesh_reserve(amps_ctx *ctx, amps_mesh *m, amps_int node_cap) {
    void *p;
    size_t nc = (size_t)node_cap;
    if (!m) return amps__err(ctx, AMPS_ERR_ARG, "amps_mesh_reserve: NULL mesh");
    if (node_cap <= m->node_cap) return AMPS_OK;
    if (node_cap > amps__fem_imax() / 3)
        return amps__err(ctx, AMPS_ERR_CAPACITY, "amps_mesh_reserve: %lld nodes exceed the index type", (long long)node_cap);
    /* arrays that grew before a failure stay grown; node_cap changes only when all succeed */
    p = m->xyz;
    if (amps__realloc(ctx, &p, 3 * nc, sizeof(double))) goto oom;
    m->xyz = AMPS__CAST(double *, p);
    p = m->origin;
    if (amps__realloc(ctx, &p, nc, sizeof(amps_int))) goto oom;
    m->origin = AMPS__CAST(amps_int *, p);
    p = m->inc_ptr;
    if (amps__realloc(ctx, &p, nc, sizeof(amps_int))) goto oom;
    m->inc_ptr = AMPS__CAST(amps_int *, p);
    p = m->inc_len;
    if (amps__realloc(ctx, &p, nc, sizeof(amps_int))) goto oom;
    m->inc_len = AMPS__CAST(amps_int *, p);
    m->node_cap = node_cap;
    return AMPS_OK;
oom:
    return amps__err(ctx, AMPS_ERR_OOM, "amps_mesh_reserve: out of memory for %lld nodes", (long long)node_cap);
}

AMPS_API amps_int amps_mesh_degree(const amps_mesh *m, amps_int v) {
    if (!m || v < 0 || v >= m->nnode) return 0;
    return m->inc_len[v];
}

AMPS_API const amps_int *amps_mesh_incident(const amps_mesh *m, amps_int v, amps_int *deg) {
    if (!m || v < 0 || v >= m->nnode) {
        if (deg) *deg = 0;
        return NULL;
    }
    if (deg) *deg = m->inc_len[v];
    return m->inc + m->inc_ptr[v];
}

AMPS_API amps_status amps_mesh_check(amps_ctx *ctx, const amps_mesh *m) {
    const char *fn = "amps_mesh_check";
    unsigned char *seen;
    amps_int v, t, q, r, j, total = 0;
    if (!m) return amps__err(ctx, AMPS_ERR_ARG, "%s: NULL mesh", fn);
    if (m->ntet < 1 || m->nfile < 0 || m->nfile > m->nnode || m->nnode > m->node_cap)
        return amps__err(ctx, AMPS_ERR_MESH, "%s: inconsistent counts", fn);
    for (t = 0; t < m->ntet; t++)
        for (q = 0; q < 4; q++) {
            v = m->tet[4 * t + q];
            if (v < 0 || v >= m->nnode)
                return amps__err(ctx, AMPS_ERR_MESH, "%s: tetrahedron %lld: node %lld out of range", fn, (long long)t, (long long)v);
            for (r = 0; r < q; r++)
                if (m->tet[4 * t + r] == v)
                    return amps__err(ctx, AMPS_ERR_MESH, "%s: tetrahedron %lld repeats node %lld", fn, (long long)t, (long long)v);
        }
    for (v = 0; v < m->nnode; v++) {
        amps_int o = m->origin[v];
        if (v < m->nfile ? o != v : (o < 0 || o >= m->nfile))
            return amps__err(ctx, AMPS_ERR_MESH, "%s: node %lld has invalid origin %lld", fn, (long long)v, (long long)o);
        if (m->xyz[3 * v] != m->xyz[3 * o] || m->xyz[3 * v + 1] != m->xyz[3 * o + 1] || m->xyz[3 * v + 2] != m->xyz[3 * o + 2])
            return amps__err(ctx, AMPS_ERR_MESH, "%s: copy %lld does not have the coordinates of its origin", fn, (long long)v);
    }
    seen = AMPS__CAST(unsigned char *, amps__calloc(ctx, 4 * (size_t)m->ntet, 1));
    if (!seen) return AMPS_ERR_OOM;
    for (v = 0; v < m->nnode; v++) {
        amps_int p = m->inc_ptr[v], n = m->inc_len[v];
        if (n < 0 || p < 0 || p > 4 * m->ntet || n > 4 * m->ntet - p) {
            amps__free(ctx, seen);
            return amps__err(ctx, AMPS_ERR_MESH, "%s: node %lld: incidence slot out of range", fn, (long long)v);
        }
        for (j = 0; j < n; j++) {
            const char *why = NULL;
            t = m->inc[p + j];
            if (seen[p + j]) why = "overlaps another slot";
            else if (t < 0 || t >= m->ntet) why = "lists an invalid tetrahedron";
            else if (j > 0 && t <= m->inc[p + j - 1]) why = "is not strictly ascending";
            else if (m->tet[4 * t] != v && m->tet[4 * t + 1] != v && m->tet[4 * t + 2] != v && m->tet[4 * t + 3] != v)
                why = "lists a tetrahedron without the node";
            if (why) {
                amps__free(ctx, seen);
                return amps__err(ctx, AMPS_ERR_MESH, "%s: node %lld: incidence list %s", fn, (long long)v, why);
            }
            seen[p + j] = 1;
        }
        total += n;
    }
    amps__free(ctx, seen);
    if (total != 4 * m->ntet)
        return amps__err(ctx, AMPS_ERR_MESH, "%s: incidence lists hold %lld entries, expected %lld", fn, (long long)total,
                         (long long)(4 * m->ntet));
    return AMPS_OK;
}

AMPS_API amps_int amps_mesh_select(const amps_mesh *m, int axis, amps_cmp cmp, double value, amps_int *out) {
    amps_int v, n = 0;
    if (!m || axis < 0 || axis > 2) return -1;
    for (v = 0; v < m->nnode; v++) {
        double x = m->xyz[3 * v + axis];
        if (cmp == AMPS_LT ? x < value : x > value) {
            if (out) out[n] = v;
            n++;
        }
    }
    return n;
}

AMPS_API amps_int amps_mesh_number_dofs(const amps_mesh *m, const unsigned char *fixed, amps_int *dof) {
    amps_int v, n = 0;
    int d;
    if (!m || !dof) return 0;
    for (v = 0; v < m->nnode; v++)
        for (d = 0; d < 3; d++) dof[3 * v + d] = ((fixed && fixed[v]) || m->inc_len[v] == 0) ? -1 : n++;
    return n;
}

AMPS_API void amps_mesh_tet_coords(const amps_mesh *m, amps_int t, double X[12]) {
    int a, c;
    for (a = 0; a < 4; a++)
        for (c = 0; c < 3; c++) X[3 * a + c] = m->xyz[3 * m->tet[4 * t + a] + c];
}

AMPS_API double amps_mesh_tet_stiffness(const amps_mesh *m, amps_int t, double Ke[144]) {
    double X[12];
    amps_mesh_tet_coords(m, t, X);
    return amps_tet_stiffness(X, m->E[t], m->nu[t], Ke);
}

AMPS_API amps_status amps_mesh_stress(amps_ctx *ctx, const amps_mesh *m, const double *disp, double *sigma, double *von_mises,
                                      double *principal) {
    amps_int t;
    if (!m || !disp) return amps__err(ctx, AMPS_ERR_ARG, "amps_mesh_stress: NULL mesh or displacement");
    for (t = 0; t < m->ntet; t++) {
        double X[12], u[12], s[6], vm, pr[3];
        int a, c;
        amps_mesh_tet_coords(m, t, X);
        for (a = 0; a < 4; a++)
            for (c = 0; c < 3; c++) u[3 * a + c] = disp[3 * m->tet[4 * t + a] + c];
        amps_tet_stress(X, m->E[t], m->nu[t], u, s, &vm, principal ? pr : NULL);
        if (sigma) memcpy(sigma + 6 * t, s, sizeof(s));
        if (von_mises) von_mises[t] = vm;
        if (principal) memcpy(principal + 3 * t, pr, sizeof(pr));
    }
    return AMPS_OK;
}

AMPS_API amps_csc *amps_mesh_assemble(amps_ctx *ctx, const amps_mesh *m, const amps_int *dof, amps_int ndof) {
    const char *fn = "amps_mesh_assemble";
    amps_int *owner = NULL, *mark = NULL, *adjp = NULL, *adj = NULL, *cc = NULL;
    amps_int n, v, w, t, k, i, j, c;
    amps_csc *A = NULL;
    long long cnt;
    int e;
    if (!m || !dof || ndof < 0) {
        amps__err(ctx, AMPS_ERR_ARG, "%s: NULL mesh / dof or negative ndof", fn);
        return NULL;
    }
    n = m->nnode;
    owner = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)ndof, sizeof(amps_int)));
    cc = AMPS__CAST(amps_int *, amps__calloc(ctx, (size_t)ndof + 1, sizeof(amps_int)));
    mark = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)n, sizeof(amps_int)));
    adjp = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)n + 1, sizeof(amps_int)));
    if (!owner || !cc || !mark || !adjp) goto fail;
    /* owner[i] = the DOF 3v+d numbered i */
    for (i = 0; i < ndof; i++) owner[i] = -1;
    for (k = 0; k < 3 * n; k++) {
        i = dof[k];
        if (i < -1 || i >= ndof) {
            amps__err(ctx, AMPS_ERR_INDEX, "%s: dof[%lld] = %lld out of range [-1, %lld)", fn, (long long)k, (long long)i, (long long)ndof);
            goto fail;
        }
        if (i < 0) continue;
        if (owner[i] >= 0) {
            amps__err(ctx, AMPS_ERR_ARG, "%s: equation %lld used by dof[%lld] and dof[%lld]", fn, (long long)i, (long long)owner[i],
                      (long long)k);
            goto fail;
        }
        owner[i] = k;
    }
    /* node graph: adj(v) = nodes sharing a tet with v (v included) */
    for (v = 0; v < n; v++) mark[v] = -1;
    for (v = 0, cnt = 0; v < n; v++) {
        const amps_int *lst = m->inc + m->inc_ptr[v];
        adjp[v] = (amps_int)cnt;
        for (j = 0; j < m->inc_len[v]; j++)
            for (e = 0; e < 4; e++) {
                w = m->tet[4 * lst[j] + e];
                if (mark[w] != v) {
                    mark[w] = v;
                    cnt++;
                }
            }
        if (cnt > (long long)amps__fem_imax()) {
            amps__err(ctx, AMPS_ERR_OOM, "%s: node graph too large for the index type", fn);
            goto fail;
        }
    }
    adjp[n] = (amps_int)cnt;
    adj = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)cnt, sizeof(amps_int)));
    if (!adj) goto fail;
    for (v = 0; v < n; v++) mark[v] = -1;
    for (v = 0; v < n; v++) {
        const amps_int *lst = m->inc + m->inc_ptr[v];
        k = adjp[v];
        for (j = 0; j < m->inc_len[v]; j++)
            for (e = 0; e < 4; e++) {
                w = m->tet[4 * lst[j] + e];
                if (mark[w] != v) {
                    mark[w] = v;
                    adj[k++] = w;
                }
            }
    }
    /* pattern: visiting equations i in ascending order and appending i to every column c >= i it
       couples with gives each column its rows in ascending order */
    for (i = 0; i < ndof; i++) {
        if (owner[i] < 0) continue;
        v = owner[i] / 3;
        for (j = adjp[v]; j < adjp[v + 1]; j++)
            for (e = 0; e < 3; e++) {
                c = dof[3 * adj[j] + e];
                if (c >= i) cc[c + 1]++;
            }
    }
    for (c = 0, cnt = 0; c < ndof; c++) {
        cnt += cc[c + 1];
        if (cnt > (long long)amps__fem_imax()) {
            amps__err(ctx, AMPS_ERR_OOM, "%s: matrix too large for the index type", fn);
            goto fail;
        }
        cc[c + 1] = (amps_int)cnt;
    }
    A = amps_csc_alloc(ctx, ndof, ndof, (amps_int)cnt, 1);
    if (!A) goto fail;
    memcpy(A->p, cc, sizeof(amps_int) * ((size_t)ndof + 1));
    for (i = 0; i < ndof; i++) {
        if (owner[i] < 0) continue;
        v = owner[i] / 3;
        for (j = adjp[v]; j < adjp[v + 1]; j++)
            for (e = 0; e < 3; e++) {
                c = dof[3 * adj[j] + e];
                if (c >= i) A->i[cc[c]++] = i;
            }
    }
    for (k = 0; k < (amps_int)cnt; k++) A->x[k] = 0.0;
    /* values: scatter the upper entries (r <= c) of every element matrix */
    for (t = 0; t < m->ntet; t++) {
        double Ke[144];
        int a, b;
        amps_int rd[12];
        amps_mesh_tet_stiffness(m, t, Ke);
        for (a = 0; a < 12; a++) rd[a] = dof[3 * m->tet[4 * t + a / 3] + a % 3];
        for (b = 0; b < 12; b++) {
            amps_int col = rd[b], lo, hi;
            if (col < 0) continue;
            for (a = 0; a < 12; a++) {
                amps_int row = rd[a];
                if (row < 0 || row > col) continue;
                lo = A->p[col];
                hi = A->p[col + 1] - 1;
                while (lo < hi) {
                    amps_int mid = lo + (hi - lo) / 2;
                    if (A->i[mid] < row) lo = mid + 1;
                    else hi = mid;
                }
                AMPS_ASSERT(A->i[lo] == row);
                A->x[lo] += Ke[12 * a + b];
            }
        }
    }
    amps__free(ctx, owner);
    amps__free(ctx, cc);
    amps__free(ctx, mark);
    amps__free(ctx, adjp);
    amps__free(ctx, adj);
    return A;
fail:
    amps__free(ctx, owner);
    amps__free(ctx, cc);
    amps__free(ctx, mark);
    amps__free(ctx, adjp);
    amps__free(ctx, adj);
    return NULL;
}

/* Sign test of amps_mesh_cut: (centroid(t) - p) . nrm in the reference configuration. */
static double amps__cut_side(const amps_mesh *m, amps_int t, const double p[3], const double nrm[3]) {
    const amps_int *tv = m->tet + 4 * t;
    double s = 0.0;
    int c;
    for (c = 0; c < 3; c++) {
        double x = 0.25 * (m->xyz[3 * tv[0] + c] + m->xyz[3 * tv[1] + c] + m->xyz[3 * tv[2] + c] + m->xyz[3 * tv[3] + c]);
        s += (x - p[c]) * nrm[c];
    }
    return s;
}

AMPS_API amps_status amps_mesh_cut(amps_ctx *ctx, amps_mesh *m, amps_int v, const double p[3], const double nrm[3],
                                   amps_int *new_node, amps_int *moved, amps_int *nmoved) {
    const char *fn = "amps_mesh_cut";
    amps_int base, deg, nm = 0, keep, j, mi, vc, t;
    int c, q;
    if (new_node) *new_node = -1;
    if (nmoved) *nmoved = 0;
    if (!m || !p || !nrm || !moved) return amps__err(ctx, AMPS_ERR_ARG, "%s: NULL mesh, plane or moved array", fn);
    if (v < 0 || v >= m->nnode)
        return amps__err(ctx, AMPS_ERR_INDEX, "%s: node %lld out of range [0, %lld)", fn, (long long)v, (long long)m->nnode);
    for (c = 0; c < 3; c++)
        if (!amps__isfinite(p[c]) || !amps__isfinite(nrm[c])) return amps__err(ctx, AMPS_ERR_VALUE, "%s: non-finite plane point or normal", fn);
    if (nrm[0] == 0.0 && nrm[1] == 0.0 && nrm[2] == 0.0) return amps__err(ctx, AMPS_ERR_ARG, "%s: zero plane normal", fn);
    base = m->inc_ptr[v];
    deg = m->inc_len[v];
    for (j = 0; j < deg; j++) {
        t = m->inc[base + j];
        if (amps__cut_side(m, t, p, nrm) < 0.0) moved[nm++] = t;
    }
    if (nm == 0 || nm == deg)
        return amps__err(ctx, AMPS_WARN_NOOP, "%s: all %lld tetrahedra at node %lld lie on one side of the plane; nothing cut", fn,
                         (long long)deg, (long long)v);
    if (m->nnode == m->node_cap) {
        amps_int cap = m->node_cap + m->node_cap / 2 + 16;
        amps_status s;
        if (cap > amps__fem_imax() / 3 || cap < m->node_cap) cap = amps__fem_imax() / 3;
        if (cap <= m->nnode) return amps__err(ctx, AMPS_ERR_CAPACITY, "%s: node count at the limit of the index type", fn);
        s = amps_mesh_reserve(ctx, m, cap);
        if (s) return s;
    }
    vc = m->nnode;
    for (c = 0; c < 3; c++) m->xyz[3 * vc + c] = m->xyz[3 * v + c];
    m->origin[vc] = m->origin[v];
    /* stable partition of v's slot: kept tets first, then the moved ones (the slot of vc) */
    for (j = 0, mi = 0, keep = 0; j < deg; j++) {
        t = m->inc[base + j];
        if (mi < nm && moved[mi] == t) mi++;
        else m->inc[base + keep++] = t;
    }
    for (j = 0; j < nm; j++) m->inc[base + keep + j] = moved[j];
    m->inc_len[v] = keep;
    m->inc_ptr[vc] = base + keep;
    m->inc_len[vc] = nm;
    for (j = 0; j < nm; j++)
        for (q = 0; q < 4; q++)
            if (m->tet[4 * moved[j] + q] == v) m->tet[4 * moved[j] + q] = vc;
    m->nnode++;
    if (new_node) *new_node = vc;
    if (nmoved) *nmoved = nm;
    return AMPS_OK;
}
#endif /* AMPS_NO_FEM */

/* ==================================== I/O impl ==================================== */
#if !defined(AMPS_NO_FEM) && !defined(AMPS_NO_STDIO)
/* @@SECTION io: owned by fem */
/* ---- tokenizer over a memory buffer, with line numbers ---- */

typedef struct amps__lex {
    amps_ctx *ctx;
    const char *buf, *p, *end; /* whole buffer, cursor, end */
    const char *name;          /* file name for messages */
    long long line;            /* line of the cursor (1-based) */
    int comment;               /* comment character (to end of line), or 0 */
    const char *tok;           /* last token and its length and line */
    size_t tlen;
    long long tline;
} amps__lex;

static void amps__lx_init(amps__lex *L, amps_ctx *ctx, const char *buf, size_t len, const char *name, int comment) {
    L->ctx = ctx;
    L->buf = L->p = buf ? buf : "";
    L->end = L->p + (buf ? len : 0);
    L->name = name ? name : "<memory>";
    L->line = 1;
    L->comment = comment;
    L->tok = L->p;
    L->tlen = 0;
    L->tline = 1;
}

static int amps__lx_blank(int c) { return c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v'; }

/* Skips blanks and comments, and with cross also line ends. Returns 1 if a token follows. */
static int amps__lx_skip(amps__lex *L, int cross) {
    while (L->p < L->end) {
        char c = *L->p;
        if (c == '\n') {
            if (!cross) return 0;
            L->line++;
            L->p++;
        } else if (amps__lx_blank(c)) {
            L->p++;
        } else if (L->comment && c == L->comment) {
            while (L->p < L->end && *L->p != '\n') L->p++;
        } else {
            return 1;
        }
    }
    return 0;
}

/* Next token (on the current line unless cross). Returns 0 at end of line / file. */
static int amps__lx_tok(amps__lex *L, int cross) {
    if (!amps__lx_skip(L, cross)) return 0;
    L->tok = L->p;
    L->tline = L->line;
    while (L->p < L->end && *L->p != '\n' && !amps__lx_blank(*L->p) && !(L->comment && *L->p == L->comment)) L->p++;
    L->tlen = (size_t)(L->p - L->tok);
    return 1;
}

/* Moves the cursor past the end of the current line. */
static void amps__lx_eol(amps__lex *L) {
    while (L->p < L->end && *L->p != '\n') L->p++;
    if (L->p < L->end) {
        L->p++;
        L->line++;
    }
}

/* Line to report for "something missing here": the cursor's line, or at the end of the file
   the last line that has characters. */
static long long amps__lx_here(const amps__lex *L) {
    if (L->p >= L->end && L->end > L->buf && L->end[-1] == '\n' && L->line > 1) return L->line - 1;
    return L->line;
}

/* Records "name:line: message" with status s; returns s. */
static amps_status amps__lx_err(amps__lex *L, long long line, amps_status s, const char *fmt, ...) {
    char msg[200];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof(msg), fmt, ap);
    va_end(ap);
    return amps__err(L->ctx, s, "%s:%lld: %s", L->name, line, msg);
}

/* The last token, printable and shortened, in out. */
static const char *amps__lx_show(const amps__lex *L, char out[40]) {
    size_t k, n = L->tlen < 24 ? L->tlen : 24;
    for (k = 0; k < n; k++) {
        unsigned char c = (unsigned char)L->tok[k];
        out[k] = (c >= 32 && c < 127 && c != '\'') ? (char)c : '?';
    }
    if (n < L->tlen) {
        out[n++] = '.';
        out[n++] = '.';
        out[n++] = '.';
    }
    out[n] = 0;
    return out;
}

/* 1 if the last token equals s, ignoring case if nocase. */
static int amps__lx_is(const amps__lex *L, const char *s, int nocase) {
    size_t k, n = strlen(s);
    if (L->tlen != n) return 0;
    for (k = 0; k < n; k++) {
        int a = (unsigned char)L->tok[k], b = (unsigned char)s[k];
        if (nocase) {
            if (a >= 'A' && a <= 'Z') a += 'a' - 'A';
            if (b >= 'A' && b <= 'Z') b += 'a' - 'A';
        }
        if (a != b) return 0;
    }
    return 1;
}

/* The last token as a decimal integer (optional sign, |v| < 1e18). Returns 1 on success. */
static int amps__lx_ll(const amps__lex *L, long long *v) {
    size_t k = 0;
    long long x = 0;
    int neg = 0;
    if (L->tlen == 0) return 0;
    if (L->tok[0] == '+' || L->tok[0] == '-') {
        neg = L->tok[0] == '-';
        k = 1;
    }
    if (k == L->tlen) return 0;
    for (; k < L->tlen; k++) {
        char c = L->tok[k];
        if (c < '0' || c > '9' || x >= 100000000000000000LL) return 0;
        x = 10 * x + (c - '0');
    }
    *v = neg ? -x : x;
    return 1;
}

/* The last token as a floating-point number (any strtod syntax, whole token). */
static int amps__lx_real(const amps__lex *L, double *v) {
    char tmp[128], *e;
    if (L->tlen == 0 || L->tlen >= sizeof(tmp)) return 0;
    memcpy(tmp, L->tok, L->tlen);
    tmp[L->tlen] = 0;
    *v = strtod(tmp, &e);
    return e == tmp + L->tlen;
}

/* Reads an integer token named what (on the current line unless cross). */
static amps_status amps__lx_int(amps__lex *L, int cross, long long *v, const char *what) {
    char sh[40];
    if (!amps__lx_tok(L, cross)) return amps__lx_err(L, amps__lx_here(L), AMPS_ERR_PARSE, "missing %s", what);
    if (!amps__lx_ll(L, v)) return amps__lx_err(L, L->tline, AMPS_ERR_PARSE, "invalid integer '%s' for %s", amps__lx_show(L, sh), what);
    return AMPS_OK;
}

/* Reads a finite real token named what. */
static amps_status amps__lx_num(amps__lex *L, int cross, double *v, const char *what) {
    char sh[40];
    if (!amps__lx_tok(L, cross)) return amps__lx_err(L, amps__lx_here(L), AMPS_ERR_PARSE, "missing %s", what);
    if (!amps__lx_real(L, v)) return amps__lx_err(L, L->tline, AMPS_ERR_PARSE, "invalid number '%s' for %s", amps__lx_show(L, sh), what);
    if (!amps__isfinite(*v)) return amps__lx_err(L, L->tline, AMPS_ERR_PARSE, "non-finite %s '%s'", what, amps__lx_show(L, sh));
    return AMPS_OK;
}

/* Reads 3 finite coordinates (the first on a later line if cross). */
static amps_status amps__lx_xyz(amps__lex *L, int cross, double *x) {
    amps_status s = amps__lx_num(L, cross, x, "x coordinate");
    if (!s) s = amps__lx_num(L, cross, x + 1, "y coordinate");
    if (!s) s = amps__lx_num(L, cross, x + 2, "z coordinate");
    return s;
}

/* Checks a count just read: 0 <= n, n * 4 fits amps_int, and n records of mintok tokens
   (at least one byte each) fit in the rest of the buffer, so that sizes allocated from counts
   stay proportional to the file size. */
static amps_status amps__lx_count(amps__lex *L, long long n, int mintok, const char *what) {
    long long room = (long long)(L->end - L->p) / mintok + 1;
    if (n < 0) return amps__lx_err(L, L->tline, AMPS_ERR_PARSE, "negative %s count %lld", what, n);
    if (n > room || n > (long long)(amps__fem_imax() / 4))
        return amps__lx_err(L, L->tline, AMPS_ERR_PARSE, "%s count %lld exceeds what the file can hold", what, n);
    return AMPS_OK;
}

/* Growable list of tets with the line each came from. */
typedef struct amps__tetbuf {
    amps_int *tet;
    long long *line;
    amps_int n, cap;
} amps__tetbuf;

static amps_status amps__tb_reserve(amps_ctx *ctx, amps__tetbuf *b, amps_int cap) {
    void *p;
    if (cap <= b->cap) return AMPS_OK;
    if (cap > amps__fem_imax() / 4) return amps__err(ctx, AMPS_ERR_OOM, "too many tetrahedra for the index type");
    p = b->tet;
    if (amps__realloc(ctx, &p, 4 * (size_t)cap, sizeof(amps_int))) return AMPS_ERR_OOM;
    b->tet = AMPS__CAST(amps_int *, p);
    p = b->line;
    if (amps__realloc(ctx, &p, (size_t)cap, sizeof(long long))) return AMPS_ERR_OOM;
    b->line = AMPS__CAST(long long *, p);
    b->cap = cap;
    return AMPS_OK;
}

static amps_status amps__tb_push(amps_ctx *ctx, amps__tetbuf *b, const amps_int tv[4], long long line) {
    if (b->n == b->cap) {
        amps_int cap = b->cap < 64 ? 64 : b->cap + b->cap / 2;
        amps_status s;
        if (cap > amps__fem_imax() / 4) cap = amps__fem_imax() / 4;
        s = amps__tb_reserve(ctx, b, cap);
        if (s) return s;
        if (b->n == b->cap) return amps__err(ctx, AMPS_ERR_OOM, "too many tetrahedra for the index type");
    }
    memcpy(b->tet + 4 * (size_t)b->n, tv, 4 * sizeof(amps_int));
    b->line[b->n++] = line;
    return AMPS_OK;
}

static void amps__tb_free(amps_ctx *ctx, amps__tetbuf *b) {
    amps__free(ctx, b->tet);
    amps__free(ctx, b->line);
}

/* Builds the mesh; a degenerate tet is reported as "file:line: ...". */
static amps_mesh *amps__lx_mesh(amps__lex *L, amps_int nn, const double *xyz, const amps__tetbuf *tb) {
    amps_int bad = -1;
    amps_mesh *m;
    if (tb->n == 0) {
        amps__lx_err(L, amps__lx_here(L), AMPS_ERR_PARSE, "no tetrahedra in the file");
        return NULL;
    }
    m = amps__mesh_new(L->ctx, "mesh", nn, xyz, tb->n, tb->tet, &bad);
    if (!m && bad >= 0 && L->ctx && L->ctx->status == AMPS_ERR_MESH) {
        const amps_int *tv = tb->tet + 4 * (size_t)bad;
        amps__lx_err(L, tb->line[bad], AMPS_ERR_MESH, "degenerate tetrahedron (file nodes %lld %lld %lld %lld, 0-based)",
                     (long long)tv[0], (long long)tv[1], (long long)tv[2], (long long)tv[3]);
    }
    return m;
}

/* ---- TetGen .node / .ele ---- */

AMPS_API amps_mesh *amps_mesh_read_tetgen_mem(amps_ctx *ctx, const char *node_buf, size_t node_len, const char *node_name,
                                              const char *ele_buf, size_t ele_len, const char *ele_name) {
    amps__lex L;
    amps__tetbuf tb;
    double *xyz = NULL;
    amps_mesh *m = NULL;
    long long np = 0, dim = 3, nat = 0, nbm = 0, base = 0, idx, ne, nper = 4, k, q, v;
    amps_int tv[4];
    char sh[40];
    memset(&tb, 0, sizeof(tb));
    amps__lx_init(&L, ctx, node_buf, node_len, node_name ? node_name : "<node>", '#');
    /* header: <#points> [<dimension> [<#attributes> [<#boundary markers>]]] */
    if (amps__lx_int(&L, 1, &np, "point count")) goto done;
    if (amps__lx_count(&L, np, 4, "point")) goto done;
    if (np == 0) {
        amps__lx_err(&L, L.tline, AMPS_ERR_PARSE, "the file declares no points");
        goto done;
    }
    if (amps__lx_tok(&L, 0)) {
        if (!amps__lx_ll(&L, &dim) || dim != 3) {
            amps__lx_err(&L, L.tline, AMPS_ERR_PARSE, "dimension must be 3, found '%s'", amps__lx_show(&L, sh));
            goto done;
        }
        if (amps__lx_tok(&L, 0) && (!amps__lx_ll(&L, &nat) || nat < 0)) {
            amps__lx_err(&L, L.tline, AMPS_ERR_PARSE, "invalid attribute count '%s'", amps__lx_show(&L, sh));
            goto done;
        }
        if (amps__lx_tok(&L, 0) && (!amps__lx_ll(&L, &nbm) || nbm < 0 || nbm > 1)) {
            amps__lx_err(&L, L.tline, AMPS_ERR_PARSE, "boundary marker flag must be 0 or 1, found '%s'", amps__lx_show(&L, sh));
            goto done;
        }
    }
    amps__lx_eol(&L);
    xyz = AMPS__CAST(double *, amps__malloc(ctx, 3 * (size_t)np, sizeof(double)));
    if (!xyz) goto done;
    for (k = 0; k < np; k++) {
        if (!amps__lx_skip(&L, 1)) {
            amps__lx_err(&L, amps__lx_here(&L), AMPS_ERR_PARSE, "unexpected end of file: %lld of %lld points read", k, np);
            goto done;
        }
        if (amps__lx_int(&L, 1, &idx, "point number")) goto done;
        if (k == 0) {
            if (idx != 0 && idx != 1) {
                amps__lx_err(&L, L.tline, AMPS_ERR_PARSE, "first point number must be 0 or 1, found %lld", idx);
                goto done;
            }
            base = idx;
        } else if (idx != base + k) {
            amps__lx_err(&L, L.tline, AMPS_ERR_PARSE, "point number %lld out of sequence (expected %lld)", idx, base + k);
            goto done;
        }
        if (amps__lx_xyz(&L, 0, xyz + 3 * k)) goto done;
        amps__lx_eol(&L); /* attributes and boundary marker */
    }
    if (amps__lx_tok(&L, 1)) {
        amps__lx_err(&L, L.tline, AMPS_ERR_PARSE, "unexpected data '%s' after %lld points", amps__lx_show(&L, sh), np);
        goto done;
    }

    amps__lx_init(&L, ctx, ele_buf, ele_len, ele_name ? ele_name : "<ele>", '#');
    /* header: <#tets> [<nodes per tet> [<#attributes>]] */
    if (amps__lx_int(&L, 1, &ne, "tetrahedron count")) goto done;
    if (amps__lx_count(&L, ne, 5, "tetrahedron")) goto done;
    if (amps__lx_tok(&L, 0)) {
        if (!amps__lx_ll(&L, &nper) || (nper != 4 && nper != 10)) {
            amps__lx_err(&L, L.tline, AMPS_ERR_PARSE, "nodes per tetrahedron must be 4 or 10, found '%s'", amps__lx_show(&L, sh));
            goto done;
        }
        if (amps__lx_tok(&L, 0) && (!amps__lx_ll(&L, &nat) || nat < 0)) {
            amps__lx_err(&L, L.tline, AMPS_ERR_PARSE, "invalid attribute count '%s'", amps__lx_show(&L, sh));
            goto done;
        }
    }
    amps__lx_eol(&L);
    if (amps__tb_reserve(ctx, &tb, (amps_int)(ne > 0 ? ne : 1))) goto done;
    for (k = 0; k < ne; k++) {
        long long line;
        if (!amps__lx_skip(&L, 1)) {
            amps__lx_err(&L, amps__lx_here(&L), AMPS_ERR_PARSE, "unexpected end of file: %lld of %lld tetrahedra read", k, ne);
            goto done;
        }
        if (amps__lx_int(&L, 1, &idx, "tetrahedron number")) goto done;
        line = L.tline;
        for (q = 0; q < nper; q++) {
            if (amps__lx_int(&L, 0, &v, "node index")) goto done;
            if (v < base || v - base >= np) {
                amps__lx_err(&L, L.tline, AMPS_ERR_PARSE, "node index %lld out of range [%lld, %lld]", v, base, base + np - 1);
                goto done;
            }
            if (q < 4) tv[q] = (amps_int)(v - base);
        }
        amps__lx_eol(&L); /* attributes */
        if (amps__tb_push(ctx, &tb, tv, line)) goto done;
    }
    if (amps__lx_tok(&L, 1)) {
        amps__lx_err(&L, L.tline, AMPS_ERR_PARSE, "unexpected data '%s' after %lld tetrahedra", amps__lx_show(&L, sh), ne);
        goto done;
    }
    m = amps__lx_mesh(&L, (amps_int)np, xyz, &tb);
done:
    amps__free(ctx, xyz);
    amps__tb_free(ctx, &tb);
    return m;
}

/* ---- Gmsh .msh (ASCII 2.x, 4.1) ---- */

typedef struct amps__gtag {
    long long tag, line;
    amps_int idx;
} amps__gtag;

static int amps__gtag_cmp(const void *a, const void *b) {
    const amps__gtag *x = (const amps__gtag *)a, *y = (const amps__gtag *)b;
    return x->tag < y->tag ? -1 : x->tag > y->tag ? 1 : (x->line < y->line ? -1 : x->line > y->line);
}

/* Reads a node tag and maps it to its 0-based file position. */
static amps_status amps__gmsh_node(amps__lex *L, const amps__gtag *tags, amps_int nn, amps_int *out) {
    long long tg;
    amps_int lo = 0, hi = nn - 1;
    amps_status s = amps__lx_int(L, 0, &tg, "node tag");
    if (s) return s;
    while (lo <= hi) {
        amps_int mid = lo + (hi - lo) / 2;
        if (tags[mid].tag < tg) lo = mid + 1;
        else if (tags[mid].tag > tg) hi = mid - 1;
        else {
            *out = tags[mid].idx;
            return AMPS_OK;
        }
    }
    return amps__lx_err(L, L->tline, AMPS_ERR_PARSE, "element refers to undefined node tag %lld", tg);
}

/* Expects the token "$End<sec>" at the start of the next non-blank line. */
static amps_status amps__gmsh_end(amps__lex *L, const char *sec, const char *after) {
    char want[32], sh[40];
    snprintf(want, sizeof(want), "$End%s", sec);
    if (!amps__lx_tok(L, 1)) return amps__lx_err(L, amps__lx_here(L), AMPS_ERR_PARSE, "unexpected end of file, expected %s", want);
    if (!amps__lx_is(L, want, 0))
        return amps__lx_err(L, L->tline, AMPS_ERR_PARSE, "expected %s%s, found '%s'", want, after, amps__lx_show(L, sh));
    amps__lx_eol(L);
    return AMPS_OK;
}

AMPS_API amps_mesh *amps_mesh_read_gmsh_mem(amps_ctx *ctx, const char *buf, size_t len, const char *name) {
    amps__lex L;
    amps__tetbuf tb;
    amps__gtag *tags = NULL;
    double *xyz = NULL;
    amps_mesh *m = NULL;
    amps_int nn = 0;
    int version = 0, have_nodes = 0, have_elems = 0;
    long long a, b, c, d, k, i;
    char sh[40];
    memset(&tb, 0, sizeof(tb));
    amps__lx_init(&L, ctx, buf, len, name ? name : "<msh>", 0);
    for (;;) {
        char sec[24];
        if (!amps__lx_tok(&L, 1)) break;
        if (L.tok[0] != '$' || L.tlen < 2 || L.tlen >= sizeof(sec) + 1) {
            amps__lx_err(&L, L.tline, AMPS_ERR_PARSE, "expected a section header like $Nodes, found '%s'", amps__lx_show(&L, sh));
            goto done;
        }
        memcpy(sec, L.tok + 1, L.tlen - 1);
        sec[L.tlen - 1] = 0;
        if (!version && !amps__lx_is(&L, "$MeshFormat", 0)) {
            amps__lx_err(&L, L.tline, AMPS_ERR_PARSE, "the file must start with $MeshFormat, found '%s'", amps__lx_show(&L, sh));
            goto done;
        }
        amps__lx_eol(&L);
        if (!strcmp(sec, "MeshFormat")) {
            double ver;
            if (version) {
                amps__lx_err(&L, L.tline, AMPS_ERR_PARSE, "duplicate $MeshFormat");
                goto done;
            }
            if (amps__lx_num(&L, 1, &ver, "format version")) goto done;
            if (ver >= 2.0 && ver < 3.0) version = 2;
            else if (ver == 4.1) version = 4;
            else {
                amps__lx_err(&L, L.tline, AMPS_ERR_PARSE, "unsupported .msh version %s (readable: 2.x, 4.1)", amps__lx_show(&L, sh));
                goto done;
            }
            if (amps__lx_int(&L, 0, &a, "file type")) goto done;
            if (a != 0) {
                if (a == 1) amps__lx_err(&L, L.tline, AMPS_ERR_PARSE, "binary .msh files are not supported; save the mesh as ASCII");
                else amps__lx_err(&L, L.tline, AMPS_ERR_PARSE, "invalid file type %lld (0 = ASCII)", a);
                goto done;
            }
            if (amps__lx_int(&L, 0, &a, "data size")) goto done;
            amps__lx_eol(&L);
            if (amps__gmsh_end(&L, sec, "")) goto done;
        } else if (!strcmp(sec, "Nodes")) {
            long long nblk = 1, total;
            if (have_nodes) {
                amps__lx_err(&L, L.tline, AMPS_ERR_PARSE, "duplicate $Nodes section");
                goto done;
            }
            have_nodes = 1;
            if (version == 4) {
                /* numEntityBlocks numNodes minNodeTag maxNodeTag */
                if (amps__lx_int(&L, 1, &nblk, "entity block count")) goto done;
                if (amps__lx_count(&L, nblk, 4, "entity block")) goto done;
                if (amps__lx_int(&L, 0, &total, "node count")) goto done;
            } else {
                if (amps__lx_int(&L, 1, &total, "node count")) goto done;
            }
            if (amps__lx_count(&L, total, 4, "node")) goto done;
            amps__lx_eol(&L);
            nn = (amps_int)total;
            xyz = AMPS__CAST(double *, amps__malloc(ctx, 3 * (size_t)nn, sizeof(double)));
            tags = AMPS__CAST(amps__gtag *, amps__malloc(ctx, (size_t)nn, sizeof(amps__gtag)));
            if (!xyz || !tags) goto done;
            if (version == 2) {
                for (k = 0; k < total; k++) {
                    if (amps__lx_int(&L, 1, &a, "node tag")) goto done;
                    tags[k].tag = a;
                    tags[k].line = L.tline;
                    tags[k].idx = (amps_int)k;
                    if (amps__lx_xyz(&L, 0, xyz + 3 * k)) goto done;
                    amps__lx_eol(&L);
                }
            } else {
                long long got = 0, nin, par;
                for (b = 0; b < nblk; b++) {
                    /* entityDim entityTag parametric numNodesInBlock */
                    if (amps__lx_int(&L, 1, &a, "entity dimension")) goto done;
                    if (amps__lx_int(&L, 0, &a, "entity tag")) goto done;
                    if (amps__lx_int(&L, 0, &par, "parametric flag")) goto done;
                    if (amps__lx_int(&L, 0, &nin, "block node count")) goto done;
                    if (nin < 0 || nin > total - got) {
                        amps__lx_err(&L, L.tline, AMPS_ERR_PARSE, "block node count %lld exceeds the %lld nodes declared", nin, total);
                        goto done;
                    }
                    amps__lx_eol(&L);
                    for (i = 0; i < nin; i++) {
                        if (amps__lx_int(&L, 1, &a, "node tag")) goto done;
                        tags[got + i].tag = a;
                        tags[got + i].line = L.tline;
                        tags[got + i].idx = (amps_int)(got + i);
                        amps__lx_eol(&L);
                    }
                    for (i = 0; i < nin; i++) {
                        if (amps__lx_xyz(&L, 1, xyz + 3 * (got + i))) goto done;
                        amps__lx_eol(&L); /* parametric coordinates */
                    }
                    got += nin;
                }
                if (got != total) {
                    amps__lx_err(&L, amps__lx_here(&L), AMPS_ERR_PARSE, "$Nodes declares %lld nodes, its blocks hold %lld", total, got);
                    goto done;
                }
            }
            if (amps__gmsh_end(&L, sec, " (node count mismatch?)")) goto done;
            qsort(tags, (size_t)nn, sizeof(amps__gtag), amps__gtag_cmp);
            for (k = 1; k < total; k++)
                if (tags[k].tag == tags[k - 1].tag) {
                    amps__lx_err(&L, tags[k].line, AMPS_ERR_PARSE, "duplicate node tag %lld (first on line %lld)", tags[k].tag,
                                 tags[k - 1].line);
                    goto done;
                }
        } else if (!strcmp(sec, "Elements")) {
            long long nblk = 1, total, got = 0, nin, type;
            amps_int tv[4];
            if (!have_nodes) {
                amps__lx_err(&L, L.tline, AMPS_ERR_PARSE, "$Elements before $Nodes");
                goto done;
            }
            if (have_elems) {
                amps__lx_err(&L, L.tline, AMPS_ERR_PARSE, "duplicate $Elements section");
                goto done;
            }
            have_elems = 1;
            if (version == 4) {
                if (amps__lx_int(&L, 1, &nblk, "entity block count")) goto done;
                if (amps__lx_count(&L, nblk, 4, "entity block")) goto done;
                if (amps__lx_int(&L, 0, &total, "element count")) goto done;
            } else {
                if (amps__lx_int(&L, 1, &total, "element count")) goto done;
            }
            if (amps__lx_count(&L, total, 2, "element")) goto done;
            amps__lx_eol(&L);
            if (version == 2) {
                for (k = 0; k < total; k++) {
                    long long line;
                    /* elm-number elm-type number-of-tags <tags> node-number-list */
                    if (amps__lx_int(&L, 1, &a, "element number")) goto done;
                    line = L.tline;
                    if (amps__lx_int(&L, 0, &type, "element type")) goto done;
                    if (amps__lx_int(&L, 0, &c, "tag count")) goto done;
                    if (c < 0) {
                        amps__lx_err(&L, L.tline, AMPS_ERR_PARSE, "negative tag count %lld", c);
                        goto done;
                    }
                    if (type == 4) {
                        for (i = 0; i < c; i++)
                            if (amps__lx_int(&L, 0, &d, "element tag")) goto done;
                        for (i = 0; i < 4; i++)
                            if (amps__gmsh_node(&L, tags, nn, tv + i)) goto done;
                        if (amps__tb_push(ctx, &tb, tv, line)) goto done;
                    }
                    amps__lx_eol(&L);
                }
            } else {
                for (b = 0; b < nblk; b++) {
                    /* entityDim entityTag elementType numElementsInBlock */
                    if (amps__lx_int(&L, 1, &a, "entity dimension")) goto done;
                    if (amps__lx_int(&L, 0, &a, "entity tag")) goto done;
                    if (amps__lx_int(&L, 0, &type, "element type")) goto done;
                    if (amps__lx_int(&L, 0, &nin, "block element count")) goto done;
                    if (nin < 0 || nin > total - got) {
                        amps__lx_err(&L, L.tline, AMPS_ERR_PARSE, "block element count %lld exceeds the %lld elements declared", nin,
                                     total);
                        goto done;
                    }
                    amps__lx_eol(&L);
                    for (i = 0; i < nin; i++) {
                        if (type == 4) {
                            long long line;
                            if (amps__lx_int(&L, 1, &a, "element tag")) goto done;
                            line = L.tline;
                            for (c = 0; c < 4; c++)
                                if (amps__gmsh_node(&L, tags, nn, tv + c)) goto done;
                            if (amps__tb_push(ctx, &tb, tv, line)) goto done;
                        } else if (!amps__lx_skip(&L, 1)) {
                            amps__lx_err(&L, amps__lx_here(&L), AMPS_ERR_PARSE, "unexpected end of file in an element block");
                            goto done;
                        }
                        amps__lx_eol(&L);
                    }
                    got += nin;
                }
                if (got != total) {
                    amps__lx_err(&L, amps__lx_here(&L), AMPS_ERR_PARSE, "$Elements declares %lld elements, its blocks hold %lld", total,
                                 got);
                    goto done;
                }
            }
            if (amps__gmsh_end(&L, sec, " (element count mismatch?)")) goto done;
        } else {
            /* unknown section: skip lines up to $End<sec> */
            char want[32];
            long long start = L.tline;
            snprintf(want, sizeof(want), "$End%s", sec);
            for (;;) {
                if (!amps__lx_tok(&L, 1)) {
                    amps__lx_err(&L, start, AMPS_ERR_PARSE, "section $%s is not closed by %s", sec, want);
                    goto done;
                }
                amps__lx_eol(&L);
                if (amps__lx_is(&L, want, 0)) break;
            }
        }
    }
    if (!version) {
        amps__lx_err(&L, amps__lx_here(&L), AMPS_ERR_PARSE, "empty file (no $MeshFormat)");
        goto done;
    }
    if (!have_nodes) {
        amps__lx_err(&L, amps__lx_here(&L), AMPS_ERR_PARSE, "no $Nodes section");
        goto done;
    }
    if (tb.n == 0) {
        amps__lx_err(&L, amps__lx_here(&L), AMPS_ERR_PARSE, "no tetrahedra (element type 4) in the file");
        goto done;
    }
    m = amps__lx_mesh(&L, nn, xyz, &tb);
done:
    amps__free(ctx, xyz);
    amps__free(ctx, tags);
    amps__tb_free(ctx, &tb);
    return m;
}

/* ---- MEDIT .mesh (ASCII) ---- */

/* 1 if the last token looks like a number (so it is not a keyword). */
static int amps__lx_numeric(const amps__lex *L) {
    char c = L->tok[0];
    return (c >= '0' && c <= '9') || c == '+' || c == '-' || c == '.';
}

AMPS_API amps_mesh *amps_mesh_read_medit_mem(amps_ctx *ctx, const char *buf, size_t len, const char *name) {
    amps__lex L;
    amps__tetbuf tb;
    double *xyz = NULL;
    amps_mesh *m = NULL;
    amps_int nn = 0;
    int have_tets = 0;
    long long n, k, q, v, ref;
    char sh[40];
    memset(&tb, 0, sizeof(tb));
    amps__lx_init(&L, ctx, buf, len, name ? name : "<mesh>", '#');
    while (amps__lx_tok(&L, 1)) {
        if (amps__lx_is(&L, "End", 1)) break;
        if (amps__lx_is(&L, "MeshVersionFormatted", 1)) {
            if (amps__lx_int(&L, 1, &n, "format version")) goto done;
        } else if (amps__lx_is(&L, "Dimension", 1)) {
            if (amps__lx_int(&L, 1, &n, "dimension")) goto done;
            if (n != 3) {
                amps__lx_err(&L, L.tline, AMPS_ERR_PARSE, "dimension must be 3, found %lld", n);
                goto done;
            }
        } else if (amps__lx_is(&L, "Vertices", 1)) {
            if (xyz) {
                amps__lx_err(&L, L.tline, AMPS_ERR_PARSE, "duplicate Vertices section");
                goto done;
            }
            if (amps__lx_int(&L, 1, &n, "vertex count")) goto done;
            if (amps__lx_count(&L, n, 4, "vertex")) goto done;
            nn = (amps_int)n;
            xyz = AMPS__CAST(double *, amps__malloc(ctx, 3 * (size_t)nn, sizeof(double)));
            if (!xyz) goto done;
            for (k = 0; k < n; k++) {
                if (amps__lx_xyz(&L, 1, xyz + 3 * k)) goto done;
                if (amps__lx_int(&L, 1, &ref, "vertex reference")) goto done;
            }
        } else if (amps__lx_is(&L, "Tetrahedra", 1)) {
            if (!xyz) {
                amps__lx_err(&L, L.tline, AMPS_ERR_PARSE, "Tetrahedra before Vertices");
                goto done;
            }
            if (have_tets) {
                amps__lx_err(&L, L.tline, AMPS_ERR_PARSE, "duplicate Tetrahedra section");
                goto done;
            }
            have_tets = 1;
            if (amps__lx_int(&L, 1, &n, "tetrahedron count")) goto done;
            if (amps__lx_count(&L, n, 5, "tetrahedron")) goto done;
            if (amps__tb_reserve(ctx, &tb, (amps_int)(n > 0 ? n : 1))) goto done;
            for (k = 0; k < n; k++) {
                amps_int tv[4];
                long long line = 0;
                for (q = 0; q < 4; q++) {
                    if (amps__lx_int(&L, 1, &v, "vertex index")) goto done;
                    if (q == 0) line = L.tline;
                    if (v < 1 || v > nn) {
                        amps__lx_err(&L, L.tline, AMPS_ERR_PARSE, "vertex index %lld out of range [1, %lld]", v, (long long)nn);
                        goto done;
                    }
                    tv[q] = (amps_int)(v - 1);
                }
                if (amps__lx_int(&L, 1, &ref, "tetrahedron reference")) goto done;
                if (amps__tb_push(ctx, &tb, tv, line)) goto done;
            }
        } else if (!amps__lx_numeric(&L)) {
            /* other keyword: skip its numeric data */
            while (amps__lx_skip(&L, 1)) {
                const char *save = L.p;
                long long sline = L.line;
                amps__lx_tok(&L, 1);
                if (!amps__lx_numeric(&L)) {
                    L.p = save;
                    L.line = sline;
                    break;
                }
            }
        } else {
            amps__lx_err(&L, L.tline, AMPS_ERR_PARSE, "expected a keyword, found '%s'", amps__lx_show(&L, sh));
            goto done;
        }
    }
    if (!xyz) {
        amps__lx_err(&L, amps__lx_here(&L), AMPS_ERR_PARSE, "no Vertices section");
        goto done;
    }
    if (!have_tets || tb.n == 0) {
        amps__lx_err(&L, amps__lx_here(&L), AMPS_ERR_PARSE, "no Tetrahedra in the file");
        goto done;
    }
    m = amps__lx_mesh(&L, nn, xyz, &tb);
done:
    amps__free(ctx, xyz);
    amps__tb_free(ctx, &tb);
    return m;
}

/* ---- files ---- */

/* Whole file into a new buffer (*len bytes, NUL-terminated). */
static amps_status amps__read_all(amps_ctx *ctx, const char *path, char **out, size_t *len) {
    FILE *f;
    char *b = NULL;
    size_t n = 0, cap = 0, got;
    *out = NULL;
    *len = 0;
    if (!path) return amps__err(ctx, AMPS_ERR_ARG, "NULL file name");
    f = fopen(path, "rb");
    if (!f) return amps__err(ctx, AMPS_ERR_IO, "%s: cannot open file", path);
    for (;;) {
        if (cap - n < 2) {
            void *p = b;
            size_t nc = cap ? 2 * cap : 65536;
            if (nc < cap || amps__realloc(ctx, &p, nc, 1)) {
                amps__free(ctx, b);
                fclose(f);
                return amps__err(ctx, AMPS_ERR_OOM, "%s: out of memory reading the file", path);
            }
            b = AMPS__CAST(char *, p);
            cap = nc;
        }
        got = fread(b + n, 1, cap - n - 1, f);
        n += got;
        if (got == 0) break;
    }
    if (ferror(f)) {
        amps__free(ctx, b);
        fclose(f);
        return amps__err(ctx, AMPS_ERR_IO, "%s: read error", path);
    }
    fclose(f);
    b[n] = 0;
    *out = b;
    *len = n;
    return AMPS_OK;
}

AMPS_API amps_mesh *amps_mesh_read_gmsh(amps_ctx *ctx, const char *path) {
    char *b;
    size_t n;
    amps_mesh *m;
    if (amps__read_all(ctx, path, &b, &n)) return NULL;
    m = amps_mesh_read_gmsh_mem(ctx, b, n, path);
    amps__free(ctx, b);
    return m;
}

AMPS_API amps_mesh *amps_mesh_read_medit(amps_ctx *ctx, const char *path) {
    char *b;
    size_t n;
    amps_mesh *m;
    if (amps__read_all(ctx, path, &b, &n)) return NULL;
    m = amps_mesh_read_medit_mem(ctx, b, n, path);
    amps__free(ctx, b);
    return m;
}

AMPS_API amps_mesh *amps_mesh_read_tetgen(amps_ctx *ctx, const char *node_path, const char *ele_path) {
    char *nb, *eb;
    size_t nl, el;
    amps_mesh *m;
    if (amps__read_all(ctx, node_path, &nb, &nl)) return NULL;
    if (amps__read_all(ctx, ele_path, &eb, &el)) {
        amps__free(ctx, nb);
        return NULL;
    }
    m = amps_mesh_read_tetgen_mem(ctx, nb, nl, node_path, eb, el, ele_path);
    amps__free(ctx, nb);
    amps__free(ctx, eb);
    return m;
}

/* 1 if path ends with ext (ignoring case). */
static int amps__has_ext(const char *path, const char *ext) {
    size_t n = strlen(path), e = strlen(ext), k;
    if (n < e) return 0;
    for (k = 0; k < e; k++) {
        int a = (unsigned char)path[n - e + k], b = (unsigned char)ext[k];
        if (a >= 'A' && a <= 'Z') a += 'a' - 'A';
        if (a != b) return 0;
    }
    return 1;
}

AMPS_API amps_mesh *amps_mesh_read(amps_ctx *ctx, const char *path) {
    if (!path) {
        amps__err(ctx, AMPS_ERR_ARG, "amps_mesh_read: NULL path");
        return NULL;
    }
    if (amps__has_ext(path, ".node") || amps__has_ext(path, ".ele")) {
        size_t n = strlen(path), stem = n - (amps__has_ext(path, ".ele") ? 4 : 5);
        char *np = AMPS__CAST(char *, amps__malloc(ctx, stem + 6, 1));
        char *ep = AMPS__CAST(char *, amps__malloc(ctx, stem + 6, 1));
        amps_mesh *m = NULL;
        if (np && ep) {
            memcpy(np, path, stem);
            memcpy(np + stem, ".node", 6);
            memcpy(ep, path, stem);
            memcpy(ep + stem, ".ele", 5);
            m = amps_mesh_read_tetgen(ctx, np, ep);
        }
        amps__free(ctx, np);
        amps__free(ctx, ep);
        return m;
    }
    if (amps__has_ext(path, ".msh")) return amps_mesh_read_gmsh(ctx, path);
    if (amps__has_ext(path, ".mesh")) return amps_mesh_read_medit(ctx, path);
    amps__err(ctx, AMPS_ERR_ARG, "%s: unknown mesh format (expected .node, .ele, .msh or .mesh)", path);
    return NULL;
}

/* ---- writers ---- */

typedef struct amps__out {
    FILE *f;
    int bad;
} amps__out;

static void amps__pr(amps__out *o, const char *fmt, ...) {
    va_list ap;
    if (o->bad) return;
    va_start(ap, fmt);
    if (vfprintf(o->f, fmt, ap) < 0) o->bad = 1;
    va_end(ap);
}

static amps_status amps__open_out(amps_ctx *ctx, const char *fn, const char *path, amps__out *o) {
    o->bad = 0;
    o->f = path ? fopen(path, "wb") : NULL;
    if (!o->f) return amps__err(ctx, AMPS_ERR_IO, "%s: %s: cannot open for writing", fn, path ? path : "(null)");
    return AMPS_OK;
}

static amps_status amps__close_out(amps_ctx *ctx, const char *fn, const char *path, amps__out *o) {
    if (fclose(o->f) != 0) o->bad = 1;
    if (o->bad) return amps__err(ctx, AMPS_ERR_IO, "%s: %s: write failed", fn, path);
    return AMPS_OK;
}

AMPS_API amps_status amps_write_vtu(amps_ctx *ctx, const char *path, const amps_mesh *m, const double *disp,
                                    const double *von_mises, const double *principal) {
    const char *fn = "amps_write_vtu";
    amps__out o;
    amps_int v, t;
    amps_status s;
    if (!m) return amps__err(ctx, AMPS_ERR_ARG, "%s: NULL mesh", fn);
    s = amps__open_out(ctx, fn, path, &o);
    if (s) return s;
    amps__pr(&o, "<?xml version=\"1.0\"?>\n<VTKFile type=\"UnstructuredGrid\" version=\"0.1\" byte_order=\"LittleEndian\">\n");
    amps__pr(&o, "<UnstructuredGrid>\n<Piece NumberOfPoints=\"%lld\" NumberOfCells=\"%lld\">\n", (long long)m->nnode, (long long)m->ntet);
    amps__pr(&o, "<Points>\n<DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"ascii\">\n");
    for (v = 0; v < m->nnode; v++) amps__pr(&o, "%.17g %.17g %.17g\n", m->xyz[3 * v], m->xyz[3 * v + 1], m->xyz[3 * v + 2]);
    amps__pr(&o, "</DataArray>\n</Points>\n<Cells>\n<DataArray type=\"Int64\" Name=\"connectivity\" format=\"ascii\">\n");
    for (t = 0; t < m->ntet; t++)
        amps__pr(&o, "%lld %lld %lld %lld\n", (long long)m->tet[4 * t], (long long)m->tet[4 * t + 1], (long long)m->tet[4 * t + 2],
                 (long long)m->tet[4 * t + 3]);
    amps__pr(&o, "</DataArray>\n<DataArray type=\"Int64\" Name=\"offsets\" format=\"ascii\">\n");
    for (t = 0; t < m->ntet; t++) amps__pr(&o, "%lld\n", 4 * (long long)(t + 1));
    amps__pr(&o, "</DataArray>\n<DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">\n");
    for (t = 0; t < m->ntet; t++) amps__pr(&o, "10\n");
    amps__pr(&o, "</DataArray>\n</Cells>\n");
    amps__pr(&o, "<PointData%s>\n", disp ? " Vectors=\"displacement\"" : "");
    if (disp) {
        amps__pr(&o, "<DataArray type=\"Float64\" Name=\"displacement\" NumberOfComponents=\"3\" format=\"ascii\">\n");
        for (v = 0; v < m->nnode; v++) amps__pr(&o, "%.17g %.17g %.17g\n", disp[3 * v], disp[3 * v + 1], disp[3 * v + 2]);
        amps__pr(&o, "</DataArray>\n");
    }
    amps__pr(&o, "<DataArray type=\"Int64\" Name=\"origin\" format=\"ascii\">\n");
    for (v = 0; v < m->nnode; v++) amps__pr(&o, "%lld\n", (long long)m->origin[v]);
    amps__pr(&o, "</DataArray>\n</PointData>\n");
    amps__pr(&o, "<CellData%s>\n", von_mises ? " Scalars=\"von_mises\"" : "");
    if (von_mises) {
        amps__pr(&o, "<DataArray type=\"Float64\" Name=\"von_mises\" format=\"ascii\">\n");
        for (t = 0; t < m->ntet; t++) amps__pr(&o, "%.17g\n", von_mises[t]);
        amps__pr(&o, "</DataArray>\n");
    }
    if (principal) {
        amps__pr(&o, "<DataArray type=\"Float64\" Name=\"principal_stress\" NumberOfComponents=\"3\" format=\"ascii\">\n");
        for (t = 0; t < m->ntet; t++) amps__pr(&o, "%.17g %.17g %.17g\n", principal[3 * t], principal[3 * t + 1], principal[3 * t + 2]);
        amps__pr(&o, "</DataArray>\n");
    }
    amps__pr(&o, "<DataArray type=\"UInt8\" Name=\"cut\" format=\"ascii\">\n");
    for (t = 0; t < m->ntet; t++) {
        const amps_int *tv = m->tet + 4 * t;
        int cut = tv[0] >= m->nfile || tv[1] >= m->nfile || tv[2] >= m->nfile || tv[3] >= m->nfile;
        amps__pr(&o, "%d\n", cut);
    }
    amps__pr(&o, "</DataArray>\n</CellData>\n</Piece>\n</UnstructuredGrid>\n</VTKFile>\n");
    return amps__close_out(ctx, fn, path, &o);
}

AMPS_API amps_status amps_write_tetgen(amps_ctx *ctx, const char *base, const amps_mesh *m, int first_index) {
    const char *fn = "amps_write_tetgen";
    amps__out o;
    amps_int v, t;
    amps_status s;
    char *path;
    size_t n;
    if (!m || !base || (first_index != 0 && first_index != 1))
        return amps__err(ctx, AMPS_ERR_ARG, "%s: NULL mesh or base name, or first index not 0 or 1", fn);
    n = strlen(base);
    path = AMPS__CAST(char *, amps__malloc(ctx, n + 6, 1));
    if (!path) return AMPS_ERR_OOM;
    memcpy(path, base, n);
    memcpy(path + n, ".node", 6);
    s = amps__open_out(ctx, fn, path, &o);
    if (!s) {
        amps__pr(&o, "%lld 3 0 0\n", (long long)m->nnode);
        for (v = 0; v < m->nnode; v++)
            amps__pr(&o, "%lld %.17g %.17g %.17g\n", (long long)v + first_index, m->xyz[3 * v], m->xyz[3 * v + 1], m->xyz[3 * v + 2]);
        amps__pr(&o, "# written by amps.h\n");
        s = amps__close_out(ctx, fn, path, &o);
    }
    if (!s) {
        memcpy(path + n, ".ele", 5);
        s = amps__open_out(ctx, fn, path, &o);
    }
    if (!s) {
        amps__pr(&o, "%lld 4 0\n", (long long)m->ntet);
        for (t = 0; t < m->ntet; t++)
            amps__pr(&o, "%lld %lld %lld %lld %lld\n", (long long)t + first_index, (long long)m->tet[4 * t] + first_index,
                     (long long)m->tet[4 * t + 1] + first_index, (long long)m->tet[4 * t + 2] + first_index,
                     (long long)m->tet[4 * t + 3] + first_index);
        s = amps__close_out(ctx, fn, path, &o);
    }
    amps__free(ctx, path);
    return s;
}

AMPS_API amps_status amps_write_gmsh(amps_ctx *ctx, const char *path, const amps_mesh *m, int version) {
    const char *fn = "amps_write_gmsh";
    amps__out o;
    amps_int v, t;
    amps_status s;
    long long nn, nt;
    if (!m || (version != 2 && version != 4)) return amps__err(ctx, AMPS_ERR_ARG, "%s: NULL mesh or version not 2 or 4", fn);
    s = amps__open_out(ctx, fn, path, &o);
    if (s) return s;
    nn = (long long)m->nnode;
    nt = (long long)m->ntet;
    amps__pr(&o, "$MeshFormat\n%s 0 8\n$EndMeshFormat\n$Nodes\n", version == 2 ? "2.2" : "4.1");
    if (version == 2) {
        amps__pr(&o, "%lld\n", nn);
        for (v = 0; v < m->nnode; v++)
            amps__pr(&o, "%lld %.17g %.17g %.17g\n", (long long)v + 1, m->xyz[3 * v], m->xyz[3 * v + 1], m->xyz[3 * v + 2]);
        amps__pr(&o, "$EndNodes\n$Elements\n%lld\n", nt);
        for (t = 0; t < m->ntet; t++)
            amps__pr(&o, "%lld 4 2 0 1 %lld %lld %lld %lld\n", (long long)t + 1, (long long)m->tet[4 * t] + 1, (long long)m->tet[4 * t + 1] + 1,
                     (long long)m->tet[4 * t + 2] + 1, (long long)m->tet[4 * t + 3] + 1);
    } else {
        amps__pr(&o, "1 %lld 1 %lld\n3 1 0 %lld\n", nn, nn, nn);
        for (v = 0; v < m->nnode; v++) amps__pr(&o, "%lld\n", (long long)v + 1);
        for (v = 0; v < m->nnode; v++) amps__pr(&o, "%.17g %.17g %.17g\n", m->xyz[3 * v], m->xyz[3 * v + 1], m->xyz[3 * v + 2]);
        amps__pr(&o, "$EndNodes\n$Elements\n1 %lld 1 %lld\n3 1 4 %lld\n", nt, nt, nt);
        for (t = 0; t < m->ntet; t++)
            amps__pr(&o, "%lld %lld %lld %lld %lld\n", (long long)t + 1, (long long)m->tet[4 * t] + 1, (long long)m->tet[4 * t + 1] + 1,
                     (long long)m->tet[4 * t + 2] + 1, (long long)m->tet[4 * t + 3] + 1);
    }
    amps__pr(&o, "$EndElements\n");
    return amps__close_out(ctx, fn, path, &o);
}

AMPS_API amps_status amps_write_medit(amps_ctx *ctx, const char *path, const amps_mesh *m) {
    const char *fn = "amps_write_medit";
    amps__out o;
    amps_int v, t;
    amps_status s;
    if (!m) return amps__err(ctx, AMPS_ERR_ARG, "%s: NULL mesh", fn);
    s = amps__open_out(ctx, fn, path, &o);
    if (s) return s;
    amps__pr(&o, "MeshVersionFormatted 2\nDimension 3\nVertices\n%lld\n", (long long)m->nnode);
    for (v = 0; v < m->nnode; v++) amps__pr(&o, "%.17g %.17g %.17g 0\n", m->xyz[3 * v], m->xyz[3 * v + 1], m->xyz[3 * v + 2]);
    amps__pr(&o, "Tetrahedra\n%lld\n", (long long)m->ntet);
    for (t = 0; t < m->ntet; t++)
        amps__pr(&o, "%lld %lld %lld %lld 1\n", (long long)m->tet[4 * t] + 1, (long long)m->tet[4 * t + 1] + 1, (long long)m->tet[4 * t + 2] + 1,
                 (long long)m->tet[4 * t + 3] + 1);
    amps__pr(&o, "End\n");
    return amps__close_out(ctx, fn, path, &o);
}
#endif

#ifdef __cplusplus
}
#endif

#endif /* AMPS_IMPLEMENTATION_DONE */
#endif /* AMPS_IMPLEMENTATION */

/*
MIT License

Copyright (c) 2026 The amps.h authors

Permission is hereby granted, free of charge, to any person obtaining a copy of this software
and associated documentation files (the "Software"), to deal in the Software without
restriction, including without limitation the rights to use, copy, modify, merge, publish,
distribute, sublicense, and/or sell copies of the Software, and to permit persons to whom the
Software is furnished to do so, subject to the following conditions:

The above copyright notice and this permission notice shall be included in all copies or
substantial portions of the Software.

THE SOFTWARE IS PROVIDED "AS IS", WITHOUT WARRANTY OF ANY KIND, EXPRESS OR IMPLIED, INCLUDING BUT
NOT LIMITED TO THE WARRANTIES OF MERCHANTABILITY, FITNESS FOR A PARTICULAR PURPOSE AND
NONINFRINGEMENT. IN NO EVENT SHALL THE AUTHORS OR COPYRIGHT HOLDERS BE LIABLE FOR ANY CLAIM,
DAMAGES OR OTHER LIABILITY, WHETHER IN AN ACTION OF CONTRACT, TORT OR OTHERWISE, ARISING FROM, OUT
OF OR IN CONNECTION WITH THE SOFTWARE OR THE USE OR OTHER DEALINGS IN THE SOFTWARE.
*/
