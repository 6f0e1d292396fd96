/* What a scene test knows independently of the scene (fixed file nodes, pins, forces), and the
   reference solution of the current mesh by CHOLMOD: the cut mesh assembled from scratch with
   amps_mesh_assemble, fixed nodes eliminated, pins moved to the right-hand side.
   Include after amps.h (with the FEM section), amps_test.h and cholmod_ref.h. */
#ifndef SCENE_REF_H
#define SCENE_REF_H
#include <string.h>

typedef struct shadow {
    unsigned char *fixed0;  /* fixed flag of the file nodes */
    unsigned char *pinned;  /* per node */
    double *pinval, *force; /* 3 per node */
    int cap;
    int *watch, nwatch; /* watched nodes (copies of watched nodes are watched) */
} shadow;

REF_UNUSED static void shadow_grow(shadow *w, int n) {
    if (n <= w->cap) return;
    w->pinned = (unsigned char *)realloc(w->pinned, n);
    w->pinval = (double *)realloc(w->pinval, sizeof(double) * 3 * n);
    w->force = (double *)realloc(w->force, sizeof(double) * 3 * n);
    memset(w->pinned + w->cap, 0, n - w->cap);
    memset(w->pinval + 3 * w->cap, 0, sizeof(double) * 3 * (n - w->cap));
    memset(w->force + 3 * w->cap, 0, sizeof(double) * 3 * (n - w->cap));
    w->cap = n;
}

REF_UNUSED static void shadow_free(shadow *w) {
    free(w->fixed0);
    free(w->pinned);
    free(w->pinval);
    free(w->force);
    memset(w, 0, sizeof(*w));
}

/* Measurements of one reference solve. */
typedef struct scene_ref_info {
    int n;           /* equations of the reduced system */
    double res_chol; /* CHOLMOD's relative residual before refinement */
    double err_chol; /* CHOLMOD's relative error before refinement, against the refined solution */
    double res_ref;  /* relative residual of the reference (after refinement) */
    double res_disp; /* relative residual of the given displacements (disp), -1 if none */
    double be_chol;  /* CHOLMOD's normwise backward error ||r|| / (||K||_1 ||x|| + ||b||), before refinement */
    double be_disp;  /* the same for disp */
    double cond;     /* amps_condest of the reduced matrix (when asked), else -1 */
} scene_ref_info;

/* Reference displacements u (3 per node) of the current mesh m by CHOLMOD with nrefine steps of
   iterative refinement; when disp (3 per node) is given, also the relative residual of disp on
   the same reduced system; with want_cond the condition estimate of the reduced matrix (amps
   factor + amps_condest). Returns the reference's relative residual (-1 if CHOLMOD failed). */
