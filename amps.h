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
    AMPS_ORDER_AUTO = 0,     /* least fill (symbolic count) of AMD, ND and METIS (when built in) */
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
    const double *coords;    /* optional: 3 coordinates per node (per block) for ND; per unknown
                                when block = 0 (a detected node takes its first unknown's) */
} amps_order_opts;

/* perm (size n) = fill-reducing ordering of symmetric A (stype part): perm[k] = original index k-th.
   Only the pattern of A is used; entries outside the stype triangle are rejected (any entry is
   accepted for AMPS_FULL, whose pattern is symmetrized). The nodes' unknowns stay consecutive and
   ascending. AMD/ND/METIS/AUTO orders are postordered (same fill, contiguous supernodes).
   Errors: AMPS_ERR_ARG (NULL, shapes, options, GIVEN not a permutation), AMPS_ERR_INDEX (row index
   or GIVEN entry out of range), AMPS_ERR_PATTERN (pointers, triangle), AMPS_ERR_VALUE (coords not
   finite), AMPS_ERR_UNSUPPORTED (METIS without AMPS_USE_METIS), AMPS_ERR_OOM. perm is written
   only on success. */
AMPS_API amps_status amps_order(amps_ctx *ctx, const amps_csc *A, amps_stype stype,
                                const amps_order_opts *opts, amps_int *perm);
/* AMD on a symmetric graph given in CSC with both triangles (diagonal entries ignored; a pattern
   given as one triangle is symmetrized). */
AMPS_API amps_status amps_amd(amps_ctx *ctx, amps_int n, const amps_int *Ap, const amps_int *Ai, amps_int *perm);
/* Nested dissection on the same kind of graph; xyz (3n, may be NULL) guides the bisections.
   Vertices with identical closed neighbourhoods (consecutive) are ordered together. */
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

