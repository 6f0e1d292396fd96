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
/* The update engine keeps the exact solution of K^ x = f^ while K^ changes from the factored
   base K (order n) by principal submatrix updates, appended degrees of freedom and Dirichlet
   constraints (paper 000, Table 1, Steps 1-6). Indices are in the current numbering: 0..n-1 are
   K's rows in its original numbering, n.. are appended DOFs in order of creation.

   Changes are recorded by the update calls and applied atomically by amps_update_commit (called
   by amps_update_solve). If a commit fails (singular system, capacity) every change since the
   last successful commit is discarded and the engine is as it was.

   Allocation: amps_update_create allocates everything for the capacities in opts. Update,
   commit and solve calls allocate only when a capacity is exceeded and opts.grow is set
   (otherwise they fail with AMPS_ERR_CAPACITY and change nothing). */
typedef struct amps_update amps_update;

typedef enum amps_formulation {
    AMPS_FORM_PRIMAL = 0,   /* unknowns x_S (Eq. 3.8), x_S taken from the small system (Eq. 3.20) */
    AMPS_FORM_DUAL = 1      /* unknowns the correction forces (Eq. 3.16-3.17) */
} amps_formulation;

typedef struct amps_update_opts {
    amps_int cap_mod;       /* capacity of |S u C| (order of the dense system); default 256 */
    amps_int cap_new;       /* capacity of appended DOFs; default 3 * 256 */
    double cap_vpool;       /* memoized L^{-1} columns, in entries; default cap_mod * tree height */
    amps_int cap_delta;     /* stored entries of K^ - K-bar on S x S; default 96 * cap_mod */
    amps_int cap_pending;   /* changes recorded between commits; default 4096 */
    int grow;               /* 1: grow capacities on demand (may allocate in update calls) */
    amps_formulation formulation;
    double singular_tol;    /* pivot of the dense system below tol * column norm is singular; default 1e-12 */
    int refine;             /* refinement steps on the residual of the modified rows inside the same
                               full solve (default 1; each adds a partial backward solve over
                               closure(S u C u neighbours) and O(|S u C|^2)); 0 = none */
    int eq320;              /* 1: take x_S from the small system (Eq. 3.20); default 0 (see bench/RESULTS.md) */
} amps_update_opts;

/* Per-commit and per-solve measurements (seconds) and sizes. */
typedef struct amps_update_stats {
    double t_step[7];       /* [1] L^{-1} columns, [2] inverse principal submatrix, [3] dense
                               columns, [4] right-hand side, [5] dense factor+solve, [6] full solution */
    amps_int dim;           /* current order n + k */
    amps_int nmod;          /* |S|: indices whose row differs from K-bar */
    amps_int ncon;          /* |C|: constrained indices */
    amps_int nsys;          /* |S u C|: order of the dense system */
    amps_int lu_cols;       /* dense columns refactored by the last commit */
    amps_int lu_full;       /* full dense refactorizations so far */
    double vpool_entries;   /* memoized entries of L^{-1} H */
    amps_int ncommit, nsolve;
} amps_update_stats;

AMPS_API void amps_update_opts_default(amps_update_opts *opts);
/* Engine for base matrix K (stype part, original numbering) and its numeric factor F, which
   must stay alive and unchanged while the engine uses it. K is copied. Forces start at zero. */
AMPS_API amps_update *amps_update_create(amps_ctx *ctx, const amps_csc *K, amps_stype stype,
                                         const amps_factor *F, const amps_update_opts *opts);
AMPS_API void amps_update_free(amps_ctx *ctx, amps_update *U);
/* Current order n + k, counting DOFs added since the last commit. */
AMPS_API amps_int amps_update_dim(const amps_update *U);
/* Appends k DOFs with zero rows and zero force; *first receives the index of the first. */
AMPS_API amps_status amps_update_add_dofs(amps_ctx *ctx, amps_update *U, amps_int k, amps_int *first);
/* K^[r,c] += v and K^[c,r] += v for the nz entries (r[k], c[k], v[k]) (one entry per pair). */
AMPS_API amps_status amps_update_add(amps_ctx *ctx, amps_update *U, amps_int nz, const amps_int *r,
                                     const amps_int *c, const double *v);
/* Replaces rows (and by symmetry columns) rows[0..nrow-1] of K^ with new values: row rows[k] has
   entries (ci[j], cx[j]) for j in cp[k]..cp[k+1]-1; entries not given become zero. Where two
   given rows meet, their values must agree (to 1e-12 relative). */
AMPS_API amps_status amps_update_set_rows(amps_ctx *ctx, amps_update *U, amps_int nrow, const amps_int *rows,
                                          const amps_int *cp, const amps_int *ci, const double *cx);
/* Constrains x[idx[k]] = val[k] (adds the constraint, or moves it). */
AMPS_API amps_status amps_update_constrain(amps_ctx *ctx, amps_update *U, amps_int m, const amps_int *idx, const double *val);
/* Removes constraints; indices that are not constrained are ignored. */
AMPS_API amps_status amps_update_release(amps_ctx *ctx, amps_update *U, amps_int m, const amps_int *idx);
/* Sets f^[idx[k]] = val[k]. */
AMPS_API amps_status amps_update_set_force(amps_ctx *ctx, amps_update *U, amps_int m, const amps_int *idx, const double *val);
/* Drops every change recorded since the last commit (forces stay). */
AMPS_API void amps_update_discard(amps_update *U);
/* Applies the recorded changes (Steps 1-5). On failure discards them all. */
AMPS_API amps_status amps_update_commit(amps_ctx *ctx, amps_update *U);
/* Commits, then solves (Step 6): x (room for amps_update_dim, may be NULL) receives the solution. */
AMPS_API amps_status amps_update_solve(amps_ctx *ctx, amps_update *U, double *x);
/* Solution of the last solve (amps_update_dim entries at that time). */
AMPS_API const double *amps_update_solution(const amps_update *U);
/* Reaction force (K^ x - f^)[i] at constrained index i after the last solve; 0 if not constrained. */
AMPS_API double amps_update_reaction(const amps_update *U, amps_int i);
/* Relative residual of the constrained system after the last solve:
   ||(K^ x - f^)_F|| / ||f^_F - K^_FC x_C||, F = unconstrained indices (one sparse product). */
AMPS_API amps_status amps_update_residual(amps_ctx *ctx, amps_update *U, double *relres);
AMPS_API void amps_update_get_stats(const amps_update *U, amps_update_stats *st);

/* ================================ FEM scene ================================ */
#ifndef AMPS_NO_FEM
/* @@API fem: owned by fem */
#endif /* AMPS_NO_FEM */

/* =================================== I/O =================================== */
#if !defined(AMPS_NO_FEM) && !defined(AMPS_NO_STDIO)
/* @@API io: owned by fem */
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
#include <time.h>
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
/* Notation. n = order of the factored base K = P L D L^T P^T, N = n + k the current order,
   K-bar = diag(K, sigma I) (sigma = mean diagonal of K, so appended DOFs are scaled like K),
   K^ = K-bar + H Delta H^T the current matrix, H = I(:, U) for the index set U = S u C
   (S: indices whose rows differ from K-bar, C: constrained indices, x_C = g), and
     G = H^T K-bar^{-1} H = W^T W restricted to base indices, W = D^{-1/2} L^{-1} P^T H  (Steps 1-2)
     r = H^T K-bar^{-1} f^                                                           (Step 4)
   Writing w = Delta y + J lambda for the forces the augmentation applies (y = x_U, lambda the
   constraint multipliers, J = I(U, C)), K-bar x = f^ - H w gives y = r - G w. With F' = U \ C,
   the unknowns z = (y_F', w_C) satisfy the order-|U| system
     (I~ + G Delta~) z = r - G d - g^                                                 (Steps 3, 5)
   where I~ = diag(1 on F', 0 on C), Delta~[:, j] = Delta[F', j] (rows in C dropped) for j in F'
   and e_j for j in C, d = Delta[F', C] g, g^ = g on C and 0 on F'. Then
     w_F' = Delta[F', :] y,  x = K-bar^{-1} (f^ - H w),  x_U = y (Eq. 3.20),             (Step 6)
     reaction (K^ x - f^)_C = (Delta y)_C - w_C.
   Without constraints this is Eq. 3.8 with E-bar = -Delta; with S empty it is Eq. 3.30.
   The dual formulation (Eq. 3.16-3.17) solves the transposed system (I~ + G Delta~)^T w~ = b'
   for the correction forces w directly (b'_F' = Delta[F', :] r^, b'_C = r_C - g, r^ = r on F',
   g on C) and takes x_U from the full solve.

   Every change of K^ or of C changes columns of A = I~ + G Delta~ (column j depends on
   Delta[:, j], on the kind of j and of its Delta-neighbours) or appends rows and columns (G only
   grows). The dense LU with partial pivoting is left-looking in a column order that keeps
   recently changed columns last: a commit refactors only the columns from the first changed
   position on, O(|U|^2 r) for r changed columns. */

#define AMPS__UMOD 1u  /* index in S */
#define AMPS__UCON 2u  /* index in C */
#define AMPS__NB 32    /* dense panel width */
#define AMPS__VB 16    /* right-hand sides per chunk of Step 1 */

typedef struct amps__pdelta { amps_int r, c; double v; } amps__pdelta;
typedef struct amps__pcon { amps_int i; int release; double v; } amps__pcon;
typedef struct amps__djour { amps_int a, st, ln, cp; } amps__djour;
typedef struct amps__kjour { amps_int a; unsigned char kind; double g; } amps__kjour;

struct amps_update {
    const amps_factor *F;
    amps_formulation form;
    double tol, sigma;
    int grow, nthr, refine, eq320;
    amps_int n, N, kpend, capN;
    amps_int *Kp, *Ki;  double *Kx;        /* base K, both triangles, original numbering */
    double *f;                             /* capN forces */
    double *ct;                            /* n: D^{-1/2} L^{-1} P^T fct, permuted */
    double *fct;                           /* n: the base forces ct was computed from */
    int pf_all;                            /* pf overflowed: recompute ct in full */
    double *isd;                           /* n: D^{-1/2} */
    amps_int *pf; amps_int npf, nct_inc;   /* base forces changed since ct was updated */
    amps__pdelta *pd; amps_int npd, cappd; /* recorded K^ changes */
    amps__pcon *pc; amps_int npc, cappc;   /* recorded constraint changes */
    amps_int u, capu;                      /* |U| and capacity */
    amps_int *uidx, *upos;                 /* U position -> index; index -> U position or -1 */
    unsigned char *ukind;
    double *g;                             /* prescribed values (constrained positions) */
    size_t *voff; amps_int *vlen;          /* memoized W columns (base positions) */
    double *vval; amps_int *vidx; size_t vused, vcap;
    amps_int *dst, *dln, *dcp;             /* Delta rows (U positions): start, length, capacity */
    amps_int *dcol; double *dval; amps_int dused, dcap;
    double *G, *LU, *cnorm;                /* capu x capu column major; column norms of A */
    amps_int *rowperm, *colorder, *colpos, *cstamp; amps_int stamp;
    amps_int *rst, *rcnt; amps_int rstamp;  /* rows touched by a commit, their added entries */
    double *pbuf;                          /* nthr * capu column buffers */
    double *rv;                            /* 2 * capN residual vectors */
    amps__djour *dj; amps_int ndj;         /* Delta row headers before this commit */
    amps__kjour *kj; amps_int nkj;         /* kinds and values before this commit (cappc) */
    double *x, *react, *z, *rhs, *tmp, *yv, *wv; /* solution and dense vectors */
    double *sb, *rd, *wd, *yd, *rho;       /* dense vectors of the refinement step */
    double *work;                          /* nthr * n, zero between uses */
    double *work2;                         /* n: copy for the partial backward solve */
    double *xb; amps_int xrows;            /* Step 1 chunks: nthr * xrows * AMPS__VB */
    amps_int *lmap, *clo;                  /* Step 1: nthr * n each (lmap -1 between uses) */
    amps_int *iwork;                       /* n + capN */
    amps_marker mk, mkN;
    int dirty, has_sol;
    amps_int solN;
    amps_update_stats st;
};