REF_UNUSED static double scene_reference(amps_ctx *ctx, const amps_mesh *m, const shadow *w, int nrefine,
                                         const double *disp, double *u, scene_ref_info *info, int want_cond) {
    int nn = m->nnode, v, d, n, nf = 0, k, *map;
    unsigned char *fixed = (unsigned char *)calloc(nn + 1, 1);
    amps_int *dof = (amps_int *)malloc(sizeof(amps_int) * 3 * nn);
    amps_csc *K, *R;
    double *rhs, *x, *x0, *y, *gv, res = -1;
    int *ti, *tj, nz = 0, j, p;
    double *tx;
    scene_ref_info inf;
    inf.res_chol = inf.err_chol = inf.res_ref = inf.res_disp = inf.be_chol = inf.be_disp = inf.cond = -1;
    for (v = 0; v < nn; v++) fixed[v] = w->fixed0[m->origin[v]];
    n = (int)amps_mesh_number_dofs(m, fixed, dof);
    K = amps_mesh_assemble(ctx, m, dof, n);
    map = (int *)malloc(sizeof(int) * (n + 1));
    for (k = 0; k < n; k++) map[k] = 0;
    for (v = 0; v < nn; v++)
        if (w->pinned[v])
            for (d = 0; d < 3; d++) map[dof[3 * v + d]] = -1;
    for (k = 0; k < n; k++) map[k] = map[k] < 0 ? -1 : nf++;
    rhs = (double *)calloc(nf + 1, sizeof(double));
    x = (double *)calloc(nf + 1, sizeof(double));
    x0 = (double *)calloc(nf + 1, sizeof(double));
    y = (double *)calloc(nf + 1, sizeof(double));
    gv = (double *)calloc(n + 1, sizeof(double));
    inf.n = nf;
    for (v = 0; v < nn; v++)
        for (d = 0; d < 3; d++) {
            int e = dof[3 * v + d];
            if (e < 0) continue;
            if (w->pinned[v]) gv[e] = w->pinval[3 * v + d];
            else rhs[map[e]] = w->force[3 * v + d];
        }
    ti = (int *)malloc(sizeof(int) * (K->p[n] + 1));
    tj = (int *)malloc(sizeof(int) * (K->p[n] + 1));
    tx = (double *)malloc(sizeof(double) * (K->p[n] + 1));
    for (j = 0; j < n; j++)
        for (p = K->p[j]; p < K->p[j + 1]; p++) {
            int i = K->i[p];
            double val = K->x[p];
            if (map[i] >= 0 && map[j] >= 0) {
                ti[nz] = map[i];
                tj[nz] = map[j];
                tx[nz] = val;
                nz++;
            } else if (map[i] >= 0) rhs[map[i]] -= val * gv[j];
            else if (map[j] >= 0 && i != j) rhs[map[j]] -= val * gv[i];
        }
    R = amps_csc_from_triplets(ctx, nf, nz, ti, tj, tx, AMPS_UPPER);
    if (R && ref_solve_refined(nf, R->p, R->i, R->x, rhs, x, nrefine, x0) == 0) {
        double knorm = 0, nb = t_norm(nf, rhs);
        for (k = 0; k < nf; k++) y[k] = 0;
        for (j = 0; j < nf; j++)
            for (p = R->p[j]; p < R->p[j + 1]; p++) {
                y[j] += fabs(R->x[p]);
                if (R->i[p] != j) y[R->i[p]] += fabs(R->x[p]);
            }
        for (k = 0; k < nf; k++)
            if (y[k] > knorm) knorm = y[k];
        for (k = 0; k < nf; k++) y[k] = 0;
        inf.res_chol = ref_resid(nf, R->p, R->i, R->x, x0, rhs);
        inf.be_chol = inf.res_chol * nb / (knorm * t_norm(nf, x0) + nb);
        inf.err_chol = t_reldiff(nf, x0, x);
        res = inf.res_ref = ref_resid(nf, R->p, R->i, R->x, x, rhs);
        if (disp) {
            for (v = 0; v < nn; v++)
                for (d = 0; d < 3; d++) {
                    int e = dof[3 * v + d];
                    if (e >= 0 && map[e] >= 0) y[map[e]] = disp[3 * v + d];
                }
            inf.res_disp = ref_resid(nf, R->p, R->i, R->x, y, rhs);
            inf.be_disp = inf.res_disp * nb / (knorm * t_norm(nf, y) + nb);
        }
        if (want_cond && nf > 0) {
            amps_factor *F = amps_analyze(ctx, R, AMPS_UPPER, NULL);
            double c;
            if (F && amps_factorize(ctx, F, R) == AMPS_OK && amps_condest(ctx, R, AMPS_UPPER, F, NULL, &c) == AMPS_OK)
                inf.cond = c;
            amps_factor_free(ctx, F);
        }
    }
    for (v = 0; v < nn; v++)
        for (d = 0; d < 3; d++) {
            int e = dof[3 * v + d];
            u[3 * v + d] = e < 0 ? 0.0 : (map[e] < 0 ? gv[e] : x[map[e]]);
        }
    amps_csc_free(ctx, R);
    amps_csc_free(ctx, K);
    free(gv);
    free(ti);
    free(tj);
    free(tx);
    free(fixed);
    free(dof);
    free(map);
    free(rhs);
    free(x);
    free(x0);
    free(y);
    if (info) *info = inf;
    return res;
}
#endif
