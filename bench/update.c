/* bench/update: AMPS update steps against CHOLMOD on the same sequence, side by side.

   usage: update <mesh> <cut|deform> <steps> <out.csv> [cholmod_every]
     mesh: beam:<h> | brick:<R> | path to a TetGen .node / .msh / .mesh file
   cut:    an advancing planar cut: the nodes within half a mesh spacing of the plane x = centre,
           from the top / free end inward, each cut by the plane x = its own x (steps whose
           plane would leave a side empty move on to the next node), with opposing forces
           pulling the two sides apart;
   deform: a pin with a nonzero displacement added on one more node per step.
   Per step it records the AMPS step time (the change + solve), Steps 1-6, |S u C|, the relative
   residual (measured outside the timed step), and, every cholmod_every steps, CHOLMOD on the
   explicitly assembled current system: analyze + factorize + solve (supernodal, a new analysis
   each step since the dimension changes), and a plain solve with that factor.
   Build: see the Makefile (make bench). */
#define AMPS_IMPLEMENTATION
#include "../amps.h"
#include <cholmod.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <math.h>
#include "bench_util.h"


/* CHOLMOD on the reduced system of the current mesh: fixed (by origin) and pinned DOFs
   eliminated. Returns times of analyze+factorize+solve and of a second plain solve. */
typedef struct chol_result { double t_refactor, t_solve, relres; } chol_result;

static chol_result cholmod_step(amps_ctx *ctx, const amps_mesh *m, const unsigned char *fixed0, const unsigned char *pinned,
                                const double *pinval, const double *force, int simplicial) {
    chol_result r = {0, 0, -1};
    int nn = (int)m->nnode, v, d, n, nf = 0, j, p, k, *map;
    unsigned char *fixed = (unsigned char *)malloc((size_t)nn);
    amps_int *dof = (amps_int *)malloc(sizeof(amps_int) * 3 * (size_t)nn);
    amps_csc *K;
    double *gv, t0;
    cholmod_common c;
    cholmod_sparse *A;
    cholmod_factor *L;
    cholmod_dense *B, *X;
    for (v = 0; v < nn; v++) fixed[v] = fixed0[m->origin[v]];
    n = (int)amps_mesh_number_dofs(m, fixed, dof);
    K = amps_mesh_assemble(ctx, m, dof, n);
    map = (int *)malloc(sizeof(int) * ((size_t)n + 1));
    gv = (double *)calloc((size_t)n + 1, sizeof(double));
    for (k = 0; k < n; k++) map[k] = 0;
    for (v = 0; v < nn; v++) if (pinned[v]) for (d = 0; d < 3; d++) { map[dof[3 * v + d]] = -1; gv[dof[3 * v + d]] = pinval[3 * v + d]; }
    for (k = 0; k < n; k++) map[k] = map[k] < 0 ? -1 : nf++;
    cholmod_start(&c);
    c.supernodal = simplicial ? CHOLMOD_SIMPLICIAL : CHOLMOD_SUPERNODAL;
    c.final_ll = simplicial ? 0 : 1;
    {
        /* reduced matrix (upper) and right-hand side f_F - K_FC g */
        int nz = 0;
        int *cp = (int *)calloc((size_t)nf + 1, sizeof(int));
        double *rhs;
        for (j = 0; j < n; j++) if (map[j] >= 0) for (p = K->p[j]; p < K->p[j + 1]; p++) if (map[K->i[p]] >= 0) cp[map[j] + 1]++;
        for (j = 0; j < nf; j++) cp[j + 1] += cp[j];
        A = cholmod_allocate_sparse((size_t)nf, (size_t)nf, (size_t)cp[nf], 1, 1, 1, CHOLMOD_REAL, &c);
        memcpy(A->p, cp, sizeof(int) * ((size_t)nf + 1));
        B = cholmod_zeros((size_t)nf, 1, CHOLMOD_REAL, &c);
        rhs = (double *)B->x;
        for (v = 0; v < nn; v++) for (d = 0; d < 3; d++) { int e = dof[3 * v + d]; if (e >= 0 && map[e] >= 0) rhs[map[e]] = force[3 * v + d]; }
        for (j = 0; j < n; j++)
            for (p = K->p[j]; p < K->p[j + 1]; p++) {
                int i = K->i[p];
                double val = K->x[p];
                if (map[i] >= 0 && map[j] >= 0) { ((int *)A->i)[nz] = map[i]; ((double *)A->x)[nz] = val; nz++; }
                else if (map[i] >= 0) rhs[map[i]] -= val * gv[j];
                else if (map[j] >= 0 && i != j) rhs[map[j]] -= val * gv[i];
            }
        free(cp);
    }
    t0 = amps_now();
    L = cholmod_analyze(A, &c);
    cholmod_factorize(A, L, &c);
    X = cholmod_solve(CHOLMOD_A, L, B, &c);
    r.t_refactor = amps_now() - t0;
    cholmod_free_dense(&X, &c);
    t0 = amps_now();
    X = cholmod_solve(CHOLMOD_A, L, B, &c);
    r.t_solve = amps_now() - t0;
    if (X) {
        double one[2] = {1, 0}, mone[2] = {-1, 0};
        cholmod_dense *R = cholmod_copy_dense(B, &c);
        cholmod_sdmult(A, 0, mone, one, X, R, &c);
        r.relres = cholmod_norm_dense(R, 2, &c) / cholmod_norm_dense(B, 2, &c);
        cholmod_free_dense(&R, &c);
    }
    cholmod_free_dense(&X, &c); cholmod_free_dense(&B, &c);
    cholmod_free_factor(&L, &c); cholmod_free_sparse(&A, &c);
    cholmod_finish(&c);
    amps_csc_free(ctx, K);
    free(fixed); free(dof); free(map); free(gv);
    return r;
}