static double amps__now(void) {
#ifdef _OPENMP
    return omp_get_wtime();
#else
    return (double)clock() / (double)CLOCKS_PER_SEC;
#endif
}

AMPS_API void amps_update_opts_default(amps_update_opts *o) {
    if (!o) return;
    memset(o, 0, sizeof(*o));
    o->cap_mod = 256;
    o->cap_new = 3 * 256;
    o->cap_delta = 0;
    o->cap_pending = 4096;
    o->grow = 0;
    o->formulation = AMPS_FORM_PRIMAL;
    o->singular_tol = 1e-12;
    o->refine = 1;
    o->eq320 = 0;
}

/* ---- allocation of the capacity-dependent arrays ---- */

/* Grows every U-sized array to capacity cap (> capu). All-or-nothing. */
static amps_status amps__grow_u(amps_ctx *ctx, amps_update *U, amps_int cap) {
    double *G = NULL, *LU = NULL;
    amps_int old = U->capu, u = U->u;
    size_t c = (size_t)cap;
    G = AMPS__CAST(double *, amps__malloc(ctx, c * c, sizeof(double)));
    LU = AMPS__CAST(double *, amps__malloc(ctx, c * c, sizeof(double)));
    if (!G || !LU) { amps__free(ctx, G); amps__free(ctx, LU); return amps__err(ctx, AMPS_ERR_OOM, "amps_update: out of memory growing the dense system to %ld", (long)cap); }
    /* vector arrays: a failure leaves earlier ones larger, which is harmless */
    if (amps__realloc(ctx, (void **)&U->uidx, c, sizeof(amps_int)) ||
        amps__realloc(ctx, (void **)&U->ukind, c, 1) ||
        amps__realloc(ctx, (void **)&U->g, c, sizeof(double)) ||
        amps__realloc(ctx, (void **)&U->voff, c, sizeof(size_t)) ||
        amps__realloc(ctx, (void **)&U->vlen, c, sizeof(amps_int)) ||
        amps__realloc(ctx, (void **)&U->dst, c, sizeof(amps_int)) ||
        amps__realloc(ctx, (void **)&U->dln, c, sizeof(amps_int)) ||
        amps__realloc(ctx, (void **)&U->dcp, c, sizeof(amps_int)) ||
        amps__realloc(ctx, (void **)&U->cnorm, c, sizeof(double)) ||
        amps__realloc(ctx, (void **)&U->rowperm, c, sizeof(amps_int)) ||
        amps__realloc(ctx, (void **)&U->colorder, c, sizeof(amps_int)) ||
        amps__realloc(ctx, (void **)&U->colpos, c, sizeof(amps_int)) ||
        amps__realloc(ctx, (void **)&U->cstamp, c, sizeof(amps_int)) ||
        amps__realloc(ctx, (void **)&U->rst, c, sizeof(amps_int)) ||
        amps__realloc(ctx, (void **)&U->rcnt, c, sizeof(amps_int)) ||
        amps__realloc(ctx, (void **)&U->pbuf, c * (size_t)U->nthr, sizeof(double)) ||
        amps__realloc(ctx, (void **)&U->dj, c, sizeof(amps__djour)) ||
        amps__realloc(ctx, (void **)&U->react, c, sizeof(double)) ||
        amps__realloc(ctx, (void **)&U->z, c, sizeof(double)) ||
        amps__realloc(ctx, (void **)&U->rhs, c, sizeof(double)) ||
        amps__realloc(ctx, (void **)&U->tmp, c, sizeof(double)) ||
        amps__realloc(ctx, (void **)&U->yv, c, sizeof(double)) ||
        amps__realloc(ctx, (void **)&U->wv, c, sizeof(double)) ||
        amps__realloc(ctx, (void **)&U->sb, c, sizeof(double)) ||
        amps__realloc(ctx, (void **)&U->rd, c, sizeof(double)) ||
        amps__realloc(ctx, (void **)&U->wd, c, sizeof(double)) ||
        amps__realloc(ctx, (void **)&U->yd, c, sizeof(double)) ||
        amps__realloc(ctx, (void **)&U->rho, c, sizeof(double))) {
        amps__free(ctx, G); amps__free(ctx, LU);
        return amps__err(ctx, AMPS_ERR_OOM, "amps_update: out of memory growing to %ld modified indices", (long)cap);
    }
    {
        amps_int j;
        for (j = 0; j < u; j++) {
            memcpy(G + (size_t)j * c, U->G + (size_t)j * (size_t)old, sizeof(double) * (size_t)u);
            memcpy(LU + (size_t)j * c, U->LU + (size_t)j * (size_t)old, sizeof(double) * (size_t)u);
        }
        for (j = old; j < cap; j++) { U->cstamp[j] = 0; U->rst[j] = 0; }
    }
    amps__free(ctx, U->G); amps__free(ctx, U->LU);
    U->G = G; U->LU = LU; U->capu = cap;
    return AMPS_OK;
}

/* Ensures room for `need` more U positions (grows by doubling when allowed). */
static amps_status amps__need_u(amps_ctx *ctx, amps_update *U, amps_int need) {
    amps_int cap = U->capu;
    if (U->u + need <= cap) return AMPS_OK;
    if (!U->grow)
        return amps__err(ctx, AMPS_ERR_CAPACITY, "amps_update: %ld modified/constrained indices exceed cap_mod = %ld (raise it or set grow)",
                         (long)(U->u + need), (long)cap);
    while (cap < U->u + need) cap = cap * 2 + 16;
    return amps__grow_u(ctx, U, cap);
}

static amps_status amps__need_N(amps_ctx *ctx, amps_update *U, amps_int need) {
    amps_int cap = U->capN, old = U->capN, i;
    if (U->N + U->kpend + need <= cap) return AMPS_OK;
    if (!U->grow)
        return amps__err(ctx, AMPS_ERR_CAPACITY, "amps_update: %ld appended DOFs exceed cap_new = %ld (raise it or set grow)",
                         (long)(U->N + U->kpend + need - U->n), (long)(cap - U->n));
    while (cap < U->N + U->kpend + need) cap = cap + cap / 2 + 16;
    if (amps__realloc(ctx, (void **)&U->f, (size_t)cap, sizeof(double)) ||
        amps__realloc(ctx, (void **)&U->x, (size_t)cap, sizeof(double)) ||
        amps__realloc(ctx, (void **)&U->upos, (size_t)cap, sizeof(amps_int)) ||
        amps__realloc(ctx, (void **)&U->iwork, (size_t)(U->n + cap), sizeof(amps_int)) ||
        amps__realloc(ctx, (void **)&U->rv, 2 * (size_t)cap, sizeof(double)))
        return AMPS_ERR_OOM;
    {
        amps_marker m2;
        if (amps_marker_init(ctx, &m2, cap)) return AMPS_ERR_OOM;
        amps_marker_free(ctx, &U->mkN);
        U->mkN = m2;
    }
    for (i = old; i < cap; i++) { U->f[i] = 0; U->x[i] = 0; U->upos[i] = -1; }
    U->capN = cap;
    return AMPS_OK;
}

static amps_status amps__need_pending(amps_ctx *ctx, amps_update *U, amps_int nd, amps_int nc) {
    if (U->npd + nd > U->cappd) {
        amps_int cap = U->cappd;
        if (!U->grow) return amps__err(ctx, AMPS_ERR_CAPACITY, "amps_update: more than cap_pending = %ld changes recorded before a commit", (long)cap);
        while (cap < U->npd + nd) cap = cap * 2 + 64;
        if (amps__realloc(ctx, (void **)&U->pd, (size_t)cap, sizeof(amps__pdelta))) return AMPS_ERR_OOM;
        U->cappd = cap;
    }
    if (U->npc + nc > U->cappc) {
        amps_int cap = U->cappc;
        if (!U->grow) return amps__err(ctx, AMPS_ERR_CAPACITY, "amps_update: more than cap_pending = %ld constraint changes recorded before a commit", (long)cap);
        while (cap < U->npc + nc) cap = cap * 2 + 64;
        if (amps__realloc(ctx, (void **)&U->pc, (size_t)cap, sizeof(amps__pcon)) ||
            amps__realloc(ctx, (void **)&U->kj, (size_t)cap, sizeof(amps__kjour))) return AMPS_ERR_OOM;
        U->cappc = cap;
    }
    return AMPS_OK;
}

AMPS_API void amps_update_free(amps_ctx *ctx, amps_update *U) {
    if (!U) return;
    amps__free(ctx, U->Kp); amps__free(ctx, U->Ki); amps__free(ctx, U->Kx);
    amps__free(ctx, U->f); amps__free(ctx, U->ct); amps__free(ctx, U->fct); amps__free(ctx, U->isd); amps__free(ctx, U->pf);
    amps__free(ctx, U->pd); amps__free(ctx, U->pc);
    amps__free(ctx, U->uidx); amps__free(ctx, U->upos); amps__free(ctx, U->ukind); amps__free(ctx, U->g);
    amps__free(ctx, U->voff); amps__free(ctx, U->vlen); amps__free(ctx, U->vval); amps__free(ctx, U->vidx);
    amps__free(ctx, U->dst); amps__free(ctx, U->dln); amps__free(ctx, U->dcp);
    amps__free(ctx, U->dcol); amps__free(ctx, U->dval);
    amps__free(ctx, U->G); amps__free(ctx, U->LU); amps__free(ctx, U->cnorm);
    amps__free(ctx, U->rowperm); amps__free(ctx, U->colorder); amps__free(ctx, U->colpos); amps__free(ctx, U->cstamp);
    amps__free(ctx, U->rst); amps__free(ctx, U->rcnt); amps__free(ctx, U->pbuf); amps__free(ctx, U->rv);
    amps__free(ctx, U->dj); amps__free(ctx, U->kj);
    amps__free(ctx, U->x); amps__free(ctx, U->react); amps__free(ctx, U->z); amps__free(ctx, U->rhs);
    amps__free(ctx, U->tmp); amps__free(ctx, U->yv); amps__free(ctx, U->wv);
    amps__free(ctx, U->sb); amps__free(ctx, U->rd); amps__free(ctx, U->wd); amps__free(ctx, U->yd); amps__free(ctx, U->rho);
    amps__free(ctx, U->work); amps__free(ctx, U->work2); amps__free(ctx, U->iwork);
    amps__free(ctx, U->xb); amps__free(ctx, U->lmap); amps__free(ctx, U->clo);
    amps_marker_free(ctx, &U->mk); amps_marker_free(ctx, &U->mkN);
    amps__free(ctx, U);
}

