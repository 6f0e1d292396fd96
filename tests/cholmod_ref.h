/* Reference computations with CHOLMOD (SuiteSparse) for the tests: independent factorization
   and solve of an explicitly given symmetric matrix (upper CSC, amps_csc layout, int indices). */
#ifndef CHOLMOD_REF_H
#define CHOLMOD_REF_H
#include <cholmod.h>

/* Copy of upper-triangular A (n x n) as a CHOLMOD sparse matrix (stype = 1). */
static cholmod_sparse *ref_sparse(int n, const int *Ap, const int *Ai, const double *Ax, cholmod_common *c) {
    cholmod_sparse *S = cholmod_allocate_sparse(n, n, Ap[n], 1, 1, 1, CHOLMOD_REAL, c);
    memcpy(S->p, Ap, sizeof(int) * (n + 1));
    memcpy(S->i, Ai, sizeof(int) * Ap[n]);
    memcpy(S->x, Ax, sizeof(double) * Ap[n]);
    return S;
}

/* Solves A x = b with CHOLMOD. perm: given ordering (perm[k] = original index k-th) or NULL for
   CHOLMOD's AMD. simplicial: 1 = simplicial LDL^T, 0 = supernodal LL^T. Returns 0 on success. */
static int ref_solve(int n, const int *Ap, const int *Ai, const double *Ax, const int *perm, int simplicial,
                     const double *b, double *x) {
    cholmod_common c; cholmod_sparse *A; cholmod_factor *L; cholmod_dense *B, *X; int ok;
    cholmod_start(&c);
    c.supernodal = simplicial ? CHOLMOD_SIMPLICIAL : CHOLMOD_SUPERNODAL;
    c.final_ll = simplicial ? 0 : 1;
    if (perm) { c.nmethods = 1; c.method[0].ordering = CHOLMOD_GIVEN; c.postorder = 0; }
    else { c.nmethods = 1; c.method[0].ordering = CHOLMOD_AMD; }
    A = ref_sparse(n, Ap, Ai, Ax, &c);
    L = perm ? cholmod_analyze_p(A, (int *)perm, NULL, 0, &c) : cholmod_analyze(A, &c);
    ok = cholmod_factorize(A, L, &c) && c.status == CHOLMOD_OK;
    B = cholmod_allocate_dense(n, 1, n, CHOLMOD_REAL, &c);
    memcpy(B->x, b, sizeof(double) * n);
    X = ok ? cholmod_solve(CHOLMOD_A, L, B, &c) : NULL;
    ok = ok && X != NULL;
    if (X) memcpy(x, X->x, sizeof(double) * n);
    cholmod_free_dense(&X, &c); cholmod_free_dense(&B, &c);
    cholmod_free_factor(&L, &c); cholmod_free_sparse(&A, &c); cholmod_finish(&c);
    return ok ? 0 : 1;
}

/* nnz(L) (with diagonal) for ordering: perm given, or NULL for CHOLMOD AMD (method=CHOLMOD_AMD)
   or METIS (method=CHOLMOD_METIS). If perm_out, receives the ordering CHOLMOD used. */
static double ref_nnzL(int n, const int *Ap, const int *Ai, const double *Ax, const int *perm, int method, int *perm_out) {
    cholmod_common c; cholmod_sparse *A; cholmod_factor *L; double nz = -1; int j;
    cholmod_start(&c);
    c.supernodal = CHOLMOD_SIMPLICIAL;
    c.nmethods = 1; c.method[0].ordering = perm ? CHOLMOD_GIVEN : method; c.postorder = perm ? 0 : 1;
    A = ref_sparse(n, Ap, Ai, Ax, &c);
    L = perm ? cholmod_analyze_p(A, (int *)perm, NULL, 0, &c) : cholmod_analyze(A, &c);
    if (L) {
        const int *cc = (const int *)L->ColCount;
        nz = 0; for (j = 0; j < n; j++) nz += cc[j];
        if (perm_out) memcpy(perm_out, L->Perm, sizeof(int) * n);
    }
    cholmod_free_factor(&L, &c); cholmod_free_sparse(&A, &c); cholmod_finish(&c);
    return nz;
}
#endif
