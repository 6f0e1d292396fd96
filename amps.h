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
   opts may be NULL (AMPS_ORDER_AUTO, block detection). With AMPS_FULL only entries with row <= column
   are read (A is taken as symmetric). Also builds the pattern Li and the scatter map of A into L, and
   the workspace of amps_factorize for ctx->nthreads threads (0: the OpenMP default). */
AMPS_API amps_factor *amps_analyze(amps_ctx *ctx, const amps_csc *A, amps_stype stype, const amps_order_opts *opts);
/* Numeric LDL^T of A, which must have the pattern given to amps_analyze (values may differ).
   A pivot must be finite and exceed AMPS_PIVOT_TOL (default 1e-12) times the column's diagonal entry
   of A, else AMPS_ERR_NOT_SPD names the failing column in the original numbering; F is then not
   numeric. Uses ctx->nthreads OpenMP threads (at most the count at amps_analyze); the result does
   not depend on the thread count. Allocates nothing. */
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
/* Solves K X = B for nrhs right-hand sides: columns of B (leading dimension ldb >= n) into X
   (ldx >= n; X may equal B), original numbering. Blocks of 4 columns run in parallel on OpenMP
   threads (ctx->nthreads, else the OpenMP default). work: amps_solve_multi_work(ctx, F, nrhs)
   doubles (4n per thread used; query it with the same ctx settings). Allocates nothing. */
AMPS_API amps_status amps_solve_multi(amps_ctx *ctx, const amps_factor *F, amps_int nrhs, const double *B, amps_int ldb,
                                      double *X, amps_int ldx, double *work);
AMPS_API size_t amps_solve_multi_work(const amps_ctx *ctx, const amps_factor *F, amps_int nrhs);
#ifdef AMPS_COUNT_TOUCH
/* Instrumentation (define AMPS_COUNT_TOUCH before including): L entries read by amps_lsolve_sparse and
   amps_ltsolve_partial on F since the last reset. */
AMPS_API double amps_touch_count(const amps_factor *F);
AMPS_API void amps_touch_reset(const amps_factor *F);
#endif

/* ============================ augmented updates ============================ */
/* @@API update: owned by engine */

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

/* Largest value of amps_int. */
#define AMPS__IMAX ((amps_int)((((unsigned long long)1) << (sizeof(amps_int) * 8 - 1)) - 1))

AMPS_API amps_csc *amps_csc_alloc(amps_ctx *ctx, amps_int nrow, amps_int ncol, amps_int nzmax, int with_values) {
    amps_csc *A;
    if (nrow < 0 || ncol < 0 || nzmax < 0) {
        amps__err(ctx, AMPS_ERR_ARG, "amps_csc_alloc: negative size (nrow %lld, ncol %lld, nzmax %lld)",
                  (long long)nrow, (long long)ncol, (long long)nzmax);
        return NULL;
    }
    A = AMPS__CAST(amps_csc *, amps__calloc(ctx, 1, sizeof(amps_csc)));
    if (!A) return NULL;
    A->nrow = nrow;
    A->ncol = ncol;
    A->p = AMPS__CAST(amps_int *, amps__calloc(ctx, (size_t)ncol + 1, sizeof(amps_int)));
    A->i = A->p ? AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)nzmax, sizeof(amps_int))) : NULL;
    A->x = (A->i && with_values) ? AMPS__CAST(double *, amps__malloc(ctx, (size_t)nzmax, sizeof(double))) : NULL;
    if (!A->p || !A->i || (with_values && !A->x)) {
        amps_csc_free(ctx, A);
        amps__err(ctx, AMPS_ERR_OOM, "amps_csc_alloc: out of memory (%lld x %lld, nzmax %lld)",
                  (long long)nrow, (long long)ncol, (long long)nzmax);
        return NULL;
    }
    return A;
}

AMPS_API void amps_csc_free(amps_ctx *ctx, amps_csc *A) {
    if (!A) return;
    amps__free(ctx, A->p);
    amps__free(ctx, A->i);
    amps__free(ctx, A->x);
    amps__free(ctx, A);
}

AMPS_API amps_status amps_csc_check(amps_ctx *ctx, const amps_csc *A, amps_stype stype) {
    amps_int n, j, p;
    if (!A) return amps__err(ctx, AMPS_ERR_ARG, "amps_csc_check: matrix is NULL");
    if (stype != AMPS_LOWER && stype != AMPS_FULL && stype != AMPS_UPPER)
        return amps__err(ctx, AMPS_ERR_ARG, "amps_csc_check: invalid stype %d", (int)stype);
    if (A->nrow < 0 || A->ncol < 0)
        return amps__err(ctx, AMPS_ERR_ARG, "amps_csc_check: negative dimension %lld x %lld", (long long)A->nrow,
                         (long long)A->ncol);
    if (A->nrow != A->ncol)
        return amps__err(ctx, AMPS_ERR_ARG, "amps_csc_check: matrix is %lld x %lld, not square", (long long)A->nrow,
                         (long long)A->ncol);
    n = A->ncol;
    if (!A->p) return amps__err(ctx, AMPS_ERR_ARG, "amps_csc_check: column pointer array is NULL");
    if (A->p[0] != 0) return amps__err(ctx, AMPS_ERR_PATTERN, "amps_csc_check: p[0] = %lld, must be 0", (long long)A->p[0]);
    for (j = 0; j < n; j++)
        if (A->p[j + 1] < A->p[j])
            return amps__err(ctx, AMPS_ERR_PATTERN, "amps_csc_check: column %lld: p[%lld] = %lld < p[%lld] = %lld",
                             (long long)j, (long long)(j + 1), (long long)A->p[j + 1], (long long)j, (long long)A->p[j]);
    if (A->p[n] > 0 && !A->i) return amps__err(ctx, AMPS_ERR_ARG, "amps_csc_check: row index array is NULL");
    for (j = 0; j < n; j++) {
        for (p = A->p[j]; p < A->p[j + 1]; p++) {
            amps_int i = A->i[p];
            if (i < 0 || i >= n)
                return amps__err(ctx, AMPS_ERR_INDEX, "amps_csc_check: column %lld: row %lld out of range [0,%lld)",
                                 (long long)j, (long long)i, (long long)n);
            if (p > A->p[j] && i <= A->i[p - 1])
                return amps__err(ctx, AMPS_ERR_PATTERN, "amps_csc_check: column %lld: row %lld %s row %lld",
                                 (long long)j, (long long)i, i == A->i[p - 1] ? "duplicates" : "is not above previous",
                                 (long long)A->i[p - 1]);
            if ((stype == AMPS_UPPER && i > j) || (stype == AMPS_LOWER && i < j))
                return amps__err(ctx, AMPS_ERR_PATTERN, "amps_csc_check: column %lld: row %lld is outside the %s triangle",
                                 (long long)j, (long long)i, stype == AMPS_UPPER ? "upper" : "lower");
            if (A->x && !amps__isfinite(A->x[p]))
                return amps__err(ctx, AMPS_ERR_VALUE, "amps_csc_check: column %lld: row %lld: non-finite value",
                                 (long long)j, (long long)i);
        }
    }
    return AMPS_OK;
}

AMPS_API amps_csc *amps_csc_from_triplets(amps_ctx *ctx, amps_int n, amps_int nz, const amps_int *ti,
                                          const amps_int *tj, const double *tx, amps_stype stype) {
    amps_int k, m = 0, j, r, p, q, nnz;
    amps_int *Tp = NULL, *Tj = NULL, *Cp = NULL, *Ci = NULL, *w = NULL;
    double *Tx = NULL, *Cx = NULL;
    amps_csc *A = NULL;
    if (n < 0 || nz < 0) {
        amps__err(ctx, AMPS_ERR_ARG, "amps_csc_from_triplets: negative size (n %lld, nz %lld)", (long long)n, (long long)nz);
        return NULL;
    }
    if (stype != AMPS_LOWER && stype != AMPS_FULL && stype != AMPS_UPPER) {
        amps__err(ctx, AMPS_ERR_ARG, "amps_csc_from_triplets: invalid stype %d", (int)stype);
        return NULL;
    }
    if (nz > 0 && (!ti || !tj || !tx)) {
        amps__err(ctx, AMPS_ERR_ARG, "amps_csc_from_triplets: NULL triplet array");
        return NULL;
    }
    for (k = 0; k < nz; k++) {
        if (ti[k] < 0 || ti[k] >= n || tj[k] < 0 || tj[k] >= n) {
            amps__err(ctx, AMPS_ERR_INDEX, "amps_csc_from_triplets: triplet %lld: (row %lld, column %lld) out of range [0,%lld)",
                      (long long)k, (long long)ti[k], (long long)tj[k], (long long)n);
            return NULL;
        }
        if (!amps__isfinite(tx[k])) {
            amps__err(ctx, AMPS_ERR_VALUE, "amps_csc_from_triplets: triplet %lld: (row %lld, column %lld) non-finite value",
                      (long long)k, (long long)ti[k], (long long)tj[k]);
            return NULL;
        }
        m += (stype == AMPS_FULL && ti[k] != tj[k]) ? 2 : 1;
        if (m < 0 || m > AMPS__IMAX / 2) {
            amps__err(ctx, AMPS_ERR_ARG, "amps_csc_from_triplets: too many entries for the index type");
            return NULL;
        }
    }
    /* bucket by row, then by column (stable): columns come out with ascending rows */
    Tp = AMPS__CAST(amps_int *, amps__calloc(ctx, (size_t)n + 1, sizeof(amps_int)));
    Cp = AMPS__CAST(amps_int *, amps__calloc(ctx, (size_t)n + 1, sizeof(amps_int)));
    w = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)n + 1, sizeof(amps_int)));
    Tj = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)m, sizeof(amps_int)));
    Tx = AMPS__CAST(double *, amps__malloc(ctx, (size_t)m, sizeof(double)));
    Ci = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)m, sizeof(amps_int)));
    Cx = AMPS__CAST(double *, amps__malloc(ctx, (size_t)m, sizeof(double)));
    if (!Tp || !Cp || !w || !Tj || !Tx || !Ci || !Cx) {
        amps__err(ctx, AMPS_ERR_OOM, "amps_csc_from_triplets: out of memory (n %lld, nz %lld)", (long long)n, (long long)nz);
        goto done;
    }
    for (k = 0; k < nz; k++) {
        amps_int a = ti[k], b = tj[k], lo = a < b ? a : b, hi = a < b ? b : a;
        if (stype == AMPS_UPPER) Tp[lo]++;
        else if (stype == AMPS_LOWER) Tp[hi]++;
        else { Tp[a]++; if (a != b) Tp[b]++; }
    }
    for (r = 0, p = 0; r < n; r++) { q = Tp[r]; Tp[r] = p; w[r] = p; p += q; }
    Tp[n] = p;
    for (k = 0; k < nz; k++) {
        amps_int a = ti[k], b = tj[k], lo = a < b ? a : b, hi = a < b ? b : a;
        if (stype == AMPS_UPPER) { q = w[lo]++; Tj[q] = hi; Tx[q] = tx[k]; }
        else if (stype == AMPS_LOWER) { q = w[hi]++; Tj[q] = lo; Tx[q] = tx[k]; }
        else {
            q = w[a]++; Tj[q] = b; Tx[q] = tx[k];
            if (a != b) { q = w[b]++; Tj[q] = a; Tx[q] = tx[k]; }
        }
    }
    for (q = 0; q < m; q++) Cp[Tj[q]]++;
    for (j = 0, p = 0; j < n; j++) { q = Cp[j]; Cp[j] = p; w[j] = p; p += q; }
    Cp[n] = p;
    for (r = 0; r < n; r++)
        for (q = Tp[r]; q < Tp[r + 1]; q++) { p = w[Tj[q]]++; Ci[p] = r; Cx[p] = Tx[q]; }
    /* sum duplicates in place */
    for (j = 0, nnz = 0; j < n; j++) {
        amps_int start = nnz;
        for (q = Cp[j]; q < Cp[j + 1]; q++) {
            if (nnz > start && Ci[nnz - 1] == Ci[q]) Cx[nnz - 1] += Cx[q];
            else { Ci[nnz] = Ci[q]; Cx[nnz] = Cx[q]; nnz++; }
        }
        Cp[j] = start;
    }
    Cp[n] = nnz;
    /* hand the arrays over, shrunk to nnz */
    {
        void *ti2 = Ci, *tx2 = Cx;
        if (amps__realloc(ctx, &ti2, (size_t)nnz, sizeof(amps_int)) != AMPS_OK) goto done;
        Ci = AMPS__CAST(amps_int *, ti2);
        if (amps__realloc(ctx, &tx2, (size_t)nnz, sizeof(double)) != AMPS_OK) goto done;
        Cx = AMPS__CAST(double *, tx2);
    }
    A = AMPS__CAST(amps_csc *, amps__calloc(ctx, 1, sizeof(amps_csc)));
    if (!A) goto done;
    A->nrow = A->ncol = n;
    A->p = Cp; A->i = Ci; A->x = Cx;
    Cp = Ci = NULL;
    Cx = NULL;