/* Full symmetric copy (both triangles, sorted columns) of K given as its stype part. */
static amps_status amps__sym_full(amps_ctx *ctx, const amps_csc *A, amps_stype stype, amps_int **Cp, amps_int **Ci, double **Cx) {
    amps_int n = A->ncol, j, p, *cnt;
    *Cp = AMPS__CAST(amps_int *, amps__calloc(ctx, (size_t)n + 1, sizeof(amps_int)));
    cnt = AMPS__CAST(amps_int *, amps__calloc(ctx, (size_t)n + 1, sizeof(amps_int)));
    *Ci = NULL; *Cx = NULL;
    if (!*Cp || !cnt) goto oom;
    for (j = 0; j < n; j++)
        for (p = A->p[j]; p < A->p[j + 1]; p++) {
            amps_int i = A->i[p];
            cnt[i]++;
            if (i != j && stype != AMPS_FULL) cnt[j]++;
        }
    for (j = 0; j < n; j++) (*Cp)[j + 1] = (*Cp)[j] + cnt[j];
    *Ci = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)(*Cp)[n], sizeof(amps_int)));
    *Cx = AMPS__CAST(double *, amps__malloc(ctx, (size_t)(*Cp)[n], sizeof(double)));
    if (!*Ci || !*Cx) goto oom;
    for (j = 0; j < n; j++) cnt[j] = (*Cp)[j];
    /* column j of the result lists rows in ascending order when filled column by column */
    for (j = 0; j < n; j++)
        for (p = A->p[j]; p < A->p[j + 1]; p++) {
            amps_int i = A->i[p];
            double v = A->x ? A->x[p] : 0.0;
            (*Ci)[cnt[i]] = j; (*Cx)[cnt[i]++] = v;       /* entry (j, i) stored in column i */
            if (i != j && stype != AMPS_FULL) { (*Ci)[cnt[j]] = i; (*Cx)[cnt[j]++] = v; }
        }
    amps__free(ctx, cnt);
    return AMPS_OK;
oom:
    amps__free(ctx, cnt); amps__free(ctx, *Cp); amps__free(ctx, *Ci); amps__free(ctx, *Cx);
    *Cp = NULL; *Ci = NULL; *Cx = NULL;
    return AMPS_ERR_OOM;
}

AMPS_API amps_update *amps_update_create(amps_ctx *ctx, const amps_csc *K, amps_stype stype,
                                         const amps_factor *F, const amps_update_opts *opts) {
    amps_update_opts o;
    amps_update *U;
    amps_int n, j, capu, capN;
    double sdiag = 0;
    size_t vcap;
    if (!K || !F) { amps__err(ctx, AMPS_ERR_ARG, "amps_update_create: NULL matrix or factor"); return NULL; }
    if (!F->is_numeric) { amps__err(ctx, AMPS_ERR_STATE, "amps_update_create: the factor has no numeric values (call amps_factorize)"); return NULL; }
    if (K->ncol != F->n || K->nrow != F->n) { amps__err(ctx, AMPS_ERR_ARG, "amps_update_create: K is %ldx%ld but the factor has order %ld", (long)K->nrow, (long)K->ncol, (long)F->n); return NULL; }
    if (amps_csc_check(ctx, K, stype) != AMPS_OK) return NULL;
    if (opts) o = *opts; else amps_update_opts_default(&o);
    if (o.cap_mod <= 0) o.cap_mod = 256;
    if (o.cap_new < 0) o.cap_new = 0;
    if (o.cap_pending <= 0) o.cap_pending = 4096;
    if (!(o.singular_tol >= 0) || o.singular_tol >= 1) { amps__err(ctx, AMPS_ERR_ARG, "amps_update_create: singular_tol must be in [0, 1)"); return NULL; }
    n = F->n; capu = o.cap_mod; capN = n + o.cap_new;
    U = AMPS__CAST(amps_update *, amps__calloc(ctx, 1, sizeof(amps_update)));
    if (!U) return NULL;
    U->F = F; U->form = o.formulation; U->tol = o.singular_tol; U->grow = o.grow;
    U->refine = o.refine; U->eq320 = o.eq320;
    U->n = n; U->N = n; U->capN = capN; U->capu = 0; U->u = 0;
#ifdef _OPENMP
    U->nthr = ctx && ctx->nthreads > 0 ? ctx->nthreads : omp_get_max_threads();
#else
    U->nthr = 1;
#endif
    if (U->nthr < 1) U->nthr = 1;
    if (amps__sym_full(ctx, K, stype, &U->Kp, &U->Ki, &U->Kx)) goto fail;
    vcap = o.cap_vpool > 0 ? (size_t)o.cap_vpool : (size_t)capu * (size_t)(F->height > 0 ? F->height : 1);
    U->vcap = vcap;
    U->dcap = o.cap_delta > 0 ? o.cap_delta : 96 * capu;
    U->cappd = o.cap_pending; U->cappc = o.cap_pending;
    U->f = AMPS__CAST(double *, amps__calloc(ctx, (size_t)capN, sizeof(double)));
    U->x = AMPS__CAST(double *, amps__calloc(ctx, (size_t)capN, sizeof(double)));
    U->upos = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)capN, sizeof(amps_int)));
    U->iwork = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)(n + capN), sizeof(amps_int)));
    U->ct = AMPS__CAST(double *, amps__calloc(ctx, (size_t)n, sizeof(double)));
    U->fct = AMPS__CAST(double *, amps__calloc(ctx, (size_t)n, sizeof(double)));
    U->isd = AMPS__CAST(double *, amps__malloc(ctx, (size_t)n, sizeof(double)));
    U->pf = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)n, sizeof(amps_int)));
    U->work = AMPS__CAST(double *, amps__calloc(ctx, (size_t)n * (size_t)U->nthr, sizeof(double)));
    U->work2 = AMPS__CAST(double *, amps__malloc(ctx, (size_t)n, sizeof(double)));
    U->xrows = F->height > 0 && (double)F->height * AMPS__VB < (double)n ? F->height * AMPS__VB : n;
    U->xb = AMPS__CAST(double *, amps__malloc(ctx, (size_t)U->nthr * (size_t)U->xrows * AMPS__VB, sizeof(double)));
    U->lmap = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)U->nthr * (size_t)n, sizeof(amps_int)));
    U->clo = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)U->nthr * (size_t)n, sizeof(amps_int)));
    U->pd = AMPS__CAST(amps__pdelta *, amps__malloc(ctx, (size_t)U->cappd, sizeof(amps__pdelta)));
    U->pc = AMPS__CAST(amps__pcon *, amps__malloc(ctx, (size_t)U->cappc, sizeof(amps__pcon)));
    U->vval = AMPS__CAST(double *, amps__malloc(ctx, vcap, sizeof(double)));
    U->vidx = AMPS__CAST(amps_int *, amps__malloc(ctx, vcap, sizeof(amps_int)));
    U->dcol = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)U->dcap, sizeof(amps_int)));
    U->dval = AMPS__CAST(double *, amps__malloc(ctx, (size_t)U->dcap, sizeof(double)));
    U->kj = AMPS__CAST(amps__kjour *, amps__malloc(ctx, (size_t)U->cappc, sizeof(amps__kjour)));
    U->rv = AMPS__CAST(double *, amps__malloc(ctx, 2 * (size_t)capN, sizeof(double)));
    if (!U->f || !U->x || !U->upos || !U->iwork || !U->ct || !U->fct || !U->isd || !U->pf || !U->work || !U->work2 || !U->xb || !U->lmap || !U->clo || !U->pd || !U->pc ||
        !U->vval || !U->vidx || !U->dcol || !U->dval || !U->kj || !U->rv)
        goto fail;
    if (amps_marker_init(ctx, &U->mk, n > 0 ? n : 1) || amps_marker_init(ctx, &U->mkN, capN > 0 ? capN : 1)) goto fail;
    U->G = AMPS__CAST(double *, amps__malloc(ctx, 1, sizeof(double)));
    U->LU = AMPS__CAST(double *, amps__malloc(ctx, 1, sizeof(double)));
    if (!U->G || !U->LU) goto fail;
    if (amps__grow_u(ctx, U, capu)) goto fail;
    for (j = 0; j < capN; j++) U->upos[j] = -1;
    for (j = 0; j < n * U->nthr; j++) U->lmap[j] = -1;
    for (j = 0; j < n; j++) {
        U->isd[j] = 1.0 / sqrt(F->D[j]);
        sdiag += F->D[j];
    }
    /* sigma: scale of K-bar's identity block; mean of the diagonal of K */
    {
        double s = 0; amps_int p;
        for (j = 0; j < n; j++)
            for (p = U->Kp[j]; p < U->Kp[j + 1]; p++)
                if (U->Ki[p] == j) s += U->Kx[p];
        U->sigma = n > 0 && s > 0 ? s / (double)n : 1.0;
        (void)sdiag;
    }
    U->dirty = 1;
    U->st.dim = n;
    return U;
fail:
    if (ctx && ctx->status != AMPS_ERR_OOM) amps__err(ctx, AMPS_ERR_OOM, "amps_update_create: out of memory");
    amps_update_free(ctx, U);
    return NULL;
}

AMPS_API amps_int amps_update_dim(const amps_update *U) { return U ? U->N + U->kpend : 0; }

/* ---- recording changes ---- */

static amps_status amps__chk_idx(amps_ctx *ctx, const amps_update *U, const char *fn, amps_int m,
                                 const amps_int *idx, const double *val, int nodup, amps_marker *mk) {
    amps_int k, N = U->N + U->kpend;
    if (m < 0) return amps__err(ctx, AMPS_ERR_ARG, "%s: negative count %ld", fn, (long)m);
    if (m > 0 && !idx) return amps__err(ctx, AMPS_ERR_ARG, "%s: NULL index array", fn);
    if (nodup) amps_marker_next(mk);
    for (k = 0; k < m; k++) {
        if (idx[k] < 0 || idx[k] >= N) return amps__err(ctx, AMPS_ERR_INDEX, "%s: index %ld (entry %ld) out of range [0, %ld)", fn, (long)idx[k], (long)k, (long)N);
        if (val && !amps__isfinite(val[k])) return amps__err(ctx, AMPS_ERR_VALUE, "%s: value of entry %ld (index %ld) is not finite", fn, (long)k, (long)idx[k]);
        if (nodup) {
            if (mk->mark[idx[k]] == mk->stamp) return amps__err(ctx, AMPS_ERR_ARG, "%s: index %ld given twice", fn, (long)idx[k]);
            mk->mark[idx[k]] = mk->stamp;
        }
    }
    return AMPS_OK;
}

AMPS_API amps_status amps_update_add_dofs(amps_ctx *ctx, amps_update *U, amps_int k, amps_int *first) {
    amps_int i, base;
    amps_status s;
    if (!U || k < 0) return amps__err(ctx, AMPS_ERR_ARG, "amps_update_add_dofs: %s", U ? "negative count" : "NULL engine");
    if ((s = amps__need_N(ctx, U, k)) != AMPS_OK) return s;
    if ((s = amps__need_pending(ctx, U, k, 0)) != AMPS_OK) return s;
    base = U->N + U->kpend;
    for (i = 0; i < k; i++) {
        /* K-bar has sigma on the new diagonal; the recorded -sigma makes the new row zero */
        U->pd[U->npd].r = base + i; U->pd[U->npd].c = base + i; U->pd[U->npd].v = -U->sigma; U->npd++;
        U->f[base + i] = 0;
    }
    U->kpend += k;
    if (first) *first = base;
    return AMPS_OK;
}

static int amps__int_cmp(const void *a, const void *b) {
    amps_int x = *(const amps_int *)a, y = *(const amps_int *)b;
    return x < y ? -1 : (x > y ? 1 : 0);
}

static int amps__pd_cmp(const void *a, const void *b) {
    const amps__pdelta *x = (const amps__pdelta *)a, *y = (const amps__pdelta *)b;
    amps_int xr = x->r < x->c ? x->r : x->c, xc = x->r < x->c ? x->c : x->r;
    amps_int yr = y->r < y->c ? y->r : y->c, yc = y->r < y->c ? y->c : y->r;
    if (xr != yr) return xr < yr ? -1 : 1;
    if (xc != yc) return xc < yc ? -1 : 1;
    return 0;
}

