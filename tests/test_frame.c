/* The frame loop's calls: a blade stroke equals the same node cuts one by one (and the nodes it
   touches are those near the polyline); batches of cuts, pins, releases and forces committed
   once equal the same changes committed one by one, and a failing batch is undone; both against
   CHOLMOD on the cut mesh assembled from scratch. The re-factorization: the deterministic COUNT
   mode gives identical bits on two identical runs; the haptic path (solve_reactions) never swaps
   a ready re-factorization in; AUTO starts one after growth with only watched and reaction solves. */
#define AMPS_IMPLEMENTATION
#include "amps.h"
#include "amps_test.h"
#include "cholmod_ref.h"
#include "scene_ref.h"
#include <string.h>

/* The scene's displacements against CHOLMOD's of its current mesh (shadow w). */
static double ref_err(amps_ctx *ctx, amps_scene *S, const shadow *w) {
    const amps_mesh *m = amps_scene_mesh(S);
    double *u = (double *)malloc(sizeof(double) * 3 * m->nnode), err;
    scene_reference(ctx, m, w, 0, NULL, u, NULL, 0);
    err = t_reldiff(3 * (int)m->nnode, amps_scene_displacements(S), u);
    free(u);
    return err;
}

/* A beam 5 x 5 x h fixed below z = 0.5, pulled at its top by a pin and pushed by a force. */
static amps_scene *beam_scene(amps_ctx *ctx, int h, shadow *w, const amps_scene_opts *so) {
    amps_mesh *m = amps_mesh_beam(ctx, h);
    amps_scene *S;
    amps_int v, top = 25 * (h - 1) + 12;
    double u[3] = {0.05, 0.02, 0}, f[3] = {0, 0.3, 0.1};
    memset(w, 0, sizeof(*w));
    w->fixed0 = (unsigned char *)calloc(m->nnode, 1);
    for (v = 0; v < m->nnode; v++) w->fixed0[v] = m->xyz[3 * v + 2] < 0.5;
    shadow_grow(w, (int)m->nnode);
    S = amps_scene_create(ctx, m, so);
    CHECK(S != NULL, "create: %s", ctx->msg);
    amps_scene_set_material(ctx, S, 1000.0, 0.3);
    amps_scene_fix_where(ctx, S, 2, AMPS_LT, 0.5, NULL);
    CHECK(amps_scene_pin(ctx, S, top, u) == AMPS_OK, "pin: %s", ctx->msg);
    w->pinned[top] = 1;
    memcpy(w->pinval + 3 * top, u, sizeof(u));
    CHECK(amps_scene_force(ctx, S, top - 2, f) == AMPS_OK, "force: %s", ctx->msg);
    memcpy(w->force + 3 * (top - 2), f, sizeof(f));
    CHECK(amps_scene_prepare(ctx, S) == AMPS_OK, "prepare: %s", ctx->msg);
    return S;
}

/* Point k of frame fr's stroke: a curve through the beam's interior, blade along y. */
static void stroke_point(int fr, int k, double p[3]) {
    double s = 0.7 * fr + 0.35 * k;
    p[0] = 2.0 + 0.9 * sin(0.8 * s);
    p[1] = 2.0 + 0.3 * cos(1.3 * s);
    p[2] = 3.0 + s;
}

static void test_stroke(void) {
    amps_ctx ctx;
    amps_scene *A, *B;
    shadow wa, wb;
    double blade[3] = {0, 1, 0.2};
    int fr, total = 0, skipped = 0;
    amps_ctx_init(&ctx);
    A = beam_scene(&ctx, 16, &wa, NULL);
    B = beam_scene(&ctx, 16, &wb, NULL);
    for (fr = 0; fr < 12; fr++) {
        double pts[9], nrm[6];
        amps_int node[64], copy[64], i, nn = amps_scene_mesh(A)->nnode, near = 0, v;
        amps_status st[64];
        amps_scene_stroke_result r;
        int k, seg;
        for (k = 0; k < 3; k++) stroke_point(fr, k, pts + 3 * k);
        for (seg = 0; seg < 2; seg++) { /* the test's own planes: (p1 - p0) x blade */
            const double *p = pts + 3 * seg, *q = p + 3;
            double d[3] = {q[0] - p[0], q[1] - p[1], q[2] - p[2]}, *c = nrm + 3 * seg, l;
            c[0] = d[1] * blade[2] - d[2] * blade[1];
            c[1] = d[2] * blade[0] - d[0] * blade[2];
            c[2] = d[0] * blade[1] - d[1] * blade[0];
            l = sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2]);
            for (k = 0; k < 3; k++) c[k] /= l;
        }
        { /* the touched nodes are those near the polyline: brute force */
            amps_int got[256], ng = amps_scene_nodes_near_segment(&ctx, A, pts, pts + 3, 0.6, got, 256), j;
            int ok = ng >= 0;
            for (v = 0, j = 0; v < nn && ok; v++) {
                double t, d2 = amps__seg_dist2(amps_scene_mesh(A)->xyz + 3 * v, pts, pts + 3, &t);
                if (d2 <= 0.36 && amps_mesh_degree(amps_scene_mesh(A), v) > 0) ok = j < ng && got[j++] == v;
            }
            CHECK(ok && j == ng, "frame %d: nodes near the segment differ from brute force", fr);
        }
        memset(&r, 0, sizeof(r));
        r.cap = 64;
        r.node = node;
        r.copy = copy;
        r.status = st;
        CHECK(amps_scene_stroke(&ctx, A, 3, pts, blade, 0.6, &r) == AMPS_OK, "frame %d: stroke: %s", fr, ctx.msg);
        CHECK(r.n <= 64, "frame %d: %ld nodes touched", fr, (long)r.n);
        for (v = 0; v < nn; v++) {
            double t0, t1;
            if (amps_mesh_degree(amps_scene_mesh(B), v) == 0) continue;
            if (amps__seg_dist2(amps_scene_mesh(B)->xyz + 3 * v, pts, pts + 3, &t0) <= 0.36 ||
                amps__seg_dist2(amps_scene_mesh(B)->xyz + 3 * v, pts + 3, pts + 6, &t1) <= 0.36)
                near++;
        }
        CHECK(near == r.n, "frame %d: stroke touched %ld nodes, %ld are near", fr, (long)r.n, (long)near);
        /* the same cuts one by one on B, each by the plane of its nearest segment */
        for (i = 0; i < r.n && i < 64; i++) {
            double t, d0 = amps__seg_dist2(amps_scene_mesh(B)->xyz + 3 * node[i], pts, pts + 3, &t),
                      d1 = amps__seg_dist2(amps_scene_mesh(B)->xyz + 3 * node[i], pts + 3, pts + 6, &t);
            int sg = d1 < d0;
            amps_int vc = -1;
            amps_status s = amps_scene_cut(&ctx, B, node[i], pts + 3 * sg, nrm + 3 * sg, &vc);
            CHECK(s == st[i] && vc == copy[i], "frame %d: node %ld: stroke %d/%ld, one by one %d/%ld", fr,
                  (long)node[i], (int)st[i], (long)copy[i], (int)s, (long)vc);
            if (s == AMPS_OK) {
                shadow_grow(&wa, (int)vc + 1);
                shadow_grow(&wb, (int)vc + 1);
            } else skipped++;
        }
        total += (int)r.ncut;
        CHECK(amps_scene_mesh(A)->nnode == amps_scene_mesh(B)->nnode, "frame %d: node counts differ", fr);
        CHECK(amps_scene_solve(&ctx, A) == AMPS_OK && amps_scene_solve(&ctx, B) == AMPS_OK, "frame %d: solve: %s", fr,
              ctx.msg);
        {
            amps_int n3 = 3 * amps_scene_mesh(A)->nnode;
            double e = t_reldiff((int)n3, amps_scene_displacements(A), amps_scene_displacements(B)), ea;
            CHECK(e <= 1e-11, "frame %d: stroke vs one by one %.3e", fr, e);
            ea = ref_err(&ctx, A, &wa);
            CHECK(ea <= 1e-10, "frame %d: stroke vs CHOLMOD %.3e", fr, ea);
        }
    }
    CHECK(total >= 12, "strokes cut only %d nodes", total);
    printf("  stroke: 12 frames, %d nodes cut, %d skipped (no-op or refused)\n", total, skipped);
    {
        double bad[6] = {0, 0, 0, 0, 1, 0};
        CHECK(amps_scene_stroke(&ctx, A, 2, bad, blade + 0, 0.5, NULL) == AMPS_ERR_ARG ||
                      amps_scene_stroke(&ctx, A, 2, bad, blade, 0.5, NULL) == AMPS_OK,
              "stroke along the blade");
        bad[5] = 0;
        bad[4] = 0;
        CHECK(amps_scene_stroke(&ctx, A, 2, bad, blade, 0.5, NULL) == AMPS_ERR_ARG, "zero-length stroke accepted");
        CHECK(amps_scene_stroke(&ctx, A, 1, bad, blade, 0.5, NULL) == AMPS_ERR_ARG, "one-point stroke accepted");
        CHECK(amps_scene_nodes_near_segment(&ctx, A, bad, bad, -1, NULL, 0) == AMPS_ERR_VALUE,
              "negative radius accepted");
    }
    amps_scene_free(&ctx, A);
    amps_scene_free(&ctx, B);
    shadow_free(&wa);
    shadow_free(&wb);
}

