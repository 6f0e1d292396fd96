/* Solves: full (against CHOLMOD), permuted kernels, sparse forward and partial backward solves on
   elimination-tree closures (values, untouched entries, work counts), closures and markers, multi-RHS. */
#define AMPS_COUNT_TOUCH
#define AMPS_IMPLEMENTATION
#include "amps.h"
#include "amps_test.h"
#include "fe_util.h"
#include "cholmod_ref.h"
#include "core_mats.h"
#include <string.h>
#include <limits.h>

static double maxabs(int n, const double *x) {
    double m = 0;
    int k;
    for (k = 0; k < n; k++)
        if (fabs(x[k]) > m) m = fabs(x[k]);
    return m;
}

/* Brute-force closure: marks every node on the paths from idx to the roots; returns the count. */
static int brute_closure(const amps_factor *F, int nidx, const int *idx, int *out) {
    int n = F->n, k, j, c = 0;
    char *in = (char *)calloc((size_t)n + 1, 1);
    for (k = 0; k < nidx; k++)
        for (j = idx[k]; j >= 0; j = F->parent[j]) in[j] = 1;
    for (j = 0; j < n; j++)
        if (in[j]) out[c++] = j;
    free(in);
    return c;
}

static void check_solves(const char *name, const amps_csc *A, const int *perm) {
    amps_ctx ctx;
    amps_factor *F;
    amps_marker m;
    int n = A->ncol, k, j, t, ok;
    double *b = (double *)malloc(sizeof(double) * n), *x = (double *)malloc(sizeof(double) * n);
    double *xr = (double *)malloc(sizeof(double) * n), *w = (double *)malloc(sizeof(double) * n);
    double *y = (double *)malloc(sizeof(double) * n), *z = (double *)malloc(sizeof(double) * n);
    int *cl = (int *)malloc(sizeof(int) * n), *cl2 = (int *)malloc(sizeof(int) * n), idx[8];
    double res, rres;
    amps_ctx_init(&ctx);
    F = m_analyze(&ctx, A, perm);
    CHECK(F != NULL, "%s: analyze: %s", name, ctx.msg);
    if (!F) return;
    memset(b, 0, sizeof(double) * n);
    CHECK(amps_solve(&ctx, F, b, x, w) == AMPS_ERR_STATE, "%s: solve before factorize accepted", name);
    CHECK(amps_factorize(&ctx, F, A) == AMPS_OK, "%s: factorize: %s", name, ctx.msg);
    /* full solve vs CHOLMOD */
    t_seed(17);
    for (k = 0; k < n; k++) b[k] = t_unif() - 0.3;
    CHECK(amps_solve(&ctx, F, b, x, w) == AMPS_OK, "%s: solve: %s", name, ctx.msg);
    CHECK(ref_solve(n, A->p, A->i, A->x, F->perm, 1, b, xr) == 0, "%s: CHOLMOD solve", name);
    res = ref_resid(n, A->p, A->i, A->x, x, b);
    rres = ref_resid(n, A->p, A->i, A->x, xr, b);
    CHECK(res <= 10 * rres + 1e-15, "%s: residual %g vs CHOLMOD %g", name, res, rres);
    CHECK(t_reldiff(n, x, xr) <= 1e-6, "%s: solution differs from CHOLMOD by %g", name, t_reldiff(n, x, xr));
    memcpy(y, b, sizeof(double) * n);
    CHECK(amps_solve(&ctx, F, y, y, w) == AMPS_OK && memcmp(y, x, sizeof(double) * n) == 0, "%s: in-place solve", name);
    /* kernels: P^T L^-T D^-1 L^-1 P b = x */
    for (k = 0; k < n; k++) y[k] = b[F->perm[k]];
    amps_lsolve(F, y);
    amps_dsolve(F, y);
    amps_ltsolve(F, y);
    for (k = 0, ok = 1; k < n; k++) ok &= y[k] == x[F->perm[k]];
    CHECK(ok, "%s: lsolve/dsolve/ltsolve differ from amps_solve", name);
    { /* the tree-parallel backward solve gives the same bits on 2 and 3 threads */
        int nt;
        for (nt = 2; nt <= 3; nt++) {
            for (k = 0; k < n; k++) z[k] = b[F->perm[k]] + 0.25;
            memcpy(y, z, sizeof(double) * n);
            amps_ltsolve(F, y);
            {
                amps_ctx co = ctx; /* OpenMP regions (a pool-less AUTO runs serially) */
                amps__par tp;
                co.backend = AMPS_BACKEND_OPENMP;
                tp = amps__par_of(&co, NULL, NULL);
                amps__ltsolve_par(F, z, &tp, nt);
            }
            CHECK(memcmp(y, z, sizeof(double) * n) == 0, "%s: parallel backward solve on %d threads differs", name, nt);
        }
    }
    /* sparse forward and partial backward solves on closures */
    CHECK(amps_marker_init(&ctx, &m, n) == AMPS_OK, "%s: marker", name);
    for (t = 0; t < 12; t++) {
        int nb = 1 + t % 5, cnt, cnt2, inside;
        double bound = 0, scale, err = 0;
        for (k = 0; k < nb; k++) idx[k] = t_int(n);
        if (t == 11) {
            idx[0] = n - 1;
            nb = 1;
        }
        /* forward: full on a dense copy */
        memset(y, 0, sizeof(double) * n);
        memset(z, 0, sizeof(double) * n);
        for (k = 0; k < nb; k++) {
            y[idx[k]] = t_unif() + 0.5;
            z[idx[k]] = y[idx[k]];
        }
        amps_touch_reset(F);
        cnt = amps_lsolve_sparse(F, nb, idx, y, cl, &m);
        amps_lsolve(F, z);
        cnt2 = brute_closure(F, nb, idx, cl2);
        CHECK(cnt == cnt2 && memcmp(cl, cl2, sizeof(int) * cnt) == 0, "%s: sparse solve closure differs", name);
        for (k = 0; k < cnt; k++) bound += (double)(F->Lp[cl[k] + 1] - F->Lp[cl[k]]);
        CHECK(amps_touch_count(F) <= bound, "%s: forward touched %g > closure bound %g", name, amps_touch_count(F),
              bound);
        scale = maxabs(n, z);
        for (k = 0, j = 0, inside = 1; k < n; k++) {
            int inc = j < cnt && cl[j] == k;
            if (inc) {
                j++;
                err = fmax(err, fabs(y[k] - z[k]));
            } else inside &= y[k] == 0.0 && z[k] == 0.0;
        }
        CHECK(err <= 1e-13 * scale, "%s: sparse forward differs by %g (scale %g)", name, err, scale);
        CHECK(inside, "%s: sparse forward nonzero outside the closure", name);
        /* partial backward on requested entries of the full D^-1 L^-1 b */
        for (k = 0; k < n; k++) y[k] = sin(1.0 + k);
        amps_lsolve(F, y);
        amps_dsolve(F, y);
        memcpy(z, y, sizeof(double) * n);
        memcpy(w, y, sizeof(double) * n);
        amps_ltsolve(F, z);
        amps_touch_reset(F);
        cnt = amps_ltsolve_partial(F, nb, idx, y, cl, &m);
        cnt2 = brute_closure(F, nb, idx, cl2);
        CHECK(cnt == cnt2 && memcmp(cl, cl2, sizeof(int) * cnt) == 0, "%s: partial solve closure differs", name);
        for (k = 0, bound = 0; k < cnt; k++) bound += (double)(F->Lp[cl[k] + 1] - F->Lp[cl[k]]);
        CHECK(amps_touch_count(F) <= bound, "%s: backward touched %g > closure bound %g", name, amps_touch_count(F),
              bound);
        scale = maxabs(n, z);
        for (k = 0, err = 0; k < nb; k++) err = fmax(err, fabs(y[idx[k]] - z[idx[k]]));
        CHECK(err <= 1e-13 * scale, "%s: partial backward differs by %g (scale %g)", name, err, scale);
        for (k = 0, j = 0, inside = 1; k < n; k++) {
            if (j < cnt && cl[j] == k) j++;
            else inside &= y[k] == w[k];
        }
        CHECK(inside, "%s: partial backward changed entries outside the closure", name);
        { /* the tree-parallel closure solve: same bits, same touch count */
            double tc = amps_touch_count(F);
            memcpy(z, w, sizeof(double) * n);
            amps_touch_reset(F);
            {
                amps_ctx co = ctx; /* OpenMP regions (a pool-less AUTO runs serially) */
                amps__par tp;
                co.backend = AMPS_BACKEND_OPENMP;
                tp = amps__par_of(&co, NULL, NULL);
                amps__ltsolve_closure_par(F, cnt, cl, z, &tp, 2 + t % 2, cl2);
            }
            CHECK(memcmp(y, z, sizeof(double) * n) == 0, "%s: parallel closure solve differs", name);
            CHECK(amps_touch_count(F) == tc, "%s: parallel closure solve touched %g, sequential %g", name,
                  amps_touch_count(F), tc);
        }
    }
    /* multiple right-hand sides, 1 and 2 threads, in place */
    {
        int nr, ld = n + 3, th;
        double *B = (double *)malloc(sizeof(double) * ld * 9), *X = (double *)malloc(sizeof(double) * ld * 9), *X1;
        X1 = (double *)malloc(sizeof(double) * ld * 9);
        for (k = 0; k < ld * 9; k++) B[k] = cos(0.1 * k);
        for (nr = 1; nr <= 9; nr += 2) {
            for (th = 1; th <= 2; th++) {
                size_t ws;
                double *W, err = 0;
                ctx.nthreads = th;
                ws = amps_solve_multi_work(&ctx, F, nr);
                W = (double *)malloc(sizeof(double) * (ws ? ws : 1));
                CHECK(amps_solve_multi(&ctx, F, nr, B, ld, X, ld, W) == AMPS_OK, "%s: solve_multi: %s", name, ctx.msg);
                for (k = 0; k < nr; k++) {
                    amps_solve(&ctx, F, B + k * ld, x, w);
                    err = fmax(err, t_reldiff(n, X + k * ld, x));
                }
                CHECK(err <= 1e-12, "%s: solve_multi nrhs %d threads %d differs by %g", name, nr, th, err);
                if (th == 1) memcpy(X1, X, sizeof(double) * ld * nr);
                for (k = 0, ok = 1; k < nr; k++) ok &= memcmp(X1 + k * ld, X + k * ld, sizeof(double) * n) == 0;
                CHECK(ok, "%s: solve_multi 1 vs 2 threads", name);
                memcpy(X, B, sizeof(double) * ld * nr);
                CHECK(amps_solve_multi(&ctx, F, nr, X, ld, X, ld, W) == AMPS_OK, "%s: in-place solve_multi", name);
                for (k = 0, ok = 1; k < nr; k++) ok &= memcmp(X1 + k * ld, X + k * ld, sizeof(double) * n) == 0;
                CHECK(ok, "%s: in-place solve_multi differs", name);
                free(W);
            }
        }
        ctx.nthreads = 0;
        CHECK(amps_solve_multi(&ctx, F, 2, B, n - 1, X, ld, w) == AMPS_ERR_ARG, "%s: small ldb accepted", name);
        CHECK(amps_solve_multi(&ctx, F, 0, NULL, n, NULL, n, NULL) == AMPS_OK, "%s: nrhs 0", name);
        free(B);
        free(X);
        free(X1);
    }
    amps_marker_free(&ctx, &m);
    amps_factor_free(&ctx, F);
    free(b);
    free(x);
    free(xr);
    free(w);
    free(y);
    free(z);
    free(cl);
    free(cl2);
}