AMPS_API amps_status amps_update_add(amps_ctx *ctx, amps_update *U, amps_int nz, const amps_int *r,
                                     const amps_int *c, const double *v) {
    amps_int k, N, start;
    amps_status s;
    if (!U) return amps__err(ctx, AMPS_ERR_ARG, "amps_update_add: NULL engine");
    if (nz < 0 || (nz > 0 && (!r || !c || !v))) return amps__err(ctx, AMPS_ERR_ARG, "amps_update_add: bad count or NULL array");
    N = U->N + U->kpend;
    for (k = 0; k < nz; k++) {
        if (r[k] < 0 || r[k] >= N || c[k] < 0 || c[k] >= N)
            return amps__err(ctx, AMPS_ERR_INDEX, "amps_update_add: entry %ld (%ld, %ld) out of range [0, %ld)", (long)k, (long)r[k], (long)c[k], (long)N);
        if (!amps__isfinite(v[k])) return amps__err(ctx, AMPS_ERR_VALUE, "amps_update_add: value of entry %ld (%ld, %ld) is not finite", (long)k, (long)r[k], (long)c[k]);
    }
    if ((s = amps__need_pending(ctx, U, nz, 0)) != AMPS_OK) return s;
    start = U->npd;
    for (k = 0; k < nz; k++) { U->pd[start + k].r = r[k]; U->pd[start + k].c = c[k]; U->pd[start + k].v = v[k]; }
    qsort(U->pd + start, (size_t)nz, sizeof(amps__pdelta), amps__pd_cmp);
    for (k = start + 1; k < start + nz; k++)
        if (amps__pd_cmp(U->pd + k - 1, U->pd + k) == 0)
            return amps__err(ctx, AMPS_ERR_ARG, "amps_update_add: entry (%ld, %ld) given twice", (long)U->pd[k].r, (long)U->pd[k].c);
    U->npd = start + nz;
    return AMPS_OK;
}

/* Current value K^[r, c] including recorded changes (r, c < N + kpend). */
static double amps__cur_entry(const amps_update *U, amps_int r, amps_int c) {
    double v = 0;
    amps_int p, k, a;
    if (r < U->n && c < U->n) {
        for (p = U->Kp[c]; p < U->Kp[c + 1]; p++) if (U->Ki[p] == r) { v = U->Kx[p]; break; }
    } else if (r == c) v = U->sigma;
    a = r < U->N ? U->upos[r] : -1;
    if (a >= 0 && (c < U->N ? U->upos[c] : -1) >= 0) {
        amps_int b = U->upos[c];
        for (k = 0; k < U->dln[a]; k++) if (U->dcol[U->dst[a] + k] == b) { v += U->dval[U->dst[a] + k]; break; }
    }
    for (k = 0; k < U->npd; k++)
        if ((U->pd[k].r == r && U->pd[k].c == c) || (U->pd[k].r == c && U->pd[k].c == r)) v += U->pd[k].v;
    return v;
}

AMPS_API amps_status amps_update_set_rows(amps_ctx *ctx, amps_update *U, amps_int nrow, const amps_int *rows,
                                          const amps_int *cp, const amps_int *ci, const double *cx) {
    amps_int k, j, q, N, start, *iw;
    amps_status s;
    if (!U) return amps__err(ctx, AMPS_ERR_ARG, "amps_update_set_rows: NULL engine");
    if (nrow < 0 || (nrow > 0 && (!rows || !cp))) return amps__err(ctx, AMPS_ERR_ARG, "amps_update_set_rows: bad count or NULL array");
    if ((s = amps__chk_idx(ctx, U, "amps_update_set_rows", nrow, rows, NULL, 1, &U->mkN)) != AMPS_OK) return s;
    N = U->N + U->kpend;
    if (cp[0] != 0) return amps__err(ctx, AMPS_ERR_ARG, "amps_update_set_rows: cp[0] must be 0");
    for (k = 0; k < nrow; k++) {
        if (cp[k + 1] < cp[k]) return amps__err(ctx, AMPS_ERR_ARG, "amps_update_set_rows: cp decreases at row %ld", (long)k);
        for (j = cp[k]; j < cp[k + 1]; j++) {
            if (ci[j] < 0 || ci[j] >= N) return amps__err(ctx, AMPS_ERR_INDEX, "amps_update_set_rows: row %ld, column %ld out of range [0, %ld)", (long)rows[k], (long)ci[j], (long)N);
            if (!amps__isfinite(cx[j])) return amps__err(ctx, AMPS_ERR_VALUE, "amps_update_set_rows: row %ld, column %ld: value not finite", (long)rows[k], (long)ci[j]);
            for (q = cp[k]; q < j; q++)
                if (ci[q] == ci[j]) return amps__err(ctx, AMPS_ERR_ARG, "amps_update_set_rows: row %ld lists column %ld twice", (long)rows[k], (long)ci[j]);
        }
    }
    /* symmetry where two given rows meet: row a's entry at b must equal row b's entry at a */
    for (k = 0; k < nrow; k++)
        for (j = cp[k]; j < cp[k + 1]; j++)
            if (U->mkN.mark[ci[j]] == U->mkN.stamp) {
                amps_int kk, b = ci[j];
                double vb = 0;
                for (kk = 0; kk < nrow && rows[kk] != b; kk++) {}
                for (q = cp[kk]; q < cp[kk + 1]; q++) if (ci[q] == rows[k]) { vb = cx[q]; break; }
                if (fabs(vb - cx[j]) > 1e-12 * (fabs(vb) + fabs(cx[j])))
                    return amps__err(ctx, AMPS_ERR_ARG, "amps_update_set_rows: rows %ld and %ld disagree at their crossing (%g vs %g)", (long)rows[k], (long)b, cx[j], vb);
            }
    /* the changes: for each row r, every column c of the current or the new row gets
       new - current; a pair of two given rows is recorded once (from the smaller row) */
    start = U->npd;
    iw = U->iwork;
    for (k = 0; k < nrow; k++) {
        amps_int r = rows[k], a, cnt = 0;
        a = r < U->N ? U->upos[r] : -1;
        if ((r < U->n ? U->Kp[r + 1] - U->Kp[r] : 1) + (a >= 0 ? U->dln[a] : 0) + U->npd + (cp[k + 1] - cp[k]) > U->n + U->capN) {
            U->npd = start;
            return amps__err(ctx, AMPS_ERR_CAPACITY, "amps_update_set_rows: too many changes recorded; commit first");
        }
        /* columns of the current row: base pattern, Delta row, recorded changes; then new ones */
        if (r < U->n) for (q = U->Kp[r]; q < U->Kp[r + 1]; q++) iw[cnt++] = U->Ki[q];
        else iw[cnt++] = r;
        if (a >= 0) for (q = 0; q < U->dln[a]; q++) iw[cnt++] = U->uidx[U->dcol[U->dst[a] + q]];
        for (q = 0; q < start; q++) {
            if (U->pd[q].r == r) iw[cnt++] = U->pd[q].c;
            else if (U->pd[q].c == r) iw[cnt++] = U->pd[q].r;
        }
        for (j = cp[k]; j < cp[k + 1]; j++) iw[cnt++] = ci[j];
        qsort(iw, (size_t)cnt, sizeof(amps_int), amps__int_cmp);
        {
            amps_int i2, m2 = 0;
            for (i2 = 0; i2 < cnt; i2++) if (m2 == 0 || iw[m2 - 1] != iw[i2]) iw[m2++] = iw[i2];
            cnt = m2;
        }
        if ((s = amps__need_pending(ctx, U, cnt, 0)) != AMPS_OK) { U->npd = start; return s; }
        for (q = 0; q < cnt; q++) {
            amps_int c = iw[q];
            double nv = 0, d;
            if (U->mkN.mark[c] == U->mkN.stamp && c < r) continue;   /* recorded from row c */
            for (j = cp[k]; j < cp[k + 1]; j++) if (ci[j] == c) { nv = cx[j]; break; }
            d = nv - amps__cur_entry(U, r, c);
            if (d != 0) { U->pd[U->npd].r = r; U->pd[U->npd].c = c; U->pd[U->npd].v = d; U->npd++; }
        }
    }
    return AMPS_OK;
}

AMPS_API amps_status amps_update_constrain(amps_ctx *ctx, amps_update *U, amps_int m, const amps_int *idx, const double *val) {
    amps_int k;
    amps_status s;
    if (!U) return amps__err(ctx, AMPS_ERR_ARG, "amps_update_constrain: NULL engine");
    if (m > 0 && !val) return amps__err(ctx, AMPS_ERR_ARG, "amps_update_constrain: NULL values");
    if ((s = amps__chk_idx(ctx, U, "amps_update_constrain", m, idx, val, 1, &U->mkN)) != AMPS_OK) return s;
    if ((s = amps__need_pending(ctx, U, 0, m)) != AMPS_OK) return s;
    for (k = 0; k < m; k++) { U->pc[U->npc].i = idx[k]; U->pc[U->npc].release = 0; U->pc[U->npc].v = val[k]; U->npc++; }
    return AMPS_OK;
}

AMPS_API amps_status amps_update_release(amps_ctx *ctx, amps_update *U, amps_int m, const amps_int *idx) {
    amps_int k;
    amps_status s;
    if (!U) return amps__err(ctx, AMPS_ERR_ARG, "amps_update_release: NULL engine");
    if ((s = amps__chk_idx(ctx, U, "amps_update_release", m, idx, NULL, 1, &U->mkN)) != AMPS_OK) return s;
    if ((s = amps__need_pending(ctx, U, 0, m)) != AMPS_OK) return s;
    for (k = 0; k < m; k++) { U->pc[U->npc].i = idx[k]; U->pc[U->npc].release = 1; U->pc[U->npc].v = 0; U->npc++; }
    return AMPS_OK;
}

AMPS_API amps_status amps_update_set_force(amps_ctx *ctx, amps_update *U, amps_int m, const amps_int *idx, const double *val) {
    amps_int k;
    amps_status s;
    if (!U) return amps__err(ctx, AMPS_ERR_ARG, "amps_update_set_force: NULL engine");
    if (m > 0 && !val) return amps__err(ctx, AMPS_ERR_ARG, "amps_update_set_force: NULL values");
    if ((s = amps__chk_idx(ctx, U, "amps_update_set_force", m, idx, val, 1, &U->mkN)) != AMPS_OK) return s;
    for (k = 0; k < m; k++) {
        amps_int i = idx[k];
        if (U->f[i] == val[k]) continue;
        /* base forces reach ct at the next solve, from the difference f - fct */
        if (i < U->n) { if (U->npf < U->n) U->pf[U->npf++] = i; else U->pf_all = 1; }
        U->f[i] = val[k];
    }
    if (m > 0) U->dirty = 1;
    return AMPS_OK;
}

/* ---- Steps 1-2: memoized columns of W = D^{-1/2} L^{-1} and entries of G = W^T W ---- */

static amps_int amps__path_len(const amps_factor *F, amps_int p) {
    amps_int len = 0;
    for (; p != -1; p = F->parent[p]) len++;
    return len;
}

/* X := L^{-1} X restricted to the ascending node list clo[0..nc-1] (closed under the elimination
   tree's parents), X row-major with W columns, row t for node clo[t], lmap: node -> row. */