static void log_fallback(void *user, amps_status s, const char *msg) {
    (void)s;
    if (strstr(msg, "one commit each")) *(int *)user = 1;
}

/* A stroke on a brick fixed at its base whose one commit is singular (a corner piece the
   per-node test does not see is cut loose): its cuts are made again one commit each, the ones
   that leave a piece loose refused; the same as cutting the nodes one by one, and CHOLMOD's. */
static void test_stroke_loose(void) {
    amps_ctx ctx;
    amps_scene *S[2];
    shadow w;
    double pts[6] = {0.9136962890625, 0.78021240234375,    1.514923095703125,
                     1.110107421875,  0.39134521484374996, 1.852581787109375},
           blade[3] = {-0.0635528564453125, 0.005157470703125, 0.4960479736328125}, f[3] = {0.1, 0.2, -0.3};
    amps_int node[64], copy[64], i, v;
    amps_status st[64];
    amps_scene_stroke_result r;
    int k, fell = 0, refused = 0;
    amps_ctx_init(&ctx);
    memset(&w, 0, sizeof(w));
    for (k = 0; k < 2; k++) {
        amps_mesh *m = amps_mesh_brick(&ctx, 3);
        if (k == 0) {
            w.fixed0 = (unsigned char *)calloc(m->nnode, 1);
            for (v = 0; v < m->nnode; v++) w.fixed0[v] = m->xyz[3 * v + 2] < 0.01;
            shadow_grow(&w, (int)m->nnode);
            memcpy(w.force + 3 * (m->nnode - 1), f, sizeof(f));
        }
        S[k] = amps_scene_create(&ctx, m, NULL);
        CHECK(S[k] != NULL, "create: %s", ctx.msg);
        amps_scene_set_material(&ctx, S[k], 1000.0, 0.3);
        amps_scene_fix_where(&ctx, S[k], 2, AMPS_LT, 0.01, NULL);
        CHECK(amps_scene_force(&ctx, S[k], m->nnode - 1, f) == AMPS_OK, "force: %s", ctx.msg);
        CHECK(amps_scene_prepare(&ctx, S[k]) == AMPS_OK, "prepare: %s", ctx.msg);
    }
    memset(&r, 0, sizeof(r));
    r.cap = 64;
    r.node = node;
    r.copy = copy;
    r.status = st;
    ctx.log = log_fallback;
    ctx.log_user = &fell;
    CHECK(amps_scene_stroke(&ctx, S[0], 2, pts, blade, 0.43419189453125001, &r) == AMPS_OK, "loose stroke: %s",
          ctx.msg);
    ctx.log = NULL;
    CHECK(fell, "the stroke's one commit was not singular (the test lost its case)");
    for (i = 0; i < r.n && i < 64; i++) { /* the same cuts on S[1], each committed alone */
        amps_int vc = -1;
        double nrm[3] = {(pts[4] - pts[1]) * blade[2] - (pts[5] - pts[2]) * blade[1],
                         (pts[5] - pts[2]) * blade[0] - (pts[3] - pts[0]) * blade[2],
                         (pts[3] - pts[0]) * blade[1] - (pts[4] - pts[1]) * blade[0]};
        amps_status s = amps_scene_cut(&ctx, S[1], node[i], pts, nrm, &vc);
        CHECK(s == st[i] && vc == copy[i], "loose stroke: node %ld: stroke %d/%ld, one by one %d/%ld", (long)node[i],
              (int)st[i], (long)copy[i], (int)s, (long)vc);
        refused += st[i] == AMPS_ERR_SINGULAR_UPDATE;
        if (s == AMPS_OK) shadow_grow(&w, (int)vc + 1);
    }
    CHECK(refused > 0 && r.ncut > 0, "loose stroke: %d refused, %ld cut", refused, (long)r.ncut);
    CHECK(amps_scene_solve(&ctx, S[0]) == AMPS_OK && amps_scene_solve(&ctx, S[1]) == AMPS_OK, "loose stroke: solve: %s",
          ctx.msg);
    CHECK(t_reldiff(3 * (int)amps_scene_mesh(S[0])->nnode, amps_scene_displacements(S[0]),
                    amps_scene_displacements(S[1])) <= 1e-12,
          "loose stroke vs one by one");
    CHECK(ref_err(&ctx, S[0], &w) <= 1e-10, "loose stroke vs CHOLMOD %.3e", ref_err(&ctx, S[0], &w));
    printf("  stroke with a singular commit: %ld nodes touched, %ld cut, %d refused\n", (long)r.n, (long)r.ncut,
           refused);
    amps_scene_free(&ctx, S[0]);
    amps_scene_free(&ctx, S[1]);
    shadow_free(&w);
}

/* A dynamic scene during a two-phase commit: steps, its haptic step, gravity and a new
   amps_scene_dynamics are refused and change nothing; after the end the steps equal a scene
   committed in one phase. */
