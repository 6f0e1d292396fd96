/* The parallel layer: every parallel kernel (numeric factorization with the parallel top groups,
   solves: tree-parallel backward, closure, multi-RHS; the update engine's Steps 1-4, its dense
   factorization and the residual check) run on the test job system (tests/jobs_test.h: inline, 4 workers, 4 workers
   with random delays, refusing to queue), on OpenMP teams of 2 and 3 and on amps' own workers
   (2 and 4 participants) gives the bits of the serial run; each kernel is checked to have gone
   through the host's enqueue. */
#define AMPS_IMPLEMENTATION
#define AMPS__PAR_ADAPT 0 /* every eligible loop parallel, whatever the timing says */
#define AMPS__BE_PARMIN 0 /* the residual check's blocks on the layer at any size */
#include "amps.h"
#include "amps_test.h"
#include "fe_util.h"
#include "cholmod_ref.h"
#include "core_mats.h"
#include "jobs_test.h"
#include <string.h>

static int t_nenq = 0; /* enqueues seen (calling thread only) */
static void *count_enqueue(amps_task_fn *task, amps_int n, amps_int min_range, void *task_ctx, void *user) {
    t_nenq++;
    return t_jobs_enqueue(task, n, min_range, task_ctx, user);
}

/* Context variant v: 0 serial, 1..4 the job system's modes, 5/6 OpenMP teams of 2/3, 7/8 amps'
   own workers, 2/4 participants. */
static void ctx_variant(amps_ctx *ctx, int v) {
    amps_ctx_init(ctx);
    ctx->enqueue_task = NULL;
    ctx->finish_task = NULL;
    ctx->nthreads = 1;
    if (v >= 1 && v <= 4) {
        t_jobs_ctx(ctx, v);
        ctx->enqueue_task = count_enqueue;
    } else if (v == 5 || v == 6) {
        ctx->nthreads = v - 3;
        ctx->backend = AMPS_BACKEND_OPENMP;
    } else if (v >= 7) {
        ctx->nthreads = v == 7 ? 2 : 4;
        ctx->backend = AMPS_BACKEND_THREADS;
    }
}
#define NVAR 9
static const char *vname[NVAR] = {"serial", "inline", "pool", "delays", "refuse", "omp2", "omp3", "threads2", "threads4"};

/* amps__par_for covers [0, n) by its chunks exactly once, with slots below nt. */
static void chunk_mark(amps_int b, amps_int e, int slot, void *arg) {
    int *a = (int *)arg;
    for (; b < e; b++) a[b] += 1 + 1000 * slot;
}
static void check_layer(void) {
    int v, nt;
    for (v = 0; v < NVAR; v++)
        for (nt = 1; nt <= 6; nt++) {
            amps_ctx ctx;
            amps__par par;
            amps__pool *pool;
            int a[1001], k, once = 1, slots = 1;
            ctx_variant(&ctx, v);
            pool = amps__pool_new(&ctx);
            CHECK((pool != NULL) == (AMPS__HAVE_POOL && v >= 7), "layer %s: workers %p", vname[v], (void *)pool);
            par = amps__par_of(&ctx, NULL, pool);
            memset(a, 0, sizeof(a));
            amps__par_for(&par, nt, 1000, 7, chunk_mark, a);
            for (k = 0; k < 1000; k++) {
                once &= a[k] % 1000 == 1;
                slots &= a[k] / 1000 < nt;
            }
            CHECK(once && slots && a[1000] == 0, "layer %s nt %d: items once %d, slots %d", vname[v], nt, once, slots);
            amps__pool_free(&ctx, pool);
        }
}

/* amps' own workers take chunks: the caller's first chunk waits (up to 5 s) until a worker ran
   one; a loop whose worker is slow finishes, and the workers are joined at free. */
typedef struct wait_arg {
    int nt, by_worker;
} wait_arg;
static void chunk_wait(amps_int b, amps_int e, int slot, void *arg) {
    wait_arg *w = (wait_arg *)arg;
    (void)b;
    (void)e;
    if (slot < w->nt - 1) {
        __atomic_store_n(&w->by_worker, 1, __ATOMIC_RELEASE);
        return;
    }
    if (b == 0 || b == 1) {
        double t0 = amps_now();
        while (!__atomic_load_n(&w->by_worker, __ATOMIC_ACQUIRE) && amps_now() - t0 < 5.0) {}
    }
}
static void check_workers(void) {
#if AMPS__HAVE_POOL
    int rep;
    for (rep = 0; rep < 20; rep++) {
        amps_ctx ctx;
        amps__pool *pool;
        amps__par par;
        wait_arg w;
        ctx_variant(&ctx, rep % 2 ? 8 : 7);
        pool = amps__pool_new(&ctx);
        par = amps__par_of(&ctx, NULL, pool);
        w.nt = ctx.nthreads;
        w.by_worker = 0;
        amps__par_for(&par, w.nt, 64, 1, chunk_wait, &w);
        CHECK(w.by_worker, "%s: no chunk ran on a worker", vname[rep % 2 ? 8 : 7]);
        amps__pool_free(&ctx, pool);
    }
#endif
}