#define AMPS__WSOLVE(W)                                                                        \
    static void amps__wsolve##W(const amps_factor *F, const amps_int *clo, amps_int nc,         \
                                const amps_int *lmap, double *X) {                             \
        amps_int t, e, j;                                                                      \
        for (t = 0; t < nc; t++) {                                                             \
            double xk[W];                                                                      \
            amps_int k = clo[t];                                                               \
            int nz = 0;                                                                        \
            memcpy(xk, X + (size_t)t * W, sizeof(xk));                                         \
            for (j = 0; j < W; j++) nz |= xk[j] != 0.0;                                        \
            if (!nz) continue;                                                                 \
            for (e = F->Lp[k]; e < F->Lp[k + 1]; e++) {                                        \
                double l = F->Lx[e], *xr = X + (size_t)lmap[F->Li[e]] * W;                     \
                for (j = 0; j < W; j++) xr[j] -= l * xk[j];                                    \
            }                                                                                  \
        }                                                                                      \
    }
AMPS__WSOLVE(4)
AMPS__WSOLVE(8)
AMPS__WSOLVE(16)
#undef AMPS__WSOLVE

/* W columns (W = D^{-1/2} L^{-1} e_p on the root path of p, ascending) of the U positions
   list[0..nb-1], written at voff/vlen. The columns are split into chunks of at most AMPS__VB,
   one chunk per thread at a time; a chunk is one forward solve over the union of its paths
   (ascending = topological), X(t, j) row-major over the chunk, so each column of L on the
   union is read once per chunk. The rows of L(:, k) lie on the path of k, so no solve leaves
   the union. Workspace per thread: xb (xrows * AMPS__VB), lmap (n, -1 outside use), clo (n). */
static void amps__wcols(amps_update *U, const amps_int *list, amps_int nb) {
    const amps_factor *F = U->F;
    amps_int nchunk, csize, ch;
    if (nb <= 0) return;
    {   /* threads only when the work (entries of L on one path, times nb) is worth a fork */
        double work = 0;
        amps_int k;
        for (k = F->iperm[U->uidx[list[0]]]; k != -1; k = F->parent[k]) work += (double)(F->Lp[k + 1] - F->Lp[k]);
        work *= (double)nb;
        csize = work > 2e6 ? (nb + U->nthr - 1) / U->nthr : nb;
    }
    if (csize > AMPS__VB) csize = AMPS__VB;
    nchunk = (nb + csize - 1) / csize;
#ifdef _OPENMP
#pragma omp parallel for schedule(dynamic, 1) num_threads(U->nthr) if (nchunk > 1)
#endif
    for (ch = 0; ch < nchunk; ch++) {
#ifdef _OPENMP
        int th = omp_get_thread_num();
#else
        int th = 0;
#endif
        double *X = U->xb + (size_t)th * (size_t)U->xrows * AMPS__VB;
        amps_int *lmap = U->lmap + (size_t)th * (size_t)U->n, *clo = U->clo + (size_t)th * (size_t)U->n;
        amps_int j0 = ch * csize, m = nb - j0 < csize ? nb - j0 : csize, nc = 0, j, t, k, mw;
        /* union of the root paths, ascending */
        for (j = 0; j < m; j++)
            for (k = F->iperm[U->uidx[list[j0 + j]]]; k != -1 && lmap[k] < 0; k = F->parent[k]) { lmap[k] = 0; clo[nc++] = k; }
        qsort(clo, (size_t)nc, sizeof(amps_int), amps__int_cmp);
        for (t = 0; t < nc; t++) lmap[clo[t]] = t;
        mw = m <= 4 ? 4 : (m <= 8 ? 8 : AMPS__VB);
        memset(X, 0, sizeof(double) * (size_t)nc * (size_t)mw);
        for (j = 0; j < m; j++) X[(size_t)lmap[F->iperm[U->uidx[list[j0 + j]]]] * (size_t)mw + (size_t)j] = 1.0;
        /* X := L^{-1} X on the union, with a fixed row width mw >= m (zero padding) */
        if (m <= 4) amps__wsolve4(F, clo, nc, lmap, X);
        else if (m <= 8) amps__wsolve8(F, clo, nc, lmap, X);
        else amps__wsolve16(F, clo, nc, lmap, X);
        /* gather each column along its own path, scaled by D^{-1/2} */
        for (j = 0; j < m; j++) {
            amps_int aa = list[j0 + j], len = 0;
            double *wv = U->vval + U->voff[aa];
            amps_int *wi = U->vidx + U->voff[aa];
            for (k = F->iperm[U->uidx[aa]]; k != -1; k = F->parent[k]) {
                wi[len] = k;
                wv[len] = X[(size_t)lmap[k] * (size_t)mw + (size_t)j] * U->isd[k];
                len++;
            }
        }
        for (t = 0; t < nc; t++) lmap[clo[t]] = -1;
    }
}

/* Position of v in ascending a[0..len-1], or -1. */
static amps_int amps__bsearch(const amps_int *a, amps_int len, amps_int v) {
    amps_int lo = 0, hi = len - 1;
    while (lo <= hi) {
        amps_int mid = lo + (hi - lo) / 2;
        if (a[mid] == v) return mid;
        if (a[mid] < v) lo = mid + 1; else hi = mid - 1;
    }
    return -1;
}

/* W_a^T W_b: the two root paths share exactly a common suffix (from their lowest common
   ancestor on); membership in path b is monotone along path a, so bisection finds its start. */
static double amps__wdot(const amps_int *ia, const double *va, amps_int la, const amps_int *ib, const double *vb, amps_int lb) {
    amps_int lo = 0, hi = la - 1, m, t;
    double s = 0;
    if (la == 0 || lb == 0 || ia[la - 1] != ib[lb - 1]) return 0.0;   /* different trees */
    while (lo < hi) {                     /* first position of path a that lies on path b */
        amps_int mid = lo + (hi - lo) / 2;
        if (amps__bsearch(ib, lb, ia[mid]) >= 0) hi = mid; else lo = mid + 1;
    }
    m = la - lo;
    va += lo; vb += lb - m;
    for (t = 0; t < m; t++) s += va[t] * vb[t];
    return s;
}

/* G entry of U positions a, b (K-bar^{-1} is 1/sigma on appended DOFs). */
static double amps__gentry(const amps_update *U, amps_int a, amps_int b) {
    amps_int i = U->uidx[a], j = U->uidx[b];
    if (i >= U->n || j >= U->n) return (a == b) ? 1.0 / U->sigma : 0.0;
    return amps__wdot(U->vidx + U->voff[a], U->vval + U->voff[a], U->vlen[a],
                      U->vidx + U->voff[b], U->vval + U->voff[b], U->vlen[b]);
}

/* ---- Step 3: columns of A = I~ + G Delta~ ---- */

/* out (U positions) = A(:, j). */
static void amps__acol(const amps_update *U, amps_int j, double *out) {
    amps_int u = U->u, i, k;
    size_t ld = (size_t)U->capu;
    if (U->ukind[j] & AMPS__UCON) { memcpy(out, U->G + (size_t)j * ld, sizeof(double) * (size_t)u); return; }
    memset(out, 0, sizeof(double) * (size_t)u);
    out[j] = 1.0;
    for (k = 0; k < U->dln[j]; k++) {
        amps_int b = U->dcol[U->dst[j] + k];
        double v = U->dval[U->dst[j] + k];
        const double *gb;
        if (U->ukind[b] & AMPS__UCON) continue;      /* rows of Delta in C are dropped */
        gb = U->G + (size_t)b * ld;                  /* G symmetric: G(:, b) */
        for (i = 0; i < u; i++) out[i] += gb[i] * v;
    }
}

/* A(i, j). */
static double amps__aentry(const amps_update *U, amps_int i, amps_int j) {
    size_t ld = (size_t)U->capu;
    double s;
    amps_int k;
    if (U->ukind[j] & AMPS__UCON) return U->G[(size_t)j * ld + (size_t)i];
    s = (i == j) ? 1.0 : 0.0;
    for (k = 0; k < U->dln[j]; k++) {
        amps_int b = U->dcol[U->dst[j] + k];
        if (!(U->ukind[b] & AMPS__UCON)) s += U->G[(size_t)b * ld + (size_t)i] * U->dval[U->dst[j] + k];
    }
    return s;
}

/* ---- Step 5: left-looking dense LU with partial pivoting, P A(:, colorder) = L U ---- */

/* C(0:m, 0:w) -= A(0:m, 0:kk) B(0:kk, 0:w), column major; one parallel region over row
   blocks of 128 (a block of C stays in cache while A streams through once). */
static void amps__gemm_sub(amps_int m, amps_int w, amps_int kk, const double *A, size_t lda,
                           const double *B, size_t ldb, double *C, size_t ldc, int nthr) {
    amps_int rb, nrb = (m + 127) / 128;
    (void)nthr;
    if (m <= 0 || w <= 0 || kk <= 0) return;
#ifdef _OPENMP
#pragma omp parallel for schedule(static) num_threads(nthr) if ((double)m * w * kk > 1e6)
#endif
    for (rb = 0; rb < nrb; rb++) {
        amps_int r0 = rb * 128, r1 = r0 + 128 < m ? r0 + 128 : m, k, c, r;
        for (k = 0; k < kk; k++) {
            const double *a = A + (size_t)k * lda;
            for (c = 0; c < w; c++) {
                double bv = B[(size_t)c * ldb + (size_t)k];
                double *cc = C + (size_t)c * ldc;
                if (bv == 0.0) continue;
                for (r = r0; r < r1; r++) cc[r] -= a[r] * bv;
            }
        }
    }
}

/* Factors positions nf..u-1 given positions 0..nf-1 factored for physical rows 0..u_old-1;
   rows u_old..u-1 are new (rowperm set). Returns AMPS_OK, AMPS_ERR_SINGULAR_UPDATE (position in
   *bad), or AMPS_ERR_CAPACITY when the new rows' multipliers grow past 1e6 (refactor from 0). */