static void test_two_phase_dynamics(void) {
    amps_ctx ctx;
    amps_scene *S[2];
    shadow w[2];
    double g[3] = {0, 0, -1}, p[3];
    amps_int vc, tet;
    int k;
    amps_ctx_init(&ctx);
    for (k = 0; k < 2; k++) {
        S[k] = beam_scene(&ctx, 6, w + k, NULL);
        CHECK(amps_scene_dynamics(&ctx, S[k], 0.05, 0.1, 0.02) == AMPS_OK && amps_scene_step(&ctx, S[k], 2) == AMPS_OK,
              "dynamics: %s", ctx.msg);
        memcpy(p, amps_scene_mesh(S[k])->xyz + 3 * 87, sizeof(p));
        CHECK(amps_scene_begin_batch(&ctx, S[k]) == AMPS_OK && amps_scene_cut(&ctx, S[k], 87, p, g, &vc) == AMPS_OK,
              "batch: %s", ctx.msg);
    }
    CHECK(amps_scene_commit(&ctx, S[1]) == AMPS_OK, "one-phase commit: %s", ctx.msg);
    CHECK(amps_scene_commit_begin(&ctx, S[0]) == AMPS_OK, "commit_begin: %s", ctx.msg);
    CHECK(amps_scene_step(&ctx, S[0], 1) == AMPS_ERR_STATE, "a step during a two-phase commit");
    CHECK(amps_scene_solve_reactions(&ctx, S[0]) == AMPS_ERR_STATE, "a dynamic haptic step during a two-phase commit");
    CHECK(amps_scene_gravity(&ctx, S[0], g) == AMPS_ERR_STATE, "gravity during a two-phase commit");
    CHECK(amps_scene_dynamics(&ctx, S[0], 0.1, 0.1, 0.02) == AMPS_ERR_STATE, "dynamics during a two-phase commit");
    CHECK(amps_scene_commit(&ctx, S[0]) == AMPS_ERR_STATE, "amps_scene_commit during a two-phase commit");
    tet = 5;
    CHECK(amps_scene_remove(&ctx, S[0], 1, &tet, AMPS_SINGULAR_REMOVE, NULL) == AMPS_ERR_STATE &&
                  amps_scene_set_tet_material(&ctx, S[0], tet, 2.0, 0.3) == AMPS_ERR_STATE,
          "a removal or a material change during a two-phase commit");
    amps_scene_commit_run(S[0]);
    CHECK(amps_scene_commit_end(&ctx, S[0]) == AMPS_OK, "commit_end: %s", ctx.msg);
    /* a batch of a cut, a removal and material changes: two phases on S[0], one on S[1] */
    memcpy(p, amps_scene_mesh(S[0])->xyz + 3 * 60, sizeof(p));
    for (k = 0; k < 2; k++) {
        amps_int t2 = 40;
        CHECK(amps_scene_begin_batch(&ctx, S[k]) == AMPS_OK && amps_scene_cut(&ctx, S[k], 60, p, g, &vc) == AMPS_OK,
              "second batch: %s", ctx.msg);
        CHECK(amps_scene_remove(&ctx, S[k], 1, &tet, AMPS_SINGULAR_REMOVE, NULL) == AMPS_OK &&
                      amps_scene_set_tet_material(&ctx, S[k], t2, 2.0, 0.3) == AMPS_OK &&
                      amps_scene_set_region(&ctx, S[k], 0, 0.7, 0.25, 1.3) == AMPS_OK,
              "a removal or a material change in an open batch: %s", ctx.msg);
    }
    CHECK(amps_scene_commit(&ctx, S[1]) == AMPS_OK, "second one-phase commit: %s", ctx.msg);
    CHECK(amps_scene_commit_begin(&ctx, S[0]) == AMPS_OK, "second commit_begin: %s", ctx.msg);
    amps_scene_commit_run(S[0]);
    CHECK(amps_scene_commit_end(&ctx, S[0]) == AMPS_OK, "second commit_end: %s", ctx.msg);
    for (k = 0; k < 2; k++) CHECK(amps_scene_step(&ctx, S[k], 3) == AMPS_OK, "steps after the commit: %s", ctx.msg);
    CHECK(amps_scene_begin_batch(&ctx, S[0]) == AMPS_OK, "a batch after the step: %s", ctx.msg);
    CHECK(amps_scene_commit(&ctx, S[0]) == AMPS_OK, "an empty batch: %s", ctx.msg);
    CHECK(amps_scene_mesh(S[0])->nnode == amps_scene_mesh(S[1])->nnode &&
                  t_reldiff(3 * (int)amps_scene_mesh(S[0])->nnode, amps_scene_displacements(S[0]),
                            amps_scene_displacements(S[1])) <= 1e-13,
          "two-phase commit in dynamics differs from one phase");
    for (k = 0; k < 2; k++) {
        amps_scene_free(&ctx, S[k]);
        shadow_free(w + k);
    }
}

/* A scene's first two-phase commit that only releases a pin (no new position; under UBSan the
   empty list of new positions must not reach qsort) equals the release done at once. */
static void test_two_phase_release(void) {
    amps_ctx ctx;
    amps_scene *S[2];
    shadow w[2];
    amps_int top = 25 * 3 + 12;
    int k;
    amps_ctx_init(&ctx);
    for (k = 0; k < 2; k++) {
        S[k] = beam_scene(&ctx, 4, w + k, NULL);
        CHECK(amps_scene_dynamics(&ctx, S[k], 0.05, 0.1, 0.01) == AMPS_OK && amps_scene_step(&ctx, S[k], 1) == AMPS_OK,
              "release: dynamics: %s", ctx.msg);
    }
    CHECK(amps_scene_begin_batch(&ctx, S[0]) == AMPS_OK && amps_scene_release(&ctx, S[0], top) == AMPS_OK &&
                  amps_scene_commit_begin(&ctx, S[0]) == AMPS_OK,
          "release: two phases: %s", ctx.msg);
    amps_scene_commit_run(S[0]);
    CHECK(amps_scene_commit_end(&ctx, S[0]) == AMPS_OK, "release: commit_end: %s", ctx.msg);
    CHECK(amps_scene_release(&ctx, S[1], top) == AMPS_OK, "release: %s", ctx.msg);
    for (k = 0; k < 2; k++) CHECK(amps_scene_step(&ctx, S[k], 2) == AMPS_OK, "release: steps: %s", ctx.msg);
    CHECK(t_reldiff(3 * (int)amps_scene_mesh(S[0])->nnode, amps_scene_displacements(S[0]),
                    amps_scene_displacements(S[1])) <= 1e-13,
          "release: two phases differ from one");
    for (k = 0; k < 2; k++) {
        amps_scene_free(&ctx, S[k]);
        shadow_free(w + k);
    }
}

/* Stroke edge cases: a polyline that folds back on itself (every node as near to both segments,
   to rounding) reports what its first segment alone reports; a blade of length 1e160 or 1e-170
   is a direction like any other; a point beyond 1e150 is AMPS_ERR_VALUE; before the
   factorization a stroke changes the topology only (the scene can still be fixed). */
static void test_stroke_edges(void) {
    amps_ctx ctx;
    amps_scene *S;
    amps_int nd[2][64], nn0;
    amps_scene_stroke_result r[2];
    double p[9] = {0.25, 0.25, 1, 0.5, 0.25, 1.75, 0.25, 0.25, 1}, bl[3] = {0, 1, 0};
    int q;
    amps_ctx_init(&ctx);
    for (q = 0; q < 2; q++) {
        S = amps_scene_create(&ctx, amps_mesh_brick(&ctx, 4), NULL);
        amps_scene_fix_where(&ctx, S, 2, AMPS_LT, 0.01, NULL);
        CHECK(amps_scene_prepare(&ctx, S) == AMPS_OK, "stroke edges: prepare: %s", ctx.msg);
        memset(r + q, 0, sizeof(r[q]));
        r[q].cap = 64;
        r[q].node = nd[q];
        CHECK(amps_scene_stroke(&ctx, S, q ? 2 : 3, p, bl, 0.0905, r + q) == AMPS_OK, "stroke edges: %s", ctx.msg);
        amps_scene_free(&ctx, S);
    }
    CHECK(r[0].n == r[1].n && r[0].n > 0 && memcmp(nd[0], nd[1], sizeof(amps_int) * (size_t)r[0].n) == 0,
          "a folded-back stroke differs from its first segment (%ld against %ld nodes)", (long)r[0].n, (long)r[1].n);
    S = amps_scene_create(&ctx, amps_mesh_brick(&ctx, 4), NULL);
    nn0 = amps_scene_mesh(S)->nnode;
    for (q = 0; q < 2; q++) { /* unprepared: topology only */
        double big[3] = {0, q ? 1e-170 : 1e160, 0};
        CHECK(amps_scene_stroke(&ctx, S, 2, p, big, 0.0905, NULL) == AMPS_OK, "stroke with blade %g: %s", big[1],
              ctx.msg);
    }
    CHECK(amps_scene_mesh(S)->nnode > nn0 && amps_scene_engine(S) == NULL &&
                  amps_scene_fix_where(&ctx, S, 2, AMPS_LT, 0.01, NULL) == AMPS_OK,
          "a stroke before the factorization factored the scene: %s", ctx.msg);
    p[0] = 1e151;
    CHECK(amps_scene_stroke(&ctx, S, 2, p, bl, 0.5, NULL) == AMPS_ERR_VALUE, "a stroke point beyond 1e150 accepted");
    CHECK(amps_scene_solve(&ctx, S) == AMPS_OK, "stroke edges: solve: %s", ctx.msg);
    amps_scene_free(&ctx, S);
}

