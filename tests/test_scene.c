/* FEM scene: after any sequence of cuts, pins, releases and forces the node displacements equal
   CHOLMOD's solution of the cut mesh assembled from scratch (fixed nodes eliminated, pins
   moved to the right-hand side); cuts of pinned, fixed and copied nodes; a cut that detaches a
   piece is undone; changes before the factorization; bad arguments. */
#define AMPS_IMPLEMENTATION
#include "amps.h"
#include "amps_test.h"
#include "cholmod_ref.h"
#include <string.h>

/* What the test knows independently of the scene. */
typedef struct shadow {
    unsigned char *fixed0;   /* fixed flag of the file nodes */
    unsigned char *pinned;   /* per node */
    double *pinval, *force;  /* 3 per node */
    int cap;
    int *watch, nwatch;      /* watched nodes (copies of watched nodes are watched) */
} shadow;

static void shadow_grow(shadow *w, int n) {
    if (n <= w->cap) return;
    w->pinned = (unsigned char *)realloc(w->pinned, n);
    w->pinval = (double *)realloc(w->pinval, sizeof(double) * 3 * n);
    w->force = (double *)realloc(w->force, sizeof(double) * 3 * n);
    memset(w->pinned + w->cap, 0, n - w->cap);
    memset(w->pinval + 3 * w->cap, 0, sizeof(double) * 3 * (n - w->cap));
    memset(w->force + 3 * w->cap, 0, sizeof(double) * 3 * (n - w->cap));
    w->cap = n;
}

/* Reference displacements (3 per node) of the current mesh by CHOLMOD; returns its residual. */
static double reference(amps_ctx *ctx, const amps_mesh *m, const shadow *w, double *u) {
    int nn = m->nnode, v, d, n, nf = 0, k, *map;
    unsigned char *fixed = (unsigned char *)malloc(nn);
    amps_int *dof = (amps_int *)malloc(sizeof(amps_int) * 3 * nn);
    amps_csc *K, *R;
    double *rhs, *x, res = -1, num = 0, den = 0;
    int *ti, *tj, nz = 0, j, p;
    double *tx;
    for (v = 0; v < nn; v++) fixed[v] = w->fixed0[m->origin[v]];
    n = (int)amps_mesh_number_dofs(m, fixed, dof);
    K = amps_mesh_assemble(ctx, m, dof, n);
    map = (int *)malloc(sizeof(int) * (n + 1));
    for (k = 0; k < n; k++) map[k] = 0;
    for (v = 0; v < nn; v++) if (w->pinned[v]) for (d = 0; d < 3; d++) map[dof[3 * v + d]] = -1;
    for (k = 0; k < n; k++) map[k] = map[k] < 0 ? -1 : nf++;
    rhs = (double *)calloc(nf + 1, sizeof(double)); x = (double *)calloc(nf + 1, sizeof(double));
    {   /* full vector of pinned values */
        double *gv = (double *)calloc(n + 1, sizeof(double));
        for (v = 0; v < nn; v++) for (d = 0; d < 3; d++) {
            int e = dof[3 * v + d];
            if (e < 0) continue;
            if (w->pinned[v]) gv[e] = w->pinval[3 * v + d];
            else rhs[map[e]] = w->force[3 * v + d];
        }
        ti = (int *)malloc(sizeof(int) * (K->p[n] + 1)); tj = (int *)malloc(sizeof(int) * (K->p[n] + 1)); tx = (double *)malloc(sizeof(double) * (K->p[n] + 1));
        for (j = 0; j < n; j++)
            for (p = K->p[j]; p < K->p[j + 1]; p++) {
                int i = K->i[p];
                double val = K->x[p];
                if (map[i] >= 0 && map[j] >= 0) { ti[nz] = map[i]; tj[nz] = map[j]; tx[nz] = val; nz++; }
                else if (map[i] >= 0) rhs[map[i]] -= val * gv[j];
                else if (map[j] >= 0 && i != j) rhs[map[j]] -= val * gv[i];
            }
        R = amps_csc_from_triplets(ctx, nf, nz, ti, tj, tx, AMPS_UPPER);
        if (R && ref_solve(nf, R->p, R->i, R->x, NULL, 0, rhs, x) == 0) {
            double *y = (double *)calloc(nf + 1, sizeof(double));
            amps_csc_symv(R, AMPS_UPPER, x, y);
            for (k = 0; k < nf; k++) { num += (y[k] - rhs[k]) * (y[k] - rhs[k]); den += rhs[k] * rhs[k]; }
            res = den > 0 ? sqrt(num / den) : sqrt(num);
            free(y);
        }
        for (v = 0; v < nn; v++) for (d = 0; d < 3; d++) {
            int e = dof[3 * v + d];
            u[3 * v + d] = e < 0 ? 0.0 : (map[e] < 0 ? gv[e] : x[map[e]]);
        }
        free(gv); free(ti); free(tj); free(tx);
        amps_csc_free(ctx, R);
    }
    amps_csc_free(ctx, K);
    free(fixed); free(dof); free(map); free(rhs); free(x);
    return res;
}