static amps_status amps__lu_extend(amps_update *U, amps_int nf, amps_int u_old, amps_int *bad) {
    amps_int u = U->u, q, qp, r, k;
    size_t ld = (size_t)U->capu;
    double *LU = U->LU;
    /* new rows: L(r, 0:nf) solves l U11 = A(r, colorder[0:nf]) */
    if (nf > 0 && u > u_old) {
        double growth = 0;
        for (q = 0; q < nf; q++) {
            double *lq = LU + (size_t)q * ld, piv = LU[(size_t)q * ld + (size_t)q];
            amps_int j = U->colorder[q];
            for (r = u_old; r < u; r++) lq[r] = amps__aentry(U, U->rowperm[r], j);
            for (k = 0; k < q; k++) {
                const double *lk = LU + (size_t)k * ld;
                double ukq = lq[k];
                if (ukq == 0.0) continue;
                for (r = u_old; r < u; r++) lq[r] -= lk[r] * ukq;
            }
            for (r = u_old; r < u; r++) { lq[r] /= piv; if (fabs(lq[r]) > growth) growth = fabs(lq[r]); }
        }
        if (!(growth <= 1e6)) return AMPS_ERR_CAPACITY;
    }
    for (qp = nf; qp < u; qp += AMPS__NB) {
        amps_int w = u - qp < AMPS__NB ? u - qp : AMPS__NB, c, kb;
        double *P = LU + (size_t)qp * ld;
        /* load the panel: A(rowperm, colorder[qp:qp+w]) and its column norms */
#ifdef _OPENMP
#pragma omp parallel for schedule(dynamic, 1) num_threads(U->nthr) if (w > 1 && u > 64)
#endif
        for (c = 0; c < w; c++) {
#ifdef _OPENMP
            double *buf = U->pbuf + (size_t)omp_get_thread_num() * ld;
#else
            double *buf = U->pbuf;
#endif
            amps_int j = U->colorder[qp + c], rr;
            double nrm = 0, *col = P + (size_t)c * ld;
            amps__acol(U, j, buf);
            for (rr = 0; rr < u; rr++) { col[rr] = buf[U->rowperm[rr]]; if (fabs(buf[rr]) > nrm) nrm = fabs(buf[rr]); }
            U->cnorm[j] = nrm;
        }
        /* apply the factored columns 0..qp-1: P(0:qp) = L11^{-1} P(0:qp) (unit lower, per
           column), then P(qp:u) -= L(qp:u, 0:qp) P(0:qp) */
#ifdef _OPENMP
#pragma omp parallel for schedule(static) num_threads(U->nthr) if (w > 1 && (double)qp * qp * w > 4e5)
#endif
        for (c = 0; c < w; c++) {
            double *col = P + (size_t)c * ld;
            for (kb = 0; kb < qp; kb++) {
                const double *lk = LU + (size_t)kb * ld;
                double x = col[kb];
                if (x == 0.0) continue;
                for (r = kb + 1; r < qp; r++) col[r] -= lk[r] * x;
            }
        }
        amps__gemm_sub(u - qp, w, qp, LU + (size_t)qp, ld, P, ld, P + (size_t)qp, ld, U->nthr);
        /* factor the panel with partial pivoting; swaps act on whole rows 0..qp+w-1 */
        for (c = 0; c < w; c++) {
            amps_int qq = qp + c, pr = qq, j = U->colorder[qq], cc;
            double *col = LU + (size_t)qq * ld, pmax = fabs(col[qq]), piv;
            for (r = qq + 1; r < u; r++) if (fabs(col[r]) > pmax) { pmax = fabs(col[r]); pr = r; }
            /* reference: the column's norm; for unconstrained columns at least the identity part,
               so that a column cancelled to rounding level (a row with no stiffness) is caught */
            if (!(pmax > U->tol * ((U->ukind[j] & AMPS__UCON) || U->cnorm[j] > 1.0 ? U->cnorm[j] : 1.0)) || pmax == 0.0) {
                *bad = j;
                return AMPS_ERR_SINGULAR_UPDATE;
            }
            if (pr != qq) {
                amps_int t = U->rowperm[pr];
                U->rowperm[pr] = U->rowperm[qq]; U->rowperm[qq] = t;
                for (cc = 0; cc < qp + w; cc++) {
                    double *cl = LU + (size_t)cc * ld, tv = cl[pr];
                    cl[pr] = cl[qq]; cl[qq] = tv;
                }
            }
            piv = col[qq];
            for (r = qq + 1; r < u; r++) col[r] /= piv;
            for (cc = qq + 1; cc < qp + w; cc++) {
                double *cl = LU + (size_t)cc * ld, x = cl[qq];
                if (x == 0.0) continue;
                for (r = qq + 1; r < u; r++) cl[r] -= col[r] * x;
            }
        }
    }
    for (q = 0; q < u; q++) U->colpos[U->colorder[q]] = q;
    return AMPS_OK;
}

/* z = A^{-1} b (U positions); t is scratch of length u. */
static void amps__lu_solve(const amps_update *U, const double *b, double *z, double *t) {
    amps_int u = U->u, q, r;
    size_t ld = (size_t)U->capu;
    for (r = 0; r < u; r++) t[r] = b[U->rowperm[r]];
    for (q = 0; q < u; q++) {
        const double *l = U->LU + (size_t)q * ld;
        double x = t[q];
        if (x != 0.0) for (r = q + 1; r < u; r++) t[r] -= l[r] * x;
    }
    for (q = u - 1; q >= 0; q--) {
        const double *col = U->LU + (size_t)q * ld;
        double x = t[q] / col[q];
        t[q] = x;
        if (x != 0.0) for (r = 0; r < q; r++) t[r] -= col[r] * x;
    }
    for (q = 0; q < u; q++) z[U->colorder[q]] = t[q];
}

/* z = A^{-T} b (U positions). */
static void amps__lu_solve_t(const amps_update *U, const double *b, double *z, double *t) {
    amps_int u = U->u, q, r;
    size_t ld = (size_t)U->capu;
    for (q = 0; q < u; q++) t[q] = b[U->colorder[q]];
    for (q = 0; q < u; q++) {                 /* U^T v = t */
        const double *col = U->LU + (size_t)q * ld;
        double s = t[q];
        for (r = 0; r < q; r++) s -= col[r] * t[r];
        t[q] = s / col[q];
    }
    for (q = u - 1; q >= 0; q--) {            /* L^T */
        const double *l = U->LU + (size_t)q * ld;
        double s = t[q];
        for (r = q + 1; r < u; r++) s -= l[r] * t[r];
        t[q] = s;
    }
    for (r = 0; r < u; r++) z[U->rowperm[r]] = t[r];
}

/* Full refactorization of A in position order. */
static amps_status amps__lu_full(amps_update *U, amps_int *bad) {
    amps_int q;
    for (q = 0; q < U->u; q++) { U->colorder[q] = q; U->rowperm[q] = q; }
    U->st.lu_full++;
    U->st.lu_cols = U->u;
    return amps__lu_extend(U, 0, 0, bad);
}

/* ---- Delta rows ---- */

/* Moves rows to the front of the pool in position order, dropping holes. */
static void amps__delta_compact(amps_update *U) {
    amps_int a, used = 0, *order = U->iwork, k;
    /* rows sorted by their start so that moving towards the front never overwrites */
    for (a = 0; a < U->u; a++) order[a] = a;
    for (a = 1; a < U->u; a++) {
        amps_int v = order[a], b = a - 1;
        while (b >= 0 && U->dst[order[b]] > U->dst[v]) { order[b + 1] = order[b]; b--; }
        order[b + 1] = v;
    }
    for (k = 0; k < U->u; k++) {
        a = order[k];
        if (U->dcp[a] == 0) continue;
        memmove(U->dcol + used, U->dcol + U->dst[a], sizeof(amps_int) * (size_t)U->dln[a]);
        memmove(U->dval + used, U->dval + U->dst[a], sizeof(double) * (size_t)U->dln[a]);
        U->dst[a] = used;
        U->dcp[a] = U->dln[a];
        used += U->dln[a];
    }
    U->dused = used;
}

/* Delta(a, b) += v; row a has been relocated with room for its additions this commit. */
static void amps__delta_add(amps_update *U, amps_int a, amps_int b, double v) {
    amps_int k, st = U->dst[a];
    for (k = 0; k < U->dln[a]; k++) if (U->dcol[st + k] == b) { U->dval[st + k] += v; return; }
    AMPS_ASSERT(U->dln[a] < U->dcp[a]);
    U->dcol[st + U->dln[a]] = b; U->dval[st + U->dln[a]] = v; U->dln[a]++;
}

/* Undo a failed commit: drop new positions, restore Delta rows, kinds and values, refactor. */
static void amps__rollback(amps_update *U, amps_int u_old, size_t vused_old, amps_int dused_old) {
    amps_int a, k, bad;
    for (a = u_old; a < U->u; a++) U->upos[U->uidx[a]] = -1;
    for (k = U->ndj - 1; k >= 0; k--) {
        amps__djour *d = U->dj + k;
        if (d->a < u_old) { U->dst[d->a] = d->st; U->dln[d->a] = d->ln; U->dcp[d->a] = d->cp; }
    }
    for (k = U->nkj - 1; k >= 0; k--)
        if (U->kj[k].a < u_old) { U->ukind[U->kj[k].a] = U->kj[k].kind; U->g[U->kj[k].a] = U->kj[k].g; }
    U->u = u_old; U->vused = vused_old; U->dused = dused_old;
    U->ndj = 0; U->nkj = 0;
    U->npd = 0; U->npc = 0; U->kpend = 0;
    if (U->u > 0) (void)amps__lu_full(U, &bad);   /* the old system was regular */
    U->dirty = 1;
}

AMPS_API void amps_update_discard(amps_update *U) {
    if (!U) return;
    U->npd = 0; U->npc = 0; U->kpend = 0;
}

