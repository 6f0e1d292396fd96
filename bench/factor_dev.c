/* Development benchmark of the core LDL^T against CHOLMOD on the same ordering (not a test).
   Build: gcc -std=c99 -O2 -g -fopenmp -I. -Itests -I/usr/include/suitesparse bench/factor_dev.c -o build/factor_dev -lcholmod -lm
   Run:   OMP_NUM_THREADS=1 build/factor_dev [reps]   (and OMP_NUM_THREADS=2)
   Prints, per matrix and ordering (CHOLMOD's AMD and METIS): symbolic analysis, numeric factorization
   and solve times of amps and CHOLMOD (simplicial LDL^T; supernodal LL^T), with ratios amps/CHOLMOD. */
#define _POSIX_C_SOURCE 199309L
#define AMPS_IMPLEMENTATION
#include "amps.h"
#include "amps_test.h"
#include "fe_util.h"
#include "cholmod_ref.h"
#include "core_mats.h"
#include <string.h>
#include <time.h>

static double now(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

static void run(const char *name, const amps_csc *A, int method, int reps, int chol) {
    amps_ctx ctx; amps_factor *F = NULL; amps_order_opts o; cholmod_common c; cholmod_sparse *S; cholmod_factor *L;
    cholmod_dense *B, *X;
    int n = A->ncol, r, i, *perm = m_cholmod_perm(A, method);
    double t, ta = 1e30, tf = 1e30, ts = 1e30, ca = 1e30, cf = 1e30, cs = 1e30, sf = 1e30, ss = 1e30, res, cres = 0;
    double *b = (double *)malloc(sizeof(double) * n), *x = (double *)calloc((size_t)n, sizeof(double));
    double *w = (double *)malloc(sizeof(double) * n);
    amps_ctx_init(&ctx);
    memset(&o, 0, sizeof(o));
    o.method = AMPS_ORDER_GIVEN; o.perm = perm;
    for (r = 0; r < n; r++) b[r] = sin(0.37 * r) + 0.5;
    for (r = 0; r < reps; r++) {
        amps_factor_free(&ctx, F);
        t = now(); F = amps_analyze(&ctx, A, AMPS_UPPER, &o); ta = fmin(ta, now() - t);
        t = now();
        if (amps_factorize(&ctx, F, A, AMPS_UPPER) != AMPS_OK) { printf("factorize failed: %s\n", ctx.msg); exit(1); }
        tf = fmin(tf, now() - t);
        for (i = 0; i < 5; i++) { t = now(); amps_solve(&ctx, F, b, x, w); ts = fmin(ts, now() - t); }
    }
    res = ref_resid(n, A->p, A->i, A->x, x, b);
    if (!chol) {
        printf("%-22s n=%6d nnzL=%9.0f | analyze %7.4f | factor %7.4f | solve %7.5f | resid %.1e\n", name, n,
               amps_factor_nnz(F), ta, tf, ts, res);
        amps_factor_free(&ctx, F);
        free(perm); free(b); free(x); free(w);
        return;
    }
    cholmod_start(&c);
    c.nmethods = 1; c.method[0].ordering = CHOLMOD_GIVEN; c.postorder = 0;
    S = ref_sparse(n, A->p, A->i, A->x, &c);
    B = cholmod_allocate_dense(n, 1, n, CHOLMOD_REAL, &c);
    memcpy(B->x, b, sizeof(double) * n);
    for (r = 0; r < reps; r++) {
        c.supernodal = CHOLMOD_SIMPLICIAL; c.final_ll = 0;
        t = now(); L = cholmod_analyze_p(S, perm, NULL, 0, &c); ca = fmin(ca, now() - t);
        t = now(); cholmod_factorize(S, L, &c); cf = fmin(cf, now() - t);
        for (i = 0; i < 5; i++) {
            t = now(); X = cholmod_solve(CHOLMOD_A, L, B, &c); cs = fmin(cs, now() - t);
            if (r == reps - 1) cres = ref_resid(n, A->p, A->i, A->x, (double *)X->x, b);
            cholmod_free_dense(&X, &c);
        }
        cholmod_free_factor(&L, &c);
        c.supernodal = CHOLMOD_SUPERNODAL; c.final_ll = 1;
        L = cholmod_analyze_p(S, perm, NULL, 0, &c);
        t = now(); cholmod_factorize(S, L, &c); sf = fmin(sf, now() - t);
        for (i = 0; i < 5; i++) {
            t = now(); X = cholmod_solve(CHOLMOD_A, L, B, &c); ss = fmin(ss, now() - t);
            cholmod_free_dense(&X, &c);
        }
        cholmod_free_factor(&L, &c);
    }
    printf("%-22s n=%6d nnzL=%9.0f groups=%6d | analyze %7.4f (chol %7.4f) | factor %7.4f  chol-simpl %7.4f  ratio %5.2f"
           "  chol-super %7.4f | solve %7.5f  chol-simpl %7.5f ratio %5.2f  chol-super %7.5f | resid %.1e (chol %.1e)\n",
           name, n, amps_factor_nnz(F), (int)((amps__fpriv *)F->priv)->ng, ta, ca, tf, cf, tf / cf, sf, ts, cs, ts / cs, ss,
           res, cres);
    fflush(stdout);
    cholmod_free_dense(&B, &c);
    cholmod_free_sparse(&S, &c);
    cholmod_finish(&c);
    amps_factor_free(&ctx, F);
    free(perm); free(b); free(x); free(w);
}

int main(int argc, char **argv) {
    amps_ctx ctx;
    amps_csc *A;
    int reps = argc > 1 ? atoi(argv[1]) : 3, which = argc > 2 ? atoi(argv[2]) : 0;
    amps_ctx_init(&ctx);
#ifdef _OPENMP
    printf("threads: %d\n", omp_get_max_threads());
#endif
    if (which == 0 || which == 1) {
        A = m_fe(&ctx, fe_grid(5, 5, 256, 1, 1, 1), 1);
        run("beam 5x5x256 amd", A, CHOLMOD_AMD, reps, 1);
        run("beam 5x5x256 metis", A, CHOLMOD_METIS, reps, 1);
        amps_csc_free(&ctx, A);
    }
    if (which == 0 || which == 2) {
        A = m_fe(&ctx, fe_brick(16), 1);
        run("brick R=16 amd", A, CHOLMOD_AMD, reps, 1);
        run("brick R=16 metis", A, CHOLMOD_METIS, reps, 1);
        amps_csc_free(&ctx, A);
    }
    if (which == 0 || which == 3) {
        A = m_fe(&ctx, fe_brick(20), 1);
        run("brick R=20 amd", A, CHOLMOD_AMD, reps, 1);
        run("brick R=20 metis", A, CHOLMOD_METIS, reps, 1);
        amps_csc_free(&ctx, A);
    }
    if (which == 4) { /* large: symbolic analysis speed */
        A = m_fe(&ctx, fe_brick(28), 1);
        run("brick R=28 metis", A, CHOLMOD_METIS, 1, 0);
        amps_csc_free(&ctx, A);
    }
    return 0;
}