done:
    amps__free(ctx, Tp); amps__free(ctx, Cp); amps__free(ctx, w); amps__free(ctx, Tj);
    amps__free(ctx, Tx); amps__free(ctx, Ci); amps__free(ctx, Cx);
    return A;
}

AMPS_API void amps_csc_symv(const amps_csc *A, amps_stype stype, const double *x, double *y) {
    amps_int j, p, n = A->ncol;
    for (j = 0; j < A->nrow; j++) y[j] = 0.0;
    for (j = 0; j < n; j++) {
        double xj = x[j], s = 0.0;
        for (p = A->p[j]; p < A->p[j + 1]; p++) {
            amps_int i = A->i[p];
            double a = A->x[p];
            y[i] += a * xj;
            if (stype != AMPS_FULL && i != j) s += a * x[i];
        }
        y[j] += s;
    }
}

/* ============================== ordering impl ============================== */
/* @@SECTION ordering: owned by ordering */

/* TEMP: replaced by the ordering section */
AMPS_API amps_status amps_amd(amps_ctx *ctx, amps_int n, const amps_int *Ap, const amps_int *Ai, amps_int *perm) {
    amps_int k;
    (void)ctx; (void)Ap; (void)Ai;
    for (k = 0; k < n; k++) perm[k] = k;
    return AMPS_OK;
}

/* TEMP: replaced by the ordering section */
AMPS_API amps_status amps_nd(amps_ctx *ctx, amps_int n, const amps_int *Ap, const amps_int *Ai, const double *xyz,
                             amps_int *perm) {
    (void)xyz;
    return amps_amd(ctx, n, Ap, Ai, perm);
}

/* TEMP: replaced by the ordering section */
AMPS_API amps_status amps_order(amps_ctx *ctx, const amps_csc *A, amps_stype stype, const amps_order_opts *opts,
                                amps_int *perm) {
    amps_int n, k;
    amps_int *seen;
    (void)stype;
    if (!A || !perm) return amps__err(ctx, AMPS_ERR_ARG, "amps_order: NULL argument");
    n = A->ncol;
    if (opts && opts->method == AMPS_ORDER_GIVEN) {
        if (!opts->perm) return amps__err(ctx, AMPS_ERR_ARG, "amps_order: AMPS_ORDER_GIVEN with NULL perm");
        seen = AMPS__CAST(amps_int *, amps__calloc(ctx, (size_t)n, sizeof(amps_int)));
        if (!seen) return AMPS_ERR_OOM;
        for (k = 0; k < n; k++) {
            amps_int i = opts->perm[k];
            if (i < 0 || i >= n || seen[i]) {
                amps__free(ctx, seen);
                return amps__err(ctx, i < 0 || i >= n ? AMPS_ERR_INDEX : AMPS_ERR_ARG,
                                 "amps_order: perm[%lld] = %lld %s", (long long)k, (long long)i,
                                 i < 0 || i >= n ? "out of range" : "repeated");
            }
            seen[i] = 1;
        }
        memcpy(perm, opts->perm, sizeof(amps_int) * (size_t)n);
        amps__free(ctx, seen);
        return AMPS_OK;
    }
    for (k = 0; k < n; k++) perm[k] = k;
    return AMPS_OK;
}

/* ==================== symbolic + numeric LDL^T impl ==================== */
/* @@SECTION factor: owned by core */

/* Factor internals. Columns are grouped: group g = columns gs[g]..gs[g+1]-1 where column c+1 is the
   parent of c and struct L(:,c) = {c+1} u struct L(:,c+1) (e.g. the 3 DOFs of a node). With ke the
   last column of a group, the shared pattern S = struct L(:,ke) is Li[Lp[ke]..Lp[ke+1]) and column
   c of the group stores rows c+1..ke, then S: its S part starts at Lx + Lp[c] + (ke - c).
   The numeric factorization is left-looking over groups: a finished group K is kept in the list
   (head/next) of the group holding row S_K[gpos[K]], the next row of S_K not yet used as a target.
   Groups are split into independent subtrees (processed in parallel) and a top part. */
typedef struct amps__fpriv {
    amps_stype stype;
    amps_int nnzA;                /* A->p[n] at analysis */
    unsigned long long hash;      /* hash of A's pattern */
    amps_int ng;                  /* number of column groups */
    amps_int *gs;                 /* ng+1 group starts */
    amps_int *cgrp;               /* n: group of each column */
    amps_int *Sp, *Ssrc, *Sdst;   /* column c of P A P^T (below diagonal): Lx[Sdst[q]] = Ax[Ssrc[q]], q in Sp[c].. */
    amps_int *dsrc;               /* n: index in Ax of the diagonal of column c, -1 if absent */
    amps_int *head, *next, *gpos; /* ng: pending-update lists */
    amps_int *gsub;               /* ng: subtree of a group, -1 for the top part */
    amps_int nsub;                /* number of subtrees */
    amps_int *subp, *subg;        /* groups of subtree i: subg[subp[i]..subp[i+1]), ascending */
    amps_int ntop, *topg;         /* groups of the top part, ascending */
    amps_int nthr;                /* threads with workspace */
    amps_int *iwork;              /* nthr * 2n: row map of thread i at 2n i; a parallel group keeps its
                                     update list at 2n..4n */
    amps_int *fail;               /* nsub + 1: failing permuted column per subtree, or -1 */
    double work;                  /* sum of squared column counts (flop estimate) */
    double parmin;                /* factorizations with less work run on one thread */
    double pargroup;              /* top groups with (entries of their columns) x (width) >= this run on all threads */
    double touch;                 /* AMPS_COUNT_TOUCH: L entries read by sparse/partial solves */
} amps__fpriv;

/* Relative pivot threshold: pivot d of column c is accepted iff d > AMPS_PIVOT_TOL * A(c,c) (original
   diagonal). Rounding leaves the zero pivots of a singular matrix (e.g. the rigid-body modes of an
   unsupported FE model) at about 1e-16..1e-9 * A(c,c) with either sign. */