AMPS_API amps_status amps_update_commit(amps_ctx *ctx, amps_update *U) {
    amps_int u_old, k, a, nnew = 0, q0, bad = -1, touched = 0;
    size_t vused_old, vneed = 0;
    amps_int dused_old;
    amps_status s;
    double t0, t1;
    if (!U) return amps__err(ctx, AMPS_ERR_ARG, "amps_update_commit: NULL engine");
    if (!U->npd && !U->npc && !U->kpend) return AMPS_OK;
    t0 = amps__now();
    u_old = U->u; vused_old = U->vused; dused_old = U->dused;
    U->ndj = 0; U->nkj = 0;
    /* 1. new members of U: ends of recorded changes and newly constrained indices */
    amps_marker_next(&U->mkN);
    for (k = 0; k < U->npd; k++) {
        amps_int e[2], t;
        e[0] = U->pd[k].r; e[1] = U->pd[k].c;
        for (t = 0; t < 2; t++) {
            amps_int i = e[t];
            if ((i >= U->N || U->upos[i] < 0) && U->mkN.mark[i] != U->mkN.stamp) { U->mkN.mark[i] = U->mkN.stamp; nnew++; }
        }
    }
    for (k = 0; k < U->npc; k++) {
        amps_int i = U->pc[k].i;
        if (!U->pc[k].release && (i >= U->N || U->upos[i] < 0) && U->mkN.mark[i] != U->mkN.stamp) { U->mkN.mark[i] = U->mkN.stamp; nnew++; }
    }
    if ((s = amps__need_u(ctx, U, nnew)) != AMPS_OK) goto fail_nochange;
    /* assign positions in order of first appearance */
    amps_marker_next(&U->mkN);
    for (k = 0; k < U->npd + U->npc; k++) {
        amps_int e[2], t, ne;
        if (k < U->npd) { e[0] = U->pd[k].r; e[1] = U->pd[k].c; ne = 2; }
        else { if (U->pc[k - U->npd].release) continue; e[0] = U->pc[k - U->npd].i; ne = 1; }
        for (t = 0; t < ne; t++) {
            amps_int i = e[t];
            if (U->upos[i] >= 0 && U->upos[i] < U->u && U->uidx[U->upos[i]] == i) continue;
            a = U->u++;
            U->upos[i] = a; U->uidx[a] = i; U->ukind[a] = 0; U->g[a] = 0;
            U->dst[a] = 0; U->dln[a] = 0; U->dcp[a] = 0; U->vlen[a] = 0; U->voff[a] = 0;
            if (i < U->n) vneed += (size_t)amps__path_len(U->F, U->F->iperm[i]);
        }
    }
    if (U->vused + vneed > U->vcap) {
        size_t cap = U->vcap;
        if (!U->grow) {
            s = amps__err(ctx, AMPS_ERR_CAPACITY, "amps_update: memoized columns need %.0f entries, cap_vpool is %.0f (raise it or set grow)",
                          (double)(U->vused + vneed), (double)U->vcap);
            goto fail;
        }
        while (cap < U->vused + vneed) cap = cap * 2 + 1024;
        if (amps__realloc(ctx, (void **)&U->vval, cap, sizeof(double)) || amps__realloc(ctx, (void **)&U->vidx, cap, sizeof(amps_int))) { s = AMPS_ERR_OOM; goto fail; }
        U->vcap = cap;
    }
    /* Step 1: W columns of the new base positions, in batches over the union of their paths */
    {
        amps_int nb = 0, *list = U->iwork;
        for (a = u_old; a < U->u; a++)
            if (U->uidx[a] < U->n) {
                U->voff[a] = U->vused;
                U->vlen[a] = amps__path_len(U->F, U->F->iperm[U->uidx[a]]);
                U->vused += (size_t)U->vlen[a];
                list[nb++] = a;
            }
        amps__wcols(U, list, nb);
    }
    t1 = amps__now(); U->st.t_step[1] = t1 - t0; t0 = t1;
    /* Step 2: trapezoidal augmentation of G (Eq. 3.25-3.27), both triangles stored */
    if (U->u > u_old) {
        amps_int b, u = U->u;
        size_t ld = (size_t)U->capu;
#ifdef _OPENMP
#pragma omp parallel for schedule(dynamic, 8) num_threads(U->nthr) if ((double)u * (u - u_old) > 4096)
#endif
        for (b = 0; b < u; b++) {
            amps_int aa;
            for (aa = (b > u_old ? b : u_old); aa < u; aa++) {
                double gv = amps__gentry(U, aa, b);
                U->G[(size_t)b * ld + (size_t)aa] = gv;
                U->G[(size_t)aa * ld + (size_t)b] = gv;
            }
        }
    }
    t1 = amps__now(); U->st.t_step[2] = t1 - t0; t0 = t1;
    /* Delta: relocate every touched row to the end of the pool with room for its additions
       (old locations stay intact, so a rollback only restores headers) */
    U->rstamp++;
    if (U->rstamp == 0x7fffffff) { for (a = 0; a < U->capu; a++) U->rst[a] = 0; U->rstamp = 1; }
    for (k = 0; k < U->npd; k++) {
        amps_int ra = U->upos[U->pd[k].r], rb = U->upos[U->pd[k].c], t, e[2];
        e[0] = ra; e[1] = rb;
        for (t = 0; t < (ra == rb ? 1 : 2); t++) {
            if (U->rst[e[t]] != U->rstamp) { U->rst[e[t]] = U->rstamp; U->rcnt[e[t]] = 0; touched++; }
            U->rcnt[e[t]]++;
        }
    }
    {
        amps_int need = 0;
        for (a = 0; a < U->u; a++) if (U->rst[a] == U->rstamp) need += U->dln[a] + U->rcnt[a];
        if (U->dused + need > U->dcap) {
            amps__delta_compact(U);
            dused_old = U->dused;
        }
        if (U->dused + need > U->dcap) {
            amps_int cap = U->dcap;
            if (!U->grow) {
                s = amps__err(ctx, AMPS_ERR_CAPACITY, "amps_update: %ld stored changes exceed cap_delta = %ld (raise it or set grow)", (long)(U->dused + need), (long)U->dcap);
                goto fail;
            }
            while (cap < U->dused + need) cap = cap * 2 + 256;
            if (amps__realloc(ctx, (void **)&U->dcol, (size_t)cap, sizeof(amps_int)) || amps__realloc(ctx, (void **)&U->dval, (size_t)cap, sizeof(double))) { s = AMPS_ERR_OOM; goto fail; }
            U->dcap = cap;
        }
        for (a = 0; a < U->u; a++)
            if (U->rst[a] == U->rstamp) {
                amps__djour *d = U->dj + U->ndj++;
                d->a = a; d->st = U->dst[a]; d->ln = U->dln[a]; d->cp = U->dcp[a];
                memcpy(U->dcol + U->dused, U->dcol + U->dst[a], sizeof(amps_int) * (size_t)U->dln[a]);
                memcpy(U->dval + U->dused, U->dval + U->dst[a], sizeof(double) * (size_t)U->dln[a]);
                U->dst[a] = U->dused; U->dcp[a] = U->dln[a] + U->rcnt[a];
                U->dused += U->dcp[a];
            }
    }
    /* apply the changes; every touched row's column changes */
    U->stamp++;
    if (U->stamp == 0x7fffffff) { for (a = 0; a < U->capu; a++) U->cstamp[a] = 0; U->stamp = 1; }
    for (k = 0; k < U->npd; k++) {
        amps_int ra = U->upos[U->pd[k].r], rb = U->upos[U->pd[k].c];
        amps__delta_add(U, ra, rb, U->pd[k].v);
        if (ra != rb) amps__delta_add(U, rb, ra, U->pd[k].v);
        U->cstamp[ra] = U->stamp; U->cstamp[rb] = U->stamp;
    }
    for (a = u_old; a < U->u; a++) U->cstamp[a] = U->stamp;
    /* constraints: a change of kind changes the column and the columns of Delta-neighbours */
    for (k = 0; k < U->npc; k++) {
        amps_int i = U->pc[k].i;
        amps__kjour *j;
        a = (i < U->N + U->kpend && U->upos[i] >= 0) ? U->upos[i] : -1;
        if (a < 0) continue;                      /* release of an unconstrained index */
        if (U->pc[k].release && !(U->ukind[a] & AMPS__UCON)) continue;
        j = U->kj + U->nkj++;
        j->a = a; j->kind = U->ukind[a]; j->g = U->g[a];
        if (U->pc[k].release) U->ukind[a] &= (unsigned char)~AMPS__UCON;
        else { U->ukind[a] |= AMPS__UCON; U->g[a] = U->pc[k].v; }
        if ((j->kind ^ U->ukind[a]) & AMPS__UCON) {
            amps_int t;
            U->cstamp[a] = U->stamp;
            for (t = 0; t < U->dln[a]; t++) U->cstamp[U->dcol[U->dst[a] + t]] = U->stamp;
        }
    }
    /* Steps 3 and 5: refactor from the first changed column; the changed ones go last */
    q0 = u_old;
    for (a = 0; a < u_old; a++) if (U->cstamp[a] == U->stamp && U->colpos[a] < q0) q0 = U->colpos[a];
    {
        amps_int q, m = q0;
        for (q = q0; q < u_old; q++) if (U->cstamp[U->colorder[q]] != U->stamp) U->iwork[m++] = U->colorder[q];
        for (q = q0; q < u_old; q++) if (U->cstamp[U->colorder[q]] == U->stamp) U->iwork[m++] = U->colorder[q];
        for (q = q0; q < u_old; q++) U->colorder[q] = U->iwork[q];
        for (a = u_old; a < U->u; a++) { U->colorder[a] = a; U->rowperm[a] = a; }
    }
    t1 = amps__now(); U->st.t_step[3] = t1 - t0; t0 = t1;
    U->st.lu_cols = U->u - q0;
    s = amps__lu_extend(U, q0, u_old, &bad);
    if (s == AMPS_ERR_CAPACITY) s = amps__lu_full(U, &bad);     /* multipliers grew: refactor */
    t1 = amps__now(); U->st.t_step[5] = t1 - t0;
    if (s != AMPS_OK) {
        amps_int bi = bad >= 0 ? U->uidx[bad] : -1;
        amps__rollback(U, u_old, vused_old, dused_old);
        return amps__err(ctx, AMPS_ERR_SINGULAR_UPDATE,
                         "amps_update_commit: the updated system is singular (pivot of index %ld below %g of its column); the changes were discarded",
                         (long)bi, U->tol);
    }
    U->N += U->kpend; U->kpend = 0;
    U->npd = 0; U->npc = 0;
    U->dirty = 1;
    U->st.ncommit++;
    (void)touched;
    return AMPS_OK;
fail:
    amps__rollback(U, u_old, vused_old, dused_old);
    return s;
fail_nochange:
    U->npd = 0; U->npc = 0; U->kpend = 0;
    return s;
}

/* ---- Steps 4 and 6 ---- */

/* Brings ct = D^{-1/2} L^{-1} P^T f up to date: the changed base forces go through one sparse
   forward solve over their closure; after many increments (or a long list) a full solve. */
static void amps__update_ct(amps_update *U) {
    const amps_factor *F = U->F;
    amps_int n = U->n, k, nb = 0, *list = U->iwork, *clo = U->iwork + n;
    double *x = U->work;
    if (U->npf == 0 && !U->pf_all) return;
    if (U->pf_all || U->nct_inc >= 1024 || U->npf > n / 8) {
        for (k = 0; k < n; k++) x[k] = U->f[F->perm[k]];
        amps_lsolve(F, x);
        for (k = 0; k < n; k++) { U->ct[k] = x[k] * U->isd[k]; x[k] = 0; }
        memcpy(U->fct, U->f, sizeof(double) * (size_t)n);
        U->nct_inc = 0;
    } else {
        amps_int ncl;
        amps_marker_next(&U->mk);
        for (k = 0; k < U->npf; k++) {
            amps_int i = U->pf[k], p = F->iperm[i];
            double d = U->f[i] - U->fct[i];
            U->fct[i] = U->f[i];
            if (d == 0.0) continue;
            x[p] += d;
            if (U->mk.mark[p] != U->mk.stamp) { U->mk.mark[p] = U->mk.stamp; list[nb++] = p; }
        }
        if (nb > 0) {
            ncl = amps_lsolve_sparse(F, nb, list, x, clo, &U->mk);
            for (k = 0; k < ncl; k++) { amps_int j = clo[k]; U->ct[j] += x[j] * U->isd[j]; x[j] = 0; }
            U->nct_inc++;
        }
    }
    U->npf = 0; U->pf_all = 0;
}

/* Step 5: the forces w of the augmentation (and y = x_U, primal form) for right-hand side
   r = H^T K-bar^{-1} f and prescribed values g on C (hom: g = 0). */
static void amps__dense_step(amps_update *U, const double *r, int hom, double *yv, double *wv) {
    amps_int u = U->u, a, k;
    size_t ld = (size_t)U->capu;
    double *z = U->z, *b = U->sb, *d = U->tmp;
#define AMPS__G(a) (hom ? 0.0 : U->g[a])
    if (U->form == AMPS_FORM_PRIMAL) {
        /* b = r - G d - g^, d = Delta[F', C] g; z = A^{-1} b; y = (z_F', g); w = (Delta_F' y, z_C) */
        for (a = 0; a < u; a++) b[a] = r[a] - ((U->ukind[a] & AMPS__UCON) ? AMPS__G(a) : 0.0);
        if (!hom) {
            for (a = 0; a < u; a++) {
                double sum = 0;
                if (!(U->ukind[a] & AMPS__UCON))
                    for (k = 0; k < U->dln[a]; k++) {
                        amps_int bb = U->dcol[U->dst[a] + k];
                        if (U->ukind[bb] & AMPS__UCON) sum += U->dval[U->dst[a] + k] * U->g[bb];
                    }
                d[a] = sum;
            }
            for (k = 0; k < u; k++)
                if (d[k] != 0.0) {
                    const double *gk = U->G + (size_t)k * ld;
                    for (a = 0; a < u; a++) b[a] -= gk[a] * d[k];
                }
        }
        amps__lu_solve(U, b, z, U->tmp);
        for (a = 0; a < u; a++) yv[a] = (U->ukind[a] & AMPS__UCON) ? AMPS__G(a) : z[a];
        for (a = 0; a < u; a++) {
            double sum = 0;
            if (U->ukind[a] & AMPS__UCON) { wv[a] = z[a]; continue; }
            for (k = 0; k < U->dln[a]; k++) sum += U->dval[U->dst[a] + k] * yv[U->dcol[U->dst[a] + k]];
            wv[a] = sum;
        }
    } else {
        /* b'_F' = Delta[F', :] r^ (r^ = r on F', g on C), b'_C = r_C - g; w = A^{-T} b' */
        double *rh = yv;
        for (a = 0; a < u; a++) rh[a] = (U->ukind[a] & AMPS__UCON) ? AMPS__G(a) : r[a];
        for (a = 0; a < u; a++) {
            double sum = 0;
            if (U->ukind[a] & AMPS__UCON) { b[a] = r[a] - AMPS__G(a); continue; }
            for (k = 0; k < U->dln[a]; k++) sum += U->dval[U->dst[a] + k] * rh[U->dcol[U->dst[a] + k]];
            b[a] = sum;
        }
        amps__lu_solve_t(U, b, wv, U->tmp);
        for (a = 0; a < u; a++) yv[a] = (U->ukind[a] & AMPS__UCON) ? AMPS__G(a) : 0.0;
    }
#undef AMPS__G
}

