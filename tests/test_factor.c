/* Symbolic analysis and numeric LDL^T against CHOLMOD's simplicial LDL^T on the same ordering. */
#define AMPS_IMPLEMENTATION
#include "amps.h"
#include "amps_test.h"
#include "fe_util.h"
#include "cholmod_ref.h"
#include "core_mats.h"
#include <string.h>

/* max |a - b| / max(|b|, floor) over entries; floor = 1e-3 * max|b| guards tiny entries of L. */
static double relerr(int n, const double *a, const double *b) {
    double m = 0, e = 0;
    int k;
    for (k = 0; k < n; k++)
        if (fabs(b[k]) > m) m = fabs(b[k]);
    for (k = 0; k < n; k++) {
        double s = fabs(b[k]) > 1e-3 * m ? fabs(b[k]) : 1e-3 * m, d = fabs(a[k] - b[k]) / (s > 0 ? s : 1);
        if (d > e) e = d;
    }
    return e;
}

/* Checks the factor of upper A with ordering perm (NULL: amps default) against CHOLMOD. */
static void check_matrix(const char *name, const amps_csc *A, const int *perm) {
    amps_ctx ctx;
    amps_factor *F, *F2;
    amps_order_opts o;
    int *Lp = NULL, *Li = NULL, n = A->ncol, j, p, same, k;
    double *Lx = NULL, *D = NULL, err, h;
    amps_int npos, nneg, nzero;
    amps_ctx_init(&ctx);
    memset(&o, 0, sizeof(o));
    o.method = AMPS_ORDER_GIVEN;
    o.perm = perm;
    F = amps_analyze(&ctx, A, AMPS_UPPER, perm ? &o : NULL);
    CHECK(F != NULL, "%s: analyze: %s", name, ctx.msg);
    if (!F) return;
    CHECK(amps_factorize(&ctx, F, A) == AMPS_OK && F->is_numeric, "%s: factorize: %s", name, ctx.msg);
    CHECK(ref_ldl(n, A->p, A->i, A->x, F->perm, &Lp, &Li, &Lx, &D) == 0, "%s: cholmod failed", name);
    same = memcmp(Lp, F->Lp, sizeof(int) * (n + 1)) == 0 && memcmp(Li, F->Li, sizeof(int) * Lp[n]) == 0;
    CHECK(same, "%s: pattern of L differs from CHOLMOD (nnz %d vs %d)", name, (int)F->Lp[n], Lp[n]);
    CHECK(fabs(amps_factor_nnz(F) - ref_nnzL(n, A->p, A->i, A->x, F->perm, 0, NULL)) < 0.5, "%s: nnz(L)", name);
    if (same) {
        /* tolerance: 1e-12, or 10x the discrepancy between CHOLMOD's simplicial and supernodal factors
           when rounding makes them differ more (ill-conditioned FE matrices) */
        double *sx = (double *)malloc(sizeof(double) * (Lp[n] + 1)), *sd = (double *)malloc(sizeof(double) * n);
        double tl = 1e-12, td = 1e-12;
        CHECK(ref_ldl_super(n, A->p, A->i, A->x, F->perm, Lp, sx, sd) == 0, "%s: cholmod supernodal failed", name);
        tl = fmax(tl, 10 * relerr(Lp[n], sx, Lx));
        td = fmax(td, 10 * relerr(n, sd, D));
        err = relerr(Lp[n], F->Lx, Lx);
        CHECK(err <= tl, "%s: L differs from CHOLMOD by %g (tolerance %g)", name, err, tl);
        err = relerr(n, F->D, D);
        CHECK(err <= td, "%s: D differs from CHOLMOD by %g (tolerance %g)", name, err, td);
        if (tl > 1e-12)
            printf("%s: L, D within %.2g, %.2g of CHOLMOD (tolerance %.2g, %.2g)\n", name, relerr(Lp[n], F->Lx, Lx),
                   relerr(n, F->D, D), tl, td);
        free(sx);
        free(sd);
    }
    { /* solution against CHOLMOD's */
        double *b = (double *)malloc(sizeof(double) * n), *x = (double *)malloc(sizeof(double) * n);
        double *xr = (double *)malloc(sizeof(double) * n), *w = (double *)malloc(sizeof(double) * n);
        for (j = 0; j < n; j++) b[j] = cos(0.3 * j) + 0.25;
        CHECK(amps_solve(&ctx, F, b, x, w) == AMPS_OK && ref_solve(n, A->p, A->i, A->x, F->perm, 1, b, xr) == 0,
              "%s: solve", name);
        CHECK(t_reldiff(n, x, xr) <= 1e-6 && t_norm(n, x) > 0, "%s: solution differs from CHOLMOD's by %g", name,
              t_reldiff(n, x, xr));
        free(b);
        free(x);
        free(xr);
        free(w);
    }
    amps_factor_inertia(F, &npos, &nneg, &nzero);
    CHECK(npos == n && nneg == 0 && nzero == 0, "%s: inertia %d %d %d", name, (int)npos, (int)nneg, (int)nzero);
    /* elimination tree = first off-diagonal row of each column; height = longest path */
    for (j = 0, k = 1; j < n; j++) k &= F->parent[j] == (F->Lp[j + 1] > F->Lp[j] ? F->Li[F->Lp[j]] : -1);
    CHECK(k, "%s: parent is not the elimination tree", name);
    {
        int *dep = (int *)malloc(sizeof(int) * (n + 1)), hh = 0;
        for (j = n - 1; j >= 0; j--) {
            dep[j] = F->parent[j] < 0 ? 1 : dep[F->parent[j]] + 1;
            if (dep[j] > hh) hh = dep[j];
        }
        CHECK(F->height == hh, "%s: height %d, expected %d", name, (int)F->height, hh);
        free(dep);
    }
    /* other stored triangles, and 1 vs 2 threads */
    {
        amps_stype st[2] = {AMPS_LOWER, AMPS_FULL};
        int s;
        for (s = 0; s < 2; s++) {
            amps_csc *B = m_convert(&ctx, A, st[s]);
            o.perm = F->perm;
            o.method = AMPS_ORDER_GIVEN;
            F2 = amps_analyze(&ctx, B, st[s], &o);
            CHECK(F2 && amps_factorize(&ctx, F2, B) == AMPS_OK, "%s: stype %d: %s", name, st[s], ctx.msg);
            if (F2)
                CHECK(F2->Lp[n] == F->Lp[n] && relerr(F->Lp[n], F2->Lx, F->Lx) == 0 && relerr(n, F2->D, F->D) == 0,
                      "%s: stype %d gives a different factor", name, st[s]);
            amps_factor_free(&ctx, F2);
            amps_csc_free(&ctx, B);
        }
        /* 1 thread, 2 threads, 2 threads with the parallel paths forced on this small matrix */
        for (k = 1; k <= 3; k++) {
            ctx.nthreads = k == 1 ? 1 : 2;
            F2 = amps_analyze(&ctx, A, AMPS_UPPER, &o);
            if (F2 && k == 3) {
                ((amps__fpriv *)F2->priv)->parmin = 0;
                ((amps__fpriv *)F2->priv)->pargroup = 0;
            }
            CHECK(F2 && amps_factorize(&ctx, F2, A) == AMPS_OK, "%s: threads %d: %s", name, k, ctx.msg);
            if (F2)
                CHECK(relerr(F->Lp[n], F2->Lx, F->Lx) <= 1e-14 && relerr(n, F2->D, F->D) <= 1e-14,
                      "%s: thread variant %d differs", name, k);
            amps_factor_free(&ctx, F2);
        }
        ctx.nthreads = 0;
    }
    /* refactorization with new values (same pattern): 2A gives 2D, same L */
    {
        double *x2 = (double *)malloc(sizeof(double) * (A->p[n] + 1)), *x0 = A->x;
        double *L1 = (double *)malloc(sizeof(double) * (F->Lp[n] + 1)), *D1 = (double *)malloc(sizeof(double) * n);
        amps_csc A2 = *A;
        memcpy(L1, F->Lx, sizeof(double) * F->Lp[n]);
        memcpy(D1, F->D, sizeof(double) * n);
        for (p = 0; p < A->p[n]; p++) x2[p] = 2 * x0[p];
        A2.x = x2;
        CHECK(amps_factorize(&ctx, F, &A2) == AMPS_OK, "%s: refactorize: %s", name, ctx.msg);
        for (j = 0, h = 0; j < n; j++) h = fmax(h, fabs(F->D[j] - 2 * D1[j]));
        CHECK(h == 0 && relerr(F->Lp[n], F->Lx, L1) == 0, "%s: refactorization of 2A: %g", name, h);
        free(x2);
        free(L1);
        free(D1);
    }
    free(Lp);
    free(Li);
    free(Lx);
    free(D);
    amps_factor_free(&ctx, F);
}