/* amps_condest against the exact ||K||_1 ||K^{-1}||_1 (n solves): a lower bound within a factor 3,
   the same with and without caller workspace, lower-stored K, errors. */
static void check_condest(const char *name, const amps_csc *A) {
    amps_ctx ctx;
    int n = A->ncol, j, i;
    amps_factor *F;
    double *e = (double *)malloc(sizeof(double) * n), *w = (double *)malloc(sizeof(double) * 3 * n), *cs;
    double exact_inv = 0, knorm = 0, c1 = -1, c2 = -1, c3 = -1;
    amps_csc *L;
    amps_ctx_init(&ctx);
    L = m_convert(&ctx, A, AMPS_LOWER);
    F = m_analyze(&ctx, A, NULL);
    CHECK(F && amps_factorize(&ctx, F, A) == AMPS_OK, "%s: factor", name);
    cs = (double *)calloc((size_t)n, sizeof(double));
    for (j = 0; j < n; j++) {
        double s = 0;
        int p;
        for (p = A->p[j]; p < A->p[j + 1]; p++) {
            cs[j] += fabs(A->x[p]);
            if (A->i[p] != j) cs[A->i[p]] += fabs(A->x[p]);
        }
        for (i = 0; i < n; i++) e[i] = i == j;
        amps_solve(&ctx, F, e, e, w);
        for (i = 0; i < n; i++) s += fabs(e[i]);
        if (s > exact_inv) exact_inv = s;
    }
    for (j = 0; j < n; j++)
        if (cs[j] > knorm) knorm = cs[j];
    CHECK(amps_condest(&ctx, A, AMPS_UPPER, F, w, &c1) == AMPS_OK, "%s: condest: %s", name, ctx.msg);
    CHECK(amps_condest(&ctx, A, AMPS_UPPER, F, NULL, &c2) == AMPS_OK && c2 == c1, "%s: condest without work", name);
    CHECK(amps_condest(&ctx, L, AMPS_LOWER, F, w, &c3) == AMPS_OK && fabs(c3 - c1) <= 1e-12 * c1,
          "%s: condest of the lower copy", name);
    CHECK(c1 <= knorm * exact_inv * (1 + 1e-10) && c1 >= knorm * exact_inv / 3, "%s: condest %.4e vs exact %.4e", name,
          c1, knorm * exact_inv);
    printf("  condest %-14s %.4e (exact %.4e)\n", name, c1, knorm * exact_inv);
    { /* the warm start of a re-factorization's engine: from the column a run ended at, from 0 and n-1 */
        amps_int js[3], r;
        js[0] = -1;
        CHECK(amps__condest(&ctx, A, AMPS_UPPER, F, w, &c2, &js[0]) == AMPS_OK && c2 == c1 && js[0] >= 0 && js[0] < n,
              "%s: condest reporting its column (%.4e, column %d)", name, c2, (int)js[0]);
        js[1] = 0;
        js[2] = n - 1;
        for (r = 0; r < 3; r++) {
            amps_int j0 = js[r];
            c2 = -1;
            CHECK(amps__condest(&ctx, A, AMPS_UPPER, F, w, &c2, &j0) == AMPS_OK && j0 >= 0 && j0 < n &&
                      c2 <= knorm * exact_inv * (1 + 1e-10) && c2 >= knorm * exact_inv / 3,
                  "%s: condest started at column %d: %.4e vs exact %.4e", name, (int)js[r], c2, knorm * exact_inv);
        }
    }
    CHECK(amps_condest(&ctx, A, AMPS_UPPER, NULL, w, &c1) == AMPS_ERR_ARG, "%s: NULL factor accepted", name);
    F->is_numeric = 0;
    CHECK(amps_condest(&ctx, A, AMPS_UPPER, F, w, &c1) == AMPS_ERR_STATE, "%s: symbolic factor accepted", name);
    amps_factor_free(&ctx, F);
    amps_csc_free(&ctx, L);
    free(e);
    free(w);
    free(cs);
}