static double worst_err = 0, worst_res = 0;

static void compare(amps_ctx *ctx, amps_scene *S, const shadow *w, const char *what, int step) {
    const amps_mesh *m = amps_scene_mesh(S);
    double *u = (double *)malloc(sizeof(double) * 3 * m->nnode), err, res, rref;
    double *rf = (double *)malloc(sizeof(double) * 3 * m->nnode), *uw = (double *)malloc(sizeof(double) * 3 * (w->nwatch + 1));
    amps_status s;
    int k, d;
    /* the haptic path (reactions from the dense system) and the watched solve, before the full solve */
    CHECK(amps_scene_solve_forces(ctx, S) == AMPS_OK, "%s step %d: forces-only solve: %s", what, step, ctx->msg);
    for (k = 0; k < m->nnode; k++) amps_scene_reaction(ctx, S, k, rf + 3 * k);
    CHECK(amps_scene_solve_watched(ctx, S) == AMPS_OK, "%s step %d: watched solve: %s", what, step, ctx->msg);
    for (k = 0; k < w->nwatch; k++) memcpy(uw + 3 * k, amps_scene_displacements(S) + 3 * w->watch[k], 3 * sizeof(double));
    s = amps_scene_solve(ctx, S);
    CHECK(s == AMPS_OK, "%s step %d: solve: %s", what, step, ctx->msg);
    rref = reference(ctx, m, w, u);
    err = t_reldiff(3 * m->nnode, amps_scene_displacements(S), u);
    CHECK(err <= 1e-10, "%s step %d: relative error %.3e", what, step, err);
    if (amps_scene_residual(ctx, S, &res) == AMPS_OK) {
        CHECK(res <= 10 * rref + 1e-14, "%s step %d: residual %.3e vs CHOLMOD %.3e", what, step, res, rref);
        if (res > worst_res) worst_res = res;
    }
    if (err > worst_err) worst_err = err;
    {   /* deformed positions = reference + displacement, all nodes and a subset */
        double *pos = (double *)malloc(sizeof(double) * 3 * m->nnode), q[3];
        amps_int last = m->nnode - 1;
        CHECK(amps_scene_positions(ctx, S, 0, NULL, pos) == AMPS_OK, "positions");
        CHECK(pos[3 * last + 2] == m->xyz[3 * last + 2] + amps_scene_displacements(S)[3 * last + 2], "%s: position of the last node", what);
        CHECK(amps_scene_positions(ctx, S, 1, &last, q) == AMPS_OK && q[0] == pos[3 * last] && q[2] == pos[3 * last + 2], "%s: subset positions", what);
        last = m->nnode;
        CHECK(amps_scene_positions(ctx, S, 1, &last, q) == AMPS_ERR_INDEX, "%s: position out of range accepted", what);
        free(pos);
    }
    {   /* reactions at pins: nonzero somewhere when a pin moves the model */
        amps_int v;
        for (v = 0; v < m->nnode; v++) {
            double r[3];
            amps_scene_reaction(ctx, S, v, r);
            if (!w->pinned[v]) CHECK(r[0] == 0 && r[1] == 0 && r[2] == 0, "%s: reaction at unpinned node %ld", what, (long)v);
            for (d = 0; d < 3; d++)
                CHECK(fabs(r[d] - rf[3 * v + d]) <= 1e-8 * (1 + fabs(r[d])), "%s step %d: reaction at node %ld: forces-only %.6e vs full %.6e",
                      what, step, (long)v, rf[3 * v + d], r[d]);
        }
    }
    {
        double un = t_norm(3 * m->nnode, amps_scene_displacements(S));
        for (k = 0; k < w->nwatch; k++)
            for (d = 0; d < 3; d++)
                CHECK(fabs(uw[3 * k + d] - amps_scene_displacements(S)[3 * w->watch[k] + d]) <= 1e-10 * un,
                      "%s step %d: watched node %d: %.6e vs full %.6e", what, step, w->watch[k], uw[3 * k + d],
                      amps_scene_displacements(S)[3 * w->watch[k] + d]);
    }
    free(u); free(rf); free(uw);
}

/* Random cuts (random planes through nodes, copies included), pins (new, moved, released, on
   copies), forces; fixed nodes cut too. */