/* Expects AMPS_ERR_NOT_SPD with a column named in the message. */
static void check_not_spd(const char *name, const amps_csc *A, const int *perm) {
    amps_ctx ctx;
    amps_factor *F;
    amps_status s;
    amps_ctx_init(&ctx);
    F = m_analyze(&ctx, A, perm);
    CHECK(F != NULL, "%s: analyze: %s", name, ctx.msg);
    if (!F) return;
    s = amps_factorize(&ctx, F, A);
    CHECK(s == AMPS_ERR_NOT_SPD && ctx.status == AMPS_ERR_NOT_SPD, "%s: status %d (%s)", name, (int)s, ctx.msg);
    CHECK(strstr(ctx.msg, "column") != NULL && F->is_numeric == 0, "%s: message '%s'", name, ctx.msg);
    { /* the parallel paths report the same column */
        char msg[256];
        memcpy(msg, ctx.msg, sizeof(msg));
        ctx.nthreads = 2;
        ((amps__fpriv *)F->priv)->parmin = 0;
        ((amps__fpriv *)F->priv)->pargroup = 0;
        s = amps_factorize(&ctx, F, A);
        CHECK(s == AMPS_ERR_NOT_SPD && strcmp(msg, ctx.msg) == 0, "%s: 2 threads: '%s' vs '%s'", name, ctx.msg, msg);
    }
    amps_factor_free(&ctx, F);
}