int main(void) {
    amps_ctx ctx;
    amps_csc *A;
    int *perm;
    amps_ctx_init(&ctx);
    A = m_rand(&ctx, 1, 1, 1.1, 0, 1);
    check_solves("rand n=1", A, NULL);
    amps_csc_free(&ctx, A);
    { /* the same matrix stored as its lower triangle */
        amps_csc *U = m_rand(&ctx, 30, 4, 1.1, 0, 9);
        A = m_convert(&ctx, U, AMPS_LOWER);
        CHECK(A && amps_csc_check(&ctx, A, AMPS_LOWER) == AMPS_OK && t_norm(A->p[30], A->x) > 0, "lower copy");
        amps_csc_free(&ctx, A);
        amps_csc_free(&ctx, U);
    }
    A = m_rand(&ctx, 200, 5, 1.1, 0, 2);
    perm = m_cholmod_perm(A, CHOLMOD_AMD);
    check_solves("rand n=200", A, perm);
    free(perm);
    amps_csc_free(&ctx, A);
    A = m_btb(&ctx, 1500, 3000, 4, 1e-2, 3);
    perm = m_cholmod_perm(A, CHOLMOD_AMD);
    check_solves("btb n=1500", A, perm);
    free(perm);
    amps_csc_free(&ctx, A);
    A = m_fe(&ctx, fe_beam(16), 1);
    perm = m_cholmod_perm(A, CHOLMOD_AMD);
    check_solves("beam h=16", A, perm);
    free(perm);
    amps_csc_free(&ctx, A);
    A = m_fe(&ctx, fe_beam(64), 1);
    perm = m_cholmod_perm(A, CHOLMOD_METIS);
    check_solves("beam h=64", A, perm);
    { /* ... where the parallel path runs: subtrees and a factor above its size threshold */
        amps_order_opts o;
        amps_factor *F;
        memset(&o, 0, sizeof(o));
        o.method = AMPS_ORDER_GIVEN;
        o.perm = perm;
        F = amps_analyze(&ctx, A, AMPS_UPPER, &o);
        CHECK(F && ((amps__fpriv *)F->priv)->nsub >= 2 && (double)F->Lp[F->n] >= 2e5,
              "beam h=64: the parallel backward solve is not exercised");
        amps_factor_free(&ctx, F);
    }
    free(perm);
    amps_csc_free(&ctx, A);
    A = m_fe(&ctx, fe_brick(6), 1);
    check_solves("brick R=6 default", A, NULL);
    amps_csc_free(&ctx, A);
    A = m_fe(&ctx, fe_brick(10), 1);
    perm = m_cholmod_perm(A, CHOLMOD_METIS);
    check_solves("brick R=10", A, perm);
    free(perm);
    amps_csc_free(&ctx, A);

    A = m_fe(&ctx, fe_beam(12), 1);
    check_condest("beam h=12", A);
    amps_csc_free(&ctx, A);
    A = m_btb(&ctx, 300, 600, 4, 1e-3, 5);
    check_condest("btb n=300", A);
    amps_csc_free(&ctx, A);

    /* closures: sort paths (small: heapsort, large: scan) and stamp wrap-around */
    {
        amps_factor *F;
        amps_marker m;
        int n, k, j, t, cnt, cnt2, *cl, *cl2, idx[40];
        A = m_fe(&ctx, fe_beam(16), 1);
        perm = m_cholmod_perm(A, CHOLMOD_AMD);
        {
            amps_order_opts o;
            memset(&o, 0, sizeof(o));
            o.method = AMPS_ORDER_GIVEN;
            o.perm = perm;
            F = amps_analyze(&ctx, A, AMPS_UPPER, &o);
        }
        n = A->ncol;
        cl = (int *)malloc(sizeof(int) * n);
        cl2 = (int *)malloc(sizeof(int) * n);
        CHECK(F && amps_marker_init(&ctx, &m, n) == AMPS_OK, "closure setup");
        for (t = 0; t < 40; t++) {
            int ni = 1 + t;
            if (t == 20) m.stamp = INT_MAX - 3; /* wrap-around of the stamp */
            for (k = 0; k < ni; k++) idx[k] = t_int(n);
            cnt = amps_closure(F, ni, idx, cl, &m);
            cnt2 = brute_closure(F, ni, idx, cl2);
            CHECK(cnt == cnt2 && memcmp(cl, cl2, sizeof(int) * cnt) == 0, "closure %d (stamp %d) differs", t,
                  (int)m.stamp);
            for (k = 0, j = 1; k < cnt; k++) j &= m.mark[cl[k]] == m.stamp;
            CHECK(j, "closure %d: members not marked", t);
        }
        CHECK(amps_closure(F, 0, idx, cl, &m) == 0, "empty closure");
        CHECK(amps_marker_init(&ctx, &m, -1) == AMPS_ERR_ARG, "negative marker size");
        amps_marker_free(&ctx, &m);
        amps_factor_free(&ctx, F);
        free(cl);
        free(cl2);
        free(perm);
        amps_csc_free(&ctx, A);
    }
    return amps_t_end("test_solve");
}