static void random_scene(amps_mesh *m0, int fix_axis, double fix_below, int steps, unsigned long long seed, int before, const char *what) {
    amps_ctx ctx;
    amps_scene *S;
    shadow w;
    int st, v, ncut = 0;
    amps_ctx_init(&ctx);
    memset(&w, 0, sizeof(w));
    t_seed(seed);
    w.fixed0 = (unsigned char *)calloc(m0->nnode, 1);
    for (v = 0; v < m0->nnode; v++) w.fixed0[v] = m0->xyz[3 * v + fix_axis] < fix_below;
    S = amps_scene_create(&ctx, m0, NULL);
    CHECK(S != NULL, "create: %s", ctx.msg);
    amps_scene_set_material(&ctx, S, 1000.0, 0.3);
    CHECK(amps_scene_fix_where(&ctx, S, fix_axis, AMPS_LT, fix_below, NULL) == AMPS_OK, "fix");
    shadow_grow(&w, m0->nnode);
    w.watch = (int *)malloc(sizeof(int) * (m0->nnode + steps));
    {
        amps_int *wl = (amps_int *)malloc(sizeof(amps_int) * m0->nnode);
        for (v = 0; v < m0->nnode; v += 5) { w.watch[w.nwatch] = v; wl[w.nwatch++] = v; }
        CHECK(amps_scene_watch(&ctx, S, w.nwatch, wl) == AMPS_OK, "watch: %s", ctx.msg);
        v = m0->nnode; CHECK(amps_scene_watch(&ctx, S, 1, &v) == AMPS_ERR_INDEX, "watch out of range accepted");
        free(wl);
    }
    for (st = 0; st < steps; st++) {
        const amps_mesh *m = amps_scene_mesh(S);
        int op = t_int(10), nn = m->nnode;
        v = t_int(nn);
        if (op < 4) {
            double p[3], nrm[3];
            amps_int vc;
            amps_status s;
            int d;
            for (d = 0; d < 3; d++) { p[d] = m->xyz[3 * v + d]; nrm[d] = t_unif() - 0.5; }
            s = amps_scene_cut(&ctx, S, v, p, nrm, &vc);
            CHECK(s == AMPS_OK || s == AMPS_WARN_NOOP || s == AMPS_ERR_SINGULAR_UPDATE, "%s: cut: %s", what, ctx.msg);
            if (s == AMPS_OK) {
                int k, nw = w.nwatch;
                shadow_grow(&w, (int)vc + 1); ncut++; CHECK(vc == nn, "copy index %ld vs %d", (long)vc, nn);
                for (k = 0; k < nw; k++) if (w.watch[k] == v) w.watch[w.nwatch++] = (int)vc;
            }
            if (s == AMPS_ERR_SINGULAR_UPDATE) CHECK(amps_scene_mesh(S)->nnode == nn, "%s: detached cut not undone", what);
        } else if (op < 6) {
            double u[3];
            int d;
            for (d = 0; d < 3; d++) u[d] = 0.02 * (t_unif() - 0.5);
            if (w.fixed0[m->origin[v]]) {
                CHECK(amps_scene_pin(&ctx, S, v, u) == AMPS_ERR_ARG, "%s: pinning a fixed node accepted", what);
            } else if (amps_mesh_degree(m, v) > 0) {
                CHECK(amps_scene_pin(&ctx, S, v, u) == AMPS_OK, "%s: pin: %s", what, ctx.msg);
                w.pinned[v] = 1; memcpy(w.pinval + 3 * v, u, sizeof(u));
            }
        } else if (op == 6) {
            amps_status s = amps_scene_release(&ctx, S, v);
            CHECK(s == AMPS_OK || s == AMPS_ERR_SINGULAR_UPDATE, "%s: release: %s", what, ctx.msg);
            if (s == AMPS_OK) w.pinned[v] = 0;
        } else {
            double f[3];
            int d;
            for (d = 0; d < 3; d++) f[d] = t_unif() - 0.5;
            CHECK(amps_scene_force(&ctx, S, v, f) == AMPS_OK, "%s: force: %s", what, ctx.msg);
            memcpy(w.force + 3 * v, f, sizeof(f));
        }
        if (st >= before && (t_int(2) || st == steps - 1)) compare(&ctx, S, &w, what, st);
    }
    CHECK(ncut > steps / 8, "%s: only %d cuts", what, ncut);
    printf("  %-22s steps %d, cuts %d, nodes %ld, worst error %.2e, worst residual %.2e\n", what, steps, ncut,
           (long)amps_scene_mesh(S)->nnode, worst_err, worst_res);
    amps_scene_free(&ctx, S);
    free(w.fixed0); free(w.pinned); free(w.pinval); free(w.force); free(w.watch);
}