/* amps_etree, amps_postorder and amps_colcounts of upper A under perm (NULL: identity) against
   cholmod_etree, cholmod_postorder and cholmod_rowcolcounts of C = P A P^T; amps_etree also on the
   full graph of A with the ordering given, and the counts against the factor's Lp. */
static void check_symbolic(const char *name, const amps_csc *A, const int *perm) {
    int n = A->ncol, nz = A->p[n], j, p, k, ok;
    int *iperm = (int *)malloc(sizeof(int) * (n + 1)), *ord = (int *)malloc(sizeof(int) * (n + 1));
    int *Cp = (int *)calloc((size_t)n + 1, sizeof(int)), *Ci = (int *)malloc(sizeof(int) * (nz + 1));
    int *Lp = (int *)calloc((size_t)n + 1, sizeof(int)), *Li = (int *)malloc(sizeof(int) * (nz + 1));
    int *Gp = (int *)calloc((size_t)n + 1, sizeof(int)), *Gi = (int *)malloc(sizeof(int) * (2 * nz + 1));
    int *par = (int *)malloc(sizeof(int) * (n + 1)), *par2 = (int *)malloc(sizeof(int) * (n + 1));
    int *post = (int *)malloc(sizeof(int) * (n + 1)), *cc = (int *)malloc(sizeof(int) * (n + 1));
    int *w = (int *)malloc(sizeof(int) * (4 * n + 1)), *cpar = (int *)malloc(sizeof(int) * (n + 1));
    int *cpost = (int *)malloc(sizeof(int) * (n + 1)), *rc = (int *)malloc(sizeof(int) * (n + 1));
    int *ccc = (int *)malloc(sizeof(int) * (n + 1)), *first = (int *)malloc(sizeof(int) * (n + 1));
    int *level = (int *)malloc(sizeof(int) * (n + 1));
    cholmod_common c;
    cholmod_sparse *S, *St;
    for (k = 0; k < n; k++) {
        ord[k] = perm ? perm[k] : k;
        iperm[ord[k]] = k;
    }
    /* C = P A P^T: upper columns (Cp, Ci), lower columns (Lp, Li); full graph of A (Gp, Gi) */
    for (j = 0; j < n; j++)
        for (p = A->p[j]; p < A->p[j + 1]; p++) {
            int a = iperm[A->i[p]], b = iperm[j];
            Cp[(a > b ? a : b) + 1]++;
            Lp[(a < b ? a : b) + 1]++;
            Gp[j + 1]++;
            if (A->i[p] != j) Gp[A->i[p] + 1]++;
        }
    for (j = 0; j < n; j++) {
        Cp[j + 1] += Cp[j];
        Lp[j + 1] += Lp[j];
        Gp[j + 1] += Gp[j];
    }
    for (j = 0; j < n; j++)
        for (p = A->p[j]; p < A->p[j + 1]; p++) {
            int a = iperm[A->i[p]], b = iperm[j], lo = a < b ? a : b, hi = a < b ? b : a;
            Ci[Cp[hi]++] = lo;
            Li[Lp[lo]++] = hi;
            Gi[Gp[j]++] = A->i[p];
            if (A->i[p] != j) Gi[Gp[A->i[p]]++] = j;
        }
    for (j = n; j > 0; j--) {
        Cp[j] = Cp[j - 1];
        Lp[j] = Lp[j - 1];
        Gp[j] = Gp[j - 1];
    }
    Cp[0] = Lp[0] = Gp[0] = 0;
    amps_etree(n, Cp, Ci, NULL, NULL, par, w);
    amps_etree(n, Gp, Gi, ord, iperm, par2, w);
    CHECK(memcmp(par, par2, sizeof(int) * n) == 0, "%s: etree of the upper part of P A P^T and of A ordered differ",
          name);
    amps_postorder(n, par, post, w);
    amps_colcounts(n, par, post, Lp, Li, cc, w);
    cholmod_start(&c);
    S = cholmod_allocate_sparse(n, n, nz, 0, 1, 1, CHOLMOD_PATTERN, &c);
    memcpy(S->p, Cp, sizeof(int) * (n + 1));
    memcpy(S->i, Ci, sizeof(int) * (nz + 1 > 1 ? nz : 1));
    St = cholmod_transpose(S, 0, &c);
    ok = cholmod_etree(S, cpar, &c) && cholmod_postorder(cpar, n, NULL, cpost, &c) == n &&
         cholmod_rowcolcounts(St, NULL, 0, cpar, cpost, rc, ccc, first, level, &c);
    CHECK(ok && c.status == CHOLMOD_OK, "%s: cholmod symbolic failed (status %d)", name, c.status);
    if (ok) {
        CHECK(memcmp(par, cpar, sizeof(int) * n) == 0, "%s: etree differs from cholmod_etree", name);
        CHECK(memcmp(post, cpost, sizeof(int) * n) == 0, "%s: postorder differs from cholmod_postorder", name);
        CHECK(memcmp(cc, ccc, sizeof(int) * n) == 0, "%s: column counts differ from cholmod_rowcolcounts", name);
    }
    if (perm) {
        amps_ctx ctx;
        amps_order_opts o;
        amps_factor *F;
        amps_ctx_init(&ctx);
        memset(&o, 0, sizeof(o));
        o.method = AMPS_ORDER_GIVEN;
        o.perm = perm;
        F = amps_analyze(&ctx, A, AMPS_UPPER, &o);
        CHECK(F != NULL, "%s: analyze: %s", name, ctx.msg);
        for (k = 0, ok = 1; F && k < n; k++) ok = ok && F->parent[k] == par[k] && F->Lp[k + 1] - F->Lp[k] == cc[k] - 1;
        CHECK(F && ok, "%s: analyze's tree or Lp differ from amps_etree / amps_colcounts", name);
        amps_factor_free(&ctx, F);
    }
    cholmod_free_sparse(&S, &c);
    cholmod_free_sparse(&St, &c);
    cholmod_finish(&c);
    free(iperm);
    free(ord);
    free(Cp);
    free(Ci);
    free(Lp);
    free(Li);
    free(Gp);
    free(Gi);
    free(par);
    free(par2);
    free(post);
    free(cc);
    free(w);
    free(cpar);
    free(cpost);
    free(rc);
    free(ccc);
    free(first);
    free(level);
}

