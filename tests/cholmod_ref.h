/* Reference computations with CHOLMOD (SuiteSparse) for the tests: independent factorization
   and solve of an explicitly given symmetric matrix (upper CSC, amps_csc layout, int indices). */
#ifndef CHOLMOD_REF_H
#define CHOLMOD_REF_H
#include <cholmod.h>

#if defined(__GNUC__) || defined(__clang__)
#define REF_UNUSED __attribute__((unused))
#else
#define REF_UNUSED
#endif

/* Copy of upper-triangular A (n x n) as a CHOLMOD sparse matrix (stype = 1). */
REF_UNUSED static cholmod_sparse *ref_sparse(int n, const int *Ap, const int *Ai, const double *Ax, cholmod_common *c) {
    cholmod_sparse *S = cholmod_allocate_sparse(n, n, Ap[n], 1, 1, 1, CHOLMOD_REAL, c);
    memcpy(S->p, Ap, sizeof(int) * (n + 1));
    memcpy(S->i, Ai, sizeof(int) * Ap[n]);
    memcpy(S->x, Ax, sizeof(double) * Ap[n]);
    return S;
}

/* Solves A x = b with CHOLMOD. perm: given ordering (perm[k] = original index k-th) or NULL for
   CHOLMOD's AMD. simplicial: 1 = simplicial LDL^T, 0 = supernodal LL^T. Returns 0 on success. */
REF_UNUSED static int ref_solve(int n, const int *Ap, const int *Ai, const double *Ax, const int *perm, int simplicial,
                                const double *b, double *x) {
    cholmod_common c;
    cholmod_sparse *A;
    cholmod_factor *L;
    cholmod_dense *B, *X;
    int ok;
    cholmod_start(&c);
    c.supernodal = simplicial ? CHOLMOD_SIMPLICIAL : CHOLMOD_SUPERNODAL;
    c.final_ll = simplicial ? 0 : 1;
    if (perm) {
        c.nmethods = 1;
        c.method[0].ordering = CHOLMOD_GIVEN;
        c.postorder = 0;
    } else {
        c.nmethods = 1;
        c.method[0].ordering = CHOLMOD_AMD;
    }
    A = ref_sparse(n, Ap, Ai, Ax, &c);
    L = perm ? cholmod_analyze_p(A, (int *)perm, NULL, 0, &c) : cholmod_analyze(A, &c);
    ok = cholmod_factorize(A, L, &c) && c.status == CHOLMOD_OK;
    B = cholmod_allocate_dense(n, 1, n, CHOLMOD_REAL, &c);
    memcpy(B->x, b, sizeof(double) * n);
    X = ok ? cholmod_solve(CHOLMOD_A, L, B, &c) : NULL;
    ok = ok && X != NULL;
    if (X) memcpy(x, X->x, sizeof(double) * n);
    cholmod_free_dense(&X, &c);
    cholmod_free_dense(&B, &c);
    cholmod_free_factor(&L, &c);
    cholmod_free_sparse(&A, &c);
    cholmod_finish(&c);
    return ok ? 0 : 1;
}

/* r = b - A x for symmetric upper A (both triangles applied). */
REF_UNUSED static void ref_residual_vec(int n, const int *Ap, const int *Ai, const double *Ax, const double *x,
                                        const double *b, double *r) {
    int j, p;
    for (j = 0; j < n; j++) r[j] = b[j];
    for (j = 0; j < n; j++)
        for (p = Ap[j]; p < Ap[j + 1]; p++) {
            int i = Ai[p];
            r[i] -= Ax[p] * x[j];
            if (i != j) r[j] -= Ax[p] * x[i];
        }
}

/* Solves A x = b with CHOLMOD (supernodal, its default ordering) followed by nrefine steps of
   iterative refinement with the same factor (residual in double precision). x0 (may be NULL)
   receives the unrefined solution. Returns 0 on success. */
