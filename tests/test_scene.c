/* FEM scene: after any sequence of cuts, pins, releases and forces the node displacements equal
   CHOLMOD's solution of the cut mesh assembled from scratch (fixed nodes eliminated, pins
   moved to the right-hand side); cuts of pinned, fixed and copied nodes; a cut that detaches a
   piece is undone, and so is one that leaves a piece turning about a line of nodes; changes
   before the factorization; bad arguments. */
#define AMPS_IMPLEMENTATION
#include "amps.h"
#include "amps_test.h"
#include "cholmod_ref.h"
#include "scene_ref.h"
#include <string.h>

static double worst_err = 0, worst_res = 0;

static void compare(amps_ctx *ctx, amps_scene *S, const shadow *w, const char *what, int step) {
    const amps_mesh *m = amps_scene_mesh(S);
    double *u = (double *)malloc(sizeof(double) * 3 * m->nnode), err, res, rref;
    double *rf = (double *)malloc(sizeof(double) * 3 * m->nnode),
           *uw = (double *)malloc(sizeof(double) * 3 * (w->nwatch + 1));
    amps_status s;
    int k, d;
    /* the haptic path (reactions from the dense system) and the watched solve, before the full solve */
    CHECK(amps_scene_solve_reactions(ctx, S) == AMPS_OK, "%s step %d: forces-only solve: %s", what, step, ctx->msg);
    for (k = 0; k < m->nnode; k++) amps_scene_reaction(ctx, S, k, rf + 3 * k);
    CHECK(amps_scene_solve_watched(ctx, S) == AMPS_OK, "%s step %d: watched solve: %s", what, step, ctx->msg);
    for (k = 0; k < w->nwatch; k++)
        memcpy(uw + 3 * k, amps_scene_displacements(S) + 3 * w->watch[k], 3 * sizeof(double));
    s = amps_scene_solve(ctx, S);
    CHECK(s == AMPS_OK, "%s step %d: solve: %s", what, step, ctx->msg);
    rref = scene_reference(ctx, m, w, 0, NULL, u, NULL, 0);
    err = t_reldiff(3 * m->nnode, amps_scene_displacements(S), u);
    CHECK(err <= 1e-10, "%s step %d: relative error %.3e", what, step, err);
    if (amps_scene_residual(ctx, S, &res) == AMPS_OK) {
        CHECK(res <= 10 * rref + 1e-14, "%s step %d: residual %.3e vs CHOLMOD %.3e", what, step, res, rref);
        if (res > worst_res) worst_res = res;
    }
    if (err > worst_err) worst_err = err;
    { /* a watched solve after a full one (the watch set given again) leaves the full x: the next
         full solve returns the same bits */
        double *u1 = (double *)malloc(sizeof(double) * 3 * m->nnode);
        amps_int *wl = (amps_int *)malloc(sizeof(amps_int) * (w->nwatch + 1));
        for (k = 0; k < w->nwatch; k++) wl[k] = w->watch[k];
        memcpy(u1, amps_scene_displacements(S), sizeof(double) * 3 * m->nnode);
        CHECK(amps_scene_watch(ctx, S, w->nwatch, wl) == AMPS_OK, "%s: watch again: %s", what, ctx->msg);
        CHECK(amps_scene_solve_watched(ctx, S) == AMPS_OK, "%s step %d: watched solve after a full one: %s", what, step,
              ctx->msg);
        CHECK(amps_scene_solve(ctx, S) == AMPS_OK, "%s step %d: solve again: %s", what, step, ctx->msg);
        CHECK(memcmp(u1, amps_scene_displacements(S), sizeof(double) * 3 * m->nnode) == 0,
              "%s step %d: a full solve after a watched one changed the full solve's values", what, step);
        free(u1);
        free(wl);
    }
    { /* deformed positions = reference + displacement, all nodes and a subset */
        double *pos = (double *)malloc(sizeof(double) * 3 * m->nnode), q[3];
        amps_int last = m->nnode - 1;
        CHECK(amps_scene_positions(ctx, S, 0, NULL, pos) == AMPS_OK, "positions");
        CHECK(pos[3 * last + 2] == m->xyz[3 * last + 2] + amps_scene_displacements(S)[3 * last + 2],
              "%s: position of the last node", what);
        CHECK(amps_scene_positions(ctx, S, 1, &last, q) == AMPS_OK && q[0] == pos[3 * last] &&
                      q[2] == pos[3 * last + 2],
              "%s: subset positions", what);
        last = m->nnode;
        CHECK(amps_scene_positions(ctx, S, 1, &last, q) == AMPS_ERR_INDEX, "%s: position out of range accepted", what);
        free(pos);
    }
    { /* reactions at pins: nonzero somewhere when a pin moves the model */
        amps_int v;
        for (v = 0; v < m->nnode; v++) {
            double r[3];
            amps_scene_reaction(ctx, S, v, r);
            if (!w->pinned[v])
                CHECK(r[0] == 0 && r[1] == 0 && r[2] == 0, "%s: reaction at unpinned node %ld", what, (long)v);
            for (d = 0; d < 3; d++)
                CHECK(fabs(r[d] - rf[3 * v + d]) <= 1e-8 * (1 + fabs(r[d])),
                      "%s step %d: reaction at node %ld: forces-only %.6e vs full %.6e", what, step, (long)v,
                      rf[3 * v + d], r[d]);
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
    free(u);
    free(rf);
    free(uw);
}

/* Random cuts (random planes through nodes, copies included), pins (new, moved, released, on
   copies), forces; fixed nodes cut too. */
static void random_scene(amps_mesh *m0, int fix_axis, double fix_below, int steps, unsigned long long seed, int before,
                         const char *what) {
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
        for (v = 0; v < m0->nnode; v += 5) {
            w.watch[w.nwatch] = v;
            wl[w.nwatch++] = v;
        }
        CHECK(amps_scene_watch(&ctx, S, w.nwatch, wl) == AMPS_OK, "watch: %s", ctx.msg);
        v = m0->nnode;
        CHECK(amps_scene_watch(&ctx, S, 1, &v) == AMPS_ERR_INDEX, "watch out of range accepted");
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
            for (d = 0; d < 3; d++) {
                p[d] = m->xyz[3 * v + d];
                nrm[d] = t_unif() - 0.5;
            }
            s = amps_scene_cut(&ctx, S, v, p, nrm, &vc);
            CHECK(s == AMPS_OK || s == AMPS_WARN_NOOP || s == AMPS_ERR_SINGULAR_UPDATE, "%s: cut: %s", what, ctx.msg);
            if (s == AMPS_OK) {
                int k, nw = w.nwatch;
                shadow_grow(&w, (int)vc + 1);
                ncut++;
                CHECK(vc == nn, "copy index %ld vs %d", (long)vc, nn);
                for (k = 0; k < nw; k++)
                    if (w.watch[k] == v) w.watch[w.nwatch++] = (int)vc;
            }
            if (s == AMPS_ERR_SINGULAR_UPDATE)
                CHECK(amps_scene_mesh(S)->nnode == nn, "%s: detached cut not undone", what);
        } else if (op < 6) {
            double u[3];
            int d;
            for (d = 0; d < 3; d++) u[d] = 0.02 * (t_unif() - 0.5);
            if (w.fixed0[m->origin[v]]) {
                CHECK(amps_scene_pin(&ctx, S, v, u) == AMPS_ERR_ARG, "%s: pinning a fixed node accepted", what);
            } else if (amps_mesh_degree(m, v) > 0) {
                CHECK(amps_scene_pin(&ctx, S, v, u) == AMPS_OK, "%s: pin: %s", what, ctx.msg);
                w.pinned[v] = 1;
                memcpy(w.pinval + 3 * v, u, sizeof(u));
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
    free(w.watch);
    shadow_free(&w);
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
            CHECK(strstr(ctx.msg, "held by nothing") != NULL || strstr(ctx.msg, "on one line") != NULL,
                  "detach message: %s", ctx.msg);
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

/* An ill-conditioned beam (2 x 2 x 101 nodes, E 1 and 1e6 by halves, nu 0.4999, clamped at
   z = 0, tip forces): a legal cut whose dense pivot falls below singular_tol (cond(K^) about
   1e16) is committed by a re-factorization, not refused; the residual stays within 10x of
   CHOLMOD's, and the displacements agree as far as the conditioning lets two backward-stable
   solves agree. */
static void test_illcond(void) {
    amps_ctx ctx;
    amps_mesh *m;
    amps_scene *S;
    shadow w;
    amps_int t, v = 1 + 2 * (0 + 2 * 26), vc, q;
    double f[3] = {1e-3, 0.5e-3, -1e-3}, nrm[3] = {0, 0.3, 1}, p[3], *u, res, rref, err;
    amps_update_stats st;
    int a;
    amps_ctx_init(&ctx);
    memset(&w, 0, sizeof(w));
    m = amps_mesh_grid(&ctx, 2, 2, 101, 1, 1, 1);
    for (t = 0; t < m->ntet; t++) {
        double zc = 0;
        for (a = 0; a < 4; a++) zc += 0.25 * m->xyz[3 * m->tet[4 * t + a] + 2];
        amps_mesh_set_tet_material(&ctx, m, t, zc < 50.0 ? 1.0 : 1e6, 0.4999);
    }
    w.fixed0 = (unsigned char *)calloc(m->nnode, 1);
    for (q = 0; q < m->nnode; q++) w.fixed0[q] = m->xyz[3 * q + 2] < 1e-9;
    shadow_grow(&w, m->nnode + 1);
    memcpy(p, m->xyz + 3 * v, sizeof(p));
    S = amps_scene_create(&ctx, m, NULL);
    CHECK(S && amps_scene_fix_where(&ctx, S, 2, AMPS_LT, 1e-9, NULL) == AMPS_OK, "illcond: create: %s", ctx.msg);
    for (q = 0; q < 4; q++) {
        amps_scene_force(&ctx, S, 4 * 100 + q, f);
        memcpy(w.force + 3 * (4 * 100 + q), f, sizeof(f));
    }
    CHECK(amps_scene_solve(&ctx, S) == AMPS_OK, "illcond: solve: %s", ctx.msg);
    CHECK(amps_scene_cut(&ctx, S, v, p, nrm, &vc) == AMPS_OK, "illcond: a legal cut refused: %s", ctx.msg);
    amps_update_get_stats(amps_scene_engine(S), &st);
    CHECK(st.pivot_folds >= 1, "illcond: the cut's dense pivot passed (the test is moot)");
    CHECK(amps_scene_solve(&ctx, S) == AMPS_OK, "illcond: solve after the cut: %s", ctx.msg);
    m = (amps_mesh *)amps_scene_mesh(S);
    u = (double *)malloc(sizeof(double) * 3 * m->nnode);
    rref = scene_reference(&ctx, m, &w, 0, NULL, u, NULL, 0);
    err = t_reldiff(3 * m->nnode, amps_scene_displacements(S), u);
    CHECK(amps_scene_residual(&ctx, S, &res) == AMPS_OK && res <= 10 * rref + 1e-14,
          "illcond: residual %.3e vs CHOLMOD %.3e", res, rref);
    CHECK(err <= 1e-2, "illcond: relative difference from CHOLMOD %.3e", err);
    printf("  ill-conditioned beam cut: residual %.2e (CHOLMOD %.2e), difference from CHOLMOD %.2e\n", res, rref, err);
    free(u);
    shadow_free(&w);
    amps_scene_free(&ctx, S);
}

/* 1 if the grid points (integer coordinates) are all on one line. */
static int grid_collinear(int n, const int (*p)[3]) {
    int a, b = -1, k, d;
    if (n <= 1) return 1;
    for (k = 1; k < n && b < 0; k++)
        if (p[k][0] != p[0][0] || p[k][1] != p[0][1] || p[k][2] != p[0][2]) b = k;
    if (b < 0) return 1;
    for (a = 1; a < n; a++) {
        long u[3], w[3], c[3];
        for (d = 0; d < 3; d++) {
            u[d] = p[b][d] - p[0][d];
            w[d] = p[a][d] - p[0][d];
        }
        c[0] = u[1] * w[2] - u[2] * w[1];
        c[1] = u[2] * w[0] - u[0] * w[2];
        c[2] = u[0] * w[1] - u[1] * w[0];
        if (c[0] || c[1] || c[2]) return 0;
    }
    return 1;
}

/* Mechanisms: a 4 x 4 x 5 node grid fixed at the bottom, its layer z = 2 cut node by node
   (serpentine order). The top block then hangs on the uncut nodes of that layer and on its
   pins (npin of the top nodes, pinned at 0), so a cut must be refused exactly when those
   points are on one line (a hinge, a ball joint, nothing); a refused cut leaves the scene as it
   was, an accepted one a system with a small residual. With stray, the mesh also has a node in
   no tet far away (1e11), which must not change the test's line tolerance. */
static void test_mechanism(int npin, const int *pins, int stray) {
    amps_ctx ctx;
    amps_mesh *m;
    amps_scene *S;
    double nrm[3] = {0, 0, 1}, f[3] = {0.3, -0.2, 0.1}, zero[3] = {0, 0, 0}, *u0;
    int uncut[16], k, i, nref = 0, nacc = 0, nn;
    amps_ctx_init(&ctx);
    m = amps_mesh_grid(&ctx, 4, 4, 5, 1.0, 1.0, 1.0);
    if (stray) {
        double *xyz = (double *)malloc(sizeof(double) * 3 * (m->nnode + 1));
        amps_mesh *m2;
        memcpy(xyz, m->xyz, sizeof(double) * 3 * m->nnode);
        xyz[3 * m->nnode] = 1e11;
        xyz[3 * m->nnode + 1] = xyz[3 * m->nnode + 2] = 0;
        m2 = amps_mesh_create(&ctx, m->nnode + 1, xyz, m->ntet, m->tet);
        CHECK(m2 != NULL, "mechanism: mesh with a stray node: %s", ctx.msg);
        amps_mesh_free(&ctx, m);
        free(xyz);
        m = m2;
    }
    S = amps_scene_create(&ctx, m, NULL);
    amps_scene_fix_where(&ctx, S, 2, AMPS_LT, 0.5, NULL);
    amps_scene_force(&ctx, S, 4 * 4 * 4 + 5, f);
    for (k = 0; k < npin; k++) amps_scene_pin(&ctx, S, pins[k], zero);
    CHECK(amps_scene_solve(&ctx, S) == AMPS_OK, "mechanism: first solve: %s", ctx.msg);
    u0 = (double *)malloc(sizeof(double) * 3 * (81 + 16));
    for (k = 0; k < 16; k++) uncut[k] = 1;
    for (k = 0; k < 16; k++) {
        int row = k / 4, col = row % 2 ? 3 - k % 4 : k % 4, v = col + 4 * (row + 4 * 2), npt = 0, expect;
        int pt[20][3];
        double p[3], res = -1;
        amps_int vc;
        amps_status s;
        uncut[row * 4 + col] = 0;
        for (i = 0; i < 16; i++)
            if (uncut[i]) {
                pt[npt][0] = i % 4;
                pt[npt][1] = i / 4;
                pt[npt][2] = 2;
                npt++;
            }
        for (i = 0; i < npin; i++) {
            pt[npt][0] = pins[i] % 4;
            pt[npt][1] = (pins[i] / 4) % 4;
            pt[npt][2] = pins[i] / 16;
            npt++;
        }
        expect = grid_collinear(npt, (const int(*)[3])pt);
        nn = (int)amps_scene_mesh(S)->nnode;
        memcpy(u0, amps_scene_displacements(S), sizeof(double) * 3 * (size_t)nn);
        memcpy(p, amps_scene_mesh(S)->xyz + 3 * v, sizeof(p));
        s = amps_scene_cut(&ctx, S, v, p, nrm, &vc);
        if (expect) {
            CHECK(s == AMPS_ERR_SINGULAR_UPDATE,
                  "mechanism (%d pins): cut %d of node %d accepted (%s), leaving the top loose", npin, k, v, ctx.msg);
            if (s != AMPS_ERR_SINGULAR_UPDATE) break;
            nref++;
            uncut[row * 4 + col] = 1;
            CHECK(strstr(ctx.msg, "on one line") != NULL || strstr(ctx.msg, "held by nothing") != NULL,
                  "mechanism message: %s", ctx.msg);
            CHECK(amps_scene_mesh(S)->nnode == nn, "mechanism: node count not restored");
            CHECK(amps_mesh_check(&ctx, amps_scene_mesh(S)) == AMPS_OK, "mechanism: mesh invariants: %s", ctx.msg);
            CHECK(amps_scene_solve(&ctx, S) == AMPS_OK, "mechanism: solve after undo: %s", ctx.msg);
            CHECK(t_reldiff(3 * nn, amps_scene_displacements(S), u0) < 1e-12,
                  "mechanism: a refused cut changed the solution");
        } else {
            CHECK(s == AMPS_OK, "mechanism (%d pins): cut %d of node %d refused: %s", npin, k, v, ctx.msg);
            if (s != AMPS_OK) break;
            nacc++;
            CHECK(amps_scene_solve(&ctx, S) == AMPS_OK, "mechanism: solve: %s", ctx.msg);
            CHECK(amps_scene_residual(&ctx, S, &res) == AMPS_OK && res <= 1e-9,
                  "mechanism (%d pins): cut %d: residual %.2e", npin, k, res);
        }
    }
    printf("  mechanism, %d pins on the top%s: %d cuts accepted, %d refused\n", npin, stray ? ", a stray node" : "",
           nacc, nref);
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
    CHECK(amps_scene_set_material(&ctx, S, 1, 0.3) == AMPS_OK, "material after factorization (an update): %s", ctx.msg);
    CHECK(amps_scene_set_material(&ctx, S, -1, 0.3) == AMPS_ERR_ARG, "negative E after factorization accepted");
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
    test_illcond();
    {
        static const int pins1[1] = {4 * 16 + 5}, pins2[2] = {4 * 16 + 0, 4 * 16 + 15},
                         pins3[3] = {4 * 16 + 0, 4 * 16 + 3, 4 * 16 + 12};
        test_mechanism(0, NULL, 0);
        test_mechanism(1, pins1, 0);
        test_mechanism(2, pins2, 0);
        test_mechanism(3, pins3, 0);
        test_mechanism(2, pins2, 1);
    }
    random_scene(amps_mesh_beam(&ctx, 8), 2, 0.5, 120, 11, 0, "beam 5x5x8");
    random_scene(amps_mesh_brick(&ctx, 3), 2, 1e-9, 120, 12, 0, "brick R=3");
    random_scene(amps_mesh_brick(&ctx, 3), 0, 1e-9, 80, 13, 20, "brick, late factor");
    return amps_t_end("test_scene");
}
