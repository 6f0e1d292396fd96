/* The haptic model (amps_scene_haptic_build, amps_haptic_eval): after random cuts, pins (also
   on copies), releases and forces, in statics and in dynamics, the model's reactions at random
   pin targets g equal amps_scene_solve_reactions' with the pins moved to g, and the reactions of
   CHOLMOD's solve of the system assembled from scratch (tests/step_ref.h); H is symmetric. Bad
   input: NULL, no pin, a released pin, a two-phase commit in progress, corotational mode. */
#define AMPS_IMPLEMENTATION
#include "amps.h"
#include "amps_test.h"
#include "cholmod_ref.h"
#include "scene_ref.h"
#include "step_ref.h"
#include <string.h>

static double worst_scene = 0, worst_ref = 0, worst_sym = 0;

/* A random node in some tet and not fixed (-1 if none found). */
static amps_int free_node(const amps_mesh *m, const tstate *w) {
    int k;
    for (k = 0; k < 100; k++) {
        amps_int v = t_int((int)m->nnode);
        if (amps_mesh_degree(m, v) > 0 && !w->sh.fixed0[m->origin[v]]) return v;
    }
    return -1;
}

/* Builds the model, then for a few random targets g: eval(g) against the scene's haptic step with
   the pins at g and against the reference. The pins are left at the last g (w follows). */
static void check_model(amps_ctx *ctx, amps_scene *S, tstate *w, amps_haptic *h, const char *what, int it) {
    const amps_mesh *m = amps_scene_mesh(S);
    int nn = (int)m->nnode, np = 0, v, k, d, trial;
    double *g, *re, *rs, *rr, *ur, *wr, scale = 0;
    amps_status s;
    for (v = 0; v < nn; v++) np += w->sh.pinned[v];
    s = amps_scene_haptic_build(ctx, S, h);
    CHECK(s == (np ? AMPS_OK : AMPS_WARN_NOOP) && h->n == np, "%s %d: build %d (%s), %ld of %d pins", what, it, (int)s,
          ctx->msg, (long)h->n, np);
    if (h->n != np || np == 0) return;
    for (k = 0; k < np; k++) {
        CHECK(w->sh.pinned[h->node[k]] && (k == 0 || h->node[k] > h->node[k - 1]) &&
                      amps_haptic_find(h, h->node[k]) == k,
              "%s %d: node list", what, it);
        for (d = 0; d < 3; d++) CHECK(h->g0[3 * k + d] == w->sh.pinval[3 * h->node[k] + d], "%s %d: g0", what, it);
    }
    for (k = 0; k < 9 * np * np; k++) scale = fmax(scale, fabs(h->H[k]));
    for (k = 0; k < 3 * np; k++)
        for (d = 0; d < k; d++) {
            double e = fabs(h->H[(size_t)k * 3 * np + d] - h->H[(size_t)d * 3 * np + k]) / scale;
            worst_sym = fmax(worst_sym, e);
            CHECK(e < 1e-10, "%s %d: H not symmetric (%.2e)", what, it, e);
        }
    g = (double *)malloc(sizeof(double) * 3 * np);
    re = (double *)malloc(sizeof(double) * 3 * np);
    rs = (double *)malloc(sizeof(double) * 3 * np);
    rr = (double *)calloc(3 * nn, sizeof(double));
    ur = (double *)calloc(3 * nn, sizeof(double));
    wr = (double *)calloc(3 * nn, sizeof(double));
    for (trial = 0; trial < 3; trial++) {
        double e1, e2, *rrp = (double *)malloc(sizeof(double) * 3 * np);
        for (k = 0; k < 3 * np; k++) g[k] = h->g0[k] + (trial == 0 ? 0.0 : 0.05 * (t_unif() - 0.5));
        CHECK(amps_haptic_eval(h, g, re) == AMPS_OK, "%s %d: eval", what, it);
        for (k = 0; k < np; k++) {
            v = (int)h->node[k];
            CHECK(amps_scene_pin(ctx, S, v, g + 3 * k) == AMPS_OK, "%s %d: pin: %s", what, it, ctx->msg);
            memcpy(w->sh.pinval + 3 * v, g + 3 * k, sizeof(double) * 3);
        }
        CHECK(amps_scene_solve_reactions(ctx, S) == AMPS_OK, "%s %d: solve_reactions: %s", what, it, ctx->msg);
        for (k = 0; k < np; k++) amps_scene_reaction(ctx, S, h->node[k], rs + 3 * k);
        CHECK(ref_step(ctx, m, w, amps_scene_displacements(S), amps_scene_velocities(S), ur, wr, rr) == 0,
              "%s %d: reference failed", what, it);
        for (k = 0; k < np; k++) memcpy(rrp + 3 * k, rr + 3 * h->node[k], sizeof(double) * 3);
        e1 = t_relerr_floor(3 * np, re, rs, 1e-12);
        e2 = t_relerr_floor(3 * np, re, rrp, 1e-12 + 1e-9 * t_norm(3 * nn, wr));
        worst_scene = fmax(worst_scene, e1);
        worst_ref = fmax(worst_ref, e2);
        CHECK(e1 < 1e-10, "%s %d trial %d: eval vs solve_reactions %.2e", what, it, trial, e1);
        CHECK(e2 < 1e-10, "%s %d trial %d: eval vs CHOLMOD %.2e", what, it, trial, e2);
        free(rrp);
    }
    free(g);
    free(re);
    free(rs);
    free(rr);
    free(ur);
    free(wr);
}