#ifndef AMPS_PIVOT_TOL
#define AMPS_PIVOT_TOL 1e-12
#endif
/* Gather-update kernels: for p in [0,m): d_t[rel[Si[p]]] -= sum_k s_k[p] * W[4k+t], k < KC, t < TC. */
static void amps__kern11(amps_int m, const amps_int *Si, const amps_int *rel, const double *const *s, const double *W,
                         double *const *d) {
    const double *s0 = s[0];
    double *d0 = d[0];
    const double w00 = W[0];
    amps_int p;
    for (p = 0; p < m; p++) {
        amps_int r = rel[Si[p]];
        const double l0 = s0[p];
        d0[r] -= l0 * w00;
    }
}
static void amps__kern12(amps_int m, const amps_int *Si, const amps_int *rel, const double *const *s, const double *W,
                         double *const *d) {
    const double *s0 = s[0];
    double *d0 = d[0]; double *d1 = d[1];
    const double w00 = W[0], w01 = W[1];
    amps_int p;
    for (p = 0; p < m; p++) {
        amps_int r = rel[Si[p]];
        const double l0 = s0[p];
        d0[r] -= l0 * w00;
        d1[r] -= l0 * w01;
    }
}
static void amps__kern13(amps_int m, const amps_int *Si, const amps_int *rel, const double *const *s, const double *W,
                         double *const *d) {
    const double *s0 = s[0];
    double *d0 = d[0]; double *d1 = d[1]; double *d2 = d[2];
    const double w00 = W[0], w01 = W[1], w02 = W[2];
    amps_int p;
    for (p = 0; p < m; p++) {
        amps_int r = rel[Si[p]];
        const double l0 = s0[p];
        d0[r] -= l0 * w00;
        d1[r] -= l0 * w01;
        d2[r] -= l0 * w02;
    }
}
static void amps__kern14(amps_int m, const amps_int *Si, const amps_int *rel, const double *const *s, const double *W,
                         double *const *d) {
    const double *s0 = s[0];
    double *d0 = d[0]; double *d1 = d[1]; double *d2 = d[2]; double *d3 = d[3];
    const double w00 = W[0], w01 = W[1], w02 = W[2], w03 = W[3];
    amps_int p;
    for (p = 0; p < m; p++) {
        amps_int r = rel[Si[p]];
        const double l0 = s0[p];
        d0[r] -= l0 * w00;
        d1[r] -= l0 * w01;
        d2[r] -= l0 * w02;
        d3[r] -= l0 * w03;
    }
}
static void amps__kern21(amps_int m, const amps_int *Si, const amps_int *rel, const double *const *s, const double *W,
                         double *const *d) {
    const double *s0 = s[0]; const double *s1 = s[1];
    double *d0 = d[0];
    const double w00 = W[0], w10 = W[4];
    amps_int p;
    for (p = 0; p < m; p++) {
        amps_int r = rel[Si[p]];
        const double l0 = s0[p], l1 = s1[p];
        d0[r] -= l0 * w00 + l1 * w10;
    }
}
static void amps__kern22(amps_int m, const amps_int *Si, const amps_int *rel, const double *const *s, const double *W,
                         double *const *d) {
    const double *s0 = s[0]; const double *s1 = s[1];
    double *d0 = d[0]; double *d1 = d[1];
    const double w00 = W[0], w01 = W[1], w10 = W[4], w11 = W[5];
    amps_int p;
    for (p = 0; p < m; p++) {
        amps_int r = rel[Si[p]];
        const double l0 = s0[p], l1 = s1[p];
        d0[r] -= l0 * w00 + l1 * w10;
        d1[r] -= l0 * w01 + l1 * w11;
    }
}
static void amps__kern23(amps_int m, const amps_int *Si, const amps_int *rel, const double *const *s, const double *W,
                         double *const *d) {
    const double *s0 = s[0]; const double *s1 = s[1];
    double *d0 = d[0]; double *d1 = d[1]; double *d2 = d[2];
    const double w00 = W[0], w01 = W[1], w02 = W[2], w10 = W[4], w11 = W[5], w12 = W[6];
    amps_int p;
    for (p = 0; p < m; p++) {
        amps_int r = rel[Si[p]];
        const double l0 = s0[p], l1 = s1[p];
        d0[r] -= l0 * w00 + l1 * w10;
        d1[r] -= l0 * w01 + l1 * w11;
        d2[r] -= l0 * w02 + l1 * w12;
    }
}
static void amps__kern24(amps_int m, const amps_int *Si, const amps_int *rel, const double *const *s, const double *W,
                         double *const *d) {
    const double *s0 = s[0]; const double *s1 = s[1];
    double *d0 = d[0]; double *d1 = d[1]; double *d2 = d[2]; double *d3 = d[3];
    const double w00 = W[0], w01 = W[1], w02 = W[2], w03 = W[3], w10 = W[4], w11 = W[5], w12 = W[6], w13 = W[7];
    amps_int p;
    for (p = 0; p < m; p++) {
        amps_int r = rel[Si[p]];
        const double l0 = s0[p], l1 = s1[p];
        d0[r] -= l0 * w00 + l1 * w10;
        d1[r] -= l0 * w01 + l1 * w11;
        d2[r] -= l0 * w02 + l1 * w12;
        d3[r] -= l0 * w03 + l1 * w13;
    }
}
static void amps__kern31(amps_int m, const amps_int *Si, const amps_int *rel, const double *const *s, const double *W,
                         double *const *d) {
    const double *s0 = s[0]; const double *s1 = s[1]; const double *s2 = s[2];
    double *d0 = d[0];
    const double w00 = W[0], w10 = W[4], w20 = W[8];
    amps_int p;
    for (p = 0; p < m; p++) {
        amps_int r = rel[Si[p]];
        const double l0 = s0[p], l1 = s1[p], l2 = s2[p];
        d0[r] -= l0 * w00 + l1 * w10 + l2 * w20;
    }
}
static void amps__kern32(amps_int m, const amps_int *Si, const amps_int *rel, const double *const *s, const double *W,
                         double *const *d) {
    const double *s0 = s[0]; const double *s1 = s[1]; const double *s2 = s[2];
    double *d0 = d[0]; double *d1 = d[1];
    const double w00 = W[0], w01 = W[1], w10 = W[4], w11 = W[5], w20 = W[8], w21 = W[9];
    amps_int p;
    for (p = 0; p < m; p++) {
        amps_int r = rel[Si[p]];
        const double l0 = s0[p], l1 = s1[p], l2 = s2[p];
        d0[r] -= l0 * w00 + l1 * w10 + l2 * w20;
        d1[r] -= l0 * w01 + l1 * w11 + l2 * w21;
    }
}
static void amps__kern33(amps_int m, const amps_int *Si, const amps_int *rel, const double *const *s, const double *W,
                         double *const *d) {
    const double *s0 = s[0]; const double *s1 = s[1]; const double *s2 = s[2];
    double *d0 = d[0]; double *d1 = d[1]; double *d2 = d[2];
    const double w00 = W[0], w01 = W[1], w02 = W[2], w10 = W[4], w11 = W[5], w12 = W[6], w20 = W[8], w21 = W[9], w22 = W[10];
    amps_int p;
    for (p = 0; p < m; p++) {
        amps_int r = rel[Si[p]];
        const double l0 = s0[p], l1 = s1[p], l2 = s2[p];
        d0[r] -= l0 * w00 + l1 * w10 + l2 * w20;
        d1[r] -= l0 * w01 + l1 * w11 + l2 * w21;
        d2[r] -= l0 * w02 + l1 * w12 + l2 * w22;
    }
}
static void amps__kern34(amps_int m, const amps_int *Si, const amps_int *rel, const double *const *s, const double *W,
                         double *const *d) {
    const double *s0 = s[0]; const double *s1 = s[1]; const double *s2 = s[2];
    double *d0 = d[0]; double *d1 = d[1]; double *d2 = d[2]; double *d3 = d[3];
    const double w00 = W[0], w01 = W[1], w02 = W[2], w03 = W[3], w10 = W[4], w11 = W[5], w12 = W[6], w13 = W[7], w20 = W[8], w21 = W[9], w22 = W[10], w23 = W[11];
    amps_int p;
    for (p = 0; p < m; p++) {
        amps_int r = rel[Si[p]];
        const double l0 = s0[p], l1 = s1[p], l2 = s2[p];
        d0[r] -= l0 * w00 + l1 * w10 + l2 * w20;
        d1[r] -= l0 * w01 + l1 * w11 + l2 * w21;
        d2[r] -= l0 * w02 + l1 * w12 + l2 * w22;
        d3[r] -= l0 * w03 + l1 * w13 + l2 * w23;
    }
}
static void amps__kern41(amps_int m, const amps_int *Si, const amps_int *rel, const double *const *s, const double *W,
                         double *const *d) {
    const double *s0 = s[0]; const double *s1 = s[1]; const double *s2 = s[2]; const double *s3 = s[3];
    double *d0 = d[0];
    const double w00 = W[0], w10 = W[4], w20 = W[8], w30 = W[12];
    amps_int p;
    for (p = 0; p < m; p++) {
        amps_int r = rel[Si[p]];
        const double l0 = s0[p], l1 = s1[p], l2 = s2[p], l3 = s3[p];
        d0[r] -= l0 * w00 + l1 * w10 + l2 * w20 + l3 * w30;
    }
}
static void amps__kern42(amps_int m, const amps_int *Si, const amps_int *rel, const double *const *s, const double *W,
                         double *const *d) {
    const double *s0 = s[0]; const double *s1 = s[1]; const double *s2 = s[2]; const double *s3 = s[3];
    double *d0 = d[0]; double *d1 = d[1];
    const double w00 = W[0], w01 = W[1], w10 = W[4], w11 = W[5], w20 = W[8], w21 = W[9], w30 = W[12], w31 = W[13];
    amps_int p;
    for (p = 0; p < m; p++) {
        amps_int r = rel[Si[p]];
        const double l0 = s0[p], l1 = s1[p], l2 = s2[p], l3 = s3[p];
        d0[r] -= l0 * w00 + l1 * w10 + l2 * w20 + l3 * w30;
        d1[r] -= l0 * w01 + l1 * w11 + l2 * w21 + l3 * w31;
    }
}
static void amps__kern43(amps_int m, const amps_int *Si, const amps_int *rel, const double *const *s, const double *W,
                         double *const *d) {
    const double *s0 = s[0]; const double *s1 = s[1]; const double *s2 = s[2]; const double *s3 = s[3];
    double *d0 = d[0]; double *d1 = d[1]; double *d2 = d[2];
    const double w00 = W[0], w01 = W[1], w02 = W[2], w10 = W[4], w11 = W[5], w12 = W[6], w20 = W[8], w21 = W[9], w22 = W[10], w30 = W[12], w31 = W[13], w32 = W[14];
    amps_int p;
    for (p = 0; p < m; p++) {
        amps_int r = rel[Si[p]];
        const double l0 = s0[p], l1 = s1[p], l2 = s2[p], l3 = s3[p];
        d0[r] -= l0 * w00 + l1 * w10 + l2 * w20 + l3 * w30;
        d1[r] -= l0 * w01 + l1 * w11 + l2 * w21 + l3 * w31;
        d2[r] -= l0 * w02 + l1 * w12 + l2 * w22 + l3 * w32;
    }
}
static void amps__kern44(amps_int m, const amps_int *Si, const amps_int *rel, const double *const *s, const double *W,
                         double *const *d) {
    const double *s0 = s[0]; const double *s1 = s[1]; const double *s2 = s[2]; const double *s3 = s[3];
    double *d0 = d[0]; double *d1 = d[1]; double *d2 = d[2]; double *d3 = d[3];
    const double w00 = W[0], w01 = W[1], w02 = W[2], w03 = W[3], w10 = W[4], w11 = W[5], w12 = W[6], w13 = W[7], w20 = W[8], w21 = W[9], w22 = W[10], w23 = W[11], w30 = W[12], w31 = W[13], w32 = W[14], w33 = W[15];
    amps_int p;
    for (p = 0; p < m; p++) {
        amps_int r = rel[Si[p]];
        const double l0 = s0[p], l1 = s1[p], l2 = s2[p], l3 = s3[p];
        d0[r] -= l0 * w00 + l1 * w10 + l2 * w20 + l3 * w30;
        d1[r] -= l0 * w01 + l1 * w11 + l2 * w21 + l3 * w31;
        d2[r] -= l0 * w02 + l1 * w12 + l2 * w22 + l3 * w32;
        d3[r] -= l0 * w03 + l1 * w13 + l2 * w23 + l3 * w33;
    }
}
typedef void (*amps__kern_fn)(amps_int, const amps_int *, const amps_int *, const double *const *, const double *,
                              double *const *);
static const amps__kern_fn amps__kern[4][4] = {
    {amps__kern11, amps__kern12, amps__kern13, amps__kern14},
    {amps__kern21, amps__kern22, amps__kern23, amps__kern24},
    {amps__kern31, amps__kern32, amps__kern33, amps__kern34},
    {amps__kern41, amps__kern42, amps__kern43, amps__kern44}
};
/* Dense variants: d_t[p] -= sum_k s_k[p] * W[4k+t] (rows of a group against its own columns). */
static void amps__dkern11(amps_int m, const double *const *s, const double *W, double *const *d) {
    const double *s0 = s[0];
    double *d0 = d[0];
    const double w00 = W[0];
    amps_int p;
    for (p = 0; p < m; p++) {
        const double l0 = s0[p];
        d0[p] -= l0 * w00;
    }
}
static void amps__dkern12(amps_int m, const double *const *s, const double *W, double *const *d) {
    const double *s0 = s[0];
    double *d0 = d[0]; double *d1 = d[1];
    const double w00 = W[0], w01 = W[1];
    amps_int p;
    for (p = 0; p < m; p++) {
        const double l0 = s0[p];
        d0[p] -= l0 * w00;
        d1[p] -= l0 * w01;
    }
}
static void amps__dkern13(amps_int m, const double *const *s, const double *W, double *const *d) {
    const double *s0 = s[0];
    double *d0 = d[0]; double *d1 = d[1]; double *d2 = d[2];
    const double w00 = W[0], w01 = W[1], w02 = W[2];
    amps_int p;
    for (p = 0; p < m; p++) {
        const double l0 = s0[p];
        d0[p] -= l0 * w00;
        d1[p] -= l0 * w01;
        d2[p] -= l0 * w02;
    }
}
static void amps__dkern14(amps_int m, const double *const *s, const double *W, double *const *d) {
    const double *s0 = s[0];
    double *d0 = d[0]; double *d1 = d[1]; double *d2 = d[2]; double *d3 = d[3];
    const double w00 = W[0], w01 = W[1], w02 = W[2], w03 = W[3];
    amps_int p;
    for (p = 0; p < m; p++) {
        const double l0 = s0[p];
        d0[p] -= l0 * w00;
        d1[p] -= l0 * w01;
        d2[p] -= l0 * w02;
        d3[p] -= l0 * w03;
    }
}
static void amps__dkern21(amps_int m, const double *const *s, const double *W, double *const *d) {
    const double *s0 = s[0]; const double *s1 = s[1];
    double *d0 = d[0];
    const double w00 = W[0], w10 = W[4];
    amps_int p;
    for (p = 0; p < m; p++) {
        const double l0 = s0[p], l1 = s1[p];
        d0[p] -= l0 * w00 + l1 * w10;
    }
}
static void amps__dkern22(amps_int m, const double *const *s, const double *W, double *const *d) {
    const double *s0 = s[0]; const double *s1 = s[1];
    double *d0 = d[0]; double *d1 = d[1];
    const double w00 = W[0], w01 = W[1], w10 = W[4], w11 = W[5];
    amps_int p;
    for (p = 0; p < m; p++) {
        const double l0 = s0[p], l1 = s1[p];
        d0[p] -= l0 * w00 + l1 * w10;
        d1[p] -= l0 * w01 + l1 * w11;
    }
}
static void amps__dkern23(amps_int m, const double *const *s, const double *W, double *const *d) {
    const double *s0 = s[0]; const double *s1 = s[1];
    double *d0 = d[0]; double *d1 = d[1]; double *d2 = d[2];
    const double w00 = W[0], w01 = W[1], w02 = W[2], w10 = W[4], w11 = W[5], w12 = W[6];
    amps_int p;
    for (p = 0; p < m; p++) {
        const double l0 = s0[p], l1 = s1[p];
        d0[p] -= l0 * w00 + l1 * w10;
        d1[p] -= l0 * w01 + l1 * w11;
        d2[p] -= l0 * w02 + l1 * w12;
    }
}
static void amps__dkern24(amps_int m, const double *const *s, const double *W, double *const *d) {
    const double *s0 = s[0]; const double *s1 = s[1];
    double *d0 = d[0]; double *d1 = d[1]; double *d2 = d[2]; double *d3 = d[3];
    const double w00 = W[0], w01 = W[1], w02 = W[2], w03 = W[3], w10 = W[4], w11 = W[5], w12 = W[6], w13 = W[7];
    amps_int p;
    for (p = 0; p < m; p++) {
        const double l0 = s0[p], l1 = s1[p];
        d0[p] -= l0 * w00 + l1 * w10;
        d1[p] -= l0 * w01 + l1 * w11;
        d2[p] -= l0 * w02 + l1 * w12;
        d3[p] -= l0 * w03 + l1 * w13;
    }
}
static void amps__dkern31(amps_int m, const double *const *s, const double *W, double *const *d) {
    const double *s0 = s[0]; const double *s1 = s[1]; const double *s2 = s[2];
    double *d0 = d[0];
    const double w00 = W[0], w10 = W[4], w20 = W[8];
    amps_int p;
    for (p = 0; p < m; p++) {
        const double l0 = s0[p], l1 = s1[p], l2 = s2[p];
        d0[p] -= l0 * w00 + l1 * w10 + l2 * w20;
    }
}
static void amps__dkern32(amps_int m, const double *const *s, const double *W, double *const *d) {
    const double *s0 = s[0]; const double *s1 = s[1]; const double *s2 = s[2];
    double *d0 = d[0]; double *d1 = d[1];
    const double w00 = W[0], w01 = W[1], w10 = W[4], w11 = W[5], w20 = W[8], w21 = W[9];
    amps_int p;
    for (p = 0; p < m; p++) {
        const double l0 = s0[p], l1 = s1[p], l2 = s2[p];
        d0[p] -= l0 * w00 + l1 * w10 + l2 * w20;
        d1[p] -= l0 * w01 + l1 * w11 + l2 * w21;
    }
}
static void amps__dkern33(amps_int m, const double *const *s, const double *W, double *const *d) {
    const double *s0 = s[0]; const double *s1 = s[1]; const double *s2 = s[2];
    double *d0 = d[0]; double *d1 = d[1]; double *d2 = d[2];
    const double w00 = W[0], w01 = W[1], w02 = W[2], w10 = W[4], w11 = W[5], w12 = W[6], w20 = W[8], w21 = W[9], w22 = W[10];
    amps_int p;
    for (p = 0; p < m; p++) {
        const double l0 = s0[p], l1 = s1[p], l2 = s2[p];
        d0[p] -= l0 * w00 + l1 * w10 + l2 * w20;
        d1[p] -= l0 * w01 + l1 * w11 + l2 * w21;
        d2[p] -= l0 * w02 + l1 * w12 + l2 * w22;
    }
}
static void amps__dkern34(amps_int m, const double *const *s, const double *W, double *const *d) {
    const double *s0 = s[0]; const double *s1 = s[1]; const double *s2 = s[2];
    double *d0 = d[0]; double *d1 = d[1]; double *d2 = d[2]; double *d3 = d[3];
    const double w00 = W[0], w01 = W[1], w02 = W[2], w03 = W[3], w10 = W[4], w11 = W[5], w12 = W[6], w13 = W[7], w20 = W[8], w21 = W[9], w22 = W[10], w23 = W[11];
    amps_int p;
    for (p = 0; p < m; p++) {
        const double l0 = s0[p], l1 = s1[p], l2 = s2[p];
        d0[p] -= l0 * w00 + l1 * w10 + l2 * w20;
        d1[p] -= l0 * w01 + l1 * w11 + l2 * w21;
        d2[p] -= l0 * w02 + l1 * w12 + l2 * w22;
        d3[p] -= l0 * w03 + l1 * w13 + l2 * w23;
    }
}
static void amps__dkern41(amps_int m, const double *const *s, const double *W, double *const *d) {
    const double *s0 = s[0]; const double *s1 = s[1]; const double *s2 = s[2]; const double *s3 = s[3];
    double *d0 = d[0];
    const double w00 = W[0], w10 = W[4], w20 = W[8], w30 = W[12];
    amps_int p;
    for (p = 0; p < m; p++) {
        const double l0 = s0[p], l1 = s1[p], l2 = s2[p], l3 = s3[p];
        d0[p] -= l0 * w00 + l1 * w10 + l2 * w20 + l3 * w30;
    }
}
static void amps__dkern42(amps_int m, const double *const *s, const double *W, double *const *d) {
    const double *s0 = s[0]; const double *s1 = s[1]; const double *s2 = s[2]; const double *s3 = s[3];
    double *d0 = d[0]; double *d1 = d[1];
    const double w00 = W[0], w01 = W[1], w10 = W[4], w11 = W[5], w20 = W[8], w21 = W[9], w30 = W[12], w31 = W[13];
    amps_int p;
    for (p = 0; p < m; p++) {
        const double l0 = s0[p], l1 = s1[p], l2 = s2[p], l3 = s3[p];
        d0[p] -= l0 * w00 + l1 * w10 + l2 * w20 + l3 * w30;
        d1[p] -= l0 * w01 + l1 * w11 + l2 * w21 + l3 * w31;
    }
}
static void amps__dkern43(amps_int m, const double *const *s, const double *W, double *const *d) {
    const double *s0 = s[0]; const double *s1 = s[1]; const double *s2 = s[2]; const double *s3 = s[3];
    double *d0 = d[0]; double *d1 = d[1]; double *d2 = d[2];
    const double w00 = W[0], w01 = W[1], w02 = W[2], w10 = W[4], w11 = W[5], w12 = W[6], w20 = W[8], w21 = W[9], w22 = W[10], w30 = W[12], w31 = W[13], w32 = W[14];
    amps_int p;
    for (p = 0; p < m; p++) {
        const double l0 = s0[p], l1 = s1[p], l2 = s2[p], l3 = s3[p];
        d0[p] -= l0 * w00 + l1 * w10 + l2 * w20 + l3 * w30;
        d1[p] -= l0 * w01 + l1 * w11 + l2 * w21 + l3 * w31;
        d2[p] -= l0 * w02 + l1 * w12 + l2 * w22 + l3 * w32;
    }
}
static void amps__dkern44(amps_int m, const double *const *s, const double *W, double *const *d) {
    const double *s0 = s[0]; const double *s1 = s[1]; const double *s2 = s[2]; const double *s3 = s[3];
    double *d0 = d[0]; double *d1 = d[1]; double *d2 = d[2]; double *d3 = d[3];
    const double w00 = W[0], w01 = W[1], w02 = W[2], w03 = W[3], w10 = W[4], w11 = W[5], w12 = W[6], w13 = W[7], w20 = W[8], w21 = W[9], w22 = W[10], w23 = W[11], w30 = W[12], w31 = W[13], w32 = W[14], w33 = W[15];
    amps_int p;
    for (p = 0; p < m; p++) {
        const double l0 = s0[p], l1 = s1[p], l2 = s2[p], l3 = s3[p];
        d0[p] -= l0 * w00 + l1 * w10 + l2 * w20 + l3 * w30;
        d1[p] -= l0 * w01 + l1 * w11 + l2 * w21 + l3 * w31;
        d2[p] -= l0 * w02 + l1 * w12 + l2 * w22 + l3 * w32;
        d3[p] -= l0 * w03 + l1 * w13 + l2 * w23 + l3 * w33;
    }
}
typedef void (*amps__dkern_fn)(amps_int, const double *const *, const double *, double *const *);
static const amps__dkern_fn amps__dkern[4][4] = {
    {amps__dkern11, amps__dkern12, amps__dkern13, amps__dkern14},
    {amps__dkern21, amps__dkern22, amps__dkern23, amps__dkern24},
    {amps__dkern31, amps__dkern32, amps__dkern33, amps__dkern34},
    {amps__dkern41, amps__dkern42, amps__dkern43, amps__dkern44}
};