/* Hand cases: n = 0, n = 1, a diagonal matrix (a forest of single nodes), two paths. */
static void check_symbolic_small(void) {
    int Ap[6] = {0}, Ai[8] = {0}, par[5], post[5], cc[5], w[20], k, ok;
    /* n = 0 and n = 1 */
    amps_etree(0, Ap, Ai, NULL, NULL, par, w);
    amps_postorder(0, par, post, w);
    amps_colcounts(0, par, post, Ap, Ai, cc, w);
    Ap[1] = 1;
    Ai[0] = 0;
    amps_etree(1, Ap, Ai, NULL, NULL, par, w);
    amps_postorder(1, par, post, w);
    amps_colcounts(1, par, post, Ap, Ai, cc, w);
    CHECK(par[0] == -1 && post[0] == 0 && cc[0] == 1, "n = 1: parent %d post %d count %d", par[0], post[0], cc[0]);
    /* diagonal 4 x 4: four roots */
    for (k = 0; k <= 4; k++) Ap[k] = k;
    for (k = 0; k < 4; k++) Ai[k] = k;
    amps_etree(4, Ap, Ai, NULL, NULL, par, w);
    amps_postorder(4, par, post, w);
    amps_colcounts(4, par, post, Ap, Ai, cc, w);
    for (k = 0, ok = 1; k < 4; k++) ok = ok && par[k] == -1 && post[k] == k && cc[k] == 1;
    CHECK(ok, "diagonal: forest of single nodes");
    { /* upper pattern of the paths 0 - 2 - 4 and 1 - 3: roots 3 and 4, the tree of 3 first */
        static const int up[6] = {0, 0, 0, 1, 2, 3}, ui[3] = {0, 1, 2};
        static const int lp[6] = {0, 1, 2, 3, 3, 3}, li[3] = {2, 3, 4};
        static const int epar[5] = {2, 3, 4, -1, -1}, epost[5] = {1, 3, 0, 2, 4}, ecc[5] = {2, 2, 2, 1, 1};
        static const int order[5] = {1, 0, 2, 3, 4}, iorder[5] = {1, 0, 2, 3, 4};
        static const int fp[6] = {0, 1, 2, 4, 5, 6}, fi[6] = {2, 3, 0, 4, 1, 2}; /* both triangles */
        static const int rpar[5] = {3, 2, 4, -1, -1};                            /* 0 and 1 swapped */
        int d[5];
        amps_etree(5, up, ui, NULL, NULL, par, w);
        amps_postorder(5, par, post, w);
        amps_colcounts(5, par, post, lp, li, cc, w);
        for (k = 0, ok = 1; k < 5; k++) ok = ok && par[k] == epar[k] && post[k] == epost[k] && cc[k] == ecc[k];
        CHECK(ok, "two paths: parent, postorder or counts");
        amps_etree(5, fp, fi, NULL, NULL, d, w);
        CHECK(memcmp(d, epar, sizeof(d)) == 0, "two paths: etree of the full pattern");
        amps_etree(5, fp, fi, order, iorder, d, w);
        CHECK(memcmp(d, rpar, sizeof(d)) == 0, "two paths, 0 and 1 swapped: %d %d %d %d %d", d[0], d[1], d[2], d[3],
              d[4]);
        amps_colcounts(5, par, post, fp, fi, d, w); /* entries above the diagonal ignored */
        CHECK(memcmp(d, ecc, sizeof(d)) == 0, "two paths: counts from the full pattern");
    }
}