typedef struct result {
    double *Lx, *D, *x, *X, *y, *xu, *xu2, *rho, be[2]; /* rho, be: the residual check */
    size_t nnz;                                         /* entries of L */
} result;

static void result_free(result *r) {
    free(r->Lx);
    free(r->D);
    free(r->x);
    free(r->X);
    free(r->y);
    free(r->xu);
    free(r->xu2);
    free(r->rho);
}

static double *dupd(const double *p, size_t n) {
    double *q = (double *)malloc(sizeof(double) * (n ? n : 1));
    memcpy(q, p, sizeof(double) * n);
    return q;
}

/* Every kernel under variant v on K (upper, order n) with ordering perm; r receives the results. */
static void run_all(int v, const amps_csc *K, const int *perm, result *r, int *nenq) {
    amps_ctx ctx;
    amps_order_opts o;
    amps_factor *F;
    amps_update *U;
    amps_marker mk;
    int n = K->ncol, k, nrhs = 11, nreq = 5, ncl, before;
    int *req = (int *)malloc(sizeof(int) * n), *clo = (int *)malloc(sizeof(int) * n),
        *iw = (int *)malloc(sizeof(int) * n);
    double *b = (double *)malloc(sizeof(double) * n), *w = (double *)malloc(sizeof(double) * n), *B, *work;
    ctx_variant(&ctx, v);
    memset(&o, 0, sizeof(o));
    o.method = AMPS_ORDER_GIVEN;
    o.perm = perm;
    memset(r, 0, sizeof(*r));
    /* numeric factorization, the parallel paths forced */
    before = t_nenq;
    F = amps_analyze(&ctx, K, AMPS_UPPER, &o);
    CHECK(F != NULL, "%s: analyze: %s", vname[v], ctx.msg);
    if (!F) return;
    ((amps__fpriv *)F->priv)->parmin = 0;
    ((amps__fpriv *)F->priv)->pargroup = 0;
    CHECK(amps_factorize(&ctx, F, K) == AMPS_OK, "%s: factorize: %s", vname[v], ctx.msg);
    nenq[0] = t_nenq - before;
    r->nnz = (size_t)F->Lp[n];
    r->Lx = dupd(F->Lx, r->nnz);
    r->D = dupd(F->D, (size_t)n);
    /* solve (tree-parallel backward) */
    for (k = 0; k < n; k++) b[k] = sin(0.1 * k) + 0.5;
    r->x = (double *)malloc(sizeof(double) * n);
    before = t_nenq;
    CHECK(amps_solve(&ctx, F, b, r->x, w) == AMPS_OK, "%s: solve", vname[v]);
    nenq[1] = t_nenq - before;
    /* multi-RHS */
    B = (double *)malloc(sizeof(double) * n * nrhs);
    r->X = (double *)malloc(sizeof(double) * n * nrhs);
    for (k = 0; k < n * nrhs; k++) B[k] = cos(0.01 * k);
    work = (double *)malloc(sizeof(double) * amps_solve_multi_work(&ctx, F, nrhs));
    before = t_nenq;
    CHECK(amps_solve_multi(&ctx, F, nrhs, B, n, r->X, n, work) == AMPS_OK, "%s: solve_multi", vname[v]);
    nenq[2] = t_nenq - before;
    /* closure backward solve */
    CHECK(amps_marker_init(&ctx, &mk, n) == AMPS_OK, "marker");
    for (k = 0; k < nreq; k++) req[k] = (k * 7919) % n;
    ncl = amps_closure(F, nreq, req, clo, &mk);
    r->y = dupd(b, (size_t)n);
    {
        amps__par par = amps__par_of(&ctx, NULL, ((amps__fpriv *)F->priv)->pool);
        before = t_nenq;
        amps__ltsolve_closure_par(F, ncl, clo, r->y, &par, amps__nthreads(&ctx, 1024), iw);
        nenq[3] = t_nenq - before;
    }
    amps_marker_free(&ctx, &mk);
    /* the update engine: Steps 1-4 and the dense factorization on many positions, twice */
    {
        amps_update_opts uo;
        amps_update_opts_default(&uo);
        uo.cap_mod = 512;
        U = amps_update_create(&ctx, K, AMPS_UPPER, F, &uo);
    }
    CHECK(U != NULL, "%s: update create: %s", vname[v], ctx.msg);
    if (U) {
        int m = 240, *ci = (int *)malloc(sizeof(int) * n), *ri = (int *)malloc(sizeof(int) * n);
        double *cv = (double *)malloc(sizeof(double) * n), *f = (double *)malloc(sizeof(double) * n);
        amps_status s;
        for (k = 0; k < n; k++) {
            ci[k] = k;
            f[k] = 1e-3 * cos(0.37 * k);
        }
        CHECK(amps_update_set_force(&ctx, U, n, ci, f) == AMPS_OK, "force");
        for (k = 0; k < m; k++) {
            ci[k] = (int)(((long long)k * 104729) % n);
            cv[k] = 0.0;
            ri[k] = (int)(((long long)k * 7) % n);
        }
        CHECK(amps_update_constrain(&ctx, U, m, ci, cv) == AMPS_OK, "constrain");
        for (k = 0; k < 60; k++) cv[k] = 50.0 + k;
        CHECK(amps_update_add(&ctx, U, 60, ri, ri, cv) == AMPS_OK, "add");
        r->xu = (double *)malloc(sizeof(double) * n);
        before = t_nenq;
        s = amps_update_solve(&ctx, U, r->xu);
        CHECK(s == AMPS_OK, "%s: update solve: %d %s", vname[v], (int)s, ctx.msg);
        nenq[4] = t_nenq - before;
        for (k = 0; k < 100; k++) {
            ci[k] = (int)(((long long)(k + m) * 104729) % n);
            cv[k] = 1e-4;
        }
        CHECK(amps_update_constrain(&ctx, U, 100, ci, cv) == AMPS_OK, "constrain 2");
        r->xu2 = (double *)malloc(sizeof(double) * n);
        s = amps_update_solve(&ctx, U, r->xu2);
        CHECK(s == AMPS_OK, "%s: update solve 2: %d %s", vname[v], (int)s, ctx.msg);
        { /* the residual check (amps__backward_error's 3x3 blocks on the layer) */
            double rn;
            before = t_nenq;
            r->be[0] = amps__backward_error(U, U->sol.x, U->work.resid, &rn, 0, &r->be[1]);
            r->rho = dupd(U->work.resid, (size_t)n);
            nenq[5] = t_nenq - before;
        }
        amps_update_free(&ctx, U);
        free(ci);
        free(ri);
        free(cv);
        free(f);
    }
    amps_factor_free(&ctx, F);
    free(req);
    free(clo);
    free(iw);
    free(b);
    free(w);
    free(B);
    free(work);
}