/* FNV-1a style hash of the pattern (p, i) of A. */
static unsigned long long amps__pattern_hash(const amps_csc *A) {
    unsigned long long h = 1469598103934665603ULL;
    amps_int j, n = A->ncol, nz = A->p[A->ncol];
    for (j = 0; j <= n; j++) h = (h ^ (unsigned long long)A->p[j]) * 1099511628211ULL;
    for (j = 0; j < nz; j++) h = (h ^ (unsigned long long)A->i[j]) * 1099511628211ULL;
    return h;
}

static void amps__fpriv_free(amps_ctx *ctx, amps__fpriv *P) {
    if (!P) return;
    amps__free(ctx, P->gs); amps__free(ctx, P->cgrp); amps__free(ctx, P->Sp); amps__free(ctx, P->Ssrc);
    amps__free(ctx, P->Sdst); amps__free(ctx, P->dsrc); amps__free(ctx, P->head); amps__free(ctx, P->next);
    amps__free(ctx, P->gpos); amps__free(ctx, P->gsub); amps__free(ctx, P->subp); amps__free(ctx, P->subg);
    amps__free(ctx, P->topg); amps__free(ctx, P->iwork); amps__free(ctx, P->fail);
    amps__free(ctx, P);
}

AMPS_API void amps_factor_free(amps_ctx *ctx, amps_factor *F) {
    if (!F) return;
    amps__fpriv_free(ctx, AMPS__CAST(amps__fpriv *, F->priv));
    amps__free(ctx, F->perm); amps__free(ctx, F->iperm); amps__free(ctx, F->parent); amps__free(ctx, F->Lp);
    amps__free(ctx, F->Li); amps__free(ctx, F->Lx); amps__free(ctx, F->D);
    amps__free(ctx, F);
}

AMPS_API double amps_factor_nnz(const amps_factor *F) {
    return F && F->Lp ? (double)F->Lp[F->n] + (double)F->n : 0.0;
}

AMPS_API void amps_factor_inertia(const amps_factor *F, amps_int *npos, amps_int *nneg, amps_int *nzero) {
    amps_int k, a = 0, b = 0, z = 0;
    for (k = 0; F && F->D && k < F->n; k++) {
        if (F->D[k] > 0) a++;
        else if (F->D[k] < 0) b++;
        else z++;
    }
    if (npos) *npos = a;
    if (nneg) *nneg = b;
    if (nzero) *nzero = z;
}

/* Threads for a kernel: ctx->nthreads, else the OpenMP default; at most cap. */
static int amps__nthreads(const amps_ctx *ctx, amps_int cap) {
    int t = 1;
#ifdef _OPENMP
    t = (ctx && ctx->nthreads > 0) ? ctx->nthreads : omp_get_max_threads();
#else
    (void)ctx;
#endif
    if (t > cap) t = (int)cap;
    return t < 1 ? 1 : t;
}

/* Column counts of L (with diagonal) from the elimination tree and the lower pattern of C = P A P^T
   (column j: rows Cr[Cp[j]..Cp[j+1]) > j): cc[j] = number of row subtrees containing j, accumulated
   from +1 at the leaves of each row subtree and -1 at least common ancestors of consecutive leaves
   (in postorder) and at the parent of each subtree root. w: 5n ints. */
static void amps__colcounts(amps_int n, const amps_int *parent, const amps_int *Cp, const amps_int *Cr,
                            amps_int *cc, amps_int *w) {
    amps_int *post = w, *first = w + n, *maxfirst = w + 2 * n, *prevleaf = w + 3 * n, *anc = w + 4 * n;
    amps_int *chead = maxfirst, *cnext = prevleaf, *stack = anc;
    amps_int j, k, q, r, top;
    /* postorder (children lists in ascending order, explicit stack) */
    for (j = 0; j < n; j++) chead[j] = -1;
    for (j = n - 1; j >= 0; j--)
        if (parent[j] >= 0) { cnext[j] = chead[parent[j]]; chead[parent[j]] = j; }
    for (j = 0, k = 0; j < n; j++) {
        if (parent[j] >= 0) continue;
        top = 0;
        stack[top++] = j;
        while (top > 0) {
            amps_int v = stack[top - 1], ch = chead[v];
            if (ch >= 0) { chead[v] = cnext[ch]; stack[top++] = ch; }
            else { top--; post[k++] = v; }
        }
    }
    for (j = 0; j < n; j++) { first[j] = -1; maxfirst[j] = -1; prevleaf[j] = -1; anc[j] = j; }
    for (k = 0; k < n; k++)
        for (r = post[k]; r >= 0 && first[r] < 0; r = parent[r]) first[r] = k;
    for (k = 0; k < n; k++) { j = post[k]; cc[j] = (first[j] == k) ? 1 : 0; }
    for (k = 0; k < n; k++) {
        j = post[k];
        if (parent[j] >= 0) cc[parent[j]]--;
        for (q = Cp[j]; q < Cp[j + 1]; q++) {
            amps_int i = Cr[q], jprev;
            if (first[j] <= maxfirst[i]) continue; /* j is not a leaf of row subtree i */
            maxfirst[i] = first[j];
            jprev = prevleaf[i];
            prevleaf[i] = j;
            cc[j]++;
            if (jprev >= 0) { /* least common ancestor of jprev and j: root of jprev's set */
                amps_int root = jprev, s, t;
                while (anc[root] != root) root = anc[root];
                for (s = jprev; s != root; s = t) { t = anc[s]; anc[s] = root; }
                cc[root]--;
            }
        }
        if (parent[j] >= 0) anc[j] = parent[j];
    }
    for (k = 0; k < n; k++) { j = post[k]; if (parent[j] >= 0) cc[parent[j]] += cc[j]; }
}

#ifndef AMPS__SBLK
#define AMPS__SBLK 64 /* superblock width (multiple of 4) in the parallel factorization of a group */
#endif
#ifndef AMPS__PARGROUP
#define AMPS__PARGROUP 2e6 /* top groups with (entries of their columns) x (width) >= this use all threads */
#endif
#ifndef AMPS__PARMIN
#define AMPS__PARMIN 1e9 /* factorizations with a smaller flop estimate (sum of squared column counts) run on one thread */
#endif
#ifndef AMPS__NSUB
#define AMPS__NSUB 8 /* split the tree until no subtree has more than 1/AMPS__NSUB of the subtree work */
#endif