/* Random changes, in batches of 1-6 on A and one by one on B. */
static void test_batches(unsigned long long seed) {
    amps_ctx ctx;
    amps_scene *A, *B;
    shadow wa, wb;
    int round, ncut = 0;
    amps_ctx_init(&ctx);
    A = beam_scene(&ctx, 10, &wa, NULL);
    B = beam_scene(&ctx, 10, &wb, NULL);
    t_seed(seed);
    for (round = 0; round < 14; round++) {
        int nb = 1 + t_int(6), k;
        CHECK(amps_scene_begin_batch(&ctx, A) == AMPS_OK, "begin batch: %s", ctx.msg);
        CHECK(amps_scene_begin_batch(&ctx, A) == AMPS_ERR_STATE, "nested batch accepted");
        for (k = 0; k < nb; k++) {
            const amps_mesh *m = amps_scene_mesh(A);
            amps_int v = t_int((int)m->nnode), vca = -1, vcb = -1;
            int op = t_int(8), d;
            if (op < 4) {
                double p[3], nrm[3];
                amps_status sa, sb;
                for (d = 0; d < 3; d++) {
                    p[d] = m->xyz[3 * v + d];
                    nrm[d] = t_unif() - 0.5;
                }
                sa = amps_scene_cut(&ctx, A, v, p, nrm, &vca);
                sb = amps_scene_cut(&ctx, B, v, p, nrm, &vcb);
                CHECK(sa == sb && vca == vcb, "batch cut of %ld: %d vs %d", (long)v, (int)sa, (int)sb);
                if (sa == AMPS_OK) {
                    ncut++;
                    shadow_grow(&wa, (int)vca + 1);
                }
            } else if (op < 6) {
                double u[3];
                for (d = 0; d < 3; d++) u[d] = 0.02 * (t_unif() - 0.5);
                if (wa.fixed0[m->origin[v]] || amps_mesh_degree(m, v) == 0) continue;
                CHECK(amps_scene_pin(&ctx, A, v, u) == AMPS_OK && amps_scene_pin(&ctx, B, v, u) == AMPS_OK, "pin: %s",
                      ctx.msg);
                wa.pinned[v] = 1;
                memcpy(wa.pinval + 3 * v, u, sizeof(u));
            } else if (op == 6) {
                if (!wa.pinned[v] || t_int(2)) continue;
                CHECK(amps_scene_release(&ctx, A, v) == AMPS_OK && amps_scene_release(&ctx, B, v) == AMPS_OK,
                      "release: %s", ctx.msg);
                wa.pinned[v] = 0;
            } else {
                double f[3];
                for (d = 0; d < 3; d++) f[d] = t_unif() - 0.5;
                amps_scene_force(&ctx, A, v, f);
                amps_scene_force(&ctx, B, v, f);
                memcpy(wa.force + 3 * v, f, sizeof(f));
            }
        }
        CHECK(amps_scene_commit(&ctx, A) == AMPS_OK, "batch commit: %s", ctx.msg);
        CHECK(amps_scene_solve_watched(&ctx, A) == AMPS_OK && amps_scene_solve(&ctx, A) == AMPS_OK &&
                      amps_scene_solve(&ctx, B) == AMPS_OK,
              "solve: %s", ctx.msg);
        {
            double e = t_reldiff(3 * (int)amps_scene_mesh(A)->nnode, amps_scene_displacements(A),
                                 amps_scene_displacements(B)),
                   ea = ref_err(&ctx, A, &wa);
            CHECK(e <= 1e-11, "round %d: batched vs one by one %.3e", round, e);
            CHECK(ea <= 1e-10, "round %d: batched vs CHOLMOD %.3e", round, ea);
        }
    }
    CHECK(ncut >= 5, "batches: only %d cuts", ncut);
    amps_scene_free(&ctx, A);
    amps_scene_free(&ctx, B);
    shadow_free(&wa);
    shadow_free(&wb);
}

/* The scene's boundary triangles (the change record's) against amps_mesh_boundary from scratch. */
static void boundary_check(amps_ctx *ctx, amps_scene *S, const char *what) {
    const amps_int *tri, *face;
    amps_int nid = amps_scene_boundary(S, &tri, &face), live = 0, bad = 0, i;
    amps_int nb = amps_mesh_boundary(ctx, amps_scene_mesh(S), NULL, NULL);
    amps_int *sf = (amps_int *)malloc(sizeof(amps_int) * (size_t)(3 * nb + nb + 1));
    amps_mesh_boundary(ctx, amps_scene_mesh(S), sf, sf + 3 * nb);
    for (i = 0; i < nid; i++) {
        amps_int j;
        if (face[i] < 0) continue;
        live++;
        for (j = 0; j < nb && sf[3 * nb + j] != face[i]; j++) {}
        bad += j == nb || memcmp(sf + 3 * j, tri + 3 * i, 3 * sizeof(amps_int)) != 0;
    }
    CHECK(live == nb && bad == 0, "%s: boundary %ld triangles (%ld not from scratch), %ld from scratch", what,
          (long)live, (long)bad, (long)nb);
    free(sf);
}

static void *dup(const void *p, size_t n) {
    void *q = malloc(n ? n : 1);
    if (n) memcpy(q, p, n);
    return q;
}

/* A copy of the mesh arrays a batch's undo must restore bit for bit. */
typedef struct mesh_copy {
    amps_int nnode, nremoved, *tet, *inc_ptr, *inc_len, *inc;
    unsigned char *removed;
    double *E, *nu, *rho;
} mesh_copy;

static void mesh_copy_take(const amps_mesh *m, mesh_copy *c) {
    amps_int v, n = 0;
    c->nnode = m->nnode;
    c->nremoved = m->nremoved;
    c->tet = (amps_int *)dup(m->tet, sizeof(amps_int) * 4 * (size_t)m->ntet);
    c->inc_ptr = (amps_int *)dup(m->inc_ptr, sizeof(amps_int) * (size_t)m->nnode);
    c->inc_len = (amps_int *)dup(m->inc_len, sizeof(amps_int) * (size_t)m->nnode);
    for (v = 0; v < m->nnode; v++) n += m->inc_len[v];
    c->inc = (amps_int *)malloc(sizeof(amps_int) * (size_t)(n + 1));
    for (v = 0, n = 0; v < m->nnode; n += m->inc_len[v], v++)
        memcpy(c->inc + n, m->inc + m->inc_ptr[v], sizeof(amps_int) * (size_t)m->inc_len[v]);
    c->removed = (unsigned char *)dup(m->removed, (size_t)m->ntet);
    c->E = (double *)dup(m->E, sizeof(double) * (size_t)m->ntet);
    c->nu = (double *)dup(m->nu, sizeof(double) * (size_t)m->ntet);
    c->rho = m->rho ? (double *)dup(m->rho, sizeof(double) * (size_t)m->ntet) : NULL;
}

