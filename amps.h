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
