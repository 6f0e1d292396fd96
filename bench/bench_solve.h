/* bench/bench_solve.h: the reference and iterative solvers on an explicit system (bench_sys of
   bench.h), shared by bench/harness and bench/dynamics: CHOLMOD on the reduced system with
   refinement in quad precision, and our (Jacobi-)CG with snapshots at the tolerances bench_tols.
   Include after bench.h; link -lcholmod. */
#ifndef BENCH_SOLVE_H
#define BENCH_SOLVE_H
#include <cholmod.h>

#define BENCH_NTOL 4
static const double bench_tols[BENCH_NTOL] = {1e-4, 1e-6, 1e-8, 1e-10};

/* The reduced upper matrix K_FF (CHOLMOD, stype 1) and b_F of S; fmap[i] = position of equation i in F or -1 */
static inline cholmod_sparse *bench_reduced(const bench_sys *S, int *fmap, cholmod_dense **B, cholmod_common *c) {
    int i, j, p, nf = 0, nz = 0;
    cholmod_sparse *A;
    for (i = 0; i < S->n; i++) fmap[i] = S->con[i] ? -1 : nf++;
    for (j = 0; j < S->n; j++)
        if (fmap[j] >= 0)
            for (p = S->K->p[j]; p < S->K->p[j + 1]; p++) nz += fmap[S->K->i[p]] >= 0;
    A = cholmod_allocate_sparse((size_t)nf, (size_t)nf, (size_t)nz, 1, 1, 1, CHOLMOD_REAL, c);
    *B = cholmod_zeros((size_t)nf, 1, CHOLMOD_REAL, c);
    nz = 0;
    for (j = 0; j < S->n; j++) {
        if (fmap[j] < 0) continue;
        ((int *)A->p)[fmap[j]] = nz;
        for (p = S->K->p[j]; p < S->K->p[j + 1]; p++)
            if (fmap[S->K->i[p]] >= 0) {
                ((int *)A->i)[nz] = fmap[S->K->i[p]];
                ((double *)A->x)[nz++] = S->K->x[p];
            }
        ((double *)(*B)->x)[fmap[j]] = S->b[j];
    }
    ((int *)A->p)[nf] = nz;
    return A;
}

/* x (n) from the reduced solution xf: x_F = xf, x_C = g. */
static inline void bench_expand(const bench_sys *S, const int *fmap, const double *xf, double *x) {
    int i;
    for (i = 0; i < S->n; i++) x[i] = fmap[i] >= 0 ? xf[fmap[i]] : S->g[i];
}

#ifdef __SIZEOF_FLOAT128__
__extension__ typedef __float128 bench_quad;
#else
typedef long double bench_quad;
#endif

/* r = b - A x summed in quad precision (A: the upper triangle, stype 1), rounded to double. */
static inline void bench_quad_residual(const cholmod_sparse *A, const double *b, const bench_quad *x, bench_quad *acc,
                                       double *r) {
    const int *Ap = (const int *)A->p, *Ai = (const int *)A->i;
    const double *Ax = (const double *)A->x;
    int n = (int)A->ncol, j, p;
    for (j = 0; j < n; j++) acc[j] = b[j];
    for (j = 0; j < n; j++)
        for (p = Ap[j]; p < Ap[j + 1]; p++) {
            int i = Ai[p];
            acc[i] -= (bench_quad)Ax[p] * x[j];
            if (i != j) acc[j] -= (bench_quad)Ax[p] * x[i];
        }
    for (j = 0; j < n; j++) r[j] = (double)acc[j];
}

/* Iterative refinement of the solution X of A X = B (L the factor of A): X += A^{-1} (B - A X) with
   the residual summed and X kept in quad precision, at most maxit steps, until a correction is
   below 1e-3 eps ||X||. */