int main(int argc, char **argv) {
    amps_ctx ctx;
    amps_mesh *m;
    amps_scene *S;
    const char *spec, *mode, *out;
    int steps, every = 5, st, axis_len, nn0, cut;
    double lo[3], hi[3];
    unsigned char *fixed0, *pinned;
    double *pinval, *force, t_prep;
    double *t_amps, *t_chol, *t_cs;
    int nt = 0, nc = 0;
    bu_cut cp;
    FILE *csv;
    if (argc < 5) { fprintf(stderr, "usage: update <beam:h|brick:R|file> <cut|deform> <steps> <out.csv> [cholmod_every]\n"); return 2; }
    spec = argv[1]; mode = argv[2]; steps = atoi(argv[3]); out = argv[4];
    if (argc > 5) every = atoi(argv[5]);
    cut = !strcmp(mode, "cut");
    amps_ctx_init(&ctx);
    m = bu_load_mesh(&ctx, spec);
    if (!m) { fprintf(stderr, "%s: %s\n", spec, ctx.msg); return 1; }
    nn0 = (int)m->nnode;
    if (nn0 <= 0) return 1;
    bu_bbox(m, lo, hi);
    axis_len = bu_up_axis(spec);
    fixed0 = bu_base(m, axis_len, lo, hi);
    {
        amps_scene_opts so;
        bu_scene_opts(&so);
        S = amps_scene_create(&ctx, m, &so);
    }
    amps_scene_set_material(&ctx, S, 1000.0, 0.3);
    bu_fix(&ctx, S, nn0, fixed0);
    /* the cut path: nodes on (or nearest to) the plane x = xc, from the far end of the long axis */
    if (bu_cut_init(&cp, m, fixed0, axis_len, lo, hi)) return 1;
    pinned = (unsigned char *)calloc((size_t)(nn0 + steps + 16), 1);
    pinval = (double *)calloc(3 * (size_t)(nn0 + steps + 16), sizeof(double));
    force = (double *)calloc(3 * (size_t)(nn0 + steps + 16), sizeof(double));
    /* opposing forces near the start of the cut on either side */
    if (cut) bu_cut_forces(&ctx, S, m, fixed0, &cp, force);
    t_prep = amps_now();
    if (amps_scene_solve(&ctx, S) != AMPS_OK) { fprintf(stderr, "first solve: %s\n", ctx.msg); return 1; }
    t_prep = amps_now() - t_prep;
    {
        const amps_factor *F = amps_scene_factor(S);
        printf("%s %s: %d nodes, %ld equations, nnz(L) %.0f, tree height %ld, first solve (ordering+factor) %.3f s, path %d nodes\n",
               spec, mode, nn0, (long)F->n, amps_factor_nnz(F), (long)F->height, t_prep, cp.npath);
    }
    csv = fopen(out, "w");
    if (!csv) { fprintf(stderr, "cannot write %s\n", out); return 1; }
    fprintf(csv, "step,dofs,nsys,t_step,t1,t2,t3,t4,t5,t6,relres,t_cholmod_refactor_solve,t_cholmod_solve,relres_cholmod\n");
    t_amps = (double *)malloc(sizeof(double) * (size_t)steps);
    t_chol = (double *)malloc(sizeof(double) * (size_t)steps);
    t_cs = (double *)malloc(sizeof(double) * (size_t)steps);
    for (st = 0; st < steps && cp.ip < cp.npath; st++) {
        double t0, dt, res = -1;
        amps_update_stats us;
        amps_status s = AMPS_WARN_NOOP;
        int node = -1;
        chol_result cr = {-1, -1, -1};
        t0 = amps_now();
        if (cut) {
            /* the plane through the next path node that the cut actually splits */
            s = bu_cut_next(&ctx, S, &cp, &node);
            if (s == AMPS_WARN_NOOP) break;
        } else {
            double u[3] = {0, 0, 0};
            node = cp.path[cp.ip++];
            u[axis_len] = -0.01 * (hi[axis_len] - lo[axis_len]);
            s = amps_scene_pin(&ctx, S, node, u);
            if (s == AMPS_OK) { pinned[node] = 1; memcpy(pinval + 3 * node, u, sizeof(u)); }
        }
        if (s != AMPS_OK) { fprintf(stderr, "step %d: %s\n", st, ctx.msg); continue; }
        if (amps_scene_solve(&ctx, S) != AMPS_OK) { fprintf(stderr, "solve: %s\n", ctx.msg); return 1; }
        dt = amps_now() - t0;
        amps_update_get_stats(amps_scene_engine(S), &us);
        amps_scene_residual(&ctx, S, &res);
        t_amps[nt++] = dt;
        if (every > 0 && (st % every == 0 || st == steps - 1)) {
            cr = cholmod_step(&ctx, amps_scene_mesh(S), fixed0, pinned, pinval, force, 0);
            t_chol[nc] = cr.t_refactor; t_cs[nc] = cr.t_solve; nc++;
        }
        fprintf(csv, "%d,%ld,%ld,%.6e,%.6e,%.6e,%.6e,%.6e,%.6e,%.6e,%.3e,%.6e,%.6e,%.3e\n", st + 1, (long)us.dim, (long)us.nsys, dt,
                us.t_step[1], us.t_step[2], us.t_step[3], us.t_step[4], us.t_step[5], us.t_step[6], res, cr.t_refactor, cr.t_solve, cr.relres);
        fflush(csv);
    }
    fclose(csv);
    {
        double ma = bu_median(t_amps, nt), mc = bu_median(t_chol, nc), ms = bu_median(t_cs, nc);
        printf("  steps %d: median AMPS step %.2f ms (%.0f Hz); CHOLMOD analyze+factor+solve %.1f ms (x%.1f); CHOLMOD solve %.2f ms (AMPS step / solve = %.2f)\n",
               nt, 1e3 * ma, 1 / ma, 1e3 * mc, mc / ma, 1e3 * ms, ma / ms);
    }
    amps_scene_free(&ctx, S);
    free(fixed0); free(pinned); free(pinval); free(force); free(cp.path); free(t_amps); free(t_chol); free(t_cs);
    return 0;
}
