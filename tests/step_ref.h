/* The reference of one scene solve or dynamics step by CHOLMOD on the system assembled from
   scratch (statics K u = f + M g, dynamics paper "GPU-accelerated surgery simulation for opening
   a brain fissure", Eq. 27), with the pin reactions. Include after scene_ref.h. */
#ifndef STEP_REF_H
#define STEP_REF_H
/* What the test knows independently of the scene: the shadow of scene_ref.h (fixed file
   nodes, pins, forces) and the gravity and time integration. */
typedef struct tstate {
    shadow sh;
    double g[3];
    int dyn;
    double dt, alpha, beta;
} tstate;

/* The reference of one solve of the current mesh m: statics K u = f + M g (pins u = g), or one
   step from (u, w): A w+ = M w + dt (f + M g - K u) (pins w = (g - u)/dt), u+ = u + dt w+.
   uo, wo (3 per node) receive the result (statics: wo untouched, may be NULL), react (may be
   NULL) the pin reactions. Orphans (nodes in no tet) keep u, w = 0. Returns 0 on success. */
REF_UNUSED static int ref_step(amps_ctx *ctx, const amps_mesh *m, const tstate *w, const double *u, const double *vel,
                               double *uo, double *wo, double *react) {
    int nn = m->nnode, v, d, n, nf = 0, k, j, p, nz = 0, ok, *map, *ti, *tj;
    unsigned char *fixed = (unsigned char *)calloc(nn + 1, 1);
    amps_int *dof = (amps_int *)malloc(sizeof(amps_int) * 3 * nn);
    double *mass = (double *)malloc(sizeof(double) * (nn + 1)), *b, *ue, *gv, *rhs, *x, *tx, *ax;
    double cM = w->dyn ? 1 + w->alpha * w->dt : 0, cK = w->dyn ? w->beta * w->dt + w->dt * w->dt : 1;
    amps_csc *K, *R;
    for (v = 0; v < nn; v++) fixed[v] = w->sh.fixed0[m->origin[v]];
    n = (int)amps_mesh_number_dofs(m, fixed, dof);
    K = amps_mesh_assemble(ctx, m, dof, n);
    amps_mesh_lumped_mass(m, mass);
    b = (double *)calloc(n + 1, sizeof(double));
    ue = (double *)calloc(n + 1, sizeof(double));
    gv = (double *)calloc(n + 1, sizeof(double));
    ax = (double *)calloc(n + 1, sizeof(double));
    map = (int *)calloc(n + 1, sizeof(int));
    for (v = 0; v < nn; v++)
        for (d = 0; d < 3; d++) {
            int e = dof[3 * v + d];
            if (e < 0) continue;
            ue[e] = u[3 * v + d];
            b[e] = w->sh.force[3 * v + d] + mass[v] * w->g[d];
            if (w->sh.pinned[v]) {
                map[e] = -1;
                gv[e] = w->dyn ? (w->sh.pinval[3 * v + d] - u[3 * v + d]) / w->dt : w->sh.pinval[3 * v + d];
            }
        }
    if (w->dyn) { /* b = M w + dt (f + M g - K u) */
        amps_csc_symv(K, AMPS_UPPER, ue, ax);
        for (v = 0; v < nn; v++)
            for (d = 0; d < 3; d++) {
                int e = dof[3 * v + d];
                if (e >= 0) b[e] = mass[v] * vel[3 * v + d] + w->dt * (b[e] - ax[e]);
            }
    }
    for (p = 0; p < K->p[n]; p++) K->x[p] *= cK; /* A = cK K + cM M */
    for (v = 0; v < nn; v++)
        for (d = 0; d < 3; d++) {
            int e = dof[3 * v + d];
            if (e >= 0) K->x[K->p[e + 1] - 1] += cM * mass[v];
        }
    for (k = 0; k < n; k++) map[k] = map[k] < 0 ? -1 : nf++;
    rhs = (double *)calloc(nf + 1, sizeof(double));
    x = (double *)calloc(nf + 1, sizeof(double));
    ti = (int *)calloc(K->p[n] + 1, sizeof(int));
    tj = (int *)calloc(K->p[n] + 1, sizeof(int));
    tx = (double *)calloc(K->p[n] + 1, sizeof(double));
    amps_csc_symv(K, AMPS_UPPER, gv, ax); /* the prescribed values move to the right-hand side */
    for (k = 0; k < n; k++)
        if (map[k] >= 0) rhs[map[k]] = b[k] - ax[k];
    for (j = 0; j < n; j++) /* the free block */
        for (p = K->p[j]; p < K->p[j + 1]; p++)
            if (map[K->i[p]] >= 0 && map[j] >= 0) {
                ti[nz] = map[K->i[p]];
                tj[nz] = map[j];
                tx[nz++] = K->x[p];
            }
    R = amps_csc_from_triplets(ctx, nf, nz, ti, tj, tx, AMPS_UPPER);
    ok = R && ref_solve_refined(nf, R->p, R->i, R->x, rhs, x, 2, NULL) == 0;
    for (k = 0; k < n; k++) ue[k] = map[k] < 0 ? gv[k] : x[map[k]]; /* the solution on every equation */
    amps_csc_symv(K, AMPS_UPPER, ue, ax);                           /* A x - b */
    for (j = 0; j < n; j++) ax[j] -= b[j];
    for (v = 0; v < nn; v++)
        for (d = 0; d < 3; d++) {
            int e = dof[3 * v + d];
            double s = e >= 0 ? ue[e] : 0.0;
            if (w->dyn) {
                wo[3 * v + d] = s;
                uo[3 * v + d] = u[3 * v + d] + w->dt * s;
            } else {
                uo[3 * v + d] = e >= 0 ? s : (fixed[v] ? 0.0 : u[3 * v + d]);
            }
            if (react) react[3 * v + d] = (e >= 0 && w->sh.pinned[v]) ? ax[e] / (w->dyn ? w->dt : 1.0) : 0.0;
        }
    amps_csc_free(ctx, R);
    amps_csc_free(ctx, K);
    free(fixed);
    free(dof);
    free(mass);
    free(b);
    free(ue);
    free(gv);
    free(ax);
    free(map);
    free(rhs);
    free(x);
    free(ti);
    free(tj);
    free(tx);
    return ok ? 0 : 1;
}

/* Pins node v at its current displacement plus a random offset of at most 0.005 per axis; the
   shadow follows a successful pin. Returns 1 if pinned. */
static int t_pin_near(amps_ctx *ctx, amps_scene *S, shadow *sh, int v) {
    double g[3];
    int d;
    for (d = 0; d < 3; d++) g[d] = amps_scene_displacements(S)[3 * v + d] + 0.01 * (t_unif() - 0.5);
    if (amps_scene_pin(ctx, S, v, g) != AMPS_OK) return 0;
    sh->pinned[v] = 1;
    memcpy(sh->pinval + 3 * v, g, sizeof(g));
    return 1;
}

#endif