static int same(const double *a, const double *b, size_t n) { return a && b && memcmp(a, b, sizeof(double) * n) == 0; }

int main(void) {
    amps_ctx ctx;
    amps_csc *K;
    int *perm, n, v;
    result r0, r;
    (void)m_analyze;
    (void)fe_beam;
    check_layer();
    check_workers();
    amps_ctx_init(&ctx);
    K = m_fe(&ctx, fe_brick(9), 1);
    n = K->ncol;
    {
        amps_factor *F = amps_analyze(&ctx, K, AMPS_UPPER, NULL);
        perm = (int *)malloc(sizeof(int) * n);
        memcpy(perm, F->perm, sizeof(int) * n);
        amps_factor_free(&ctx, F);
    }
    {
        int nenq[6];
        run_all(0, K, perm, &r0, nenq);
    }
    for (v = 1; v < NVAR; v++) {
        int nenq[6] = {0, 0, 0, 0, 0, 0};
        run_all(v, K, perm, &r, nenq);
        CHECK(r.nnz == r0.nnz && same(r.Lx, r0.Lx, r0.nnz) && same(r.D, r0.D, (size_t)n), "%s: factor differs",
              vname[v]);
        CHECK(same(r.x, r0.x, (size_t)n), "%s: solve differs", vname[v]);
        CHECK(same(r.X, r0.X, (size_t)n * 11), "%s: multi-RHS solve differs", vname[v]);
        CHECK(same(r.y, r0.y, (size_t)n), "%s: closure solve differs", vname[v]);
        CHECK(same(r.xu, r0.xu, (size_t)n) && same(r.xu2, r0.xu2, (size_t)n), "%s: update solves differ", vname[v]);
        CHECK(same(r.rho, r0.rho, (size_t)n) && same(r.be, r0.be, 2), "%s: residual check differs", vname[v]);
        if (v >= 1 && v <= 3) {
            int k;
            for (k = 0; k < 6; k++)
                CHECK(nenq[k] > 0, "%s: kernel %d did not reach the host (%d enqueues)", vname[v], k, nenq[k]);
        }
        result_free(&r);
    }
    printf("  brick(9): n = %d\n", n);
    result_free(&r0);
    free(perm);
    amps_csc_free(&ctx, K);
    return amps_t_end("test_par");
}