AMPS_API amps_factor *amps_analyze(amps_ctx *ctx, const amps_csc *A, amps_stype stype, const amps_order_opts *opts) {
    amps_factor *F = NULL;
    amps__fpriv *P = NULL;
    amps_int n, j, p, q, k, c, g, ng, nnzC = 0, nthr;
    amps_int *Up = NULL, *Ui = NULL, *Cr = NULL, *tw = NULL, *cc = NULL, *gpar = NULL, *cand = NULL;
    double *gw = NULL, total, lnz;
    amps_status st;
    if (amps_csc_check(ctx, A, stype) != AMPS_OK) return NULL;
    n = A->ncol;
    F = AMPS__CAST(amps_factor *, amps__calloc(ctx, 1, sizeof(amps_factor)));
    if (!F) return NULL;
    P = AMPS__CAST(amps__fpriv *, amps__calloc(ctx, 1, sizeof(amps__fpriv)));
    F->priv = P;
    F->n = n;
    if (!P) goto oom;
    P->stype = stype;
    P->nnzA = A->p[n];
    F->perm = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)n, sizeof(amps_int)));
    F->iperm = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)n, sizeof(amps_int)));
    F->parent = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)n, sizeof(amps_int)));
    F->Lp = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)n + 1, sizeof(amps_int)));
    F->D = AMPS__CAST(double *, amps__malloc(ctx, (size_t)n, sizeof(double)));
    P->cgrp = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)n, sizeof(amps_int)));
    P->Sp = AMPS__CAST(amps_int *, amps__calloc(ctx, (size_t)n + 1, sizeof(amps_int)));
    P->dsrc = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)n, sizeof(amps_int)));
    Up = AMPS__CAST(amps_int *, amps__calloc(ctx, (size_t)n + 1, sizeof(amps_int)));
    tw = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)n * 5 + 1, sizeof(amps_int)));
    cc = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)n + 1, sizeof(amps_int)));
    if (!F->perm || !F->iperm || !F->parent || !F->Lp || !F->D || !P->cgrp || !P->Sp || !P->dsrc || !Up || !tw || !cc)
        goto oom;
    st = amps_order(ctx, A, stype, opts, F->perm);
    if (st != AMPS_OK) goto fail;
    for (k = 0; k < n; k++) F->iperm[k] = -1;
    for (k = 0; k < n; k++) {
        amps_int i = F->perm[k];
        if (i < 0 || i >= n || F->iperm[i] >= 0) {
            amps__err(ctx, AMPS_ERR_ARG, "amps_analyze: ordering is not a permutation (perm[%lld] = %lld)",
                      (long long)k, (long long)i);
            goto fail;
        }
        F->iperm[i] = k;
    }
    /* C = P A P^T: upper pattern (Up, Ui) and strictly lower columns (Sp, Ssrc, Cr) with their sources in A */
    for (k = 0; k < n; k++) P->dsrc[k] = -1;
    for (j = 0; j < n; j++)
        for (p = A->p[j]; p < A->p[j + 1]; p++) {
            amps_int i = A->i[p], a = F->iperm[i], b = F->iperm[j];
            if (stype == AMPS_FULL && i > j) continue;
            if (a > b) { amps_int t = a; a = b; b = t; }
            Up[b]++;
            nnzC++;
            if (a == b) P->dsrc[a] = p;
            else P->Sp[a]++;
        }
    for (k = 0, p = 0, q = 0; k < n; k++) {
        amps_int t = Up[k]; Up[k] = p; p += t;
        t = P->Sp[k]; P->Sp[k] = q; q += t;
    }
    Up[n] = p;
    P->Sp[n] = q;
    Ui = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)nnzC, sizeof(amps_int)));
    Cr = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)q, sizeof(amps_int)));
    P->Ssrc = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)q, sizeof(amps_int)));
    P->Sdst = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)q, sizeof(amps_int)));
    if (!Ui || !Cr || !P->Ssrc || !P->Sdst) goto oom;
    {
        amps_int *wu = tw, *wl = tw + n;
        for (k = 0; k < n; k++) { wu[k] = Up[k]; wl[k] = P->Sp[k]; }
        for (j = 0; j < n; j++)
            for (p = A->p[j]; p < A->p[j + 1]; p++) {
                amps_int i = A->i[p], a = F->iperm[i], b = F->iperm[j];
                if (stype == AMPS_FULL && i > j) continue;
                if (a > b) { amps_int t = a; a = b; b = t; }
                Ui[wu[b]++] = a;
                if (a != b) { q = wl[a]++; Cr[q] = b; P->Ssrc[q] = p; }
            }
    }
    /* elimination tree (tw = ancestor with path compression) */
    {
        amps_int *parent = F->parent, *anc = tw;
        for (k = 0; k < n; k++) {
            parent[k] = -1;
            anc[k] = -1;
            for (p = Up[k]; p < Up[k + 1]; p++) {
                amps_int i = Ui[p];
                while (i >= 0 && i < k) {
                    amps_int nx = anc[i];
                    anc[i] = k;
                    if (nx < 0) parent[i] = k;
                    i = nx;
                }
            }
        }
    }
    amps__colcounts(n, F->parent, P->Sp, Cr, cc, tw);
    lnz = 0;
    F->Lp[0] = 0;
    for (k = 0; k < n; k++) {
        lnz += (double)cc[k] - 1.0;
        if (lnz > (double)AMPS__IMAX) {
            amps__err(ctx, AMPS_ERR_OOM, "amps_analyze: nnz(L) exceeds the index type at column %lld; use a wider AMPS_INT",
                      (long long)k);
            goto fail;
        }
        F->Lp[k + 1] = F->Lp[k] + cc[k] - 1;
    }
    /* column groups: c joins the group of c-1 when parent(c-1) = c and the patterns nest */
    ng = 0;
    for (c = 0; c < n; c++) {
        if (c == 0 || !(F->parent[c - 1] == c && cc[c - 1] == cc[c] + 1)) tw[ng++] = c;
        P->cgrp[c] = ng - 1;
    }
    tw[ng] = n;
    P->ng = ng;
    P->gs = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)ng + 1, sizeof(amps_int)));
    gpar = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)ng, sizeof(amps_int)));
    P->head = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)ng, sizeof(amps_int)));
    P->next = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)ng, sizeof(amps_int)));
    P->gpos = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)ng, sizeof(amps_int)));
    P->gsub = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)ng, sizeof(amps_int)));
    gw = AMPS__CAST(double *, amps__malloc(ctx, (size_t)ng * 2, sizeof(double)));
    cand = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)ng, sizeof(amps_int)));
    F->Li = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)F->Lp[n], sizeof(amps_int)));
    F->Lx = AMPS__CAST(double *, amps__malloc(ctx, (size_t)F->Lp[n], sizeof(double)));
    if (!P->gs || !gpar || !P->head || !P->next || !P->gpos || !P->gsub || !gw || !cand || !F->Li || !F->Lx) goto oom;
    memcpy(P->gs, tw, sizeof(amps_int) * ((size_t)ng + 1));
    for (g = 0; g < ng; g++) {
        amps_int pe = F->parent[P->gs[g + 1] - 1];
        gpar[g] = pe < 0 ? -1 : P->cgrp[pe];
    }
    /* pattern: row i joins S_g for every group g strictly below group(i) on the paths from the
       columns j < i of C(:, i); rows arrive in ascending order. tw: fill count, mark. */
    {
        amps_int *cnt = tw, *mark = tw + n;
        amps_int *Lp = F->Lp, *Li = F->Li;
        const amps_int *gs = P->gs, *cgrp = P->cgrp;
        for (g = 0; g < ng; g++) { cnt[g] = 0; mark[g] = -1; }
        for (k = 0; k < n; k++) {
            amps_int gi = cgrp[k];
            for (p = Up[k]; p < Up[k + 1]; p++) {
                amps_int jj = Ui[p];
                if (jj >= k) continue;
                for (g = cgrp[jj]; g != gi && mark[g] != k; g = gpar[g]) {
                    AMPS_ASSERT(g >= 0);
                    mark[g] = k;
                    Li[Lp[gs[g + 1] - 1] + cnt[g]++] = k;
                }
            }
        }
        for (g = 0; g < ng; g++) {
            amps_int ks = gs[g], ke = gs[g + 1] - 1, ns = Lp[ke + 1] - Lp[ke];
            AMPS_ASSERT(cnt[g] == ns);
            for (c = ks; c < ke; c++) {
                amps_int *dst = Li + Lp[c], o;
                for (o = 0; o < ke - c; o++) dst[o] = c + 1 + o;
                memcpy(dst + (ke - c), Li + Lp[ke], sizeof(amps_int) * (size_t)ns);
            }
        }
        /* scatter destinations (tw = position of a row in S_g) */
        for (g = 0; g < ng; g++) {
            amps_int ks = gs[g], ke = gs[g + 1] - 1, ns = Lp[ke + 1] - Lp[ke];
            const amps_int *S = Li + Lp[ke];
            for (p = 0; p < ns; p++) tw[S[p]] = p;
            for (c = ks; c <= ke; c++)
                for (q = P->Sp[c]; q < P->Sp[c + 1]; q++) {
                    amps_int r = Cr[q];
                    P->Sdst[q] = r <= ke ? Lp[c] + r - c - 1 : Lp[c] + (ke - c) + tw[r];
                }
        }
    }
    /* height of the elimination tree */
    F->height = 0;
    for (k = n - 1; k >= 0; k--) {
        tw[k] = F->parent[k] < 0 ? 1 : tw[F->parent[k]] + 1;
        if (tw[k] > F->height) F->height = tw[k];
    }
    /* subtree decomposition: repeatedly split the heaviest candidate subtree (its root goes to the top part) */
    {
        double *sw = gw + ng, subtot = 0;
        amps_int ncand = 0, nsub = 0, ntop = 0, best, i, *chead = tw + 2 * n, *cnext = tw + 3 * n;
        for (g = 0; g < ng; g++) {
            double s = 0;
            for (c = P->gs[g]; c < P->gs[g + 1]; c++) s += (double)cc[c] * (double)cc[c];
            gw[g] = s;
            sw[g] = 0;
        }
        for (g = 0; g < ng; g++) chead[g] = -1;
        for (g = ng - 1; g >= 0; g--)
            if (gpar[g] >= 0) { cnext[g] = chead[gpar[g]]; chead[gpar[g]] = g; }
        total = 0;
        for (g = 0; g < ng; g++) {
            sw[g] += gw[g];
            if (gpar[g] >= 0) sw[gpar[g]] += sw[g];
            else { cand[ncand++] = g; subtot += sw[g]; }
            P->gsub[g] = -2;
            total += gw[g];
        }
        for (;;) {
            best = -1;
            for (i = 0; i < ncand; i++)
                if (best < 0 || sw[cand[i]] > sw[cand[best]]) best = i;
            if (best < 0 || sw[cand[best]] * AMPS__NSUB <= subtot || sw[cand[best]] <= gw[cand[best]]) break;
            g = cand[best];
            P->gsub[g] = -1;
            ntop++;
            subtot -= gw[g];
            cand[best] = cand[--ncand];
            for (k = chead[g]; k >= 0; k = cnext[k]) cand[ncand++] = k;
            if (ncand > 16 * AMPS__NSUB) break;
        }
        P->work = total;
        /* candidates become subtrees, heaviest first */
        for (i = 1; i < ncand; i++) {
            amps_int t = cand[i], m2 = i;
            while (m2 > 0 && sw[cand[m2 - 1]] < sw[t]) { cand[m2] = cand[m2 - 1]; m2--; }
            cand[m2] = t;
        }
        for (i = 0; i < ncand; i++) P->gsub[cand[i]] = i;
        nsub = ncand;
        for (g = ng - 1; g >= 0; g--)
            if (P->gsub[g] == -2) P->gsub[g] = P->gsub[gpar[g]];
        P->nsub = nsub;
        P->ntop = ntop;
        P->subp = AMPS__CAST(amps_int *, amps__calloc(ctx, (size_t)nsub + 1, sizeof(amps_int)));
        P->subg = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)(ng - ntop), sizeof(amps_int)));
        P->topg = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)ntop, sizeof(amps_int)));
        P->fail = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)nsub + 1, sizeof(amps_int)));
        if (!P->subp || !P->subg || !P->topg || !P->fail) goto oom;
        for (g = 0; g < ng; g++)
            if (P->gsub[g] >= 0) P->subp[P->gsub[g] + 1]++;
        for (i = 0; i < nsub; i++) P->subp[i + 1] += P->subp[i];
        for (i = 0; i < nsub; i++) tw[i] = P->subp[i];
        for (g = 0, k = 0; g < ng; g++) {
            if (P->gsub[g] >= 0) P->subg[tw[P->gsub[g]]++] = g;
            else P->topg[k++] = g;
        }
    }
    nthr = amps__nthreads(ctx, 1024);
    P->nthr = nthr;
    P->iwork = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)nthr * 2, (size_t)n * sizeof(amps_int)));
    if (!P->iwork) goto oom;
    P->hash = amps__pattern_hash(A);
    P->pargroup = AMPS__PARGROUP;
    P->parmin = AMPS__PARMIN;
    amps__free(ctx, Up); amps__free(ctx, Ui); amps__free(ctx, Cr); amps__free(ctx, tw); amps__free(ctx, cc);
    amps__free(ctx, gpar); amps__free(ctx, gw); amps__free(ctx, cand);
    return F;