static inline void bench_refine(cholmod_sparse *A, cholmod_factor *L, cholmod_dense *B, cholmod_dense *X, int maxit,
                                cholmod_common *c) {
    size_t k, nr = X->nrow;
    int it;
    bench_quad *xq = (bench_quad *)bench_alloc(sizeof(bench_quad) * (nr + 1));
    bench_quad *acc = (bench_quad *)bench_alloc(sizeof(bench_quad) * (nr + 1));
    cholmod_dense *R = cholmod_copy_dense(B, c);
    for (k = 0; k < nr; k++) xq[k] = ((double *)X->x)[k];
    for (it = 0; it < maxit; it++) {
        cholmod_dense *D;
        double dn = 0, xn = 0;
        bench_quad_residual(A, (const double *)B->x, xq, acc, (double *)R->x);
        D = cholmod_solve(CHOLMOD_A, L, R, c);
        for (k = 0; k < nr; k++) {
            xq[k] += ((double *)D->x)[k];
            dn += ((double *)D->x)[k] * ((double *)D->x)[k];
            xn += (double)xq[k] * (double)xq[k];
        }
        cholmod_free_dense(&D, c);
        if (dn <= 1e-6 * 4.93e-32 * xn) break;
    }
    for (k = 0; k < nr; k++) ((double *)X->x)[k] = (double)xq[k];
    cholmod_free_dense(&R, c);
    free(xq);
    free(acc);
}

/* ---- CG (ours) ----
   K_FF x_F = b_F on the full numbering with x_C = g held: r = (f - K x)_F, products with p
   zero on C and the result zeroed on C. Jacobi: z = r ./ diag(K). Stops at ||r|| <= tol ||b_F||
   (recursive residual) or maxit. Records for each tolerance the time, iterations and iterate. */
typedef struct bench_snaps {
    double t[BENCH_NTOL], *x[BENCH_NTOL];
    int it[BENCH_NTOL], conv[BENCH_NTOL];
} bench_snaps;

static inline void bench_cg_run(const bench_sys *S, const double *x0, int jacobi, int maxit, bench_snaps *sn) {
    int n = S->n, i, it = 0, ti = 0;
    double *x = (double *)bench_alloc(sizeof(double) * (size_t)n),
           *r = (double *)bench_alloc(sizeof(double) * (size_t)n);
    double *z = (double *)bench_alloc(sizeof(double) * (size_t)n),
           *p = (double *)bench_alloc(sizeof(double) * (size_t)n);
    double *q = (double *)bench_alloc(sizeof(double) * (size_t)n),
           *dinv = (double *)bench_alloc(sizeof(double) * (size_t)n);
    double rz, rr, t0 = amps_now(), tpause = 0;
    for (i = 0; i < n; i++) {
        amps_int k;
        dinv[i] = 1;
        if (jacobi)
            for (k = S->Kf->p[i]; k < S->Kf->p[i + 1]; k++)
                if (S->Kf->i[k] == i) dinv[i] = 1 / S->Kf->x[k];
        x[i] = S->con[i] ? S->g[i] : x0[i];
    }
    bench_spmv(S->Kf, x, q);
    rz = rr = 0;
    for (i = 0; i < n; i++) {
        r[i] = S->con[i] ? 0 : S->f[i] - q[i];
        z[i] = p[i] = dinv[i] * r[i];
        rz += r[i] * z[i];
        rr += r[i] * r[i];
    }
    for (;;) {
        double pq = 0, alpha, rz1 = 0, beta;
        while (ti < BENCH_NTOL && sqrt(rr) <= bench_tols[ti] * S->nb) { /* snapshot, not timed */
            double t1 = amps_now();
            sn->t[ti] = t1 - t0 - tpause;
            sn->it[ti] = it;
            sn->conv[ti] = 1;
            memcpy(sn->x[ti], x, sizeof(double) * (size_t)n);
            ti++;
            tpause += amps_now() - t1;
        }
        if (ti == BENCH_NTOL || it >= maxit) break;
        bench_spmv(S->Kf, p, q);
        for (i = 0; i < n; i++) {
            if (S->con[i]) q[i] = 0;
            pq += p[i] * q[i];
        }
        alpha = rz / pq;
        rr = 0;
        for (i = 0; i < n; i++) {
            x[i] += alpha * p[i];
            r[i] -= alpha * q[i];
            z[i] = dinv[i] * r[i];
            rz1 += r[i] * z[i];
            rr += r[i] * r[i];
        }
        beta = rz1 / rz;
        rz = rz1;
        for (i = 0; i < n; i++) p[i] = z[i] + beta * p[i];
        it++;
    }
    for (; ti < BENCH_NTOL; ti++) {
        sn->t[ti] = amps_now() - t0 - tpause;
        sn->it[ti] = it;
        sn->conv[ti] = 0;
        memcpy(sn->x[ti], x, sizeof(double) * (size_t)n);
    }
    free(x);
    free(r);
    free(z);
    free(p);
    free(q);
    free(dinv);
}

#endif