/* Random cuts, pins (also of copies), releases and forces; a model check after each change;
   dyn: implicit dynamics with a step after each check. */
static void random_sequence(const char *what, amps_mesh *m, int nops, unsigned long long seed, int dyn, int dual) {
    amps_ctx ctx;
    amps_scene *S;
    tstate w;
    amps_haptic h;
    amps_scene_opts so;
    int op, v, ncut = 0, npin = 0;
    worst_scene = worst_ref = worst_sym = 0;
    amps_scene_opts_default(&so);
    if (dual) so.update.formulation = AMPS_FORM_DUAL;
    memset(&w, 0, sizeof(w));
    amps_ctx_init(&ctx);
    amps_haptic_init(&h);
    t_seed(seed);
    amps_mesh_set_density(&ctx, m, 1.0);
    w.sh.fixed0 = (unsigned char *)calloc(m->nnode, 1);
    for (v = 0; v < m->nnode; v++) w.sh.fixed0[v] = m->xyz[3 * v + 2] < 0.5;
    shadow_grow(&w.sh, m->nnode);
    S = amps_scene_create(&ctx, m, &so);
    amps_scene_fix_where(&ctx, S, 2, AMPS_LT, 0.5, NULL);
    if (dyn) CHECK(amps_scene_dynamics(&ctx, S, 0.05, 0.1, 0.01) == AMPS_OK, "%s: dynamics: %s", what, ctx.msg);
    w.dyn = dyn;
    w.dt = 0.05;
    w.alpha = 0.1;
    w.beta = 0.01;
    for (op = 0; op < nops; op++) {
        const amps_mesh *mm = amps_scene_mesh(S);
        int kind = t_int(8);
        shadow_grow(&w.sh, mm->nnode + 1);
        if (kind <= 1) { /* cut, the copy pinned at times */
            double p[3], nrm[3] = {t_unif() - 0.5, t_unif() - 0.5, t_unif() - 0.5};
            amps_int vc;
            v = (int)free_node(mm, &w);
            if (v < 0) continue;
            memcpy(p, mm->xyz + 3 * v, sizeof(p));
            if (amps_scene_cut(&ctx, S, v, p, nrm, &vc) == AMPS_OK && vc >= 0) {
                shadow_grow(&w.sh, (int)vc + 1);
                ncut++;
                if (t_int(2)) {
                    double u[3];
                    memcpy(u, amps_scene_displacements(S) + 3 * vc, sizeof(u));
                    if (amps_scene_pin(&ctx, S, vc, u) == AMPS_OK) {
                        w.sh.pinned[vc] = 1;
                        memcpy(w.sh.pinval + 3 * vc, u, sizeof(u));
                        npin++;
                    }
                }
            }
        } else if (kind <= 4) { /* pin near the current displacement */
            v = (int)free_node(mm, &w);
            if (v < 0) continue;
            npin += t_pin_near(&ctx, S, &w.sh, v);
        } else if (kind == 5) { /* release */
            for (v = 0; v < mm->nnode && !w.sh.pinned[v]; v++) {}
            if (v < mm->nnode && amps_scene_release(&ctx, S, v) == AMPS_OK) w.sh.pinned[v] = 0;
        } else { /* force */
            double f[3] = {0.1 * (t_unif() - 0.5), 0.1 * (t_unif() - 0.5), 0.1 * (t_unif() - 0.5)};
            v = (int)free_node(mm, &w);
            if (v < 0) continue;
            amps_scene_force(&ctx, S, v, f);
            memcpy(w.sh.force + 3 * v, f, sizeof(f));
        }
        check_model(&ctx, S, &w, &h, what, op);
        if (dyn) CHECK(amps_scene_step(&ctx, S, 1) == AMPS_OK, "%s %d: step: %s", what, op, ctx.msg);
    }
    printf("%s: %d ops, %d cuts, %d pins, %ld nodes, worst: vs solve_reactions %.1e, vs CHOLMOD %.1e, asymmetry %.1e\n",
           what, nops, ncut, npin, (long)amps_scene_mesh(S)->nnode, worst_scene, worst_ref, worst_sym);
    amps_haptic_free(&ctx, &h);
    amps_scene_free(&ctx, S);
    shadow_free(&w.sh);
}