#ifdef AMPS_USE_METIS
#ifdef __cplusplus
}
#endif
#include <metis.h>
#ifdef __cplusplus
extern "C" {
#endif
#endif

#define AMPS__IMAX ((amps_int)(~0ULL >> (65 - 8 * (int)sizeof(amps_int))))

/* ---------------------------- graph helpers ---------------------------- */

/* Allocates k amps_int arrays *pp[a] of len[a] entries; on failure frees the ones made. */
static amps_status amps__ialloc(amps_ctx *ctx, int k, amps_int **pp[], const size_t *len) {
    int a;
    for (a = 0; a < k; a++) {
        *pp[a] = (amps_int *)amps__malloc(ctx, len[a], sizeof(amps_int));
        if (!*pp[a]) {
            while (a-- > 0) { amps__free(ctx, *pp[a]); *pp[a] = NULL; }
            return AMPS_ERR_OOM;
        }
    }
    return AMPS_OK;
}

/* Checks the n x n CSC pattern Ap/Ai (stype part; entries outside it are rejected, any entry is
   accepted for stype 0) and returns its symmetric adjacency graph: both triangles, no diagonal,
   no duplicates, rows ascending. *Gp (n+1) and *Gi are allocated here; fn prefixes messages. */
static amps_status amps__graph_sym(amps_ctx *ctx, const char *fn, amps_int n, const amps_int *Ap, const amps_int *Ai,
                                   int stype, amps_int **Gp_out, amps_int **Gi_out) {
    amps_int j, p, i, nz, *Cp = NULL, *Ci = NULL, *w = NULL, *mk = NULL, *Gp = NULL, *Gi = NULL;
    amps_int **pp[5];
    size_t len[5];
    amps_status s;
    int sorted = 1;
    if (n > 0 && !Ap) return amps__err(ctx, AMPS_ERR_ARG, "%s: column pointer array is NULL", fn);
    if (n > 0 && Ap[0] != 0) return amps__err(ctx, AMPS_ERR_PATTERN, "%s: column pointer p[0] = %ld, must be 0", fn, (long)Ap[0]);
    for (j = 0; j < n; j++)
        if (Ap[j + 1] < Ap[j])
            return amps__err(ctx, AMPS_ERR_PATTERN, "%s: column pointers decrease at column %ld", fn, (long)j);
    nz = n > 0 ? Ap[n] : 0;
    if (nz > 0 && !Ai) return amps__err(ctx, AMPS_ERR_ARG, "%s: row index array is NULL", fn);
    if (nz > AMPS__IMAX / 2 - 1) return amps__err(ctx, AMPS_ERR_OOM, "%s: too many entries (%ld)", fn, (long)nz);
    for (j = 0; j < n; j++)
        for (p = Ap[j]; p < Ap[j + 1]; p++) {
            i = Ai[p];
            if (i < 0 || i >= n)
                return amps__err(ctx, AMPS_ERR_INDEX, "%s: row index %ld out of range [0,%ld) in column %ld", fn, (long)i,
                                 (long)n, (long)j);
            if ((stype > 0 && i > j) || (stype < 0 && i < j))
                return amps__err(ctx, AMPS_ERR_PATTERN, "%s: entry (%ld,%ld) is outside the %s triangle", fn, (long)i,
                                 (long)j, stype > 0 ? "upper" : "lower");
            if (p > Ap[j] && i <= Ai[p - 1]) sorted = 0;
        }
    if (stype != 0 && sorted) {
        /* one triangle, rows strictly increasing: no duplicates, and sweeping the columns in order
           appends to every row in increasing order */
        Gp = (amps_int *)amps__malloc(ctx, (size_t)n + 1, sizeof(amps_int));
        w = (amps_int *)amps__malloc(ctx, (size_t)n + 1, sizeof(amps_int));
        if (!Gp || !w) { amps__free(ctx, Gp); amps__free(ctx, w); return AMPS_ERR_OOM; }
        for (j = 0; j <= n; j++) Gp[j] = 0;
        for (j = 0; j < n; j++)
            for (p = Ap[j]; p < Ap[j + 1]; p++)
                if (Ai[p] != j) { Gp[Ai[p] + 1]++; Gp[j + 1]++; }
        for (j = 0; j < n; j++) { Gp[j + 1] += Gp[j]; w[j] = Gp[j]; }
        Gi = (amps_int *)amps__malloc(ctx, (size_t)Gp[n], sizeof(amps_int));
        if (!Gi) { amps__free(ctx, Gp); amps__free(ctx, w); return AMPS_ERR_OOM; }
        for (j = 0; j < n; j++)
            for (p = Ap[j]; p < Ap[j + 1]; p++)
                if ((i = Ai[p]) != j) { Gi[w[i]++] = j; Gi[w[j]++] = i; }
        amps__free(ctx, w);
        *Gp_out = Gp; *Gi_out = Gi;
        return AMPS_OK;
    }
    pp[0] = &Cp; pp[1] = &Ci; pp[2] = &w; pp[3] = &mk; pp[4] = &Gp;
    len[0] = (size_t)n + 1; len[1] = 2 * (size_t)nz; len[2] = (size_t)n + 1; len[3] = (size_t)n + 1; len[4] = (size_t)n + 1;
    if ((s = amps__ialloc(ctx, 5, pp, len)) != AMPS_OK) return s;
    /* C: both directions of every off-diagonal entry (duplicates allowed) */
    for (j = 0; j <= n; j++) Cp[j] = 0;
    for (j = 0; j < n; j++)
        for (p = Ap[j]; p < Ap[j + 1]; p++)
            if (Ai[p] != j) { Cp[Ai[p] + 1]++; Cp[j + 1]++; }
    for (j = 0; j < n; j++) Cp[j + 1] += Cp[j];
    for (j = 0; j < n; j++) w[j] = Cp[j];
    for (j = 0; j < n; j++)
        for (p = Ap[j]; p < Ap[j + 1]; p++)
            if ((i = Ai[p]) != j) { Ci[w[i]++] = j; Ci[w[j]++] = i; }
    /* G = C^T without duplicates; rows come out ascending */
    for (j = 0; j <= n; j++) Gp[j] = 0;
    for (j = 0; j < n; j++) mk[j] = -1;
    for (j = 0; j < n; j++)
        for (p = Cp[j]; p < Cp[j + 1]; p++)
            if (mk[i = Ci[p]] != j) { mk[i] = j; Gp[i + 1]++; }
    for (j = 0; j < n; j++) Gp[j + 1] += Gp[j];
    Gi = (amps_int *)amps__malloc(ctx, (size_t)(n > 0 ? Gp[n] : 0), sizeof(amps_int));
    if (!Gi) { amps__free(ctx, Cp); amps__free(ctx, Ci); amps__free(ctx, w); amps__free(ctx, mk); amps__free(ctx, Gp); return AMPS_ERR_OOM; }
    for (j = 0; j < n; j++) { mk[j] = -1; w[j] = Gp[j]; }
    for (j = 0; j < n; j++)
        for (p = Cp[j]; p < Cp[j + 1]; p++)
            if (mk[i = Ci[p]] != j) { mk[i] = j; Gi[w[i]++] = j; }
    amps__free(ctx, Cp); amps__free(ctx, Ci); amps__free(ctx, w); amps__free(ctx, mk);
    *Gp_out = Gp; *Gi_out = Gi;
    return AMPS_OK;
}

/* Groups of consecutive vertices with identical closed neighbourhoods in the sorted graph G:
   writes gfirst[0..ng] (group g = vertices gfirst[g] .. gfirst[g+1]-1) and returns ng. */
static amps_int amps__graph_runs(amps_int n, const amps_int *Gp, const amps_int *Gi, amps_int *gfirst) {
    amps_int j, ng = 0;
    for (j = 0; j < n; j++) {
        int same = 0;
        if (j > 0 && Gp[j] - Gp[j - 1] == Gp[j + 1] - Gp[j]) {
            /* closed neighbourhoods of a = j-1 and b = j agree iff b in adj(a) and
               adj(a) \ {b} == adj(b) \ {a} (both sorted) */
            amps_int a = j - 1, b = j, p = Gp[a], q = Gp[b], pe = Gp[a + 1], qe = Gp[b + 1];
            int hit = 0;
            same = 1;
            while (same) {
                if (p < pe && Gi[p] == b) { p++; hit = 1; continue; }
                if (q < qe && Gi[q] == a) { q++; continue; }
                if (p >= pe || q >= qe) { same = (p >= pe && q >= qe); break; }
                if (Gi[p] != Gi[q]) same = 0;
                p++; q++;
            }
            same = same && hit;
        }
        if (!same) gfirst[ng++] = j;
    }
    gfirst[ng] = n;
    return ng;
}

/* Quotient graph of G for the groups gfirst[0..ng] (consecutive vertex ranges): node adjacency
   without self loops or duplicates, and weights (group sizes). same: the members of each group
   have identical closed neighbourhoods (only the first is scanned). Allocates *Qp, *Qi, *Qw. */
static amps_status amps__graph_quotient(amps_ctx *ctx, amps_int n, const amps_int *Gp, const amps_int *Gi, amps_int ng,
                                        const amps_int *gfirst, int same, amps_int **Qp_out, amps_int **Qi_out,
                                        amps_int **Qw_out) {
    amps_int g, j, p, h, nz, *gid = NULL, *mk = NULL, *Qp = NULL, *Qi = NULL, *Qw = NULL;
    amps_int **pp[4];
    size_t len[4];
    amps_status s;
    pp[0] = &gid; pp[1] = &mk; pp[2] = &Qp; pp[3] = &Qw;
    len[0] = (size_t)n + 1; len[1] = (size_t)ng + 1; len[2] = (size_t)ng + 1; len[3] = (size_t)ng + 1;
    if ((s = amps__ialloc(ctx, 4, pp, len)) != AMPS_OK) return s;
    for (g = 0; g < ng; g++) {
        for (j = gfirst[g]; j < gfirst[g + 1]; j++) gid[j] = g;
        mk[g] = -1;
        Qw[g] = gfirst[g + 1] - gfirst[g];
    }
    for (nz = 0, g = 0; g < ng; g++) {
        Qp[g] = nz;
        for (j = gfirst[g]; j < (same ? gfirst[g] + 1 : gfirst[g + 1]); j++)
            for (p = Gp[j]; p < Gp[j + 1]; p++)
                if ((h = gid[Gi[p]]) != g && mk[h] != g) { mk[h] = g; nz++; }
    }
    Qp[ng] = nz;
    Qi = (amps_int *)amps__malloc(ctx, (size_t)nz, sizeof(amps_int));
    if (!Qi) { amps__free(ctx, gid); amps__free(ctx, mk); amps__free(ctx, Qp); amps__free(ctx, Qw); return AMPS_ERR_OOM; }
    for (g = 0; g < ng; g++) mk[g] = -1;
    for (nz = 0, g = 0; g < ng; g++)
        for (j = gfirst[g]; j < (same ? gfirst[g] + 1 : gfirst[g + 1]); j++)
            for (p = Gp[j]; p < Gp[j + 1]; p++)
                if ((h = gid[Gi[p]]) != g && mk[h] != g) { mk[h] = g; Qi[nz++] = h; }
    amps__free(ctx, gid); amps__free(ctx, mk);
    *Qp_out = Qp; *Qi_out = Qi; *Qw_out = Qw;
    return AMPS_OK;
}

/* ------------------------- approximate minimum degree ------------------------- */
/* Amestoy, Davis & Duff (1996). The quotient graph lives in iw: a variable's list holds its
   elen elements first, then its variables; an element's list holds its variables. */

enum { AMPS__AMD_VAR = 0, AMPS__AMD_ELEM = 1, AMPS__AMD_DEAD = 2, AMPS__AMD_DENSE = 3 };

/* Compacts the live lists of iw to its front; returns the new end of used space. */
static amps_int amps__amd_gc(amps_int n, amps_int *iw, amps_int pfree, amps_int *pe, const amps_int *len,
                             const unsigned char *kind) {
    amps_int j, src, dst, q;
    for (j = 0; j < n; j++)
        if ((kind[j] == AMPS__AMD_VAR || kind[j] == AMPS__AMD_ELEM) && len[j] > 0) {
            q = pe[j];
            pe[j] = iw[q];       /* save the first entry, */
            iw[q] = -(j + 1);    /* and mark the list head */
        }
    for (src = 0, dst = 0; src < pfree;) {
        if (iw[src] < 0) {
            j = -iw[src] - 1;
            iw[dst] = pe[j];
            pe[j] = dst;
            for (q = 1; q < len[j]; q++) iw[dst + q] = iw[src + q];
            dst += len[j];
            src += len[j];
        } else {
            src++;
        }
    }
    return dst;
}

/* AMD ordering of a clean symmetric graph (no diagonal, no duplicates) with vertex weights vw
   (NULL = 1). Only vertices 0..nfree-1 are ordered; vertices nfree..n-1 take part in the degrees
   but are never eliminated (constrained to come later). order[0..nfree-1] receives the elimination
   order. dense: weighted degree above which a free vertex is ordered last (<= 0: default
   max(16, 10 sqrt(total weight))). */
static amps_status amps__amd_core(amps_ctx *ctx, amps_int n, const amps_int *Gp, const amps_int *Gi, const amps_int *vw,
                                  amps_int nfree, double dense, amps_int *order) {
    amps_int *mem, *iw, *pe, *len, *elen, *nv, *deg, *wv, *head, *next, *last, *hhead, *hnext, *hkey, *mk, *rep, *lme,
        *estep, *cnt;
    unsigned char *kind;
    amps_int i, j, k, p, q, e, me, nz, ntot, nleft, mindeg, pfree, iwlen, wbase, wmax, stamp, nsteps, ndense;
    size_t need;
    nz = n > 0 ? Gp[n] : 0;
    if (n <= 0 || nfree <= 0) return AMPS_OK;
    ntot = 0;
    for (i = 0; i < n; i++) ntot += vw ? vw[i] : 1;
    if ((double)nz + nz / 5 + 2.0 * n + 16 > (double)AMPS__IMAX) return amps__err(ctx, AMPS_ERR_OOM, "graph too large for AMD (%ld entries)", (long)nz);
    iwlen = nz + nz / 5 + 2 * n + 16;
    need = 17 * (size_t)n + (size_t)ntot + 8;
    mem = (amps_int *)amps__malloc(ctx, need, sizeof(amps_int));
    iw = (amps_int *)amps__malloc(ctx, (size_t)iwlen, sizeof(amps_int));
    kind = (unsigned char *)amps__calloc(ctx, (size_t)n, 1);
    if (!mem || !iw || !kind) { amps__free(ctx, mem); amps__free(ctx, iw); amps__free(ctx, kind); return AMPS_ERR_OOM; }
    pe = mem; len = pe + n; elen = len + n; nv = elen + n; deg = nv + n; wv = deg + n;
    next = wv + n; last = next + n; hhead = last + n; hnext = hhead + n; hkey = hnext + n; mk = hkey + n;
    rep = mk + n; lme = rep + n; estep = lme + n; cnt = estep + n; head = cnt + n + 1;

    /* dense free vertices are set aside and ordered last */
    if (dense <= 0) { dense = 10.0 * sqrt((double)ntot); if (dense < 16) dense = 16; }
    for (i = 0; i < n; i++) {
        amps_int d = 0;
        for (p = Gp[i]; p < Gp[i + 1]; p++) d += vw ? vw[Gi[p]] : 1;
        kind[i] = (i < nfree && (double)d > dense) ? AMPS__AMD_DENSE : AMPS__AMD_VAR;
    }
    for (i = 0; i <= ntot; i++) head[i] = -1;
    pfree = 0; nleft = 0; ndense = 0;
    for (i = 0; i < n; i++) {
        amps_int d = 0;
        pe[i] = pfree; elen[i] = 0; rep[i] = -1; estep[i] = -1; wv[i] = 1; mk[i] = 0; hhead[i] = -1;
        nv[i] = vw ? vw[i] : 1;
        if (kind[i] == AMPS__AMD_DENSE) { len[i] = 0; ndense++; continue; }
        for (p = Gp[i]; p < Gp[i + 1]; p++)
            if (kind[j = Gi[p]] != AMPS__AMD_DENSE) { iw[pfree++] = j; d += vw ? vw[j] : 1; }
        len[i] = pfree - pe[i];
        deg[i] = d;
        if (i < nfree) nleft += nv[i];
    }
    mindeg = ntot;
    for (i = 0; i < nfree; i++) {
        if (kind[i] != AMPS__AMD_VAR) continue;
        next[i] = head[deg[i]]; last[i] = -1;
        if (head[deg[i]] >= 0) last[head[deg[i]]] = i;
        head[deg[i]] = i;
        if (deg[i] < mindeg) mindeg = deg[i];
    }
    wbase = 2; stamp = 0; nsteps = 0;

    while (nleft > 0) {
        amps_int nvpiv, degme, nl, pme;
        /* select a pivot of minimum approximate degree */
        while (head[mindeg] < 0) mindeg++;
        me = head[mindeg];
        head[mindeg] = next[me];
        if (next[me] >= 0) last[next[me]] = -1;
        nvpiv = nv[me];
        nv[me] = -nvpiv;
        degme = 0; nl = 0;

        /* Lme = (union of the elements of me) + (variables of me), minus me */
        for (q = 0; q < len[me]; q++) {
            amps_int x = iw[pe[me] + q], pb, pend;
            if (q < elen[me]) {
                if (kind[x] != AMPS__AMD_ELEM) continue;
                pb = pe[x]; pend = pb + len[x];
                kind[x] = AMPS__AMD_DEAD; /* absorbed into me */
                wv[x] = 0;
            } else {
                pb = pe[me] + q; pend = pb + 1;
            }
            for (p = pb; p < pend; p++) {
                i = iw[p];
                if (kind[i] != AMPS__AMD_VAR || nv[i] <= 0) continue;
                degme += nv[i];
                nv[i] = -nv[i];
                lme[nl++] = i;
                if (i < nfree) { /* leave the degree lists */
                    if (last[i] >= 0) next[last[i]] = next[i]; else head[deg[i]] = next[i];
                    if (next[i] >= 0) last[next[i]] = last[i];
                }
            }
        }
        kind[me] = AMPS__AMD_ELEM;
        len[me] = 0; elen[me] = 0;
        if (pfree + nl > iwlen) pfree = amps__amd_gc(n, iw, pfree, pe, len, kind);
        if (pfree + nl > iwlen) { /* not expected: the quotient graph never outgrows A */
            void *t = iw;
            if (amps__realloc(ctx, &t, (size_t)pfree + nl + n, sizeof(amps_int)) != AMPS_OK) {
                amps__free(ctx, kind); amps__free(ctx, mem); amps__free(ctx, iw);
                return AMPS_ERR_OOM;
            }
            iw = (amps_int *)t;
            iwlen = pfree + nl + n;
        }
        pme = pfree;
        pe[me] = pme;
        for (q = 0; q < nl; q++) iw[pme + q] = lme[q];
        len[me] = nl;
        pfree += nl;

        /* |Le \ Lme| for every element e adjacent to Lme: wv[e] - wbase */
        wmax = wbase;
        for (q = 0; q < nl; q++) {
            amps_int nvi;
            i = iw[pme + q];
            nvi = -nv[i];
            for (p = pe[i]; p < pe[i] + elen[i]; p++) {
                amps_int we;
                e = iw[p];
                we = wv[e];
                if (we >= wbase) wv[e] = we - nvi;
                else if (we != 0) {
                    wv[e] = deg[e] + wbase - nvi;
                    if (deg[e] + wbase > wmax) wmax = deg[e] + wbase;
                }
            }
        }

        /* degree update, element absorption, mass elimination, hashing */
        for (q = 0; q < nl; q++) {
            amps_int nvi, d = 0, ce, c, p1, pn, L;
            unsigned long h = 0;
            i = iw[pme + q];
            nvi = -nv[i];
            p1 = pe[i]; pn = p1; L = len[i];
            for (p = p1; p < p1 + elen[i]; p++) {
                amps_int dext;
                e = iw[p];
                if (wv[e] == 0) continue;
                dext = wv[e] - wbase;
                if (dext > 0) { d += dext; iw[pn++] = e; h += (unsigned long)e; }
                else { kind[e] = AMPS__AMD_DEAD; wv[e] = 0; } /* aggressive absorption: Le inside Lme */
            }
            ce = pn - p1;
            for (p = p1 + elen[i]; p < p1 + L; p++) {
                j = iw[p];
                if (kind[j] == AMPS__AMD_VAR && nv[j] > 0) { d += nv[j]; iw[pn++] = j; h += (unsigned long)j; }
            }
            c = pn - p1;
            if (d == 0 && i < nfree) {
                /* mass elimination: i is adjacent to Lme only */
                kind[i] = AMPS__AMD_DEAD; rep[i] = me;
                nvpiv += nvi; degme -= nvi;
                nv[i] = 0; len[i] = 0; elen[i] = 0;
                continue;
            }
            AMPS_ASSERT(c < L);
            /* put me first: [me, elements, variables] */
            if (c > ce) iw[p1 + c] = iw[p1 + ce];
            if (ce > 0) iw[p1 + ce] = iw[p1];
            iw[p1] = me;
            len[i] = c + 1; elen[i] = ce + 1;
            if (d < deg[i]) deg[i] = d;
            h += (unsigned long)me;
            hkey[i] = (amps_int)(h % (unsigned long)n);
            hnext[i] = hhead[hkey[i]];
            hhead[hkey[i]] = i;
        }

        /* supervariable detection: merge indistinguishable variables of Lme */
        for (q = 0; q < nl; q++) {
            amps_int a, b, prev;
            i = iw[pme + q];
            if (kind[i] != AMPS__AMD_VAR || nv[i] >= 0 || hhead[hkey[i]] < 0) continue;
            b = hhead[hkey[i]];
            hhead[hkey[i]] = -1;
            for (a = b; a >= 0; a = hnext[a]) {
                if (kind[a] != AMPS__AMD_VAR || hnext[a] < 0) continue;
                if (stamp >= AMPS__IMAX - 2) { for (k = 0; k < n; k++) mk[k] = 0; stamp = 0; }
                stamp++;
                for (p = pe[a]; p < pe[a] + len[a]; p++) mk[iw[p]] = stamp;
                prev = a;
                for (j = hnext[a]; j >= 0; j = hnext[j]) {
                    int same = len[j] == len[a] && elen[j] == elen[a] && ((a < nfree) == (j < nfree));
                    for (p = pe[j]; same && p < pe[j] + len[j]; p++) same = mk[iw[p]] == stamp;
                    if (same) {
                        nv[a] += nv[j]; /* both negative */
                        nv[j] = 0; kind[j] = AMPS__AMD_DEAD; rep[j] = a; len[j] = 0; elen[j] = 0;
                        hnext[prev] = hnext[j];
                    } else {
                        prev = j;
                    }
                }
            }
        }

        /* finalize degrees, restore weights, compact Lme */
        nleft -= nvpiv;
        for (k = 0, q = 0; q < nl; q++) {
            amps_int nvi, dd;
            i = iw[pme + q];
            if (kind[i] != AMPS__AMD_VAR || nv[i] >= 0) continue;
            nvi = -nv[i];
            nv[i] = nvi;
            dd = deg[i] + degme - nvi;
            if (i < nfree) {
                if (dd > nleft - nvi) dd = nleft - nvi;
                if (dd < 0) dd = 0;
                deg[i] = dd;
                next[i] = head[dd]; last[i] = -1;
                if (head[dd] >= 0) last[head[dd]] = i;
                head[dd] = i;
                if (dd < mindeg) mindeg = dd;
            } else {
                deg[i] = dd;
            }
            iw[pme + k++] = i;
        }
        len[me] = k;
        deg[me] = degme;
        nv[me] = nvpiv;
        estep[me] = nsteps++;
        if (wmax >= AMPS__IMAX - ntot - 2) {
            for (e = 0; e < n; e++) if (wv[e] != 0) wv[e] = 1;
            wbase = 2;
        } else {
            wbase = wmax + 1;
        }
    }

    /* order: pivots by step, each followed by the variables merged into it; dense last */
    for (k = 0; k <= nsteps; k++) cnt[k] = 0;
    for (i = 0; i < nfree; i++) {
        if (kind[i] == AMPS__AMD_DENSE) continue;
        j = i;
        while (estep[j] < 0) j = rep[j];
        k = j;
        for (j = i; estep[j] < 0;) { amps_int t = rep[j]; rep[j] = k; j = t; } /* path compression */
        cnt[estep[k] + 1]++;
    }
    for (k = 0; k < nsteps; k++) cnt[k + 1] += cnt[k];
    for (i = 0; i < nfree; i++)
        if (kind[i] != AMPS__AMD_DENSE && estep[i] >= 0) order[cnt[estep[i]]++] = i;
    for (i = 0; i < nfree; i++)
        if (kind[i] != AMPS__AMD_DENSE && estep[i] < 0) order[cnt[estep[rep[i]]]++] = i;
    k = nfree - ndense;
    for (i = 0; i < nfree; i++)
        if (kind[i] == AMPS__AMD_DENSE) order[k++] = i;
    amps__free(ctx, kind);
    amps__free(ctx, mem);
    amps__free(ctx, iw);
    return AMPS_OK;
}

/* ------------------------------ nested dissection ------------------------------ */

/* Tuning of the nested dissection (measured on FE meshes against METIS 5). */
#define AMPS__ND_LEAF 100     /* parts of at most this many nodes are ordered by AMD */
#define AMPS__ND_BAL 0.60     /* each side of a bisection holds at most this share of the weight */
#define AMPS__ND_COARSE 120   /* size of the coarsest graph of a multilevel bisection */
#define AMPS__ND_TRIES 6      /* greedy growings tried on the coarsest graph */
#define AMPS__ND_MIDN 2000    /* graphs this large are bisected AMPS__ND_MID times at an */
#define AMPS__ND_MID 5        /* intermediate level of at most AMPS__ND_MIDL coarsenings */
#define AMPS__ND_MIDL 4       /* (about n/16 vertices), keeping the best */
#define AMPS__ND_PASS 8       /* refinement passes per level */
#define AMPS__ND_WIN 0.10     /* plane cuts: each side holds 1/2 -+ this share */

/* Weighted graph for nested dissection: CSR adjacency (symmetric, no self loops), vertex weights,
   optional edge weights (NULL = 1) and coordinates (3 per vertex, may be NULL). */
typedef struct amps__ndg {
    amps_int n;
    amps_int *p, *i, *vw, *ew;
    double *xyz;
    amps_int *cmap;   /* vertex -> vertex of the next coarser graph */
} amps__ndg;

static void amps__ndg_free(amps_ctx *ctx, amps__ndg *g) {
    amps__free(ctx, g->p); amps__free(ctx, g->i); amps__free(ctx, g->vw); amps__free(ctx, g->ew);
    amps__free(ctx, g->xyz); amps__free(ctx, g->cmap);
    memset(g, 0, sizeof(*g));
}

/* Deterministic xorshift64* stream. */
static amps_int amps__rand(unsigned long long *s, amps_int m) {
    *s ^= *s >> 12; *s ^= *s << 25; *s ^= *s >> 27;
    return m > 0 ? (amps_int)(((*s) * 2685821657736338717ULL >> 17) % (unsigned long long)m) : 0;
}

/* Indexed binary max-heap over vertices 0..n-1 with keys key[v]; pos[v] = -1 when absent. */
typedef struct amps__heap { amps_int size, *h, *pos, *key; } amps__heap;

static void amps__heap_up(amps__heap *H, amps_int k) {
    amps_int v = H->h[k];
    while (k > 0) {
        amps_int par = (k - 1) / 2;
        if (H->key[H->h[par]] >= H->key[v]) break;
        H->h[k] = H->h[par]; H->pos[H->h[k]] = k; k = par;
    }
    H->h[k] = v; H->pos[v] = k;
}
static void amps__heap_down(amps__heap *H, amps_int k) {
    amps_int v = H->h[k];
    for (;;) {
        amps_int c = 2 * k + 1;
        if (c >= H->size) break;
        if (c + 1 < H->size && H->key[H->h[c + 1]] > H->key[H->h[c]]) c++;
        if (H->key[H->h[c]] <= H->key[v]) break;
        H->h[k] = H->h[c]; H->pos[H->h[k]] = k; k = c;
    }
    H->h[k] = v; H->pos[v] = k;
}
static void amps__heap_push(amps__heap *H, amps_int v, amps_int key) {
    H->key[v] = key;
    H->h[H->size] = v; H->pos[v] = H->size; H->size++;
    amps__heap_up(H, H->size - 1);
}
static void amps__heap_del(amps__heap *H, amps_int v) {
    amps_int k = H->pos[v], u;
    if (k < 0) return;
    H->pos[v] = -1;
    H->size--;
    if (k == H->size) return;
    u = H->h[H->size];
    H->h[k] = u; H->pos[u] = k;
    amps__heap_up(H, k);
    amps__heap_down(H, H->pos[u]);
}
static void amps__heap_set(amps__heap *H, amps_int v, amps_int key) {
    amps_int old;
    if (H->pos[v] < 0) return;
    old = H->key[v]; H->key[v] = key;
    if (key > old) amps__heap_up(H, H->pos[v]); else amps__heap_down(H, H->pos[v]);
}

/* Workspace of the separator refinement, sized for graphs of up to n vertices. */
typedef struct amps__fmws {
    amps_int n;
    amps__heap H;
    amps_int *mem, *ed, *lock, *sl, *sl2, *logv, *logw;
} amps__fmws;

static amps_status amps__fmws_init(amps_ctx *ctx, amps__fmws *W, amps_int n) {
    amps_int k, *m;
    size_t n1 = (size_t)n + 1;
    m = (amps_int *)amps__malloc(ctx, 11 * n1, sizeof(amps_int));
    if (!m) return AMPS_ERR_OOM;
    W->n = n; W->mem = m;
    W->H.size = 0; W->H.h = m; W->H.pos = m + n1; W->H.key = m + 2 * n1;
    W->ed = m + 3 * n1; W->lock = m + 4 * n1; W->sl = m + 5 * n1; W->sl2 = m + 6 * n1;
    W->logv = m + 7 * n1; W->logw = m + 9 * n1;
    for (k = 0; k < n; k++) { W->H.pos[k] = -1; W->lock[k] = 0; }
    return AMPS_OK;
}

/* Is state (sep s, part weights a, b) better than (bs, ba, bb)? Feasible (both parts <= maxpw)
   beats infeasible; then smaller separator, then better balance. */
static int amps__sep_better(amps_int s, amps_int a, amps_int b, amps_int bs, amps_int ba, amps_int bb, amps_int maxpw) {
    int f = a <= maxpw && b <= maxpw, bf = ba <= maxpw && bb <= maxpw;
    amps_int m = a > b ? a : b, bm = ba > bb ? ba : bb;
    if (f != bf) return f;
    if (!f) return m < bm;
    if (s != bs) return s < bs;
    return m < bm;
}

/* Vertex-separator refinement (Fiduccia-Mattheyses, one-sided passes alternating between the
   lighter and the heavier side): where[v] in {0,1,2} (2 = separator), pw[0..2] part weights
   (updated). Moving a separator vertex to side a pulls its neighbours on the other side into the
   separator; the best state of each pass is kept. */
static void amps__nd_fm(const amps__ndg *g, amps_int *where, amps_int *pw, amps_int maxpw, amps__fmws *W, int npass) {
    amps_int n = g->n, v, u, x, p, q, k, nlog, nlogmax, bestlog, bs, b0, b1, nbad, limit, ns = 0, *ed = W->ed;
    const amps_int *vw = g->vw;
    amps__heap *H = &W->H;
    int pass, idle = 0, a, b;
    limit = n / 100; /* moves without improvement before a pass stops */
    if (limit < 25) limit = 25;
    if (limit > 150) limit = 150;
    for (v = 0; v < n; v++)
        if (where[v] == 2) W->sl[ns++] = v;
    for (pass = 0; pass < npass; pass++) {
        amps_int s0 = pw[2], m0 = pw[0] > pw[1] ? pw[0] : pw[1], *t;
        a = (pass & 1) ? (pw[0] < pw[1] ? 1 : 0) : (pw[0] < pw[1] ? 0 : 1);
        b = 1 - a;
        H->size = 0;
        for (k = 0; k < ns; k++) {
            v = W->sl[k];
            ed[v] = 0;
            for (p = g->p[v]; p < g->p[v + 1]; p++)
                if (where[g->i[p]] == b) ed[v] += vw[g->i[p]];
            amps__heap_push(H, v, vw[v] - ed[v]);
        }
        nlog = 0; bestlog = 0; bs = pw[2]; b0 = pw[0]; b1 = pw[1]; nbad = 0; nlogmax = 0;
        while (H->size > 0) {
            v = H->h[0];
            if (pw[a] + vw[v] > maxpw) break;
            /* move v from the separator to side a */
            amps__heap_del(H, v);
            W->logv[nlog] = v; W->logw[nlog++] = 2;
            where[v] = a; pw[2] -= vw[v]; pw[a] += vw[v]; W->lock[v] = 1;
            for (p = g->p[v]; p < g->p[v + 1]; p++) {
                u = g->i[p];
                if (where[u] != b) continue;
                /* u joins the separator */
                W->logv[nlog] = u; W->logw[nlog++] = b;
                where[u] = 2; pw[b] -= vw[u]; pw[2] += vw[u];
                ed[u] = 0;
                for (q = g->p[u]; q < g->p[u + 1]; q++) {
                    x = g->i[q];
                    if (where[x] == 2) {
                        if (H->pos[x] >= 0) { ed[x] -= vw[u]; amps__heap_set(H, x, vw[x] - ed[x]); }
                    } else if (where[x] == b) {
                        ed[u] += vw[x];
                    }
                }
                amps__heap_push(H, u, vw[u] - ed[u]);
            }
            if (nlog > nlogmax) nlogmax = nlog;
            if (amps__sep_better(pw[2], pw[0], pw[1], bs, b0, b1, maxpw)) {
                bs = pw[2]; b0 = pw[0]; b1 = pw[1]; bestlog = nlog; nbad = 0;
            } else if (++nbad > limit) {
                break;
            }
        }
        /* roll back to the best state */
        while (nlog > bestlog) {
            nlog--;
            v = W->logv[nlog];
            pw[where[v]] -= vw[v];
            where[v] = W->logw[nlog];
            pw[where[v]] += vw[v];
        }
        for (k = 0; k < H->size; k++) H->pos[H->h[k]] = -1;
        H->size = 0;
        /* separator list: old separator plus touched vertices still in it (lock marks duplicates) */
        for (k = 0; k < nlogmax; k++) W->lock[W->logv[k]] = 0;
        t = W->sl2; q = 0;
        for (k = 0; k < ns + nlogmax; k++) {
            v = k < ns ? W->sl[k] : W->logv[k - ns];
            if (where[v] == 2 && !W->lock[v]) { W->lock[v] = 1; t[q++] = v; }
        }
        for (k = 0; k < q; k++) W->lock[t[k]] = 0;
        W->sl2 = W->sl; W->sl = t; ns = q;
        if (!amps__sep_better(pw[2], pw[0], pw[1], s0, m0, m0, maxpw) || bestlog == 0) {
            if (++idle >= 2) break;
        } else {
            idle = 0;
        }
    }
}

/* Turns a 2-way partition (where 0/1) into a vertex separator: every vertex still adjacent to
   the other side, visited in index order, joins the separator (a greedy cover of the cut edges).
   Sets pw[0..2]. */
static void amps__nd_sep_from_cut(const amps__ndg *g, amps_int *where, amps_int *pw) {
    amps_int v, p;
    for (v = 0; v < g->n; v++) {
        if (where[v] == 2) continue;
        for (p = g->p[v]; p < g->p[v + 1]; p++)
            if (where[g->i[p]] == 1 - where[v]) { where[v] = 2; break; }
    }
    pw[0] = pw[1] = pw[2] = 0;
    for (v = 0; v < g->n; v++) pw[where[v]] += g->vw[v];
}

/* Grows side 0 by breadth-first search from seed until it holds half the weight (where 0/1);
   queue has room for n. */
static void amps__nd_grow(const amps__ndg *g, amps_int seed, amps_int *where, amps_int *queue, unsigned long long *rng) {
    amps_int n = g->n, v, p, k, head = 0, tail = 0, tot = 0, w0 = 0;
    for (v = 0; v < n; v++) { where[v] = 1; tot += g->vw[v]; }
    where[seed] = 4; queue[tail++] = seed;
    while (2 * w0 < tot) {
        if (head == tail) { /* disconnected: continue from another unvisited vertex */
            amps_int s0 = amps__rand(rng, n);
            for (k = 0; k < n && where[(s0 + k) % n] != 1; k++) {}
            if (k == n) break;
            v = (s0 + k) % n;
            where[v] = 4; queue[tail++] = v;
        }
        v = queue[head++];
        where[v] = 0; w0 += g->vw[v];
        for (p = g->p[v]; p < g->p[v + 1]; p++)
            if (where[g->i[p]] == 1) { where[g->i[p]] = 4; queue[tail++] = g->i[p]; }
    }
    while (head < tail) where[queue[head++]] = 1;
}

/* A vertex far from start (last level of repeated breadth-first searches); dist has room for n. */
static amps_int amps__nd_far(const amps__ndg *g, amps_int start, amps_int *dist, amps_int *queue) {
    amps_int it, v, p, far = start, ecc = -1;
    for (it = 0; it < 3; it++) {
        amps_int head = 0, tail = 0, last = start;
        for (v = 0; v < g->n; v++) dist[v] = -1;
        dist[start] = 0; queue[tail++] = start;
        while (head < tail) {
            v = queue[head++]; last = v;
            for (p = g->p[v]; p < g->p[v + 1]; p++)
                if (dist[g->i[p]] < 0) { dist[g->i[p]] = dist[v] + 1; queue[tail++] = g->i[p]; }
        }
        if (dist[last] <= ecc) break;
        ecc = dist[last]; far = last; start = last;
    }
    return far;
}

/* Coarsens g by heavy-edge matching into *c (allocated); sets g->cmap. */
static amps_status amps__nd_coarsen(amps_ctx *ctx, amps__ndg *g, amps__ndg *c, unsigned long long *rng) {
    amps_int n = g->n, v, u, p, k, nc, nz, tot = 0, maxvw, *match = NULL, *perm = NULL, *mk = NULL, *cmap;
    amps_int **pp[4];
    size_t len[4];
    memset(c, 0, sizeof(*c));
    pp[0] = &match; pp[1] = &perm; pp[2] = &g->cmap; pp[3] = &mk;
    len[0] = len[1] = len[2] = len[3] = (size_t)n + 1;
    if (amps__ialloc(ctx, 4, pp, len) != AMPS_OK) return AMPS_ERR_OOM;
    cmap = g->cmap;
    for (v = 0; v < n; v++) { match[v] = -1; perm[v] = v; tot += g->vw[v]; }
    maxvw = (amps_int)(1.5 * (double)tot / 80.0) + 1;
    for (v = n - 1; v > 0; v--) { k = amps__rand(rng, v + 1); u = perm[v]; perm[v] = perm[k]; perm[k] = u; }
    for (k = 0; k < n; k++) {
        amps_int best = -1, bw = -1;
        v = perm[k];
        if (match[v] >= 0) continue;
        for (p = g->p[v]; p < g->p[v + 1]; p++) {
            amps_int w = g->ew ? g->ew[p] : 1;
            u = g->i[p];
            if (match[u] >= 0 || g->vw[u] + g->vw[v] > maxvw) continue;
            if (w > bw || (w == bw && g->vw[u] < g->vw[best])) { bw = w; best = u; }
        }
        if (best < 0) match[v] = v;
        else { match[v] = best; match[best] = v; }
    }
    for (v = 0; v < n; v++) cmap[v] = -1;
    for (nc = 0, v = 0; v < n; v++)
        if (cmap[v] < 0) { cmap[v] = nc; cmap[match[v]] = nc; perm[nc++] = v; }
    /* coarse graph */
    c->n = nc;
    c->p = (amps_int *)amps__malloc(ctx, (size_t)nc + 1, sizeof(amps_int));
    c->vw = (amps_int *)amps__malloc(ctx, (size_t)nc + 1, sizeof(amps_int));
    c->i = (amps_int *)amps__malloc(ctx, (size_t)(g->p[n] > 0 ? g->p[n] : 1), sizeof(amps_int));
    c->ew = (amps_int *)amps__malloc(ctx, (size_t)(g->p[n] > 0 ? g->p[n] : 1), sizeof(amps_int));
    if (g->xyz) c->xyz = (double *)amps__malloc(ctx, 3 * (size_t)nc + 1, sizeof(double));
    if (!c->p || !c->vw || !c->i || !c->ew || (g->xyz && !c->xyz)) {
        amps__ndg_free(ctx, c); amps__free(ctx, match); amps__free(ctx, perm); amps__free(ctx, mk);
        amps__free(ctx, g->cmap); g->cmap = NULL;
        return amps__err(ctx, AMPS_ERR_OOM, "out of memory coarsening a graph of %ld vertices", (long)n);
    }
    for (k = 0; k < nc; k++) mk[k] = -1;
    for (nz = 0, k = 0; k < nc; k++) {
        amps_int m[2], a, cnt, start = nz;
        m[0] = perm[k]; m[1] = match[m[0]];
        cnt = m[1] != m[0] ? 2 : 1;
        c->p[k] = nz;
        c->vw[k] = 0;
        if (c->xyz) c->xyz[3 * k] = c->xyz[3 * k + 1] = c->xyz[3 * k + 2] = 0;
        for (a = 0; a < cnt; a++) {
            v = m[a];
            c->vw[k] += g->vw[v];
            if (c->xyz) {
                c->xyz[3 * k] += g->vw[v] * g->xyz[3 * v];
                c->xyz[3 * k + 1] += g->vw[v] * g->xyz[3 * v + 1];
                c->xyz[3 * k + 2] += g->vw[v] * g->xyz[3 * v + 2];
            }
            for (p = g->p[v]; p < g->p[v + 1]; p++) {
                amps_int cu = cmap[g->i[p]], w = g->ew ? g->ew[p] : 1;
                if (cu == k) continue;
                if (mk[cu] < start) { mk[cu] = nz; c->i[nz] = cu; c->ew[nz++] = w; }
                else c->ew[mk[cu]] += w;
            }
        }
        if (c->xyz) { double s = 1.0 / c->vw[k]; c->xyz[3 * k] *= s; c->xyz[3 * k + 1] *= s; c->xyz[3 * k + 2] *= s; }
    }
    c->p[nc] = nz;
    amps__free(ctx, match); amps__free(ctx, perm); amps__free(ctx, mk);
    return AMPS_OK;
}

/* Eigenvectors of the symmetric 3x3 matrix a (row-major, destroyed) by Jacobi rotations: columns
   of V. */
static void amps__eig3(double *a, double *V) {
    int it, p, q, k;
    for (k = 0; k < 9; k++) V[k] = (k % 4 == 0) ? 1.0 : 0.0;
    for (it = 0; it < 50; it++) {
        double off = fabs(a[1]) + fabs(a[2]) + fabs(a[5]);
        if (off < 1e-14 * (fabs(a[0]) + fabs(a[4]) + fabs(a[8])) || off == 0) break;
        for (p = 0; p < 2; p++)
            for (q = p + 1; q < 3; q++) {
                double apq = a[3 * p + q], th, t, c, s;
                if (apq == 0) continue;
                th = (a[3 * q + q] - a[3 * p + p]) / (2 * apq);
                t = (th >= 0 ? 1.0 : -1.0) / (fabs(th) + sqrt(th * th + 1));
                c = 1 / sqrt(t * t + 1); s = t * c;
                for (k = 0; k < 3; k++) { /* a := a J */
                    double akp = a[3 * k + p], akq = a[3 * k + q];
                    a[3 * k + p] = c * akp - s * akq; a[3 * k + q] = s * akp + c * akq;
                }
                for (k = 0; k < 3; k++) { /* a := J^T a */
                    double apk = a[3 * p + k], aqk = a[3 * q + k];
                    a[3 * p + k] = c * apk - s * aqk; a[3 * q + k] = s * apk + c * aqk;
                }
                for (k = 0; k < 3; k++) {
                    double vkp = V[3 * k + p], vkq = V[3 * k + q];
                    V[3 * k + p] = c * vkp - s * vkq; V[3 * k + q] = s * vkp + c * vkq;
                }
            }
    }
}

typedef struct amps__keyv { double k; amps_int v; } amps__keyv;

static int amps__keyv_cmp(const void *a, const void *b) {
    const amps__keyv *x = (const amps__keyv *)a, *y = (const amps__keyv *)b;
    if (x->k < y->k) return -1;
    if (x->k > y->k) return 1;
    return (x->v > y->v) - (x->v < y->v);
}


/* Plane-cut bisection of g (with coordinates): for each direction (coordinate and principal
   axes) sweeps the sorted projections and keeps the split inside the balance window with the
   lightest one-sided boundary; the best split over all directions gives the separator, refined by
   FM. Result in where/pw. kv, cnt, rank (n) are workspace. */
static void amps__nd_geo(const amps__ndg *g, amps_int *where, amps_int *pw, amps_int maxpw, amps__fmws *W,
                         amps__keyv *kv, amps_int *cnt, amps_int *rank) {
    amps_int n = g->n, v, u, p, k, tot = 0, d, bk;
    double cen[3] = {0, 0, 0}, C[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0}, V[9], dir[6][3];
    amps_int best = 0;
    int haveb = 0;
    for (v = 0; v < n; v++) {
        tot += g->vw[v];
        for (k = 0; k < 3; k++) cen[k] += g->vw[v] * g->xyz[3 * v + k];
    }
    for (k = 0; k < 3; k++) cen[k] /= (double)tot;
    for (v = 0; v < n; v++) {
        double x[3];
        int r, c;
        for (k = 0; k < 3; k++) x[k] = g->xyz[3 * v + k] - cen[k];
        for (r = 0; r < 3; r++) for (c = 0; c < 3; c++) C[3 * r + c] += g->vw[v] * x[r] * x[c];
    }
    amps__eig3(C, V);
    for (d = 0; d < 3; d++)
        for (k = 0; k < 3; k++) { dir[d][k] = (d == k); dir[3 + d][k] = V[3 * k + d]; }
    for (d = 0; d < 6; d++) {
        amps_int wa = 0, bndA = 0, bndB = 0, bs = -1;
        double lo = tot * (0.5 - AMPS__ND_WIN), hi = tot * (0.5 + AMPS__ND_WIN), bgap = 0;
        for (v = 0; v < n; v++) {
            kv[v].k = dir[d][0] * g->xyz[3 * v] + dir[d][1] * g->xyz[3 * v + 1] + dir[d][2] * g->xyz[3 * v + 2];
            kv[v].v = v;
        }
        qsort(kv, (size_t)n, sizeof(amps__keyv), amps__keyv_cmp);
        for (k = 0; k < n; k++) { rank[kv[k].v] = k; cnt[kv[k].v] = 0; }
        bk = -1;
        for (k = 0; k < n - 1; k++) {
            amps_int c = 0;
            v = kv[k].v;
            if (cnt[v] > 0) bndB -= g->vw[v];
            for (p = g->p[v]; p < g->p[v + 1]; p++) {
                u = g->i[p];
                if (rank[u] < k) { if (--cnt[u] == 0) bndA -= g->vw[u]; }
                else { c++; if (++cnt[u] == 1) bndB += g->vw[u]; }
            }
            cnt[v] = c;
            if (c > 0) bndA += g->vw[v];
            wa += g->vw[v];
            if (wa >= lo && wa <= hi) {
                amps_int s = bndA < bndB ? bndA : bndB;
                double gap = fabs(wa - 0.5 * tot);
                if (bs < 0 || s < bs || (s == bs && gap < bgap)) { bs = s; bk = k; bgap = gap; }
            }
        }
        if (bk < 0 || (haveb && bs >= best)) continue;
        haveb = 1; best = bs;
        for (v = 0; v < n; v++) where[v] = rank[v] <= bk ? 0 : 1;
    }
    if (!haveb) /* no split in the window (cannot happen with positive weights): halve the index range */
        for (v = 0; v < n; v++) where[v] = v < n / 2 ? 0 : 1;
    amps__nd_sep_from_cut(g, where, pw);
    amps__nd_fm(g, where, pw, maxpw, W, AMPS__ND_PASS);
}

/* Multilevel vertex bisection of g: heavy-edge coarsening, greedy growing + FM on the coarsest
   graph, FM refinement while projecting back. Graphs of at least AMPS__ND_MIDN vertices are first
   coarsened to about 1/16 of their size, where nmid independent bisections are tried
   and the best is kept. where/pw receive the result; wa, wb (n) are workspace. */
static amps_status amps__nd_ml(amps_ctx *ctx, amps__ndg *g, amps_int *where, amps_int *pw, amps_int maxpw,
                               amps__fmws *W, amps_int *wa, amps_int *wb, unsigned long long *rng, int nmid) {
    amps__ndg lev[64];
    int nl = 1, t, l, maxl = 64;
    amps_int v, bestpw[3] = {0, 0, 0}, *cw, *fw, target = AMPS__ND_COARSE;
    amps_status s = AMPS_OK;
    lev[0] = *g;
    if (nmid > 1 && g->n >= AMPS__ND_MIDN) {
        target = g->n / 16;
        if (target < AMPS__ND_COARSE) target = AMPS__ND_COARSE;
        maxl = 1 + AMPS__ND_MIDL;
    } else {
        nmid = 0;
    }
    while (lev[nl - 1].n > target && nl < maxl) {
        if ((s = amps__nd_coarsen(ctx, &lev[nl - 1], &lev[nl], rng)) != AMPS_OK) break;
        if (lev[nl].n > 0.9 * lev[nl - 1].n) {
            amps__ndg_free(ctx, &lev[nl]);
            amps__free(ctx, lev[nl - 1].cmap); lev[nl - 1].cmap = NULL;
            break;
        }
        nl++;
    }
    if (s == AMPS_OK && nmid > 0 && nl > 1) {
        /* several independent bisections of the intermediate graph; the best goes to wa */
        amps__ndg *c = &lev[nl - 1];
        amps_int *cw2 = (amps_int *)amps__malloc(ctx, 2 * (size_t)c->n, sizeof(amps_int));
        if (!cw2) s = AMPS_ERR_OOM;
        for (t = 0; t < nmid && s == AMPS_OK; t++) {
            amps_int lpw[3];
            if ((s = amps__nd_ml(ctx, c, cw2, lpw, maxpw, W, cw2 + c->n, wb, rng, 1)) != AMPS_OK) break;
            if (t == 0 || amps__sep_better(lpw[2], lpw[0], lpw[1], bestpw[2], bestpw[0], bestpw[1], maxpw)) {
                bestpw[0] = lpw[0]; bestpw[1] = lpw[1]; bestpw[2] = lpw[2];
                memcpy(wa, cw2, sizeof(amps_int) * (size_t)c->n);
            }
        }
        amps__free(ctx, cw2);
    } else if (s == AMPS_OK) {
        /* coarsest graph: plane cuts (with coordinates) and several greedy growings, each refined;
           keep the best in wa */
        amps__ndg *c = &lev[nl - 1];
        t = 0;
        if (c->xyz) {
            amps__keyv *kv = (amps__keyv *)amps__malloc(ctx, (size_t)c->n, sizeof(amps__keyv));
            amps_int *ws = (amps_int *)amps__malloc(ctx, 2 * (size_t)c->n, sizeof(amps_int));
            if (kv && ws) {
                amps__nd_geo(c, wa, bestpw, maxpw, W, kv, ws, ws + c->n);
                t = 1;
            }
            amps__free(ctx, kv); amps__free(ctx, ws);
            if (!t) s = AMPS_ERR_OOM;
        }
        for (; t < AMPS__ND_TRIES + (c->xyz != NULL) && s == AMPS_OK; t++) {
            amps_int lpw[3], seed = amps__rand(rng, c->n);
            if (t == 0) seed = amps__nd_far(c, seed, wb, where);
            amps__nd_grow(c, seed, wb, where, rng);
            amps__nd_sep_from_cut(c, wb, lpw);
            amps__nd_fm(c, wb, lpw, maxpw, W, AMPS__ND_PASS);
            if (t == 0 || amps__sep_better(lpw[2], lpw[0], lpw[1], bestpw[2], bestpw[0], bestpw[1], maxpw)) {
                bestpw[0] = lpw[0]; bestpw[1] = lpw[1]; bestpw[2] = lpw[2];
                memcpy(wa, wb, sizeof(amps_int) * (size_t)c->n);
            }
        }
    }
    if (s != AMPS_OK) {
        for (l = 1; l < nl; l++) amps__ndg_free(ctx, &lev[l]);
        amps__free(ctx, lev[0].cmap);
        g->cmap = NULL;
        return s;
    }
    cw = wa; fw = wb;
    pw[0] = bestpw[0]; pw[1] = bestpw[1]; pw[2] = bestpw[2];
    for (l = nl - 2; l >= 0; l--) {
        amps_int *tmp;
        for (v = 0; v < lev[l].n; v++) fw[v] = cw[lev[l].cmap[v]];
        amps__nd_fm(&lev[l], fw, pw, maxpw, W, AMPS__ND_PASS);
        tmp = cw; cw = fw; fw = tmp;
    }
    memcpy(where, cw, sizeof(amps_int) * (size_t)g->n);
    for (l = 1; l < nl; l++) amps__ndg_free(ctx, &lev[l]);
    amps__free(ctx, lev[0].cmap);
    g->cmap = NULL;
    return AMPS_OK;
}

/* AMD ordering of the part vs[0..m-1] of graph G (weights vw, NULL = 1) with its halo: the
   outside neighbours (vertices of enclosing separators, eliminated later) count in the degrees
   but are not ordered. Reorders vs in place. loc (n, all -1) is restored; lord has room for m. */
static amps_status amps__nd_leaf(amps_ctx *ctx, const amps_int *Gp, const amps_int *Gi, const amps_int *vw, amps_int *vs,
                                 amps_int m, amps_int *loc, amps_int *lord) {
    amps_int k, p, v, u, h = 0, dsum = 0, *lp = NULL, *li = NULL, *lw = NULL, *hv = NULL;
    amps_status s = AMPS_OK;
    for (k = 0; k < m; k++) dsum += Gp[vs[k] + 1] - Gp[vs[k]];
    hv = (amps_int *)amps__malloc(ctx, (size_t)dsum + 1, sizeof(amps_int));
    if (!hv) return AMPS_ERR_OOM;
    for (k = 0; k < m; k++) loc[vs[k]] = k;
    for (k = 0; k < m; k++)
        for (v = vs[k], p = Gp[v]; p < Gp[v + 1]; p++)
            if (loc[u = Gi[p]] < 0) { loc[u] = m + h; hv[h++] = u; }
    lp = (amps_int *)amps__malloc(ctx, (size_t)(m + h) + 1, sizeof(amps_int));
    li = (amps_int *)amps__malloc(ctx, 2 * (size_t)dsum + 1, sizeof(amps_int));
    lw = (amps_int *)amps__malloc(ctx, (size_t)(m + h) + 1, sizeof(amps_int));
    if (!lp || !li || !lw) { s = AMPS_ERR_OOM; goto done; }
    /* part vertices keep all their edges; halo vertices get their edges into the part */
    for (k = 0; k <= m + h; k++) lp[k] = 0;
    for (k = 0; k < m; k++)
        for (v = vs[k], p = Gp[v]; p < Gp[v + 1]; p++) {
            lp[k + 1]++;
            if ((u = loc[Gi[p]]) >= m) lp[u + 1]++;
        }
    for (k = 0; k < m + h; k++) lp[k + 1] += lp[k];
    for (k = 0; k < m + h; k++) lw[k] = lp[k]; /* fill pointers */
    for (k = 0; k < m; k++)
        for (v = vs[k], p = Gp[v]; p < Gp[v + 1]; p++) {
            u = loc[Gi[p]];
            li[lw[k]++] = u;
            if (u >= m) li[lw[u]++] = k;
        }
    for (k = 0; k < m; k++) lw[k] = vw ? vw[vs[k]] : 1;
    for (k = 0; k < h; k++) lw[m + k] = vw ? vw[hv[k]] : 1;
    s = amps__amd_core(ctx, m + h, lp, li, lw, m, 0, lord);
    if (s == AMPS_OK) {
        for (k = 0; k < m; k++) lord[k] = vs[lord[k]];
        memcpy(vs, lord, sizeof(amps_int) * (size_t)m);
    }
done:
    for (k = 0; k < m; k++) loc[vs[k]] = -1;
    for (k = 0; k < h; k++) loc[hv[k]] = -1;
    amps__free(ctx, lp); amps__free(ctx, li); amps__free(ctx, lw); amps__free(ctx, hv);
    return s;
}

/* Nested dissection of a clean symmetric graph with vertex weights vw (NULL = 1) and optional
   coordinates xyz (3 per vertex): order[k] = vertex eliminated k-th; separators come after the
   parts they separate, parts of at most AMPS__ND_LEAF vertices are ordered by AMD. */
static amps_status amps__nd_core(amps_ctx *ctx, amps_int n, const amps_int *Gp, const amps_int *Gi, const amps_int *vw,
                                 const double *xyz, amps_int *order) {
    amps_int *loc = NULL, *stk = NULL, *where = NULL, *wa = NULL, *wb = NULL, *tmpv = NULL, *lord = NULL, *cnt = NULL;
    amps__fmws W;
    amps__ndg sub;
    amps_int k, v, p, nstk = 0;
    amps_status s = AMPS_OK;
    unsigned long long rng = 0x9E3779B97F4A7C15ULL;
    amps_int **pp[8];
    size_t len[8];
    if (n <= 0) return AMPS_OK;
    memset(&sub, 0, sizeof(sub));
    W.mem = NULL;
    pp[0] = &loc; pp[1] = &stk; pp[2] = &where; pp[3] = &wa; pp[4] = &wb; pp[5] = &tmpv; pp[6] = &lord; pp[7] = &cnt;
    for (k = 0; k < 8; k++) len[k] = (size_t)n + 1;
    len[1] = 2 * ((size_t)n + 1);
    if ((s = amps__ialloc(ctx, 8, pp, len)) != AMPS_OK) return s;
    if (amps__fmws_init(ctx, &W, n) != AMPS_OK) { s = AMPS_ERR_OOM; goto done; }
    for (k = 0; k < n; k++) { order[k] = k; loc[k] = -1; }
    stk[nstk++] = 0; stk[nstk++] = n;
    while (nstk > 0) {
        amps_int hi = stk[--nstk], lo = stk[--nstk], m = hi - lo, nz = 0, ncomp, pw[3], maxpw, tot = 0;
        if (m <= 1) continue;
        if (m <= AMPS__ND_LEAF) {
            if ((s = amps__nd_leaf(ctx, Gp, Gi, vw, order + lo, m, loc, lord)) != AMPS_OK) goto done;
            continue;
        }
        /* induced subgraph of order[lo..hi) */
        for (k = 0; k < m; k++) loc[order[lo + k]] = k;
        for (k = 0; k < m; k++)
            for (v = order[lo + k], p = Gp[v]; p < Gp[v + 1]; p++) nz += loc[Gi[p]] >= 0;
        sub.n = m;
        sub.p = (amps_int *)amps__malloc(ctx, (size_t)m + 1, sizeof(amps_int));
        sub.i = (amps_int *)amps__malloc(ctx, (size_t)nz, sizeof(amps_int));
        sub.vw = (amps_int *)amps__malloc(ctx, (size_t)m, sizeof(amps_int));
        if (xyz) sub.xyz = (double *)amps__malloc(ctx, 3 * (size_t)m, sizeof(double));
        if (!sub.p || !sub.i || !sub.vw || (xyz && !sub.xyz)) { s = AMPS_ERR_OOM; goto done; }
        for (nz = 0, k = 0; k < m; k++) {
            v = order[lo + k];
            sub.p[k] = nz;
            sub.vw[k] = vw ? vw[v] : 1;
            tot += sub.vw[k];
            if (xyz) { sub.xyz[3 * k] = xyz[3 * v]; sub.xyz[3 * k + 1] = xyz[3 * v + 1]; sub.xyz[3 * k + 2] = xyz[3 * v + 2]; }
            for (p = Gp[v]; p < Gp[v + 1]; p++)
                if (loc[Gi[p]] >= 0) sub.i[nz++] = loc[Gi[p]];
        }
        sub.p[m] = nz;
        for (k = 0; k < m; k++) loc[order[lo + k]] = -1;
        /* connected components: label in where, order them one after another */
        for (k = 0; k < m; k++) where[k] = -1;
        for (ncomp = 0, k = 0; k < m; k++) {
            amps_int head = 0, tail = 0;
            if (where[k] >= 0) continue;
            where[k] = ncomp; wa[tail++] = k;
            while (head < tail) {
                v = wa[head++];
                for (p = sub.p[v]; p < sub.p[v + 1]; p++)
                    if (where[sub.i[p]] < 0) { where[sub.i[p]] = ncomp; wa[tail++] = sub.i[p]; }
            }
            ncomp++;
        }
        if (ncomp > 1) {
            amps_int c;
            for (c = 0; c <= ncomp; c++) cnt[c] = 0;
            for (k = 0; k < m; k++) cnt[where[k] + 1]++;
            for (c = 0; c < ncomp; c++) cnt[c + 1] += cnt[c];
            for (c = 0; c < ncomp; c++)
                if (cnt[c + 1] - cnt[c] > 1) { stk[nstk++] = lo + cnt[c]; stk[nstk++] = lo + cnt[c + 1]; }
            for (k = 0; k < m; k++) tmpv[cnt[where[k]]++] = order[lo + k];
            memcpy(order + lo, tmpv, sizeof(amps_int) * (size_t)m);
            amps__ndg_free(ctx, &sub);
            continue;
        }
        maxpw = (amps_int)(AMPS__ND_BAL * tot);
        if ((s = amps__nd_ml(ctx, &sub, where, pw, maxpw, &W, wa, wb, &rng, AMPS__ND_MID)) != AMPS_OK) goto done;
        amps__ndg_free(ctx, &sub);
        if (pw[0] == 0 || pw[1] == 0) { /* inseparable (e.g. a clique) */
            if ((s = amps__nd_leaf(ctx, Gp, Gi, vw, order + lo, m, loc, lord)) != AMPS_OK) goto done;
            continue;
        }
        {
            amps_int c[3];
            c[0] = c[1] = c[2] = 0;
            for (k = 0; k < m; k++) c[where[k]]++;
            c[2] = c[0] + c[1]; c[1] = c[0]; c[0] = 0; /* start of each part: 0, 1, separator */
            if (c[1] > 1) { stk[nstk++] = lo; stk[nstk++] = lo + c[1]; }
            if (c[2] - c[1] > 1) { stk[nstk++] = lo + c[1]; stk[nstk++] = lo + c[2]; }
            for (k = 0; k < m; k++) tmpv[c[where[k]]++] = order[lo + k];
        }
        memcpy(order + lo, tmpv, sizeof(amps_int) * (size_t)m);
    }
done:
    amps__ndg_free(ctx, &sub);
    amps__free(ctx, W.mem);
    amps__free(ctx, loc); amps__free(ctx, stk); amps__free(ctx, where); amps__free(ctx, wa); amps__free(ctx, wb);
    amps__free(ctx, tmpv); amps__free(ctx, lord); amps__free(ctx, cnt);
    return s;
}

/* ------------------------- elimination tree, fill, postorder ------------------------- */

/* Elimination tree of graph G eliminated in order (iord = inverse): parent[k] (positions, -1 at
   roots). anc is workspace (n). */
static void amps__etree(amps_int n, const amps_int *Gp, const amps_int *Gi, const amps_int *order, const amps_int *iord,
                        amps_int *parent, amps_int *anc) {
    amps_int k, p, r, t;
    for (k = 0; k < n; k++) {
        amps_int v = order[k];
        parent[k] = -1; anc[k] = -1;
        for (p = Gp[v]; p < Gp[v + 1]; p++) {
            r = iord[Gi[p]];
            if (r >= k) continue;
            while (anc[r] >= 0 && anc[r] != k) { t = anc[r]; anc[r] = k; r = t; }
            if (anc[r] < 0) { anc[r] = k; parent[r] = k; }
        }
    }
}

/* nnz(L) including the diagonal when G is eliminated in order, vertex v standing for a clique of
   vw[v] (NULL = 1) consecutive unknowns. Cost O(nnz(L of G)). mark is workspace (n). */
static double amps__nnzl(amps_int n, const amps_int *Gp, const amps_int *Gi, const amps_int *vw, const amps_int *order,
                         const amps_int *iord, const amps_int *parent, amps_int *mark) {
    amps_int k, p, j;
    double nz = 0;
    for (k = 0; k < n; k++) mark[k] = -1;
    for (k = 0; k < n; k++) {
        amps_int v = order[k];
        double wk = vw ? vw[v] : 1, s = 0;
        nz += wk * (wk + 1) / 2;
        mark[k] = k;
        for (p = Gp[v]; p < Gp[v + 1]; p++)
            for (j = iord[Gi[p]]; j < k && mark[j] != k; j = parent[j]) {
                mark[j] = k;
                s += vw ? vw[order[j]] : 1;
            }
        nz += wk * s;
    }
    return nz;
}

/* Replaces order by a postorder of its elimination tree (an equivalent ordering: same fill).
   parent as from amps__etree; w is workspace (4n). */
static void amps__postorder(amps_int n, amps_int *order, const amps_int *parent, amps_int *w) {
    amps_int *head = w, *nxt = w + n, *stack = w + 2 * n, *post = w + 3 * n, k, top, pos = 0;
    for (k = 0; k < n; k++) head[k] = -1;
    for (k = n - 1; k >= 0; k--)
        if (parent[k] >= 0) { nxt[k] = head[parent[k]]; head[parent[k]] = k; }
    for (k = 0; k < n; k++) {
        if (parent[k] >= 0) continue;
        top = 0; stack[top++] = k;
        while (top > 0) {
            amps_int j = stack[top - 1], c = head[j];
            if (c >= 0) { head[j] = nxt[c]; stack[top++] = c; }
            else { top--; post[pos++] = j; }
        }
    }
    for (k = 0; k < n; k++) head[k] = order[post[k]];
    memcpy(order, head, sizeof(amps_int) * (size_t)n);
}

#ifdef AMPS_USE_METIS
/* METIS_NodeND on G (weights vw, NULL = 1): order[k] = vertex k-th. */
static amps_status amps__metis(amps_ctx *ctx, amps_int n, const amps_int *Gp, const amps_int *Gi, const amps_int *vw,
                               amps_int *order) {
    idx_t nv = (idx_t)n, *xadj, *adj, *w, *mp, *ip, options[METIS_NOPTIONS];
    amps_int k, nz = Gp[n];
    int r;
    if ((amps_int)(idx_t)n != n || (amps_int)(idx_t)nz != nz)
        return amps__err(ctx, AMPS_ERR_UNSUPPORTED, "graph too large for METIS idx_t");
    xadj = (idx_t *)amps__malloc(ctx, (size_t)n + 1, sizeof(idx_t));
    adj = (idx_t *)amps__malloc(ctx, (size_t)nz, sizeof(idx_t));
    w = (idx_t *)amps__malloc(ctx, (size_t)n, sizeof(idx_t));
    mp = (idx_t *)amps__malloc(ctx, (size_t)n, sizeof(idx_t));
    ip = (idx_t *)amps__malloc(ctx, (size_t)n, sizeof(idx_t));
    if (!xadj || !adj || !w || !mp || !ip) {
        amps__free(ctx, xadj); amps__free(ctx, adj); amps__free(ctx, w); amps__free(ctx, mp); amps__free(ctx, ip);
        return amps__err(ctx, AMPS_ERR_OOM, "out of memory for METIS");
    }
    for (k = 0; k <= n; k++) xadj[k] = (idx_t)Gp[k];
    for (k = 0; k < nz; k++) adj[k] = (idx_t)Gi[k];
    for (k = 0; k < n; k++) w[k] = (idx_t)(vw ? vw[k] : 1);
    METIS_SetDefaultOptions(options);
    options[METIS_OPTION_NUMBERING] = 0;
    r = METIS_NodeND(&nv, xadj, adj, w, options, mp, ip);
    if (r == METIS_OK)
        for (k = 0; k < n; k++) order[k] = (amps_int)mp[k];
    amps__free(ctx, xadj); amps__free(ctx, adj); amps__free(ctx, w); amps__free(ctx, mp); amps__free(ctx, ip);
    if (r != METIS_OK) return amps__err(ctx, r == METIS_ERROR_MEMORY ? AMPS_ERR_OOM : AMPS_ERR_ARG,
                                        "METIS_NodeND failed (status %d)", r);
    return AMPS_OK;
}
#endif

/* Prefixes the message of a failure reported by an internal routine with "fn: ". */
static amps_status amps__order_fail(amps_ctx *ctx, const char *fn, amps_status s) {
    size_t l = strlen(fn);
    if (ctx && s != AMPS_OK && (strncmp(ctx->msg, fn, l) != 0 || ctx->msg[l] != ':')) {
        char tmp[sizeof(ctx->msg)];
        memcpy(tmp, ctx->msg, sizeof(tmp));
        tmp[sizeof(tmp) - 1] = 0;
        amps__err(ctx, s, "%s: %s", fn, tmp[0] ? tmp : amps_status_str(s));
    }
    return s;
}

/* Orders graph G (n vertices, clean and symmetric) by method after compressing it into nodes
   (block b >= 1: b consecutive vertices; 0: runs of identical closed neighbourhoods) and expands
   the node order into perm (n). coords: 3 per node (b >= 1) or per vertex (b = 0), may be NULL.
   post: replace the node order by its elimination-tree postorder. Failures: AMPS_ERR_OOM (or a
   METIS error) with the message of the routine that failed. */
static amps_status amps__order_graph(amps_ctx *ctx, amps_int n, const amps_int *Gp, const amps_int *Gi, int method,
                                     amps_int block, const double *coords, int post, amps_int *perm) {
    amps_int *gfirst = NULL, *Qp = NULL, *Qi = NULL, *Qw = NULL, *ord = NULL, *ord2 = NULL, *wk = NULL, ng, k, j, q;
    const amps_int *P, *I;
    double *xyz = NULL;
    const double *nx = NULL;
    amps_status s = AMPS_OK;
    gfirst = (amps_int *)amps__malloc(ctx, (size_t)n + 1, sizeof(amps_int));
    if (!gfirst) return AMPS_ERR_OOM;
    if (block == 0) ng = amps__graph_runs(n, Gp, Gi, gfirst);
    else { ng = n / block; for (k = 0; k <= ng; k++) gfirst[k] = k * block; }
    if (ng < n) {
        if ((s = amps__graph_quotient(ctx, n, Gp, Gi, ng, gfirst, block == 0, &Qp, &Qi, &Qw)) != AMPS_OK) goto done;
        P = Qp; I = Qi;
    } else {
        P = Gp; I = Gi;
    }
    if (coords && block == 0 && ng < n) {
        xyz = (double *)amps__malloc(ctx, 3 * (size_t)ng, sizeof(double));
        if (!xyz) { s = AMPS_ERR_OOM; goto done; }
        for (k = 0; k < ng; k++) for (j = 0; j < 3; j++) xyz[3 * k + j] = coords[3 * gfirst[k] + j];
        nx = xyz;
    } else {
        nx = coords;
    }
    ord = (amps_int *)amps__malloc(ctx, (size_t)ng, sizeof(amps_int));
    ord2 = (amps_int *)amps__malloc(ctx, (size_t)ng, sizeof(amps_int));
    wk = (amps_int *)amps__malloc(ctx, 5 * (size_t)ng, sizeof(amps_int));
    if (!ord || !ord2 || !wk) { s = AMPS_ERR_OOM; goto done; }
    if (method == AMPS_ORDER_AMD) {
        s = amps__amd_core(ctx, ng, P, I, Qw, ng, 0, ord);
    } else if (method == AMPS_ORDER_ND) {
        s = amps__nd_core(ctx, ng, P, I, Qw, nx, ord);
#ifdef AMPS_USE_METIS
    } else if (method == AMPS_ORDER_METIS) {
        s = amps__metis(ctx, ng, P, I, Qw, ord);
#endif
    } else { /* AUTO: the candidate with the least fill */
        double best, f;
        amps_int *iord = wk, *par = wk + ng, *tmp = wk + 2 * ng;
        int c, nc = 1;
        int cand[3];
        cand[0] = AMPS_ORDER_AMD;
        if (ng > AMPS__ND_LEAF) {
            cand[nc++] = AMPS_ORDER_ND;
#ifdef AMPS_USE_METIS
            cand[nc++] = AMPS_ORDER_METIS;
#endif
        }
        best = -1;
        for (c = 0; c < nc && s == AMPS_OK; c++) {
            if (cand[c] == AMPS_ORDER_AMD) s = amps__amd_core(ctx, ng, P, I, Qw, ng, 0, ord2);
            else if (cand[c] == AMPS_ORDER_ND) s = amps__nd_core(ctx, ng, P, I, Qw, nx, ord2);
#ifdef AMPS_USE_METIS
            else s = amps__metis(ctx, ng, P, I, Qw, ord2);
#endif
            if (s != AMPS_OK) break;
            if (nc == 1) { memcpy(ord, ord2, sizeof(amps_int) * (size_t)ng); break; }
            for (k = 0; k < ng; k++) iord[ord2[k]] = k;
            amps__etree(ng, P, I, ord2, iord, par, tmp);
            f = amps__nnzl(ng, P, I, Qw, ord2, iord, par, tmp);
            if (best < 0 || f < best) { best = f; memcpy(ord, ord2, sizeof(amps_int) * (size_t)ng); }
        }
    }
    if (s != AMPS_OK) goto done;
    if (post) {
        amps_int *iord = wk, *par = wk + 4 * ng;
        for (k = 0; k < ng; k++) iord[ord[k]] = k;
        amps__etree(ng, P, I, ord, iord, par, wk + ng);
        amps__postorder(ng, ord, par, wk);
    }
    for (q = 0, k = 0; k < ng; k++)
        for (j = gfirst[ord[k]]; j < gfirst[ord[k] + 1]; j++) perm[q++] = j;
done:
    amps__free(ctx, gfirst); amps__free(ctx, Qp); amps__free(ctx, Qi); amps__free(ctx, Qw);
    amps__free(ctx, xyz); amps__free(ctx, ord); amps__free(ctx, ord2); amps__free(ctx, wk);
    return s;
}

AMPS_API amps_status amps_order(amps_ctx *ctx, const amps_csc *A, amps_stype stype, const amps_order_opts *opts,
                                amps_int *perm) {
    const char *fn = "amps_order";
    amps_ordering method = opts ? opts->method : AMPS_ORDER_AUTO;
    amps_int block = opts ? opts->block : 0, n, k, *Gp = NULL, *Gi = NULL, *out = NULL;
    const double *coords = opts ? opts->coords : NULL;
    amps_status s;
    if (!A) return amps__err(ctx, AMPS_ERR_ARG, "%s: matrix A is NULL", fn);
    if (!perm) return amps__err(ctx, AMPS_ERR_ARG, "%s: output perm is NULL", fn);
    if (stype != AMPS_UPPER && stype != AMPS_LOWER && stype != AMPS_FULL)
        return amps__err(ctx, AMPS_ERR_ARG, "%s: invalid stype %d", fn, (int)stype);
    if ((int)method < (int)AMPS_ORDER_AUTO || (int)method > (int)AMPS_ORDER_METIS)
        return amps__err(ctx, AMPS_ERR_ARG, "%s: invalid ordering method %d", fn, (int)method);
    n = A->ncol;
    if (n < 0 || A->nrow != A->ncol)
        return amps__err(ctx, AMPS_ERR_ARG, "%s: matrix is %ld x %ld, must be square", fn, (long)A->nrow, (long)A->ncol);
    if (block < 0) return amps__err(ctx, AMPS_ERR_ARG, "%s: block = %ld is negative", fn, (long)block);
    if (block > 1 && n % block != 0)
        return amps__err(ctx, AMPS_ERR_ARG, "%s: n = %ld is not a multiple of block = %ld", fn, (long)n, (long)block);
#ifndef AMPS_USE_METIS
    if (method == AMPS_ORDER_METIS)
        return amps__err(ctx, AMPS_ERR_UNSUPPORTED, "%s: AMPS_ORDER_METIS needs amps.h built with AMPS_USE_METIS (and -lmetis)", fn);
#endif
    if (method == AMPS_ORDER_GIVEN && !opts->perm)
        return amps__err(ctx, AMPS_ERR_ARG, "%s: AMPS_ORDER_GIVEN with opts->perm NULL", fn);
    if (coords && (method == AMPS_ORDER_ND || method == AMPS_ORDER_AUTO)) {
        amps_int nc = 3 * (block >= 1 ? n / block : n);
        for (k = 0; k < nc; k++)
            if (!amps__isfinite(coords[k]))
                return amps__err(ctx, AMPS_ERR_VALUE, "%s: coordinate %ld of node %ld is not finite", fn, (long)(k % 3),
                                 (long)(k / 3));
    }
    if ((s = amps__graph_sym(ctx, fn, n, A->p, A->i, (int)stype, &Gp, &Gi)) != AMPS_OK) return amps__order_fail(ctx, fn, s);
    out = (amps_int *)amps__malloc(ctx, (size_t)n, sizeof(amps_int));
    if (!out) { amps__free(ctx, Gp); amps__free(ctx, Gi); return amps__order_fail(ctx, fn, AMPS_ERR_OOM); }
    if (method == AMPS_ORDER_NATURAL) {
        for (k = 0; k < n; k++) out[k] = k;
    } else if (method == AMPS_ORDER_GIVEN) {
        const amps_int *g = opts->perm;
        for (k = 0; k < n; k++) out[k] = -1; /* out[v] = position of v while checking */
        for (k = 0; k < n && s == AMPS_OK; k++) {
            if (g[k] < 0 || g[k] >= n)
                s = amps__err(ctx, AMPS_ERR_INDEX, "%s: given perm[%ld] = %ld is out of range [0,%ld)", fn, (long)k,
                              (long)g[k], (long)n);
            else if (out[g[k]] >= 0)
                s = amps__err(ctx, AMPS_ERR_ARG, "%s: given perm is not a permutation: perm[%ld] = perm[%ld] = %ld", fn,
                              (long)out[g[k]], (long)k, (long)g[k]);
            else
                out[g[k]] = k;
        }
        if (s == AMPS_OK) memcpy(out, g, sizeof(amps_int) * (size_t)n);
    } else if (n > 0) {
        s = amps__order_fail(ctx, fn, amps__order_graph(ctx, n, Gp, Gi, (int)method, block, coords, 1, out));
    }
    if (s == AMPS_OK && n > 0) memcpy(perm, out, sizeof(amps_int) * (size_t)n);
    amps__free(ctx, Gp); amps__free(ctx, Gi); amps__free(ctx, out);
    return s;
}

AMPS_API amps_status amps_amd(amps_ctx *ctx, amps_int n, const amps_int *Ap, const amps_int *Ai, amps_int *perm) {
    amps_int *Gp = NULL, *Gi = NULL, *out = NULL;
    amps_status s;
    if (n < 0) return amps__err(ctx, AMPS_ERR_ARG, "amps_amd: n = %ld is negative", (long)n);
    if (n > 0 && !perm) return amps__err(ctx, AMPS_ERR_ARG, "amps_amd: output perm is NULL");
    if ((s = amps__graph_sym(ctx, "amps_amd", n, Ap, Ai, 0, &Gp, &Gi)) != AMPS_OK) return amps__order_fail(ctx, "amps_amd", s);
    out = (amps_int *)amps__malloc(ctx, (size_t)n, sizeof(amps_int));
    if (!out) s = AMPS_ERR_OOM;
    else if ((s = amps__amd_core(ctx, n, Gp, Gi, NULL, n, 0, out)) == AMPS_OK && n > 0) memcpy(perm, out, sizeof(amps_int) * (size_t)n);
    amps__order_fail(ctx, "amps_amd", s);
    amps__free(ctx, Gp); amps__free(ctx, Gi); amps__free(ctx, out);
    return s;
}

AMPS_API amps_status amps_nd(amps_ctx *ctx, amps_int n, const amps_int *Ap, const amps_int *Ai, const double *xyz,
                             amps_int *perm) {
    amps_int *Gp = NULL, *Gi = NULL, *out = NULL, k;
    amps_status s;
    if (n < 0) return amps__err(ctx, AMPS_ERR_ARG, "amps_nd: n = %ld is negative", (long)n);
    if (n > 0 && !perm) return amps__err(ctx, AMPS_ERR_ARG, "amps_nd: output perm is NULL");
    if (xyz)
        for (k = 0; k < 3 * n; k++)
            if (!amps__isfinite(xyz[k]))
                return amps__err(ctx, AMPS_ERR_VALUE, "amps_nd: coordinate %ld of vertex %ld is not finite", (long)(k % 3),
                                 (long)(k / 3));
    if ((s = amps__graph_sym(ctx, "amps_nd", n, Ap, Ai, 0, &Gp, &Gi)) != AMPS_OK) return amps__order_fail(ctx, "amps_nd", s);
    out = (amps_int *)amps__malloc(ctx, (size_t)n, sizeof(amps_int));
    if (!out) s = AMPS_ERR_OOM;
    else if (n > 0 && (s = amps__order_graph(ctx, n, Gp, Gi, AMPS_ORDER_ND, 0, xyz, 1, out)) == AMPS_OK)
        memcpy(perm, out, sizeof(amps_int) * (size_t)n);
    amps__order_fail(ctx, "amps_nd", s);
    amps__free(ctx, Gp); amps__free(ctx, Gi); amps__free(ctx, out);
    return s;
}

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