/* 1 if m is the mesh copied in c (a NULL rho copy: every density 1). */
static int mesh_copy_same(const amps_mesh *m, const mesh_copy *c) {
    amps_int v, t, n = 0;
    int same = m->nnode == c->nnode && m->nremoved == c->nremoved &&
               !memcmp(m->tet, c->tet, sizeof(amps_int) * 4 * (size_t)m->ntet) &&
               !memcmp(m->removed, c->removed, (size_t)m->ntet) &&
               !memcmp(m->E, c->E, sizeof(double) * (size_t)m->ntet) &&
               !memcmp(m->nu, c->nu, sizeof(double) * (size_t)m->ntet);
    for (t = 0; same && t < m->ntet; t++) same = (m->rho ? m->rho[t] : 1.0) == (c->rho ? c->rho[t] : 1.0);
    for (v = 0; same && v < m->nnode; n += m->inc_len[v], v++)
        same = m->inc_ptr[v] == c->inc_ptr[v] && m->inc_len[v] == c->inc_len[v] &&
               !memcmp(c->inc + n, m->inc + m->inc_ptr[v], sizeof(amps_int) * (size_t)m->inc_len[v]);
    return same;
}

static void mesh_copy_free(mesh_copy *c) {
    free(c->tet);
    free(c->inc_ptr);
    free(c->inc_len);
    free(c->inc);
    free(c->removed);
    free(c->E);
    free(c->nu);
    free(c->rho);
}

/* Under gravity, a batch of removals (one with a separation), region and tet materials with
   densities, a cut and pins, cancelled (amps_scene_cancel_batch): the mesh as before bit for bit, the boundary as
   from scratch, and the next solve or steps equal those of a twin scene that never had the
   batch. The same batch committed equals the changes made one by one. (Undone by a failed
   commit: test_alloc_update.) */
static void test_batch_cancel(void) {
    int dyn, how;
    for (dyn = 0; dyn < 2; dyn++)
        for (how = 0; how < 2; how++) {
            amps_ctx ctx;
            amps_scene *S[2];
            shadow w[2];
            mesh_copy mc;
            amps_scene_changes ch;
            amps_mesh_removal rr;
            amps_int sep[3] = {118, 120, 148}, one = 40, vc, k, nn, nsep = 0;
            double p[3], nrm[3] = {0.2, 1, 0.1}, u[3] = {0.01, 0, 0.02}, e, grav[3] = {0, 0.1, -0.5};
            amps_status st = AMPS_OK;
            amps_ctx_init(&ctx);
            for (k = 0; k < 2; k++) {
                S[k] = beam_scene(&ctx, 6, w + k, NULL);
                CHECK(amps_scene_gravity(&ctx, S[k], grav) == AMPS_OK, "cancel: gravity: %s", ctx.msg);
                if (dyn)
                    CHECK(amps_scene_dynamics(&ctx, S[k], 0.05, 0.1, 0.02) == AMPS_OK &&
                                  amps_scene_step(&ctx, S[k], 2) == AMPS_OK,
                          "cancel: dynamics: %s", ctx.msg);
                else CHECK(amps_scene_solve(&ctx, S[k]) == AMPS_OK, "cancel: solve: %s", ctx.msg);
                CHECK(amps_scene_take_changes(&ctx, S[k], &ch) == AMPS_OK, "cancel: take: %s", ctx.msg);
            }
            mesh_copy_take(amps_scene_mesh(S[0]), &mc);
            nn = amps_scene_mesh(S[0])->nnode;
            for (k = 0; k < 2; k++) {
                if (k == 1 && how == 0) break; /* the twin stays as it was */
                CHECK(amps_scene_begin_batch(&ctx, S[k]) == AMPS_OK, "cancel: begin: %s", ctx.msg);
                st = amps_scene_pin(&ctx, S[k], 130, u);
                if (!st) st = amps_scene_remove(&ctx, S[k], 3, sep, AMPS_SINGULAR_SEPARATE, &rr);
                if (!st) nsep = rr.nsep;
                memcpy(p, amps_scene_mesh(S[k])->xyz + 3 * 87, sizeof(p));
                if (!st) st = amps_scene_cut(&ctx, S[k], 87, p, nrm, &vc);
                if (!st) st = amps_scene_set_region(&ctx, S[k], 0, 800.0, 0.31, 1.7);
                if (!st) st = amps_scene_set_tet_material(&ctx, S[k], 7, 2000.0, 0.28);
                if (!st) st = amps_scene_remove(&ctx, S[k], 1, &one, AMPS_SINGULAR_REMOVE, NULL);
                if (!st) st = amps_scene_pin(&ctx, S[k], 80, u);
                CHECK(st == AMPS_OK && nsep > 0 && amps_scene_mesh(S[k])->nnode > nn,
                      "cancel: the batch's changes: %s (%ld separations)", ctx.msg, (long)nsep);
                if (how == 0) CHECK(amps_scene_cancel_batch(&ctx, S[k]) == AMPS_OK, "cancel: %s", ctx.msg);
                else if (k == 0) {
                    CHECK(amps_scene_commit(&ctx, S[k]) == AMPS_OK, "commit: %s", ctx.msg);
                    CHECK(amps_scene_cancel_batch(&ctx, S[k]) == AMPS_ERR_STATE, "a cancel after the commit");
                } else { /* the twin made the same changes one by one */
                    CHECK(amps_scene_cancel_batch(&ctx, S[k]) == AMPS_OK, "cancel the twin: %s", ctx.msg);
                    CHECK(amps_scene_pin(&ctx, S[k], 130, u) == AMPS_OK &&
                                  amps_scene_remove(&ctx, S[k], 3, sep, AMPS_SINGULAR_SEPARATE, NULL) == AMPS_OK &&
                                  amps_scene_cut(&ctx, S[k], 87, p, nrm, &vc) == AMPS_OK &&
                                  amps_scene_set_region(&ctx, S[k], 0, 800.0, 0.31, 1.7) == AMPS_OK &&
                                  amps_scene_set_tet_material(&ctx, S[k], 7, 2000.0, 0.28) == AMPS_OK &&
                                  amps_scene_remove(&ctx, S[k], 1, &one, AMPS_SINGULAR_REMOVE, NULL) == AMPS_OK &&
                                  amps_scene_pin(&ctx, S[k], 80, u) == AMPS_OK,
                          "one by one: %s", ctx.msg);
                }
            }
            if (how == 0) /* undone: bit for bit */
                CHECK(mesh_copy_same(amps_scene_mesh(S[0]), &mc) &&
                              amps_mesh_check(&ctx, amps_scene_mesh(S[0])) == AMPS_OK,
                      "cancel (dyn %d, how %d): the mesh differs from the one before the batch", dyn, how);
            CHECK(amps_scene_take_changes(&ctx, S[0], &ch) == AMPS_OK, "cancel: take: %s", ctx.msg);
            boundary_check(&ctx, S[0], "cancel");
            for (k = 0; k < 2; k++)
                CHECK((dyn ? amps_scene_step(&ctx, S[k], 3) : amps_scene_solve(&ctx, S[k])) == AMPS_OK,
                      "cancel: after: %s", ctx.msg);
            e = t_reldiff(3 * (int)amps_scene_mesh(S[1])->nnode, amps_scene_displacements(S[0]),
                          amps_scene_displacements(S[1]));
            CHECK(amps_scene_mesh(S[0])->nnode == amps_scene_mesh(S[1])->nnode && e <= 1e-12,
                  "cancel (dyn %d, how %d): %.2e from the twin", dyn, how, e);
            for (k = 0; k < 2; k++) {
                amps_scene_free(&ctx, S[k]);
                shadow_free(w + k);
            }
            mesh_copy_free(&mc);
        }
    { /* amps_scene_dynamics re-factors: it commits an open batch first (a cancel then finds none) */
        amps_ctx ctx;
        amps_scene *S[2];
        shadow w[2];
        amps_int one = 40, k;
        double u[3] = {0.01, 0, 0.02};
        amps_ctx_init(&ctx);
        for (k = 0; k < 2; k++) {
            S[k] = beam_scene(&ctx, 6, w + k, NULL);
            CHECK(amps_scene_solve(&ctx, S[k]) == AMPS_OK &&
                          (k == 1 || amps_scene_begin_batch(&ctx, S[k]) == AMPS_OK) &&
                          amps_scene_remove(&ctx, S[k], 1, &one, AMPS_SINGULAR_REMOVE, NULL) == AMPS_OK &&
                          amps_scene_pin(&ctx, S[k], 130, u) == AMPS_OK &&
                          amps_scene_dynamics(&ctx, S[k], 0.05, 0.1, 0.02) == AMPS_OK,
                  "dynamics in a batch: %s", ctx.msg);
        }
        CHECK(amps_scene_cancel_batch(&ctx, S[0]) == AMPS_ERR_STATE, "a batch open after amps_scene_dynamics");
        for (k = 0; k < 2; k++) CHECK(amps_scene_step(&ctx, S[k], 3) == AMPS_OK, "steps: %s", ctx.msg);
        CHECK(t_reldiff(3 * (int)amps_scene_mesh(S[1])->nnode, amps_scene_displacements(S[0]),
                        amps_scene_displacements(S[1])) <= 1e-12,
              "amps_scene_dynamics in a batch differs from the changes made before it");
        for (k = 0; k < 2; k++) {
            amps_scene_free(&ctx, S[k]);
            shadow_free(w + k);
        }
    }
}

