/* amps.h - exact real-time solves of finite element models under cuts, pins and forces.
   Augmented Matrix Principal Submatrix updates (AMPS) over a sparse LDL^T factorization.
   Single-file library, MIT license (see end of file). The FEM layer is linear elasticity (small
   strains) on linear tetrahedra.

   USAGE
     In exactly one C or C++ file:
         #define AMPS_IMPLEMENTATION
         #include "amps.h"
     Everywhere else just #include "amps.h".

   CONTENTS
     The header reads in the order the data flows. Each part has its declarations first and its
     implementation after the IMPLEMENTATION line, in the same order; grep '\[amps:PART' finds
     both banners (the implementation's tag is "[amps:PART impl]").
       [amps:common]    status codes, the context (allocator user pointer, threads, last error),
                        the clock
       [amps:sparse]    compressed sparse column matrices: triplets, checks, products
       [amps:ordering]  fill-reducing orderings: minimum degree, nested dissection, METIS
       [amps:symbolic]  elimination tree, postorder, column counts
       [amps:numeric]   the LDL^T factor: analysis (ordering + symbolic), numeric factorization
       [amps:solve]     triangular solves, elimination-tree closures, sparse and partial solves
       [amps:update]    the AMPS engine: changed rows, appended DOFs, constraints and forces, one
                        commit (Steps 1-5) and the solves (Step 6); watch sets, reactions, the
                        accuracy guard, background re-factorization
       [amps:fem]       the tetrahedral mesh (cuts, assembly, stresses) and P1 elasticity
       [amps:scene]     a mesh with fixed nodes, forces, pins and cuts, solved by the engine
       [amps:io]        mesh readers (TetGen, Gmsh, MEDIT) and writers (VTU, TetGen, Gmsh, MEDIT)

   REFERENCES (cited by these short names)
     [AMPS]  Y.-H. Yeung, A. Pothen, J. Crouch, "AMPS: real-time mesh cutting with augmented
             matrices for surgical simulations", Numerical Linear Algebra with Applications, 2018.
     [Interactive cutting]  Y.-H. Yeung, J. Crouch, A. Pothen, "Interactively cutting and
             constraining vertices in meshes using augmented matrices", ACM Transactions on
             Graphics, 2016.
     [CSparse]  T. A. Davis, "Direct Methods for Sparse Linear Systems", SIAM, 2006.

   OPTIONS (define before the implementation include)
     AMPS_STATIC          all functions static (private copy per translation unit)
     AMPS_INT             index type (default int; e.g. -DAMPS_INT=int64_t for huge models)
     AMPS_MALLOC(sz,u) AMPS_REALLOC(p,sz,u) AMPS_FREE(p,u)
                          custom allocator; define all three or none. u is amps_ctx.alloc_user.
     AMPS_ASSERT(x)       internal assertion (default assert from <assert.h>)
     AMPS_NOW()           your monotonic clock in seconds (default: see amps_now)
     AMPS_USE_METIS       enable AMPS_ORDER_METIS (link -lmetis)
     AMPS_PIVOT_TOL       LDL^T pivots below this times the column's diagonal are "not SPD" (1e-12)
     AMPS_COUNT_TOUCH     tests: count the L entries the sparse and partial solves read
     AMPS_NO_FEM          linear algebra only (sparse, ordering, factor, solve, update engine):
                          leaves out the mesh and element layer, the scene and the mesh I/O
     AMPS_NO_STDIO        no <stdio.h>: leaves out the file readers and writers (amps_mesh_read*,
                          amps_mesh_write_*); the *_mem readers stay. Error messages never use
                          stdio (a private formatter, the same in every build).
     AMPS_NO_THREADS      leave out amps' own threads (pthreads): the kernels' workers
                          (AMPS_BACKEND_THREADS) and the background re-factorization
     AMPS_NO_SIMD         plain C where SSE2 intrinsics would be used (the residual check)
     AMPS_NO_AVX2         no AVX2 + FMA kernels: by default (gcc, clang on x86) the update
                          kernels of amps_factorize, the dense system's products and Step 1's
                          column blocks run in AVX2 + FMA when the CPU has them (checked at run
                          time; no -mavx2 needed), else in SSE2. The two round differently; one
                          machine always gives the same bits, for any number of threads.
     Parallel kernels: see amps_backend. By default (ctx->nthreads 0) they use
     omp_get_max_threads() participants when compiled with -fopenmp, else one.

   ERRORS AND OWNERSHIP
     Every call that can fail takes an amps_ctx* and returns an amps_status (or NULL, or -1 for
     a count). On failure ctx->status and ctx->msg say what went wrong, e.g.
     "amps_factorize: zero or negative pivot at column 17 (original numbering)". A positive
     status (AMPS_WARN_*) is a success with a remark.
     A failed call leaves its objects as they were, except where its declaration says what
     changes: amps_factorize leaves the factor without values, a failed amps_update_commit
     discards the changes recorded since the last commit, and the update calls that commit
     first can fail after their commit went through. Capacities may have grown.
     Objects are owned by the caller, who frees them with the matching *_free, except the mesh
     given to amps_scene_create: the scene owns it from then on, also when the create fails.

   THREAD SAFETY
     No global mutable state: calls on distinct objects (and distinct contexts) may always run
     concurrently. One object (a factor, an engine, a scene and its engine) takes one call at a
     time, with two exceptions: amps_update_watched_run may run on any thread, concurrently with
     the other calls on the engine, between amps_update_watched_begin and _end (it reads only its
     job's vector and the base factor); and the background re-factorization (opts.refactor) runs on a thread of
     its own. That thread reads the engine's base matrix (no call changes it while a job runs),
     a copy of the changes, constraints and forces taken at the start and the engine's change log
     (under the job's mutex), and writes only the job's new base (matrix, factor, engine); the
     caller's engine calls swap a ready job in or drop a failed one, on the caller's thread.
     A haptic model (amps_haptic) points into no scene: amps_haptic_eval reads only it, so a
     haptic thread can evaluate one model while another thread changes the scene and builds the
     next into a second one (amps_scene_haptic_build; the caller swaps the two).
     An amps_ctx is used by one call at a time (it records the last error).
     Worker threads (AMPS_BACKEND_THREADS, the default with nthreads > 1): each factor and
     engine owns nthreads - 1 of them from its creation to its free; they run only chunks of
     loops of their own object's calls and sleep between them, touching nothing else.
     Task callbacks (ctx->enqueue_task, ctx->finish_task): enqueue either returns NULL (not
     queued: amps runs [0, n) itself) or a handle, and the host then runs task on sub-ranges that
     cover [0, n) once each (at least min_range long, except the last), on any threads, in any
     order; finish returns only when every sub-range of that handle has run. A task never calls amps on the object of
     the call that queued it; worker is below ctx->worker_count.
     The log callback (ctx->log) is called only on the thread of the call that got ctx, during
     that call: failures of the background thread reach it at the next call on the engine.

   EXAMPLE
     amps_ctx ctx; amps_ctx_init(&ctx);
     amps_csc *K = amps_csc_from_triplets(&ctx, n, nz, ti, tj, tx, AMPS_UPPER);
     amps_factor *F = amps_analyze(&ctx, K, AMPS_UPPER, NULL);
     if (!F || amps_factorize(&ctx, F, K)) { puts(ctx.msg); ... }
     amps_solve(&ctx, F, b, x, work);
*/
#ifndef AMPS_H
#define AMPS_H

#define AMPS_VERSION_MAJOR 0
#define AMPS_VERSION_MINOR 3
#define AMPS_VERSION_PATCH 0
#define AMPS_VERSION_STRING "0.3.0"

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

/* ==== [amps:common] status codes, the context, the clock ====================================== */

typedef enum amps_status {
    AMPS_OK = 0,
    AMPS_ERR_ARG = -1,             /* invalid argument (NULL, negative count, wrong size)   */
    AMPS_ERR_OOM = -2,             /* allocation failed                                     */
    AMPS_ERR_INDEX = -3,           /* index out of range                                    */
    AMPS_ERR_PATTERN = -4,         /* unsorted / duplicate / inconsistent sparsity pattern  */
    AMPS_ERR_VALUE = -5,           /* NaN or Inf in input                                   */
    AMPS_ERR_NOT_SPD = -6,         /* zero or negative pivot in LDL^T                       */
    AMPS_ERR_SINGULAR_UPDATE = -7, /* the updated system is singular                        */
    AMPS_ERR_CAPACITY = -8,        /* reserved capacity exhausted and growth not allowed    */
    AMPS_ERR_MESH = -9,            /* invalid mesh (degenerate or inverted element, ...)    */
    AMPS_ERR_IO = -10,             /* file could not be opened / read / written             */
    AMPS_ERR_PARSE = -11,          /* malformed file or scenario                            */
    AMPS_ERR_STATE = -12,          /* call not valid in the object's current state          */
    AMPS_ERR_UNSUPPORTED = -13,    /* feature compiled out (e.g. METIS)                     */
    AMPS_WARN_NOOP = 1,            /* success, but nothing was done (e.g. a cut with one empty side) */
    AMPS_WARN_INACCURATE = 2       /* solved, but the accuracy guard's tolerance was not reached */
} amps_status;

/* A range task: runs items [begin, end) on worker `worker` (0 <= worker < worker_count). */
typedef void amps_task_fn(amps_int begin, amps_int end, int worker, void *task_ctx);
/* Host task system (Box2D v3 style). enqueue hands the host n items with a minimum range
   min_range; the host calls task on sub-ranges covering [0, n) exactly once each, on any of its
   workers, and returns a handle it later receives in finish, which returns when every sub-range
   has run. Returning NULL means "not queued": amps runs the task itself, inline.
   Contract: enqueue and finish are called from the thread that called amps (never from amps'
   background re-factorization thread, which runs its kernels serially); the task function may
   run on any thread, concurrently with itself; finish must not return before every sub-range
   has returned. Each item amps enqueues claims the next chunks of the loop from an atomic
   counter (so does the calling thread meanwhile): an item that starts late finds the work done
   and returns at once, and finish waits only for chunks already claimed, provided the host runs
   queued items itself in finish or has free workers. */
typedef void *amps_enqueue_task_fn(amps_task_fn *task, amps_int n, amps_int min_range, void *task_ctx, void *user);
typedef void amps_finish_task_fn(void *handle, void *user);

/* Where the kernels' parallel loops run when no task callbacks are set (amps_ctx.backend).
   AMPS_BACKEND_THREADS: amps' own worker threads (POSIX threads; not with AMPS_NO_THREADS), one
   set per engine and per factor large enough to factor in parallel, started by
   amps_update_create and by the factor's first parallel amps_factorize, joined when the object
   is freed. The calling thread claims chunks too and waits only for chunks a worker has begun,
   never for a worker that has not started: beside other busy processes a loop takes at most
   about as long as running it alone. A loop that finds its object's workers busy (a concurrent
   solve of one factor) runs serially.
   AMPS_BACKEND_OPENMP: an OpenMP parallel region per loop (compiled with -fopenmp); the region
   ends when every thread of the team has arrived, so under load a loop waits for the slowest to
   get a core. */
typedef enum amps_backend {
    AMPS_BACKEND_AUTO = 0,    /* THREADS where compiled (pthreads), else OPENMP where compiled, else serial */
    AMPS_BACKEND_THREADS = 1, /* amps' own threads (serial where there are none) */
    AMPS_BACKEND_OPENMP = 2,  /* OpenMP regions (serial without -fopenmp) */
    AMPS_BACKEND_SERIAL = 3   /* every loop on the calling thread */
} amps_backend;

/* Caller-owned context: allocator user pointer, threads or the host's task system, and the last
   error. The kernels run on the host's task system when enqueue_task and finish_task are set
   (both or neither), else as backend says, on nthreads participants. */
typedef struct amps_ctx {
    void *alloc_user; /* passed as u to AMPS_MALLOC/AMPS_REALLOC/AMPS_FREE */
    int nthreads;     /* participants of a parallel loop (the caller and nthreads - 1 workers);
                         0 = omp_get_max_threads() with OpenMP, else 1; 1 = serial */
    amps_backend backend;               /* without task callbacks (0 = AMPS_BACKEND_AUTO) */
    amps_enqueue_task_fn *enqueue_task; /* host back end (both or neither); NULL = backend */
    amps_finish_task_fn *finish_task;
    void *task_user;  /* passed as user to both */
    int worker_count; /* workers of the host system (>= 1; worker indices < it); 0 = 1 */
    /* optional: warnings (AMPS_WARN_*), accuracy refinements and re-factorizations, and failures
       of the background re-factorization, as they happen (s: their status, AMPS_OK for a
       remark); called on the caller's thread only (see THREAD SAFETY); NULL: none */
    void (*log)(void *user, amps_status s, const char *msg);
    void *log_user;
    amps_status status; /* status of the last call that failed or warned */
    char msg[256];      /* human-readable message for status */
} amps_ctx;

AMPS_API void amps_ctx_init(amps_ctx *ctx);
AMPS_API const char *amps_status_str(amps_status s);
/* Seconds of a monotonic wall clock (arbitrary origin): clock_gettime(CLOCK_MONOTONIC),
   QueryPerformanceCounter on Windows, mach_absolute_time on Apple; define AMPS_NOW() to supply
   your own. Where none of these is available (a strict ISO build that included <time.h> before
   the implementation), omp_get_wtime with OpenMP, else processor time (clock), which the
   re-factorization's cost model then misreads in threaded builds. */
AMPS_API double amps_now(void);
/* AMPS_VERSION_STRING of the implementation ("major.minor.patch"; static storage). */
AMPS_API const char *amps_version(void);

/* ==== [amps:sparse] sparse matrices =========================================================== */

/* Which part of a symmetric matrix a CSC array holds. */
typedef enum amps_stype { AMPS_LOWER = -1, AMPS_FULL = 0, AMPS_UPPER = 1 } amps_stype;

/* Compressed sparse column matrix. Column j holds rows i[p[j] .. p[j+1]-1]. */
typedef struct amps_csc {
    amps_int nrow, ncol;
    amps_int *p; /* ncol+1 column pointers, p[0] = 0 */
    amps_int *i; /* p[ncol] row indices */
    double *x;   /* p[ncol] values (may be NULL for a pattern) */
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

/* ==== [amps:ordering] fill-reducing orderings ================================================= */

typedef enum amps_ordering {
    AMPS_ORDER_AUTO = 0, /* least fill (symbolic count) of AMD, ND and METIS (when built in) */
    AMPS_ORDER_NATURAL,  /* identity */
    AMPS_ORDER_GIVEN,    /* opts->perm */
    AMPS_ORDER_AMD,      /* our approximate minimum degree */
    AMPS_ORDER_ND,       /* our nested dissection (uses opts->coords when given) */
    AMPS_ORDER_METIS     /* METIS_NodeND (needs AMPS_USE_METIS) */
} amps_ordering;

typedef struct amps_order_opts {
    amps_ordering method;
    const amps_int *perm; /* GIVEN: perm[k] = original index eliminated k-th */
    amps_int block;       /* DOFs per node (3 for 3D elasticity): order the compressed node graph
                                and expand; 0 = detect identical consecutive columns, 1 = none */
    const double *coords; /* optional: 3 coordinates per node (per block) for ND; per unknown
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
AMPS_API amps_status amps_order(amps_ctx *ctx, const amps_csc *A, amps_stype stype, const amps_order_opts *opts,
                                amps_int *perm);
/* AMD on a symmetric graph given in CSC with both triangles (diagonal entries ignored; a pattern
   given as one triangle is symmetrized). */
AMPS_API amps_status amps_amd(amps_ctx *ctx, amps_int n, const amps_int *Ap, const amps_int *Ai, amps_int *perm);
/* Nested dissection on the same kind of graph; xyz (3n, may be NULL) guides the bisections.
   Vertices with identical closed neighbourhoods (consecutive) are ordered together. */
AMPS_API amps_status amps_nd(amps_ctx *ctx, amps_int n, const amps_int *Ap, const amps_int *Ai, const double *xyz,
                             amps_int *perm);

/* ==== [amps:symbolic] symbolic analysis ======================================================= */

/* Elimination tree of a symmetric n x n pattern eliminated in the order order[0..n-1] (order[k] =
   vertex eliminated k-th; order and iorder = its inverse both NULL for the identity):
   parent[k] = min { i > k : L(i, k) != 0 } in positions, -1 at roots.
   Column v of (Ap, Ai) lists neighbours of v; only those eliminated before v are read, so the
   pattern is either both triangles, or (identity order) the upper triangle. Diagonal entries and
   duplicates are allowed. parent (n) is written; work (n) is workspace.
   Cost O(nnz log n) (ancestor path compression). */
AMPS_API void amps_etree(amps_int n, const amps_int *Ap, const amps_int *Ai, const amps_int *order,
                         const amps_int *iorder, amps_int *parent, amps_int *work);
/* Postorder of the forest parent[0..n-1] (parent[j] > j or -1): post[k] = k-th node of a depth-first
   traversal that lists every node after its descendants, roots and children in ascending order, so
   the nodes of each subtree are consecutive. post (n) is written; work (3n) is workspace. Cost O(n). */
AMPS_API void amps_postorder(amps_int n, const amps_int *parent, amps_int *post, amps_int *work);
/* Column counts of L for the lower triangle of a symmetric pattern C (positions, i.e. already
   permuted): cc[j] = |struct L(:, j)| including the diagonal = number of row subtrees holding j.
   Column j of (Cp, Ci) lists rows i of C(i, j) != 0; entries with i <= j are ignored. parent is the
   elimination tree of C (amps_etree) and post a postorder of it (amps_postorder). cc (n) is written;
   work (4n) is workspace. Cost O(nnz(C) log n) (least common ancestors by path compression). */
AMPS_API void amps_colcounts(amps_int n, const amps_int *parent, const amps_int *post, const amps_int *Cp,
                             const amps_int *Ci, amps_int *cc, amps_int *work);

/* ==== [amps:numeric] the LDL^T factor ========================================================= */

/* K = P L D L^T P^T. Everything in permuted numbering unless said otherwise:
   pivot k is original index perm[k]; L is unit lower triangular, stored strictly below the
   diagonal, column by column, rows ascending; parent is the elimination tree (parent[j] > j,
   -1 at roots), so the ancestors of j are the path j -> root and ascending order is topological. */
typedef struct amps_factor {
    amps_int n;
    amps_int *perm, *iperm; /* perm[k] = original index of pivot k; iperm[perm[k]] = k */
    amps_int *parent;       /* elimination tree */
    amps_int *Lp, *Li;      /* strictly lower part of L, CSC (n+1, Lp[n]) */
    double *Lx;             /* values of L */
    double *D;              /* n pivots */
    amps_int height;        /* nodes on the longest leaf-to-root path of the elimination tree */
    int is_numeric;         /* 1 after a successful amps_factorize */
    amps_int failed;        /* the column (original numbering) whose pivot the last amps_factorize refused, -1 */
    void *priv;             /* implementation data (pattern maps, workspace) */
} amps_factor;

/* Ordering + elimination tree + column counts + Lp for symmetric A (stype part); allocates L.
   opts may be NULL (AMPS_ORDER_AUTO, block detection). With AMPS_FULL only entries with row <= column
   are read (A is taken as symmetric). Also builds the pattern Li and the scatter map of A into L, and
   the workspace of amps_factorize for the participants of ctx's back end (host workers + 1, or
   ctx->nthreads). */
AMPS_API amps_factor *amps_analyze(amps_ctx *ctx, const amps_csc *A, amps_stype stype, const amps_order_opts *opts);
/* Numeric LDL^T of A, which must have the pattern given to amps_analyze, stored as the same
   triangle (values may differ; AMPS_ERR_PATTERN otherwise).
   A pivot must be finite and exceed AMPS_PIVOT_TOL (default 1e-12) times the column's diagonal entry
   of A, else AMPS_ERR_NOT_SPD names the failing column in the original numbering; F is then not
   numeric. Runs on ctx's back end (at most the participants of amps_analyze); the result does
   not depend on the back end or the thread count. Allocates nothing, except that the first call
   that factors in parallel on amps' own workers starts the factor's nthreads - 1 threads (kept
   until amps_factor_free; none if they cannot start: the loops then run serially). */
AMPS_API amps_status amps_factorize(amps_ctx *ctx, amps_factor *F, const amps_csc *A);
AMPS_API void amps_factor_free(amps_ctx *ctx, amps_factor *F);
/* Number of entries of L, counting the unit diagonal. */
AMPS_API double amps_factor_nnz(const amps_factor *F);
/* Counts of positive, negative and zero pivots in D. */
AMPS_API void amps_factor_inertia(const amps_factor *F, amps_int *npos, amps_int *nneg, amps_int *nzero);

/* ==== [amps:solve] triangular solves and closures ============================================= */

/* Reusable marker over 0..n-1: j is marked iff mark[j] == stamp; clearing is ++stamp. */
typedef struct amps_marker {
    amps_int n;
    amps_int stamp;
    amps_int *mark;
} amps_marker;
AMPS_API amps_status amps_marker_init(amps_ctx *ctx, amps_marker *m, amps_int n);
AMPS_API void amps_marker_free(amps_ctx *ctx, amps_marker *m);
/* Grows m to n indices (nothing if n <= m->n); the new ones are unmarked and the current marking
   goes on. AMPS_ERR_OOM leaves m as it was. */
AMPS_API amps_status amps_marker_grow(amps_ctx *ctx, amps_marker *m, amps_int n);
/* Starts a new marking; all indices become unmarked in O(1) (amortized). */
AMPS_API void amps_marker_next(amps_marker *m);

/* closure_L(idx) = union of the elimination-tree paths from idx[0..nidx-1] (permuted numbering)
   to their roots. Writes it to out (room for n) in ascending (topological) order, returns its
   size. Cost O(closure size + its sort). Uses m (starts a new marking). */
AMPS_API amps_int amps_closure(const amps_factor *F, amps_int nidx, const amps_int *idx, amps_int *out, amps_marker *m);

/* Full solve K x = b in the original numbering; x may equal b; work has n doubles. The backward
   solve of a large factor runs on ctx's back end (same result on any). */
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
/* The same backward solve over a closure computed once by amps_closure (ascending, closed
   under parent): x = L^{-T} y on closure[0..cnt-1] only. Reads L's columns in the closure. */
AMPS_API void amps_ltsolve_closure(const amps_factor *F, amps_int cnt, const amps_int *closure, double *y);
/* Solves K X = B for nrhs right-hand sides: columns of B (leading dimension ldb >= n) into X
   (ldx >= n; X may equal B), original numbering. Blocks of 4 columns run in parallel on ctx's
   back end. work: amps_solve_multi_work(ctx, F, nrhs) doubles (4n per participant: host workers
   + 1, or ctx->nthreads; query it with the same ctx settings). Allocates nothing. */
AMPS_API amps_status amps_solve_multi(amps_ctx *ctx, const amps_factor *F, amps_int nrhs, const double *B, amps_int ldb,
                                      double *X, amps_int ldx, double *work);
AMPS_API size_t amps_solve_multi_work(const amps_ctx *ctx, const amps_factor *F, amps_int nrhs);
/* Estimate of the 1-norm condition number ||K||_1 ||K^{-1}||_1 of the symmetric matrix K (stype
   part, original numbering) whose numeric factor is F (Hager's method with Higham's refinements,
   as LAPACK's xLACON: at most 5 iterations of 2 solves each, plus one extra solve). The estimate is
   a lower bound of the true value, almost always within a factor 3. work: 3n doubles, or NULL to
   let the call allocate (and free) them; with work given it allocates nothing. K and F are only
   read. Errors: AMPS_ERR_ARG (NULL, sizes of K and F differ), AMPS_ERR_STATE (F not numeric),
   AMPS_ERR_VALUE (estimate not finite), AMPS_ERR_OOM (work NULL and allocation failed); *cond is
   written only on success. */
AMPS_API amps_status amps_condest(amps_ctx *ctx, const amps_csc *K, amps_stype stype, const amps_factor *F,
                                  double *work, double *cond);
#ifdef AMPS_COUNT_TOUCH
/* Instrumentation (define AMPS_COUNT_TOUCH before including): L entries read by amps_lsolve_sparse and
   amps_ltsolve_partial on F since the last reset. */
AMPS_API double amps_touch_count(const amps_factor *F);
AMPS_API void amps_touch_reset(const amps_factor *F);
#endif

/* ==== [amps:update] augmented updates: the AMPS engine ======================================== */
/* The update engine keeps the exact solution of K^ x = f^ while K^ changes from the factored
   base K (order n) by principal submatrix updates, appended degrees of freedom and Dirichlet
   constraints ([AMPS] Table 1, Steps 1-6). Indices are in the current numbering: 0..n-1 are
   K's rows in its original numbering, n.. are appended DOFs in order of creation.

   Changes are recorded by the update calls and applied atomically by amps_update_commit (called
   by amps_update_solve and the other solves). A failed call leaves the engine as it was (only
   capacities may have grown), with one exception: a failed commit also discards every change
   recorded since the last successful commit (see amps_update_commit). The calls that commit
   first and can fail after their commit went through say so.

   Allocation: amps_update_create allocates everything for the capacities in opts. Update,
   commit and solve calls allocate only when a capacity is exceeded and opts.grow is set
   (otherwise they fail with AMPS_ERR_CAPACITY and change nothing). */
typedef struct amps_update amps_update;

typedef enum amps_formulation {
    AMPS_FORM_PRIMAL =
            0, /* unknowns x_S ([AMPS] Eq. 3.8); with opts.xs_from_dense, x_S taken from the small system (Eq. 3.20) */
    AMPS_FORM_DUAL = 1 /* unknowns the correction forces ([AMPS] Eq. 3.16-3.17) */
} amps_formulation;

/* Re-factorization ([Interactive cutting] Sec. 3.6): the augmentation (S u C, the memoized
   columns, the dense system) only grows, and every step pays for it. A re-factorization factors the current
   matrix K^ + sigma P_C (C: the indices constrained at its start, whose rows stay in the
   augmentation with Delta = -sigma e_i e_i^T) with its own analysis, in a background thread,
   while updates and solves go on with the old factors. When it is done, the next call that
   commits (or amps_update_refactor_wait) swaps it in: the changes made since it started (m')
   are re-expressed on the new base, whose augmentation is then C and m' only. The swap costs a
   commit of those changes. The indices keep their numbering.
   Memory: at most two factorizations (and two augmentations) exist at a time; the old ones are
   freed at the swap, except the storage of a retired base's L (12 bytes per entry of L, plus up
   to a quarter), which the next re-factorization reuses (fresh pages cost a page fault each on
   first touch) and amps_update_free frees. A failed re-factorization (not SPD, out of memory)
   is reported by amps_update_refactor_wait / the stats and the engine goes on with the old
   factors.
   With AMPS_NO_THREADS there is no background thread: AUTO does nothing and start/refactor
   run synchronously. Custom allocators (AMPS_MALLOC) must then be thread-safe.
   Triggers (AUTO): the cost model after a full amps_update_solve (refactor_ratio), and after every
   commit, whatever solve follows it, the size: a commit that leaves |S u C| above
   refactor_size plus its size at the last base starts one. So |S u C| stays below
   |C| + refactor_size + the growth during one re-factorization, and the haptic step
   (amps_update_solve_reactions with only prescribed values moved, O(|S u C|^2)) stays bounded.
   Deterministic mode (COUNT): structural commits (those that change K^, add DOFs or grow S u C)
   are counted; the one that brings the count since the last base to refactor_every starts a
   re-factorization, and the first commit that may swap (not amps_update_solve_reactions) after
   refactor_every / 2 more structural commits waits for it and swaps it in. The worker only
   factors (the swap replays every change since the start), so identical call sequences give
   identical bits; AUTO depends on the clock.
   Which calls may take how long: a swap (O(one commit of the changes since the start)) happens
   only at the start of amps_update_commit, solve, solve_watched, watched_begin, refactor_wait and
   refactor, never in amps_update_solve_reactions; a commit costs Steps 1-5 (Step 1: the
   L^{-1} columns of the new indices, O(their closures); Steps 2-3: O(|S u C| x new); Step 5:
   O(|S u C|^2 x changed columns)); a start copies the augmentation (O(|Delta| + N)). */
typedef enum amps_refactor_policy {
    AMPS_REFACTOR_AUTO = 0,   /* start by the cost model and the size (only with threads) and on request */
    AMPS_REFACTOR_MANUAL = 1, /* only on request */
    AMPS_REFACTOR_OFF = 2,    /* never */
    AMPS_REFACTOR_COUNT = 3   /* deterministic: at points fixed by the count of structural commits */
} amps_refactor_policy;
/* AUTO and COUNT also commit a change set whose dense work would exceed about four
   factorizations (thousands of new indices: a fracture that tears a large part away) by a
   synchronous re-factorization of K^ with the changes applied, inside amps_update_commit
   (stats.commit_folds; the point depends on the change set only, not on the clock). */

/* Options; amps_update_opts_default gives the defaults. A capacity, refactor_threads or
   refactor_ratio that is 0 or negative means its default. */
typedef struct amps_update_opts {
    amps_int cap_mod;     /* capacity of |S u C| (order of the dense system); default 256 */
    amps_int cap_new;     /* capacity of appended DOFs; default 3 * 256 */
    double cap_vpool;     /* memoized L^{-1} columns, in entries; default cap_mod * tree height */
    amps_int cap_delta;   /* stored entries of K^ - K-bar on S x S; default 96 * cap_mod */
    amps_int cap_pending; /* changes recorded between commits; default 4096 */
    int grow;             /* 1: grow capacities on demand (may allocate in update calls) */
    amps_formulation formulation;
    double singular_tol;            /* pivot of the dense system below tol * column norm: the commit goes to a
                                       re-factorization (amps_update_commit); default 1e-13 (about 450 eps: a
                                       singular K^ leaves a pivot at the rounding level of the dense system) */
    int refine;                     /* refinement steps on the residual of the modified rows inside the same
                               full solve (default 1; each adds a partial backward solve over
                               closure(S u C u neighbours) and O(|S u C|^2)); 0 = none */
    int xs_from_dense;              /* 1: take x_S from the small dense system ([AMPS] Eq. 3.20) instead of the full
                               solve; default 0 (see bench/RESULTS.md) */
    double guard_tol;               /* accuracy guard: > 0 computes the relative residual of every solve (one
                               product with K^) and, while it exceeds guard_tol, refines with the
                               same factors (each step one more forward and backward solve), at
                               most 3 steps; if still above, re-factors synchronously (unless
                               refactor is OFF) and solves again; stats.guard_result says which
                               happened; AMPS_WARN_INACCURATE if the tolerance was not reached.
                               0 (default) = off */
    amps_refactor_policy refactor;  /* re-factorization of the current matrix (see below); default AUTO */
    amps_order_opts refactor_order; /* its ordering; default nested dissection with node blocks
                                      detected (block 0); with block > 0 (the scene sets 3) the
                                      couplings a change cancelled exactly leave the pattern too.
                                      AMD often has less fill but a tall elimination tree: long
                                      closures make Steps 1-2 slower */
    int refactor_threads;           /* threads of the background factorization; default 1: the
                                      worker, and (when the engine's back end has 2 or more participants)
                                      one helper thread that takes the factorization's parallel chunks
                                      only while no commit or solve of the engine runs; same bits */
    double refactor_ratio;          /* AUTO: start when the extra time the augmentation has cost since the
                               last base reaches this times the (measured or estimated) time of a
                               re-factorization; default 0.25: it runs on another core, so the steps
                               lose less than its time (1 would be rent or buy; bench/RESULTS.md) */
    double refine_tol;              /* accuracy of amps_update_solve (and the scene solve): the mixed backward
                               error omega = ||r_F|| / || |K^| |x| + |f^| ||_F, r = f^ - K^ x, of
                               every full solve (F: free indices) from one product with K^ (skipped
                               where Step 6 cancels little: stats.cancel_ratio <= 1), and
                               while omega > refine_tol and omega > 4 omega_d (omega_d: what a direct
                               solve with the base factor reaches on K-bar, measured once per base)
                               refinement steps with the same factors (each
                               a forward and a backward solve, the residual in double-double; at
                               most 3, stopping when omega no longer halves); on a base whose
                               condition estimate exceeds 9.0e6 (stats.base_cond) every full
                               solve takes one step, for its forward error; when the normwise
                               eta = ||r_F|| / (||K^||_inf ||x_F|| + ||f^_F||) <= omega is still
                               above 64 refine_tol after them a synchronous
                               re-factorization (unless refactor is OFF) and the solve again.
                               After a solve from zero that took a step (two in a row unless its
                               forces changed on many rows, as in a time step), the next 16 full
                               solves start from the last solution x0 (x = x0 + K^{-1} (f^ - K^ x0),
                               one product with K^ more, and a forward solve more unless the forces
                               changed on many rows; stats.warm_solves): when consecutive solutions
                               are close they meet the tolerance without a step.
                               Default 2.2e-16 (1 eps: the level of a fresh direct solve);
                               0 = off (solves then cost no product with K^) */
    amps_int refactor_size;         /* AUTO: start after a commit that grows |S u C| past its size at the
                                      last base plus this; default 384 */
    amps_int refactor_every;        /* COUNT: structural commits between re-factorizations; default 32 */
    int refactor_reuse;             /* 1 (default): a re-factorization keeps the base's ordering with each
                                      appended DOF placed right after its origin (amps_update_set_origin)
                                      and the base's analysis when the pattern is unchanged; a fresh
                                      ordering (refactor_order) when the kept one's nnz(L) exceeds 1.2x
                                      the last fresh one's fill per entry of the matrix, for the first
                                      and every 16th, and in amps_update_refactor. 0: always a fresh
                                      ordering */
} amps_update_opts;

/* The steps of [AMPS] Table 1, indices of amps_update_stats.t_step. */
typedef enum amps_update_step {
    AMPS_STEP_WCOLS = 0, /* Step 1: L^{-1} columns */
    AMPS_STEP_GRAM = 1,  /* Step 2: inverse principal submatrix G */
    AMPS_STEP_DCOLS = 2, /* Step 3: dense columns */
    AMPS_STEP_RHS = 3,   /* Step 4: right-hand side */
    AMPS_STEP_DENSE = 4, /* Step 5: dense factor and solve */
    AMPS_STEP_SOLVE = 5, /* Step 6: full solution */
    AMPS_STEP_COUNT = 6
} amps_update_step;

/* Outcome of the accuracy guard in the last solve (amps_update_stats.guard_result). */
typedef enum amps_guard_result {
    AMPS_GUARD_MET = 0,        /* tolerance met at once (also: guard off) */
    AMPS_GUARD_REFINED = 1,    /* met after refinement steps */
    AMPS_GUARD_REFACTORED = 2, /* met after a synchronous re-factorization */
    AMPS_GUARD_NOT_MET = 3     /* not met (AMPS_WARN_INACCURATE) */
} amps_guard_result;

/* Per-commit and per-solve measurements (seconds) and sizes. */
typedef struct amps_update_stats {
    double t_step[AMPS_STEP_COUNT]; /* time of each step (amps_update_step) */
    amps_int dim;                   /* current order n + k */
    amps_int nmod;                  /* |S|: indices whose row differs from K-bar */
    amps_int ncon;                  /* |C|: constrained indices */
    amps_int nsys;                  /* |S u C|: order of the dense system */
    amps_int lu_cols;               /* dense columns refactored by the last commit */
    amps_int lu_full;               /* full dense refactorizations so far */
    amps_int lu_drops;              /* commits that moved their changed dense columns to the end without
                               refactoring the unchanged columns after them (amps__lu_drop) */
    amps_int lu_drop_fails;         /* ... of which fell back to refactoring them (a multiplier, an entry of L
                               or a pivot out of bounds) */
    double vpool_entries;           /* memoized entries of L^{-1} H */
    amps_int ncommit, nsolve;
    amps_int guard_steps;           /* refinement steps of the last solve (opts.refine_tol and the guard) */
    amps_guard_result guard_result; /* last solve (AMPS_GUARD_MET when the guard is off) */
    double relres;                  /* relative residual of the last solve when the guard is on, else -1 */
    amps_int nrefactor;             /* re-factorizations swapped in */
    amps_int refactor_failed;       /* re-factorizations that failed (the engine kept its factors) */
    amps_int commit_folds;          /* commits too large for the augmentation, done as a synchronous
                                       re-factorization with the changes applied (among nrefactor) */
    amps_int pivot_folds;           /* of them, commits whose dense pivot test failed (an ill-conditioned
                                       K^; a singular one fails the re-factorization too) */
    int refactor_running;           /* 1 while one is in progress (started, not yet swapped) */
    double t_refactor;              /* wall time of the last one, start to ready (background) */
    double t_swap;                  /* time of its swap (inside the call that did it) */
    double refactor_nnzL;           /* nnz(L) of the current base */
    double backward_error;          /* normwise backward error eta of the last amps_update_solve (opts.refine_tol),
                               -1 when neither it nor the guard is on, or the check was skipped */
    amps_int refine_solves;         /* refinement steps (one forward and one backward solve each) so far */
    amps_int warm_solves;           /* full solves started from the last solution (opts.refine_tol) so far */
    amps_int checks_skipped;        /* full solves whose product with K^ was skipped (cancellation ratio at
                                       most 1, no forward step, guard off; backward_error -1 then) */
    double cancel_ratio;            /* Step 6's cancellation ratio mu of the last full solve (-1: none) */
    double base_cond;               /* kappa_1(K-bar) of the current base, estimated at its creation when
                               opts.refine_tol > 0 (amps_condest; it sets the forward refinement) */
    /* the last re-factorization swapped in, by phase (wall time in the worker): */
    double t_refactor_order;    /* fresh ordering (0 when the base's was kept) */
    double t_refactor_symbolic; /* symbolic analysis (or the copy of the base's) */
    double t_refactor_numeric;  /* numeric factorization */
    double t_refactor_catchup;  /* the new base's engine and the changes replayed in the worker */
    int refactor_order_kept;    /* 0 fresh ordering, 1 the base's kept (DOFs placed), 2 its analysis kept */
    int refactor_reused;        /* 1: it took a retired base's storage for L (see the memory note above) */
    double refactor_fill;       /* its nnz(L) / (nnz(L) per matrix entry of the last fresh ordering x nnz) */
} amps_update_stats;

AMPS_API void amps_update_opts_default(amps_update_opts *opts);
/* Engine for base matrix K (stype part, original numbering) and its numeric factor F, which
   must stay alive and unchanged until amps_update_free (after a re-factorization the engine
   works on its own factor, amps_update_factor). K is copied. Forces start at zero. */
AMPS_API amps_update *amps_update_create(amps_ctx *ctx, const amps_csc *K, amps_stype stype, const amps_factor *F,
                                         const amps_update_opts *opts);
AMPS_API void amps_update_free(amps_ctx *ctx, amps_update *U);
/* Current order n + k, counting DOFs added since the last commit. */
AMPS_API amps_int amps_update_dim(const amps_update *U);
/* Appends k DOFs with zero rows and zero force; *first receives the index of the first. */
AMPS_API amps_status amps_update_add_dofs(amps_ctx *ctx, amps_update *U, amps_int k, amps_int *first);
/* K^[r,c] += v and K^[c,r] += v for the nz entries (r[k], c[k], v[k]) (one entry per pair). */
AMPS_API amps_status amps_update_add(amps_ctx *ctx, amps_update *U, amps_int nz, const amps_int *r, const amps_int *c,
                                     const double *v);
/* Replaces rows (and by symmetry columns) rows[0..nrow-1] of K^ with new values: row rows[k] has
   entries (ci[j], cx[j]) for j in cp[k]..cp[k+1]-1; entries not given become zero. Where two
   given rows meet, their values must agree (to 1e-12 relative). */
AMPS_API amps_status amps_update_set_rows(amps_ctx *ctx, amps_update *U, amps_int nrow, const amps_int *rows,
                                          const amps_int *cp, const amps_int *ci, const double *cx);
/* Constrains x[idx[k]] = val[k] (adds the constraint, or moves it). */
AMPS_API amps_status amps_update_constrain(amps_ctx *ctx, amps_update *U, amps_int m, const amps_int *idx,
                                           const double *val);
/* Removes constraints; indices that are not constrained are ignored. */
AMPS_API amps_status amps_update_release(amps_ctx *ctx, amps_update *U, amps_int m, const amps_int *idx);
/* Sets f^[idx[k]] = val[k]. */
AMPS_API amps_status amps_update_set_force(amps_ctx *ctx, amps_update *U, amps_int m, const amps_int *idx,
                                           const double *val);
/* Drops every change recorded since the last commit (forces stay). */
AMPS_API void amps_update_discard(amps_update *U);
/* Applies the recorded changes (Steps 1-5). On failure (AMPS_ERR_SINGULAR_UPDATE, AMPS_ERR_CAPACITY,
   AMPS_ERR_OOM) the committed system is restored: matrix, constraints, forces and watch set as
   before the call; the solution and reactions are marked stale and the dense factor is
   recomputed, so later results agree with the earlier ones to rounding, not bitwise. The
   exception to the failure rule: every change recorded since the last successful commit is
   discarded (as by amps_update_discard); record them again, corrected, to retry. A finished
   re-factorization the call swapped in first stays swapped in. A change set too large for the
   augmentation is committed by a synchronous re-factorization (see amps_refactor_policy: allocates
   as one, and amps_update_factor changes); if that fails, through the augmentation as usual.
   AMPS_ERR_SINGULAR_UPDATE comes from a pivot of the dense system below singular_tol of its
   column; an ill-conditioned K^ (stiffness ratios of 1e6, nu near 0.5) can meet one too, so the
   changes are then committed by a synchronous re-factorization of K^ with them applied (any
   policy; stats.pivot_folds; not while a two-phase watched solve runs), and refused only if
   that finds K^ singular. */
AMPS_API amps_status amps_update_commit(amps_ctx *ctx, amps_update *U);
/* The same in two phases, for a caller whose haptic thread must not wait for a commit's Steps 1-2
   (the L^{-1} columns of the new indices and the new rows of G: the expensive part):
     amps_update_commit_begin (under the caller's lock) swaps a ready re-factorization in, takes
                              the recorded structural changes (matrix entries, DOFs, new
                              constraints, releases), places their new indices and reserves
                              their memory; the engine still shows the committed system;
     amps_update_commit_run   (no lock) Steps 1-2 on memory no other call reads or writes;
     amps_update_commit_end   (under the lock) Steps 3 and 5 (O(|S u C|^2 x changed columns))
                              with the moves recorded since applied after the job's changes.
   Between begin and end the other calls work on the committed system: solves (haptic
   amps_update_solve_reactions, watched and full ones), moves of constraints (amps_update_constrain
   of a constrained index) and forces; any other change (amps_update_add, set_rows, add_dofs,
   release, a new constraint) fails with AMPS_ERR_STATE, and nothing swaps a re-factorization
   in. A change set without new indices or releases is committed by begin at once (run and end
   then do nothing). One job at a time; end without run runs it. Allocates (begin: the run
   phase's workspace, nbuf x base order, once, and capacities as amps_update_commit). Failures
   as amps_update_commit: begin (capacity, memory) or end (singular, capacity) discards the
   recorded changes and leaves the committed system. Results equal amps_update_commit's bitwise. */
AMPS_API amps_status amps_update_commit_begin(amps_ctx *ctx, amps_update *U);
AMPS_API void amps_update_commit_run(amps_update *U);
AMPS_API amps_status amps_update_commit_end(amps_ctx *ctx, amps_update *U);
/* Commits, then solves (Step 6): x (room for amps_update_dim, may be NULL) receives the solution,
   refined until its backward error on the current K^ is at most opts.refine_tol (default: that
   of a fresh direct solve; stats.backward_error) or within 4x of what a direct solve with the
   base factor reaches; the product with K^ that measures it is skipped where Step 6 cancelled
   little (stats.cancel_ratio <= 4: x then has a direct solve's rounding). A failed commit: see
   amps_update_commit.
   AMPS_WARN_INACCURATE (accuracy guard) is a warning: the solution is stored, and the guard may
   have re-factored. */
AMPS_API amps_status amps_update_solve(amps_ctx *ctx, amps_update *U, double *x);
/* Watch set: the indices amps_update_solve_watched computes (replaces the previous set; m = 0
   clears it). closure_L of the watched indices is computed here, once. Allocates the set (and
   room for a closure of n indices) on the first call or when the set outgrows it. */
AMPS_API amps_status amps_update_watch(amps_ctx *ctx, amps_update *U, amps_int m, const amps_int *idx);
/* Commits, then computes x on the watched indices only: xw[k] = x[idx[k]] (xw may be NULL; the
   values also land in amps_update_solution, whose other entries are then stale). The backward
   solve reads L only on closure_L(watched) and, for the local refinement, on the closure of
   the unconstrained rows of S u C and their neighbours (none while S u C holds only
   constrained rows, such as pins: no refinement then). Updates the reactions too. Allocates
   nothing. After an amps_update_solve with no change since, x is current and nothing is solved
   (the watched values are the full solve's). Neither the default refinement (opts.refine_tol)
   nor the guard: a product with K^ would cost more than this solve, so x is the augmented
   solve's with the local refinement (opts.refine), whose backward error on a badly conditioned
   K^ can exceed a fresh direct solve's (measured up to 0.02 eps sqrt(cond(K^)),
   bench/RESULTS.md section 6b); amps_update_solve gives x at that level.
   AMPS_ERR_INDEX (a watched index no longer exists) comes before the commit; a failed commit:
   see amps_update_commit. */
AMPS_API amps_status amps_update_solve_watched(amps_ctx *ctx, amps_update *U, double *xw);
/* The same in two phases, for a caller whose second thread runs the backward solve outside the
   lock it holds for every other engine call (a 60 Hz visual loop beside a 1 kHz haptic loop):
     amps_update_watched_begin  (under the lock) commits, Steps 4-5 and the right-hand side of the
                                backward solve into job->y (caller-owned, ylen doubles: at least
                                amps_update_base_order after the commit, which a re-factorization
                                raises to the dimension at its start, so amps_update_dim always
                                suffices; AMPS_ERR_CAPACITY otherwise), and the watched values the dense
                                system gives into xw (caller-owned, the watch set's size);
     amps_update_watched_run    (no lock: reads only job and the factor) the backward solve on
                                closure_L(watched), completing xw;
     amps_update_watched_end    (under the lock) ends the job.
   One job at a time; the watch set must not change between begin and end; other engine calls
   may run meanwhile (the factor the job reads stays alive until end). Allocates nothing.
   amps_update_watched_begin fails before its commit (bad arguments, a job in progress, a watched
   index gone: nothing changes), in the commit (see amps_update_commit), or after it with
   AMPS_ERR_CAPACITY (y too short): then the changes stay committed and no job is started. */
typedef struct amps_update_job {
    const amps_factor *F;        /* the factor the job reads */
    amps_int nw, ncw;            /* watched entries, closure size */
    const amps_int *widx, *wclo; /* watched indices, their closure (engine-owned) */
    const unsigned char *wovr;   /* 1: xw[k] was set by begin */
    double *y, *xw;              /* caller-owned */
} amps_update_job;
AMPS_API amps_int amps_update_base_order(const amps_update *U);
AMPS_API amps_status amps_update_watched_begin(amps_ctx *ctx, amps_update *U, amps_update_job *job, double *y,
                                               amps_int ylen, double *xw);
AMPS_API void amps_update_watched_run(amps_update_job *job);
AMPS_API void amps_update_watched_end(amps_update *U, amps_update_job *job);
/* Commits, then computes the reaction forces at the constrained indices from the dense system
   alone (Steps 4-5, no full solve): O(|S u C|^2) when only prescribed values moved, plus a sparse
   forward solve over closure_L of the changed forces and O(sum of root paths) when forces
   changed. The haptic path: a pin moved, read its force. amps_update_solution is not updated.
   Its commit never swaps in nor starts a re-factorization (the next other commit does).
   Allocates nothing. A failed commit: see amps_update_commit. */
AMPS_API amps_status amps_update_solve_reactions(amps_ctx *ctx, amps_update *U);
/* Solution of the last solve (amps_update_dim entries at that time). */
AMPS_API const double *amps_update_solution(const amps_update *U);
/* Reaction force (K^ x - f^)[i] at constrained index i after the last solve (any of the three
   kinds); 0 if not constrained. */
AMPS_API double amps_update_reaction(const amps_update *U, amps_int i);
/* Relative residual of the constrained system after the last solve:
   ||(K^ x - f^)_F|| / ||f^_F - K^_FC x_C||, F = unconstrained indices (one sparse product). */
AMPS_API amps_status amps_update_residual(amps_ctx *ctx, amps_update *U, double *relres);
AMPS_API void amps_update_get_stats(const amps_update *U, amps_update_stats *st);
/* The current base factor (the one given at creation until a re-factorization is swapped in). */
AMPS_API const amps_factor *amps_update_factor(const amps_update *U);
/* Starts a re-factorization of the current (committed) matrix; returns at once (AMPS_WARN_NOOP
   if one is already running). Copies the changes of the augmentation (O(|Delta| + N)); may
   allocate. Without threads it runs synchronously (like amps_update_refactor). */
AMPS_API amps_status amps_update_refactor_start(amps_ctx *ctx, amps_update *U);
/* Blocks until the running re-factorization is done and swaps it in. AMPS_OK if swapped (or
   none running: AMPS_WARN_NOOP); its error (the engine unchanged) if it failed. */
AMPS_API amps_status amps_update_refactor_wait(amps_ctx *ctx, amps_update *U);
/* Stops a running re-factorization and frees it; blocks until the thread has stopped (at most
   one phase: ordering, analysis, factorization or a catch-up commit). */
AMPS_API void amps_update_refactor_cancel(amps_ctx *ctx, amps_update *U);
/* Commits, then re-factors synchronously (start + wait) with a fresh ordering (opts.refactor_order,
   never the kept one of opts.refactor_reuse). Blocks. A failed commit: see
   amps_update_commit; a failed re-factorization leaves the changes committed and the engine on
   its old factors. */
AMPS_API amps_status amps_update_refactor(amps_ctx *ctx, amps_update *U);
/* Applies the inverse of the committed constrained system to a caller's right-hand side:
   x_F = K^_FF^-1 rhs_F and x_C = 0 (F: free indices, C: constrained ones; rhs_C is ignored),
   through the augmented solve (the base factor and the dense system, with the local refinement
   of opts.refine, no backward-error refinement). rhs and x have amps_update_dim entries (x may
   be rhs). The engine's forces, solution and reactions do not change. Commits pending changes
   first (a failed commit: see amps_update_commit; a ready re-factorization may swap in there).
   Like amps_update_solve it feeds the AUTO re-factorization cost model with its time, which may
   start a background re-factorization (that allocates); otherwise it allocates nothing after the
   commit. It uses the engine's workspace: no other call on U may run meanwhile. A
   preconditioner for iterative solves of nearby matrices (the scene's corotational step). */
AMPS_API amps_status amps_update_solve_rhs(amps_ctx *ctx, amps_update *U, const double *rhs, double *x);
/* Declares appended DOFs idx[k] (added, perhaps not yet committed) copies of indices orig[k] < idx[k]
   (the DOFs of a cut's node copy v' of v): a re-factorization that keeps the base's ordering
   (opts.refactor_reuse) places each right after its origin; a DOF without one is placed after
   its neighbour (in the matrix at the start of the re-factorization) eliminated last. Allocates
   the table (grown with the dimension). Errors: AMPS_ERR_ARG, AMPS_ERR_INDEX (idx[k] not an
   appended DOF, orig[k] not below it), AMPS_ERR_OOM; a failure changes nothing. */
AMPS_API amps_status amps_update_set_origin(amps_ctx *ctx, amps_update *U, amps_int m, const amps_int *idx,
                                            const amps_int *orig);

/* ==== [amps:fem] mesh and P1 elasticity ======================================================= */
#ifndef AMPS_NO_FEM
/* The elasticity is linear (small strains, small displacements, isotropic Hooke material): K is
   the stiffness of the reference configuration and does not follow large deformations, except in
   the scene's corotational dynamics (amps_scene_corotational: element stiffness rotated with each
   tet, exact for rigid motions). */
/* ---- tetrahedral mesh ---- */

/* Tetrahedral mesh in the reference configuration, with the node copies made by cuts.
   Nodes 0..nfile-1 are the nodes given at creation (origin[v] = v); nodes nfile..nnode-1 are
   copies made by amps_mesh_cut, origin[v] = the creation node they descend from. A copy has
   the reference coordinates of its origin. Every tet has 4 distinct nodes and nonzero volume;
   either orientation is allowed. Material: E[t], nu[t] (default E = 1, nu = 0.3).
   Incidence: the tets containing node v are inc[inc_ptr[v] .. inc_ptr[v] + inc_len[v] - 1],
   in ascending order. The slots of all nodes partition inc[0 .. 4*ntet-1]; a cut splits the
   slot of v into the slots of v and its copy, so incidence never needs more memory.
   Removed tets (amps_mesh_remove) keep their index and nodes but are in no incidence list; the
   slots of the nodes then cover only part of inc.
   Fields are read-only for callers: change a mesh only through amps_mesh_* functions. */
typedef struct amps_mesh {
    amps_int nnode;    /* nodes in use */
    amps_int nfile;    /* nodes given at creation */
    amps_int ntet;     /* tetrahedra */
    amps_int node_cap; /* allocated node capacity (>= nnode) */
    double *xyz;       /* 3 * node_cap: reference coordinates of node v at xyz[3v .. 3v+2] */
    amps_int *tet;     /* 4 * ntet node indices */
    double *E, *nu;    /* ntet: Young's modulus and Poisson ratio */
    amps_int *origin;  /* node_cap */
    amps_int *inc_ptr; /* node_cap */
    amps_int *inc_len; /* node_cap */
    amps_int *inc;     /* 4 * ntet tet indices */

    amps_int *region;                   /* ntet: region attribute (0 when the file has none) */
    double *rho;                        /* ntet: density (default 1) */
    unsigned char *removed;             /* ntet: 1 = removed (indices never shift) */
    amps_int nremoved;                  /* tets with removed[t] = 1 */
    struct amps__removal *last_removal; /* internal: record and undo log of the last amps_mesh_remove */
} amps_mesh;

/* Mesh with nnode nodes (xyz: 3 per node) and ntet tets (tet: 4 node indices each), copied.
   Errors: AMPS_ERR_INDEX (node index out of range), AMPS_ERR_VALUE (non-finite coordinate),
   AMPS_ERR_MESH (no tets, or a degenerate tet: volume < 1e-12 L^3, L its longest edge). */
AMPS_API amps_mesh *amps_mesh_create(amps_ctx *ctx, amps_int nnode, const double *xyz, amps_int ntet,
                                     const amps_int *tet);
AMPS_API void amps_mesh_free(amps_ctx *ctx, amps_mesh *m);
/* Sets the material of all tets / of tet t. Requires E > 0 finite and -1 < nu < 0.5. */
AMPS_API amps_status amps_mesh_set_material(amps_ctx *ctx, amps_mesh *m, double E, double nu);
AMPS_API amps_status amps_mesh_set_tet_material(amps_ctx *ctx, amps_mesh *m, amps_int t, double E, double nu);
/* Structured grid of nx * ny * nz nodes (node (i,j,k) = i + nx (j + ny k) at (i hx, j hy, k hz)),
   each grid cell split into 6 tets around its main diagonal (Kuhn split, conforming).
   amps_mesh_beam(h)  = grid 5 x 5 x h, spacing 1 (z along the beam, h >= 2).
   amps_mesh_brick(R) = 1 x 1 x 2 brick: grid (R+1) x (R+1) x (2R+1), spacing 1/R (R >= 1). */
AMPS_API amps_mesh *amps_mesh_grid(amps_ctx *ctx, amps_int nx, amps_int ny, amps_int nz, double hx, double hy,
                                   double hz);
AMPS_API amps_mesh *amps_mesh_beam(amps_ctx *ctx, amps_int h);
AMPS_API amps_mesh *amps_mesh_brick(amps_ctx *ctx, amps_int R);
/* Makes room for node_cap nodes so that cuts up to that many nodes allocate nothing. */
AMPS_API amps_status amps_mesh_reserve(amps_ctx *ctx, amps_mesh *m, amps_int node_cap);
/* Number of tets containing v (0 if v is out of range). */
AMPS_API amps_int amps_mesh_degree(const amps_mesh *m, amps_int v);
/* The tets containing v, ascending; *deg receives their number (NULL and 0 if v is invalid). */
AMPS_API const amps_int *amps_mesh_incident(const amps_mesh *m, amps_int v, amps_int *deg);
/* Verifies the mesh invariants (indices, origins, incidence slots against tet and the removed
   flags, densities). O(nnode + ntet). */
AMPS_API amps_status amps_mesh_check(amps_ctx *ctx, const amps_mesh *m);

typedef enum amps_cmp { AMPS_LT = 0, AMPS_GT = 1 } amps_cmp;
/* Nodes v (copies included) with xyz[3v+axis] < value (AMPS_LT) or > value (AMPS_GT), ascending,
   written to out (room for nnode; may be NULL to count). Returns their number, or -1 with
   AMPS_ERR_ARG (NULL mesh, axis not 0, 1, 2, cmp not AMPS_LT/AMPS_GT) or AMPS_ERR_VALUE (NaN). */
AMPS_API amps_int amps_mesh_select(amps_ctx *ctx, const amps_mesh *m, int axis, amps_cmp cmp, double value,
                                   amps_int *out);
/* Equation numbers in node order: dof[3v+d] = next number, or -1 if fixed[v] (fixed may be NULL)
   or v lies in no tet. dof has 3 * nnode entries. Returns the number of equations. */
AMPS_API amps_int amps_mesh_number_dofs(const amps_mesh *m, const unsigned char *fixed, amps_int *dof);
/* Reference coordinates of the 4 nodes of tet t (X[3a+c]). */
AMPS_API void amps_mesh_tet_coords(const amps_mesh *m, amps_int t, double X[12]);
/* amps_tet_stiffness of tet t with its material; returns its volume. */
AMPS_API double amps_mesh_tet_stiffness(const amps_mesh *m, amps_int t, double Ke[144]);
/* Upper triangle of the stiffness matrix K = sum_t Ke(t) over the live tets, in equations: the DOF
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
/* Undoes the last cut of m: vc = m->nnode - 1 is the copy of v, moved[0..nmoved-1] the tets the cut
   moved (ascending, as amps_mesh_cut returned them). AMPS_ERR_ARG (m unchanged) if vc is not the
   last copy of v or nmoved does not match. */
AMPS_API amps_status amps_mesh_uncut(amps_ctx *ctx, amps_mesh *m, amps_int v, amps_int vc, const amps_int *moved,
                                     amps_int nmoved);
/* Per-tet stress for displacements disp (3 per node): sigma (6 per tet), von_mises (1 per tet),
   principal (3 per tet, descending); each output may be NULL. Removed tets get zeros. */
AMPS_API amps_status amps_mesh_stress(amps_ctx *ctx, const amps_mesh *m, const double *disp, double *sigma,
                                      double *von_mises, double *principal);

/* ---- density, regions, lumped mass, element removal ---- */

/* Density of all tets / of tet t. Requires rho > 0 finite (AMPS_ERR_VALUE for NaN/Inf,
   AMPS_ERR_ARG otherwise; AMPS_ERR_INDEX for t); on error m is unchanged. */
AMPS_API amps_status amps_mesh_set_density(amps_ctx *ctx, amps_mesh *m, double rho);
AMPS_API amps_status amps_mesh_set_tet_density(amps_ctx *ctx, amps_mesh *m, amps_int t, double rho);
/* E, nu and rho of every tet t with region[t] = id (removed ones included); rho <= 0 keeps the
   densities. Errors (m unchanged): the checks of amps_mesh_set_material, a NaN rho, and
   AMPS_ERR_ARG "no tetrahedron has region id" when none has it. */
AMPS_API amps_status amps_mesh_set_region_material(amps_ctx *ctx, amps_mesh *m, amps_int id, double E, double nu,
                                                   double rho);
/* Sets region[t] = id (for meshes built in code). AMPS_ERR_INDEX for t out of range. */
AMPS_API amps_status amps_mesh_set_tet_region(amps_ctx *ctx, amps_mesh *m, amps_int t, amps_int id);
/* Lumped mass m_i = sum over the non-removed tets t containing node i of rho_t |V_t| / 4
   (mass has nnode entries; a node in no live tet gets 0). */
AMPS_API void amps_mesh_lumped_mass(const amps_mesh *m, double *mass);

/* What amps_mesh_remove does at a singular vertex or edge (see there). */
typedef enum amps_singular_policy {
    AMPS_SINGULAR_REMOVE = 0,   /* default: keep the largest group, remove the others */
    AMPS_SINGULAR_SEPARATE = 1, /* give every other group its own copy of the vertex */
    AMPS_SINGULAR_IGNORE = 2    /* remove only the given tets */
} amps_singular_policy;
/* What a removal did; arrays are mesh-owned, valid until the next change of the mesh. */
typedef struct amps_mesh_removal {
    amps_int ntet;
    const amps_int *tets; /* every tet removed (the given ones first, in the given order) */
    amps_int nsep;        /* separations, in the order made: node sep_node[k] ... */
    const amps_int *sep_node;
    const amps_int *sep_copy; /* ... got the copy sep_copy[k] (origin as a cut copy) ... */
    const amps_int *sep_ptr;  /* ... and the tets sep_tets[sep_ptr[k] .. sep_ptr[k+1]-1] (ascending) */
    const amps_int *sep_tets; /*     moved from sep_node[k] to it; sep_ptr has nsep + 1 entries */
    amps_int norphan;
    const amps_int *orphans; /* nodes left in no live tet (copies made by this removal included), ascending */
} amps_mesh_removal;
/* Removes tets[0..n-1]: marks them removed and takes them out of the incidence lists; then,
   unless policy is AMPS_SINGULAR_IGNORE, resolves singularities at the vertices and edges of
   every tet removed or changed, repeatedly, until none of those is singular. A vertex is
   singular when its tets are not connected through shared edges (two are adjacent when they
   share a vertex besides it); an edge when its tets are not connected through shared faces.
   The group with most tets is kept (a tie keeps the group holding the lowest tet index).
   AMPS_SINGULAR_REMOVE removes the tets of the other groups. AMPS_SINGULAR_SEPARATE gives each
   other group of a singular vertex its own copy of the vertex (a cut-like copy: origin, xyz,
   split incidence slot, node capacity growth as amps_mesh_cut); at a singular edge (a, b) it
   copies the endpoint a (else b) whose tets, grouped by shared faces, put the edge's groups in
   different face-connected parts, giving each part that does not hold the kept group its own
   copy; when neither endpoint separates them (the edge is pinched from both sides) the other
   groups are removed as with AMPS_SINGULAR_REMOVE.
   out (may be NULL) describes the result. Errors (m unchanged): AMPS_ERR_ARG (NULL mesh or
   array, n < 1, a tet given twice or already removed), AMPS_ERR_INDEX (a tet out of range),
   AMPS_ERR_OOM / AMPS_ERR_CAPACITY. */
AMPS_API amps_status amps_mesh_remove(amps_ctx *ctx, amps_mesh *m, amps_int n, const amps_int *tets,
                                      amps_singular_policy policy, amps_mesh_removal *out);
/* Undoes the last amps_mesh_remove exactly (tets, incidence, nnode, removed flags), r being its
   record. AMPS_ERR_ARG (m unchanged) if r is not the record of the last change of m. */
AMPS_API amps_status amps_mesh_unremove(amps_ctx *ctx, amps_mesh *m, const amps_mesh_removal *r);
/* Singular vertices / edges of the current mesh (definitions of amps_mesh_remove), from scratch:
   out (may be NULL to count) receives the vertices ascending / the edges as pairs a < b, sorted.
   Returns their number, or -1 (NULL mesh, AMPS_ERR_OOM). */
AMPS_API amps_int amps_mesh_singular_vertices(amps_ctx *ctx, const amps_mesh *m, amps_int *out);
AMPS_API amps_int amps_mesh_singular_edges(amps_ctx *ctx, const amps_mesh *m, amps_int *out);

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
/* Rotation of a tet's deformation (corotational FEM): F = D_s D_m^-1 (D_s, D_m: the edge vectors
   x_a - x_0, X_a - X_0, a = 1..3, of the deformed positions x and the reference X), its SVD
   F = U S V^T (s1 >= s2 >= s3 >= 0) and R = U diag(1, 1, det(U V^T)) V^T, the rotation nearest
   to F (it maximizes tr(R^T F) = s1 + s2 + sign(det F) s3). Inverted tets (det F < 0) get a
   rotation too, never a reflection. Where R is not unique (rank F <= 1, or det F < 0 with
   s2 = s3) R is one of the maximizers; F = 0, a degenerate X or a non-finite F give R = I.
   Computed by Newton's iteration for the polar factor where det F is well above 0 (the same R to
   rounding), else by a one-sided Jacobi SVD. Returns det F (0 for a degenerate X). Allocates
   nothing. */
AMPS_API double amps_tet_rotation(const double X[12], const double x[12], double R[9]);

/* ---- boundary ---- */

/* Boundary triangles of m: the faces of exactly one tet. A cut makes its faces between the tets
   that use v and those that use the copy v' boundary faces of both (the two sides of the cut).
   A tet that the incidence lists of its nodes do not contain (a removed tet) has no faces.
   Triangle k is tri[3k .. 3k+2], ordered so that its normal (x1 - x0) x (x2 - x0) (reference
   coordinates) points out of its tet; face[k] = 4 t + f: tet t, local face f = the face opposite
   the tet's node f, the others in tet order (up to orientation). Triangles come in ascending
   face order. tri and face may be NULL (count only), else have room for the count (at most
   4 ntet). Returns the number of triangles, or -1: AMPS_ERR_ARG (NULL mesh), AMPS_ERR_OOM.
   Cost O(ntet * degree); allocates O(nnode + ntet) scratch. */
AMPS_API amps_int amps_mesh_boundary(amps_ctx *ctx, const amps_mesh *m, amps_int *tri, amps_int *face);

#endif /* AMPS_NO_FEM */

/* ==== [amps:scene] a mesh with fixed nodes, forces, pins and cuts ============================= */
#ifndef AMPS_NO_FEM
/* The scene: a mesh with fixed nodes, forces, pins and cuts, solved by the update engine.
   The model is linear elasticity (small strains): displacements are linear in the forces and
   pins, and every stiffness is that of the reference configuration.
   Node displacements are kept exact with one factorization of the initial stiffness matrix
   (fixed nodes eliminated); every cut, pin and release becomes an update of the engine:
   a cut changes the rows of v, its copy v' and the nodes of the tets that moved, computed from
   the element stiffness of those tets only. Lifecycle: create, fix nodes and set materials,
   then any sequence of force / pin / release / cut / solve (the first of these factors K).
   A failed scene call leaves the scene as it was. Structural changes (a pin of a node not
   pinned yet, a release, a cut, a removal, a material change) commit to the engine at once,
   outside a batch
   (amps_scene_begin_batch); moved pins and forces wait for the next solve, whose commit then
   has only values to apply.
   Allocation: amps_scene_prepare (or the first change) allocates everything; later calls
   allocate only when a capacity is exceeded and opts.update.grow is set (the default). */
typedef struct amps_scene amps_scene;

typedef struct amps_scene_opts {
    amps_order_opts order;   /* ordering of K (default: ND guided by the node coordinates) */
    amps_update_opts update; /* engine options (default: amps_update_opts_default, grow = 1);
                                   update.refactor_order.block 0 becomes 3 (node triples) */
} amps_scene_opts;

AMPS_API void amps_scene_opts_default(amps_scene_opts *o);
/* Scene over mesh m, which it takes over in every case: the scene cuts it and frees it with
   itself, and a failed create frees it. So amps_scene_create(ctx, amps_mesh_read(ctx, path),
   opts) leaks nothing; when the reader fails (NULL), ctx keeps the reader's status and message
   (a NULL m with no error in ctx gives AMPS_ERR_ARG). */
AMPS_API amps_scene *amps_scene_create(amps_ctx *ctx, amps_mesh *m, const amps_scene_opts *opts);
AMPS_API void amps_scene_free(amps_ctx *ctx, amps_scene *S);
AMPS_API const amps_mesh *amps_scene_mesh(const amps_scene *S);
/* Sets the material of every tet (after the factorization: one update, see amps_scene_set_tet_material). */
AMPS_API amps_status amps_scene_set_material(amps_ctx *ctx, amps_scene *S, double E, double nu);
/* Fixes nodes (zero displacement, eliminated from the system); before the factorization only.
   amps_scene_fix_where fixes the nodes whose coordinate axis (0, 1, 2) is below / above value. */
AMPS_API amps_status amps_scene_fix(amps_ctx *ctx, amps_scene *S, amps_int nv, const amps_int *v);
AMPS_API amps_status amps_scene_fix_where(amps_ctx *ctx, amps_scene *S, int axis, amps_cmp cmp, double value,
                                          amps_int *count);
/* Assembles and factors K (ordering, symbolic, numeric) and creates the engine. */
AMPS_API amps_status amps_scene_prepare(amps_ctx *ctx, amps_scene *S);
/* Sets (replaces) the external force on node v; no effect on fixed nodes. */
AMPS_API amps_status amps_scene_force(amps_ctx *ctx, amps_scene *S, amps_int v, const double f[3]);
/* Holds node v at displacement u (again to move it); AMPS_ERR_ARG for a fixed node. */
AMPS_API amps_status amps_scene_pin(amps_ctx *ctx, amps_scene *S, amps_int v, const double u[3]);
/* Releases a pin; does nothing for a node that is not pinned. In statics a release that leaves
   the node-connected piece of v held by nothing, or only by constrained nodes on one line, or a
   face-connected piece of v's tets joined to the rest only at nodes of one line (a hinge) and not
   held off it, is AMPS_ERR_SINGULAR_UPDATE with the piece named, and the pin stays (cost: the
   pieces explored until three constrained nodes off one line); in a batch the commit's pivot
   test decides. */
AMPS_API amps_status amps_scene_release(amps_ctx *ctx, amps_scene *S, amps_int v);
/* Cut at node v with the plane (p, nrm) (semantics of amps_mesh_cut). The copy v' starts free
   (no pin, no force) with v's displacement, and is fixed if v is. AMPS_WARN_NOOP if the plane
   leaves one side empty. In statics a cut that leaves a piece held by nothing, or joined to the
   rest only at nodes on one line (a hinge, a ball joint) and not held off it by fixed or pinned
   nodes, returns AMPS_ERR_SINGULAR_UPDATE and the scene is as it was: a face-connected piece is
   tested by exploring the pieces around v, at a cost of about the tets of the pieces the cut
   separates (when it splits the model, also the largest piece until it meets three constrained
   nodes off one line).
   (Chains of pieces that are loose only together are left to the engine's pivot test.) In
   dynamics a piece cut free is legal (its mass holds it) and moves. Before the model is
   factored a cut changes the topology only, as for amps_scene_remove. */
AMPS_API amps_status amps_scene_cut(amps_ctx *ctx, amps_scene *S, amps_int v, const double p[3], const double nrm[3],
                                    amps_int *new_node);
/* Solves for the displacements of every node. AMPS_WARN_INACCURATE (the accuracy guard's
   tolerance was not reached) still gives the displacements. */
AMPS_API amps_status amps_scene_solve(amps_ctx *ctx, amps_scene *S);
/* Watch set: the nodes amps_scene_solve_watched computes (replaces the previous set; nv = 0
   clears it; a node given twice counts once). A cut of a watched node watches its copy too.
   Allocates. */
AMPS_API amps_status amps_scene_watch(amps_ctx *ctx, amps_scene *S, amps_int nv, const amps_int *nodes);
/* Solves for the displacements of the watched nodes only (amps_update_solve_watched: the
   backward solve touches closure_L of their DOFs); other entries of amps_scene_displacements
   keep their last values. Updates the pin reactions. Allocates only the first time after
   amps_scene_watch or after a cut of a watched node. */
AMPS_API amps_status amps_scene_solve_watched(amps_ctx *ctx, amps_scene *S);
/* The haptic step: updates the pin reactions (amps_scene_reaction) from the dense system alone,
   without computing displacements (amps_update_solve_reactions). */
AMPS_API amps_status amps_scene_solve_reactions(amps_ctx *ctx, amps_scene *S);
/* Haptic model: the pin reactions as an affine function of the pin targets, for a haptic thread
   that never touches the scene. For the committed system and the pin set P (the pinned nodes
   node[0..n-1], ascending; entry 3k + d of a vector is component d of node[k]):
       r(g) = r0 + H (g - g0),
   g0 the pin targets and r0 the reactions (amps_scene_reaction after amps_scene_solve_reactions)
   at the build, H (3n x 3n, column major, symmetric) the Schur complement on P of the system
   matrix: K^ in statics; A / dt^2 in dynamics (the pins' velocities are (g - u_P) / dt and the
   reactions (A w+ - b)_P / dt: amps_scene_step). Exact while the pin set, forces, materials and
   topology (dynamics: also the state u, w) are as at the build; a new pin, a release, a cut, a
   removal or a step needs a rebuild, and evaluating a stale model is the caller's choice. Pins
   on cut copies are nodes like others. The struct owns its arrays and points into no scene:
   one thread may evaluate it while another changes the scene and builds into a second one
   (publish by swapping pointers). Initialize with amps_haptic_init, free with amps_haptic_free. */
typedef struct amps_haptic {
    amps_int n;      /* pinned nodes in the model */
    amps_int cap;    /* capacity in nodes */
    amps_int *node;  /* n pinned nodes, ascending */
    amps_int *eq;    /* 3 n: the equation of each entry (amps_scene_node_dofs), -1: none */
    double *g0, *r0; /* 3 n each: pin targets and reactions at the build */
    double *H;       /* 3n x 3n, column major: dr/dg */
    long serial;     /* builds into this struct so far */
} amps_haptic;
AMPS_API void amps_haptic_init(amps_haptic *h);
AMPS_API void amps_haptic_free(amps_ctx *ctx, amps_haptic *h);
/* Builds h for the current scene (after amps_scene_solve_reactions' commit: moved pins and forces
   are included). Cost: that haptic step plus one solve with the engine's dense factor per pinned
   DOF (in blocks of up to 16 that share each pass over the factor), O(3n |S u C|^2) in all,
   O(9 n^2) to store; allocates only when n exceeds h->cap. In the corotational mode r0 and g0
   are those of its haptic call and H = Rb H_A Rb^T / dt^2 (H_A: the Schur complement of the
   linear A, Rb: the pinned nodes' frames; see amps_scene_corotational). Errors (h unchanged):
   AMPS_ERR_ARG (NULL), AMPS_ERR_STATE (a two-phase commit in progress), AMPS_ERR_OOM, the
   commit's. No pin: AMPS_WARN_NOOP with h->n = 0. */
AMPS_API amps_status amps_scene_haptic_build(amps_ctx *ctx, amps_scene *S, amps_haptic *h);
/* r = r0 + H (g - g0) (3 h->n entries each; g NULL: r = r0). O(9 n^2), allocates nothing, reads
   only h: callable from any thread concurrently with anything on the scene. AMPS_ERR_ARG (NULL h
   or r). */
AMPS_API amps_status amps_haptic_eval(const amps_haptic *h, const double *g, double *r);
/* The position k of node v in h->node (its entries are 3k..3k+2), or -1. O(log n). */
AMPS_API amps_int amps_haptic_find(const amps_haptic *h, amps_int v);
/* Displacements of the last solve, 3 per node (nodes created since: their origin's values). */
AMPS_API const double *amps_scene_displacements(const amps_scene *S);
/* Deformed positions (reference + displacement of the last solve) of nodes[0..n-1], or of all
   nodes when nodes is NULL (n ignored), 3 per node into out. */
AMPS_API amps_status amps_scene_positions(amps_ctx *ctx, const amps_scene *S, amps_int n, const amps_int *nodes,
                                          double *out);
/* Reaction force the pin of node v exerts (K^ x - f at its DOFs); zero if v is not pinned. */
AMPS_API amps_status amps_scene_reaction(amps_ctx *ctx, const amps_scene *S, amps_int v, double r[3]);
/* Relative residual of the reduced system (fixed and pinned DOFs eliminated) of the last solve. */
AMPS_API amps_status amps_scene_residual(amps_ctx *ctx, amps_scene *S, double *relres);
/* Per-tet stresses of the last solve (see amps_mesh_stress); outputs may be NULL. */
AMPS_API amps_status amps_scene_stress(amps_ctx *ctx, const amps_scene *S, double *sigma, double *von_mises,
                                       double *principal);
/* Equations of the current system (free DOFs of the initial mesh plus those of cut copies),
   those of a batch being committed in two phases included: every amps_scene_node_dofs entry is
   below it. */
AMPS_API amps_int amps_scene_ndof(const amps_scene *S);
/* The engine (for statistics) and its current base factor; NULL before the factorization. */
AMPS_API amps_update *amps_scene_engine(const amps_scene *S);
AMPS_API const amps_factor *amps_scene_factor(const amps_scene *S);

/* ---- rendering data, node map, picking and selection ---- */

/* What changed since the last amps_scene_take_changes: boundary triangles by stable id (see
   amps_scene_boundary), the copies cuts created and the tets whose nodes they changed. */
typedef struct amps_scene_changes {
    int reset; /* 1: redraw everything from amps_scene_boundary (the first take, or
                                 an allocation failed while recording); added lists every
                                 triangle, removed is empty */
    amps_int nadded, nremoved;
    const amps_int *added;   /* ids of the triangles that appeared (an id whose triangle changed
                                 nodes appears in removed and added) */
    const amps_int *removed; /* ids of the triangles that disappeared; reused after this take */
    amps_int nnew;
    const amps_int *new_nodes; /* copies created by cuts, in creation order */
    amps_int nmoved;
    const amps_int *moved_tets; /* tets that use a new node instead of its original, each once */
} amps_scene_changes;

/* Takes the change record: fills c (arrays valid until the next change to the scene) and starts
   a new one. The first call starts the recording (allocates O(ntet) and reports reset = 1);
   from then on every cut records its changes, at a cost of O(degree^2) of the cut node. Only
   this call and amps_scene_boundary read the record. Errors: AMPS_ERR_ARG (NULL), AMPS_ERR_OOM
   (the recording stays off). */
AMPS_API amps_status amps_scene_take_changes(amps_ctx *ctx, amps_scene *S, amps_scene_changes *c);
/* The boundary triangles (amps_mesh_boundary's, oriented outward) by stable id: returns the
   number of ids; id k is the triangle (*tri)[3k .. 3k+2] of face (*face)[k] = 4 t + f, or a
   free id (nodes and face -1). Valid from the first amps_scene_take_changes to the next change;
   returns 0 (pointers NULL) before it. */
AMPS_API amps_int amps_scene_boundary(const amps_scene *S, const amps_int **tri, const amps_int **face);

/* The equations of node v's DOFs (copies included): dof[d] = equation of DOF d, or -1 if v is
   fixed or in no tet. A pinned node keeps its equations (they are constrained). Errors:
   AMPS_ERR_STATE before the factorization (no numbering yet), AMPS_ERR_INDEX, AMPS_ERR_ARG. */
AMPS_API amps_status amps_scene_node_dofs(amps_ctx *ctx, const amps_scene *S, amps_int v, amps_int dof[3]);
/* The watch set (amps_scene_watch, with the copies cuts added): *n nodes; NULL if empty. */
AMPS_API const amps_int *amps_scene_watched(const amps_scene *S, amps_int *n);
/* Deformed positions of the watched nodes (reference + displacement of the last solve or
   watched solve), 3 per node in amps_scene_watched's order, into out. */
AMPS_API amps_status amps_scene_watched_positions(amps_ctx *ctx, const amps_scene *S, double *out);

/* The node nearest to p in the reference configuration (copies share their origin's place:
   among equally near nodes the smallest index), over the nodes in at least one tet; *v = -1
   if there is none. The first call builds a uniform grid over the nodes (O(nnode) memory);
   later calls cost about the nodes of a few grid cells. Errors: AMPS_ERR_VALUE (NaN/Inf in
   p, or a coordinate beyond 1e150 in magnitude), AMPS_ERR_ARG (NULL), AMPS_ERR_OOM. For
   picking on the deformed surface, pass the reference point of the picked triangle
   (barycentric coordinates map it back). */
AMPS_API amps_status amps_scene_nearest_node(amps_ctx *ctx, amps_scene *S, const double p[3], amps_int *v);
/* Fixes the nodes (copies included) whose reference coordinates lie in the closed box
   [lo, hi] / the closed ball |x - c| <= r; before the factorization only (AMPS_ERR_STATE).
   *count (may be NULL) receives their number. Errors (nothing fixed): AMPS_ERR_VALUE (NaN/Inf),
   AMPS_ERR_ARG (lo > hi on an axis, r < 0, NULL), AMPS_ERR_STATE. */
AMPS_API amps_status amps_scene_fix_box(amps_ctx *ctx, amps_scene *S, const double lo[3], const double hi[3],
                                        amps_int *count);
AMPS_API amps_status amps_scene_fix_sphere(amps_ctx *ctx, amps_scene *S, const double c[3], double r, amps_int *count);
/* 1 if node v is fixed / pinned, else 0 (also for a NULL scene or v out of range). */
AMPS_API int amps_scene_is_fixed(const amps_scene *S, amps_int v);
AMPS_API int amps_scene_is_pinned(const amps_scene *S, amps_int v);
/* Nodes within distance radius (>= 0) of the segment [a, b] (a point if a = b) in the reference
   configuration, that belong to a tet: what a blade or a grasper touches. out receives the first
   min(count, cap) of them, ascending (out may be NULL when cap is 0). Returns their count, or a
   negative status (AMPS_ERR_ARG: NULL scene, a, b, or out with cap > 0; AMPS_ERR_VALUE: not
   finite, a coordinate beyond 1e150 in magnitude, negative radius). O(nnode); allocates
   nothing. */
AMPS_API amps_int amps_scene_nodes_near_segment(amps_ctx *ctx, const amps_scene *S, const double a[3],
                                                const double b[3], double radius, amps_int *out, amps_int cap);
/* Batches: between amps_scene_begin_batch and amps_scene_commit, cuts, pins, releases, removals,
   material changes and forces only record their changes (each cut's and, in statics, each
   removal's mechanism test still runs at the call, so its refusal is immediate and leaves the
   batch as it was; the scene's mesh, node numbering and materials change at once; in statics the
   releases are tested at the commit, on the state after the batch, as amps_scene_release tests
   one); amps_scene_commit applies them to the engine in one commit. The solves and steps commit
   an open batch first, as amps_scene_commit does. amps_scene_begin_batch prepares the scene if
   needed (AMPS_ERR_STATE if a batch is open). amps_scene_commit ends the batch; on failure
   (AMPS_ERR_SINGULAR_UPDATE: a piece the mechanism test missed is loose; AMPS_ERR_CAPACITY,
   AMPS_ERR_OOM) every cut, pin, release, removal and material change of the batch is undone,
   last first (forces stay, as in the engine; the masses and gravity loads follow the restored
   mesh) and the scene is as at amps_scene_begin_batch. A cut, removal or material change in a
   batch that fails for lack of memory or capacity (AMPS_ERR_OOM, AMPS_ERR_CAPACITY) also undoes
   the batch (the batch is closed); its other errors leave the batch open as it was. Outside a
   batch amps_scene_commit commits what the scene recorded (moved pins, forces). Cost: one engine
   commit (see amps_update_commit) for the whole batch instead of one per change; the log holds
   the changes' undo records (a removal's: its tets, separations and the incidence slots it
   changed) and grows only past its largest size. */
AMPS_API amps_status amps_scene_begin_batch(amps_ctx *ctx, amps_scene *S);
AMPS_API amps_status amps_scene_commit(amps_ctx *ctx, amps_scene *S);
/* Undoes every change of the open batch, last first, as a failed amps_scene_commit does, and
   closes it (forces stay). AMPS_ERR_STATE if no batch is open or a two-phase commit runs. */
AMPS_API amps_status amps_scene_cancel_batch(amps_ctx *ctx, amps_scene *S);
/* amps_scene_commit in two phases (amps_update_commit_begin/run/end): begin and end under the
   caller's lock, run outside it (Steps 1-2, the expensive part). Meanwhile the haptic thread may
   move pins (amps_scene_pin of a node pinned before the batch), set forces and, in statics,
   solve (the state before the batch: amps_scene_solve_reactions never waits for the job nor
   swaps a re-factorization in); cuts, new pins, releases, batches, amps_scene_commit, removals,
   material changes, gravity, amps_scene_dynamics, steps and the haptic step of a dynamic scene
   (its K u needs the committed matrix: use the haptic model there) fail with AMPS_ERR_STATE. A
   failed begin or end undoes the batch (as amps_scene_commit).
   Costs: begin O(recorded changes + the new indices' root paths), plus a swap if one is ready;
   run Steps 1-2 (O(closure of the new indices) + O(|S u C| x new)); end Steps 3 and 5
   (O(|S u C|^2 x changed columns)); the haptic step O(|S u C|^2). */
AMPS_API amps_status amps_scene_commit_begin(amps_ctx *ctx, amps_scene *S);
AMPS_API void amps_scene_commit_run(amps_scene *S);
AMPS_API amps_status amps_scene_commit_end(amps_ctx *ctx, amps_scene *S);
/* A blade stroke: the polyline pts[0..npts-1] (3 per point, npts >= 2, reference configuration)
   moved along the blade direction blade sweeps the surface made of one planar strip per segment
   [p_i, p_i+1]: the plane through p_i spanned by the segment and the blade, whose normal is
   n_i = (p_i+1 - p_i) x blade / |...|. Every node within radius of the polyline (of the nodes
   that exist at the call and belong to a tet) is cut (amps_scene_cut) by the plane of its nearest
   segment (the first of equal ones; distances that differ by less than 1e-12 of the squared
   distance plus the squared segment length count as equal), in the order of the segments and
   then of the position along the segment (ties by node number). The cuts form one batch
   committed once (inside an open batch they join it and the caller commits; before the
   factorization they change the topology only, as amps_scene_cut, and nothing is factored).
   out (may be NULL) reports the nodes touched: node[k], copy[k] (the new node, or -1) and
   status[k] (AMPS_OK: cut; AMPS_WARN_NOOP: the plane leaves
   one side of the node empty; AMPS_ERR_SINGULAR_UPDATE: refused by the mechanism test) for
   k < min(n, cap) (arrays caller-owned, cap entries each), n the number touched, ncut the nodes
   cut. A commit that is singular (a piece the per-node test missed is left loose) is undone and
   the cuts are made again one commit each, the cuts that leave a piece loose refused
   (AMPS_ERR_SINGULAR_UPDATE in status); inside an open batch the caller's commit decides.
   Errors: AMPS_ERR_ARG (npts < 2, NULL, a segment of zero length or parallel to the blade),
   AMPS_ERR_VALUE (not finite, a point's coordinate beyond 1e150, radius < 0), AMPS_ERR_STATE (a
   two-phase commit in progress), the commit's (the stroke undone, as amps_scene_commit)
   and AMPS_ERR_OOM / AMPS_ERR_CAPACITY (in the one-commit-each pass the cuts made before it
   stay). Allocates O(nnode) scratch. */
typedef struct amps_scene_stroke_result {
    amps_int cap;          /* entries of the arrays (set by the caller) */
    amps_int *node, *copy; /* caller-owned, cap entries each (may be NULL when cap is 0) */
    amps_status *status;   /* caller-owned, cap entries (may be NULL when cap is 0) */
    amps_int n, ncut;      /* nodes touched (may exceed cap), nodes cut */
} amps_scene_stroke_result;
AMPS_API amps_status amps_scene_stroke(amps_ctx *ctx, amps_scene *S, amps_int npts, const double *pts,
                                       const double blade[3], double radius, amps_scene_stroke_result *out);
/* ---- dynamics, removal, runtime materials, fracture ----
   Mass: lumped, m_v = sum over the live tets t containing v of rho_t |V_t| / 4. The system
   matrix is A = cM M + cK K: statics cM = 0, cK = 1 (A = K); dynamics cM = 1 + alpha dt,
   cK = beta dt + dt^2. Every change of A (cut, removal, material) is an update of the engine. */

/* Density of every tet (rho > 0 finite, else AMPS_ERR_VALUE); before the factorization only
   (AMPS_ERR_STATE). */
AMPS_API amps_status amps_scene_set_density(amps_ctx *ctx, amps_scene *S, double rho);
/* E, nu and (rho > 0; 0 keeps) of the tets whose region attribute is id. Before the
   factorization it sets the mesh; after, the change of their element matrices is one update
   (O(tets of the region) element matrices; allocates the region's list, and workspace when the
   change is larger than every earlier one), committed at once or, inside a batch, with the
   batch. Errors: AMPS_ERR_ARG (no tet has region id), AMPS_ERR_VALUE (material, rho < 0 or not
   finite), AMPS_ERR_STATE (a two-phase commit in progress), a failed commit; the scene
   unchanged. */
AMPS_API amps_status amps_scene_set_region(amps_ctx *ctx, amps_scene *S, amps_int id, double E, double nu, double rho);
/* Material of tet t at any time (after the factorization: an update of its nodes' rows, as
   amps_scene_set_region; amps_scene_set_material likewise updates every tet). A removed tet keeps
   the material given (it has no effect). AMPS_ERR_INDEX. */
AMPS_API amps_status amps_scene_set_tet_material(amps_ctx *ctx, amps_scene *S, amps_int t, double E, double nu);
/* Gravity: body force f_v += m_v g on every node (default 0), statics and dynamics, any time.
   In statics after the factorization it sets the force of every equation (O(nnode)); the loads
   follow the masses through cuts and removals. AMPS_ERR_VALUE (not finite). */
AMPS_API amps_status amps_scene_gravity(amps_ctx *ctx, amps_scene *S, const double g[3]);
/* Implicit dynamics from now on (paper "GPU-accelerated surgery simulation for opening a brain
   fissure", Eq. 27): backward Euler in velocity form with Rayleigh damping C = alpha M + beta K.
   dt > 0, alpha, beta >= 0, finite, with 1 + alpha dt and beta dt + dt^2 > 0 finite
   (AMPS_ERR_VALUE). The first call starts the state (u, w) at the
   current displacements and zero velocity; a later call keeps u and w. Called after the
   factorization with new values it re-factors
   A (a full amps_scene_prepare; if that fails the scene is left unprepared, prepared again by
   the next call), after committing an open batch (as the solves do). Then amps_scene_solve /
   amps_scene_solve_watched are AMPS_ERR_STATE. */
AMPS_API amps_status amps_scene_dynamics(amps_ctx *ctx, amps_scene *S, double dt, double alpha, double beta);
/* nsteps time steps: A w+ = M w + dt (f + M g - K u), u+ = u + dt w+; fixed DOFs w+ = 0, a pin
   with target g has w+ = (g - u)/dt, an orphan node w+ = 0; the free DOFs solve the reduced
   system (one engine solve). K u = (A u - cM M u) / cK takes one product with the engine's
   matrix, M one pass over the tets (about 0.4 of a solve's instructions on brick R=6); the
   product is kept while u and the matrix stay the same, so the haptic calls between two steps
   (pins moved, amps_scene_solve_reactions) cost O(N) and the dense system only. Reactions
   (amps_scene_reaction) are (A w+ - b)_P / dt; the haptic path amps_scene_solve_reactions gives
   those of the step that would be taken now. With fracture on,
   after each step the tets over the threshold are removed (amps_scene_fracture). AMPS_ERR_STATE
   in statics; a failing step returns its error with the earlier steps done, except that a
   fracture's removal that fails (memory, capacity) returns its error with its step taken and
   nothing fractured (amps_scene_step_info's steps counts the steps taken; the next step tests
   the stresses again). With
   amps_scene_corotational on, every step is the corotational one (see there). */
AMPS_API amps_status amps_scene_step(amps_ctx *ctx, amps_scene *S, amps_int nsteps);
/* Velocities w, 3 per node (NULL before amps_scene_dynamics). */
AMPS_API const double *amps_scene_velocities(const amps_scene *S);
/* Removes tets[0..n-1] with the mesh removal (amps_mesh_remove, policy for singular vertices and
   edges; report may be NULL), then updates A on the rows of the affected nodes: minus the element
   matrices of the removed tets, separated nodes as new equations (like cut copies, with their
   origin's u and w). Orphans (nodes left in no tet) are held: statics at their displacement,
   dynamics at w = 0, by rows of their own in A (not constraints, so the next re-factorization
   takes them out of the dense system). In statics a removal that leaves a node-connected piece
   whose fixed and pinned nodes are none or all on one line (it could turn about that line), a
   face-connected piece joined to the rest only at nodes of one line (a hinge) and not held off
   it (the test of amps_scene_cut, from the tets of the removed tets' nodes), or a piece the
   engine finds singular (chains of pieces loose only together), is
   AMPS_ERR_SINGULAR_UPDATE with the piece named, and the scene is as it was
   (amps_mesh_unremove); in dynamics a free piece is legal. Before the model is factored
   (amps_scene_prepare, the first solve or step) a removal changes the topology only, as fixing
   may still follow: there a loose piece is found by the factorization (AMPS_ERR_NOT_SPD naming
   a node of it). Errors of amps_mesh_remove (index, removed twice) change nothing. Inside a batch
   (amps_scene_begin_batch) the engine's change waits for the batch's commit. Allocates only when
   a removal is larger than every earlier one (the mesh's and the scene's workspaces grow). */
AMPS_API amps_status amps_scene_remove(amps_ctx *ctx, amps_scene *S, amps_int n, const amps_int *tets,
                                       amps_singular_policy policy, amps_mesh_removal *report);
/* Fracture: after each step, tets with max |principal stress| > sigma_max are removed (default
   policy) before the next step; sigma_max <= 0 turns it off. AMPS_ERR_VALUE for NaN. */
AMPS_API amps_status amps_scene_fracture(amps_ctx *ctx, amps_scene *S, double sigma_max);
/* The threshold of the tets of region id only (<= 0: none fracture there), over the one of
   amps_scene_fracture. AMPS_ERR_ARG (no tet has region id), AMPS_ERR_VALUE (NaN). */
AMPS_API amps_status amps_scene_fracture_region(amps_ctx *ctx, amps_scene *S, amps_int id, double sigma_max);
/* Tets fractured by the last step; *total (may be NULL) receives those of all steps. */
AMPS_API amps_int amps_scene_fractured(const amps_scene *S, amps_int *total);
/* Corotational dynamics (paper "GPU-accelerated surgery simulation for opening a brain fissure",
   Corotational FEM and Appendix A-B; on != 0) or linear (on = 0): each step, from the state
   (u, w) at its start, R_e = amps_tet_rotation of every live tet at x = X + u,
   K_e = R_e K0_e R_e^T and the elastic force g_e = R_e K0_e (R_e^T x_e - X_e) (R_e: R four
   times on the diagonal, K0_e the reference stiffness), assembled to K_R and g; the step solves
   A_R w+ = M w + dt (f + M g_grav - g), A_R = cM M + cK K_R, with the constraint rules of
   amps_scene_step (fixed, pins w_P = (g_P - u_P) / dt, orphans w = 0), u+ = u + dt w+; the
   reactions (amps_scene_reaction) are (A_R w+ - b)_P / dt. With every R_e = I it is the linear
   step. Nothing is re-factored for it: conjugate gradients on the reduced A_R, started from the
   extrapolation 2 w - w_prev of the last two steps' velocities, to the relative residual
   ||(b - A_R w+)_F|| / ||(b - A_R w_C)_F|| <= tol (amps_scene_corotational_tol;
   amps_scene_residual reports it), preconditioned by one of two: Rn A^-1 Rn^T (A^-1: the
   engine's exact solve with the current linear A, amps_update_solve_rhs, so cuts, removals and
   pins stay updates; Rn: per node the rotation nearest to the volume-weighted mean of its tets'
   R_e, which makes it exact for a rigid rotation), or symmetric Gauss-Seidel on A_R's 3x3
   blocks (Eisenstat's form: two sweeps per iteration, which read the blocks once, as a product
   does; far cheaper per iteration than the engine's, and enough where the mass dominates A_R, as
   with small dt). The step takes the one whose last iteration count times its cost per
   iteration (bytes streamed: the factor's and A_R's entries, a model, so the choice is
   reproducible) is smaller; Gauss-Seidel is tried on the second step and every 32 steps, and
   left for the engine's (from the current iterate) once it has cost 1.5 times the engine's last
   step. amps_scene_step_info reports the iterations of each. A_R is assembled each step in 3x3
   blocks by node (the pattern is rebuilt when a cut or a node separation changed the tets'
   nodes), its rows stored in the sweeps' order: slabs of about 3,000 nodes across the model (1,
   2, 4, ... at most 16), each slab's inner nodes by a colouring, then the slabs' interface. The
   slabs of a sweep run in parallel; assembly, products and the PCG's vector updates are parallel
   on the engine's threads; all are bitwise independent of the thread count (the order depends
   on the mesh alone, and dot products are summed per chunk of 256 nodes or per slab, then in
   order). Whole runs repeat bit for bit only with a re-factorization policy that does not
   depend on the clock (AMPS_REFACTOR_COUNT, MANUAL or OFF): the default AUTO swaps a new base
   in when its background job is done, which changes the preconditioner and the engine's
   rounding (results agree to the solve's tolerance). Memory from the first step: 36 doubles
   and 36 indices per tet (reference gradients,
   volume, R_e, Lame constants, element results; the block map and the workspace of its
   rebuild), 60 doubles, a long, 9 indices and 4 bytes per node (and 2 doubles per 256 nodes), 9
   doubles and 2 indices per block of A_R (one per pair of nodes sharing a tet), a double and a
   byte per equation; a rebuilt pattern allocates when it outgrows them. Stresses
   (amps_scene_stress and fracture) are those of eps = sym(R^T F - I), F = D_s D_m^-1. The
   haptic path between steps (amps_scene_solve_reactions, amps_scene_haptic_build) is a model,
   not the next step: per
   pinned node r = r0 + Rn dr, r0 the last step's reaction (0 for a pin made since), dr the
   reaction of the engine's linear A to the pin moves since the step (g - g0, g0 the target at
   the step, or the node's displacement for a new pin) taken into the node frames Rn of the
   current state (Rn^T (g - g0)): the cost of the linear haptic step (the dense system, O(N)),
   plus, once per state, one pass of the rotations and the frames of the pinned nodes (once a
   haptic call was made, each step ends with them, so the calls do not). Its response to pin
   moves is that of the next step exactly when every R_e is the same (a rigid rotation, or
   R = I), to first order in the spread of the rotations otherwise; r0 lags by a step (the
   state moves on in a step). Dynamics only and before the first step: AMPS_ERR_STATE otherwise
   (nothing changes). */
AMPS_API amps_status amps_scene_corotational(amps_ctx *ctx, amps_scene *S, int on);
/* PCG tolerance (0 < tol < 1, default 1e-10) and iteration cap (maxit >= 1, 0: default 200) of
   the corotational step: at most the work of maxit iterations with the engine's preconditioner
   (a Gauss-Seidel iteration counts as its cost ratio to one of those). A step that does not
   reach tol within it (slivers, rotations far from the engine's frames) factors its own A_R
   (amps_analyze, amps_factorize: it allocates, and costs about a factorization) and goes on with
   it as the preconditioner, which it stays for the next steps until it stalls in turn or the
   free entries change; a step still above tol is taken and amps_scene_step returns
   AMPS_WARN_INACCURATE. AMPS_ERR_VALUE otherwise. */
AMPS_API amps_status amps_scene_corotational_tol(amps_ctx *ctx, amps_scene *S, double tol, amps_int maxit);
/* What the last step did. */
typedef struct amps_scene_step_stats {
    int corotational;          /* 1: the step was corotational */
    amps_int iterations;       /* PCG iterations (preconditioner applications) of the last step */
    double relres;             /* its final relative residual (recomputed, not the recursion's); -1: linear */
    amps_int products;         /* products with A_R */
    double t_rotation;         /* seconds: rotations, elastic forces, masses */
    double t_solve;            /* seconds: the PCG */
    amps_int iterations_total; /* PCG iterations of all steps */
    amps_int iterations_gs;    /* of the last step's iterations, those with the Gauss-Seidel preconditioner */
    amps_int factored;         /* steps whose PCG stalled and factored A_R (see amps_scene_corotational_tol) */
    amps_int steps;            /* steps taken since amps_scene_dynamics was first called */
} amps_scene_step_stats;
/* Fills st with the last step's statistics (zeros before the first step). AMPS_ERR_ARG for NULL. */
AMPS_API amps_status amps_scene_step_info(const amps_scene *S, amps_scene_step_stats *st);
#endif /* AMPS_NO_FEM */

/* ==== [amps:io] mesh readers and writers ====================================================== */
#ifndef AMPS_NO_FEM
/* Mesh readers. Nodes are numbered in file order from 0; tets keep file order. Return NULL on
   failure, with AMPS_ERR_PARSE and "file:line: message" in ctx for malformed input (AMPS_ERR_IO
   if a file cannot be read, AMPS_ERR_MESH "file:line: ..." for a degenerate tet).
   TetGen .node/.ele: index base = first point number in .node (0 or 1), point numbers
     consecutive; node attributes and boundary markers ignored; 4 or 10 nodes per tet (first 4
     used); region = the first tet attribute (an integer, as tetgen -A writes it).
   Gmsh .msh ASCII 2.x and 4.1: tetrahedra are element type 4 (types 11, 29, 30, 31, of higher
     order, are read as linear tets on their 4 corners: the other nodes belong to no tet);
     surface, line and point elements are skipped; hexahedra, prisms and pyramids (any order)
     are an error, AMPS_ERR_MESH with their counts and the line of the first; node tags may be
     any distinct integers. Binary files are rejected. Region: 2.x the first (physical) tag; 4.1
     the first physical tag of the element's volume entity ($Entities; of a partitioned file,
     $PartitionedEntities, a volume without one taking its parent's); tets in an entity that
     the file does not list, or not of dimension 3, are an error. A tet given twice (2.x
     writes an element once per physical group holding its volume) is read once, in the place
     and with the region of its first line (logged).
   MEDIT .mesh (ASCII): Dimension 3, Vertices, Tetrahedra; Hexahedra, Prisms, Pyramids and the
     higher-order volume keywords with elements are an error (AMPS_ERR_MESH); other keywords are
     skipped.
     Region: the reference number of each tetrahedron.
   A tet without a region attribute gets region 0.
   amps_mesh_read picks the reader by extension: .node (and the .ele of the same name), .ele
   (and the .node), .msh, .mesh. The *_mem variants parse a buffer of len bytes (no NUL needed);
   name is used in messages. With AMPS_NO_STDIO only the *_mem variants exist. */
AMPS_API amps_mesh *amps_mesh_read_tetgen_mem(amps_ctx *ctx, const char *node_buf, size_t node_len,
                                              const char *node_name, const char *ele_buf, size_t ele_len,
                                              const char *ele_name);
AMPS_API amps_mesh *amps_mesh_read_gmsh_mem(amps_ctx *ctx, const char *buf, size_t len, const char *name);
AMPS_API amps_mesh *amps_mesh_read_medit_mem(amps_ctx *ctx, const char *buf, size_t len, const char *name);
#ifndef AMPS_NO_STDIO
AMPS_API amps_mesh *amps_mesh_read(amps_ctx *ctx, const char *path);
AMPS_API amps_mesh *amps_mesh_read_tetgen(amps_ctx *ctx, const char *node_path, const char *ele_path);
AMPS_API amps_mesh *amps_mesh_read_gmsh(amps_ctx *ctx, const char *path);
AMPS_API amps_mesh *amps_mesh_read_medit(amps_ctx *ctx, const char *path);

/* VTK XML UnstructuredGrid (ASCII) of the mesh in its reference configuration (copies are
   separate points, so a cut opens under "Warp By Vector"). Removed tets are left out. Point
   data: "displacement" (disp, 3 per node, if given) and "origin". Cell data of the kept tets:
   "von_mises" (von_mises has 1 per tet of m, if given), "principal_stress" (3 per tet, if
   given), "region" and "cut" (1 if the tet uses a cut copy node). */
AMPS_API amps_status amps_mesh_write_vtu(amps_ctx *ctx, const char *path, const amps_mesh *m, const double *disp,
                                         const double *von_mises, const double *principal);
/* Writers of all nnode nodes and the live tets in index order (copies become ordinary nodes;
   removed tets are left out, so the tets of a mesh with removals are renumbered; materials
   and densities are not written). Regions are written so that every reader gives them back.
   TetGen: base.node and base.ele with numbering from first_index (0 or 1), one tet attribute
   (the region) when any region is not 0. Gmsh: version 2 (2.2: the region as the physical tag,
   an elementary tag per region) or 4 (4.1: a volume entity per region with the region as its
   physical tag), ASCII; Gmsh itself reads either back with the regions.
   MEDIT: .mesh, version 2, the region as the tet reference. */
AMPS_API amps_status amps_mesh_write_tetgen(amps_ctx *ctx, const char *base, const amps_mesh *m, int first_index);
AMPS_API amps_status amps_mesh_write_gmsh(amps_ctx *ctx, const char *path, const amps_mesh *m, int version);
AMPS_API amps_status amps_mesh_write_medit(amps_ctx *ctx, const char *path, const amps_mesh *m);
/* ParaView .pvd collection of n frames: frame k is the file vtu_files[k] (written as given, so
   relative to the folder of the .pvd) at time times[k]. Errors: AMPS_ERR_ARG (NULL path or
   array, n < 0), AMPS_ERR_VALUE (non-finite time), AMPS_ERR_IO. */
AMPS_API amps_status amps_pvd_write(amps_ctx *ctx, const char *path, amps_int n, const char *const *vtu_files,
                                    const double *times);
#endif /* AMPS_NO_STDIO */
#endif /* AMPS_NO_FEM */

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

/* clock_gettime is POSIX: a strict ISO C build (-std=c99) declares it only with _POSIX_C_SOURCE,
   which takes effect when the implementation is the first include of its file. Otherwise, and on
   systems without it, amps_now falls back as its declaration says. */
#if !defined(_WIN32) && defined(__STRICT_ANSI__) && !defined(_POSIX_C_SOURCE) && !defined(_XOPEN_SOURCE) && \
        !defined(_GNU_SOURCE) && !defined(_DEFAULT_SOURCE) && !defined(_BSD_SOURCE)
#define _POSIX_C_SOURCE 200112L
#endif
#include <stdlib.h>
#include <string.h>
#include <math.h>
#include <stdarg.h>
#include <time.h>
#if defined(_WIN32) && !defined(AMPS_NOW)
#ifndef WIN32_LEAN_AND_MEAN
#define WIN32_LEAN_AND_MEAN
#endif
#include <windows.h>
#elif defined(__APPLE__) && !defined(AMPS_NOW)
#include <mach/mach_time.h>
#endif
#if !defined(AMPS_NO_FEM) && !defined(AMPS_NO_STDIO)
#include <stdio.h> /* file readers and writers only */
#endif
#ifdef _OPENMP
#include <omp.h>
#endif
#if !defined(AMPS_NO_SIMD) && (defined(__SSE2__) || defined(_M_X64) || (defined(_M_IX86_FP) && _M_IX86_FP >= 2))
#include <emmintrin.h> /* two-row kernels: the factorization updates, the solves, the residual check */
#define AMPS__SSE2 1
#if !defined(AMPS_NO_AVX2) && (defined(__x86_64__) || defined(__i386__)) && (defined(__GNUC__) || defined(__clang__))
#include <immintrin.h> /* AVX2 + FMA kernels, chosen at run time (amps__cpu_avx2) */
#define AMPS__AVX2 1
#define AMPS__TARGET_AVX2 __attribute__((target("avx2,fma")))
#endif
#endif
#ifndef AMPS_NO_THREADS
#include <pthread.h>
#include <sys/select.h> /* select() as a short sleep: declared without feature macros, unlike nanosleep */
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

/* ==== [amps:common impl] status codes, the context, the clock ================================= */

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
    case AMPS_WARN_INACCURATE: return "solved above the accuracy guard's tolerance";
    }
    return "unknown status";
}

AMPS_API double amps_now(void) {
#if defined(AMPS_NOW)
    return AMPS_NOW();
#elif defined(_WIN32)
    LARGE_INTEGER c, f;
    QueryPerformanceCounter(&c);
    QueryPerformanceFrequency(&f);
    return (double)c.QuadPart / (double)f.QuadPart;
#elif defined(__APPLE__)
    mach_timebase_info_data_t tb;
    mach_timebase_info(&tb);
    return (double)mach_absolute_time() * ((double)tb.numer / (double)tb.denom) * 1e-9;
#elif defined(CLOCK_MONOTONIC)
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
#elif defined(_OPENMP)
    return omp_get_wtime();
#else
    return (double)clock() / (double)CLOCKS_PER_SEC;
#endif
}

AMPS_API const char *amps_version(void) { return AMPS_VERSION_STRING; }

/* ---- messages: a small printf subset, identical in every build and free of <stdio.h> ----
   Conversions: %% %c %s %d %u %ld %lu %lld %llu, and %f %e %g with an optional precision
   (%.3g); no flags or widths; %P prints a path (a string) of over 80 characters as its first 32,
   "..." and its last 45, so that a long path leaves room for the reason after it. Numbers carry
   at most 15 significant digits (later ones print as 0); otherwise the output is printf's, correctly rounded (tests/test_fmt.c compares the two). */

typedef struct amps__str {
    char *p, *end;
} amps__str; /* cursor; end keeps room for the NUL */

static void amps__puts(amps__str *o, const char *s, size_t n) {
    while (n-- > 0 && o->p < o->end) *o->p++ = *s++;
}

static void amps__putc(amps__str *o, char c) {
    if (o->p < o->end) *o->p++ = c;
}

/* Decimal digits of u into d (room for 20); returns their number. */
static int amps__udec(char *d, unsigned long long u) {
    char t[20];
    int n = 0, k;
    do t[n++] = (char)('0' + (int)(u % 10));
    while (u /= 10);
    for (k = 0; k < n; k++) d[k] = t[n - 1 - k];
    return n;
}

/* a * 10^k (a > 0) rounded to an integer, ties to even. a * 10^k = (a 2^k) * 5^k, with a 2^k
   exact, 5^|k| the double-double h + l, and the rounding error e of the product (or quotient)
   from fma, so that near-ties round as printf's. */
static double amps__round10(double a, int k) {
    double h = 1.0, l = 0.0, t, e, r, d;
    int i;
    for (i = 0; i < (k < 0 ? -k : k); i++) {
        t = h * 5.0;
        l = fma(h, 5.0, -t) + l * 5.0;
        h = t;
    }
    a = ldexp(a, k);
    if (k >= 0) t = a * h, e = fma(a, h, -t) + a * l;
    else t = a / h, e = (fma(-t, h, a) - t * l) / h;
    r = floor(t);
    d = (t - r - 0.5) + e; /* t - r - 0.5 is 0 or at least ulp(t) > |e| */
    if (d > 0 || (d == 0 && fmod(r, 2.0) != 0.0)) r += 1.0;
    return r;
}

/* The first nd (1..15) significant digits of a > 0 (rounded) into d; returns the decimal
   exponent of the first. */
static int amps__sig(double a, int nd, char *d) {
    double lo = pow(10.0, nd - 1), r = lo;
    int x = (int)floor(log10(a)), it, k;
    for (it = 0; it < 4; it++) { /* log10 may be off by one next to a power of 10 */
        r = amps__round10(a, nd - 1 - x);
        if (r >= 10.0 * lo) x++;
        else if (r < lo) x--;
        else break;
    }
    k = amps__udec(d, (unsigned long long)r);
    while (k < nd) d[k++] = '0';
    return x;
}

/* Digits d[0..n-1] (the first of exponent x; the ones after n are 0) as %f with p decimals. */
static void amps__fixed(amps__str *o, const char *d, int n, int x, int p) {
    int i;
    if (x < 0) amps__putc(o, '0');
    for (i = 0; i <= x; i++) amps__putc(o, i < n ? d[i] : '0');
    if (p > 0) amps__putc(o, '.');
    for (i = x + 1; i <= x + p; i++) amps__putc(o, i >= 0 && i < n ? d[i] : '0');
}

/* v as %f, %e or %g (conv) with precision p (< 0: 6). */
static void amps__putd(amps__str *o, double v, char conv, int p) {
    char d[24];
    int n = 1, x = 0;
    if (p < 0) p = 6;
    if (signbit(v)) amps__putc(o, '-');
    v = fabs(v);
    if (v != v || v - v != 0) {
        amps__puts(o, v != v ? "nan" : "inf", 3);
        return;
    }
    d[0] = '0';
    if (conv == 'f') {
        if (v > 0) {
            int nd = (int)floor(log10(v)) + 1 + p;
            if (nd >= 1) x = amps__sig(v, n = nd < 15 ? nd : 15, d);
            else if (nd == 0 && amps__round10(v, p) >= 1) x = -p, d[0] = '1'; /* rounds up to 10^-p */
        }
        amps__fixed(o, d, n, x, p);
        return;
    }
    if (conv == 'g' && p == 0) p = 1;
    n = conv == 'g' ? p : p + 1;
    if (n > 15) n = 15;
    if (v > 0) x = amps__sig(v, n, d);
    else n = 1;
    if (conv == 'g') { /* shortest of the p significant digits */
        while (n > 1 && d[n - 1] == '0') n--;
        if (x >= -4 && x < p) {
            amps__fixed(o, d, n, x, n - 1 - x > 0 ? n - 1 - x : 0);
            return;
        }
        p = n - 1;
    }
    amps__fixed(o, d, n, 0, p);
    amps__putc(o, 'e');
    amps__putc(o, x < 0 ? '-' : '+');
    if (x > -10 && x < 10) amps__putc(o, '0');
    amps__puts(o, d, (size_t)amps__udec(d, (unsigned long long)(x < 0 ? -x : x)));
}

/* vsnprintf for the conversions above: at most size - 1 characters and a NUL into buf. */
static void amps__vfmt(char *buf, size_t size, const char *fmt, va_list ap) {
    amps__str o;
    char t[24];
    if (!buf || !size) return;
    o.p = buf;
    o.end = buf + size - 1;
    while (*fmt) {
        const char *spec = fmt;
        int p = -1, l = 0;
        char c;
        if (*fmt != '%') {
            amps__putc(&o, *fmt++);
            continue;
        }
        if (*++fmt == '.')
            for (p = 0; *++fmt >= '0' && *fmt <= '9';) p = 10 * p + (*fmt - '0');
        while (*fmt == 'l') l++, fmt++;
        c = *fmt;
        if (c) fmt++;
        if (c == 'd') {
            long long v = l == 0 ? va_arg(ap, int) : l == 1 ? va_arg(ap, long) : va_arg(ap, long long);
            if (v < 0) amps__putc(&o, '-');
            amps__puts(&o, t, (size_t)amps__udec(t, v < 0 ? 0ULL - (unsigned long long)v : (unsigned long long)v));
        } else if (c == 'u') {
            unsigned long long v = l == 0   ? va_arg(ap, unsigned)
                                   : l == 1 ? va_arg(ap, unsigned long)
                                            : va_arg(ap, unsigned long long);
            amps__puts(&o, t, (size_t)amps__udec(t, v));
        } else if (c == 'f' || c == 'e' || c == 'g') {
            amps__putd(&o, va_arg(ap, double), c, p);
        } else if (c == 's') {
            const char *s = va_arg(ap, const char *);
            if (!s) s = "(null)";
            amps__puts(&o, s, strlen(s));
        } else if (c == 'P') { /* a path: at most 80 characters, shortened in the middle */
            const char *s = va_arg(ap, const char *);
            size_t n;
            if (!s) s = "(null)";
            n = strlen(s);
            if (n <= 80) amps__puts(&o, s, n);
            else {
                amps__puts(&o, s, 32);
                amps__puts(&o, "...", 3);
                amps__puts(&o, s + n - 45, 45);
            }
        } else if (c == 'c') {
            amps__putc(&o, (char)va_arg(ap, int));
        } else if (c == '%') {
            amps__putc(&o, '%');
        } else {
            amps__puts(&o, spec, (size_t)(fmt - spec)); /* unsupported: copied as is */
        }
    }
    *o.p = 0;
}


/* Passes a message formatted by amps__vfmt with status s to ctx->log, if set (caller's thread
   only: see THREAD SAFETY). ctx->status and ctx->msg stay. */
static void amps__log(amps_ctx *ctx, amps_status s, const char *fmt, ...) {
    char msg[256];
    va_list ap;
    if (!ctx || !ctx->log) return;
    va_start(ap, fmt);
    amps__vfmt(msg, sizeof(msg), fmt, ap);
    va_end(ap);
    ctx->log(ctx->log_user, s, msg);
}

/* Records status s and a message formatted by amps__vfmt in ctx; returns s. A warning (s > 0)
   also goes to ctx->log. */
static amps_status amps__err(amps_ctx *ctx, amps_status s, const char *fmt, ...) {
    if (ctx) {
        va_list ap;
        ctx->status = s;
        va_start(ap, fmt);
        amps__vfmt(ctx->msg, sizeof(ctx->msg), fmt, ap);
        va_end(ap);
        if (s > 0 && ctx->log) ctx->log(ctx->log_user, s, ctx->msg);
    }
    return s;
}

/* n*size bytes, or NULL (with AMPS_ERR_OOM in ctx) on overflow or failure. Never 0 bytes. */
/* qsort of n entries of a (a may be NULL when n < 2: qsort's pointer must not be). */
static void amps__sort(void *a, size_t n, size_t size, int (*cmp)(const void *, const void *)) {
    if (n > 1) qsort(a, n, size, cmp);
}

static void *amps__malloc(amps_ctx *ctx, size_t n, size_t size) {
    void *p;
    if (n == 0) n = 1;
    if (size && n > ((size_t)-1) / size) {
        amps__err(ctx, AMPS_ERR_OOM, "allocation size overflow");
        return NULL;
    }
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

/* Largest value of amps_int. */
#define AMPS__IMAX ((amps_int)((((unsigned long long)1) << (sizeof(amps_int) * 8 - 1)) - 1))

/* ---- the parallel layer: one loop primitive over three back ends ----
   amps__par_for(par, nt, n, chunk, fn, arg) runs fn(begin, end, slot, arg) on the chunks
   [c * chunk, min(n, (c + 1) * chunk)) of [0, n), each exactly once, on at most nt participants
   (nt <= the scratch slots of the kernel; slot < nt indexes its per-participant scratch; no two
   participants share a slot). The chunks depend on (n, chunk) only, never on the participants,
   and every participant claims the next chunk from one atomic counter, so a descheduled worker
   delays only the chunk it holds and no kernel waits for a particular worker. Kernels give each
   output one writer (a chunk); a kernel that reduces across chunks keeps a partial result per
   chunk and combines them in chunk order on one thread afterwards, so results are bitwise the
   same for any participant count and schedule.
   Back ends: the host's task system (ctx->enqueue_task/finish_task): the caller enqueues
   min(nt - 1, chunks - 1) items, each claiming chunks under slot = its item index, claims
   chunks itself under the last slot, then calls finish; the owner's workers (amps__pool, the
   default): workers below nt - 1 and the caller (slot nt - 1) claim chunks, and the caller
   waits only for chunks begun; OpenMP (AMPS_BACKEND_OPENMP, or AUTO in a build without
   AMPS__HAVE_POOL): a team of nt threads claims chunks (slot = thread number); serial
   otherwise (also an object without workers), when nt <= 1, when there is one chunk, or when
   the mode choice below picks serial.
   Mode choice: a parallel loop ends when its slowest participant does; beside other busy
   processes a woken worker may wait a time slice for a core while the caller waits for it at
   the end of the loop, and the loop is then slower than the serial one. So every owner times
   its loops: per kernel (fn), an exponential average of seconds per item of [0, n) in each mode
   (serial, parallel), over all of the loop including wake-up and join. A loop runs in the mode
   with the smaller average; a few loops (pseudo-randomly chosen, so they are not tied to a
   position in a sequence of loops; at most one in AMPS__PAR_EXPLORE, fewer the slower the other
   mode is) run in the other mode, which keeps both averages current when the load changes. Serial and parallel runs give the same bits, so this trades
   only time. */
#ifndef AMPS__PAR_ADAPT
#define AMPS__PAR_ADAPT 1 /* 0: every eligible loop runs in parallel (tests of the schedule) */
#endif
#ifndef AMPS__PAR_EXPLORE
#define AMPS__PAR_EXPLORE 16
#endif
#define AMPS__PAR_KERNELS 61 /* timing slots per owner (a prime: fn addresses hash into it) */

#if defined(__GNUC__) || defined(__clang__)
#define AMPS__HAVE_ATOMICS 1
#define AMPS__FETCH_ADD(p, v) __atomic_fetch_add((p), (v), __ATOMIC_ACQ_REL)
static double amps__dload(const double *p) {
    double v;
    __atomic_load(p, &v, __ATOMIC_RELAXED);
    return v;
}
static void amps__dstore(double *p, double v) { __atomic_store(p, &v, __ATOMIC_RELAXED); }
#define AMPS__ZLOAD(p) __atomic_load_n((p), __ATOMIC_RELAXED)
#define AMPS__ZSTORE(p, v) __atomic_store_n((p), (v), __ATOMIC_RELAXED)
#if !defined(AMPS_NO_THREADS)
#define AMPS__HAVE_POOL 1 /* amps' own workers: POSIX threads and these atomics */
#endif
#elif defined(_MSC_VER)
#include <intrin.h>
#define AMPS__HAVE_ATOMICS 1
#define AMPS__FETCH_ADD(p, v) _InterlockedExchangeAdd((volatile long *)(p), (v))
static double amps__dload(const double *p) { return *(const volatile double *)p; }
static void amps__dstore(double *p, double v) { *(volatile double *)p = v; }
#define AMPS__ZLOAD(p) (*(volatile size_t *)(p))
#define AMPS__ZSTORE(p, v) (*(volatile size_t *)(p) = (v))
#else
#define AMPS__HAVE_ATOMICS 0 /* no atomic counter: every loop runs serially */
static double amps__dload(const double *p) { return *p; }
static void amps__dstore(double *p, double v) { *p = v; }
#define AMPS__ZLOAD(p) (*(p))
#define AMPS__ZSTORE(p, v) (*(p) = (v))
#endif

#ifdef _OPENMP
#define AMPS__HAVE_OMP 1
#else
#define AMPS__HAVE_OMP 0
#endif
#ifndef AMPS__HAVE_POOL
#define AMPS__HAVE_POOL 0
#endif

typedef void amps__chunk_fn(amps_int begin, amps_int end, int slot, void *arg);
typedef struct amps__pool amps__pool;

/* Loop timing of one owner (relaxed atomics: the solves of one factor may run concurrently,
   and a background job shares its engine's state). slot[k] holds kernel key[k] (the hashed fn
   address; 0 = free) with avg[k][mode] seconds per item (0 = no sample yet). */
typedef struct amps__parbo {
    size_t key[AMPS__PAR_KERNELS];
    double avg[AMPS__PAR_KERNELS][2];
    long tick; /* loops timed so far: the exploration's pseudo-random sequence */
} amps__parbo;

/* A back end captured from a context: the host's callbacks, else the owner's workers (pool),
   else OpenMP regions (omp), else serial; bo points at the owner's loop timing (or NULL). */
typedef struct amps__par {
    amps_enqueue_task_fn *enqueue;
    amps_finish_task_fn *finish;
    void *user;
    amps__pool *pool;
    int omp;
    amps__parbo *bo;
} amps__par;

/* Participants (scratch slots) of the context's back end: worker_count + 1 (the caller claims
   chunks too) with callbacks, else ctx->nthreads, else the OpenMP default, else 1. */
static int amps__par_slots(const amps_ctx *ctx) {
    int t = 1;
    if (ctx && ctx->enqueue_task && ctx->finish_task) return (ctx->worker_count > 1 ? ctx->worker_count : 1) + 1;
    if (ctx && ctx->backend == AMPS_BACKEND_SERIAL) return 1;
    if (ctx && ctx->nthreads > 0) return ctx->nthreads;
#ifdef _OPENMP
    t = omp_get_max_threads();
#endif
    return t < 1 ? 1 : t;
}

/* Whether ctx asks for amps' own workers (no callbacks; AUTO or THREADS; 2 or more slots). */
static int amps__par_wants_pool(const amps_ctx *ctx) {
    return AMPS__HAVE_POOL && !(ctx && ctx->enqueue_task && ctx->finish_task) &&
           (!ctx || ctx->backend == AMPS_BACKEND_AUTO || ctx->backend == AMPS_BACKEND_THREADS) &&
           amps__par_slots(ctx) > 1;
}

/* The back end of a call with ctx on an object whose workers are pool (NULL: none; where amps
   has workers, AUTO then runs serially, as on a factor too small to start any). */
static amps__par amps__par_of(const amps_ctx *ctx, amps__parbo *bo, amps__pool *pool) {
    amps__par p;
    amps_backend be = ctx ? ctx->backend : AMPS_BACKEND_AUTO;
    p.enqueue = ctx && ctx->finish_task ? ctx->enqueue_task : NULL;
    p.finish = p.enqueue ? ctx->finish_task : NULL;
    p.user = p.enqueue ? ctx->task_user : NULL;
    p.pool = amps__par_wants_pool(ctx) ? pool : NULL; /* never beside callbacks */
    p.omp = AMPS__HAVE_OMP && !p.enqueue && (be == AMPS_BACKEND_OPENMP || (be == AMPS_BACKEND_AUTO && !AMPS__HAVE_POOL));
    p.bo = bo;
    return p;
}

typedef struct amps__job {
    amps__chunk_fn *fn;
    void *arg;
    amps_int n, chunk;
    long nchunk, next; /* chunks; the next one to claim (atomic) */
    int nt;            /* participants: slots 0 .. nt - 1 */
} amps__job;

/* Runs chunks of j under slot until none is left. */
static void amps__par_claim(amps__job *j, int slot) {
#if AMPS__HAVE_ATOMICS
    long c;
    while ((c = AMPS__FETCH_ADD(&j->next, 1L)) < j->nchunk) {
        amps_int b = (amps_int)c * j->chunk;
        j->fn(b, j->n - b < j->chunk ? j->n : b + j->chunk, slot, j->arg);
    }
#else
    (void)j;
    (void)slot;
#endif
}

/* The task handed to the host: item `begin` is a participant with slot = begin. */
static void amps__par_task(amps_int begin, amps_int end, int worker, void *task_ctx) {
    (void)end;
    (void)worker;
    amps__par_claim(AMPS__CAST(amps__job *, task_ctx), (int)begin);
}

/* ---- amps' own workers (AMPS_BACKEND_THREADS) ----
   nw threads; worker w is participant (slot) w of a loop, the caller the last one (nt - 1).
   Posting a loop: the caller publishes the job and a new generation under the mutex (waking
   sleeping workers), claims chunks like everyone else, then closes the job (job = NULL) and
   waits until no worker is inside it (spinning AMPS__POOL_SPIN pauses on users, then on idle:
   a sleep and a wake-up per loop cost more than the short loops of a step). A worker enters a
   job only under the mutex, while it is open, and counts itself in users; one that wakes after
   the close finds no job and sleeps again. So the caller waits for chunks begun, never for a
   worker that has not started: beside busy processes a loop costs about its serial time, or
   less. A worker spins AMPS__POOL_SPIN pauses on the generation before it sleeps (loops follow
   each other closely in a step). */
#ifndef AMPS__POOL_SPIN
#define AMPS__POOL_SPIN 2000
#endif
#define AMPS__POOL_MAX 64
#if AMPS__HAVE_POOL
struct amps__pool_arg {
    amps__pool *pool;
    int id; /* the worker's slot */
};
struct amps__pool {
    pthread_mutex_t m;
    pthread_cond_t wake;  /* workers: a new generation, or stop */
    pthread_cond_t idle;  /* the caller: users fell to 0 */
    long gen;             /* loops posted (written under m, atomically: spinning workers read it) */
    amps__job *job;       /* the open job (NULL: none); under m */
    int users;            /* workers inside job (written under m, atomically: the caller spins on it) */
    int sleepers;         /* workers waiting on wake; under m */
    int closing, stop;    /* the caller waits on idle; the workers exit; under m */
    int busy;             /* a caller owns the pool (atomic exchange) */
    int nw;               /* worker threads */
    pthread_t th[AMPS__POOL_MAX];
    struct amps__pool_arg arg[AMPS__POOL_MAX];
};

static void amps__cpu_pause(void) {
#if defined(__x86_64__) || defined(__i386__)
    __builtin_ia32_pause();
#elif defined(__aarch64__)
    __asm__ __volatile__("yield");
#endif
}

static void *amps__pool_main(void *varg) {
    struct amps__pool_arg *a = AMPS__CAST(struct amps__pool_arg *, varg);
    amps__pool *P = a->pool;
    long seen = 0;
    for (;;) {
        amps__job *j;
        int k;
        for (k = 0; k < AMPS__POOL_SPIN && __atomic_load_n(&P->gen, __ATOMIC_RELAXED) == seen; k++) amps__cpu_pause();
        pthread_mutex_lock(&P->m);
        while (!P->stop && P->gen == seen) {
            P->sleepers++;
            pthread_cond_wait(&P->wake, &P->m);
            P->sleepers--;
        }
        if (P->stop) break;
        seen = P->gen;
        j = P->job && a->id < P->job->nt - 1 ? P->job : NULL; /* slots below the caller's only */
        if (j) __atomic_store_n(&P->users, P->users + 1, __ATOMIC_RELAXED);
        pthread_mutex_unlock(&P->m);
        if (!j) continue;
        amps__par_claim(j, a->id);
        pthread_mutex_lock(&P->m);
        __atomic_store_n(&P->users, P->users - 1, __ATOMIC_RELEASE); /* the chunks' writes before it */
        if (P->users == 0 && P->closing) pthread_cond_signal(&P->idle);
        pthread_mutex_unlock(&P->m);
    }
    pthread_mutex_unlock(&P->m);
    return NULL;
}

static void amps__pool_free(amps_ctx *ctx, amps__pool *P) {
    int w;
    if (!P) return;
    pthread_mutex_lock(&P->m);
    P->stop = 1;
    pthread_cond_broadcast(&P->wake);
    pthread_mutex_unlock(&P->m);
    for (w = 0; w < P->nw; w++) pthread_join(P->th[w], NULL);
    pthread_cond_destroy(&P->wake);
    pthread_cond_destroy(&P->idle);
    pthread_mutex_destroy(&P->m);
    amps__free(ctx, P);
}

/* The workers of an object made with ctx (slots - 1 threads), or NULL: ctx wants none, or no
   thread could start (the object's loops then run serially; not an error). */
static amps__pool *amps__pool_new(amps_ctx *ctx) {
    amps__pool *P;
    int nw = amps__par_slots(ctx) - 1, w;
    if (!amps__par_wants_pool(ctx)) return NULL;
    if (nw > AMPS__POOL_MAX) nw = AMPS__POOL_MAX;
    P = AMPS__CAST(amps__pool *, amps__calloc(ctx, 1, sizeof(amps__pool)));
    if (!P) return NULL;
    if (pthread_mutex_init(&P->m, NULL)) goto fail_m;
    if (pthread_cond_init(&P->wake, NULL)) goto fail_w;
    if (pthread_cond_init(&P->idle, NULL)) goto fail_i;
    for (w = 0; w < nw; w++) {
        P->arg[w].pool = P;
        P->arg[w].id = w;
        if (pthread_create(&P->th[w], NULL, amps__pool_main, &P->arg[w])) break;
        P->nw = w + 1;
    }
    if (P->nw > 0) return P;
    pthread_cond_destroy(&P->idle);
fail_i:
    pthread_cond_destroy(&P->wake);
fail_w:
    pthread_mutex_destroy(&P->m);
fail_m:
    amps__free(ctx, P);
    return NULL;
}

/* Runs j on P's workers and the calling thread (slot nt - 1); 0 if another loop holds P (the
   caller then runs j serially). */
static int amps__pool_run(amps__pool *P, amps__job *j, int nt) {
    int wake, k;
    if (__atomic_exchange_n(&P->busy, 1, __ATOMIC_ACQUIRE)) return 0;
    if (nt > P->nw + 1) nt = P->nw + 1;
    j->nt = nt;
    pthread_mutex_lock(&P->m);
    P->job = j;
    __atomic_store_n(&P->gen, P->gen + 1, __ATOMIC_RELAXED);
    wake = P->sleepers > 0;
    pthread_mutex_unlock(&P->m);
    if (wake) pthread_cond_broadcast(&P->wake);
    amps__par_claim(j, nt - 1);
    pthread_mutex_lock(&P->m);
    P->job = NULL; /* closed: a worker that wakes from now on finds nothing */
    pthread_mutex_unlock(&P->m);
    /* the workers inside finish their chunks: spin as they do before sleeping, then wait */
    for (k = 0; k < AMPS__POOL_SPIN && __atomic_load_n(&P->users, __ATOMIC_ACQUIRE) > 0; k++) amps__cpu_pause();
    pthread_mutex_lock(&P->m);
    P->closing = 1;
    while (P->users > 0) pthread_cond_wait(&P->idle, &P->m);
    P->closing = 0;
    pthread_mutex_unlock(&P->m);
    __atomic_store_n(&P->busy, 0, __ATOMIC_RELEASE);
    return 1;
}
#else
static void amps__pool_free(amps_ctx *ctx, amps__pool *P) {
    (void)ctx;
    (void)P;
}
static amps__pool *amps__pool_new(amps_ctx *ctx) {
    (void)ctx;
    return NULL;
}
#endif

/* The timing slot of kernel fn in bo (an existing one, else a free one, else the home slot,
   whose averages it then takes over). */
static amps_int amps__par_slot(amps__parbo *bo, amps__chunk_fn *fn) {
    size_t key = (size_t)fn | 1, home = ((size_t)fn >> 3) % AMPS__PAR_KERNELS, k, q;
    for (q = 0; q < 4; q++) {
        size_t have = AMPS__ZLOAD(&bo->key[(home + q) % AMPS__PAR_KERNELS]);
        if (have == key) return (amps_int)((home + q) % AMPS__PAR_KERNELS);
        if (have == 0) break;
    }
    k = (home + (q < 4 ? q : 0)) % AMPS__PAR_KERNELS;
    AMPS__ZSTORE(&bo->key[k], key);
    amps__dstore(&bo->avg[k][0], 0.0);
    amps__dstore(&bo->avg[k][1], 0.0);
    return (amps_int)k;
}

/* The mode of the next loop of slot k (1 parallel, 0 serial): the faster average, or a mode
   without a sample yet; the other mode with probability p = 0.05 t_fast / (t_slow - t_fast)
   within [1/1024, 1/16], so exploring costs about 5% of the loops' time however slow the other
   mode is. */
static int amps__par_pick(amps__parbo *bo, amps_int k) {
    double ts = amps__dload(&bo->avg[k][0]), tp = amps__dload(&bo->avg[k][1]), p, u;
    unsigned long h = (unsigned long)AMPS__FETCH_ADD(&bo->tick, 1L) * 2654435761UL;
    int best = tp <= ts;
    if (tp == 0.0) return 1;
    if (ts == 0.0) return 0;
    p = best ? (ts > tp ? 0.05 * tp / (ts - tp) : 1.0) : 0.05 * ts / (tp - ts);
    p = p < 1.0 / 1024 ? 1.0 / 1024 : p > 1.0 / AMPS__PAR_EXPLORE ? 1.0 / AMPS__PAR_EXPLORE : p;
    u = (double)((h >> 8) & 0xfffffUL) / 1048576.0;
    return u < p ? !best : best;
}

/* avg <- avg + (sample - avg) / 8, sample = seconds per item of a loop in that mode. */
static void amps__par_note(amps__parbo *bo, amps_int k, int mode, double t0, double t1, amps_int n) {
    double e = (t1 - t0) / (double)n, a = amps__dload(&bo->avg[k][mode]);
    if (e <= 0.0) e = 1e-12;
    amps__dstore(&bo->avg[k][mode], a == 0.0 ? e : a + (e - a) / 8);
}

static void amps__par_for(const amps__par *par, int nt, amps_int n, amps_int chunk, amps__chunk_fn *fn, void *arg) {
    amps__job j;
    amps__parbo *bo = AMPS__PAR_ADAPT ? par->bo : NULL;
    amps_int k = 0;
    double t0 = 0;
    int mode = 1;
    if (n <= 0) return;
    if (chunk < 1) chunk = 1;
    j.fn = fn;
    j.arg = arg;
    j.n = n;
    j.chunk = chunk;
    j.nchunk = (long)((n - 1) / chunk + 1);
    j.next = 0;
    if (nt > j.nchunk) nt = (int)j.nchunk;
    j.nt = nt;
    if (!AMPS__HAVE_ATOMICS || nt <= 1 || (!par->enqueue && !par->pool && !par->omp)) {
        fn(0, n, 0, arg);
        return;
    }
    if (bo) {
        k = amps__par_slot(bo, fn);
        mode = amps__par_pick(bo, k);
        t0 = amps_now();
    }
    if (!mode) fn(0, n, 0, arg);
    else if (par->enqueue) {
        void *h = par->enqueue(amps__par_task, (amps_int)(nt - 1), 1, &j, par->user);
        amps__par_claim(&j, nt - 1);
        if (h) par->finish(h, par->user); /* not queued (NULL): the caller claimed every chunk */
    }
#if AMPS__HAVE_POOL
    else if (par->pool) {
        if (!amps__pool_run(par->pool, &j, nt)) fn(0, n, 0, arg);
    }
#endif
#ifdef _OPENMP
    else {
#pragma omp parallel num_threads(nt)
        amps__par_claim(&j, omp_get_thread_num());
    }
#endif
    if (bo) amps__par_note(bo, k, mode, t0, amps_now(), n);
}

/* ==== [amps:sparse impl] sparse matrices ====================================================== */

/* Largest value of amps_int. */

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
        amps__err(ctx, AMPS_ERR_OOM, "amps_csc_alloc: out of memory (%lld x %lld, nzmax %lld)", (long long)nrow,
                  (long long)ncol, (long long)nzmax);
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
    if (A->p[0] != 0)
        return amps__err(ctx, AMPS_ERR_PATTERN, "amps_csc_check: p[0] = %lld, must be 0", (long long)A->p[0]);
    for (j = 0; j < n; j++)
        if (A->p[j + 1] < A->p[j])
            return amps__err(ctx, AMPS_ERR_PATTERN, "amps_csc_check: column %lld: p[%lld] = %lld < p[%lld] = %lld",
                             (long long)j, (long long)(j + 1), (long long)A->p[j + 1], (long long)j,
                             (long long)A->p[j]);
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
                return amps__err(ctx, AMPS_ERR_PATTERN,
                                 "amps_csc_check: column %lld: row %lld is outside the %s triangle", (long long)j,
                                 (long long)i, stype == AMPS_UPPER ? "upper" : "lower");
            if (A->x && !amps__isfinite(A->x[p]))
                return amps__err(ctx, AMPS_ERR_VALUE, "amps_csc_check: column %lld: row %lld: non-finite value",
                                 (long long)j, (long long)i);
        }
    }
    return AMPS_OK;
}

/* Checks the triplets of amps_csc_from_triplets; *m = the entries they give in the stype part
   (off-diagonal ones twice for AMPS_FULL). */
static amps_status amps__triplets_check(amps_ctx *ctx, amps_int n, amps_int nz, const amps_int *ti, const amps_int *tj,
                                        const double *tx, amps_stype stype, amps_int *m) {
    const char *fn = "amps_csc_from_triplets";
    amps_int k;
    *m = 0;
    if (n < 0 || nz < 0)
        return amps__err(ctx, AMPS_ERR_ARG, "%s: negative size (n %lld, nz %lld)", fn, (long long)n, (long long)nz);
    if (stype != AMPS_LOWER && stype != AMPS_FULL && stype != AMPS_UPPER)
        return amps__err(ctx, AMPS_ERR_ARG, "%s: invalid stype %d", fn, (int)stype);
    if (nz > 0 && (!ti || !tj || !tx)) return amps__err(ctx, AMPS_ERR_ARG, "%s: NULL triplet array", fn);
    for (k = 0; k < nz; k++) {
        if (ti[k] < 0 || ti[k] >= n || tj[k] < 0 || tj[k] >= n)
            return amps__err(ctx, AMPS_ERR_INDEX, "%s: triplet %lld: (row %lld, column %lld) out of range [0,%lld)", fn,
                             (long long)k, (long long)ti[k], (long long)tj[k], (long long)n);
        if (!amps__isfinite(tx[k]))
            return amps__err(ctx, AMPS_ERR_VALUE, "%s: triplet %lld: (row %lld, column %lld) non-finite value", fn,
                             (long long)k, (long long)ti[k], (long long)tj[k]);
        *m += (stype == AMPS_FULL && ti[k] != tj[k]) ? 2 : 1;
        if (*m < 0 || *m > AMPS__IMAX / 2)
            return amps__err(ctx, AMPS_ERR_ARG, "%s: too many entries for the index type", fn);
    }
    return AMPS_OK;
}

/* The m stype-part entries of the triplets bucketed by row: row r holds (Tj, Tx)[Tp[r] .. Tp[r+1]),
   in triplet order. Tp has n + 1 entries (zero on entry), w n + 1 of workspace. */
static void amps__triplets_by_row(amps_int n, amps_int nz, const amps_int *ti, const amps_int *tj, const double *tx,
                                  amps_stype stype, amps_int *Tp, amps_int *Tj, double *Tx, amps_int *w) {
    amps_int k, r, p, q;
    for (k = 0; k < nz; k++) {
        amps_int a = ti[k], b = tj[k], lo = a < b ? a : b, hi = a < b ? b : a;
        if (stype == AMPS_UPPER) Tp[lo]++;
        else if (stype == AMPS_LOWER) Tp[hi]++;
        else {
            Tp[a]++;
            if (a != b) Tp[b]++;
        }
    }
    for (r = 0, p = 0; r < n; r++) {
        q = Tp[r];
        Tp[r] = p;
        w[r] = p;
        p += q;
    }
    Tp[n] = p;
    for (k = 0; k < nz; k++) {
        amps_int a = ti[k], b = tj[k], lo = a < b ? a : b, hi = a < b ? b : a;
        if (stype == AMPS_UPPER) {
            q = w[lo]++;
            Tj[q] = hi;
            Tx[q] = tx[k];
        } else if (stype == AMPS_LOWER) {
            q = w[hi]++;
            Tj[q] = lo;
            Tx[q] = tx[k];
        } else {
            q = w[a]++;
            Tj[q] = b;
            Tx[q] = tx[k];
            if (a != b) {
                q = w[b]++;
                Tj[q] = a;
                Tx[q] = tx[k];
            }
        }
    }
}

/* Sums the duplicates of each column of (Cp, Ci, Cx) in place (rows ascending, duplicates
   adjacent); returns the number of entries left. */
static amps_int amps__csc_sum_dups(amps_int n, amps_int *Cp, amps_int *Ci, double *Cx) {
    amps_int j, q, nnz = 0;
    for (j = 0; j < n; j++) {
        amps_int start = nnz;
        for (q = Cp[j]; q < Cp[j + 1]; q++) {
            if (nnz > start && Ci[nnz - 1] == Ci[q]) Cx[nnz - 1] += Cx[q];
            else {
                Ci[nnz] = Ci[q];
                Cx[nnz] = Cx[q];
                nnz++;
            }
        }
        Cp[j] = start;
    }
    Cp[n] = nnz;
    return nnz;
}

AMPS_API amps_csc *amps_csc_from_triplets(amps_ctx *ctx, amps_int n, amps_int nz, const amps_int *ti,
                                          const amps_int *tj, const double *tx, amps_stype stype) {
    amps_int m = 0, j, r, p, q, nnz;
    amps_int *Tp = NULL, *Tj = NULL, *Cp = NULL, *Ci = NULL, *w = NULL;
    double *Tx = NULL, *Cx = NULL;
    amps_csc *A = NULL;
    if (amps__triplets_check(ctx, n, nz, ti, tj, tx, stype, &m) != AMPS_OK) return NULL;
    /* bucket by row, then by column (stable): columns come out with ascending rows */
    Tp = AMPS__CAST(amps_int *, amps__calloc(ctx, (size_t)n + 1, sizeof(amps_int)));
    Cp = AMPS__CAST(amps_int *, amps__calloc(ctx, (size_t)n + 1, sizeof(amps_int)));
    w = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)n + 1, sizeof(amps_int)));
    Tj = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)m, sizeof(amps_int)));
    Tx = AMPS__CAST(double *, amps__malloc(ctx, (size_t)m, sizeof(double)));
    Ci = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)m, sizeof(amps_int)));
    Cx = AMPS__CAST(double *, amps__malloc(ctx, (size_t)m, sizeof(double)));
    if (!Tp || !Cp || !w || !Tj || !Tx || !Ci || !Cx) {
        amps__err(ctx, AMPS_ERR_OOM, "amps_csc_from_triplets: out of memory (n %lld, nz %lld)", (long long)n,
                  (long long)nz);
        goto done;
    }
    amps__triplets_by_row(n, nz, ti, tj, tx, stype, Tp, Tj, Tx, w);
    for (q = 0; q < m; q++) Cp[Tj[q]]++;
    for (j = 0, p = 0; j < n; j++) {
        q = Cp[j];
        Cp[j] = p;
        w[j] = p;
        p += q;
    }
    Cp[n] = p;
    for (r = 0; r < n; r++)
        for (q = Tp[r]; q < Tp[r + 1]; q++) {
            p = w[Tj[q]]++;
            Ci[p] = r;
            Cx[p] = Tx[q];
        }
    nnz = amps__csc_sum_dups(n, Cp, Ci, Cx);
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
    A->p = Cp;
    A->i = Ci;
    A->x = Cx;
    Cp = Ci = NULL;
    Cx = NULL;
done:
    amps__free(ctx, Tp);
    amps__free(ctx, Cp);
    amps__free(ctx, w);
    amps__free(ctx, Tj);
    amps__free(ctx, Tx);
    amps__free(ctx, Ci);
    amps__free(ctx, Cx);
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

/* ==== [amps:ordering impl] fill-reducing orderings ============================================ */

#ifdef AMPS_USE_METIS
#ifdef __cplusplus
}
#endif
#include <metis.h>
#ifdef __cplusplus
extern "C" {
#endif
#endif


/* ---------------------------- graph helpers ---------------------------- */

/* Allocates k amps_int arrays *pp[a] of len[a] entries; on failure frees the ones made. */
static amps_status amps__ialloc(amps_ctx *ctx, int k, amps_int **pp[], const size_t *len) {
    int a;
    for (a = 0; a < k; a++) {
        *pp[a] = (amps_int *)amps__malloc(ctx, len[a], sizeof(amps_int));
        if (!*pp[a]) {
            while (a-- > 0) {
                amps__free(ctx, *pp[a]);
                *pp[a] = NULL;
            }
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
    if (n > 0 && Ap[0] != 0)
        return amps__err(ctx, AMPS_ERR_PATTERN, "%s: column pointer p[0] = %ld, must be 0", fn, (long)Ap[0]);
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
                return amps__err(ctx, AMPS_ERR_INDEX, "%s: row index %ld out of range [0,%ld) in column %ld", fn,
                                 (long)i, (long)n, (long)j);
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
        if (!Gp || !w) {
            amps__free(ctx, Gp);
            amps__free(ctx, w);
            return AMPS_ERR_OOM;
        }
        for (j = 0; j <= n; j++) Gp[j] = 0;
        for (j = 0; j < n; j++)
            for (p = Ap[j]; p < Ap[j + 1]; p++)
                if (Ai[p] != j) {
                    Gp[Ai[p] + 1]++;
                    Gp[j + 1]++;
                }
        for (j = 0; j < n; j++) {
            Gp[j + 1] += Gp[j];
            w[j] = Gp[j];
        }
        Gi = (amps_int *)amps__malloc(ctx, (size_t)Gp[n], sizeof(amps_int));
        if (!Gi) {
            amps__free(ctx, Gp);
            amps__free(ctx, w);
            return AMPS_ERR_OOM;
        }
        for (j = 0; j < n; j++)
            for (p = Ap[j]; p < Ap[j + 1]; p++)
                if ((i = Ai[p]) != j) {
                    Gi[w[i]++] = j;
                    Gi[w[j]++] = i;
                }
        amps__free(ctx, w);
        *Gp_out = Gp;
        *Gi_out = Gi;
        return AMPS_OK;
    }
    pp[0] = &Cp;
    pp[1] = &Ci;
    pp[2] = &w;
    pp[3] = &mk;
    pp[4] = &Gp;
    len[0] = (size_t)n + 1;
    len[1] = 2 * (size_t)nz;
    len[2] = (size_t)n + 1;
    len[3] = (size_t)n + 1;
    len[4] = (size_t)n + 1;
    if ((s = amps__ialloc(ctx, 5, pp, len)) != AMPS_OK) return s;
    /* C: both directions of every off-diagonal entry (duplicates allowed) */
    for (j = 0; j <= n; j++) Cp[j] = 0;
    for (j = 0; j < n; j++)
        for (p = Ap[j]; p < Ap[j + 1]; p++)
            if (Ai[p] != j) {
                Cp[Ai[p] + 1]++;
                Cp[j + 1]++;
            }
    for (j = 0; j < n; j++) Cp[j + 1] += Cp[j];
    for (j = 0; j < n; j++) w[j] = Cp[j];
    for (j = 0; j < n; j++)
        for (p = Ap[j]; p < Ap[j + 1]; p++)
            if ((i = Ai[p]) != j) {
                Ci[w[i]++] = j;
                Ci[w[j]++] = i;
            }
    /* G = C^T without duplicates; rows come out ascending */
    for (j = 0; j <= n; j++) Gp[j] = 0;
    for (j = 0; j < n; j++) mk[j] = -1;
    for (j = 0; j < n; j++)
        for (p = Cp[j]; p < Cp[j + 1]; p++)
            if (mk[i = Ci[p]] != j) {
                mk[i] = j;
                Gp[i + 1]++;
            }
    for (j = 0; j < n; j++) Gp[j + 1] += Gp[j];
    Gi = (amps_int *)amps__malloc(ctx, (size_t)(n > 0 ? Gp[n] : 0), sizeof(amps_int));
    if (!Gi) {
        amps__free(ctx, Cp);
        amps__free(ctx, Ci);
        amps__free(ctx, w);
        amps__free(ctx, mk);
        amps__free(ctx, Gp);
        return AMPS_ERR_OOM;
    }
    for (j = 0; j < n; j++) {
        mk[j] = -1;
        w[j] = Gp[j];
    }
    for (j = 0; j < n; j++)
        for (p = Cp[j]; p < Cp[j + 1]; p++)
            if (mk[i = Ci[p]] != j) {
                mk[i] = j;
                Gi[w[i]++] = j;
            }
    amps__free(ctx, Cp);
    amps__free(ctx, Ci);
    amps__free(ctx, w);
    amps__free(ctx, mk);
    *Gp_out = Gp;
    *Gi_out = Gi;
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
                if (p < pe && Gi[p] == b) {
                    p++;
                    hit = 1;
                    continue;
                }
                if (q < qe && Gi[q] == a) {
                    q++;
                    continue;
                }
                if (p >= pe || q >= qe) {
                    same = (p >= pe && q >= qe);
                    break;
                }
                if (Gi[p] != Gi[q]) same = 0;
                p++;
                q++;
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
    pp[0] = &gid;
    pp[1] = &mk;
    pp[2] = &Qp;
    pp[3] = &Qw;
    len[0] = (size_t)n + 1;
    len[1] = (size_t)ng + 1;
    len[2] = (size_t)ng + 1;
    len[3] = (size_t)ng + 1;
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
                if ((h = gid[Gi[p]]) != g && mk[h] != g) {
                    mk[h] = g;
                    nz++;
                }
    }
    Qp[ng] = nz;
    Qi = (amps_int *)amps__malloc(ctx, (size_t)nz, sizeof(amps_int));
    if (!Qi) {
        amps__free(ctx, gid);
        amps__free(ctx, mk);
        amps__free(ctx, Qp);
        amps__free(ctx, Qw);
        return AMPS_ERR_OOM;
    }
    for (g = 0; g < ng; g++) mk[g] = -1;
    for (nz = 0, g = 0; g < ng; g++)
        for (j = gfirst[g]; j < (same ? gfirst[g] + 1 : gfirst[g + 1]); j++)
            for (p = Gp[j]; p < Gp[j + 1]; p++)
                if ((h = gid[Gi[p]]) != g && mk[h] != g) {
                    mk[h] = g;
                    Qi[nz++] = h;
                }
    amps__free(ctx, gid);
    amps__free(ctx, mk);
    *Qp_out = Qp;
    *Qi_out = Qi;
    *Qw_out = Qw;
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
            pe[j] = iw[q];    /* save the first entry, */
            iw[q] = -(j + 1); /* and mark the list head */
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
    if ((double)nz + nz / 5 + 2.0 * n + 16 > (double)AMPS__IMAX)
        return amps__err(ctx, AMPS_ERR_OOM, "graph too large for AMD (%ld entries)", (long)nz);
    iwlen = nz + nz / 5 + 2 * n + 16;
    need = 17 * (size_t)n + (size_t)ntot + 8;
    mem = (amps_int *)amps__malloc(ctx, need, sizeof(amps_int));
    iw = (amps_int *)amps__malloc(ctx, (size_t)iwlen, sizeof(amps_int));
    kind = (unsigned char *)amps__calloc(ctx, (size_t)n, 1);
    if (!mem || !iw || !kind) {
        amps__free(ctx, mem);
        amps__free(ctx, iw);
        amps__free(ctx, kind);
        return AMPS_ERR_OOM;
    }
    pe = mem;
    len = pe + n;
    elen = len + n;
    nv = elen + n;
    deg = nv + n;
    wv = deg + n;
    next = wv + n;
    last = next + n;
    hhead = last + n;
    hnext = hhead + n;
    hkey = hnext + n;
    mk = hkey + n;
    rep = mk + n;
    lme = rep + n;
    estep = lme + n;
    cnt = estep + n;
    head = cnt + n + 1;

    /* dense free vertices are set aside and ordered last */
    if (dense <= 0) {
        dense = 10.0 * sqrt((double)ntot);
        if (dense < 16) dense = 16;
    }
    for (i = 0; i < n; i++) {
        amps_int d = 0;
        for (p = Gp[i]; p < Gp[i + 1]; p++) d += vw ? vw[Gi[p]] : 1;
        kind[i] = (i < nfree && (double)d > dense) ? AMPS__AMD_DENSE : AMPS__AMD_VAR;
    }
    for (i = 0; i <= ntot; i++) head[i] = -1;
    pfree = 0;
    nleft = 0;
    ndense = 0;
    for (i = 0; i < n; i++) {
        amps_int d = 0;
        pe[i] = pfree;
        elen[i] = 0;
        rep[i] = -1;
        estep[i] = -1;
        wv[i] = 1;
        mk[i] = 0;
        hhead[i] = -1;
        nv[i] = vw ? vw[i] : 1;
        if (kind[i] == AMPS__AMD_DENSE) {
            len[i] = 0;
            ndense++;
            continue;
        }
        for (p = Gp[i]; p < Gp[i + 1]; p++)
            if (kind[j = Gi[p]] != AMPS__AMD_DENSE) {
                iw[pfree++] = j;
                d += vw ? vw[j] : 1;
            }
        len[i] = pfree - pe[i];
        deg[i] = d;
        if (i < nfree) nleft += nv[i];
    }
    mindeg = ntot;
    for (i = 0; i < nfree; i++) {
        if (kind[i] != AMPS__AMD_VAR) continue;
        next[i] = head[deg[i]];
        last[i] = -1;
        if (head[deg[i]] >= 0) last[head[deg[i]]] = i;
        head[deg[i]] = i;
        if (deg[i] < mindeg) mindeg = deg[i];
    }
    wbase = 2;
    stamp = 0;
    nsteps = 0;

    while (nleft > 0) {
        amps_int nvpiv, degme, nl, pme;
        /* select a pivot of minimum approximate degree */
        while (head[mindeg] < 0) mindeg++;
        me = head[mindeg];
        head[mindeg] = next[me];
        if (next[me] >= 0) last[next[me]] = -1;
        nvpiv = nv[me];
        nv[me] = -nvpiv;
        degme = 0;
        nl = 0;

        /* Lme = (union of the elements of me) + (variables of me), minus me */
        for (q = 0; q < len[me]; q++) {
            amps_int x = iw[pe[me] + q], pb, pend;
            if (q < elen[me]) {
                if (kind[x] != AMPS__AMD_ELEM) continue;
                pb = pe[x];
                pend = pb + len[x];
                kind[x] = AMPS__AMD_DEAD; /* absorbed into me */
                wv[x] = 0;
            } else {
                pb = pe[me] + q;
                pend = pb + 1;
            }
            for (p = pb; p < pend; p++) {
                i = iw[p];
                if (kind[i] != AMPS__AMD_VAR || nv[i] <= 0) continue;
                degme += nv[i];
                nv[i] = -nv[i];
                lme[nl++] = i;
                if (i < nfree) { /* leave the degree lists */
                    if (last[i] >= 0) next[last[i]] = next[i];
                    else head[deg[i]] = next[i];
                    if (next[i] >= 0) last[next[i]] = last[i];
                }
            }
        }
        kind[me] = AMPS__AMD_ELEM;
        len[me] = 0;
        elen[me] = 0;
        if (pfree + nl > iwlen) pfree = amps__amd_gc(n, iw, pfree, pe, len, kind);
        if (pfree + nl > iwlen) { /* not expected: the quotient graph never outgrows A */
            void *t = iw;
            if (amps__realloc(ctx, &t, (size_t)pfree + nl + n, sizeof(amps_int)) != AMPS_OK) {
                amps__free(ctx, kind);
                amps__free(ctx, mem);
                amps__free(ctx, iw);
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
            p1 = pe[i];
            pn = p1;
            L = len[i];
            for (p = p1; p < p1 + elen[i]; p++) {
                amps_int dext;
                e = iw[p];
                if (wv[e] == 0) continue;
                dext = wv[e] - wbase;
                if (dext > 0) {
                    d += dext;
                    iw[pn++] = e;
                    h += (unsigned long)e;
                } else {
                    kind[e] = AMPS__AMD_DEAD;
                    wv[e] = 0;
                } /* aggressive absorption: Le inside Lme */
            }
            ce = pn - p1;
            for (p = p1 + elen[i]; p < p1 + L; p++) {
                j = iw[p];
                if (kind[j] == AMPS__AMD_VAR && nv[j] > 0) {
                    d += nv[j];
                    iw[pn++] = j;
                    h += (unsigned long)j;
                }
            }
            c = pn - p1;
            if (d == 0 && i < nfree) {
                /* mass elimination: i is adjacent to Lme only */
                kind[i] = AMPS__AMD_DEAD;
                rep[i] = me;
                nvpiv += nvi;
                degme -= nvi;
                nv[i] = 0;
                len[i] = 0;
                elen[i] = 0;
                continue;
            }
            AMPS_ASSERT(c < L);
            /* put me first: [me, elements, variables] */
            if (c > ce) iw[p1 + c] = iw[p1 + ce];
            if (ce > 0) iw[p1 + ce] = iw[p1];
            iw[p1] = me;
            len[i] = c + 1;
            elen[i] = ce + 1;
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
                if (stamp >= AMPS__IMAX - 2) {
                    for (k = 0; k < n; k++) mk[k] = 0;
                    stamp = 0;
                }
                stamp++;
                for (p = pe[a]; p < pe[a] + len[a]; p++) mk[iw[p]] = stamp;
                prev = a;
                for (j = hnext[a]; j >= 0; j = hnext[j]) {
                    int same = len[j] == len[a] && elen[j] == elen[a] && ((a < nfree) == (j < nfree));
                    for (p = pe[j]; same && p < pe[j] + len[j]; p++) same = mk[iw[p]] == stamp;
                    if (same) {
                        nv[a] += nv[j]; /* both negative */
                        nv[j] = 0;
                        kind[j] = AMPS__AMD_DEAD;
                        rep[j] = a;
                        len[j] = 0;
                        elen[j] = 0;
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
                next[i] = head[dd];
                last[i] = -1;
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
            for (e = 0; e < n; e++)
                if (wv[e] != 0) wv[e] = 1;
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
        for (j = i; estep[j] < 0;) {
            amps_int t = rep[j];
            rep[j] = k;
            j = t;
        } /* path compression */
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
#define AMPS__ND_LEAF 100   /* parts of at most this many nodes are ordered by AMD */
#define AMPS__ND_BAL 0.60   /* each side of a bisection holds at most this share of the weight */
#define AMPS__ND_COARSE 120 /* size of the coarsest graph of a multilevel bisection */
#define AMPS__ND_TRIES 6    /* greedy growings tried on the coarsest graph */
#define AMPS__ND_MIDN 2000  /* graphs this large are bisected AMPS__ND_MID times at an */
#define AMPS__ND_MID 5      /* intermediate level of at most AMPS__ND_MIDL coarsenings */
#define AMPS__ND_MIDL 4     /* (about n/16 vertices), keeping the best */
#define AMPS__ND_PASS 8     /* refinement passes per level */
#define AMPS__ND_WIN 0.10   /* plane cuts: each side holds 1/2 -+ this share */

/* Weighted graph for nested dissection: CSR adjacency (symmetric, no self loops), vertex weights,
   optional edge weights (NULL = 1) and coordinates (3 per vertex, may be NULL). */
typedef struct amps__ndg {
    amps_int n;
    amps_int *p, *i, *vw, *ew;
    double *xyz;
    amps_int *cmap; /* vertex -> vertex of the next coarser graph */
} amps__ndg;

static void amps__ndg_free(amps_ctx *ctx, amps__ndg *g) {
    amps__free(ctx, g->p);
    amps__free(ctx, g->i);
    amps__free(ctx, g->vw);
    amps__free(ctx, g->ew);
    amps__free(ctx, g->xyz);
    amps__free(ctx, g->cmap);
    memset(g, 0, sizeof(*g));
}

/* Deterministic xorshift64* stream. */
static amps_int amps__rand(unsigned long long *s, amps_int m) {
    *s ^= *s >> 12;
    *s ^= *s << 25;
    *s ^= *s >> 27;
    return m > 0 ? (amps_int)(((*s) * 2685821657736338717ULL >> 17) % (unsigned long long)m) : 0;
}

/* Indexed binary max-heap over vertices 0..n-1 with keys key[v]; pos[v] = -1 when absent. */
typedef struct amps__heap {
    amps_int size, *h, *pos, *key;
} amps__heap;

static void amps__heap_up(amps__heap *H, amps_int k) {
    amps_int v = H->h[k];
    while (k > 0) {
        amps_int par = (k - 1) / 2;
        if (H->key[H->h[par]] >= H->key[v]) break;
        H->h[k] = H->h[par];
        H->pos[H->h[k]] = k;
        k = par;
    }
    H->h[k] = v;
    H->pos[v] = k;
}
static void amps__heap_down(amps__heap *H, amps_int k) {
    amps_int v = H->h[k];
    for (;;) {
        amps_int c = 2 * k + 1;
        if (c >= H->size) break;
        if (c + 1 < H->size && H->key[H->h[c + 1]] > H->key[H->h[c]]) c++;
        if (H->key[H->h[c]] <= H->key[v]) break;
        H->h[k] = H->h[c];
        H->pos[H->h[k]] = k;
        k = c;
    }
    H->h[k] = v;
    H->pos[v] = k;
}
static void amps__heap_push(amps__heap *H, amps_int v, amps_int key) {
    H->key[v] = key;
    H->h[H->size] = v;
    H->pos[v] = H->size;
    H->size++;
    amps__heap_up(H, H->size - 1);
}
static void amps__heap_del(amps__heap *H, amps_int v) {
    amps_int k = H->pos[v], u;
    if (k < 0) return;
    H->pos[v] = -1;
    H->size--;
    if (k == H->size) return;
    u = H->h[H->size];
    H->h[k] = u;
    H->pos[u] = k;
    amps__heap_up(H, k);
    amps__heap_down(H, H->pos[u]);
}
static void amps__heap_set(amps__heap *H, amps_int v, amps_int key) {
    amps_int old;
    if (H->pos[v] < 0) return;
    old = H->key[v];
    H->key[v] = key;
    if (key > old) amps__heap_up(H, H->pos[v]);
    else amps__heap_down(H, H->pos[v]);
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
    W->n = n;
    W->mem = m;
    W->H.size = 0;
    W->H.h = m;
    W->H.pos = m + n1;
    W->H.key = m + 2 * n1;
    W->ed = m + 3 * n1;
    W->lock = m + 4 * n1;
    W->sl = m + 5 * n1;
    W->sl2 = m + 6 * n1;
    W->logv = m + 7 * n1;
    W->logw = m + 9 * n1;
    for (k = 0; k < n; k++) {
        W->H.pos[k] = -1;
        W->lock[k] = 0;
    }
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
        nlog = 0;
        bestlog = 0;
        bs = pw[2];
        b0 = pw[0];
        b1 = pw[1];
        nbad = 0;
        nlogmax = 0;
        while (H->size > 0) {
            v = H->h[0];
            if (pw[a] + vw[v] > maxpw) break;
            /* move v from the separator to side a */
            amps__heap_del(H, v);
            W->logv[nlog] = v;
            W->logw[nlog++] = 2;
            where[v] = a;
            pw[2] -= vw[v];
            pw[a] += vw[v];
            W->lock[v] = 1;
            for (p = g->p[v]; p < g->p[v + 1]; p++) {
                u = g->i[p];
                if (where[u] != b) continue;
                /* u joins the separator */
                W->logv[nlog] = u;
                W->logw[nlog++] = b;
                where[u] = 2;
                pw[b] -= vw[u];
                pw[2] += vw[u];
                ed[u] = 0;
                for (q = g->p[u]; q < g->p[u + 1]; q++) {
                    x = g->i[q];
                    if (where[x] == 2) {
                        if (H->pos[x] >= 0) {
                            ed[x] -= vw[u];
                            amps__heap_set(H, x, vw[x] - ed[x]);
                        }
                    } else if (where[x] == b) {
                        ed[u] += vw[x];
                    }
                }
                amps__heap_push(H, u, vw[u] - ed[u]);
            }
            if (nlog > nlogmax) nlogmax = nlog;
            if (amps__sep_better(pw[2], pw[0], pw[1], bs, b0, b1, maxpw)) {
                bs = pw[2];
                b0 = pw[0];
                b1 = pw[1];
                bestlog = nlog;
                nbad = 0;
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
        t = W->sl2;
        q = 0;
        for (k = 0; k < ns + nlogmax; k++) {
            v = k < ns ? W->sl[k] : W->logv[k - ns];
            if (where[v] == 2 && !W->lock[v]) {
                W->lock[v] = 1;
                t[q++] = v;
            }
        }
        for (k = 0; k < q; k++) W->lock[t[k]] = 0;
        W->sl2 = W->sl;
        W->sl = t;
        ns = q;
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
            if (where[g->i[p]] == 1 - where[v]) {
                where[v] = 2;
                break;
            }
    }
    pw[0] = pw[1] = pw[2] = 0;
    for (v = 0; v < g->n; v++) pw[where[v]] += g->vw[v];
}

/* Grows side 0 by breadth-first search from seed until it holds half the weight (where 0/1);
   queue has room for n. */
static void amps__nd_grow(const amps__ndg *g, amps_int seed, amps_int *where, amps_int *queue,
                          unsigned long long *rng) {
    amps_int n = g->n, v, p, k, head = 0, tail = 0, tot = 0, w0 = 0;
    for (v = 0; v < n; v++) {
        where[v] = 1;
        tot += g->vw[v];
    }
    where[seed] = 4;
    queue[tail++] = seed;
    while (2 * w0 < tot) {
        if (head == tail) { /* disconnected: continue from another unvisited vertex */
            amps_int s0 = amps__rand(rng, n);
            for (k = 0; k < n && where[(s0 + k) % n] != 1; k++) {}
            if (k == n) break;
            v = (s0 + k) % n;
            where[v] = 4;
            queue[tail++] = v;
        }
        v = queue[head++];
        where[v] = 0;
        w0 += g->vw[v];
        for (p = g->p[v]; p < g->p[v + 1]; p++)
            if (where[g->i[p]] == 1) {
                where[g->i[p]] = 4;
                queue[tail++] = g->i[p];
            }
    }
    while (head < tail) where[queue[head++]] = 1;
}

/* A vertex far from start (last level of repeated breadth-first searches); dist has room for n. */
static amps_int amps__nd_far(const amps__ndg *g, amps_int start, amps_int *dist, amps_int *queue) {
    amps_int it, v, p, far = start, ecc = -1;
    for (it = 0; it < 3; it++) {
        amps_int head = 0, tail = 0, last = start;
        for (v = 0; v < g->n; v++) dist[v] = -1;
        dist[start] = 0;
        queue[tail++] = start;
        while (head < tail) {
            v = queue[head++];
            last = v;
            for (p = g->p[v]; p < g->p[v + 1]; p++)
                if (dist[g->i[p]] < 0) {
                    dist[g->i[p]] = dist[v] + 1;
                    queue[tail++] = g->i[p];
                }
        }
        if (dist[last] <= ecc) break;
        ecc = dist[last];
        far = last;
        start = last;
    }
    return far;
}

/* Coarsens g by heavy-edge matching into *c (allocated); sets g->cmap. */
static amps_status amps__nd_coarsen(amps_ctx *ctx, amps__ndg *g, amps__ndg *c, unsigned long long *rng) {
    amps_int n = g->n, v, u, p, k, nc, nz, tot = 0, maxvw, *match = NULL, *perm = NULL, *mk = NULL, *cmap;
    amps_int **pp[4];
    size_t len[4];
    memset(c, 0, sizeof(*c));
    pp[0] = &match;
    pp[1] = &perm;
    pp[2] = &g->cmap;
    pp[3] = &mk;
    len[0] = len[1] = len[2] = len[3] = (size_t)n + 1;
    if (amps__ialloc(ctx, 4, pp, len) != AMPS_OK) return AMPS_ERR_OOM;
    cmap = g->cmap;
    for (v = 0; v < n; v++) {
        match[v] = -1;
        perm[v] = v;
        tot += g->vw[v];
    }
    maxvw = (amps_int)(1.5 * (double)tot / 80.0) + 1;
    for (v = n - 1; v > 0; v--) {
        k = amps__rand(rng, v + 1);
        u = perm[v];
        perm[v] = perm[k];
        perm[k] = u;
    }
    for (k = 0; k < n; k++) {
        amps_int best = -1, bw = -1;
        v = perm[k];
        if (match[v] >= 0) continue;
        for (p = g->p[v]; p < g->p[v + 1]; p++) {
            amps_int w = g->ew ? g->ew[p] : 1;
            u = g->i[p];
            if (match[u] >= 0 || g->vw[u] + g->vw[v] > maxvw) continue;
            if (w > bw || (w == bw && g->vw[u] < g->vw[best])) {
                bw = w;
                best = u;
            }
        }
        if (best < 0) match[v] = v;
        else {
            match[v] = best;
            match[best] = v;
        }
    }
    for (v = 0; v < n; v++) cmap[v] = -1;
    for (nc = 0, v = 0; v < n; v++)
        if (cmap[v] < 0) {
            cmap[v] = nc;
            cmap[match[v]] = nc;
            perm[nc++] = v;
        }
    /* coarse graph */
    c->n = nc;
    c->p = (amps_int *)amps__malloc(ctx, (size_t)nc + 1, sizeof(amps_int));
    c->vw = (amps_int *)amps__malloc(ctx, (size_t)nc + 1, sizeof(amps_int));
    c->i = (amps_int *)amps__malloc(ctx, (size_t)(g->p[n] > 0 ? g->p[n] : 1), sizeof(amps_int));
    c->ew = (amps_int *)amps__malloc(ctx, (size_t)(g->p[n] > 0 ? g->p[n] : 1), sizeof(amps_int));
    if (g->xyz) c->xyz = (double *)amps__malloc(ctx, 3 * (size_t)nc + 1, sizeof(double));
    if (!c->p || !c->vw || !c->i || !c->ew || (g->xyz && !c->xyz)) {
        amps__ndg_free(ctx, c);
        amps__free(ctx, match);
        amps__free(ctx, perm);
        amps__free(ctx, mk);
        amps__free(ctx, g->cmap);
        g->cmap = NULL;
        return amps__err(ctx, AMPS_ERR_OOM, "out of memory coarsening a graph of %ld vertices", (long)n);
    }
    for (k = 0; k < nc; k++) mk[k] = -1;
    for (nz = 0, k = 0; k < nc; k++) {
        amps_int m[2], a, cnt, start = nz;
        m[0] = perm[k];
        m[1] = match[m[0]];
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
                if (mk[cu] < start) {
                    mk[cu] = nz;
                    c->i[nz] = cu;
                    c->ew[nz++] = w;
                } else c->ew[mk[cu]] += w;
            }
        }
        if (c->xyz) {
            double s = 1.0 / c->vw[k];
            c->xyz[3 * k] *= s;
            c->xyz[3 * k + 1] *= s;
            c->xyz[3 * k + 2] *= s;
        }
    }
    c->p[nc] = nz;
    amps__free(ctx, match);
    amps__free(ctx, perm);
    amps__free(ctx, mk);
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
                c = 1 / sqrt(t * t + 1);
                s = t * c;
                for (k = 0; k < 3; k++) { /* a := a J */
                    double akp = a[3 * k + p], akq = a[3 * k + q];
                    a[3 * k + p] = c * akp - s * akq;
                    a[3 * k + q] = s * akp + c * akq;
                }
                for (k = 0; k < 3; k++) { /* a := J^T a */
                    double apk = a[3 * p + k], aqk = a[3 * q + k];
                    a[3 * p + k] = c * apk - s * aqk;
                    a[3 * q + k] = s * apk + c * aqk;
                }
                for (k = 0; k < 3; k++) {
                    double vkp = V[3 * k + p], vkq = V[3 * k + q];
                    V[3 * k + p] = c * vkp - s * vkq;
                    V[3 * k + q] = s * vkp + c * vkq;
                }
            }
    }
}

typedef struct amps__keyv {
    double k;
    amps_int v;
} amps__keyv;

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
        for (r = 0; r < 3; r++)
            for (c = 0; c < 3; c++) C[3 * r + c] += g->vw[v] * x[r] * x[c];
    }
    amps__eig3(C, V);
    for (d = 0; d < 3; d++)
        for (k = 0; k < 3; k++) {
            dir[d][k] = (d == k);
            dir[3 + d][k] = V[3 * k + d];
        }
    for (d = 0; d < 6; d++) {
        amps_int wa = 0, bndA = 0, bndB = 0, bs = -1;
        double lo = tot * (0.5 - AMPS__ND_WIN), hi = tot * (0.5 + AMPS__ND_WIN), bgap = 0;
        for (v = 0; v < n; v++) {
            kv[v].k = dir[d][0] * g->xyz[3 * v] + dir[d][1] * g->xyz[3 * v + 1] + dir[d][2] * g->xyz[3 * v + 2];
            kv[v].v = v;
        }
        amps__sort(kv, (size_t)n, sizeof(amps__keyv), amps__keyv_cmp);
        for (k = 0; k < n; k++) {
            rank[kv[k].v] = k;
            cnt[kv[k].v] = 0;
        }
        bk = -1;
        for (k = 0; k < n - 1; k++) {
            amps_int c = 0;
            v = kv[k].v;
            if (cnt[v] > 0) bndB -= g->vw[v];
            for (p = g->p[v]; p < g->p[v + 1]; p++) {
                u = g->i[p];
                if (rank[u] < k) {
                    if (--cnt[u] == 0) bndA -= g->vw[u];
                } else {
                    c++;
                    if (++cnt[u] == 1) bndB += g->vw[u];
                }
            }
            cnt[v] = c;
            if (c > 0) bndA += g->vw[v];
            wa += g->vw[v];
            if (wa >= lo && wa <= hi) {
                amps_int s = bndA < bndB ? bndA : bndB;
                double gap = fabs(wa - 0.5 * tot);
                if (bs < 0 || s < bs || (s == bs && gap < bgap)) {
                    bs = s;
                    bk = k;
                    bgap = gap;
                }
            }
        }
        if (bk < 0 || (haveb && bs >= best)) continue;
        haveb = 1;
        best = bs;
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
            amps__free(ctx, lev[nl - 1].cmap);
            lev[nl - 1].cmap = NULL;
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
                bestpw[0] = lpw[0];
                bestpw[1] = lpw[1];
                bestpw[2] = lpw[2];
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
            amps__free(ctx, kv);
            amps__free(ctx, ws);
            if (!t) s = AMPS_ERR_OOM;
        }
        for (; t < AMPS__ND_TRIES + (c->xyz != NULL) && s == AMPS_OK; t++) {
            amps_int lpw[3], seed = amps__rand(rng, c->n);
            if (t == 0) seed = amps__nd_far(c, seed, wb, where);
            amps__nd_grow(c, seed, wb, where, rng);
            amps__nd_sep_from_cut(c, wb, lpw);
            amps__nd_fm(c, wb, lpw, maxpw, W, AMPS__ND_PASS);
            if (t == 0 || amps__sep_better(lpw[2], lpw[0], lpw[1], bestpw[2], bestpw[0], bestpw[1], maxpw)) {
                bestpw[0] = lpw[0];
                bestpw[1] = lpw[1];
                bestpw[2] = lpw[2];
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
    cw = wa;
    fw = wb;
    pw[0] = bestpw[0];
    pw[1] = bestpw[1];
    pw[2] = bestpw[2];
    for (l = nl - 2; l >= 0; l--) {
        amps_int *tmp;
        for (v = 0; v < lev[l].n; v++) fw[v] = cw[lev[l].cmap[v]];
        amps__nd_fm(&lev[l], fw, pw, maxpw, W, AMPS__ND_PASS);
        tmp = cw;
        cw = fw;
        fw = tmp;
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
static amps_status amps__nd_leaf(amps_ctx *ctx, const amps_int *Gp, const amps_int *Gi, const amps_int *vw,
                                 amps_int *vs, amps_int m, amps_int *loc, amps_int *lord) {
    amps_int k, p, v, u, h = 0, dsum = 0, *lp = NULL, *li = NULL, *lw = NULL, *hv = NULL;
    amps_status s = AMPS_OK;
    for (k = 0; k < m; k++) dsum += Gp[vs[k] + 1] - Gp[vs[k]];
    hv = (amps_int *)amps__malloc(ctx, (size_t)dsum + 1, sizeof(amps_int));
    if (!hv) return AMPS_ERR_OOM;
    for (k = 0; k < m; k++) loc[vs[k]] = k;
    for (k = 0; k < m; k++)
        for (v = vs[k], p = Gp[v]; p < Gp[v + 1]; p++)
            if (loc[u = Gi[p]] < 0) {
                loc[u] = m + h;
                hv[h++] = u;
            }
    lp = (amps_int *)amps__malloc(ctx, (size_t)(m + h) + 1, sizeof(amps_int));
    li = (amps_int *)amps__malloc(ctx, 2 * (size_t)dsum + 1, sizeof(amps_int));
    lw = (amps_int *)amps__malloc(ctx, (size_t)(m + h) + 1, sizeof(amps_int));
    if (!lp || !li || !lw) {
        s = AMPS_ERR_OOM;
        goto done;
    }
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
    amps__free(ctx, lp);
    amps__free(ctx, li);
    amps__free(ctx, lw);
    amps__free(ctx, hv);
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
    pp[0] = &loc;
    pp[1] = &stk;
    pp[2] = &where;
    pp[3] = &wa;
    pp[4] = &wb;
    pp[5] = &tmpv;
    pp[6] = &lord;
    pp[7] = &cnt;
    for (k = 0; k < 8; k++) len[k] = (size_t)n + 1;
    len[1] = 2 * ((size_t)n + 1);
    if ((s = amps__ialloc(ctx, 8, pp, len)) != AMPS_OK) return s;
    if (amps__fmws_init(ctx, &W, n) != AMPS_OK) {
        s = AMPS_ERR_OOM;
        goto done;
    }
    for (k = 0; k < n; k++) {
        order[k] = k;
        loc[k] = -1;
    }
    stk[nstk++] = 0;
    stk[nstk++] = n;
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
        if (!sub.p || !sub.i || !sub.vw || (xyz && !sub.xyz)) {
            s = AMPS_ERR_OOM;
            goto done;
        }
        for (nz = 0, k = 0; k < m; k++) {
            v = order[lo + k];
            sub.p[k] = nz;
            sub.vw[k] = vw ? vw[v] : 1;
            tot += sub.vw[k];
            if (xyz) {
                sub.xyz[3 * k] = xyz[3 * v];
                sub.xyz[3 * k + 1] = xyz[3 * v + 1];
                sub.xyz[3 * k + 2] = xyz[3 * v + 2];
            }
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
            where[k] = ncomp;
            wa[tail++] = k;
            while (head < tail) {
                v = wa[head++];
                for (p = sub.p[v]; p < sub.p[v + 1]; p++)
                    if (where[sub.i[p]] < 0) {
                        where[sub.i[p]] = ncomp;
                        wa[tail++] = sub.i[p];
                    }
            }
            ncomp++;
        }
        if (ncomp > 1) {
            amps_int c;
            for (c = 0; c <= ncomp; c++) cnt[c] = 0;
            for (k = 0; k < m; k++) cnt[where[k] + 1]++;
            for (c = 0; c < ncomp; c++) cnt[c + 1] += cnt[c];
            for (c = 0; c < ncomp; c++)
                if (cnt[c + 1] - cnt[c] > 1) {
                    stk[nstk++] = lo + cnt[c];
                    stk[nstk++] = lo + cnt[c + 1];
                }
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
            c[2] = c[0] + c[1];
            c[1] = c[0];
            c[0] = 0; /* start of each part: 0, 1, separator */
            if (c[1] > 1) {
                stk[nstk++] = lo;
                stk[nstk++] = lo + c[1];
            }
            if (c[2] - c[1] > 1) {
                stk[nstk++] = lo + c[1];
                stk[nstk++] = lo + c[2];
            }
            for (k = 0; k < m; k++) tmpv[c[where[k]]++] = order[lo + k];
        }
        memcpy(order + lo, tmpv, sizeof(amps_int) * (size_t)m);
    }
done:
    amps__ndg_free(ctx, &sub);
    amps__free(ctx, W.mem);
    amps__free(ctx, loc);
    amps__free(ctx, stk);
    amps__free(ctx, where);
    amps__free(ctx, wa);
    amps__free(ctx, wb);
    amps__free(ctx, tmpv);
    amps__free(ctx, lord);
    amps__free(ctx, cnt);
    return s;
}

/* ------------------------------ fill count, METIS ------------------------------ */

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
        amps__free(ctx, xadj);
        amps__free(ctx, adj);
        amps__free(ctx, w);
        amps__free(ctx, mp);
        amps__free(ctx, ip);
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
    amps__free(ctx, xadj);
    amps__free(ctx, adj);
    amps__free(ctx, w);
    amps__free(ctx, mp);
    amps__free(ctx, ip);
    if (r != METIS_OK)
        return amps__err(ctx, r == METIS_ERROR_MEMORY ? AMPS_ERR_OOM : AMPS_ERR_ARG, "METIS_NodeND failed (status %d)",
                         r);
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

/* AUTO: ord (ng) = the order of least fill (amps__nnzl) among AMD, ND (more than AMPS__ND_LEAF
   nodes) and METIS (when built in) of the node graph (P, I, weights Qw, coordinates nx, may be
   NULL). ord2 (ng) and wk (3 ng) are workspace. */
static amps_status amps__order_auto(amps_ctx *ctx, amps_int ng, const amps_int *P, const amps_int *I,
                                    const amps_int *Qw, const double *nx, amps_int *ord, amps_int *ord2, amps_int *wk) {
    double best = -1, f;
    amps_int *iord = wk, *par = wk + ng, *tmp = wk + 2 * ng, k;
    amps_status s = AMPS_OK;
    int c, nc = 1;
    int cand[3];
    cand[0] = AMPS_ORDER_AMD;
    if (ng > AMPS__ND_LEAF) {
        cand[nc++] = AMPS_ORDER_ND;
#ifdef AMPS_USE_METIS
        cand[nc++] = AMPS_ORDER_METIS;
#endif
    }
    for (c = 0; c < nc && s == AMPS_OK; c++) {
        if (cand[c] == AMPS_ORDER_AMD) s = amps__amd_core(ctx, ng, P, I, Qw, ng, 0, ord2);
        else if (cand[c] == AMPS_ORDER_ND) s = amps__nd_core(ctx, ng, P, I, Qw, nx, ord2);
#ifdef AMPS_USE_METIS
        else s = amps__metis(ctx, ng, P, I, Qw, ord2);
#endif
        if (s != AMPS_OK) break;
        if (nc == 1) {
            memcpy(ord, ord2, sizeof(amps_int) * (size_t)ng);
            break;
        }
        for (k = 0; k < ng; k++) iord[ord2[k]] = k;
        amps_etree(ng, P, I, ord2, iord, par, tmp);
        f = amps__nnzl(ng, P, I, Qw, ord2, iord, par, tmp);
        if (best < 0 || f < best) {
            best = f;
            memcpy(ord, ord2, sizeof(amps_int) * (size_t)ng);
        }
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
    else {
        ng = n / block;
        for (k = 0; k <= ng; k++) gfirst[k] = k * block;
    }
    if (ng < n) {
        if ((s = amps__graph_quotient(ctx, n, Gp, Gi, ng, gfirst, block == 0, &Qp, &Qi, &Qw)) != AMPS_OK) goto done;
        P = Qp;
        I = Qi;
    } else {
        P = Gp;
        I = Gi;
    }
    if (coords && block == 0 && ng < n) {
        xyz = (double *)amps__malloc(ctx, 3 * (size_t)ng, sizeof(double));
        if (!xyz) {
            s = AMPS_ERR_OOM;
            goto done;
        }
        for (k = 0; k < ng; k++)
            for (j = 0; j < 3; j++) xyz[3 * k + j] = coords[3 * gfirst[k] + j];
        nx = xyz;
    } else {
        nx = coords;
    }
    ord = (amps_int *)amps__malloc(ctx, (size_t)ng, sizeof(amps_int));
    ord2 = (amps_int *)amps__malloc(ctx, (size_t)ng, sizeof(amps_int));
    wk = (amps_int *)amps__malloc(ctx, 5 * (size_t)ng, sizeof(amps_int));
    if (!ord || !ord2 || !wk) {
        s = AMPS_ERR_OOM;
        goto done;
    }
    if (method == AMPS_ORDER_AMD) {
        s = amps__amd_core(ctx, ng, P, I, Qw, ng, 0, ord);
    } else if (method == AMPS_ORDER_ND) {
        s = amps__nd_core(ctx, ng, P, I, Qw, nx, ord);
#ifdef AMPS_USE_METIS
    } else if (method == AMPS_ORDER_METIS) {
        s = amps__metis(ctx, ng, P, I, Qw, ord);
#endif
    } else {
        s = amps__order_auto(ctx, ng, P, I, Qw, nx, ord, ord2, wk);
    }
    if (s != AMPS_OK) goto done;
    if (post) { /* ord := ord(postorder of its elimination tree): same fill */
        amps_int *iord = wk, *par = wk + 4 * ng, *pst = wk;
        for (k = 0; k < ng; k++) iord[ord[k]] = k;
        amps_etree(ng, P, I, ord, iord, par, wk + ng);
        amps_postorder(ng, par, pst, wk + ng);
        for (k = 0; k < ng; k++) ord2[k] = ord[pst[k]];
        memcpy(ord, ord2, sizeof(amps_int) * (size_t)ng);
    }
    for (q = 0, k = 0; k < ng; k++)
        for (j = gfirst[ord[k]]; j < gfirst[ord[k] + 1]; j++) perm[q++] = j;
done:
    amps__free(ctx, gfirst);
    amps__free(ctx, Qp);
    amps__free(ctx, Qi);
    amps__free(ctx, Qw);
    amps__free(ctx, xyz);
    amps__free(ctx, ord);
    amps__free(ctx, ord2);
    amps__free(ctx, wk);
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
        return amps__err(ctx, AMPS_ERR_ARG, "%s: matrix is %ld x %ld, must be square", fn, (long)A->nrow,
                         (long)A->ncol);
    if (block < 0) return amps__err(ctx, AMPS_ERR_ARG, "%s: block = %ld is negative", fn, (long)block);
    if (block > 1 && n % block != 0)
        return amps__err(ctx, AMPS_ERR_ARG, "%s: n = %ld is not a multiple of block = %ld", fn, (long)n, (long)block);
#ifndef AMPS_USE_METIS
    if (method == AMPS_ORDER_METIS)
        return amps__err(ctx, AMPS_ERR_UNSUPPORTED,
                         "%s: AMPS_ORDER_METIS needs amps.h built with AMPS_USE_METIS (and -lmetis)", fn);
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
    if ((s = amps__graph_sym(ctx, fn, n, A->p, A->i, (int)stype, &Gp, &Gi)) != AMPS_OK)
        return amps__order_fail(ctx, fn, s);
    out = (amps_int *)amps__malloc(ctx, (size_t)n, sizeof(amps_int));
    if (!out) {
        amps__free(ctx, Gp);
        amps__free(ctx, Gi);
        return amps__order_fail(ctx, fn, AMPS_ERR_OOM);
    }
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
            else out[g[k]] = k;
        }
        if (s == AMPS_OK) memcpy(out, g, sizeof(amps_int) * (size_t)n);
    } else if (n > 0) {
        s = amps__order_fail(ctx, fn, amps__order_graph(ctx, n, Gp, Gi, (int)method, block, coords, 1, out));
    }
    if (s == AMPS_OK && n > 0) memcpy(perm, out, sizeof(amps_int) * (size_t)n);
    amps__free(ctx, Gp);
    amps__free(ctx, Gi);
    amps__free(ctx, out);
    return s;
}

AMPS_API amps_status amps_amd(amps_ctx *ctx, amps_int n, const amps_int *Ap, const amps_int *Ai, amps_int *perm) {
    amps_int *Gp = NULL, *Gi = NULL, *out = NULL;
    amps_status s;
    if (n < 0) return amps__err(ctx, AMPS_ERR_ARG, "amps_amd: n = %ld is negative", (long)n);
    if (n > 0 && !perm) return amps__err(ctx, AMPS_ERR_ARG, "amps_amd: output perm is NULL");
    if ((s = amps__graph_sym(ctx, "amps_amd", n, Ap, Ai, 0, &Gp, &Gi)) != AMPS_OK)
        return amps__order_fail(ctx, "amps_amd", s);
    out = (amps_int *)amps__malloc(ctx, (size_t)n, sizeof(amps_int));
    if (!out) s = AMPS_ERR_OOM;
    else if ((s = amps__amd_core(ctx, n, Gp, Gi, NULL, n, 0, out)) == AMPS_OK && n > 0)
        memcpy(perm, out, sizeof(amps_int) * (size_t)n);
    amps__order_fail(ctx, "amps_amd", s);
    amps__free(ctx, Gp);
    amps__free(ctx, Gi);
    amps__free(ctx, out);
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
                return amps__err(ctx, AMPS_ERR_VALUE, "amps_nd: coordinate %ld of vertex %ld is not finite",
                                 (long)(k % 3), (long)(k / 3));
    if ((s = amps__graph_sym(ctx, "amps_nd", n, Ap, Ai, 0, &Gp, &Gi)) != AMPS_OK)
        return amps__order_fail(ctx, "amps_nd", s);
    out = (amps_int *)amps__malloc(ctx, (size_t)n, sizeof(amps_int));
    if (!out) s = AMPS_ERR_OOM;
    else if (n > 0 && (s = amps__order_graph(ctx, n, Gp, Gi, AMPS_ORDER_ND, 0, xyz, 1, out)) == AMPS_OK)
        memcpy(perm, out, sizeof(amps_int) * (size_t)n);
    amps__order_fail(ctx, "amps_nd", s);
    amps__free(ctx, Gp);
    amps__free(ctx, Gi);
    amps__free(ctx, out);
    return s;
}

/* ==== [amps:symbolic impl] symbolic analysis ================================================== */

/* Row k of L: the pattern's neighbours i of vertex order[k] at positions r < k lie in the subtree of
   k, so climbing from r to its current root (anc, compressed to k on the way) finds the child of k. */
AMPS_API void amps_etree(amps_int n, const amps_int *Ap, const amps_int *Ai, const amps_int *order,
                         const amps_int *iorder, amps_int *parent, amps_int *work) {
    amps_int *anc = work, k, p, r, t;
    for (k = 0; k < n; k++) {
        amps_int v = order ? order[k] : k;
        parent[k] = -1;
        anc[k] = -1;
        for (p = Ap[v]; p < Ap[v + 1]; p++) {
            r = iorder ? iorder[Ai[p]] : Ai[p];
            if (r >= k) continue;
            while (anc[r] >= 0 && anc[r] != k) {
                t = anc[r];
                anc[r] = k;
                r = t;
            }
            if (anc[r] < 0) {
                anc[r] = k;
                parent[r] = k;
            }
        }
    }
}

/* Depth-first from each root with an explicit stack; head/next are the child lists, built from
   the highest node down so that they ascend. */
AMPS_API void amps_postorder(amps_int n, const amps_int *parent, amps_int *post, amps_int *work) {
    amps_int *head = work, *next = work + n, *stack = work + 2 * n, k, top, pos = 0;
    for (k = 0; k < n; k++) head[k] = -1;
    for (k = n - 1; k >= 0; k--)
        if (parent[k] >= 0) {
            next[k] = head[parent[k]];
            head[parent[k]] = k;
        }
    for (k = 0; k < n; k++) {
        if (parent[k] >= 0) continue;
        top = 0;
        stack[top++] = k;
        while (top > 0) {
            amps_int j = stack[top - 1], c = head[j];
            if (c >= 0) {
                head[j] = next[c];
                stack[top++] = c;
            } else {
                top--;
                post[pos++] = j;
            }
        }
    }
}

/* Row subtree i = {j : L(i, j) != 0}, a subtree of the tree with root i. cc[j] = the sum over the
   subtree of j of delta, where each row subtree i puts +1 at each of its leaves, -1 at the least
   common ancestor of consecutive leaves (in postorder) and -1 at parent[i]. The leaves of row
   subtree i are the j with C(i, j) != 0 and first[j] > maxfirst[i] (first[j]: first postorder
   position in the subtree of j; maxfirst[i]: largest first[] of i's previous leaf), and i itself
   when i is a leaf of the tree. The ancestors form a disjoint-set forest over the finished nodes. */
AMPS_API void amps_colcounts(amps_int n, const amps_int *parent, const amps_int *post, const amps_int *Cp,
                             const amps_int *Ci, amps_int *cc, amps_int *work) {
    amps_int *first = work, *maxfirst = work + n, *prevleaf = work + 2 * n, *anc = work + 3 * n;
    amps_int j, k, q, r;
    for (j = 0; j < n; j++) {
        first[j] = -1;
        maxfirst[j] = -1;
        prevleaf[j] = -1;
        anc[j] = j;
    }
    for (k = 0; k < n; k++)
        for (r = post[k]; r >= 0 && first[r] < 0; r = parent[r]) first[r] = k;
    for (k = 0; k < n; k++) {
        j = post[k];
        cc[j] = (first[j] == k) ? 1 : 0;
    }
    for (k = 0; k < n; k++) {
        j = post[k];
        if (parent[j] >= 0) cc[parent[j]]--;
        for (q = Cp[j]; q < Cp[j + 1]; q++) {
            amps_int i = Ci[q], jprev;
            if (i <= j || first[j] <= maxfirst[i]) continue; /* j is not a leaf of row subtree i */
            maxfirst[i] = first[j];
            jprev = prevleaf[i];
            prevleaf[i] = j;
            cc[j]++;
            if (jprev >= 0) { /* least common ancestor of jprev and j: root of jprev's set */
                amps_int root = jprev, s, t;
                while (anc[root] != root) root = anc[root];
                for (s = jprev; s != root; s = t) {
                    t = anc[s];
                    anc[s] = root;
                }
                cc[root]--;
            }
        }
        if (parent[j] >= 0) anc[j] = parent[j];
    }
    for (k = 0; k < n; k++) {
        j = post[k];
        if (parent[j] >= 0) cc[parent[j]] += cc[j];
    }
}

/* ==== [amps:numeric impl] the LDL^T factor ==================================================== */

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
    size_t lcap;                  /* entries allocated for Li and Lx (>= Lp[n]) */
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
    amps__parbo bo;               /* loop timing of the factorization's and the solves' parallel loops */
    amps__pool *pool;             /* the factor's workers (AMPS_BACKEND_THREADS; NULL: none), started by
                                     the first amps_factorize that runs in parallel */
    int avx2;                     /* the update kernels in AVX2 + FMA (amps__cpu_avx2, set by amps_factorize) */
} amps__fpriv;

/* Relative pivot threshold: pivot d of column c is accepted iff d > AMPS_PIVOT_TOL * A(c,c) (original
   diagonal). Rounding leaves the zero pivots of a singular matrix (e.g. the rigid-body modes of an
   unsupported FE model) at about 1e-16..1e-9 * A(c,c) with either sign. */
#ifndef AMPS_PIVOT_TOL
#define AMPS_PIVOT_TOL 1e-12
#endif
/* Fixed-width dense kernels (here and in Steps 1-2 of the update): each is one body written with
   loops over compile-time widths, forced inline into one-line instantiations per width, where the
   compiler unrolls the loops completely and keeps the accumulators in registers. */
#if defined(__clang__) && defined(__has_feature)
#if __has_feature(address_sanitizer) /* clang 14's UBSan checks on unrolled kernels compile for minutes */
#define AMPS__CLANG_SAN 1
#endif
#endif
#if defined(__clang__)
#define AMPS__KERNEL static inline __attribute__((always_inline))
#ifdef AMPS__CLANG_SAN
#define AMPS__UNROLL
#else
#define AMPS__UNROLL _Pragma("clang loop unroll(full)")
#endif
#elif defined(__GNUC__)
#define AMPS__KERNEL static inline __attribute__((always_inline))
#define AMPS__UNROLL _Pragma("GCC unroll 16")
#else
#define AMPS__KERNEL static inline
#define AMPS__UNROLL
#endif
#ifdef AMPS__SSE2
/* Rows p, p+1 of amps__kern_body into target rows r0 < r1 (same operations per entry as its scalar loop). */
AMPS__KERNEL void amps__kern_pair(int KC, int TC, const double *const *sk, amps_int p, amps_int r0, amps_int r1,
                                  double (*w)[4], double *const *dt) {
    __m128d l[4];
    int k, t;
    AMPS__UNROLL
    for (k = 0; k < KC; k++) l[k] = _mm_loadu_pd(sk[k] + p);
    AMPS__UNROLL
    for (t = 0; t < TC; t++) {
        __m128d a = _mm_mul_pd(l[0], _mm_set1_pd(w[0][t])), v;
        AMPS__UNROLL
        for (k = 1; k < KC; k++) a = _mm_add_pd(a, _mm_mul_pd(l[k], _mm_set1_pd(w[k][t])));
        if (r1 == r0 + 1) {
            _mm_storeu_pd(dt[t] + r0, _mm_sub_pd(_mm_loadu_pd(dt[t] + r0), a));
        } else {
            v = _mm_sub_pd(_mm_loadh_pd(_mm_load_sd(dt[t] + r0), dt[t] + r1), a);
            _mm_storel_pd(dt[t] + r0, v);
            _mm_storeh_pd(dt[t] + r1, v);
        }
    }
}
#endif
/* Update kernel of a column block: for p in [0,m), with r = rel[Si[p]] (gather) or p (dense),
   d_t[r] -= sum_k s_k[p] * W[4k+t] for t < TC, the sum over k < KC in ascending order. */
AMPS__KERNEL void amps__kern_body(int KC, int TC, int gather, amps_int m, const amps_int *Si, const amps_int *rel,
                                  const double *const *s, const double *W, double *const *d) {
    const double *sk[4];
    double *dt[4], w[4][4];
    amps_int p;
    int k, t;
    AMPS__UNROLL
    for (k = 0; k < KC; k++) sk[k] = s[k];
    AMPS__UNROLL
    for (t = 0; t < TC; t++) dt[t] = d[t];
    AMPS__UNROLL
    for (k = 0; k < KC; k++) {
        AMPS__UNROLL
        for (t = 0; t < TC; t++) w[k][t] = W[4 * k + t];
    }
    p = 0;
#ifdef AMPS__SSE2
    /* four, then two rows at a time: the same products and sums per entry as the loop below */
    for (; p + 3 < m; p += 4) {
        amps_int r0 = gather ? rel[Si[p]] : p, r3 = gather ? rel[Si[p + 3]] : p + 3;
        if (r3 == r0 + 3) { /* rel is increasing along Si: the four target rows are contiguous */
            __m128d l[4], h[4];
            AMPS__UNROLL
            for (k = 0; k < KC; k++) {
                l[k] = _mm_loadu_pd(sk[k] + p);
                h[k] = _mm_loadu_pd(sk[k] + p + 2);
            }
            AMPS__UNROLL
            for (t = 0; t < TC; t++) {
                __m128d wk = _mm_set1_pd(w[0][t]), a = _mm_mul_pd(l[0], wk), c = _mm_mul_pd(h[0], wk);
                AMPS__UNROLL
                for (k = 1; k < KC; k++) {
                    wk = _mm_set1_pd(w[k][t]);
                    a = _mm_add_pd(a, _mm_mul_pd(l[k], wk));
                    c = _mm_add_pd(c, _mm_mul_pd(h[k], wk));
                }
                _mm_storeu_pd(dt[t] + r0, _mm_sub_pd(_mm_loadu_pd(dt[t] + r0), a));
                _mm_storeu_pd(dt[t] + r0 + 2, _mm_sub_pd(_mm_loadu_pd(dt[t] + r0 + 2), c));
            }
        } else {
            amps__kern_pair(KC, TC, sk, p, r0, rel[Si[p + 1]], w, dt);
            amps__kern_pair(KC, TC, sk, p + 2, rel[Si[p + 2]], r3, w, dt);
        }
    }
    if (p + 1 < m) {
        amps__kern_pair(KC, TC, sk, p, gather ? rel[Si[p]] : p, gather ? rel[Si[p + 1]] : p + 1, w, dt);
        p += 2;
    }
#endif
    for (; p < m; p++) {
        amps_int r = gather ? rel[Si[p]] : p;
        double l[4];
        AMPS__UNROLL
        for (k = 0; k < KC; k++) l[k] = sk[k][p];
        AMPS__UNROLL
        for (t = 0; t < TC; t++) {
            double a = l[0] * w[0][t];
            AMPS__UNROLL
            for (k = 1; k < KC; k++) a += l[k] * w[k][t];
            dt[t][r] -= a;
        }
    }
}
/* amps__kern{K}{T}: gather-update (rows of a finished group scattered into a target group);
   amps__dkern{K}{T}: dense (rows of a group against its own columns). */
#define AMPS__KERN(K, T)                                                                                      \
    static void amps__kern##K##T(amps_int m, const amps_int *Si, const amps_int *rel, const double *const *s, \
                                 const double *W, double *const *d) {                                         \
        amps__kern_body(K, T, 1, m, Si, rel, s, W, d);                                                        \
    }                                                                                                         \
    static void amps__dkern##K##T(amps_int m, const double *const *s, const double *W, double *const *d) {    \
        amps__kern_body(K, T, 0, m, NULL, NULL, s, W, d);                                                     \
    }
/* clang-format off */
AMPS__KERN(1, 1) AMPS__KERN(1, 2) AMPS__KERN(1, 3) AMPS__KERN(1, 4)
AMPS__KERN(2, 1) AMPS__KERN(2, 2) AMPS__KERN(2, 3) AMPS__KERN(2, 4)
AMPS__KERN(3, 1) AMPS__KERN(3, 2) AMPS__KERN(3, 3) AMPS__KERN(3, 4)
AMPS__KERN(4, 1) AMPS__KERN(4, 2) AMPS__KERN(4, 3) AMPS__KERN(4, 4)
#undef AMPS__KERN
typedef void (*amps__kern_fn)(amps_int, const amps_int *, const amps_int *, const double *const *, const double *,
                              double *const *);
static const amps__kern_fn amps__kern[4][4] = {
    {amps__kern11, amps__kern12, amps__kern13, amps__kern14},
    {amps__kern21, amps__kern22, amps__kern23, amps__kern24},
    {amps__kern31, amps__kern32, amps__kern33, amps__kern34},
    {amps__kern41, amps__kern42, amps__kern43, amps__kern44}
};
typedef void (*amps__dkern_fn)(amps_int, const double *const *, const double *, double *const *);
static const amps__dkern_fn amps__dkern[4][4] = {
    {amps__dkern11, amps__dkern12, amps__dkern13, amps__dkern14},
    {amps__dkern21, amps__dkern22, amps__dkern23, amps__dkern24},
    {amps__dkern31, amps__dkern32, amps__dkern33, amps__dkern34},
    {amps__dkern41, amps__dkern42, amps__dkern43, amps__dkern44}
};
/* clang-format on */
#ifdef AMPS__AVX2
/* Source columns per pass of the AVX2 update kernels (AMPS__SBLK is a multiple of it). */
#define AMPS__KW 32
/* d_t[r_i] -= a_t[i] for the four rows r_i = rel[Si[p+i]] (gather) or p+i (dense), t < TC. */
AMPS__KERNEL AMPS__TARGET_AVX2 void amps__wstore(int TC, int gather, const amps_int *Si, const amps_int *rel,
                                                 amps_int p, const __m256d *a, double *const *d) {
    int t, i;
    amps_int r[4];
    r[0] = gather ? rel[Si[p]] : p;
    r[3] = gather ? rel[Si[p + 3]] : p + 3;
    if (r[3] == r[0] + 3) { /* rel increases along Si: contiguous rows */
        AMPS__UNROLL
        for (t = 0; t < TC; t++) _mm256_storeu_pd(d[t] + r[0], _mm256_sub_pd(_mm256_loadu_pd(d[t] + r[0]), a[t]));
        return;
    }
    r[1] = rel[Si[p + 1]];
    r[2] = rel[Si[p + 2]];
    AMPS__UNROLL
    for (t = 0; t < TC; t++) {
        double v[4];
        _mm256_storeu_pd(v, a[t]);
        AMPS__UNROLL
        for (i = 0; i < 4; i++) d[t][r[i]] -= v[i];
    }
}
/* sum_{k < nk} s_k[p] W[4k+t] with the kernels' fused multiply-adds (ascending k, from 0). */
static AMPS__TARGET_AVX2 double amps__wsum(const double *const *s, amps_int p, const double *W, int t, amps_int nk) {
    __m128d a = _mm_setzero_pd();
    amps_int k;
    for (k = 0; k < nk; k++) a = _mm_fmadd_sd(_mm_load_sd(s[k] + p), _mm_load_sd(W + 4 * k + t), a);
    return _mm_cvtsd_f64(a);
}
/* AVX2 + FMA update kernel of a block of nk <= AMPS__KW source columns: for p in [0,m), with
   r = rel[Si[p]] (gather) or p (dense), d_t[r] -= sum_{k < nk} s_k[p] W[4k+t] for t < TC: the sum
   is formed first (ascending k, fused multiply-adds from 0: four rows to a vector, and
   amps__wsum on the last m mod 4 rows), then subtracted once: an entry gets the same bits
   whichever block holds it. */
AMPS__KERNEL AMPS__TARGET_AVX2 void amps__wkern_body(int TC, int gather, amps_int m, const amps_int *Si,
                                                     const amps_int *rel, int nk, const double *const *s,
                                                     const double *W, double *const *d) {
    amps_int p = 0;
    int k, t;
    for (; p + 7 < m; p += 8) {
        __m256d a[4], b[4];
        AMPS__UNROLL
        for (t = 0; t < TC; t++) a[t] = b[t] = _mm256_setzero_pd();
        for (k = 0; k < nk; k++) {
            __m256d l = _mm256_loadu_pd(s[k] + p), h = _mm256_loadu_pd(s[k] + p + 4);
            AMPS__UNROLL
            for (t = 0; t < TC; t++) {
                __m256d wv = _mm256_broadcast_sd(W + 4 * k + t);
                a[t] = _mm256_fmadd_pd(l, wv, a[t]);
                b[t] = _mm256_fmadd_pd(h, wv, b[t]);
            }
        }
        amps__wstore(TC, gather, Si, rel, p, a, d);
        amps__wstore(TC, gather, Si, rel, p + 4, b, d);
    }
    if (p + 3 < m) {
        __m256d a[4];
        AMPS__UNROLL
        for (t = 0; t < TC; t++) a[t] = _mm256_setzero_pd();
        for (k = 0; k < nk; k++) {
            __m256d l = _mm256_loadu_pd(s[k] + p);
            AMPS__UNROLL
            for (t = 0; t < TC; t++) a[t] = _mm256_fmadd_pd(l, _mm256_broadcast_sd(W + 4 * k + t), a[t]);
        }
        amps__wstore(TC, gather, Si, rel, p, a, d);
        p += 4;
    }
    for (; p < m; p++) {
        amps_int r0 = gather ? rel[Si[p]] : p;
        AMPS__UNROLL
        for (t = 0; t < TC; t++) d[t][r0] -= amps__wsum(s, p, W, t, nk);
    }
}
#define AMPS__WKERN(T)                                                                                         \
    static AMPS__TARGET_AVX2 void amps__wkern##T(amps_int m, const amps_int *Si, const amps_int *rel, int nk, \
                                                 const double *const *s, const double *W, double *const *d) { \
        if (Si) amps__wkern_body(T, 1, m, Si, rel, nk, s, W, d);                                               \
        else amps__wkern_body(T, 0, m, NULL, NULL, nk, s, W, d);                                               \
    }
AMPS__WKERN(1) AMPS__WKERN(2) AMPS__WKERN(3) AMPS__WKERN(4)
#undef AMPS__WKERN
/* amps__wkern[TC-1]; Si NULL: the dense form (r = p). */
typedef void (*amps__wkern_fn)(amps_int, const amps_int *, const amps_int *, int, const double *const *,
                               const double *, double *const *);
static const amps__wkern_fn amps__wkern[4] = {amps__wkern1, amps__wkern2, amps__wkern3, amps__wkern4};
#else
#define AMPS__KW 4
#endif

/* Source columns per pass of the factorization's update kernels: AMPS__KW with AVX2, else 4. */
#ifdef AMPS__AVX2
#define AMPS__KWIDTH(P) ((P)->avx2 ? AMPS__KW : 4)
#else
#define AMPS__KWIDTH(P) 4
#endif

/* sum_{k < nk} s_k[p] W[4k+t] as the update kernels of P form it (amps__wsum with AVX2, else
   plain products and sums in ascending k), so that an entry's bits do not depend on which of
   them computes it. */
static double amps__ksum(const amps__fpriv *P, const double *const *s, amps_int p, const double *W, int t,
                         amps_int nk) {
    double sm = 0;
    amps_int k;
#ifdef AMPS__AVX2
    if (P->avx2) return amps__wsum(s, p, W, t, nk);
#endif
    (void)P;
    for (k = 0; k < nk; k++) sm += s[k][p] * W[4 * k + t];
    return sm;
}

/* 1 when this CPU runs the AVX2 + FMA kernels (AMPS_NO_AVX2 or another target: 0). */
static int amps__cpu_avx2(void) {
#ifdef AMPS__AVX2
    __builtin_cpu_init();
    return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
#else
    return 0;
#endif
}

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
    amps__free(ctx, P->gs);
    amps__free(ctx, P->cgrp);
    amps__free(ctx, P->Sp);
    amps__free(ctx, P->Ssrc);
    amps__free(ctx, P->Sdst);
    amps__free(ctx, P->dsrc);
    amps__free(ctx, P->head);
    amps__free(ctx, P->next);
    amps__free(ctx, P->gpos);
    amps__free(ctx, P->gsub);
    amps__free(ctx, P->subp);
    amps__free(ctx, P->subg);
    amps__free(ctx, P->topg);
    amps__free(ctx, P->iwork);
    amps__free(ctx, P->fail);
    amps__pool_free(ctx, P->pool);
    amps__free(ctx, P);
}

AMPS_API void amps_factor_free(amps_ctx *ctx, amps_factor *F) {
    if (!F) return;
    amps__fpriv_free(ctx, AMPS__CAST(amps__fpriv *, F->priv));
    amps__free(ctx, F->perm);
    amps__free(ctx, F->iperm);
    amps__free(ctx, F->parent);
    amps__free(ctx, F->Lp);
    amps__free(ctx, F->Li);
    amps__free(ctx, F->Lx);
    amps__free(ctx, F->D);
    amps__free(ctx, F);
}

AMPS_API double amps_factor_nnz(const amps_factor *F) { return F && F->Lp ? (double)F->Lp[F->n] + (double)F->n : 0.0; }

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

/* Participants of a kernel: the back end's slots (amps__par_slots); at most cap. */
static int amps__nthreads(const amps_ctx *ctx, amps_int cap) {
    int t = amps__par_slots(ctx);
    if (t > cap) t = (int)cap;
    return t < 1 ? 1 : t;
}

#ifndef AMPS__SBLK
#define AMPS__SBLK 64 /* superblock width (a multiple of AMPS__KW) in the parallel factorization of a group */
#endif
#ifndef AMPS__PARGROUP
#define AMPS__PARGROUP 2e6 /* top groups with (entries of their columns) x (width) >= this use all threads */
#endif
#ifndef AMPS__PARMIN
#define AMPS__PARMIN \
    1e9 /* factorizations with a smaller flop estimate (sum of squared column counts) run on one thread */
#endif
#ifndef AMPS__NSUB
#define AMPS__NSUB 8 /* split the tree until no subtree has more than 1/AMPS__NSUB of the subtree work */
#endif

/* The storage of a retired factor's L (Li, Lx; capacities in entries), kept for the next
   re-factorization: fresh pages cost a page fault each on first touch (about a third of a
   millisecond per megabyte on a virtual machine), reused ones do not. */
typedef struct amps__lspare {
    void *li, *lx; /* amps_int[nli], double[nlx] */
    size_t nli, nlx;
} amps__lspare;

static void amps__spare_free(amps_ctx *ctx, amps__lspare *sp) {
    amps__free(ctx, sp->li);
    amps__free(ctx, sp->lx);
    memset(sp, 0, sizeof(*sp));
}

/* Storage for need entries of size bytes: *sp (cap entries; taken: *sp = NULL), grown to need
   plus a quarter when it is smaller (L grows a little from one re-factorization to the next; the
   pages it had stay), or new (with that quarter when sp is given). *got receives the entries. */
static void *amps__spare_take(amps_ctx *ctx, void **sp, size_t cap, size_t need, size_t size, size_t *got) {
    void *p = sp ? *sp : NULL;
    *got = sp ? need + need / 4 : need;
    if (p && cap < need && amps__realloc(ctx, &p, *got, size) != AMPS_OK) return NULL; /* *sp kept */
    if (!p) return amps__malloc(ctx, *got, size);
    if (cap >= need) *got = cap;
    *sp = NULL;
    return p;
}

/* The storage of F's L back to sp (F keeps none). */
static void amps__spare_put(amps_ctx *ctx, amps__lspare *sp, amps_factor *F) {
    amps__spare_free(ctx, sp);
    sp->li = F->Li;
    sp->lx = F->Lx;
    sp->nli = sp->nlx = AMPS__CAST(amps__fpriv *, F->priv)->lcap;
    F->Li = NULL;
    F->Lx = NULL;
}

/* Temporaries of amps_analyze: C = P A P^T as its upper pattern (Up, Ui: column k holds the rows
   <= k) and its strictly lower columns (P->Sp, Cr); column counts cc (n + 1), the tree of the
   column groups gpar (ng), workspace tw (5n + 1); sp: storage for L to reuse. */
typedef struct amps__ana {
    amps_int *Up, *Ui, *Cr, *cc, *gpar, *tw;
    amps__lspare *sp; /* storage for L to reuse (NULL: none) */
} amps__ana;

static void amps__ana_free(amps_ctx *ctx, amps__ana *T) {
    amps__free(ctx, T->Up);
    amps__free(ctx, T->Ui);
    amps__free(ctx, T->Cr);
    amps__free(ctx, T->cc);
    amps__free(ctx, T->gpar);
    amps__free(ctx, T->tw);
}

static amps_status amps__analyze_oom(amps_ctx *ctx, amps_int n, amps_int nnzA) {
    return amps__err(ctx, AMPS_ERR_OOM, "amps_analyze: out of memory (n %lld, nnz(A) %lld)", (long long)n,
                     (long long)nnzA);
}

/* F->priv, F->n and the arrays of size n of F, its private part and T. */
static amps_status amps__analyze_alloc(amps_ctx *ctx, const amps_csc *A, amps_stype stype, amps_factor *F,
                                       amps__ana *T) {
    amps_int n = A->ncol;
    amps__fpriv *P = AMPS__CAST(amps__fpriv *, amps__calloc(ctx, 1, sizeof(amps__fpriv)));
    F->priv = P;
    F->n = n;
    if (!P) return amps__analyze_oom(ctx, n, A->p[n]);
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
    T->Up = AMPS__CAST(amps_int *, amps__calloc(ctx, (size_t)n + 1, sizeof(amps_int)));
    T->tw = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)n * 5 + 1, sizeof(amps_int)));
    T->cc = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)n + 1, sizeof(amps_int)));
    if (!F->perm || !F->iperm || !F->parent || !F->Lp || !F->D || !P->cgrp || !P->Sp || !P->dsrc || !T->Up || !T->tw ||
        !T->cc)
        return amps__analyze_oom(ctx, n, A->p[n]);
    return AMPS_OK;
}

/* F->perm by amps_order, checked to be a permutation, and F->iperm. */
static amps_status amps__analyze_order(amps_ctx *ctx, const amps_csc *A, amps_stype stype, const amps_order_opts *opts,
                                       amps_factor *F) {
    amps_int k, n = F->n;
    amps_status st = AMPS_OK;
    if (opts && opts->method == AMPS_ORDER_GIVEN && opts->perm) /* checked below; no graph needed */
        memcpy(F->perm, opts->perm, sizeof(amps_int) * (size_t)n);
    else st = amps_order(ctx, A, stype, opts, F->perm);
    if (st != AMPS_OK) return st;
    for (k = 0; k < n; k++) F->iperm[k] = -1;
    for (k = 0; k < n; k++) {
        amps_int i = F->perm[k];
        if (i < 0 || i >= n || F->iperm[i] >= 0)
            return amps__err(ctx, AMPS_ERR_ARG, "amps_analyze: ordering is not a permutation (perm[%lld] = %lld)",
                             (long long)k, (long long)i);
        F->iperm[i] = k;
    }
    return AMPS_OK;
}

/* C = P A P^T: upper pattern (T->Up, T->Ui) and strictly lower columns (P->Sp, T->Cr) with their
   sources in A (P->Ssrc; P->dsrc for the diagonal); allocates P->Sdst for the scatter map. */
static amps_status amps__analyze_permute(amps_ctx *ctx, const amps_csc *A, amps_stype stype, amps_factor *F,
                                         amps__ana *T) {
    amps__fpriv *P = AMPS__CAST(amps__fpriv *, F->priv);
    amps_int n = F->n, *Up = T->Up, j, p, q, k, nnzC = 0;
    for (k = 0; k < n; k++) P->dsrc[k] = -1;
    for (j = 0; j < n; j++)
        for (p = A->p[j]; p < A->p[j + 1]; p++) {
            amps_int i = A->i[p], a = F->iperm[i], b = F->iperm[j];
            if (stype == AMPS_FULL && i > j) continue;
            if (a > b) {
                amps_int t = a;
                a = b;
                b = t;
            }
            Up[b]++;
            nnzC++;
            if (a == b) P->dsrc[a] = p;
            else P->Sp[a]++;
        }
    for (k = 0, p = 0, q = 0; k < n; k++) {
        amps_int t = Up[k];
        Up[k] = p;
        p += t;
        t = P->Sp[k];
        P->Sp[k] = q;
        q += t;
    }
    Up[n] = p;
    P->Sp[n] = q;
    T->Ui = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)nnzC, sizeof(amps_int)));
    T->Cr = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)q, sizeof(amps_int)));
    P->Ssrc = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)q, sizeof(amps_int)));
    P->Sdst = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)q, sizeof(amps_int)));
    if (!T->Ui || !T->Cr || !P->Ssrc || !P->Sdst) return amps__analyze_oom(ctx, n, A->p[n]);
    {
        amps_int *wu = T->tw, *wl = T->tw + n;
        for (k = 0; k < n; k++) {
            wu[k] = Up[k];
            wl[k] = P->Sp[k];
        }
        for (j = 0; j < n; j++)
            for (p = A->p[j]; p < A->p[j + 1]; p++) {
                amps_int i = A->i[p], a = F->iperm[i], b = F->iperm[j];
                if (stype == AMPS_FULL && i > j) continue;
                if (a > b) {
                    amps_int t = a;
                    a = b;
                    b = t;
                }
                T->Ui[wu[b]++] = a;
                if (a != b) {
                    q = wl[a]++;
                    T->Cr[q] = b;
                    P->Ssrc[q] = p;
                }
            }
    }
    return AMPS_OK;
}

/* Elimination tree F->parent, column counts T->cc (with diagonal) and F->Lp of C. Fails with
   AMPS_ERR_OOM when nnz(L) exceeds amps_int. */
static amps_status amps__analyze_counts(amps_ctx *ctx, amps_factor *F, amps__ana *T) {
    const amps__fpriv *P = AMPS__CAST(const amps__fpriv *, F->priv);
    amps_int n = F->n, k, *cc = T->cc;
    double lnz = 0;
    amps_etree(n, T->Up, T->Ui, NULL, NULL, F->parent, T->tw);
    amps_postorder(n, F->parent, T->tw, T->tw + n);
    amps_colcounts(n, F->parent, T->tw, P->Sp, T->Cr, cc, T->tw + n);
    F->Lp[0] = 0;
    for (k = 0; k < n; k++) {
        lnz += (double)cc[k] - 1.0;
        if (lnz > (double)AMPS__IMAX)
            return amps__err(ctx, AMPS_ERR_OOM,
                             "amps_analyze: nnz(L) exceeds the index type at column %lld; use a wider AMPS_INT",
                             (long long)k);
        F->Lp[k + 1] = F->Lp[k] + cc[k] - 1;
    }
    return AMPS_OK;
}

/* Column groups: c joins the group of c-1 when parent(c-1) = c and the patterns nest. Writes
   P->ng, P->gs, P->cgrp and the group tree T->gpar; allocates the per-group arrays and L. */
static amps_status amps__analyze_groups(amps_ctx *ctx, amps_factor *F, amps__ana *T) {
    amps__fpriv *P = AMPS__CAST(amps__fpriv *, F->priv);
    amps_int n = F->n, c, g, ng = 0, *tw = T->tw, *cc = T->cc;
    size_t gi, gx;
    for (c = 0; c < n; c++) {
        if (c == 0 || !(F->parent[c - 1] == c && cc[c - 1] == cc[c] + 1)) tw[ng++] = c;
        P->cgrp[c] = ng - 1;
    }
    tw[ng] = n;
    P->ng = ng;
    P->gs = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)ng + 1, sizeof(amps_int)));
    T->gpar = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)ng, sizeof(amps_int)));
    P->head = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)ng, sizeof(amps_int)));
    P->next = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)ng, sizeof(amps_int)));
    P->gpos = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)ng, sizeof(amps_int)));
    P->gsub = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)ng, sizeof(amps_int)));
    F->Li = AMPS__CAST(amps_int *, amps__spare_take(ctx, T->sp ? &T->sp->li : NULL, T->sp ? T->sp->nli : 0,
                                                    (size_t)F->Lp[n], sizeof(amps_int), &gi));
    F->Lx = AMPS__CAST(double *, amps__spare_take(ctx, T->sp ? &T->sp->lx : NULL, T->sp ? T->sp->nlx : 0,
                                                  (size_t)F->Lp[n], sizeof(double), &gx));
    P->lcap = gi < gx ? gi : gx;
    if (!P->gs || !T->gpar || !P->head || !P->next || !P->gpos || !P->gsub || !F->Li || !F->Lx)
        return amps__analyze_oom(ctx, n, P->nnzA);
    memcpy(P->gs, tw, sizeof(amps_int) * ((size_t)ng + 1));
    for (g = 0; g < ng; g++) {
        amps_int pe = F->parent[P->gs[g + 1] - 1];
        T->gpar[g] = pe < 0 ? -1 : P->cgrp[pe];
    }
    return AMPS_OK;
}

/* Pattern Li: row i joins S_g for every group g strictly below group(i) on the paths from the
   columns j < i of C(:, i); rows arrive in ascending order. Column c < ke of a group then stores
   rows c+1..ke and S_g. tw: fill count, mark. */
static void amps__analyze_lpattern(amps_factor *F, amps__ana *T) {
    const amps__fpriv *P = AMPS__CAST(const amps__fpriv *, F->priv);
    amps_int n = F->n, ng = P->ng, *cnt = T->tw, *mark = T->tw + n, *Lp = F->Lp, *Li = F->Li, k, p, g, c;
    const amps_int *gs = P->gs, *cgrp = P->cgrp, *gpar = T->gpar;
    for (g = 0; g < ng; g++) {
        cnt[g] = 0;
        mark[g] = -1;
    }
    for (k = 0; k < n; k++) {
        amps_int gi = cgrp[k];
        for (p = T->Up[k]; p < T->Up[k + 1]; p++) {
            amps_int jj = T->Ui[p];
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
}

/* Scatter map of A into L: Lx[Sdst[q]] receives C(Cr[q], c), q in Sp[c].. (tw = position of a row
   in S_g). */
static void amps__analyze_scatter(amps_factor *F, amps__ana *T) {
    amps__fpriv *P = AMPS__CAST(amps__fpriv *, F->priv);
    const amps_int *Lp = F->Lp, *gs = P->gs;
    amps_int *tw = T->tw, g, p, c, q;
    for (g = 0; g < P->ng; g++) {
        amps_int ks = gs[g], ke = gs[g + 1] - 1, ns = Lp[ke + 1] - Lp[ke];
        const amps_int *S = F->Li + Lp[ke];
        for (p = 0; p < ns; p++) tw[S[p]] = p;
        for (c = ks; c <= ke; c++)
            for (q = P->Sp[c]; q < P->Sp[c + 1]; q++) {
                amps_int r = T->Cr[q];
                P->Sdst[q] = r <= ke ? Lp[c] + r - c - 1 : Lp[c] + (ke - c) + tw[r];
            }
    }
}

/* F->height: nodes on the longest leaf-to-root path (depth, tw). */
static void amps__analyze_height(amps_factor *F, amps_int *tw) {
    amps_int k;
    F->height = 0;
    for (k = F->n - 1; k >= 0; k--) {
        tw[k] = F->parent[k] < 0 ? 1 : tw[F->parent[k]] + 1;
        if (tw[k] > F->height) F->height = tw[k];
    }
}

/* Subtree roots cand[0..ncand-1] for the threads: starting from the roots of the group tree,
   repeatedly moves the heaviest candidate (subtree work sw, group work gw = sum of squared column
   counts) to the top part (gsub = -1) and its children to the candidates, until no candidate
   holds more than 1/AMPS__NSUB of the candidates' work. The candidates end heaviest first; *ntop
   counts the top groups, P->gsub is -2 elsewhere, P->work = total work. chead, cnext: ng. */
static amps_int amps__analyze_split(amps_factor *F, const amps__ana *T, double *gw, double *sw, amps_int *cand,
                                    amps_int *chead, amps_int *cnext, amps_int *ntop) {
    amps__fpriv *P = AMPS__CAST(amps__fpriv *, F->priv);
    amps_int ng = P->ng, ncand = 0, best, i, g, c, k;
    const amps_int *gpar = T->gpar, *cc = T->cc;
    double subtot = 0, total = 0;
    *ntop = 0;
    for (g = 0; g < ng; g++) {
        double s = 0;
        for (c = P->gs[g]; c < P->gs[g + 1]; c++) s += (double)cc[c] * (double)cc[c];
        gw[g] = s;
        sw[g] = 0;
    }
    for (g = 0; g < ng; g++) chead[g] = -1;
    for (g = ng - 1; g >= 0; g--)
        if (gpar[g] >= 0) {
            cnext[g] = chead[gpar[g]];
            chead[gpar[g]] = g;
        }
    for (g = 0; g < ng; g++) {
        sw[g] += gw[g];
        if (gpar[g] >= 0) sw[gpar[g]] += sw[g];
        else {
            cand[ncand++] = g;
            subtot += sw[g];
        }
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
        (*ntop)++;
        subtot -= gw[g];
        cand[best] = cand[--ncand];
        for (k = chead[g]; k >= 0; k = cnext[k]) cand[ncand++] = k;
        if (ncand > 16 * AMPS__NSUB) break;
    }
    P->work = total;
    for (i = 1; i < ncand; i++) {
        amps_int t = cand[i], m2 = i;
        while (m2 > 0 && sw[cand[m2 - 1]] < sw[t]) {
            cand[m2] = cand[m2 - 1];
            m2--;
        }
        cand[m2] = t;
    }
    return ncand;
}

/* Subtree decomposition: the candidates of amps__analyze_split become subtrees 0..nsub-1 (P->gsub:
   subtree of each group, -1 for the top part), listed ascending in P->subp/subg and P->topg. */
static amps_status amps__analyze_subtrees(amps_ctx *ctx, amps_factor *F, amps__ana *T) {
    amps__fpriv *P = AMPS__CAST(amps__fpriv *, F->priv);
    amps_int ng = P->ng, n = F->n, nsub, ntop, i, g, k, *tw = T->tw;
    double *gw = AMPS__CAST(double *, amps__malloc(ctx, (size_t)ng * 2, sizeof(double)));
    amps_int *cand = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)ng, sizeof(amps_int)));
    if (!gw || !cand) {
        amps__free(ctx, gw);
        amps__free(ctx, cand);
        return amps__analyze_oom(ctx, n, P->nnzA);
    }
    nsub = amps__analyze_split(F, T, gw, gw + ng, cand, tw + 2 * n, tw + 3 * n, &ntop);
    for (i = 0; i < nsub; i++) P->gsub[cand[i]] = i;
    amps__free(ctx, gw);
    amps__free(ctx, cand);
    for (g = ng - 1; g >= 0; g--)
        if (P->gsub[g] == -2) P->gsub[g] = P->gsub[T->gpar[g]];
    P->nsub = nsub;
    P->ntop = ntop;
    P->subp = AMPS__CAST(amps_int *, amps__calloc(ctx, (size_t)nsub + 1, sizeof(amps_int)));
    P->subg = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)(ng - ntop), sizeof(amps_int)));
    P->topg = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)ntop, sizeof(amps_int)));
    P->fail = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)nsub + 1, sizeof(amps_int)));
    if (!P->subp || !P->subg || !P->topg || !P->fail) return amps__analyze_oom(ctx, n, P->nnzA);
    for (g = 0; g < ng; g++)
        if (P->gsub[g] >= 0) P->subp[P->gsub[g] + 1]++;
    for (i = 0; i < nsub; i++) P->subp[i + 1] += P->subp[i];
    for (i = 0; i < nsub; i++) tw[i] = P->subp[i];
    for (g = 0, k = 0; g < ng; g++) {
        if (P->gsub[g] >= 0) P->subg[tw[P->gsub[g]]++] = g;
        else P->topg[k++] = g;
    }
    return AMPS_OK;
}

/* Workspace of amps_factorize for the back end's participants, the pattern hash and the thresholds. */
static amps_status amps__analyze_workspace(amps_ctx *ctx, const amps_csc *A, amps_factor *F) {
    amps__fpriv *P = AMPS__CAST(amps__fpriv *, F->priv);
    amps_int nthr = amps__nthreads(ctx, 1024);
    P->nthr = nthr;
    P->iwork = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)nthr * 2, (size_t)F->n * sizeof(amps_int)));
    if (!P->iwork) return amps__analyze_oom(ctx, F->n, P->nnzA);
    P->hash = amps__pattern_hash(A);
    P->pargroup = AMPS__PARGROUP;
    P->parmin = AMPS__PARMIN;
    return AMPS_OK;
}

/* amps_analyze with L's storage taken from sp where it is large enough (sp may be NULL). */
static amps_factor *amps__analyze_reuse(amps_ctx *ctx, const amps_csc *A, amps_stype stype, const amps_order_opts *opts,
                                        amps__lspare *sp) {
    amps_factor *F;
    amps__ana T;
    amps_status st;
    if (amps_csc_check(ctx, A, stype) != AMPS_OK) return NULL;
    F = AMPS__CAST(amps_factor *, amps__calloc(ctx, 1, sizeof(amps_factor)));
    if (!F) return NULL;
    F->failed = -1;
    memset(&T, 0, sizeof(T));
    T.sp = sp;
    st = amps__analyze_alloc(ctx, A, stype, F, &T);
    if (st == AMPS_OK) st = amps__analyze_order(ctx, A, stype, opts, F); /* perm, iperm */
    if (st == AMPS_OK) st = amps__analyze_permute(ctx, A, stype, F, &T); /* pattern of P A P^T */
    if (st == AMPS_OK) st = amps__analyze_counts(ctx, F, &T);            /* etree, column counts, Lp */
    if (st == AMPS_OK) st = amps__analyze_groups(ctx, F, &T);            /* column groups, L allocated */
    if (st == AMPS_OK) {
        amps__analyze_lpattern(F, &T); /* Li */
        amps__analyze_scatter(F, &T);  /* map of A into L */
        amps__analyze_height(F, T.tw);
        st = amps__analyze_subtrees(ctx, F, &T); /* parallel split */
    }
    if (st == AMPS_OK) st = amps__analyze_workspace(ctx, A, F);
    amps__ana_free(ctx, &T);
    if (st == AMPS_OK) return F;
    amps_factor_free(ctx, F);
    return NULL;
}

AMPS_API amps_factor *amps_analyze(amps_ctx *ctx, const amps_csc *A, amps_stype stype, const amps_order_opts *opts) {
    return amps__analyze_reuse(ctx, A, stype, opts, NULL);
}

/* 1 if A (stype part) has the pattern F was analyzed with (the test of amps_factorize). */
static int amps__factor_same_pattern(const amps_factor *F, const amps_csc *A, amps_stype stype) {
    const amps__fpriv *P = F ? AMPS__CAST(const amps__fpriv *, F->priv) : NULL;
    return P && A && A->ncol == F->n && P->stype == stype && A->p[F->n] == P->nnzA && amps__pattern_hash(A) == P->hash;
}

/* Copies n entries of src into a new array (NULL on failure; n = 0 gives a 1-entry array). */
static void *amps__dup(amps_ctx *ctx, const void *src, size_t n, size_t size) {
    void *d = amps__malloc(ctx, n ? n : 1, size);
    if (d && n) memcpy(d, src, n * size);
    return d;
}

/* A factor with F's analysis (order, pattern of L, groups, subtrees, the scatter map of A) and
   its own values and workspace for ctx's back end, for amps_factorize of a matrix with the
   pattern F was analyzed with. Reads only the parts of F no factorization or solve writes. L's
   storage comes from sp where it is large enough (sp may be NULL). */
static amps_factor *amps__factor_clone_symbolic(amps_ctx *ctx, const amps_factor *F, amps__lspare *sp) {
    const amps__fpriv *P = AMPS__CAST(const amps__fpriv *, F->priv);
    amps_factor *G = AMPS__CAST(amps_factor *, amps__calloc(ctx, 1, sizeof(amps_factor)));
    amps__fpriv *Q = AMPS__CAST(amps__fpriv *, amps__calloc(ctx, 1, sizeof(amps__fpriv)));
    size_t n = (size_t)F->n, nl = (size_t)F->Lp[F->n], ng = (size_t)P->ng, ns = (size_t)P->nsub, gi = 0, gx = 0;
    int nthr = amps__nthreads(ctx, 1024);
    if (!G || !Q) {
        amps__free(ctx, G);
        amps__free(ctx, Q);
        amps__err(ctx, AMPS_ERR_OOM, "amps_analyze: out of memory (a copy of the analysis)");
        return NULL;
    }
    G->n = F->n;
    G->height = F->height;
    G->failed = -1;
    G->priv = Q;
    G->perm = AMPS__CAST(amps_int *, amps__dup(ctx, F->perm, n, sizeof(amps_int)));
    G->iperm = AMPS__CAST(amps_int *, amps__dup(ctx, F->iperm, n, sizeof(amps_int)));
    G->parent = AMPS__CAST(amps_int *, amps__dup(ctx, F->parent, n, sizeof(amps_int)));
    G->Lp = AMPS__CAST(amps_int *, amps__dup(ctx, F->Lp, n + 1, sizeof(amps_int)));
    G->Li = AMPS__CAST(amps_int *, amps__spare_take(ctx, sp ? &sp->li : NULL, sp ? sp->nli : 0, nl ? nl : 1,
                                                    sizeof(amps_int), &gi));
    G->Lx = AMPS__CAST(double *,
                       amps__spare_take(ctx, sp ? &sp->lx : NULL, sp ? sp->nlx : 0, nl ? nl : 1, sizeof(double), &gx));
    if (G->Li && nl) memcpy(G->Li, F->Li, nl * sizeof(amps_int));
    G->D = AMPS__CAST(double *, amps__malloc(ctx, n ? n : 1, sizeof(double)));
    /* the sizes and parameters (the fields before touch; touch and bo are the solves') */
    memcpy(Q, P, (size_t)((const char *)&P->touch - (const char *)P));
    Q->nthr = nthr;
    Q->lcap = gi < gx ? gi : gx;
    Q->gs = AMPS__CAST(amps_int *, amps__dup(ctx, P->gs, ng + 1, sizeof(amps_int)));
    Q->cgrp = AMPS__CAST(amps_int *, amps__dup(ctx, P->cgrp, n, sizeof(amps_int)));
    Q->Sp = AMPS__CAST(amps_int *, amps__dup(ctx, P->Sp, n + 1, sizeof(amps_int)));
    Q->Ssrc = AMPS__CAST(amps_int *, amps__dup(ctx, P->Ssrc, (size_t)P->Sp[n], sizeof(amps_int)));
    Q->Sdst = AMPS__CAST(amps_int *, amps__dup(ctx, P->Sdst, (size_t)P->Sp[n], sizeof(amps_int)));
    Q->dsrc = AMPS__CAST(amps_int *, amps__dup(ctx, P->dsrc, n, sizeof(amps_int)));
    Q->head = AMPS__CAST(amps_int *, amps__malloc(ctx, ng ? ng : 1, sizeof(amps_int)));
    Q->next = AMPS__CAST(amps_int *, amps__malloc(ctx, ng ? ng : 1, sizeof(amps_int)));
    Q->gpos = AMPS__CAST(amps_int *, amps__malloc(ctx, ng ? ng : 1, sizeof(amps_int)));
    Q->gsub = AMPS__CAST(amps_int *, amps__dup(ctx, P->gsub, ng, sizeof(amps_int)));
    Q->subp = AMPS__CAST(amps_int *, amps__dup(ctx, P->subp, ns + 1, sizeof(amps_int)));
    Q->subg = AMPS__CAST(amps_int *, amps__dup(ctx, P->subg, ng - (size_t)P->ntop, sizeof(amps_int)));
    Q->topg = AMPS__CAST(amps_int *, amps__dup(ctx, P->topg, (size_t)P->ntop, sizeof(amps_int)));
    Q->fail = AMPS__CAST(amps_int *, amps__malloc(ctx, ns + 1, sizeof(amps_int)));
    Q->iwork = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)nthr * 2, (n ? n : 1) * sizeof(amps_int)));
    if (!G->perm || !G->iperm || !G->parent || !G->Lp || !G->Li || !G->Lx || !G->D || !Q->gs || !Q->cgrp || !Q->Sp ||
        !Q->Ssrc || !Q->Sdst || !Q->dsrc || !Q->head || !Q->next || !Q->gpos || !Q->gsub || !Q->subp || !Q->subg ||
        !Q->topg || !Q->fail || !Q->iwork) {
        amps_factor_free(ctx, G);
        amps__err(ctx, AMPS_ERR_OOM, "amps_analyze: out of memory (a copy of the analysis)");
        return NULL;
    }
    return G;
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
    amps_int q0, q1, k0, i, k, pp, kw = AMPS__KWIDTH(P);
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
        for (k0 = ks; k0 <= ke; k0 += kw) {
            amps_int kc = ke + 1 - k0 < kw ? ke + 1 - k0 : kw;
            const double *src[AMPS__KW], *srq[AMPS__KW];
            double W[4 * AMPS__KW];
            for (k = 0; k < kc; k++) {
                src[k] = Lx + Lp[k0 + k] + (ke - k0 - k);
                for (i = 0; i < tc; i++) W[4 * k + i] = D[k0 + k] * src[k][q0 + i];
                srq[k] = src[k] + q1;
            }
            for (i = 0; i < tc; i++) { /* the targets' own rows, with the kernel's arithmetic */
                D[SK[q0 + i]] -= amps__ksum(P, src, q0 + i, W, (int)i, kc);
                for (pp = q0 + i + 1; pp < q1; pp++) dst[i][rel[SK[pp]]] -= amps__ksum(P, src, pp, W, (int)i, kc);
            }
#ifdef AMPS__AVX2
            if (P->avx2) {
                amps__wkern[tc - 1](nK - q1, SK + q1, rel, (int)kc, srq, W, dst);
                continue;
            }
#endif
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
   multiple of AMPS__KW), for the rows [r0, r1) of the rows below the panel (the group's rows after the panel,
   then its S), which are stored consecutively in every column of the group. */
static void amps__panel_rect(amps_factor *F, const amps__fpriv *P, amps_int klo, amps_int khi, amps_int c0,
                             amps_int tc, amps_int r0, amps_int r1) {
    const amps_int *Lp = F->Lp;
    double *Lx = F->Lx, *D = F->D;
    amps_int c1 = c0 + tc, k0, k, i, kw = AMPS__KWIDTH(P);
    double *dst[4];
    (void)P;
    if (r1 <= r0) return;
    for (i = 0; i < tc; i++) dst[i] = Lx + Lp[c0 + i] + (c1 - c0 - i - 1) + r0;
    for (k0 = klo; k0 < khi; k0 += kw) {
        amps_int kc = khi - k0 < kw ? khi - k0 : kw;
        const double *srq[AMPS__KW];
        double W[4 * AMPS__KW];
        for (k = 0; k < kc; k++) {
            const double *src = Lx + Lp[k0 + k] + (c0 - k0 - k - 1); /* row c0 of column k0+k */
            for (i = 0; i < tc; i++) W[4 * k + i] = D[k0 + k] * src[i];
            srq[k] = src + tc + r0;
        }
#ifdef AMPS__AVX2
        if (P->avx2) {
            amps__wkern[tc - 1](r1 - r0, NULL, NULL, (int)kc, srq, W, dst);
            continue;
        }
#endif
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
            o = 0;
#ifdef AMPS__SSE2
            for (; o + 1 < len2; o += 2)
                _mm_storeu_pd(L2 + o,
                              _mm_sub_pd(_mm_loadu_pd(L2 + o), _mm_mul_pd(_mm_loadu_pd(Ls + o), _mm_set1_pd(lv))));
#endif
            for (; o < len2; o++) L2[o] -= Ls[o] * lv;
        }
        o = 0;
#ifdef AMPS__SSE2
        for (; o + 1 < len; o += 2) _mm_storeu_pd(Lc + o, _mm_div_pd(_mm_loadu_pd(Lc + o), _mm_set1_pd(d)));
#endif
        for (; o < len; o++) Lc[o] /= d;
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
        amps__panel_rect(F, P, s, c0, c0, tc, 0, (e - c0 - tc + 1) + nJ);
        bad = amps__panel_factor(F, P, Ax, e, s, c0, c0, tc, rel, 1);
        if (bad >= 0) return bad;
    }
    P->gpos[J] = 0;
    amps__link(F, P, J, sub);
    return -1;
}

/* A parallel loop of amps__fgroup_par. */
typedef struct amps__fgjob {
    amps_factor *F;
    amps__fpriv *P;
    const double *Ax;
    const amps_int *rel, *kl, *kb;
    amps_int s, e, nJ, cnt, cb, ce;
} amps__fgjob;

/* Owner classes of the targets in amps__fgroup_par's updates (the chunks of that loop). */
#ifndef AMPS__FOWN
#define AMPS__FOWN 8
#endif

static void amps__fg_scatter(amps_int b, amps_int e, int slot, void *arg) {
    amps__fgjob *g = AMPS__CAST(amps__fgjob *, arg);
    (void)slot;
    amps__scatter(g->F, g->P, g->Ax, g->s + b, g->s + e - 1);
}

/* Owner classes [b, e): the queued updates of the targets each owns, in list order. */
static void amps__fg_update(amps_int b, amps_int e, int slot, void *arg) {
    amps__fgjob *g = AMPS__CAST(amps__fgjob *, arg);
    amps_int o, i;
    (void)slot;
    for (o = b; o < e; o++)
        for (i = 0; i < g->cnt; i++)
            amps__update(g->F, g->P, g->kl[i], g->s, g->e, g->P->gpos[g->kl[i]], g->kb[i], g->rel, (int)o, AMPS__FOWN);
}

/* Panels [b, e) of superblock [cb, ce): the updates from the group's columns before cb. */
static void amps__fg_panels(amps_int b, amps_int e, int slot, void *arg) {
    amps__fgjob *g = AMPS__CAST(amps__fgjob *, arg);
    amps_int ip;
    (void)slot;
    for (ip = b; ip < e; ip++) {
        amps_int c0 = g->cb + 4 * ip, tc = g->ce - c0 < 4 ? g->ce - c0 : 4;
        amps__panel_rect(g->F, g->P, g->s, g->cb, c0, tc, 0, (g->e - c0 - tc + 1) + g->nJ);
        amps__panel_factor(g->F, g->P, g->Ax, g->e, g->s, g->cb, c0, tc, g->rel, 0);
    }
}

/* amps__fgroup for a top-part group as a sequence of parallel loops (no loop waits for a
   particular participant): the scatter by columns; the queued updates by the AMPS__FOWN owner
   classes of the targets (4-column blocks, cyclic); per superblock of AMPS__SBLK columns the
   updates of its panels from the columns before it, by panels, then its own factorization on
   the caller. Same arithmetic per entry as amps__fgroup (the k chunks stay aligned at s). Uses
   the workspace of slots 0 and 1. */
static amps_int amps__fgroup_par(amps_factor *F, amps__fpriv *P, const double *Ax, amps_int J, const amps__par *par,
                                 int nt) {
    amps_int s = P->gs[J], e = P->gs[J + 1] - 1, n = F->n, cnt = 0, bad = -1, i, c0, cb, K;
    amps_int *rel = P->iwork, *kl = P->iwork + 2 * n, *kb = P->iwork + 3 * n;
    amps__fgjob g;
    g.F = F;
    g.P = P;
    g.Ax = Ax;
    g.rel = rel;
    g.kl = kl;
    g.kb = kb;
    g.s = s;
    g.e = e;
    g.nJ = F->Lp[e + 1] - F->Lp[e];
    amps__par_for(par, nt, e + 1 - s, 16, amps__fg_scatter, &g);
    amps__rowmaps(F, s, e, rel);
    while ((K = P->head[J]) >= 0) {
        P->head[J] = P->next[K];
        kl[cnt] = K;
        kb[cnt++] = amps__span(F, P, K, e);
    }
    g.cnt = cnt;
    amps__par_for(par, nt, AMPS__FOWN, 1, amps__fg_update, &g);
    for (i = 0; i < cnt; i++) {
        P->gpos[kl[i]] = kb[i];
        amps__link(F, P, kl[i], -1);
    }
    for (cb = s; cb <= e && bad < 0; cb += AMPS__SBLK) {
        amps_int ce = cb + AMPS__SBLK <= e + 1 ? cb + AMPS__SBLK : e + 1;
        g.cb = cb;
        g.ce = ce;
        if (cb > s) amps__par_for(par, nt, (ce - cb + 3) / 4, 1, amps__fg_panels, &g);
        for (c0 = cb; c0 < ce && bad < 0; c0 += 4) {
            amps_int tc = ce - c0 < 4 ? ce - c0 : 4;
            amps__panel_rect(F, P, cb, c0, c0, tc, 0, (e - c0 - tc + 1) + g.nJ);
            bad = amps__panel_factor(F, P, Ax, e, cb, c0, c0, tc, rel, 1);
        }
    }
    if (bad < 0) {
        P->gpos[J] = 0;
        amps__link(F, P, J, -1);
    }
    return bad;
}

/* A parallel loop of amps_factorize over subtrees. */
typedef struct amps__fsjob {
    amps_factor *F;
    amps__fpriv *P;
    const double *Ax;
} amps__fsjob;

/* Subtrees [b, e), each by ascending groups, with the row maps of slot. */
static void amps__fsub(amps_int b, amps_int e, int slot, void *arg) {
    amps__fsjob *j = AMPS__CAST(amps__fsjob *, arg);
    amps__fpriv *P = j->P;
    amps_int *iw = P->iwork + (size_t)slot * 2 * (size_t)j->F->n, i, q;
    for (i = b; i < e; i++)
        for (q = P->subp[i]; q < P->subp[i + 1]; q++) {
            amps_int col = amps__fgroup(j->F, P, j->Ax, P->subg[q], iw, i);
            if (col >= 0) {
                P->fail[i] = col;
                break;
            }
        }
}

AMPS_API amps_status amps_factorize(amps_ctx *ctx, amps_factor *F, const amps_csc *A) {
    amps__fpriv *P;
    amps_int n, k, g, i, bad = -1, nsub;
    const double *Ax;
    int nt;
    amps__par par;
    amps__fsjob fj;
    if (!F || !F->priv || !A) return amps__err(ctx, AMPS_ERR_ARG, "amps_factorize: NULL argument");
    P = AMPS__CAST(amps__fpriv *, F->priv);
    n = F->n;
    if (A->nrow != n || A->ncol != n || !A->p || (A->p[n] > 0 && (!A->i || !A->x)))
        return amps__err(ctx, AMPS_ERR_ARG, "amps_factorize: matrix is %lld x %lld (values %s), factor is for n = %lld",
                         (long long)A->nrow, (long long)A->ncol, A->x ? "present" : "missing", (long long)n);
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
    F->failed = -1;
    P->avx2 = amps__cpu_avx2();
    nsub = P->nsub;
    for (g = 0; g < P->ng; g++) P->head[g] = -1;
    for (i = 0; i <= nsub; i++) P->fail[i] = -1;
    nt = P->work < P->parmin ? 1 : amps__nthreads(ctx, P->nthr < nsub ? P->nthr : (nsub > 0 ? nsub : 1));
    if (nt > 1 && !P->pool) P->pool = amps__pool_new(ctx); /* a factor too small to factor in parallel starts none */
    par = amps__par_of(ctx, &P->bo, P->pool);
    fj.F = F;
    fj.P = P;
    fj.Ax = Ax;
    amps__par_for(&par, nt, nsub, 1, amps__fsub, &fj);
    for (i = 0; i < nsub; i++)
        if (P->fail[i] >= 0 && (bad < 0 || P->fail[i] < bad)) bad = P->fail[i];
    if (bad < 0) {
        for (g = 0; g < P->ng; g++)
            if (P->gsub[g] >= 0) amps__link(F, P, g, -1);
        int ntp = P->work < P->parmin ? 1 : amps__nthreads(ctx, P->nthr);
        for (k = 0; k < P->ntop && bad < 0; k++) {
            amps_int J = P->topg[k], s = P->gs[J], e = P->gs[J + 1] - 1;
            if (ntp > 1 && (double)(F->Lp[e + 1] - F->Lp[s]) * (double)(e - s + 1) >= P->pargroup) {
                bad = amps__fgroup_par(F, P, Ax, J, &par, ntp);
                continue;
            }
            bad = amps__fgroup(F, P, Ax, J, P->iwork, -1);
        }
    }
    F->failed = bad >= 0 ? F->perm[bad] : -1;
    if (bad >= 0) {
        amps_int p;
        double acc = 0;
        for (p = A->p[F->perm[bad]]; p < A->p[F->perm[bad] + 1]; p++)
            if (A->i[p] == F->perm[bad]) acc = Ax[p];
        return amps__err(ctx, AMPS_ERR_NOT_SPD,
                         "amps_factorize: matrix not positive definite: pivot %.3g at column %lld (original numbering; "
                         "diagonal %.3g)",
                         F->D[bad], (long long)F->perm[bad], acc);
    }
    F->is_numeric = 1;
    return AMPS_OK;
}

/* ==== [amps:solve impl] triangular solves and closures ======================================== */

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

AMPS_API amps_status amps_marker_grow(amps_ctx *ctx, amps_marker *m, amps_int n) {
    amps_int j;
    if (n <= m->n) return AMPS_OK;
    if (amps__realloc(ctx, (void **)&m->mark, (size_t)n, sizeof(amps_int))) return AMPS_ERR_OOM;
    for (j = m->n; j < n; j++) m->mark[j] = 0;
    if (m->stamp < 1) m->stamp = 1;
    m->n = n;
    return AMPS_OK;
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
            t = a[k];
            a[k] = a[c];
            a[c] = t;
        }
    for (end = n - 1; end > 0; end--) {
        t = a[0];
        a[0] = a[end];
        a[end] = t;
        for (k = 0; (c = 2 * k + 1) < end; k = c) {
            if (c + 1 < end && a[c + 1] > a[c]) c++;
            if (a[k] >= a[c]) break;
            t = a[k];
            a[k] = a[c];
            a[c] = t;
        }
    }
}

AMPS_API amps_int amps_closure(const amps_factor *F, amps_int nidx, const amps_int *idx, amps_int *out,
                               amps_marker *m) {
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

/* Forward kernel of a block of KC (1-4 or 8) columns c..c+KC-1 of a group ending at ke, S its
   shared rows: x(S) -= sum_k L(S, c+k) x(c+k), summed in ascending k by blocks of 4, the two
   blocks of 8 columns added last. */
AMPS__KERNEL void amps__fwd_block(int KC, const amps_factor *F, amps_int c, amps_int ke, const amps_int *S, amps_int ns,
                                  double *x) {
    const double *s[8];
    double xk[8];
    amps_int p;
    int k;
    AMPS__UNROLL
    for (k = 0; k < KC; k++) {
        s[k] = F->Lx + F->Lp[c + k] + (ke - c - k); /* L(S, c+k) */
        xk[k] = x[c + k];
    }
    p = 0;
#ifdef AMPS__SSE2
    { /* two rows at a time, each with the operations of the scalar loop below */
        __m128d xv[8];
        AMPS__UNROLL
        for (k = 0; k < KC; k++) xv[k] = _mm_set1_pd(xk[k]);
        for (; p + 2 <= ns; p += 2) {
            __m128d a = _mm_mul_pd(_mm_loadu_pd(s[0] + p), xv[0]);
            AMPS__UNROLL
            for (k = 1; k < (KC < 4 ? KC : 4); k++) a = _mm_add_pd(a, _mm_mul_pd(_mm_loadu_pd(s[k] + p), xv[k]));
            if (KC > 4) {
                __m128d b = _mm_mul_pd(_mm_loadu_pd(s[4] + p), xv[4]);
                AMPS__UNROLL
                for (k = 5; k < KC; k++) b = _mm_add_pd(b, _mm_mul_pd(_mm_loadu_pd(s[k] + p), xv[k]));
                a = _mm_add_pd(a, b);
            }
            x[S[p]] -= _mm_cvtsd_f64(a);
            x[S[p + 1]] -= _mm_cvtsd_f64(_mm_unpackhi_pd(a, a));
        }
    }
#endif
    for (; p < ns; p++) {
        double a = s[0][p] * xk[0];
        AMPS__UNROLL
        for (k = 1; k < (KC < 4 ? KC : 4); k++) a += s[k][p] * xk[k];
        if (KC > 4) {
            double b = s[4][p] * xk[4];
            AMPS__UNROLL
            for (k = 5; k < KC; k++) b += s[k][p] * xk[k];
            a = a + b;
        }
        x[S[p]] -= a;
    }
}

/* Backward kernel of a block of KC (1-4 or 8) columns c..c+KC-1 of a group ending at ke:
   x(c+k) -= L(S, c+k)^T x(S), each dot product summed in ascending order of S (with SSE2: as two
   partial sums over the even and the odd positions of S, added at the end, then the last odd
   position; the order depends on the pattern alone). */
AMPS__KERNEL void amps__bwd_block(int KC, const amps_factor *F, amps_int c, amps_int ke, const amps_int *S, amps_int ns,
                                  double *x) {
    const double *s[8];
    double t[8];
    amps_int p = 0;
    int k;
    AMPS__UNROLL
    for (k = 0; k < KC; k++) {
        s[k] = F->Lx + F->Lp[c + k] + (ke - c - k);
        t[k] = 0;
    }
#ifdef AMPS__SSE2
    if (ns >= 2) {
        __m128d tv[8];
        AMPS__UNROLL
        for (k = 0; k < KC; k++) tv[k] = _mm_setzero_pd();
        for (; p + 2 <= ns; p += 2) {
            __m128d xs = _mm_loadh_pd(_mm_load_sd(x + S[p]), x + S[p + 1]);
            AMPS__UNROLL
            for (k = 0; k < KC; k++) tv[k] = _mm_add_pd(tv[k], _mm_mul_pd(_mm_loadu_pd(s[k] + p), xs));
        }
        AMPS__UNROLL
        for (k = 0; k < KC; k++) t[k] = _mm_cvtsd_f64(tv[k]) + _mm_cvtsd_f64(_mm_unpackhi_pd(tv[k], tv[k]));
    }
#endif
    for (; p < ns; p++) {
        double xs = x[S[p]];
        AMPS__UNROLL
        for (k = 0; k < KC; k++) t[k] += s[k][p] * xs;
    }
    AMPS__UNROLL
    for (k = 0; k < KC; k++) x[c + k] -= t[k];
}

/* Block width for the kc columns left: 8, 4, or all of them when fewer than 4. */
static int amps__block_width(amps_int kc) { return kc >= 8 ? 8 : (kc >= 4 ? 4 : (int)kc); }

/* x := L^{-1} x on columns c0..ke of one group (ke its last column; width-1 groups are plain columns). */
static void amps__fwd(const amps_factor *F, amps_int c0, amps_int ke, double *x) {
    const amps_int *Lp = F->Lp;
    const double *Lx = F->Lx;
    const amps_int *S = F->Li + Lp[ke];
    amps_int ns = Lp[ke + 1] - Lp[ke], c, o;
    int w;
    for (c = c0; c < ke; c++) { /* the group's triangle */
        const double *Lc = Lx + Lp[c];
        double xc = x[c];
        o = 0;
#ifdef AMPS__SSE2
        {
            __m128d xv = _mm_set1_pd(xc);
            for (; o + 2 <= ke - c; o += 2)
                _mm_storeu_pd(x + c + 1 + o,
                              _mm_sub_pd(_mm_loadu_pd(x + c + 1 + o), _mm_mul_pd(_mm_loadu_pd(Lc + o), xv)));
        }
#endif
        for (; o < ke - c; o++) x[c + 1 + o] -= Lc[o] * xc;
    }
    for (c = c0; c <= ke; c += w) {
        switch (w = amps__block_width(ke + 1 - c)) {
        case 8: amps__fwd_block(8, F, c, ke, S, ns, x); break;
        case 4: amps__fwd_block(4, F, c, ke, S, ns, x); break;
        case 3: amps__fwd_block(3, F, c, ke, S, ns, x); break;
        case 2: amps__fwd_block(2, F, c, ke, S, ns, x); break;
        default: amps__fwd_block(1, F, c, ke, S, ns, x); break;
        }
    }
}

/* x(c0:cl) -= L(S, c0:cl)^T x(S) for columns c0..cl of the group ending at ke, S its shared rows
   (below ke). The columns are independent: blocks of them may run on different threads. */
static void amps__bwd_rows(const amps_factor *F, amps_int c0, amps_int cl, amps_int ke, double *x) {
    const amps_int *S = F->Li + F->Lp[ke];
    amps_int ns = F->Lp[ke + 1] - F->Lp[ke], c;
    int w;
    for (c = c0; c <= cl; c += w) {
        switch (w = amps__block_width(cl + 1 - c)) {
        case 8: amps__bwd_block(8, F, c, ke, S, ns, x); break;
        case 4: amps__bwd_block(4, F, c, ke, S, ns, x); break;
        case 3: amps__bwd_block(3, F, c, ke, S, ns, x); break;
        case 2: amps__bwd_block(2, F, c, ke, S, ns, x); break;
        default: amps__bwd_block(1, F, c, ke, S, ns, x); break;
        }
    }
}

/* x(c0:ke) := L(c0:ke, c0:ke)^{-T} x(c0:ke), the triangle of a group (each dot product summed as in
   amps__bwd_block). */
static void amps__bwd_tri(const amps_factor *F, amps_int c0, amps_int ke, double *x) {
    const amps_int *Lp = F->Lp;
    const double *Lx = F->Lx;
    amps_int c, o;
    for (c = ke - 1; c >= c0; c--) {
        const double *Lc = Lx + Lp[c];
        double t = 0;
        o = 0;
#ifdef AMPS__SSE2
        if (ke - c >= 2) { /* the partial sums of even and odd o, as in amps__bwd_block */
            __m128d tv = _mm_setzero_pd();
            for (; o + 2 <= ke - c; o += 2)
                tv = _mm_add_pd(tv, _mm_mul_pd(_mm_loadu_pd(Lc + o), _mm_loadu_pd(x + c + 1 + o)));
            t = _mm_cvtsd_f64(tv) + _mm_cvtsd_f64(_mm_unpackhi_pd(tv, tv));
        }
#endif
        for (; o < ke - c; o++) t += Lc[o] * x[c + 1 + o];
        x[c] -= t;
    }
}

/* x := L^{-T} x on columns c0..ke of one group (rows above c0 untouched). */
static void amps__bwd(const amps_factor *F, amps_int c0, amps_int ke, double *x) {
    amps__bwd_rows(F, c0, ke, ke, x);
    amps__bwd_tri(F, c0, ke, x);
}

AMPS_API void amps_lsolve(const amps_factor *F, double *x) {
    const amps__fpriv *P = AMPS__CAST(const amps__fpriv *, F->priv);
    amps_int g, c;
    if (P)
        for (g = 0; g < P->ng; g++) amps__fwd(F, P->gs[g], P->gs[g + 1] - 1, x);
    else
        for (c = 0; c < F->n; c++) amps__fwd(F, c, c, x);
}

AMPS_API void amps_dsolve(const amps_factor *F, double *x) {
    amps_int k;
    for (k = 0; k < F->n; k++) x[k] /= F->D[k];
}

AMPS_API void amps_ltsolve(const amps_factor *F, double *x) {
    const amps__fpriv *P = AMPS__CAST(const amps__fpriv *, F->priv);
    amps_int g, c;
    if (P)
        for (g = P->ng - 1; g >= 0; g--) amps__bwd(F, P->gs[g], P->gs[g + 1] - 1, x);
    else
        for (c = F->n - 1; c >= 0; c--) amps__bwd(F, c, c, x);
}

/* A parallel loop of the backward solves. */
typedef struct amps__bwjob {
    const amps_factor *F;
    double *x;
    amps_int c0, ke, nr;
    const amps_int *iw; /* the runs of amps__ltsolve_closure_par */
} amps__bwjob;

/* Blocks [b, e) of 8 columns of amps__bwd_par. */
static void amps__bw_rows(amps_int b, amps_int e, int slot, void *arg) {
    amps__bwjob *j = AMPS__CAST(amps__bwjob *, arg);
    (void)slot;
    for (; b < e; b++) amps__bwd_rows(j->F, j->c0 + 8 * b, j->c0 + 8 * b + 7, j->ke, j->x);
}

/* amps__bwd of columns c0..ke of a group on nthr participants when it is large: x(c) -= L(S, c)^T
   x(S) is independent per column, so chunks of 4 blocks of 8 columns are claimed; then the
   triangle. */
static void amps__bwd_par(const amps_factor *F, amps_int c0, amps_int ke, double *x, const amps__par *par, int nthr) {
    amps_int nb = (ke + 1 - c0) / 8;
    amps__bwjob j;
    if (nb < 2 || (double)(F->Lp[ke + 1] - F->Lp[c0]) < 1e5) {
        amps__bwd(F, c0, ke, x);
        return;
    }
    j.F = F;
    j.x = x;
    j.c0 = c0;
    j.ke = ke;
    amps__par_for(par, nthr, nb, 4, amps__bw_rows, &j);
    amps__bwd_rows(F, c0 + 8 * nb, ke, ke, x);
    amps__bwd_tri(F, c0, ke, x);
}

/* Whether the tree-parallel backward solves are worth their threads. */
static int amps__par_bwd(const amps_factor *F, int nthr) {
    const amps__fpriv *P = AMPS__CAST(const amps__fpriv *, F->priv);
    return P && nthr > 1 && P->nsub >= 2 && (double)F->Lp[F->n] >= 2e5;
}

/* Subtrees [b, e) of amps__ltsolve_par, each by descending groups. */
static void amps__bw_sub(amps_int b, amps_int e, int slot, void *arg) {
    amps__bwjob *j = AMPS__CAST(amps__bwjob *, arg);
    const amps__fpriv *P = AMPS__CAST(const amps__fpriv *, j->F->priv);
    amps_int i, k;
    (void)slot;
    for (i = b; i < e; i++)
        for (k = P->subp[i + 1] - 1; k >= P->subp[i]; k--) {
            amps_int g = P->subg[k];
            amps__bwd(j->F, P->gs[g], P->gs[g + 1] - 1, j->x);
        }
}

/* amps_ltsolve on nthr participants, same result bit for bit: the top part of the subtree
   decomposition (closed under parents) first, by descending groups (amps__bwd_par); then the
   subtrees, one chunk each, each by descending groups (it reads only its own and top rows, and
   writes its own). */
static void amps__ltsolve_par(const amps_factor *F, double *x, const amps__par *par, int nthr) {
    const amps__fpriv *P = AMPS__CAST(const amps__fpriv *, F->priv);
    amps_int i;
    amps__bwjob j;
    if (!amps__par_bwd(F, nthr)) {
        amps_ltsolve(F, x);
        return;
    }
    for (i = P->ntop - 1; i >= 0; i--) amps__bwd_par(F, P->gs[P->topg[i]], P->gs[P->topg[i] + 1] - 1, x, par, nthr);
    j.F = F;
    j.x = x;
    amps__par_for(par, nthr, P->nsub, 1, amps__bw_sub, &j);
}

/* First index j <= k of the run of closure[0..k] that ends at closure[k] inside its group. */
static amps_int amps__run_start(const amps_factor *F, const amps_int *closure, amps_int k) {
    const amps__fpriv *P = AMPS__CAST(const amps__fpriv *, F->priv);
    amps_int s = P ? P->gs[P->cgrp[closure[k]]] : closure[k], j;
    for (j = k; j > 0 && closure[j - 1] >= s; j--) {}
    return j;
}

/* Subtrees [b, e) of amps__ltsolve_closure_par: the runs (j->iw) in each, in list order. */
static void amps__bw_runs(amps_int b, amps_int e, int slot, void *arg) {
    amps__bwjob *j = AMPS__CAST(amps__bwjob *, arg);
    const amps__fpriv *P = AMPS__CAST(const amps__fpriv *, j->F->priv);
    amps_int i, r;
    (void)slot;
    for (i = b; i < e; i++)
        for (r = 0; r < j->nr; r++) {
            amps_int c = j->iw[r], g = P->cgrp[c];
            if (P->gsub[g] == i) amps__bwd(j->F, c, P->gs[g + 1] - 1, j->x);
        }
}

/* amps_ltsolve_closure on nthr participants, same result bit for bit, as amps__ltsolve_par: the
   runs of the closure in top groups first (descending), the others listed in iw (room for cnt)
   by their first index and solved per subtree, one chunk per subtree. The closure is closed
   under parents and a group is a chain, so a run ends at its group's last column. Each chunk
   scans the list: O(nsub x runs) index work beside the solve. */
static void amps__ltsolve_closure_par(const amps_factor *F, amps_int cnt, const amps_int *closure, double *y,
                                      const amps__par *par, int nthr, amps_int *iw) {
    amps__fpriv *P = AMPS__CAST(amps__fpriv *, F->priv);
    amps_int k, j, nr = 0;
    amps__bwjob bj;
    if (!amps__par_bwd(F, nthr)) {
        amps_ltsolve_closure(F, cnt, closure, y);
        return;
    }
    for (k = cnt - 1; k >= 0; k = j - 1) {
        amps_int ke = closure[k];
        j = amps__run_start(F, closure, k);
#ifdef AMPS_COUNT_TOUCH
        P->touch += (double)(F->Lp[ke + 1] - F->Lp[closure[j]]);
#endif
        if (P->gsub[P->cgrp[ke]] < 0) amps__bwd_par(F, closure[j], ke, y, par, nthr);
        else iw[nr++] = closure[j];
    }
    bj.F = F;
    bj.x = y;
    bj.nr = nr;
    bj.iw = iw;
    amps__par_for(par, nthr, P->nsub, 1, amps__bw_runs, &bj);
}

AMPS_API amps_status amps_solve(amps_ctx *ctx, const amps_factor *F, const double *b, double *x, double *work) {
    amps_int k, n;
    if (!F || !b || !x || !work) return amps__err(ctx, AMPS_ERR_ARG, "amps_solve: NULL argument");
    if (!F->is_numeric) return amps__err(ctx, AMPS_ERR_STATE, "amps_solve: factor has no numeric values");
    n = F->n;
    for (k = 0; k < n; k++) work[k] = b[F->perm[k]];
    amps_lsolve(F, work);
    amps_dsolve(F, work);
    {
        amps__fpriv *P = AMPS__CAST(amps__fpriv *, F->priv);
        amps__par par = amps__par_of(ctx, P ? &P->bo : NULL, P ? P->pool : NULL);
        amps__ltsolve_par(F, work, &par, amps__nthreads(ctx, 1024));
    }
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
    amps_int cnt = amps_closure(F, nreq, req, closure, m);
    amps_ltsolve_closure(F, cnt, closure, y);
    return cnt;
}

AMPS_API void amps_ltsolve_closure(const amps_factor *F, amps_int cnt, const amps_int *closure, double *y) {
#ifdef AMPS_COUNT_TOUCH
    amps__fpriv *P = AMPS__CAST(amps__fpriv *, F->priv);
#endif
    amps_int k, j, ke;
    /* closures of columns in one group are contiguous runs: solve each run as one block */
    for (k = cnt - 1; k >= 0; k = j - 1) {
        ke = closure[k];
        j = amps__run_start(F, closure, k);
        amps__bwd(F, closure[j], ke, y);
#ifdef AMPS_COUNT_TOUCH
        if (P) P->touch += (double)(F->Lp[ke + 1] - F->Lp[closure[j]]);
#endif
    }
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
            y[0] -= l * x0;
            y[1] -= l * x1;
            y[2] -= l * x2;
            y[3] -= l * x3;
        }
    }
    for (c = 0; c < n; c++) {
        double d = F->D[c];
        w[4 * c] /= d;
        w[4 * c + 1] /= d;
        w[4 * c + 2] /= d;
        w[4 * c + 3] /= d;
    }
    for (c = n - 1; c >= 0; c--) {
        double t0 = 0, t1 = 0, t2 = 0, t3 = 0;
        for (p = Lp[c]; p < Lp[c + 1]; p++) {
            double l = Lx[p];
            const double *y = w + 4 * (size_t)Li[p];
            t0 += l * y[0];
            t1 += l * y[1];
            t2 += l * y[2];
            t3 += l * y[3];
        }
        w[4 * c] -= t0;
        w[4 * c + 1] -= t1;
        w[4 * c + 2] -= t2;
        w[4 * c + 3] -= t3;
    }
}

/* A parallel loop of amps_solve_multi. */
typedef struct amps__msjob {
    const amps_factor *F;
    amps_int nrhs, ldb, ldx;
    const double *B;
    double *X, *work;
} amps__msjob;

/* Blocks [b, e) of AMPS__RHSB right-hand sides, in the workspace of slot. */
static void amps__ms_blocks(amps_int b, amps_int e, int slot, void *arg) {
    amps__msjob *j = AMPS__CAST(amps__msjob *, arg);
    const amps_factor *F = j->F;
    amps_int n = F->n, blk;
    double *w = j->work + (size_t)slot * AMPS__RHSB * (size_t)n;
    for (blk = b; blk < e; blk++) {
        amps_int r0 = blk * AMPS__RHSB, rc = j->nrhs - r0 < AMPS__RHSB ? j->nrhs - r0 : AMPS__RHSB, k, r;
        for (k = 0; k < n; k++) {
            const double *bk = j->B + F->perm[k] + (size_t)r0 * (size_t)j->ldb;
            for (r = 0; r < AMPS__RHSB; r++) w[AMPS__RHSB * k + r] = r < rc ? bk[(size_t)r * (size_t)j->ldb] : 0.0;
        }
        if (rc == 1) {
            for (k = 0; k < n; k++) w[k] = w[AMPS__RHSB * k]; /* single vector: use the grouped kernels */
            amps_lsolve(F, w);
            amps_dsolve(F, w);
            amps_ltsolve(F, w);
            for (k = 0; k < n; k++) j->X[F->perm[k] + (size_t)r0 * (size_t)j->ldx] = w[k];
            continue;
        }
        amps__solve4(F, w);
        for (k = 0; k < n; k++) {
            double *xk = j->X + F->perm[k] + (size_t)r0 * (size_t)j->ldx;
            for (r = 0; r < rc; r++) xk[(size_t)r * (size_t)j->ldx] = w[AMPS__RHSB * k + r];
        }
    }
}

AMPS_API amps_status amps_solve_multi(amps_ctx *ctx, const amps_factor *F, amps_int nrhs, const double *B, amps_int ldb,
                                      double *X, amps_int ldx, double *work) {
    amps_int nblk, n;
    amps__msjob j;
    amps__par par;
    if (!F || nrhs < 0 || (nrhs > 0 && (!B || !X || !work)))
        return amps__err(ctx, AMPS_ERR_ARG, "amps_solve_multi: NULL argument or negative nrhs %lld", (long long)nrhs);
    if (!F->is_numeric) return amps__err(ctx, AMPS_ERR_STATE, "amps_solve_multi: factor has no numeric values");
    n = F->n;
    if (ldb < n || ldx < n)
        return amps__err(ctx, AMPS_ERR_ARG, "amps_solve_multi: leading dimension (ldb %lld, ldx %lld) below n = %lld",
                         (long long)ldb, (long long)ldx, (long long)n);
    nblk = (nrhs + AMPS__RHSB - 1) / AMPS__RHSB;
    j.F = F;
    j.nrhs = nrhs;
    j.B = B;
    j.ldb = ldb;
    j.X = X;
    j.ldx = ldx;
    j.work = work;
    {
        amps__fpriv *P = AMPS__CAST(amps__fpriv *, F->priv);
        par = amps__par_of(ctx, P ? &P->bo : NULL, P ? P->pool : NULL);
    }
    amps__par_for(&par, amps__nthreads(ctx, nblk > 0 ? nblk : 1), nblk, 1, amps__ms_blocks, &j);
    return AMPS_OK;
}

/* amps_condest; *jstart (if not NULL): on entry a column in [0, n) to start Hager's iteration at
   (x = e_jstart, as the iteration's own later steps do; else x = 1/n), on success the column the
   iteration ended at (a warm start for a nearby matrix: 3 solves when it is still the maximizer). */
static amps_status amps__condest(amps_ctx *ctx, const amps_csc *K, amps_stype stype, const amps_factor *F,
                                 double *work, double *cond, amps_int *jstart) {
    amps_int n, j, p, it, jmax = 0, jlast = -1;
    int warm;
    double *w, *x, *y, *sw, knorm = 0, est = 0, alt = 0;
    amps_status s = AMPS_OK;
    if (!K || !F || !cond || !K->p || (K->p[K->ncol] > 0 && !K->i) || !K->x)
        return amps__err(ctx, AMPS_ERR_ARG, "amps_condest: NULL argument");
    if (K->nrow != K->ncol || K->ncol != F->n)
        return amps__err(ctx, AMPS_ERR_ARG, "amps_condest: K is %lld x %lld, the factor has order %lld",
                         (long long)K->nrow, (long long)K->ncol, (long long)F->n);
    if (!F->is_numeric) return amps__err(ctx, AMPS_ERR_STATE, "amps_condest: factor has no numeric values");
    n = F->n;
    if (n == 0) {
        *cond = 0;
        return AMPS_OK;
    }
    w = work ? work : AMPS__CAST(double *, amps__malloc(ctx, 3 * (size_t)n, sizeof(double)));
    if (!w) return AMPS_ERR_OOM;
    x = w;
    y = w + n;
    sw = w + 2 * (size_t)n;
    /* ||K||_1: largest absolute column sum of the symmetric matrix (the other triangle mirrored) */
    for (j = 0; j < n; j++) y[j] = 0;
    for (j = 0; j < n; j++)
        for (p = K->p[j]; p < K->p[j + 1]; p++) {
            amps_int i = K->i[p];
            double a = fabs(K->x[p]);
            y[j] += a;
            if (i != j && stype != AMPS_FULL) y[i] += a;
        }
    for (j = 0; j < n; j++)
        if (y[j] > knorm) knorm = y[j];
    /* Hager: maximize ||K^{-1} x||_1 over ||x||_1 = 1 (K^{-1} symmetric, so K^{-T} = K^{-1}) */
    warm = jstart && *jstart >= 0 && *jstart < n;
    for (j = 0; j < n; j++) x[j] = warm ? (j == *jstart ? 1.0 : 0.0) : 1.0 / (double)n;
    if (warm) jlast = *jstart;
    for (it = 0; it < 5; it++) {
        double ny = 0, zx = 0, zmax;
        if ((s = amps_solve(ctx, F, x, y, sw)) != AMPS_OK) goto done;
        for (j = 0; j < n; j++) ny += fabs(y[j]);
        if (it > 0 && ny <= est) break;
        est = ny;
        for (j = 0; j < n; j++) y[j] = y[j] >= 0 ? 1.0 : -1.0;
        if ((s = amps_solve(ctx, F, y, y, sw)) != AMPS_OK) goto done; /* z = K^{-1} sign(K^{-1} x) */
        for (j = 0; j < n; j++) zx += y[j] * x[j];
        jmax = 0;
        zmax = fabs(y[0]);
        for (j = 1; j < n; j++)
            if (fabs(y[j]) > zmax) {
                zmax = fabs(y[j]);
                jmax = j;
            }
        if ((it > 0 || warm) && (zmax <= zx || jmax == jlast)) break;
        jlast = jmax;
        for (j = 0; j < n; j++) x[j] = 0;
        x[jmax] = 1;
    }
    /* Higham's alternating test vector guards against the rare failures of the iteration */
    for (j = 0; j < n; j++) x[j] = (j % 2 ? -1.0 : 1.0) * (1.0 + (n > 1 ? (double)j / (double)(n - 1) : 0.0));
    if ((s = amps_solve(ctx, F, x, y, sw)) != AMPS_OK) goto done;
    for (j = 0; j < n; j++) alt += fabs(y[j]);
    alt = 2.0 * alt / (3.0 * (double)n);
    if (alt > est) est = alt;
    if (!amps__isfinite(est * knorm)) {
        s = amps__err(ctx, AMPS_ERR_VALUE, "amps_condest: estimate not finite");
        goto done;
    }
    *cond = est * knorm;
    if (jstart) *jstart = jlast >= 0 ? jlast : jmax;
done:
    if (!work) amps__free(ctx, w);
    return s;
}

AMPS_API amps_status amps_condest(amps_ctx *ctx, const amps_csc *K, amps_stype stype, const amps_factor *F,
                                  double *work, double *cond) {
    return amps__condest(ctx, K, stype, F, work, cond, NULL);
}

/* ==== [amps:update impl] augmented updates: the AMPS engine =================================== */
/* References:
     [AMPS]  Yeung, Pothen, Crouch, "AMPS: real-time mesh cutting with augmented matrices for
             surgical simulations" (the algorithm: Eq. 3.x, Table 1 Steps 1-6);
     [Interactive cutting]  Yeung, Crouch, Pothen, "Interactively cutting and constraining
             vertices in meshes using augmented matrices" (background re-factorization, Sec. 3.6).
   Notation. n = order of the factored base K = P L D L^T P^T, N = n + k the current order,
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
     w_F' = Delta[F', :] y,  x = K-bar^{-1} (f^ - H w),  x_U = y ([AMPS] Eq. 3.20),      (Step 6)
     reaction (K^ x - f^)_C = (Delta y)_C - w_C.
   Without constraints this is [AMPS] Eq. 3.8 with E-bar = -Delta; with S empty Eq. 3.30.
   The dual formulation ([AMPS] Eq. 3.16-3.17) solves the transposed system (I~ + G Delta~)^T w~ = b'
   for the correction forces w directly (b'_F' = Delta[F', :] r^, b'_C = r_C - g, r^ = r on F',
   g on C) and takes x_U from the full solve.

   Every change of K^ or of C changes columns of A = I~ + G Delta~ (column j depends on
   Delta[:, j], on the kind of j and of its Delta-neighbours) or appends rows and columns (G only
   grows). The dense LU with partial pivoting is left-looking in a column order that keeps
   recently changed columns last. A commit removes its changed columns from the factor (the
   unchanged ones after them keep theirs: the upper Hessenberg U left by the removal is
   re-triangularized by adjacent-row transforms, amps__lu_drop) and appends them with the new
   ones: O(|U|^2 (r + k)) for r changed and k new columns. Where a transform exceeds its bounds
   (AMPS__DMULT, AMPS__DLMAX, the pivot test) the commit refactors from that column on. */

#define AMPS__UMOD 1u    /* index in S */
#define AMPS__UCON 2u    /* index in C */
#define AMPS__NB 32      /* dense panel width */
#define AMPS__TB 64      /* diagonal block of the panel's triangular solve */
#define AMPS__GKC 256    /* k block of the dense product amps__gemm_sub */
#define AMPS__GPACK (8 * AMPS__GKC) /* its packed rows per thread */
#define AMPS__DMAX 160              /* most changed dense columns amps__lu_drop moves in one commit */
#define AMPS__DMULT 8.0             /* largest multiplier amps__lu_drop accepts */
#define AMPS__DLMAX 64.0 /* largest entry of L it may create */
#define AMPS__VB 16      /* right-hand sides per chunk of Step 1 */

/* A recorded change K^[r, c] += v (and K^[c, r] += v). */
typedef struct amps__pdelta {
    amps_int r, c;
    double v;
} amps__pdelta;
/* A recorded constraint change: x_i = v, or its release. */
typedef struct amps__pcon {
    amps_int i;
    int release;
    double v;
} amps__pcon;
/* Delta row header of position pos before the commit. */
typedef struct amps__djour {
    amps_int pos, start, len, cap;
} amps__djour;
/* Kind and prescribed value of position pos before the commit. */
typedef struct amps__kjour {
    amps_int pos;
    unsigned char kind;
    double g;
} amps__kjour;

struct amps_update {
    const amps_factor *F; /* base factor: the one given, or refac.F_own */
    amps_formulation form;
    double singular_tol;  /* pivot test of the dense LU (opts.singular_tol) */
    double sigma;         /* K-bar's diagonal on appended DOFs */
    int grow;             /* capacities grow on demand (opts.grow) */
    int refine;           /* refinement steps of a full solve (opts.refine) */
    int xs_from_dense;    /* x_U from the dense system (opts.xs_from_dense) */
    int nthr;             /* threads of the kernels */
    int nbuf;             /* threads the per-thread buffers are sized for (>= nthr) */
    amps_int n, N, cap_N; /* base order, committed order n + k, capacity of N */
    unsigned long kver;   /* version of K^: counts the commits that changed it (Delta, new DOFs) and the swaps */
    struct {              /* the base matrix */
        amps_int *Kp, *Ki;
        double *Kx;         /* K, both triangles, original numbering */
        double *inv_sqrt_d; /* n: D^{-1/2} */
        int blk3;           /* K's pattern is made of 3x3 blocks (node blocks): amps__resid_blk */
        amps_int *bcol;     /* blk3: first column of each block, block row B's at Kp[3B] / 9 (the
                               check streams Kx and these, a ninth of Ki) */
    } base;
    struct {                          /* forces and ct = D^{-1/2} L^{-1} P^T f_ct */
        double *f;                    /* cap_N: f^ */
        double *ct;                   /* n, permuted */
        double *f_ct;                 /* n: the base forces ct was computed from */
        amps_int *changed, n_changed; /* n: base forces changed since ct was updated */
        int changed_all;              /* the list overflowed: recompute ct in full */
        amps_int n_increments;        /* sparse updates of ct since its last full solve */
    } force;
    struct { /* changes recorded since the last commit */
        amps__pdelta *delta;
        amps_int n_delta, cap_delta; /* K^ entries */
        amps__pcon *con;
        amps_int n_con, cap_con; /* constraints */
        amps_int n_dofs;         /* appended DOFs */
    } pending;
    struct {                 /* the index set U = S u C */
        amps_int size, cap;  /* |U| and capacity */
        amps_int *idx;       /* U position -> index */
        amps_int *pos;       /* cap_N: index -> U position or -1 */
        unsigned char *kind; /* AMPS__UMOD | AMPS__UCON per position */
        double *g;           /* prescribed values (constrained positions) */
    } aug;
    struct { /* memoized W columns (base positions) in a pool */
        size_t *off;
        amps_int *len; /* per position: start in the pool, length (root path) */
        double *val;
        amps_int *idx;    /* the pool: values and rows (permuted numbering) */
        size_t used, cap; /* pool entries used, capacity */
    } memo;
    struct {                                     /* Delta rows (U positions) in a pool */
        amps_int *row_start, *row_len, *row_cap; /* per position */
        amps_int *col;
        double *val;         /* the pool: columns (U positions) and values */
        amps_int used, cap;  /* pool entries used, capacity */
        amps_marker touched; /* aug.cap: rows the commit changes */
        amps_int *n_add;     /* aug.cap: entries the commit adds to each */
    } delta;
    struct {                           /* the dense system A = I~ + G Delta~ and P A Q = L U */
        double *G, *LU;                /* aug.cap x aug.cap, column major */
        double *col_norm;              /* column norms of A (pivot test) */
        amps_int *row_perm;            /* P: factor row -> U position */
        amps_int *col_order, *col_pos; /* Q: factor column -> U position, and inverse */
        amps_marker changed;           /* aug.cap: columns the commit changes */
        double *panel;                 /* max(nbuf, 4) * max(aug.cap, AMPS__GPACK): column buffers, and
                                          the packed rows of amps__gemm_sub */
        double *transforms;            /* 3 AMPS__DMAX aug.cap: row transforms of amps__lu_drop */
    } lu;
    struct { /* state before the commit, for its rollback */
        amps__djour *rows;
        amps_int n_rows; /* aug.cap: Delta row headers */
        amps__kjour *kinds;
        amps_int n_kinds; /* pending.cap_con: kinds and prescribed values */
    } journal;
    struct {                                    /* dense vectors (U positions) */
        double *z, *rhs, *tmp;                  /* Step 5 unknowns, Step 4 r, scratch */
        double *y, *w;                          /* y = x_U, the forces w of the augmentation */
        double *b;                              /* Step 5 right-hand side */
        double *r_corr, *y_corr, *w_corr, *rho; /* the refinement step's r, y, w and residual */
    } dense;
    struct {          /* workspace */
        double *vec;  /* nthr * n, zero between uses */
        double *vec2; /* n: copy for the partial backward solve */
        double *chunk;
        amps_int chunk_rows;         /* Step 1 chunks: nthr * chunk_rows * AMPS__VB */
        amps_int *row_map, *closure; /* Step 1: nthr * n each (row_map -1 between uses) */
        unsigned char *lanes;        /* Step 1: nthr * 2n, lane bounds of the union's rows */
        amps_int *idx;               /* n + cap_N */
        double *resid;               /* 2 * cap_N residual vectors */
        amps_marker mark_n, mark_N;  /* over base nodes (n) and indices (cap_N) */
    } work;
    struct {                        /* the solution */
        double *x;                  /* cap_N */
        double *react;              /* aug.cap: reactions (K^ x - f^) at U positions */
        int x_stale, has_x;         /* x is stale / x was computed at least once */
        int react_stale, has_react; /* reactions stale / computed */
        int watched_stale;          /* watched entries of x stale */
        amps_int x_dim;             /* order of the last solve */
        amps_int n_rhs;             /* dense.rhs[0..n_rhs-1] = W^T ct is current on base positions */
        int commit_unsolved;        /* a commit since the last solve (its step times count) */
    } sol;
    struct {             /* accuracy guard */
        double tol;      /* 0: off */
        double *ct;      /* n: forward solve of the residual */
        double *scratch; /* 2 * cap_N */
        double knorm;    /* ||K-bar||_inf (the base rows and sigma), the scale of the backward error */
        double omega_d;  /* the mixed backward error of a direct solve with the base factor (amps__direct_omega) */
        double cond;     /* kappa_1(K-bar) estimated at the creation of the base (amps_condest; 0: unknown) */
        amps_int cond_j; /* the column at which that estimate's iteration ended (-1: none) */
        int warm_left;   /* full solves still to start from the last solution (amps__warm_solve) */
        int cold_refined; /* the last checked solve from zero took a refinement step */
    } guard;
    struct {                   /* re-factorization */
        amps_update_opts opts; /* as created (for the engine of a new base) */
        amps_factor *F_own;
        amps_csc *K_own;             /* base factor and matrix owned by the engine (after a swap) */
        amps__lspare spare;          /* the storage of the last retired F_own's L (the next job's) */
        struct amps__bg *job;        /* the one in progress, or NULL */
        double t_factor;             /* measured (or estimated) factorization time */
        double t_step_base, t_extra; /* step time after the last swap, extra time since */
        amps_int size_base;          /* |U| after the last swap */
        amps_int n_struct;           /* structural commits since the last swap (COUNT) */
        amps_int *origin;            /* origin[j] of appended DOF j (-1: unknown), j < cap_origin */
        amps_int cap_origin;
        double fill_ref;   /* nnz(L) / nnz(B) of the last fresh ordering (0: not known) */
        double fold_flops; /* sum_j c_j^2 of the base factor (amps__commit_wants_fold; 0: not known) */
        amps_int n_kept;   /* re-factorizations since the last fresh ordering */
        int fresh;         /* 1: the next start orders afresh (amps_update_refactor) */
    } refac;
    struct {                        /* watch set */
        amps_int n, n_closure, cap; /* size, |closure_L of its base indices|, capacity */
        amps_int *idx, *closure;
        unsigned char *from_dense; /* watched entry given by the dense system */
        double *job_y, *job_xw;    /* the two-phase job in progress (NULL: none) */
    } watch;
    amps_update_stats stats;
    amps__par par; /* the kernels' back end (from the ctx at create; bo points at this handle's bo) */
    amps__parbo bo;
    amps__pool *pool; /* the engine's workers (par.pool; NULL: none), kept across re-factorizations */
    struct {                   /* the two-phase commit (amps_update_commit_begin) */
        int state;             /* 0 none, 1 begun (written by the caller's thread only) */
        int ran;               /* the run phase done (written by the thread that runs it) */
        amps_int u_old, nlist; /* |U| before it; the new base positions (list) */
        struct amps_update *J; /* the copy of the engine the run phase works on */
        amps__pdelta *delta;   /* its matrix changes and appended DOFs */
        amps__pcon *con;       /* its structural constraint changes */
        amps_int n_delta, n_con, n_dofs, cap_delta, cap_con;
        amps_int *list, cap_list;    /* the new base positions (Step 1) */
        double *chunk;               /* the run phase's Step 1-2 workspace (as work.*) */
        amps_int *row_map, *closure; /* row_map -1 between uses */
        unsigned char *lanes;
        amps_int ws_n;          /* base order the workspace is sized for (0: none) */
        size_t vused_old;       /* memo.used before it */
        double t_wcols, t_gram; /* the run phase's step times */
    } cjob;
};


AMPS_API void amps_update_opts_default(amps_update_opts *o) {
    if (!o) return;
    memset(o, 0, sizeof(*o));
    o->cap_mod = 256;
    o->cap_new = 3 * 256;
    o->cap_delta = 0;
    o->cap_pending = 4096;
    o->grow = 0;
    o->formulation = AMPS_FORM_PRIMAL;
    o->singular_tol = 1e-13;
    o->refine = 1;
    o->xs_from_dense = 0;
    o->refactor = AMPS_REFACTOR_AUTO;
    o->refactor_order.method = AMPS_ORDER_ND;
    o->refactor_order.block = 0;
    o->refactor_threads = 1;
    o->refactor_ratio = 0.25;
    o->refine_tol = 2.220446049250313e-16;
    o->refactor_size = 384;
    o->refactor_every = 32;
    o->refactor_reuse = 1;
}

/* ---- allocation of the capacity-dependent arrays ---- */

/* Grows every U-sized array to capacity cap (> aug.cap). All-or-nothing. */
static amps_status amps__grow_u(amps_ctx *ctx, amps_update *U, amps_int cap) {
    double *G = NULL, *LU = NULL;
    amps_int old = U->aug.cap, u = U->aug.size;
    size_t c = (size_t)cap;
    amps_marker changed = {0, 0, NULL}, touched = {0, 0, NULL};
    G = AMPS__CAST(double *, amps__malloc(ctx, c * c, sizeof(double)));
    LU = AMPS__CAST(double *, amps__malloc(ctx, c * c, sizeof(double)));
    if (!G || !LU || amps_marker_init(ctx, &changed, cap) || amps_marker_init(ctx, &touched, cap)) {
        amps__free(ctx, G);
        amps__free(ctx, LU);
        amps_marker_free(ctx, &changed);
        amps_marker_free(ctx, &touched);
        return amps__err(ctx, AMPS_ERR_OOM, "amps_update: out of memory growing the dense system to %ld", (long)cap);
    }
    /* vector arrays: a failure leaves earlier ones larger, which is harmless */
    if (amps__realloc(ctx, (void **)&U->aug.idx, c, sizeof(amps_int)) ||
        amps__realloc(ctx, (void **)&U->aug.kind, c, 1) || amps__realloc(ctx, (void **)&U->aug.g, c, sizeof(double)) ||
        amps__realloc(ctx, (void **)&U->memo.off, c, sizeof(size_t)) ||
        amps__realloc(ctx, (void **)&U->memo.len, c, sizeof(amps_int)) ||
        amps__realloc(ctx, (void **)&U->delta.row_start, c, sizeof(amps_int)) ||
        amps__realloc(ctx, (void **)&U->delta.row_len, c, sizeof(amps_int)) ||
        amps__realloc(ctx, (void **)&U->delta.row_cap, c, sizeof(amps_int)) ||
        amps__realloc(ctx, (void **)&U->lu.col_norm, c, sizeof(double)) ||
        amps__realloc(ctx, (void **)&U->lu.row_perm, c, sizeof(amps_int)) ||
        amps__realloc(ctx, (void **)&U->lu.col_order, c, sizeof(amps_int)) ||
        amps__realloc(ctx, (void **)&U->lu.col_pos, c, sizeof(amps_int)) ||
        amps__realloc(ctx, (void **)&U->delta.n_add, c, sizeof(amps_int)) ||
        amps__realloc(ctx, (void **)&U->lu.panel,
                      (c > (size_t)AMPS__GPACK ? c : (size_t)AMPS__GPACK) * (size_t)(U->nbuf > 4 ? U->nbuf : 4),
                      sizeof(double)) ||
        amps__realloc(ctx, (void **)&U->lu.transforms, c * (size_t)(3 * AMPS__DMAX), sizeof(double)) ||
        amps__realloc(ctx, (void **)&U->journal.rows, c, sizeof(amps__djour)) ||
        amps__realloc(ctx, (void **)&U->sol.react, c, sizeof(double)) ||
        amps__realloc(ctx, (void **)&U->dense.z, c, sizeof(double)) ||
        amps__realloc(ctx, (void **)&U->dense.rhs, c, sizeof(double)) ||
        amps__realloc(ctx, (void **)&U->dense.tmp, c, sizeof(double)) ||
        amps__realloc(ctx, (void **)&U->dense.y, c, sizeof(double)) ||
        amps__realloc(ctx, (void **)&U->dense.w, c, sizeof(double)) ||
        amps__realloc(ctx, (void **)&U->dense.b, c, sizeof(double)) ||
        amps__realloc(ctx, (void **)&U->dense.r_corr, c, sizeof(double)) ||
        amps__realloc(ctx, (void **)&U->dense.w_corr, c, sizeof(double)) ||
        amps__realloc(ctx, (void **)&U->dense.y_corr, c, sizeof(double)) ||
        amps__realloc(ctx, (void **)&U->dense.rho, c, sizeof(double))) {
        amps__free(ctx, G);
        amps__free(ctx, LU);
        amps_marker_free(ctx, &changed);
        amps_marker_free(ctx, &touched);
        return amps__err(ctx, AMPS_ERR_OOM, "amps_update: out of memory growing to %ld modified indices", (long)cap);
    }
    {
        amps_int j;
        for (j = 0; j < u; j++) {
            memcpy(G + (size_t)j * c, U->lu.G + (size_t)j * (size_t)old, sizeof(double) * (size_t)u);
            memcpy(LU + (size_t)j * c, U->lu.LU + (size_t)j * (size_t)old, sizeof(double) * (size_t)u);
        }
    }
    amps__free(ctx, U->lu.G);
    amps__free(ctx, U->lu.LU);
    amps_marker_free(ctx, &U->lu.changed);
    amps_marker_free(ctx, &U->delta.touched);
    U->lu.G = G;
    U->lu.LU = LU;
    U->lu.changed = changed;
    U->delta.touched = touched;
    U->aug.cap = cap;
    return AMPS_OK;
}

/* Ensures room for `need` more U positions (grows by doubling when allowed). */
static amps_status amps__need_u(amps_ctx *ctx, amps_update *U, amps_int need) {
    amps_int cap = U->aug.cap;
    if (U->aug.size + need <= cap) return AMPS_OK;
    if (!U->grow)
        return amps__err(ctx, AMPS_ERR_CAPACITY,
                         "amps_update: %ld modified/constrained indices exceed cap_mod = %ld (raise it or set grow)",
                         (long)(U->aug.size + need), (long)cap);
    while (cap < U->aug.size + need) cap = cap * 2 + 16;
    return amps__grow_u(ctx, U, cap);
}

static amps_status amps__need_N(amps_ctx *ctx, amps_update *U, amps_int need) {
    amps_int cap = U->cap_N, old = U->cap_N, i;
    if (U->N + U->pending.n_dofs + need <= cap) return AMPS_OK;
    if (!U->grow)
        return amps__err(ctx, AMPS_ERR_CAPACITY,
                         "amps_update: %ld appended DOFs exceed cap_new = %ld (raise it or set grow)",
                         (long)(U->N + U->pending.n_dofs + need - U->n), (long)(cap - U->n));
    while (cap < U->N + U->pending.n_dofs + need) cap = cap + cap / 2 + 16;
    if (amps__realloc(ctx, (void **)&U->force.f, (size_t)cap, sizeof(double)) ||
        amps__realloc(ctx, (void **)&U->sol.x, (size_t)cap, sizeof(double)) ||
        amps__realloc(ctx, (void **)&U->aug.pos, (size_t)cap, sizeof(amps_int)) ||
        amps__realloc(ctx, (void **)&U->work.idx, (size_t)(U->n + cap), sizeof(amps_int)) ||
        amps__realloc(ctx, (void **)&U->work.resid, 2 * (size_t)cap, sizeof(double)) ||
        amps__realloc(ctx, (void **)&U->guard.scratch, 2 * (size_t)cap, sizeof(double)))
        return AMPS_ERR_OOM;
    {
        amps_marker m2;
        if (amps_marker_init(ctx, &m2, cap)) return AMPS_ERR_OOM;
        amps_marker_free(ctx, &U->work.mark_N);
        U->work.mark_N = m2;
    }
    for (i = old; i < cap; i++) {
        U->force.f[i] = 0;
        U->sol.x[i] = 0;
        U->aug.pos[i] = -1;
    }
    U->cap_N = cap;
    return AMPS_OK;
}

static amps_status amps__need_pending(amps_ctx *ctx, amps_update *U, amps_int nd, amps_int nc) {
    if (U->pending.n_delta + nd > U->pending.cap_delta) {
        amps_int cap = U->pending.cap_delta;
        if (!U->grow)
            return amps__err(ctx, AMPS_ERR_CAPACITY,
                             "amps_update: more than cap_pending = %ld changes recorded before a commit", (long)cap);
        while (cap < U->pending.n_delta + nd) cap = cap * 2 + 64;
        if (amps__realloc(ctx, (void **)&U->pending.delta, (size_t)cap, sizeof(amps__pdelta))) return AMPS_ERR_OOM;
        U->pending.cap_delta = cap;
    }
    if (U->pending.n_con + nc > U->pending.cap_con) {
        amps_int cap = U->pending.cap_con;
        if (!U->grow)
            return amps__err(ctx, AMPS_ERR_CAPACITY,
                             "amps_update: more than cap_pending = %ld constraint changes recorded before a commit",
                             (long)cap);
        while (cap < U->pending.n_con + nc) cap = cap * 2 + 64;
        if (amps__realloc(ctx, (void **)&U->pending.con, (size_t)cap, sizeof(amps__pcon)) ||
            amps__realloc(ctx, (void **)&U->journal.kinds, (size_t)cap, sizeof(amps__kjour)))
            return AMPS_ERR_OOM;
        U->pending.cap_con = cap;
    }
    return AMPS_OK;
}

static void amps__bg_discard(amps_ctx *ctx, amps_update *U);
static void amps__bg_poll(amps_ctx *ctx, amps_update *U);
static void amps__bg_log(amps_update *U, amps_int kpend, const amps__pdelta *pd, amps_int npd);
static void amps__bg_policy(amps_ctx *ctx, amps_update *U, double t);
static void amps__bg_after_commit(amps_ctx *ctx, amps_update *U, int structural, int may_swap);
static int amps__commit_wants_fold(amps_update *U);
static amps_status amps__commit_fold(amps_ctx *ctx, amps_update *U);

AMPS_API void amps_update_free(amps_ctx *ctx, amps_update *U) {
    if (!U) return;
    amps__bg_discard(ctx, U);
    amps__pool_free(ctx, U->pool);
    amps__free(ctx, U->cjob.J);
    amps__free(ctx, U->cjob.delta);
    amps__free(ctx, U->cjob.con);
    amps__free(ctx, U->cjob.list);
    amps__free(ctx, U->cjob.chunk);
    amps__free(ctx, U->cjob.row_map);
    amps__free(ctx, U->cjob.closure);
    amps__free(ctx, U->cjob.lanes);
    amps_factor_free(ctx, U->refac.F_own);
    amps_csc_free(ctx, U->refac.K_own);
    amps__spare_free(ctx, &U->refac.spare);
    amps__free(ctx, U->refac.origin);
    amps__free(ctx, U->base.Kp);
    amps__free(ctx, U->base.Ki);
    amps__free(ctx, U->base.bcol);
    amps__free(ctx, U->base.Kx);
    amps__free(ctx, U->base.inv_sqrt_d);
    amps__free(ctx, U->force.f);
    amps__free(ctx, U->force.ct);
    amps__free(ctx, U->force.f_ct);
    amps__free(ctx, U->force.changed);
    amps__free(ctx, U->pending.delta);
    amps__free(ctx, U->pending.con);
    amps__free(ctx, U->aug.idx);
    amps__free(ctx, U->aug.pos);
    amps__free(ctx, U->aug.kind);
    amps__free(ctx, U->aug.g);
    amps__free(ctx, U->memo.off);
    amps__free(ctx, U->memo.len);
    amps__free(ctx, U->memo.val);
    amps__free(ctx, U->memo.idx);
    amps__free(ctx, U->delta.row_start);
    amps__free(ctx, U->delta.row_len);
    amps__free(ctx, U->delta.row_cap);
    amps__free(ctx, U->delta.col);
    amps__free(ctx, U->delta.val);
    amps__free(ctx, U->delta.n_add);
    amps_marker_free(ctx, &U->delta.touched);
    amps__free(ctx, U->lu.G);
    amps__free(ctx, U->lu.LU);
    amps__free(ctx, U->lu.col_norm);
    amps__free(ctx, U->lu.row_perm);
    amps__free(ctx, U->lu.col_order);
    amps__free(ctx, U->lu.col_pos);
    amps__free(ctx, U->lu.panel);
    amps__free(ctx, U->lu.transforms);
    amps_marker_free(ctx, &U->lu.changed);
    amps__free(ctx, U->journal.rows);
    amps__free(ctx, U->journal.kinds);
    amps__free(ctx, U->dense.z);
    amps__free(ctx, U->dense.rhs);
    amps__free(ctx, U->dense.tmp);
    amps__free(ctx, U->dense.y);
    amps__free(ctx, U->dense.w);
    amps__free(ctx, U->dense.b);
    amps__free(ctx, U->dense.r_corr);
    amps__free(ctx, U->dense.y_corr);
    amps__free(ctx, U->dense.w_corr);
    amps__free(ctx, U->dense.rho);
    amps__free(ctx, U->work.vec);
    amps__free(ctx, U->work.vec2);
    amps__free(ctx, U->work.chunk);
    amps__free(ctx, U->work.row_map);
    amps__free(ctx, U->work.closure);
    amps__free(ctx, U->work.lanes);
    amps__free(ctx, U->work.idx);
    amps__free(ctx, U->work.resid);
    amps_marker_free(ctx, &U->work.mark_n);
    amps_marker_free(ctx, &U->work.mark_N);
    amps__free(ctx, U->sol.x);
    amps__free(ctx, U->sol.react);
    amps__free(ctx, U->guard.ct);
    amps__free(ctx, U->guard.scratch);
    amps__free(ctx, U->watch.idx);
    amps__free(ctx, U->watch.closure);
    amps__free(ctx, U->watch.from_dense);
    amps__free(ctx, U);
}

/* Full symmetric copy (both triangles, sorted columns) of K given as its stype part. */
static amps_status amps__sym_full(amps_ctx *ctx, const amps_csc *A, amps_stype stype, amps_int **Cp, amps_int **Ci,
                                  double **Cx) {
    amps_int n = A->ncol, j, p, *cnt;
    *Cp = AMPS__CAST(amps_int *, amps__calloc(ctx, (size_t)n + 1, sizeof(amps_int)));
    cnt = AMPS__CAST(amps_int *, amps__calloc(ctx, (size_t)n + 1, sizeof(amps_int)));
    *Ci = NULL;
    *Cx = NULL;
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
            (*Ci)[cnt[i]] = j;
            (*Cx)[cnt[i]++] = v; /* entry (j, i) stored in column i */
            if (i != j && stype != AMPS_FULL) {
                (*Ci)[cnt[j]] = i;
                (*Cx)[cnt[j]++] = v;
            }
        }
    amps__free(ctx, cnt);
    return AMPS_OK;
oom:
    amps__free(ctx, cnt);
    amps__free(ctx, *Cp);
    amps__free(ctx, *Ci);
    amps__free(ctx, *Cx);
    *Cp = NULL;
    *Ci = NULL;
    *Cx = NULL;
    return AMPS_ERR_OOM;
}

/* 1 when the full symmetric pattern (Kp, Ki; rows ascending) is made of aligned 3x3 blocks:
   columns 3B, 3B+1, 3B+2 list the same rows, in triples 3C, 3C+1, 3C+2 (n a multiple of 3). */
static int amps__blk3(amps_int n, const amps_int *Kp, const amps_int *Ki) {
    amps_int B, k, r, len;
    if (n % 3 != 0) return 0;
    for (B = 0; B < n / 3; B++) {
        const amps_int *c0 = Ki + Kp[3 * B];
        len = Kp[3 * B + 1] - Kp[3 * B];
        if (len % 3 != 0) return 0;
        for (r = 1; r < 3; r++)
            if (Kp[3 * B + r + 1] - Kp[3 * B + r] != len) return 0;
        for (k = 0; k < len; k += 3)
            if (c0[k] % 3 != 0 || c0[k + 1] != c0[k] + 1 || c0[k + 2] != c0[k] + 2) return 0;
        for (r = 1; r < 3; r++)
            for (k = 0; k < len; k++)
                if (Ki[Kp[3 * B + r] + k] != c0[k]) return 0;
    }
    return 1;
}

/* The first column of each 3x3 block of a pattern amps__blk3 accepted, block row B's blocks from
   Kp[3B] / 9 (Kp[3B] is 9 times the blocks before it); NULL when out of memory. */
static amps_int *amps__blk3_cols(amps_ctx *ctx, amps_int n, const amps_int *Kp, const amps_int *Ki) {
    amps_int B, k, *bc = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)Kp[n] / 9 + 1, sizeof(amps_int)));
    for (B = 0; bc && B < n / 3; B++)
        for (k = Kp[3 * B]; k < Kp[3 * B + 1]; k += 3) bc[Kp[3 * B] / 9 + (k - Kp[3 * B]) / 3] = Ki[k];
    return bc;
}

/* Options of a new engine: opts (NULL: the defaults) with the sizes and rates that are 0 or
   negative replaced by the defaults of amps_update_opts_default. */
static amps_status amps__create_opts(amps_ctx *ctx, const amps_update_opts *opts, amps_update_opts *o) {
    amps_update_opts d;
    amps_update_opts_default(&d);
    *o = opts ? *opts : d;
    if (o->cap_mod <= 0) o->cap_mod = d.cap_mod;
    if (o->cap_new < 0) o->cap_new = 0;
    if (o->cap_pending <= 0) o->cap_pending = d.cap_pending;
    if (!(o->singular_tol >= 0) || o->singular_tol >= 1)
        return amps__err(ctx, AMPS_ERR_ARG, "amps_update_create: singular_tol must be in [0, 1)");
    if (!(o->refactor_ratio > 0)) o->refactor_ratio = d.refactor_ratio;
    if (o->refactor_threads <= 0) o->refactor_threads = d.refactor_threads;
    if (o->refactor_size <= 0) o->refactor_size = d.refactor_size;
    if (o->refactor_every <= 0) o->refactor_every = d.refactor_every;
    if (o->refactor_order.method == AMPS_ORDER_GIVEN)
        o->refactor_order.method = d.refactor_order.method; /* a given perm has the old order */
    o->refactor_order.perm = NULL;
    o->refactor_order.coords = NULL;
    return AMPS_OK;
}

/* Allocates the arrays of U for capacities capu (|U|) and U->cap_N (order); U->n, nthr and the
   pool capacities are set. */
static amps_status amps__create_alloc(amps_ctx *ctx, amps_update *U, amps_int capu) {
    amps_int n = U->n, capN = U->cap_N, j;
    size_t nt = (size_t)U->nthr;
    U->force.f = AMPS__CAST(double *, amps__calloc(ctx, (size_t)capN, sizeof(double)));
    U->sol.x = AMPS__CAST(double *, amps__calloc(ctx, (size_t)capN, sizeof(double)));
    U->aug.pos = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)capN, sizeof(amps_int)));
    U->work.idx = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)(n + capN), sizeof(amps_int)));
    U->force.ct = AMPS__CAST(double *, amps__calloc(ctx, (size_t)n, sizeof(double)));
    U->force.f_ct = AMPS__CAST(double *, amps__calloc(ctx, (size_t)n, sizeof(double)));
    U->base.inv_sqrt_d = AMPS__CAST(double *, amps__malloc(ctx, (size_t)n, sizeof(double)));
    U->force.changed = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)n, sizeof(amps_int)));
    U->work.vec = AMPS__CAST(double *, amps__calloc(ctx, (size_t)n * nt, sizeof(double)));
    U->work.vec2 = AMPS__CAST(double *, amps__malloc(ctx, (size_t)n, sizeof(double)));
    U->work.chunk = AMPS__CAST(double *, amps__malloc(ctx, nt * (size_t)U->work.chunk_rows * AMPS__VB, sizeof(double)));
    U->work.row_map = AMPS__CAST(amps_int *, amps__malloc(ctx, nt * (size_t)n, sizeof(amps_int)));
    U->work.closure = AMPS__CAST(amps_int *, amps__malloc(ctx, nt * (size_t)n, sizeof(amps_int)));
    U->work.lanes = AMPS__CAST(unsigned char *, amps__malloc(ctx, nt * 2 * (size_t)n + 1, 1));
    U->pending.delta =
            AMPS__CAST(amps__pdelta *, amps__malloc(ctx, (size_t)U->pending.cap_delta, sizeof(amps__pdelta)));
    U->pending.con = AMPS__CAST(amps__pcon *, amps__malloc(ctx, (size_t)U->pending.cap_con, sizeof(amps__pcon)));
    U->memo.val = AMPS__CAST(double *, amps__malloc(ctx, U->memo.cap, sizeof(double)));
    U->memo.idx = AMPS__CAST(amps_int *, amps__malloc(ctx, U->memo.cap, sizeof(amps_int)));
    U->delta.col = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)U->delta.cap, sizeof(amps_int)));
    U->delta.val = AMPS__CAST(double *, amps__malloc(ctx, (size_t)U->delta.cap, sizeof(double)));
    U->journal.kinds = AMPS__CAST(amps__kjour *, amps__malloc(ctx, (size_t)U->pending.cap_con, sizeof(amps__kjour)));
    U->work.resid = AMPS__CAST(double *, amps__malloc(ctx, 2 * (size_t)capN, sizeof(double)));
    U->guard.scratch = AMPS__CAST(double *, amps__malloc(ctx, 2 * (size_t)capN, sizeof(double)));
    U->guard.ct = AMPS__CAST(double *, amps__malloc(ctx, (size_t)n, sizeof(double)));
    if (!U->force.f || !U->sol.x || !U->aug.pos || !U->work.idx || !U->force.ct || !U->force.f_ct ||
        !U->base.inv_sqrt_d || !U->force.changed || !U->work.vec || !U->work.vec2 || !U->work.chunk ||
        !U->work.row_map || !U->work.closure || !U->work.lanes || !U->pending.delta || !U->pending.con ||
        !U->memo.val || !U->memo.idx || !U->delta.col || !U->delta.val || !U->journal.kinds || !U->work.resid ||
        !U->guard.scratch || !U->guard.ct)
        return AMPS_ERR_OOM;
    if (amps_marker_init(ctx, &U->work.mark_n, n > 0 ? n : 1) ||
        amps_marker_init(ctx, &U->work.mark_N, capN > 0 ? capN : 1))
        return AMPS_ERR_OOM;
    U->lu.G = AMPS__CAST(double *, amps__malloc(ctx, 1, sizeof(double)));
    U->lu.LU = AMPS__CAST(double *, amps__malloc(ctx, 1, sizeof(double)));
    if (!U->lu.G || !U->lu.LU) return AMPS_ERR_OOM;
    if (amps__grow_u(ctx, U, capu)) return AMPS_ERR_OOM;
    for (j = 0; j < capN; j++) U->aug.pos[j] = -1;
    for (j = 0; j < n * U->nthr; j++) U->work.row_map[j] = -1;
    return AMPS_OK;
}

/* The mixed backward error omega_d = ||b - K-bar x||_2 / || |K-bar| |x| + |b| ||_2 that a direct
   solve x = K-bar^{-1} b with the base factor (L, D, L^T, double residual) reaches on this matrix,
   for b = K-bar x_p with x_p pseudo-random in [-1, 1): the accuracy a fresh factorization of the
   base gives, the yardstick of amps__accuracy. One solve and two products (work.resid,
   guard.scratch, guard.ct as workspace). */
static double amps__direct_omega(amps_update *U) {
    const amps_factor *F = U->F;
    amps_int n = U->n, j, p, k;
    double *xp = U->guard.scratch, *b = U->guard.scratch + U->cap_N, *x = U->work.resid, *ax = U->work.resid + U->cap_N;
    double *ct = U->guard.ct, num = 0, den = 0;
    for (j = 0; j < n; j++) {
        unsigned long h = ((unsigned long)j * 2654435761UL + 12345UL) & 0xffffUL;
        xp[j] = (double)h / 32768.0 - 1.0;
        b[j] = 0.0;
    }
    for (j = 0; j < n; j++)
        for (p = U->base.Kp[j]; p < U->base.Kp[j + 1]; p++) b[U->base.Ki[p]] += U->base.Kx[p] * xp[j];
    for (k = 0; k < n; k++) ct[k] = b[F->perm[k]];
    amps_lsolve(F, ct);
    amps_dsolve(F, ct);
    amps_ltsolve(F, ct);
    for (k = 0; k < n; k++) x[F->perm[k]] = ct[k];
    for (j = 0; j < n; j++) xp[j] = ax[j] = 0.0;
    for (j = 0; j < n; j++)
        for (p = U->base.Kp[j]; p < U->base.Kp[j + 1]; p++) {
            double q = U->base.Kx[p] * x[j];
            xp[U->base.Ki[p]] += q;
            ax[U->base.Ki[p]] += fabs(q);
        }
    for (j = 0; j < n; j++) {
        num += (b[j] - xp[j]) * (b[j] - xp[j]);
        den += (ax[j] + fabs(b[j])) * (ax[j] + fabs(b[j]));
    }
    return num > 0 && den > 0 ? sqrt(num / den) : 0.0;
}

/* amps_update_create; cond_j >= 0: the column at which the base's condition estimate starts
   (amps__condest; a re-factorization passes the previous base's). */
static amps_update *amps__update_new(amps_ctx *ctx, const amps_csc *K, amps_stype stype, const amps_factor *F,
                                     const amps_update_opts *opts, amps_int cond_j) {
    amps_update_opts o;
    amps_update *U;
    amps_int n, j, p;
    double s = 0;
    if (!K || !F) {
        amps__err(ctx, AMPS_ERR_ARG, "amps_update_create: NULL matrix or factor");
        return NULL;
    }
    if (!F->is_numeric) {
        amps__err(ctx, AMPS_ERR_STATE, "amps_update_create: the factor has no numeric values (call amps_factorize)");
        return NULL;
    }
    if (K->ncol != F->n || K->nrow != F->n) {
        amps__err(ctx, AMPS_ERR_ARG, "amps_update_create: K is %ldx%ld but the factor has order %ld", (long)K->nrow,
                  (long)K->ncol, (long)F->n);
        return NULL;
    }
    if (amps_csc_check(ctx, K, stype) != AMPS_OK) return NULL;
    if (amps__create_opts(ctx, opts, &o) != AMPS_OK) return NULL;
    n = F->n;
    U = AMPS__CAST(amps_update *, amps__calloc(ctx, 1, sizeof(amps_update)));
    if (!U) return NULL;
    U->F = F;
    U->form = o.formulation;
    U->singular_tol = o.singular_tol;
    U->grow = o.grow;
    U->refine = o.refine;
    U->xs_from_dense = o.xs_from_dense;
    U->guard.tol = o.guard_tol;
    U->refac.opts = o;
    U->n = n;
    U->N = n;
    U->cap_N = n + o.cap_new;
    U->nthr = amps__par_slots(ctx);
    U->nbuf = U->nthr;
    U->pool = amps__pool_new(ctx);
    U->par = amps__par_of(ctx, &U->bo, U->pool);
    if (amps__sym_full(ctx, K, stype, &U->base.Kp, &U->base.Ki, &U->base.Kx)) goto fail;
    U->memo.cap = o.cap_vpool > 0 ? (size_t)o.cap_vpool : (size_t)o.cap_mod * (size_t)(F->height > 0 ? F->height : 1);
    U->delta.cap = o.cap_delta > 0 ? o.cap_delta : 96 * o.cap_mod;
    U->pending.cap_delta = o.cap_pending;
    U->pending.cap_con = o.cap_pending;
    U->work.chunk_rows = F->height > 0 && (double)F->height * AMPS__VB < (double)n ? F->height * AMPS__VB : n;
    if (amps__create_alloc(ctx, U, o.cap_mod) != AMPS_OK) goto fail;
    for (j = 0; j < n; j++) U->base.inv_sqrt_d[j] = 1.0 / sqrt(F->D[j]);
    /* sigma: scale of K-bar's identity block; mean of the diagonal of K */
    for (j = 0; j < n; j++)
        for (p = U->base.Kp[j]; p < U->base.Kp[j + 1]; p++)
            if (U->base.Ki[p] == j) s += U->base.Kx[p];
    U->sigma = n > 0 && s > 0 ? s / (double)n : 1.0;
    U->base.blk3 = amps__blk3(n, U->base.Kp, U->base.Ki);
    if (U->base.blk3 && !(U->base.bcol = amps__blk3_cols(ctx, n, U->base.Kp, U->base.Ki))) goto fail;
    U->guard.knorm = U->sigma;
    for (j = 0; j < n; j++) {
        double sa = 0;
        for (p = U->base.Kp[j]; p < U->base.Kp[j + 1]; p++) sa += fabs(U->base.Kx[p]);
        if (sa > U->guard.knorm) U->guard.knorm = sa;
    }
    U->guard.omega_d = amps__direct_omega(U);
    U->guard.cond_j = -1;
    if (o.refine_tol > 0 && n > 0) { /* the forward refinement's yardstick: about 11 solves */
        amps_csc Kb;
        amps_ctx c1; /* serial, silent: this may run on the re-factorization's worker */
        double *cw = AMPS__CAST(double *, amps__malloc(ctx, 3 * (size_t)n, sizeof(double)));
        if (!cw) goto fail;
        amps_ctx_init(&c1);
        c1.nthreads = 1;
        Kb.nrow = Kb.ncol = n;
        Kb.p = U->base.Kp;
        Kb.i = U->base.Ki;
        Kb.x = U->base.Kx;
        U->guard.cond_j = cond_j;
        if (amps__condest(&c1, &Kb, AMPS_FULL, F, cw, &U->guard.cond, &U->guard.cond_j) != AMPS_OK) {
            U->guard.cond = 0;
            U->guard.cond_j = -1;
        }
        amps__free(ctx, cw);
    }
    U->stats.base_cond = U->guard.cond;
    U->sol.x_stale = U->sol.react_stale = U->sol.watched_stale = 1;
    U->stats.dim = n;
    return U;
fail:
    if (ctx && ctx->status != AMPS_ERR_OOM) amps__err(ctx, AMPS_ERR_OOM, "amps_update_create: out of memory");
    amps_update_free(ctx, U);
    return NULL;
}

AMPS_API amps_update *amps_update_create(amps_ctx *ctx, const amps_csc *K, amps_stype stype, const amps_factor *F,
                                         const amps_update_opts *opts) {
    return amps__update_new(ctx, K, stype, F, opts, -1);
}

AMPS_API amps_int amps_update_dim(const amps_update *U) { return U ? U->N + U->pending.n_dofs : 0; }

/* ---- recording changes ---- */

static amps_status amps__chk_idx(amps_ctx *ctx, const amps_update *U, const char *fn, amps_int m, const amps_int *idx,
                                 const double *val, int nodup, amps_marker *mk) {
    amps_int k, N = U->N + U->pending.n_dofs;
    if (m < 0) return amps__err(ctx, AMPS_ERR_ARG, "%s: negative count %ld", fn, (long)m);
    if (m > 0 && !idx) return amps__err(ctx, AMPS_ERR_ARG, "%s: NULL index array", fn);
    if (nodup) amps_marker_next(mk);
    for (k = 0; k < m; k++) {
        if (idx[k] < 0 || idx[k] >= N)
            return amps__err(ctx, AMPS_ERR_INDEX, "%s: index %ld (entry %ld) out of range [0, %ld)", fn, (long)idx[k],
                             (long)k, (long)N);
        if (val && !amps__isfinite(val[k]))
            return amps__err(ctx, AMPS_ERR_VALUE, "%s: value of entry %ld (index %ld) is not finite", fn, (long)k,
                             (long)idx[k]);
        if (nodup) {
            if (mk->mark[idx[k]] == mk->stamp)
                return amps__err(ctx, AMPS_ERR_ARG, "%s: index %ld given twice", fn, (long)idx[k]);
            mk->mark[idx[k]] = mk->stamp;
        }
    }
    return AMPS_OK;
}

/* Index i (< N) is constrained in the committed system. */
static int amps__is_con(const amps_update *U, amps_int i) {
    amps_int a = U->aug.pos[i];
    return a >= 0 && a < U->aug.size && U->aug.idx[a] == i && (U->aug.kind[a] & AMPS__UCON);
}

static amps_status amps__cjob_busy(amps_ctx *ctx, const char *fn) {
    return amps__err(ctx, AMPS_ERR_STATE,
                     "%s: a two-phase commit is in progress (only moved constraints and forces until its end)", fn);
}

AMPS_API amps_status amps_update_add_dofs(amps_ctx *ctx, amps_update *U, amps_int k, amps_int *first) {
    amps_int i, base;
    amps_status s;
    if (!U || k < 0)
        return amps__err(ctx, AMPS_ERR_ARG, "amps_update_add_dofs: %s", U ? "negative count" : "NULL engine");
    if (k > 0 && U->cjob.state) return amps__cjob_busy(ctx, "amps_update_add_dofs");
    if ((s = amps__need_N(ctx, U, k)) != AMPS_OK) return s;
    if ((s = amps__need_pending(ctx, U, k, 0)) != AMPS_OK) return s;
    base = U->N + U->pending.n_dofs;
    for (i = 0; i < k; i++) {
        /* K-bar has sigma on the new diagonal; the recorded -sigma makes the new row zero */
        U->pending.delta[U->pending.n_delta].r = base + i;
        U->pending.delta[U->pending.n_delta].c = base + i;
        U->pending.delta[U->pending.n_delta].v = -U->sigma;
        U->pending.n_delta++;
        U->force.f[base + i] = 0;
    }
    U->pending.n_dofs += k;
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

AMPS_API amps_status amps_update_add(amps_ctx *ctx, amps_update *U, amps_int nz, const amps_int *r, const amps_int *c,
                                     const double *v) {
    amps_int k, N, start;
    amps_status s;
    if (!U) return amps__err(ctx, AMPS_ERR_ARG, "amps_update_add: NULL engine");
    if (nz < 0 || (nz > 0 && (!r || !c || !v)))
        return amps__err(ctx, AMPS_ERR_ARG, "amps_update_add: bad count or NULL array");
    if (nz > 0 && U->cjob.state) return amps__cjob_busy(ctx, "amps_update_add");
    N = U->N + U->pending.n_dofs;
    for (k = 0; k < nz; k++) {
        if (r[k] < 0 || r[k] >= N || c[k] < 0 || c[k] >= N)
            return amps__err(ctx, AMPS_ERR_INDEX, "amps_update_add: entry %ld (%ld, %ld) out of range [0, %ld)",
                             (long)k, (long)r[k], (long)c[k], (long)N);
        if (!amps__isfinite(v[k]))
            return amps__err(ctx, AMPS_ERR_VALUE, "amps_update_add: value of entry %ld (%ld, %ld) is not finite",
                             (long)k, (long)r[k], (long)c[k]);
    }
    if ((s = amps__need_pending(ctx, U, nz, 0)) != AMPS_OK) return s;
    start = U->pending.n_delta;
    for (k = 0; k < nz; k++) {
        U->pending.delta[start + k].r = r[k];
        U->pending.delta[start + k].c = c[k];
        U->pending.delta[start + k].v = v[k];
    }
    amps__sort(U->pending.delta + start, (size_t)nz, sizeof(amps__pdelta), amps__pd_cmp);
    for (k = start + 1; k < start + nz; k++)
        if (amps__pd_cmp(U->pending.delta + k - 1, U->pending.delta + k) == 0)
            return amps__err(ctx, AMPS_ERR_ARG, "amps_update_add: entry (%ld, %ld) given twice",
                             (long)U->pending.delta[k].r, (long)U->pending.delta[k].c);
    U->pending.n_delta = start + nz;
    return AMPS_OK;
}

/* Current value K^[r, c] including recorded changes (r, c < N + pending.n_dofs). */
static double amps__cur_entry(const amps_update *U, amps_int r, amps_int c) {
    double v = 0;
    amps_int p, k, a;
    if (r < U->n && c < U->n) {
        for (p = U->base.Kp[c]; p < U->base.Kp[c + 1]; p++)
            if (U->base.Ki[p] == r) {
                v = U->base.Kx[p];
                break;
            }
    } else if (r == c) v = U->sigma;
    a = r < U->N ? U->aug.pos[r] : -1;
    if (a >= 0 && (c < U->N ? U->aug.pos[c] : -1) >= 0) {
        amps_int b = U->aug.pos[c];
        for (k = 0; k < U->delta.row_len[a]; k++)
            if (U->delta.col[U->delta.row_start[a] + k] == b) {
                v += U->delta.val[U->delta.row_start[a] + k];
                break;
            }
    }
    for (k = 0; k < U->pending.n_delta; k++)
        if ((U->pending.delta[k].r == r && U->pending.delta[k].c == c) ||
            (U->pending.delta[k].r == c && U->pending.delta[k].c == r))
            v += U->pending.delta[k].v;
    return v;
}

/* Arguments of amps_update_set_rows: indices, values, no column twice in a row, and agreement
   where two given rows meet. The given rows are left marked in work.mark_N. */
static amps_status amps__set_rows_check(amps_ctx *ctx, amps_update *U, amps_int nrow, const amps_int *rows,
                                        const amps_int *cp, const amps_int *ci, const double *cx) {
    const amps_marker *mk = &U->work.mark_N;
    amps_int k, j, q, N;
    amps_status s;
    if (nrow < 0 || (nrow > 0 && (!rows || !cp)))
        return amps__err(ctx, AMPS_ERR_ARG, "amps_update_set_rows: bad count or NULL array");
    if ((s = amps__chk_idx(ctx, U, "amps_update_set_rows", nrow, rows, NULL, 1, &U->work.mark_N)) != AMPS_OK) return s;
    N = U->N + U->pending.n_dofs;
    if (cp[0] != 0) return amps__err(ctx, AMPS_ERR_ARG, "amps_update_set_rows: cp[0] must be 0");
    for (k = 0; k < nrow; k++) {
        if (cp[k + 1] < cp[k])
            return amps__err(ctx, AMPS_ERR_ARG, "amps_update_set_rows: cp decreases at row %ld", (long)k);
        for (j = cp[k]; j < cp[k + 1]; j++) {
            if (ci[j] < 0 || ci[j] >= N)
                return amps__err(ctx, AMPS_ERR_INDEX, "amps_update_set_rows: row %ld, column %ld out of range [0, %ld)",
                                 (long)rows[k], (long)ci[j], (long)N);
            if (!amps__isfinite(cx[j]))
                return amps__err(ctx, AMPS_ERR_VALUE, "amps_update_set_rows: row %ld, column %ld: value not finite",
                                 (long)rows[k], (long)ci[j]);
            for (q = cp[k]; q < j; q++)
                if (ci[q] == ci[j])
                    return amps__err(ctx, AMPS_ERR_ARG, "amps_update_set_rows: row %ld lists column %ld twice",
                                     (long)rows[k], (long)ci[j]);
        }
    }
    /* symmetry where two given rows meet: row a's entry at b must equal row b's entry at a */
    for (k = 0; k < nrow; k++)
        for (j = cp[k]; j < cp[k + 1]; j++)
            if (mk->mark[ci[j]] == mk->stamp) {
                amps_int kk, b = ci[j];
                double vb = 0;
                for (kk = 0; kk < nrow && rows[kk] != b; kk++) {}
                for (q = cp[kk]; q < cp[kk + 1]; q++)
                    if (ci[q] == rows[k]) {
                        vb = cx[q];
                        break;
                    }
                if (fabs(vb - cx[j]) > 1e-12 * (fabs(vb) + fabs(cx[j])))
                    return amps__err(ctx, AMPS_ERR_ARG,
                                     "amps_update_set_rows: rows %ld and %ld disagree at their crossing (%g vs %g)",
                                     (long)rows[k], (long)b, cx[j], vb);
            }
    return AMPS_OK;
}

/* Columns of row r of the current K^ (base pattern, Delta row, the changes recorded before
   pending entry `start`) and the new columns ci[0..nc-1], ascending without repeats, into iw;
   returns their count. a: r's U position or -1. */
static amps_int amps__row_columns(const amps_update *U, amps_int r, amps_int a, amps_int start, const amps_int *ci,
                                  amps_int nc, amps_int *iw) {
    amps_int q, cnt = 0, m = 0;
    if (r < U->n)
        for (q = U->base.Kp[r]; q < U->base.Kp[r + 1]; q++) iw[cnt++] = U->base.Ki[q];
    else iw[cnt++] = r;
    if (a >= 0)
        for (q = 0; q < U->delta.row_len[a]; q++) iw[cnt++] = U->aug.idx[U->delta.col[U->delta.row_start[a] + q]];
    for (q = 0; q < start; q++) {
        if (U->pending.delta[q].r == r) iw[cnt++] = U->pending.delta[q].c;
        else if (U->pending.delta[q].c == r) iw[cnt++] = U->pending.delta[q].r;
    }
    for (q = 0; q < nc; q++) iw[cnt++] = ci[q];
    amps__sort(iw, (size_t)cnt, sizeof(amps_int), amps__int_cmp);
    for (q = 0; q < cnt; q++)
        if (m == 0 || iw[m - 1] != iw[q]) iw[m++] = iw[q];
    return m;
}

AMPS_API amps_status amps_update_set_rows(amps_ctx *ctx, amps_update *U, amps_int nrow, const amps_int *rows,
                                          const amps_int *cp, const amps_int *ci, const double *cx) {
    const amps_marker *mk;
    amps_int k, j, q, start, *iw;
    amps_status s;
    if (!U) return amps__err(ctx, AMPS_ERR_ARG, "amps_update_set_rows: NULL engine");
    if (U->cjob.state) return amps__cjob_busy(ctx, "amps_update_set_rows");
    if ((s = amps__set_rows_check(ctx, U, nrow, rows, cp, ci, cx)) != AMPS_OK) return s;
    /* the changes: for each row r, every column c of the current or the new row gets
       new - current; a pair of two given rows is recorded once (from the smaller row) */
    mk = &U->work.mark_N;
    start = U->pending.n_delta;
    iw = U->work.idx;
    for (k = 0; k < nrow; k++) {
        amps_int r = rows[k], a, cnt;
        a = r < U->N ? U->aug.pos[r] : -1;
        if ((r < U->n ? U->base.Kp[r + 1] - U->base.Kp[r] : 1) + (a >= 0 ? U->delta.row_len[a] : 0) +
                    U->pending.n_delta + (cp[k + 1] - cp[k]) >
            U->n + U->cap_N) {
            U->pending.n_delta = start;
            return amps__err(ctx, AMPS_ERR_CAPACITY, "amps_update_set_rows: too many changes recorded; commit first");
        }
        cnt = amps__row_columns(U, r, a, start, ci + cp[k], cp[k + 1] - cp[k], iw);
        if ((s = amps__need_pending(ctx, U, cnt, 0)) != AMPS_OK) {
            U->pending.n_delta = start;
            return s;
        }
        for (q = 0; q < cnt; q++) {
            amps_int c = iw[q];
            double nv = 0, d;
            amps__pdelta *e;
            if (mk->mark[c] == mk->stamp && c < r) continue; /* recorded from row c */
            for (j = cp[k]; j < cp[k + 1]; j++)
                if (ci[j] == c) {
                    nv = cx[j];
                    break;
                }
            d = nv - amps__cur_entry(U, r, c);
            if (d == 0) continue;
            e = U->pending.delta + U->pending.n_delta++;
            e->r = r;
            e->c = c;
            e->v = d;
        }
    }
    return AMPS_OK;
}

/* Records constraint changes: x[idx[k]] = val[k], or releases (val NULL). */
static amps_status amps__record_con(amps_ctx *ctx, amps_update *U, const char *fn, amps_int m, const amps_int *idx,
                                    const double *val, int release) {
    amps_int k;
    amps_status s;
    if (!U) return amps__err(ctx, AMPS_ERR_ARG, "%s: NULL engine", fn);
    if (!release && m > 0 && !val) return amps__err(ctx, AMPS_ERR_ARG, "%s: NULL values", fn);
    if ((s = amps__chk_idx(ctx, U, fn, m, idx, release ? NULL : val, 1, &U->work.mark_N)) != AMPS_OK) return s;
    for (k = 0; k < m && U->cjob.state; k++) /* during a two-phase commit: moves of constraints only */
        if (release || idx[k] >= U->N || !amps__is_con(U, idx[k])) return amps__cjob_busy(ctx, fn);
    if ((s = amps__need_pending(ctx, U, 0, m)) != AMPS_OK) return s;
    for (k = 0; k < m; k++) {
        U->pending.con[U->pending.n_con].i = idx[k];
        U->pending.con[U->pending.n_con].release = release;
        U->pending.con[U->pending.n_con].v = release ? 0.0 : val[k];
        U->pending.n_con++;
    }
    return AMPS_OK;
}

AMPS_API amps_status amps_update_constrain(amps_ctx *ctx, amps_update *U, amps_int m, const amps_int *idx,
                                           const double *val) {
    return amps__record_con(ctx, U, "amps_update_constrain", m, idx, val, 0);
}

AMPS_API amps_status amps_update_release(amps_ctx *ctx, amps_update *U, amps_int m, const amps_int *idx) {
    return amps__record_con(ctx, U, "amps_update_release", m, idx, NULL, 1);
}

AMPS_API amps_status amps_update_set_force(amps_ctx *ctx, amps_update *U, amps_int m, const amps_int *idx,
                                           const double *val) {
    amps_int k;
    amps_status s;
    if (!U) return amps__err(ctx, AMPS_ERR_ARG, "amps_update_set_force: NULL engine");
    if (m > 0 && !val) return amps__err(ctx, AMPS_ERR_ARG, "amps_update_set_force: NULL values");
    if ((s = amps__chk_idx(ctx, U, "amps_update_set_force", m, idx, val, 1, &U->work.mark_N)) != AMPS_OK) return s;
    for (k = 0; k < m; k++) {
        amps_int i = idx[k];
        if (U->force.f[i] == val[k]) continue;
        /* base forces reach ct at the next solve, from the difference f - f_ct */
        if (i < U->n) {
            if (U->force.n_changed < U->n) U->force.changed[U->force.n_changed++] = i;
            else U->force.changed_all = 1;
        }
        U->force.f[i] = val[k];
    }
    if (m > 0) U->sol.x_stale = U->sol.react_stale = U->sol.watched_stale = 1;
    return AMPS_OK;
}

/* ---- Steps 1-2: memoized columns of W = D^{-1/2} L^{-1} and entries of G = W^T W ---- */

static amps_int amps__path_len(const amps_factor *F, amps_int p) {
    amps_int len = 0;
    for (; p != -1; p = F->parent[p]) len++;
    return len;
}

/* Row width of a chunk of m <= AMPS__VB right-hand sides (zero padded): 4, 8, 12 or 16. */
static amps_int amps__width(amps_int m) { return m <= 4 ? 4 : (m <= 8 ? 8 : (m <= 12 ? 12 : AMPS__VB)); }

/* X := L^{-1} X restricted to the ascending node list clo[0..nc-1] (closed under the elimination
   tree's parents), X row-major with row stride ld, row t for node clo[t], lmap: node -> row. The
   union enters a column group c0..ke at some c and then holds c..ke (a chain) in consecutive rows.
   The group goes by blocks of b = 4 (2, 1) columns o..o+b-1: the small triangle inside the block,
   then X(r, 0:W) -= sum_i L(r, o+i) X(o+i, 0:W) for the rows r after the block, first those of the
   group (consecutive) then its shared rows S, so each row of X is loaded and stored once per block.
   Xo and X point at the block's first row and at row 0, both at the block's first lane. The
   block's rows are copied to a local array (no aliasing: the row loop vectorizes). */
AMPS__KERNEL void amps__wblock_body(int W, const double *const *sl, amps_int b, amps_int ng, const amps_int *S,
                                    amps_int ns, const amps_int *lmap, size_t ld, double *Xo, double *X) {
    double a[4][AMPS__VB];
    amps_int i, q, j;
    for (i = 1; i < b; i++) { /* triangle: row o+i from o..o+i-1 */
        amps_int k;
        for (k = 0; k < i; k++) {
            double l = sl[k][i - b]; /* L(o+i, o+k) */
            AMPS__UNROLL
            for (j = 0; j < W; j++) Xo[(size_t)i * ld + j] -= l * Xo[(size_t)k * ld + j];
        }
    }
    for (i = 0; i < b; i++) memcpy(a[i], Xo + (size_t)i * ld, sizeof(double) * (size_t)W);
#define AMPS__WROW(q) (q < ng ? Xo + (size_t)(b + q) * ld : X + (size_t)lmap[S[q - ng]] * ld)
    if (b == 4) {
        const double *s0 = sl[0], *s1 = sl[1], *s2 = sl[2], *s3 = sl[3];
        for (q = 0; q < ng + ns; q++) {
            double l0 = s0[q], l1 = s1[q], l2 = s2[q], l3 = s3[q], *xr = AMPS__WROW(q);
            AMPS__UNROLL
            for (j = 0; j < W; j++) xr[j] -= (l0 * a[0][j] + l1 * a[1][j]) + (l2 * a[2][j] + l3 * a[3][j]);
        }
    } else if (b == 2) {
        const double *s0 = sl[0], *s1 = sl[1];
        for (q = 0; q < ng + ns; q++) {
            double l0 = s0[q], l1 = s1[q], *xr = AMPS__WROW(q);
            AMPS__UNROLL
            for (j = 0; j < W; j++) xr[j] -= l0 * a[0][j] + l1 * a[1][j];
        }
    } else {
        const double *s0 = sl[0];
        for (q = 0; q < ng + ns; q++) {
            double l0 = s0[q], *xr = AMPS__WROW(q);
            AMPS__UNROLL
            for (j = 0; j < W; j++) xr[j] -= l0 * a[0][j];
        }
    }
#undef AMPS__WROW
}
/* Instantiations of amps__wblock_body per width W (ATTR: a target attribute, SUF: a name suffix). */
#define AMPS__WBLOCK(W, ATTR, SUF)                                                                                \
    static ATTR void amps__wblock##W##SUF(const double *const *sl, amps_int b, amps_int ng, const amps_int *S,   \
                                          amps_int ns, const amps_int *lmap, size_t ld, double *Xo, double *X) { \
        amps__wblock_body(W, sl, b, ng, S, ns, lmap, ld, Xo, X);                                                 \
    }
typedef void (*amps__wblock_fn)(const double *const *, amps_int, amps_int, const amps_int *, amps_int,
                                const amps_int *, size_t, double *, double *);
AMPS__WBLOCK(4, , )
AMPS__WBLOCK(8, , )
AMPS__WBLOCK(12, , )
AMPS__WBLOCK(16, , )
static const amps__wblock_fn amps__wblocks[4] = {amps__wblock4, amps__wblock8, amps__wblock12, amps__wblock16};
#ifdef AMPS__AVX2 /* the same kernels compiled for AVX2 (4 lanes to a vector; the same operations per lane) */
AMPS__WBLOCK(4, AMPS__TARGET_AVX2, _avx2)
AMPS__WBLOCK(8, AMPS__TARGET_AVX2, _avx2)
AMPS__WBLOCK(12, AMPS__TARGET_AVX2, _avx2)
AMPS__WBLOCK(16, AMPS__TARGET_AVX2, _avx2)
static const amps__wblock_fn amps__wblocks_avx2[4] = {amps__wblock4_avx2, amps__wblock8_avx2, amps__wblock12_avx2,
                                                      amps__wblock16_avx2};
#endif
#undef AMPS__WBLOCK

/* amps__wblock_body on the lanes [lo, lo + W) of X (row stride mw), W = 4, 8, 12 or 16; avx2: the
   AVX2 build of the kernels (the factor's amps__fpriv.avx2). */
static void amps__wblock(int avx2, amps_int W, const double *const *sl, amps_int b, amps_int ng, const amps_int *S,
                         amps_int ns, const amps_int *lmap, amps_int mw, amps_int lo, double *Xo, double *X) {
    amps__wblock_fn fn = amps__wblocks[W / 4 - 1];
#ifdef AMPS__AVX2
    if (avx2) fn = amps__wblocks_avx2[W / 4 - 1];
#else
    (void)avx2;
#endif
    fn(sl, b, ng, S, ns, lmap, (size_t)mw, Xo + lo, X + lo);
}

/* X := L^{-1} X on the union clo[0..nc-1] (see amps__wblock_body), X with mw lanes. lanes[2t] and
   lanes[2t+1] bound the lanes of row t that can be nonzero (those of the columns whose path holds
   clo[t]; every other lane of the row stays zero): a block updates only the lanes of its top
   column, which holds those of the block's other columns, in the narrowest kernel covering them.
   Each lane sees the same operations as at full width. */
static void amps__wsolve(const amps_factor *F, const amps_int *clo, amps_int nc, const amps_int *lmap,
                         const unsigned char *lanes, amps_int mw, double *X) {
    const amps__fpriv *P = AMPS__CAST(const amps__fpriv *, F->priv);
    const amps_int *Lp = F->Lp;
    amps_int t, c, ke, o, b, i;
    int avx2 = P ? P->avx2 : 0; /* amps_factorize's choice */
    for (t = 0; t < nc; t += ke - c + 1) {
        const amps_int *S;
        amps_int ns;
        c = clo[t];
        ke = P ? P->gs[P->cgrp[c] + 1] - 1 : c;
        AMPS_ASSERT(t + ke - c < nc && clo[t + ke - c] == ke);
        S = F->Li + Lp[ke];
        ns = Lp[ke + 1] - Lp[ke];
        for (o = c; o <= ke; o += b) {
            const double *sl[4];
            amps_int top, lo, w;
            b = ke + 1 - o >= 4 ? 4 : (ke + 1 - o >= 2 ? 2 : 1);
            /* column o+i: rows o+i+1..ke, then S; sl[i] starts at row o+b */
            for (i = 0; i < b; i++) sl[i] = F->Lx + Lp[o + i] + (b - 1 - i);
            top = t + o - c + b - 1;
            lo = lanes[2 * top];
            w = amps__width(lanes[2 * top + 1] - lo + 1);
            if (lo > mw - w) lo = mw - w;
            amps__wblock(avx2, w, sl, b, ke + 1 - o - b, S, ns, lmap, mw, lo, X + (size_t)(t + o - c) * (size_t)mw, X);
        }
    }
}

typedef struct amps__wcjob {
    amps_update *U;
    const amps_int *list;
    amps_int nb, csize;
} amps__wcjob;

/* Chunks [b, e) of amps__wcols. */
static void amps__wc_chunks(amps_int b, amps_int e, int th, void *arg) {
    amps__wcjob *wj = AMPS__CAST(amps__wcjob *, arg);
    amps_update *U = wj->U;
    const amps_factor *F = U->F;
    const amps_int *list = wj->list;
    amps_int nb = wj->nb, csize = wj->csize, ch;
    for (ch = b; ch < e; ch++) {
        double *X = U->work.chunk + (size_t)th * (size_t)U->work.chunk_rows * AMPS__VB;
        amps_int *lmap = U->work.row_map + (size_t)th * (size_t)U->n,
                 *clo = U->work.closure + (size_t)th * (size_t)U->n;
        unsigned char *lanes = U->work.lanes + (size_t)th * 2 * (size_t)U->n;
        amps_int j0 = ch * csize, m = nb - j0 < csize ? nb - j0 : csize, nc = 0, j, t, k, mw;
        /* union of the root paths, ascending */
        for (j = 0; j < m; j++)
            for (k = F->iperm[U->aug.idx[list[j0 + j]]]; k != -1 && lmap[k] < 0; k = F->parent[k]) {
                lmap[k] = 0;
                clo[nc++] = k;
            }
        amps__sort(clo, (size_t)nc, sizeof(amps_int), amps__int_cmp);
        for (t = 0; t < nc; t++) {
            lmap[clo[t]] = t;
            lanes[2 * t] = (unsigned char)(AMPS__VB - 1);
            lanes[2 * t + 1] = 0;
        }
        mw = amps__width(m);
        memset(X, 0, sizeof(double) * (size_t)nc * (size_t)mw);
        for (j = 0; j < m; j++) { /* lane j: its unit entry, its bounds up the tree (parents come later) */
            t = lmap[F->iperm[U->aug.idx[list[j0 + j]]]];
            X[(size_t)t * (size_t)mw + (size_t)j] = 1.0;
            if (lanes[2 * t] > j) lanes[2 * t] = (unsigned char)j;
            if (lanes[2 * t + 1] < j) lanes[2 * t + 1] = (unsigned char)j;
        }
        for (t = 0; t < nc; t++) {
            amps_int p = F->parent[clo[t]], tp;
            if (p == -1) continue;
            tp = lmap[p];
            if (lanes[2 * tp] > lanes[2 * t]) lanes[2 * tp] = lanes[2 * t];
            if (lanes[2 * tp + 1] < lanes[2 * t + 1]) lanes[2 * tp + 1] = lanes[2 * t + 1];
        }
        /* X := L^{-1} X on the union, each block on the lanes its columns can reach */
        amps__wsolve(F, clo, nc, lmap, lanes, mw, X);
        /* gather each column along its own path, scaled by D^{-1/2} */
        for (j = 0; j < m; j++) {
            amps_int aa = list[j0 + j], len = 0;
            double *wv = U->memo.val + U->memo.off[aa];
            amps_int *wi = U->memo.idx + U->memo.off[aa];
            for (k = F->iperm[U->aug.idx[aa]]; k != -1; k = F->parent[k]) {
                wi[len] = k;
                wv[len] = X[(size_t)lmap[k] * (size_t)mw + (size_t)j] * U->base.inv_sqrt_d[k];
                len++;
            }
        }
        for (t = 0; t < nc; t++) lmap[clo[t]] = -1;
    }
}

/* W columns (W = D^{-1/2} L^{-1} e_p on the root path of p, ascending) of the U positions
   list[0..nb-1], written at memo.off/memo.len. The columns are split into chunks of at most AMPS__VB,
   one chunk per participant at a time; a chunk is one forward solve over the union of its paths
   (ascending = topological), X(t, j) row-major over the chunk, so each column of L on the
   union is read once per chunk. The rows of L(:, k) lie on the path of k, so no solve leaves
   the union; a block of L's columns updates only the lanes its columns reach (amps__wsolve).
   list: by ascending factor position (amps__step1_list). Workspace per slot: work.chunk
   (chunk_rows * AMPS__VB), work.row_map (n, -1 outside use), work.closure (n), work.lanes (2n). */
static void amps__wcols(amps_update *U, const amps_int *list, amps_int nb) {
    amps_int nchunk, csize;
    amps__wcjob wj;
    if (nb <= 0) return;
    csize = AMPS__VB;
    nchunk = (nb + csize - 1) / csize;
    wj.U = U;
    wj.list = list;
    wj.nb = nb;
    wj.csize = csize;
    amps__par_for(&U->par, nchunk > 1 ? U->nthr : 1, nchunk, 1, amps__wc_chunks, &wj);
}

/* acc(0:W) = sum over the common suffix of the root path (wi, wv, len) and the union mapped by
   lmap of wv[t] X(lmap[wi[t]], 0:W): the union is closed under parents, so the path's nodes in
   it are a suffix (found by bisection). Summed upwards, as the path is stored. */
AMPS__KERNEL void amps__gscan_body(int W, const amps_int *wi, const double *wv, amps_int len, const amps_int *lmap,
                                   const double *X, double *acc) {
    double a[AMPS__VB]; /* fully unrolled: the accumulators live in registers */
    amps_int t = 0, hi = len;
    int j;
    AMPS__UNROLL
    for (j = 0; j < W; j++) a[j] = 0;
    while (t < hi) { /* the suffix's start: the path's members of the union are a suffix */
        amps_int mid = t + (hi - t) / 2;
        if (lmap[wi[mid]] >= 0) hi = mid;
        else t = mid + 1;
    }
    for (; t < len; t++) {
        const double *xr = X + (size_t)lmap[wi[t]] * W;
        double v = wv[t];
        AMPS__UNROLL
        for (j = 0; j < W; j++) a[j] += v * xr[j];
    }
    AMPS__UNROLL
    for (j = 0; j < W; j++) acc[j] = a[j];
}
#define AMPS__GSCAN(W)                                                                                   \
    static void amps__gscan##W(const amps_int *wi, const double *wv, amps_int len, const amps_int *lmap, \
                               const double *X, double *acc) {                                           \
        amps__gscan_body(W, wi, wv, len, lmap, X, acc);                                                  \
    }
AMPS__GSCAN(4)
AMPS__GSCAN(8)
AMPS__GSCAN(12)
AMPS__GSCAN(16)
#undef AMPS__GSCAN

/* Step 2: G(a, b) = W_a^T W_b for the new positions a >= u_old and every b <= a (both triangles).
   The new columns go by chunks of at most AMPS__VB: a chunk is scattered row-major over the union
   of its root paths, and each W_b is then read once for the whole chunk (its suffix in the
   union), the products W_b^T X in one pass; the b go by chunks of 16 to the participants. */
typedef struct amps__gcjob {
    amps_update *U;
    const double *X;
    const amps_int *lmap;
    amps_int u_old, a0, m, mw;
} amps__gcjob;

/* The b in [b0, b1) of amps__gcols for its chunk a0..a0+m-1. */
static void amps__gc_rows(amps_int b0, amps_int b1, int slot, void *arg) {
    amps__gcjob *gj = AMPS__CAST(amps__gcjob *, arg);
    amps_update *U = gj->U;
    amps_int n = U->n, b, a0 = gj->a0, mw = gj->mw;
    size_t ld = (size_t)U->aug.cap;
    (void)slot;
    for (b = b0; b < b1; b++) {
        double acc[AMPS__VB];
        amps_int jj;
        if (U->aug.idx[b] < n) {
            const amps_int *wi = U->memo.idx + U->memo.off[b];
            const double *wv = U->memo.val + U->memo.off[b];
            if (mw == 4) amps__gscan4(wi, wv, U->memo.len[b], gj->lmap, gj->X, acc);
            else if (mw == 8) amps__gscan8(wi, wv, U->memo.len[b], gj->lmap, gj->X, acc);
            else if (mw == 12) amps__gscan12(wi, wv, U->memo.len[b], gj->lmap, gj->X, acc);
            else amps__gscan16(wi, wv, U->memo.len[b], gj->lmap, gj->X, acc);
        }
        for (jj = 0; jj < gj->m; jj++) {
            amps_int a = a0 + jj;
            double gv;
            if (b >= gj->u_old && b > a) continue; /* the chunk of b writes it */
            gv = (U->aug.idx[a] >= n || U->aug.idx[b] >= n) ? (a == b ? 1.0 / U->sigma : 0.0) : acc[jj];
            U->lu.G[(size_t)b * ld + (size_t)a] = gv;
            U->lu.G[(size_t)a * ld + (size_t)b] = gv;
        }
    }
}

static void amps__gcols(amps_update *U, amps_int u_old) {
    amps_int u = U->aug.size, n = U->n, a0;
    double *X = U->work.chunk; /* slot 0's Step 1 workspace */
    amps_int *lmap = U->work.row_map, *clo = U->work.closure;
    amps__gcjob gj;
    gj.U = U;
    gj.u_old = u_old;
    for (a0 = u_old; a0 < u; a0 += AMPS__VB) {
        amps_int m = u - a0 < AMPS__VB ? u - a0 : AMPS__VB, mw = amps__width(m), nc = 0, j, t;
        for (j = 0; j < m; j++) {
            const amps_int *wi = U->memo.idx + U->memo.off[a0 + j];
            if (U->aug.idx[a0 + j] >= n) continue;
            for (t = 0; t < U->memo.len[a0 + j]; t++)
                if (lmap[wi[t]] < 0) {
                    lmap[wi[t]] = nc;
                    clo[nc++] = wi[t];
                }
        }
        memset(X, 0, sizeof(double) * (size_t)nc * (size_t)mw);
        for (j = 0; j < m; j++) {
            const amps_int *wi = U->memo.idx + U->memo.off[a0 + j];
            const double *wv = U->memo.val + U->memo.off[a0 + j];
            if (U->aug.idx[a0 + j] >= n) continue;
            for (t = 0; t < U->memo.len[a0 + j]; t++) X[(size_t)lmap[wi[t]] * (size_t)mw + (size_t)j] = wv[t];
        }
        gj.X = X;
        gj.lmap = lmap;
        gj.a0 = a0;
        gj.m = m;
        gj.mw = mw;
        amps__par_for(&U->par, (double)u * nc > 1e5 ? U->nthr : 1, u, 16, amps__gc_rows, &gj);
        for (t = 0; t < nc; t++) lmap[clo[t]] = -1;
    }
}

/* ---- Step 3: columns of A = I~ + G Delta~ ---- */

/* out (U positions) = A(:, j). */
static void amps__acol(const amps_update *U, amps_int j, double *out) {
    amps_int u = U->aug.size, i, k;
    size_t ld = (size_t)U->aug.cap;
    if (U->aug.kind[j] & AMPS__UCON) {
        memcpy(out, U->lu.G + (size_t)j * ld, sizeof(double) * (size_t)u);
        return;
    }
    memset(out, 0, sizeof(double) * (size_t)u);
    out[j] = 1.0;
    for (k = 0; k < U->delta.row_len[j]; k++) {
        amps_int b = U->delta.col[U->delta.row_start[j] + k];
        double v = U->delta.val[U->delta.row_start[j] + k];
        const double *gb;
        if (U->aug.kind[b] & AMPS__UCON) continue; /* rows of Delta in C are dropped */
        gb = U->lu.G + (size_t)b * ld;             /* G symmetric: G(:, b) */
        for (i = 0; i < u; i++) out[i] += gb[i] * v;
    }
}

/* A(i, j). */
static double amps__aentry(const amps_update *U, amps_int i, amps_int j) {
    size_t ld = (size_t)U->aug.cap;
    double s;
    amps_int k;
    const double *gi = U->lu.G + (size_t)i * ld; /* G(i, :) = G(:, i): contiguous */
    if (U->aug.kind[j] & AMPS__UCON) return gi[j];
    s = (i == j) ? 1.0 : 0.0;
    for (k = 0; k < U->delta.row_len[j]; k++) {
        amps_int b = U->delta.col[U->delta.row_start[j] + k];
        if (!(U->aug.kind[b] & AMPS__UCON)) s += gi[b] * U->delta.val[U->delta.row_start[j] + k];
    }
    return s;
}

/* ---- Step 5: left-looking dense LU with partial pivoting, P A(:, colorder) = L U ---- */

/* Pivot test of dense column j: |pivot| > tol * reference, the reference being the column's norm,
   for unconstrained columns at least the identity part (so that a column cancelled to rounding
   level, a row with no stiffness, is caught). */
static int amps__pivot_ok(const amps_update *U, amps_int j, double apiv) {
    return apiv > U->singular_tol *
                           ((U->aug.kind[j] & AMPS__UCON) || U->lu.col_norm[j] > 1.0 ? U->lu.col_norm[j] : 1.0) &&
           apiv != 0.0;
}

/* C(r0:r1, 0:w) -= A(r0:r1, k0:k1) B(k0:k1, 0:w), column major, by tiles of 4 columns and
   2 vectors of rows held in registers (AVX2 + FMA where the CPU has them, else GNU vector
   extensions where available, else scalars): A and B are read once per tile, C once per call. */
#if defined(__GNUC__) || defined(__clang__)
#if defined(__AVX__)
#define AMPS__VL 4
typedef double amps__vd __attribute__((vector_size(32)));
#else
#define AMPS__VL 2
typedef double amps__vd __attribute__((vector_size(16)));
#endif
#define AMPS__VLD(v, p) memcpy(&(v), (p), sizeof(amps__vd))
#define AMPS__VSUB(p, s)              \
    do {                              \
        amps__vd t_;                  \
        memcpy(&t_, (p), sizeof(t_)); \
        t_ -= (s);                    \
        memcpy((p), &t_, sizeof(t_)); \
    } while (0)
#else
#define AMPS__VL 1
#endif
/* y(0:n) -= a x(0:n) (y and x do not overlap), four entries at a time in SSE2: the bits of the
   scalar loop. */
static void amps__axpy_sub(double *y, const double *x, double a, amps_int n) {
    amps_int i = 0;
#ifdef AMPS__SSE2
    const __m128d av = _mm_set1_pd(a);
    for (; i + 4 <= n; i += 4) {
        _mm_storeu_pd(y + i, _mm_sub_pd(_mm_loadu_pd(y + i), _mm_mul_pd(_mm_loadu_pd(x + i), av)));
        _mm_storeu_pd(y + i + 2, _mm_sub_pd(_mm_loadu_pd(y + i + 2), _mm_mul_pd(_mm_loadu_pd(x + i + 2), av)));
    }
#endif
    for (; i < n; i++) y[i] -= x[i] * a;
}

/* The columns c0..w-1 of amps__gemm_tile (fewer than 4), one product at a time. */
static void amps__gemm_rest(amps_int c0, amps_int r0, amps_int r1, amps_int w, amps_int k0, amps_int k1,
                            const double *A, size_t lda, const double *B, size_t ldb, double *C, size_t ldc) {
    amps_int c, k;
    for (c = c0; c < w; c++) {
        const double *b = B + (size_t)c * ldb;
        double *cc = C + (size_t)c * ldc;
        for (k = k0; k < k1; k++) {
            const double *a = A + (size_t)k * lda;
            double bv = b[k];
            if (bv != 0.0) amps__axpy_sub(cc + r0, a + r0, bv, r1 - r0);
        }
    }
}
#ifdef AMPS__AVX2
/* C(0:nr, 0:4) -= sum_k A(0:8, k) B(k, 0:4) (nr <= 8; column k of A at a + k as, column t of B
   at b + t ldb, of C at c + t ldc): per entry a chain of fused multiply-adds from 0 over k, the
   accumulators in registers (named: with arrays gcc -O2 kept them in memory). */
static AMPS__TARGET_AVX2 void amps__gemm_k8(const double *a, size_t as, amps_int kn, const double *b, size_t ldb,
                                            double *c, size_t ldc, amps_int nr) {
    const double *b0 = b, *b1 = b0 + ldb, *b2 = b1 + ldb, *b3 = b2 + ldb;
    __m256d z = _mm256_setzero_pd(), s00 = z, s01 = z, s10 = z, s11 = z, s20 = z, s21 = z, s30 = z, s31 = z;
    __m256d s0[4], s1[4];
    amps_int k, i;
    int t;
    for (k = 0; k < kn; k++, a += as) {
        __m256d a0 = _mm256_loadu_pd(a), a1 = _mm256_loadu_pd(a + 4), v;
        v = _mm256_broadcast_sd(b0 + k);
        s00 = _mm256_fmadd_pd(a0, v, s00);
        s01 = _mm256_fmadd_pd(a1, v, s01);
        v = _mm256_broadcast_sd(b1 + k);
        s10 = _mm256_fmadd_pd(a0, v, s10);
        s11 = _mm256_fmadd_pd(a1, v, s11);
        v = _mm256_broadcast_sd(b2 + k);
        s20 = _mm256_fmadd_pd(a0, v, s20);
        s21 = _mm256_fmadd_pd(a1, v, s21);
        v = _mm256_broadcast_sd(b3 + k);
        s30 = _mm256_fmadd_pd(a0, v, s30);
        s31 = _mm256_fmadd_pd(a1, v, s31);
    }
    s0[0] = s00;
    s1[0] = s01;
    s0[1] = s10;
    s1[1] = s11;
    s0[2] = s20;
    s1[2] = s21;
    s0[3] = s30;
    s1[3] = s31;
    for (t = 0; t < 4; t++, c += ldc) {
        if (nr == 8) {
            _mm256_storeu_pd(c, _mm256_sub_pd(_mm256_loadu_pd(c), s0[t]));
            _mm256_storeu_pd(c + 4, _mm256_sub_pd(_mm256_loadu_pd(c + 4), s1[t]));
        } else {
            double sv[8];
            _mm256_storeu_pd(sv, s0[t]);
            _mm256_storeu_pd(sv + 4, s1[t]);
            for (i = 0; i < nr; i++) c[i] -= sv[i];
        }
    }
}

/* amps__gemm_tile in AVX2 + FMA: each sum over k is a chain of fused multiply-adds from 0 (8 rows
   at a time by amps__gemm_k8, the others one at a time, the same bits for a row either way). */
static AMPS__TARGET_AVX2 void amps__gemm_tile_avx2(amps_int r0, amps_int r1, amps_int w, amps_int k0, amps_int k1,
                                                   const double *A, size_t lda, const double *B, size_t ldb,
                                                   double *C, size_t ldc) {
    amps_int c, r, k;
    for (c = 0; c + 4 <= w; c += 4) {
        const double *b = B + (size_t)c * ldb;
        double *cc = C + (size_t)c * ldc;
        int t;
        for (r = r0; r + 8 <= r1; r += 8)
            amps__gemm_k8(A + (size_t)k0 * lda + (size_t)r, lda, k1 - k0, b + k0, ldb, cc + r, ldc, 8);
        for (; r < r1; r++) {
            __m128d s[4];
            for (t = 0; t < 4; t++) s[t] = _mm_setzero_pd();
            for (k = k0; k < k1; k++) {
                __m128d av = _mm_load_sd(A + (size_t)k * lda + (size_t)r);
                for (t = 0; t < 4; t++) s[t] = _mm_fmadd_sd(av, _mm_load_sd(b + (size_t)t * ldb + k), s[t]);
            }
            for (t = 0; t < 4; t++) cc[(size_t)t * ldc + r] -= _mm_cvtsd_f64(s[t]);
        }
    }
    amps__gemm_rest(c, r0, r1, w, k0, k1, A, lda, B, ldb, C, ldc);
}

/* Ap(0:8, 0:k1-k0) = A(r0:r1, k0:k1) (r1 - r0 <= 8) row-packed, the rows past r1 zero: the k loop
   of amps__gemm_tile8_avx2 then reads one contiguous line per k instead of one per column of A. */
static AMPS__TARGET_AVX2 void amps__gemm_pack8(amps_int r0, amps_int r1, amps_int k0, amps_int k1, const double *A,
                                               size_t lda, double *Ap) {
    amps_int k, i;
    for (k = k0; k < k1; k++, Ap += 8) {
        const double *a = A + (size_t)k * lda + (size_t)r0;
        if (r1 - r0 == 8) {
            _mm256_storeu_pd(Ap, _mm256_loadu_pd(a));
            _mm256_storeu_pd(Ap + 4, _mm256_loadu_pd(a + 4));
        } else
            for (i = 0; i < 8; i++) Ap[i] = i < r1 - r0 ? a[i] : 0.0;
    }
}

/* C(r0:r1, 0:w4) -= A(r0:r1, k0:k1) B(k0:k1, 0:w4), w4 = w - w % 4, r1 - r0 <= 8, from Ap of
   amps__gemm_pack8 (a zero row of Ap is computed and not stored): the bits of
   amps__gemm_tile_avx2. */
static AMPS__TARGET_AVX2 void amps__gemm_tile8_avx2(amps_int r0, amps_int r1, amps_int w, amps_int k0, amps_int k1,
                                                    const double *Ap, const double *B, size_t ldb, double *C,
                                                    size_t ldc) {
    amps_int c;
    for (c = 0; c + 4 <= w; c += 4)
        amps__gemm_k8(Ap, 8, k1 - k0, B + (size_t)c * ldb + (size_t)k0, ldb, C + (size_t)c * ldc + (size_t)r0, ldc,
                      r1 - r0);
}
#endif
static void amps__gemm_tile(amps_int r0, amps_int r1, amps_int w, amps_int k0, amps_int k1, const double *A, size_t lda,
                            const double *B, size_t ldb, double *C, size_t ldc) {
    amps_int c, r, k;
#ifdef AMPS__AVX2
    if (amps__cpu_avx2()) {
        amps__gemm_tile_avx2(r0, r1, w, k0, k1, A, lda, B, ldb, C, ldc);
        return;
    }
#endif
    for (c = 0; c + 4 <= w; c += 4) {
        const double *b0 = B + (size_t)c * ldb, *b1 = b0 + ldb, *b2 = b1 + ldb, *b3 = b2 + ldb;
        double *c0 = C + (size_t)c * ldc, *c1 = c0 + ldc, *c2 = c1 + ldc, *c3 = c2 + ldc;
        r = r0;
#if AMPS__VL > 1
        for (; r + 2 * AMPS__VL <= r1; r += 2 * AMPS__VL) {
            amps__vd z = {0}, s00 = z, s10 = z, s01 = z, s11 = z, s02 = z, s12 = z, s03 = z, s13 = z, a0, a1, v;
            const double *a = A + (size_t)k0 * lda + (size_t)r;
            for (k = k0; k < k1; k++, a += lda) {
                AMPS__VLD(a0, a);
                AMPS__VLD(a1, a + AMPS__VL);
                v = z + b0[k];
                s00 += a0 * v;
                s10 += a1 * v;
                v = z + b1[k];
                s01 += a0 * v;
                s11 += a1 * v;
                v = z + b2[k];
                s02 += a0 * v;
                s12 += a1 * v;
                v = z + b3[k];
                s03 += a0 * v;
                s13 += a1 * v;
            }
            AMPS__VSUB(c0 + r, s00);
            AMPS__VSUB(c0 + r + AMPS__VL, s10);
            AMPS__VSUB(c1 + r, s01);
            AMPS__VSUB(c1 + r + AMPS__VL, s11);
            AMPS__VSUB(c2 + r, s02);
            AMPS__VSUB(c2 + r + AMPS__VL, s12);
            AMPS__VSUB(c3 + r, s03);
            AMPS__VSUB(c3 + r + AMPS__VL, s13);
        }
#endif
        for (; r < r1; r++) {
            double s0 = 0, s1 = 0, s2 = 0, s3 = 0;
            for (k = k0; k < k1; k++) {
                double av = A[(size_t)k * lda + (size_t)r];
                s0 += av * b0[k];
                s1 += av * b1[k];
                s2 += av * b2[k];
                s3 += av * b3[k];
            }
            c0[r] -= s0;
            c1[r] -= s1;
            c2[r] -= s2;
            c3[r] -= s3;
        }
    }
    amps__gemm_rest(c, r0, r1, w, k0, k1, A, lda, B, ldb, C, ldc);
}

/* s[i] = a_i(0:n)^T b(0:n) for the nr <= 4 vectors a_i = a + i lda: b is read once for all. */
static void amps__dot4(const double *a, size_t lda, amps_int nr, const double *b, amps_int n, double *s) {
    const double *a0 = a, *a1 = nr > 1 ? a + lda : a, *a2 = nr > 2 ? a + 2 * lda : a, *a3 = nr > 3 ? a + 3 * lda : a;
    double t0 = 0, t1 = 0, t2 = 0, t3 = 0;
    amps_int k = 0;
#if AMPS__VL > 1
    {
        amps__vd s0 = {0}, s1 = s0, s2 = s0, s3 = s0, x, y;
        int l;
        for (; k + AMPS__VL <= n; k += AMPS__VL) {
            AMPS__VLD(y, b + k);
            AMPS__VLD(x, a0 + k);
            s0 += x * y;
            AMPS__VLD(x, a1 + k);
            s1 += x * y;
            AMPS__VLD(x, a2 + k);
            s2 += x * y;
            AMPS__VLD(x, a3 + k);
            s3 += x * y;
        }
        for (l = 0; l < AMPS__VL; l++) {
            t0 += s0[l];
            t1 += s1[l];
            t2 += s2[l];
            t3 += s3[l];
        }
    }
#endif
    for (; k < n; k++) {
        t0 += a0[k] * b[k];
        t1 += a1[k] * b[k];
        t2 += a2[k] * b[k];
        t3 += a3[k] * b[k];
    }
    s[0] = t0;
    s[1] = t1;
    s[2] = t2;
    s[3] = t3;
}

/* C(0:m, 0:w) -= A(0:m, 0:kk) B(0:kk, 0:w), column major; one parallel region over row blocks
   of 128, each swept in k blocks of AMPS__GKC (the block of A stays in cache for all of C's
   columns). With AVX2 each 8 rows of a block are first packed (amps__gemm_pack8) into the slot's
   AMPS__GPACK doubles of pack; the bits are those of amps__gemm_tile either way. */
typedef struct amps__gmjob {
    amps_int m, w, kk;
    const double *A, *B;
    double *C, *pack;
    size_t lda, ldb, ldc;
} amps__gmjob;

/* Row blocks [b, e) of 128 rows of amps__gemm_sub. */
static void amps__gm_rows(amps_int b, amps_int e, int slot, void *arg) {
    amps__gmjob *j = AMPS__CAST(amps__gmjob *, arg);
    amps_int rb;
    for (rb = b; rb < e; rb++) {
        amps_int r0 = rb * 128, r1 = r0 + 128 < j->m ? r0 + 128 : j->m, k0;
        for (k0 = 0; k0 < j->kk; k0 += AMPS__GKC) {
            amps_int k1 = k0 + AMPS__GKC < j->kk ? k0 + AMPS__GKC : j->kk;
#ifdef AMPS__AVX2
            if (j->pack && j->w >= 4 && amps__cpu_avx2()) {
                double *Ap = j->pack + (size_t)slot * AMPS__GPACK;
                amps_int t;
                for (t = r0; t < r1; t += 8) {
                    amps_int t1 = t + 8 < r1 ? t + 8 : r1;
                    amps__gemm_pack8(t, t1, k0, k1, j->A, j->lda, Ap);
                    amps__gemm_tile8_avx2(t, t1, j->w, k0, k1, Ap, j->B, j->ldb, j->C, j->ldc);
                }
                amps__gemm_rest(j->w - j->w % 4, r0, r1, j->w, k0, k1, j->A, j->lda, j->B, j->ldb, j->C, j->ldc);
                continue;
            }
#endif
            amps__gemm_tile(r0, r1, j->w, k0, k1, j->A, j->lda, j->B, j->ldb, j->C, j->ldc);
        }
    }
    (void)slot;
}

/* pack: NULL, or AMPS__GPACK doubles for each of the nthr slots. */
static void amps__gemm_sub(amps_int m, amps_int w, amps_int kk, const double *A, size_t lda, const double *B,
                           size_t ldb, double *C, size_t ldc, double *pack, const amps__par *par, int nthr) {
    amps__gmjob j;
    if (m <= 0 || w <= 0 || kk <= 0) return;
    j.pack = pack;
    j.m = m;
    j.w = w;
    j.kk = kk;
    j.A = A;
    j.lda = lda;
    j.B = B;
    j.ldb = ldb;
    j.C = C;
    j.ldc = ldc;
    amps__par_for(par, (double)m * w * kk > 1e6 ? nthr : 1, (m + 127) / 128, 1, amps__gm_rows, &j);
}

/* The new rows u_old..u-1 of L on the factored positions 0..nf-1: L(r, 0:nf) solves
   l U11 = A(r, col_order[0:nf]), by groups of 4 rows kept row-major in lu.panel, so that each
   entry is one dot product with a column of U11. AMPS_ERR_CAPACITY when a multiplier exceeds 1e6. */
static amps_status amps__lu_new_rows(amps_update *U, amps_int nf, amps_int u_old) {
    amps_int u = U->aug.size, q;
    size_t ld = (size_t)U->aug.cap;
    double *LU = U->lu.LU, growth = 0;
    amps_int r0, i;
    for (r0 = u_old; r0 < u; r0 += 4) {
        amps_int nr = u - r0 < 4 ? u - r0 : 4;
        double *lr = U->lu.panel;
        for (q = 0; q < nf; q++) {
            const double *uq = LU + (size_t)q * ld;
            amps_int j = U->lu.col_order[q];
            double d[4];
            amps__dot4(lr, ld, nr, uq, q, d);
            for (i = 0; i < nr; i++)
                lr[(size_t)i * ld + (size_t)q] = (amps__aentry(U, U->lu.row_perm[r0 + i], j) - d[i]) / uq[q];
        }
        for (i = 0; i < nr; i++)
            for (q = 0; q < nf; q++) {
                double v = lr[(size_t)i * ld + (size_t)q];
                LU[(size_t)q * ld + (size_t)(r0 + i)] = v;
                if (fabs(v) > growth) growth = fabs(v);
            }
    }
    return growth <= 1e6 ? AMPS_OK : AMPS_ERR_CAPACITY;
}

/* Panel qp..qp+w-1 of the factor: A(row_perm, col_order[qp:qp+w]), and the column norms. */
typedef struct amps__pljob {
    amps_update *U;
    amps_int qp;
} amps__pljob;

/* Columns qp + [b, e) of the panel, with the column buffer of slot. */
static void amps__pl_cols(amps_int b, amps_int e, int slot, void *arg) {
    amps__pljob *pj = AMPS__CAST(amps__pljob *, arg);
    amps_update *U = pj->U;
    amps_int u = U->aug.size, c;
    size_t ld = (size_t)U->aug.cap;
    double *P = U->lu.LU + (size_t)pj->qp * ld, *buf = U->lu.panel + (size_t)slot * ld;
    for (c = b; c < e; c++) {
        amps_int j = U->lu.col_order[pj->qp + c], rr;
        double nrm = 0, *col = P + (size_t)c * ld;
        amps__acol(U, j, buf);
        for (rr = 0; rr < u; rr++) {
            col[rr] = buf[U->lu.row_perm[rr]];
            if (fabs(buf[rr]) > nrm) nrm = fabs(buf[rr]);
        }
        U->lu.col_norm[j] = nrm;
    }
}

static void amps__lu_panel_load(amps_update *U, amps_int qp, amps_int w) {
    amps__pljob pj;
    pj.U = U;
    pj.qp = qp;
    amps__par_for(&U->par, w > 1 && U->aug.size > 64 ? U->nthr : 1, w, 1, amps__pl_cols, &pj);
}

/* The factored columns 0..qp-1 applied to the panel P = qp..qp+w-1: P(0:qp) = L11^{-1} P(0:qp)
   (unit lower) by blocks of AMPS__TB rows: the diagonal block per column, the rows below it by
   one product; then P(qp:u) -= L(qp:u, 0:qp) P(0:qp). */
static void amps__lu_panel_apply(amps_update *U, amps_int qp, amps_int w) {
    amps_int u = U->aug.size, c, r, kb;
    size_t ld = (size_t)U->aug.cap;
    const double *LU = U->lu.LU;
    double *P = U->lu.LU + (size_t)qp * ld;
    for (kb = 0; kb < qp; kb += AMPS__TB) {
        amps_int k1 = kb + AMPS__TB < qp ? kb + AMPS__TB : qp, kk;
        amps_int ib;
        for (ib = kb; ib < k1; ib += 8) { /* the diagonal block by blocks of 8 */
            amps_int i1 = ib + 8 < k1 ? ib + 8 : k1;
            for (c = 0; c < w; c++) {
                double *col = P + (size_t)c * ld;
                for (kk = ib; kk < i1; kk++) {
                    const double *lk = LU + (size_t)kk * ld;
                    double x = col[kk];
                    if (x != 0.0)
                        for (r = kk + 1; r < i1; r++) col[r] -= lk[r] * x;
                }
            }
            amps__gemm_tile(i1, k1, w, ib, i1, LU, ld, P, ld, P, ld);
        }
        amps__gemm_sub(qp - k1, w, k1 - kb, LU + (size_t)kb * ld + (size_t)k1, ld, P + (size_t)kb, ld, P + (size_t)k1,
                       ld, U->lu.panel, &U->par, U->nthr);
    }
    amps__gemm_sub(u - qp, w, qp, LU + (size_t)qp, ld, P, ld, P + (size_t)qp, ld, U->lu.panel, &U->par, U->nthr);
}

/* Factors the panel qp..qp+w-1 with partial pivoting (swaps act on whole rows 0..qp+w-1);
   AMPS_ERR_SINGULAR_UPDATE (U position in *bad) at a pivot that fails amps__pivot_ok. */
static amps_status amps__lu_panel_factor(amps_update *U, amps_int qp, amps_int w, amps_int *bad) {
    amps_int u = U->aug.size, c, r;
    size_t ld = (size_t)U->aug.cap;
    double *LU = U->lu.LU;
    for (c = 0; c < w; c++) {
        amps_int qq = qp + c, pr = qq, j = U->lu.col_order[qq], cc;
        double *col = LU + (size_t)qq * ld, pmax = fabs(col[qq]), piv;
        for (r = qq + 1; r < u; r++)
            if (fabs(col[r]) > pmax) {
                pmax = fabs(col[r]);
                pr = r;
            }
        if (!amps__pivot_ok(U, j, pmax)) {
            *bad = j;
            return AMPS_ERR_SINGULAR_UPDATE;
        }
        if (pr != qq) {
            amps_int t = U->lu.row_perm[pr];
            U->lu.row_perm[pr] = U->lu.row_perm[qq];
            U->lu.row_perm[qq] = t;
            for (cc = 0; cc < qp + w; cc++) {
                double *cl = LU + (size_t)cc * ld, tv = cl[pr];
                cl[pr] = cl[qq];
                cl[qq] = tv;
            }
        }
        piv = col[qq];
        for (r = qq + 1; r < u; r++) col[r] /= piv;
        for (cc = qq + 1; cc < qp + w; cc++) {
            double *cl = LU + (size_t)cc * ld, x = cl[qq];
            if (x == 0.0) continue;
            amps__axpy_sub(cl + qq + 1, col + qq + 1, x, u - qq - 1);
        }
    }
    return AMPS_OK;
}

/* Factors positions nf..u-1 given positions 0..nf-1 factored for physical rows 0..u_old-1;
   rows u_old..u-1 are new (lu.row_perm set). Returns AMPS_OK, AMPS_ERR_SINGULAR_UPDATE (position in
   *bad), or AMPS_ERR_CAPACITY when the new rows' multipliers grow past 1e6 (refactor from 0). */
static amps_status amps__lu_extend(amps_update *U, amps_int nf, amps_int u_old, amps_int *bad) {
    amps_int u = U->aug.size, q, qp;
    amps_status s;
    if (nf > 0 && u > u_old && (s = amps__lu_new_rows(U, nf, u_old)) != AMPS_OK) return s;
    for (qp = nf; qp < u; qp += AMPS__NB) {
        amps_int w = u - qp < AMPS__NB ? u - qp : AMPS__NB;
        amps__lu_panel_load(U, qp, w);
        amps__lu_panel_apply(U, qp, w);
        if ((s = amps__lu_panel_factor(U, qp, w, bad)) != AMPS_OK) return s;
    }
    for (q = 0; q < u; q++) U->lu.col_pos[U->lu.col_order[q]] = q;
    return AMPS_OK;
}

/* ---- Step 5 with column removal: the unchanged columns after a changed one keep their factor ---- */

/* x(r-1:r) <- T x(r-1:r) for a row transform h = {m, l, swap} of amps__lu_drop: without swap
   x_r -= m x_{r-1}; with swap the rows exchange, x_{r-1} += l x_r, then x_r -= m x_{r-1}. */
static void amps__pair(double *x, amps_int r, const double *h) {
    if (h[2] != 0.0) {
        double t = x[r - 1];
        x[r - 1] = x[r] + h[1] * t;
        x[r] = t;
    }
    x[r] -= h[0] * x[r - 1];
}

/* Rows i0..i1-1 of two columns of L: with swap (x0, x1) <- (x1, x0 - c x1) and g = max(g, |x1|),
   else x0 += c x1 and g = max(g, |x0|) (a NaN leaves g); returns g. Two rows at a time in SSE2,
   the same bits as one at a time. */
static double amps__pair_cols(double *L0, double *L1, double c, int swap, amps_int i0, amps_int i1, double g) {
    amps_int i = i0;
#ifdef AMPS__SSE2
    if (i1 - i0 >= 8) {
        const __m128d cv = _mm_set1_pd(c), sgn = _mm_set1_pd(-0.0);
        __m128d gv = _mm_set1_pd(g);
        double gl[2];
        for (; i + 2 <= i1; i += 2) {
            __m128d x0 = _mm_loadu_pd(L0 + i), x1 = _mm_loadu_pd(L1 + i), y;
            if (swap) {
                y = _mm_sub_pd(x0, _mm_mul_pd(cv, x1));
                _mm_storeu_pd(L0 + i, x1);
                _mm_storeu_pd(L1 + i, y);
            } else {
                y = _mm_add_pd(x0, _mm_mul_pd(cv, x1));
                _mm_storeu_pd(L0 + i, y);
            }
            gv = _mm_max_pd(_mm_andnot_pd(sgn, y), gv); /* a NaN lane keeps gv */
        }
        _mm_storeu_pd(gl, gv);
        g = gl[0] > gl[1] ? gl[0] : gl[1];
    }
#endif
    for (; i < i1; i++) {
        double y;
        if (swap) {
            y = L0[i] - c * L1[i];
            L0[i] = L1[i];
            L1[i] = y;
        } else {
            y = L0[i] + c * L1[i];
            L0[i] = y;
        }
        if (fabs(y) > g) g = fabs(y);
    }
    return g;
}

/* L <- L T^{-1} for the transform h of rows r-1, r (rows of L below q0 live in rows 0..u_old-1).
   Without swap: E = I - m e_r e_{r-1}^T, column r-1 += m (e_r + L(r+1:, r)). With swap the rows
   (P and L, columns < q0 deferred through perm) and the columns r-1, r of L exchange, which puts
   l = L(r, r-1) above the diagonal; R = I + l e_{r-1} e_r^T removes it (column r -= l column r-1,
   U row r-1 += l row r: the h[1] of amps__pair); then E as before. L stays unit lower. */
static double amps__lpair(amps_update *U, amps_int q0, amps_int u_old, amps_int r, const double *h, amps_int *perm) {
    size_t ld = (size_t)U->aug.cap;
    double *L0 = U->lu.LU + (size_t)(r - 1) * ld, *L1 = U->lu.LU + (size_t)r * ld, m = h[0], l = h[1], g = 0.0;
    amps_int c;
    if (h[2] != 0.0) {
        amps_int t = U->lu.row_perm[r - 1];
        U->lu.row_perm[r - 1] = U->lu.row_perm[r];
        U->lu.row_perm[r] = t;
        t = perm[r - 1 - q0];
        perm[r - 1 - q0] = perm[r - q0];
        perm[r - q0] = t;
        for (c = q0; c < r - 1; c++) {
            double *lc = U->lu.LU + (size_t)c * ld, tv = lc[r - 1];
            lc[r - 1] = lc[r];
            lc[r] = tv;
        }
        g = amps__pair_cols(L0, L1, l, 1, r + 1, u_old, g);
        L0[r] = 0.0; /* (Pi L Pi)(r, r-1) = L(r-1, r) = 0 */
    }
    L0[r] += m;
    g = fabs(L0[r]) > g ? fabs(L0[r]) : g;
    if (m != 0.0 || h[2] != 0.0) g = amps__pair_cols(L0, L1, m, 0, r + 1, u_old, g);
    return g;
}

/* Column removal. On entry positions 0..u_old-1 of LU hold P A_old Q_old = L U, and the new
   order colorder keeps positions 0..q0-1 and puts at q0..q0+nk-1 the unchanged columns of old
   positions q0..u_old-1 in their old order (old position colpos[j] = p + d_p, d_p <= AMPS__DMAX).
   Without the changed columns U' = U(:, kept) is upper Hessenberg below q0, with d_p
   subdiagonals in column p. They are eliminated bottom-up by transforms of adjacent rows
   (Gaussian elimination with pairwise pivoting: the row exchange is taken when it gives the
   smaller multiplier), U'' = T U', L'' = L T^{-1}, P'' = Pi P, and then P'' A(:, kept) =
   L''(:, 0:q0+nk) U''(0:q0+nk, :): positions 0..q0+nk-1 are factored for rows 0..u_old-1, in
   O(d (nk + u)) flops per column instead of O(u^2). Stops at the first column whose multiplier
   exceeds AMPS__DMULT, that would make an entry of L larger than AMPS__DLMAX or whose pivot
   fails the test of amps__lu_extend. Returns the number of positions factored (q0..q0+nk);
   the rest must be refactored. */
static amps_int amps__lu_drop(amps_update *U, amps_int q0, amps_int nk, amps_int u_old) {
    size_t ld = (size_t)U->aug.cap;
    double *LU = U->lu.LU, *x = U->lu.panel;
    amps_int *perm = U->work.idx, p, k, r, i, c, nr = u_old - q0;
    int fail = 0;
    for (i = 0; i < nr; i++) perm[i] = i;
    for (p = q0; p < q0 + nk; p++) {
        amps_int j = U->lu.col_order[p], op = U->lu.col_pos[j];
        double *dst = LU + (size_t)p * ld, *h = U->lu.transforms + (size_t)(p - q0) * 3 * AMPS__DMAX;
        const double *src = LU + (size_t)op * ld;
        /* column p of U': rows q0..op of old column op, then the transforms of columns q0..p-1 */
        for (r = q0; r <= op; r++) x[r] = src[r];
        for (k = q0; k < p; k++) {
            amps_int dk = U->lu.col_pos[U->lu.col_order[k]] - k;
            const double *hk = U->lu.transforms + (size_t)(k - q0) * 3 * AMPS__DMAX;
            for (r = k + dk; r > k; r--, hk += 3) amps__pair(x, r, hk);
        }
        /* its own subdiagonals, bottom-up: the pair (r-1, r) zeroes x_r */
        for (r = op; r > p; r--, h += 3) {
            double a = x[r - 1], b = x[r], l = LU[(size_t)(r - 1) * ld + (size_t)r];
            double ma = a != 0.0 ? b / a : (b == 0.0 ? 0.0 : HUGE_VAL), pb = b + l * a,
                   mb = pb != 0.0 ? a / pb : HUGE_VAL;
            if (fabs(ma) <= 1.0 || fabs(ma) <= fabs(mb)) {
                h[0] = ma;
                h[1] = 0.0;
                h[2] = 0.0;
            } else {
                h[0] = mb;
                h[1] = l;
                h[2] = 1.0;
            }
            if (!(fabs(h[0]) <= AMPS__DMULT)) {
                fail = 1;
                break;
            }
            amps__pair(x, r, h);
            x[r] = 0.0;
            if (!(amps__lpair(U, q0, u_old, r, h, perm) <= AMPS__DLMAX)) {
                fail = 1;
                break;
            }
        }
        if (fail) break;
        if (!amps__pivot_ok(U, j, fabs(x[p]))) break;
        /* U''(0:p, p): rows above q0 move with the column (old column p was read before) */
        if (op != p) memcpy(dst, src, sizeof(double) * (size_t)q0);
        for (r = q0; r <= p; r++) dst[r] = x[r];
    }
    /* the deferred row exchanges of L(q0:u_old, 0:q0) */
    for (c = 0; c < q0; c++) {
        double *lc = LU + (size_t)c * ld + (size_t)q0;
        for (i = 0; i < nr; i++) x[i] = lc[perm[i]];
        memcpy(lc, x, sizeof(double) * (size_t)nr);
    }
    return p;
}

/* z = A^{-1} b (U positions); t is scratch of length u. */
static void amps__lu_solve(const amps_update *U, const double *b, double *z, double *t) {
    amps_int u = U->aug.size, q, r;
    size_t ld = (size_t)U->aug.cap;
    for (r = 0; r < u; r++) t[r] = b[U->lu.row_perm[r]];
    for (q = 0; q < u; q++) {
        const double *l = U->lu.LU + (size_t)q * ld;
        double x = t[q];
        if (x != 0.0)
            amps__axpy_sub(t + q + 1, l + q + 1, x, u - q - 1);
    }
    for (q = u - 1; q >= 0; q--) {
        const double *col = U->lu.LU + (size_t)q * ld;
        double x = t[q] / col[q];
        t[q] = x;
        if (x != 0.0)
            amps__axpy_sub(t, col, x, q);
    }
    for (q = 0; q < u; q++) z[U->lu.col_order[q]] = t[q];
}

/* z = A^{-T} b (U positions). */
static void amps__lu_solve_t(const amps_update *U, const double *b, double *z, double *t) {
    amps_int u = U->aug.size, q, r;
    size_t ld = (size_t)U->aug.cap;
    for (q = 0; q < u; q++) t[q] = b[U->lu.col_order[q]];
    for (q = 0; q < u; q++) { /* U^T v = t */
        const double *col = U->lu.LU + (size_t)q * ld;
        double s = t[q];
        for (r = 0; r < q; r++) s -= col[r] * t[r];
        t[q] = s / col[q];
    }
    for (q = u - 1; q >= 0; q--) { /* L^T */
        const double *l = U->lu.LU + (size_t)q * ld;
        double s = t[q];
        for (r = q + 1; r < u; r++) s -= l[r] * t[r];
        t[q] = s;
    }
    for (r = 0; r < u; r++) z[U->lu.row_perm[r]] = t[r];
}

/* Full refactorization of A in position order. */
static amps_status amps__lu_full(amps_update *U, amps_int *bad) {
    amps_int q;
    for (q = 0; q < U->aug.size; q++) {
        U->lu.col_order[q] = q;
        U->lu.row_perm[q] = q;
    }
    U->stats.lu_full++;
    U->stats.lu_cols = U->aug.size;
    return amps__lu_extend(U, 0, 0, bad);
}

/* ---- Delta rows ---- */

/* Moves rows to the front of the pool in position order, dropping holes. */
static void amps__delta_compact(amps_update *U) {
    amps_int a, used = 0, *order = U->work.idx, k;
    /* rows sorted by their start so that moving towards the front never overwrites */
    for (a = 0; a < U->aug.size; a++) order[a] = a;
    for (a = 1; a < U->aug.size; a++) {
        amps_int v = order[a], b = a - 1;
        while (b >= 0 && U->delta.row_start[order[b]] > U->delta.row_start[v]) {
            order[b + 1] = order[b];
            b--;
        }
        order[b + 1] = v;
    }
    for (k = 0; k < U->aug.size; k++) {
        a = order[k];
        if (U->delta.row_cap[a] == 0) continue;
        memmove(U->delta.col + used, U->delta.col + U->delta.row_start[a],
                sizeof(amps_int) * (size_t)U->delta.row_len[a]);
        memmove(U->delta.val + used, U->delta.val + U->delta.row_start[a],
                sizeof(double) * (size_t)U->delta.row_len[a]);
        U->delta.row_start[a] = used;
        U->delta.row_cap[a] = U->delta.row_len[a];
        used += U->delta.row_len[a];
    }
    U->delta.used = used;
}

/* Delta(a, b) += v; row a has been relocated with room for its additions this commit. */
static void amps__delta_add(amps_update *U, amps_int a, amps_int b, double v) {
    amps_int k, st = U->delta.row_start[a];
    for (k = 0; k < U->delta.row_len[a]; k++)
        if (U->delta.col[st + k] == b) {
            U->delta.val[st + k] += v;
            return;
        }
    AMPS_ASSERT(U->delta.row_len[a] < U->delta.row_cap[a]);
    U->delta.col[st + U->delta.row_len[a]] = b;
    U->delta.val[st + U->delta.row_len[a]] = v;
    U->delta.row_len[a]++;
}

/* The engine before a failed commit, its recorded changes kept: drops the new positions,
   restores the Delta row headers, kinds and prescribed values from the journal and the pool
   sizes, and refactors the old system. */
static void amps__restore(amps_update *U, amps_int u_old, size_t vused_old, amps_int dused_old) {
    amps_int a, k, bad;
    for (a = u_old; a < U->aug.size; a++) U->aug.pos[U->aug.idx[a]] = -1;
    for (k = U->journal.n_rows - 1; k >= 0; k--) {
        const amps__djour *d = U->journal.rows + k;
        if (d->pos < u_old) {
            U->delta.row_start[d->pos] = d->start;
            U->delta.row_len[d->pos] = d->len;
            U->delta.row_cap[d->pos] = d->cap;
        }
    }
    for (k = U->journal.n_kinds - 1; k >= 0; k--) {
        const amps__kjour *j = U->journal.kinds + k;
        if (j->pos < u_old) {
            U->aug.kind[j->pos] = j->kind;
            U->aug.g[j->pos] = j->g;
        }
    }
    U->aug.size = u_old;
    U->memo.used = vused_old;
    U->delta.used = dused_old;
    if (U->sol.n_rhs > u_old) U->sol.n_rhs = u_old;
    U->journal.n_rows = 0;
    U->journal.n_kinds = 0;
    /* refactor the old system from scratch. It was accepted, but a fresh elimination order can
       meet a pivot below tol; the singularity test must not stop this factorization halfway
       (a partial LU gives garbage solutions: beam 5x5x4096 in tests/test_stress.c) */
    if (U->aug.size > 0) {
        double tol = U->singular_tol;
        U->singular_tol = 0.0;
        (void)amps__lu_full(U, &bad);
        U->singular_tol = tol;
    }
    U->sol.x_stale = U->sol.react_stale = U->sol.watched_stale = 1;
}

/* Rollback of a failed commit: amps__restore, and the recorded changes discarded. */
static void amps__rollback(amps_update *U, amps_int u_old, size_t vused_old, amps_int dused_old) {
    amps__restore(U, u_old, vused_old, dused_old);
    amps_update_discard(U);
}

AMPS_API void amps_update_discard(amps_update *U) {
    if (!U) return;
    U->pending.n_delta = 0;
    U->pending.n_con = 0;
    U->pending.n_dofs = 0;
}

/* ---- the steps of a commit ---- */

/* Indices the recorded changes add to U: ends of changed entries and newly constrained indices. */
static amps_int amps__count_new(amps_update *U) {
    amps_marker *mk = &U->work.mark_N;
    amps_int k, t, nnew = 0;
    amps_marker_next(mk);
    for (k = 0; k < U->pending.n_delta; k++) {
        amps_int e[2];
        e[0] = U->pending.delta[k].r;
        e[1] = U->pending.delta[k].c;
        for (t = 0; t < 2; t++) {
            amps_int i = e[t];
            if ((i >= U->N || U->aug.pos[i] < 0) && mk->mark[i] != mk->stamp) {
                mk->mark[i] = mk->stamp;
                nnew++;
            }
        }
    }
    for (k = 0; k < U->pending.n_con; k++) {
        amps_int i = U->pending.con[k].i;
        if (!U->pending.con[k].release && (i >= U->N || U->aug.pos[i] < 0) && mk->mark[i] != mk->stamp) {
            mk->mark[i] = mk->stamp;
            nnew++;
        }
    }
    return nnew;
}

/* Grows U (room checked by amps__need_u): the new indices get positions in order of first
   appearance, with empty Delta rows and the lengths of their W columns. Returns the memoized
   entries these need. */
static size_t amps__grow_aug(amps_update *U) {
    amps_int k, t, a, nd = U->pending.n_delta;
    size_t vneed = 0;
    for (k = 0; k < nd + U->pending.n_con; k++) {
        amps_int e[2], ne;
        if (k < nd) {
            e[0] = U->pending.delta[k].r;
            e[1] = U->pending.delta[k].c;
            ne = 2;
        } else {
            if (U->pending.con[k - nd].release) continue;
            e[0] = U->pending.con[k - nd].i;
            ne = 1;
        }
        for (t = 0; t < ne; t++) {
            amps_int i = e[t];
            if (U->aug.pos[i] >= 0 && U->aug.pos[i] < U->aug.size && U->aug.idx[U->aug.pos[i]] == i) continue;
            a = U->aug.size++;
            U->aug.pos[i] = a;
            U->aug.idx[a] = i;
            U->aug.kind[a] = 0;
            U->aug.g[a] = 0;
            U->delta.row_start[a] = 0;
            U->delta.row_len[a] = 0;
            U->delta.row_cap[a] = 0;
            U->memo.off[a] = 0;
            U->memo.len[a] = i < U->n ? amps__path_len(U->F, U->F->iperm[i]) : 0;
            vneed += (size_t)U->memo.len[a];
        }
    }
    return vneed;
}

/* Room for vneed more memoized entries (grows the pool when allowed). */
static amps_status amps__need_memo(amps_ctx *ctx, amps_update *U, size_t vneed) {
    size_t need = U->memo.used + vneed, cap = U->memo.cap;
    if (need > cap && !U->grow)
        return amps__err(ctx, AMPS_ERR_CAPACITY,
                         "amps_update: memoized columns need %.0f entries, cap_vpool is %.0f (raise it or set grow)",
                         (double)need, (double)cap);
    if (need > cap) {
        while (cap < need) cap = cap * 2 + 1024;
        if (amps__realloc(ctx, (void **)&U->memo.val, cap, sizeof(double)) ||
            amps__realloc(ctx, (void **)&U->memo.idx, cap, sizeof(amps_int)))
            return AMPS_ERR_OOM;
        U->memo.cap = cap;
    }
    return AMPS_OK;
}

/* Step 1's list: the memo offsets of the new base positions u_old.. (in position order), and
   these positions into list by ascending factor position of their indices (one index per
   position), the order amps__wcols takes: a chunk's paths share most of their length, and its
   columns whose paths hold a node are consecutive lanes. Returns their number. */
static amps_int amps__step1_list(amps_update *U, amps_int u_old, amps_int *list) {
    const amps_factor *F = U->F;
    amps_int a, k, nb = 0;
    for (a = u_old; a < U->aug.size; a++)
        if (U->aug.idx[a] < U->n) {
            U->memo.off[a] = U->memo.used; /* memo.len was set with the position */
            U->memo.used += (size_t)U->memo.len[a];
            list[nb++] = F->iperm[U->aug.idx[a]];
        }
    amps__sort(list, (size_t)nb, sizeof(amps_int), amps__int_cmp);
    for (k = 0; k < nb; k++) list[k] = U->aug.pos[F->perm[list[k]]];
    return nb;
}

/* Step 1: W columns of the new base positions u_old.., in batches over the union of their paths. */
static void amps__step1(amps_update *U, amps_int u_old) {
    amps_int nb = amps__step1_list(U, u_old, U->work.idx);
    amps__wcols(U, U->work.idx, nb);
}

/* Delta: relocates every row the changes touch to the end of the pool with room for its
   additions (old locations stay intact, so a rollback only restores the journaled headers).
   Compacting the pool first moves the old locations: *dused_old follows. */
static amps_status amps__delta_relocate(amps_ctx *ctx, amps_update *U, amps_int *dused_old) {
    amps_marker *tm = &U->delta.touched;
    amps_int *n_add = U->delta.n_add, k, t, a, need = 0;
    amps_marker_next(tm);
    for (k = 0; k < U->pending.n_delta; k++) {
        amps_int e[2];
        e[0] = U->aug.pos[U->pending.delta[k].r];
        e[1] = U->aug.pos[U->pending.delta[k].c];
        for (t = 0; t < (e[0] == e[1] ? 1 : 2); t++) {
            if (tm->mark[e[t]] != tm->stamp) {
                tm->mark[e[t]] = tm->stamp;
                n_add[e[t]] = 0;
            }
            n_add[e[t]]++;
        }
    }
    for (a = 0; a < U->aug.size; a++)
        if (tm->mark[a] == tm->stamp) need += U->delta.row_len[a] + n_add[a];
    if (U->delta.used + need > U->delta.cap) {
        amps__delta_compact(U);
        *dused_old = U->delta.used;
    }
    if (U->delta.used + need > U->delta.cap) {
        amps_int cap = U->delta.cap;
        if (!U->grow)
            return amps__err(ctx, AMPS_ERR_CAPACITY,
                             "amps_update: %ld stored changes exceed cap_delta = %ld (raise it or set grow)",
                             (long)(U->delta.used + need), (long)U->delta.cap);
        while (cap < U->delta.used + need) cap = cap * 2 + 256;
        if (amps__realloc(ctx, (void **)&U->delta.col, (size_t)cap, sizeof(amps_int)) ||
            amps__realloc(ctx, (void **)&U->delta.val, (size_t)cap, sizeof(double)))
            return AMPS_ERR_OOM;
        U->delta.cap = cap;
    }
    for (a = 0; a < U->aug.size; a++)
        if (tm->mark[a] == tm->stamp) {
            amps__djour *d = U->journal.rows + U->journal.n_rows++;
            amps_int st = U->delta.row_start[a], len = U->delta.row_len[a], used = U->delta.used;
            d->pos = a;
            d->start = st;
            d->len = len;
            d->cap = U->delta.row_cap[a];
            memcpy(U->delta.col + used, U->delta.col + st, sizeof(amps_int) * (size_t)len);
            memcpy(U->delta.val + used, U->delta.val + st, sizeof(double) * (size_t)len);
            U->delta.row_start[a] = used;
            U->delta.row_cap[a] = len + n_add[a];
            U->delta.used += U->delta.row_cap[a];
        }
    return AMPS_OK;
}

/* Applies the recorded changes to Delta and the kinds (journaled) and marks the dense columns
   they change in lu.changed: the touched rows outside C, the new positions, and where a kind
   changes the column and those of its Delta-neighbours. */
static void amps__apply_pending(amps_update *U, amps_int u_old) {
    amps_marker *cm = &U->lu.changed;
    amps_int k, a;
    amps_marker_next(cm);
    for (k = 0; k < U->pending.n_delta; k++) {
        amps_int ra = U->aug.pos[U->pending.delta[k].r], rb = U->aug.pos[U->pending.delta[k].c];
        amps__delta_add(U, ra, rb, U->pending.delta[k].v);
        if (ra != rb) amps__delta_add(U, rb, ra, U->pending.delta[k].v);
        /* A(:, a) holds Delta(a, b) only for a and b both outside C (amps__acol); where a kind
           changes below, its column and its Delta-neighbours are marked there */
        if ((U->aug.kind[ra] | U->aug.kind[rb]) & AMPS__UCON) continue;
        cm->mark[ra] = cm->stamp;
        cm->mark[rb] = cm->stamp;
    }
    for (a = u_old; a < U->aug.size; a++) cm->mark[a] = cm->stamp;
    for (k = 0; k < U->pending.n_con; k++) {
        amps_int i = U->pending.con[k].i;
        amps__kjour *j;
        a = (i < U->N + U->pending.n_dofs && U->aug.pos[i] >= 0) ? U->aug.pos[i] : -1;
        if (a < 0) continue; /* release of an unconstrained index */
        if (U->pending.con[k].release && !(U->aug.kind[a] & AMPS__UCON)) continue;
        j = U->journal.kinds + U->journal.n_kinds++;
        j->pos = a;
        j->kind = U->aug.kind[a];
        j->g = U->aug.g[a];
        if (U->pending.con[k].release) U->aug.kind[a] &= (unsigned char)~AMPS__UCON;
        else {
            U->aug.kind[a] |= AMPS__UCON;
            U->aug.g[a] = U->pending.con[k].v;
        }
        if ((j->kind ^ U->aug.kind[a]) & AMPS__UCON) {
            amps_int t;
            cm->mark[a] = cm->stamp;
            for (t = 0; t < U->delta.row_len[a]; t++) cm->mark[U->delta.col[U->delta.row_start[a] + t]] = cm->stamp;
        }
    }
}

/* Step 3: the column order from the first changed column q0 on keeps the unchanged columns in
   their order and puts the changed ones after them, then the new ones. Returns q0. */
static amps_int amps__reorder_columns(amps_update *U, amps_int u_old) {
    const amps_marker *cm = &U->lu.changed;
    amps_int *order = U->lu.col_order, *tmp = U->work.idx, q0 = u_old, q, m, a;
    for (a = 0; a < u_old; a++)
        if (cm->mark[a] == cm->stamp && U->lu.col_pos[a] < q0) q0 = U->lu.col_pos[a];
    m = q0;
    for (q = q0; q < u_old; q++)
        if (cm->mark[order[q]] != cm->stamp) tmp[m++] = order[q];
    for (q = q0; q < u_old; q++)
        if (cm->mark[order[q]] == cm->stamp) tmp[m++] = order[q];
    for (q = q0; q < u_old; q++) order[q] = tmp[q];
    for (a = u_old; a < U->aug.size; a++) {
        order[a] = a;
        U->lu.row_perm[a] = a;
    }
    return q0;
}

/* Step 5: the LU from column q0 on. The unchanged columns after q0 keep their factor when the
   changed ones are few (amps__lu_drop); a growth of the new rows' multipliers refactors all.
   The drop of d changed columns before nk kept ones costs about nk d (1.5 nk + u) flops (the
   transforms applied to the kept columns and to L), refactoring them u_old (u_old^2 - q0^2) / 2;
   the cheaper is taken (both then append the changed and the new columns). */
static amps_status amps__lu_update(amps_update *U, amps_int q0, amps_int u_old, amps_int *bad) {
    const amps_marker *cm = &U->lu.changed;
    amps_int nk = 0, q, nf = q0, d;
    amps_status s;
    double drop, refac;
    for (q = q0; q < u_old; q++)
        if (cm->mark[U->lu.col_order[q]] != cm->stamp) nk++;
    d = u_old - q0 - nk;
    drop = (double)nk * (double)d * (1.5 * (double)nk + (double)U->aug.size);
    refac = 0.5 * (double)u_old * ((double)u_old * (double)u_old - (double)q0 * (double)q0);
    if (nk >= 8 && d <= AMPS__DMAX && drop < refac) {
        U->stats.lu_drops++;
        nf = amps__lu_drop(U, q0, nk, u_old);
        if (nf < q0 + nk) U->stats.lu_drop_fails++;
    }
    U->stats.lu_cols = U->aug.size - nf;
    s = amps__lu_extend(U, nf, u_old, bad);
    if (s == AMPS_ERR_CAPACITY) s = amps__lu_full(U, bad);
    return s;
}

/* Steps 3 and 5 of a commit whose new positions u_old.. have their W columns and G entries
   (memo.used was vused_old before them), and its end; on failure the rollback. */
static amps_status amps__commit_finish(amps_ctx *ctx, amps_update *U, amps_int u_old, size_t vused_old, int structural,
                                       int may_swap) {
    amps_int dused_old = U->delta.used, q0, bad = -1;
    amps_status s;
    double t0 = amps_now(), t1;
    U->journal.n_rows = 0;
    U->journal.n_kinds = 0;
    /* apply the pending changes to Delta and the kinds */
    if ((s = amps__delta_relocate(ctx, U, &dused_old)) != AMPS_OK) goto fail;
    amps__apply_pending(U, u_old);
    /* Steps 3 and 5: refactor from the first changed column; the changed ones go last */
    q0 = amps__reorder_columns(U, u_old);
    t1 = amps_now();
    U->stats.t_step[AMPS_STEP_DCOLS] = t1 - t0;
    t0 = t1;
    s = amps__lu_update(U, q0, u_old, &bad);
    t1 = amps_now();
    U->stats.t_step[AMPS_STEP_DENSE] = t1 - t0;
    if (s != AMPS_OK) { /* the dense pivot test failed: a singular K^, or an ill-conditioned one */
        amps_int bi = bad >= 0 ? U->aug.idx[bad] : -1;
        amps__restore(U, u_old, vused_old, dused_old);
        if (may_swap && !U->watch.job_y && amps__commit_fold(ctx, U) == AMPS_OK) {
            U->stats.pivot_folds++;
            return AMPS_OK;
        }
        amps_update_discard(U);
        return amps__err(ctx, AMPS_ERR_SINGULAR_UPDATE,
                         "amps_update_commit: the updated system is singular (pivot of index %ld below %g of its "
                         "column, and a re-factorization with the changes failed); the changes were discarded",
                         (long)bi, U->singular_tol);
    }
    /* done: the log of a running re-factorization, the new order, the solution stale */
    if (U->refac.job) amps__bg_log(U, U->pending.n_dofs, U->pending.delta, U->pending.n_delta);
    U->N += U->pending.n_dofs;
    amps_update_discard(U);
    U->sol.x_stale = U->sol.react_stale = U->sol.watched_stale = 1;
    U->sol.commit_unsolved = 1;
    U->stats.ncommit++;
    if (structural) U->kver++;
    amps__bg_after_commit(ctx, U, structural || U->aug.size > u_old, may_swap);
    return AMPS_OK;
fail:
    amps__rollback(U, u_old, vused_old, dused_old);
    return s;
}

/* The start of a commit: positions for the new indices, room for their W columns; on failure
   the changes are discarded. */
static amps_status amps__commit_grow(amps_ctx *ctx, amps_update *U) {
    amps_int u_old = U->aug.size;
    size_t vused_old = U->memo.used;
    amps_status s;
    U->journal.n_rows = 0;
    U->journal.n_kinds = 0;
    if ((s = amps__need_u(ctx, U, amps__count_new(U))) != AMPS_OK) {
        amps_update_discard(U);
        return s;
    }
    if ((s = amps__need_memo(ctx, U, amps__grow_aug(U))) != AMPS_OK) {
        amps__rollback(U, u_old, vused_old, U->delta.used);
        return s;
    }
    return AMPS_OK;
}

/* amps_update_commit; may_swap 0 (the haptic path) neither swaps nor starts a re-factorization. */
static amps_status amps__commit(amps_ctx *ctx, amps_update *U, int may_swap) {
    amps_int u_old;
    size_t vused_old;
    amps_status s;
    double t0, t1;
    int structural;
    if (!U) return amps__err(ctx, AMPS_ERR_ARG, "amps_update_commit: NULL engine");
    /* a finished re-factorization is swapped in first: the recorded changes move along and are
       then committed on the new base, against its small augmentation */
    if (U->refac.job && may_swap && !U->cjob.state) amps__bg_poll(ctx, U);
    if (!U->pending.n_delta && !U->pending.n_con && !U->pending.n_dofs) return AMPS_OK;
    if (may_swap && amps__commit_wants_fold(U) && amps__commit_fold(ctx, U) == AMPS_OK) return AMPS_OK;
    structural = U->pending.n_delta > 0 || U->pending.n_dofs > 0;
    t0 = amps_now();
    u_old = U->aug.size;
    vused_old = U->memo.used;
    if ((s = amps__commit_grow(ctx, U)) != AMPS_OK) return s;
    /* Step 1: W columns */
    amps__step1(U, u_old);
    t1 = amps_now();
    U->stats.t_step[AMPS_STEP_WCOLS] = t1 - t0;
    t0 = t1;
    /* Step 2: trapezoidal augmentation of G ([AMPS] Eq. 3.25-3.27), both triangles stored */
    amps__gcols(U, u_old);
    U->stats.t_step[AMPS_STEP_GRAM] = amps_now() - t0;
    return amps__commit_finish(ctx, U, u_old, vused_old, structural, may_swap);
}

AMPS_API amps_status amps_update_commit(amps_ctx *ctx, amps_update *U) { return amps__commit(ctx, U, 1); }

/* ---- the two-phase commit ---- */

/* The run phase's workspace (as work.chunk, row_map, closure, lanes) for base order n. */
static amps_status amps__cjob_workspace(amps_ctx *ctx, amps_update *U) {
    size_t nb = (size_t)U->nbuf, n = (size_t)U->n, k;
    if (U->cjob.ws_n == U->n && U->cjob.J) return AMPS_OK;
    amps__free(ctx, U->cjob.chunk);
    amps__free(ctx, U->cjob.row_map);
    amps__free(ctx, U->cjob.closure);
    amps__free(ctx, U->cjob.lanes);
    U->cjob.ws_n = 0;
    U->cjob.chunk = AMPS__CAST(double *, amps__malloc(ctx, nb * (size_t)U->work.chunk_rows * AMPS__VB, sizeof(double)));
    U->cjob.row_map = AMPS__CAST(amps_int *, amps__malloc(ctx, nb * n, sizeof(amps_int)));
    U->cjob.closure = AMPS__CAST(amps_int *, amps__malloc(ctx, nb * n, sizeof(amps_int)));
    U->cjob.lanes = AMPS__CAST(unsigned char *, amps__malloc(ctx, nb * 2 * n + 1, 1));
    if (!U->cjob.J) U->cjob.J = AMPS__CAST(amps_update *, amps__malloc(ctx, 1, sizeof(amps_update)));
    if (!U->cjob.chunk || !U->cjob.row_map || !U->cjob.closure || !U->cjob.lanes || !U->cjob.J)
        return amps__err(ctx, AMPS_ERR_OOM, "amps_update_commit_begin: out of memory");
    for (k = 0; k < nb * n; k++) U->cjob.row_map[k] = -1;
    U->cjob.ws_n = U->n;
    return AMPS_OK;
}

/* Moves the structural changes (matrix entries, DOFs, new constraints, releases and the moves of
   constraints released later) from pending to the job; moves of constraints stay. */
static amps_status amps__cjob_take(amps_ctx *ctx, amps_update *U) {
    amps_marker *mk = &U->work.mark_N;
    amps_int k, keep = 0, nc = 0;
    if (U->pending.n_delta > U->cjob.cap_delta) {
        if (amps__realloc(ctx, (void **)&U->cjob.delta, (size_t)U->pending.n_delta, sizeof(amps__pdelta)))
            return AMPS_ERR_OOM;
        U->cjob.cap_delta = U->pending.n_delta;
    }
    if (U->pending.n_con > U->cjob.cap_con) {
        if (amps__realloc(ctx, (void **)&U->cjob.con, (size_t)U->pending.n_con, sizeof(amps__pcon)))
            return AMPS_ERR_OOM;
        U->cjob.cap_con = U->pending.n_con;
    }
    if (U->pending.n_delta) memcpy(U->cjob.delta, U->pending.delta, sizeof(amps__pdelta) * (size_t)U->pending.n_delta);
    U->cjob.n_delta = U->pending.n_delta;
    U->cjob.n_dofs = U->pending.n_dofs;
    amps_marker_next(mk);
    for (k = 0; k < U->pending.n_con; k++)
        if (U->pending.con[k].release) mk->mark[U->pending.con[k].i] = mk->stamp;
    for (k = 0; k < U->pending.n_con; k++) {
        const amps__pcon *c = U->pending.con + k;
        if (!c->release && c->i < U->N && mk->mark[c->i] != mk->stamp && amps__is_con(U, c->i))
            U->pending.con[keep++] = *c;
        else U->cjob.con[nc++] = *c;
    }
    U->cjob.n_con = nc;
    U->pending.n_con = keep;
    U->pending.n_delta = 0;
    U->pending.n_dofs = 0;
    return AMPS_OK;
}

AMPS_API amps_status amps_update_commit_begin(amps_ctx *ctx, amps_update *U) {
    amps_int u_old, a, nl = 0;
    size_t vused_old;
    amps_status s;
    if (!U) return amps__err(ctx, AMPS_ERR_ARG, "amps_update_commit_begin: NULL engine");
    if (U->cjob.state) return amps__err(ctx, AMPS_ERR_STATE, "amps_update_commit_begin: a job is in progress");
    if (U->refac.job) amps__bg_poll(ctx, U);
    if (!U->pending.n_delta && !U->pending.n_dofs && amps__count_new(U) == 0) {
        amps_int k; /* no new positions and no matrix change: one ordinary (short) commit */
        for (k = 0; k < U->pending.n_con && !U->pending.con[k].release; k++) {}
        if (k == U->pending.n_con) {
            if ((s = amps__commit(ctx, U, 1)) != AMPS_OK) return s;
            U->cjob.state = 1;
            U->cjob.ran = 0;
            U->cjob.nlist = -1;
            return AMPS_OK;
        }
    }
    if ((s = amps__cjob_workspace(ctx, U)) != AMPS_OK) {
        amps_update_discard(U); /* as documented for a failed begin */
        return s;
    }
    u_old = U->aug.size;
    vused_old = U->memo.used;
    if ((s = amps__commit_grow(ctx, U)) != AMPS_OK) return s;
    if (U->aug.size - u_old > U->cjob.cap_list &&
        amps__realloc(ctx, (void **)&U->cjob.list, (size_t)(U->aug.size - u_old), sizeof(amps_int))) {
        amps__rollback(U, u_old, vused_old, U->delta.used);
        return AMPS_ERR_OOM;
    }
    if (U->aug.size - u_old > U->cjob.cap_list) U->cjob.cap_list = U->aug.size - u_old;
    nl = amps__step1_list(U, u_old, U->cjob.list);
    if ((s = amps__cjob_take(ctx, U)) != AMPS_OK) {
        amps__rollback(U, u_old, vused_old, U->delta.used);
        return amps__err(ctx, s, "amps_update_commit_begin: out of memory");
    }
    /* the run phase's copy sees the new positions; the engine does not until the end */
    *U->cjob.J = *U;
    U->cjob.J->work.chunk = U->cjob.chunk;
    U->cjob.J->work.row_map = U->cjob.row_map;
    U->cjob.J->work.closure = U->cjob.closure;
    U->cjob.J->work.lanes = U->cjob.lanes;
    for (a = u_old; a < U->aug.size; a++) U->aug.pos[U->aug.idx[a]] = -1;
    U->aug.size = u_old;
    U->cjob.u_old = u_old;
    U->cjob.vused_old = vused_old;
    U->cjob.nlist = nl;
    U->cjob.state = 1;
    U->cjob.ran = 0;
    return AMPS_OK;
}

AMPS_API void amps_update_commit_run(amps_update *U) {
    amps_update *J;
    double t0, t1;
    if (!U || U->cjob.state != 1 || U->cjob.ran) return;
    if (U->cjob.nlist >= 0) {
        J = U->cjob.J;
        t0 = amps_now();
        amps__wcols(J, U->cjob.list, U->cjob.nlist);
        t1 = amps_now();
        amps__gcols(J, U->cjob.u_old);
        U->cjob.t_wcols = t1 - t0;
        U->cjob.t_gram = amps_now() - t1;
    }
    U->cjob.ran = 1; /* not state: the caller's thread reads that concurrently */
}

AMPS_API amps_status amps_update_commit_end(amps_ctx *ctx, amps_update *U) {
    amps_int u_old, a, nc, left;
    amps_status s;
    if (!U) return amps__err(ctx, AMPS_ERR_ARG, "amps_update_commit_end: NULL engine");
    if (!U->cjob.state) return amps__err(ctx, AMPS_ERR_STATE, "amps_update_commit_end: no commit begun");
    if (!U->cjob.ran) amps_update_commit_run(U);
    U->cjob.state = 0;
    if (U->cjob.nlist < 0) return AMPS_OK;
    u_old = U->cjob.u_old;
    U->aug.size = U->cjob.J->aug.size;
    for (a = u_old; a < U->aug.size; a++) U->aug.pos[U->aug.idx[a]] = a;
    /* the job's changes first, then the moves recorded since */
    nc = U->cjob.n_con;
    left = U->pending.n_con;
    if ((s = amps__need_pending(ctx, U, U->cjob.n_delta, nc)) != AMPS_OK) {
        amps__rollback(U, u_old, U->cjob.vused_old, U->delta.used);
        return s;
    }
    if (nc && left) memmove(U->pending.con + nc, U->pending.con, sizeof(amps__pcon) * (size_t)left);
    if (nc) memcpy(U->pending.con, U->cjob.con, sizeof(amps__pcon) * (size_t)nc);
    U->pending.n_con = nc + left;
    if (U->cjob.n_delta) memcpy(U->pending.delta, U->cjob.delta, sizeof(amps__pdelta) * (size_t)U->cjob.n_delta);
    U->pending.n_delta = U->cjob.n_delta;
    U->pending.n_dofs = U->cjob.n_dofs;
    U->stats.t_step[AMPS_STEP_WCOLS] = U->cjob.t_wcols;
    U->stats.t_step[AMPS_STEP_GRAM] = U->cjob.t_gram;
    return amps__commit_finish(ctx, U, u_old, U->cjob.vused_old, 1, 1);
}

/* ---- Steps 4 and 6 ---- */

/* The next amps__update_ct is a full forward solve (the forces changed on many rows). */
static int amps__ct_full(const amps_update *U) {
    return U->force.changed_all ||
           (U->force.n_changed > 0 && (U->force.n_increments >= 1024 || U->force.n_changed > U->n / 8));
}

/* Brings ct = D^{-1/2} L^{-1} P^T f up to date: the changed base forces go through one sparse
   forward solve over their closure; after many increments (or a long list) a full solve. */
static void amps__update_ct(amps_update *U) {
    const amps_factor *F = U->F;
    amps_int n = U->n, k, nb = 0, *list = U->work.idx, *clo = U->work.idx + n;
    double *x = U->work.vec;
    if (U->force.n_changed == 0 && !U->force.changed_all) return;
    U->sol.n_rhs = 0;
    if (amps__ct_full(U)) {
        for (k = 0; k < n; k++) x[k] = U->force.f[F->perm[k]];
        amps_lsolve(F, x);
        for (k = 0; k < n; k++) {
            U->force.ct[k] = x[k] * U->base.inv_sqrt_d[k];
            x[k] = 0;
        }
        memcpy(U->force.f_ct, U->force.f, sizeof(double) * (size_t)n);
        U->force.n_increments = 0;
    } else {
        amps_int ncl;
        amps_marker_next(&U->work.mark_n);
        for (k = 0; k < U->force.n_changed; k++) {
            amps_int i = U->force.changed[k], p = F->iperm[i];
            double d = U->force.f[i] - U->force.f_ct[i];
            U->force.f_ct[i] = U->force.f[i];
            if (d == 0.0) continue;
            x[p] += d;
            if (U->work.mark_n.mark[p] != U->work.mark_n.stamp) {
                U->work.mark_n.mark[p] = U->work.mark_n.stamp;
                list[nb++] = p;
            }
        }
        if (nb > 0) {
            ncl = amps_lsolve_sparse(F, nb, list, x, clo, &U->work.mark_n);
            for (k = 0; k < ncl; k++) {
                amps_int j = clo[k];
                U->force.ct[j] += x[j] * U->base.inv_sqrt_d[j];
                x[j] = 0;
            }
            U->force.n_increments++;
        }
    }
    U->force.n_changed = 0;
    U->force.changed_all = 0;
}

/* Step 5: the forces w of the augmentation (and y = x_U, primal form) for right-hand side
   r = H^T K-bar^{-1} f and prescribed values gv on C (U positions; NULL: g = 0). */
static void amps__dense_step_g(amps_update *U, const double *r, const double *gv, double *yv, double *wv) {
    amps_int u = U->aug.size, a, k;
    size_t ld = (size_t)U->aug.cap;
    double *z = U->dense.z, *b = U->dense.b, *d = U->dense.tmp;
#define AMPS__G(a) (gv ? gv[a] : 0.0)
    if (U->form == AMPS_FORM_PRIMAL) {
        /* b = r - G d - g^, d = Delta[F', C] g; z = A^{-1} b; y = (z_F', g); w = (Delta_F' y, z_C) */
        for (a = 0; a < u; a++) b[a] = r[a] - ((U->aug.kind[a] & AMPS__UCON) ? AMPS__G(a) : 0.0);
        if (gv) {
            for (a = 0; a < u; a++) {
                double sum = 0;
                if (!(U->aug.kind[a] & AMPS__UCON))
                    for (k = 0; k < U->delta.row_len[a]; k++) {
                        amps_int bb = U->delta.col[U->delta.row_start[a] + k];
                        if (U->aug.kind[bb] & AMPS__UCON) sum += U->delta.val[U->delta.row_start[a] + k] * gv[bb];
                    }
                d[a] = sum;
            }
            for (k = 0; k < u; k++)
                if (d[k] != 0.0) {
                    const double *gk = U->lu.G + (size_t)k * ld;
                    amps__axpy_sub(b, gk, d[k], u);
                }
        }
        amps__lu_solve(U, b, z, U->dense.tmp);
        for (a = 0; a < u; a++) yv[a] = (U->aug.kind[a] & AMPS__UCON) ? AMPS__G(a) : z[a];
        for (a = 0; a < u; a++) {
            double sum = 0;
            if (U->aug.kind[a] & AMPS__UCON) {
                wv[a] = z[a];
                continue;
            }
            for (k = 0; k < U->delta.row_len[a]; k++)
                sum += U->delta.val[U->delta.row_start[a] + k] * yv[U->delta.col[U->delta.row_start[a] + k]];
            wv[a] = sum;
        }
    } else {
        /* b'_F' = Delta[F', :] r^ (r^ = r on F', g on C), b'_C = r_C - g; w = A^{-T} b' */
        double *rh = yv;
        for (a = 0; a < u; a++) rh[a] = (U->aug.kind[a] & AMPS__UCON) ? AMPS__G(a) : r[a];
        for (a = 0; a < u; a++) {
            double sum = 0;
            if (U->aug.kind[a] & AMPS__UCON) {
                b[a] = r[a] - AMPS__G(a);
                continue;
            }
            for (k = 0; k < U->delta.row_len[a]; k++)
                sum += U->delta.val[U->delta.row_start[a] + k] * rh[U->delta.col[U->delta.row_start[a] + k]];
            b[a] = sum;
        }
        amps__lu_solve_t(U, b, wv, U->dense.tmp);
        for (a = 0; a < u; a++) yv[a] = (U->aug.kind[a] & AMPS__UCON) ? AMPS__G(a) : 0.0;
    }
#undef AMPS__G
}

/* amps__dense_step_g with the engine's prescribed values (hom: zero). */
static void amps__dense_step(amps_update *U, const double *r, int hom, double *yv, double *wv) {
    amps__dense_step_g(U, r, hom ? NULL : U->aug.g, yv, wv);
}

/* sv -= D^{-1/2} sum_a c_a W_a (permuted n-vector; appended DOFs have no W), and where t is
   not NULL t += sum_a |c_a| |D^{-1/2} W_a| in the same pass (amps__cancel_ratio's sum). */
static void amps__scatter_w(const amps_update *U, const double *c, double *sv, double *t) {
    amps_int a, k;
    for (a = 0; a < U->aug.size; a++) {
        const double *w = U->memo.val + U->memo.off[a];
        const amps_int *wi = U->memo.idx + U->memo.off[a];
        double ca = c[a];
        if (U->aug.idx[a] >= U->n || ca == 0.0) continue;
        if (t)
            for (k = 0; k < U->memo.len[a]; k++) {
                double q = ca * w[k] * U->base.inv_sqrt_d[wi[k]];
                sv[wi[k]] -= q;
                t[wi[k]] += fabs(q);
            }
        else
            for (k = 0; k < U->memo.len[a]; k++) sv[wi[k]] -= ca * w[k] * U->base.inv_sqrt_d[wi[k]];
    }
}

/* (K^ v)_i for the committed K^, reading v[j] for the neighbours j of i only. */
static double amps__krow(const amps_update *U, amps_int i, const double *v) {
    amps_int p, a = U->aug.pos[i], k;
    double s = 0;
    if (i < U->n)
        for (p = U->base.Kp[i]; p < U->base.Kp[i + 1]; p++) s += U->base.Kx[p] * v[U->base.Ki[p]];
    else s = U->sigma * v[i];
    if (a >= 0)
        for (k = 0; k < U->delta.row_len[a]; k++)
            s += U->delta.val[U->delta.row_start[a] + k] * v[U->aug.idx[U->delta.col[U->delta.row_start[a] + k]]];
    return s;
}

/* Refinement: x~ = K-bar^{-1}(f - H w) on the free base rows of U and their neighbours (what
   rho reads) by a partial backward solve of sv (a copy), rho = (f - K^ x~) on the free rows of U
   (0 on the constrained ones, whose x~ is g), and the correction problem K^ d = H rho (d_C = 0)
   gives dense.w_corr; afterwards the full solve uses w + w_corr - rho. x~ is gathered into x. */
static void amps__refine(amps_update *U, const double *sv, const double *wv, const double *fv, int hom, double *x) {
    const amps_factor *F = U->F;
    amps_int u = U->aug.size, n = U->n, a, k, p, nreq = 0, *req = U->work.idx, *clo = U->work.idx + n, ncl;
    double *s2 = U->work.vec2;
    size_t ld = (size_t)U->aug.cap;
    amps_marker_next(&U->work.mark_n);
    for (a = 0; a < u; a++) {
        amps_int i = U->aug.idx[a];
        if (i >= n || (U->aug.kind[a] & AMPS__UCON)) continue;
        for (p = U->base.Kp[i]; p < U->base.Kp[i + 1]; p++) {
            amps_int q = F->iperm[U->base.Ki[p]];
            if (U->work.mark_n.mark[q] != U->work.mark_n.stamp) {
                U->work.mark_n.mark[q] = U->work.mark_n.stamp;
                req[nreq++] = q;
            }
        }
        {
            amps_int q = F->iperm[i];
            if (U->work.mark_n.mark[q] != U->work.mark_n.stamp) {
                U->work.mark_n.mark[q] = U->work.mark_n.stamp;
                req[nreq++] = q;
            }
        }
    }
    memcpy(s2, sv, sizeof(double) * (size_t)n);
    ncl = amps_closure(F, nreq, req, clo, &U->work.mark_n);
    amps__ltsolve_closure_par(F, ncl, clo, s2, &U->par, U->nthr, req); /* req is free again */
    for (k = 0; k < ncl; k++) x[F->perm[clo[k]]] = s2[clo[k]];
    for (k = n; k < U->N; k++) {
        a = U->aug.pos[k];
        x[k] = (fv[k] - (a >= 0 ? wv[a] : 0.0)) / U->sigma;
    }
    for (a = 0; a < u; a++)
        if (U->aug.kind[a] & AMPS__UCON) x[U->aug.idx[a]] = hom ? 0.0 : U->aug.g[a];
    for (a = 0; a < u; a++) {
        amps_int i = U->aug.idx[a];
        U->dense.rho[a] = (U->aug.kind[a] & AMPS__UCON) ? 0.0 : fv[i] - amps__krow(U, i, x);
    }
    /* r_d = G rho */
    for (a = 0; a < u; a++) U->dense.r_corr[a] = 0;
    for (k = 0; k < u; k++)
        if (U->dense.rho[k] != 0.0) {
            const double *gk = U->lu.G + (size_t)k * ld;
            for (a = 0; a < u; a++) U->dense.r_corr[a] += gk[a] * U->dense.rho[k];
        }
    amps__dense_step(U, U->dense.r_corr, 1, U->dense.y_corr, U->dense.w_corr);
    for (a = 0; a < u; a++) U->dense.w_corr[a] -= U->dense.rho[a];
}

/* Step 4: r = H^T K-bar^{-1} f = W^T ct on base positions, f/sigma on appended ones. With
   cache (ct is force.ct), the base entries r[0..sol.n_rhs-1] are current and only later ones
   are formed. */
/* A parallel loop of amps__step4. */
typedef struct amps__s4job {
    const amps_update *U;
    const double *ct;
    double *r;
    amps_int a0;
} amps__s4job;

/* r[a] = W_a^T ct for the base positions a in a0 + [b, e). */
static void amps__s4_rows(amps_int b, amps_int e, int slot, void *arg) {
    amps__s4job *j = AMPS__CAST(amps__s4job *, arg);
    const amps_update *U = j->U;
    amps_int a;
    (void)slot;
    for (a = j->a0 + b; a < j->a0 + e; a++) {
        amps_int i = U->aug.idx[a], t;
        if (i < U->n) {
            const double *w = U->memo.val + U->memo.off[a];
            const amps_int *wi = U->memo.idx + U->memo.off[a];
            double sum = 0;
            for (t = 0; t < U->memo.len[a]; t++) sum += w[t] * j->ct[wi[t]];
            j->r[a] = sum;
        }
    }
}

static void amps__step4(amps_update *U, const double *ct, const double *fv, int cache, double *r) {
    amps_int u = U->aug.size, n = U->n, a, a0 = cache ? U->sol.n_rhs : 0;
    double t0 = amps_now();
    amps__s4job j;
    j.U = U;
    j.ct = ct;
    j.r = r;
    j.a0 = a0;
    amps__par_for(&U->par, u - a0 > 64 ? U->nthr : 1, u - a0, 16, amps__s4_rows, &j);
    for (a = 0; a < u; a++)
        if (U->aug.idx[a] >= n) r[a] = fv[U->aug.idx[a]] / U->sigma;
    if (cache) U->sol.n_rhs = u;
    U->stats.t_step[AMPS_STEP_RHS] += amps_now() - t0;
}

/* Watched entries that do not come from the backward solve: appended DOFs ((f - w) / sigma)
   and members of U whose value the dense system gives (constrained; all with xs_from_dense). x[i] is set and
   wovr[k] = 1 for those (i = widx[k]), wovr[k] = 0 for the others. */
static void amps__watch_fixed(amps_update *U, const double *fv, double *x) {
    amps_int k;
    for (k = 0; k < U->watch.n; k++) {
        amps_int i = U->watch.idx[k], a = U->aug.pos[i];
        U->watch.from_dense[k] = 1;
        if (a >= 0 && ((U->aug.kind[a] & AMPS__UCON) || (U->xs_from_dense && U->form == AMPS_FORM_PRIMAL)))
            x[i] = U->dense.y[a];
        else if (i >= U->n) x[i] = (fv[i] - (a >= 0 ? U->dense.w[a] : 0.0)) / U->sigma;
        else U->watch.from_dense[k] = 0;
    }
}

/* The cancellation ratio of Step 6: mu = || sum_a |w_a| |D^{-1/2} W_a| ||_2 / ||sv||_2, where
   sv = D^{-1/2} ct - sum_a w_a D^{-1/2} W_a is what the backward solve turns into x, from
   t = sum_a |w_a| |D^{-1/2} W_a| (amps__scatter_w; with the local refinement's corrections
   |w_a| + |w_corr_a|, an upper bound). The entries of sv are rounded by ~eps (|D^{-1/2} ct| + t),
   so for mu of order one x has the rounding of a direct solve (amps__accuracy). O(n). */
static double amps__cancel_ratio(const amps_update *U, const double *sv, const double *t) {
    amps_int k;
    double num = 0, den = 0;
    for (k = 0; k < U->n; k++) {
        num += t[k] * t[k];
        den += sv[k] * sv[k];
    }
    return den > 0 ? sqrt(num / den) : (num > 0 ? HUGE_VAL : 0.0);
}

/* Steps 4-6 for forces fv (N) with ct = D^{-1/2} L^{-1} P^T fv(0:n) and the prescribed values
   (hom: zero) into x (N). A full solve that amps__accuracy may skip sets stats.cancel_ratio. */
static void amps__solve_core(amps_update *U, const double *ct, const double *fv, int hom, int watched, double *x) {
    const amps_factor *F = U->F;
    amps_int u = U->aug.size, n = U->n, a, k;
    double t0, t1, *r = hom ? U->dense.r_corr : U->dense.rhs, *yv = U->dense.y, *wv = U->dense.w, *sv = U->work.vec,
                   *mt;
    amps__step4(U, ct, fv, !hom, r);
    t0 = amps_now();
    /* Step 5 */
    amps__dense_step(U, r, hom, yv, wv);
    t1 = amps_now();
    U->stats.t_step[AMPS_STEP_DENSE] += t1 - t0;
    t0 = t1;
    /* Step 6: x = K-bar^{-1} (f - H w), permuted: L^{-T} D^{-1/2} (ct - sum_a w_a W_a) */
    /* mt: amps__accuracy's skip test wants the cancellation ratio (guard.ct as its sum t) */
    mt = !hom && !watched && U->refac.opts.refine_tol > 0 && U->guard.tol <= 0 ? U->guard.ct : NULL;
    for (k = 0; k < n; k++) sv[k] = ct[k] * U->base.inv_sqrt_d[k];
    if (mt)
        for (k = 0; k < n; k++) mt[k] = 0.0;
    amps__scatter_w(U, wv, sv, mt);
    for (a = 0; a < u && (U->aug.kind[a] & AMPS__UCON); a++) {}
    if (a < u) { /* a free row in U (rho is 0 on constrained rows: no correction) */
        int it;
        for (it = 0; it < U->refine; it++) {
            amps__refine(U, sv, wv, fv, hom, x);
            amps__scatter_w(U, U->dense.w_corr, sv, mt);
            for (a = 0; a < u; a++) {
                wv[a] += U->dense.w_corr[a];
                yv[a] += U->dense.y_corr[a];
            }
        }
    }
    if (mt) U->stats.cancel_ratio = amps__cancel_ratio(U, sv, mt);
    if (watched) {
        amps__watch_fixed(U, fv, x);
        if (watched == 2) {
            /* a two-phase job: the backward solve runs later, in amps_update_watched_run */
            for (k = 0; k < U->watch.n; k++)
                if (U->watch.from_dense[k]) U->watch.job_xw[k] = x[U->watch.idx[k]];
            memcpy(U->watch.job_y, sv, sizeof(double) * (size_t)n);
        } else {
            /* the watched entries only: L^{-T} on their closure */
            amps_ltsolve_closure(F, U->watch.n_closure, U->watch.closure, sv);
            for (k = 0; k < U->watch.n; k++)
                if (!U->watch.from_dense[k]) x[U->watch.idx[k]] = sv[F->iperm[U->watch.idx[k]]];
        }
        memset(sv, 0, sizeof(double) * (size_t)n);
        U->stats.t_step[AMPS_STEP_SOLVE] += amps_now() - t0;
        return;
    } else {
        amps__ltsolve_par(F, sv, &U->par, U->nthr);
        for (k = 0; k < n; k++) {
            x[F->perm[k]] = sv[k];
            sv[k] = 0.0;
        }
        for (k = n; k < U->N; k++) {
            a = U->aug.pos[k];
            x[k] = (fv[k] - (a >= 0 ? wv[a] : 0.0)) / U->sigma;
        }
    }
    for (a = 0; a < u; a++)
        if ((U->aug.kind[a] & AMPS__UCON) || (U->xs_from_dense && U->form == AMPS_FORM_PRIMAL))
            x[U->aug.idx[a]] = yv[a];
    U->stats.t_step[AMPS_STEP_SOLVE] += amps_now() - t0;
}

static void amps__kmul(const amps_update *U, const double *v, double *y);

/* Error-free transformations: a b = *p + *e and a + b = *s + *e exactly (TwoProduct by fma where
   it is a hardware instruction, else by Dekker's split; TwoSum by Knuth). */
static void amps__two_prod(double a, double b, double *p, double *e) {
#ifdef FP_FAST_FMA
    *p = a * b;
    *e = fma(a, b, -*p);
#else
    static const double split = 134217729.0; /* 2^27 + 1 */
    double t = split * a, ah = t - (t - a), al = a - ah, bh, bl;
    t = split * b;
    bh = t - (t - b);
    bl = b - bh;
    *p = a * b;
    *e = ((ah * bh - *p) + ah * bl + al * bh) + al * bl;
#endif
}
static void amps__two_sum(double a, double b, double *s, double *e) {
    double z, t;
    *s = a + b;
    z = *s - a;
    t = *s - z;
    *e = (a - t) + (b - z);
}

/* hi + lo -= a v in double-double; *t += |a v|. */
static void amps__dd_sub_prod(double a, double v, double *hi, double *lo, double *t) {
    double p, e, s, e2;
    amps__two_prod(-a, v, &p, &e);
    amps__two_sum(*hi, p, &s, &e2);
    *hi = s;
    *lo += e + e2;
    *t += fabs(p);
}

/* (f^ - K^ x)_j, row j of the residual, in double, and *ax = (|K^| |x|)_j; or (dd) accumulated in
   double-double and rounded once: its rounding error is then eps |rho_j| + O(eps^2) (|K^| |x|)_j,
   where a double sum leaves ~eps (|K^| |x|)_j, the size of the residual being corrected. */
static double amps__resid_row(const amps_update *U, amps_int j, const double *x, int dd, double *ax) {
    amps_int a = U->aug.pos[j], p, k, p0 = j < U->n ? U->base.Kp[j] : 0, p1 = j < U->n ? U->base.Kp[j + 1] : 0;
    const amps_int *dc = a >= 0 ? U->delta.col + U->delta.row_start[a] : NULL;
    const double *dv = a >= 0 ? U->delta.val + U->delta.row_start[a] : NULL;
    amps_int nd = a >= 0 ? U->delta.row_len[a] : 0;
    double hi = U->force.f[j], lo = 0, s = 0, t = 0;
    if (!dd) {
        if (j < U->n)
            for (p = p0; p < p1; p++) {
                double q = U->base.Kx[p] * x[U->base.Ki[p]];
                s += q;
                t += fabs(q);
            }
        else t = fabs(s = U->sigma * x[j]);
        for (k = 0; k < nd; k++) {
            double q = dv[k] * x[U->aug.idx[dc[k]]];
            s += q;
            t += fabs(q);
        }
        *ax = t;
        return hi - s;
    }
    if (j < U->n)
        for (p = p0; p < p1; p++) amps__dd_sub_prod(U->base.Kx[p], x[U->base.Ki[p]], &hi, &lo, &t);
    else amps__dd_sub_prod(U->sigma, x[j], &hi, &lo, &t);
    for (k = 0; k < nd; k++) amps__dd_sub_prod(dv[k], x[U->aug.idx[dc[k]]], &hi, &lo, &t);
    *ax = t;
    return hi + lo;
}

#ifdef AMPS__SSE2
/* *S += a[0..5] .* (X0, X1, X2) and *T += |a[0..5] .* (X0, X1, X2)|, lane by lane. */
static void amps__blk_row(const double *a, __m128d X0, __m128d X1, __m128d X2, __m128d *S, __m128d *T) {
    const __m128d nosign = _mm_castsi128_pd(_mm_set_epi32(0x7fffffff, -1, 0x7fffffff, -1));
    __m128d q0 = _mm_mul_pd(_mm_loadu_pd(a), X0), q1 = _mm_mul_pd(_mm_loadu_pd(a + 2), X1),
            q2 = _mm_mul_pd(_mm_loadu_pd(a + 4), X2);
    *S = _mm_add_pd(_mm_add_pd(_mm_add_pd(*S, q0), q1), q2);
    *T = _mm_add_pd(_mm_add_pd(_mm_add_pd(*T, _mm_and_pd(q0, nosign)), _mm_and_pd(q1, nosign)), _mm_and_pd(q2, nosign));
}
#endif

/* Rows 3B..3B+2 of the base part of K^ x (base.blk3): s[r] = (K x)_{3B+r}, t[r] = (|K| |x|)_{3B+r},
   one column index per 3x3 block (base.bcol: the pass reads 8 bytes of K and 4/9 of an index per
   entry, against 12 with Ki). The order of the sums is fixed by the pattern alone (with
   SSE2: two lanes, entries 2i and 2i+1 of the row, added at the end, then a last odd block), so
   a result does not depend on threads or schedule; it differs from amps__resid_row's by rounding,
   which only the check (its trigger and stats) sees. */
static void amps__resid_blk(const amps_update *U, amps_int B, const double *x, double s[3], double t[3]) {
    const amps_int *bc = U->base.bcol + U->base.Kp[3 * B] / 9; /* block k / 3 starts at column bc[k / 3] */
    const double *a0 = U->base.Kx + U->base.Kp[3 * B], *a1 = U->base.Kx + U->base.Kp[3 * B + 1],
                 *a2 = U->base.Kx + U->base.Kp[3 * B + 2];
    amps_int k = 0, len = U->base.Kp[3 * B + 1] - U->base.Kp[3 * B];
    double s0 = 0, s1 = 0, s2 = 0, t0 = 0, t1 = 0, t2 = 0;
#ifdef AMPS__SSE2
    {
        __m128d S0 = _mm_setzero_pd(), S1 = S0, S2 = S0, T0 = S0, T1 = S0, T2 = S0, X0, X1, X2;
        double l0[2], l1[2], l2[2];
        /* two blocks (6 entries of each row) at a time: X0 X1 X2 = x of columns c, c+1 | c+2, d |
           d+1, d+2, where c and d are the blocks' first columns */
        for (; k + 6 <= len; k += 6) {
            const double *xc = x + bc[k / 3], *xd = x + bc[k / 3 + 1];
            X0 = _mm_loadu_pd(xc);
            X1 = _mm_loadh_pd(_mm_load_sd(xc + 2), xd);
            X2 = _mm_loadu_pd(xd + 1);
            amps__blk_row(a0 + k, X0, X1, X2, &S0, &T0);
            amps__blk_row(a1 + k, X0, X1, X2, &S1, &T1);
            amps__blk_row(a2 + k, X0, X1, X2, &S2, &T2);
        }
        _mm_storeu_pd(l0, S0), s0 = l0[0] + l0[1], _mm_storeu_pd(l0, T0), t0 = l0[0] + l0[1];
        _mm_storeu_pd(l1, S1), s1 = l1[0] + l1[1], _mm_storeu_pd(l1, T1), t1 = l1[0] + l1[1];
        _mm_storeu_pd(l2, S2), s2 = l2[0] + l2[1], _mm_storeu_pd(l2, T2), t2 = l2[0] + l2[1];
    }
#endif
    for (; k < len; k += 3) {
        const double *xc = x + bc[k / 3];
        double x0 = xc[0], x1 = xc[1], x2 = xc[2], q;
        q = a0[k] * x0, s0 += q, t0 += fabs(q);
        q = a1[k] * x0, s1 += q, t1 += fabs(q);
        q = a2[k] * x0, s2 += q, t2 += fabs(q);
        q = a0[k + 1] * x1, s0 += q, t0 += fabs(q);
        q = a1[k + 1] * x1, s1 += q, t1 += fabs(q);
        q = a2[k + 1] * x1, s2 += q, t2 += fabs(q);
        q = a0[k + 2] * x2, s0 += q, t0 += fabs(q);
        q = a1[k + 2] * x2, s1 += q, t1 += fabs(q);
        q = a2[k + 2] * x2, s2 += q, t2 += fabs(q);
    }
    s[0] = s0, s[1] = s1, s[2] = s2;
    t[0] = t0, t[1] = t1, t[2] = t2;
}

/* Constrained rows of amps__backward_error (rho_j = 0). */
static int amps__resid_con(const amps_update *U, amps_int j) {
    amps_int a = U->aug.pos[j];
    return a >= 0 && (U->aug.kind[a] & AMPS__UCON);
}

/* Adds rho_j^2, x_j^2, f^_j^2 and ((|K^| |x|)_j + |f^_j|)^2 (ax: (|K^| |x|)_j) to sums[0..3]. */
static void amps__resid_sums(const amps_update *U, amps_int j, const double *x, double rj, double ax, double sums[4]) {
    double f = U->force.f[j];
    ax += fabs(f);
    sums[0] += rj * rj;
    sums[1] += x[j] * x[j];
    sums[2] += f * f;
    sums[3] += ax * ax;
}

/* Row j < n of amps__backward_error from the base part kx = (K x)_j, tx = (|K| |x|)_j: adds the
   delta row's part and sets rho_j = (f^ - K^ x)_j and ax_j = (|K^| |x|)_j (free rows; both 0 on
   a constrained one). */
static void amps__resid_base_row(const amps_update *U, amps_int j, const double *x, double kx, double tx, double *rho,
                                 double *ax) {
    amps_int a = U->aug.pos[j], k;
    if (amps__resid_con(U, j)) {
        rho[j] = ax[j] = 0.0;
        return;
    }
    for (k = 0; a >= 0 && k < U->delta.row_len[a]; k++) {
        double q = U->delta.val[U->delta.row_start[a] + k] * x[U->aug.idx[U->delta.col[U->delta.row_start[a] + k]]];
        kx += q;
        tx += fabs(q);
    }
    rho[j] = U->force.f[j] - kx;
    ax[j] = tx;
}

/* The node blocks [b0, b1) of amps__backward_error's base rows: rho_j and ax_j of their rows.
   Each row has one writer, so the chunks may run on any participants. */
#ifndef AMPS__BE_PARMIN
#define AMPS__BE_PARMIN 6144 /* rows below which the check runs on one participant */
#endif
typedef struct amps__bejob {
    const amps_update *U;
    const double *x;
    double *rho, *ax;
} amps__bejob;

static void amps__be_blocks(amps_int b0, amps_int b1, int slot, void *arg) {
    const amps__bejob *j = AMPS__CAST(const amps__bejob *, arg);
    double sb[3], tb[3];
    amps_int B, r;
    (void)slot;
    for (B = b0; B < b1; B++) {
        amps__resid_blk(j->U, B, j->x, sb, tb);
        for (r = 0; r < 3; r++) amps__resid_base_row(j->U, 3 * B + r, j->x, sb[r], tb[r], j->rho, j->ax);
    }
}

/* rho = f^ - K^ x on the free rows F (0 on the constrained rows C) in one pass over K^ (nnz(K^);
   in double-double when dd; by 3x3 blocks when base.blk3 and !dd, the blocks on the parallel
   layer, their rows' sums afterwards in row order so that the result does not depend on the
   participants), and two backward errors of x on the reduced system: the normwise
   eta = ||rho_F||_2 / (||K-bar||_inf ||x_F||_2 + ||f^_F||_2) (returned) and the mixed
   *omega = ||rho_F||_2 / || |K^| |x| + |f^| ||_2 (F rows) >= eta, which does not take the largest
   row's norm for every row's (slivers: omega 20x eta). ||K-bar||_inf stands for ||K^||_inf: the
   changes (cuts, constraints) remove couplings, and the unmodified rows dominate the norm.
   *rnorm receives ||rho_F||_2. rho is work.resid; guard.scratch holds (|K^| |x|)_j meanwhile. */
static double amps__backward_error(const amps_update *U, const double *x, double *rho, double *rnorm, int dd,
                                   double *omega) {
    double num, xn, fn, den, *axj = U->guard.scratch;
    amps_int N = U->N, j, nb = !dd && U->base.blk3 ? U->n : 0;
    /* sums: ||rho_F||^2, ||x_F||^2, ||f^_F||^2, den^2; base rows by 3x3 blocks (their delta rows'
       changes added row by row), then the rest row by row: appended rows, no blocks, or dd */
    double sums[4] = {0, 0, 0, 0}, ax;
    if (nb > 0) {
        amps__bejob bj;
        bj.U = U, bj.x = x, bj.rho = rho, bj.ax = axj;
        amps__par_for(&U->par, nb > AMPS__BE_PARMIN ? U->nthr : 1, nb / 3, 64, amps__be_blocks, &bj);
        for (j = 0; j < nb; j++)
            if (!amps__resid_con(U, j)) amps__resid_sums(U, j, x, rho[j], axj[j], sums);
    }
    for (j = nb; j < N; j++) {
        if (amps__resid_con(U, j)) {
            rho[j] = 0.0;
            continue;
        }
        rho[j] = amps__resid_row(U, j, x, dd, &ax);
        amps__resid_sums(U, j, x, rho[j], ax, sums);
    }
    num = sums[0], xn = sums[1], fn = sums[2], den = sums[3];
    *rnorm = sqrt(num);
    if (omega) *omega = num > 0 ? sqrt(num / den) : 0.0;
    return num > 0 ? sqrt(num) / (U->guard.knorm * sqrt(xn) + sqrt(fn)) : 0.0;
}

/* ||f^_F - K^_FC g||_2, the norm of the reduced system's right-hand side (tmp: 2 N). */
static double amps__rhs_norm(const amps_update *U, double *tmp) {
    amps_int i, a, N = U->N;
    double den = 0;
    for (i = 0; i < N; i++) tmp[i] = 0;
    for (a = 0; a < U->aug.size; a++)
        if (U->aug.kind[a] & AMPS__UCON) tmp[U->aug.idx[a]] = U->aug.g[a];
    amps__kmul(U, tmp, tmp + N);
    for (i = 0; i < N; i++) {
        a = U->aug.pos[i];
        if (a >= 0 && (U->aug.kind[a] & AMPS__UCON)) continue;
        den += (U->force.f[i] - tmp[N + i]) * (U->force.f[i] - tmp[N + i]);
    }
    return sqrt(den);
}

/* Step times of a solve: those of the commit since the last solve (if any) plus its own. */
static void amps__solve_times_begin(amps_update *U) {
    amps_int k;
    if (!U->sol.commit_unsolved)
        for (k = 0; k < AMPS_STEP_SOLVE; k++) U->stats.t_step[k] = 0;
    U->sol.commit_unsolved = 0;
    U->stats.t_step[AMPS_STEP_RHS] = 0;
    U->stats.t_step[AMPS_STEP_SOLVE] = 0;
}

/* ct brought up to date (amps__update_ct), timed as Step 4. */
static void amps__solve_ct(amps_update *U) {
    double t0 = amps_now();
    amps__update_ct(U);
    U->stats.t_step[AMPS_STEP_RHS] += amps_now() - t0;
}

/* Both (the full solve from zero, the haptic and the watched ones). */
static void amps__solve_stats_begin(amps_update *U) {
    amps__solve_times_begin(U);
    amps__solve_ct(U);
}

/* One refinement step with the same factors: x += K^{-1} rho through the augmented solve (a full
   forward solve of rho and Steps 4-6 with g = 0). */
static void amps__refine_full(amps_update *U, const double *rho, double *dx) {
    const amps_factor *F = U->F;
    amps_int k;
    for (k = 0; k < U->n; k++) U->guard.ct[k] = rho[F->perm[k]];
    amps_lsolve(F, U->guard.ct);
    for (k = 0; k < U->n; k++) U->guard.ct[k] *= U->base.inv_sqrt_d[k];
    amps__solve_core(U, U->guard.ct, rho, 1, 0, dx);
    for (k = 0; k < U->N; k++) U->sol.x[k] += dx[k];
}

/* A full solve started from the last solution: x = x0 + K^{-1} rho, rho = f^ - K^ x0 (free rows,
   in double, like the check), one refinement step from x0 (amps__refine_full). x0 is the last
   solve's x with the prescribed values on C (the correction is then homogeneous there) and each
   index appended since at its origin's value (0 without one). Step 6 rounds the correction by
   eps mu ||dx|| where a solve from zero rounds eps mu ||x||, so when consecutive solutions are
   close (a time step, a local cut) x has a direct solve's backward error where a solve from zero
   would take a refinement step. Where the forces changed on many rows (a time step's right-hand
   side) the solve from zero does a full forward solve too, and this one costs one product with
   K^ more (ct is left for the next call that needs it, amps__update_ct); one refined solve from
   zero starts a run (amps__accuracy's cheap). Otherwise (ct current, or updated on a few rows:
   cuts, pins, a haptic call before the step) it costs a forward solve more, and only two refined
   solves from zero in a row start one: after one, bench/refactor's bunny20k steps after a fresh
   base took 19.7-24.4 ms against 17.0. Returns 0 (x untouched past x0) when the residual is not
   finite: the caller then solves from zero. */
#ifndef AMPS__WARM_RUN
#define AMPS__WARM_RUN 16 /* full solves started from the last solution after a refined one from zero */
#endif
static int amps__warm_ok(const amps_update *U) {
    return U->guard.warm_left > 0 && U->sol.has_x && U->sol.x_dim <= U->N && U->refac.opts.refine_tol > 0;
}

static int amps__warm_solve(amps_update *U) {
    double *x = U->sol.x, *rho = U->work.resid, *dx = U->work.resid + U->cap_N, rn;
    amps_int a, k;
    for (k = U->sol.x_dim; k < U->N; k++) {
        amps_int o = k < U->refac.cap_origin ? U->refac.origin[k] : -1;
        x[k] = o >= 0 && o < U->sol.x_dim ? x[o] : 0.0;
    }
    for (a = 0; a < U->aug.size; a++)
        if (U->aug.kind[a] & AMPS__UCON) x[U->aug.idx[a]] = U->aug.g[a];
    amps__backward_error(U, x, rho, &rn, 0, NULL);
    U->guard.warm_left--;
    if (!(rn < HUGE_VAL)) return 0;
    amps__refine_full(U, rho, dx);
    U->stats.warm_solves++;
    return 1;
}

/* The accuracy of a full solve into sol.x.
   Where the error enters. x = K-bar^{-1}(f - H w) comes from the base factor (backward stable
   for K-bar, like CHOLMOD's) and the forces w of the small system A = I~ + G Delta~. Measured on
   a cantilever fixed at one end, loaded at its free end and cut 25 times near it (refinement of
   every kind off, then on; tests/test_stress.c fwd_*):
     model             max|G| sigma  |G||Delta| / |A|  LU growth  max|w| / max|f|  be, refine 0 / 1 / 2
     beam 5x5x256      5.6e5         4.0e6             2.0        1.4e7            4.3e4 / 0.6 / 0.7 eps
     beam 5x5x1024     3.6e7         2.7e8             1.0        9.0e8            1.0e6 / 3.1 / 3.1 eps
     brick, nu 0.4999  9.0e3         3.1e4             1.0        1.2e5            658 / 0.2 / 0.2 eps
   (be: normwise backward error; CHOLMOD's is 0.1-0.2 eps.) The dense LU does not grow (growth
   <= 2), the dual form gives the same (3.0 eps on 5x5x1024) and x_S from the small system is
   worse (3.7e6 eps): the error is not in the small system's solve. It is the size of w: the
   correction forces are up to 1e9 times the applied ones, G's entries cancel into A by the
   same factor, and x is the difference of the large terms K-bar^{-1} f and K-bar^{-1} H w, so
   the base solve's rounding of K-bar^{-1} H w leaves a residual ~ eps ||H w|| on every row that
   x depends on through w. The local refinement (opts.refine) removes it on the rows of S u C
   and their neighbours only; a second step changes nothing (3.1 eps), and with random pins and
   forces the rest reaches 370 eps (beam 5x5x256, stress suite).
   The fix: the residual of the explicit current system, one product with K^ (nnz(K^), by 3x3
   node blocks, two lanes with SSE2: 4.5 instructions per stored entry; callgrind, 10 cut steps
   from the uncut model, bench/refine_cost: +9.5% on bunny20k, +5.5% on bunny50k), its backward
   errors, and while the mixed one
   omega > refine_tol (default 1 eps) refinement steps through the augmented solve with the same
   factors (the correction is driven by a residual of size eps ||H w||, so its own w is small):
   on 5x5x1024, 17 steps over the 25 cut solves bring eta from 3.1 to 0.1 eps; bricks and bunnies
   meet 1 eps without a step on free cuts (bunny20k: omega 0.44-0.53 eps over 200 solves), but not
   always under opposing forces (brick:14, bench/refine_cost: 19 of 20 solves refined under the
   1 eps trigger alone, 2.4x the instructions of the cut steps). The trigger is omega,
   not the normwise eta: on a TetGen sliver mesh (stress suite) eta is 0.03-0.2 eps at every step
   while omega is 0.5-3.8 eps and the residual up to 12x CHOLMOD's; ||K^||_inf ||x|| is the norm of
   the stiffest row, 20x the typical row's. Refined on omega the residual stays within 3.2x. The
   refinement residual is summed in double-double: a double sum of row j errs by ~eps (|K^||x|)_j,
   the size of the residual it corrects, which caps a double-residual refinement at about omega ~ 1.
   At most 3 steps; they stop when omega no longer halves. The trigger is relative to omega_d, the
   mixed backward error of a direct solve with the base factor on K-bar (amps__direct_omega, at
   the creation of each base): the target is a residual within 10x of a fresh direct solve's
   (issue 18), and a solve within 4x of omega_d (a margin for the probe right-hand side) meets it
   unrefined. Measured on the TetGen fissure cube in dynamics (bench/dynamics, 231 pins, 25
   steps): omega_d 0.72 eps, the unrefined omega 0.8-4.1 eps; one refinement step brings it to
   0.07 eps but leaves the residual against CHOLMOD's from-scratch system where it was (3.8e-14
   refined, 4.1e-14 unrefined, CHOLMOD 2.0e-15: that gap is the rounding of the two right-hand
   sides b = M w + dt (f - K u), not of the solve), at twice the step's cost. If eta is still
   above 64 refine_tol, the augmentation itself has gone bad and the caller re-factors. With the
   guard on, the relative residual ||rho|| / ||f^_F - K^_FC g|| must also reach guard.tol. Sets
   stats.relres (guard on), backward_error, guard_steps, refine_solves and guard_result (pass 1:
   after a re-factorization); returns 1 when a re-factorization is wanted. warm: x came from
   amps__warm_solve; cheap: a solve from zero did a full forward solve (amps__ct_full); a refined
   solve from zero starts a run of amps__warm_solve (see there).
   Skipping the check. The error above enters where Step 6 cancels: sv = D^{-1/2} ct - sum_a
   w_a D^{-1/2} W_a is rounded by ~eps (|D^{-1/2} ct| + sum_a |w_a| |D^{-1/2} W_a|), and the
   cancellation ratio mu = || sum_a |w_a| |D^{-1/2} W_a| ||_2 / ||sv||_2 (amps__cancel_ratio: the
   sum rides on Step 6's own pass over the memoized columns, then O(n)) says how far that is from
   a direct solve's rounding of sv. Over the full solves of tests/test_stress.c, test_update.c,
   test_dynamics.c, test_scene.c and test_corot.c (5,227 solves), every solve the omega trigger
   refined had mu >= 11.2, and where mu <= 4 omega stayed within 3.0 omega_d; but the long mode
   of tests/test_stress.c (soft_layer_1000, a 1000x softer layer, 60 steps) has first solves after
   a change of K^ at mu 1.2 and 3.5 with omega 4.4 and 6.6 omega_d, whose unrefined residuals are
   12-13x CHOLMOD's. So with the guard off and no forward step due, a solve with mu <=
   AMPS__MU_SKIP = 1 takes no product with K^ (stats.checks_skipped; bench/refine_cost's bunny20k
   cut: mu 0.05-3.8 over the first 30 cut steps, where the check was 9-10% of the step's
   instructions).
   A check above AMPS__MU_SKIP does not bound a later solve's omega at about the same mu: on
   tests/test_stress.c's brick_nu_0.499 (long mode, pins moved between solves) a check at mu 4.19
   found omega 0.82 omega_d, and a solve at mu 4.13-4.42 a few pins later had a residual 20-55x
   CHOLMOD's (3 of 12 runs under load). So every solve above AMPS__MU_SKIP checks.
   Forward error. A backward error at a direct solve's level does not give its forward error:
   on beam 5x5x256 (kappa 8.7e9, tests/test_stress.c fwd_*) the augmented solve reaches omega
   0.7-1.4 eps (omega_d 0.5 eps, no step taken) and a residual 1.4-2.2x CHOLMOD's, yet its error
   against the quad-precision reference is 9.7-10.5x CHOLMOD's (2.2-2.4e-8 against 2.3e-9): the
   rounding of K-bar^{-1} H w lies along K's small eigenvectors, where a direct solve's does not.
   One step with the double-double residual contracts the error by about kappa eps (2e-6 here)
   and brings it to 0.01-0.2x CHOLMOD's (0.03x on beam 5x5x128). Unrefined, beam 5x5x32 (kappa
   2.3e6) is at 1.1x, 5x5x64 (3.5e7) at 1.8-3.0x, the TetGen slivers (1.2e7) at 0.8-0.9x, and the
   brick at nu 0.4999 (1.1e7) at 4.3-8.1x over 16 runs (it depends on when the background
   re-factorization lands): too close to 10x. The benchmark's bricks and bunnies lie below
   (brick:14 1.4e5, bunny20k 6.6e6, bunny50k 7.7e6) and keep their cost: the solves of a base
   with kappa eps > AMPS__FWD_KAPPA_EPS (kappa > 9.0e6, estimated at its creation by amps_condest,
   about 11 solves) take one step. A fresh base (no augmentation) takes it too: our direct solve
   is as backward stable as CHOLMOD's, but at this kappa two such solves' forward errors differ by
   their orderings' rounding, up to 10.6-11.8x on beams 5x5x256 and 5x5x64 (re-factored after every
   cut, tests/test_stress.c with AMPS_STRESS_COUNT=1). */
#define AMPS__DIRECT_RATIO 4.0
#define AMPS__MU_SKIP 1.0
#ifndef AMPS__FWD_KAPPA_EPS /* (overridable for bench/refine_cost only) */
#define AMPS__FWD_KAPPA_EPS 2e-9
#endif
static int amps__accuracy(amps_update *U, int pass, int warm, int cheap) {
    double *rho = U->work.resid, *dx = U->work.resid + U->cap_N, tol = U->refac.opts.refine_tol, om;
    double gtol = U->guard.tol, rn, den, eta, rel, eta0, rel0;
    amps_int it, k;
    /* the forward trigger: a solve on an ill-conditioned base (kappa eps above
       AMPS__FWD_KAPPA_EPS) takes one step */
    int fwd = tol > 0 && U->guard.cond * 2.220446049250313e-16 > AMPS__FWD_KAPPA_EPS;
    double mu = U->stats.cancel_ratio;
    int prev_refined = U->guard.cold_refined;
    if (!warm) U->guard.cold_refined = 0;
    if (gtol <= 0 && !fwd && mu >= 0 && mu <= AMPS__MU_SKIP) {
        /* Step 6 cancelled little: x has a direct solve's rounding, no product with K^ */
        U->stats.backward_error = -1;
        U->stats.checks_skipped++;
        return 0;
    }
    den = gtol > 0 ? amps__rhs_norm(U, U->guard.scratch) : 0;
    eta = amps__backward_error(U, U->sol.x, rho, &rn, 0, &om);
    rel = den > 0 ? rn / den : rn;
    for (it = 0; it < 3; it++) {
        int want_g = gtol > 0 && rel > gtol, want_e = tol > 0 && om > tol && om > AMPS__DIRECT_RATIO * U->guard.omega_d;
        int want_f = fwd && it == 0;
        double om0 = om;
        if (!want_g && !want_e && !want_f) break;
        if (it == 0 && want_e && !warm) { /* the next solves start from x (amps__warm_solve) */
            if (cheap || prev_refined) U->guard.warm_left = AMPS__WARM_RUN;
            U->guard.cold_refined = 1;
        }
        if (it == 0) amps__backward_error(U, U->sol.x, rho, &rn, 1, NULL);
        amps__refine_full(U, rho, dx);
        eta0 = eta;
        rel0 = rel;
        eta = amps__backward_error(U, U->sol.x, rho, &rn, 1, &om);
        rel = den > 0 ? rn / den : rn;
        U->stats.guard_steps++;
        U->stats.refine_solves++;
        if (!want_g && !want_e && om > om0 && om > AMPS__DIRECT_RATIO * U->guard.omega_d) {
            /* a forward step that left the backward error worse than a direct solve's: undone */
            for (k = 0; k < U->N; k++) U->sol.x[k] -= dx[k];
            eta = eta0;
            rel = rel0;
            break;
        }
        if (!want_g && !(om <= 0.5 * om0)) break; /* stagnates: the factors are not the limit */
    }
    U->stats.backward_error = eta;
    if (gtol > 0) {
        U->stats.relres = rel;
        U->stats.guard_result = !(rel <= gtol)             ? AMPS_GUARD_NOT_MET
                                : pass                     ? AMPS_GUARD_REFACTORED
                                : U->stats.guard_steps > 0 ? AMPS_GUARD_REFINED
                                                           : AMPS_GUARD_MET;
    }
    return (gtol > 0 && rel > gtol) || (tol > 0 && eta > 64 * tol);
}

AMPS_API amps_status amps_update_solve(amps_ctx *ctx, amps_update *U, double *xout) {
    amps_int a, k;
    amps_status s;
    int pass = 0, warm, cheap;
    if (!U) return amps__err(ctx, AMPS_ERR_ARG, "amps_update_solve: NULL engine");
    if ((s = amps_update_commit(ctx, U)) != AMPS_OK) return s;
    if (!U->sol.x_stale && U->sol.has_x) {
        if (xout) memcpy(xout, U->sol.x, sizeof(double) * (size_t)U->N);
        return AMPS_OK;
    }
again:
    U->stats.cancel_ratio = -1;
    amps__solve_times_begin(U);
    cheap = amps__ct_full(U); /* a solve from zero does a full forward solve */
    warm = pass == 0 && amps__warm_ok(U) && amps__warm_solve(U);
    if (!warm) {
        amps__solve_ct(U);
        amps__solve_core(U, U->force.ct, U->force.f, 0, 0, U->sol.x);
    }
    U->stats.guard_steps = 0;
    U->stats.guard_result = AMPS_GUARD_MET;
    U->stats.relres = -1;
    U->stats.backward_error = -1;
    if ((U->guard.tol > 0 || U->refac.opts.refine_tol > 0) && amps__accuracy(U, pass, warm, cheap) && pass == 0 &&
        U->refac.opts.refactor != AMPS_REFACTOR_OFF && U->aug.size > 0) {
        /* the augmentation is the suspect: a fresh base, then the same solve again */
        pass = 1;
        if ((s = amps_update_refactor(ctx, U)) == AMPS_OK) {
            amps__log(ctx, AMPS_OK, "amps_update_solve: %s not reached with the augmentation: re-factored",
                      U->guard.tol > 0 ? "the accuracy guard's tolerance" : "the backward error tolerance");
            goto again;
        }
        amps__log(ctx, s, "amps_update_solve: the accuracy re-factorization failed (%s)", ctx ? ctx->msg : "");
    }
    if (U->guard.tol > 0 && U->stats.guard_steps > 0)
        amps__log(ctx, AMPS_OK, "amps_update_solve: accuracy guard: %d refinement step(s)%s, relative residual %.3g",
                  (int)U->stats.guard_steps, pass ? " after a re-factorization" : "", U->stats.relres);
    /* reactions (K^ x - f^)_C */
    for (a = 0; a < U->aug.size; a++) {
        amps_int i = U->aug.idx[a];
        U->sol.react[a] = (U->aug.kind[a] & AMPS__UCON) ? amps__krow(U, i, U->sol.x) - U->force.f[i] : 0.0;
    }
    U->sol.x_stale = 0;
    U->sol.has_x = 1;
    U->sol.x_dim = U->N;
    U->sol.react_stale = 0;
    U->sol.has_react = 1;
    U->sol.watched_stale = 0;
    U->stats.nsolve++;
    if (xout) memcpy(xout, U->sol.x, sizeof(double) * (size_t)U->N);
    {
        double t = 0;
        for (k = 0; k < AMPS_STEP_COUNT; k++) t += U->stats.t_step[k];
        amps__bg_policy(ctx, U, t);
    }
    if (U->guard.tol > 0 && U->stats.guard_result == AMPS_GUARD_NOT_MET)
        return amps__err(ctx, AMPS_WARN_INACCURATE, "amps_update_solve: relative residual %.3g above the guard's %.3g",
                         U->stats.relres, U->guard.tol);
    return AMPS_OK;
}

AMPS_API const double *amps_update_solution(const amps_update *U) { return U ? U->sol.x : NULL; }

/* Reactions (K^ x - f^)_C = (Delta y)_C - w_C from the dense step's y = x_U (F' entries formed
   as y = r - G w in the dual form) and w. */
static void amps__small_reactions(amps_update *U, const double *r, double *yv, const double *wv) {
    amps_int u = U->aug.size, a, b, k;
    size_t ld = (size_t)U->aug.cap;
    if (U->form == AMPS_FORM_DUAL)
        for (a = 0; a < u; a++) {
            double sum = r[a];
            if (U->aug.kind[a] & AMPS__UCON) continue;
            for (b = 0; b < u; b++) sum -= U->lu.G[(size_t)b * ld + (size_t)a] * wv[b];
            yv[a] = sum;
        }
    for (a = 0; a < u; a++) {
        double sum = 0;
        if (!(U->aug.kind[a] & AMPS__UCON)) {
            U->sol.react[a] = 0.0;
            continue;
        }
        for (k = 0; k < U->delta.row_len[a]; k++)
            sum += U->delta.val[U->delta.row_start[a] + k] * yv[U->delta.col[U->delta.row_start[a] + k]];
        U->sol.react[a] = sum - wv[a];
    }
    U->sol.react_stale = 0;
    U->sol.has_react = 1;
}

AMPS_API amps_status amps_update_solve_reactions(amps_ctx *ctx, amps_update *U) {
    amps_status s;
    double t0;
    if (!U) return amps__err(ctx, AMPS_ERR_ARG, "amps_update_solve_reactions: NULL engine");
    if ((s = amps__commit(ctx, U, 0)) != AMPS_OK) return s;
    if (!U->sol.react_stale && U->sol.has_react) return AMPS_OK;
    amps__solve_stats_begin(U);
    amps__step4(U, U->force.ct, U->force.f, 1, U->dense.rhs);
    t0 = amps_now();
    amps__dense_step(U, U->dense.rhs, 0, U->dense.y, U->dense.w);
    amps__small_reactions(U, U->dense.rhs, U->dense.y, U->dense.w);
    U->stats.t_step[AMPS_STEP_DENSE] += amps_now() - t0;
    return AMPS_OK;
}

AMPS_API amps_status amps_update_watch(amps_ctx *ctx, amps_update *U, amps_int m, const amps_int *idx) {
    amps_int k, *wi, *wc, nb = 0;
    amps_status s;
    if (!U) return amps__err(ctx, AMPS_ERR_ARG, "amps_update_watch: NULL engine");
    if ((s = amps__chk_idx(ctx, U, "amps_update_watch", m, idx, NULL, 1, &U->work.mark_N)) != AMPS_OK) return s;
    if (U->watch.job_y) return amps__err(ctx, AMPS_ERR_STATE, "amps_update_watch: a watched-solve job is in progress");
    if (m > U->watch.cap || !U->watch.closure) {
        unsigned char *wo = AMPS__CAST(unsigned char *, amps__malloc(ctx, (size_t)(m > 0 ? m : 1), 1));
        wi = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)(m > 0 ? m : 1), sizeof(amps_int)));
        wc = U->watch.closure
                     ? U->watch.closure
                     : AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)(U->n > 0 ? U->n : 1), sizeof(amps_int)));
        if (!wi || !wc || !wo) {
            amps__free(ctx, wi);
            amps__free(ctx, wo);
            if (wc != U->watch.closure) amps__free(ctx, wc);
            return amps__err(ctx, AMPS_ERR_OOM, "amps_update_watch: out of memory for %ld indices", (long)m);
        }
        amps__free(ctx, U->watch.idx);
        amps__free(ctx, U->watch.from_dense);
        U->watch.idx = wi;
        U->watch.closure = wc;
        U->watch.from_dense = wo;
        U->watch.cap = m;
    }
    for (k = 0; k < m; k++) {
        U->watch.idx[k] = idx[k];
        if (idx[k] < U->n) U->work.idx[nb++] = U->F->iperm[idx[k]];
    }
    U->watch.n = m;
    U->watch.n_closure = amps_closure(U->F, nb, U->work.idx, U->watch.closure, &U->work.mark_n);
    U->sol.watched_stale = 1;
    return AMPS_OK;
}

AMPS_API amps_int amps_update_base_order(const amps_update *U) { return U ? U->n : 0; }

/* Every watched index still exists (DOFs appended later are never removed; a discarded batch is). */
static amps_status amps__watch_valid(amps_ctx *ctx, const amps_update *U, const char *fn) {
    amps_int k;
    for (k = 0; k < U->watch.n; k++)
        if (U->watch.idx[k] >= U->N + U->pending.n_dofs)
            return amps__err(ctx, AMPS_ERR_INDEX, "%s: watched index %ld no longer exists", fn, (long)U->watch.idx[k]);
    return AMPS_OK;
}
AMPS_API const amps_factor *amps_update_factor(const amps_update *U) { return U ? U->F : NULL; }

AMPS_API amps_status amps_update_watched_begin(amps_ctx *ctx, amps_update *U, amps_update_job *job, double *y,
                                               amps_int ylen, double *xw) {
    amps_status s;
    if (!U || !job || !y || (!xw && U->watch.n > 0))
        return amps__err(ctx, AMPS_ERR_ARG, "amps_update_watched_begin: NULL argument");
    if (U->watch.job_y)
        return amps__err(ctx, AMPS_ERR_STATE, "amps_update_watched_begin: a job is already in progress");
    if ((s = amps__watch_valid(ctx, U, "amps_update_watched_begin")) != AMPS_OK) return s;
    if ((s = amps_update_commit(ctx, U)) != AMPS_OK) return s;
    if (ylen < U->n)
        return amps__err(ctx, AMPS_ERR_CAPACITY, "amps_update_watched_begin: y has %ld entries, the base order is %ld",
                         (long)ylen, (long)U->n);
    U->watch.job_y = y;
    U->watch.job_xw = xw;
    amps__solve_stats_begin(U);
    amps__solve_core(U, U->force.ct, U->force.f, 0, 2, U->sol.x);
    amps__small_reactions(U, U->dense.rhs, U->dense.y, U->dense.w);
    U->stats.nsolve++;
    job->F = U->F;
    job->nw = U->watch.n;
    job->ncw = U->watch.n_closure;
    job->widx = U->watch.idx;
    job->wclo = U->watch.closure;
    job->wovr = U->watch.from_dense;
    job->y = y;
    job->xw = xw;
    return AMPS_OK;
}

AMPS_API void amps_update_watched_run(amps_update_job *job) {
    amps_int k;
    if (!job || !job->F) return;
    amps_ltsolve_closure(job->F, job->ncw, job->wclo, job->y);
    for (k = 0; k < job->nw; k++)
        if (!job->wovr[k]) job->xw[k] = job->y[job->F->iperm[job->widx[k]]];
}

AMPS_API void amps_update_watched_end(amps_update *U, amps_update_job *job) {
    if (!U || !job) return;
    U->watch.job_y = NULL;
    U->watch.job_xw = NULL;
    job->F = NULL;
}

AMPS_API amps_status amps_update_solve_watched(amps_ctx *ctx, amps_update *U, double *xw) {
    amps_status s;
    amps_int k;
    if (!U) return amps__err(ctx, AMPS_ERR_ARG, "amps_update_solve_watched: NULL engine");
    if ((s = amps__watch_valid(ctx, U, "amps_update_solve_watched")) != AMPS_OK) return s;
    if ((s = amps_update_commit(ctx, U)) != AMPS_OK) return s;
    if (!U->sol.has_x || (U->sol.watched_stale && U->sol.x_stale)) { /* a current full x holds them */
        amps__solve_stats_begin(U);
        amps__solve_core(U, U->force.ct, U->force.f, 0, 1, U->sol.x);
        amps__small_reactions(U, U->dense.rhs, U->dense.y, U->dense.w);
        U->sol.watched_stale = 0;
        U->stats.nsolve++;
    }
    if (xw)
        for (k = 0; k < U->watch.n; k++) xw[k] = U->sol.x[U->watch.idx[k]];
    return AMPS_OK;
}

AMPS_API double amps_update_reaction(const amps_update *U, amps_int i) {
    amps_int a;
    if (!U || i < 0 || i >= U->N || !U->sol.has_react) return 0.0;
    a = U->aug.pos[i];
    return (a >= 0 && (U->aug.kind[a] & AMPS__UCON)) ? U->sol.react[a] : 0.0;
}

/* y = K^ v for the committed K^ (v and y of length N). */
static void amps__kmul(const amps_update *U, const double *v, double *y) {
    amps_int n = U->n, j, p, a, k;
    for (j = 0; j < n; j++) {
        double s = 0;
        for (p = U->base.Kp[j]; p < U->base.Kp[j + 1]; p++) s += U->base.Kx[p] * v[U->base.Ki[p]];
        y[j] = s;
    }
    for (j = n; j < U->N; j++) y[j] = U->sigma * v[j];
    for (a = 0; a < U->aug.size; a++) {
        double s = 0;
        for (k = 0; k < U->delta.row_len[a]; k++)
            s += U->delta.val[U->delta.row_start[a] + k] * v[U->aug.idx[U->delta.col[U->delta.row_start[a] + k]]];
        y[U->aug.idx[a]] += s;
    }
}

AMPS_API amps_status amps_update_residual(amps_ctx *ctx, amps_update *U, double *relres) {
    double rn, den;
    if (!U || !relres) return amps__err(ctx, AMPS_ERR_ARG, "amps_update_residual: NULL argument");
    if (!U->sol.has_x || U->sol.x_stale || U->pending.n_delta || U->pending.n_con || U->pending.n_dofs)
        return amps__err(ctx, AMPS_ERR_STATE, "amps_update_residual: no current solution (call amps_update_solve)");
    amps__backward_error(U, U->sol.x, U->work.resid, &rn, 0, NULL);
    den = amps__rhs_norm(U, U->guard.scratch);
    *relres = den > 0 ? rn / den : rn;
    return AMPS_OK;
}

AMPS_API void amps_update_get_stats(const amps_update *U, amps_update_stats *st) {
    amps_int a, nm = 0, nc = 0;
    if (!U || !st) return;
    *st = U->stats;
    for (a = 0; a < U->aug.size; a++) {
        if (U->delta.row_len[a] > 0) nm++;
        if (U->aug.kind[a] & AMPS__UCON) nc++;
    }
    st->dim = U->N;
    st->nmod = nm;
    st->ncon = nc;
    st->nsys = U->aug.size;
    st->vpool_entries = (double)U->memo.used;
    st->refactor_running = U->refac.job != NULL;
    st->refactor_nnzL = (double)U->F->Lp[U->F->n] + (double)U->F->n;
}

/* ---- re-factorization ([Interactive cutting] Sec. 3.6) ---- */

/* An entry of the m' log: r >= 0: K^[r,c] += v (and K^[c,r]); r < 0: c DOFs appended. */
typedef struct amps__lentry {
    amps_int r, c;
    double v;
} amps__lentry;

enum { AMPS__BG_RUNNING = 1, AMPS__BG_READY = 2, AMPS__BG_FAILED = 3 };

/* Tests may define AMPS_TEST_BG_FAULT(phase) to make phase 1 (analysis), 2 (factorization) or
   3 (catch-up) of a background re-factorization fail. */
#ifndef AMPS_TEST_BG_FAULT
#define AMPS_TEST_BG_FAULT(phase) 0
#endif
/* Tests may define AMPS_TEST_BG_PARALLEL nonzero to run every loop of the background factorization
   in parallel (no minimum size), so that its helper thread runs on small matrices. */
#ifndef AMPS_TEST_BG_PARALLEL
#define AMPS_TEST_BG_PARALLEL 0
#endif

typedef struct amps__bg {
    struct {                 /* the snapshot at the start (owned) and the parent's base (immutable until the swap) */
        amps_int N, n, nthr; /* order, base order, the parent's threads */
        amps_int cond_j;     /* where the parent base's condition estimate ended (a warm start) */
        double sigma;
        amps_int nt;
        amps_int *ti, *tj;
        double *tx; /* K^ - K on the upper triangle, sigma on appended and constrained diagonals */
        amps_int nc;
        amps_int *ci;
        double *cg; /* constrained indices and values */
        double *f;  /* N forces */
        const amps_int *Kp, *Ki;
        const double *Kx; /* the parent's base K */
        amps_update_opts opts;
        void *alloc_user;
        amps__par par; /* the parent's back end, and its slots (nbuf) */
        int nbuf;
        const amps_factor *F; /* the parent's base factor: its order and analysis (reuse) */
        amps_int *org;        /* N - n: origin of appended DOF n + k, -1 unknown */
        double fill_ref;      /* the parent's refac.fill_ref */
        int keep;             /* 1: keep the parent's order (opts.refactor_reuse, not the 16th time) */
        int threaded;         /* 1: the worker runs on its own thread */
        amps__lspare spare;   /* the parent's spare storage for L (owned; amps__lspare) */
    } snap;
    struct { /* the m' log: appended by the engine's thread, read by the worker (under mu) */
        amps__lentry *entries;
        amps_int n, cap;
        amps_int done; /* entries the worker has replayed */
    } log;
    struct { /* the new base: matrix, factor, engine */
        amps_csc *K;
        amps_factor *F;
        amps_update *U;
    } result;
    amps_status status;
    char msg[256];     /* the failure */
    double t0, t1;     /* start and ready times */
    int state, cancel; /* AMPS__BG_*; cancel requested (under mu) */
#ifndef AMPS_NO_THREADS
    pthread_mutex_t mu;
    pthread_t th;
    int has_thread, has_mu;
#endif
    struct { /* phases of the worker (seconds), what the ordering kept, L's storage reused */
        double order, symbolic, numeric, catchup, fill, fill_ref;
        int kept, reused;
    } ph;
    struct {          /* the foreground (under mu): the factorization's helper waits while it is busy */
        int busy;     /* a commit or solve of the parent is running */
        double since; /* when it began */
        double len;   /* its expected length: 4x the last step time (busy expires after it) */
    } fg;
#ifndef AMPS_NO_THREADS
    struct { /* the helper thread of one parallel loop of the factorization */
        pthread_t th;
        amps_task_fn *task;
        void *task_ctx;
        amps_int n;
    } help;
#endif
} amps__bg;

static void amps__bg_lock(amps__bg *b) {
#ifndef AMPS_NO_THREADS
    pthread_mutex_lock(&b->mu);
#else
    (void)b;
#endif
}
static void amps__bg_unlock(amps__bg *b) {
#ifndef AMPS_NO_THREADS
    pthread_mutex_unlock(&b->mu);
#else
    (void)b;
#endif
}

/* Reads a field shared with the worker under the lock. */
static int amps__bg_get(amps__bg *b, const int *field) {
    int v;
    amps__bg_lock(b);
    v = *field;
    amps__bg_unlock(b);
    return v;
}

static void amps__bg_free(amps_ctx *ctx, amps__bg *b) {
    if (!b) return;
    amps_update_free(ctx, b->result.U);
    amps_factor_free(ctx, b->result.F);
    amps_csc_free(ctx, b->result.K);
    amps__free(ctx, b->snap.ti);
    amps__free(ctx, b->snap.tj);
    amps__free(ctx, b->snap.tx);
    amps__free(ctx, b->snap.ci);
    amps__free(ctx, b->snap.cg);
    amps__free(ctx, b->snap.f);
    amps__free(ctx, b->snap.org);
    amps__spare_free(ctx, &b->snap.spare);
    amps__free(ctx, b->log.entries);
#ifndef AMPS_NO_THREADS
    if (b->has_mu) pthread_mutex_destroy(&b->mu);
#endif
    amps__free(ctx, b);
}

/* Snapshot of the committed K^, constraints and forces of U: O(|Delta| + N). */
/* The constraints of the snapshot into snap.ci/cg: the committed ones, then (fold) the recorded
   constraint changes applied in their order (a release drops an index, a constraint sets or
   adds it). pos (N' entries, -1) is scratch. */
static void amps__bg_snap_cons(const amps_update *U, amps__bg *b, int fold, amps_int *pos) {
    amps_int a, k;
    for (a = 0; a < U->aug.size; a++)
        if (U->aug.kind[a] & AMPS__UCON) {
            b->snap.ci[b->snap.nc] = U->aug.idx[a];
            b->snap.cg[b->snap.nc] = U->aug.g[a];
            b->snap.nc++;
        }
    if (!fold) return;
    for (k = 0; k < b->snap.nc; k++) pos[b->snap.ci[k]] = k;
    for (k = 0; k < U->pending.n_con; k++) {
        const amps__pcon *c = U->pending.con + k;
        amps_int q = pos[c->i];
        if (c->release && q >= 0) { /* the last entry takes its place */
            amps_int l = --b->snap.nc;
            b->snap.ci[q] = b->snap.ci[l];
            b->snap.cg[q] = b->snap.cg[l];
            pos[b->snap.ci[q]] = q;
            pos[c->i] = -1;
        } else if (!c->release) {
            if (q < 0) q = pos[c->i] = b->snap.nc++;
            b->snap.ci[q] = c->i;
            b->snap.cg[q] = c->v;
        }
    }
}

/* A snapshot of the committed system K^ (fold 0), or of K^ with the recorded changes applied
   (fold 1: the matrix entries, the appended DOFs and the constraint changes since the last
   commit; amps__commit_fold), for a re-factorization. */
static amps__bg *amps__bg_snapshot(amps_ctx *ctx, amps_update *U, int fold) {
    amps__bg *b = AMPS__CAST(amps__bg *, amps__calloc(ctx, 1, sizeof(amps__bg)));
    amps_int a, k, nt = 0, nc = 0, cap, N = U->N + (fold ? U->pending.n_dofs : 0), *pos = NULL;
    if (!b) return NULL;
    b->snap.N = N;
    b->snap.n = U->n;
    b->snap.sigma = U->sigma;
    b->snap.nthr = U->nthr;
    b->snap.cond_j = U->guard.cond_j;
    b->snap.par = U->par;
    b->snap.nbuf = U->nbuf;
    b->snap.Kp = U->base.Kp;
    b->snap.Ki = U->base.Ki;
    b->snap.Kx = U->base.Kx;
    b->snap.opts = U->refac.opts;
    b->snap.alloc_user = ctx ? ctx->alloc_user : NULL;
    b->snap.F = U->F;
    b->snap.fill_ref = U->refac.fill_ref;
    b->snap.keep = U->refac.opts.refactor_reuse && U->refac.fill_ref > 0 && U->refac.n_kept < 15 && !U->refac.fresh;
    b->fg.len = 4 * U->refac.t_step_base > 0.002 ? 4 * U->refac.t_step_base : 0.002;
    for (a = 0; a < U->aug.size; a++)
        if (U->aug.kind[a] & AMPS__UCON) nc++;
    if (fold) nc += U->pending.n_con;
    cap = U->delta.used + (N - U->n) + nc + 1 + (fold ? U->pending.n_delta : 0);
    b->snap.ti = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)cap, sizeof(amps_int)));
    b->snap.tj = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)cap, sizeof(amps_int)));
    b->snap.tx = AMPS__CAST(double *, amps__malloc(ctx, (size_t)cap, sizeof(double)));
    b->snap.ci = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)nc + 1, sizeof(amps_int)));
    b->snap.cg = AMPS__CAST(double *, amps__malloc(ctx, (size_t)nc + 1, sizeof(double)));
    b->snap.f = AMPS__CAST(double *, amps__malloc(ctx, (size_t)N + 1, sizeof(double)));
    b->snap.org = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)(N - U->n) + 1, sizeof(amps_int)));
    b->log.cap = 4 * U->refac.opts.cap_pending; /* > 0: amps__create_opts */
    b->log.entries = AMPS__CAST(amps__lentry *, amps__malloc(ctx, (size_t)b->log.cap, sizeof(amps__lentry)));
    if (fold && (pos = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)N + 1, sizeof(amps_int)))))
        for (k = 0; k < N; k++) pos[k] = -1;
    if (!b->snap.ti || !b->snap.tj || !b->snap.tx || !b->snap.ci || !b->snap.cg || !b->snap.f || !b->snap.org ||
        !b->log.entries || (fold && !pos)) {
        amps__free(ctx, pos);
        amps__bg_free(ctx, b);
        return NULL;
    }
    for (k = U->n; k < N; k++) b->snap.org[k - U->n] = k < U->refac.cap_origin ? U->refac.origin[k] : -1;
    for (a = 0; a < U->aug.size; a++) {
        amps_int i = U->aug.idx[a];
        for (k = 0; k < U->delta.row_len[a]; k++) {
            amps_int j = U->aug.idx[U->delta.col[U->delta.row_start[a] + k]];
            if (i > j) continue; /* Delta is stored in both rows */
            b->snap.ti[nt] = i;
            b->snap.tj[nt] = j;
            b->snap.tx[nt] = U->delta.val[U->delta.row_start[a] + k];
            nt++;
        }
    }
    for (k = 0; fold && k < U->pending.n_delta; k++) { /* K^[r, c] += v (and K^[c, r]) */
        const amps__pdelta *d = U->pending.delta + k;
        b->snap.ti[nt] = d->r < d->c ? d->r : d->c;
        b->snap.tj[nt] = d->r < d->c ? d->c : d->r;
        b->snap.tx[nt] = d->v;
        nt++;
    }
    amps__bg_snap_cons(U, b, fold, pos);
    amps__free(ctx, pos);
    for (k = 0; k < b->snap.nc; k++) { /* + sigma e_i e_i^T */
        b->snap.ti[nt] = b->snap.tj[nt] = b->snap.ci[k];
        b->snap.tx[nt] = U->sigma;
        nt++;
    }
    for (k = U->n; k < N; k++) {
        b->snap.ti[nt] = k;
        b->snap.tj[nt] = k;
        b->snap.tx[nt] = U->sigma;
        nt++;
    } /* K-bar */
    b->snap.nt = nt;
    memcpy(b->snap.f, U->force.f, sizeof(double) * (size_t)N);
#ifndef AMPS_NO_THREADS
    if (pthread_mutex_init(&b->mu, NULL) != 0) {
        amps__bg_free(ctx, b);
        amps__err(ctx, AMPS_ERR_STATE, "amps_update_refactor_start: cannot create a mutex");
        return NULL;
    }
    b->has_mu = 1;
#endif
    b->snap.spare = U->refac.spare; /* the job owns it now */
    memset(&U->refac.spare, 0, sizeof(U->refac.spare));
    b->state = AMPS__BG_RUNNING;
    return b;
}

/* Removes the off-diagonal entries of A that are exactly zero, in place. */
static void amps__csc_drop_zeros(amps_csc *A) {
    amps_int j, p, q = 0, p0 = 0;
    for (j = 0; j < A->ncol; j++) {
        amps_int p1 = A->p[j + 1];
        A->p[j] = q;
        for (p = p0; p < p1; p++)
            if (A->x[p] != 0.0 || A->i[p] == j) {
                A->i[q] = A->i[p];
                A->x[q] = A->x[p];
                q++;
            }
        p0 = p1;
    }
    A->p[A->ncol] = q;
}

/* Records the changes of one commit in the log; on failure the re-factorization is cancelled. */
static void amps__bg_log(amps_update *U, amps_int kpend, const amps__pdelta *pd, amps_int npd) {
    amps__bg *b = U->refac.job;
    amps_int need, k;
    amps__bg_lock(b);
    need = b->log.n + npd + (kpend > 0);
    if (b->state == AMPS__BG_FAILED) {
        amps__bg_unlock(b);
        return;
    }
    if (need > b->log.cap) {
        amps_int cap = b->log.cap;
        amps_ctx c2;
        amps_ctx_init(&c2);
        c2.alloc_user = b->snap.alloc_user;
        while (cap < need) cap = cap * 2 + 1024;
        if (!U->grow || amps__realloc(&c2, (void **)&b->log.entries, (size_t)cap, sizeof(amps__lentry))) {
            b->cancel = 1;
            b->status = AMPS_ERR_CAPACITY;
            memcpy(b->msg, "re-factorization cancelled: its log of changes is full", 55);
            amps__bg_unlock(b);
            return;
        }
        b->log.cap = cap;
    }
    if (kpend > 0) {
        b->log.entries[b->log.n].r = -1;
        b->log.entries[b->log.n].c = kpend;
        b->log.entries[b->log.n].v = 0;
        b->log.n++;
    }
    for (k = 0; k < npd; k++) {
        b->log.entries[b->log.n].r = pd[k].r;
        b->log.entries[b->log.n].c = pd[k].c;
        b->log.entries[b->log.n].v = pd[k].v;
        b->log.n++;
    }
    amps__bg_unlock(b);
}

/* Records log entries e[0..cnt-1] in the engine U2 of the new base (sigma: the parent's). The
   parent's appended DOFs start with a recorded -sigma diagonal, which the log replays, so U2's
   own zero row gets +sigma first. */
static amps_status amps__bg_replay(amps_ctx *ctx, amps_update *U2, const amps__lentry *e, amps_int cnt, double sigma) {
    amps_int k, j, first;
    amps_status s;
    for (k = 0; k < cnt; k++) {
        if (e[k].r < 0) {
            if ((s = amps_update_add_dofs(ctx, U2, e[k].c, &first)) != AMPS_OK) return s;
            for (j = first; j < first + e[k].c; j++)
                if ((s = amps_update_add(ctx, U2, 1, &j, &j, &sigma)) != AMPS_OK) return s;
        } else if ((s = amps_update_add(ctx, U2, 1, &e[k].r, &e[k].c, &e[k].v)) != AMPS_OK) return s;
    }
    return AMPS_OK;
}

/* Worker step 1: B = K^(t0) + sigma P_C on the upper triangle, into b->result.K. Couplings a
   change cancelled exactly (a cut moves K[i, j] to a copy of j) leave the pattern, so that they
   cause no fill; with node blocks detected (block 0) the pattern stays whole. */
static amps_status amps__bg_assemble(amps_ctx *c2, amps__bg *b) {
    amps_int j, p, nz = 0, nt = b->snap.nt, *ti, *tj;
    double *tx;
    for (j = 0; j < b->snap.n; j++)
        for (p = b->snap.Kp[j]; p < b->snap.Kp[j + 1]; p++)
            if (b->snap.Ki[p] <= j) nz++;
    ti = AMPS__CAST(amps_int *, amps__malloc(c2, (size_t)(nz + nt) + 1, sizeof(amps_int)));
    tj = AMPS__CAST(amps_int *, amps__malloc(c2, (size_t)(nz + nt) + 1, sizeof(amps_int)));
    tx = AMPS__CAST(double *, amps__malloc(c2, (size_t)(nz + nt) + 1, sizeof(double)));
    if (ti && tj && tx) {
        nz = 0;
        for (j = 0; j < b->snap.n; j++)
            for (p = b->snap.Kp[j]; p < b->snap.Kp[j + 1]; p++)
                if (b->snap.Ki[p] <= j) {
                    ti[nz] = b->snap.Ki[p];
                    tj[nz] = j;
                    tx[nz] = b->snap.Kx[p];
                    nz++;
                }
        memcpy(ti + nz, b->snap.ti, sizeof(amps_int) * (size_t)nt);
        memcpy(tj + nz, b->snap.tj, sizeof(amps_int) * (size_t)nt);
        memcpy(tx + nz, b->snap.tx, sizeof(double) * (size_t)nt);
        b->result.K = amps_csc_from_triplets(c2, b->snap.N, nz + nt, ti, tj, tx, AMPS_UPPER);
    }
    amps__free(c2, ti);
    amps__free(c2, tj);
    amps__free(c2, tx);
    if (!ti || !tj || !tx) return AMPS_ERR_OOM;
    if (!b->result.K) return c2->status;
    if (b->snap.opts.refactor_order.block != 0) amps__csc_drop_zeros(b->result.K);
    return AMPS_OK;
}

/* perm (order of the upper-triangle pattern B) := perm (postorder of its elimination tree): the
   same fill, chains (supernodes) contiguous. O(nnz(B) log N). */
static amps_status amps__order_postorder(amps_ctx *c2, const amps_csc *B, amps_int *perm) {
    amps_int N = B->ncol, k, *Gp = NULL, *Gi = NULL;
    amps_int *w = AMPS__CAST(amps_int *, amps__calloc(c2, 6 * (size_t)N + 1, sizeof(amps_int)));
    amps_status s =
            w ? amps__graph_sym(c2, "amps_update_refactor", N, B->p, B->i, (int)AMPS_UPPER, &Gp, &Gi) : AMPS_ERR_OOM;
    if (s == AMPS_OK) {
        amps_int *iord = w, *par = w + N, *pst = w + 2 * N, *wk = w + 3 * N;
        for (k = 0; k < N; k++) iord[perm[k]] = k;
        amps_etree(N, Gp, Gi, perm, iord, par, wk);
        amps_postorder(N, par, pst, wk);
        for (k = 0; k < N; k++) iord[k] = perm[pst[k]];
        memcpy(perm, iord, sizeof(amps_int) * (size_t)N);
    }
    amps__free(c2, w);
    amps__free(c2, Gp);
    amps__free(c2, Gi);
    return s;
}

/* The order of B = b->result.K (order N) kept from the parent's base order (n): each appended
   DOF j follows its anchor, the base index its origin chain ends at (origin: snap.org, else its
   neighbour i < j in B eliminated last); appended DOFs with consecutive indices and consecutive
   anchors (a node's unknowns) all follow the run's last anchor, so node blocks stay together;
   then postordered (amps__order_postorder). perm (N) is written. O(nnz(B) log N). */
static amps_status amps__bg_order_kept(amps_ctx *c2, const amps__bg *b, amps_int *perm) {
    const amps_csc *B = b->result.K;
    const amps_int *po = b->snap.F->perm, *ip = b->snap.F->iperm;
    amps_int n = b->snap.n, N = b->snap.N, j, p, k, q = 0, t = 0;
    amps_int *anc = AMPS__CAST(amps_int *, amps__malloc(c2, (size_t)N + 1, sizeof(amps_int)));
    amps_int *cnt = AMPS__CAST(amps_int *, amps__calloc(c2, (size_t)n + 1, sizeof(amps_int)));
    amps_int *lst = AMPS__CAST(amps_int *, amps__malloc(c2, (size_t)(N - n) + 1, sizeof(amps_int)));
    if (!anc || !cnt || !lst || n < 1) {
        amps__free(c2, anc);
        amps__free(c2, cnt);
        amps__free(c2, lst);
        return n < 1 ? AMPS_ERR_ARG : AMPS_ERR_OOM;
    }
    for (j = 0; j < n; j++) anc[j] = ip[j];
    for (j = n; j < N; j++) {
        amps_int o = b->snap.org[j - n], a = -1;
        if (o >= 0 && o < j) a = anc[o];
        else
            for (p = B->p[j]; p < B->p[j + 1]; p++)
                if (B->i[p] < j && anc[B->i[p]] > a) a = anc[B->i[p]];
        anc[j] = a < 0 ? n - 1 : a;
    }
    if (N - 1 >= n) { /* runs, from the last: anc[j] + 1 == anc[j + 1] (as computed) */
        amps_int nxt = anc[N - 1], fin = anc[N - 1];
        for (j = N - 2; j >= n; j--) {
            amps_int a = anc[j];
            if (nxt == a + 1) anc[j] = fin;
            else fin = a;
            nxt = a;
        }
    }
    for (j = n; j < N; j++) cnt[anc[j] + 1]++; /* counting sort by anchor, stable in j */
    for (k = 0; k < n; k++) cnt[k + 1] += cnt[k];
    for (j = n; j < N; j++) lst[cnt[anc[j]]++] = j;
    for (k = 0; k < n; k++) {
        perm[q++] = po[k];
        while (t < N - n && anc[lst[t]] == k) perm[q++] = lst[t++];
    }
    amps__free(c2, anc);
    amps__free(c2, cnt);
    amps__free(c2, lst);
    return amps__order_postorder(c2, B, perm);
}

/* The bound on the fill of a kept ordering: nnz(L) / nnz(B) at most this times the last fresh
   ordering's (tests may lower it to force the fall-back). */
#ifndef AMPS_REFACTOR_FILL_BOUND
#define AMPS_REFACTOR_FILL_BOUND 1.2
#endif

/* Ordering and analysis of B into b->result.F: the parent's analysis when B has its pattern
   (snap.keep), else the kept order (amps__bg_order_kept) unless its nnz(L) exceeds
   AMPS_REFACTOR_FILL_BOUND times the last fresh ordering's fill per matrix entry, else a fresh
   ordering (opts.refactor_order). */
static amps_status amps__bg_analyze(amps_ctx *c2, amps__bg *b) {
    const amps_factor *F0 = b->snap.F;
    const amps_csc *K = b->result.K;
    amps_int N = b->snap.N, *perm;
    double t0 = amps_now(), nnzB = (double)K->p[N], bound = AMPS_REFACTOR_FILL_BOUND * b->snap.fill_ref * nnzB;
    amps_order_opts go;
    amps_status s = AMPS_OK;
    int had = b->snap.spare.lx != NULL;
    b->ph.kept = b->snap.keep ? 1 : 0;
    if (b->snap.keep && amps__factor_same_pattern(F0, K, AMPS_UPPER)) {
        b->ph.kept = 2;
        if (!(b->result.F = amps__factor_clone_symbolic(c2, F0, &b->snap.spare)))
            return c2->status ? c2->status : AMPS_ERR_OOM;
    } else {
        if (!(perm = AMPS__CAST(amps_int *, amps__malloc(c2, (size_t)N + 1, sizeof(amps_int))))) return AMPS_ERR_OOM;
        go.method = AMPS_ORDER_GIVEN;
        go.perm = perm;
        go.block = 1;
        go.coords = NULL;
        if (b->ph.kept && (s = amps__bg_order_kept(c2, b, perm)) == AMPS_OK) {
            b->result.F = amps__analyze_reuse(c2, K, AMPS_UPPER, &go, &b->snap.spare);
            if (b->result.F && amps_factor_nnz(b->result.F) > bound) { /* too much fill: a fresh ordering */
                amps__spare_put(c2, &b->snap.spare, b->result.F);
                amps_factor_free(c2, b->result.F);
                b->result.F = NULL;
                b->ph.kept = 0;
            }
        }
        if (s == AMPS_OK && !b->ph.kept) {
            double t1 = amps_now();
            s = amps_order(c2, K, AMPS_UPPER, &b->snap.opts.refactor_order, perm);
            b->ph.order = amps_now() - t1;
            if (s == AMPS_OK) b->result.F = amps__analyze_reuse(c2, K, AMPS_UPPER, &go, &b->snap.spare);
        }
        amps__free(c2, perm);
        if (s != AMPS_OK) return s;
        if (!b->result.F) return c2->status;
    }
    b->ph.symbolic = amps_now() - t0 - b->ph.order;
    b->ph.reused = had && !b->snap.spare.lx;
    b->ph.fill_ref = nnzB > 0 ? amps_factor_nnz(b->result.F) / nnzB : 0;
    b->ph.fill = b->snap.fill_ref > 0 ? b->ph.fill_ref / b->snap.fill_ref : 1;
    return AMPS_OK;
}

/* Worker step 2: ordering, analysis and factorization of B, into b->result.F; stops early when
   cancelled. */
static amps_status amps__bg_factor(amps_ctx *c2, amps__bg *b) {
    amps_status s;
    double t;
    if (amps__bg_get(b, &b->cancel)) return AMPS_ERR_STATE;
    if (AMPS_TEST_BG_FAULT(1)) return amps__err(c2, AMPS_ERR_OOM, "injected failure in the analysis");
    if ((s = amps__bg_analyze(c2, b)) != AMPS_OK) return s;
    if (amps__bg_get(b, &b->cancel)) return AMPS_ERR_STATE;
    if (AMPS_TEST_BG_FAULT(2)) return amps__err(c2, AMPS_ERR_NOT_SPD, "injected failure in the factorization");
    if (AMPS_TEST_BG_PARALLEL) {
        amps__fpriv *P = AMPS__CAST(amps__fpriv *, b->result.F->priv);
        P->parmin = 0;
        P->pargroup = 0;
    }
    t = amps_now();
    s = amps_factorize(c2, b->result.F, b->result.K);
    b->ph.numeric = amps_now() - t;
    if (s != AMPS_OK) return s;
    if (amps__bg_get(b, &b->cancel)) return AMPS_ERR_STATE;
    return AMPS_OK;
}

/* Worker step 3: the engine of the new base, b->result.U: the forces, C with Delta = -sigma and
   the constraints, committed. */
static amps_status amps__bg_engine(amps_ctx *c2, amps__bg *b) {
    amps_update_opts o2 = b->snap.opts;
    amps_update *V;
    amps_int j;
    amps_status s;
    o2.grow = 1;
    o2.refactor = AMPS_REFACTOR_OFF;
    c2->nthreads = b->snap.nthr;            /* per-thread buffers for the owner's threads */
    c2->enqueue_task = b->snap.par.enqueue; /* ... or the owner's task system, used only after */
    c2->finish_task = b->snap.par.finish;   /* the swap, on the owner's thread (nthr = 1 here) */
    c2->task_user = b->snap.par.user;
    c2->worker_count = b->snap.nbuf - 1;
    c2->backend = AMPS_BACKEND_OPENMP; /* no workers of its own: the swap gives V the owner's */
    V = b->result.U = amps__update_new(c2, b->result.K, AMPS_UPPER, b->result.F, &o2, b->snap.cond_j);
    c2->backend = AMPS_BACKEND_AUTO;
    c2->enqueue_task = NULL; /* this thread never calls the host */
    c2->finish_task = NULL;
    if (!V) return c2->status;
    V->nthr = 1; /* the catch-up runs on this thread alone */
    for (j = 0; j < b->snap.N; j++)
        if (b->snap.f[j] != 0.0 && (s = amps_update_set_force(c2, V, 1, &j, b->snap.f + j)) != AMPS_OK) return s;
    for (j = 0; j < b->snap.nc; j++) {
        double ms = -b->snap.sigma;
        if ((s = amps_update_add(c2, V, 1, b->snap.ci + j, b->snap.ci + j, &ms)) != AMPS_OK) return s;
    }
    if ((s = amps_update_constrain(c2, V, b->snap.nc, b->snap.ci, b->snap.cg)) != AMPS_OK) return s;
    return amps_update_commit(c2, V);
}

/* Worker step 4: catches up with the log while it grows (at most 8 rounds of at least 32
   entries; the swap commits the rest). */
static amps_status amps__bg_follow_log(amps_ctx *c2, amps__bg *b) {
    amps_int round;
    amps_status s;
    for (round = 0; round < 8; round++) {
        amps_int lo, cnt;
        amps__lentry *chunk;
        amps__bg_lock(b);
        lo = b->log.done;
        cnt = b->log.n - lo;
        if (b->cancel || cnt < 32) {
            amps__bg_unlock(b);
            break;
        }
        chunk = AMPS__CAST(amps__lentry *, amps__malloc(c2, (size_t)cnt, sizeof(amps__lentry)));
        if (chunk) memcpy(chunk, b->log.entries + lo, sizeof(amps__lentry) * (size_t)cnt);
        amps__bg_unlock(b);
        if (!chunk) return AMPS_ERR_OOM;
        if (AMPS_TEST_BG_FAULT(3)) s = amps__err(c2, AMPS_ERR_SINGULAR_UPDATE, "injected failure in the catch-up");
        else if ((s = amps__bg_replay(c2, b->result.U, chunk, cnt, b->snap.sigma)) == AMPS_OK)
            s = amps_update_commit(c2, b->result.U);
        amps__free(c2, chunk);
        if (s != AMPS_OK) return s;
        amps__bg_lock(b);
        b->log.done = lo + cnt;
        amps__bg_unlock(b);
    }
    return AMPS_OK;
}

#ifndef AMPS_NO_THREADS
/* 1 while a commit or solve of the parent runs (amps__bg_fg_mark), for at most fg.len. */
static int amps__bg_fg_busy(amps__bg *b) {
    int busy;
    double now = amps_now();
    amps__bg_lock(b);
    busy = b->fg.busy && now - b->fg.since < b->fg.len;
    amps__bg_unlock(b);
    return busy;
}

/* The helper of one parallel loop: claims the loop's chunks (slot 0) while the foreground is not
   busy and chunks are left; waits (0.1 ms sleeps) while it is. */
static void *amps__bg_help_main(void *arg) {
    amps__bg *b = AMPS__CAST(amps__bg *, arg);
    amps__job *j = AMPS__CAST(amps__job *, b->help.task_ctx);
    for (;;) {
        long c;
        while (AMPS__FETCH_ADD(&j->next, 0L) < j->nchunk && amps__bg_fg_busy(b)) {
            struct timeval tv;
            tv.tv_sec = 0;
            tv.tv_usec = 100;
            select(0, NULL, NULL, NULL, &tv);
        }
        if ((c = AMPS__FETCH_ADD(&j->next, 1L)) >= j->nchunk) break;
        {
            amps_int lo = (amps_int)c * j->chunk;
            j->fn(lo, j->n - lo < j->chunk ? j->n : lo + j->chunk, 0, j->arg);
        }
    }
    return NULL;
}

/* The worker's back end for its analysis and factorization (worker_count 1): a parallel loop of
   two or more chunks gets one helper thread, which claims chunks only while the foreground is idle
   (amps__bg_help_main); the worker claims chunks all the time. Other tasks run at once. */
static void *amps__bg_enqueue(amps_task_fn *task, amps_int n, amps_int min_range, void *task_ctx, void *user) {
    amps__bg *b = AMPS__CAST(amps__bg *, user);
    (void)min_range;
    if (task != amps__par_task) {
        task(0, n, 0, task_ctx);
        return NULL;
    }
    if (n < 2) return NULL; /* a helper started while the foreground is busy waits for it to idle */
    b->help.task = task;
    b->help.task_ctx = task_ctx;
    b->help.n = n;
    return pthread_create(&b->help.th, NULL, amps__bg_help_main, b) == 0 ? b : NULL;
}

static void amps__bg_finish(void *handle, void *user) {
    (void)user;
    pthread_join(AMPS__CAST(amps__bg *, handle)->help.th, NULL);
}
#endif

/* Marks the parent's foreground busy (a commit began) or idle (a full solve ended, t its step time). */
static void amps__bg_fg_mark(amps__bg *b, int busy, double t) {
    amps__bg_lock(b);
    b->fg.busy = busy;
    b->fg.since = amps_now();
    if (t > 0) b->fg.len = 4 * t > 0.002 ? 4 * t : 0.002;
    amps__bg_unlock(b);
}

/* The worker: B = K^(t0) + sigma P_C assembled, ordered, analyzed and factored; the engine of
   the new base gets the forces, Delta = -sigma on C with the constraints, and catches up with
   the log while it grows. With refactor_threads 1 the analysis and factorization run on the
   worker and, while the foreground is idle, a helper (amps__bg_enqueue); with more, on that many
   OpenMP threads. Either way the factor's bits are the same. */
static void amps__bg_work(amps__bg *b) {
    amps_ctx c2;
    amps_status s;
    double t;
    amps_ctx_init(&c2);
    c2.alloc_user = b->snap.alloc_user;
    c2.nthreads = b->snap.opts.refactor_threads; /* > 0: amps__create_opts */
#ifndef AMPS_NO_THREADS
    if (b->snap.threaded && c2.nthreads == 1 && b->snap.nbuf > 1) {
        c2.enqueue_task = amps__bg_enqueue;
        c2.finish_task = amps__bg_finish;
        c2.task_user = b;
        c2.worker_count = 1;
    }
#endif
    b->t0 = amps_now();
    if ((s = amps__bg_assemble(&c2, b)) == AMPS_OK) s = amps__bg_factor(&c2, b);
    c2.enqueue_task = NULL;
    c2.finish_task = NULL;
    t = amps_now();
    if (s == AMPS_OK && (s = amps__bg_engine(&c2, b)) == AMPS_OK && b->snap.opts.refactor != AMPS_REFACTOR_COUNT)
        s = amps__bg_follow_log(&c2, b); /* COUNT: the swap replays the whole log (same bits) */
    b->ph.catchup = amps_now() - t;
    amps__bg_lock(b);
    if (s == AMPS_OK && b->cancel) s = b->status ? b->status : AMPS_ERR_STATE;
    if (s != AMPS_OK) {
        b->status = s;
        if (!b->msg[0]) memcpy(b->msg, c2.msg, sizeof(b->msg));
        b->state = AMPS__BG_FAILED;
    } else b->state = AMPS__BG_READY;
    b->t1 = amps_now();
    amps__bg_unlock(b);
}

#ifndef AMPS_NO_THREADS
static void *amps__bg_main(void *arg) {
    amps__bg_work(AMPS__CAST(amps__bg *, arg));
    return NULL;
}
#endif

/* Waits for the worker thread to end. */
static void amps__bg_join(amps__bg *b) {
#ifndef AMPS_NO_THREADS
    if (b->has_thread) {
        pthread_join(b->th, NULL);
        b->has_thread = 0;
    }
#else
    (void)b;
#endif
}

/* Ends the background job of U (joined, freed); the kernels get their threads back. */
static void amps__bg_end(amps_ctx *ctx, amps_update *U, int failed) {
    amps__bg *b = U->refac.job;
    if (!b) return;
    amps__bg_join(b);
    if (b->result.F) amps__spare_put(ctx, &U->refac.spare, b->result.F); /* its storage: the next job's */
    else if (b->snap.spare.lx) {
        amps__spare_free(ctx, &U->refac.spare);
        U->refac.spare = b->snap.spare;
        memset(&b->snap.spare, 0, sizeof(b->snap.spare));
    }
    amps__bg_free(ctx, b);
    U->refac.job = NULL;
    U->nthr = U->nbuf;
    if (failed) U->stats.refactor_failed++;
}

#ifndef AMPS_NO_THREADS
/* Factorization time estimated from the solve time: flops sum_j c_j^2 against 4 sum_j c_j. */
static double amps__fact_estimate(const amps_factor *F, double t_solve) {
    double s1 = 0, s2 = 0;
    amps_int j;
    for (j = 0; j < F->n; j++) {
        double c = (double)(F->Lp[j + 1] - F->Lp[j]) + 1;
        s1 += c;
        s2 += c * c;
    }
    return s1 > 0 ? t_solve * s2 / (4 * s1) : 0;
}
#endif

/* Brings the engine V of a ready re-factorization up to U: the rest of the log, the constraints
   and forces as they are now (committed on V), then U's recorded changes (recorded on V). */
static amps_status amps__bg_catch_up(amps_ctx *c2, amps_update *U, amps_update *V, amps__bg *b) {
    amps_int lo, cnt, a, i;
    amps_status s;
    amps__bg_lock(b);
    lo = b->log.done;
    cnt = b->log.n - lo;
    amps__bg_unlock(b);
    if ((s = amps__bg_replay(c2, V, b->log.entries + lo, cnt, b->snap.sigma)) != AMPS_OK) return s;
    /* constraints and forces as they are now */
    for (a = 0; a < V->aug.size; a++) {
        i = V->aug.idx[a];
        if ((V->aug.kind[a] & AMPS__UCON) && !(U->aug.pos[i] >= 0 && (U->aug.kind[U->aug.pos[i]] & AMPS__UCON)))
            if ((s = amps_update_release(c2, V, 1, &i)) != AMPS_OK) return s;
    }
    for (a = 0; a < U->aug.size; a++) {
        amps_int a2;
        i = U->aug.idx[a];
        if (!(U->aug.kind[a] & AMPS__UCON)) continue;
        a2 = i < V->N ? V->aug.pos[i] : -1;
        if (a2 < 0 || !(V->aug.kind[a2] & AMPS__UCON) || V->aug.g[a2] != U->aug.g[a])
            if ((s = amps_update_constrain(c2, V, 1, &i, U->aug.g + a)) != AMPS_OK) return s;
    }
    if ((s = amps_update_commit(c2, V)) != AMPS_OK) return s;
    for (i = 0; i < U->N; i++)
        if (V->force.f[i] != U->force.f[i] && (s = amps_update_set_force(c2, V, 1, &i, U->force.f + i)) != AMPS_OK)
            return s;
    /* changes recorded but not committed move along (as the log does) */
    if (U->pending.n_dofs > 0) {
        amps__lentry e;
        e.r = -1;
        e.c = U->pending.n_dofs;
        e.v = 0;
        if ((s = amps__bg_replay(c2, V, &e, 1, b->snap.sigma)) != AMPS_OK) return s;
        memcpy(V->force.f + U->N, U->force.f + U->N, sizeof(double) * (size_t)U->pending.n_dofs);
    }
    for (a = 0; a < U->pending.n_delta; a++)
        if ((s = amps_update_add(c2, V, 1, &U->pending.delta[a].r, &U->pending.delta[a].c, &U->pending.delta[a].v)) !=
            AMPS_OK)
            return s;
    for (a = 0; a < U->pending.n_con; a++) {
        s = U->pending.con[a].release ? amps_update_release(c2, V, 1, &U->pending.con[a].i)
                                      : amps_update_constrain(c2, V, 1, &U->pending.con[a].i, &U->pending.con[a].v);
        if (s != AMPS_OK) return s;
    }
    return AMPS_OK;
}

/* The new base V takes the handle's place: U gets V's contents with U's options, watch set,
   solution, reactions, freshness and stats; U's old contents are freed. The watch set's
   closure (room for V->n) is recomputed on the new factor. */
static void amps__bg_take(amps_ctx *c2, amps_update *U, amps_update *V, amps__bg *b) {
    amps_update old = *U;
    amps_int a;
    *U = *V;
    U->grow = old.grow;
    U->nthr = old.nbuf;
    U->par = old.par;
    U->pool = old.pool; /* V has none (amps__bg_engine) */
    old.pool = NULL;
    U->guard.tol = old.guard.tol;
    U->refac = old.refac;
    U->refac.job = NULL;
    U->refac.F_own = b->result.F;
    U->refac.K_own = b->result.K;
    b->result.F = NULL;
    b->result.K = NULL;
    b->result.U = NULL;
    U->refac.t_factor = b->t1 - b->t0;
    U->refac.t_step_base = 0;
    U->refac.t_extra = 0;
    U->refac.size_base = U->aug.size;
    U->refac.n_struct = 0;
    U->watch = old.watch; /* no job in progress (the callers check) */
    old.watch.idx = NULL;
    old.watch.from_dense = NULL;
    old.watch.closure = NULL;
    old.refac.job = NULL;
    U->watch.n_closure = 0;
    if (U->watch.closure) {
        amps_int nb = 0, k;
        for (k = 0; k < U->watch.n; k++)
            if (U->watch.idx[k] < U->n) U->work.idx[nb++] = U->F->iperm[U->watch.idx[k]];
        U->watch.n_closure = amps_closure(U->F, nb, U->work.idx, U->watch.closure, &U->work.mark_n);
    }
    memcpy(U->sol.x, old.sol.x, sizeof(double) * (size_t)old.N);
    for (a = 0; a < U->aug.size; a++) {
        amps_int ao = old.aug.pos[U->aug.idx[a]];
        U->sol.react[a] = ao >= 0 ? old.sol.react[ao] : 0.0;
    }
    U->sol.x_stale = old.sol.x_stale;
    U->sol.has_x = old.sol.has_x;
    U->sol.react_stale = old.sol.react_stale;
    U->sol.has_react = old.sol.has_react;
    U->sol.watched_stale = old.sol.watched_stale;
    U->sol.x_dim = old.sol.x_dim;
    U->sol.commit_unsolved = old.sol.commit_unsolved;
    U->stats = old.stats;
    U->stats.nrefactor++;
    U->kver = old.kver + 1;
    U->stats.t_refactor = b->t1 - b->t0;
    U->stats.t_refactor_order = b->ph.order;
    U->stats.t_refactor_symbolic = b->ph.symbolic;
    U->stats.t_refactor_numeric = b->ph.numeric;
    U->stats.t_refactor_catchup = b->ph.catchup;
    U->stats.refactor_order_kept = b->ph.kept;
    U->stats.refactor_reused = b->ph.reused;
    U->stats.refactor_fill = b->ph.fill;
    if (!b->ph.kept) U->refac.fill_ref = b->ph.fill_ref;
    U->refac.n_kept = b->ph.kept ? U->refac.n_kept + 1 : 0;
    U->refac.fold_flops = 0;
    old.refac.origin = NULL; /* U keeps the table */
    memset(&old.refac.spare, 0, sizeof(old.refac.spare));                       /* U keeps it */
    if (old.refac.F_own) amps__spare_put(c2, &U->refac.spare, old.refac.F_own); /* the next job's storage */
    *V = old;
    amps_update_free(c2, V);
}

/* The watch set's closure workspace sized for the new base V (amps__bg_take computes it there). */
static amps_status amps__bg_watch_room(amps_ctx *c2, amps_update *U, const amps_update *V) {
    if (U->watch.closure && amps__realloc(c2, (void **)&U->watch.closure, (size_t)V->n, sizeof(amps_int)))
        return AMPS_ERR_OOM;
    return AMPS_OK;
}

/* Swaps a ready re-factorization in: amps__bg_catch_up, then the new base takes the handle's
   place. The system is unchanged, so the solution, reactions and their freshness carry over.
   On failure the engine keeps its old factors (the re-factorization is dropped). */
static amps_status amps__bg_swap(amps_ctx *ctx, amps_update *U) {
    amps__bg *b = U->refac.job;
    amps_update *V = b->result.U;
    amps_ctx c2;
    amps_status s;
    double t0 = amps_now();
    amps_ctx_init(&c2);
    c2.alloc_user = ctx ? ctx->alloc_user : NULL;
    amps__bg_join(b);
    V->nthr = U->nbuf;
    s = amps__bg_catch_up(&c2, U, V, b);
    if (s == AMPS_OK) s = amps__bg_watch_room(&c2, U, V);
    if (s != AMPS_OK) {
        amps__bg_end(&c2, U, 1);
        return amps__err(ctx, s,
                         "amps_update: swapping the re-factorization in failed (%s); the engine keeps its factors",
                         c2.msg);
    }
    amps__bg_take(&c2, U, V, b);
    amps__bg_free(&c2, b);
    U->stats.t_swap = amps_now() - t0;
    return AMPS_OK;
}

/* At the start of a commit: swaps a ready re-factorization in (not while a watched-solve job
   runs), drops a failed one; the AUTO policy starts one. Never fails the caller. */
static void amps__bg_poll(amps_ctx *ctx, amps_update *U) {
    if (U->refac.job) amps__bg_fg_mark(U->refac.job, 1, 0);
    if (U->refac.job && U->refac.opts.refactor == AMPS_REFACTOR_COUNT) {
        /* deterministic: at the fixed point only, waiting for the worker */
        amps_int every = U->refac.opts.refactor_every;
        if (U->refac.n_struct >= every + every / 2 && !U->watch.job_y) {
            amps_ctx c2;
            amps_ctx_init(&c2);
            c2.alloc_user = ctx ? ctx->alloc_user : NULL;
            amps__bg_join(U->refac.job);
            if (U->refac.job->state == AMPS__BG_READY) (void)amps__bg_swap(&c2, U);
            else amps__bg_end(ctx, U, 1);
        }
    } else if (U->refac.job) {
        int st = amps__bg_get(U->refac.job, &U->refac.job->state);
        if (st == AMPS__BG_READY && !U->watch.job_y) {
            amps_ctx c2;
            amps_ctx_init(&c2);
            c2.alloc_user = ctx ? ctx->alloc_user : NULL;
            if (amps__bg_swap(&c2, U) != AMPS_OK) amps__log(ctx, c2.status, "%s", c2.msg);
        } else if (st == AMPS__BG_FAILED) {
            amps__log(ctx, U->refac.job->status ? U->refac.job->status : AMPS_ERR_STATE,
                      "amps_update: the automatic re-factorization failed (%s); the engine keeps its factors",
                      U->refac.job->msg);
            amps__bg_end(ctx, U, 1);
        }
    }
}

/* AUTO policy after a full solve of step time t (commit + solve): the extra time over the step
   time after the last swap accumulates; when it reaches refactor_ratio times the cost of a
   factorization (measured, or estimated from the solve), a re-factorization starts. */
static void amps__bg_policy(amps_ctx *ctx, amps_update *U, double t) {
#ifndef AMPS_NO_THREADS
    if (U->refac.job) amps__bg_fg_mark(U->refac.job, 0, t);
    if (U->refac.opts.refactor != AMPS_REFACTOR_AUTO || U->refac.job || U->aug.size <= U->refac.size_base + 8) {
        if (!U->refac.job && (U->refac.t_step_base == 0 || t < U->refac.t_step_base)) U->refac.t_step_base = t;
        return;
    }
    if (U->refac.t_step_base == 0 || t < U->refac.t_step_base) U->refac.t_step_base = t;
    if (U->refac.t_factor == 0) U->refac.t_factor = amps__fact_estimate(U->F, U->stats.t_step[AMPS_STEP_SOLVE]);
    U->refac.t_extra += t - U->refac.t_step_base;
    if (U->refac.t_extra >= U->refac.opts.refactor_ratio * U->refac.t_factor) {
        amps_ctx c2;
        amps_ctx_init(&c2);
        c2.alloc_user = ctx ? ctx->alloc_user : NULL;
        if (amps_update_refactor_start(&c2, U) < 0)
            amps__log(ctx, c2.status, "amps_update: starting the automatic re-factorization failed (%s)", c2.msg);
    }
#else
    (void)ctx;
    (void)U;
    (void)t;
#endif
}

/* After a successful commit (structural: it changed K^, added DOFs or grew S u C): counts it and,
   in a call that may swap, starts a re-factorization when the count (COUNT) or the growth of
   |S u C| since the last base (AUTO, with threads) calls for one. */
static void amps__bg_after_commit(amps_ctx *ctx, amps_update *U, int structural, int may_swap) {
    amps_refactor_policy pol = U->refac.opts.refactor;
    int start;
    amps_ctx c2;
    if (structural) U->refac.n_struct++;
    if (U->refac.job || !may_swap || U->cjob.state) return;
    start = pol == AMPS_REFACTOR_COUNT && U->refac.n_struct >= U->refac.opts.refactor_every;
#ifndef AMPS_NO_THREADS
    start |= pol == AMPS_REFACTOR_AUTO && U->aug.size > U->refac.size_base + U->refac.opts.refactor_size;
#endif
    if (!start) return;
    amps_ctx_init(&c2);
    c2.alloc_user = ctx ? ctx->alloc_user : NULL;
    if (amps_update_refactor_start(&c2, U) == AMPS_OK && U->refac.job)
        amps__bg_fg_mark(U->refac.job, 1, 0); /* the rest of this call's step follows */
}

AMPS_API amps_status amps_update_refactor_start(amps_ctx *ctx, amps_update *U) {
    amps__bg *b;
    if (!U) return amps__err(ctx, AMPS_ERR_ARG, "amps_update_refactor_start: NULL engine");
    if (U->refac.opts.refactor == AMPS_REFACTOR_OFF)
        return amps__err(ctx, AMPS_ERR_STATE, "amps_update_refactor_start: re-factorization is off (opts.refactor)");
    if (U->refac.job) return AMPS_WARN_NOOP;
    b = amps__bg_snapshot(ctx, U, 0);
    if (!b) return ctx && ctx->status ? ctx->status : AMPS_ERR_OOM;
    U->refac.job = b;
    U->refac.t_extra = 0;
#ifndef AMPS_NO_THREADS
    b->snap.threaded = 1;
    if (pthread_create(&b->th, NULL, amps__bg_main, b) == 0) {
        /* the worker takes refactor_threads cores: the kernels leave them to it (OpenMP teams
           that wait on a descheduled thread are slower than fewer threads) */
        int nt = U->nbuf - U->refac.opts.refactor_threads;
        U->nthr = nt > 1 ? nt : 1;
        b->has_thread = 1;
        return AMPS_OK;
    }
    b->snap.threaded = 0;
#endif
    amps__bg_work(b); /* no thread: synchronously */
    return AMPS_OK;
}

AMPS_API amps_status amps_update_refactor_wait(amps_ctx *ctx, amps_update *U) {
    amps__bg *b;
    if (!U) return amps__err(ctx, AMPS_ERR_ARG, "amps_update_refactor_wait: NULL engine");
    if (!(b = U->refac.job)) return AMPS_WARN_NOOP;
    if (U->watch.job_y || U->cjob.state)
        return amps__err(ctx, AMPS_ERR_STATE, "amps_update_refactor_wait: a two-phase job is in progress");
    amps__bg_join(b);
    if (b->state == AMPS__BG_READY) return amps__bg_swap(ctx, U);
    {
        amps_status s = b->status ? b->status : AMPS_ERR_STATE;
        char msg[256];
        memcpy(msg, b->msg, sizeof(msg));
        amps__bg_end(ctx, U, 1);
        return amps__err(ctx, s,
                         "amps_update_refactor_wait: the re-factorization failed (%s); the engine keeps its factors",
                         msg);
    }
}

static void amps__bg_discard(amps_ctx *ctx, amps_update *U) {
    if (!U->refac.job) return;
    amps__bg_lock(U->refac.job);
    U->refac.job->cancel = 1;
    amps__bg_unlock(U->refac.job);
    amps__bg_end(ctx, U, 0);
}

AMPS_API void amps_update_refactor_cancel(amps_ctx *ctx, amps_update *U) {
    if (U) amps__bg_discard(ctx, U);
}

/* A commit too large for the augmentation. With k = |S u C| before it and k' the indices it adds
   (new rows of Delta, appended DOFs, new constraints), its dense work is about
   2 (k + k')^2 k' (the LU's extension) + 2 (k + k') k' h (the rows of G; h: the elimination
   tree's height, the length of a W column) flops, and a re-factorization's sum_j c_j^2 (c_j:
   the nonzeros of L's column j). A fracture that tears a large part of a model away adds
   thousands of indices in one commit: measured on a 4,431-equation two-region model (Gmsh),
   5,112 tets torn in one step made the commit 25 s of dense work (k' = 3,765) against 0.2 s for
   a factorization. Returns 1 when the dense work exceeds 4 re-factorizations (k' >= 64; policy
   AUTO or COUNT; no two-phase or watched job in progress). O(recorded changes). */
static int amps__commit_wants_fold(amps_update *U) {
    amps_marker *mk = &U->work.mark_N;
    amps_int k, kn = U->pending.n_dofs, u = U->aug.size;
    double h = (double)(U->F->height > 0 ? U->F->height : 1), kk, dense;
    if ((U->refac.opts.refactor != AMPS_REFACTOR_AUTO && U->refac.opts.refactor != AMPS_REFACTOR_COUNT) ||
        U->cjob.state || U->watch.job_y)
        return 0;
    if (U->pending.n_delta + U->pending.n_con < 64) return 0;
    amps_marker_next(mk);
    for (k = 0; k < 2 * U->pending.n_delta + U->pending.n_con; k++) {
        amps_int i = k < 2 * U->pending.n_delta ? (k & 1 ? U->pending.delta[k / 2].c : U->pending.delta[k / 2].r)
                                                : U->pending.con[k - 2 * U->pending.n_delta].i;
        if (i >= U->N || U->aug.pos[i] >= 0 || mk->mark[i] == mk->stamp) continue; /* appended: in n_dofs */
        mk->mark[i] = mk->stamp;
        kn++;
    }
    if (kn < 64) return 0;
    if (U->refac.fold_flops <= 0) {
        double s2 = 0;
        for (k = 0; k < U->F->n; k++) {
            double c = (double)(U->F->Lp[k + 1] - U->F->Lp[k]) + 1;
            s2 += c * c;
        }
        U->refac.fold_flops = s2 > 1 ? s2 : 1;
    }
    kk = (double)u + (double)kn;
    dense = 2.0 * kk * kk * (double)kn + 2.0 * kk * (double)kn * h;
    return dense > 4.0 * U->refac.fold_flops;
}

/* Commits the recorded changes by a synchronous re-factorization of K^ with them applied
   (amps__bg_snapshot, fold 1), the new base then taking the engine's place as after a swap (the
   log is empty: there is nothing to catch up). A running re-factorization is cancelled first. On
   failure (memory, a matrix that is not positive definite) the engine is as before with the
   changes still recorded, and the caller commits them through the augmentation. */
static amps_status amps__commit_fold(amps_ctx *ctx, amps_update *U) {
    amps__bg *b;
    amps_update *V;
    amps_ctx c2;
    amps_int kn = U->pending.n_dofs;
    double t0 = amps_now();
    amps_ctx_init(&c2);
    c2.alloc_user = ctx ? ctx->alloc_user : NULL;
    if (U->refac.job) amps_update_refactor_cancel(ctx, U);
    if (!(b = amps__bg_snapshot(&c2, U, 1))) return c2.status ? c2.status : AMPS_ERR_OOM;
    U->refac.job = b;
    amps__bg_work(b); /* not threaded: this thread, the engine's kernels' back end unused */
    if (b->state != AMPS__BG_READY || amps__bg_watch_room(&c2, U, b->result.U) != AMPS_OK) {
        amps_status s = b->state != AMPS__BG_READY ? (b->status ? b->status : AMPS_ERR_STATE) : AMPS_ERR_OOM;
        amps__log(ctx, s, "amps_update_commit: committing by a re-factorization failed (%s)",
                  b->state != AMPS__BG_READY ? b->msg : "out of memory");
        amps__bg_end(&c2, U, 1);
        return s;
    }
    V = b->result.U;
    V->nthr = U->nbuf;
    amps__bg_take(&c2, U, V, b);
    amps__bg_free(&c2, b);
    U->sol.x_stale = U->sol.react_stale = U->sol.watched_stale = 1;
    U->stats.ncommit++;
    U->stats.commit_folds++;
    U->stats.t_swap = amps_now() - t0;
    amps__log(ctx, AMPS_OK,
              "amps_update_commit: %ld new DOFs and a dense system of %ld committed by a re-factorization", (long)kn,
              (long)U->aug.size);
    return AMPS_OK;
}

AMPS_API amps_status amps_update_refactor(amps_ctx *ctx, amps_update *U) {
    amps_status s;
    if (!U) return amps__err(ctx, AMPS_ERR_ARG, "amps_update_refactor: NULL engine");
    if ((s = amps_update_commit(ctx, U)) != AMPS_OK) return s;
    if (U->refac.job) amps_update_refactor_cancel(ctx, U);
    U->refac.fresh = 1;
    s = amps_update_refactor_start(ctx, U);
    U->refac.fresh = 0;
    if (s != AMPS_OK) return s;
    return amps_update_refactor_wait(ctx, U);
}

AMPS_API amps_status amps_update_solve_rhs(amps_ctx *ctx, amps_update *U, const double *rhs, double *x) {
    const amps_factor *F;
    amps_int k, a;
    amps_status s;
    double *f, t0 = amps_now();
    if (!U || !rhs || !x) return amps__err(ctx, AMPS_ERR_ARG, "amps_update_solve_rhs: NULL argument");
    if ((s = amps_update_commit(ctx, U)) != AMPS_OK) return s;
    F = U->F;
    f = U->work.resid + U->cap_N; /* rhs with zeros at C (x may alias rhs) */
    for (k = 0; k < U->N; k++) f[k] = rhs[k];
    for (a = 0; a < U->aug.size; a++)
        if (U->aug.kind[a] & AMPS__UCON) f[U->aug.idx[a]] = 0.0;
    for (k = 0; k < U->n; k++) U->guard.ct[k] = f[F->perm[k]];
    amps_lsolve(F, U->guard.ct);
    for (k = 0; k < U->n; k++) U->guard.ct[k] *= U->base.inv_sqrt_d[k];
    amps__solve_core(U, U->guard.ct, f, 1, 0, x);
    for (a = 0; a < U->aug.size; a++)
        if (U->aug.kind[a] & AMPS__UCON) x[U->aug.idx[a]] = 0.0;
    amps__bg_policy(ctx, U, amps_now() - t0);
    return AMPS_OK;
}

AMPS_API amps_status amps_update_set_origin(amps_ctx *ctx, amps_update *U, amps_int m, const amps_int *idx,
                                            const amps_int *orig) {
    amps_int k, top = 0, dim;
    if (!U || m < 0 || (m > 0 && (!idx || !orig)))
        return amps__err(ctx, AMPS_ERR_ARG, "amps_update_set_origin: %s", U ? "bad arguments" : "NULL engine");
    dim = U->N + U->pending.n_dofs;
    for (k = 0; k < m; k++) {
        if (idx[k] < U->n || idx[k] >= dim || orig[k] < 0 || orig[k] >= idx[k])
            return amps__err(
                    ctx, AMPS_ERR_INDEX,
                    "amps_update_set_origin: DOF %lld (origin %lld) is not an appended DOF with an earlier origin",
                    (long long)idx[k], (long long)orig[k]);
        if (idx[k] >= top) top = idx[k] + 1;
    }
    if (top > U->refac.cap_origin) {
        amps_int cap = top > 2 * U->refac.cap_origin ? top : 2 * U->refac.cap_origin;
        if (amps__realloc(ctx, (void **)&U->refac.origin, (size_t)cap, sizeof(amps_int)))
            return amps__err(ctx, AMPS_ERR_OOM, "amps_update_set_origin: out of memory");
        for (k = U->refac.cap_origin; k < cap; k++) U->refac.origin[k] = -1;
        U->refac.cap_origin = cap;
    }
    for (k = 0; k < m; k++) U->refac.origin[idx[k]] = orig[k];
    return AMPS_OK;
}

/* ==== [amps:fem impl] mesh and P1 elasticity ================================================== */
#ifndef AMPS_NO_FEM

/* ---- P1 element ---- */

/* c = a x b. */
static void amps__cross3(const double a[3], const double b[3], double c[3]) {
    c[0] = a[1] * b[2] - a[2] * b[1];
    c[1] = a[2] * b[0] - a[0] * b[2];
    c[2] = a[0] * b[1] - a[1] * b[0];
}

/* C = the cofactors of A (3x3, row-major; row i of C = row i+1 x row i+2 of A): A^-T = C / det A,
   A^-1 = C^T / det A; returns det A. */
static double amps__cof3(const double A[9], double C[9]) {
    amps__cross3(A + 3, A + 6, C);
    amps__cross3(A + 6, A, C + 3);
    amps__cross3(A, A + 3, C + 6);
    return A[0] * C[0] + A[1] * C[1] + A[2] * C[2];
}

AMPS_API double amps_tet_gradients(const double X[12], double G[12]) {
    double J[9], C[9], det, inv;
    int a, b, c;
    for (a = 0; a < 3; a++)
        for (b = 0; b < 3; b++) J[3 * a + b] = X[3 * (b + 1) + a] - X[a];
    det = amps__cof3(J, C);
    if (det == 0.0 || !amps__isfinite(det)) {
        for (a = 0; a < 12; a++) G[a] = 0.0;
        return 0.0;
    }
    inv = 1.0 / det;
    /* rows 1..3 of G = rows of J^{-1} = C^T / det; row 0 = -(sum of the others) */
    for (a = 0; a < 3; a++)
        for (b = 0; b < 3; b++) G[3 + 3 * a + b] = C[3 * b + a] * inv;
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
        l0 = s[0];
        l1 = s[1];
        l2 = s[2];
    } else {
        for (k = 0; k < 6; k++) a[k] = s[k] / scale;
        q = (a[0] + a[1] + a[2]) / 3.0;
        a[0] -= q;
        a[1] -= q;
        a[2] -= q;
        p2 = a[0] * a[0] + a[1] * a[1] + a[2] * a[2] + 2.0 * (a[3] * a[3] + a[4] * a[4] + a[5] * a[5]);
        p = sqrt(p2 / 6.0);
        /* B = A / p has trace 0 and |B|_F^2 = 6: eigenvalues 2 cos(phi + 2 pi k / 3), cos(3 phi) = det(B) / 2 */
        r = 0.5 *
            (a[0] * (a[1] * a[2] - a[4] * a[4]) - a[3] * (a[3] * a[2] - a[4] * a[5]) +
             a[5] * (a[3] * a[4] - a[1] * a[5])) /
            (p * p * p);
        phi = r <= -1.0 ? pi / 3.0 : r >= 1.0 ? 0.0 : acos(r) / 3.0;
        l0 = p * (r >= 0.0 ? 2.0 * cos(phi) : 2.0 * cos(phi + 2.0 * pi / 3.0));
        R[0][0] = a[0] - l0;
        R[0][1] = a[3];
        R[0][2] = a[5];
        R[1][0] = a[3];
        R[1][1] = a[1] - l0;
        R[1][2] = a[4];
        R[2][0] = a[5];
        R[2][1] = a[4];
        R[2][2] = a[2] - l0;
        for (i = 0; i < 3; i++)
            for (j = i + 1; j < 3; j++) {
                double n2;
                c[0] = R[i][1] * R[j][2] - R[i][2] * R[j][1];
                c[1] = R[i][2] * R[j][0] - R[i][0] * R[j][2];
                c[2] = R[i][0] * R[j][1] - R[i][1] * R[j][0];
                n2 = c[0] * c[0] + c[1] * c[1] + c[2] * c[2];
                if (n2 > best) {
                    best = n2;
                    v[0] = c[0];
                    v[1] = c[1];
                    v[2] = c[2];
                }
            }
        if (best == 0.0) {
            l1 = l2 = l0;
        } else {
            t = 1.0 / sqrt(best);
            v[0] *= t;
            v[1] *= t;
            v[2] *= t;
            if (fabs(v[0]) > fabs(v[1])) {
                t = 1.0 / sqrt(v[0] * v[0] + v[2] * v[2]);
                u[0] = -v[2] * t;
                u[1] = 0.0;
                u[2] = v[0] * t;
            } else {
                t = 1.0 / sqrt(v[1] * v[1] + v[2] * v[2]);
                u[0] = 0.0;
                u[1] = v[2] * t;
                u[2] = -v[1] * t;
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
    if (l0 < l1) {
        t = l0;
        l0 = l1;
        l1 = t;
    }
    if (l1 < l2) {
        t = l1;
        l1 = l2;
        l2 = t;
    }
    if (l0 < l1) {
        t = l0;
        l0 = l1;
        l1 = t;
    }
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

/* R = the orthogonal polar factor of F (row-major) by Newton's iteration X <- (g X + X^-T / g) / 2
   (g = (||X^-1||_F / ||X||_F)^(1/2) in the first two steps, then 1), which converges
   quadratically to U V^T when det F > 0: the error after a step that changed X by d is about
   d^2 / 2 (relative), so a step with d <= 1e-9 ||X||_F leaves it below rounding. 1 when it
   converged so, 0 when it stopped (det X <= 1e-6 ||X||_F^3 / 27: nearly degenerate or inverted,
   or 12 steps) and R is not set. */
static int amps__polar_newton(const double F[9], double R[9]) {
    double X[9], C[9], nx = 0, det, g, h, d;
    int it, i;
    AMPS__UNROLL
    for (i = 0; i < 9; i++) {
        X[i] = F[i];
        nx += F[i] * F[i];
    }
    for (it = 0; it < 12; it++) {
        double nc = 0;
        det = amps__cof3(X, C); /* X^-T = C / det X */
        if (!(det > 1e-6 * nx * sqrt(nx) / 27.0)) return 0;
        g = 1.0;
        if (it < 2) {
            AMPS__UNROLL
            for (i = 0; i < 9; i++) nc += C[i] * C[i];
            g = sqrt(sqrt(nc) / (det * sqrt(nx)));
        }
        h = 0.5 / (g * det); /* X+ = (g / 2) X + h C */
        g *= 0.5;
        d = 0;
        nx = 0;
        AMPS__UNROLL
        for (i = 0; i < 9; i++) {
            double xn = g * X[i] + h * C[i];
            d += (xn - X[i]) * (xn - X[i]);
            X[i] = xn;
            nx += xn * xn;
        }
        if (d <= 1e-18 * nx) {
            memcpy(R, X, sizeof(X));
            return 1;
        }
    }
    return 0;
}

/* R of the polar decomposition of F (row-major) as amps_tet_rotation states it: for det F well
   above 0, Newton's iteration (amps__polar_newton: the same R to rounding); else one-sided
   Jacobi on the columns of W = F V (rotations of pairs until every pair is orthogonal to
   eps), s_i = |w_i| sorted descending, u1 = w1 / s1, u2 = w2 orthogonalized against u1 (any
   unit vector orthogonal to u1 when that vanishes), U = [u1, u2, u1 x u2], and with
   V' = [v1, v2, v1 x v2]: R = U V'^T (the det(U V^T) flip folded into the signs of u3, v3). */
static void amps__polar(const double F[9], double R[9]) {
    double W[9], V[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1}, n[3], u[9], v[9], scale = 0.0;
    int sweep, p, q, i, k, ord[3] = {0, 1, 2};
    if (amps__polar_newton(F, R)) return;
    for (i = 0; i < 9; i++) {
        if (!amps__isfinite(F[i])) scale = -1.0;
        else if (scale >= 0 && fabs(F[i]) > scale) scale = fabs(F[i]);
    }
    for (i = 0; i < 9; i++) R[i] = (i % 4 == 0) ? 1.0 : 0.0;
    if (!(scale > 0)) return;
    for (i = 0; i < 9; i++) W[i] = F[i] / scale;
    for (sweep = 0; sweep < 30; sweep++) {
        int rotated = 0;
        for (p = 0; p < 2; p++)
            for (q = p + 1; q < 3; q++) {
                double al = 0, be = 0, ga = 0, zeta, t, c, sn;
                for (i = 0; i < 3; i++) {
                    al += W[3 * i + p] * W[3 * i + p];
                    be += W[3 * i + q] * W[3 * i + q];
                    ga += W[3 * i + p] * W[3 * i + q];
                }
                if (fabs(ga) <= 2.220446049250313e-16 * sqrt(al * be) || ga == 0.0) continue;
                rotated = 1;
                zeta = (be - al) / (2.0 * ga);
                t = (zeta >= 0 ? 1.0 : -1.0) / (fabs(zeta) + sqrt(1.0 + zeta * zeta));
                c = 1.0 / sqrt(1.0 + t * t);
                sn = c * t;
                for (i = 0; i < 3; i++) {
                    double wp = W[3 * i + p], wq = W[3 * i + q], vp = V[3 * i + p], vq = V[3 * i + q];
                    W[3 * i + p] = c * wp - sn * wq;
                    W[3 * i + q] = sn * wp + c * wq;
                    V[3 * i + p] = c * vp - sn * vq;
                    V[3 * i + q] = sn * vp + c * vq;
                }
            }
        if (!rotated) break;
    }
    for (k = 0; k < 3; k++) n[k] = sqrt(W[k] * W[k] + W[3 + k] * W[3 + k] + W[6 + k] * W[6 + k]);
    for (p = 0; p < 2; p++) /* columns by descending norm */
        for (q = 0; q < 2 - p; q++)
            if (n[ord[q]] < n[ord[q + 1]]) {
                k = ord[q];
                ord[q] = ord[q + 1];
                ord[q + 1] = k;
            }
    if (!(n[ord[0]] > 0)) return;
    for (i = 0; i < 3; i++) { /* u[3 k + i], v[3 k + i]: component i of u_k+1, v_k+1 */
        u[i] = W[3 * i + ord[0]] / n[ord[0]];
        u[3 + i] = W[3 * i + ord[1]];
        v[i] = V[3 * i + ord[0]];
        v[3 + i] = V[3 * i + ord[1]];
    }
    {
        double d = u[0] * u[3] + u[1] * u[4] + u[2] * u[5], l;
        for (i = 0; i < 3; i++) u[3 + i] -= d * u[i];
        l = sqrt(u[3] * u[3] + u[4] * u[4] + u[5] * u[5]);
        if (!(l > 1e-150)) { /* rank 1: any unit vector orthogonal to u1 */
            k = fabs(u[0]) <= fabs(u[1]) && fabs(u[0]) <= fabs(u[2]) ? 0 : fabs(u[1]) <= fabs(u[2]) ? 1 : 2;
            for (i = 0; i < 3; i++) u[3 + i] = (i == k ? 1.0 : 0.0) - u[k] * u[i];
            l = sqrt(u[3] * u[3] + u[4] * u[4] + u[5] * u[5]);
        }
        for (i = 0; i < 3; i++) u[3 + i] /= l;
    }
    amps__cross3(u, u + 3, u + 6);
    amps__cross3(v, v + 3, v + 6);
    for (i = 0; i < 3; i++)
        for (k = 0; k < 3; k++) R[3 * i + k] = u[i] * v[k] + u[3 + i] * v[3 + k] + u[6 + i] * v[6 + k];
}

AMPS_API double amps_tet_rotation(const double X[12], const double x[12], double R[9]) {
    double G[12], F[9], C[9];
    int a, i, j;
    if (amps_tet_gradients(X, G) == 0.0) {
        for (i = 0; i < 9; i++) R[i] = (i % 4 == 0) ? 1.0 : 0.0;
        return 0.0;
    }
    for (i = 0; i < 3; i++) /* F = sum_a (x_a - x_0) G_a^T: G_1..3 are the rows of D_m^-1 */
        for (j = 0; j < 3; j++) {
            double f = 0;
            for (a = 1; a < 4; a++) f += (x[3 * a + i] - x[i]) * G[3 * a + j];
            F[3 * i + j] = f;
        }
    amps__polar(F, R);
    return amps__cof3(F, C);
}

/* ---- mesh ---- */

static void amps__removal_free(amps_ctx *ctx, struct amps__removal *r);
static void amps__removal_forget(amps_mesh *m);
static amps_status amps__mesh_grow(amps_ctx *ctx, amps_mesh *m, const char *fn);

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
    amps__free(ctx, m->region);
    amps__free(ctx, m->rho);
    amps__free(ctx, m->removed);
    amps__removal_free(ctx, m->last_removal);
    amps__free(ctx, m);
}

/* Error unless tet t (nodes tv) has volume > 1e-12 L^3, L = longest edge. */
static amps_status amps__mesh_check_tet(amps_ctx *ctx, const char *fn, amps_int t, const amps_int *tv,
                                        const double *xyz) {
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
        return amps__err(ctx, AMPS_ERR_MESH,
                         "%s: tetrahedron %lld (nodes %lld %lld %lld %lld) is degenerate: volume %g, longest edge %g",
                         fn, (long long)t, (long long)tv[0], (long long)tv[1], (long long)tv[2], (long long)tv[3], vol,
                         sqrt(L2));
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
    m->region = AMPS__CAST(amps_int *, amps__calloc(ctx, nt, sizeof(amps_int)));
    m->rho = AMPS__CAST(double *, amps__malloc(ctx, nt, sizeof(double)));
    m->removed = AMPS__CAST(unsigned char *, amps__calloc(ctx, nt, 1));
    if (!m->xyz || !m->origin || !m->inc_ptr || !m->inc_len || !m->tet || !m->inc || !m->E || !m->nu || !m->region ||
        !m->rho || !m->removed) {
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
    if (nnode > AMPS__IMAX / 3 || ntet > AMPS__IMAX / 4) {
        amps__err(ctx, AMPS_ERR_ARG, "%s: %lld nodes / %lld tetrahedra exceed the index type", fn, (long long)nnode,
                  (long long)ntet);
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
                amps__err(ctx, AMPS_ERR_INDEX, "%s: tetrahedron %lld: node index %lld out of range [0, %lld)", fn,
                          (long long)t, (long long)k, (long long)nnode);
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
        m->rho[t] = 1.0;
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

AMPS_API amps_mesh *amps_mesh_create(amps_ctx *ctx, amps_int nnode, const double *xyz, amps_int ntet,
                                     const amps_int *tet) {
    return amps__mesh_new(ctx, "amps_mesh_create", nnode, xyz, ntet, tet, NULL);
}

static amps_status amps__check_material(amps_ctx *ctx, const char *fn, double E, double nu) {
    if (!amps__isfinite(E) || !amps__isfinite(nu))
        return amps__err(ctx, AMPS_ERR_VALUE, "%s: non-finite material (E %g, nu %g)", fn, E, nu);
    if (!(E > 0.0)) return amps__err(ctx, AMPS_ERR_ARG, "%s: Young's modulus E = %g must be positive", fn, E);
    if (!(nu > -1.0 && nu < 0.5))
        return amps__err(ctx, AMPS_ERR_ARG, "%s: Poisson ratio nu = %g must lie in (-1, 0.5)", fn, nu);
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
        return amps__err(ctx, AMPS_ERR_INDEX, "amps_mesh_set_tet_material: tetrahedron %lld out of range [0, %lld)",
                         (long long)t, (long long)m->ntet);
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
static amps_mesh *amps__mesh_grid(amps_ctx *ctx, const char *fn, amps_int nx, amps_int ny, amps_int nz, double hx,
                                  double hy, double hz) {
    static const int kt[6][4] = {{0, 1, 3, 7}, {0, 1, 5, 7}, {0, 2, 3, 7}, {0, 2, 6, 7}, {0, 4, 5, 7}, {0, 4, 6, 7}};
    double *xyz;
    amps_int *tet, i, j, k, nn, nt = 0;
    amps_mesh *m;
    int c, q, s;
    if (nx < 2 || ny < 2 || nz < 2) {
        amps__err(ctx, AMPS_ERR_ARG, "%s: need at least 2 nodes per direction (got %lld x %lld x %lld)", fn,
                  (long long)nx, (long long)ny, (long long)nz);
        return NULL;
    }
    if (!(hx > 0.0 && hy > 0.0 && hz > 0.0) || !amps__isfinite(hx + hy + hz)) {
        amps__err(ctx, AMPS_ERR_ARG, "%s: grid spacings must be positive and finite", fn);
        return NULL;
    }
    if ((double)nx * (double)ny * (double)nz * 24.0 > (double)AMPS__IMAX) {
        amps__err(ctx, AMPS_ERR_ARG, "%s: grid %lld x %lld x %lld too large for the index type", fn, (long long)nx,
                  (long long)ny, (long long)nz);
        return NULL;
    }
    nn = nx * ny * nz;
    xyz = AMPS__CAST(double *, amps__malloc(ctx, 3 * (size_t)nn, sizeof(double)));
    tet = AMPS__CAST(amps_int *,
                     amps__malloc(ctx, 24 * (size_t)(nx - 1) * (size_t)(ny - 1) * (size_t)(nz - 1), sizeof(amps_int)));
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

AMPS_API amps_mesh *amps_mesh_grid(amps_ctx *ctx, amps_int nx, amps_int ny, amps_int nz, double hx, double hy,
                                   double hz) {
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
    if (R < 1 || R > AMPS__IMAX / 4) {
        amps__err(ctx, AMPS_ERR_ARG, "amps_mesh_brick: resolution R = %lld must be at least 1", (long long)R);
        return NULL;
    }
    return amps__mesh_grid(ctx, "amps_mesh_brick", R + 1, R + 1, 2 * R + 1, 1.0 / (double)R, 1.0 / (double)R,
                           1.0 / (double)R);
}

AMPS_API amps_status amps_mesh_reserve(amps_ctx *ctx, amps_mesh *m, amps_int node_cap) {
    void *p;
    size_t nc = (size_t)node_cap;
    if (!m) return amps__err(ctx, AMPS_ERR_ARG, "amps_mesh_reserve: NULL mesh");
    if (node_cap <= m->node_cap) return AMPS_OK;
    if (node_cap > AMPS__IMAX / 3)
        return amps__err(ctx, AMPS_ERR_CAPACITY, "amps_mesh_reserve: %lld nodes exceed the index type",
                         (long long)node_cap);
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
    for (t = 0, r = 0; t < m->ntet; t++) {
        if (m->removed[t] > 1 || !(m->rho[t] > 0.0) || !amps__isfinite(m->rho[t]))
            return amps__err(ctx, AMPS_ERR_MESH, "%s: tetrahedron %lld: invalid removed flag or density", fn,
                             (long long)t);
        r += m->removed[t];
    }
    if (r != m->nremoved)
        return amps__err(ctx, AMPS_ERR_MESH, "%s: %lld tetrahedra are marked removed, nremoved is %lld", fn,
                         (long long)r, (long long)m->nremoved);
    for (t = 0; t < m->ntet; t++)
        for (q = 0; q < 4; q++) {
            v = m->tet[4 * t + q];
            if (v < 0 || v >= m->nnode)
                return amps__err(ctx, AMPS_ERR_MESH, "%s: tetrahedron %lld: node %lld out of range", fn, (long long)t,
                                 (long long)v);
            for (r = 0; r < q; r++)
                if (m->tet[4 * t + r] == v)
                    return amps__err(ctx, AMPS_ERR_MESH, "%s: tetrahedron %lld repeats node %lld", fn, (long long)t,
                                     (long long)v);
        }
    for (v = 0; v < m->nnode; v++) {
        amps_int o = m->origin[v];
        if (v < m->nfile ? o != v : (o < 0 || o >= m->nfile))
            return amps__err(ctx, AMPS_ERR_MESH, "%s: node %lld has invalid origin %lld", fn, (long long)v,
                             (long long)o);
        if (m->xyz[3 * v] != m->xyz[3 * o] || m->xyz[3 * v + 1] != m->xyz[3 * o + 1] ||
            m->xyz[3 * v + 2] != m->xyz[3 * o + 2])
            return amps__err(ctx, AMPS_ERR_MESH, "%s: copy %lld does not have the coordinates of its origin", fn,
                             (long long)v);
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
            else if (m->removed[t]) why = "lists a removed tetrahedron";
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
    if (total != 4 * (m->ntet - m->nremoved))
        return amps__err(ctx, AMPS_ERR_MESH, "%s: incidence lists hold %lld entries, expected %lld", fn,
                         (long long)total, (long long)(4 * (m->ntet - m->nremoved)));
    return AMPS_OK;
}

AMPS_API amps_int amps_mesh_select(amps_ctx *ctx, const amps_mesh *m, int axis, amps_cmp cmp, double value,
                                   amps_int *out) {
    amps_int v, n = 0;
    if (!m) {
        amps__err(ctx, AMPS_ERR_ARG, "amps_mesh_select: NULL mesh");
        return -1;
    }
    if (axis < 0 || axis > 2 || (cmp != AMPS_LT && cmp != AMPS_GT)) {
        amps__err(ctx, AMPS_ERR_ARG, "amps_mesh_select: axis %d, comparison %d (axis 0-2, AMPS_LT or AMPS_GT)", axis,
                  (int)cmp);
        return -1;
    }
    if (value != value) {
        amps__err(ctx, AMPS_ERR_VALUE, "amps_mesh_select: value is NaN");
        return -1;
    }
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

AMPS_API amps_status amps_mesh_stress(amps_ctx *ctx, const amps_mesh *m, const double *disp, double *sigma,
                                      double *von_mises, double *principal) {
    amps_int t;
    if (!m || !disp) return amps__err(ctx, AMPS_ERR_ARG, "amps_mesh_stress: NULL mesh or displacement");
    for (t = 0; t < m->ntet; t++) {
        double X[12], u[12], s[6], vm, pr[3];
        int a, c;
        if (m->removed[t]) {
            if (sigma) memset(sigma + 6 * t, 0, sizeof(s));
            if (von_mises) von_mises[t] = 0.0;
            if (principal) memset(principal + 3 * t, 0, sizeof(pr));
            continue;
        }
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

/* owner[i] = the DOF 3v+d numbered i by dof (-1 if none); checks that dof numbers each equation
   of [0, ndof) at most once. */
static amps_status amps__dof_owner(amps_ctx *ctx, const char *fn, amps_int n, const amps_int *dof, amps_int ndof,
                                   amps_int *owner) {
    amps_int i, k;
    for (i = 0; i < ndof; i++) owner[i] = -1;
    for (k = 0; k < 3 * n; k++) {
        i = dof[k];
        if (i < -1 || i >= ndof)
            return amps__err(ctx, AMPS_ERR_INDEX, "%s: dof[%lld] = %lld out of range [-1, %lld)", fn, (long long)k,
                             (long long)i, (long long)ndof);
        if (i < 0) continue;
        if (owner[i] >= 0)
            return amps__err(ctx, AMPS_ERR_ARG, "%s: equation %lld used by dof[%lld] and dof[%lld]", fn, (long long)i,
                             (long long)owner[i], (long long)k);
        owner[i] = k;
    }
    return AMPS_OK;
}

/* Node graph of m: adj[adjp[v] .. adjp[v+1]) = the nodes sharing a tet with v (v included).
   Allocates *adjp (n + 1) and *adj; mark is workspace (n). */
static amps_status amps__node_graph(amps_ctx *ctx, const char *fn, const amps_mesh *m, amps_int *mark,
                                    amps_int **adjp_out, amps_int **adj_out) {
    amps_int n = m->nnode, v, j, w, k, *adjp, *adj = NULL;
    long long cnt = 0;
    int e, pass;
    *adjp_out = *adj_out = NULL;
    adjp = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)n + 1, sizeof(amps_int)));
    if (!adjp) return AMPS_ERR_OOM;
    *adjp_out = adjp;
    for (pass = 0; pass < 2; pass++) { /* pass 0 counts, pass 1 fills */
        for (v = 0; v < n; v++) mark[v] = -1;
        for (v = 0, cnt = 0; v < n; v++) {
            const amps_int *lst = m->inc + m->inc_ptr[v];
            if (pass == 0) adjp[v] = (amps_int)cnt;
            k = adjp[v];
            for (j = 0; j < m->inc_len[v]; j++)
                for (e = 0; e < 4; e++) {
                    w = m->tet[4 * lst[j] + e];
                    if (mark[w] == v) continue;
                    mark[w] = v;
                    if (pass) adj[k++] = w;
                    else cnt++;
                }
            if (cnt > (long long)AMPS__IMAX)
                return amps__err(ctx, AMPS_ERR_OOM, "%s: node graph too large for the index type", fn);
        }
        if (pass == 0) {
            adjp[n] = (amps_int)cnt;
            adj = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)cnt, sizeof(amps_int)));
            if (!adj) return AMPS_ERR_OOM;
            *adj_out = adj;
        }
    }
    return AMPS_OK;
}

/* Upper-triangular pattern of K over the equations (values zero): visiting equations i in
   ascending order and appending i to every column c >= i it couples with gives each column its
   rows in ascending order. cc is workspace (ndof + 1, zero). */
static amps_csc *amps__assemble_pattern(amps_ctx *ctx, const char *fn, const amps_int *dof, amps_int ndof,
                                        const amps_int *owner, const amps_int *adjp, const amps_int *adj,
                                        amps_int *cc) {
    amps_int i, j, c, k, v;
    long long cnt;
    amps_csc *A = NULL;
    int e, pass;
    for (pass = 0; pass < 2; pass++) { /* pass 0 counts the entries of each column, pass 1 places them */
        for (i = 0; i < ndof; i++) {
            if (owner[i] < 0) continue;
            v = owner[i] / 3;
            for (j = adjp[v]; j < adjp[v + 1]; j++)
                for (e = 0; e < 3; e++) {
                    c = dof[3 * adj[j] + e];
                    if (c < i) continue;
                    if (pass) A->i[cc[c]++] = i;
                    else cc[c + 1]++;
                }
        }
        if (pass) break;
        for (c = 0, cnt = 0; c < ndof; c++) {
            cnt += cc[c + 1];
            if (cnt > (long long)AMPS__IMAX) {
                amps__err(ctx, AMPS_ERR_OOM, "%s: matrix too large for the index type", fn);
                return NULL;
            }
            cc[c + 1] = (amps_int)cnt;
        }
        A = amps_csc_alloc(ctx, ndof, ndof, (amps_int)cnt, 1);
        if (!A) return NULL;
        memcpy(A->p, cc, sizeof(amps_int) * ((size_t)ndof + 1));
        for (k = 0; k < (amps_int)cnt; k++) A->x[k] = 0.0;
    }
    return A;
}

/* A += the upper entries (row <= column) of the 12 x 12 element matrix Ke (row-major) on the
   equations rd (-1: eliminated); the pattern of A holds them. */
static void amps__csc_add_element(amps_csc *A, const amps_int rd[12], const double *Ke) {
    int a, b;
    for (b = 0; b < 12; b++) {
        amps_int col = rd[b], lo, hi;
        if (col < 0) continue;
        for (a = 0; a < 12; a++) {
            amps_int row = rd[a];
            if (row < 0 || row > col) continue;
            lo = A->p[col];
            hi = A->p[col + 1] - 1;
            while (lo < hi) { /* binary search of row in column col */
                amps_int mid = lo + (hi - lo) / 2;
                if (A->i[mid] < row) lo = mid + 1;
                else hi = mid;
            }
            AMPS_ASSERT(A->i[lo] == row);
            A->x[lo] += Ke[12 * a + b];
        }
    }
}

AMPS_API amps_csc *amps_mesh_assemble(amps_ctx *ctx, const amps_mesh *m, const amps_int *dof, amps_int ndof) {
    const char *fn = "amps_mesh_assemble";
    amps_int *owner = NULL, *mark = NULL, *adjp = NULL, *adj = NULL, *cc = NULL, t;
    amps_csc *A = NULL;
    if (!m || !dof || ndof < 0) {
        amps__err(ctx, AMPS_ERR_ARG, "%s: NULL mesh / dof or negative ndof", fn);
        return NULL;
    }
    owner = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)ndof, sizeof(amps_int)));
    cc = AMPS__CAST(amps_int *, amps__calloc(ctx, (size_t)ndof + 1, sizeof(amps_int)));
    mark = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)m->nnode, sizeof(amps_int)));
    if (owner && cc && mark && amps__dof_owner(ctx, fn, m->nnode, dof, ndof, owner) == AMPS_OK &&
        amps__node_graph(ctx, fn, m, mark, &adjp, &adj) == AMPS_OK)
        A = amps__assemble_pattern(ctx, fn, dof, ndof, owner, adjp, adj, cc);
    for (t = 0; A && t < m->ntet; t++) { /* values: every element matrix */
        double Ke[144];
        amps_int rd[12];
        int a;
        if (m->removed[t]) continue;
        amps_mesh_tet_stiffness(m, t, Ke);
        for (a = 0; a < 12; a++) rd[a] = dof[3 * m->tet[4 * t + a / 3] + a % 3];
        amps__csc_add_element(A, rd, Ke);
    }
    amps__free(ctx, owner);
    amps__free(ctx, cc);
    amps__free(ctx, mark);
    amps__free(ctx, adjp);
    amps__free(ctx, adj);
    return A;
}

/* Sign test of amps_mesh_cut: (centroid(t) - p) . nrm in the reference configuration. */
static double amps__cut_side(const amps_mesh *m, amps_int t, const double p[3], const double nrm[3]) {
    const amps_int *tv = m->tet + 4 * t;
    double s = 0.0;
    int c;
    for (c = 0; c < 3; c++) {
        double x =
                0.25 * (m->xyz[3 * tv[0] + c] + m->xyz[3 * tv[1] + c] + m->xyz[3 * tv[2] + c] + m->xyz[3 * tv[3] + c]);
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
        return amps__err(ctx, AMPS_ERR_INDEX, "%s: node %lld out of range [0, %lld)", fn, (long long)v,
                         (long long)m->nnode);
    for (c = 0; c < 3; c++)
        if (!amps__isfinite(p[c]) || !amps__isfinite(nrm[c]))
            return amps__err(ctx, AMPS_ERR_VALUE, "%s: non-finite plane point or normal", fn);
    if (nrm[0] == 0.0 && nrm[1] == 0.0 && nrm[2] == 0.0)
        return amps__err(ctx, AMPS_ERR_ARG, "%s: zero plane normal", fn);
    base = m->inc_ptr[v];
    deg = m->inc_len[v];
    for (j = 0; j < deg; j++) {
        t = m->inc[base + j];
        if (amps__cut_side(m, t, p, nrm) < 0.0) moved[nm++] = t;
    }
    if (nm == 0 || nm == deg)
        return amps__err(ctx, AMPS_WARN_NOOP,
                         "%s: all %lld tetrahedra at node %lld lie on one side of the plane; nothing cut", fn,
                         (long long)deg, (long long)v);
    if (m->nnode == m->node_cap) {
        amps_status s = amps__mesh_grow(ctx, m, fn);
        if (s) return s;
    }
    amps__removal_forget(m);
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

AMPS_API amps_status amps_mesh_uncut(amps_ctx *ctx, amps_mesh *m, amps_int v, amps_int vc, const amps_int *moved,
                                     amps_int nmoved) {
    amps_int base, keep, i, j, w, k;
    int q;
    if (!m || vc != m->nnode - 1 || v < 0 || v >= vc || m->inc_len[vc] != nmoved ||
        m->inc_ptr[vc] != m->inc_ptr[v] + m->inc_len[v])
        return amps__err(ctx, AMPS_ERR_ARG, "amps_mesh_uncut: node %ld is not the last copy of node %ld", (long)vc,
                         (long)v);
    for (k = 0; k < nmoved; k++)
        for (q = 0; q < 4; q++)
            if (m->tet[4 * moved[k] + q] == vc) m->tet[4 * moved[k] + q] = v;
    /* merge v's kept tets and the moved ones back into one ascending slot, from the back */
    base = m->inc_ptr[v];
    keep = m->inc_len[v];
    i = keep - 1;
    j = nmoved - 1;
    w = keep + nmoved - 1;
    while (j >= 0) {
        if (i >= 0 && m->inc[base + i] > moved[j]) m->inc[base + w--] = m->inc[base + i--];
        else m->inc[base + w--] = moved[j--];
    }
    m->inc_len[v] = keep + nmoved;
    m->inc_len[vc] = 0;
    m->inc_ptr[vc] = 0;
    m->nnode--;
    amps__removal_forget(m);
    return AMPS_OK;
}

/* ---- boundary ---- */

/* 1 if the incidence list of tet t's first node contains t (a tet in use). */
static int amps__tet_live(const amps_mesh *m, amps_int t) {
    const amps_int *inc = m->inc + m->inc_ptr[m->tet[4 * t]];
    amps_int lo = 0, hi = m->inc_len[m->tet[4 * t]] - 1;
    while (lo <= hi) {
        amps_int mid = lo + (hi - lo) / 2;
        if (inc[mid] == t) return 1;
        if (inc[mid] < t) lo = mid + 1;
        else hi = mid - 1;
    }
    return 0;
}

/* The nodes of face f of tet t (the face opposite its node f), ordered so that the normal
   (x1 - x0) x (x2 - x0) points away from node f. */
static void amps__face_tri(const amps_mesh *m, amps_int t, int f, amps_int tri[3]) {
    const double *x = m->xyz;
    double e1[3], e2[3], e3[3], s;
    int q, k = 0;
    for (q = 0; q < 4; q++)
        if (q != f) tri[k++] = m->tet[4 * t + q];
    for (q = 0; q < 3; q++) {
        e1[q] = x[3 * tri[1] + q] - x[3 * tri[0] + q];
        e2[q] = x[3 * tri[2] + q] - x[3 * tri[0] + q];
        e3[q] = x[3 * m->tet[4 * t + f] + q] - x[3 * tri[0] + q];
    }
    s = (e1[1] * e2[2] - e1[2] * e2[1]) * e3[0] + (e1[2] * e2[0] - e1[0] * e2[2]) * e3[1] +
        (e1[0] * e2[1] - e1[1] * e2[0]) * e3[2];
    if (s > 0) {
        amps_int w = tri[1];
        tri[1] = tri[2];
        tri[2] = w;
    }
}

/* The nodes of face f of tet t in ascending order. */
static void amps__face_key(const amps_mesh *m, amps_int t, int f, amps_int key[3]) {
    int q, k = 0;
    for (q = 0; q < 4; q++)
        if (q != f) {
            amps_int v = m->tet[4 * t + q];
            int j = k++;
            while (j > 0 && key[j - 1] > v) {
                key[j] = key[j - 1];
                j--;
            }
            key[j] = v;
        }
}

/* Sorting the faces by their smallest node (a counting sort), then comparing the faces in each
   bucket: a face with no equal is a boundary face. */
AMPS_API amps_int amps_mesh_boundary(amps_ctx *ctx, const amps_mesh *m, amps_int *tri, amps_int *face) {
    amps_int nf, t, i, j, v, n = 0, *start, *order;
    unsigned char *bnd;
    if (!m) return amps__err(ctx, AMPS_ERR_ARG, "amps_mesh_boundary: NULL mesh"), -1;
    nf = 4 * m->ntet;
    start = AMPS__CAST(amps_int *, amps__calloc(ctx, (size_t)m->nnode + 2, sizeof(amps_int)));
    order = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)nf, sizeof(amps_int)));
    bnd = AMPS__CAST(unsigned char *, amps__calloc(ctx, (size_t)nf, 1));
    if (!start || !order || !bnd) {
        amps__free(ctx, start);
        amps__free(ctx, order);
        amps__free(ctx, bnd);
        return amps__err(ctx, AMPS_ERR_OOM, "amps_mesh_boundary: out of memory"), -1;
    }
    for (i = 0; i < 2; i++) { /* the bucket sizes, then the faces in their buckets */
        for (t = 0; t < m->ntet; t++) {
            amps_int key[3];
            int f;
            if (!amps__tet_live(m, t)) continue;
            for (f = 0; f < 4; f++) {
                amps__face_key(m, t, f, key);
                if (i == 0) start[key[0] + 2]++;
                else order[start[key[0] + 1]++] = 4 * t + f;
            }
        }
        for (v = 0; i == 0 && v < m->nnode; v++) start[v + 2] += start[v + 1];
    }
    for (v = 0; v < m->nnode; v++) /* faces start[v] .. start[v+1]-1 have smallest node v */
        for (i = start[v]; i < start[v + 1]; i++) {
            amps_int a[3];
            amps__face_key(m, order[i] / 4, (int)(order[i] % 4), a);
            for (j = start[v]; j < start[v + 1]; j++) {
                amps_int b[3];
                if (j == i) continue;
                amps__face_key(m, order[j] / 4, (int)(order[j] % 4), b);
                if (a[1] == b[1] && a[2] == b[2]) break;
            }
            if (j == start[v + 1]) bnd[order[i]] = 1;
        }
    for (i = 0; i < nf; i++)
        if (bnd[i]) {
            if (tri) amps__face_tri(m, i / 4, (int)(i % 4), tri + 3 * n);
            if (face) face[n] = i;
            n++;
        }
    amps__free(ctx, start);
    amps__free(ctx, order);
    amps__free(ctx, bnd);
    return n;
}

/* ---- density, regions, lumped mass ---- */

static amps_status amps__check_density(amps_ctx *ctx, const char *fn, double rho) {
    if (!amps__isfinite(rho)) return amps__err(ctx, AMPS_ERR_VALUE, "%s: non-finite density %g", fn, rho);
    if (!(rho > 0.0)) return amps__err(ctx, AMPS_ERR_ARG, "%s: density rho = %g must be positive", fn, rho);
    return AMPS_OK;
}

AMPS_API amps_status amps_mesh_set_density(amps_ctx *ctx, amps_mesh *m, double rho) {
    amps_int t;
    amps_status s;
    if (!m) return amps__err(ctx, AMPS_ERR_ARG, "amps_mesh_set_density: NULL mesh");
    s = amps__check_density(ctx, "amps_mesh_set_density", rho);
    if (s) return s;
    for (t = 0; t < m->ntet; t++) m->rho[t] = rho;
    return AMPS_OK;
}

AMPS_API amps_status amps_mesh_set_tet_density(amps_ctx *ctx, amps_mesh *m, amps_int t, double rho) {
    amps_status s;
    if (!m) return amps__err(ctx, AMPS_ERR_ARG, "amps_mesh_set_tet_density: NULL mesh");
    if (t < 0 || t >= m->ntet)
        return amps__err(ctx, AMPS_ERR_INDEX, "amps_mesh_set_tet_density: tetrahedron %lld out of range [0, %lld)",
                         (long long)t, (long long)m->ntet);
    s = amps__check_density(ctx, "amps_mesh_set_tet_density", rho);
    if (s) return s;
    m->rho[t] = rho;
    return AMPS_OK;
}

AMPS_API amps_status amps_mesh_set_region_material(amps_ctx *ctx, amps_mesh *m, amps_int id, double E, double nu,
                                                   double rho) {
    const char *fn = "amps_mesh_set_region_material";
    amps_int t, n = 0;
    amps_status s;
    if (!m) return amps__err(ctx, AMPS_ERR_ARG, "%s: NULL mesh", fn);
    s = amps__check_material(ctx, fn, E, nu);
    if (s) return s;
    if (rho > 0.0 || rho != rho) {
        s = amps__check_density(ctx, fn, rho);
        if (s) return s;
    }
    for (t = 0; t < m->ntet; t++) n += m->region[t] == id;
    if (n == 0) return amps__err(ctx, AMPS_ERR_ARG, "%s: no tetrahedron has region %lld", fn, (long long)id);
    for (t = 0; t < m->ntet; t++)
        if (m->region[t] == id) {
            m->E[t] = E;
            m->nu[t] = nu;
            if (rho > 0.0) m->rho[t] = rho;
        }
    return AMPS_OK;
}

AMPS_API amps_status amps_mesh_set_tet_region(amps_ctx *ctx, amps_mesh *m, amps_int t, amps_int id) {
    if (!m) return amps__err(ctx, AMPS_ERR_ARG, "amps_mesh_set_tet_region: NULL mesh");
    if (t < 0 || t >= m->ntet)
        return amps__err(ctx, AMPS_ERR_INDEX, "amps_mesh_set_tet_region: tetrahedron %lld out of range [0, %lld)",
                         (long long)t, (long long)m->ntet);
    m->region[t] = id;
    return AMPS_OK;
}

/* Lumped mass of node v, m_v = sum over the tets t that contain it of rho_t |V_t| / 4, summed in
   incidence order; vol[t] = |V_t| (NULL: from the coordinates). The one definition of the mass. */
static double amps__mesh_node_mass(const amps_mesh *m, const double *vol, amps_int v) {
    double mv = 0.0, X[12], G[12];
    amps_int k;
    for (k = 0; k < m->inc_len[v]; k++) {
        amps_int t = m->inc[m->inc_ptr[v] + k];
        double V;
        if (vol) V = vol[t];
        else {
            amps_mesh_tet_coords(m, t, X);
            V = fabs(amps_tet_gradients(X, G));
        }
        mv += (m->rho ? m->rho[t] : 1.0) * V / 4;
    }
    return mv;
}

AMPS_API void amps_mesh_lumped_mass(const amps_mesh *m, double *mass) {
    amps_int v;
    if (!m || !mass) return;
    for (v = 0; v < m->nnode; v++) mass[v] = amps__mesh_node_mass(m, NULL, v);
}

/* ---- element removal and topological singularities ---- */

/* Growable array of amps_int. */
typedef struct amps__ivec {
    amps_int *a;
    size_t n, cap;
} amps__ivec;

static amps_status amps__iv_push(amps_ctx *ctx, amps__ivec *v, amps_int x) {
    if (v->n == v->cap) {
        void *p = v->a;
        size_t cap = v->cap ? 2 * v->cap : 64;
        if (amps__realloc(ctx, &p, cap, sizeof(amps_int))) return AMPS_ERR_OOM;
        v->a = AMPS__CAST(amps_int *, p);
        v->cap = cap;
    }
    v->a[v->n++] = x;
    return AMPS_OK;
}

/* The record of the last amps_mesh_remove and its undo log. A node's slot is saved (once)
   before its first change; restoring the saved slots, the tet entries and nnode undoes it. */
struct amps__removal {
    int valid;       /* 1 while the removal is the last change of the mesh */
    amps_int nnode0; /* nnode before */
    amps__ivec tets; /* tets removed, in order */
    amps__ivec sep_node, sep_copy, sep_ptr, sep_tets, orphans;
    amps__ivec saved;                  /* per saved node: node, inc_ptr, inc_len, offset into slot */
    amps__ivec slot;                   /* the saved slot contents */
    amps__ivec edits;                  /* per changed tet entry: 4 t + q, the old node */
    amps__ivec queue;                  /* work items (a, b): vertex a (b = -1) or edge a < b */
    amps__ivec star, grp, aux, ed, eg; /* scratch of the singularity tests */
    unsigned char *flag;               /* flag_cap: node saved */
    size_t flag_cap;
};

static void amps__removal_free(amps_ctx *ctx, struct amps__removal *r) {
    amps__ivec *v[15];
    int k;
    if (!r) return;
    v[0] = &r->tets, v[1] = &r->sep_node, v[2] = &r->sep_copy, v[3] = &r->sep_ptr, v[4] = &r->sep_tets;
    v[5] = &r->orphans, v[6] = &r->saved, v[7] = &r->slot, v[8] = &r->edits, v[9] = &r->queue;
    v[10] = &r->star, v[11] = &r->grp, v[12] = &r->aux, v[13] = &r->ed, v[14] = &r->eg;
    for (k = 0; k < 15; k++) amps__free(ctx, v[k]->a);
    amps__free(ctx, r->flag);
    amps__free(ctx, r);
}

static void amps__removal_forget(amps_mesh *m) {
    if (m->last_removal) m->last_removal->valid = 0;
}

/* Grows the node capacity of m by half when it is full (amps_mesh_cut's growth). */
static amps_status amps__mesh_grow(amps_ctx *ctx, amps_mesh *m, const char *fn) {
    amps_int cap = m->node_cap + m->node_cap / 2 + 16;
    if (m->nnode < m->node_cap) return AMPS_OK;
    if (cap > AMPS__IMAX / 3 || cap < m->node_cap) cap = AMPS__IMAX / 3;
    if (cap <= m->nnode) return amps__err(ctx, AMPS_ERR_CAPACITY, "%s: node count at the limit of the index type", fn);
    return amps_mesh_reserve(ctx, m, cap);
}

/* Number of nodes tets p and q share. */
static int amps__tet_shared(const amps_mesh *m, amps_int p, amps_int q) {
    const amps_int *a = m->tet + 4 * p, *b = m->tet + 4 * q;
    int i, j, n = 0;
    for (i = 0; i < 4; i++)
        for (j = 0; j < 4; j++) n += a[i] == b[j];
    return n;
}

/* star = the live tets containing a (and b if b >= 0), ascending. */
static amps_status amps__star(amps_ctx *ctx, const amps_mesh *m, amps_int a, amps_int b, amps__ivec *star) {
    const amps_int *lst = m->inc + m->inc_ptr[a];
    amps_int j;
    star->n = 0;
    for (j = 0; j < m->inc_len[a]; j++) {
        const amps_int *tv = m->tet + 4 * lst[j];
        if (b >= 0 && tv[0] != b && tv[1] != b && tv[2] != b && tv[3] != b) continue;
        if (amps__iv_push(ctx, star, lst[j])) return AMPS_ERR_OOM;
    }
    return AMPS_OK;
}

static amps_int amps__uf_root(amps_int *g, amps_int i) {
    while (g[i] != i) i = g[i] = g[g[i]];
    return i;
}

/* Connected groups of the tets star[0..n-1], two adjacent when they share at least need nodes:
   grp[i] = the first (lowest) member of i's group. Returns the number of groups; *kept = the
   root of the largest group, a tie the one with the lowest tet. */
static amps_int amps__groups(const amps_mesh *m, const amps_int *star, amps_int n, int need, amps_int *grp,
                             amps_int *kept) {
    amps_int i, j, ng = 0, best = -1, bsize = 0;
    for (i = 0; i < n; i++) grp[i] = i;
    for (i = 0; i < n; i++)
        for (j = i + 1; j < n; j++) {
            amps_int ri, rj;
            if (amps__tet_shared(m, star[i], star[j]) < need) continue;
            ri = amps__uf_root(grp, i);
            rj = amps__uf_root(grp, j);
            if (ri < rj) grp[rj] = ri;
            else if (rj < ri) grp[ri] = rj;
        }
    for (i = 0; i < n; i++) grp[i] = amps__uf_root(grp, i);
    for (i = 0; i < n; i++) {
        amps_int size = 0;
        if (grp[i] != i) continue;
        ng++;
        for (j = i; j < n; j++) size += grp[j] == i;
        if (size > bsize) bsize = size, best = i;
    }
    *kept = best;
    return ng;
}

/* Groups of the tets containing a (and b if b >= 0), adjacent when they share need nodes, into
   R->star / R->grp (see amps__groups); returns their number. */
static amps_int amps__rm_groups(amps_ctx *ctx, const amps_mesh *m, struct amps__removal *R, amps_int a, amps_int b,
                                int need, amps_int *kept, amps_status *s) {
    *s = amps__star(ctx, m, a, b, &R->star);
    if (*s) return 0;
    while (R->grp.cap < R->star.n)
        if ((*s = amps__iv_push(ctx, &R->grp, 0)) != AMPS_OK) return 0;
    return amps__groups(m, R->star.a, (amps_int)R->star.n, need, R->grp.a, kept);
}

/* Saves the slot of node v before its first change (copies made by this removal need none). */
static amps_status amps__rm_save(amps_ctx *ctx, const amps_mesh *m, struct amps__removal *R, amps_int v) {
    size_t n0 = R->saved.n, s0 = R->slot.n;
    amps_int j;
    if (v >= R->nnode0 || R->flag[v]) return AMPS_OK;
    for (j = 0; j < m->inc_len[v]; j++)
        if (amps__iv_push(ctx, &R->slot, m->inc[m->inc_ptr[v] + j])) goto oom;
    if (amps__iv_push(ctx, &R->saved, v) || amps__iv_push(ctx, &R->saved, m->inc_ptr[v]) ||
        amps__iv_push(ctx, &R->saved, m->inc_len[v]) || amps__iv_push(ctx, &R->saved, (amps_int)s0))
        goto oom;
    R->flag[v] = 1;
    return AMPS_OK;
oom: /* a partial record is dropped */
    R->saved.n = n0;
    R->slot.n = s0;
    return AMPS_ERR_OOM;
}

/* Queues the 4 vertices and 6 edges of tet t. */
static amps_status amps__rm_queue_tet(amps_ctx *ctx, const amps_mesh *m, struct amps__removal *R, amps_int t) {
    const amps_int *tv = m->tet + 4 * t;
    int i, j;
    for (i = 0; i < 4; i++) {
        if (amps__iv_push(ctx, &R->queue, tv[i]) || amps__iv_push(ctx, &R->queue, -1)) return AMPS_ERR_OOM;
        for (j = i + 1; j < 4; j++) {
            amps_int a = tv[i] < tv[j] ? tv[i] : tv[j], b = tv[i] < tv[j] ? tv[j] : tv[i];
            if (amps__iv_push(ctx, &R->queue, a) || amps__iv_push(ctx, &R->queue, b)) return AMPS_ERR_OOM;
        }
    }
    return AMPS_OK;
}

/* Removes the live tet t: flag, incidence lists of its nodes, the record; queues its items. */
static amps_status amps__rm_take(amps_ctx *ctx, amps_mesh *m, struct amps__removal *R, amps_int t) {
    int q;
    for (q = 0; q < 4; q++)
        if (amps__rm_save(ctx, m, R, m->tet[4 * t + q])) return AMPS_ERR_OOM;
    if (amps__iv_push(ctx, &R->tets, t)) return AMPS_ERR_OOM;
    for (q = 0; q < 4; q++) {
        amps_int v = m->tet[4 * t + q], *lst = m->inc + m->inc_ptr[v], n = m->inc_len[v], j = 0;
        while (lst[j] != t) j++;
        for (; j + 1 < n; j++) lst[j] = lst[j + 1];
        m->inc_len[v] = n - 1;
    }
    m->removed[t] = 1;
    m->nremoved++;
    return amps__rm_queue_tet(ctx, m, R, t);
}

/* Gives the tets star[i] with grp[i] == g (ascending, all containing v) a new copy of v: the
   stable partition of v's slot of amps_mesh_cut, recorded as a separation; queues the items of
   the moved tets before and after. */
static amps_status amps__rm_separate(amps_ctx *ctx, amps_mesh *m, struct amps__removal *R, amps_int v,
                                     const amps_int *star, const amps_int *grp, amps_int n, amps_int g) {
    amps_int base, deg, keep = 0, nm = 0, vc, j, i;
    int q;
    amps_status s = amps__rm_save(ctx, m, R, v);
    if (!s) s = amps__mesh_grow(ctx, m, "amps_mesh_remove");
    while (!s && R->aux.cap < (size_t)m->inc_len[v]) s = amps__iv_push(ctx, &R->aux, 0);
    if (s) return s;
    vc = m->nnode;
    if (amps__iv_push(ctx, &R->sep_node, v) || amps__iv_push(ctx, &R->sep_copy, vc)) return AMPS_ERR_OOM;
    for (i = 0; i < n; i++)
        if (grp[i] == g && (amps__iv_push(ctx, &R->sep_tets, star[i]) || amps__rm_queue_tet(ctx, m, R, star[i])))
            return AMPS_ERR_OOM;
    if (amps__iv_push(ctx, &R->sep_ptr, (amps_int)R->sep_tets.n)) return AMPS_ERR_OOM;
    for (q = 0; q < 3; q++) m->xyz[3 * vc + q] = m->xyz[3 * v + q];
    m->origin[vc] = m->origin[v];
    base = m->inc_ptr[v];
    deg = m->inc_len[v];
    for (j = 0, i = 0; j < deg; j++) { /* kept tets first, the moved ones (the slot of vc) after */
        amps_int t = m->inc[base + j];
        while (i < n && star[i] < t) i++;
        if (i < n && star[i] == t && grp[i] == g) R->aux.a[nm++] = t;
        else m->inc[base + keep++] = t;
    }
    for (j = 0; j < nm; j++) m->inc[base + keep + j] = R->aux.a[j];
    m->inc_len[v] = keep;
    m->inc_ptr[vc] = base + keep;
    m->inc_len[vc] = nm;
    m->nnode++;
    for (j = 0; j < nm; j++) {
        amps_int t = m->inc[base + keep + j];
        for (q = 0; q < 4; q++)
            if (m->tet[4 * t + q] == v) {
                if (amps__iv_push(ctx, &R->edits, 4 * t + q) || amps__iv_push(ctx, &R->edits, v)) return AMPS_ERR_OOM;
                m->tet[4 * t + q] = vc;
            }
        if (amps__rm_queue_tet(ctx, m, R, t)) return AMPS_ERR_OOM;
    }
    return amps__iv_push(ctx, &R->queue, v) || amps__iv_push(ctx, &R->queue, -1) ? AMPS_ERR_OOM : AMPS_OK;
}

/* Position of tet t in the ascending star[0..n-1] (-1 if absent). */
static amps_int amps__star_find(const amps_int *star, amps_int n, amps_int t) {
    amps_int lo = 0, hi = n - 1;
    while (lo <= hi) {
        amps_int mid = lo + (hi - lo) / 2;
        if (star[mid] < t) lo = mid + 1;
        else if (star[mid] > t) hi = mid - 1;
        else return mid;
    }
    return -1;
}

/* Separates the singular edge (a, b), its tets and groups in R->star / R->grp (kept root k),
   at the first endpoint x whose star, grouped through shared faces, holds the kept group and
   another group in different parts: each such part without the kept group gets its own copy
   of x. *done = 0 when neither endpoint separates them. */
static amps_status amps__rm_separate_edge(amps_ctx *ctx, amps_mesh *m, struct amps__removal *R, amps_int a, amps_int b,
                                          amps_int k, int *done) {
    amps_int i, j, n = (amps_int)R->star.n, kept, x, K;
    amps_status s = AMPS_OK;
    int e;
    *done = 0;
    R->ed.n = R->eg.n = 0;
    for (i = 0; i < n && !s; i++) {
        s = amps__iv_push(ctx, &R->ed, R->star.a[i]);
        if (!s) s = amps__iv_push(ctx, &R->eg, R->grp.a[i] == R->grp.a[k]);
    }
    for (e = 0; e < 2 && !s && !*done; e++) {
        x = e ? b : a;
        (void)amps__rm_groups(ctx, m, R, x, -1, 3, &kept, &s);
        if (s) break;
        for (i = 0; !R->eg.a[i]; i++) {}
        K = R->grp.a[amps__star_find(R->star.a, (amps_int)R->star.n, R->ed.a[i])];
        for (i = 0; i < n && !s; i++) {
            amps_int t = R->ed.a[i], L;
            if (R->eg.a[i]) continue;
            j = amps__star_find(R->star.a, (amps_int)R->star.n, t);
            if (j < 0) continue;
            L = R->grp.a[j];
            if (m->tet[4 * t] != x && m->tet[4 * t + 1] != x && m->tet[4 * t + 2] != x && m->tet[4 * t + 3] != x)
                continue; /* its part already has a copy of x */
            if (L == K) continue;
            s = amps__rm_separate(ctx, m, R, x, R->star.a, R->grp.a, (amps_int)R->star.n, L);
            *done = 1;
        }
    }
    return s;
}

/* Resolves the queued vertices and edges until none is singular (policy REMOVE or SEPARATE). */
static amps_status amps__rm_resolve(amps_ctx *ctx, amps_mesh *m, struct amps__removal *R, amps_singular_policy policy) {
    size_t h;
    for (h = 0; h < R->queue.n; h += 2) {
        amps_int a = R->queue.a[h], b = R->queue.a[h + 1], kept, ng, i, n;
        amps_status s = AMPS_OK;
        int done = 0;
        ng = amps__rm_groups(ctx, m, R, a, b, b < 0 ? 2 : 3, &kept, &s);
        if (s) return s;
        if (ng < 2) continue;
        n = (amps_int)R->star.n;
        if (policy == AMPS_SINGULAR_SEPARATE && b < 0) {
            for (i = 0; i < n && !s; i++)
                if (R->grp.a[i] == i && i != kept) s = amps__rm_separate(ctx, m, R, a, R->star.a, R->grp.a, n, i);
            if (s) return s;
            continue;
        }
        if (policy == AMPS_SINGULAR_SEPARATE) {
            s = amps__rm_separate_edge(ctx, m, R, a, b, kept, &done);
            if (!s && !done) ng = amps__rm_groups(ctx, m, R, a, b, 3, &kept, &s);
            if (s) return s;
            if (done) continue;
            n = (amps_int)R->star.n;
        }
        /* take a copy of the doomed tets first: amps__rm_take changes the stars */
        R->aux.n = 0;
        for (i = 0; i < n && !s; i++)
            if (R->grp.a[i] != R->grp.a[kept]) s = amps__iv_push(ctx, &R->aux, R->star.a[i]);
        for (i = 0; i < (amps_int)R->aux.n && !s; i++) s = amps__rm_take(ctx, m, R, R->aux.a[i]);
        if (s) return s;
    }
    return AMPS_OK;
}

/* The log of a removal, flat: {nnode0, ntet, nsaved, nslot, nedits, tets, saved, slot, edits}
   (the parts of struct amps__removal that undo it). */
#define AMPS__RMLOG_HEAD 5

/* Restores m to its state before a removal from its undo record: the tet entries edited (pairs
   4 t + q, old node; undone last first), the saved incidence slots (per node: node, inc_ptr,
   inc_len, offset into slot), nnode and the removed flags of tets. */
static void amps__rm_restore(amps_mesh *m, amps_int nnode0, const amps_int *tets, amps_int ntet, const amps_int *saved,
                             amps_int nsaved, const amps_int *slot, const amps_int *edits, amps_int nedits) {
    amps_int k, v;
    for (k = nedits; k >= 2; k -= 2) m->tet[edits[k - 2]] = edits[k - 1];
    for (k = 0; k + 4 <= nsaved; k += 4) {
        const amps_int *sv = saved + k;
        m->inc_ptr[sv[0]] = sv[1];
        m->inc_len[sv[0]] = sv[2];
        if (sv[2] > 0) memcpy(m->inc + sv[1], slot + sv[3], sizeof(amps_int) * (size_t)sv[2]);
    }
    for (v = nnode0; v < m->nnode; v++) m->inc_ptr[v] = m->inc_len[v] = 0;
    m->nnode = nnode0;
    for (k = 0; k < ntet; k++) m->removed[tets[k]] = 0;
    m->nremoved -= ntet;
}

/* Restores m to its state before the removal R recorded. */
static void amps__rm_undo(amps_mesh *m, struct amps__removal *R) {
    amps__rm_restore(m, R->nnode0, R->tets.a, (amps_int)R->tets.n, R->saved.a, (amps_int)R->saved.n, R->slot.a,
                     R->edits.a, (amps_int)R->edits.n);
    R->valid = 0;
}

/* The log of a removal, flat: {nnode0, ntet, nsaved, nslot, nedits, tets, saved, slot, edits}. */
#define AMPS__RMLOG_HEAD 5

/* The length of the log of the last removal of m (0 if it is not the last change of m). */
static amps_int amps__rm_log_len(const amps_mesh *m) {
    const struct amps__removal *R = m->last_removal;
    if (!R || !R->valid) return 0;
    return AMPS__RMLOG_HEAD + (amps_int)(R->tets.n + R->saved.n + R->slot.n + R->edits.n);
}

/* Writes the log of the last removal of m (amps__rm_log_len entries) to L. */
static void amps__rm_log_save(const amps_mesh *m, amps_int *L) {
    const struct amps__removal *R = m->last_removal;
    const amps__ivec *part[4];
    int k;
    part[0] = &R->tets, part[1] = &R->saved, part[2] = &R->slot, part[3] = &R->edits;
    L[0] = R->nnode0;
    for (k = 0; k < 4; k++) L[1 + k] = (amps_int)part[k]->n;
    L += AMPS__RMLOG_HEAD;
    for (k = 0; k < 4; L += part[k]->n, k++)
        if (part[k]->n) memcpy(L, part[k]->a, sizeof(amps_int) * part[k]->n);
}

/* Undoes the removal logged in L; the changes of m since (cuts, removals) must have been undone,
   last first. */
static void amps__rm_log_undo(amps_mesh *m, const amps_int *L) {
    const amps_int *tets = L + AMPS__RMLOG_HEAD, *saved = tets + L[1], *slot = saved + L[2];
    amps__rm_restore(m, L[0], tets, L[1], saved, L[2], slot, slot + L[3], L[4]);
    amps__removal_forget(m);
}

/* Checks the tets of amps_mesh_remove: in range, live, none twice (marked 2 while checking). */
static amps_status amps__rm_check_input(amps_ctx *ctx, amps_mesh *m, amps_int n, const amps_int *tets) {
    const char *fn = "amps_mesh_remove";
    amps_status s = AMPS_OK;
    amps_int i, k;
    for (i = 0; i < n && !s; i++) {
        amps_int t = tets[i];
        if (t < 0 || t >= m->ntet)
            s = amps__err(ctx, AMPS_ERR_INDEX, "%s: tetrahedron %lld out of range [0, %lld)", fn, (long long)t,
                          (long long)m->ntet);
        else if (m->removed[t] == 1)
            s = amps__err(ctx, AMPS_ERR_ARG, "%s: tetrahedron %lld is already removed", fn, (long long)t);
        else if (m->removed[t] == 2)
            s = amps__err(ctx, AMPS_ERR_ARG, "%s: tetrahedron %lld is given twice", fn, (long long)t);
        else m->removed[t] = 2;
    }
    for (k = 0; k < i; k++) /* tets[i - 1] may be the one out of range */
        if (tets[k] >= 0 && tets[k] < m->ntet && m->removed[tets[k]] == 2) m->removed[tets[k]] = 0;
    return s;
}

/* Resets the record R for a removal from the current state of m. */
static amps_status amps__rm_begin(amps_ctx *ctx, amps_mesh *m, struct amps__removal *R) {
    R->valid = 0;
    R->nnode0 = m->nnode;
    R->tets.n = R->sep_node.n = R->sep_copy.n = R->sep_ptr.n = R->sep_tets.n = R->orphans.n = 0;
    R->saved.n = R->slot.n = R->edits.n = R->queue.n = 0;
    if (R->flag_cap < (size_t)m->nnode) {
        void *p = R->flag;
        if (amps__realloc(ctx, &p, (size_t)m->nnode, 1)) return AMPS_ERR_OOM;
        R->flag = AMPS__CAST(unsigned char *, p);
        memset(R->flag, 0, (size_t)m->nnode);
        R->flag_cap = (size_t)m->nnode;
    }
    return amps__iv_push(ctx, &R->sep_ptr, 0);
}

/* Orphans of the removal R (saved nodes and new copies left in no tet), ascending. */
static amps_status amps__rm_orphans(amps_ctx *ctx, const amps_mesh *m, struct amps__removal *R) {
    size_t k;
    amps_int v;
    for (k = 0; k + 4 <= R->saved.n; k += 4)
        if (m->inc_len[R->saved.a[k]] == 0 && amps__iv_push(ctx, &R->orphans, R->saved.a[k])) return AMPS_ERR_OOM;
    for (v = R->nnode0; v < m->nnode; v++)
        if (m->inc_len[v] == 0 && amps__iv_push(ctx, &R->orphans, v)) return AMPS_ERR_OOM;
    amps__sort(R->orphans.a, R->orphans.n, sizeof(amps_int), amps__int_cmp);
    return AMPS_OK;
}

AMPS_API amps_status amps_mesh_remove(amps_ctx *ctx, amps_mesh *m, amps_int n, const amps_int *tets,
                                      amps_singular_policy policy, amps_mesh_removal *out) {
    const char *fn = "amps_mesh_remove";
    struct amps__removal *R;
    amps_status s;
    amps_int i;
    size_t k;
    if (out) memset(out, 0, sizeof(*out));
    if (!m || !tets || n < 1) return amps__err(ctx, AMPS_ERR_ARG, "%s: NULL mesh or tets, or n < 1", fn);
    if (policy != AMPS_SINGULAR_REMOVE && policy != AMPS_SINGULAR_SEPARATE && policy != AMPS_SINGULAR_IGNORE)
        return amps__err(ctx, AMPS_ERR_ARG, "%s: unknown singularity policy %d", fn, (int)policy);
    s = amps__rm_check_input(ctx, m, n, tets);
    if (s) return s;
    if (!m->last_removal) {
        m->last_removal = AMPS__CAST(struct amps__removal *, amps__calloc(ctx, 1, sizeof(struct amps__removal)));
        if (!m->last_removal) return AMPS_ERR_OOM;
    }
    R = m->last_removal;
    s = amps__rm_begin(ctx, m, R);
    for (i = 0; i < n && !s; i++) s = amps__rm_take(ctx, m, R, tets[i]);
    if (!s && policy != AMPS_SINGULAR_IGNORE) s = amps__rm_resolve(ctx, m, R, policy);
    if (!s) s = amps__rm_orphans(ctx, m, R);
    for (k = 0; k + 4 <= R->saved.n; k += 4) R->flag[R->saved.a[k]] = 0;
    if (s) {
        amps__rm_undo(m, R);
        return s;
    }
    R->valid = 1;
    if (out) {
        out->ntet = (amps_int)R->tets.n;
        out->tets = R->tets.a;
        out->nsep = (amps_int)R->sep_node.n;
        out->sep_node = R->sep_node.a;
        out->sep_copy = R->sep_copy.a;
        out->sep_ptr = R->sep_ptr.a;
        out->sep_tets = R->sep_tets.a;
        out->norphan = (amps_int)R->orphans.n;
        out->orphans = R->orphans.a;
    }
    return AMPS_OK;
}

AMPS_API amps_status amps_mesh_unremove(amps_ctx *ctx, amps_mesh *m, const amps_mesh_removal *r) {
    struct amps__removal *R = m ? m->last_removal : NULL;
    if (!R || !R->valid || !r || r->tets != R->tets.a || r->ntet != (amps_int)R->tets.n)
        return amps__err(ctx, AMPS_ERR_ARG, "amps_mesh_unremove: not the record of the last change of the mesh");
    amps__rm_undo(m, R);
    return AMPS_OK;
}

/* Singular vertices (edges 0) or edges (edges 1) of m, see amps_mesh_singular_vertices. */
static amps_int amps__singular(amps_ctx *ctx, const amps_mesh *m, int edges, amps_int *out) {
    struct amps__removal R;
    amps_int a, j, cnt = 0, kept;
    amps_status s = AMPS_OK;
    size_t k;
    int q;
    if (!m) {
        amps__err(ctx, AMPS_ERR_ARG, "amps_mesh_singular_%s: NULL mesh", edges ? "edges" : "vertices");
        return -1;
    }
    memset(&R, 0, sizeof(R));
    for (a = 0; a < m->nnode && !s; a++) {
        const amps_int *lst = m->inc + m->inc_ptr[a];
        if (!edges) {
            if (m->inc_len[a] > 1 && amps__rm_groups(ctx, m, &R, a, -1, 2, &kept, &s) > 1) {
                if (out) out[cnt] = a;
                cnt++;
            }
            continue;
        }
        R.aux.n = 0; /* the neighbours b > a, ascending and distinct */
        for (j = 0; j < m->inc_len[a] && !s; j++)
            for (q = 0; q < 4 && !s; q++)
                if (m->tet[4 * lst[j] + q] > a) s = amps__iv_push(ctx, &R.aux, m->tet[4 * lst[j] + q]);
        if (s) break;
        amps__sort(R.aux.a, R.aux.n, sizeof(amps_int), amps__int_cmp);
        for (k = 0; k < R.aux.n && !s; k++) {
            if (k > 0 && R.aux.a[k] == R.aux.a[k - 1]) continue;
            if (amps__rm_groups(ctx, m, &R, a, R.aux.a[k], 3, &kept, &s) > 1) {
                if (out) out[2 * cnt] = a, out[2 * cnt + 1] = R.aux.a[k];
                cnt++;
            }
        }
    }
    amps__free(ctx, R.star.a);
    amps__free(ctx, R.grp.a);
    amps__free(ctx, R.aux.a);
    return s ? -1 : cnt;
}

AMPS_API amps_int amps_mesh_singular_vertices(amps_ctx *ctx, const amps_mesh *m, amps_int *out) {
    return amps__singular(ctx, m, 0, out);
}

AMPS_API amps_int amps_mesh_singular_edges(amps_ctx *ctx, const amps_mesh *m, amps_int *out) {
    return amps__singular(ctx, m, 1, out);
}

#endif /* AMPS_NO_FEM */

/* ==== [amps:scene impl] a mesh with fixed nodes, forces, pins and cuts ======================== */
#ifndef AMPS_NO_FEM

/* Per-node state (node.cap nodes allocated; vectors hold 3 entries per node). */
typedef struct amps__scene_nodes {
    amps_int cap;                  /* node capacity of the arrays */
    unsigned char *fixed, *pinned; /* fixed: eliminated from the system; pinned: constrained */
    double *pin_value;             /* target displacement of a pin */
    double *force;                 /* external force */
    double *disp;                  /* displacement of the last solve */
    double *mass;                  /* lumped mass m_v (amps__mesh_node_mass), valid once factored */
    amps_int *dof;                 /* equation of each DOF, or -1 */
} amps__scene_nodes;

/* Workspace of a cut, sized by the largest node degree at the factorization. */
typedef struct amps__scene_cutws {
    amps_int max_degree;
    amps_int *moved;     /* the tets the cut moved */
    amps_int *local_dof; /* equations of their nodes (12 max_degree + 3) */
    double *local_K;     /* the stiffness change on local_dof x local_dof */
    amps_int *row, *col; /* its upper triangle as triplets for amps_update_add */
    double *val;
} amps__scene_cutws;

/* Workspace of the mechanism test of a cut or a removal (amps__mechanism). */
typedef struct amps__scene_mech {
    amps_int *tet_piece;    /* per tet: label of the piece exploring it, -1 between tests */
    amps_int *tet_next;     /* per tet: next tet in its piece's queue */
    amps_int *visited;      /* the tets labelled in this test */
    amps_marker node_seen;  /* per node: visited in the current joint scan */
    amps_int npiece;        /* capacity of the per-piece arrays (max_degree + 1, grown by removals) */
    amps_int *piece_parent; /* per piece: union-find parent */
    amps_int *queue_head, *queue_tail;
    amps_int *active; /* 1 while the piece is still growing */
    double scale;     /* the model's extent (tolerance of the line test) */
} amps__scene_mech;

/* The watched nodes (amps_scene_watch). */
typedef struct amps__scene_watch {
    amps_int *nodes, n, cap;
    int stale; /* the engine's watch set must be rebuilt */
} amps__scene_watch;

/* The boundary triangles by stable id and the change record (amps_scene_take_changes). Ids
   freed since the last take are held (not reused) until the next take. */
typedef struct amps__scene_render {
    int on;               /* recording since the first take */
    int lost;             /* an allocation failed while recording: the next take rebuilds */
    int taken;            /* the lists were taken: the next change starts new ones */
    amps_int *face_id;    /* 4 ntet: the id of face 4t+f, or -1 */
    amps_int nid, cap;    /* ids in use or freed; capacity of the per-id arrays */
    amps_int *tri, *face; /* per id: nodes (3), face; -1 when free */
    unsigned char *fresh; /* per id: added since the last take */
    amps_int *free_ids, nfree, *held, nheld;
    amps_int *added, nadded, *removed, nremoved;
    amps_int *new_nodes, nnew, cap_new;
    amps_int *moved, nmoved;  /* room for ntet */
    amps_int *tet_moved;      /* per tet: the recorded cuts that moved it (in moved iff > 0) */
} amps__scene_render;

/* The uniform grid of amps_scene_nearest_node over the creation nodes; copies are chained to
   their origin (next_copy, ascending). */
typedef struct amps__scene_grid {
    int built;
    amps_int n[3];
    double lo[3], h;
    amps_int *cell_ptr, *cell_node;
    amps_int *next_copy, *last_copy, nlinked, cap;
} amps__scene_grid;

static void amps__scene_render_free(amps_ctx *ctx, amps_scene *S);
static void amps__scene_cut_recorded(amps_ctx *ctx, amps_scene *S, amps_int v, amps_int vc);
/* An open batch (amps_scene_begin_batch): the changes it recorded, to undo them if its commit
   fails. Op k's integers are ilog[op.at .. op.at + op.len - 1], its doubles from dlog[op.dat]. */
typedef struct amps__scene_op {
    int kind;                /* 0 cut, 1 pin, 2 release, 3 material, 4 removal */
    int watched, was_pinned; /* cut: its copy joined the watch set; pin: v was pinned; material: rho set */
    amps_int v, vc;          /* the node, the cut's copy */
    amps_int at, len, dat;   /* cut: its moved tets; material: its tets, their old (E, nu, rho) in dlog;
                                removal: amps__scene_batch_removal's log */
    double old[3];           /* pin: the previous pin value */
} amps__scene_op;
typedef struct amps__scene_batch {
    int open, committing; /* a batch records; a two-phase commit of it is in progress */
    amps_int n, cap, nilog, cap_ilog, ndlog, cap_dlog;
    amps__scene_op *ops;
    amps_int *ilog;
    double *dlog;
} amps__scene_batch;

/* The corotational PCG's Gauss-Seidel sweeps run on at most AMPS__CR_PARTS slabs of about
   AMPS__CR_SLAB nodes at once. */
#define AMPS__CR_PARTS 16
#ifndef AMPS__CR_SLAB
#define AMPS__CR_SLAB 3000
#endif

/* Dynamics, gravity and fracture (amps_scene_dynamics, amps_scene_gravity, amps_scene_fracture). */
typedef struct amps__scene_dyn {
    int on;                 /* implicit dynamics: system A = cM M + cK K */
    double dt, alpha, beta; /* time step, Rayleigh damping C = alpha M + beta K */
    double cM, cK;          /* 1 + alpha dt, beta dt + dt^2 (used only when on) */
    double g[3];            /* gravity: body force per unit mass */
    amps_int cap;           /* node capacity of the arrays below */
    double *vel;            /* 3 per node: velocity w */
    double *ku;             /* per DOF: K u */
    amps_int *idx;          /* scratch: 3 per node */
    double *val;            /* scratch: 3 per node */
    double *vol;            /* ntet: |V| of each tet (reference configuration), NULL until factored */
    double *xe, *ye;        /* per equation (ncap): the u of the last K u, A u */
    amps_int ncap;
    struct {                /* what the last K u was computed with (amps__scene_dyn_ku) */
        int ok;             /* 0: recompute */
        unsigned long kver; /* the engine's version of K^ */
        double cM, cK;
    } kukey;
    unsigned char *orphan;                        /* 1: the node lies in no tet and is held where it is */
    double orphan_d;                              /* an orphan's rows of the engine: this on the diagonal */
    double sigma_max;                             /* fracture threshold (<= 0: off) */
    amps_int nfreg;                               /* regions with their own threshold */
    amps_int *freg_id;                            /* nfreg region ids */
    double *freg_sigma;                           /* their thresholds (<= 0: no fracture there) */
    amps_int nstep, nfractured, nfractured_total; /* steps taken; tets fractured by the last step, in all */
    int corot;                                    /* corotational steps (amps_scene_corotational) */
    int cr_rvalid;                                /* cr_R holds the rotations of the current u */
    long cr_rnkey[3];                             /* the state of cr_serial: steps, nodes, removals */
    long cr_serial;                               /* advanced when the state (u, nodes, removals) changes */
    long cr_rnall;                                /* cr_Rn holds every node's frame of the state with this serial */
    long *cr_rnst;                                /* per node: cr_Rn holds its frame of the state with this serial */
    double corot_tol;                             /* PCG relative residual (<= 0: 1e-10) */
    amps_int corot_maxit;                         /* PCG iteration cap (<= 0: 200) */
    double *cr_G;                                 /* 12 per tet: reference gradients (NULL until the first step) */
    double *cr_R;                                 /* 9 per tet: R_e */
    double *cr_lm;                                /* 2 per tet: lambda |V|, mu |V| */
    double *cr_ye;                                /* 12 per tet: element results of the last pass */
    double *cr_gel, *cr_react;                    /* 3 per node: elastic force g, pin reactions of the last step */
    double *cr_Rn;                                /* 9 per node: the node's rotation (the preconditioner's frame) */
    struct {                                      /* the PCG's start and its choice of preconditioner */
        double *wprev;                            /* 3 per node: w before the last step (the start extrapolates) */
        amps_int nprev;                           /* nodes 0..nprev-1 have wprev (0: none) */
        amps_int it[2]; /* iterations of the last step with each preconditioner (0: none yet) */
        amps_int probe; /* steps since Gauss-Seidel was last tried */
        double gsr;     /* Gauss-Seidel: |r^| / |r| at the last check (0: none yet) */
    } crP;
    struct {                /* A_R factored at a step whose PCG stalled (amps__cr_own): the preconditioner
                               in place of the engine's while the free entries keep their pattern */
        amps_factor *F;     /* NULL: none */
        amps_int n, nf;     /* PCG entries, free ones (F's order) */
        amps_int *idx;      /* n: the free entry's index in F (-1: held) */
        unsigned char *cp;  /* n: cr_cp when F was made */
        double *w, *work;   /* nf each */
    } crF;
    struct {                /* the haptic path between corotational steps */
        double *g0, *r0;    /* 3 per node: pin targets and reactions of the last step */
        unsigned char *pin; /* per node: pinned at the last step */
        int used;           /* a haptic call was made: each step ends with the frames */
    } crH;
    amps_int cr_cap;                              /* node capacity of cr_gel, cr_react */
    double *cr_vec;                               /* 27 per node: b, x, r, z, p, q, t, s, d in the PCG's order */
    unsigned char *cr_cp;                         /* 3 per node: the PCG's held entries */
    double *cr_eng;                               /* 1 per equation: the engine's preconditioner */
    double *cr_part;                              /* 2 per 256 nodes: the PCG's partial sums */
    struct {                                      /* A_R of the step in 3x3 blocks by node (amps__cr_assemble) */
        amps_int *bp, *bu, *bj;                   /* the row of node v (k = rank[v]): its blocks of earlier */
                                                  /* nodes bp[k] .. bp[k+1]-1, then of v and later nodes */
                                                  /* bu[k] .. bu[k+1]-1, the diagonal block first (bu[0] = */
                                                  /* bp[nnode]; empty: a node in no tet); bj: the nodes */
        double *bx;                               /* 9 per block, row-major */
        amps_int *be;                             /* per block: 3 rank of its column node (the PCG's entry) */
        amps_int *ord, *rank;                     /* the Gauss-Seidel order of the nodes, and its inverse */
        amps_int *wgs;                            /* workspace of the order: 3 per node + 2 */
        amps_int np, pp[AMPS__CR_PARTS + 2];      /* ord: np parts, part k at pp[k] .. pp[k+1]-1, then the */
                                                  /* interface (pp[np] .. pp[np+1]-1) */
        double *dinv;                             /* 9 per rank: the inverse of the node's diagonal block */
        amps_int *map;           /* 16 per tet: map[16 t + 4 a + b] = block of tet node b in row of node a */
        amps_int *tet;           /* 4 per tet: the nodes the pattern was built for */
        amps_int *wrow, *wcnt;   /* workspace of a rebuild: 16 per tet; 2 per node + 2 */
        amps_int nnode, ntet;    /* the mesh it was built for (0: none) */
        size_t cap_row, cap_blk; /* capacities of bp (nodes + 1) and bj, bx */
    } crA;
    unsigned char *cr_con;                        /* 1 per equation: constrained in the engine */
    amps_int cr_ncap;                             /* equation capacity of cr_eng, cr_con */
    amps_scene_step_stats info;                   /* the last step (amps_scene_step_info) */
    amps_int *rm_list, *rm_flag, *rm_rename, *rm_queue, *rm_sort; /* removal and fracture workspace, grown */
    unsigned char *rm_seen; /* on demand: tets, orphans flagged, node map, queue, changed tets, marks */
    size_t rm_list_cap, rm_flag_cap, rm_rename_cap, rm_queue_cap, rm_sort_cap, rm_seen_cap;
} amps__scene_dyn;

/* Triplets of a change of the system matrix (upper triangle in equations): the scene's workspace
   (kept between changes: a change allocates only when it is larger than every one before), and
   the summed entries handed to amps_update_add. */
typedef struct amps__trip {
    amps_int r, c;
    double v;
} amps__trip;
typedef struct amps__trips {
    amps__trip *e;
    size_t n, cap;
    amps_int *r, *c; /* cap_sum summed entries */
    double *v;
    size_t cap_sum;
} amps__trips;

struct amps_scene {
    amps_mesh *m;
    amps_scene_opts opts;
    int prepared; /* K factored, engine created */
    amps__scene_nodes node;
    amps_int ndof0; /* equations of the initial system */
    amps_csc *K;    /* initial stiffness matrix (upper triangle, equations) */
    amps_factor *F; /* its factor */
    amps_update *U; /* the engine holding every change since */
    amps__scene_watch watch;
    amps__scene_cutws cut;
    amps__scene_mech mech;
    amps__scene_render rd;
    amps__scene_grid grid;
    amps__scene_batch batch;
    amps__scene_dyn dyn;
    amps__trips trips;
};

/* Ae = cK Ke + cM Me of tet t, Me = diag(rho |V| / 4) (statics: Ae = Ke): every element matrix
   of the scene's system. Returns |V|. */
static double amps__scene_tet_matrix(const amps_scene *S, amps_int t, double Ae[144]) {
    double V = amps_mesh_tet_stiffness(S->m, t, Ae), mv;
    int a;
    if (!S->dyn.on) return V;
    mv = S->dyn.cM * (S->m->rho ? S->m->rho[t] : 1.0) * V / 4;
    for (a = 0; a < 144; a++) Ae[a] *= S->dyn.cK;
    for (a = 0; a < 12; a++) Ae[13 * a] += mv;
    return V;
}
static double amps__scene_body_force(const amps_scene *S, amps_int v, int d);
static amps_status amps__scene_dyn_room(amps_ctx *ctx, amps_scene *S, amps_int nnode);
static void amps__scene_dyn_cut(amps_ctx *ctx, amps_scene *S, amps_int v, amps_int vc);
static amps_status amps__scene_dyn_load(amps_ctx *ctx, amps_scene *S);
static amps_status amps__scene_set_material_all(amps_ctx *ctx, amps_scene *S, double E, double nu);

AMPS_API void amps_scene_opts_default(amps_scene_opts *o) {
    if (!o) return;
    memset(o, 0, sizeof(*o));
    o->order.method = AMPS_ORDER_AUTO;
    o->order.block = 3;
    amps_update_opts_default(&o->update);
    o->update.grow = 1;
}

static void amps__cr_own_free(amps_ctx *ctx, amps_scene *S);

AMPS_API void amps_scene_free(amps_ctx *ctx, amps_scene *S) {
    if (!S) return;
    amps_update_free(ctx, S->U);
    amps_factor_free(ctx, S->F);
    amps_csc_free(ctx, S->K);
    amps_mesh_free(ctx, S->m);
    amps__free(ctx, S->node.fixed);
    amps__free(ctx, S->node.pinned);
    amps__free(ctx, S->node.pin_value);
    amps__free(ctx, S->node.force);
    amps__free(ctx, S->node.disp);
    amps__free(ctx, S->node.mass);
    amps__free(ctx, S->node.dof);
    amps__free(ctx, S->cut.moved);
    amps__free(ctx, S->cut.local_dof);
    amps__free(ctx, S->cut.row);
    amps__free(ctx, S->cut.col);
    amps__free(ctx, S->cut.local_K);
    amps__free(ctx, S->cut.val);
    amps__free(ctx, S->watch.nodes);
    amps__free(ctx, S->mech.tet_piece);
    amps__free(ctx, S->mech.tet_next);
    amps__free(ctx, S->mech.visited);
    amps_marker_free(ctx, &S->mech.node_seen);
    amps__free(ctx, S->mech.piece_parent);
    amps__free(ctx, S->mech.queue_head);
    amps__free(ctx, S->mech.queue_tail);
    amps__free(ctx, S->mech.active);
    amps__scene_render_free(ctx, S);
    amps__free(ctx, S->batch.ops);
    amps__free(ctx, S->batch.ilog);
    amps__free(ctx, S->trips.e);
    amps__free(ctx, S->trips.r);
    amps__free(ctx, S->trips.c);
    amps__free(ctx, S->trips.v);
    amps__free(ctx, S->batch.dlog);
    amps__free(ctx, S->dyn.vel);
    amps__free(ctx, S->dyn.ku);
    amps__free(ctx, S->dyn.idx);
    amps__free(ctx, S->dyn.val);
    amps__free(ctx, S->dyn.orphan);
    amps__free(ctx, S->dyn.vol);
    amps__free(ctx, S->dyn.xe);
    amps__free(ctx, S->dyn.ye);
    amps__free(ctx, S->dyn.freg_id);
    amps__free(ctx, S->dyn.freg_sigma);
    amps__free(ctx, S->dyn.cr_G);
    amps__free(ctx, S->dyn.cr_R);
    amps__free(ctx, S->dyn.cr_lm);
    amps__free(ctx, S->dyn.cr_ye);
    amps__free(ctx, S->dyn.cr_gel);
    amps__free(ctx, S->dyn.cr_react);
    amps__free(ctx, S->dyn.cr_Rn);
    amps__free(ctx, S->dyn.crP.wprev);
    amps__free(ctx, S->dyn.crH.g0);
    amps__free(ctx, S->dyn.crH.r0);
    amps__free(ctx, S->dyn.crH.pin);
    amps__free(ctx, S->dyn.cr_rnst);
    amps__free(ctx, S->dyn.cr_vec);
    amps__free(ctx, S->dyn.cr_cp);
    amps__free(ctx, S->dyn.cr_eng);
    amps__free(ctx, S->dyn.cr_part);
    amps__free(ctx, S->dyn.crA.bp);
    amps__free(ctx, S->dyn.crA.bu);
    amps__free(ctx, S->dyn.crA.bj);
    amps__free(ctx, S->dyn.crA.bx);
    amps__free(ctx, S->dyn.crA.be);
    amps__free(ctx, S->dyn.crA.dinv);
    amps__free(ctx, S->dyn.crA.ord);
    amps__free(ctx, S->dyn.crA.rank);
    amps__free(ctx, S->dyn.crA.wgs);
    amps__cr_own_free(ctx, S);
    amps__free(ctx, S->dyn.crA.map);
    amps__free(ctx, S->dyn.crA.tet);
    amps__free(ctx, S->dyn.crA.wrow);
    amps__free(ctx, S->dyn.crA.wcnt);
    amps__free(ctx, S->dyn.cr_con);
    amps__free(ctx, S->dyn.rm_list);
    amps__free(ctx, S->dyn.rm_flag);
    amps__free(ctx, S->dyn.rm_rename);
    amps__free(ctx, S->dyn.rm_queue);
    amps__free(ctx, S->dyn.rm_sort);
    amps__free(ctx, S->dyn.rm_seen);
    amps__free(ctx, S);
}

/* Grows the per-node arrays to cap nodes (new entries zero, dof -1). All-or-nothing in effect:
   arrays already grown stay valid. */
static amps_status amps__scene_grow(amps_ctx *ctx, amps_scene *S, amps_int cap) {
    amps_int v, old = S->node.cap;
    size_t c = (size_t)cap;
    if (amps__realloc(ctx, (void **)&S->node.fixed, c, 1) || amps__realloc(ctx, (void **)&S->node.pinned, c, 1) ||
        amps__realloc(ctx, (void **)&S->node.pin_value, 3 * c, sizeof(double)) ||
        amps__realloc(ctx, (void **)&S->node.force, 3 * c, sizeof(double)) ||
        amps__realloc(ctx, (void **)&S->node.disp, 3 * c, sizeof(double)) ||
        amps__realloc(ctx, (void **)&S->node.mass, c, sizeof(double)) ||
        amps__realloc(ctx, (void **)&S->node.dof, 3 * c, sizeof(amps_int)) ||
        amps_marker_grow(ctx, &S->mech.node_seen, cap))
        return AMPS_ERR_OOM;
    for (v = old; v < cap; v++) {
        int d;
        S->node.fixed[v] = 0;
        S->node.pinned[v] = 0;
        S->node.mass[v] = 0;
        for (d = 0; d < 3; d++) {
            S->node.pin_value[3 * v + d] = 0;
            S->node.force[3 * v + d] = 0;
            S->node.disp[3 * v + d] = 0;
            S->node.dof[3 * v + d] = -1;
        }
    }
    S->node.cap = cap;
    return AMPS_OK;
}

AMPS_API amps_scene *amps_scene_create(amps_ctx *ctx, amps_mesh *m, const amps_scene_opts *opts) {
    amps_scene *S;
    if (!m) { /* a reader's failure keeps its message */
        if (!ctx || ctx->status >= 0) amps__err(ctx, AMPS_ERR_ARG, "amps_scene_create: NULL mesh");
        return NULL;
    }
    S = AMPS__CAST(amps_scene *, amps__calloc(ctx, 1, sizeof(amps_scene)));
    if (!S || amps__scene_grow(ctx, S, m->node_cap > m->nnode ? m->node_cap : m->nnode + 1)) {
        amps__err(ctx, AMPS_ERR_OOM, "amps_scene_create: out of memory");
        amps_scene_free(ctx, S); /* S->m is NULL: the mesh is freed below */
        amps_mesh_free(ctx, m);
        return NULL;
    }
    if (opts) S->opts = *opts;
    else amps_scene_opts_default(&S->opts);
    S->m = m;
    return S;
}

AMPS_API const amps_mesh *amps_scene_mesh(const amps_scene *S) { return S ? S->m : NULL; }
AMPS_API amps_update *amps_scene_engine(const amps_scene *S) { return S ? S->U : NULL; }
AMPS_API const amps_factor *amps_scene_factor(const amps_scene *S) {
    return S && S->U ? amps_update_factor(S->U) : NULL;
}
AMPS_API amps_int amps_scene_ndof(const amps_scene *S) {
    if (!S) return 0;
    if (!S->U) return S->ndof0;
    return amps_update_dim(S->U) + (S->U->cjob.state && S->U->cjob.nlist >= 0 ? S->U->cjob.n_dofs : 0);
}

AMPS_API amps_status amps_scene_set_material(amps_ctx *ctx, amps_scene *S, double E, double nu) {
    if (!S) return amps__err(ctx, AMPS_ERR_ARG, "amps_scene_set_material: NULL scene");
    if (S->prepared) return amps__scene_set_material_all(ctx, S, E, nu);
    return amps_mesh_set_material(ctx, S->m, E, nu);
}

AMPS_API amps_status amps_scene_fix(amps_ctx *ctx, amps_scene *S, amps_int nv, const amps_int *v) {
    amps_int k;
    if (!S || nv < 0 || (nv > 0 && !v)) return amps__err(ctx, AMPS_ERR_ARG, "amps_scene_fix: bad arguments");
    if (S->prepared)
        return amps__err(ctx, AMPS_ERR_STATE,
                         "amps_scene_fix: the system is already factored (fix nodes before the first change or solve)");
    for (k = 0; k < nv; k++)
        if (v[k] < 0 || v[k] >= S->m->nnode)
            return amps__err(ctx, AMPS_ERR_INDEX, "amps_scene_fix: node %ld out of range [0, %ld)", (long)v[k],
                             (long)S->m->nnode);
    for (k = 0; k < nv; k++) S->node.fixed[v[k]] = 1;
    return AMPS_OK;
}

AMPS_API amps_status amps_scene_fix_where(amps_ctx *ctx, amps_scene *S, int axis, amps_cmp cmp, double value,
                                          amps_int *count) {
    amps_int v, c = 0;
    if (!S || axis < 0 || axis > 2 || !amps__isfinite(value))
        return amps__err(ctx, AMPS_ERR_ARG, "amps_scene_fix_where: bad axis or value");
    if (S->prepared) return amps__err(ctx, AMPS_ERR_STATE, "amps_scene_fix_where: the system is already factored");
    for (v = 0; v < S->m->nnode; v++) {
        double x = S->m->xyz[3 * v + axis];
        if (cmp == AMPS_LT ? x < value : x > value) {
            S->node.fixed[v] = 1;
            c++;
        }
    }
    if (count) *count = c;
    return AMPS_OK;
}

/* The tet volumes (dyn.vol, once: the reference configuration does not move) and the lumped
   mass of every node (node.mass). */
static amps_status amps__scene_masses(amps_ctx *ctx, amps_scene *S) {
    const amps_mesh *m = S->m;
    amps_int t, v;
    if (!S->dyn.vol) {
        S->dyn.vol = AMPS__CAST(double *, amps__malloc(ctx, (size_t)m->ntet + 1, sizeof(double)));
        if (!S->dyn.vol) return amps__err(ctx, AMPS_ERR_OOM, "amps_scene: out of memory");
        for (t = 0; t < m->ntet; t++) {
            double X[12], G[12];
            amps_mesh_tet_coords(m, t, X);
            S->dyn.vol[t] = fabs(amps_tet_gradients(X, G));
        }
    }
    for (v = 0; v < m->nnode; v++) S->node.mass[v] = amps__mesh_node_mass(m, S->dyn.vol, v);
    return AMPS_OK;
}

/* node.mass[v] after a change of the tets of v (cut, removal, density); before the first
   factorization nothing (amps__scene_masses computes them all). */
static void amps__scene_mass_node(amps_scene *S, amps_int v) {
    if (S->dyn.vol && v >= 0 && v < S->node.cap)
        S->node.mass[v] = v < S->m->nnode ? amps__mesh_node_mass(S->m, S->dyn.vol, v) : 0.0;
}

/* K (upper triangle over node.dof) becomes cK K + cM M, M the lumped mass: the system of
   amps__scene_tet_matrix summed. */
static void amps__scene_mass_diag(amps_scene *S, amps_csc *K) {
    amps_int v, p, j;
    int d;
    for (p = 0; p < K->p[K->ncol]; p++) K->x[p] *= S->dyn.cK;
    for (v = 0; v < S->m->nnode; v++)
        for (d = 0; d < 3; d++)
            if ((j = S->node.dof[3 * v + d]) >= 0 && K->p[j + 1] > K->p[j] && K->i[K->p[j + 1] - 1] == j)
                K->x[K->p[j + 1] - 1] += S->dyn.cM * S->node.mass[v];
}

/* K = the stiffness matrix of the free DOFs (node.dof numbered), its factor F (ordered with the
   free nodes' coordinates unless opts.order gives some) and the engine U over them. */
static amps_status amps__scene_factor(amps_ctx *ctx, amps_scene *S, amps_int n) {
    amps_int v, k, nfree = 0;
    double *coords;
    amps_order_opts ord;
    amps_update_opts uo = S->opts.update;
    if (amps__scene_masses(ctx, S) != AMPS_OK) return AMPS_ERR_OOM;
    S->K = amps_mesh_assemble(ctx, S->m, S->node.dof, n);
    if (!S->K) return AMPS_ERR_OOM;
    if (S->dyn.on) amps__scene_mass_diag(S, S->K);
    /* coordinates of the free nodes, one per block of 3 equations, for the ordering */
    coords = AMPS__CAST(double *, amps__malloc(ctx, (size_t)n, sizeof(double)));
    if (!coords) return AMPS_ERR_OOM;
    for (v = 0; v < S->m->nnode; v++)
        if (S->node.dof[3 * v] >= 0) {
            for (k = 0; k < 3; k++) coords[3 * nfree + k] = S->m->xyz[3 * v + k];
            nfree++;
        }
    ord = S->opts.order;
    if (!ord.coords && ord.block == 3 && 3 * nfree == n) ord.coords = coords;
    S->F = amps_analyze(ctx, S->K, AMPS_UPPER, &ord);
    amps__free(ctx, coords);
    if (!S->F) return AMPS_ERR_OOM;
    if (amps_factorize(ctx, S->F, S->K) != AMPS_OK) {
        char msg[256];
        amps_int bad = -1, e;
        memcpy(msg, ctx ? ctx->msg : "", ctx ? sizeof(msg) : 1);
        for (e = 0; e < 3 * S->m->nnode && bad < 0 && S->F->failed >= 0; e++)
            if (S->node.dof[e] == S->F->failed) bad = e / 3;
        return amps__err(ctx, AMPS_ERR_NOT_SPD,
                         "amps_scene_prepare: the stiffness matrix is singular at node %ld (is the piece holding it "
                         "held? fix some of its nodes): %s",
                         (long)bad, msg);
    }
    if (uo.refactor_order.block == 0) uo.refactor_order.block = 3; /* re-factorizations order node triples */
    S->U = amps_update_create(ctx, S->K, AMPS_UPPER, S->F, &uo);
    return S->U ? AMPS_OK : AMPS_ERR_OOM;
}

/* The cut and mechanism-test workspaces, sized by the largest node degree, and the model's extent. */
static amps_status amps__scene_workspace(amps_ctx *ctx, amps_scene *S) {
    amps_int v, k, t, maxdeg = 0, nt = S->m->ntet, ng;
    size_t nl, ne;
    double lo[3], hi[3];
    for (v = 0; v < S->m->nnode; v++) {
        amps_int d = amps_mesh_degree(S->m, v);
        if (d > maxdeg) maxdeg = d;
    }
    S->cut.max_degree = maxdeg;
    nl = (size_t)(12 * maxdeg + 3);
    ne = nl * nl;
    ng = maxdeg + 1;
    S->cut.moved = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)maxdeg + 1, sizeof(amps_int)));
    S->cut.local_dof = AMPS__CAST(amps_int *, amps__malloc(ctx, nl, sizeof(amps_int)));
    S->cut.local_K = AMPS__CAST(double *, amps__calloc(ctx, ne, sizeof(double)));
    S->cut.row = AMPS__CAST(amps_int *, amps__malloc(ctx, ne, sizeof(amps_int)));
    S->cut.col = AMPS__CAST(amps_int *, amps__malloc(ctx, ne, sizeof(amps_int)));
    S->cut.val = AMPS__CAST(double *, amps__malloc(ctx, ne, sizeof(double)));
    S->mech.tet_piece = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)nt, sizeof(amps_int)));
    S->mech.tet_next = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)nt, sizeof(amps_int)));
    S->mech.visited = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)nt, sizeof(amps_int)));
    S->mech.piece_parent = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)ng, sizeof(amps_int)));
    S->mech.queue_head = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)ng, sizeof(amps_int)));
    S->mech.queue_tail = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)ng, sizeof(amps_int)));
    S->mech.active = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)ng, sizeof(amps_int)));
    S->mech.npiece = ng;
    if (!S->cut.moved || !S->cut.local_dof || !S->cut.local_K || !S->cut.row || !S->cut.col || !S->cut.val ||
        !S->mech.tet_piece || !S->mech.tet_next || !S->mech.visited || !S->mech.piece_parent || !S->mech.queue_head ||
        !S->mech.queue_tail || !S->mech.active)
        return AMPS_ERR_OOM;
    for (t = 0; t < nt; t++) S->mech.tet_piece[t] = -1;
    for (k = 0; k < 3; k++) {
        lo[k] = HUGE_VAL;
        hi[k] = -HUGE_VAL;
    }
    for (t = 0; t < 4 * nt; t++) /* the nodes of the tets (a node in none does not size the model) */
        for (v = S->m->tet[t], k = 0; k < 3 && v >= 0; k++) {
            double x = S->m->xyz[3 * v + k];
            if (x < lo[k]) lo[k] = x;
            if (x > hi[k]) hi[k] = x;
        }
    if (nt == 0)
        for (k = 0; k < 3; k++) lo[k] = hi[k] = 0.0;
    S->mech.scale = sqrt((hi[0] - lo[0]) * (hi[0] - lo[0]) + (hi[1] - lo[1]) * (hi[1] - lo[1]) +
                         (hi[2] - lo[2]) * (hi[2] - lo[2]));
    return AMPS_OK;
}

/* Frees what amps_scene_prepare made; the scene is unprepared again. */
static void amps__scene_unprepare(amps_ctx *ctx, amps_scene *S) {
    amps_int v;
    amps_update_free(ctx, S->U);
    S->U = NULL;
    S->dyn.kukey.ok = 0;
    amps_factor_free(ctx, S->F);
    S->F = NULL;
    amps_csc_free(ctx, S->K);
    S->K = NULL;
    amps__free(ctx, S->cut.moved);
    amps__free(ctx, S->cut.local_dof);
    amps__free(ctx, S->cut.local_K);
    amps__free(ctx, S->cut.row);
    amps__free(ctx, S->cut.col);
    amps__free(ctx, S->cut.val);
    S->cut.moved = S->cut.local_dof = S->cut.row = S->cut.col = NULL;
    S->cut.local_K = S->cut.val = NULL;
    amps__free(ctx, S->mech.tet_piece);
    amps__free(ctx, S->mech.tet_next);
    amps__free(ctx, S->mech.visited);
    amps__free(ctx, S->mech.piece_parent);
    amps__free(ctx, S->mech.queue_head);
    amps__free(ctx, S->mech.queue_tail);
    amps__free(ctx, S->mech.active);
    S->mech.tet_piece = S->mech.tet_next = S->mech.visited = NULL;
    S->mech.piece_parent = S->mech.queue_head = S->mech.queue_tail = S->mech.active = NULL;
    for (v = 0; v < 3 * S->m->nnode; v++) S->node.dof[v] = -1;
}

AMPS_API amps_status amps_scene_prepare(amps_ctx *ctx, amps_scene *S) {
    amps_int n, v, k;
    if (!S) return amps__err(ctx, AMPS_ERR_ARG, "amps_scene_prepare: NULL scene");
    if (S->prepared) return AMPS_OK;
    n = amps_mesh_number_dofs(S->m, S->node.fixed, S->node.dof);
    if (n == 0) return amps__err(ctx, AMPS_ERR_STATE, "amps_scene_prepare: every node is fixed; nothing to solve");
    if (amps__scene_factor(ctx, S, n) != AMPS_OK || amps__scene_workspace(ctx, S) != AMPS_OK) goto fail;
    S->ndof0 = n;
    /* forces and pins set before the factorization */
    for (v = 0; v < S->m->nnode; v++)
        for (k = 0; k < 3; k++)
            if (S->node.dof[3 * v + k] >= 0 && (S->node.force[3 * v + k] != 0.0 || S->dyn.g[k] != 0.0)) {
                amps_int i = S->node.dof[3 * v + k];
                double f = S->node.force[3 * v + k] + amps__scene_body_force(S, v, (int)k);
                if (amps_update_set_force(ctx, S->U, 1, &i, &f)) goto fail;
            }
    for (v = 0; v < S->m->nnode; v++)
        if (S->node.pinned[v] && amps_update_constrain(ctx, S->U, 3, S->node.dof + 3 * v, S->node.pin_value + 3 * v))
            goto fail;
    if (amps_update_commit(ctx, S->U)) goto fail;
    S->prepared = 1;
    return AMPS_OK;
fail:
    amps__scene_unprepare(ctx, S);
    return ctx && ctx->status ? ctx->status : AMPS_ERR_OOM;
}

/* Orphans (nodes left in no tet) keep their equations, held by their own rows rather than by
   constraints: the rows of K^ (zero up to rounding once the last tet is gone) get dyn.orphan_d
   on the diagonal, the right-hand side there is orphan_d u (statics) or 0 (dynamics: w = 0), and
   the scene keeps the displacement (statics) or a zero velocity (dynamics) whatever the solve
   returns there. As rows they are folded into the base by the next re-factorization and leave
   the augmentation; as constraints they would stay in its dense system for ever. */
static int amps__scene_orphan(const amps_scene *S, amps_int v) {
    return S->dyn.orphan && v < S->dyn.cap && S->dyn.orphan[v];
}

/* 1 if node v holds its piece in statics: fixed, or pinned and not an orphan. */
static int amps__scene_holds(const amps_scene *S, amps_int v) {
    return S->node.fixed[v] || (S->node.pinned[v] && !amps__scene_orphan(S, v));
}

static amps_status amps__scene_node(amps_ctx *ctx, amps_scene *S, amps_int v, const char *fn) {
    if (!S) return amps__err(ctx, AMPS_ERR_ARG, "%s: NULL scene", fn);
    if (v < 0 || v >= S->m->nnode)
        return amps__err(ctx, AMPS_ERR_INDEX, "%s: node %ld out of range [0, %ld)", fn, (long)v, (long)S->m->nnode);
    return AMPS_OK;
}

AMPS_API amps_status amps_scene_force(amps_ctx *ctx, amps_scene *S, amps_int v, const double f[3]) {
    amps_int k, idx[3], m = 0;
    double val[3];
    amps_status s;
    if (!f) return amps__err(ctx, AMPS_ERR_ARG, "amps_scene_force: NULL force");
    for (k = 0; k < 3; k++)
        if (!amps__isfinite(f[k]))
            return amps__err(ctx, AMPS_ERR_VALUE, "amps_scene_force: non-finite force on node %ld", (long)v);
    if ((s = amps__scene_node(ctx, S, v, "amps_scene_force")) != AMPS_OK) return s;
    for (k = 0; k < 3; k++)
        if (S->prepared && S->node.dof[3 * v + k] >= 0 && !amps__scene_orphan(S, v)) {
            idx[m] = S->node.dof[3 * v + k];
            val[m] = f[k] + amps__scene_body_force(S, v, (int)k);
            m++;
        }
    if (S->prepared && (s = amps_update_set_force(ctx, S->U, m, idx, val)) != AMPS_OK) return s;
    for (k = 0; k < 3; k++) S->node.force[3 * v + k] = f[k];
    return AMPS_OK;
}

static amps_status amps__scene_batch_room(amps_ctx *ctx, amps_scene *S, amps_int ni, amps_int nd);
static void amps__scene_batch_pin(amps_scene *S, int kind, amps_int v);

AMPS_API amps_status amps_scene_pin(amps_ctx *ctx, amps_scene *S, amps_int v, const double u[3]) {
    amps_int k, idx[3];
    amps_status s;
    if (!u) return amps__err(ctx, AMPS_ERR_ARG, "amps_scene_pin: NULL displacement");
    for (k = 0; k < 3; k++)
        if (!amps__isfinite(u[k]))
            return amps__err(ctx, AMPS_ERR_VALUE, "amps_scene_pin: non-finite displacement for node %ld", (long)v);
    if ((s = amps__scene_node(ctx, S, v, "amps_scene_pin")) != AMPS_OK) return s;
    if (S->node.fixed[v]) return amps__err(ctx, AMPS_ERR_ARG, "amps_scene_pin: node %ld is fixed", (long)v);
    if (S->batch.committing && !S->node.pinned[v])
        return amps__err(ctx, AMPS_ERR_STATE, "amps_scene_pin: node %ld: a new pin during a two-phase commit", (long)v);
    if (amps_mesh_degree(S->m, v) == 0)
        return amps__err(ctx, AMPS_ERR_ARG, "amps_scene_pin: node %ld belongs to no tetrahedron", (long)v);
    if (!S->prepared) {
        S->node.pinned[v] = 1;
        for (k = 0; k < 3; k++) S->node.pin_value[3 * v + k] = u[k];
        return AMPS_OK;
    }
    for (k = 0; k < 3; k++) idx[k] = S->node.dof[3 * v + k];
    if (S->batch.open && (s = amps__scene_batch_room(ctx, S, 0, 0)) != AMPS_OK) return s;
    if ((s = amps_update_constrain(ctx, S->U, 3, idx, u)) != AMPS_OK) return s;
    if (S->batch.open) amps__scene_batch_pin(S, 1, v);
    else if (!S->node.pinned[v] && (s = amps_update_commit(ctx, S->U)) != AMPS_OK) return s;
    S->node.pinned[v] = 1;
    for (k = 0; k < 3; k++) S->node.pin_value[3 * v + k] = u[k];
    return AMPS_OK;
}

static amps_status amps__scene_held_ws(amps_ctx *ctx, amps_scene *S);
static int amps__scene_piece_held(amps_scene *S, amps_int seed, amps_int *ntet, amps_int *ncon, amps_int *con);
static int amps__face_piece_loose(amps_scene *S, amps_int t0, amps_int g, amps_int *nvis, amps_int *ntet, amps_int *nj,
                                  amps_int *jn);

/* Statics: the piece of node v held without v's pin (amps__scene_piece_held), or
   AMPS_ERR_SINGULAR_UPDATE naming it. pinned[v] is kept. */
static amps_status amps__scene_release_held(amps_ctx *ctx, amps_scene *S, amps_int v) {
    amps_int ntet, ncon, con;
    unsigned char was = S->node.pinned[v];
    int held;
    amps_status s;
    if (S->dyn.on || S->m->inc_len[v] == 0) return AMPS_OK;
    if ((s = amps__scene_held_ws(ctx, S)) != AMPS_OK) return s;
    S->node.pinned[v] = 0;
    held = amps__scene_piece_held(S, v, &ntet, &ncon, &con);
    if (held) { /* the face-connected pieces of v's tets: none a hinge (as amps__mechanism) */
        amps_int k, nvis = 0, nj = 0, jn = -1, g = 0;
        for (k = 0; k < S->m->inc_len[v] && held; k++) {
            amps_int t = S->m->inc[S->m->inc_ptr[v] + k];
            if (S->mech.tet_piece[t] >= 0) continue;
            if (amps__face_piece_loose(S, t, g++, &nvis, &ntet, &nj, &jn)) held = 0;
        }
        for (k = 0; k < nvis; k++) S->mech.tet_piece[S->mech.visited[k]] = -1;
        if (!held) {
            S->node.pinned[v] = was;
            return amps__err(ctx, AMPS_ERR_SINGULAR_UPDATE,
                             "amps_scene_release: releasing node %ld leaves a piece of %ld tets joined to the rest at "
                             "%ld node%s on one line (node %ld) and not held otherwise: it could turn about that "
                             "line; the pin stays",
                             (long)v, (long)ntet, (long)nj, nj == 1 ? "" : "s", (long)jn);
        }
    }
    S->node.pinned[v] = was;
    if (held) return AMPS_OK;
    if (ncon == 0)
        return amps__err(ctx, AMPS_ERR_SINGULAR_UPDATE,
                         "amps_scene_release: releasing node %ld leaves its piece of %ld tets held by nothing; the pin "
                         "stays",
                         (long)v, (long)ntet);
    return amps__err(ctx, AMPS_ERR_SINGULAR_UPDATE,
                     "amps_scene_release: releasing node %ld leaves its piece of %ld tets held only at %ld constrained "
                     "node%s on one line (node %ld): it could turn about that line; the pin stays",
                     (long)v, (long)ntet, (long)ncon, ncon == 1 ? "" : "s", (long)con);
}

AMPS_API amps_status amps_scene_release(amps_ctx *ctx, amps_scene *S, amps_int v) {
    amps_int k, idx[3];
    amps_status s;
    if ((s = amps__scene_node(ctx, S, v, "amps_scene_release")) != AMPS_OK) return s;
    if (!S->node.pinned[v]) return AMPS_OK;
    if (!S->prepared) {
        S->node.pinned[v] = 0;
        return AMPS_OK;
    }
    if (!S->batch.open && (s = amps__scene_release_held(ctx, S, v)) != AMPS_OK) return s;
    for (k = 0; k < 3; k++) idx[k] = S->node.dof[3 * v + k];
    if (S->batch.open && (s = amps__scene_batch_room(ctx, S, 0, 0)) != AMPS_OK) return s;
    if ((s = amps_update_release(ctx, S->U, 3, idx)) != AMPS_OK) return s;
    if (S->batch.open) amps__scene_batch_pin(S, 2, v);
    else if ((s = amps_update_commit(ctx, S->U)) != AMPS_OK) {
        char msg[256];
        memcpy(msg, ctx ? ctx->msg : "", ctx ? sizeof(msg) : 1);
        return amps__err(ctx, s, "amps_scene_release: releasing node %ld leaves a piece held by nothing (%s)", (long)v,
                         msg);
    }
    S->node.pinned[v] = 0;
    return AMPS_OK;
}

/* ---- mechanism test of a cut ---- */

/* The tet other than t that holds the face of t opposite its q-th node, or -1. */
static amps_int amps__tet_face_nb(const amps_mesh *m, amps_int t, int q) {
    amps_int a = m->tet[4 * t + (q + 1) % 4], b = m->tet[4 * t + (q + 2) % 4], c = m->tet[4 * t + (q + 3) % 4], k;
    for (k = 0; k < m->inc_len[a]; k++) {
        amps_int o = m->inc[m->inc_ptr[a] + k], r;
        int hb = 0, hc = 0;
        if (o == t) continue;
        for (r = 0; r < 4; r++) {
            hb |= m->tet[4 * o + r] == b;
            hc |= m->tet[4 * o + r] == c;
        }
        if (hb && hc) return o;
    }
    return -1;
}

/* Points added one by one: are they all on one line? Points closer than tol count as one. */
typedef struct amps__line {
    int state;
    double p0[3], d[3], tol;
} amps__line; /* state: 0 none, 1 point, 2 line, 3 not on a line */
static void amps__line_add(amps__line *L, const double *p) {
    double w[3], c[3], len;
    int k;
    if (L->state == 3) return;
    if (L->state == 0) {
        for (k = 0; k < 3; k++) L->p0[k] = p[k];
        L->state = 1;
        return;
    }
    for (k = 0; k < 3; k++) w[k] = p[k] - L->p0[k];
    if (L->state == 1) {
        len = sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
        if (len > L->tol) {
            for (k = 0; k < 3; k++) L->d[k] = w[k] / len;
            L->state = 2;
        }
        return;
    }
    /* distance from the line: |w x d| */
    c[0] = w[1] * L->d[2] - w[2] * L->d[1];
    c[1] = w[2] * L->d[0] - w[0] * L->d[2];
    c[2] = w[0] * L->d[1] - w[1] * L->d[0];
    if (sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]) > L->tol) L->state = 3;
}

static amps_int amps__gfind(amps_int *par, amps_int g) {
    while (par[g] != g) {
        par[g] = par[par[g]];
        g = par[g];
    }
    return g;
}

/* Is the face-connected piece X (root g; its tets among tvis[0:nvis]) joined to the rest at
   nodes on one line, and then is X or the rest not held off that line by constrained (fixed or
   pinned) nodes? A face-connected piece is rigid; two rigid pieces sharing three nodes not on
   one line move together, otherwise one turns about that line (or falls off) at zero energy.
   *nj and *jn receive the number of joint nodes and one of them (-1 when none). */
static int amps__piece_loose(amps_scene *S, amps_int g, amps_int nvis, amps_int *nj, amps_int *jn) {
    const amps_mesh *m = S->m;
    amps_marker *seen = &S->mech.node_seen;
    amps__line J, JX, JR;
    amps_int k, n;
    int q;
    J.state = 0;
    J.tol = 1e-9 * S->mech.scale;
    JX = J;
    JR = J;
    *nj = 0;
    *jn = -1;
    amps_marker_next(&S->mech.node_seen);
    for (k = 0; k < nvis; k++) {
        amps_int t = S->mech.visited[k];
        if (amps__gfind(S->mech.piece_parent, S->mech.tet_piece[t]) != g) continue;
        for (q = 0; q < 4; q++) {
            amps_int v = m->tet[4 * t + q], r;
            int joint = 0;
            if (seen->mark[v] == seen->stamp) continue;
            seen->mark[v] = seen->stamp;
            for (r = 0; r < m->inc_len[v] && !joint; r++) {
                amps_int o = m->inc[m->inc_ptr[v] + r];
                joint = S->mech.tet_piece[o] < 0 || amps__gfind(S->mech.piece_parent, S->mech.tet_piece[o]) != g;
            }
            if (joint) {
                amps__line_add(&J, m->xyz + 3 * v);
                (*nj)++;
                *jn = v;
            }
            if (joint || S->node.fixed[v] || S->node.pinned[v]) amps__line_add(&JX, m->xyz + 3 * v);
        }
    }
    if (J.state == 3) return 0; /* a rigid joint */
    /* the rest: the joint and the constrained nodes outside X */
    JR = J;
    for (n = 0; n < m->nnode && JR.state != 3; n++)
        if ((S->node.fixed[n] || S->node.pinned[n]) && seen->mark[n] != seen->stamp)
            amps__line_add(&JR, m->xyz + 3 * n);
    return JX.state != 3 || JR.state != 3;
}

/* Face-connected piece g (its tets so far labelled g among visited[0:*nvis], more queued from
   mech.queue_head[g]) grown face by face until it holds three constrained nodes off one line
   (held: returns 0), or to its end; then 1 when it is loose (amps__piece_loose; *ntet, *nj, *jn
   as amps__mechanism). Its labels stay in mech.tet_piece (visited); the caller clears them. */
static int amps__piece_grow_loose(amps_scene *S, amps_int g, amps_int *nvis, amps_int *ntet, amps_int *nj,
                                  amps_int *jn) {
    const amps_mesh *m = S->m;
    amps_int k, t, c = 0;
    amps__line L;
    int q;
    L.state = 0;
    L.tol = 1e-9 * S->mech.scale;
    for (k = 0; k < *nvis && L.state != 3; k++) /* its constrained nodes so far */
        if (amps__gfind(S->mech.piece_parent, S->mech.tet_piece[S->mech.visited[k]]) == g)
            for (q = 0; q < 4; q++) {
                amps_int v = m->tet[4 * S->mech.visited[k] + q];
                if (amps__scene_holds(S, v)) amps__line_add(&L, m->xyz + 3 * v);
            }
    while ((t = S->mech.queue_head[g]) >= 0 && L.state != 3) {
        S->mech.queue_head[g] = S->mech.tet_next[t];
        for (q = 0; q < 4; q++) {
            amps_int o = amps__tet_face_nb(m, t, q), v = m->tet[4 * t + q];
            if (amps__scene_holds(S, v)) amps__line_add(&L, m->xyz + 3 * v);
            if (o < 0 || S->mech.tet_piece[o] >= 0) continue;
            S->mech.tet_piece[o] = g;
            S->mech.tet_next[o] = -1;
            S->mech.visited[(*nvis)++] = o;
            if (S->mech.queue_head[g] >= 0) S->mech.tet_next[S->mech.queue_tail[g]] = o;
            else S->mech.queue_head[g] = o;
            S->mech.queue_tail[g] = o;
        }
    }
    if (L.state == 3 || !amps__piece_loose(S, g, *nvis, nj, jn)) return 0;
    for (k = 0; k < *nvis; k++) c += amps__gfind(S->mech.piece_parent, S->mech.tet_piece[S->mech.visited[k]]) == g;
    *ntet = c;
    return 1;
}

/* The piece still growing when amps__mechanism's others finished (a change that splits the model:
   it need not be the held rest), tested by amps__piece_grow_loose. */
static int amps__mechanism_rest(amps_scene *S, amps_int ng, amps_int *nvis, amps_int *ntet, amps_int *nj,
                                amps_int *jn) {
    amps_int g;
    for (g = 0; g < ng && !S->mech.active[g]; g++) {}
    return g < ng && amps__piece_grow_loose(S, g, nvis, ntet, nj, jn);
}

/* After a cut (of v into v and vc) or a removal: explores the face-connected pieces that hold
   the tets of nodes[0..nn-1] together, one tet per piece per round, merging pieces that meet,
   until one piece is left unfinished (the rest of the model). Cost: about (number of pieces) x
   (tets of the pieces that finish), so a change that separates nothing stops as soon as the
   pieces around it meet. The tets of the nodes must number at most mech.npiece. Returns 1 if a
   finished piece is loose (amps__piece_loose); *ntet, *nj, *jn describe it. */
static int amps__mechanism(amps_scene *S, const amps_int *nodes, amps_int nn, amps_int *ntet, amps_int *nj,
                           amps_int *jn) {
    const amps_mesh *m = S->m;
    amps_int ng = 0, nact, nvis = 0, k, g, loose = 0, w, nfin = 0;
    for (w = 0; w < nn; w++)
        for (k = 0; k < m->inc_len[nodes[w]] && ng < S->mech.npiece; k++) {
            amps_int t = m->inc[m->inc_ptr[nodes[w]] + k];
            if (S->mech.tet_piece[t] >= 0) continue;
            S->mech.piece_parent[ng] = ng;
            S->mech.queue_head[ng] = t;
            S->mech.queue_tail[ng] = t;
            S->mech.active[ng] = 1;
            S->mech.tet_piece[t] = ng;
            S->mech.tet_next[t] = -1;
            S->mech.visited[nvis++] = t;
            ng++;
        }
    nact = ng;
    while (nact > 1 && !loose) {
        for (g = 0; g < ng && nact > 1 && !loose; g++) {
            amps_int t;
            int q;
            if (!S->mech.active[g]) continue;
            t = S->mech.queue_head[g];
            if (t < 0) { /* piece g is finished */
                amps_int c = 0;
                S->mech.active[g] = 0;
                nact--;
                nfin++;
                if (amps__piece_loose(S, g, nvis, nj, jn)) {
                    for (k = 0; k < nvis; k++)
                        c += amps__gfind(S->mech.piece_parent, S->mech.tet_piece[S->mech.visited[k]]) == g;
                    *ntet = c;
                    loose = 1;
                }
                continue;
            }
            S->mech.queue_head[g] = S->mech.tet_next[t];
            if (S->mech.queue_head[g] < 0) S->mech.queue_tail[g] = -1;
            for (q = 0; q < 4; q++) {
                amps_int o = amps__tet_face_nb(m, t, q), h;
                if (o < 0) continue;
                if (S->mech.tet_piece[o] < 0) { /* a new tet of piece g */
                    S->mech.tet_piece[o] = g;
                    S->mech.tet_next[o] = -1;
                    S->mech.visited[nvis++] = o;
                    if (S->mech.queue_tail[g] >= 0) S->mech.tet_next[S->mech.queue_tail[g]] = o;
                    else S->mech.queue_head[g] = o;
                    S->mech.queue_tail[g] = o;
                    continue;
                }
                h = amps__gfind(S->mech.piece_parent, S->mech.tet_piece[o]);
                if (h == g) continue;
                /* pieces g and h meet: h joins g with its queue */
                S->mech.piece_parent[h] = g;
                if (S->mech.queue_head[h] >= 0) {
                    if (S->mech.queue_tail[g] >= 0) S->mech.tet_next[S->mech.queue_tail[g]] = S->mech.queue_head[h];
                    else S->mech.queue_head[g] = S->mech.queue_head[h];
                    S->mech.queue_tail[g] = S->mech.queue_tail[h];
                }
                if (S->mech.active[h]) {
                    S->mech.active[h] = 0;
                    nact--;
                }
            }
        }
    }
    if (!loose && nact == 1 && nfin > 0) /* the change split the model: the rest may be the loose part */
        loose = amps__mechanism_rest(S, ng, &nvis, ntet, nj, jn);
    for (k = 0; k < nvis; k++) S->mech.tet_piece[S->mech.visited[k]] = -1;
    return loose;
}

/* Room for one more node and, when v is watched (*watched), for its copy in the watch set. */
static amps_status amps__scene_cut_room(amps_ctx *ctx, amps_scene *S, amps_int v, int *watched) {
    amps_int k;
    if (S->m->nnode + 1 > S->node.cap) {
        if (!S->opts.update.grow)
            return amps__err(ctx, AMPS_ERR_CAPACITY, "amps_scene_cut: node capacity %ld reached", (long)S->node.cap);
        if (amps__scene_grow(ctx, S, 2 * S->node.cap + 16)) return AMPS_ERR_OOM;
    }
    for (k = 0; k < S->watch.n && S->watch.nodes[k] != v; k++) {}
    *watched = k < S->watch.n;
    if (*watched && S->watch.n == S->watch.cap) {
        if (amps__realloc(ctx, (void **)&S->watch.nodes, (size_t)S->watch.cap * 2 + 8, sizeof(amps_int)))
            return amps__err(ctx, AMPS_ERR_OOM, "amps_scene_cut: out of memory");
        S->watch.cap = S->watch.cap * 2 + 8;
    }
    return AMPS_OK;
}

/* A cut before the factorization is topology only: K is assembled from the cut mesh. */
static amps_status amps__scene_cut_topology(amps_ctx *ctx, amps_scene *S, amps_int v, const double p[3],
                                            const double nrm[3], amps_int *vc) {
    amps_int k, nmoved = 0, deg = amps_mesh_degree(S->m, v);
    amps_int *mv = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)deg + 1, sizeof(amps_int)));
    amps_status s;
    if (!mv) return AMPS_ERR_OOM;
    s = amps_mesh_cut(ctx, S->m, v, p, nrm, vc, mv, &nmoved);
    amps__free(ctx, mv);
    if (s != AMPS_OK) return s;
    S->node.fixed[*vc] = S->node.fixed[v];
    for (k = 0; k < 3; k++) S->node.disp[3 * *vc + k] = S->node.disp[3 * v + k];
    return AMPS_OK;
}

/* Statics, a release of v (pinned[v] already 0): the face-connected piece of tet t0 (unlabelled)
   as piece g, tested by amps__piece_grow_loose (1: loose). */
static int amps__face_piece_loose(amps_scene *S, amps_int t0, amps_int g, amps_int *nvis, amps_int *ntet, amps_int *nj,
                                  amps_int *jn) {
    S->mech.piece_parent[g] = g;
    S->mech.tet_piece[t0] = g;
    S->mech.tet_next[t0] = -1;
    S->mech.queue_head[g] = S->mech.queue_tail[g] = t0;
    S->mech.visited[(*nvis)++] = t0;
    return amps__piece_grow_loose(S, g, nvis, ntet, nj, jn);
}

/* The mechanism test of the cut of v into v and vc: AMPS_ERR_SINGULAR_UPDATE with the loose piece
   described, or AMPS_OK. */
static amps_status amps__scene_cut_held(amps_ctx *ctx, amps_scene *S, amps_int v, amps_int vc) {
    amps_int nt = 0, nj = 0, jn = -1, nodes[2];
    nodes[0] = v;
    nodes[1] = vc;
    if (!amps__mechanism(S, nodes, 2, &nt, &nj, &jn)) return AMPS_OK;
    if (nj == 0)
        return amps__err(ctx, AMPS_ERR_SINGULAR_UPDATE,
                         "amps_scene_cut: the cut at node %ld detaches a piece of %ld tets held by nothing; "
                         "the cut was undone",
                         (long)v, (long)nt);
    return amps__err(
            ctx, AMPS_ERR_SINGULAR_UPDATE,
            "amps_scene_cut: the cut at node %ld leaves a piece of %ld tets joined to the rest at %ld node%s on "
            "one line (node %ld) and not held otherwise: it could turn about that line; the cut was undone",
            (long)v, (long)nt, (long)nj, nj == 1 ? "" : "s", (long)jn);
}

/* cut.local_dof = the equations of the nodes of the moved tets, with v's for each DOF of vc;
   returns their number nl. */
static amps_int amps__cut_local_dofs(amps_scene *S, amps_int v, amps_int vc, amps_int nmoved) {
    const amps_mesh *m = S->m;
    amps_int *ld = S->cut.local_dof, nl = 0, k, t;
    int q, d;
    for (k = 0; k < nmoved; k++)
        for (q = 0; q < 4; q++) {
            amps_int node = m->tet[4 * S->cut.moved[k] + q];
            for (d = 0; d < 3; d++) {
                amps_int e = S->node.dof[3 * node + d], e2 = S->node.dof[3 * v + d];
                if (e < 0) continue;
                for (t = 0; t < nl && ld[t] != e; t++) {}
                if (t == nl) ld[nl++] = e;
                if (node != vc) continue;
                for (t = 0; t < nl && ld[t] != e2; t++) {}
                if (t == nl && e2 >= 0) ld[nl++] = e2;
            }
        }
    return nl;
}

/* cut.local_K (nl x nl over cut.local_dof) = sum over the moved tets of Ae (amps__scene_tet_matrix)
   scattered with vc minus Ae scattered with v: the change of the system matrix the cut makes. */
static void amps__cut_local_K(amps_scene *S, amps_int v, amps_int vc, amps_int nmoved, amps_int nl) {
    const amps_mesh *m = S->m;
    const amps_int *ld = S->cut.local_dof;
    double *lk = S->cut.local_K;
    amps_int k, a, b, t;
    for (a = 0; a < nl * nl; a++) lk[a] = 0.0;
    for (k = 0; k < nmoved; k++) {
        double Ke[144];
        amps_int loc_new[12], loc_old[12];
        int q, d, pass;
        amps__scene_tet_matrix(S, S->cut.moved[k], Ke);
        for (q = 0; q < 4; q++) {
            amps_int node = m->tet[4 * S->cut.moved[k] + q];
            for (d = 0; d < 3; d++) {
                amps_int en = S->node.dof[3 * node + d], eo = node == vc ? S->node.dof[3 * v + d] : en;
                loc_new[3 * q + d] = -1;
                loc_old[3 * q + d] = -1;
                for (t = 0; t < nl; t++) {
                    if (ld[t] == en) loc_new[3 * q + d] = t;
                    if (ld[t] == eo) loc_old[3 * q + d] = t;
                }
                if (en < 0) loc_new[3 * q + d] = -1;
                if (eo < 0) loc_old[3 * q + d] = -1;
            }
        }
        for (pass = 0; pass < 2; pass++) {
            const amps_int *loc = pass ? loc_new : loc_old;
            double sg = pass ? 1.0 : -1.0;
            for (a = 0; a < 12; a++) {
                if (loc[a] < 0) continue;
                for (b = 0; b < 12; b++)
                    if (loc[b] >= 0) lk[loc[a] * nl + loc[b]] += sg * Ke[12 * a + b];
            }
        }
    }
}

static void amps__scene_batch_cut(amps_scene *S, amps_int v, amps_int vc, amps_int nmoved);
static void amps__scene_batch_undo(amps_scene *S);
static void amps__scene_batch_abort(amps_scene *S);

/* A cut of the factored model: the mesh cut, the mechanism test, new equations for the copy,
   the change of K^ on the moved tets' equations, one commit (in a batch: recorded). On failure
   the cut is undone. */
static amps_status amps__scene_cut_update(amps_ctx *ctx, amps_scene *S, amps_int v, const double p[3],
                                          const double nrm[3], amps_int *vcp) {
    amps_int vc, nmoved = 0, k, nl, nz = 0, first = -1, a, b;
    amps_status s = amps_mesh_cut(ctx, S->m, v, p, nrm, &vc, S->cut.moved, &nmoved);
    if (s != AMPS_OK) return s; /* includes the no-op */
    S->node.fixed[vc] = S->node.fixed[v];
    S->node.pinned[vc] = 0;
    for (k = 0; k < 3; k++) {
        S->node.pin_value[3 * vc + k] = 0;
        S->node.force[3 * vc + k] = 0;
        S->node.disp[3 * vc + k] = S->node.disp[3 * v + k];
        S->node.dof[3 * vc + k] = -1;
    }
    if (!S->dyn.on && (s = amps__scene_cut_held(ctx, S, v, vc)) != AMPS_OK) goto undo; /* dynamics: mass holds */
    if (!S->node.fixed[v] && S->node.dof[3 * v] >= 0) {
        if ((s = amps_update_add_dofs(ctx, S->U, 3, &first)) != AMPS_OK) goto undo_engine;
        for (k = 0; k < 3; k++) S->node.dof[3 * vc + k] = first + k;
        (void)amps_update_set_origin(ctx, S->U, 3, S->node.dof + 3 * vc, S->node.dof + 3 * v); /* ordering hint */
    }
    nl = amps__cut_local_dofs(S, v, vc, nmoved);
    amps__cut_local_K(S, v, vc, nmoved, nl);
    for (a = 0; a < nl; a++) /* its upper triangle */
        for (b = a; b < nl; b++) {
            double val = S->cut.local_K[a * nl + b];
            if (val == 0.0) continue;
            S->cut.row[nz] = S->cut.local_dof[a];
            S->cut.col[nz] = S->cut.local_dof[b];
            S->cut.val[nz] = val;
            nz++;
        }
    if ((s = amps_update_add(ctx, S->U, nz, S->cut.row, S->cut.col, S->cut.val)) != AMPS_OK) goto undo_engine;
    if (S->batch.open) amps__scene_batch_cut(S, v, vc, nmoved);
    else if ((s = amps_update_commit(ctx, S->U)) != AMPS_OK) {
        if (s == AMPS_ERR_SINGULAR_UPDATE)
            amps__err(ctx, s, "amps_scene_cut: the cut at node %ld leaves a piece held by nothing; the cut was undone",
                      (long)v);
        goto undo;
    }
    *vcp = vc;
    return AMPS_OK;
undo_engine:
    amps_update_discard(S->U);
undo:
    for (k = 0; k < 3; k++) S->node.dof[3 * vc + k] = -1;
    S->node.fixed[vc] = 0;
    {
        amps_ctx c2;
        amps_ctx_init(&c2);
        (void)amps_mesh_uncut(&c2, S->m, v, vc, S->cut.moved, nmoved);
    }
    if (S->batch.open && s != AMPS_ERR_SINGULAR_UPDATE) amps__scene_batch_undo(S); /* the engine discarded it */
    return s;
}

static amps_status amps__scene_batch_room(amps_ctx *ctx, amps_scene *S, amps_int ni, amps_int nd);
static amps_status amps__scene_batch_failed(amps_scene *S, amps_status s);

/* The refusal of a call that must wait for the end of a two-phase commit. */
static amps_status amps__scene_committing(amps_ctx *ctx, const char *fn) {
    return amps__err(ctx, AMPS_ERR_STATE, "%s: a two-phase commit is in progress", fn);
}

AMPS_API amps_status amps_scene_cut(amps_ctx *ctx, amps_scene *S, amps_int v, const double p[3], const double nrm[3],
                                    amps_int *new_node) {
    amps_int vc = -1;
    amps_status s;
    int watched;
    if (new_node) *new_node = -1;
    if ((s = amps__scene_node(ctx, S, v, "amps_scene_cut")) != AMPS_OK) return s;
    if (S->batch.committing) return amps__scene_committing(ctx, "amps_scene_cut");
    if (S->prepared && !S->batch.open && (s = amps_update_commit(ctx, S->U)) != AMPS_OK)
        return s; /* earlier changes first */
    if ((s = amps__scene_cut_room(ctx, S, v, &watched)) != AMPS_OK ||
        (S->batch.open && (s = amps__scene_batch_room(ctx, S, amps_mesh_degree(S->m, v), 0)) != AMPS_OK) ||
        (s = amps__scene_dyn_room(ctx, S, S->m->nnode + 1)) != AMPS_OK) {
        if (S->batch.open) amps__scene_batch_abort(S); /* as documented for a batch's cut */
        return s;
    }
    s = S->prepared ? amps__scene_cut_update(ctx, S, v, p, nrm, &vc) : amps__scene_cut_topology(ctx, S, v, p, nrm, &vc);
    if (s != AMPS_OK) return amps__scene_batch_failed(S, s);
    amps__scene_cut_recorded(ctx, S, v, vc);
    amps__scene_dyn_cut(ctx, S, v, vc);
    if (new_node) *new_node = vc;
    if (watched) {
        S->watch.nodes[S->watch.n++] = vc;
        S->watch.stale = 1;
        if (S->batch.open) S->batch.ops[S->batch.n - 1].watched = 1;
    }
    return AMPS_OK;
}

static void amps__scene_gather(amps_scene *S, amps_int nv, const amps_int *nodes);

/* The preamble of the static solves (fn names the caller in messages): S is static, prepared
   (amps_scene_prepare on the first call) and its open batch committed; with watch, the engine's
   watch set follows a stale scene watch set (the equations of the watched nodes; allocates 3 nv
   indices for the call). */
static amps_status amps__scene_ready(amps_ctx *ctx, amps_scene *S, const char *fn, int watch) {
    amps_status s;
    if (!S) return amps__err(ctx, AMPS_ERR_ARG, "%s: NULL scene", fn);
    if (S->dyn.on) return amps__err(ctx, AMPS_ERR_STATE, "%s: the scene is dynamic (use amps_scene_step)", fn);
    if (!S->prepared && (s = amps_scene_prepare(ctx, S)) != AMPS_OK) return s;
    if (S->batch.open && (s = amps_scene_commit(ctx, S)) != AMPS_OK) return s;
    if (watch && S->watch.stale) {
        amps_int k, d, m = 0,
                       *idx = AMPS__CAST(amps_int *, amps__malloc(ctx, 3 * (size_t)(S->watch.n > 0 ? S->watch.n : 1),
                                                                  sizeof(amps_int)));
        if (!idx) return amps__err(ctx, AMPS_ERR_OOM, "%s: out of memory", fn);
        for (k = 0; k < S->watch.n; k++)
            for (d = 0; d < 3; d++) {
                amps_int e = S->node.dof[3 * S->watch.nodes[k] + d];
                if (e >= 0) idx[m++] = e;
            }
        s = amps_update_watch(ctx, S->U, m, idx);
        amps__free(ctx, idx);
        if (s != AMPS_OK) return s;
        S->watch.stale = 0;
    }
    return AMPS_OK;
}

AMPS_API amps_status amps_scene_solve(amps_ctx *ctx, amps_scene *S) {
    amps_status s;
    if ((s = amps__scene_ready(ctx, S, "amps_scene_solve", 0)) != AMPS_OK) return s;
    if ((s = amps_update_solve(ctx, S->U, NULL)) < 0) return s;
    amps__scene_gather(S, 0, NULL);
    return s; /* AMPS_WARN_INACCURATE: solved all the same */
}

AMPS_API amps_status amps_scene_watch(amps_ctx *ctx, amps_scene *S, amps_int nv, const amps_int *nodes) {
    amps_int k;
    if (!S || nv < 0 || (nv > 0 && !nodes)) return amps__err(ctx, AMPS_ERR_ARG, "amps_scene_watch: bad arguments");
    for (k = 0; k < nv; k++)
        if (nodes[k] < 0 || nodes[k] >= S->m->nnode)
            return amps__err(ctx, AMPS_ERR_INDEX, "amps_scene_watch: node %ld out of range [0, %ld)", (long)nodes[k],
                             (long)S->m->nnode);
    if (nv > S->watch.cap) {
        amps_int *w = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)nv, sizeof(amps_int)));
        if (!w) return amps__err(ctx, AMPS_ERR_OOM, "amps_scene_watch: out of memory");
        amps__free(ctx, S->watch.nodes);
        S->watch.nodes = w;
        S->watch.cap = nv;
    }
    for (k = 0; k < nv; k++) S->watch.nodes[k] = nodes[k];
    amps__sort(S->watch.nodes, (size_t)nv, sizeof(amps_int), amps__int_cmp);
    for (S->watch.n = 0, k = 0; k < nv; k++) /* ascending, each once */
        if (k == 0 || S->watch.nodes[k] != S->watch.nodes[k - 1]) S->watch.nodes[S->watch.n++] = S->watch.nodes[k];
    S->watch.stale = 1;
    return AMPS_OK;
}

/* Copies the engine's solution into the displacements of nodes[0..nv-1] (all nodes if NULL). */
static void amps__scene_gather(amps_scene *S, amps_int nv, const amps_int *nodes) {
    const double *x = amps_update_solution(S->U);
    amps_int k, d;
    if (!nodes) nv = S->m->nnode;
    for (k = 0; k < nv; k++) {
        amps_int v = nodes ? nodes[k] : k;
        if (amps__scene_orphan(S, v)) continue; /* held where it is */
        for (d = 0; d < 3; d++) {
            amps_int e = S->node.dof[3 * v + d];
            S->node.disp[3 * v + d] = e >= 0 ? x[e] : 0.0;
        }
    }
}

AMPS_API amps_status amps_scene_solve_watched(amps_ctx *ctx, amps_scene *S) {
    amps_status s;
    if ((s = amps__scene_ready(ctx, S, "amps_scene_solve_watched", 1)) != AMPS_OK) return s;
    if ((s = amps_update_solve_watched(ctx, S->U, NULL)) < 0) return s;
    amps__scene_gather(S, S->watch.n, S->watch.nodes);
    return s;
}

static amps_status amps__scene_corot_haptic(amps_ctx *ctx, amps_scene *S);
static void amps__cr_haptic_rotate(const amps_scene *S, amps_haptic *h);

AMPS_API amps_status amps_scene_solve_reactions(amps_ctx *ctx, amps_scene *S) {
    amps_status s;
    if (!S) return amps__err(ctx, AMPS_ERR_ARG, "amps_scene_solve_reactions: NULL scene");
    if (S->batch.committing && S->dyn.on) return amps__scene_committing(ctx, "amps_scene_solve_reactions (dynamics)");
    if (!S->prepared && (s = amps_scene_prepare(ctx, S)) != AMPS_OK) return s;
    if (S->batch.open && (s = amps_scene_commit(ctx, S)) != AMPS_OK) return s;
    if (S->dyn.corot) return amps__scene_corot_haptic(ctx, S);
    if (S->dyn.on && (s = amps__scene_dyn_load(ctx, S)) != AMPS_OK) return s;
    return amps_update_solve_reactions(ctx, S->U);
}

AMPS_API const double *amps_scene_displacements(const amps_scene *S) { return S ? S->node.disp : NULL; }

AMPS_API amps_status amps_scene_positions(amps_ctx *ctx, const amps_scene *S, amps_int n, const amps_int *nodes,
                                          double *out) {
    amps_int k, d;
    if (!S || !out) return amps__err(ctx, AMPS_ERR_ARG, "amps_scene_positions: NULL argument");
    if (!nodes) n = S->m->nnode;
    for (k = 0; k < n; k++) {
        amps_int v = nodes ? nodes[k] : k;
        if (v < 0 || v >= S->m->nnode)
            return amps__err(ctx, AMPS_ERR_INDEX, "amps_scene_positions: node %ld out of range", (long)v);
        for (d = 0; d < 3; d++) out[3 * k + d] = S->m->xyz[3 * v + d] + S->node.disp[3 * v + d];
    }
    return AMPS_OK;
}

AMPS_API amps_status amps_scene_reaction(amps_ctx *ctx, const amps_scene *S, amps_int v, double r[3]) {
    int k;
    if (!S || !r) return amps__err(ctx, AMPS_ERR_ARG, "amps_scene_reaction: NULL argument");
    if (v < 0 || v >= S->m->nnode)
        return amps__err(ctx, AMPS_ERR_INDEX, "amps_scene_reaction: node %ld out of range", (long)v);
    for (k = 0; k < 3; k++)
        r[k] = (S->U && S->node.pinned[v]) ? amps_update_reaction(S->U, S->node.dof[3 * v + k]) : 0.0;
    if (S->dyn.corot) {
        for (k = 0; k < 3; k++) r[k] = S->node.pinned[v] && v < S->dyn.cr_cap ? S->dyn.cr_react[3 * v + k] : 0.0;
        return AMPS_OK;
    }
    if (S->dyn.on)
        for (k = 0; k < 3; k++) r[k] /= S->dyn.dt; /* (A w+ - b)_P / dt */
    return AMPS_OK;
}

AMPS_API void amps_haptic_init(amps_haptic *h) {
    if (h) memset(h, 0, sizeof(*h));
}

AMPS_API void amps_haptic_free(amps_ctx *ctx, amps_haptic *h) {
    if (!h) return;
    amps__free(ctx, h->node);
    amps__free(ctx, h->eq);
    amps__free(ctx, h->g0);
    amps__free(ctx, h->r0);
    amps__free(ctx, h->H);
    amps_haptic_init(h);
}

/* H[:, j] = d react_P / d g_j for the engine's committed dense system (m pinned indices idx,
   -1: none), column major with leading dimension m: per column the dense step with r = 0 and
   g = e_j on C, then the reactions (Delta y)_P - w_P (amps__small_reactions). Primal form: the
   columns in blocks that share each pass over the LU factor (b_j = -e_j - G Delta[:, j],
   z_j = A^{-1} b_j, y_j = (z_j on F', e_j on C), w_j = z_j on C), the blocks in work.resid. */
static void amps__pin_schur(amps_update *U, amps_int m, const amps_int *idx, double *H) {
    amps_int u = U->aug.size, a, b, i, j, k, q, rr, j0, nbmax;
    size_t ld = (size_t)U->aug.cap, su = (size_t)u;
    for (k = 0; k < m * m; k++) H[k] = 0.0;
    if (U->form == AMPS_FORM_PRIMAL && u > 0) {
        double *Z = U->work.resid, *T;
        nbmax = U->cap_N / u < 16 ? U->cap_N / u : 16; /* 2 u nb <= 2 cap_N */
        T = Z + su * (size_t)nbmax;
        for (j0 = 0; j0 < m; j0 += nbmax) {
            amps_int nb = m - j0 < nbmax ? m - j0 : nbmax, pj[16];
            for (k = 0; k < nb; k++) {
                amps_int p = idx[j0 + k] >= 0 ? U->aug.pos[idx[j0 + k]] : -1;
                pj[k] = p >= 0 && (U->aug.kind[p] & AMPS__UCON) ? p : -1;
                for (a = 0; a < u; a++) Z[(size_t)k * su + (size_t)a] = 0.0;
                if (pj[k] >= 0) Z[(size_t)k * su + (size_t)pj[k]] = -1.0;
            }
            for (a = 0; a < u; a++) /* b -= G[:, a] Delta[a, p_j] over the free rows a */
                if (!(U->aug.kind[a] & AMPS__UCON))
                    for (i = 0; i < U->delta.row_len[a]; i++) {
                        amps_int c = U->delta.col[U->delta.row_start[a] + i];
                        double dv = U->delta.val[U->delta.row_start[a] + i];
                        if (!(U->aug.kind[c] & AMPS__UCON) || dv == 0.0) continue;
                        for (k = 0; k < nb; k++)
                            if (pj[k] == c) {
                                const double *ga = U->lu.G + (size_t)a * ld;
                                double *zk = Z + (size_t)k * su;
                                for (b = 0; b < u; b++) zk[b] -= ga[b] * dv;
                            }
                    }
            for (k = 0; k < nb; k++) /* t = P b */
                for (rr = 0; rr < u; rr++)
                    T[(size_t)k * su + (size_t)rr] = Z[(size_t)k * su + (size_t)U->lu.row_perm[rr]];
            for (q = 0; q < u; q++) { /* L */
                const double *l = U->lu.LU + (size_t)q * ld;
                for (k = 0; k < nb; k++) {
                    double *t = T + (size_t)k * su, x = t[q];
                    if (x != 0.0)
                        for (rr = q + 1; rr < u; rr++) t[rr] -= l[rr] * x;
                }
            }
            for (q = u - 1; q >= 0; q--) { /* U */
                const double *col = U->lu.LU + (size_t)q * ld;
                for (k = 0; k < nb; k++) {
                    double *t = T + (size_t)k * su, x = t[q] / col[q];
                    t[q] = x;
                    if (x != 0.0)
                        for (rr = 0; rr < q; rr++) t[rr] -= col[rr] * x;
                }
            }
            for (k = 0; k < nb; k++) {
                double *zk = Z + (size_t)k * su;
                if (pj[k] < 0) continue;
                for (q = 0; q < u; q++) zk[U->lu.col_order[q]] = T[(size_t)k * su + (size_t)q];
                for (i = 0; i < m; i++) {
                    amps_int pi = idx[i] >= 0 ? U->aug.pos[idx[i]] : -1;
                    double sum = 0;
                    if (pi < 0 || !(U->aug.kind[pi] & AMPS__UCON)) continue;
                    for (a = 0; a < U->delta.row_len[pi]; a++) {
                        amps_int c = U->delta.col[U->delta.row_start[pi] + a];
                        double yc = (U->aug.kind[c] & AMPS__UCON) ? (c == pj[k] ? 1.0 : 0.0) : zk[c];
                        sum += U->delta.val[U->delta.row_start[pi] + a] * yc;
                    }
                    H[(size_t)(j0 + k) * (size_t)m + (size_t)i] = sum - zk[pi];
                }
            }
        }
        return;
    }
    {
        double *r = U->dense.r_corr, *gv = U->dense.rho, *yv = U->dense.y_corr, *wv = U->dense.w_corr;
        for (a = 0; a < u; a++) r[a] = gv[a] = 0.0;
        for (j = 0; j < m; j++) {
            amps_int pj = idx[j] >= 0 ? U->aug.pos[idx[j]] : -1;
            if (pj < 0 || !(U->aug.kind[pj] & AMPS__UCON)) continue;
            gv[pj] = 1.0;
            amps__dense_step_g(U, r, gv, yv, wv);
            gv[pj] = 0.0;
            if (U->form == AMPS_FORM_DUAL)
                for (a = 0; a < u; a++) {
                    double sum = 0;
                    if (U->aug.kind[a] & AMPS__UCON) continue;
                    for (b = 0; b < u; b++) sum -= U->lu.G[(size_t)b * ld + (size_t)a] * wv[b];
                    yv[a] = sum;
                }
            for (i = 0; i < m; i++) {
                amps_int pi = idx[i] >= 0 ? U->aug.pos[idx[i]] : -1;
                double sum = 0;
                if (pi < 0 || !(U->aug.kind[pi] & AMPS__UCON)) continue;
                for (k = 0; k < U->delta.row_len[pi]; k++)
                    sum += U->delta.val[U->delta.row_start[pi] + k] * yv[U->delta.col[U->delta.row_start[pi] + k]];
                H[(size_t)j * (size_t)m + (size_t)i] = sum - wv[pi];
            }
        }
    }
}

AMPS_API amps_status amps_scene_haptic_build(amps_ctx *ctx, amps_scene *S, amps_haptic *h) {
    amps_int nn, v, n = 0, k, m, *idx;
    amps_status s;
    double sc;
    if (!S || !h) return amps__err(ctx, AMPS_ERR_ARG, "amps_scene_haptic_build: NULL argument");
    if (S->batch.committing)
        return amps__err(ctx, AMPS_ERR_STATE, "amps_scene_haptic_build: a two-phase commit is in progress");
    if ((s = amps_scene_solve_reactions(ctx, S)) < 0) return s;
    nn = S->m->nnode;
    for (v = 0; v < nn; v++) n += S->node.pinned[v] != 0;
    if (n > h->cap) {
        size_t c = (size_t)n;
        amps_int *nd = AMPS__CAST(amps_int *, amps__malloc(ctx, c, sizeof(amps_int)));
        amps_int *eq = AMPS__CAST(amps_int *, amps__malloc(ctx, 3 * c, sizeof(amps_int)));
        double *g0 = AMPS__CAST(double *, amps__malloc(ctx, 3 * c, sizeof(double)));
        double *r0 = AMPS__CAST(double *, amps__malloc(ctx, 3 * c, sizeof(double)));
        double *H = AMPS__CAST(double *, amps__malloc(ctx, 9 * c * c, sizeof(double)));
        if (!nd || !eq || !g0 || !r0 || !H) {
            amps__free(ctx, nd);
            amps__free(ctx, eq);
            amps__free(ctx, g0);
            amps__free(ctx, r0);
            amps__free(ctx, H);
            return amps__err(ctx, AMPS_ERR_OOM, "amps_scene_haptic_build: out of memory for %ld pins", (long)n);
        }
        {
            long serial = h->serial;
            amps_haptic_free(ctx, h);
            h->serial = serial;
        }
        h->node = nd;
        h->eq = eq;
        h->g0 = g0;
        h->r0 = r0;
        h->H = H;
        h->cap = n;
    }
    m = 3 * n;
    idx = h->eq;
    for (n = 0, v = 0; v < nn; v++) {
        int d;
        if (!S->node.pinned[v]) continue;
        h->node[n] = v;
        amps_scene_reaction(ctx, S, v, h->r0 + 3 * n);
        for (d = 0; d < 3; d++) {
            int orphan = amps__scene_orphan(S, v);
            h->g0[3 * n + d] = S->node.pin_value[3 * v + d];
            idx[3 * n + d] = orphan ? -1 : S->node.dof[3 * v + d]; /* orphans: held, not by the pin */
        }
        n++;
    }
    h->n = n;
    h->serial++;
    if (n == 0) return amps__err(ctx, AMPS_WARN_NOOP, "amps_scene_haptic_build: no pinned node");
    amps__pin_schur(S->U, m, idx, h->H);
    sc = S->dyn.on ? 1.0 / (S->dyn.dt * S->dyn.dt) : 1.0;
    if (sc != 1.0)
        for (k = 0; k < m * m; k++) h->H[k] *= sc;
    if (S->dyn.corot) amps__cr_haptic_rotate(S, h);
    return AMPS_OK;
}

AMPS_API amps_status amps_haptic_eval(const amps_haptic *h, const double *g, double *r) {
    amps_int m, i, j;
    if (!h || !r || (h->n > 0 && (!h->r0 || !h->H))) return AMPS_ERR_ARG;
    m = 3 * h->n;
    for (i = 0; i < m; i++) r[i] = h->r0[i];
    if (!g) return AMPS_OK;
    for (j = 0; j < m; j++) {
        double dg = g[j] - h->g0[j];
        const double *hj = h->H + (size_t)j * (size_t)m;
        if (dg != 0.0)
            for (i = 0; i < m; i++) r[i] += hj[i] * dg;
    }
    return AMPS_OK;
}

AMPS_API amps_int amps_haptic_find(const amps_haptic *h, amps_int v) {
    amps_int lo = 0, hi;
    if (!h || !h->node) return -1;
    hi = h->n - 1;
    while (lo <= hi) {
        amps_int mid = lo + (hi - lo) / 2;
        if (h->node[mid] == v) return mid;
        if (h->node[mid] < v) lo = mid + 1;
        else hi = mid - 1;
    }
    return -1;
}

AMPS_API amps_status amps_scene_residual(amps_ctx *ctx, amps_scene *S, double *relres) {
    if (!S || !S->U) return amps__err(ctx, AMPS_ERR_STATE, "amps_scene_residual: nothing solved yet");
    if (S->dyn.corot && relres) { /* the last corotational step's PCG */
        *relres = S->dyn.info.relres;
        return AMPS_OK;
    }
    return amps_update_residual(ctx, S->U, relres);
}

static amps_status amps__scene_corot_stress(amps_ctx *ctx, const amps_scene *S, double *sigma, double *von_mises,
                                            double *principal);
AMPS_API amps_status amps_scene_stress(amps_ctx *ctx, const amps_scene *S, double *sigma, double *von_mises,
                                       double *principal) {
    if (!S) return amps__err(ctx, AMPS_ERR_ARG, "amps_scene_stress: NULL scene");
    if (S->dyn.corot) return amps__scene_corot_stress(ctx, S, sigma, von_mises, principal);
    return amps_mesh_stress(ctx, S->m, S->node.disp, sigma, von_mises, principal);
}

/* ---- rendering data ---- */

static void amps__scene_render_free(amps_ctx *ctx, amps_scene *S) {
    amps__scene_render *R = &S->rd;
    amps__scene_grid *G = &S->grid;
    amps__free(ctx, R->face_id);
    amps__free(ctx, R->tri);
    amps__free(ctx, R->face);
    amps__free(ctx, R->fresh);
    amps__free(ctx, R->free_ids);
    amps__free(ctx, R->held);
    amps__free(ctx, R->added);
    amps__free(ctx, R->removed);
    amps__free(ctx, R->new_nodes);
    amps__free(ctx, R->moved);
    amps__free(ctx, R->tet_moved);
    memset(R, 0, sizeof(*R));
    amps__free(ctx, G->cell_ptr);
    amps__free(ctx, G->cell_node);
    amps__free(ctx, G->next_copy);
    amps__free(ctx, G->last_copy);
    memset(G, 0, sizeof(*G));
}

/* Room for cap ids in every per-id array. */
static amps_status amps__render_ids(amps_ctx *ctx, amps__scene_render *R, amps_int cap) {
    size_t c = (size_t)cap;
    if (cap <= R->cap) return AMPS_OK;
    if (amps__realloc(ctx, (void **)&R->tri, 3 * c, sizeof(amps_int)) ||
        amps__realloc(ctx, (void **)&R->face, c, sizeof(amps_int)) || amps__realloc(ctx, (void **)&R->fresh, c, 1) ||
        amps__realloc(ctx, (void **)&R->free_ids, c, sizeof(amps_int)) ||
        amps__realloc(ctx, (void **)&R->held, c, sizeof(amps_int)) ||
        amps__realloc(ctx, (void **)&R->added, c, sizeof(amps_int)) ||
        amps__realloc(ctx, (void **)&R->removed, c, sizeof(amps_int)))
        return AMPS_ERR_OOM;
    R->cap = cap;
    return AMPS_OK;
}

/* After a take, the first change starts new lists: the held ids become free, the moved marks clear. */
static void amps__render_begin(amps__scene_render *R) {
    amps_int k;
    if (!R->taken) return;
    for (k = 0; k < R->nheld; k++) R->free_ids[R->nfree++] = R->held[k];
    for (k = 0; k < R->nmoved; k++) R->tet_moved[R->moved[k]] = 0;
    R->nheld = R->nadded = R->nremoved = R->nnew = R->nmoved = 0;
    R->taken = 0;
}

/* Removes the triangle of face fc (it has one). */
static void amps__render_remove(amps__scene_render *R, amps_int fc) {
    amps_int id = R->face_id[fc];
    if (!R->fresh[id]) R->removed[R->nremoved++] = id;
    R->fresh[id] = 0;
    R->tri[3 * id] = R->tri[3 * id + 1] = R->tri[3 * id + 2] = R->face[id] = -1;
    R->held[R->nheld++] = id;
    R->face_id[fc] = -1;
}

/* Adds the triangle tri of face fc (it has none). */
static amps_status amps__render_add(amps_ctx *ctx, amps__scene_render *R, amps_int fc, const amps_int tri[3]) {
    amps_int id;
    if (R->nfree > 0) id = R->free_ids[--R->nfree];
    else {
        if (R->nid == R->cap && amps__render_ids(ctx, R, 2 * R->cap + 64)) return AMPS_ERR_OOM;
        id = R->nid++;
    }
    memcpy(R->tri + 3 * id, tri, 3 * sizeof(amps_int));
    R->face[id] = fc;
    R->fresh[id] = 1;
    R->added[R->nadded++] = id;
    R->face_id[fc] = id;
    return AMPS_OK;
}

/* 1 if a tet other than t in the incidence lists contains the nodes key[0..2]. */
static int amps__face_shared(const amps_mesh *m, amps_int t, const amps_int key[3]) {
    amps_int k, deg, best = key[0];
    const amps_int *inc;
    int q;
    for (q = 1; q < 3; q++)
        if (m->inc_len[key[q]] < m->inc_len[best]) best = key[q];
    inc = amps_mesh_incident(m, best, &deg);
    for (k = 0; k < deg; k++) {
        amps_int u = inc[k], hits = 0;
        if (u == t) continue;
        for (q = 0; q < 4; q++) {
            amps_int w = m->tet[4 * u + q];
            hits += w == key[0] || w == key[1] || w == key[2];
        }
        if (hits == 3) return 1;
    }
    return 0;
}

/* Brings the triangle of face f of tet t up to date with the mesh. */
static amps_status amps__render_face(amps_ctx *ctx, amps_scene *S, amps_int t, int f) {
    amps__scene_render *R = &S->rd;
    amps_int key[3], tri[3], fc = 4 * t + f, id = R->face_id[fc];
    amps__face_key(S->m, t, f, key);
    if (!amps__tet_live(S->m, t) || amps__face_shared(S->m, t, key)) {
        if (id >= 0) amps__render_remove(R, fc);
        return AMPS_OK;
    }
    amps__face_tri(S->m, t, f, tri);
    if (id >= 0 && !memcmp(R->tri + 3 * id, tri, sizeof(tri))) return AMPS_OK;
    if (id >= 0) amps__render_remove(R, fc);
    return amps__render_add(ctx, R, fc, tri);
}

/* Recomputes the boundary faces of tets[0..n-1] and of their face neighbours (the tets that
   share the nodes of one of their faces), after a change of their nodes or their removal (a
   tet no incidence list holds has no faces). An allocation failure stops the recording (the
   next take reports a reset). */
static void amps__scene_faces_changed(amps_ctx *ctx, amps_scene *S, const amps_int *tets, amps_int n) {
    const amps_mesh *m = S->m;
    amps_int k, j, deg;
    int f, q;
    if (!S->rd.on || S->rd.lost) return;
    amps__render_begin(&S->rd);
    for (k = 0; k < n; k++)
        for (f = 0; f < 4; f++) {
            amps_int t = tets[k], key[3];
            const amps_int *inc;
            if (amps__render_face(ctx, S, t, f)) goto lost;
            amps__face_key(m, t, f, key);
            inc = amps_mesh_incident(m, key[0], &deg);
            for (j = 0; j < deg; j++) { /* the neighbours across face f */
                amps_int u = inc[j], hits = 0;
                if (u == t) continue;
                for (q = 0; q < 4; q++) hits += m->tet[4 * u + q] == key[1] || m->tet[4 * u + q] == key[2];
                for (q = 0; q < 4 && hits == 2; q++) {
                    amps_int w = m->tet[4 * u + q];
                    if (w != key[0] && w != key[1] && w != key[2] && amps__render_face(ctx, S, u, q)) goto lost;
                }
            }
        }
    return;
lost:
    S->rd.lost = 1;
}

/* The change record of a cut of v into v and vc: the copy, the tets that moved to it, the faces
   around both. */
static void amps__scene_cut_recorded(amps_ctx *ctx, amps_scene *S, amps_int v, amps_int vc) {
    amps__scene_render *R = &S->rd;
    amps_int k, deg;
    const amps_int *inc;
    if (!R->on || R->lost || vc < 0) return;
    amps__render_begin(R);
    if (R->nnew == R->cap_new) {
        if (amps__realloc(ctx, (void **)&R->new_nodes, (size_t)R->cap_new * 2 + 16, sizeof(amps_int))) {
            R->lost = 1;
            return;
        }
        R->cap_new = R->cap_new * 2 + 16;
    }
    R->new_nodes[R->nnew++] = vc;
    inc = amps_mesh_incident(S->m, vc, &deg);
    for (k = 0; k < deg; k++)
        if (R->tet_moved[inc[k]]++ == 0) R->moved[R->nmoved++] = inc[k];
    amps__scene_faces_changed(ctx, S, inc, deg);
    inc = amps_mesh_incident(S->m, v, &deg);
    amps__scene_faces_changed(ctx, S, inc, deg);
}

/* The change record of the undoing of the cut of v into v and vc (vc gone; mv[0..nmv-1] the tets
   it moved back to v): vc leaves the new nodes, each of those tets leaves the moved ones unless
   another recorded cut moved it (or the record was taken since the cut: then it moved again),
   the faces around v are brought up to date (v < 0: the record of vc and mv only). */
static void amps__scene_uncut_recorded(amps_ctx *ctx, amps_scene *S, amps_int v, amps_int vc, const amps_int *mv,
                                       amps_int nmv) {
    amps__scene_render *R = &S->rd;
    amps_int k, j, deg;
    const amps_int *inc;
    if (!R->on || R->lost) return;
    amps__render_begin(R);
    for (k = R->nnew - 1; k >= 0; k--)
        if (R->new_nodes[k] == vc) {
            memmove(R->new_nodes + k, R->new_nodes + k + 1, sizeof(amps_int) * (size_t)(R->nnew - k - 1));
            R->nnew--;
            break;
        }
    for (j = 0; j < nmv; j++) {
        amps_int t = mv[j];
        if (R->tet_moved[t] == 0) { /* moved back after a take */
            R->tet_moved[t] = 1;
            R->moved[R->nmoved++] = t;
        } else if (--R->tet_moved[t] == 0) {
            for (k = R->nmoved - 1; k >= 0 && R->moved[k] != t; k--) {}
            if (k >= 0) {
                memmove(R->moved + k, R->moved + k + 1, sizeof(amps_int) * (size_t)(R->nmoved - k - 1));
                R->nmoved--;
            }
        }
    }
    if (v < 0) return; /* the record only */
    inc = amps_mesh_incident(S->m, v, &deg);
    amps__scene_faces_changed(ctx, S, inc, deg);
}

/* Every triangle from scratch, with new ids (all added). */
static amps_status amps__render_rebuild(amps_ctx *ctx, amps_scene *S) {
    amps__scene_render *R = &S->rd;
    const amps_mesh *m = S->m;
    amps_int k, nt = 4 * m->ntet, n = amps_mesh_boundary(ctx, m, NULL, NULL);
    if (n < 0) return ctx ? ctx->status : AMPS_ERR_OOM;
    if (!R->face_id) R->face_id = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)nt, sizeof(amps_int)));
    if (!R->moved) R->moved = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)m->ntet, sizeof(amps_int)));
    if (!R->tet_moved) R->tet_moved = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)m->ntet, sizeof(amps_int)));
    if (!R->face_id || !R->moved || !R->tet_moved) return AMPS_ERR_OOM;
    if (amps__render_ids(ctx, R, n + 64)) return AMPS_ERR_OOM;
    if (amps_mesh_boundary(ctx, m, R->tri, R->face) != n) return AMPS_ERR_OOM;
    for (k = 0; k < nt; k++) R->face_id[k] = -1;
    for (k = 0; k < m->ntet; k++) R->tet_moved[k] = 0;
    for (k = 0; k < n; k++) {
        R->face_id[R->face[k]] = k;
        R->added[k] = k;
        R->fresh[k] = 0;
    }
    R->nid = R->nadded = n;
    R->nfree = R->nheld = R->nremoved = R->nnew = R->nmoved = 0;
    R->lost = 0;
    return AMPS_OK;
}

AMPS_API amps_status amps_scene_take_changes(amps_ctx *ctx, amps_scene *S, amps_scene_changes *c) {
    amps__scene_render *R;
    amps_int k, n = 0;
    if (!S || !c) return amps__err(ctx, AMPS_ERR_ARG, "amps_scene_take_changes: NULL argument");
    R = &S->rd;
    memset(c, 0, sizeof(*c));
    if (!R->on || R->lost) {
        if (amps__render_rebuild(ctx, S)) {
            R->on = 0;
            return amps__err(ctx, AMPS_ERR_OOM, "amps_scene_take_changes: out of memory");
        }
        R->on = 1;
        c->reset = 1;
    } else {
        amps__render_begin(R);          /* a take after a take: empty lists */
        for (k = 0; k < R->nadded; k++) /* the ids added and still there */
            if (R->fresh[R->added[k]]) {
                R->fresh[R->added[k]] = 0;
                R->added[n++] = R->added[k];
            }
        R->nadded = n;
    }
    c->nadded = R->nadded;
    c->added = R->added;
    c->nremoved = R->nremoved;
    c->removed = R->removed;
    c->nnew = R->nnew;
    c->new_nodes = R->new_nodes;
    c->nmoved = R->nmoved;
    c->moved_tets = R->moved;
    R->taken = 1;
    return AMPS_OK;
}

AMPS_API amps_int amps_scene_boundary(const amps_scene *S, const amps_int **tri, const amps_int **face) {
    int on = S && S->rd.on;
    if (tri) *tri = on ? S->rd.tri : NULL;
    if (face) *face = on ? S->rd.face : NULL;
    return on ? S->rd.nid : 0;
}

/* ---- node map and watched positions ---- */

AMPS_API amps_status amps_scene_node_dofs(amps_ctx *ctx, const amps_scene *S, amps_int v, amps_int dof[3]) {
    int d;
    if (!S || !dof) return amps__err(ctx, AMPS_ERR_ARG, "amps_scene_node_dofs: NULL argument");
    if (v < 0 || v >= S->m->nnode)
        return amps__err(ctx, AMPS_ERR_INDEX, "amps_scene_node_dofs: node %ld out of range [0, %ld)", (long)v,
                         (long)S->m->nnode);
    if (!S->prepared)
        return amps__err(ctx, AMPS_ERR_STATE,
                         "amps_scene_node_dofs: no equations before the factorization (call amps_scene_prepare)");
    for (d = 0; d < 3; d++) dof[d] = S->m->inc_len[v] > 0 ? S->node.dof[3 * v + d] : -1; /* orphans: rows held apart */
    return AMPS_OK;
}

AMPS_API const amps_int *amps_scene_watched(const amps_scene *S, amps_int *n) {
    if (n) *n = S ? S->watch.n : 0;
    return S && S->watch.n > 0 ? S->watch.nodes : NULL;
}

AMPS_API amps_status amps_scene_watched_positions(amps_ctx *ctx, const amps_scene *S, double *out) {
    if (!S || !out) return amps__err(ctx, AMPS_ERR_ARG, "amps_scene_watched_positions: NULL argument");
    return S->watch.n > 0 ? amps_scene_positions(ctx, S, S->watch.n, S->watch.nodes, out) : AMPS_OK;
}

/* ---- picking and selection ---- */

/* The grid cell coordinate of x on axis k (clamped to the grid). */
static amps_int amps__grid_cell(const amps__scene_grid *G, int k, double x) {
    double c = floor((x - G->lo[k]) / G->h);
    return c < 0 ? 0 : c >= (double)G->n[k] ? G->n[k] - 1 : (amps_int)c;
}

/* The grid over the creation nodes: cells of side h about one node each (cells <= 2 nfile + 8). */
static amps_status amps__scene_grid_build(amps_ctx *ctx, amps_scene *S) {
    amps__scene_grid *G = &S->grid;
    const amps_mesh *m = S->m;
    amps_int v, nf = m->nfile, ncell, c;
    double hi[3], vol = 1, ext = 0;
    int k;
    for (k = 0; k < 3; k++) G->lo[k] = hi[k] = m->xyz[k];
    for (v = 0; v < nf; v++)
        for (k = 0; k < 3; k++) {
            double x = m->xyz[3 * v + k];
            if (x < G->lo[k]) G->lo[k] = x;
            if (x > hi[k]) hi[k] = x;
        }
    for (k = 0; k < 3; k++) {
        vol *= hi[k] - G->lo[k];
        if (hi[k] - G->lo[k] > ext) ext = hi[k] - G->lo[k];
    }
    G->h = vol > 0 ? cbrt(vol / (double)nf) : (ext > 0 ? ext / cbrt((double)nf) : 1.0);
    if (!(G->h > 0)) G->h = 1.0;
    for (;;) {
        double cells = 1;
        for (k = 0; k < 3; k++) cells *= floor((hi[k] - G->lo[k]) / G->h) + 1;
        if (cells <= 2.0 * (double)nf + 8) break;
        G->h *= 1.26;
    }
    for (k = 0; k < 3; k++) G->n[k] = (amps_int)floor((hi[k] - G->lo[k]) / G->h) + 1;
    ncell = G->n[0] * G->n[1] * G->n[2];
    G->cell_ptr = AMPS__CAST(amps_int *, amps__calloc(ctx, (size_t)ncell + 2, sizeof(amps_int)));
    G->cell_node = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)nf, sizeof(amps_int)));
    G->last_copy = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)nf, sizeof(amps_int)));
    if (!G->cell_ptr || !G->cell_node || !G->last_copy) return AMPS_ERR_OOM;
    for (v = 0; v < nf; v++) {
        const double *x = m->xyz + 3 * v;
        c = amps__grid_cell(G, 0, x[0]) +
            G->n[0] * (amps_int)(amps__grid_cell(G, 1, x[1]) + G->n[1] * amps__grid_cell(G, 2, x[2]));
        G->cell_ptr[c + 2]++;
    }
    for (c = 0; c < ncell; c++) G->cell_ptr[c + 2] += G->cell_ptr[c + 1];
    for (v = 0; v < nf; v++) {
        const double *x = m->xyz + 3 * v;
        c = amps__grid_cell(G, 0, x[0]) +
            G->n[0] * (amps_int)(amps__grid_cell(G, 1, x[1]) + G->n[1] * amps__grid_cell(G, 2, x[2]));
        G->cell_node[G->cell_ptr[c + 1]++] = v;
        G->last_copy[v] = v;
    }
    G->nlinked = 0;
    G->built = 1;
    return AMPS_OK;
}

/* Chains the nodes created since the last query to their origins. */
static amps_status amps__scene_grid_link(amps_ctx *ctx, amps_scene *S) {
    amps__scene_grid *G = &S->grid;
    const amps_mesh *m = S->m;
    amps_int v;
    if (m->nnode > G->cap) {
        if (amps__realloc(ctx, (void **)&G->next_copy, (size_t)m->nnode, sizeof(amps_int))) return AMPS_ERR_OOM;
        G->cap = m->nnode;
    }
    for (v = G->nlinked; v < m->nnode; v++) {
        G->next_copy[v] = -1;
        if (v >= m->nfile) {
            G->next_copy[G->last_copy[m->origin[v]]] = v;
            G->last_copy[m->origin[v]] = v;
        }
    }
    G->nlinked = m->nnode;
    return AMPS_OK;
}

/* The nodes of grid cell c (i, j, k) against the best (*bd2, *bv) so far. */
static void amps__grid_scan(const amps_scene *S, amps_int i, amps_int j, amps_int k, const double p[3], double *bd2,
                            amps_int *bv) {
    const amps__scene_grid *G = &S->grid;
    amps_int c = i + G->n[0] * (j + G->n[1] * k), a;
    for (a = G->cell_ptr[c]; a < G->cell_ptr[c + 1]; a++) {
        amps_int o = G->cell_node[a], w = o;
        const double *x = S->m->xyz + 3 * o;
        double d2 = (x[0] - p[0]) * (x[0] - p[0]) + (x[1] - p[1]) * (x[1] - p[1]) + (x[2] - p[2]) * (x[2] - p[2]);
        while (w >= 0 && S->m->inc_len[w] == 0) w = G->next_copy[w];
        if (w >= 0 && (d2 < *bd2 || (d2 == *bd2 && w < *bv))) {
            *bd2 = d2;
            *bv = w;
        }
    }
}

/* A lower bound on the distance from p to the cells beyond the shell r around cell c; -1 if
   there are none. */
static double amps__grid_gap(const amps__scene_grid *G, const amps_int c[3], amps_int r, const double p[3]) {
    double gap = -1;
    int k;
    for (k = 0; k < 3; k++) {
        if (c[k] + r + 1 < G->n[k]) {
            double g = G->lo[k] + (double)(c[k] + r + 1) * G->h - p[k];
            g = g > 0 ? g : 0;
            if (gap < 0 || g < gap) gap = g;
        }
        if (c[k] - r - 1 >= 0) {
            double g = p[k] - (G->lo[k] + (double)(c[k] - r) * G->h);
            g = g > 0 ? g : 0;
            if (gap < 0 || g < gap) gap = g;
        }
    }
    return gap;
}

/* Shells of cells at growing Chebyshev distance r around p's cell, until the best distance is
   below what any cell beyond can hold. */
/* 1 if the 3 coordinates are finite and at most 1e150 in magnitude (squared distances of
   picking stay finite). */
static int amps__pick_ok(const double *p) {
    int k;
    for (k = 0; k < 3; k++)
        if (!amps__isfinite(p[k]) || fabs(p[k]) > 1e150) return 0;
    return 1;
}

AMPS_API amps_status amps_scene_nearest_node(amps_ctx *ctx, amps_scene *S, const double p[3], amps_int *v) {
    amps__scene_grid *G;
    amps_int c[3], r, i, j, k, bv = -1;
    double bd2 = HUGE_VAL;
    int a;
    if (v) *v = -1;
    if (!S || !p || !v) return amps__err(ctx, AMPS_ERR_ARG, "amps_scene_nearest_node: NULL argument");
    if (!amps__pick_ok(p))
        return amps__err(ctx, AMPS_ERR_VALUE, "amps_scene_nearest_node: a coordinate is NaN, Inf or beyond 1e150");
    G = &S->grid;
    if (!G->built && amps__scene_grid_build(ctx, S)) {
        amps__free(ctx, G->cell_ptr);
        amps__free(ctx, G->cell_node);
        amps__free(ctx, G->last_copy);
        G->cell_ptr = G->cell_node = G->last_copy = NULL;
        return amps__err(ctx, AMPS_ERR_OOM, "amps_scene_nearest_node: out of memory");
    }
    if (amps__scene_grid_link(ctx, S)) return amps__err(ctx, AMPS_ERR_OOM, "amps_scene_nearest_node: out of memory");
    for (a = 0; a < 3; a++) c[a] = amps__grid_cell(G, a, p[a]);
    for (r = 0;; r++) {
        double gap;
        for (k = c[2] - r; k <= c[2] + r; k++)
            for (j = c[1] - r; j <= c[1] + r; j++)
                for (i = c[0] - r; i <= c[0] + r; i++) {
                    amps_int di = i - c[0], dj = j - c[1], dk = k - c[2];
                    if (i < 0 || j < 0 || k < 0 || i >= G->n[0] || j >= G->n[1] || k >= G->n[2]) continue;
                    if ((di < 0 ? -di : di) != r && (dj < 0 ? -dj : dj) != r && (dk < 0 ? -dk : dk) != r) continue;
                    amps__grid_scan(S, i, j, k, p, &bd2, &bv);
                }
        gap = amps__grid_gap(G, c, r, p);
        if (gap < 0) break;
        gap -= 1e-9 * G->h; /* a node rounded into the cell next to its own */
        if (bv >= 0 && gap > 0 && bd2 < gap * gap) break;
    }
    *v = bv;
    return AMPS_OK;
}

/* Fixes the nodes whose reference coordinates lie in the box [lo, hi] (ball = 0) or in the ball
   of center lo and radius r (ball = 1). */
static amps_status amps__scene_fix_region(amps_ctx *ctx, amps_scene *S, const double *lo, const double *hi, double r,
                                          int ball, amps_int *count, const char *fn) {
    amps_int v, n = 0;
    int k;
    if (count) *count = 0;
    if (!S || !lo || !hi) return amps__err(ctx, AMPS_ERR_ARG, "%s: NULL argument", fn);
    for (k = 0; k < 3; k++)
        if (!amps__isfinite(lo[k]) || !amps__isfinite(hi[k]) || !amps__isfinite(r))
            return amps__err(ctx, AMPS_ERR_VALUE, "%s: NaN or Inf in the region", fn);
    for (k = 0; k < 3; k++)
        if (lo[k] > hi[k])
            return amps__err(ctx, AMPS_ERR_ARG, "%s: lo[%d] = %g above hi[%d] = %g", fn, k, lo[k], k, hi[k]);
    if (r < 0) return amps__err(ctx, AMPS_ERR_ARG, "%s: negative radius %g", fn, r);
    if (S->prepared)
        return amps__err(ctx, AMPS_ERR_STATE,
                         "%s: the system is already factored (fix nodes before the first change or solve)", fn);
    for (v = 0; v < S->m->nnode; v++) {
        const double *x = S->m->xyz + 3 * v;
        double d2 = 0;
        int in = 1;
        for (k = 0; k < 3; k++) {
            in = in && x[k] >= lo[k] && x[k] <= hi[k];
            d2 += (x[k] - lo[k]) * (x[k] - lo[k]);
        }
        if (ball ? d2 <= r * r : in) {
            S->node.fixed[v] = 1;
            n++;
        }
    }
    if (count) *count = n;
    return AMPS_OK;
}

AMPS_API amps_status amps_scene_fix_box(amps_ctx *ctx, amps_scene *S, const double lo[3], const double hi[3],
                                        amps_int *count) {
    return amps__scene_fix_region(ctx, S, lo, hi, 0, 0, count, "amps_scene_fix_box");
}

AMPS_API amps_status amps_scene_fix_sphere(amps_ctx *ctx, amps_scene *S, const double c[3], double r, amps_int *count) {
    return amps__scene_fix_region(ctx, S, c, c, r, 1, count, "amps_scene_fix_sphere");
}

AMPS_API int amps_scene_is_fixed(const amps_scene *S, amps_int v) {
    return S && v >= 0 && v < S->m->nnode && S->node.fixed[v];
}
AMPS_API int amps_scene_is_pinned(const amps_scene *S, amps_int v) {
    return S && v >= 0 && v < S->m->nnode && S->node.pinned[v];
}

/* ---- batches, strokes and segment queries ---- */

static amps_status amps__scene_refresh_force(amps_ctx *ctx, amps_scene *S, amps_int v);

/* Room in the batch log for one more change with ni integers and nd doubles. */
static amps_status amps__scene_batch_room(amps_ctx *ctx, amps_scene *S, amps_int ni, amps_int nd) {
    amps__scene_batch *B = &S->batch;
    if (B->n + 1 > B->cap) {
        amps_int cap = 2 * B->cap + 16;
        if (amps__realloc(ctx, (void **)&B->ops, (size_t)cap, sizeof(amps__scene_op)))
            return amps__err(ctx, AMPS_ERR_OOM, "amps_scene: out of memory recording a batch");
        B->cap = cap;
    }
    if (B->nilog + ni > B->cap_ilog) {
        amps_int cap = 2 * B->cap_ilog + ni + 64;
        if (amps__realloc(ctx, (void **)&B->ilog, (size_t)cap, sizeof(amps_int)))
            return amps__err(ctx, AMPS_ERR_OOM, "amps_scene: out of memory recording a batch");
        B->cap_ilog = cap;
    }
    if (B->ndlog + nd > B->cap_dlog) {
        amps_int cap = 2 * B->cap_dlog + nd + 64;
        if (amps__realloc(ctx, (void **)&B->dlog, (size_t)cap, sizeof(double)))
            return amps__err(ctx, AMPS_ERR_OOM, "amps_scene: out of memory recording a batch");
        B->cap_dlog = cap;
    }
    return AMPS_OK;
}

/* A new op of the given kind and node in the log, its integers ilog[at .. at + len - 1] (to be
   written by the caller); room made by amps__scene_batch_room. */
static amps__scene_op *amps__scene_batch_op(amps_scene *S, int kind, amps_int v, amps_int len) {
    amps__scene_batch *B = &S->batch;
    amps__scene_op *op = B->ops + B->n++;
    memset(op, 0, sizeof(*op));
    op->kind = kind;
    op->v = v;
    op->vc = -1;
    op->at = B->nilog;
    op->len = len;
    op->dat = B->ndlog;
    B->nilog += len;
    return op;
}

/* Logs the cut of v into v and vc (its moved tets in cut.moved). */
static void amps__scene_batch_cut(amps_scene *S, amps_int v, amps_int vc, amps_int nmoved) {
    amps__scene_op *op = amps__scene_batch_op(S, 0, v, nmoved);
    op->vc = vc;
    memcpy(S->batch.ilog + op->at, S->cut.moved, sizeof(amps_int) * (size_t)nmoved);
}

/* Logs a pin (kind 1) or release (kind 2) of v with v's state before it. */
static void amps__scene_batch_pin(amps_scene *S, int kind, amps_int v) {
    amps__scene_op *op = amps__scene_batch_op(S, kind, v, 0);
    op->was_pinned = S->node.pinned[v];
    memcpy(op->old, S->node.pin_value + 3 * v, sizeof(op->old));
}

/* Logs the material change of tets[0..n-1], whose old (E, nu, rho) are the 3 n doubles at
   dlog[ndlog] (rho_set: the densities changed). */
static void amps__scene_batch_material(amps_scene *S, amps_int n, const amps_int *tets, int rho_set) {
    amps__scene_op *op = amps__scene_batch_op(S, 3, -1, n);
    op->was_pinned = rho_set;
    memcpy(S->batch.ilog + op->at, tets, sizeof(amps_int) * (size_t)n);
    S->batch.ndlog += 3 * n;
}

/* Integers of a removal's log: {nflag, flagged orphans, nsep, sep_node, sep_copy, the mesh's
   log (amps__rm_log_save)}. */
static amps_int amps__scene_removal_log_len(const amps_scene *S, const amps_mesh_removal *r, amps_int nflag) {
    return 2 + nflag + 2 * r->nsep + amps__rm_log_len(S->m);
}

/* Logs the removal r (the last change of the mesh) that flagged[0..nflag-1] as orphans; room
   for amps__scene_removal_log_len integers made. */
static void amps__scene_batch_removal(amps_scene *S, const amps_mesh_removal *r, const amps_int *flagged,
                                      amps_int nflag) {
    amps__scene_op *op = amps__scene_batch_op(S, 4, -1, amps__scene_removal_log_len(S, r, nflag));
    amps_int *L = S->batch.ilog + op->at, ns = r->nsep;
    *L++ = nflag;
    if (nflag > 0) memcpy(L, flagged, sizeof(amps_int) * (size_t)nflag);
    L += nflag;
    *L++ = ns;
    if (ns > 0) { /* (empty arrays may be NULL) */
        memcpy(L, r->sep_node, sizeof(amps_int) * (size_t)ns);
        memcpy(L + ns, r->sep_copy, sizeof(amps_int) * (size_t)ns);
    }
    amps__rm_log_save(S->m, L + 2 * ns);
}

/* The scene's side of undoing a removal before its mesh is restored: the orphans it flagged
   (flagged[0..nflag-1]) as they were, no equations for the nodes from nn0 on. */
static void amps__scene_unremove_nodes(amps_scene *S, const amps_int *flagged, amps_int nflag, amps_int nn0) {
    amps_int k;
    for (k = 0; k < nflag; k++) {
        S->node.pinned[flagged[k]] = (unsigned char)(S->dyn.orphan[flagged[k]] == 2);
        S->dyn.orphan[flagged[k]] = 0;
    }
    for (k = 3 * nn0; k < 3 * S->m->nnode && k < 3 * S->node.cap; k++) S->node.dof[k] = -1;
}

/* After a removal's mesh was restored: the masses and gravity loads of the nodes of its tets
   and of its separated nodes (a discard keeps the engine's forces). */
static void amps__scene_unremove_forces(amps_scene *S, const amps_int *tets, amps_int ntet, const amps_int *sep_node,
                                        amps_int nsep) {
    amps_ctx c2;
    amps_int k;
    amps_ctx_init(&c2);
    for (k = 0; S->prepared && k < 4 * ntet; k++)
        (void)amps__scene_refresh_force(&c2, S, S->m->tet[4 * tets[k / 4] + k % 4]);
    for (k = 0; S->prepared && k < nsep; k++) (void)amps__scene_refresh_force(&c2, S, sep_node[k]);
}

/* Undoes the logged removal L (amps__scene_batch_removal): scene, mesh, forces, rendering
   record (its separations' copies gone, the faces around its tets). */
static void amps__scene_batch_unremove(amps_scene *S, const amps_int *L) {
    amps_int nflag = L[0], ns = L[1 + nflag], k;
    const amps_int *fl = L + 1, *sn = fl + nflag + 1, *sc = sn + ns, *ML = sc + ns, *tets = ML + AMPS__RMLOG_HEAD;
    amps_ctx c2;
    amps_int deg;
    const amps_int *inc;
    amps_ctx_init(&c2);
    for (k = ns - 1; k >= 0; k--) { /* the copies' records as made: their tets at the end of the removal */
        inc = amps_mesh_incident(S->m, sc[k], &deg);
        amps__scene_uncut_recorded(&c2, S, -1, sc[k], inc, deg);
    }
    amps__scene_unremove_nodes(S, fl, nflag, ML[0]);
    amps__rm_log_undo(S->m, ML);
    amps__scene_unremove_forces(S, tets, ML[1], sn, ns);
    for (k = 0; k < ns; k++) { /* the faces around the nodes the tets came back to, and the removed tets' */
        inc = amps_mesh_incident(S->m, sn[k], &deg);
        amps__scene_faces_changed(&c2, S, inc, deg);
    }
    amps__scene_faces_changed(&c2, S, tets, ML[1]);
}

/* Undoes the logged material change op: the old materials and, when the densities changed, the
   masses and gravity loads of the tets' nodes. */
static void amps__scene_batch_unmaterial(amps_scene *S, const amps__scene_op *op) {
    const amps_int *tets = S->batch.ilog + op->at;
    const double *old = S->batch.dlog + op->dat;
    amps_mesh *m = S->m;
    amps_ctx c2;
    amps_int k;
    amps_ctx_init(&c2);
    for (k = 0; k < op->len; k++) {
        m->E[tets[k]] = old[3 * k];
        m->nu[tets[k]] = old[3 * k + 1];
        if (op->was_pinned) m->rho[tets[k]] = old[3 * k + 2];
    }
    for (k = 0; op->was_pinned && k < 4 * op->len; k++)
        (void)amps__scene_refresh_force(&c2, S, m->tet[4 * tets[k / 4] + k % 4]);
}

/* Undoes the logged cut op (the copy out of the watch set and the mesh, the masses of both
   nodes, the rendering record). */
static void amps__scene_batch_uncut(amps_scene *S, const amps__scene_op *op) {
    const amps_int *mv = S->batch.ilog + op->at;
    amps_int k;
    amps_ctx c2;
    amps_ctx_init(&c2);
    for (k = S->watch.n - 1; op->watched && k >= 0; k--)
        if (S->watch.nodes[k] == op->vc) {
            memmove(S->watch.nodes + k, S->watch.nodes + k + 1, sizeof(amps_int) * (size_t)(S->watch.n - k - 1));
            S->watch.n--;
            S->watch.stale = 1;
            break;
        }
    for (k = 0; k < 3; k++) S->node.dof[3 * op->vc + k] = -1;
    S->node.fixed[op->vc] = 0;
    S->node.pinned[op->vc] = 0;
    (void)amps_mesh_uncut(&c2, S->m, op->v, op->vc, mv, op->len);
    amps__scene_mass_node(S, op->vc);
    (void)amps__scene_refresh_force(&c2, S, op->v); /* its mass and gravity load (a discard keeps forces) */
    amps__scene_uncut_recorded(&c2, S, op->v, op->vc, mv, op->len);
}

/* Undoes the batch's changes, last first, and closes it (the engine has discarded its
   changes). */
static void amps__scene_batch_undo(amps_scene *S) {
    amps__scene_batch *B = &S->batch;
    amps_int i;
    for (i = B->n - 1; i >= 0; i--) {
        const amps__scene_op *op = B->ops + i;
        if (op->kind == 1) {
            S->node.pinned[op->v] = (unsigned char)op->was_pinned;
            memcpy(S->node.pin_value + 3 * op->v, op->old, sizeof(op->old));
        } else if (op->kind == 2) S->node.pinned[op->v] = 1;
        else if (op->kind == 3) amps__scene_batch_unmaterial(S, op);
        else if (op->kind == 4) amps__scene_batch_unremove(S, B->ilog + op->at);
        else amps__scene_batch_uncut(S, op);
    }
    B->open = 0;
    B->n = B->nilog = B->ndlog = 0;
}

/* A failed batch: the engine's pending changes discarded (the batch began with none), then the
   scene's undone. */
static void amps__scene_batch_abort(amps_scene *S) {
    amps_update_discard(S->U);
    amps__scene_batch_undo(S);
}

/* Statics: the releases of the open batch tested as amps_scene_release tests one, on the state
   after the batch (a node released and not pinned again); a refusal undoes the batch. */
static amps_status amps__scene_batch_held(amps_ctx *ctx, amps_scene *S, const char *fn) {
    amps_int i, nops = S->batch.n;
    amps_status s = AMPS_OK;
    for (i = 0; i < nops && !s; i++)
        if (S->batch.ops[i].kind == 2 && !S->node.pinned[S->batch.ops[i].v])
            s = amps__scene_release_held(ctx, S, S->batch.ops[i].v);
    if (s) {
        char msg[200];
        memcpy(msg, ctx ? ctx->msg : "", ctx ? sizeof(msg) : 1);
        msg[sizeof(msg) - 1] = 0;
        amps__scene_batch_abort(S);
        return amps__err(ctx, s, "%s: the batch of %ld changes was undone (%s)", fn, (long)nops, msg);
    }
    return AMPS_OK;
}

AMPS_API amps_status amps_scene_begin_batch(amps_ctx *ctx, amps_scene *S) {
    amps_status s;
    if (!S) return amps__err(ctx, AMPS_ERR_ARG, "amps_scene_begin_batch: NULL scene");
    if (S->batch.committing) return amps__scene_committing(ctx, "amps_scene_begin_batch");
    if (S->batch.open) return amps__err(ctx, AMPS_ERR_STATE, "amps_scene_begin_batch: a batch is open");
    if (!S->prepared && (s = amps_scene_prepare(ctx, S)) != AMPS_OK) return s;
    if ((s = amps_update_commit(ctx, S->U)) != AMPS_OK) return s; /* earlier changes first */
    S->batch.open = 1;
    S->batch.n = S->batch.nilog = S->batch.ndlog = 0;
    return AMPS_OK;
}

AMPS_API amps_status amps_scene_commit(amps_ctx *ctx, amps_scene *S) {
    amps_status s;
    amps_int nops;
    if (!S) return amps__err(ctx, AMPS_ERR_ARG, "amps_scene_commit: NULL scene");
    if (S->batch.committing) return amps__scene_committing(ctx, "amps_scene_commit");
    if (!S->prepared && (s = amps_scene_prepare(ctx, S)) != AMPS_OK) return s;
    nops = S->batch.n;
    if (S->batch.open && (s = amps__scene_batch_held(ctx, S, "amps_scene_commit")) != AMPS_OK) return s;
    s = amps_update_commit(ctx, S->U);
    if (s != AMPS_OK && S->batch.open) {
        char msg[200];
        memcpy(msg, ctx ? ctx->msg : "", ctx ? sizeof(msg) : 1);
        msg[sizeof(msg) - 1] = 0;
        amps__scene_batch_undo(S);
        return amps__err(ctx, s, "amps_scene_commit: the batch of %ld changes was undone (%s)", (long)nops, msg);
    }
    S->batch.open = 0;
    S->batch.n = S->batch.nilog = S->batch.ndlog = 0;
    return s;
}

AMPS_API amps_status amps_scene_cancel_batch(amps_ctx *ctx, amps_scene *S) {
    if (!S) return amps__err(ctx, AMPS_ERR_ARG, "amps_scene_cancel_batch: NULL scene");
    if (S->batch.committing) return amps__scene_committing(ctx, "amps_scene_cancel_batch");
    if (!S->batch.open) return amps__err(ctx, AMPS_ERR_STATE, "amps_scene_cancel_batch: no batch is open");
    amps__scene_batch_abort(S);
    return AMPS_OK;
}

AMPS_API amps_status amps_scene_commit_begin(amps_ctx *ctx, amps_scene *S) {
    amps_status s;
    if (!S) return amps__err(ctx, AMPS_ERR_ARG, "amps_scene_commit_begin: NULL scene");
    if (S->batch.committing) return amps__err(ctx, AMPS_ERR_STATE, "amps_scene_commit_begin: a commit is in progress");
    if (!S->prepared && (s = amps_scene_prepare(ctx, S)) != AMPS_OK) return s;
    if (S->batch.open && (s = amps__scene_batch_held(ctx, S, "amps_scene_commit_begin")) != AMPS_OK) return s;
    if ((s = amps_update_commit_begin(ctx, S->U)) != AMPS_OK) {
        if (S->batch.open) amps__scene_batch_undo(S); /* the engine discarded it */
        return s;
    }
    S->batch.committing = 1;
    S->batch.open = 0; /* its log stays until the end, to undo it */
    return AMPS_OK;
}

AMPS_API void amps_scene_commit_run(amps_scene *S) {
    if (S && S->batch.committing) amps_update_commit_run(S->U);
}

AMPS_API amps_status amps_scene_commit_end(amps_ctx *ctx, amps_scene *S) {
    amps_status s;
    if (!S) return amps__err(ctx, AMPS_ERR_ARG, "amps_scene_commit_end: NULL scene");
    if (!S->batch.committing) return amps__err(ctx, AMPS_ERR_STATE, "amps_scene_commit_end: no commit begun");
    S->batch.committing = 0;
    if ((s = amps_update_commit_end(ctx, S->U)) != AMPS_OK) {
        amps__scene_batch_undo(S);
        return s;
    }
    S->batch.n = S->batch.nilog = S->batch.ndlog = 0;
    return AMPS_OK;
}

/* Squared distance of x to the segment [a, b]; *t: the parameter in [0, 1] of the nearest point. */
static double amps__seg_dist2(const double *x, const double *a, const double *b, double *t) {
    double d[3], w[3], dd = 0, wd = 0, r = 0, tt = 0;
    int k;
    for (k = 0; k < 3; k++) {
        d[k] = b[k] - a[k];
        w[k] = x[k] - a[k];
        dd += d[k] * d[k];
        wd += w[k] * d[k];
    }
    if (dd > 0) tt = wd <= 0 ? 0 : wd >= dd ? 1 : wd / dd;
    for (k = 0; k < 3; k++) {
        double e = tt == 1 ? x[k] - b[k] : w[k] - tt * d[k]; /* an end exactly: equal at a shared corner */
        r += e * e;
    }
    if (t) *t = tt;
    return r;
}

AMPS_API amps_int amps_scene_nodes_near_segment(amps_ctx *ctx, const amps_scene *S, const double a[3],
                                                const double b[3], double radius, amps_int *out, amps_int cap) {
    amps_int v, cnt = 0;
    if (!S || !a || !b || (cap > 0 && !out))
        return amps__err(ctx, AMPS_ERR_ARG, "amps_scene_nodes_near_segment: NULL argument");
    if (!amps__pick_ok(a) || !amps__pick_ok(b))
        return amps__err(ctx, AMPS_ERR_VALUE,
                         "amps_scene_nodes_near_segment: a coordinate of the segment is NaN, Inf or beyond 1e150");
    if (!(radius >= 0) || !amps__isfinite(radius))
        return amps__err(ctx, AMPS_ERR_VALUE, "amps_scene_nodes_near_segment: radius must be finite and >= 0");
    for (v = 0; v < S->m->nnode; v++) {
        if (amps_mesh_degree(S->m, v) == 0 || amps__seg_dist2(S->m->xyz + 3 * v, a, b, NULL) > radius * radius)
            continue;
        if (cnt < cap) out[cnt] = v;
        cnt++;
    }
    return cnt;
}

/* A node the stroke touches: its segment, the position along it. */
typedef struct amps__stroke_node {
    amps_int v, seg;
    double t, d2;
} amps__stroke_node;

static int amps__stroke_cmp(const void *pa, const void *pb) {
    const amps__stroke_node *x = (const amps__stroke_node *)pa, *y = (const amps__stroke_node *)pb;
    if (x->seg != y->seg) return x->seg < y->seg ? -1 : 1;
    if (x->t != y->t) return x->t < y->t ? -1 : 1;
    return x->v < y->v ? -1 : x->v > y->v;
}

/* The stroke's planes: nrm[3i..] = unit (p_i+1 - p_i) x blade. */
static amps_status amps__stroke_planes(amps_ctx *ctx, amps_int npts, const double *pts, const double *blade,
                                       double *nrm) {
    amps_int i;
    int k;
    double b[3], sb = 0;
    for (k = 0; k < 3; k++) sb = fabs(blade[k]) > sb ? fabs(blade[k]) : sb;
    for (k = 0; k < 3; k++) b[k] = sb > 0 ? blade[k] / sb : 0; /* scaled: no overflow or underflow below */
    for (i = 0; i + 1 < npts; i++) {
        const double *p = pts + 3 * i, *q = p + 3;
        double d[3], c[3], ld = 0, lb = 0, lc = 0, sd = 0;
        for (k = 0; k < 3; k++) sd = fabs(q[k] - p[k]) > sd ? fabs(q[k] - p[k]) : sd;
        for (k = 0; k < 3; k++) d[k] = sd > 0 ? (q[k] - p[k]) / sd : 0;
        c[0] = d[1] * b[2] - d[2] * b[1];
        c[1] = d[2] * b[0] - d[0] * b[2];
        c[2] = d[0] * b[1] - d[1] * b[0];
        for (k = 0; k < 3; k++) {
            ld += d[k] * d[k];
            lb += b[k] * b[k];
            lc += c[k] * c[k];
        }
        if (!(ld > 0) || !(lc > 1e-12 * ld * lb))
            return amps__err(ctx, AMPS_ERR_ARG,
                             "amps_scene_stroke: segment %ld has zero length or is parallel to the blade", (long)i);
        for (k = 0; k < 3; k++) nrm[3 * i + k] = c[k] / sqrt(lc);
    }
    return AMPS_OK;
}

/* The nodes the stroke touches, each with its nearest segment, in cut order; *nc their number. */
static amps_status amps__stroke_nodes(amps_ctx *ctx, amps_scene *S, amps_int npts, const double *pts, double radius,
                                      amps__stroke_node **list, amps_int *nc) {
    amps_int nn = S->m->nnode, i, k, n = 0, *buf, *at;
    amps__stroke_node *L;
    buf = AMPS__CAST(amps_int *, amps__malloc(ctx, 2 * (size_t)nn, sizeof(amps_int)));
    L = AMPS__CAST(amps__stroke_node *, amps__malloc(ctx, (size_t)nn, sizeof(amps__stroke_node)));
    if (!buf || !L) {
        amps__free(ctx, buf);
        amps__free(ctx, L);
        return amps__err(ctx, AMPS_ERR_OOM, "amps_scene_stroke: out of memory");
    }
    at = buf + nn;
    for (k = 0; k < nn; k++) at[k] = -1;
    for (i = 0; i + 1 < npts; i++) {
        amps_int cnt = amps_scene_nodes_near_segment(ctx, S, pts + 3 * i, pts + 3 * i + 3, radius, buf, nn);
        double len2 = 0;
        if (cnt < 0) {
            amps__free(ctx, buf);
            amps__free(ctx, L);
            return (amps_status)cnt;
        }
        for (k = 0; k < 3; k++) len2 += (pts[3 * i + 3 + k] - pts[3 * i + k]) * (pts[3 * i + 3 + k] - pts[3 * i + k]);
        for (k = 0; k < cnt; k++) {
            amps_int v = buf[k];
            double t, d2 = amps__seg_dist2(S->m->xyz + 3 * v, pts + 3 * i, pts + 3 * i + 3, &t);
            if (at[v] < 0) at[v] = n++;
            else if (!(d2 < L[at[v]].d2 - 1e-12 * (L[at[v]].d2 + len2))) continue; /* equal to rounding: the first */
            L[at[v]].v = v;
            L[at[v]].seg = i;
            L[at[v]].t = t;
            L[at[v]].d2 = d2;
        }
    }
    amps__free(ctx, buf);
    amps__sort(L, (size_t)n, sizeof(*L), amps__stroke_cmp);
    *list = L;
    *nc = n;
    return AMPS_OK;
}

/* The cuts of a stroke's nodes L[0..nc-1] in order (in the open batch, or each committed alone),
   reported in out; *ncut the nodes cut. Stops at an error other than a no-op or a refusal. */
static amps_status amps__stroke_cuts(amps_ctx *ctx, amps_scene *S, const amps__stroke_node *L, amps_int nc,
                                     const double *pts, const double *nrm, amps_scene_stroke_result *out,
                                     amps_int *ncut) {
    amps_int i;
    *ncut = 0;
    for (i = 0; i < nc; i++) {
        amps_int vc = -1, sg = L[i].seg;
        amps_status c = amps_scene_cut(ctx, S, L[i].v, pts + 3 * sg, nrm + 3 * sg, &vc);
        if (c != AMPS_OK && c != AMPS_WARN_NOOP && c != AMPS_ERR_SINGULAR_UPDATE) return c;
        if (c == AMPS_OK) ++*ncut;
        if (out && i < out->cap) {
            if (out->node) out->node[i] = L[i].v;
            if (out->copy) out->copy[i] = vc;
            if (out->status) out->status[i] = c;
        }
    }
    return AMPS_OK;
}

AMPS_API amps_status amps_scene_stroke(amps_ctx *ctx, amps_scene *S, amps_int npts, const double *pts,
                                       const double blade[3], double radius, amps_scene_stroke_result *out) {
    amps__stroke_node *L = NULL;
    double *nrm;
    amps_int i, nc = 0, ncut = 0;
    amps_status s;
    int opened = 0;
    if (!S || !pts || !blade || npts < 2) return amps__err(ctx, AMPS_ERR_ARG, "amps_scene_stroke: bad arguments");
    for (i = 0; i < npts; i++)
        if (!amps__pick_ok(pts + 3 * i) || (i < 3 && !amps__isfinite(blade[i])))
            return amps__err(ctx, AMPS_ERR_VALUE,
                             "amps_scene_stroke: the blade is not finite, or a coordinate of the points is NaN, Inf "
                             "or beyond 1e150");
    if (!(radius >= 0) || !amps__isfinite(radius))
        return amps__err(ctx, AMPS_ERR_VALUE, "amps_scene_stroke: radius must be finite and >= 0");
    nrm = AMPS__CAST(double *, amps__malloc(ctx, 3 * (size_t)npts, sizeof(double)));
    if (!nrm) return AMPS_ERR_OOM;
    if ((s = amps__stroke_planes(ctx, npts, pts, blade, nrm)) != AMPS_OK ||
        (s = amps__stroke_nodes(ctx, S, npts, pts, radius, &L, &nc)) != AMPS_OK)
        goto done;
    if (!S->prepared) { /* before the factorization: topology only, as amps_scene_cut */
        s = amps__stroke_cuts(ctx, S, L, nc, pts, nrm, out, &ncut);
        goto report;
    }
    if (!S->batch.open) {
        if ((s = amps_scene_begin_batch(ctx, S)) != AMPS_OK) goto done;
        opened = 1;
    }
    s = amps__stroke_cuts(ctx, S, L, nc, pts, nrm, out, &ncut);
    if (s != AMPS_OK && opened && S->batch.open) amps__scene_batch_abort(S);
    if (s == AMPS_OK && opened && (s = amps_scene_commit(ctx, S)) == AMPS_ERR_SINGULAR_UPDATE) {
        /* the batch was undone: the cuts again, each committed alone, the ones that leave a piece
           loose refused */
        amps__log(ctx, AMPS_OK, "amps_scene_stroke: the stroke's commit is singular; its cuts one commit each");
        s = amps__stroke_cuts(ctx, S, L, nc, pts, nrm, out, &ncut);
    }
report:
    if (out && s == AMPS_OK) {
        out->n = nc;
        out->ncut = ncut;
    }
done:
    amps__free(ctx, nrm);
    amps__free(ctx, L);
    return s;
}

/* ---- dynamics, gravity, removal, runtime materials, fracture ---- */

/* Gravity load of DOF d of node v: m_v g_d (0 without gravity). */
static double amps__scene_body_force(const amps_scene *S, amps_int v, int d) {
    return S->dyn.g[d] == 0.0 ? 0.0 : S->dyn.g[d] * S->node.mass[v];
}

/* Room for nnode nodes in the dynamics arrays (new velocities zero, not orphans). */
static amps_status amps__scene_dyn_room(amps_ctx *ctx, amps_scene *S, amps_int nnode) {
    amps_int v, cap = nnode > S->node.cap ? nnode : S->node.cap;
    size_t c = (size_t)cap;
    if (nnode <= S->dyn.cap) return AMPS_OK;
    if (amps__realloc(ctx, (void **)&S->dyn.vel, 3 * c, sizeof(double)) ||
        amps__realloc(ctx, (void **)&S->dyn.ku, 3 * c, sizeof(double)) ||
        amps__realloc(ctx, (void **)&S->dyn.idx, 3 * c, sizeof(amps_int)) ||
        amps__realloc(ctx, (void **)&S->dyn.val, 3 * c, sizeof(double)) ||
        amps__realloc(ctx, (void **)&S->dyn.orphan, c, 1))
        return amps__err(ctx, AMPS_ERR_OOM, "amps_scene: out of memory for %ld nodes", (long)nnode);
    for (v = S->dyn.cap; v < cap; v++) {
        S->dyn.vel[3 * v] = S->dyn.vel[3 * v + 1] = S->dyn.vel[3 * v + 2] = 0.0;
        S->dyn.orphan[v] = 0;
    }
    S->dyn.cap = cap;
    return AMPS_OK;
}

/* The mass of node v (its tets changed) and its engine forces: its force plus its gravity load
   (statics; dynamics loads each step). */
static amps_status amps__scene_refresh_force(amps_ctx *ctx, amps_scene *S, amps_int v) {
    amps_int idx[3], m = 0;
    double val[3];
    int d;
    amps__scene_mass_node(S, v);
    if (!S->prepared || S->dyn.on) return AMPS_OK;
    for (d = 0; d < 3; d++)
        if (S->node.dof[3 * v + d] >= 0) {
            idx[m] = S->node.dof[3 * v + d];
            val[m++] = amps__scene_orphan(S, v) ? S->dyn.orphan_d * S->node.disp[3 * v + d]
                                                : S->node.force[3 * v + d] + amps__scene_body_force(S, v, d);
        }
    return amps_update_set_force(ctx, S->U, m, idx, val);
}

/* After the cut of v into v and vc: vc moves with v's velocity; the masses of both and their
   gravity loads follow their tets. */
static void amps__scene_dyn_cut(amps_ctx *ctx, amps_scene *S, amps_int v, amps_int vc) {
    int d;
    amps__scene_mass_node(S, v);
    amps__scene_mass_node(S, vc);
    if (vc < 0 || vc >= S->dyn.cap) return;
    for (d = 0; d < 3; d++) S->dyn.vel[3 * vc + d] = S->dyn.vel[3 * v + d];
    S->dyn.orphan[vc] = 0;
    if (S->dyn.g[0] != 0.0 || S->dyn.g[1] != 0.0 || S->dyn.g[2] != 0.0) {
        (void)amps__scene_refresh_force(ctx, S, v);
        (void)amps__scene_refresh_force(ctx, S, vc);
    }
}

/* K u on every DOF (dyn.ku) as (A u - cM M u) / cK with one product by the engine's committed
   matrix A; kept when neither u nor A (nor the equations) changed since the last product (the
   haptic calls between steps move pins only). */
static amps_status amps__scene_dyn_ku(amps_ctx *ctx, amps_scene *S) {
    const amps_mesh *m = S->m;
    amps_update *U = S->U;
    amps_int nn = m->nnode, v, e, N;
    int d, same;
    if (U->pending.n_delta || U->pending.n_dofs) {
        amps_status s = amps_update_commit(ctx, U);
        if (s != AMPS_OK) return s;
    }
    N = amps_update_dim(U);
    if (N > S->dyn.ncap) {
        if (amps__realloc(ctx, (void **)&S->dyn.xe, (size_t)N, sizeof(double)) ||
            amps__realloc(ctx, (void **)&S->dyn.ye, (size_t)N, sizeof(double)))
            return amps__err(ctx, AMPS_ERR_OOM, "amps_scene_step: out of memory");
        S->dyn.ncap = N;
        S->dyn.kukey.ok = 0;
    }
    same = S->dyn.kukey.ok && S->dyn.kukey.kver == U->kver && S->dyn.kukey.cM == S->dyn.cM &&
           S->dyn.kukey.cK == S->dyn.cK;
    for (v = 0; v < 3 * nn && same; v++)
        if ((e = S->node.dof[v]) >= 0 && S->dyn.xe[e] != S->node.disp[v]) same = 0;
    if (same) return AMPS_OK;
    for (e = 0; e < N; e++) S->dyn.xe[e] = 0.0;
    for (v = 0; v < 3 * nn; v++)
        if ((e = S->node.dof[v]) >= 0) S->dyn.xe[e] = S->node.disp[v];
    amps__kmul(U, S->dyn.xe, S->dyn.ye);
    S->dyn.kukey.ok = 1;
    S->dyn.kukey.kver = U->kver;
    S->dyn.kukey.cM = S->dyn.cM;
    S->dyn.kukey.cK = S->dyn.cK;
    for (v = 0; v < nn; v++)
        for (d = 0; d < 3; d++) {
            e = S->node.dof[3 * v + d];
            S->dyn.ku[3 * v + d] =
                    e >= 0 ? (S->dyn.ye[e] - S->dyn.cM * S->node.mass[v] * S->node.disp[3 * v + d]) / S->dyn.cK : 0.0;
        }
    return AMPS_OK;
}

/* The right-hand side and pins of the next step (paper 003 Eq. 27): b = M w + dt (f + M g - K u)
   on every equation, w_P = (g_P - u_P) / dt at the pins (orphans stay at w = 0). Cost: one
   product with the engine's matrix when u or the matrix changed (amps__scene_dyn_ku), else O(N). */
static amps_status amps__scene_dyn_load(amps_ctx *ctx, amps_scene *S) {
    amps_int nn = S->m->nnode, v, n = 0;
    double dt = S->dyn.dt, *u = S->node.disp, *ku, *mass;
    int d;
    amps_status s;
    if ((s = amps__scene_dyn_room(ctx, S, nn)) != AMPS_OK || (s = amps__scene_dyn_ku(ctx, S)) != AMPS_OK) return s;
    ku = S->dyn.ku;
    mass = S->node.mass;
    for (v = 0; v < nn; v++)
        for (d = 0; d < 3; d++)
            if (S->node.dof[3 * v + d] >= 0) {
                amps_int k = 3 * v + d;
                S->dyn.idx[n] = S->node.dof[k];
                S->dyn.val[n++] = S->dyn.orphan[v] ? 0.0
                                                   : mass[v] * S->dyn.vel[k] +
                                                             dt * (S->node.force[k] + mass[v] * S->dyn.g[d] - ku[k]);
            }
    if ((s = amps_update_set_force(ctx, S->U, n, S->dyn.idx, S->dyn.val)) != AMPS_OK) return s;
    for (n = 0, v = 0; v < nn; v++)
        if (S->node.pinned[v] && !S->dyn.orphan[v])
            for (d = 0; d < 3; d++) {
                S->dyn.idx[n] = S->node.dof[3 * v + d];
                S->dyn.val[n++] = (S->node.pin_value[3 * v + d] - u[3 * v + d]) / dt;
            }
    return n ? amps_update_constrain(ctx, S->U, n, S->dyn.idx, S->dyn.val) : AMPS_OK;
}

/* Appends sign * Ae(t) scattered on the equations of its nodes (node w read as rename[w] when
   rename is given). */
static amps_status amps__trips_tet(amps_ctx *ctx, const amps_scene *S, amps__trips *T, amps_int t, double sign,
                                   const amps_int *rename) {
    double Ae[144];
    amps_int e[12];
    int a, b;
    if (T->n + 78 > T->cap) {
        size_t cap = 2 * T->cap + 78 * 16;
        if (amps__realloc(ctx, (void **)&T->e, cap, sizeof(amps__trip)))
            return amps__err(ctx, AMPS_ERR_OOM, "amps_scene: out of memory");
        T->cap = cap;
    }
    amps__scene_tet_matrix(S, t, Ae);
    for (a = 0; a < 12; a++) {
        amps_int w = S->m->tet[4 * t + a / 3];
        e[a] = S->node.dof[3 * (rename ? rename[w] : w) + a % 3];
    }
    for (a = 0; a < 12; a++)
        for (b = 0; b < 12; b++) {
            amps__trip *x;
            if (e[a] < 0 || e[b] < 0 || e[a] > e[b] || (e[a] == e[b] && a > b)) continue;
            x = T->e + T->n++;
            x->r = e[a];
            x->c = e[b];
            x->v = sign * Ae[12 * a + b];
        }
    return AMPS_OK;
}

static int amps__trip_cmp(const void *x, const void *y) {
    const amps__trip *a = (const amps__trip *)x, *b = (const amps__trip *)y;
    if (a->c != b->c) return a->c < b->c ? -1 : 1;
    return a->r < b->r ? -1 : a->r > b->r;
}

/* Records the change T (duplicates summed) with amps_update_add; T emptied, its storage kept. */
static amps_status amps__trips_add(amps_ctx *ctx, amps_scene *S, amps__trips *T) {
    size_t k, nz = 0;
    amps_status s = AMPS_OK;
    if (T->n > 0) {
        amps__sort(T->e, T->n, sizeof(amps__trip), amps__trip_cmp);
        for (k = 1; k < T->n; k++) {
            if (T->e[k].r == T->e[nz].r && T->e[k].c == T->e[nz].c) T->e[nz].v += T->e[k].v;
            else T->e[++nz] = T->e[k];
        }
        nz++;
        if (nz > T->cap_sum) {
            if (amps__realloc(ctx, (void **)&T->r, nz, sizeof(amps_int)) ||
                amps__realloc(ctx, (void **)&T->c, nz, sizeof(amps_int)) ||
                amps__realloc(ctx, (void **)&T->v, nz, sizeof(double)))
                s = amps__err(ctx, AMPS_ERR_OOM, "amps_scene: out of memory");
            else T->cap_sum = nz;
        }
        for (k = 0; !s && k < nz; k++) {
            T->r[k] = T->e[k].r;
            T->c[k] = T->e[k].c;
            T->v[k] = T->e[k].v;
        }
        if (!s) s = amps_update_add(ctx, S->U, (amps_int)nz, T->r, T->c, T->v);
    }
    T->n = 0;
    return s;
}

AMPS_API const double *amps_scene_velocities(const amps_scene *S) { return S ? S->dyn.vel : NULL; }

AMPS_API amps_status amps_scene_set_density(amps_ctx *ctx, amps_scene *S, double rho) {
    if (!S) return amps__err(ctx, AMPS_ERR_ARG, "amps_scene_set_density: NULL scene");
    if (!amps__isfinite(rho) || !(rho > 0))
        return amps__err(ctx, AMPS_ERR_VALUE, "amps_scene_set_density: density %g is not > 0", rho);
    if (S->prepared) return amps__err(ctx, AMPS_ERR_STATE, "amps_scene_set_density: the system is already factored");
    return amps_mesh_set_density(ctx, S->m, rho);
}

AMPS_API amps_status amps_scene_gravity(amps_ctx *ctx, amps_scene *S, const double g[3]) {
    amps_int v;
    amps_status s;
    int d;
    if (!S || !g) return amps__err(ctx, AMPS_ERR_ARG, "amps_scene_gravity: NULL argument");
    if (S->batch.committing) return amps__scene_committing(ctx, "amps_scene_gravity");
    for (d = 0; d < 3; d++)
        if (!amps__isfinite(g[d])) return amps__err(ctx, AMPS_ERR_VALUE, "amps_scene_gravity: non-finite gravity");
    for (d = 0; d < 3; d++) S->dyn.g[d] = g[d];
    for (v = 0; v < S->m->nnode; v++)
        if ((s = amps__scene_refresh_force(ctx, S, v)) != AMPS_OK) return s;
    return AMPS_OK;
}

AMPS_API amps_status amps_scene_dynamics(amps_ctx *ctx, amps_scene *S, double dt, double alpha, double beta) {
    amps_status s;
    if (!S) return amps__err(ctx, AMPS_ERR_ARG, "amps_scene_dynamics: NULL scene");
    if (S->batch.committing) return amps__scene_committing(ctx, "amps_scene_dynamics");
    if (!amps__isfinite(dt) || !(dt > 0) || !amps__isfinite(alpha) || !(alpha >= 0) || !amps__isfinite(beta) ||
        !(beta >= 0))
        return amps__err(ctx, AMPS_ERR_VALUE, "amps_scene_dynamics: need dt > 0, alpha >= 0, beta >= 0 (finite)");
    if (!amps__isfinite(1.0 + alpha * dt) || !amps__isfinite(beta * dt + dt * dt) || !(beta * dt + dt * dt > 0) ||
        !amps__isfinite(1.0 / dt))
        return amps__err(
                ctx, AMPS_ERR_VALUE,
                "amps_scene_dynamics: dt = %g, alpha = %g, beta = %g: 1 + alpha dt = %g or beta dt + dt^2 = %g "
                "out of range",
                dt, alpha, beta, 1.0 + alpha * dt, beta * dt + dt * dt);
    if ((s = amps__scene_dyn_room(ctx, S, S->m->nnode)) != AMPS_OK) return s;
    if (S->dyn.on && S->dyn.dt == dt && S->dyn.alpha == alpha && S->dyn.beta == beta) return AMPS_OK;
    if (S->prepared && S->batch.open && (s = amps_scene_commit(ctx, S)) != AMPS_OK) return s; /* before re-factoring */
    S->dyn.on = 1;
    S->dyn.dt = dt;
    S->dyn.alpha = alpha;
    S->dyn.beta = beta;
    S->dyn.cM = 1.0 + alpha * dt;
    S->dyn.cK = beta * dt + dt * dt;
    if (!S->prepared) return AMPS_OK;
    amps__scene_unprepare(ctx, S); /* a new system matrix: factor it again */
    S->prepared = 0;
    S->watch.stale = 1;
    return amps_scene_prepare(ctx, S);
}

/* Makes *p (workspace of the removal, *cap entries) hold n entries of size bytes: grows by half
   on demand and keeps its contents. */
static amps_status amps__scene_rm_ws(amps_ctx *ctx, void **p, size_t *cap, size_t n, size_t size) {
    size_t c = n + n / 2 + 16;
    if (*p && n <= *cap) return AMPS_OK;
    if (amps__realloc(ctx, p, c, size)) return amps__err(ctx, AMPS_ERR_OOM, "amps_scene_remove: out of memory");
    *cap = c;
    return AMPS_OK;
}

/* The face-connected pieces around the nodes of removal r (amps__mechanism: a piece joined to the
   rest at nodes of one line only, a hinge, and not held off it, is AMPS_ERR_SINGULAR_UPDATE). */
static amps_status amps__scene_removal_pieces(amps_ctx *ctx, amps_scene *S, const amps_mesh_removal *r) {
    const amps_mesh *m = S->m;
    amps_int k, nn = 0, seeds = 0, nt = 0, nj = 0, jn = -1, *nodes = S->dyn.rm_queue;
    unsigned char *seen = S->dyn.rm_seen;
    memset(seen, 0, (size_t)m->nnode + 1);
    for (k = 0; k < 4 * r->ntet + r->nsep; k++) {
        amps_int v = k < 4 * r->ntet ? m->tet[4 * r->tets[k / 4] + k % 4] : r->sep_copy[k - 4 * r->ntet];
        if (seen[v] || m->inc_len[v] == 0) continue;
        seen[v] = 1;
        nodes[nn++] = v;
        seeds += m->inc_len[v];
    }
    if (seeds >= S->mech.npiece) { /* the per-piece arrays for every seed tet */
        size_t n = (size_t)seeds + 1;
        if (amps__realloc(ctx, (void **)&S->mech.piece_parent, n, sizeof(amps_int)) ||
            amps__realloc(ctx, (void **)&S->mech.queue_head, n, sizeof(amps_int)) ||
            amps__realloc(ctx, (void **)&S->mech.queue_tail, n, sizeof(amps_int)) ||
            amps__realloc(ctx, (void **)&S->mech.active, n, sizeof(amps_int)))
            return amps__err(ctx, AMPS_ERR_OOM, "amps_scene_remove: out of memory");
        S->mech.npiece = seeds + 1;
    }
    if (!amps__mechanism(S, nodes, nn, &nt, &nj, &jn)) return AMPS_OK;
    if (nj == 0)
        return amps__err(ctx, AMPS_ERR_SINGULAR_UPDATE,
                         "amps_scene_remove: the removal leaves a piece of %ld tets held by nothing; the removal was "
                         "undone",
                         (long)nt);
    return amps__err(ctx, AMPS_ERR_SINGULAR_UPDATE,
                     "amps_scene_remove: the removal leaves a piece of %ld tets joined to the rest at %ld node%s on "
                     "one line (node %ld) and not held otherwise: it could turn about that line; the removal was "
                     "undone",
                     (long)nt, (long)nj, nj == 1 ? "" : "s", (long)jn);
}

/* The workspace of amps__scene_piece_held for the current nodes, every node unseen. */
static amps_status amps__scene_held_ws(amps_ctx *ctx, amps_scene *S) {
    size_t nn = (size_t)S->m->nnode + 1;
    amps_status s = amps__scene_rm_ws(ctx, (void **)&S->dyn.rm_seen, &S->dyn.rm_seen_cap, nn, 1);
    if (!s) s = amps__scene_rm_ws(ctx, (void **)&S->dyn.rm_queue, &S->dyn.rm_queue_cap, nn, sizeof(amps_int));
    if (!s) memset(S->dyn.rm_seen, 0, nn);
    return s;
}

/* Statics: is the node-connected piece of seed (unseen, in a tet) held by fixed or pinned nodes
   not all on one line? A piece held at points of one line turns about it at zero energy,
   whatever its inside. The piece is explored until its third constrained node off the line of
   the first two, or until it meets a piece found held (rm_seen 1; 2: the piece being explored);
   a held piece's explored nodes are marked 1. Returns 1 if held, else 0 with *ntet (tets, at
   least 1), *ncon and *con (its constrained nodes: their number and the last) describing it. */
static int amps__scene_piece_held(amps_scene *S, amps_int seed, amps_int *ntet, amps_int *ncon, amps_int *con) {
    const amps_mesh *m = S->m;
    amps_int head = 0, tail = 0, i, q, *queue = S->dyn.rm_queue, nt = 0;
    unsigned char *seen = S->dyn.rm_seen;
    amps__line L;
    int joined = 0;
    *ncon = 0;
    *con = -1;
    seen[seed] = 2;
    L.state = 0;
    L.tol = 1e-9 * S->mech.scale;
    queue[tail++] = seed;
    while (head < tail && L.state != 3 && !joined) {
        amps_int v = queue[head++], j;
        if (amps__scene_holds(S, v)) {
            amps__line_add(&L, m->xyz + 3 * v);
            (*ncon)++;
            *con = v;
        }
        nt += m->inc_len[v];
        for (j = 0; j < m->inc_len[v]; j++)
            for (q = 0; q < 4; q++) {
                amps_int w = m->tet[4 * m->inc[m->inc_ptr[v] + j] + q];
                if (seen[w] == 1) joined = 1;
                else if (!seen[w]) {
                    seen[w] = 2;
                    queue[tail++] = w;
                }
            }
    }
    *ntet = nt / 4 > 0 ? nt / 4 : 1;
    if (L.state != 3 && !joined) return 0;
    for (i = 0; i < tail; i++) seen[queue[i]] = 1;
    return 1;
}

/* The tets of a removal: statics requires every node-connected piece around them to be held
   (amps__scene_piece_held; AMPS_ERR_SINGULAR_UPDATE naming the first loose piece), then the
   face-connected pieces around them to be no hinges (amps__scene_removal_pieces). With
   singularity avoidance (REMOVE, SEPARATE) a node-connected piece is face-connected. Cost: the
   tets of the pieces explored. */
static amps_status amps__scene_removal_held(amps_ctx *ctx, amps_scene *S, const amps_mesh_removal *r) {
    const amps_mesh *m = S->m;
    amps_int k;
    amps_status s = amps__scene_held_ws(ctx, S);
    for (k = 0; !s && k < 4 * r->ntet; k++) {
        amps_int seed = m->tet[4 * r->tets[k / 4] + k % 4], ntet, ncon, con;
        if (S->dyn.rm_seen[seed] || m->inc_len[seed] == 0 || amps__scene_piece_held(S, seed, &ntet, &ncon, &con))
            continue;
        if (ncon == 0)
            s = amps__err(ctx, AMPS_ERR_SINGULAR_UPDATE,
                          "amps_scene_remove: the removal leaves a piece of %ld tets (node %ld) held by nothing; "
                          "the removal was undone",
                          (long)ntet, (long)seed);
        else
            s = amps__err(ctx, AMPS_ERR_SINGULAR_UPDATE,
                          "amps_scene_remove: the removal leaves a piece of %ld tets (node %ld) held only at %ld "
                          "constrained node%s on one line (node %ld): it could turn about that line; the removal "
                          "was undone",
                          (long)ntet, (long)seed, (long)ncon, ncon == 1 ? "" : "s", (long)con);
    }
    return s ? s : amps__scene_removal_pieces(ctx, S, r);
}

/* The change of K^ by the removal r: for each tet t removed or moved to a copy (once, though
   two of its nodes may have been separated), Ae(t) on its nodes now if it is live, minus Ae(t) on
   the nodes it had before (rename: each copy of r to the node it was made from, through copies
   of copies). */
static amps_status amps__scene_removal_trips(amps_ctx *ctx, amps_scene *S, const amps_mesh_removal *r, amps_int *rename,
                                             amps__trips *T) {
    amps_int k, n = r->ntet + r->sep_ptr[r->nsep], *ts;
    amps_status s = amps__scene_rm_ws(ctx, (void **)&S->dyn.rm_sort, &S->dyn.rm_sort_cap, (size_t)n, sizeof(amps_int));
    if (s) return s;
    ts = S->dyn.rm_sort;
    for (k = 0; k < S->m->nnode; k++) rename[k] = k;
    for (k = 0; k < r->nsep; k++) rename[r->sep_copy[k]] = rename[r->sep_node[k]];
    memcpy(ts, r->tets, sizeof(amps_int) * (size_t)r->ntet);
    if (r->sep_ptr[r->nsep] > 0) memcpy(ts + r->ntet, r->sep_tets, sizeof(amps_int) * (size_t)r->sep_ptr[r->nsep]);
    amps__sort(ts, (size_t)n, sizeof(amps_int), amps__int_cmp);
    for (k = 0; k < n && !s; k++) {
        if (k > 0 && ts[k] == ts[k - 1]) continue;
        if (!S->m->removed[ts[k]]) s = amps__trips_tet(ctx, S, T, ts[k], 1.0, NULL);
        if (!s) s = amps__trips_tet(ctx, S, T, ts[k], -1.0, rename);
    }
    return s;
}

/* The engine side of the removal r (the mesh already changed): new equations for the separated
   copies, the change of K^ (amps__scene_removal_trips), orphans held (amps__scene_orphan),
   gravity loads of the nodes whose mass changed; one commit (none inside a batch: the batch's).
   In statics the mechanism test (amps__scene_removal_held) comes first: its refusal changes
   nothing in the engine. *nflag receives the orphans flagged. */
static amps_status amps__scene_removal_update(amps_ctx *ctx, amps_scene *S, const amps_mesh_removal *r,
                                              amps_int *rename, amps_int *flagged, amps_int *nflag) {
    const amps_mesh *m = S->m;
    amps__trips *T = &S->trips;
    amps_int k, first;
    amps_status s = AMPS_OK;
    int d;
    *nflag = 0;
    if (!S->dyn.on && (s = amps__scene_removal_held(ctx, S, r)) != AMPS_OK) return s; /* before any engine change */
    for (k = 0; k < r->nsep && !s; k++) {
        amps_int v = r->sep_node[k], c = r->sep_copy[k];
        if (S->node.fixed[v] || S->node.dof[3 * v] < 0) continue;
        if ((s = amps_update_add_dofs(ctx, S->U, 3, &first)) == AMPS_OK)
            for (d = 0; d < 3; d++) S->node.dof[3 * c + d] = first + d;
    }
    T->n = 0;
    if (!s) s = amps__scene_removal_trips(ctx, S, r, rename, T);
    if (!s) s = amps__trips_add(ctx, S, T);
    for (k = 0; k < 4 * r->ntet && !s; k++) { /* orphans: held by their own rows (amps__scene_orphan) */
        amps_int v = m->tet[4 * r->tets[k / 4] + k % 4];
        double val[3];
        if (m->inc_len[v] > 0 || S->dyn.orphan[v] || S->node.dof[3 * v] < 0) continue;
        if (S->dyn.orphan_d == 0) S->dyn.orphan_d = S->U->sigma;
        for (d = 0; d < 3; d++) val[d] = S->dyn.orphan_d;
        if (S->node.pinned[v] && (s = amps_update_release(ctx, S->U, 3, S->node.dof + 3 * v)) != AMPS_OK) break;
        if ((s = amps_update_add(ctx, S->U, 3, S->node.dof + 3 * v, S->node.dof + 3 * v, val)) != AMPS_OK) break;
        S->dyn.orphan[v] = 1 + S->node.pinned[v];
        S->node.pinned[v] = 0;
        flagged[(*nflag)++] = v;
    }
    for (k = 0; k < 4 * r->ntet && !s; k++) s = amps__scene_refresh_force(ctx, S, m->tet[4 * r->tets[k / 4] + k % 4]);
    for (k = 0; k < r->nsep && !s; k++)
        if ((s = amps__scene_refresh_force(ctx, S, r->sep_node[k])) == AMPS_OK)
            s = amps__scene_refresh_force(ctx, S, r->sep_copy[k]);
    if (s) {
        amps_update_discard(S->U);
        return s;
    }
    if (S->batch.open) return AMPS_OK; /* committed with the batch */
    if ((s = amps_update_commit(ctx, S->U)) == AMPS_ERR_SINGULAR_UPDATE)
        amps__err(ctx, s, "amps_scene_remove: the removal leaves a piece held by nothing or by a hinge; undone");
    return s;
}

/* Node state of the copies of r (the origin's fixed flag, displacement and velocity). */
static void amps__scene_removal_copies(amps_scene *S, const amps_mesh_removal *r) {
    amps_int k;
    int d;
    for (k = 0; k < r->nsep; k++) {
        amps_int v = r->sep_node[k], c = r->sep_copy[k];
        S->node.fixed[c] = S->node.fixed[v];
        S->node.pinned[c] = 0;
        S->dyn.orphan[c] = 0;
        for (d = 0; d < 3; d++) {
            S->node.pin_value[3 * c + d] = S->node.force[3 * c + d] = 0.0;
            S->node.disp[3 * c + d] = S->node.disp[3 * v + d];
            S->dyn.vel[3 * c + d] = S->dyn.vel[3 * v + d];
            S->node.dof[3 * c + d] = -1;
        }
    }
}

/* A change inside an open batch that failed for lack of memory or capacity undoes the batch, as
   one that failed after reaching the engine. Returns s. */
static amps_status amps__scene_batch_failed(amps_scene *S, amps_status s) {
    if (S->batch.open && (s == AMPS_ERR_OOM || s == AMPS_ERR_CAPACITY)) amps__scene_batch_abort(S);
    return s;
}

/* Removal with the report in *out (see amps_scene_remove). Inside a batch its engine changes
   wait for the batch's commit and it is logged to be undone with the batch; a failure after
   its engine changes, or for lack of memory, undoes the batch. */
static amps_status amps__scene_remove(amps_ctx *ctx, amps_scene *S, amps_int n, const amps_int *tets,
                                      amps_singular_policy policy, amps_mesh_removal *out) {
    amps_int k, nflag = 0, nn0 = S->m->nnode, *rename = NULL, *flagged = NULL;
    amps_status s;
    amps_ctx c2;
    int engine = 0; /* the removal reached the engine */
    if (S->batch.committing) return amps__scene_committing(ctx, "amps_scene_remove");
    if (S->prepared && !S->batch.open && (s = amps_update_commit(ctx, S->U)) != AMPS_OK)
        return s; /* earlier changes first */
    if ((s = amps__scene_dyn_room(ctx, S, nn0)) != AMPS_OK || (s = amps_mesh_remove(ctx, S->m, n, tets, policy, out)))
        return amps__scene_batch_failed(S, s);
    if (S->m->nnode > S->node.cap &&
        amps__scene_grow(ctx, S, S->m->node_cap > S->m->nnode ? S->m->node_cap : S->m->nnode))
        s = amps__err(ctx, AMPS_ERR_OOM, "amps_scene_remove: out of memory");
    if (!s) s = amps__scene_dyn_room(ctx, S, S->m->nnode);
    if (!s) {
        amps__scene_removal_copies(S, out);
        s = amps__scene_rm_ws(ctx, (void **)&S->dyn.rm_flag, &S->dyn.rm_flag_cap, 4 * (size_t)out->ntet + 1,
                              sizeof(amps_int));
        if (!s)
            s = amps__scene_rm_ws(ctx, (void **)&S->dyn.rm_rename, &S->dyn.rm_rename_cap, (size_t)S->m->nnode + 1,
                                  sizeof(amps_int));
        flagged = S->dyn.rm_flag;
        rename = S->dyn.rm_rename;
    }
    for (k = 0; !s && !S->prepared && k < 4 * out->ntet; k++) /* before the factorization: topology only */
        if (S->m->inc_len[S->m->tet[4 * out->tets[k / 4] + k % 4]] == 0)
            S->node.pinned[S->m->tet[4 * out->tets[k / 4] + k % 4]] = 0;
    if (!s && S->prepared) {
        s = amps__scene_removal_update(ctx, S, out, rename, flagged, &nflag);
        engine = s != AMPS_ERR_SINGULAR_UPDATE || !S->batch.open; /* a batch's refusal comes first */
    }
    if (!s && S->batch.open &&
        (s = amps__scene_batch_room(ctx, S, amps__scene_removal_log_len(S, out, nflag), 0)) == AMPS_OK)
        amps__scene_batch_removal(S, out, flagged, nflag);
    if (s) { /* the scene as it was */
        amps__scene_unremove_nodes(S, flagged, nflag, nn0);
        amps_ctx_init(&c2);
        (void)amps_mesh_unremove(&c2, S->m, out);
        amps__scene_unremove_forces(S, out->tets, out->ntet, out->sep_node, out->nsep);
        if (S->batch.open && (engine || s == AMPS_ERR_OOM || s == AMPS_ERR_CAPACITY)) amps__scene_batch_abort(S);
        return s;
    }
    /* rendering data: the separations' copies, then the faces around the removed tets */
    for (k = 0; k < out->nsep; k++) amps__scene_cut_recorded(ctx, S, out->sep_node[k], out->sep_copy[k]);
    amps__scene_faces_changed(ctx, S, out->tets, out->ntet);
    return s;
}

AMPS_API amps_status amps_scene_remove(amps_ctx *ctx, amps_scene *S, amps_int n, const amps_int *tets,
                                       amps_singular_policy policy, amps_mesh_removal *report) {
    amps_mesh_removal r;
    if (!S) return amps__err(ctx, AMPS_ERR_ARG, "amps_scene_remove: NULL scene");
    return amps__scene_remove(ctx, S, n, tets, policy, report ? report : &r);
}

static amps_status amps__scene_corot_step(amps_ctx *ctx, amps_scene *S);
static void amps__cr_frames(amps_scene *S);
static void amps__cr_pin_frames(amps_scene *S);
static void amps__cr_pass(amps_scene *S, int mode);
static void amps__cr_sigma(const amps_scene *S, amps_int t, const double *G, const double *Rt, double sigma[6]);

/* Threads for a scene pass over n items: the engine's, 1 for n <= 2048 or inside a two-phase
   commit's run (it may hold the workers). */
static int amps__scene_nthr(const amps_scene *S, amps_int n) {
    return n > 2048 && !S->batch.committing ? S->U->nthr : 1;
}

/* flag[t] for the tets t in [b, e): 1 when t is live and the largest magnitude of its principal
   stresses (amps__cr_sigma with the rotations in cr_R when corotational, amps_tet_stress
   otherwise) exceeds the threshold of its region, else 0. */
typedef struct amps__fracjob {
    const amps_scene *S;
    amps_int *flag;
} amps__fracjob;

static void amps__scene_frac_tets(amps_int b, amps_int e, int slot, void *arg) {
    const amps__fracjob *j = AMPS__CAST(const amps__fracjob *, arg);
    const amps_scene *S = j->S;
    const amps_mesh *m = S->m;
    amps_int t;
    (void)slot;
    for (t = b; t < e; t++) {
        double X[12], u[12], sg[6], pr[3], mx, fr, smax = S->dyn.sigma_max;
        amps_int k;
        int a;
        j->flag[t] = 0;
        if (m->removed && m->removed[t]) continue;
        for (k = 0; k < S->dyn.nfreg; k++)
            if (S->dyn.freg_id[k] == (m->region ? m->region[t] : 0)) smax = S->dyn.freg_sigma[k];
        if (smax <= 0) continue;
        if (S->dyn.corot && S->dyn.cr_G) amps__cr_sigma(S, t, S->dyn.cr_G + 12 * t, S->dyn.cr_R + 9 * t, sg);
        else {
            amps_mesh_tet_coords(m, t, X); /* linear: from the reference shape and the displacements */
            for (a = 0; a < 12; a++) u[a] = S->node.disp[3 * m->tet[4 * t + a / 3] + a % 3];
            amps_tet_stress(X, m->E[t], m->nu[t], u, sg, NULL, NULL);
        }
        /* max |sigma_i| lies in [|sigma|_F / sqrt 3, |sigma|_F]: the eigenvalues only in between */
        fr = sg[0] * sg[0] + sg[1] * sg[1] + sg[2] * sg[2] + 2 * (sg[3] * sg[3] + sg[4] * sg[4] + sg[5] * sg[5]);
        if (!(fr > smax * smax)) continue;
        if (!(fr > 3 * smax * smax)) {
            amps_sym3_eig(sg, pr);
            mx = fabs(pr[0]) > fabs(pr[2]) ? fabs(pr[0]) : fabs(pr[2]);
            if (!(mx > smax)) continue;
        }
        j->flag[t] = 1;
    }
}

/* Tets whose largest principal stress magnitude exceeds sigma_max are removed (default policy);
   the stresses in parallel on the engine's threads, the list in index order. */
static amps_status amps__scene_fracture_step(amps_ctx *ctx, amps_scene *S) {
    const amps_mesh *m = S->m;
    amps_int t, n = 0, *list;
    amps_mesh_removal r;
    amps_status s = AMPS_OK;
    amps__fracjob j;
    int any = S->dyn.sigma_max > 0;
    S->dyn.nfractured = 0;
    for (t = 0; t < S->dyn.nfreg && !any; t++) any = S->dyn.freg_sigma[t] > 0;
    if (!any) return AMPS_OK; /* no threshold anywhere: no stress pass */
    if ((s = amps__scene_rm_ws(ctx, (void **)&S->dyn.rm_list, &S->dyn.rm_list_cap, (size_t)m->ntet,
                               sizeof(amps_int))) != AMPS_OK)
        return s;
    list = S->dyn.rm_list;
    if (S->dyn.corot && S->dyn.cr_G) { /* the rotations of the new state (kept for the next step) */
        amps__cr_pass(S, 2);
        S->dyn.cr_rvalid = 1;
    }
    j.S = S;
    j.flag = list;
    amps__par_for(&S->U->par, amps__scene_nthr(S, m->ntet), m->ntet, 256, amps__scene_frac_tets, &j);
    for (t = 0; t < m->ntet; t++) /* in place: n <= t */
        if (list[t]) list[n++] = t;
    if (n > 0 && (s = amps__scene_remove(ctx, S, n, list, AMPS_SINGULAR_REMOVE, &r)) == AMPS_OK) {
        S->dyn.nfractured = r.ntet;
        S->dyn.nfractured_total += r.ntet;
    }
    return s;
}

AMPS_API amps_status amps_scene_step(amps_ctx *ctx, amps_scene *S, amps_int nsteps) {
    amps_int k, v;
    amps_status s = AMPS_OK, w = AMPS_OK;
    if (!S || nsteps < 0) return amps__err(ctx, AMPS_ERR_ARG, "amps_scene_step: NULL scene or negative step count");
    if (S->batch.committing) return amps__scene_committing(ctx, "amps_scene_step");
    if (!S->dyn.on)
        return amps__err(ctx, AMPS_ERR_STATE, "amps_scene_step: the scene is static (call amps_scene_dynamics first)");
    if (!S->prepared && (s = amps_scene_prepare(ctx, S)) != AMPS_OK) return s;
    if (S->batch.open && (s = amps_scene_commit(ctx, S)) != AMPS_OK) return s; /* as the solves */
    for (k = 0; k < nsteps; k++) {
        const double *x;
        int d;
        if (S->dyn.corot) {
            if ((s = amps__scene_corot_step(ctx, S)) < 0) return s;
            if (s > 0) w = s;
            goto stepped;
        }
        if ((s = amps__scene_dyn_load(ctx, S)) != AMPS_OK) return s;
        if ((s = amps_update_solve(ctx, S->U, NULL)) < 0) return s;
        if (s > 0) w = s;
        x = amps_update_solution(S->U);
        for (v = 0; v < S->m->nnode; v++)
            for (d = 0; d < 3; d++) {
                amps_int e = S->node.dof[3 * v + d];
                double wv = e >= 0 && !S->dyn.orphan[v] ? x[e] : 0.0;
                S->dyn.vel[3 * v + d] = wv;
                S->node.disp[3 * v + d] += S->dyn.dt * wv;
            }
        S->dyn.info.corotational = 0;
        S->dyn.info.iterations = 0;
        S->dyn.info.relres = -1;
    stepped:
        S->dyn.nstep++;
        S->dyn.nfractured = 0;
        if ((S->dyn.sigma_max > 0 || S->dyn.nfreg > 0) && (s = amps__scene_fracture_step(ctx, S)) != AMPS_OK) return s;
        if (S->dyn.corot && S->dyn.crH.used) amps__cr_pin_frames(S); /* for the haptic calls to come */
    }
    return w;
}

AMPS_API amps_status amps_scene_fracture(amps_ctx *ctx, amps_scene *S, double sigma_max) {
    if (!S) return amps__err(ctx, AMPS_ERR_ARG, "amps_scene_fracture: NULL scene");
    if (sigma_max != sigma_max) return amps__err(ctx, AMPS_ERR_VALUE, "amps_scene_fracture: NaN threshold");
    S->dyn.sigma_max = sigma_max > 0 ? sigma_max : 0.0;
    return AMPS_OK;
}

AMPS_API amps_status amps_scene_fracture_region(amps_ctx *ctx, amps_scene *S, amps_int id, double sigma_max) {
    amps_int k, n;
    if (!S) return amps__err(ctx, AMPS_ERR_ARG, "amps_scene_fracture_region: NULL scene");
    if (sigma_max != sigma_max) return amps__err(ctx, AMPS_ERR_VALUE, "amps_scene_fracture_region: NaN threshold");
    for (k = 0, n = 0; k < S->m->ntet && !n; k++) n = (S->m->region ? S->m->region[k] : 0) == id;
    if (!n) return amps__err(ctx, AMPS_ERR_ARG, "amps_scene_fracture_region: no tetrahedron has region %ld", (long)id);
    for (k = 0; k < S->dyn.nfreg && S->dyn.freg_id[k] != id; k++) {}
    if (k == S->dyn.nfreg) {
        if (amps__realloc(ctx, (void **)&S->dyn.freg_id, (size_t)k + 1, sizeof(amps_int)) ||
            amps__realloc(ctx, (void **)&S->dyn.freg_sigma, (size_t)k + 1, sizeof(double)))
            return amps__err(ctx, AMPS_ERR_OOM, "amps_scene_fracture_region: out of memory");
        S->dyn.freg_id[k] = id;
        S->dyn.nfreg++;
    }
    S->dyn.freg_sigma[k] = sigma_max > 0 ? sigma_max : 0.0;
    return AMPS_OK;
}

AMPS_API amps_int amps_scene_fractured(const amps_scene *S, amps_int *total) {
    if (total) *total = S ? S->dyn.nfractured_total : 0;
    return S ? S->dyn.nfractured : 0;
}

/* Runtime material change of tets[0..n-1] to (E, nu) and, if rho > 0, rho: the change of their
   element matrices as one update (statics: the gravity loads of their nodes follow), committed
   at once or, inside a batch, logged and committed with it. The mesh values (and the masses and
   loads) are restored on failure; a failure after the engine changes, or for lack of memory,
   undoes an open batch. The old values go to the batch's double log (past its end outside a
   batch). */
static amps_status amps__scene_retet(amps_ctx *ctx, amps_scene *S, amps_int n, const amps_int *tets, double E,
                                     double nu, double rho, const char *fn) {
    amps_mesh *m = S->m;
    amps__trips *T = &S->trips;
    amps_int k;
    double *old;
    amps_status s;
    amps_ctx c2;
    if ((s = amps__check_material(ctx, fn, E, nu)) != AMPS_OK) return s;
    if (!amps__isfinite(rho)) return amps__err(ctx, AMPS_ERR_VALUE, "%s: non-finite density", fn);
    if (S->batch.committing) return amps__scene_committing(ctx, fn);
    if (rho > 0 && !m->rho && (s = amps_mesh_set_density(ctx, m, 1.0)) != AMPS_OK)
        return amps__scene_batch_failed(S, s);
    if (!S->batch.open && (s = amps_update_commit(ctx, S->U)) != AMPS_OK) return s; /* earlier changes first */
    if ((s = amps__scene_batch_room(ctx, S, n, 3 * n)) != AMPS_OK) return amps__scene_batch_failed(S, s);
    old = S->batch.dlog + S->batch.ndlog;
    T->n = 0;
    for (k = 0; k < n && !s; k++)
        if (!(m->removed && m->removed[tets[k]])) s = amps__trips_tet(ctx, S, T, tets[k], -1.0, NULL);
    for (k = 0; k < n; k++) {
        amps_int t = tets[k];
        old[3 * k] = m->E[t];
        old[3 * k + 1] = m->nu[t];
        old[3 * k + 2] = m->rho ? m->rho[t] : 1.0;
        m->E[t] = E;
        m->nu[t] = nu;
        if (rho > 0) m->rho[t] = rho;
    }
    for (k = 0; k < n && !s; k++)
        if (!(m->removed && m->removed[tets[k]])) s = amps__trips_tet(ctx, S, T, tets[k], 1.0, NULL);
    if (!s) s = amps__trips_add(ctx, S, T);
    for (k = 0; k < 4 * n && !s && rho > 0; k++) s = amps__scene_refresh_force(ctx, S, m->tet[4 * tets[k / 4] + k % 4]);
    if (!s && S->batch.open) {
        amps__scene_batch_material(S, n, tets, rho > 0);
        return AMPS_OK;
    }
    if (!s) s = amps_update_commit(ctx, S->U);
    else amps_update_discard(S->U);
    if (!s) return AMPS_OK;
    for (k = 0; k < n; k++) {
        m->E[tets[k]] = old[3 * k];
        m->nu[tets[k]] = old[3 * k + 1];
        if (rho > 0) m->rho[tets[k]] = old[3 * k + 2];
    }
    amps_ctx_init(&c2); /* a discard keeps the engine's forces */
    for (k = 0; k < 4 * n && rho > 0; k++) (void)amps__scene_refresh_force(&c2, S, m->tet[4 * tets[k / 4] + k % 4]);
    if (S->batch.open) amps__scene_batch_undo(S); /* the engine discarded it */
    return s;
}

AMPS_API amps_status amps_scene_set_tet_material(amps_ctx *ctx, amps_scene *S, amps_int t, double E, double nu) {
    if (!S) return amps__err(ctx, AMPS_ERR_ARG, "amps_scene_set_tet_material: NULL scene");
    if (t < 0 || t >= S->m->ntet)
        return amps__err(ctx, AMPS_ERR_INDEX, "amps_scene_set_tet_material: tetrahedron %ld out of range [0, %ld)",
                         (long)t, (long)S->m->ntet);
    if (!S->prepared) return amps_mesh_set_tet_material(ctx, S->m, t, E, nu);
    return amps__scene_retet(ctx, S, 1, &t, E, nu, 0.0, "amps_scene_set_tet_material");
}

/* The tets of region id (ascending) into a new array; *n their number. */
static amps_int *amps__scene_region_tets(amps_ctx *ctx, const amps_mesh *m, amps_int id, amps_int *n) {
    amps_int t, *list = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)m->ntet, sizeof(amps_int)));
    *n = 0;
    if (!list) return NULL;
    for (t = 0; t < m->ntet; t++)
        if ((m->region ? m->region[t] : 0) == id || id == AMPS__IMAX) list[(*n)++] = t;
    return list;
}

AMPS_API amps_status amps_scene_set_region(amps_ctx *ctx, amps_scene *S, amps_int id, double E, double nu, double rho) {
    amps_int n, *list;
    amps_status s;
    const char *fn = "amps_scene_set_region";
    if (!S) return amps__err(ctx, AMPS_ERR_ARG, "%s: NULL scene", fn);
    if ((s = amps__check_material(ctx, fn, E, nu)) != AMPS_OK) return s;
    if (!amps__isfinite(rho) || rho < 0) return amps__err(ctx, AMPS_ERR_VALUE, "%s: density %g is not >= 0", fn, rho);
    if (!S->prepared) return amps_mesh_set_region_material(ctx, S->m, id, E, nu, rho);
    if (!(list = amps__scene_region_tets(ctx, S->m, id, &n)))
        return amps__scene_batch_failed(S, amps__err(ctx, AMPS_ERR_OOM, "%s: out of memory", fn));
    s = n ? amps__scene_retet(ctx, S, n, list, E, nu, rho, fn)
          : amps__err(ctx, AMPS_ERR_ARG, "%s: no tetrahedron has region %ld", fn, (long)id);
    amps__free(ctx, list);
    return s;
}

/* amps_scene_set_material after the factorization: every tet, as one update. */
static amps_status amps__scene_set_material_all(amps_ctx *ctx, amps_scene *S, double E, double nu) {
    amps_int n, *list = amps__scene_region_tets(ctx, S->m, AMPS__IMAX, &n);
    amps_status s;
    if (!list)
        return amps__scene_batch_failed(S, amps__err(ctx, AMPS_ERR_OOM, "amps_scene_set_material: out of memory"));
    s = amps__scene_retet(ctx, S, n, list, E, nu, 0.0, "amps_scene_set_material");
    amps__free(ctx, list);
    return s;
}

/* ---- corotational dynamics ---- */

/* Tests may define AMPS_TEST_COROT_IDENTITY (an int expression) to make every R_e = I. */
#ifndef AMPS_TEST_COROT_IDENTITY
#define AMPS_TEST_COROT_IDENTITY 0
#endif

/* A pass of the corotational step over every tet and node: mode 0 rotations R_e, Lame
   constants and elastic forces g_e = R K0 (R^T x - X) per tet into cr_ye, then per node g, and
   the node rotations Rn; mode 2 the rotations only; mode 3 the rotations and Rn. */
typedef struct amps__crjob {
    const amps_scene *S;
    int mode;
    int frames;  /* the node pass computes Rn */
    amps_int np; /* the parts of the node pass */
} amps__crjob;

/* F = I + sum_a u_a G_a^T of tet t from the displacements u (3 per node). */
static void amps__cr_deform(const amps_scene *S, amps_int t, const double *G, double F[9]) {
    const amps_int *tv = S->m->tet + 4 * t;
    int a, i, j;
    AMPS__UNROLL
    for (i = 0; i < 9; i++) F[i] = (i % 4 == 0) ? 1.0 : 0.0;
    AMPS__UNROLL
    for (a = 0; a < 4; a++) {
        const double *u = S->node.disp + 3 * tv[a];
        AMPS__UNROLL
        for (i = 0; i < 3; i++)
            for (j = 0; j < 3; j++) F[3 * i + j] += u[i] * G[3 * a + j];
    }
}

/* Per tet t in [b, e): R (unless cr_rvalid); in mode 0 H = R^T F - I (the displacement gradient in
   the rotated frame), sigma = lambda V tr(H) I + mu V (H + H^T) and ye_a = R sigma G_a. */
static void amps__cr_tets(amps_int b, amps_int e, int slot, void *arg) {
    const amps__crjob *j = AMPS__CAST(const amps__crjob *, arg);
    const amps_scene *S = j->S;
    const amps_mesh *m = S->m;
    amps_int t;
    (void)slot;
    for (t = b; t < e; t++) {
        const double *G = S->dyn.cr_G + 12 * t;
        double *R = S->dyn.cr_R + 9 * t, *lm = S->dyn.cr_lm + 2 * t, *ye = S->dyn.cr_ye + 12 * t;
        double H[9], F[9], sg[9], tr;
        int a, i, k;
        if ((m->removed && m->removed[t]) || (j->mode != 0 && S->dyn.cr_rvalid)) continue;
        amps__cr_deform(S, t, G, F);
        if (!S->dyn.cr_rvalid) {
            if (AMPS_TEST_COROT_IDENTITY)
                for (i = 0; i < 9; i++) R[i] = (i % 4 == 0) ? 1.0 : 0.0;
            else amps__polar(F, R);
        }
        if (j->mode != 0) continue;
        amps__lame(m->E[t], m->nu[t], lm, lm + 1);
        lm[0] *= S->dyn.vol[t];
        lm[1] *= S->dyn.vol[t];
        AMPS__UNROLL
        for (i = 0; i < 3; i++)
            for (k = 0; k < 3; k++)
                H[3 * i + k] = R[i] * F[k] + R[3 + i] * F[3 + k] + R[6 + i] * F[6 + k] - (i == k ? 1.0 : 0.0);
        tr = lm[0] * (H[0] + H[4] + H[8]);
        AMPS__UNROLL
        for (i = 0; i < 3; i++)
            for (k = 0; k < 3; k++) sg[3 * i + k] = lm[1] * (H[3 * i + k] + H[3 * k + i]) + (i == k ? tr : 0.0);
        AMPS__UNROLL
        for (a = 0; a < 4; a++) {
            double f[3];
            AMPS__UNROLL
            for (i = 0; i < 3; i++)
                f[i] = sg[3 * i] * G[3 * a] + sg[3 * i + 1] * G[3 * a + 1] + sg[3 * i + 2] * G[3 * a + 2];
            AMPS__UNROLL
            for (i = 0; i < 3; i++) ye[3 * a + i] = R[3 * i] * f[0] + R[3 * i + 1] * f[1] + R[3 * i + 2] * f[2];
        }
    }
}

/* [*lo, *hi): the nodes of parts [p0, p1) of np, part k the nodes [k nnode / np, (k+1) nnode / np). */
static void amps__cr_part(const amps_mesh *m, amps_int p0, amps_int p1, amps_int np, amps_int *lo, amps_int *hi) {
    *lo = (amps_int)((double)p0 * m->nnode / np);
    *hi = p1 == np ? m->nnode : (amps_int)((double)p1 * m->nnode / np);
}

/* 1 if one of the 4 nodes tv lies in [lo, hi). */
static int amps__cr_touches(const amps_int *tv, amps_int lo, amps_int hi) {
    return (tv[0] >= lo && tv[0] < hi) || (tv[1] >= lo && tv[1] < hi) || (tv[2] >= lo && tv[2] < hi) ||
           (tv[3] >= lo && tv[3] < hi);
}

/* The serial of the current state (u, the nodes, the removals; u moves only in steps): advanced
   when (steps, nodes, removals) differ from those of the last call. */
static long amps__cr_serial(amps_scene *S) {
    amps__scene_dyn *D = &S->dyn;
    long key[3];
    key[0] = (long)D->nstep;
    key[1] = (long)S->m->nnode;
    key[2] = (long)S->m->nremoved;
    if (memcmp(key, D->cr_rnkey, sizeof(key))) {
        memcpy(D->cr_rnkey, key, sizeof(key));
        D->cr_serial++;
    }
    return D->cr_serial;
}

/* 1 if cr_Rn holds every node frame of the current state. */
static int amps__cr_frames_valid(amps_scene *S) { return S->dyn.cr_rnall == amps__cr_serial(S); }

/* The frame of node v from the rotations of the last pass: Rn_v = the polar factor of the sum of
   |V_t| R_t over its live tets in index order (the incidence list), as amps__cr_nodes sums it. */
static void amps__cr_node_frame(const amps_scene *S, amps_int v) {
    const amps_mesh *m = S->m;
    double Rs[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0};
    amps_int q;
    int d;
    for (q = m->inc_ptr[v]; q < m->inc_ptr[v] + m->inc_len[v]; q++)
        for (d = 0; d < 9; d++) Rs[d] += S->dyn.vol[m->inc[q]] * S->dyn.cr_R[9 * m->inc[q] + d];
    amps__polar(Rs, S->dyn.cr_Rn + 9 * v);
}

/* The nodes of parts [p0, p1) of np (part k: nodes [k nnode / np, (k+1) nnode / np)): g_v = the
   sum of the element results of its live tets (mode 0) and the node rotation Rn_v (nearest to the
   volume-weighted mean of their R_e), the tets in index order (streamed, which reads the tets'
   arrays in order, where a gather through the incidence lists misses the cache: 2.5 against 1.6
   ms on the brain; the same sums for any np). */
static void amps__cr_nodes(amps_int p0, amps_int p1, int slot, void *arg) {
    const amps__crjob *j = AMPS__CAST(const amps__crjob *, arg);
    const amps_scene *S = j->S;
    const amps_mesh *m = S->m;
    amps_int lo, hi, v, t;
    double *g = S->dyn.cr_gel, *Rn = S->dyn.cr_Rn;
    (void)slot;
    amps__cr_part(m, p0, p1, j->np, &lo, &hi);
    if (j->mode == 0) memset(g + 3 * (size_t)lo, 0, sizeof(double) * 3 * (size_t)(hi - lo));
    if (j->frames) memset(Rn + 9 * (size_t)lo, 0, sizeof(double) * 9 * (size_t)(hi - lo));
    for (t = 0; t < m->ntet; t++) {
        const amps_int *tv = m->tet + 4 * t;
        const double *ye = S->dyn.cr_ye + 12 * t, *R = S->dyn.cr_R + 9 * t;
        int a, d;
        if (!amps__cr_touches(tv, lo, hi) || (m->removed && m->removed[t])) continue;
        AMPS__UNROLL
        for (a = 0; a < 4; a++) {
            amps_int w = tv[a];
            if (w < lo || w >= hi) continue;
            if (j->mode == 0)
                for (d = 0; d < 3; d++) g[3 * w + d] += ye[3 * a + d];
            if (j->frames)
                for (d = 0; d < 9; d++) Rn[9 * w + d] += S->dyn.vol[t] * R[d];
        }
    }
    for (v = lo; v < hi && j->frames; v++) {
        double Rs[9];
        memcpy(Rs, Rn + 9 * v, sizeof(Rs));
        amps__polar(Rs, Rn + 9 * v);
    }
}

/* One pass (see amps__crjob) over every tet and node; parallel on the engine's threads. Mode 0
   computes Rn only when the last step's PCG ended with the engine's preconditioner (the frames
   are its; amps__cr_frames makes them when a step turns to it) and they are not already those
   of this state. R is then that of the current u (cr_rvalid) until the step moves it. */
static void amps__cr_pass(amps_scene *S, int mode) {
    amps__crjob j;
    j.S = S;
    j.mode = mode;
    j.frames = mode == 3 || (mode == 0 && !amps__cr_frames_valid(S) &&
                             (S->dyn.info.iterations == 0 || S->dyn.info.iterations > S->dyn.info.iterations_gs));
    j.np = amps__scene_nthr(S, S->m->nnode);
    amps__par_for(&S->U->par, amps__scene_nthr(S, S->m->ntet), S->m->ntet, 256, amps__cr_tets, &j);
    if (mode != 2) amps__par_for(&S->U->par, (int)j.np, j.np, 1, amps__cr_nodes, &j);
    S->dyn.cr_rvalid = 1;
    if (j.frames) S->dyn.cr_rnall = amps__cr_serial(S);
}

/* Every node frame Rn of the current state (the engine's preconditioner), once per state. */
static void amps__cr_frames(amps_scene *S) {
    if (!amps__cr_frames_valid(S)) amps__cr_pass(S, 3);
}

/* The frames Rn_v of the pinned nodes of the current state (the haptic path), each once per
   state: the rotations R_e first unless valid (the next step keeps them), then
   amps__cr_node_frame per pinned node (the same bits as the node pass). */
static void amps__cr_pin_frames(amps_scene *S) {
    amps__scene_dyn *D = &S->dyn;
    long ser = amps__cr_serial(S);
    amps_int v;
    if (D->cr_rnall == ser) return;
    if (!D->cr_rvalid) amps__cr_pass(S, 2);
    for (v = 0; v < S->m->nnode; v++)
        if (S->node.pinned[v] && D->cr_rnst[v] != ser) {
            amps__cr_node_frame(S, v);
            D->cr_rnst[v] = ser;
        }
}

/* ---- the assembled A_R: 3x3 blocks by node ---- */

/* The position of node w in bj[lo .. hi] (ordered by rank; w is there), by bisection. */
static amps_int amps__cr_find(const amps_int *bj, const amps_int *rank, amps_int lo, amps_int hi, amps_int w) {
    while (lo < hi) {
        amps_int mid = lo + (hi - lo) / 2;
        if (rank[bj[mid]] < rank[w]) lo = mid + 1;
        else hi = mid;
    }
    return lo;
}

/* The Gauss-Seidel order of the nodes (crA.ord, crA.rank, crA.np, crA.pp) for the rows bp, bj of
   the pattern (nn nodes; part: nn of workspace). np slabs of equal node counts across the longest
   axis of the reference box (np = 1, 2, 4, ... <= AMPS__CR_PARTS, about AMPS__CR_SLAB nodes a
   slab); the nodes of a slab without a neighbour in another slab come first, slab by slab, then
   the others (the interface). A slab then depends only on itself and the interface, so the
   slabs of a sweep run in parallel. Within a slab and the interface the nodes go by a greedy
   colouring (no two neighbours share a colour), then by index: consecutive rows of a sweep do
   not wait for each other. The order depends on the mesh alone (the same bits on any number of
   threads). */
static void amps__cr_order(amps_scene *S, const amps_int *bp, const amps_int *bj, amps_int nn, amps_int *part) {
    enum { NB = 512 };
    const double *xyz = S->m->xyz;
    amps_int hist[NB], at[AMPS__CR_PARTS + 2], np = 1, v, q, k, n = 0, ncol = 0;
    amps_int *ord = S->dyn.crA.ord, *pp = S->dyn.crA.pp, *col = S->dyn.crA.wgs, *stamp = col + nn, *cc = stamp + nn;
    amps_int *bycol = S->dyn.crA.rank;
    double lo[3], hi[3], w;
    int ax = 0, d;
    while (np < AMPS__CR_PARTS && 2 * np * AMPS__CR_SLAB <= nn) np *= 2;
    for (d = 0; d < 3; d++) lo[d] = hi[d] = nn ? xyz[d] : 0.0;
    for (v = 0; v < nn; v++)
        for (d = 0; d < 3; d++) {
            if (xyz[3 * v + d] < lo[d]) lo[d] = xyz[3 * v + d];
            if (xyz[3 * v + d] > hi[d]) hi[d] = xyz[3 * v + d];
        }
    for (d = 1; d < 3; d++)
        if (hi[d] - lo[d] > hi[ax] - lo[ax]) ax = d;
    w = hi[ax] > lo[ax] ? (double)NB / (hi[ax] - lo[ax]) : 0.0;
    /* slab of node v: its bin's place in the cumulative counts, so the slabs hold about nn / np */
    for (k = 0; k < NB; k++) hist[k] = 0;
    for (v = 0; v < nn; v++) {
        amps_int b = (amps_int)((xyz[3 * v + ax] - lo[ax]) * w);
        part[v] = b < 0 ? 0 : b >= NB ? NB - 1 : b;
        hist[part[v]]++;
    }
    for (k = 0; k < NB; k++) { /* hist[k]: the slab of bin k (by the nodes before its middle) */
        amps_int c = hist[k];
        hist[k] = (amps_int)(((double)n + 0.5 * (double)c) * (double)np / (double)(nn ? nn : 1));
        if (hist[k] >= np) hist[k] = np - 1;
        n += c;
    }
    for (v = 0; v < nn; v++) part[v] = hist[part[v]];
    for (v = 0; v < nn; v++) /* the interface (np): one end of every edge between two slabs */
        for (q = bp[v]; q < bp[v + 1] && part[v] < np; q++)
            if (part[bj[q]] != part[v] && part[bj[q]] < np) part[v] = np;
    /* greedy colouring in index order: the smallest colour no earlier neighbour has */
    for (v = 0; v < nn; v++) stamp[v] = -1;
    for (v = 0; v < nn; v++) {
        amps_int c = 0;
        for (q = bp[v]; q < bp[v + 1]; q++)
            if (bj[q] < v) stamp[col[bj[q]]] = v;
        while (stamp[c] == v) c++;
        col[v] = c;
        if (c + 1 > ncol) ncol = c + 1;
    }
    /* by colour (a stable counting sort), then stably by slab */
    for (k = 0; k <= ncol; k++) cc[k] = 0;
    for (v = 0; v < nn; v++) cc[col[v] + 1]++;
    for (k = 0; k < ncol; k++) cc[k + 1] += cc[k];
    for (v = 0; v < nn; v++) bycol[cc[col[v]]++] = v;
    for (k = 0; k <= np + 1; k++) at[k] = 0;
    for (v = 0; v < nn; v++) at[part[v] + 1]++;
    for (k = 0; k <= np; k++) at[k + 1] += at[k];
    for (k = 0; k <= np + 1; k++) pp[k] = at[k];
    for (k = 0; k < nn; k++) ord[at[part[bycol[k]]]++] = bycol[k];
    for (k = 0; k < nn; k++) S->dyn.crA.rank[ord[k]] = k;
    S->dyn.crA.np = np;
}

/* The block pattern of every tet, removed ones included (a removal then leaves it valid): row v
   holds node w when a tet holds both (v itself included); the rows are stored in the Gauss-Seidel
   order (amps__cr_order), each split into its blocks of earlier nodes and the rest (crA.bp,
   crA.bu), both ordered by rank; crA.map locates each tet's 16 blocks. Rebuilt when a tet's
   nodes or the node count changed (cuts, node separation). Allocates at the first call and when
   the nodes or the blocks outgrow their capacities. */
static amps_status amps__cr_pattern(amps_ctx *ctx, amps_scene *S) {
    const amps_mesh *m = S->m;
    amps_int nn = m->nnode, nt = m->ntet, v, t, k, nb = 0, *cnt, *mark, *tmp;
    size_t need;
    int a, b;
    if (S->dyn.crA.nnode == nn && S->dyn.crA.ntet == nt &&
        !memcmp(S->dyn.crA.tet, m->tet, sizeof(amps_int) * 4 * (size_t)nt))
        return AMPS_OK;
    amps__cr_own_free(ctx, S); /* its entries follow the ranks of this pattern */
    S->dyn.crA.nnode = 0;
    if ((size_t)nn + 1 > S->dyn.crA.cap_row) { /* room for the nodes: bp and the counts */
        size_t c = (size_t)(m->node_cap > nn ? m->node_cap : nn) + 1;
        if (amps__realloc(ctx, (void **)&S->dyn.crA.bp, c, sizeof(amps_int)) ||
            amps__realloc(ctx, (void **)&S->dyn.crA.bu, c, sizeof(amps_int)) ||
            amps__realloc(ctx, (void **)&S->dyn.crA.dinv, 9 * c, sizeof(double)) ||
            amps__realloc(ctx, (void **)&S->dyn.crA.ord, c, sizeof(amps_int)) ||
            amps__realloc(ctx, (void **)&S->dyn.crA.rank, c, sizeof(amps_int)) ||
            amps__realloc(ctx, (void **)&S->dyn.crA.wgs, 3 * c + 2, sizeof(amps_int)) ||
            amps__realloc(ctx, (void **)&S->dyn.crA.wcnt, 2 * c, sizeof(amps_int)))
            goto oom;
        S->dyn.crA.cap_row = c;
    }
    if (!S->dyn.crA.wrow && /* the last of the three: a failed first call is retried in full */
        (amps__realloc(ctx, (void **)&S->dyn.crA.map, 16 * (size_t)nt + 1, sizeof(amps_int)) ||
         amps__realloc(ctx, (void **)&S->dyn.crA.tet, 4 * (size_t)nt + 1, sizeof(amps_int)) ||
         amps__realloc(ctx, (void **)&S->dyn.crA.wrow, 16 * (size_t)nt + 1, sizeof(amps_int))))
        goto oom;
    /* rows with repeats: 4 entries per tet and node of it, by a counting pass */
    cnt = S->dyn.crA.wcnt;
    tmp = S->dyn.crA.wrow;
    memset(cnt, 0, sizeof(amps_int) * ((size_t)nn + 1));
    mark = cnt + nn + 1;
    for (k = 0; k < 4 * nt; k++) cnt[m->tet[k] + 1] += 4;
    for (v = 0; v < nn; v++) cnt[v + 1] += cnt[v];
    for (t = 0; t < nt; t++)
        for (a = 0; a < 4; a++)
            for (b = 0; b < 4; b++) tmp[cnt[m->tet[4 * t + a]]++] = m->tet[4 * t + b];
    for (v = nn; v > 0; v--) cnt[v] = cnt[v - 1]; /* back to the row starts */
    cnt[0] = 0;
    /* unique per row, in place */
    for (v = 0; v < nn; v++) mark[v] = -1;
    for (v = 0; v < nn; v++) {
        amps_int p0 = cnt[v], p1 = cnt[v + 1], q, w, start = nb;
        for (q = p0; q < p1; q++)
            if (mark[w = tmp[q]] != v) {
                mark[w] = v;
                tmp[nb++] = w;
            }
        cnt[v] = start;
    }
    cnt[nn] = nb;
    /* the Gauss-Seidel order, and each row by it (insertion: rows are short) */
    amps__cr_order(S, cnt, tmp, nn, mark);
    for (v = 0; v < nn; v++) {
        const amps_int *rank = S->dyn.crA.rank;
        amps_int q, r, w;
        for (q = cnt[v] + 1; q < cnt[v + 1]; q++) {
            for (w = tmp[q], r = q; r > cnt[v] && rank[tmp[r - 1]] > rank[w]; r--) tmp[r] = tmp[r - 1];
            tmp[r] = w;
        }
    }
    need = (size_t)nb;
    if (need > S->dyn.crA.cap_blk) {
        size_t c = need + need / 2 + 16;
        if (amps__realloc(ctx, (void **)&S->dyn.crA.bj, c, sizeof(amps_int)) ||
            amps__realloc(ctx, (void **)&S->dyn.crA.be, c, sizeof(amps_int)) ||
            amps__realloc(ctx, (void **)&S->dyn.crA.bx, 9 * c, sizeof(double)))
            goto oom;
        S->dyn.crA.cap_blk = c;
    }
    /* the rows in the order, their parts of earlier nodes first, then the rest: each sweep streams
       its half alone */
    for (nb = 0, a = 0; a < 2; a++)
        for (k = 0; k < nn; k++) {
            amps_int q, *start = a ? S->dyn.crA.bu : S->dyn.crA.bp;
            v = S->dyn.crA.ord[k];
            start[k] = nb;
            for (q = cnt[v]; q < cnt[v + 1]; q++)
                if ((S->dyn.crA.rank[tmp[q]] < k) == !a) S->dyn.crA.bj[nb++] = tmp[q];
            if (k == nn - 1) start[nn] = nb;
        }
    if (!nn) S->dyn.crA.bp[0] = S->dyn.crA.bu[0] = 0;
    for (k = 0; k < nb; k++) S->dyn.crA.be[k] = 3 * S->dyn.crA.rank[S->dyn.crA.bj[k]]; /* the PCG's columns */
    for (t = 0; t < nt; t++) /* the block of node b in the row of node a, by bisection */
        for (a = 0; a < 4; a++) {
            amps_int r = S->dyn.crA.rank[m->tet[4 * t + a]];
            for (b = 0; b < 4; b++) {
                amps_int w = m->tet[4 * t + b];
                const amps_int *start = S->dyn.crA.rank[w] < r ? S->dyn.crA.bp : S->dyn.crA.bu;
                S->dyn.crA.map[16 * t + 4 * a + b] =
                        amps__cr_find(S->dyn.crA.bj, S->dyn.crA.rank, start[r], start[r + 1] - 1, w);
            }
        }
    memcpy(S->dyn.crA.tet, m->tet, sizeof(amps_int) * 4 * (size_t)nt);
    S->dyn.crA.nnode = nn;
    S->dyn.crA.ntet = nt;
    return AMPS_OK;
oom:
    return amps__err(ctx, AMPS_ERR_OOM, "amps_scene_step: out of memory (corotational)");
}

/* The rows of A_R = cM M + cK K_R owned by parts [p0, p1) of nthr (part k: the nodes
   [k nnode / np, (k+1) nnode / np)): cM m_v I on the diagonal, then per live tet in index order
   (the tet arrays are streamed; every block is summed in that order for any np) and node a of it
   in the range, for each node b of it the block cK V (lambda h_a h_b^T + mu h_b h_a^T +
   mu (g_a . g_b) I), h = R g (g: the reference gradients). */
typedef struct amps__crasm {
    amps_scene *S;
    amps_int np;
} amps__crasm;

/* X = la h_a h_b^T + mu h_b h_a^T + mu (g_a . g_b) I (X^T the same with a and b swapped): B += X,
   Bt += X^T, each when not NULL (every X computed the same way, so the bits do not depend on which
   part adds it, and A_R is symmetric to the bit). */
AMPS__KERNEL void amps__cr_block(const double *h, const double *G, double la, double mu, int a, int b, double *B,
                                 double *Bt) {
    double X[9], gg = mu * (G[3 * a] * G[3 * b] + G[3 * a + 1] * G[3 * b + 1] + G[3 * a + 2] * G[3 * b + 2]);
    int i, k;
    AMPS__UNROLL
    for (i = 0; i < 3; i++)
        for (k = 0; k < 3; k++) X[3 * i + k] = la * h[3 * a + i] * h[3 * b + k] + mu * h[3 * b + i] * h[3 * a + k];
    if (a == b) { /* symmetric to the bit: the lower triangle from the upper */
        X[3] = X[1];
        X[6] = X[2];
        X[7] = X[5];
    }
    X[0] += gg;
    X[4] += gg;
    X[8] += gg;
    if (B) {
        AMPS__UNROLL
        for (i = 0; i < 9; i++) B[i] += X[i];
    }
    if (Bt) {
        AMPS__UNROLL
        for (i = 0; i < 3; i++)
            for (k = 0; k < 3; k++) Bt[3 * i + k] += X[3 * k + i];
    }
}

static void amps__cr_rows(amps_int p0, amps_int p1, int slot, void *arg) {
    const amps__crasm *j = AMPS__CAST(const amps__crasm *, arg);
    amps_scene *S = j->S;
    const amps_mesh *m = S->m;
    const amps_int *map = S->dyn.crA.map, *bp = S->dyn.crA.bp, *bu = S->dyn.crA.bu;
    const amps_int *rank = S->dyn.crA.rank;
    amps_int lo, hi, v, t;
    double *bx = S->dyn.crA.bx, cK = S->dyn.cK;
    (void)slot;
    amps__cr_part(m, p0, p1, j->np, &lo, &hi);
    for (v = lo; v < hi; v++) { /* the rows cleared, the mass on the diagonal block (first of bu) */
        amps_int r = rank[v];
        double *B = bx + 9 * (size_t)bu[r];
        memset(bx + 9 * (size_t)bp[r], 0, sizeof(double) * 9 * (size_t)(bp[r + 1] - bp[r]));
        memset(B, 0, sizeof(double) * 9 * (size_t)(bu[r + 1] - bu[r]));
        if (bu[r] < bu[r + 1]) B[0] = B[4] = B[8] = S->dyn.cM * S->node.mass[v];
    }
    for (t = 0; t < m->ntet; t++) {
        const amps_int *tv = m->tet + 4 * t;
        const double *G, *R, *lm;
        double h[12], la, mu;
        int a, b, i, in[4];
        if (!amps__cr_touches(tv, lo, hi) || (m->removed && m->removed[t])) continue;
        G = S->dyn.cr_G + 12 * t;
        R = S->dyn.cr_R + 9 * t;
        lm = S->dyn.cr_lm + 2 * t;
        la = cK * lm[0];
        mu = cK * lm[1];
        AMPS__UNROLL
        for (b = 0; b < 4; b++)
            for (i = 0; i < 3; i++)
                h[3 * b + i] = R[3 * i] * G[3 * b] + R[3 * i + 1] * G[3 * b + 1] + R[3 * i + 2] * G[3 * b + 2];
        for (a = 0; a < 4; a++) in[a] = tv[a] >= lo && tv[a] < hi && S->node.dof[3 * tv[a]] >= 0;
        AMPS__UNROLL
        for (a = 0; a < 4; a++)
            for (b = a; b < 4; b++) /* X for a <= b (X^T is the block of (b, a)) */
                if (in[a] || in[b])
                    amps__cr_block(h, G, la, mu, a, b, in[a] ? bx + 9 * (size_t)map[16 * t + 4 * a + b] : NULL,
                                   in[b] && b != a ? bx + 9 * (size_t)map[16 * t + 4 * b + a] : NULL);
    }
    for (v = lo; v < hi; v++) { /* the inverses of the diagonal blocks: C^T / det */
        amps_int r = rank[v];
        double C[9], *Di = S->dyn.crA.dinv + 9 * (size_t)r, det;
        int i, k;
        if (bu[r] == bu[r + 1]) continue; /* a node in no tet */
        det = amps__cof3(bx + 9 * (size_t)bu[r], C);
        det = det != 0.0 ? 1.0 / det : 0.0;
        AMPS__UNROLL
        for (i = 0; i < 3; i++)
            for (k = 0; k < 3; k++) Di[3 * i + k] = C[3 * k + i] * det;
    }
}

/* A_R of the step into crA (pattern first; after the mode 0 pass). */
static amps_status amps__cr_assemble(amps_ctx *ctx, amps_scene *S) {
    amps_status s = amps__cr_pattern(ctx, S);
    amps__crasm j;
    if (s != AMPS_OK) return s;
    j.S = S;
    j.np = amps__scene_nthr(S, S->m->nnode);
    amps__par_for(&S->U->par, (int)j.np, j.np, 1, amps__cr_rows, &j);
    return AMPS_OK;
}

/* The PCG's vector work in node chunks of AMPS__CR_CHUNK: each dot product is summed per chunk
   into cr_part, then over the chunks in order (the same bits for any number of threads). */
#define AMPS__CR_CHUNK 256

/* The PCG runs in the order of the nodes (crA.ord): entry 3 k + i of its vectors is equation i
   of node ord[k] (k its rank), so that the products and the sweeps stream the vectors with the
   blocks; cr_cp flags the entries held fixed there (constrained in the engine, orphans, nodes
   without equations), where the iterates keep their prescribed values (0 at the last two).

   A sweep of the ranks, a parallel loop:
   op 0: y = A_R v and the sum v . y;
   op 1: p = z + beta p (0 on the held entries);
   op 2: x += alpha p, r -= alpha q (if upd) and the sum r . r; with zd also z = D r (D: the
         diagonal blocks; Gauss-Seidel's preconditioner, below) and a second sum r . z;
   op 3: the sum of y . y over the free entries, y = (D + L) v (L: the blocks of earlier nodes;
         Gauss-Seidel's residual r from r^ = v, below).
   The sums run over the free entries, per chunk into cr_part. */
typedef struct amps__crsweep {
    const amps_scene *S;
    int op, upd, zd; /* the operation; x and r updated; z = D r */
    const double *v;
    double *y, *x, *r, *z, *p, *q;
    double alpha, beta;
} amps__crsweep;

/* x_k . y_k on the free entries of rank k (e = 3 k). */
static double amps__cr_dot_node(const unsigned char *con, amps_int e, const double *x, const double *y) {
    return (con[e] ? 0.0 : x[e] * y[e]) + (con[e + 1] ? 0.0 : x[e + 1] * y[e + 1]) +
           (con[e + 2] ? 0.0 : x[e + 2] * y[e + 2]);
}

/* The blocks q of the row of rank k in part h (0: of earlier nodes; 1: the diagonal block and
   later nodes): returns the first, *qe one past the last. */
static amps_int amps__cr_span(const amps_scene *S, int h, amps_int k, amps_int *qe) {
    const amps_int *start = h ? S->dyn.crA.bu : S->dyn.crA.bp;
    *qe = start[k + 1];
    return start[k];
}

/* y_k = sum_w B_kw x_w for the row of rank k (both parts); returns x_k . y_k on its free entries. */
static double amps__cr_mul_node(const amps_scene *S, amps_int k, const double *x, double *y) {
    const amps_int *be = S->dyn.crA.be;
    amps_int q, h, e = 3 * k;
    double y0 = 0, y1 = 0, y2 = 0;
    for (h = 0; h < 2; h++) {
        amps_int qe;
        for (q = amps__cr_span(S, h, k, &qe); q < qe; q++) {
            const double *B = S->dyn.crA.bx + 9 * (size_t)q, *u = x + be[q];
            y0 += B[0] * u[0] + B[1] * u[1] + B[2] * u[2];
            y1 += B[3] * u[0] + B[4] * u[1] + B[5] * u[2];
            y2 += B[6] * u[0] + B[7] * u[1] + B[8] * u[2];
        }
    }
    y[e] = y0;
    y[e + 1] = y1;
    y[e + 2] = y2;
    return amps__cr_dot_node(S->dyn.cr_cp, e, x, y);
}

/* y_k = D_k v_k + sum over earlier w of B_kw v_w (row k in a tet); returns y_k . y_k on its free
   entries. */
static double amps__cr_lower_node(const amps_scene *S, amps_int k, const double *v) {
    const amps_int *be = S->dyn.crA.be;
    const unsigned char *con = S->dyn.cr_cp + 3 * k;
    amps_int q = S->dyn.crA.bu[k];
    const double *B = S->dyn.crA.bx + 9 * (size_t)q, *u = v + 3 * k;
    double y0 = B[0] * u[0] + B[1] * u[1] + B[2] * u[2], y1 = B[3] * u[0] + B[4] * u[1] + B[5] * u[2];
    double y2 = B[6] * u[0] + B[7] * u[1] + B[8] * u[2];
    for (q = S->dyn.crA.bp[k]; q < S->dyn.crA.bp[k + 1]; q++) {
        B = S->dyn.crA.bx + 9 * (size_t)q;
        u = v + be[q];
        y0 += B[0] * u[0] + B[1] * u[1] + B[2] * u[2];
        y1 += B[3] * u[0] + B[4] * u[1] + B[5] * u[2];
        y2 += B[6] * u[0] + B[7] * u[1] + B[8] * u[2];
    }
    return (con[0] ? 0.0 : y0 * y0) + (con[1] ? 0.0 : y1 * y1) + (con[2] ? 0.0 : y2 * y2);
}

/* The update of rank k's entries (op 2); d[0] += r . r, d[1] += r . z. */
static void amps__cr_update_node(const amps__crsweep *j, amps_int k, double d[2]) {
    amps_int e = 3 * k, bd = j->S->dyn.crA.bu[k];
    const unsigned char *con = j->S->dyn.cr_cp + e;
    const double *Di = j->S->dyn.crA.bx + 9 * (size_t)bd;
    double *r = j->r + e;
    int i;
    for (i = 0; i < 3; i++)
        if (!con[i] && j->upd) {
            j->x[e + i] += j->alpha * j->p[e + i];
            r[i] -= j->alpha * j->q[e + i];
        }
    for (i = 0; i < 3; i++)
        if (!con[i]) d[0] += r[i] * r[i];
    if (!j->zd) return;
    for (i = 0; i < 3; i++) {
        double zi = con[i] ? 0.0 : Di[3 * i] * r[0] + Di[3 * i + 1] * r[1] + Di[3 * i + 2] * r[2];
        j->z[e + i] = zi;
        if (!con[i]) d[1] += r[i] * zi;
    }
}

static void amps__cr_sweep_rows(amps_int b0, amps_int e0, int slot, void *arg) {
    const amps__crsweep *j = AMPS__CAST(const amps__crsweep *, arg);
    const amps_scene *S = j->S;
    const unsigned char *con = S->dyn.cr_cp;
    double *part = S->dyn.cr_part;
    amps_int c, k;
    (void)slot;
    for (c = b0; c < e0; c += AMPS__CR_CHUNK) {
        amps_int c1 = c + AMPS__CR_CHUNK < e0 ? c + AMPS__CR_CHUNK : e0;
        double d[2] = {0, 0};
        for (k = c; k < c1; k++) {
            amps_int e = 3 * k;
            int i;
            if (j->op == 0) d[0] += amps__cr_mul_node(S, k, j->v, j->y);
            else if (j->op == 1)
                for (i = 0; i < 3; i++) j->p[e + i] = con[e + i] ? 0.0 : j->z[e + i] + j->beta * j->p[e + i];
            else if (S->dyn.crA.bu[k] == S->dyn.crA.bu[k + 1]) continue; /* in no tet: held */
            else if (j->op == 2) amps__cr_update_node(j, k, d);
            else d[0] += amps__cr_lower_node(S, k, j->v);
        }
        part[2 * (c / AMPS__CR_CHUNK)] = d[0];
        part[2 * (c / AMPS__CR_CHUNK) + 1] = d[1];
    }
}

/* Runs the sweep j over every rank; returns its (first) sum, *rz (may be NULL) the second. */
static double amps__cr_sweep(amps_scene *S, amps__crsweep *j, double *rz) {
    amps_int nn = S->m->nnode, c, nc = (nn + AMPS__CR_CHUNK - 1) / AMPS__CR_CHUNK;
    double d0 = 0, d1 = 0;
    j->S = S;
    amps__par_for(&S->U->par, amps__scene_nthr(S, nn), nn, AMPS__CR_CHUNK, amps__cr_sweep_rows, j);
    if (j->op == 0) S->dyn.info.products++;
    for (c = 0; c < nc; c++) {
        d0 += S->dyn.cr_part[2 * c];
        d1 += S->dyn.cr_part[2 * c + 1];
    }
    if (rz) *rz = d1;
    return d0;
}

/* |(D + L) v|^2 on the free entries (op 3). */
static double amps__cr_lower(amps_scene *S, const double *v) {
    amps__crsweep j;
    memset(&j, 0, sizeof(j));
    j.op = 3;
    j.v = v;
    return amps__cr_sweep(S, &j, NULL);
}

/* y = A_R v; returns v . y on the free entries. */
static double amps__cr_mul(amps_scene *S, const double *v, double *y) {
    amps__crsweep j;
    memset(&j, 0, sizeof(j));
    j.v = v;
    j.y = y;
    return amps__cr_sweep(S, &j, NULL);
}

/* ---- symmetric Gauss-Seidel (Eisenstat's form) ----
   With A_R = L + D + L^T in the node order crA.ord (D: the 3x3 diagonal blocks, L: the blocks
   of earlier nodes), the PCG with preconditioner (D + L) D^-1 (D + L)^T on A_R equals the PCG
   with preconditioner D on A^ = (D + L)^-1 A_R (D + L)^-T, with residual r^ = (D + L)^-1 r and
   x = x0 + (D + L)^-T d (both are CG on D^1/2 A^ D^1/2). Since A_R = (D + L) + (D + L)^T - D,
       A^ p = t + (D + L)^-1 (p - D t),  t = (D + L)^-T p,
   a backward and a forward sweep, each streaming its own half of the blocks (crA.bu, crA.bp).
   On the held entries A_R's rows and columns are those of the identity (the vectors are 0 there):
   crA.dinv holds the inverse of D with them so (amps__cr_held). */
typedef struct amps__crgs {
    const amps_scene *S;
    int fwd;             /* 1: forward sweep, 0: backward */
    const double *a, *t; /* right-hand side; the forward sweep's t (NULL: none) */
    double *s, *q;       /* the result (may be a); with t, q = t + s */
    double *p, beta;     /* backward: first p = z + beta p (p = a; NULL: none) */
    const double *z;
    double sum[AMPS__CR_PARTS + 1]; /* per part (the interface last): a . q (forward with t) */
} amps__crgs;

/* Rank k of sweep j; returns a_k . q_k (forward with t), else 0. With y = a_k - sum over
   earlier w (forward) or later w (backward) of B_kw s_w, held entries of y set to 0:
   forward: s_k = D_k^-1 y (without t); q_k = D_k^-1 y and s_k = q_k - t_k (with t: then
            s_k = D_k^-1 (a_k - D_k t_k - ...), so q = t + s);
   backward: s_k = D_k^-1 y, after a_k = p_k = z_k + beta p_k if j->p. */
static double amps__cr_gs_node(const amps__crgs *j, amps_int k) {
    const amps_scene *S = j->S;
    const amps_int *be = S->dyn.crA.be;
    const unsigned char *held = S->dyn.cr_cp + 3 * k;
    const double *bx = S->dyn.crA.bx, *Di = S->dyn.crA.dinv + 9 * (size_t)k;
    amps_int q, e = 3 * k, d = S->dyn.crA.bu[k], q0 = j->fwd ? S->dyn.crA.bp[k] : d + 1;
    amps_int q1 = j->fwd ? S->dyn.crA.bp[k + 1] : S->dyn.crA.bu[k + 1];
    double y0, y1, y2, *s = j->t ? j->q + e : j->s + e;
    if (j->p) /* p = z + beta p, 0 where held */
        for (q = e; q < e + 3; q++) j->p[q] = S->dyn.cr_cp[q] ? 0.0 : j->z[q] + j->beta * j->p[q];
    if ((held[0] && held[1] && held[2]) || d == S->dyn.crA.bu[k + 1]) { /* held, or in no tet */
        j->s[e] = j->s[e + 1] = j->s[e + 2] = 0.0;
        if (j->t) j->q[e] = j->q[e + 1] = j->q[e + 2] = 0.0;
        return 0.0;
    }
    y0 = j->a[e];
    y1 = j->a[e + 1];
    y2 = j->a[e + 2];
    for (q = q0; q < q1; q++) { /* y -= B_kw s_w */
        const double *B = bx + 9 * (size_t)q, *u = j->s + be[q];
        y0 -= B[0] * u[0] + B[1] * u[1] + B[2] * u[2];
        y1 -= B[3] * u[0] + B[4] * u[1] + B[5] * u[2];
        y2 -= B[6] * u[0] + B[7] * u[1] + B[8] * u[2];
    }
    if (held[0] || held[1] || held[2]) { /* held in some entries: D^-1 is the inverse of D^ */
        y0 = held[0] ? 0.0 : y0;
        y1 = held[1] ? 0.0 : y1;
        y2 = held[2] ? 0.0 : y2;
    }
    s[0] = Di[0] * y0 + Di[1] * y1 + Di[2] * y2;
    s[1] = Di[3] * y0 + Di[4] * y1 + Di[5] * y2;
    s[2] = Di[6] * y0 + Di[7] * y1 + Di[8] * y2;
    if (!j->t) return 0.0;
    for (q = 0; q < 3; q++) j->s[e + q] = s[q] - j->t[e + q];
    return j->a[e] * s[0] + j->a[e + 1] * s[1] + j->a[e + 2] * s[2];
}

/* Sweep j over the ranks k0 .. k1-1 (forward ascending, backward descending) into sum[p]. */
static void amps__cr_gs_range(amps__crgs *j, amps_int k0, amps_int k1, amps_int p) {
    amps_int k;
    double d = 0;
    if (j->fwd)
        for (k = k0; k < k1; k++) d += amps__cr_gs_node(j, k);
    else
        for (k = k1 - 1; k >= k0; k--) (void)amps__cr_gs_node(j, k);
    j->sum[p] = d;
}

/* Parts [b0, e0) of sweep j (a parallel loop: the parts do not depend on each other). */
static void amps__cr_gs_parts(amps_int b0, amps_int e0, int slot, void *arg) {
    amps__crgs *j = AMPS__CAST(amps__crgs *, arg);
    amps_int p;
    (void)slot;
    for (p = b0; p < e0; p++) amps__cr_gs_range(j, j->S->dyn.crA.pp[p], j->S->dyn.crA.pp[p + 1], p);
}

/* Runs sweep j (S, fwd, a, t, s, q, p, z, beta set): the parts in parallel, the interface after
   them (forward) or before them (backward); returns the sum of j->sum. */
static double amps__cr_gs_run(amps_scene *S, amps__crgs *j) {
    amps_int np = S->dyn.crA.np, k;
    double d = 0;
    if (!j->fwd) amps__cr_gs_range(j, S->dyn.crA.pp[np], S->dyn.crA.pp[np + 1], np);
    amps__par_for(&S->U->par, np > 1 ? S->U->nthr : 1, np, 1, amps__cr_gs_parts, j);
    if (j->fwd) amps__cr_gs_range(j, S->dyn.crA.pp[np], S->dyn.crA.pp[np + 1], np);
    for (k = 0; k <= np; k++) d += j->sum[k];
    return d;
}

/* The sweep: forward (fwd) s = (D + L)^-1 (a - D t) and q = t + s, or backward s = (D + L)^-T a.
   Returns a . q on the free entries (forward with t), else 0. s may be a. */
static double amps__cr_gs(amps_scene *S, int fwd, const double *a, const double *t, double *s, double *q) {
    amps__crgs j;
    memset(&j, 0, sizeof(j));
    j.S = S;
    j.fwd = fwd;
    j.a = a;
    j.t = t;
    j.s = s;
    j.q = q;
    return amps__cr_gs_run(S, &j);
}

/* p = z + beta p (0 where held) with the backward sweep, then q = A^ p (the transformed operator
   above; t, s: workspace); returns p . q on the free entries. */
static double amps__cr_gs_mul(amps_scene *S, const double *z, double beta, double *p, double *t, double *s, double *q) {
    amps__crgs j;
    memset(&j, 0, sizeof(j));
    j.S = S;
    j.a = p;
    j.s = t;
    j.p = p;
    j.z = z;
    j.beta = beta;
    (void)amps__cr_gs_run(S, &j);
    S->dyn.info.products++;
    return amps__cr_gs(S, 1, p, t, s, q);
}

/* The corotational workspace: per tet (gradients and volumes at the first call), per node and
   per equation (N). */
static amps_status amps__cr_room(amps_ctx *ctx, amps_scene *S, amps_int N) {
    amps__scene_dyn *D = &S->dyn;
    const amps_mesh *m = S->m;
    size_t nt = (size_t)m->ntet;
    amps_int t;
    if (!D->cr_G) {
        if (amps__realloc(ctx, (void **)&D->cr_R, 9 * nt, sizeof(double)) ||
            amps__realloc(ctx, (void **)&D->cr_lm, 2 * nt, sizeof(double)) ||
            amps__realloc(ctx, (void **)&D->cr_ye, 12 * nt, sizeof(double)) ||
            (!D->vol && amps__realloc(ctx, (void **)&D->vol, nt + 1, sizeof(double))) ||
            amps__realloc(ctx, (void **)&D->cr_G, 12 * nt, sizeof(double))) {
            amps__free(ctx, D->cr_G);
            D->cr_G = NULL;
            return amps__err(ctx, AMPS_ERR_OOM, "amps_scene_step: out of memory (corotational)");
        }
        for (t = 0; t < m->ntet; t++) {
            double X[12];
            amps_mesh_tet_coords(m, t, X);
            D->vol[t] = fabs(amps_tet_gradients(X, D->cr_G + 12 * t));
        }
    }
    if (m->nnode > D->cr_cap) {
        size_t c = (size_t)(m->node_cap > m->nnode ? m->node_cap : m->nnode);
        if (amps__realloc(ctx, (void **)&D->cr_gel, 3 * c, sizeof(double)) ||
            amps__realloc(ctx, (void **)&D->cr_react, 3 * c, sizeof(double)) ||
            amps__realloc(ctx, (void **)&D->cr_Rn, 9 * c, sizeof(double)) ||
            amps__realloc(ctx, (void **)&D->cr_rnst, c, sizeof(long)) ||
            amps__realloc(ctx, (void **)&D->crP.wprev, 3 * c, sizeof(double)) ||
            amps__realloc(ctx, (void **)&D->crH.g0, 3 * c, sizeof(double)) ||
            amps__realloc(ctx, (void **)&D->crH.r0, 3 * c, sizeof(double)) ||
            amps__realloc(ctx, (void **)&D->crH.pin, c, 1) ||
            amps__realloc(ctx, (void **)&D->cr_part, 2 * (c / AMPS__CR_CHUNK + 1), sizeof(double)) ||
            amps__realloc(ctx, (void **)&D->cr_vec, 27 * c, sizeof(double)) ||
            amps__realloc(ctx, (void **)&D->cr_cp, 3 * c, 1))
            return amps__err(ctx, AMPS_ERR_OOM, "amps_scene_step: out of memory (corotational)");
        memset(D->crH.pin + D->cr_cap, 0, c - (size_t)D->cr_cap);
        memset(D->cr_rnst + D->cr_cap, 0, sizeof(long) * (c - (size_t)D->cr_cap));
        memset(D->cr_react + 3 * (size_t)D->cr_cap, 0, sizeof(double) * 3 * (c - (size_t)D->cr_cap));
        D->cr_cap = (amps_int)c;
    }
    if (N > D->cr_ncap) {
        size_t c = (size_t)N + (size_t)N / 2 + 16;
        if (amps__realloc(ctx, (void **)&D->cr_eng, c, sizeof(double)) || amps__realloc(ctx, (void **)&D->cr_con, c, 1))
            return amps__err(ctx, AMPS_ERR_OOM, "amps_scene_step: out of memory (corotational)");
        D->cr_ncap = (amps_int)c;
    }
    return AMPS_OK;
}

/* sum over the free entries (PCG order, n of them) of x_i y_i, in order. */
static double amps__cr_dot(const amps_scene *S, amps_int n, const double *x, const double *y) {
    double s = 0;
    amps_int i;
    for (i = 0; i < n; i++)
        if (!S->dyn.cr_cp[i]) s += x[i] * y[i];
    return s;
}

/* The PCG's held entries (cr_cp) from the engine's constrained equations (cr_con): entry 3 k + d
   of node ord[k] is held when its equation is constrained or the node has none. A node held in
   some entries only gets the inverse of its diagonal block with identity rows and columns there
   (after the assembly). */
static void amps__cr_held(amps_scene *S) {
    amps_int v, e, k;
    int d, i, nh;
    for (v = 0; v < S->m->nnode; v++) {
        unsigned char *h = S->dyn.cr_cp + 3 * (k = S->dyn.crA.rank[v]);
        for (nh = 0, d = 0; d < 3; d++) nh += h[d] = (e = S->node.dof[3 * v + d]) < 0 || S->dyn.cr_con[e];
        if (nh > 0 && nh < 3 && S->dyn.crA.bu[k] < S->dyn.crA.bu[k + 1]) {
            double B[9], C[9], det, *Di = S->dyn.crA.dinv + 9 * (size_t)k;
            memcpy(B, S->dyn.crA.bx + 9 * (size_t)S->dyn.crA.bu[k], sizeof(B));
            for (d = 0; d < 3; d++)
                for (i = 0; i < 3; i++)
                    if (h[d] || h[i]) B[3 * d + i] = d == i;
            det = amps__cof3(B, C);
            det = det != 0.0 ? 1.0 / det : 0.0;
            for (d = 0; d < 3; d++)
                for (i = 0; i < 3; i++) Di[3 * d + i] = C[3 * i + d] * det;
        }
    }
}

/* The right-hand side b = M w + dt (f + M g_grav - g) (mode 0 pass first) and the start x: w on
   the free entries, (g_P - u_P) / dt at the pins, 0 at the orphans and nodes without equations
   (PCG order). */
static void amps__cr_rhs(amps_scene *S, double *b, double *x) {
    const amps__scene_dyn *D = &S->dyn;
    amps_int v;
    int d;
    for (v = 0; v < S->m->nnode; v++)
        for (d = 0; d < 3; d++) {
            amps_int k = 3 * v + d, i = 3 * D->crA.rank[v] + d;
            if (S->node.dof[k] < 0) {
                b[i] = x[i] = 0.0;
                continue;
            }
            b[i] = S->node.mass[v] * D->vel[k] + D->dt * (S->node.force[k] + S->node.mass[v] * D->g[d] - D->cr_gel[k]);
            x[i] = D->orphan[v]        ? 0.0
                   : S->node.pinned[v] ? (S->node.pin_value[k] - S->node.disp[k]) / D->dt
                   : v < D->crP.nprev  ? 2.0 * D->vel[k] - D->crP.wprev[k]
                                       : D->vel[k];
        }
}

/* y = R^T a (transpose) or R a for the 3x3 R (row-major); y may be a. */
static void amps__rot3(const double R[9], const double a[3], int transpose, double y[3]) {
    double t[3];
    int i;
    AMPS__UNROLL
    for (i = 0; i < 3; i++)
        t[i] = transpose ? R[i] * a[0] + R[3 + i] * a[1] + R[6 + i] * a[2]
                         : R[3 * i] * a[0] + R[3 * i + 1] * a[1] + R[3 * i + 2] * a[2];
    AMPS__UNROLL
    for (i = 0; i < 3; i++) y[i] = t[i];
}

/* y = Rn^T x (transpose) or Rn x per node, on the equations of the nodes (y may be x). */
static void amps__cr_rotate(const amps_scene *S, const double *x, double *y, int transpose) {
    amps_int v;
    for (v = 0; v < S->m->nnode; v++) {
        const amps_int *e = S->node.dof + 3 * v;
        double a[3];
        int i;
        if (e[0] < 0) continue;
        AMPS__UNROLL
        for (i = 0; i < 3; i++) a[i] = x[e[i]];
        amps__rot3(S->dyn.cr_Rn + 9 * v, a, transpose, a);
        AMPS__UNROLL
        for (i = 0; i < 3; i++) y[e[i]] = a[i];
    }
}

/* The componentwise backward error max_i |r_i| / (|A_R| |x| + |b|)_i over the free rows of the
   PCG's x with residual r: near the unit roundoff no preconditioner does better. */
static double amps__cr_eta(const amps_scene *S, const double *r, const double *x, const double *b) {
    const amps__scene_dyn *D = &S->dyn;
    const amps_int *be = D->crA.be;
    double om = 0;
    amps_int k, q, qe, e;
    int h, i;
    for (k = 0; k < D->crA.nnode; k++)
        for (i = 0; i < 3; i++) {
            double den;
            e = 3 * k + i;
            if (D->cr_cp[e]) continue;
            den = fabs(b[e]);
            for (h = 0; h < 2; h++)
                for (q = amps__cr_span(S, h, k, &qe); q < qe; q++) {
                    const double *B = D->crA.bx + 9 * (size_t)q + 3 * i, *u = x + be[q];
                    den += fabs(B[0] * u[0]) + fabs(B[1] * u[1]) + fabs(B[2] * u[2]);
                }
            if (den > 0 && fabs(r[e]) > om * den) om = fabs(r[e]) / den;
        }
    return om;
}

/* Drops the factor of amps__cr_own. */
static void amps__cr_own_free(amps_ctx *ctx, amps_scene *S) {
    amps_factor_free(ctx, S->dyn.crF.F);
    amps__free(ctx, S->dyn.crF.idx);
    amps__free(ctx, S->dyn.crF.cp);
    amps__free(ctx, S->dyn.crF.w);
    amps__free(ctx, S->dyn.crF.work);
    memset(&S->dyn.crF, 0, sizeof(S->dyn.crF));
}

/* The fallback of a PCG that stalls (slivers, large rotations): A_R of this step on its free
   entries (the PCG's order; the upper triangle, from the blocks of amps__cr_assemble) analyzed
   and factored by amps_analyze and amps_factorize. Allocates (the factor and its pattern); a
   factor of an earlier step is dropped. AMPS_ERR_NOT_SPD / AMPS_ERR_OOM leave none. */
static amps_status amps__cr_own(amps_ctx *ctx, amps_scene *S) {
    amps__scene_dyn *D = &S->dyn;
    const unsigned char *cp = D->cr_cp;
    amps_int n = 3 * S->m->nnode, nf = 0, nz = 0, e, k, q, qe, *ti = NULL, *tj = NULL;
    double *tx = NULL;
    amps_csc *K = NULL;
    amps_status s = AMPS_OK;
    size_t cap = 9 * (size_t)D->crA.bu[D->crA.nnode];
    int h, i, j;
    amps__cr_own_free(ctx, S);
    D->crF.idx = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)n + 1, sizeof(amps_int)));
    D->crF.cp = AMPS__CAST(unsigned char *, amps__malloc(ctx, (size_t)n + 1, 1));
    ti = AMPS__CAST(amps_int *, amps__malloc(ctx, cap + 1, sizeof(amps_int)));
    tj = AMPS__CAST(amps_int *, amps__malloc(ctx, cap + 1, sizeof(amps_int)));
    tx = AMPS__CAST(double *, amps__malloc(ctx, cap + 1, sizeof(double)));
    if (!D->crF.idx || !D->crF.cp || !ti || !tj || !tx) {
        s = amps__err(ctx, AMPS_ERR_OOM, "amps_scene_step: out of memory factoring A_R");
        goto done;
    }
    for (e = 0; e < n; e++) D->crF.idx[e] = cp[e] ? -1 : nf++;
    memcpy(D->crF.cp, cp, (size_t)n);
    for (k = 0; k < D->crA.nnode; k++) /* the blocks of row k: entries (3k + i, be + j), i <= j in F */
        for (h = 0; h < 2; h++)
            for (q = amps__cr_span(S, h, k, &qe); q < qe; q++)
                for (i = 0; i < 3; i++)
                    for (j = 0; j < 3; j++) {
                        amps_int a = D->crF.idx[3 * k + i], b = D->crF.idx[D->crA.be[q] + j];
                        if (a < 0 || b < 0 || a > b) continue;
                        ti[nz] = a;
                        tj[nz] = b;
                        tx[nz++] = D->crA.bx[9 * (size_t)q + 3 * i + j];
                    }
    D->crF.n = n;
    D->crF.nf = nf;
    D->crF.w = AMPS__CAST(double *, amps__malloc(ctx, (size_t)nf + 1, sizeof(double)));
    D->crF.work = AMPS__CAST(double *, amps__malloc(ctx, (size_t)nf + 1, sizeof(double)));
    if (!D->crF.w || !D->crF.work || !(K = amps_csc_from_triplets(ctx, nf, nz, ti, tj, tx, AMPS_UPPER)) ||
        !(D->crF.F = amps_analyze(ctx, K, AMPS_UPPER, NULL)) || (s = amps_factorize(ctx, D->crF.F, K)) != AMPS_OK) {
        s = ctx && ctx->status < 0 ? ctx->status : AMPS_ERR_OOM;
        goto done;
    }
done:
    amps_csc_free(ctx, K);
    amps__free(ctx, ti);
    amps__free(ctx, tj);
    amps__free(ctx, tx);
    if (s != AMPS_OK) amps__cr_own_free(ctx, S);
    return s;
}

/* amps__cr_own with ctx's status and message kept when it fails (the step goes on without it). */
static int amps__cr_own_try(amps_ctx *ctx, amps_scene *S) {
    amps_status st = ctx ? ctx->status : AMPS_OK;
    char msg[sizeof(((amps_ctx *)0)->msg)];
    if (ctx) memcpy(msg, ctx->msg, sizeof(msg));
    if (amps__cr_own(ctx, S) == AMPS_OK) return 1;
    if (ctx) {
        ctx->status = st;
        memcpy(ctx->msg, msg, sizeof(msg));
    }
    return 0;
}

/* z = A_R'^-1 r on the free entries (z held: 0) with the factor of amps__cr_own. */
static amps_status amps__cr_own_solve(amps_ctx *ctx, amps_scene *S, const double *r, double *z) {
    const amps_int *idx = S->dyn.crF.idx;
    double *w = S->dyn.crF.w;
    amps_int e, n = S->dyn.crF.n;
    amps_status s;
    for (e = 0; e < n; e++)
        if (idx[e] >= 0) w[idx[e]] = r[e];
    if ((s = amps_solve(ctx, S->dyn.crF.F, w, w, S->dyn.crF.work)) != AMPS_OK) return s;
    for (e = 0; e < n; e++) z[e] = idx[e] >= 0 ? w[idx[e]] : 0.0;
    return AMPS_OK;
}

/* z = M^-1 r with the engine's preconditioner: Rn A^-1 Rn^T, the engine's exact solve with the
   current linear A in the frame of the node rotations (r, z in the PCG's order, taken to the
   engine's N equations in cr_eng and back; the cheap one's z comes with the update sweep,
   amps__cr_update_node). */
static amps_status amps__cr_prec(amps_ctx *ctx, amps_scene *S, amps_int N, const double *r, double *z) {
    double *w = S->dyn.cr_eng;
    amps_int v, e;
    amps_status s;
    int d;
    if (S->dyn.crF.F) return amps__cr_own_solve(ctx, S, r, z);
    amps__cr_frames(S);
    for (e = 0; e < N; e++) w[e] = 0.0;
    for (v = 0; v < S->m->nnode; v++)
        for (d = 0; d < 3; d++)
            if ((e = S->node.dof[3 * v + d]) >= 0) w[e] = r[3 * S->dyn.crA.rank[v] + d];
    amps__cr_rotate(S, w, w, 1);
    if ((s = amps_update_solve_rhs(ctx, S->U, w, w)) != AMPS_OK) return s;
    amps__cr_rotate(S, w, w, 0);
    for (v = 0; v < S->m->nnode; v++)
        for (d = 0; d < 3; d++) z[3 * S->dyn.crA.rank[v] + d] = (e = S->node.dof[3 * v + d]) >= 0 ? w[e] : 0.0;
    return AMPS_OK;
}

/* The cost of a PCG iteration with preconditioner kind, in bytes streamed (a model; the same on
   every machine, so the choice is reproducible): the product with A_R or the two sweeps (76 per
   block) and the vector updates (48 per entry), and the engine's forward and backward solves (24
   per entry of L) and dense system (16 per entry) (kind 0), or Gauss-Seidel's diagonal blocks
   and their inverses (144 per node) and three vectors more (24 per entry) (kind 1). */
static double amps__cr_cost(const amps_scene *S, amps_int n, int kind) {
    double c = 76.0 * (double)S->dyn.crA.bu[S->dyn.crA.nnode] + 48.0 * (double)n;
    if (kind == 1) return c + 144.0 * (double)S->m->nnode + 24.0 * (double)n;
    {
        const amps_factor *F = amps_update_factor(S->U);
        double u = (double)S->U->aug.size;
        return c + 24.0 * (double)F->Lp[F->n] + 16.0 * u * u;
    }
}

/* The PCG iterations from r (the residual of x, PCG order) while the budget lasts, with the
   engine's preconditioner (kind 0) while |r| > goal, or symmetric Gauss-Seidel (kind 1): r
   becomes r^ = (D + L)^-1 r, the iterations run on A^ and a correction d, and x += (D + L)^-T d at
   the end. They stop when |(D + L) r^| (the recurrence's |r|, a sweep of L) is at most 0.9 goal,
   taken once |r^| is at most goal gsr (gsr: the ratio |r^| / |r| at the last check, in crP).
   *it, *kit count the iterations of each kind, *done is set when they reached the goal; returns
   the last |r| (|r^|), or a negative status. */
typedef struct amps__crpcg {
    int kind;
    double goal, ce, cj, budget;
    amps_int cap;
} amps__crpcg;

static double amps__cr_iterate(amps_ctx *ctx, amps_scene *S, amps_int N, const amps__crpcg *P, double *x, double rn,
                               amps_int *it, amps_int *kit, int *done) {
    amps__scene_dyn *D = &S->dyn;
    size_t ns = 3 * (size_t)D->cr_cap;
    double *r = D->cr_vec + 2 * ns, *z = r + ns, *p = z + ns, *q = p + ns, *t = q + ns, *sv = t + ns, *dx = sv + ns;
    double rz = 0, rzn = 0, goal = P->goal, rn0 = rn;
    amps_int n = 3 * S->m->nnode, e;
    amps__crsweep sw;
    amps_status s;
    memset(&sw, 0, sizeof(sw));
    sw.x = P->kind ? dx : x;
    sw.r = r;
    sw.z = z;
    sw.p = p;
    sw.q = q;
    sw.zd = P->kind;
    if (P->kind) { /* r^ = (D + L)^-1 r, z = D r^, d = 0 */
        (void)amps__cr_gs(S, 1, r, NULL, r, NULL);
        for (e = 0; e < n; e++) dx[e] = 0.0;
        sw.op = 2;
        rn = sqrt(amps__cr_sweep(S, &sw, &rzn));
        if (!(D->crP.gsr > 0)) D->crP.gsr = rn0 > 0 ? rn / rn0 : 1.0;
    }
    for (*done = 0;; *it += !P->kind, *kit += P->kind) {
        double rz1, pq, beta, alpha;
        if (!P->kind ? rn <= goal : rn <= goal * D->crP.gsr && sqrt(amps__cr_lower(S, r)) <= 0.9 * goal) {
            *done = 1;
            break;
        }
        if (P->kind ? *kit >= P->cap : (double)*it * P->ce + (double)*kit * P->cj >= P->budget) break;
        if (!P->kind) { /* z = M^-1 r by the engine; Gauss-Seidel's z = D r^ came with the update */
            if ((s = amps__cr_prec(ctx, S, N, r, z)) != AMPS_OK) return s;
            rz1 = amps__cr_dot(S, n, r, z);
        } else rz1 = rzn;
        beta = rz != 0 ? rz1 / rz : 0.0;
        rz = rz1;
        if (P->kind) pq = amps__cr_gs_mul(S, z, beta, p, t, sv, q); /* p = z + beta p with the sweeps */
        else {
            sw.op = 1; /* p = z + beta p */
            sw.beta = beta;
            (void)amps__cr_sweep(S, &sw, NULL);
            pq = amps__cr_mul(S, p, q);
        }
        if (!(pq > 0)) break; /* not positive definite on this direction (rounding): stop */
        alpha = rz / pq;
        sw.op = 2; /* x += alpha p, r -= alpha q, and z = D r for Gauss-Seidel */
        sw.upd = 1;
        sw.alpha = alpha;
        rn = sqrt(amps__cr_sweep(S, &sw, &rzn));
    }
    if (P->kind) { /* x += (D + L)^-T d */
        (void)amps__cr_gs(S, 0, dx, NULL, t, NULL);
        for (e = 0; e < n; e++)
            if (!D->cr_cp[e]) x[e] += t[e];
    }
    return rn;
}

/* PCG on the reduced A_R w_F = (b - A_R w_C)_F from x (x_C: the prescribed values), in place,
   in the PCG's order (N: the engine's equations); *bn receives ||(b - A_R w_C)_F||, *relres the
   final relative residual, q (the sixth vector of cr_vec) A_R x. The preconditioner is the
   engine's (amps__cr_prec) or symmetric Gauss-Seidel (amps__cr_iterate), whichever's last
   iterations times its cost per iteration (amps__cr_cost) is smaller; Gauss-Seidel is tried on
   the second step and every 32 steps after a step without it, and abandoned for the engine's (a
   restart from the current x) after 1.5 times the cost of the engine's last step. maxit caps
   the cost at maxit iterations with the engine's preconditioner (a Gauss-Seidel iteration counts
   cj / ce of one). Each run of iterations ends with a check of the true residual; at most 4
   runs. Returns the iterations of both, or a negative status. */
static amps_int amps__cr_pcg(amps_ctx *ctx, amps_scene *S, amps_int N, const double *b, double *x, double *bn,
                             double *relres) {
    amps__scene_dyn *D = &S->dyn;
    size_t ns = 3 * (size_t)D->cr_cap;
    double *r = D->cr_vec + 2 * ns, *p = r + 2 * ns, *q = p + ns;
    double tol = D->corot_tol > 0 ? D->corot_tol : 1e-10, rn, hn = -1;
    amps_int maxit = D->corot_maxit > 0 ? D->corot_maxit : 200, it = 0, e, kit = 0, n = 3 * S->m->nnode;
    int run, done, own = 0;
    amps__crpcg P;
    memset(&P, 0, sizeof(P));
    if (D->crF.F && (D->crF.n != n || memcmp(D->crF.cp, D->cr_cp, (size_t)n))) amps__cr_own_free(ctx, S);
    for (e = 0; e < n; e++) p[e] = D->cr_cp[e] ? x[e] : 0.0;
    amps__cr_mul(S, p, q);
    for (e = 0; e < n; e++) r[e] = D->cr_cp[e] ? 0.0 : b[e] - q[e];
    *bn = sqrt(amps__cr_dot(S, n, r, r));
    if (*bn == 0) {
        for (e = 0; e < n; e++)
            if (!D->cr_cp[e]) x[e] = 0.0;
        amps__cr_mul(S, x, q);
        *relres = 0;
        return 0;
    }
    /* the preconditioner: the cheaper by the last iterations, Gauss-Seidel tried now and then */
    P.ce = amps__cr_cost(S, n, 0);
    P.cj = amps__cr_cost(S, n, 1);
    P.budget = (double)maxit * P.ce;
    if (D->crP.it[0] > 0) {
        P.cap = (amps_int)(1.5 * (double)D->crP.it[0] * P.ce / P.cj) + 1;
        if (P.cap > (amps_int)(P.budget / P.cj)) P.cap = (amps_int)(P.budget / P.cj);
        if (D->crP.it[1] == 0 || D->crP.probe >= 32 || (double)D->crP.it[1] * P.cj < (double)D->crP.it[0] * P.ce)
            P.kind = 1;
    }
    D->crP.probe = P.kind ? 0 : D->crP.probe + 1;
again:
    for (run = 0;; run++) {
        /* r = b - A_R x on the free entries (the true residual) */
        amps__cr_mul(S, x, q);
        for (e = 0; e < n; e++) r[e] = D->cr_cp[e] ? 0.0 : b[e] - q[e];
        rn = sqrt(amps__cr_dot(S, n, r, r));
        *relres = rn / *bn;
        if (hn >= 0 && rn > 0) D->crP.gsr = hn / rn; /* |r^| / |r| after Gauss-Seidel iterations */
        if (*relres <= tol || run == 4 || (!P.kind && (double)it * P.ce + (double)kit * P.cj >= P.budget)) break;
        P.goal = tol * *bn;
        hn = amps__cr_iterate(ctx, S, N, &P, x, rn, &it, &kit, &done);
        if (hn < 0) return (amps_int)hn;
        if (!P.kind) hn = -1;
        else if (!done) {
            /* Gauss-Seidel too slow: on with the engine's, from x; its estimate is above the cap */
            D->crP.it[1] = kit + (amps_int)((double)D->crP.it[0] * P.ce / P.cj);
            P.kind = 0;
        }
    }
    if (*relres > tol && !own && amps__cr_eta(S, r, x, b) > 1e-13 && amps__cr_own_try(ctx, S)) {
        /* stalled: on from x with A_R of this step factored (the preconditioner of the next steps
           too, until it stalls in turn) */
        own = 1;
        P.kind = 0;
        P.budget = (double)it * P.ce + (double)kit * P.cj + (double)maxit * P.ce;
        hn = -1;
        D->info.factored++;
        goto again;
    }
    if (P.kind) D->crP.it[1] = kit > 0 ? kit : 1;
    else D->crP.it[0] = it > 0 ? it : 1;
    D->info.iterations_gs = kit;
    return it + kit;
}

/* One corotational step (see amps_scene_corotational): rotations and elastic forces, b, PCG,
   reactions, the new state. Returns AMPS_WARN_INACCURATE when the PCG stopped above tol. */
static amps_status amps__scene_corot_step(amps_ctx *ctx, amps_scene *S) {
    amps__scene_dyn *D = &S->dyn;
    amps_int N, e, v, a, it;
    double *b, *x, *q, bn, relres, t0 = amps_now(), tol = D->corot_tol > 0 ? D->corot_tol : 1e-10;
    amps_status s;
    int d;
    if ((s = amps__scene_dyn_room(ctx, S, S->m->nnode)) != AMPS_OK || (s = amps_update_commit(ctx, S->U)) != AMPS_OK)
        return s;
    N = amps_update_dim(S->U);
    if ((s = amps__cr_room(ctx, S, N)) != AMPS_OK) return s;
    b = D->cr_vec;
    x = b + 3 * (size_t)D->cr_cap;
    q = b + 15 * (size_t)D->cr_cap;
    for (e = 0; e < N; e++) D->cr_con[e] = 0;
    for (a = 0; a < S->U->aug.size; a++)
        if (S->U->aug.kind[a] & AMPS__UCON) D->cr_con[S->U->aug.idx[a]] = 1;
    for (v = 0; v < S->m->nnode; v++) /* orphans: held by their rows in the engine, by w = 0 here */
        for (d = 0; d < 3; d++)
            if (D->orphan[v] && (e = S->node.dof[3 * v + d]) >= 0) D->cr_con[e] = 1;
    D->info.products = 0;
    amps__cr_pass(S, 0);
    if ((s = amps__cr_assemble(ctx, S)) != AMPS_OK) return s;
    amps__cr_held(S);
    amps__cr_rhs(S, b, x);
    D->info.t_rotation = amps_now() - t0;
    t0 = amps_now();
    it = amps__cr_pcg(ctx, S, N, b, x, &bn, &relres);
    if (it < 0) return (amps_status)it;
    /* reactions (A_R w+ - b)_P / dt (q = A_R w+ from the PCG), the new state, and the anchor of
       the haptic calls until the next step (pins, targets, reactions) */
    for (v = 0; v < S->m->nnode; v++) {
        D->crH.pin[v] = S->node.pinned[v] && !D->orphan[v];
        for (d = 0; d < 3; d++) {
            amps_int k = 3 * v + d, i = 3 * D->crA.rank[v] + d;
            e = S->node.dof[k];
            D->cr_react[k] = (e >= 0 && D->crH.pin[v]) ? (q[i] - b[i]) / D->dt : 0.0;
            D->crH.r0[k] = D->cr_react[k];
            D->crH.g0[k] = S->node.pin_value[k];
            D->crP.wprev[k] = D->vel[k];
            D->vel[k] = e >= 0 ? x[i] : 0.0;
            S->node.disp[k] += D->dt * D->vel[k];
        }
    }
    D->crP.nprev = S->m->nnode;
    D->cr_rvalid = 0;
    D->info.corotational = 1;
    D->info.iterations = it;
    D->info.iterations_total += it;
    D->info.relres = relres;
    D->info.t_solve = amps_now() - t0;
    if (relres > tol)
        return amps__err(ctx, AMPS_WARN_INACCURATE,
                         "amps_scene_step: corotational PCG stopped at relative residual %.3g after %ld iterations "
                         "(tolerance %.3g)",
                         relres, (long)it, tol);
    return AMPS_OK;
}

/* The haptic call of the corotational mode (amps_scene_solve_reactions): for each pinned node,
   r = r0 + Rn dr, r0 the last step's reaction (0 for a node pinned since), dr the reaction of
   the engine's linear system to the pin moves since the step (g - g0, g0 the target at the step
   or, for a pin made since, the node's displacement) taken into the node frame (Rn^T), with zero
   forces: one commit and the dense system (amps_update_solve_reactions), O(N) besides. */
static amps_status amps__scene_corot_haptic(amps_ctx *ctx, amps_scene *S) {
    amps__scene_dyn *D = &S->dyn;
    amps_int nn = S->m->nnode, v, n = 0, N;
    amps_status s;
    int d;
    D->crH.used = 1;
    if ((s = amps__scene_dyn_room(ctx, S, nn)) != AMPS_OK) return s;
    N = amps_update_dim(S->U);
    if ((s = amps__cr_room(ctx, S, N)) != AMPS_OK) return s;
    for (v = 0; v < N; v++) /* the engine's forces: zero (the response to the moves alone) */
        if (S->U->force.f[v] != 0.0) {
            S->dyn.idx[n] = v;
            S->dyn.val[n++] = 0.0;
        }
    if (n && (s = amps_update_set_force(ctx, S->U, n, S->dyn.idx, S->dyn.val)) != AMPS_OK) return s;
    amps__cr_pin_frames(S);
    for (n = 0, v = 0; v < nn; v++) { /* the constraints: Rn^T (g - g0) / dt */
        const double *g0 = D->crH.pin[v] ? D->crH.g0 + 3 * v : S->node.disp + 3 * v;
        double dg[3];
        if (!S->node.pinned[v] || D->orphan[v] || S->node.dof[3 * v] < 0) continue;
        for (d = 0; d < 3; d++) dg[d] = (S->node.pin_value[3 * v + d] - g0[d]) / D->dt;
        amps__rot3(D->cr_Rn + 9 * v, dg, 1, dg);
        for (d = 0; d < 3; d++) {
            S->dyn.idx[n] = S->node.dof[3 * v + d];
            S->dyn.val[n++] = dg[d];
        }
    }
    if (n && (s = amps_update_constrain(ctx, S->U, n, S->dyn.idx, S->dyn.val)) != AMPS_OK) return s;
    if ((s = amps_update_solve_reactions(ctx, S->U)) < 0) return s;
    for (v = 0; v < nn; v++) { /* r0 + Rn dr at the pins, 0 elsewhere */
        double dr[3] = {0, 0, 0};
        int live = S->node.pinned[v] && !D->orphan[v] && S->node.dof[3 * v] >= 0;
        for (d = 0; d < 3 && live; d++) dr[d] = amps_update_reaction(S->U, S->node.dof[3 * v + d]) / D->dt;
        if (live) amps__rot3(D->cr_Rn + 9 * v, dr, 0, dr);
        for (d = 0; d < 3; d++) D->cr_react[3 * v + d] = (live && D->crH.pin[v] ? D->crH.r0[3 * v + d] : 0.0) + dr[d];
    }
    return s;
}

/* H <- Rb H Rb^T for the haptic model of the corotational mode: Rb = the node frames of the
   pinned nodes h->node on the diagonal (H: 3n x 3n, column major). */
static void amps__cr_haptic_rotate(const amps_scene *S, amps_haptic *h) {
    amps_int m = 3 * h->n, k, l;
    for (k = 0; k < h->n; k++)
        for (l = 0; l < h->n; l++) {
            const double *Rk = S->dyn.cr_Rn + 9 * h->node[k], *Rl = S->dyn.cr_Rn + 9 * h->node[l];
            double B[9], T[9];
            int i, j, q;
            for (i = 0; i < 3; i++)
                for (j = 0; j < 3; j++) B[3 * i + j] = h->H[(size_t)(3 * l + j) * m + 3 * k + i];
            for (i = 0; i < 3; i++) /* T = Rk B */
                for (j = 0; j < 3; j++)
                    T[3 * i + j] = Rk[3 * i] * B[j] + Rk[3 * i + 1] * B[3 + j] + Rk[3 * i + 2] * B[6 + j];
            for (i = 0; i < 3; i++) /* T Rl^T */
                for (j = 0; j < 3; j++) {
                    double t = 0;
                    for (q = 0; q < 3; q++) t += T[3 * i + q] * Rl[3 * j + q];
                    h->H[(size_t)(3 * l + j) * m + 3 * k + i] = t;
                }
        }
}

/* sigma (6, Voigt) of tet t from eps = sym(R^T F - I) with R = cr_R (cr_rvalid) or the polar
   rotation of F. */
static void amps__cr_sigma(const amps_scene *S, amps_int t, const double *G, const double *Rt, double sigma[6]) {
    double F[9], R[9], H[9], lam, mu, tr;
    int i, k;
    amps__cr_deform(S, t, G, F);
    if (Rt) memcpy(R, Rt, sizeof(R));
    else amps__polar(F, R);
    for (i = 0; i < 3; i++)
        for (k = 0; k < 3; k++)
            H[3 * i + k] = R[i] * F[k] + R[3 + i] * F[3 + k] + R[6 + i] * F[6 + k] - (i == k ? 1.0 : 0.0);
    amps__lame(S->m->E[t], S->m->nu[t], &lam, &mu);
    tr = H[0] + H[4] + H[8];
    for (i = 0; i < 3; i++) sigma[i] = lam * tr + 2.0 * mu * H[4 * i];
    sigma[3] = mu * (H[1] + H[3]);
    sigma[4] = mu * (H[5] + H[7]);
    sigma[5] = mu * (H[2] + H[6]);
}

/* amps_scene_stress of the corotational mode: sigma of eps = sym(R^T F - I) per live tet (the
   rotations of the current state), von Mises and principal stresses as amps_mesh_stress. */
static amps_status amps__scene_corot_stress(amps_ctx *ctx, const amps_scene *S, double *sigma, double *von_mises,
                                            double *principal) {
    const amps_mesh *m = S->m;
    amps_int t;
    (void)ctx;
    for (t = 0; t < m->ntet; t++) {
        double X[12], G[12], sg[6] = {0, 0, 0, 0, 0, 0}, pr[3] = {0, 0, 0};
        int k;
        if (!(m->removed && m->removed[t])) {
            amps_mesh_tet_coords(m, t, X);
            amps_tet_gradients(X, G);
            amps__cr_sigma(S, t, G, S->dyn.cr_rvalid && S->dyn.cr_R ? S->dyn.cr_R + 9 * t : NULL, sg);
            if (principal) amps_sym3_eig(sg, pr);
        }
        if (sigma)
            for (k = 0; k < 6; k++) sigma[6 * t + k] = sg[k];
        if (principal)
            for (k = 0; k < 3; k++) principal[3 * t + k] = pr[k];
        if (von_mises) {
            double d01 = sg[0] - sg[1], d12 = sg[1] - sg[2], d20 = sg[2] - sg[0];
            von_mises[t] = sqrt(0.5 * (d01 * d01 + d12 * d12 + d20 * d20) +
                                3.0 * (sg[3] * sg[3] + sg[4] * sg[4] + sg[5] * sg[5]));
        }
    }
    return AMPS_OK;
}

AMPS_API amps_status amps_scene_corotational(amps_ctx *ctx, amps_scene *S, int on) {
    if (!S) return amps__err(ctx, AMPS_ERR_ARG, "amps_scene_corotational: NULL scene");
    if (!S->dyn.on)
        return amps__err(ctx, AMPS_ERR_STATE,
                         "amps_scene_corotational: the scene is static (call amps_scene_dynamics first)");
    if (S->dyn.nstep > 0)
        return amps__err(ctx, AMPS_ERR_STATE, "amps_scene_corotational: only before the first step (%ld taken)",
                         (long)S->dyn.nstep);
    S->dyn.corot = on != 0;
    return AMPS_OK;
}

AMPS_API amps_status amps_scene_corotational_tol(amps_ctx *ctx, amps_scene *S, double tol, amps_int maxit) {
    if (!S) return amps__err(ctx, AMPS_ERR_ARG, "amps_scene_corotational_tol: NULL scene");
    if (!amps__isfinite(tol) || !(tol > 0) || !(tol < 1) || maxit < 0)
        return amps__err(ctx, AMPS_ERR_VALUE, "amps_scene_corotational_tol: need 0 < tol < 1 and maxit >= 0");
    S->dyn.corot_tol = tol;
    S->dyn.corot_maxit = maxit;
    return AMPS_OK;
}

AMPS_API amps_status amps_scene_step_info(const amps_scene *S, amps_scene_step_stats *st) {
    if (!S || !st) return AMPS_ERR_ARG;
    *st = S->dyn.info;
    st->steps = S->dyn.nstep;
    return AMPS_OK;
}
#endif /* AMPS_NO_FEM */

/* ==== [amps:io impl] mesh readers and writers ================================================= */
#ifndef AMPS_NO_FEM
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
    amps__vfmt(msg, sizeof(msg), fmt, ap);
    va_end(ap);
    return amps__err(L->ctx, s, "%P:%lld: %s", L->name, line, msg);
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
    if (!amps__lx_ll(L, v))
        return amps__lx_err(L, L->tline, AMPS_ERR_PARSE, "invalid integer '%s' for %s", amps__lx_show(L, sh), what);
    return AMPS_OK;
}

/* Reads a finite real token named what. */
static amps_status amps__lx_num(amps__lex *L, int cross, double *v, const char *what) {
    char sh[40];
    if (!amps__lx_tok(L, cross)) return amps__lx_err(L, amps__lx_here(L), AMPS_ERR_PARSE, "missing %s", what);
    if (!amps__lx_real(L, v))
        return amps__lx_err(L, L->tline, AMPS_ERR_PARSE, "invalid number '%s' for %s", amps__lx_show(L, sh), what);
    if (!amps__isfinite(*v))
        return amps__lx_err(L, L->tline, AMPS_ERR_PARSE, "non-finite %s '%s'", what, amps__lx_show(L, sh));
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
    if (n > room || n > (long long)(AMPS__IMAX / 4))
        return amps__lx_err(L, L->tline, AMPS_ERR_PARSE, "%s count %lld exceeds what the file can hold", what, n);
    return AMPS_OK;
}

/* Reads a count named what (e.g. "point count") of n records named unit (e.g. "point") of at
   least mintok tokens each, checked by amps__lx_count. */
static amps_status amps__lx_nrec(amps__lex *L, int cross, long long *n, const char *what, const char *unit,
                                 int mintok) {
    amps_status s = amps__lx_int(L, cross, n, what);
    return s ? s : amps__lx_count(L, *n, mintok, unit);
}

/* Optional integer on the current line: 0 if the line has no more tokens, 1 if it was read
   into *v, -1 if the token is not an integer (it stays the last token). */
static int amps__lx_optint(amps__lex *L, long long *v) {
    if (!amps__lx_tok(L, 0)) return 0;
    return amps__lx_ll(L, v) ? 1 : -1;
}

/* Records "<msg>'<last token>'" at the token's line; returns AMPS_ERR_PARSE. */
static amps_status amps__lx_found(amps__lex *L, const char *msg) {
    char sh[40];
    return amps__lx_err(L, L->tline, AMPS_ERR_PARSE, "%s'%s'", msg, amps__lx_show(L, sh));
}

/* Start of record k of n, named units, on a later line: error "unexpected end of file: k of n
   units read" if the file ends first. */
static amps_status amps__lx_rec(amps__lex *L, long long k, long long n, const char *units) {
    if (amps__lx_skip(L, 1)) return AMPS_OK;
    return amps__lx_err(L, amps__lx_here(L), AMPS_ERR_PARSE, "unexpected end of file: %lld of %lld %s read", k, n,
                        units);
}

/* End of a file of n units: error if any token follows. */
static amps_status amps__lx_trail(amps__lex *L, long long n, const char *units) {
    char sh[40];
    if (!amps__lx_tok(L, 1)) return AMPS_OK;
    return amps__lx_err(L, L->tline, AMPS_ERR_PARSE, "unexpected data '%s' after %lld %s", amps__lx_show(L, sh), n,
                        units);
}

/* Reads an index named what, in [base, base + n - 1], into *out as v - base. */
static amps_status amps__lx_index(amps__lex *L, int cross, const char *what, long long base, long long n,
                                  amps_int *out) {
    long long v;
    amps_status s = amps__lx_int(L, cross, &v, what);
    if (s) return s;
    if (v < base || v - base >= n)
        return amps__lx_err(L, L->tline, AMPS_ERR_PARSE, "%s %lld out of range [%lld, %lld]", what, v, base,
                            base + n - 1);
    *out = (amps_int)(v - base);
    return AMPS_OK;
}

/* One tetrahedron as a reader parsed it: its 4 nodes (0-based) and the line it starts on. */
typedef struct amps__tetrec {
    amps_int v[4];
    long long line;
    amps_int region; /* region attribute (0 if none) */
} amps__tetrec;

/* Growable list of tets with the line each came from. */
typedef struct amps__tetbuf {
    amps_int *tet;
    long long *line;
    amps_int n, cap;
    amps_int *region;
} amps__tetbuf;

static amps_status amps__tb_reserve(amps_ctx *ctx, amps__tetbuf *b, amps_int cap) {
    void *p;
    if (cap <= b->cap) return AMPS_OK;
    if (cap > AMPS__IMAX / 4) return amps__err(ctx, AMPS_ERR_OOM, "too many tetrahedra for the index type");
    p = b->tet;
    if (amps__realloc(ctx, &p, 4 * (size_t)cap, sizeof(amps_int))) return AMPS_ERR_OOM;
    b->tet = AMPS__CAST(amps_int *, p);
    p = b->line;
    if (amps__realloc(ctx, &p, (size_t)cap, sizeof(long long))) return AMPS_ERR_OOM;
    b->line = AMPS__CAST(long long *, p);
    p = b->region;
    if (amps__realloc(ctx, &p, (size_t)cap, sizeof(amps_int))) return AMPS_ERR_OOM;
    b->region = AMPS__CAST(amps_int *, p);
    b->cap = cap;
    return AMPS_OK;
}

static amps_status amps__tb_push(amps_ctx *ctx, amps__tetbuf *b, const amps__tetrec *r) {
    if (b->n == b->cap) {
        amps_int cap = b->cap < 64 ? 64 : b->cap + b->cap / 2;
        amps_status s;
        if (cap > AMPS__IMAX / 4) cap = AMPS__IMAX / 4;
        s = amps__tb_reserve(ctx, b, cap);
        if (s) return s;
        if (b->n == b->cap) return amps__err(ctx, AMPS_ERR_OOM, "too many tetrahedra for the index type");
    }
    memcpy(b->tet + 4 * (size_t)b->n, r->v, 4 * sizeof(amps_int));
    b->region[b->n] = r->region;
    b->line[b->n++] = r->line;
    return AMPS_OK;
}

/* A tet's sorted nodes and its position in the buffer, for amps__tb_dedup. */
typedef struct amps__tkey {
    amps_int v[4], k;
} amps__tkey;

static int amps__tkey_cmp(const void *a, const void *b) {
    const amps__tkey *x = (const amps__tkey *)a, *y = (const amps__tkey *)b;
    int i;
    for (i = 0; i < 4; i++)
        if (x->v[i] != y->v[i]) return x->v[i] < y->v[i] ? -1 : 1;
    return x->k < y->k ? -1 : x->k > y->k;
}

/* Removes every tet whose node set an earlier one has (file order kept, the first's region);
   *ndup the number removed. */
static amps_status amps__tb_dedup(amps_ctx *ctx, amps__tetbuf *b, amps_int *ndup) {
    amps__tkey *key;
    unsigned char *gone;
    amps_int k, j, n = 0;
    *ndup = 0;
    if (b->n < 2) return AMPS_OK;
    key = AMPS__CAST(amps__tkey *, amps__malloc(ctx, (size_t)b->n, sizeof(amps__tkey)));
    gone = AMPS__CAST(unsigned char *, amps__calloc(ctx, (size_t)b->n, 1));
    if (!key || !gone) {
        amps__free(ctx, key);
        amps__free(ctx, gone);
        return amps__err(ctx, AMPS_ERR_OOM, "mesh reader: out of memory");
    }
    for (k = 0; k < b->n; k++) {
        amps_int i, t, *v = key[k].v;
        memcpy(v, b->tet + 4 * (size_t)k, sizeof(key[k].v));
        for (i = 1; i < 4; i++) /* insertion sort of 4 */
            for (j = i; j > 0 && v[j - 1] > v[j]; j--) {
                t = v[j];
                v[j] = v[j - 1];
                v[j - 1] = t;
            }
        key[k].k = k;
    }
    amps__sort(key, (size_t)b->n, sizeof(amps__tkey), amps__tkey_cmp);
    for (k = 1; k < b->n; k++)
        if (!memcmp(key[k].v, key[k - 1].v, sizeof(key[k].v))) gone[key[k].k] = 1; /* not the first */
    for (k = 0; k < b->n; k++) {
        if (gone[k]) continue;
        for (j = 0; j < 4; j++) b->tet[4 * (size_t)n + j] = b->tet[4 * (size_t)k + j];
        b->region[n] = b->region[k];
        b->line[n++] = b->line[k];
    }
    *ndup = b->n - n;
    b->n = n;
    amps__free(ctx, key);
    amps__free(ctx, gone);
    return AMPS_OK;
}

static void amps__tb_free(amps_ctx *ctx, amps__tetbuf *b) {
    amps__free(ctx, b->tet);
    amps__free(ctx, b->line);
    amps__free(ctx, b->region);
}

/* Region attribute v of the last token as an amps_int into *out. */
static amps_status amps__lx_region(amps__lex *L, long long v, amps_int *out) {
    if (v < -(long long)AMPS__IMAX || v > (long long)AMPS__IMAX)
        return amps__lx_err(L, L->tline, AMPS_ERR_PARSE, "region attribute %lld out of range", v);
    *out = (amps_int)v;
    return AMPS_OK;
}

/* State of a mesh reader: the lexer, nn points (3 coordinates each, file order) and the tets. */
typedef struct amps__rd {
    amps__lex L;
    double *xyz;
    amps_int nn;
    amps__tetbuf tb;
} amps__rd;

static void amps__rd_init(amps__rd *R, amps_ctx *ctx, const char *buf, size_t len, const char *name, int comment) {
    memset(R, 0, sizeof(*R));
    amps__lx_init(&R->L, ctx, buf, len, name, comment);
}

/* Allocates R->xyz for n points (a count checked by amps__lx_count). */
static amps_status amps__rd_points(amps__rd *R, long long n) {
    R->nn = (amps_int)n;
    R->xyz = AMPS__CAST(double *, amps__malloc(R->L.ctx, 3 * (size_t)n, sizeof(double)));
    return R->xyz ? AMPS_OK : AMPS_ERR_OOM;
}

/* Builds the mesh; a degenerate tet is reported as "file:line: ...". */
static amps_mesh *amps__rd_mesh(amps__rd *R) {
    amps__lex *L = &R->L;
    amps_int bad = -1;
    amps_mesh *m;
    if (R->tb.n == 0) {
        amps__lx_err(L, amps__lx_here(L), AMPS_ERR_PARSE, "no tetrahedra in the file");
        return NULL;
    }
    m = amps__mesh_new(L->ctx, "mesh", R->nn, R->xyz, R->tb.n, R->tb.tet, &bad);
    if (!m && bad >= 0 && L->ctx && L->ctx->status == AMPS_ERR_MESH) {
        const amps_int *tv = R->tb.tet + 4 * (size_t)bad;
        amps__lx_err(L, R->tb.line[bad], AMPS_ERR_MESH,
                     "degenerate tetrahedron (file nodes %lld %lld %lld %lld, 0-based)", (long long)tv[0],
                     (long long)tv[1], (long long)tv[2], (long long)tv[3]);
    }
    if (m) memcpy(m->region, R->tb.region, sizeof(amps_int) * (size_t)R->tb.n);
    return m;
}

/* The mesh if s is AMPS_OK (else NULL, the error already recorded); frees the reader's arrays. */
static amps_mesh *amps__rd_end(amps__rd *R, amps_status s) {
    amps_mesh *m = s ? NULL : amps__rd_mesh(R);
    amps__free(R->L.ctx, R->xyz);
    amps__tb_free(R->L.ctx, &R->tb);
    return m;
}

/* ---- TetGen .node / .ele ---- */

/* .node header "<#points> [<dimension> [<#attributes> [<#boundary markers>]]]": at least one
   point, dimension 3, marker flag 0 or 1. Moves to the next line. */
static amps_status amps__tetgen_node_head(amps__lex *L, long long *np) {
    long long dim = 3, nat = 0, nbm = 0;
    int r;
    amps_status s = amps__lx_nrec(L, 1, np, "point count", "point", 4);
    if (s) return s;
    if (*np == 0) return amps__lx_err(L, L->tline, AMPS_ERR_PARSE, "the file declares no points");
    if ((r = amps__lx_optint(L, &dim)) != 0 && (r < 0 || dim != 3))
        return amps__lx_found(L, "dimension must be 3, found ");
    if ((r = amps__lx_optint(L, &nat)) != 0 && (r < 0 || nat < 0)) return amps__lx_found(L, "invalid attribute count ");
    if ((r = amps__lx_optint(L, &nbm)) != 0 && (r < 0 || nbm < 0 || nbm > 1))
        return amps__lx_found(L, "boundary marker flag must be 0 or 1, found ");
    amps__lx_eol(L);
    return AMPS_OK;
}

/* The np point lines "<number> x y z [attributes] [marker]" of .node, numbered consecutively
   from the first number (0 or 1: the index base, into *base); nothing may follow. Fills R->xyz. */
static amps_status amps__tetgen_points(amps__rd *R, long long np, long long *base) {
    amps__lex *L = &R->L;
    long long k, idx = 0;
    amps_status s = amps__rd_points(R, np);
    for (k = 0; !s && k < np; k++) {
        s = amps__lx_rec(L, k, np, "points");
        if (!s) s = amps__lx_int(L, 1, &idx, "point number");
        if (s) return s;
        if (k == 0 && idx != 0 && idx != 1)
            return amps__lx_err(L, L->tline, AMPS_ERR_PARSE, "first point number must be 0 or 1, found %lld", idx);
        if (k == 0) *base = idx;
        else if (idx != *base + k)
            return amps__lx_err(L, L->tline, AMPS_ERR_PARSE, "point number %lld out of sequence (expected %lld)", idx,
                                *base + k);
        s = amps__lx_xyz(L, 0, R->xyz + 3 * k);
        if (!s) amps__lx_eol(L); /* attributes and boundary marker */
    }
    return s ? s : amps__lx_trail(L, np, "points");
}

/* .ele header "<#tets> [<nodes per tet> [<#attributes>]]": 4 or 10 nodes per tet (*nper and
   *nat keep their values if absent). Moves to the next line. */
static amps_status amps__tetgen_ele_head(amps__lex *L, long long *ne, long long *nper, long long *nat) {
    int r;
    amps_status s = amps__lx_nrec(L, 1, ne, "tetrahedron count", "tetrahedron", 5);
    if (s) return s;
    if ((r = amps__lx_optint(L, nper)) != 0 && (r < 0 || (*nper != 4 && *nper != 10)))
        return amps__lx_found(L, "nodes per tetrahedron must be 4 or 10, found ");
    if ((r = amps__lx_optint(L, nat)) != 0 && (r < 0 || *nat < 0)) return amps__lx_found(L, "invalid attribute count ");
    amps__lx_eol(L);
    return AMPS_OK;
}

/* One .ele line "<number> <nper node indices in [base, base + np - 1]> [nat attributes]": the
   first 4 nodes (0-based), the first attribute (an integer: the region, as tetgen -A writes it;
   0 if nat = 0) and the line into r. Moves to the next line. */
static amps_status amps__tetgen_tet(amps__lex *L, long long nper, long long nat, long long base, long long np,
                                    amps__tetrec *r) {
    long long idx, q;
    amps_int extra;
    double at = 0.0;
    amps_status s = amps__lx_int(L, 1, &idx, "tetrahedron number");
    r->line = L->tline;
    r->region = 0;
    for (q = 0; !s && q < nper; q++) s = amps__lx_index(L, 0, "node index", base, np, q < 4 ? r->v + q : &extra);
    if (!s && nat > 0) s = amps__lx_num(L, 0, &at, "region attribute");
    if (!s && nat > 0 && at != floor(at))
        s = amps__lx_err(L, L->tline, AMPS_ERR_PARSE, "region attribute %g is not an integer", at);
    if (!s && nat > 0 && fabs(at) > (double)AMPS__IMAX)
        s = amps__lx_err(L, L->tline, AMPS_ERR_PARSE, "region attribute %.0f does not fit the index type (%ld at most)",
                         at, (long)AMPS__IMAX);
    if (!s) r->region = (amps_int)at;
    if (!s) amps__lx_eol(L); /* other attributes */
    return s;
}

/* The ne tet lines of .ele (nat attributes), node indices from base; nothing may follow. Fills R->tb. */
static amps_status amps__tetgen_tets(amps__rd *R, long long ne, long long nper, long long nat, long long base) {
    amps__lex *L = &R->L;
    amps__tetrec r;
    long long k;
    amps_status s = amps__tb_reserve(L->ctx, &R->tb, (amps_int)(ne > 0 ? ne : 1));
    for (k = 0; !s && k < ne; k++) {
        s = amps__lx_rec(L, k, ne, "tetrahedra");
        if (!s) s = amps__tetgen_tet(L, nper, nat, base, R->nn, &r);
        if (!s) s = amps__tb_push(L->ctx, &R->tb, &r);
    }
    return s ? s : amps__lx_trail(L, ne, "tetrahedra");
}

AMPS_API amps_mesh *amps_mesh_read_tetgen_mem(amps_ctx *ctx, const char *node_buf, size_t node_len,
                                              const char *node_name, const char *ele_buf, size_t ele_len,
                                              const char *ele_name) {
    amps__rd R;
    long long np = 0, base = 0, ne = 0, nper = 4, nat = 0;
    amps_status s;
    amps__rd_init(&R, ctx, node_buf, node_len, node_name ? node_name : "<node>", '#');
    s = amps__tetgen_node_head(&R.L, &np);
    if (!s) s = amps__tetgen_points(&R, np, &base);
    if (!s) {
        amps__lx_init(&R.L, ctx, ele_buf, ele_len, ele_name ? ele_name : "<ele>", '#');
        s = amps__tetgen_ele_head(&R.L, &ne, &nper, &nat);
    }
    if (!s) s = amps__tetgen_tets(&R, ne, nper, nat, base);
    return amps__rd_end(&R, s);
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

/* State of the Gmsh reader. */
typedef struct amps__gmsh {
    amps__rd R;
    amps__gtag *tags; /* R.nn node tags with file position and line; sorted by tag after $Nodes */
    int version;      /* 2 (2.x) or 4 (4.1) after $MeshFormat, else 0 */
    int have_nodes, have_elems;
    char sec[24]; /* name of the current section, without '$' */
    /* hexahedra, prisms, pyramids (not read) and the line of the first */
    long long nother[3], vol_line;
    long long *vol_tag; /* 4.1 $Entities: the nvol volume entities and the first physical tag of */
    amps_int *vol_phys; /* each (0 if none) */
    long long nvol;
} amps__gmsh;

/* Counts an element of Gmsh type type on line line if it is a hexahedron, prism or pyramid (of
   any order), n of them. */
static void amps__gmsh_volume(amps__gmsh *G, long long type, long long line, long long n) {
    static const int kind[][5] = {{5, 12, 17, 92, 93}, {6, 13, 18, 90, 91}, {7, 14, 19, 118, 119}};
    int a, b;
    for (a = 0; a < 3; a++)
        for (b = 0; b < 5; b++)
            if (type == kind[a][b]) {
                if (!G->nother[0] && !G->nother[1] && !G->nother[2]) G->vol_line = line;
                G->nother[a] += n;
            }
}

/* Header of a 4.1 entity block. */
typedef struct amps__gblk {
    long long dim, tag; /* the entity */
    long long kind;     /* parametric flag ($Nodes) or element type ($Elements) */
    long long n;        /* nodes or elements in the block */
} amps__gblk;

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

/* want = "$End<sec>", truncated to 31 characters. */
static void amps__gmsh_want(char want[32], const char *sec) {
    size_t n = strlen(sec);
    if (n > 27) n = 27;
    memcpy(want, "$End", 4);
    memcpy(want + 4, sec, n);
    want[4 + n] = 0;
}

/* Expects the token "$End<sec>" at the start of the next non-blank line. */
static amps_status amps__gmsh_end(amps__lex *L, const char *sec, const char *after) {
    char want[32], sh[40];
    amps__gmsh_want(want, sec);
    if (!amps__lx_tok(L, 1))
        return amps__lx_err(L, amps__lx_here(L), AMPS_ERR_PARSE, "unexpected end of file, expected %s", want);
    if (!amps__lx_is(L, want, 0))
        return amps__lx_err(L, L->tline, AMPS_ERR_PARSE, "expected %s%s, found '%s'", want, after,
                            amps__lx_show(L, sh));
    amps__lx_eol(L);
    return AMPS_OK;
}

/* Skips the unknown section $<sec>: lines up to the line that starts with $End<sec>. */
static amps_status amps__gmsh_skip(amps__lex *L, const char *sec) {
    char want[32];
    long long start = L->tline;
    amps__gmsh_want(want, sec);
    for (;;) {
        if (!amps__lx_tok(L, 1))
            return amps__lx_err(L, start, AMPS_ERR_PARSE, "section $%s is not closed by %s", sec, want);
        amps__lx_eol(L);
        if (amps__lx_is(L, want, 0)) return AMPS_OK;
    }
}

/* $MeshFormat body "version file-type data-size" and $EndMeshFormat: G->version from a
   version 2.x or 4.1; file type 0 (ASCII) only. */
static amps_status amps__gmsh_format(amps__gmsh *G) {
    amps__lex *L = &G->R.L;
    double ver;
    long long a;
    char sh[40];
    amps_status s;
    if (G->version) return amps__lx_err(L, L->tline, AMPS_ERR_PARSE, "duplicate $MeshFormat");
    s = amps__lx_num(L, 1, &ver, "format version");
    if (s) return s;
    if (ver >= 2.0 && ver < 3.0) G->version = 2;
    else if (ver == 4.1) G->version = 4;
    else
        return amps__lx_err(L, L->tline, AMPS_ERR_PARSE, "unsupported .msh version %s (readable: 2.x, 4.1)",
                            amps__lx_show(L, sh));
    s = amps__lx_int(L, 0, &a, "file type");
    if (s) return s;
    if (a == 1)
        return amps__lx_err(L, L->tline, AMPS_ERR_PARSE, "binary .msh files are not supported; save the mesh as ASCII");
    if (a != 0) return amps__lx_err(L, L->tline, AMPS_ERR_PARSE, "invalid file type %lld (0 = ASCII)", a);
    s = amps__lx_int(L, 0, &a, "data size");
    if (s) return s;
    amps__lx_eol(L);
    return amps__gmsh_end(L, "MeshFormat", "");
}

/* Head line of the $Nodes (elems 0) or $Elements (elems 1) section, which must be the first of
   its kind: the entity block count *nblk (4.1) and the total count of nodes or elements.
   Moves to the next line. */
static amps_status amps__gmsh_head(amps__gmsh *G, int elems, long long *nblk, long long *total) {
    amps__lex *L = &G->R.L;
    int *seen = elems ? &G->have_elems : &G->have_nodes;
    int cross = 1;
    amps_status s;
    if (*seen) return amps__lx_err(L, L->tline, AMPS_ERR_PARSE, "duplicate %s section", elems ? "$Elements" : "$Nodes");
    *seen = 1;
    if (G->version == 4) {
        s = amps__lx_nrec(L, 1, nblk, "entity block count", "entity block", 4);
        if (s) return s;
        cross = 0;
    }
    s = elems ? amps__lx_nrec(L, cross, total, "element count", "element", 2)
              : amps__lx_nrec(L, cross, total, "node count", "node", 4);
    if (!s) amps__lx_eol(L);
    return s;
}

/* 4.1 entity block header "entityDim entityTag <kind> <count>" in $Nodes (elems 0) or
   $Elements (elems 1): the count must fit in the total less the got already read. Moves to
   the next line. */
static amps_status amps__gmsh_block(amps__lex *L, int elems, long long total, long long got, amps__gblk *h) {
    const char *unit = elems ? "element" : "node";
    amps_status s = amps__lx_int(L, 1, &h->dim, "entity dimension");
    if (!s) s = amps__lx_int(L, 0, &h->tag, "entity tag");
    if (!s) s = amps__lx_int(L, 0, &h->kind, elems ? "element type" : "parametric flag");
    if (!s) s = amps__lx_int(L, 0, &h->n, elems ? "block element count" : "block node count");
    if (s) return s;
    if (h->n < 0 || h->n > total - got)
        return amps__lx_err(L, L->tline, AMPS_ERR_PARSE, "block %s count %lld exceeds the %lld %ss declared", unit,
                            h->n, total, unit);
    amps__lx_eol(L);
    return AMPS_OK;
}

/* Error unless the 4.1 blocks of $Nodes (elems 0) or $Elements (elems 1) held the total. */
static amps_status amps__gmsh_held(amps__lex *L, int elems, long long total, long long got) {
    if (got == total) return AMPS_OK;
    return amps__lx_err(L, amps__lx_here(L), AMPS_ERR_PARSE, "%s declares %lld %ss, its blocks hold %lld",
                        elems ? "$Elements" : "$Nodes", total, elems ? "element" : "node", got);
}

/* Reads the tag of node k (on a later line) into G->tags[k]. */
static amps_status amps__gmsh_tag(amps__gmsh *G, long long k) {
    amps__lex *L = &G->R.L;
    long long a;
    amps_status s = amps__lx_int(L, 1, &a, "node tag");
    if (s) return s;
    G->tags[k].tag = a;
    G->tags[k].line = L->tline;
    G->tags[k].idx = (amps_int)k;
    return AMPS_OK;
}

/* 2.x node lines "tag x y z". */
static amps_status amps__gmsh_nodes2(amps__gmsh *G, long long total) {
    long long k;
    amps_status s = AMPS_OK;
    for (k = 0; !s && k < total; k++) {
        s = amps__gmsh_tag(G, k);
        if (!s) s = amps__lx_xyz(&G->R.L, 0, G->R.xyz + 3 * k);
        if (!s) amps__lx_eol(&G->R.L);
    }
    return s;
}

/* 4.1 node blocks: a header, the block's tags one a line, then its coordinates one a line
   (parametric coordinates ignored); together total nodes. */
static amps_status amps__gmsh_nodes4(amps__gmsh *G, long long nblk, long long total) {
    amps__lex *L = &G->R.L;
    amps__gblk h;
    long long b, i, got = 0;
    for (b = 0; b < nblk; b++) {
        amps_status s = amps__gmsh_block(L, 0, total, got, &h);
        for (i = 0; !s && i < h.n; i++) {
            s = amps__gmsh_tag(G, got + i);
            if (!s) amps__lx_eol(L);
        }
        for (i = 0; !s && i < h.n; i++) {
            s = amps__lx_xyz(L, 1, G->R.xyz + 3 * (got + i));
            if (!s) amps__lx_eol(L); /* parametric coordinates */
        }
        if (s) return s;
        got += h.n;
    }
    return amps__gmsh_held(L, 0, total, got);
}

/* Sorts G->tags by tag for amps__gmsh_node; error at the later line of a repeated tag. */
static amps_status amps__gmsh_tagmap(amps__gmsh *G) {
    amps__gtag *t = G->tags;
    amps_int k, n = G->R.nn;
    amps__sort(t, (size_t)n, sizeof(amps__gtag), amps__gtag_cmp);
    for (k = 1; k < n; k++)
        if (t[k].tag == t[k - 1].tag)
            return amps__lx_err(&G->R.L, t[k].line, AMPS_ERR_PARSE, "duplicate node tag %lld (first on line %lld)",
                                t[k].tag, t[k - 1].line);
    return AMPS_OK;
}

/* $Nodes up to $EndNodes: R.xyz in file order and the tag map. */
static amps_status amps__gmsh_nodes(amps__gmsh *G) {
    long long nblk = 1, total;
    amps_status s = amps__gmsh_head(G, 0, &nblk, &total);
    if (s) return s;
    s = amps__rd_points(&G->R, total);
    G->tags = AMPS__CAST(amps__gtag *, amps__malloc(G->R.L.ctx, (size_t)G->R.nn, sizeof(amps__gtag)));
    if (s || !G->tags) return AMPS_ERR_OOM;
    s = G->version == 2 ? amps__gmsh_nodes2(G, total) : amps__gmsh_nodes4(G, nblk, total);
    if (!s) s = amps__gmsh_end(&G->R.L, "Nodes", " (node count mismatch?)");
    return s ? s : amps__gmsh_tagmap(G);
}

/* Gmsh element types of tetrahedra: 4 (linear), 11 (10 nodes), 29, 30, 31 (20, 35, 56 nodes),
   their first 4 nodes the corners. */
static int amps__gmsh_is_tet(long long type) {
    return type == 4 || type == 11 || type == 29 || type == 30 || type == 31;
}

/* The 4 node tags of a tetrahedron (its corners), on the current line, as file positions into r->v; then r
   joins R.tb. */
static amps_status amps__gmsh_tet(amps__gmsh *G, amps__tetrec *r) {
    int i;
    amps_status s = AMPS_OK;
    for (i = 0; !s && i < 4; i++) s = amps__gmsh_node(&G->R.L, G->tags, G->R.nn, r->v + i);
    return s ? s : amps__tb_push(G->R.L.ctx, &G->R.tb, r);
}

/* 2.x element lines "number type ntags <tags> <nodes>"; the tets (type 4) join R.tb, their
   region the first tag (the physical one; 0 without tags). */
static amps_status amps__gmsh_elems2(amps__gmsh *G, long long total) {
    amps__lex *L = &G->R.L;
    amps__tetrec r;
    long long k, i, a, type = 0, c = 0;
    amps_status s = AMPS_OK;
    for (k = 0; !s && k < total; k++) {
        s = amps__lx_int(L, 1, &a, "element number");
        r.line = L->tline;
        if (!s) s = amps__lx_int(L, 0, &type, "element type");
        if (!s) s = amps__lx_int(L, 0, &c, "tag count");
        if (!s && c < 0) s = amps__lx_err(L, L->tline, AMPS_ERR_PARSE, "negative tag count %lld", c);
        r.region = 0;
        for (i = 0; !s && amps__gmsh_is_tet(type) && i < c; i++) {
            s = amps__lx_int(L, 0, &a, "element tag");
            if (!s && i == 0) s = amps__lx_region(L, a, &r.region); /* the physical tag */
        }
        if (!s && amps__gmsh_is_tet(type)) s = amps__gmsh_tet(G, &r);
        if (!s) amps__gmsh_volume(G, type, r.line, 1);
        if (!s) amps__lx_eol(L);
    }
    return s;
}

/* 4.1 element blocks: a header, then one element a line "tag <nodes>"; the tets (type 4) join
   R.tb, their region the physical tag of the block's volume entity; together total elements. */
static amps_status amps__gmsh_elems4(amps__gmsh *G, long long nblk, long long total) {
    amps__lex *L = &G->R.L;
    amps__gblk h;
    amps__tetrec r;
    long long b, i, a, got = 0;
    int known;
    for (b = 0; b < nblk; b++) {
        amps_status s = amps__gmsh_block(L, 1, total, got, &h);
        if (!s) amps__gmsh_volume(G, h.kind, L->tline, h.n);
        r.region = 0;
        known = 0;
        for (i = 0; h.dim == 3 && i < G->nvol; i++)
            if (G->vol_tag[i] == h.tag) {
                r.region = G->vol_phys[i];
                known = 1;
            }
        if (!s && amps__gmsh_is_tet(h.kind) && h.n > 0 && (h.dim != 3 || (G->vol_tag && !known)))
            s = amps__lx_err(L, L->tline, AMPS_ERR_PARSE,
                             h.dim != 3 ? "tetrahedra in an entity of dimension %lld"
                                        : "tetrahedra in volume entity %lld, which $Entities does not list",
                             h.dim != 3 ? (long long)h.dim : (long long)h.tag);
        for (i = 0; !s && i < h.n; i++) {
            if (amps__gmsh_is_tet(h.kind)) {
                s = amps__lx_int(L, 1, &a, "element tag");
                r.line = L->tline;
                if (!s) s = amps__gmsh_tet(G, &r);
            } else if (!amps__lx_skip(L, 1)) {
                s = amps__lx_err(L, amps__lx_here(L), AMPS_ERR_PARSE, "unexpected end of file in an element block");
            }
            if (!s) amps__lx_eol(L);
        }
        if (s) return s;
        got += h.n;
    }
    return amps__gmsh_held(L, 1, total, got);
}

/* 4.1 $Entities (part 0) or $PartitionedEntities (part 1) up to its end: ("numPartitions
   numGhostEntities" and that many "ghostTag partition" first when part), "numPoints numCurves
   numSurfaces numVolumes", one entity a line; of a volume "tag [parentDim parentTag
   numPartitions partitionTag ...] minX minY minZ maxX maxY maxZ numPhysicalTags physicalTag ...
   ..." keeps the tag and its first physical tag (a partitioned volume without one: its parent's).
   Other versions skip the section. */
static amps_status amps__gmsh_entities(amps__gmsh *G, int part) {
    amps__lex *L = &G->R.L;
    long long cnt[4], k, i, nph, tag, ph, np, pdim = 0, ptag = 0, n0 = G->nvol;
    double x;
    amps_status s = AMPS_OK;
    if (G->version != 4 || (!part && G->vol_tag)) return amps__gmsh_skip(L, G->sec);
    if (G->have_elems) return amps__lx_err(L, L->tline, AMPS_ERR_PARSE, "$%s after $Elements", G->sec);
    if (part) { /* partitions, ghost entities */
        s = amps__lx_int(L, 1, &np, "partition count");
        if (!s) s = amps__lx_nrec(L, 1, &np, "ghost entity count", "ghost entity", 2);
        for (k = 0; k < 2 * np && !s; k++) s = amps__lx_int(L, 1, &tag, "ghost entity");
    }
    for (k = 0; k < 4 && !s; k++) s = amps__lx_nrec(L, k == 0, cnt + k, "entity count", "entity", 1);
    if (s) return s;
    amps__lx_eol(L);
    if (amps__realloc(L->ctx, (void **)&G->vol_tag, (size_t)(n0 + cnt[3] + 1), sizeof(long long)) ||
        amps__realloc(L->ctx, (void **)&G->vol_phys, (size_t)(n0 + cnt[3] + 1), sizeof(amps_int)))
        return AMPS_ERR_OOM;
    for (k = 0; k < cnt[0] + cnt[1] + cnt[2] && !s; k++) {
        s = amps__lx_int(L, 1, &tag, "entity tag");
        if (!s) amps__lx_eol(L);
    }
    for (k = 0; k < cnt[3] && !s; k++) {
        s = amps__lx_int(L, 1, &tag, "volume tag");
        if (!s && part) s = amps__lx_int(L, 0, &pdim, "parent dimension");
        if (!s && part) s = amps__lx_int(L, 0, &ptag, "parent tag");
        if (!s && part) s = amps__lx_int(L, 0, &np, "partition count");
        for (i = 0; part && i < np && !s; i++) s = amps__lx_int(L, 0, &ph, "partition tag");
        for (i = 0; i < 6 && !s; i++) s = amps__lx_num(L, 0, &x, "bounding box coordinate");
        if (!s) s = amps__lx_int(L, 0, &nph, "physical tag count");
        G->vol_tag[n0 + k] = tag;
        G->vol_phys[n0 + k] = 0;
        for (i = 0; part && nph <= 0 && pdim == 3 && i < n0; i++) /* its parent's */
            if (G->vol_tag[i] == ptag) G->vol_phys[n0 + k] = G->vol_phys[i];
        G->nvol = n0 + k + 1;
        for (i = 0; i < nph && !s; i++) {
            s = amps__lx_int(L, 0, &ph, "physical tag");
            if (!s && i == 0) s = amps__lx_region(L, ph, G->vol_phys + n0 + k);
        }
        if (!s) amps__lx_eol(L); /* bounding surfaces */
    }
    return s ? s : amps__gmsh_end(L, G->sec, " (entity count mismatch?)");
}

/* $Elements (after $Nodes) up to $EndElements. */
static amps_status amps__gmsh_elements(amps__gmsh *G) {
    amps__lex *L = &G->R.L;
    long long nblk = 1, total;
    amps_status s;
    if (!G->have_nodes) return amps__lx_err(L, L->tline, AMPS_ERR_PARSE, "$Elements before $Nodes");
    s = amps__gmsh_head(G, 1, &nblk, &total);
    if (s) return s;
    s = G->version == 2 ? amps__gmsh_elems2(G, total) : amps__gmsh_elems4(G, nblk, total);
    return s ? s : amps__gmsh_end(L, "Elements", " (element count mismatch?)");
}

/* The section whose header "$<name>" is the last token (the first must be $MeshFormat): its
   name into G->sec, then its body by name; unknown sections are skipped. */
static amps_status amps__gmsh_section(amps__gmsh *G) {
    amps__lex *L = &G->R.L;
    if (L->tok[0] != '$' || L->tlen < 2 || L->tlen >= sizeof(G->sec) + 1)
        return amps__lx_found(L, "expected a section header like $Nodes, found ");
    memcpy(G->sec, L->tok + 1, L->tlen - 1);
    G->sec[L->tlen - 1] = 0;
    if (!G->version && !amps__lx_is(L, "$MeshFormat", 0))
        return amps__lx_found(L, "the file must start with $MeshFormat, found ");
    amps__lx_eol(L);
    if (!strcmp(G->sec, "MeshFormat")) return amps__gmsh_format(G);
    if (!strcmp(G->sec, "Nodes")) return amps__gmsh_nodes(G);
    if (!strcmp(G->sec, "Elements")) return amps__gmsh_elements(G);
    if (!strcmp(G->sec, "Entities")) return amps__gmsh_entities(G, 0);
    if (!strcmp(G->sec, "PartitionedEntities")) return amps__gmsh_entities(G, 1);
    return amps__gmsh_skip(L, G->sec);
}

AMPS_API amps_mesh *amps_mesh_read_gmsh_mem(amps_ctx *ctx, const char *buf, size_t len, const char *name) {
    amps__gmsh G;
    amps__lex *L = &G.R.L;
    amps_status s = AMPS_OK;
    amps_mesh *m;
    amps_int ndup = 0;
    memset(&G, 0, sizeof(G));
    amps__rd_init(&G.R, ctx, buf, len, name ? name : "<msh>", 0);
    while (!s && amps__lx_tok(L, 1)) s = amps__gmsh_section(&G);
    if (!s && !G.version) s = amps__lx_err(L, amps__lx_here(L), AMPS_ERR_PARSE, "empty file (no $MeshFormat)");
    if (!s && !G.have_nodes) s = amps__lx_err(L, amps__lx_here(L), AMPS_ERR_PARSE, "no $Nodes section");
    if (!s && (G.nother[0] || G.nother[1] || G.nother[2]))
        s = amps__lx_err(L, G.vol_line, AMPS_ERR_MESH,
                         "%lld hexahedr%s, %lld prism%s, %lld pyramid%s: amps reads tetrahedra only; "
                         "mesh with tetrahedra only",
                         G.nother[0], G.nother[0] == 1 ? "on" : "a", G.nother[1], G.nother[1] == 1 ? "" : "s",
                         G.nother[2], G.nother[2] == 1 ? "" : "s");
    if (!s && G.R.tb.n == 0)
        s = amps__lx_err(L, amps__lx_here(L), AMPS_ERR_PARSE,
                         "no tetrahedra (element type 4, 11, 29, 30 or 31) in the file");
    if (!s && (s = amps__tb_dedup(ctx, &G.R.tb, &ndup)) == AMPS_OK && ndup > 0)
        amps__log(ctx, AMPS_OK,
                  "%s: %ld tetrahedra repeated (a volume in several physical groups): each read once, "
                  "its region the first group's",
                  L->name, (long)ndup);
    m = amps__rd_end(&G.R, s);
    amps__free(ctx, G.tags);
    amps__free(ctx, G.vol_tag);
    amps__free(ctx, G.vol_phys);
    return m;
}

/* ---- MEDIT .mesh (ASCII) ---- */

/* 1 if the last token looks like a number (so it is not a keyword). */
static int amps__lx_numeric(const amps__lex *L) {
    char c = L->tok[0];
    return (c >= '0' && c <= '9') || c == '+' || c == '-' || c == '.';
}

/* Skips the numeric data after an unknown keyword, up to the next non-numeric token. */
static void amps__medit_skip(amps__lex *L) {
    while (amps__lx_skip(L, 1)) {
        const char *save = L->p;
        long long sline = L->line;
        amps__lx_tok(L, 1);
        if (!amps__lx_numeric(L)) {
            L->p = save;
            L->line = sline;
            break;
        }
    }
}

/* Vertices, after the keyword (once): the count, then "x y z ref" per vertex. Fills R->xyz. */
static amps_status amps__medit_vertices(amps__rd *R) {
    amps__lex *L = &R->L;
    long long n, k, ref;
    amps_status s;
    if (R->xyz) return amps__lx_err(L, L->tline, AMPS_ERR_PARSE, "duplicate Vertices section");
    s = amps__lx_nrec(L, 1, &n, "vertex count", "vertex", 4);
    if (!s) s = amps__rd_points(R, n);
    for (k = 0; !s && k < n; k++) {
        s = amps__lx_xyz(L, 1, R->xyz + 3 * k);
        if (!s) s = amps__lx_int(L, 1, &ref, "vertex reference");
    }
    return s;
}

/* One tetrahedron "v1 v2 v3 v4 ref" (vertex indices from 1): nodes, the line of v1 and the
   region ref into r. */
static amps_status amps__medit_tet(amps__rd *R, amps__tetrec *r) {
    long long ref;
    int q;
    amps_status s = AMPS_OK;
    for (q = 0; !s && q < 4; q++) {
        s = amps__lx_index(&R->L, 1, "vertex index", 1, R->nn, r->v + q);
        if (q == 0) r->line = R->L.tline;
    }
    if (!s) s = amps__lx_int(&R->L, 1, &ref, "tetrahedron reference");
    return s ? s : amps__lx_region(&R->L, ref, &r->region);
}

/* Tetrahedra, after the keyword (after Vertices, once: *seen): the count, then the tets into R->tb. */
static amps_status amps__medit_tets(amps__rd *R, int *seen) {
    amps__lex *L = &R->L;
    amps__tetrec r;
    long long n, k;
    amps_status s;
    if (!R->xyz) return amps__lx_err(L, L->tline, AMPS_ERR_PARSE, "Tetrahedra before Vertices");
    if (*seen) return amps__lx_err(L, L->tline, AMPS_ERR_PARSE, "duplicate Tetrahedra section");
    *seen = 1;
    s = amps__lx_nrec(L, 1, &n, "tetrahedron count", "tetrahedron", 5);
    if (!s) s = amps__tb_reserve(L->ctx, &R->tb, (amps_int)(n > 0 ? n : 1));
    for (k = 0; !s && k < n; k++) {
        s = amps__medit_tet(R, &r);
        if (!s) s = amps__tb_push(L->ctx, &R->tb, &r);
    }
    return s;
}

/* The current keyword names volume elements other than linear tets (Hexahedra, Prisms,
   Pyramids, and any of their or the tets' higher-order variants such as TetrahedraP2). */
static int amps__medit_volume(const amps__lex *L) {
    static const char *kind[] = {"Hexahedra", "Prisms", "Pyramids", "Tetrahedra"};
    size_t k, i, n;
    for (k = 0; k < 4; k++) {
        n = strlen(kind[k]);
        if (L->tlen < n) continue;
        for (i = 0; i < n; i++) {
            int a = (unsigned char)L->tok[i], b = (unsigned char)kind[k][i];
            if ((a | 32) != (b | 32)) break;
        }
        if (i == n) return 1; /* Tetrahedra itself is matched before */
    }
    return 0;
}

AMPS_API amps_mesh *amps_mesh_read_medit_mem(amps_ctx *ctx, const char *buf, size_t len, const char *name) {
    amps__rd R;
    amps__lex *L = &R.L;
    int have_tets = 0;
    long long n = 0;
    amps_status s = AMPS_OK;
    amps__rd_init(&R, ctx, buf, len, name ? name : "<mesh>", '#');
    /* keywords up to End or the end of the file */
    while (!s && amps__lx_tok(L, 1) && !amps__lx_is(L, "End", 1)) {
        if (amps__lx_is(L, "MeshVersionFormatted", 1)) {
            s = amps__lx_int(L, 1, &n, "format version");
        } else if (amps__lx_is(L, "Dimension", 1)) {
            s = amps__lx_int(L, 1, &n, "dimension");
            if (!s && n != 3) s = amps__lx_err(L, L->tline, AMPS_ERR_PARSE, "dimension must be 3, found %lld", n);
        } else if (amps__lx_is(L, "Vertices", 1)) {
            s = amps__medit_vertices(&R);
        } else if (amps__lx_is(L, "Tetrahedra", 1)) {
            s = amps__medit_tets(&R, &have_tets);
        } else if (amps__medit_volume(L)) { /* other volume elements: not dropped silently */
            long long line = L->tline, cnt = 0;
            char kw[32];
            size_t kl = L->tlen < sizeof(kw) - 1 ? L->tlen : sizeof(kw) - 1;
            memcpy(kw, L->tok, kl);
            kw[kl] = '\0';
            s = amps__lx_int(L, 1, &cnt, "element count");
            if (!s && cnt != 0) /* an empty section is harmless */
                s = amps__lx_err(L, line, AMPS_ERR_MESH,
                                 "%lld %s: amps reads linear tetrahedra only (Tetrahedra); mesh with them only", cnt,
                                 kw);
        } else if (!amps__lx_numeric(L)) {
            amps__medit_skip(L); /* other keyword */
        } else {
            s = amps__lx_found(L, "expected a keyword, found ");
        }
    }
    if (!s && !R.xyz) s = amps__lx_err(L, amps__lx_here(L), AMPS_ERR_PARSE, "no Vertices section");
    if (!s && (!have_tets || R.tb.n == 0))
        s = amps__lx_err(L, amps__lx_here(L), AMPS_ERR_PARSE, "no Tetrahedra in the file");
    return amps__rd_end(&R, s);
}

/* ---- files ---- */
#ifndef AMPS_NO_STDIO

/* Whole file into a new buffer (*len bytes, NUL-terminated). */
static amps_status amps__read_all(amps_ctx *ctx, const char *path, char **out, size_t *len) {
    FILE *f;
    char *b = NULL;
    size_t n = 0, cap = 0, got;
    *out = NULL;
    *len = 0;
    if (!path) return amps__err(ctx, AMPS_ERR_ARG, "NULL file name");
    f = fopen(path, "rb");
    if (!f) return amps__err(ctx, AMPS_ERR_IO, "%P: cannot open file", path);
    for (;;) {
        if (cap - n < 2) {
            void *p = b;
            size_t nc = cap ? 2 * cap : 65536;
            if (nc < cap || amps__realloc(ctx, &p, nc, 1)) {
                amps__free(ctx, b);
                fclose(f);
                return amps__err(ctx, AMPS_ERR_OOM, "%P: out of memory reading the file", path);
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
        return amps__err(ctx, AMPS_ERR_IO, "%P: read error", path);
    }
    fclose(f);
    b[n] = 0;
    *out = b;
    *len = n;
    return AMPS_OK;
}

/* Reads the whole file at path and parses it with a from-memory reader. */
static amps_mesh *amps__read_with(amps_ctx *ctx, const char *path,
                                  amps_mesh *(*parse)(amps_ctx *, const char *, size_t, const char *)) {
    char *b;
    size_t n;
    amps_mesh *m;
    if (amps__read_all(ctx, path, &b, &n)) return NULL;
    m = parse(ctx, b, n, path);
    amps__free(ctx, b);
    return m;
}

AMPS_API amps_mesh *amps_mesh_read_gmsh(amps_ctx *ctx, const char *path) {
    return amps__read_with(ctx, path, amps_mesh_read_gmsh_mem);
}

AMPS_API amps_mesh *amps_mesh_read_medit(amps_ctx *ctx, const char *path) {
    return amps__read_with(ctx, path, amps_mesh_read_medit_mem);
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
    amps__err(ctx, AMPS_ERR_ARG, "%P: unknown mesh format (expected .node, .ele, .msh or .mesh)", path);
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
    if (!o->f) return amps__err(ctx, AMPS_ERR_IO, "%s: %P: cannot open for writing", fn, path ? path : "(null)");
    return AMPS_OK;
}

static amps_status amps__close_out(amps_ctx *ctx, const char *fn, const char *path, amps__out *o) {
    if (fclose(o->f) != 0) o->bad = 1;
    if (o->bad) return amps__err(ctx, AMPS_ERR_IO, "%s: %P: write failed", fn, path);
    return AMPS_OK;
}

AMPS_API amps_status amps_mesh_write_vtu(amps_ctx *ctx, const char *path, const amps_mesh *m, const double *disp,
                                         const double *von_mises, const double *principal) {
    const char *fn = "amps_mesh_write_vtu";
    amps__out o;
    amps_int v, t;
    amps_status s;
    if (!m) return amps__err(ctx, AMPS_ERR_ARG, "%s: NULL mesh", fn);
    s = amps__open_out(ctx, fn, path, &o);
    if (s) return s;
    amps__pr(&o, "<?xml version=\"1.0\"?>\n"
                 "<VTKFile type=\"UnstructuredGrid\" version=\"0.1\" byte_order=\"LittleEndian\">\n");
    amps__pr(&o, "<UnstructuredGrid>\n<Piece NumberOfPoints=\"%lld\" NumberOfCells=\"%lld\">\n", (long long)m->nnode,
             (long long)(m->ntet - m->nremoved));
    amps__pr(&o, "<Points>\n<DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"ascii\">\n");
    for (v = 0; v < m->nnode; v++)
        amps__pr(&o, "%.17g %.17g %.17g\n", m->xyz[3 * v], m->xyz[3 * v + 1], m->xyz[3 * v + 2]);
    amps__pr(&o,
             "</DataArray>\n</Points>\n<Cells>\n<DataArray type=\"Int64\" Name=\"connectivity\" format=\"ascii\">\n");
    for (t = 0; t < m->ntet; t++)
        if (!m->removed[t])
            amps__pr(&o, "%lld %lld %lld %lld\n", (long long)m->tet[4 * t], (long long)m->tet[4 * t + 1],
                     (long long)m->tet[4 * t + 2], (long long)m->tet[4 * t + 3]);
    amps__pr(&o, "</DataArray>\n<DataArray type=\"Int64\" Name=\"offsets\" format=\"ascii\">\n");
    for (t = 0; t < m->ntet - m->nremoved; t++) amps__pr(&o, "%lld\n", 4 * (long long)(t + 1));
    amps__pr(&o, "</DataArray>\n<DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">\n");
    for (t = 0; t < m->ntet - m->nremoved; t++) amps__pr(&o, "10\n");
    amps__pr(&o, "</DataArray>\n</Cells>\n");
    amps__pr(&o, "<PointData%s>\n", disp ? " Vectors=\"displacement\"" : "");
    if (disp) {
        amps__pr(&o, "<DataArray type=\"Float64\" Name=\"displacement\" NumberOfComponents=\"3\" format=\"ascii\">\n");
        for (v = 0; v < m->nnode; v++)
            amps__pr(&o, "%.17g %.17g %.17g\n", disp[3 * v], disp[3 * v + 1], disp[3 * v + 2]);
        amps__pr(&o, "</DataArray>\n");
    }
    amps__pr(&o, "<DataArray type=\"Int64\" Name=\"origin\" format=\"ascii\">\n");
    for (v = 0; v < m->nnode; v++) amps__pr(&o, "%lld\n", (long long)m->origin[v]);
    amps__pr(&o, "</DataArray>\n</PointData>\n");
    amps__pr(&o, "<CellData%s>\n", von_mises ? " Scalars=\"von_mises\"" : "");
    if (von_mises) {
        amps__pr(&o, "<DataArray type=\"Float64\" Name=\"von_mises\" format=\"ascii\">\n");
        for (t = 0; t < m->ntet; t++)
            if (!m->removed[t]) amps__pr(&o, "%.17g\n", von_mises[t]);
        amps__pr(&o, "</DataArray>\n");
    }
    if (principal) {
        amps__pr(&o,
                 "<DataArray type=\"Float64\" Name=\"principal_stress\" NumberOfComponents=\"3\" format=\"ascii\">\n");
        for (t = 0; t < m->ntet; t++)
            if (!m->removed[t])
                amps__pr(&o, "%.17g %.17g %.17g\n", principal[3 * t], principal[3 * t + 1], principal[3 * t + 2]);
        amps__pr(&o, "</DataArray>\n");
    }
    amps__pr(&o, "<DataArray type=\"Int64\" Name=\"region\" format=\"ascii\">\n");
    for (t = 0; t < m->ntet; t++)
        if (!m->removed[t]) amps__pr(&o, "%lld\n", (long long)m->region[t]);
    amps__pr(&o, "</DataArray>\n<DataArray type=\"UInt8\" Name=\"cut\" format=\"ascii\">\n");
    for (t = 0; t < m->ntet; t++) {
        const amps_int *tv = m->tet + 4 * t;
        int cut = tv[0] >= m->nfile || tv[1] >= m->nfile || tv[2] >= m->nfile || tv[3] >= m->nfile;
        if (!m->removed[t]) amps__pr(&o, "%d\n", cut);
    }
    amps__pr(&o, "</DataArray>\n</CellData>\n</Piece>\n</UnstructuredGrid>\n</VTKFile>\n");
    return amps__close_out(ctx, fn, path, &o);
}

AMPS_API amps_status amps_mesh_write_tetgen(amps_ctx *ctx, const char *base, const amps_mesh *m, int first_index) {
    const char *fn = "amps_mesh_write_tetgen";
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
            amps__pr(&o, "%lld %.17g %.17g %.17g\n", (long long)v + first_index, m->xyz[3 * v], m->xyz[3 * v + 1],
                     m->xyz[3 * v + 2]);
        amps__pr(&o, "# written by amps.h\n");
        s = amps__close_out(ctx, fn, path, &o);
    }
    if (!s) {
        memcpy(path + n, ".ele", 5);
        s = amps__open_out(ctx, fn, path, &o);
    }
    if (!s) {
        int nat = 0;
        long long k = first_index;
        for (t = 0; t < m->ntet; t++) nat |= !m->removed[t] && m->region[t] != 0;
        amps__pr(&o, "%lld 4 %d\n", (long long)(m->ntet - m->nremoved), nat);
        for (t = 0; t < m->ntet; t++) {
            if (m->removed[t]) continue;
            amps__pr(&o, "%lld %lld %lld %lld %lld", k++, (long long)m->tet[4 * t] + first_index,
                     (long long)m->tet[4 * t + 1] + first_index, (long long)m->tet[4 * t + 2] + first_index,
                     (long long)m->tet[4 * t + 3] + first_index);
            if (nat) amps__pr(&o, " %lld", (long long)m->region[t]);
            amps__pr(&o, "\n");
        }
        s = amps__close_out(ctx, fn, path, &o);
    }
    amps__free(ctx, path);
    return s;
}

/* The distinct regions of the live tets of m, ascending, into a new array *reg (*n of them). */
static amps_status amps__live_regions(amps_ctx *ctx, const amps_mesh *m, amps_int **reg, amps_int *n) {
    amps_int t, k = 0, *r = AMPS__CAST(amps_int *, amps__malloc(ctx, (size_t)m->ntet, sizeof(amps_int)));
    *reg = r;
    *n = 0;
    if (!r) return AMPS_ERR_OOM;
    for (t = 0; t < m->ntet; t++)
        if (!m->removed[t]) r[k++] = m->region[t];
    amps__sort(r, (size_t)k, sizeof(amps_int), amps__int_cmp);
    for (t = 0; t < k; t++)
        if (*n == 0 || r[t] != r[*n - 1]) r[(*n)++] = r[t];
    return AMPS_OK;
}

/* Index of region id in the ascending reg[0..n-1] (present). */
static amps_int amps__region_index(const amps_int *reg, amps_int n, amps_int id) {
    amps_int lo = 0, hi = n - 1;
    while (lo < hi) {
        amps_int mid = lo + (hi - lo) / 2;
        if (reg[mid] < id) lo = mid + 1;
        else hi = mid;
    }
    return lo;
}

/* Gmsh 4.1 $Entities: volume entity k + 1 per region reg[k] (physical tag reg[k]; none for
   region 0), all with the bounding box of the nodes; at least volume 1, which holds the nodes. */
static void amps__gmsh_write_entities(amps__out *o, const amps_mesh *m, const amps_int *reg, amps_int nreg) {
    double lo[3], hi[3];
    amps_int v, k;
    int c;
    for (c = 0; c < 3; c++) lo[c] = hi[c] = m->xyz[c];
    for (v = 0; v < m->nnode; v++)
        for (c = 0; c < 3; c++) {
            if (m->xyz[3 * v + c] < lo[c]) lo[c] = m->xyz[3 * v + c];
            if (m->xyz[3 * v + c] > hi[c]) hi[c] = m->xyz[3 * v + c];
        }
    amps__pr(o, "$Entities\n0 0 0 %lld\n", (long long)(nreg > 0 ? nreg : 1));
    for (k = 0; k < (nreg > 0 ? nreg : 1); k++) {
        amps__pr(o, "%lld %.17g %.17g %.17g %.17g %.17g %.17g", (long long)k + 1, lo[0], lo[1], lo[2], hi[0], hi[1],
                 hi[2]);
        if (nreg > 0 && reg[k] != 0) amps__pr(o, " 1 %lld 0\n", (long long)reg[k]);
        else amps__pr(o, " 0 0\n");
    }
    amps__pr(o, "$EndEntities\n");
}

/* Gmsh 4.1 $Elements of the live tets in index order: one block per run of equal regions, in
   the region's volume entity. */
static void amps__gmsh_write_blocks4(amps__out *o, const amps_mesh *m, const amps_int *reg, amps_int nreg) {
    amps_int t, u, nblk = 0, prev = 0;
    long long k = 1;
    for (t = 0, u = 0; t < m->ntet; t++)
        if (!m->removed[t]) {
            if (u == 0 || m->region[t] != prev) nblk++;
            prev = m->region[t];
            u = 1;
        }
    amps__pr(o, "$Elements\n%lld %lld 1 %lld\n", (long long)nblk, (long long)(m->ntet - m->nremoved),
             (long long)(m->ntet - m->nremoved));
    for (t = 0; t < m->ntet; t = u) {
        amps_int cnt = 0;
        if (m->removed[t]) {
            u = t + 1;
            continue;
        }
        for (u = t; u < m->ntet && (m->removed[u] || m->region[u] == m->region[t]); u++) cnt += !m->removed[u];
        amps__pr(o, "3 %lld 4 %lld\n", (long long)amps__region_index(reg, nreg, m->region[t]) + 1, (long long)cnt);
        for (u = t; u < m->ntet && (m->removed[u] || m->region[u] == m->region[t]); u++)
            if (!m->removed[u])
                amps__pr(o, "%lld %lld %lld %lld %lld\n", k++, (long long)m->tet[4 * u] + 1,
                         (long long)m->tet[4 * u + 1] + 1, (long long)m->tet[4 * u + 2] + 1,
                         (long long)m->tet[4 * u + 3] + 1);
    }
}

AMPS_API amps_status amps_mesh_write_gmsh(amps_ctx *ctx, const char *path, const amps_mesh *m, int version) {
    const char *fn = "amps_mesh_write_gmsh";
    amps__out o;
    amps_int v, t, *reg = NULL, nreg = 0;
    amps_status s;
    long long nn, nt, k;
    if (!m || (version != 2 && version != 4))
        return amps__err(ctx, AMPS_ERR_ARG, "%s: NULL mesh or version not 2 or 4", fn);
    s = amps__open_out(ctx, fn, path, &o);
    if (s) return s;
    nn = (long long)m->nnode;
    nt = (long long)(m->ntet - m->nremoved);
    s = amps__live_regions(ctx, m, &reg, &nreg); /* an entity per region, in both versions */
    if (s) {
        fclose(o.f);
        return s;
    }
    amps__pr(&o, "$MeshFormat\n%s 0 8\n$EndMeshFormat\n", version == 2 ? "2.2" : "4.1");
    if (version == 2) {
        amps__pr(&o, "$Nodes\n%lld\n", nn);
        for (v = 0; v < m->nnode; v++)
            amps__pr(&o, "%lld %.17g %.17g %.17g\n", (long long)v + 1, m->xyz[3 * v], m->xyz[3 * v + 1],
                     m->xyz[3 * v + 2]);
        amps__pr(&o, "$EndNodes\n$Elements\n%lld\n", nt);
        for (t = 0, k = 1; t < m->ntet; t++)
            if (!m->removed[t])
                amps__pr(&o, "%lld 4 2 %lld %lld %lld %lld %lld %lld\n", k++, (long long)m->region[t],
                         (long long)amps__region_index(reg, nreg, m->region[t]) + 1, (long long)m->tet[4 * t] + 1,
                         (long long)m->tet[4 * t + 1] + 1, (long long)m->tet[4 * t + 2] + 1,
                         (long long)m->tet[4 * t + 3] + 1);
    } else {
        amps__gmsh_write_entities(&o, m, reg, nreg);
        amps__pr(&o, "$Nodes\n1 %lld 1 %lld\n3 1 0 %lld\n", nn, nn, nn);
        for (v = 0; v < m->nnode; v++) amps__pr(&o, "%lld\n", (long long)v + 1);
        for (v = 0; v < m->nnode; v++)
            amps__pr(&o, "%.17g %.17g %.17g\n", m->xyz[3 * v], m->xyz[3 * v + 1], m->xyz[3 * v + 2]);
        amps__pr(&o, "$EndNodes\n");
        amps__gmsh_write_blocks4(&o, m, reg, nreg);
    }
    amps__free(ctx, reg);
    amps__pr(&o, "$EndElements\n");
    return amps__close_out(ctx, fn, path, &o);
}

AMPS_API amps_status amps_mesh_write_medit(amps_ctx *ctx, const char *path, const amps_mesh *m) {
    const char *fn = "amps_mesh_write_medit";
    amps__out o;
    amps_int v, t;
    amps_status s;
    if (!m) return amps__err(ctx, AMPS_ERR_ARG, "%s: NULL mesh", fn);
    s = amps__open_out(ctx, fn, path, &o);
    if (s) return s;
    amps__pr(&o, "MeshVersionFormatted 2\nDimension 3\nVertices\n%lld\n", (long long)m->nnode);
    for (v = 0; v < m->nnode; v++)
        amps__pr(&o, "%.17g %.17g %.17g 0\n", m->xyz[3 * v], m->xyz[3 * v + 1], m->xyz[3 * v + 2]);
    amps__pr(&o, "Tetrahedra\n%lld\n", (long long)(m->ntet - m->nremoved));
    for (t = 0; t < m->ntet; t++)
        if (!m->removed[t])
            amps__pr(&o, "%lld %lld %lld %lld %lld\n", (long long)m->tet[4 * t] + 1, (long long)m->tet[4 * t + 1] + 1,
                     (long long)m->tet[4 * t + 2] + 1, (long long)m->tet[4 * t + 3] + 1, (long long)m->region[t]);
    amps__pr(&o, "End\n");
    return amps__close_out(ctx, fn, path, &o);
}

/* s with the XML special characters as entities. */
static void amps__pr_xml(amps__out *o, const char *s) {
    for (; *s; s++) {
        if (*s == '&') amps__pr(o, "&amp;");
        else if (*s == '<') amps__pr(o, "&lt;");
        else if (*s == '>') amps__pr(o, "&gt;");
        else if (*s == '"') amps__pr(o, "&quot;");
        else amps__pr(o, "%c", *s);
    }
}

AMPS_API amps_status amps_pvd_write(amps_ctx *ctx, const char *path, amps_int n, const char *const *vtu_files,
                                    const double *times) {
    const char *fn = "amps_pvd_write";
    amps__out o;
    amps_int k;
    amps_status s;
    if (!path || n < 0 || (n > 0 && (!vtu_files || !times)))
        return amps__err(ctx, AMPS_ERR_ARG, "%s: NULL path or array, or n < 0", fn);
    for (k = 0; k < n; k++) {
        if (!vtu_files[k]) return amps__err(ctx, AMPS_ERR_ARG, "%s: file name %lld is NULL", fn, (long long)k);
        if (!amps__isfinite(times[k]))
            return amps__err(ctx, AMPS_ERR_VALUE, "%s: time %lld is not finite", fn, (long long)k);
    }
    s = amps__open_out(ctx, fn, path, &o);
    if (s) return s;
    amps__pr(&o, "<?xml version=\"1.0\"?>\n"
                 "<VTKFile type=\"Collection\" version=\"0.1\" byte_order=\"LittleEndian\">\n<Collection>\n");
    for (k = 0; k < n; k++) {
        amps__pr(&o, "<DataSet timestep=\"%.17g\" group=\"\" part=\"0\" file=\"", times[k]);
        amps__pr_xml(&o, vtu_files[k]);
        amps__pr(&o, "\"/>\n");
    }
    amps__pr(&o, "</Collection>\n</VTKFile>\n");
    return amps__close_out(ctx, fn, path, &o);
}
#endif /* AMPS_NO_STDIO */
#endif /* AMPS_NO_FEM */

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