oom:
    amps__err(ctx, AMPS_ERR_OOM, "amps_analyze: out of memory (n %lld, nnz(A) %lld)", (long long)n, (long long)A->p[n]);
fail:
    amps__free(ctx, Up); amps__free(ctx, Ui); amps__free(ctx, Cr); amps__free(ctx, tw); amps__free(ctx, cc);
    amps__free(ctx, gpar); amps__free(ctx, gw); amps__free(ctx, cand);
    amps_factor_free(ctx, F);
    return NULL;
}

/* Queues finished group K for its next target group (the group of row S_K[gpos[K]]). In a subtree
   (sub >= 0) targets outside the subtree are left for amps_factorize to queue after the subtrees. */
static void amps__link(const amps_factor *F, amps__fpriv *P, amps_int K, amps_int sub) {
    amps_int ke = P->gs[K + 1] - 1, b = P->gpos[K], tg;
    if (b >= F->Lp[ke + 1] - F->Lp[ke]) return;
    tg = P->cgrp[F->Li[F->Lp[ke] + b]];
    if (sub >= 0 && P->gsub[tg] != sub) return;
    P->next[K] = P->head[tg];
    P->head[tg] = K;
}

/* Position in S_K of the first row after e (K's rows up to e start at gpos[K]). */
static amps_int amps__span(const amps_factor *F, const amps__fpriv *P, amps_int K, amps_int e) {
    amps_int ke = P->gs[K + 1] - 1, nK = F->Lp[ke + 1] - F->Lp[ke], b = P->gpos[K];
    const amps_int *SK = F->Li + F->Lp[ke];
    while (b < nK && SK[b] <= e) b++;
    return b;
}

/* Thread (of T) owning target column t of the group starting at s: blocks of 4 columns, cyclic. */
#define AMPS__OWNER(t, s, T) ((int)((((t) - (s)) >> 2) % (amps_int)(T)))

/* Applies finished group K to group J = [s, e] for the targets t = S_K[q], q in [a, b), owned by thread
   tid of T: for rows r = S_K[p], p >= q: L(r,t) D(t) -= sum_k L(r,k) D(k) L(t,k) (D(t) for r = t).
   rel maps rows of J to offsets from Lx + Lp[t] + (e - t). Each entry gets the same arithmetic for
   every T. */
static void amps__update(amps_factor *F, const amps__fpriv *P, amps_int K, amps_int s, amps_int e, amps_int a,
                         amps_int b, const amps_int *rel, int tid, int T) {
    const amps_int *Lp = F->Lp;
    double *Lx = F->Lx, *D = F->D;
    amps_int ks = P->gs[K], ke = P->gs[K + 1] - 1, nK = Lp[ke + 1] - Lp[ke];
    const amps_int *SK = F->Li + Lp[ke];
    amps_int q0, q1, k0, i, k, pp;
    for (q0 = a; q0 < b; q0 = q1) {
        amps_int tc;
        double *dst[4];
        if (T > 1) {
            while (q0 < b && AMPS__OWNER(SK[q0], s, T) != tid) q0++;
            if (q0 >= b) break;
        }
        for (q1 = q0 + 1; q1 < b && q1 - q0 < 4 && (T == 1 || AMPS__OWNER(SK[q1], s, T) == tid); q1++) {}
        tc = q1 - q0;
        for (i = 0; i < tc; i++) dst[i] = Lx + Lp[SK[q0 + i]] + (e - SK[q0 + i]);
        for (k0 = ks; k0 <= ke; k0 += 4) {
            amps_int kc = ke + 1 - k0 < 4 ? ke + 1 - k0 : 4;
            const double *src[4], *srq[4];
            double W[16];
            for (k = 0; k < kc; k++) {
                src[k] = Lx + Lp[k0 + k] + (ke - k0 - k);
                for (i = 0; i < tc; i++) W[4 * k + i] = D[k0 + k] * src[k][q0 + i];
                srq[k] = src[k] + q1;
            }
            for (i = 0; i < tc; i++) {
                double sm = 0;
                for (k = 0; k < kc; k++) sm += src[k][q0 + i] * W[4 * k + i];
                D[SK[q0 + i]] -= sm;
                for (pp = q0 + i + 1; pp < q1; pp++) {
                    sm = 0;
                    for (k = 0; k < kc; k++) sm += src[k][pp] * W[4 * k + i];
                    dst[i][rel[SK[pp]]] -= sm;
                }
            }
            amps__kern[kc - 1][tc - 1](nK - q1, SK + q1, rel, srq, W, dst);
        }
    }
}

/* Zeroes columns [c0, c1] of L and D and scatters the entries of A into them. */
static void amps__scatter(amps_factor *F, const amps__fpriv *P, const double *Ax, amps_int c0, amps_int c1) {
    amps_int c, q;
    double *Lx = F->Lx;
    memset(Lx + F->Lp[c0], 0, sizeof(double) * (size_t)(F->Lp[c1 + 1] - F->Lp[c0]));
    for (c = c0; c <= c1; c++) {
        F->D[c] = P->dsrc[c] >= 0 ? Ax[P->dsrc[c]] : 0.0;
        for (q = P->Sp[c]; q < P->Sp[c + 1]; q++) Lx[P->Sdst[q]] = Ax[P->Ssrc[q]];
    }
}

/* rel: row r of group J = [s, e] -> offset of (r, t) from Lx + Lp[t] + (e - t), for any t < r in J. */
static void amps__rowmaps(const amps_factor *F, amps_int s, amps_int e, amps_int *rel) {
    amps_int c, q, nJ = F->Lp[e + 1] - F->Lp[e];
    const amps_int *SJ = F->Li + F->Lp[e];
    for (c = s; c <= e; c++) rel[c] = c - e - 1;
    for (q = 0; q < nJ; q++) rel[SJ[q]] = q;
}

/* Updates of panel [c0, c0+tc) of a group from its columns [klo, khi) (khi <= c0; klo - (group start) a
   multiple of 4), for the rows [r0, r1) of the rows below the panel (the group's rows after the panel,
   then its S), which are stored consecutively in every column of the group. */
static void amps__panel_rect(amps_factor *F, amps_int klo, amps_int khi, amps_int c0, amps_int tc, amps_int r0,
                             amps_int r1) {
    const amps_int *Lp = F->Lp;
    double *Lx = F->Lx, *D = F->D;
    amps_int c1 = c0 + tc, k0, k, i;
    double *dst[4];
    if (r1 <= r0) return;
    for (i = 0; i < tc; i++) dst[i] = Lx + Lp[c0 + i] + (c1 - c0 - i - 1) + r0;
    for (k0 = klo; k0 < khi; k0 += 4) {
        amps_int kc = khi - k0 < 4 ? khi - k0 : 4;
        const double *srq[4];
        double W[16];
        for (k = 0; k < kc; k++) {
            const double *src = Lx + Lp[k0 + k] + (c0 - k0 - k - 1); /* row c0 of column k0+k */
            for (i = 0; i < tc; i++) W[4 * k + i] = D[k0 + k] * src[i];
            srq[k] = src + tc + r0;
        }
        amps__dkern[kc - 1][tc - 1](r1 - r0, srq, W, dst);
    }
}

/* Panel [c0, c0+tc) of group J = [s, e]: updates of its diagonal block from columns [klo, khi); then, if
   fact, its LDL^T (right-looking inside the panel; all its updates must be applied). Returns -1 or the
   permuted column whose pivot is unacceptable. */
static amps_int amps__panel_factor(amps_factor *F, const amps__fpriv *P, const double *Ax, amps_int e, amps_int klo,
                                   amps_int khi, amps_int c0, amps_int tc, const amps_int *rel, int fact) {
    const amps_int *Lp = F->Lp;
    double *Lx = F->Lx, *D = F->D;
    amps_int c1 = c0 + tc, k0, k, i, pp, c;
    double *dst[4];
    for (i = 0; i < tc; i++) dst[i] = Lx + Lp[c0 + i] + (e - c0 - i);
    for (k0 = klo; k0 < khi; k0 += 4) {
        amps_int kc = khi - k0 < 4 ? khi - k0 : 4;
        const double *src[4];
        double W[16];
        for (k = 0; k < kc; k++) {
            src[k] = Lx + Lp[k0 + k] + (c0 - k0 - k - 1);
            for (i = 0; i < tc; i++) W[4 * k + i] = D[k0 + k] * src[k][i];
        }
        for (i = 0; i < tc; i++) {
            double sm = 0;
            for (k = 0; k < kc; k++) sm += src[k][i] * W[4 * k + i];
            D[c0 + i] -= sm;
            for (pp = i + 1; pp < tc; pp++) {
                sm = 0;
                for (k = 0; k < kc; k++) sm += src[k][pp] * W[4 * k + i];
                dst[i][rel[c0 + pp]] -= sm;
            }
        }
    }
    for (c = c0; fact && c < c1; c++) {
        double d = D[c], acc = P->dsrc[c] >= 0 ? Ax[P->dsrc[c]] : 0.0, *Lc = Lx + Lp[c];
        amps_int len = Lp[c + 1] - Lp[c], c2, o;
        if (!(acc > 0.0) || !(d > AMPS_PIVOT_TOL * acc) || !amps__isfinite(d)) return c;
        for (c2 = c + 1; c2 < c1; c2++) {
            double v = Lc[c2 - c - 1], lv = v / d, *L2 = Lx + Lp[c2];
            const double *Ls = Lc + (c2 - c);
            amps_int len2 = Lp[c2 + 1] - Lp[c2];
            D[c2] -= v * lv;
            for (o = 0; o < len2; o++) L2[o] -= Ls[o] * lv;
        }
        for (o = 0; o < len; o++) Lc[o] /= d;
    }
    return -1;
}

/* Numeric work of group J: scatter A, apply the queued groups, factor the columns of J (left-looking
   over panels of 4 columns), queue J. Returns -1 or the permuted column with an unacceptable pivot.
   iw: 2n ints of thread workspace. */
static amps_int amps__fgroup(amps_factor *F, amps__fpriv *P, const double *Ax, amps_int J, amps_int *iw, amps_int sub) {
    amps_int s = P->gs[J], e = P->gs[J + 1] - 1, nJ = F->Lp[e + 1] - F->Lp[e], K, c0, bad;
    amps_int *rel = iw;
    amps__scatter(F, P, Ax, s, e);
    amps__rowmaps(F, s, e, rel);
    while ((K = P->head[J]) >= 0) {
        amps_int b = amps__span(F, P, K, e);
        P->head[J] = P->next[K];
        amps__update(F, P, K, s, e, P->gpos[K], b, rel, 0, 1);
        P->gpos[K] = b;
        amps__link(F, P, K, sub);
    }
    for (c0 = s; c0 <= e; c0 += 4) {
        amps_int tc = e + 1 - c0 < 4 ? e + 1 - c0 : 4;
        amps__panel_rect(F, s, c0, c0, tc, 0, (e - c0 - tc + 1) + nJ);
        bad = amps__panel_factor(F, P, Ax, e, s, c0, c0, tc, rel, 1);
        if (bad >= 0) return bad;
    }
    P->gpos[J] = 0;
    amps__link(F, P, J, sub);
    return -1;
}

#ifdef _OPENMP
/* amps__fgroup for a top-part group on nt threads: targets of the queued updates and panels of a
   superblock are split by 4-column blocks; same arithmetic per entry as amps__fgroup (the k chunks
   stay aligned at s). Uses the workspace of threads 0 and 1. */