/* Two stacked cells held at the bottom: cutting the middle layer along z = 1 detaches the top. */
static void test_detach(void) {
    amps_ctx ctx;
    amps_mesh *m;
    amps_scene *S;
    amps_int v[4] = {4, 5, 6, 7}, vc;
    double nrm[3] = {0, 0, 1}, f[3] = {0.1, 0, 0}, *u0;
    int k, singular = 0, nn;
    amps_ctx_init(&ctx);
    m = amps_mesh_grid(&ctx, 2, 2, 3, 1.0, 1.0, 1.0);
    S = amps_scene_create(&ctx, m, NULL);
    amps_scene_fix_where(&ctx, S, 2, AMPS_LT, 0.5, NULL);
    amps_scene_force(&ctx, S, 10, f);
    CHECK(amps_scene_solve(&ctx, S) == AMPS_OK, "detach: first solve: %s", ctx.msg);
    u0 = (double *)malloc(sizeof(double) * 3 * 12);
    for (k = 0; k < 4; k++) {
        double p[3];
        amps_status s;
        nn = (int)amps_scene_mesh(S)->nnode;
        memcpy(p, amps_scene_mesh(S)->xyz + 3 * v[k], sizeof(p));
        memcpy(u0, amps_scene_displacements(S), sizeof(double) * 3 * 12);
        s = amps_scene_cut(&ctx, S, v[k], p, nrm, &vc);
        if (s == AMPS_ERR_SINGULAR_UPDATE) {
            singular = 1;
            CHECK(strstr(ctx.msg, "held by nothing") != NULL, "detach message: %s", ctx.msg);
            CHECK(amps_scene_mesh(S)->nnode == nn, "detach: node count not restored");
            CHECK(amps_mesh_check(&ctx, amps_scene_mesh(S)) == AMPS_OK, "detach: mesh invariants: %s", ctx.msg);
            CHECK(amps_scene_solve(&ctx, S) == AMPS_OK, "detach: solve after undo: %s", ctx.msg);
            CHECK(t_reldiff(3 * 12, amps_scene_displacements(S), u0) < 1e-12, "detach: solution changed");
            break;
        }
        CHECK(s == AMPS_OK, "detach cut %d: %s", k, ctx.msg);
        CHECK(amps_scene_solve(&ctx, S) == AMPS_OK, "detach solve: %s", ctx.msg);
    }
    CHECK(singular, "cutting the middle layer never detached the top cell");
    free(u0);
    amps_scene_free(&ctx, S);
}

static void test_args(void) {
    amps_ctx ctx;
    amps_scene *S;
    double z[3] = {0, 0, 0}, nan3[3] = {NAN, 0, 0}, nrm0[3] = {0, 0, 0};
    amps_int vc;
    amps_ctx_init(&ctx);
    S = amps_scene_create(&ctx, amps_mesh_beam(&ctx, 4), NULL);
    CHECK(amps_scene_fix_where(&ctx, S, 5, AMPS_LT, 0.5, NULL) == AMPS_ERR_ARG, "bad axis accepted");
    amps_scene_fix_where(&ctx, S, 2, AMPS_LT, 0.5, NULL);
    CHECK(amps_scene_pin(&ctx, S, 0, z) == AMPS_ERR_ARG, "pin of a fixed node accepted");
    CHECK(amps_scene_pin(&ctx, S, 1000, z) == AMPS_ERR_INDEX, "pin out of range accepted");
    CHECK(amps_scene_force(&ctx, S, 60, nan3) == AMPS_ERR_VALUE, "NaN force accepted");
    CHECK(amps_scene_cut(&ctx, S, 60, z, nrm0, &vc) == AMPS_ERR_ARG, "zero normal accepted");
    CHECK(amps_scene_solve(&ctx, S) == AMPS_OK, "solve: %s", ctx.msg);
    CHECK(amps_scene_set_material(&ctx, S, 1, 0.3) == AMPS_ERR_STATE, "material after factorization accepted");
    CHECK(amps_scene_fix_where(&ctx, S, 2, AMPS_LT, 0.5, NULL) == AMPS_ERR_STATE, "fix after factorization accepted");
    amps_scene_free(&ctx, S);
    /* nothing fixed: not positive definite */
    S = amps_scene_create(&ctx, amps_mesh_beam(&ctx, 3), NULL);
    CHECK(amps_scene_solve(&ctx, S) == AMPS_ERR_NOT_SPD, "free-floating model accepted: %s", ctx.msg);
    amps_scene_free(&ctx, S);
}

int main(void) {
    amps_ctx ctx;
    amps_ctx_init(&ctx);
    test_args();
    test_detach();
    random_scene(amps_mesh_beam(&ctx, 8), 2, 0.5, 120, 11, 0, "beam 5x5x8");
    random_scene(amps_mesh_brick(&ctx, 3), 2, 1e-9, 120, 12, 0, "brick R=3");
    random_scene(amps_mesh_brick(&ctx, 3), 0, 1e-9, 80, 13, 20, "brick, late factor");
    return amps_t_end("test_scene");
}