/* sv -= D^{-1/2} sum_a c_a W_a (permuted n-vector; appended DOFs have no W). */
static void amps__scatter_w(const amps_update *U, const double *c, double *sv) {
    amps_int a, t;
    for (a = 0; a < U->u; a++) {
        const double *w = U->vval + U->voff[a];
        const amps_int *wi = U->vidx + U->voff[a];
        double ca = c[a];
        if (U->uidx[a] >= U->n || ca == 0.0) continue;
        for (t = 0; t < U->vlen[a]; t++) sv[wi[t]] -= ca * w[t] * U->isd[wi[t]];
    }
}

/* (K^ v)_i for the committed K^, reading v[j] for the neighbours j of i only. */
static double amps__krow(const amps_update *U, amps_int i, const double *v) {
    amps_int p, a = U->upos[i], k;
    double s = 0;
    if (i < U->n) for (p = U->Kp[i]; p < U->Kp[i + 1]; p++) s += U->Kx[p] * v[U->Ki[p]];
    else s = U->sigma * v[i];
    if (a >= 0) for (k = 0; k < U->dln[a]; k++) s += U->dval[U->dst[a] + k] * v[U->uidx[U->dcol[U->dst[a] + k]]];
    return s;
}

/* Refinement: x~ = K-bar^{-1}(f - H w) on U and its neighbours by a partial backward solve of
   sv (a copy), rho = (f - K^ x~) on the free rows of U, and the correction problem K^ d = H rho
   (d_C = 0) gives wd; afterwards the full solve uses w + wd - rho. x~ is gathered into U->x. */
static void amps__refine(amps_update *U, const double *sv, const double *wv) {
    const amps_factor *F = U->F;
    amps_int u = U->u, n = U->n, a, k, p, nreq = 0, *req = U->iwork, *clo = U->iwork + n, ncl;
    double *s2 = U->work2;
    size_t ld = (size_t)U->capu;
    amps_marker_next(&U->mk);
    for (a = 0; a < u; a++) {
        amps_int i = U->uidx[a];
        if (i >= n) continue;
        for (p = U->Kp[i]; p < U->Kp[i + 1]; p++) {
            amps_int q = F->iperm[U->Ki[p]];
            if (U->mk.mark[q] != U->mk.stamp) { U->mk.mark[q] = U->mk.stamp; req[nreq++] = q; }
        }
        {
            amps_int q = F->iperm[i];
            if (U->mk.mark[q] != U->mk.stamp) { U->mk.mark[q] = U->mk.stamp; req[nreq++] = q; }
        }
    }
    memcpy(s2, sv, sizeof(double) * (size_t)n);
    ncl = amps_ltsolve_partial(F, nreq, req, s2, clo, &U->mk);
    for (k = 0; k < ncl; k++) U->x[F->perm[clo[k]]] = s2[clo[k]];
    for (k = n; k < U->N; k++) { a = U->upos[k]; U->x[k] = (U->f[k] - (a >= 0 ? wv[a] : 0.0)) / U->sigma; }
    for (a = 0; a < u; a++) if (U->ukind[a] & AMPS__UCON) U->x[U->uidx[a]] = U->g[a];
    for (a = 0; a < u; a++) {
        amps_int i = U->uidx[a];
        U->rho[a] = (U->ukind[a] & AMPS__UCON) ? 0.0 : U->f[i] - amps__krow(U, i, U->x);
    }
    /* r_d = G rho */
    for (a = 0; a < u; a++) U->rd[a] = 0;
    for (k = 0; k < u; k++)
        if (U->rho[k] != 0.0) {
            const double *gk = U->G + (size_t)k * ld;
            for (a = 0; a < u; a++) U->rd[a] += gk[a] * U->rho[k];
        }
    amps__dense_step(U, U->rd, 1, U->yd, U->wd);
    for (a = 0; a < u; a++) U->wd[a] -= U->rho[a];
}

AMPS_API amps_status amps_update_solve(amps_ctx *ctx, amps_update *U, double *xout) {
    const amps_factor *F;
    amps_int u, a, k, n;
    double t0, t1, *r, *yv, *wv;
    amps_status s;
    if (!U) return amps__err(ctx, AMPS_ERR_ARG, "amps_update_solve: NULL engine");
    if ((s = amps_update_commit(ctx, U)) != AMPS_OK) return s;
    if (!U->dirty && U->has_sol) {
        if (xout) memcpy(xout, U->x, sizeof(double) * (size_t)U->N);
        return AMPS_OK;
    }
    F = U->F; n = U->n; u = U->u;
    r = U->rhs; yv = U->yv; wv = U->wv;
    t0 = amps__now();
    amps__update_ct(U);
    /* Step 4: r = H^T K-bar^{-1} f^ = W^T ct on base positions, f/sigma on appended ones */
#ifdef _OPENMP
#pragma omp parallel for schedule(dynamic, 16) num_threads(U->nthr) if (u > 64)
#endif
    for (a = 0; a < u; a++) {
        amps_int i = U->uidx[a], t;
        if (i < n) {
            const double *w = U->vval + U->voff[a];
            const amps_int *wi = U->vidx + U->voff[a];
            double sum = 0;
            for (t = 0; t < U->vlen[a]; t++) sum += w[t] * U->ct[wi[t]];
            r[a] = sum;
        } else r[a] = U->f[i] / U->sigma;
    }
    t1 = amps__now(); U->st.t_step[4] = t1 - t0; t0 = t1;
    /* Step 5 */
    amps__dense_step(U, r, 0, yv, wv);
    t1 = amps__now(); U->st.t_step[5] += t1 - t0; t0 = t1;
    /* Step 6: x = K-bar^{-1} (f^ - H w), permuted: L^{-T} D^{-1/2} (ct - sum_a w_a W_a) */
    {
        double *sv = U->work;
        for (k = 0; k < n; k++) sv[k] = U->ct[k] * U->isd[k];
        amps__scatter_w(U, wv, sv);
        if (u > 0) {
            int it;
            for (it = 0; it < U->refine; it++) {
                amps__refine(U, sv, wv);
                amps__scatter_w(U, U->wd, sv);
                for (a = 0; a < u; a++) { wv[a] += U->wd[a]; yv[a] += U->yd[a]; }
            }
        }
        amps_ltsolve(F, sv);
        for (k = 0; k < n; k++) { U->x[F->perm[k]] = sv[k]; sv[k] = 0.0; }
        for (k = n; k < U->N; k++) {
            a = U->upos[k];
            U->x[k] = (U->f[k] - (a >= 0 ? wv[a] : 0.0)) / U->sigma;
        }
        for (a = 0; a < u; a++)
            if ((U->ukind[a] & AMPS__UCON) || (U->eq320 && U->form == AMPS_FORM_PRIMAL)) U->x[U->uidx[a]] = yv[a];
    }
    /* reactions (K^ x - f^)_C */
    for (a = 0; a < u; a++) {
        amps_int i = U->uidx[a];
        U->react[a] = (U->ukind[a] & AMPS__UCON) ? amps__krow(U, i, U->x) - U->f[i] : 0.0;
    }
    t1 = amps__now(); U->st.t_step[6] = t1 - t0;
    U->dirty = 0; U->has_sol = 1; U->solN = U->N;
    U->st.nsolve++;
    if (xout) memcpy(xout, U->x, sizeof(double) * (size_t)U->N);
    return AMPS_OK;
}

AMPS_API const double *amps_update_solution(const amps_update *U) { return U ? U->x : NULL; }

AMPS_API double amps_update_reaction(const amps_update *U, amps_int i) {
    amps_int a;
    if (!U || i < 0 || i >= U->N || !U->has_sol) return 0.0;
    a = U->upos[i];
    return (a >= 0 && (U->ukind[a] & AMPS__UCON)) ? U->react[a] : 0.0;
}

/* y = K^ v for the committed K^ (v and y of length N). */
static void amps__kmul(const amps_update *U, const double *v, double *y) {
    amps_int n = U->n, j, p, a, k;
    for (j = 0; j < n; j++) {
        double s = 0;
        for (p = U->Kp[j]; p < U->Kp[j + 1]; p++) s += U->Kx[p] * v[U->Ki[p]];
        y[j] = s;
    }
    for (j = n; j < U->N; j++) y[j] = U->sigma * v[j];
    for (a = 0; a < U->u; a++) {
        double s = 0;
        for (k = 0; k < U->dln[a]; k++) s += U->dval[U->dst[a] + k] * v[U->uidx[U->dcol[U->dst[a] + k]]];
        y[U->uidx[a]] += s;
    }
}

AMPS_API amps_status amps_update_residual(amps_ctx *ctx, amps_update *U, double *relres) {
    double *y, *gh, num = 0, den = 0;
    amps_int i, a, N;
    if (!U || !relres) return amps__err(ctx, AMPS_ERR_ARG, "amps_update_residual: NULL argument");
    if (!U->has_sol || U->dirty || U->npd || U->npc || U->kpend)
        return amps__err(ctx, AMPS_ERR_STATE, "amps_update_residual: no current solution (call amps_update_solve)");
    N = U->N; y = U->rv; gh = U->rv + U->capN;
    /* numerator: (K^ x - f^) on free rows */
    amps__kmul(U, U->x, y);
    for (i = 0; i < N; i++) {
        a = U->upos[i];
        if (a >= 0 && (U->ukind[a] & AMPS__UCON)) continue;
        num += (y[i] - U->f[i]) * (y[i] - U->f[i]);
    }
    /* denominator: f^_F - K^_FC g, the right-hand side of the reduced system */
    for (i = 0; i < N; i++) gh[i] = 0;
    for (a = 0; a < U->u; a++) if (U->ukind[a] & AMPS__UCON) gh[U->uidx[a]] = U->g[a];
    amps__kmul(U, gh, y);
    for (i = 0; i < N; i++) {
        a = U->upos[i];
        if (a >= 0 && (U->ukind[a] & AMPS__UCON)) continue;
        den += (U->f[i] - y[i]) * (U->f[i] - y[i]);
    }
    *relres = den > 0 ? sqrt(num / den) : sqrt(num);
    return AMPS_OK;
}

AMPS_API void amps_update_get_stats(const amps_update *U, amps_update_stats *st) {
    amps_int a, nm = 0, nc = 0;
    if (!U || !st) return;
    *st = U->st;
    for (a = 0; a < U->u; a++) {
        if (U->dln[a] > 0) nm++;
        if (U->ukind[a] & AMPS__UCON) nc++;
    }
    st->dim = U->N; st->nmod = nm; st->ncon = nc; st->nsys = U->u;
    st->vpool_entries = (double)U->vused;
}

/* ================================ FEM scene impl ================================ */
#ifndef AMPS_NO_FEM
/* @@SECTION fem: owned by fem */
#endif /* AMPS_NO_FEM */

/* ==================================== I/O impl ==================================== */
#if !defined(AMPS_NO_FEM) && !defined(AMPS_NO_STDIO)
/* @@SECTION io: owned by fem */
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