static amps_int amps__fgroup_par(amps_factor *F, amps__fpriv *P, const double *Ax, amps_int J, int nt) {
    amps_int s = P->gs[J], e = P->gs[J + 1] - 1, nJ = F->Lp[e + 1] - F->Lp[e], n = F->n, cnt = 0, bad = -1;
    amps_int *rel = P->iwork, *kl = P->iwork + 2 * n, *kb = P->iwork + 3 * n;
#pragma omp parallel num_threads(nt)
    {
        int tid = omp_get_thread_num(), T = omp_get_num_threads();
        amps_int c, i, c0, cb;
#pragma omp for schedule(static)
        for (c = s; c <= e; c++) amps__scatter(F, P, Ax, c, c);
#pragma omp single
        {
            amps_int K;
            amps__rowmaps(F, s, e, rel);
            while ((K = P->head[J]) >= 0) {
                P->head[J] = P->next[K];
                kl[cnt] = K;
                kb[cnt++] = amps__span(F, P, K, e);
            }
        }
        for (i = 0; i < cnt; i++) amps__update(F, P, kl[i], s, e, P->gpos[kl[i]], kb[i], rel, tid, T);
#pragma omp barrier
#pragma omp single
        for (i = 0; i < cnt; i++) {
            P->gpos[kl[i]] = kb[i];
            amps__link(F, P, kl[i], -1);
        }
        /* superblocks of AMPS__SBLK columns: updates from the columns before it in parallel (panels
           owned cyclically), then its own factorization on one thread */
        for (cb = s; cb <= e; cb += AMPS__SBLK) {
            amps_int ce = cb + AMPS__SBLK <= e + 1 ? cb + AMPS__SBLK : e + 1, ip;
            if (cb > s) {
                for (c0 = cb, ip = 0; c0 < ce; c0 += 4, ip++) {
                    amps_int tc = ce - c0 < 4 ? ce - c0 : 4;
                    if (ip % T != tid) continue;
                    amps__panel_rect(F, s, cb, c0, tc, 0, (e - c0 - tc + 1) + nJ);
                    amps__panel_factor(F, P, Ax, e, s, cb, c0, tc, rel, 0);
                }
#pragma omp barrier
            }
#pragma omp single
            for (c0 = cb; c0 < ce && bad < 0; c0 += 4) {
                amps_int tc = ce - c0 < 4 ? ce - c0 : 4;
                amps__panel_rect(F, cb, c0, c0, tc, 0, (e - c0 - tc + 1) + nJ);
                bad = amps__panel_factor(F, P, Ax, e, cb, c0, c0, tc, rel, 1);
            }
            if (bad >= 0) break;
        }
    }
    if (bad < 0) {
        P->gpos[J] = 0;
        amps__link(F, P, J, -1);
    }
    return bad;
}
#endif

AMPS_API amps_status amps_factorize(amps_ctx *ctx, amps_factor *F, const amps_csc *A, amps_stype stype) {
    amps__fpriv *P;
    amps_int n, k, g, i, bad = -1, nsub;
    const double *Ax;
    int nt;
    if (!F || !F->priv || !A) return amps__err(ctx, AMPS_ERR_ARG, "amps_factorize: NULL argument");
    P = AMPS__CAST(amps__fpriv *, F->priv);
    n = F->n;
    if (A->nrow != n || A->ncol != n || !A->p || (A->p[n] > 0 && (!A->i || !A->x)))
        return amps__err(ctx, AMPS_ERR_ARG, "amps_factorize: matrix is %lld x %lld (values %s), factor is for n = %lld",
                         (long long)A->nrow, (long long)A->ncol, A->x ? "present" : "missing", (long long)n);
    if (stype != P->stype)
        return amps__err(ctx, AMPS_ERR_ARG, "amps_factorize: stype %d differs from the analyzed stype %d", (int)stype,
                         (int)P->stype);
    if (A->p[n] != P->nnzA || amps__pattern_hash(A) != P->hash)
        return amps__err(ctx, AMPS_ERR_PATTERN, "amps_factorize: pattern differs from the analyzed one");
    Ax = A->x;
    for (k = 0; k < n; k++) {
        amps_int p;
        for (p = A->p[k]; p < A->p[k + 1]; p++)
            if (!amps__isfinite(Ax[p]))
                return amps__err(ctx, AMPS_ERR_VALUE, "amps_factorize: non-finite value at column %lld, row %lld",
                                 (long long)k, (long long)A->i[p]);
    }
    F->is_numeric = 0;
    nsub = P->nsub;
    for (g = 0; g < P->ng; g++) P->head[g] = -1;
    for (i = 0; i <= nsub; i++) P->fail[i] = -1;
    nt = P->work < P->parmin ? 1 : amps__nthreads(ctx, P->nthr < nsub ? P->nthr : (nsub > 0 ? nsub : 1));
    (void)nt;
#ifdef _OPENMP
#pragma omp parallel for schedule(dynamic, 1) num_threads(nt)
#endif
    for (i = 0; i < nsub; i++) {
        amps_int *iw = P->iwork;
        amps_int q;
#ifdef _OPENMP
        iw += (size_t)omp_get_thread_num() * 2 * (size_t)F->n;
#endif
        for (q = P->subp[i]; q < P->subp[i + 1]; q++) {
            amps_int col = amps__fgroup(F, P, Ax, P->subg[q], iw, i);
            if (col >= 0) { P->fail[i] = col; break; }
        }
    }
    for (i = 0; i < nsub; i++)
        if (P->fail[i] >= 0 && (bad < 0 || P->fail[i] < bad)) bad = P->fail[i];
    if (bad < 0) {
        for (g = 0; g < P->ng; g++)
            if (P->gsub[g] >= 0) amps__link(F, P, g, -1);
        int ntp = P->work < P->parmin ? 1 : amps__nthreads(ctx, P->nthr);
        (void)ntp;
        for (k = 0; k < P->ntop && bad < 0; k++) {
            amps_int J = P->topg[k], s = P->gs[J], e = P->gs[J + 1] - 1;
#ifdef _OPENMP
            if (ntp > 1 && (double)(F->Lp[e + 1] - F->Lp[s]) * (double)(e - s + 1) >= P->pargroup) {
                bad = amps__fgroup_par(F, P, Ax, J, ntp);
                continue;
            }
#endif
            (void)s; (void)e;
            bad = amps__fgroup(F, P, Ax, J, P->iwork, -1);
        }
    }
    if (bad >= 0) {
        amps_int p;
        double acc = 0;
        for (p = A->p[F->perm[bad]]; p < A->p[F->perm[bad] + 1]; p++)
            if (A->i[p] == F->perm[bad]) acc = Ax[p];
        return amps__err(ctx, AMPS_ERR_NOT_SPD,
                         "amps_factorize: matrix not positive definite: pivot %.3g at column %lld (original numbering; "
                         "diagonal %.3g)", F->D[bad], (long long)F->perm[bad], acc);
    }
    F->is_numeric = 1;
    return AMPS_OK;
}

/* ================= triangular solves and closures impl ================= */
/* @@SECTION solve: owned by core */

AMPS_API amps_status amps_marker_init(amps_ctx *ctx, amps_marker *m, amps_int n) {
    amps_int *mark;
    if (!m || n < 0) return amps__err(ctx, AMPS_ERR_ARG, "amps_marker_init: %s", m ? "negative size" : "NULL marker");
    mark = AMPS__CAST(amps_int *, amps__calloc(ctx, (size_t)n, sizeof(amps_int)));
    if (!mark) return amps__err(ctx, AMPS_ERR_OOM, "amps_marker_init: out of memory (n %lld)", (long long)n);
    m->mark = mark;
    m->n = n;
    m->stamp = 1;
    return AMPS_OK;
}

AMPS_API void amps_marker_free(amps_ctx *ctx, amps_marker *m) {
    if (!m) return;
    amps__free(ctx, m->mark);
    m->mark = NULL;
    m->n = 0;
}

AMPS_API void amps_marker_next(amps_marker *m) {
    if (m->stamp >= AMPS__IMAX - 1 || m->stamp < 1) { /* wrap: clear all marks */
        amps_int j;
        for (j = 0; j < m->n; j++) m->mark[j] = 0;
        m->stamp = 1;
    } else {
        m->stamp++;
    }
}

/* Ascending in-place heapsort of a[0..n). */
static void amps__isort(amps_int *a, amps_int n) {
    amps_int i, k, c, t, end;
    if (n < 2) return;
    for (i = n / 2 - 1; i >= 0; i--)
        for (k = i; (c = 2 * k + 1) < n; k = c) {
            if (c + 1 < n && a[c + 1] > a[c]) c++;
            if (a[k] >= a[c]) break;
            t = a[k]; a[k] = a[c]; a[c] = t;
        }
    for (end = n - 1; end > 0; end--) {
        t = a[0]; a[0] = a[end]; a[end] = t;
        for (k = 0; (c = 2 * k + 1) < end; k = c) {
            if (c + 1 < end && a[c + 1] > a[c]) c++;
            if (a[k] >= a[c]) break;
            t = a[k]; a[k] = a[c]; a[c] = t;
        }
    }
}

AMPS_API amps_int amps_closure(const amps_factor *F, amps_int nidx, const amps_int *idx, amps_int *out, amps_marker *m) {
    amps_int k, cnt = 0, j, lg = 0;
    amps_int *mark = m->mark;
    amps_marker_next(m);
    for (k = 0; k < nidx; k++) {
        for (j = idx[k]; j >= 0 && mark[j] != m->stamp; j = F->parent[j]) {
            AMPS_ASSERT(j < F->n);
            mark[j] = m->stamp;
            out[cnt++] = j;
        }
    }
    for (k = cnt; k > 1; k >>= 1) lg++;
    if ((double)cnt * (double)(lg + 1) > (double)F->n) { /* scanning the marks is cheaper than sorting */
        for (j = 0, k = 0; j < F->n; j++)
            if (mark[j] == m->stamp) out[k++] = j;
    } else {
        amps__isort(out, cnt);
    }
    return cnt;
}

/* x := L^{-1} x on columns c0..ke of one group (ke its last column; width-1 groups are plain columns). */
static void amps__fwd(const amps_factor *F, amps_int c0, amps_int ke, double *x) {
    const amps_int *Lp = F->Lp;
    const double *Lx = F->Lx;
    const amps_int *S = F->Li + Lp[ke];
    amps_int ns = Lp[ke + 1] - Lp[ke], c, o, p;
    for (c = c0; c < ke; c++) {
        const double *Lc = Lx + Lp[c];
        double xc = x[c];
        for (o = 0; o < ke - c; o++) x[c + 1 + o] -= Lc[o] * xc;
    }
    for (c = c0; c <= ke;) {
        amps_int kc = ke + 1 - c;
        if (kc >= 8) {
            const double *s0 = Lx + Lp[c] + (ke - c), *s1 = Lx + Lp[c + 1] + (ke - c - 1);
            const double *s2 = Lx + Lp[c + 2] + (ke - c - 2), *s3 = Lx + Lp[c + 3] + (ke - c - 3);
            const double *s4 = Lx + Lp[c + 4] + (ke - c - 4), *s5 = Lx + Lp[c + 5] + (ke - c - 5);
            const double *s6 = Lx + Lp[c + 6] + (ke - c - 6), *s7 = Lx + Lp[c + 7] + (ke - c - 7);
            const double x0 = x[c], x1 = x[c + 1], x2 = x[c + 2], x3 = x[c + 3];
            const double x4 = x[c + 4], x5 = x[c + 5], x6 = x[c + 6], x7 = x[c + 7];
            for (p = 0; p < ns; p++)
                x[S[p]] -= (s0[p] * x0 + s1[p] * x1 + s2[p] * x2 + s3[p] * x3) +
                           (s4[p] * x4 + s5[p] * x5 + s6[p] * x6 + s7[p] * x7);
            c += 8;
        } else if (kc >= 4) {
            const double *s0 = Lx + Lp[c] + (ke - c), *s1 = Lx + Lp[c + 1] + (ke - c - 1);
            const double *s2 = Lx + Lp[c + 2] + (ke - c - 2), *s3 = Lx + Lp[c + 3] + (ke - c - 3);
            const double x0 = x[c], x1 = x[c + 1], x2 = x[c + 2], x3 = x[c + 3];
            for (p = 0; p < ns; p++) x[S[p]] -= s0[p] * x0 + s1[p] * x1 + s2[p] * x2 + s3[p] * x3;
            c += 4;
        } else if (kc == 3) {
            const double *s0 = Lx + Lp[c] + 2, *s1 = Lx + Lp[c + 1] + 1, *s2 = Lx + Lp[c + 2];
            const double x0 = x[c], x1 = x[c + 1], x2 = x[c + 2];
            for (p = 0; p < ns; p++) x[S[p]] -= s0[p] * x0 + s1[p] * x1 + s2[p] * x2;
            c += 3;
        } else if (kc == 2) {
            const double *s0 = Lx + Lp[c] + 1, *s1 = Lx + Lp[c + 1];
            const double x0 = x[c], x1 = x[c + 1];
            for (p = 0; p < ns; p++) x[S[p]] -= s0[p] * x0 + s1[p] * x1;
            c += 2;
        } else {
            const double *s0 = Lx + Lp[c];
            const double x0 = x[c];
            for (p = 0; p < ns; p++) x[S[p]] -= s0[p] * x0;
            c += 1;
        }
    }
}