static void test_bad_input(void) {
    amps_ctx ctx;
    amps_scene *S;
    amps_haptic h;
    double u[3] = {0, 0, 0.01}, r[3], g[3] = {0, 0, 0};
    amps_int top, other;
    amps_ctx_init(&ctx);
    amps_haptic_init(&h);
    S = amps_scene_create(&ctx, amps_mesh_grid(&ctx, 3, 3, 4, 1.0, 1.0, 1.0), NULL);
    amps_scene_fix_where(&ctx, S, 2, AMPS_LT, 0.5, NULL);
    top = 3 * 9 + 4;
    other = 3 * 9 + 0;
    CHECK(amps_scene_haptic_build(&ctx, NULL, &h) == AMPS_ERR_ARG, "NULL scene");
    CHECK(amps_scene_haptic_build(&ctx, S, NULL) == AMPS_ERR_ARG, "NULL model");
    CHECK(amps_haptic_eval(NULL, g, r) == AMPS_ERR_ARG && amps_haptic_eval(&h, g, NULL) == AMPS_ERR_ARG, "eval NULL");
    CHECK(amps_haptic_find(NULL, 0) == -1 && amps_haptic_find(&h, 0) == -1, "find on nothing");
    CHECK(amps_scene_haptic_build(&ctx, S, &h) == AMPS_WARN_NOOP && h.n == 0, "no pin: %s", ctx.msg);
    CHECK(amps_haptic_eval(&h, NULL, r) == AMPS_OK, "eval of an empty model");
    CHECK(amps_scene_pin(&ctx, S, top, u) == AMPS_OK && amps_scene_pin(&ctx, S, other, g) == AMPS_OK, "pins");
    CHECK(amps_scene_haptic_build(&ctx, S, &h) == AMPS_OK && h.n == 2 && h.serial == 2, "build: %s", ctx.msg);
    CHECK(amps_haptic_find(&h, other) == 0 && amps_haptic_find(&h, top) == 1 && amps_haptic_find(&h, 5) == -1, "find");
    {
        double rg[6], rs[3];
        CHECK(amps_haptic_eval(&h, NULL, rg) == AMPS_OK, "eval g NULL");
        amps_scene_reaction(&ctx, S, top, rs);
        CHECK(t_relerr_floor(3, rg + 3, rs, 1e-300) < 1e-12, "r0 is the scene's reaction");
    }
    /* a released pin: the rebuilt model leaves it out */
    CHECK(amps_scene_release(&ctx, S, other) == AMPS_OK, "release");
    CHECK(amps_scene_haptic_build(&ctx, S, &h) == AMPS_OK && h.n == 1 && amps_haptic_find(&h, other) == -1 &&
                  h.node[0] == top,
          "after a release: n %ld", (long)h.n);
    /* a two-phase commit in progress */
    CHECK(amps_scene_begin_batch(&ctx, S) == AMPS_OK && amps_scene_pin(&ctx, S, other, u) == AMPS_OK &&
                  amps_scene_commit_begin(&ctx, S) == AMPS_OK,
          "two-phase begin: %s", ctx.msg);
    CHECK(amps_scene_haptic_build(&ctx, S, &h) == AMPS_ERR_STATE && h.n == 1, "build during a two-phase commit");
    amps_scene_commit_run(S);
    CHECK(amps_scene_commit_end(&ctx, S) == AMPS_OK, "two-phase end: %s", ctx.msg);
    CHECK(amps_scene_haptic_build(&ctx, S, &h) == AMPS_OK && h.n == 2, "after the commit");
    /* corotational mode (test_corot checks its model) */
    CHECK(amps_scene_dynamics(&ctx, S, 0.05, 0.0, 0.0) == AMPS_OK && amps_scene_corotational(&ctx, S, 1) == AMPS_OK,
          "corotational: %s", ctx.msg);
    CHECK(amps_scene_haptic_build(&ctx, S, &h) == AMPS_OK && h.n == 2, "build in corotational mode: %s", ctx.msg);
    amps_haptic_free(&ctx, &h);
    CHECK(h.n == 0 && h.H == NULL, "free");
    amps_haptic_free(&ctx, &h);
    amps_haptic_free(&ctx, NULL);
    amps_scene_free(&ctx, S);
}

int main(void) {
    amps_ctx ctx;
    amps_ctx_init(&ctx);
    test_bad_input();
    random_sequence("statics grid", amps_mesh_grid(&ctx, 4, 4, 6, 1.0, 1.0, 1.0), 40, 11, 0, 0);
    random_sequence("statics grid, dual form", amps_mesh_grid(&ctx, 4, 4, 6, 1.0, 1.0, 1.0), 40, 15, 0, 1);
    random_sequence("statics beam", amps_mesh_beam(&ctx, 8), 30, 12, 0, 0);
    random_sequence("dynamics grid", amps_mesh_grid(&ctx, 4, 4, 6, 1.0, 1.0, 1.0), 40, 13, 1, 0);
    random_sequence("dynamics grid, dual form", amps_mesh_grid(&ctx, 4, 4, 6, 1.0, 1.0, 1.0), 30, 16, 1, 1);
    random_sequence("dynamics beam", amps_mesh_beam(&ctx, 8), 30, 14, 1, 0);
    return amps_t_end("test_haptic");
}