int main(void) {
    amps_ctx ctx;
    amps_csc *A;
    int *perm, k;
    char name[64];
    amps_ctx_init(&ctx);
    check_symbolic_small();
    /* random matrices: diagonally dominant and B^T B + shift, several sizes and densities */
    {
        static const int sizes[] = {1, 2, 7, 60, 500, 1500}, degs[] = {1, 2, 4, 6, 5, 3};
        for (k = 0; k < 6; k++) {
            int n = sizes[k];
            A = m_rand(&ctx, n, degs[k], 1.1, 0, 100 + k);
            perm = m_cholmod_perm(A, CHOLMOD_AMD);
            sprintf(name, "rand_dd n=%d", n);
            check_matrix(name, A, perm);
            check_symbolic(name, A, perm);
            check_symbolic(name, A, NULL);
            check_matrix(name, A, NULL);
            free(perm);
            amps_csc_free(&ctx, A);
            A = m_btb(&ctx, n, 2 * n, k < 3 ? 2 : 4, 1e-2, 200 + k);
            perm = m_cholmod_perm(A, CHOLMOD_AMD);
            sprintf(name, "btb n=%d", n);
            check_matrix(name, A, perm);
            check_symbolic(name, A, perm);
            free(perm);
            amps_csc_free(&ctx, A);
        }
        A = m_rand(&ctx, 300, 40, 1.1, 0, 7);
        perm = m_cholmod_perm(A, CHOLMOD_AMD);
        check_matrix("rand dense-ish", A, perm);
        free(perm);
        amps_csc_free(&ctx, A);
    }
    /* finite element matrices, one end / face fixed; CHOLMOD's AMD and METIS orderings */
    {
        fe_mesh meshes[4];
        const char *names[4] = {"beam h=16", "beam h=64", "brick R=6", "brick R=10"};
        meshes[0] = fe_beam(16);
        meshes[1] = fe_beam(64);
        meshes[2] = fe_brick(6);
        meshes[3] = fe_brick(10);
        for (k = 0; k < 4; k++) {
            A = m_fe(&ctx, meshes[k], 1);
            perm = m_cholmod_perm(A, CHOLMOD_AMD);
            check_matrix(names[k], A, perm);
            check_symbolic(names[k], A, perm);
            free(perm);
            perm = m_cholmod_perm(A, CHOLMOD_METIS);
            sprintf(name, "%s metis", names[k]);
            check_matrix(name, A, perm);
            check_symbolic(name, A, perm);
            free(perm);
            if (k < 3) {
                sprintf(name, "%s default", names[k]);
                check_matrix(name, A, NULL);
            }
            amps_csc_free(&ctx, A);
        }
    }
    /* empty matrix */
    {
        amps_factor *F;
        double bx = 0, wx = 0;
        A = amps_csc_from_triplets(&ctx, 0, 0, NULL, NULL, NULL, AMPS_UPPER);
        F = amps_analyze(&ctx, A, AMPS_UPPER, NULL);
        CHECK(F && F->n == 0 && amps_factorize(&ctx, F, A) == AMPS_OK && amps_factor_nnz(F) == 0 &&
                      amps_solve(&ctx, F, &bx, &bx, &wx) == AMPS_OK,
              "empty matrix: %s", ctx.msg);
        amps_factor_free(&ctx, F);
        amps_csc_free(&ctx, A);
    }
    /* not positive definite */
    {
        int ti[8] = {0, 0, 1, 2, 2, 3}, tj[8] = {0, 1, 1, 2, 3, 3};
        double tx[8] = {1, 1, 1, 4, 1, 2};
        A = amps_csc_from_triplets(&ctx, 4, 6, ti, tj, tx, AMPS_UPPER); /* [[1,1],[1,1]] block: zero pivot */
        check_not_spd("singular 2x2 block", A, NULL);
        amps_csc_free(&ctx, A);
        tx[3] = -4;
        A = amps_csc_from_triplets(&ctx, 4, 6, ti, tj, tx, AMPS_UPPER);
        check_not_spd("negative diagonal", A, NULL);
        amps_csc_free(&ctx, A);
        A = amps_csc_from_triplets(&ctx, 4, 5, ti + 1, tj + 1, tx + 1, AMPS_UPPER); /* no (0,0) entry */
        check_not_spd("missing diagonal", A, NULL);
        amps_csc_free(&ctx, A);
        A = m_rand(&ctx, 300, 6, 0, 0.5, 11); /* indefinite */
        perm = m_cholmod_perm(A, CHOLMOD_AMD);
        check_not_spd("indefinite random", A, perm);
        free(perm);
        amps_csc_free(&ctx, A);
        A = m_fe(&ctx, fe_beam(16), 0);
        perm = m_cholmod_perm(A, CHOLMOD_AMD);
        check_not_spd("floating beam", A, perm);
        free(perm);
        amps_csc_free(&ctx, A);
        A = m_fe(&ctx, fe_brick(6), 0);
        perm = m_cholmod_perm(A, CHOLMOD_METIS);
        check_not_spd("floating brick", A, perm);
        free(perm);
        amps_csc_free(&ctx, A);
        A = m_fe(&ctx, fe_brick(11), 0); /* all pivots positive, the smallest at 1e-13 of its diagonal */
        perm = m_cholmod_perm(A, CHOLMOD_METIS);
        check_not_spd("floating brick R=11", A, perm);
        free(perm);
        amps_csc_free(&ctx, A);
    }
    /* misuse: pattern or stype differing from the analysis, bad orderings */
    {
        amps_factor *F;
        amps_csc *B;
        amps_order_opts o;
        int bad[5] = {0, 1, 1, 3, 4};
        A = m_rand(&ctx, 50, 4, 1.1, 0, 5);
        B = m_rand(&ctx, 50, 4, 1.1, 0, 6);
        F = amps_analyze(&ctx, A, AMPS_UPPER, NULL);
        CHECK(F != NULL, "analyze: %s", ctx.msg);
        CHECK(amps_factorize(&ctx, F, B) == AMPS_ERR_PATTERN, "other pattern accepted");
        { /* the same matrix stored as its other triangle has another pattern */
            amps_csc *AL = m_convert(&ctx, A, AMPS_LOWER);
            CHECK(amps_factorize(&ctx, F, AL) == AMPS_ERR_PATTERN, "other stype accepted");
            amps_csc_free(&ctx, AL);
        }
        CHECK(amps_factorize(&ctx, F, A) == AMPS_OK, "factorize: %s", ctx.msg);
        A->x[0] = NAN;
        CHECK(amps_factorize(&ctx, F, A) == AMPS_ERR_VALUE && strstr(ctx.msg, "column 0"), "NaN: %s", ctx.msg);
        A->x[0] = 1;
        amps_factor_free(&ctx, F);
        memset(&o, 0, sizeof(o));
        o.method = AMPS_ORDER_GIVEN;
        o.perm = bad;
        amps_csc_free(&ctx, A);
        A = m_rand(&ctx, 5, 2, 1.1, 0, 5);
        CHECK(amps_analyze(&ctx, A, AMPS_UPPER, &o) == NULL && ctx.status != AMPS_OK, "repeated perm entry accepted");
        bad[1] = 7;
        CHECK(amps_analyze(&ctx, A, AMPS_UPPER, &o) == NULL && ctx.status != AMPS_OK, "perm out of range accepted");
        CHECK(amps_analyze(&ctx, A, AMPS_LOWER, NULL) == NULL && ctx.status == AMPS_ERR_PATTERN,
              "upper as lower accepted");
        amps_csc_free(&ctx, A);
        amps_csc_free(&ctx, B);
    }
    return amps_t_end("test_factor");
}