/* x := L^{-T} x on columns c0..ke of one group (rows above c0 untouched). */
static void amps__bwd(const amps_factor *F, amps_int c0, amps_int ke, double *x) {
    const amps_int *Lp = F->Lp;
    const double *Lx = F->Lx;
    const amps_int *S = F->Li + Lp[ke];
    amps_int ns = Lp[ke + 1] - Lp[ke], c, o, p;
    for (c = c0; c <= ke;) {
        amps_int kc = ke + 1 - c;
        if (kc >= 8) {
            const double *s0 = Lx + Lp[c] + (ke - c), *s1 = Lx + Lp[c + 1] + (ke - c - 1);
            const double *s2 = Lx + Lp[c + 2] + (ke - c - 2), *s3 = Lx + Lp[c + 3] + (ke - c - 3);
            const double *s4 = Lx + Lp[c + 4] + (ke - c - 4), *s5 = Lx + Lp[c + 5] + (ke - c - 5);
            const double *s6 = Lx + Lp[c + 6] + (ke - c - 6), *s7 = Lx + Lp[c + 7] + (ke - c - 7);
            double t0 = 0, t1 = 0, t2 = 0, t3 = 0, t4 = 0, t5 = 0, t6 = 0, t7 = 0;
            for (p = 0; p < ns; p++) {
                double xs = x[S[p]];
                t0 += s0[p] * xs; t1 += s1[p] * xs; t2 += s2[p] * xs; t3 += s3[p] * xs;
                t4 += s4[p] * xs; t5 += s5[p] * xs; t6 += s6[p] * xs; t7 += s7[p] * xs;
            }
            x[c] -= t0; x[c + 1] -= t1; x[c + 2] -= t2; x[c + 3] -= t3;
            x[c + 4] -= t4; x[c + 5] -= t5; x[c + 6] -= t6; x[c + 7] -= t7;
            c += 8;
        } else if (kc >= 4) {
            const double *s0 = Lx + Lp[c] + (ke - c), *s1 = Lx + Lp[c + 1] + (ke - c - 1);
            const double *s2 = Lx + Lp[c + 2] + (ke - c - 2), *s3 = Lx + Lp[c + 3] + (ke - c - 3);
            double t0 = 0, t1 = 0, t2 = 0, t3 = 0;
            for (p = 0; p < ns; p++) {
                double xs = x[S[p]];
                t0 += s0[p] * xs; t1 += s1[p] * xs; t2 += s2[p] * xs; t3 += s3[p] * xs;
            }
            x[c] -= t0; x[c + 1] -= t1; x[c + 2] -= t2; x[c + 3] -= t3;
            c += 4;
        } else if (kc == 3) {
            const double *s0 = Lx + Lp[c] + 2, *s1 = Lx + Lp[c + 1] + 1, *s2 = Lx + Lp[c + 2];
            double t0 = 0, t1 = 0, t2 = 0;
            for (p = 0; p < ns; p++) {
                double xs = x[S[p]];
                t0 += s0[p] * xs; t1 += s1[p] * xs; t2 += s2[p] * xs;
            }
            x[c] -= t0; x[c + 1] -= t1; x[c + 2] -= t2;
            c += 3;
        } else if (kc == 2) {
            const double *s0 = Lx + Lp[c] + 1, *s1 = Lx + Lp[c + 1];
            double t0 = 0, t1 = 0;
            for (p = 0; p < ns; p++) {
                double xs = x[S[p]];
                t0 += s0[p] * xs; t1 += s1[p] * xs;
            }
            x[c] -= t0; x[c + 1] -= t1;
            c += 2;
        } else {
            const double *s0 = Lx + Lp[c];
            double t0 = 0;
            for (p = 0; p < ns; p++) t0 += s0[p] * x[S[p]];
            x[c] -= t0;
            c += 1;
        }
    }
    for (c = ke - 1; c >= c0; c--) {
        const double *Lc = Lx + Lp[c];
        double t = 0;
        for (o = 0; o < ke - c; o++) t += Lc[o] * x[c + 1 + o];
        x[c] -= t;
    }
}

AMPS_API void amps_lsolve(const amps_factor *F, double *x) {
    const amps__fpriv *P = AMPS__CAST(const amps__fpriv *, F->priv);
    amps_int g, c;
    if (P) for (g = 0; g < P->ng; g++) amps__fwd(F, P->gs[g], P->gs[g + 1] - 1, x);
    else for (c = 0; c < F->n; c++) amps__fwd(F, c, c, x);
}

AMPS_API void amps_dsolve(const amps_factor *F, double *x) {
    amps_int k;
    for (k = 0; k < F->n; k++) x[k] /= F->D[k];
}

AMPS_API void amps_ltsolve(const amps_factor *F, double *x) {
    const amps__fpriv *P = AMPS__CAST(const amps__fpriv *, F->priv);
    amps_int g, c;
    if (P) for (g = P->ng - 1; g >= 0; g--) amps__bwd(F, P->gs[g], P->gs[g + 1] - 1, x);
    else for (c = F->n - 1; c >= 0; c--) amps__bwd(F, c, c, x);
}

AMPS_API amps_status amps_solve(amps_ctx *ctx, const amps_factor *F, const double *b, double *x, double *work) {
    amps_int k, n;
    if (!F || !b || !x || !work) return amps__err(ctx, AMPS_ERR_ARG, "amps_solve: NULL argument");
    if (!F->is_numeric) return amps__err(ctx, AMPS_ERR_STATE, "amps_solve: factor has no numeric values");
    n = F->n;
    for (k = 0; k < n; k++) work[k] = b[F->perm[k]];
    amps_lsolve(F, work);
    amps_dsolve(F, work);
    amps_ltsolve(F, work);
    for (k = 0; k < n; k++) x[F->perm[k]] = work[k];
    return AMPS_OK;
}

AMPS_API amps_int amps_lsolve_sparse(const amps_factor *F, amps_int nb, const amps_int *bi, double *x,
                                     amps_int *closure, amps_marker *m) {
    amps__fpriv *P = AMPS__CAST(amps__fpriv *, F->priv);
    amps_int cnt = amps_closure(F, nb, bi, closure, m), k, c, ke;
    for (k = 0; k < cnt; k += ke - c + 1) {
        c = closure[k];
        ke = P ? P->gs[P->cgrp[c] + 1] - 1 : c;
        AMPS_ASSERT(k + ke - c < cnt && closure[k + ke - c] == ke);
        amps__fwd(F, c, ke, x);
#ifdef AMPS_COUNT_TOUCH
        if (P) P->touch += (double)(F->Lp[ke + 1] - F->Lp[c]);
#endif
    }
    return cnt;
}

AMPS_API amps_int amps_ltsolve_partial(const amps_factor *F, amps_int nreq, const amps_int *req, double *y,
                                       amps_int *closure, amps_marker *m) {
    amps__fpriv *P = AMPS__CAST(amps__fpriv *, F->priv);
    amps_int cnt = amps_closure(F, nreq, req, closure, m), k, j, ke, s;
    for (k = cnt - 1; k >= 0; k = j - 1) {
        ke = closure[k];
        s = P ? P->gs[P->cgrp[ke]] : ke;
        for (j = k; j > 0 && closure[j - 1] >= s; j--) {}
        amps__bwd(F, closure[j], ke, y);
#ifdef AMPS_COUNT_TOUCH
        if (P) P->touch += (double)(F->Lp[ke + 1] - F->Lp[closure[j]]);
#endif
    }
    return cnt;
}

#ifdef AMPS_COUNT_TOUCH
AMPS_API double amps_touch_count(const amps_factor *F) {
    const amps__fpriv *P = AMPS__CAST(const amps__fpriv *, F->priv);
    return P ? P->touch : 0.0;
}
AMPS_API void amps_touch_reset(const amps_factor *F) {
    amps__fpriv *P = AMPS__CAST(amps__fpriv *, F->priv);
    if (P) P->touch = 0.0;
}
#endif

/* Blocks of 4 right-hand sides are solved together, interleaved (w[4k + r]). */
#define AMPS__RHSB 4

AMPS_API size_t amps_solve_multi_work(const amps_ctx *ctx, const amps_factor *F, amps_int nrhs) {
    amps_int nblk = (nrhs + AMPS__RHSB - 1) / AMPS__RHSB;
    if (!F || nrhs <= 0) return 0;
    return (size_t)amps__nthreads(ctx, nblk) * AMPS__RHSB * (size_t)F->n;
}

/* w := L^{-1} w, D^{-1} w, L^{-T} w for 4 interleaved vectors. */
static void amps__solve4(const amps_factor *F, double *w) {
    const amps_int *Lp = F->Lp, *Li = F->Li;
    const double *Lx = F->Lx;
    amps_int n = F->n, c, p;
    for (c = 0; c < n; c++) {
        const double x0 = w[4 * c], x1 = w[4 * c + 1], x2 = w[4 * c + 2], x3 = w[4 * c + 3];
        for (p = Lp[c]; p < Lp[c + 1]; p++) {
            double l = Lx[p], *y = w + 4 * (size_t)Li[p];
            y[0] -= l * x0; y[1] -= l * x1; y[2] -= l * x2; y[3] -= l * x3;
        }
    }
    for (c = 0; c < n; c++) {
        double d = F->D[c];
        w[4 * c] /= d; w[4 * c + 1] /= d; w[4 * c + 2] /= d; w[4 * c + 3] /= d;
    }
    for (c = n - 1; c >= 0; c--) {
        double t0 = 0, t1 = 0, t2 = 0, t3 = 0;
        for (p = Lp[c]; p < Lp[c + 1]; p++) {
            double l = Lx[p];
            const double *y = w + 4 * (size_t)Li[p];
            t0 += l * y[0]; t1 += l * y[1]; t2 += l * y[2]; t3 += l * y[3];
        }
        w[4 * c] -= t0; w[4 * c + 1] -= t1; w[4 * c + 2] -= t2; w[4 * c + 3] -= t3;
    }
}

AMPS_API amps_status amps_solve_multi(amps_ctx *ctx, const amps_factor *F, amps_int nrhs, const double *B, amps_int ldb,
                                      double *X, amps_int ldx, double *work) {
    amps_int nblk, blk, n;
    int nt;
    if (!F || nrhs < 0 || (nrhs > 0 && (!B || !X || !work)))
        return amps__err(ctx, AMPS_ERR_ARG, "amps_solve_multi: NULL argument or negative nrhs %lld", (long long)nrhs);
    if (!F->is_numeric) return amps__err(ctx, AMPS_ERR_STATE, "amps_solve_multi: factor has no numeric values");
    n = F->n;
    if (ldb < n || ldx < n)
        return amps__err(ctx, AMPS_ERR_ARG, "amps_solve_multi: leading dimension (ldb %lld, ldx %lld) below n = %lld",
                         (long long)ldb, (long long)ldx, (long long)n);
    nblk = (nrhs + AMPS__RHSB - 1) / AMPS__RHSB;
    nt = amps__nthreads(ctx, nblk > 0 ? nblk : 1);
    (void)nt;
#ifdef _OPENMP
#pragma omp parallel for schedule(dynamic, 1) num_threads(nt)
#endif
    for (blk = 0; blk < nblk; blk++) {
        double *w = work;
        amps_int r0 = blk * AMPS__RHSB, rc = nrhs - r0 < AMPS__RHSB ? nrhs - r0 : AMPS__RHSB, k, r;
#ifdef _OPENMP
        w += (size_t)omp_get_thread_num() * AMPS__RHSB * (size_t)n;
#endif
        for (k = 0; k < n; k++) {
            const double *bk = B + F->perm[k] + (size_t)r0 * (size_t)ldb;
            for (r = 0; r < AMPS__RHSB; r++) w[AMPS__RHSB * k + r] = r < rc ? bk[(size_t)r * (size_t)ldb] : 0.0;
        }
        if (rc == 1) {
            for (k = 0; k < n; k++) w[k] = w[AMPS__RHSB * k]; /* single vector: use the grouped kernels */
            amps_lsolve(F, w);
            amps_dsolve(F, w);
            amps_ltsolve(F, w);
            for (k = 0; k < n; k++) X[F->perm[k] + (size_t)r0 * (size_t)ldx] = w[k];
            continue;
        }
        amps__solve4(F, w);
        for (k = 0; k < n; k++) {
            double *xk = X + F->perm[k] + (size_t)r0 * (size_t)ldx;
            for (r = 0; r < rc; r++) xk[(size_t)r * (size_t)ldx] = w[AMPS__RHSB * k + r];
        }
    }
    return AMPS_OK;
}

/* ============================ augmented updates impl ============================ */
/* @@SECTION update: owned by engine */

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