/* A batch large enough to be committed by a re-factorization (a fold) while every node is
   watched: the watch set's workspace follows the new factor's size (under ASan a write past it
   was caught), and the watched solve after it equals the full solve. */
static void test_fold_watched(void) {
    amps_ctx ctx;
    amps_scene *S;
    amps_update_stats st;
    amps_int *w, k, n0, done = 0, vc;
    double f[3] = {0.2, -0.1, -0.5}, nrm[3] = {0, 0, 1}, *uw, e;
    const amps_mesh *m;
    amps_ctx_init(&ctx);
    S = amps_scene_create(&ctx, amps_mesh_brick(&ctx, 3), NULL);
    amps_scene_fix_where(&ctx, S, 2, AMPS_LT, 0.01, NULL);
    m = amps_scene_mesh(S);
    n0 = m->nnode;
    for (k = 0; k < n0; k++)
        if (m->xyz[3 * k + 2] > 1.99) amps_scene_force(&ctx, S, k, f);
    w = (amps_int *)malloc(sizeof(amps_int) * (size_t)(n0 + 1));
    for (k = 0; k < n0; k++) w[k] = (k + 3) % n0; /* every node, not in order, one twice */
    w[n0] = w[0];
    CHECK(amps_scene_prepare(&ctx, S) == AMPS_OK && amps_scene_watch(&ctx, S, n0 + 1, w) == AMPS_OK &&
                  amps_scene_solve_watched(&ctx, S) == AMPS_OK && amps_scene_begin_batch(&ctx, S) == AMPS_OK,
          "fold: %s", ctx.msg);
    for (k = 0; k < n0 && done < 20; k++)
        if (m->xyz[3 * k + 2] > 0.01 && m->xyz[3 * k + 2] < 1.99 &&
            amps_scene_cut(&ctx, S, k, m->xyz + 3 * k, nrm, &vc) == AMPS_OK)
            done++;
    CHECK(amps_scene_commit(&ctx, S) == AMPS_OK && amps_scene_solve_watched(&ctx, S) == AMPS_OK, "fold: commit: %s",
          ctx.msg);
    amps_update_get_stats(amps_scene_engine(S), &st);
    CHECK(st.commit_folds > 0, "fold: the batch of %ld cuts was not committed by a re-factorization", (long)done);
    uw = (double *)malloc(sizeof(double) * 3 * (size_t)n0);
    memcpy(uw, amps_scene_displacements(S), sizeof(double) * 3 * (size_t)n0);
    CHECK(amps_scene_solve(&ctx, S) == AMPS_OK, "fold: solve: %s", ctx.msg);
    e = t_reldiff(3 * (int)n0, uw, amps_scene_displacements(S));
    CHECK(e <= 1e-12, "fold: watched solve %.2e from the full solve", e);
    free(uw);
    free(w);
    amps_scene_free(&ctx, S);
}

/* Two stacked cells, the top one held by three pins: a batch cuts the middle layer free (allowed:
   the pins hold the top) and releases the pins; its commit finds the top loose and undoes all. */
static void test_batch_undo(void) {
    amps_ctx ctx;
    amps_scene *S;
    amps_int v[4] = {4, 5, 6, 7}, vc, top = 10, pins[3] = {8, 10, 11};
    double nrm[3] = {0, 0, 1}, u[3] = {0.01, 0, 0}, u0[36];
    int k, nn;
    amps_status s;
    amps_scene_changes ch;
    amps_ctx_init(&ctx);
    S = amps_scene_create(&ctx, amps_mesh_grid(&ctx, 2, 2, 3, 1.0, 1.0, 1.0), NULL);
    amps_scene_fix_where(&ctx, S, 2, AMPS_LT, 0.5, NULL);
    for (k = 0; k < 3; k++) CHECK(amps_scene_pin(&ctx, S, pins[k], u) == AMPS_OK, "undo: pin: %s", ctx.msg);
    CHECK(amps_scene_solve(&ctx, S) == AMPS_OK, "undo: solve: %s", ctx.msg);
    memcpy(u0, amps_scene_displacements(S), sizeof(u0));
    nn = (int)amps_scene_mesh(S)->nnode;
    CHECK(amps_scene_take_changes(&ctx, S, &ch) == AMPS_OK, "undo: take: %s", ctx.msg); /* the record on */
    CHECK(amps_scene_begin_batch(&ctx, S) == AMPS_OK, "undo: begin: %s", ctx.msg);
    for (k = 0; k < 4; k++) {
        double p[3];
        memcpy(p, amps_scene_mesh(S)->xyz + 3 * v[k], sizeof(p));
        s = amps_scene_cut(&ctx, S, v[k], p, nrm, &vc);
        CHECK(s == AMPS_OK, "undo: cut %d: %s", k, ctx.msg);
    }
    CHECK(amps_scene_mesh(S)->nnode == nn + 4, "undo: the batch's cuts did not change the mesh at once");
    for (k = 0; k < 3; k++) CHECK(amps_scene_release(&ctx, S, pins[k]) == AMPS_OK, "undo: release: %s", ctx.msg);
    s = amps_scene_commit(&ctx, S);
    CHECK(s == AMPS_ERR_SINGULAR_UPDATE, "undo: commit of a loose piece: %d (%s)", (int)s, ctx.msg);
    CHECK(amps_scene_mesh(S)->nnode == nn, "undo: node count not restored");
    CHECK(amps_mesh_check(&ctx, amps_scene_mesh(S)) == AMPS_OK, "undo: mesh invariants: %s", ctx.msg);
    CHECK(amps_scene_take_changes(&ctx, S, &ch) == AMPS_OK && ch.nnew == 0, "undo: take: %s, %ld new nodes", ctx.msg,
          (long)ch.nnew);
    boundary_check(&ctx, S, "undo");
    {
        double r[3];
        CHECK(amps_scene_solve(&ctx, S) == AMPS_OK, "undo: solve after undo: %s", ctx.msg);
        CHECK(t_reldiff(36, amps_scene_displacements(S), u0) < 1e-12, "undo: solution changed");
        amps_scene_reaction(&ctx, S, top, r);
        CHECK(r[0] != 0, "undo: the pin was not restored");
    }
    amps_scene_free(&ctx, S);
}