REF_UNUSED static int ref_solve_refined(int n, const int *Ap, const int *Ai, const double *Ax, const double *b,
                                        double *x, int nrefine, double *x0) {
    cholmod_common c;
    cholmod_sparse *A;
    cholmod_factor *L;
    cholmod_dense *B, *X = NULL;
    int ok, it, k;
    if (n == 0) return 0;
    cholmod_start(&c);
    A = ref_sparse(n, Ap, Ai, Ax, &c);
    L = cholmod_analyze(A, &c);
    ok = L && cholmod_factorize(A, L, &c) && c.status == CHOLMOD_OK;
    B = cholmod_allocate_dense(n, 1, n, CHOLMOD_REAL, &c);
    memcpy(B->x, b, sizeof(double) * n);
    if (ok) X = cholmod_solve(CHOLMOD_A, L, B, &c);
    ok = ok && X != NULL;
    if (ok) {
        memcpy(x, X->x, sizeof(double) * n);
        if (x0) memcpy(x0, x, sizeof(double) * n);
        for (it = 0; it < nrefine && ok; it++) {
            cholmod_free_dense(&X, &c);
            ref_residual_vec(n, Ap, Ai, Ax, x, b, (double *)B->x);
            X = cholmod_solve(CHOLMOD_A, L, B, &c);
            ok = X != NULL;
            if (ok)
                for (k = 0; k < n; k++) x[k] += ((double *)X->x)[k];
        }
    }
    cholmod_free_dense(&X, &c);
    cholmod_free_dense(&B, &c);
    cholmod_free_factor(&L, &c);
    cholmod_free_sparse(&A, &c);
    cholmod_finish(&c);
    return ok ? 0 : 1;
}

/* nnz(L) (with diagonal) for ordering: perm given, or NULL for CHOLMOD AMD (method=CHOLMOD_AMD)
   or METIS (method=CHOLMOD_METIS). If perm_out, receives the ordering CHOLMOD used. */
REF_UNUSED static double ref_nnzL(int n, const int *Ap, const int *Ai, const double *Ax, const int *perm, int method,
                                  int *perm_out) {
    cholmod_common c;
    cholmod_sparse *A;
    cholmod_factor *L;
    double nz = -1;
    int j;
    cholmod_start(&c);
    c.supernodal = CHOLMOD_SIMPLICIAL;
    c.nmethods = 1;
    c.method[0].ordering = perm ? CHOLMOD_GIVEN : method;
    c.postorder = perm ? 0 : 1;
    A = ref_sparse(n, Ap, Ai, Ax, &c);
    L = perm ? cholmod_analyze_p(A, (int *)perm, NULL, 0, &c) : cholmod_analyze(A, &c);
    if (L) {
        const int *cc = (const int *)L->ColCount;
        nz = 0;
        for (j = 0; j < n; j++) nz += cc[j];
        if (perm_out) memcpy(perm_out, L->Perm, sizeof(int) * n);
    }
    cholmod_free_factor(&L, &c);
    cholmod_free_sparse(&A, &c);
    cholmod_finish(&c);
    return nz;
}
/* CHOLMOD simplicial LDL^T of upper A (n x n) with the given ordering (postorder off). Returns the
   strictly lower part of L packed in CSC (*Lp n+1, *Li, *Lx; rows ascending as CHOLMOD stores them)
   and D (n), all malloc'ed, or 1 when CHOLMOD fails (nothing allocated). */
