/* Allocation failures: a counting allocator fails the k-th call, for k = 1, 2, ... until the call
   succeeds; every failure must return NULL / AMPS_ERR_OOM and leave no live allocation. */
#include <stdlib.h>
#include <stddef.h>
static long ta_calls = 0, ta_fail_at = -1, ta_live = 0;
static void *ta_malloc(size_t sz) {
    void *p;
    if (++ta_calls == ta_fail_at) return NULL;
    p = malloc(sz);
    if (p) ta_live++;
    return p;
}
static void *ta_realloc(void *p, size_t sz) {
    void *q;
    if (++ta_calls == ta_fail_at) return NULL;
    q = realloc(p, sz);
    if (q && !p) ta_live++;
    return q;
}
static void ta_free(void *p) {
    if (p) {
        ta_live--;
        free(p);
    }
}
#define AMPS_MALLOC(sz, u) ((void)(u), ta_malloc(sz))
#define AMPS_REALLOC(p, sz, u) ((void)(u), ta_realloc((p), (sz)))
#define AMPS_FREE(p, u) ((void)(u), ta_free(p))
#define AMPS_IMPLEMENTATION
#include "amps.h"
#include "amps_test.h"
#include "fe_util.h"
#include <string.h>

/* Arms the allocator to fail at call k (counting from the next call); -1 disarms. */
static void arm(long k) {
    ta_calls = 0;
    ta_fail_at = k;
}

int main(void) {
    amps_ctx ctx;
    amps_csc *A = NULL, *B;
    amps_factor *F = NULL;
    int *ti, *tj, *dof, nz, n, k, fails;
    long base;
    double *tx, tx0 = 1;
    fe_mesh m = fe_brick(3), m2 = fe_beam(2);
    amps_ctx_init(&ctx);
    dof = (int *)malloc(sizeof(int) * 3 * m.nn);
    {
        int *fixed = (int *)calloc((size_t)m.nn, sizeof(int)), v;
        for (v = 0; v < m.nn; v++) fixed[v] = m.xyz[3 * v + 2] == 0.0;
        n = fe_number(&m, fixed, dof);
        free(fixed);
    }
    nz = fe_assemble(&m, dof, 100.0, 0.3, &ti, &tj, &tx);

    /* assembly */
    for (k = 1, fails = 0;; k++) {
        arm(k);
        A = amps_csc_from_triplets(&ctx, n, nz, ti, tj, tx, AMPS_UPPER);
        if (A) break;
        fails++;
        CHECK(ctx.status == AMPS_ERR_OOM && ta_live == 0, "from_triplets fail at %d: status %d, live %ld", k,
              (int)ctx.status, ta_live);
    }
    CHECK(fails > 0, "from_triplets never failed");
    base = ta_live;
    for (k = 1;; k++) {
        arm(k);
        B = amps_csc_alloc(&ctx, n, n, 10, 1);
        if (B) break;
        CHECK(ctx.status == AMPS_ERR_OOM && ta_live == base, "csc_alloc fail at %d: live %ld", k, ta_live);
    }
    amps_csc_free(&ctx, B);

    /* analysis with the default and a given ordering */
    base = ta_live;
    {
        amps_order_opts o;
        int *perm = (int *)malloc(sizeof(int) * n), pass;
        for (k = 0; k < n; k++) perm[k] = n - 1 - k;
        memset(&o, 0, sizeof(o));
        o.method = AMPS_ORDER_GIVEN;
        o.perm = perm;
        for (pass = 0; pass < 2; pass++) {
            for (k = 1, fails = 0;; k++) {
                arm(k);
                F = amps_analyze(&ctx, A, AMPS_UPPER, pass ? &o : NULL);
                if (F) break;
                fails++;
                CHECK(ctx.status == AMPS_ERR_OOM && ta_live == base,
                      "analyze pass %d fail at %d: status %d (%s), live %ld", pass, k, (int)ctx.status, ctx.msg,
                      ta_live);
            }
            CHECK(fails >= 10, "analyze failed only %d times", fails);
            if (!pass) amps_factor_free(&ctx, F);
        }
        free(perm);
    }

    /* numeric factorization and solves allocate nothing */
    {
        double *b = (double *)malloc(sizeof(double) * n * 3), *x = (double *)malloc(sizeof(double) * n * 3);
        double *w = (double *)malloc(sizeof(double) * n * 8);
        int *cl = (int *)malloc(sizeof(int) * n), idx[2] = {0, 5};
        amps_marker mk;
        arm(-1);
        for (k = 1;; k++) {
            arm(k);
            if (amps_marker_init(&ctx, &mk, n) == AMPS_OK) break;
            CHECK(ctx.status == AMPS_ERR_OOM, "marker_init fail at %d", k);
        }
        for (k = 0; k < 3 * n; k++) b[k] = 1.0 + k % 7;
        arm(1);
        CHECK(amps_factorize(&ctx, F, A) == AMPS_OK, "factorize: %s", ctx.msg);
        CHECK(amps_solve(&ctx, F, b, x, w) == AMPS_OK, "solve: %s", ctx.msg);
        ctx.nthreads = 1;
        CHECK(amps_solve_multi_work(&ctx, F, 3) <= (size_t)n * 8, "solve_multi work size");
        CHECK(amps_solve_multi(&ctx, F, 3, b, n, x, n, w) == AMPS_OK, "solve_multi: %s", ctx.msg);
        memset(x, 0, sizeof(double) * n);
        x[0] = 1;
        x[5] = 2;
        CHECK(amps_lsolve_sparse(F, 2, idx, x, cl, &mk) > 0, "sparse solve");
        CHECK(amps_ltsolve_partial(F, 2, idx, x, cl, &mk) > 0, "partial solve");
        CHECK(ta_calls == 0, "factorize/solves allocated %ld times", ta_calls);
        arm(-1);
        amps_marker_free(&ctx, &mk);
        free(b);
        free(x);
        free(w);
        free(cl);
    }
    amps_factor_free(&ctx, F);
    amps_csc_free(&ctx, A);
    CHECK(ta_live == 0, "live allocations at the end: %ld", ta_live);
    free(ti);
    free(tj);
    free(tx);
    free(dof);
    fe_free(&m);
    fe_free(&m2);
    t_seed(1);
    CHECK(t_int(3) >= 0 && t_unif() >= 0 && t_norm(1, &tx0) == 1 && t_reldiff(1, &tx0, &tx0) == 0, "harness");
    return amps_t_end("test_alloc");
}
