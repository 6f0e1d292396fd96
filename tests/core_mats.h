/* Test matrices for the core tests (include after amps.h, amps_test.h and fe_util.h): finite element
   stiffness matrices, random sparse SPD matrices, conversions between stored triangles. */
#ifndef CORE_MATS_H
#define CORE_MATS_H

/* P1 elasticity stiffness of mesh m (upper triangle). fix: 0 = no node fixed, 1 = nodes at z = 0 fixed. */
REF_UNUSED static amps_csc *m_fe(amps_ctx *ctx, fe_mesh m, int fix) {
    int *fixed = (int *)calloc((size_t)m.nn, sizeof(int)), *dof = (int *)malloc(sizeof(int) * 3 * (size_t)m.nn);
    int *ti, *tj, v, n, nz;
    double *tx;
    amps_csc *A;
    for (v = 0; v < m.nn; v++) fixed[v] = fix && m.xyz[3 * v + 2] == 0.0;
    n = fe_number(&m, fixed, dof);
    nz = fe_assemble(&m, dof, 1000.0, 0.3, &ti, &tj, &tx);
    A = amps_csc_from_triplets(ctx, n, nz, ti, tj, tx, AMPS_UPPER);
    free(ti);
    free(tj);
    free(tx);
    free(fixed);
    free(dof);
    fe_free(&m);
    return A;
}

/* Random symmetric n x n, about deg off-diagonal entries per column in [-1,1]; diagonal = dd * (row sum of
   |offdiag|) + 1 when dd > 0 (diagonally dominant), else the diagonal given by diag. Upper triangle. */
REF_UNUSED static amps_csc *m_rand(amps_ctx *ctx, int n, int deg, double dd, double diag, unsigned long long seed) {
    int nz = 0, k, cap = n * (deg + 1) + 1;
    int *ti = (int *)malloc(sizeof(int) * (size_t)cap), *tj = (int *)malloc(sizeof(int) * (size_t)cap);
    double *tx = (double *)malloc(sizeof(double) * (size_t)cap), *rs = (double *)calloc((size_t)n + 1, sizeof(double));
    amps_csc *A;
    t_seed(seed);
    for (k = 0; k < n * deg / 2; k++) {
        int i = t_int(n), j = t_int(n);
        double v = 2 * t_unif() - 1;
        if (i == j) continue;
        ti[nz] = i;
        tj[nz] = j;
        tx[nz] = v;
        nz++;
        rs[i] += fabs(v);
        rs[j] += fabs(v);
    }
    for (k = 0; k < n; k++) {
        ti[nz] = k;
        tj[nz] = k;
        tx[nz] = dd > 0 ? dd * rs[k] + 1 : diag;
        nz++;
    }
    A = amps_csc_from_triplets(ctx, n, nz, ti, tj, tx, AMPS_UPPER);
    free(ti);
    free(tj);
    free(tx);
    free(rs);
    return A;
}

/* B^T B + shift I for a random m x n B with k entries per row (SPD, not diagonally dominant). Upper. */
REF_UNUSED static amps_csc *m_btb(amps_ctx *ctx, int n, int m, int k, double shift, unsigned long long seed) {
    int cap = m * k * k + n, nz = 0, r, a, b;
    int *ti = (int *)malloc(sizeof(int) * (size_t)cap), *tj = (int *)malloc(sizeof(int) * (size_t)cap);
    double *tx = (double *)malloc(sizeof(double) * (size_t)cap);
    int cols[16];
    double vals[16];
    amps_csc *A;
    t_seed(seed);
    for (r = 0; r < m; r++) {
        int base = t_int(n);
        for (a = 0; a < k; a++) {
            cols[a] = (base + t_int(n / 8 + 2)) % n;
            vals[a] = 2 * t_unif() - 1;
        }
        for (a = 0; a < k; a++)
            for (b = 0; b < k; b++)
                if (cols[a] <= cols[b]) {
                    ti[nz] = cols[a];
                    tj[nz] = cols[b];
                    tx[nz] = vals[a] * vals[b];
                    nz++;
                }
    }
    for (a = 0; a < n; a++) {
        ti[nz] = a;
        tj[nz] = a;
        tx[nz] = shift;
        nz++;
    }
    A = amps_csc_from_triplets(ctx, n, nz, ti, tj, tx, AMPS_UPPER);
    free(ti);
    free(tj);
    free(tx);
    return A;
}

/* The same symmetric matrix as upper U, stored as stype (LOWER or FULL). */
REF_UNUSED static amps_csc *m_convert(amps_ctx *ctx, const amps_csc *U, amps_stype stype) {
    int n = U->ncol, nz = U->p[n], j, p, k = 0;
    int *ti = (int *)malloc(sizeof(int) * (size_t)(nz + 1)), *tj = (int *)malloc(sizeof(int) * (size_t)(nz + 1));
    double *tx = (double *)malloc(sizeof(double) * (size_t)(nz + 1));
    amps_csc *A;
    for (j = 0; j < n; j++)
        for (p = U->p[j]; p < U->p[j + 1]; p++) {
            ti[k] = U->i[p];
            tj[k] = j;
            tx[k] = U->x[p];
            k++;
        }
    A = amps_csc_from_triplets(ctx, n, nz, ti, tj, tx, stype);
    free(ti);
    free(tj);
    free(tx);
    return A;
}

/* CHOLMOD's own AMD ordering of upper A (malloc'ed). */
REF_UNUSED static int *m_cholmod_perm(const amps_csc *A, int method) {
    int *perm = (int *)malloc(sizeof(int) * (size_t)(A->ncol + 1));
    ref_nnzL(A->ncol, A->p, A->i, A->x, NULL, method, perm);
    return perm;
}
/* Symbolic analysis of A with the given ordering (perm[k] = original index k-th), or the
   default ordering when perm is NULL. */
static amps_factor *m_analyze(amps_ctx *ctx, const amps_csc *A, const int *perm) {
    amps_order_opts o;
    memset(&o, 0, sizeof(o));
    o.method = AMPS_ORDER_GIVEN;
    o.perm = perm;
    return amps_analyze(ctx, A, AMPS_UPPER, perm ? &o : NULL);
}
#endif