REF_UNUSED static int ref_ldl(int n, const int *Ap, const int *Ai, const double *Ax, const int *perm, int **Lp,
                              int **Li, double **Lx, double **D) {
    cholmod_common c;
    cholmod_sparse *A;
    cholmod_factor *L;
    int ok, j, p, nz = 0;
    cholmod_start(&c);
    c.supernodal = CHOLMOD_SIMPLICIAL;
    c.final_ll = 0;
    c.nmethods = 1;
    c.method[0].ordering = CHOLMOD_GIVEN;
    c.postorder = 0;
    A = ref_sparse(n, Ap, Ai, Ax, &c);
    L = cholmod_analyze_p(A, (int *)perm, NULL, 0, &c);
    ok = L && cholmod_factorize(A, L, &c) && c.status == CHOLMOD_OK && !L->is_ll && !L->is_super;
    if (ok) {
        const int *cp = (const int *)L->p, *ci = (const int *)L->i, *cn = (const int *)L->nz;
        const double *cx = (const double *)L->x;
        for (j = 0; j < n; j++) nz += cn[j] - 1;
        size_t sn = (size_t)(n > 0 ? n : 1), sz = (size_t)(nz > 0 ? nz : 1);
        *Lp = (int *)malloc(sizeof(int) * (sn + 1));
        *Li = (int *)malloc(sizeof(int) * sz);
        *Lx = (double *)malloc(sizeof(double) * sz);
        *D = (double *)malloc(sizeof(double) * sn);
        (*Lp)[0] = 0;
        for (j = 0; j < n; j++) {
            (*D)[j] = cx[cp[j]];
            for (p = 1; p < cn[j]; p++) {
                (*Li)[(*Lp)[j] + p - 1] = ci[cp[j] + p];
                (*Lx)[(*Lp)[j] + p - 1] = cx[cp[j] + p];
            }
            (*Lp)[j + 1] = (*Lp)[j] + cn[j] - 1;
        }
    }
    cholmod_free_factor(&L, &c);
    cholmod_free_sparse(&A, &c);
    cholmod_finish(&c);
    return ok ? 0 : 1;
}

/* Relative residual ||A x - b|| / ||b|| of symmetric upper A (both triangles applied). */
REF_UNUSED static double ref_resid(int n, const int *Ap, const int *Ai, const double *Ax, const double *x,
                                   const double *b) {
    double *r = (double *)calloc((size_t)(n ? n : 1), sizeof(double)), s = 0, t = 0;
    int j, p;
    for (j = 0; j < n; j++)
        for (p = Ap[j]; p < Ap[j + 1]; p++) {
            int i = Ai[p];
            r[i] += Ax[p] * x[j];
            if (i != j) r[j] += Ax[p] * x[i];
        }
    for (j = 0; j < n; j++) {
        s += (r[j] - b[j]) * (r[j] - b[j]);
        t += b[j] * b[j];
    }
    free(r);
    return t > 0 ? sqrt(s / t) : sqrt(s);
}
/* As ref_ldl, but from CHOLMOD's supernodal LL^T (no relaxed amalgamation) converted to LDL^T: a second,
   differently rounded factorization of the same matrix; Lx (nnz of the simplicial L) and D given. Returns
   0 on success, 1 if CHOLMOD fails or the pattern differs from Lp. */
REF_UNUSED static int ref_ldl_super(int n, const int *Ap, const int *Ai, const double *Ax, const int *perm,
                                    const int *Lp, double *Lx, double *D) {
    cholmod_common c;
    cholmod_sparse *A;
    cholmod_factor *L;
    int ok, j, p;
    cholmod_start(&c);
    c.supernodal = CHOLMOD_SUPERNODAL;
    c.nmethods = 1;
    c.method[0].ordering = CHOLMOD_GIVEN;
    c.postorder = 0;
    c.nrelax[0] = c.nrelax[1] = c.nrelax[2] = 0;
    c.zrelax[0] = c.zrelax[1] = c.zrelax[2] = 0;
    A = ref_sparse(n, Ap, Ai, Ax, &c);
    L = cholmod_analyze_p(A, (int *)perm, NULL, 0, &c);
    ok = L && cholmod_factorize(A, L, &c) && c.status == CHOLMOD_OK &&
         cholmod_change_factor(CHOLMOD_REAL, 0, 0, 1, 1, L, &c);
    if (ok) {
        const int *cp = (const int *)L->p, *cn = (const int *)L->nz;
        const double *cx = (const double *)L->x;
        for (j = 0; j < n && ok; j++) ok = cn[j] - 1 == Lp[j + 1] - Lp[j];
        for (j = 0; j < n && ok; j++) {
            D[j] = cx[cp[j]];
            for (p = 1; p < cn[j]; p++) Lx[Lp[j] + p - 1] = cx[cp[j] + p];
        }
    }
    cholmod_free_factor(&L, &c);
    cholmod_free_sparse(&A, &c);
    cholmod_finish(&c);
    return ok ? 0 : 1;
}
#endif