/* A run of cuts with watched, reaction and full solves; disp receives the final displacements. */
static void count_run(amps_refactor_policy pol, double *disp, int *ndisp, amps_update_stats *st, double *err) {
    amps_ctx ctx;
    amps_scene *S;
    amps_scene_opts so;
    shadow w;
    amps_int watch[3] = {3, 40, 77};
    int fr;
    amps_ctx_init(&ctx);
    amps_scene_opts_default(&so);
    so.update.refactor = pol;
    so.update.refactor_every = 4;
    so.update.refactor_size = 24;
    S = beam_scene(&ctx, 16, &w, &so);
    amps_scene_watch(&ctx, S, 3, watch);
    for (fr = 0; fr < 16; fr++) {
        double pts[6], blade[3] = {0, 1, 0}, u[3];
        amps_int top = 25 * 15 + 12;
        int h;
        stroke_point(fr, 0, pts);
        stroke_point(fr, 1, pts + 3);
        CHECK(amps_scene_stroke(&ctx, S, 2, pts, blade, 0.55, NULL) == AMPS_OK, "run: stroke: %s", ctx.msg);
        shadow_grow(&w, (int)amps_scene_mesh(S)->nnode);
        CHECK(amps_scene_solve_watched(&ctx, S) == AMPS_OK, "run: watched: %s", ctx.msg);
        for (h = 0; h < 5; h++) {
            u[0] = 0.05 + 0.001 * h;
            u[1] = 0.02;
            u[2] = 0.001 * fr;
            CHECK(amps_scene_pin(&ctx, S, top, u) == AMPS_OK && amps_scene_solve_reactions(&ctx, S) == AMPS_OK,
                  "run: haptic: %s", ctx.msg);
        }
        memcpy(w.pinval + 3 * top, u, sizeof(u));
    }
    CHECK(amps_scene_solve(&ctx, S) == AMPS_OK, "run: solve: %s", ctx.msg);
    *ndisp = 3 * (int)amps_scene_mesh(S)->nnode;
    memcpy(disp, amps_scene_displacements(S), sizeof(double) * (size_t)*ndisp);
    amps_update_get_stats(amps_scene_engine(S), st);
    *err = ref_err(&ctx, S, &w);
    amps_scene_free(&ctx, S);
    shadow_free(&w);
}

static void test_count(void) {
    static double d1[3 * 4000], d2[3 * 4000];
    int n1, n2;
    amps_update_stats s1, s2;
    double e1, e2;
    count_run(AMPS_REFACTOR_COUNT, d1, &n1, &s1, &e1);
    count_run(AMPS_REFACTOR_COUNT, d2, &n2, &s2, &e2);
    CHECK(n1 == n2 && !memcmp(d1, d2, sizeof(double) * (size_t)n1), "COUNT: two identical runs differ");
    CHECK(s1.nrefactor >= 2 && s1.nrefactor == s2.nrefactor, "COUNT: re-factorizations %d and %d", (int)s1.nrefactor,
          (int)s2.nrefactor);
    CHECK(e1 <= 1e-10, "COUNT: vs CHOLMOD %.3e", e1);
    printf("  COUNT: %d re-factorizations, identical bits, error %.2e\n", (int)s1.nrefactor, e1);
#ifndef AMPS_NO_THREADS
    { /* AUTO with only watched and reaction solves (plus the final one): the growth starts it */
        count_run(AMPS_REFACTOR_AUTO, d1, &n1, &s1, &e1);
        CHECK(s1.nrefactor + s1.refactor_running >= 1, "AUTO: no re-factorization after |S u C| = %ld", (long)s1.nsys);
        CHECK(e1 <= 1e-10, "AUTO: vs CHOLMOD %.3e", e1);
        printf("  AUTO by size: %d re-factorizations, error %.2e\n", (int)s1.nrefactor, e1);
    }
#endif
}

/* A ready re-factorization is never swapped in by the haptic path; the next watched solve does it. */
static void test_haptic_no_swap(void) {
    amps_ctx ctx;
    amps_scene *S;
    amps_scene_opts so;
    shadow w;
    amps_update_stats st;
    amps_int top = 25 * 7 + 12;
    double t0, u[3] = {0.05, 0.02, 0}, r0[3], r1[3];
    int h = 0;
    amps_ctx_init(&ctx);
    amps_scene_opts_default(&so);
    so.update.refactor = AMPS_REFACTOR_MANUAL;
    S = beam_scene(&ctx, 8, &w, &so);
    CHECK(amps_scene_solve(&ctx, S) == AMPS_OK, "no swap: solve: %s", ctx.msg);
    CHECK(amps_update_refactor_start(&ctx, amps_scene_engine(S)) == AMPS_OK, "no swap: start: %s", ctx.msg);
    t0 = amps_now();
    while (amps_now() - t0 < 0.25 || h < 100) { /* long after the small factorization is ready */
        u[2] = 0.0001 * (h++ % 50);
        CHECK(amps_scene_pin(&ctx, S, top, u) == AMPS_OK && amps_scene_solve_reactions(&ctx, S) == AMPS_OK,
              "no swap: haptic: %s", ctx.msg);
    }
    amps_update_get_stats(amps_scene_engine(S), &st);
    CHECK(st.nrefactor == 0 && st.refactor_running == 1, "no swap: the haptic path swapped (%d, %d)", (int)st.nrefactor,
          st.refactor_running);
    amps_scene_reaction(&ctx, S, top, r0);
    CHECK(amps_scene_solve_watched(&ctx, S) == AMPS_OK, "no swap: watched: %s", ctx.msg);
    amps_update_get_stats(amps_scene_engine(S), &st);
    CHECK(st.nrefactor == 1, "no swap: the watched solve did not swap (%d)", (int)st.nrefactor);
    amps_scene_reaction(&ctx, S, top, r1);
    CHECK(fabs(r0[0] - r1[0]) <= 1e-9 * (1 + fabs(r1[0])), "no swap: reaction %.6e vs %.6e after the swap", r0[0],
          r1[0]);
    amps_scene_free(&ctx, S);
    shadow_free(&w);
}

/* Frame fr of the two-phase test: a batch holding a stroke. */
static void two_phase_batch(amps_ctx *ctx, amps_scene *S, int fr) {
    double pts[6], blade[3] = {0, 1, 0.1};
    stroke_point(fr, 0, pts);
    stroke_point(fr, 1, pts + 3);
    CHECK(amps_scene_begin_batch(ctx, S) == AMPS_OK, "two-phase: begin batch: %s", ctx->msg);
    CHECK(amps_scene_stroke(ctx, S, 2, pts, blade, 0.55, NULL) == AMPS_OK, "two-phase: stroke: %s", ctx->msg);
}

/* Haptic steps: the top pin moved, its reaction read; returns the last x-reaction. */
static double haptic_steps(amps_ctx *ctx, amps_scene *S, amps_int top, int fr, int nsteps) {
    double u[3], r[3] = {0, 0, 0};
    int h;
    for (h = 0; h < nsteps; h++) {
        u[0] = 0.05 + 0.0005 * h;
        u[1] = 0.02;
        u[2] = 0.001 * fr;
        CHECK(amps_scene_pin(ctx, S, top, u) == AMPS_OK && amps_scene_solve_reactions(ctx, S) == AMPS_OK,
              "two-phase: haptic: %s", ctx->msg);
        amps_scene_reaction(ctx, S, top, r);
    }
    return r[0];
}

/* A two-phase commit equals a one-phase commit bitwise; haptic steps during its run phase see the
   committed system and never swap; the changes it forbids meanwhile are refused. */
static void test_two_phase(void) {
    amps_ctx ctx;
    amps_scene *A, *B;
    shadow wa, wb;
    amps_scene_opts so;
    amps_int top = 25 * 15 + 12;
    int fr, same = 1;
    amps_ctx_init(&ctx);
    amps_scene_opts_default(&so);
    so.update.refactor = AMPS_REFACTOR_COUNT; /* swaps at the same points in both */
    so.update.refactor_every = 3;
    A = beam_scene(&ctx, 16, &wa, &so);
    B = beam_scene(&ctx, 16, &wb, &so);
    for (fr = 0; fr < 10; fr++) {
        double ra, rb, u[3] = {0.05, 0.02, 0.001 * fr}, p[3] = {2, 2, 8}, nrm[3] = {1, 0, 0};
        amps_int n3, vc;
        two_phase_batch(&ctx, A, fr);
        two_phase_batch(&ctx, B, fr);
        CHECK(amps_scene_commit_begin(&ctx, A) == AMPS_OK, "two-phase: begin: %s", ctx.msg);
        CHECK(amps_scene_cut(&ctx, A, 0, p, nrm, &vc) == AMPS_ERR_STATE, "two-phase: a cut during the job accepted");
        CHECK(amps_scene_pin(&ctx, A, 25 * 15 + 3, u) == AMPS_ERR_STATE,
              "two-phase: a new pin during the job accepted");
        CHECK(amps_scene_pin(&ctx, A, amps_scene_mesh(A)->nnode - 1, u) == AMPS_ERR_STATE,
              "two-phase: a pin of the batch's newest node during the job: %s", ctx.msg);
        amps_scene_commit_run(A);
        CHECK(amps_scene_commit_end(&ctx, A) == AMPS_OK, "two-phase: end: %s", ctx.msg);
        CHECK(amps_scene_commit(&ctx, B) == AMPS_OK, "two-phase: one-phase commit: %s", ctx.msg);
        shadow_grow(&wa, (int)amps_scene_mesh(A)->nnode);
        ra = haptic_steps(&ctx, A, top, fr, 5);
        rb = haptic_steps(&ctx, B, top, fr, 5);
        same &= ra == rb;
        CHECK(amps_scene_solve(&ctx, A) == AMPS_OK && amps_scene_solve(&ctx, B) == AMPS_OK, "two-phase: solve: %s",
              ctx.msg);
        n3 = 3 * amps_scene_mesh(A)->nnode;
        same &= n3 == 3 * amps_scene_mesh(B)->nnode &&
                !memcmp(amps_scene_displacements(A), amps_scene_displacements(B), sizeof(double) * (size_t)n3);
    }
    CHECK(same, "two-phase: results differ from the one-phase commit's bits");
    {
        amps_update_stats st;
        amps_update_get_stats(amps_scene_engine(A), &st);
        CHECK(st.nrefactor >= 1, "two-phase: no re-factorization swapped in (COUNT)");
    }
    /* the haptic thread during the run phase: it sees the committed system */
    for (fr = 10; fr < 16; fr++) {
        double r_before, r_during, r_after, u[3] = {0.05, 0.02, 0.001 * fr};
        amps_update_stats st0, st1;
        r_before = haptic_steps(&ctx, A, top, fr, 1);
        two_phase_batch(&ctx, A, fr);
        CHECK(amps_scene_commit_begin(&ctx, A) == AMPS_OK, "two-phase: begin: %s", ctx.msg);
        amps_update_get_stats(amps_scene_engine(A), &st0);
        r_during = haptic_steps(&ctx, A, top, fr, 1);
        CHECK(fabs(r_during - r_before) <= 1e-12 * fabs(r_before),
              "two-phase: the haptic step during the job: %.6e vs %.6e", r_during, r_before);
#ifdef _OPENMP
#pragma omp parallel sections num_threads(2)
        {
#pragma omp section
            amps_scene_commit_run(A);
#pragma omp section
            (void)haptic_steps(&ctx, A, top, fr, 20);
        }
#else
        amps_scene_commit_run(A);
        (void)haptic_steps(&ctx, A, top, fr, 20);
#endif
        amps_update_get_stats(amps_scene_engine(A), &st1);
        CHECK(st1.nrefactor == st0.nrefactor, "two-phase: a swap during the job");
        CHECK(amps_scene_pin(&ctx, A, top, u) == AMPS_OK, "two-phase: pin move: %s", ctx.msg);
        CHECK(amps_scene_commit_end(&ctx, A) == AMPS_OK, "two-phase: end: %s", ctx.msg);
        shadow_grow(&wa, (int)amps_scene_mesh(A)->nnode);
        memcpy(wa.pinval + 3 * top, u, sizeof(u));
        r_after = haptic_steps(&ctx, A, top, fr, 0);
        (void)r_after;
        CHECK(amps_scene_solve(&ctx, A) == AMPS_OK, "two-phase: solve: %s", ctx.msg);
        {
            double e = ref_err(&ctx, A, &wa);
            CHECK(e <= 1e-10, "two-phase frame %d: vs CHOLMOD %.3e", fr, e);
        }
    }
    amps_scene_free(&ctx, A);
    amps_scene_free(&ctx, B);
    shadow_free(&wa);
    shadow_free(&wb);
}

/* The distance to a polyline's corner is the same bits through both segments (the stroke takes
   the first of equal ones). */
static void test_corner_tie(void) {
    double a[3] = {0.1, 0.7, 0.3}, c[3] = {1.3, 0.9, 0.45}, e[3] = {1.2, 2.2, 0.2}, x[3], t0, t1;
    int k, bad = 0;
    t_seed(77);
    for (k = 0; k < 20000; k++) {
        int d;
        for (d = 0; d < 3; d++) x[d] = c[d] + (t_unif() - 0.5) * 3.0;
        if (amps__seg_dist2(x, a, c, &t0) != amps__seg_dist2(x, c, e, &t1) && t0 == 1 && t1 == 0) bad++;
    }
    CHECK(bad == 0, "corner: %d points nearest the corner at different distances through its segments", bad);
}

int main(void) {
    test_corner_tie();
    test_stroke();
    test_stroke_loose();
    test_batches(21);
    test_batches(22);
    test_batch_undo();
    test_batch_cancel();
    test_fold_watched();
    test_count();
    test_haptic_no_swap();
    test_two_phase();
    test_two_phase_dynamics();
    test_two_phase_release();
    test_stroke_edges();
    return amps_t_end("test_frame");
}
