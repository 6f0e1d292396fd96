/* Allocation failures in the update path, the scene and the mesh readers: the counting allocator
   (t_alloc.h) fails the k-th allocation of one call, for k = 0, 1, ... until the call succeeds.
   Every failure must return AMPS_ERR_OOM (NULL for constructors), leak nothing, and leave the
   object as it was: solving right after the failure gives the answer of the same sequence without
   the failed call, and redoing the call and finishing the sequence gives the fault-free answer.
   Engine with tiny capacities and growth on, so that add_dofs, add, set_rows, constrain,
   release, commit and solve all allocate. */
#include "t_alloc.h"
#define AMPS_IMPLEMENTATION
#include "amps.h"
#include "amps_test.h"
#include <string.h>

static void arm(long k) { t_al.fail_at = k; }
static void disarm(void) { t_al.fail_at = -1; }
static long points = 0; /* allocation failures injected */

/* ---------------------------------- engine ---------------------------------- */

typedef struct eng {
    amps_ctx ctx; /* counted */
    amps_csc *K;
    amps_factor *F;
    amps_update *U;
    amps_int n;
} eng;

static amps_csc *base_K; /* uncounted base */
static amps_factor *base_F;

static void eng_open(eng *e) {
    amps_update_opts o;
    memset(e, 0, sizeof(*e));
    amps_ctx_init(&e->ctx);
    e->ctx.alloc_user = &t_al;
    e->ctx.nthreads = 1;
    e->n = base_K->ncol;
    amps_update_opts_default(&o);
    o.grow = 1;
    o.cap_mod = 1;
    o.cap_new = 1;
    o.cap_pending = 1;
    o.cap_delta = 1;
    o.cap_vpool = 1;
    o.refactor = AMPS_REFACTOR_MANUAL; /* the counting allocator is single-threaded */
    e->U = amps_update_create(&e->ctx, base_K, AMPS_UPPER, base_F, &o);
    CHECK(e->U != NULL, "engine create: %s", e->ctx.msg);
}

/* The sequence: recorded changes and solves (S). */
static const int op_kind[] = {0, 1, 9, 2, 9, 3, 9, 4, 9, 5, 9, 0, 1, 9, 6, 9, 7, 9, 8, 9};
#define NOPS ((int)(sizeof(op_kind) / sizeof(op_kind[0])))
static const char *op_name[] = {"add_dofs", "add",       "set_force", "constrain", "set_rows",
                                "release",  "constrain", "add",       "release",   "solve"};
static int is_solve(int j) { return op_kind[j] == 9; }

static amps_status eng_op(eng *e, int j, double *x) {
    amps_int n = e->n, dim = amps_update_dim(e->U);
    switch (op_kind[j]) {
    case 0: { /* three new DOFs */ amps_int first; return amps_update_add_dofs(&e->ctx, e->U, 3, &first);
    }
    case 1: { /* ... hung on springs to base DOFs */
        amps_int r[9], c[9], d, q = 0, nd = dim - 3;
        double v[9], sp = 50.0;
        for (d = 0; d < 3; d++) {
            amps_int b = (7 * (nd + d)) % n;
            r[q] = nd + d;
            c[q] = nd + d;
            v[q++] = sp;
            r[q] = b;
            c[q] = nd + d;
            v[q++] = -sp;
            r[q] = b;
            c[q] = b;
            v[q++] = sp;
        }
        return amps_update_add(&e->ctx, e->U, q, r, c, v);
    }
    case 2: { /* forces */
        amps_int idx[4] = {3, 17, n - 1, n + 1};
        double v[4] = {1, -2, 0.5, 3};
        return amps_update_set_force(&e->ctx, e->U, 4, idx, v);
    }
    case 3: { /* constraints */
        amps_int idx[4] = {5, 9, 30, n + 2};
        double v[4] = {0.01, -0.02, 0.03, 0.001};
        return amps_update_constrain(&e->ctx, e->U, 3, idx, v);
    }
    case 6: { /* many constraints (the pending list grows) */
        amps_int idx[80], q;
        double v[80];
        for (q = 0; q < 80; q++) {
            idx[q] = 100 + q;
            v[q] = 1e-3 * (q % 7);
        }
        return amps_update_constrain(&e->ctx, e->U, 80, idx, v);
    }
    case 4: { /* new row of the first appended DOF: its spring to base DOF 0 (the one
                           case 1 hung it on, 7n mod n) and weak springs to 100 odd base DOFs */
        amps_int row = n, cp[2], ci[102], q;
        double cx[102];
        ci[0] = 0;
        cx[0] = -50.0;
        for (q = 0; q < 100; q++) {
            ci[q + 1] = 2 * q + 1;
            cx[q + 1] = -1e-3;
        }
        ci[101] = n;
        cx[101] = 50.1;
        cp[0] = 0;
        cp[1] = 102;
        return amps_update_set_rows(&e->ctx, e->U, 1, &row, cp, ci, cx);
    }
    case 5: { /* release two pins, and 98 indices that are not pinned */
        amps_int idx[100], q;
        idx[0] = 5;
        idx[1] = 30;
        for (q = 2; q < 100; q++) idx[q] = 100 + q;
        return amps_update_release(&e->ctx, e->U, 100, idx);
    }
    case 7: { /* a stiffness term on 20 base DOFs (210 entries: the pending list grows) */
        amps_int r[210], c[210], a, b, q = 0;
        double v[210];
        for (a = 0; a < 20; a++)
            for (b = a; b < 20; b++) {
                r[q] = 10 + 2 * a;
                c[q] = 10 + 2 * b;
                v[q++] = 5.0 * (a % 2 ? 1 : -1) * (b % 2 ? 1 : -1);
            }
        return amps_update_add(&e->ctx, e->U, q, r, c, v);
    }
    case 8: { /* release most of them and one more */
        amps_int idx[71], q;
        for (q = 0; q < 70; q++) idx[q] = 100 + q;
        idx[70] = 9;
        return amps_update_release(&e->ctx, e->U, 71, idx);
    }
    }
    return amps_update_solve(&e->ctx, e->U, x);
}

static void eng_close(eng *e) {
    amps_update_free(&e->ctx, e->U);
    CHECK(t_al.live == 0, "engine: %ld blocks live after free", t_al.live);
    t_al.live = 0;
}

static void test_engine(void) {
    double *xfree[NOPS + 1], *x, *xp;
    amps_int dims[NOPS + 1];
    int t, j;
    long k;
    eng e;
    x = (double *)malloc(sizeof(double) * 4096);
    xp = (double *)malloc(sizeof(double) * 4096);
    /* fault-free run: the solution after each solve */
    eng_open(&e);
    CHECK(amps_update_solve(&e.ctx, e.U, x) == AMPS_OK, "first solve");
    for (j = 0; j < NOPS; j++) {
        amps_status s = eng_op(&e, j, x);
        CHECK(s == AMPS_OK, "fault-free op %d: %s", j, e.ctx.msg);
        dims[j] = amps_update_dim(e.U);
        xfree[j] = NULL;
        if (is_solve(j)) {
            xfree[j] = (double *)malloc(sizeof(double) * dims[j]);
            memcpy(xfree[j], x, sizeof(double) * dims[j]);
        }
    }
    CHECK(is_solve(NOPS - 1), "the sequence ends with a solve");
    eng_close(&e);
    /* create */
    for (k = 0;; k++) {
        amps_ctx c;
        amps_update_opts o;
        amps_update *U;
        amps_ctx_init(&c);
        c.alloc_user = &t_al;
        amps_update_opts_default(&o);
        arm(k);
        U = amps_update_create(&c, base_K, AMPS_UPPER, base_F, &o);
        disarm();
        if (U) {
            amps_update_free(&c, U);
            printf("  update create: %ld allocation points\n", k);
            break;
        }
        points++;
        if (k > 2000) break;
        CHECK(c.status == AMPS_ERR_OOM && t_al.live == 0, "update_create fail at %ld: status %d live %ld", k,
              (int)c.status, t_al.live);
        t_al.live = 0;
    }
    /* each operation t with its k-th allocation failing */
    for (t = 0; t < NOPS; t++) {
        int ps = t - 1;
        amps_int lastdim;
        while (ps >= 0 && !is_solve(ps)) ps--;
        lastdim = ps >= 0 ? dims[ps] : base_K->ncol;
        for (k = 0;; k++) {
            amps_status s;
            int after = 0;
            amps_int dim0;
            eng_open(&e);
            amps_update_solve(&e.ctx, e.U, x);
            for (j = 0; j < t; j++) eng_op(&e, j, x);
            memcpy(xp, amps_update_solution(e.U), sizeof(double) * lastdim);
            dim0 = amps_update_dim(e.U);
            arm(k);
            s = eng_op(&e, t, x);
            disarm();
            if (s == AMPS_OK) {
                eng_close(&e);
                printf("  engine op %2d (%s): %ld allocation points\n", t, op_name[op_kind[t]], k);
                break;
            }
            points++;
            if (s != AMPS_ERR_OOM || k > 2000) {
                CHECK(0, "op %d: status %d at fault %ld: %s", t, (int)s, k, e.ctx.msg);
                eng_close(&e);
                break;
            }
            CHECK(e.ctx.status == AMPS_ERR_OOM, "op %d fail at %ld: ctx status %d", t, k, (int)e.ctx.status);
            if (is_solve(t)) {
                /* a failed commit discards the changes since the last solve: its state again (a solve
                   may also fail after its commit went through: then the state after it) */
                s = amps_update_solve(&e.ctx, e.U, x);
                CHECK(s == AMPS_OK, "op %d fail at %ld: solve after the failure: %s", t, k, e.ctx.msg);
                if (s == AMPS_OK) {
                    amps_int d = amps_update_dim(e.U);
                    int before = d == lastdim && t_reldiff((int)d, x, xp) <= 1e-12;
                    after = d == dims[t] && t_reldiff((int)d, x, xfree[t]) <= 1e-12;
                    CHECK(before || after, "op %d fail at %ld: the engine changed (dim %ld)", t, k, (long)d);
                }
            } else {
                CHECK(amps_update_dim(e.U) == dim0, "op %d fail at %ld: dimension changed", t, k);
            }
            /* redo what was lost and finish: the fault-free answer */
            for (j = after ? t + 1 : (is_solve(t) ? ps + 1 : t); j < NOPS; j++)
                if ((s = eng_op(&e, j, x)) != AMPS_OK) break;
            CHECK(s == AMPS_OK && amps_update_dim(e.U) == dims[NOPS - 1] &&
                          t_reldiff((int)dims[NOPS - 1], x, xfree[NOPS - 1]) <= 1e-10,
                  "op %d fail at %ld: finishing the sequence: %s", t, k, s == AMPS_OK ? "different answer" : e.ctx.msg);
            eng_close(&e);
        }
    }
    for (j = 0; j < NOPS; j++) free(xfree[j]);
    free(x);
    free(xp);
}

/* ---------------------------------- scene ---------------------------------- */

#define SOPS 19
static void disarm(void);
static amps_status scene_op(amps_ctx *c, amps_scene *S, int j) {
    double f[3] = {0.5, -1, 2}, u[3] = {0.01, 0, -0.01}, u2[3] = {0, 0.02, 0}, p[3], nrm[3] = {0.3, 1, 0.2},
           pts[6] = {0.5, -0.1, 1.2, 0.5, 1.1, 1.2}, blade[3] = {0, 0, 1};
    amps_int vc;
    const amps_mesh *m = amps_scene_mesh(S);
    switch (j) {
    case 0: { /* a batch with a new pin, committed in two phases (the first: its workspace) */
        amps_status s = amps_scene_begin_batch(c, S);
        if (s != AMPS_OK) return s;
        if ((s = amps_scene_pin(c, S, 32, u)) != AMPS_OK) {
            disarm();
            (void)amps_scene_commit(c, S); /* the batch is empty: close it */
            return s;
        }
        if ((s = amps_scene_commit_begin(c, S)) != AMPS_OK) return s;
        amps_scene_commit_run(S);
        return amps_scene_commit_end(c, S);
    }
    case 1: return amps_scene_pin(c, S, 30, u);
    case 2:
    case 6:
    case 10:
    case 13: return amps_scene_solve(c, S);
    case 3: return amps_scene_stroke(c, S, 2, pts, blade, 0.3, NULL); /* a batch of 3 cuts, the first of the run */
    case 4: return amps_scene_pin(c, S, 30, u2);
    case 5: return amps_scene_pin(c, S, 31, u);
    case 7: return amps_scene_release(c, S, 30);
    case 8: memcpy(p, m->xyz + 3 * 13, sizeof(p)); return amps_scene_cut(c, S, 13, p, nrm, &vc);
    case 9:
        memcpy(p, m->xyz + 3 * 31, sizeof(p));
        nrm[0] = -1;
        return amps_scene_cut(c, S, 31, p, nrm, &vc);
    case 11: return amps_scene_force(c, S, 44, u2);
    case 12: return amps_scene_release(c, S, 31);
    case 14: memcpy(p, m->xyz + 3 * 22, sizeof(p)); return amps_scene_cut(c, S, 22, p, nrm, &vc);
    case 15: return amps_scene_solve(c, S);
    case 16: return amps_scene_force(c, S, 40, f);
    case 17: { /* a batch of a removal with separations, materials (densities too), a cut and a pin, in
                  two phases; a change that fails before reaching the engine leaves the batch open:
                  cancelled */
        amps_int tets[2] = {3, 17};
        amps_status s = amps_scene_begin_batch(c, S);
        if (s != AMPS_OK) return s;
        memcpy(p, m->xyz + 3 * 16, sizeof(p));
        if ((s = amps_scene_remove(c, S, 2, tets, AMPS_SINGULAR_SEPARATE, NULL)) != AMPS_OK ||
            (s = amps_scene_set_region(c, S, 0, 900, 0.32, 2.0)) != AMPS_OK ||
            (s = amps_scene_set_tet_material(c, S, 5, 1500, 0.3)) != AMPS_OK ||
            (s = amps_scene_cut(c, S, 16, p, nrm, &vc)) != AMPS_OK || (s = amps_scene_pin(c, S, 33, u2)) != AMPS_OK) {
            disarm();
            (void)amps_scene_cancel_batch(c, S); /* AMPS_ERR_STATE when the failure undid it */
            return s;
        }
        if ((s = amps_scene_commit_begin(c, S)) != AMPS_OK) return s;
        amps_scene_commit_run(S);
        return amps_scene_commit_end(c, S);
    }
    case 18: return amps_scene_solve(c, S);
    }
    return AMPS_OK;
}

static amps_scene *scene_open(amps_ctx *c) {
    amps_scene_opts so;
    amps_mesh *m;
    amps_scene *S;
    amps_ctx_init(c);
    c->alloc_user = &t_al;
    c->nthreads = 1;
    m = amps_mesh_brick(c, 2);
    amps_scene_opts_default(&so);
    so.update.cap_mod = 1;
    so.update.cap_new = 1;
    so.update.cap_pending = 1;
    so.update.cap_delta = 1;
    so.update.cap_vpool = 1;
    so.update.refactor = AMPS_REFACTOR_MANUAL; /* the counting allocator is single-threaded */
    S = amps_scene_create(c, m, &so);
    amps_scene_set_material(c, S, 1000, 0.3);
    amps_scene_fix_where(c, S, 2, AMPS_LT, 1e-9, NULL);
    return S;
}

/* Displacements of every node after a solve, nn nodes. */
static int scene_disp(amps_ctx *c, amps_scene *S, double *u) {
    amps_int nn = amps_scene_mesh(S)->nnode;
    if (amps_scene_solve(c, S) != AMPS_OK) return -1;
    memcpy(u, amps_scene_displacements(S), sizeof(double) * 3 * nn);
    return (int)nn;
}

static void test_scene(void) {
    amps_ctx c;
    amps_scene *S;
    double *ub[SOPS + 1], ufin[3 * 200], u[3 * 200];
    int nb[SOPS + 1], nfin, t, j;
    long k;
    /* fault-free: displacements when solving before op t, and at the end */
    for (t = 0; t <= SOPS; t++) {
        S = scene_open(&c);
        for (j = 0; j < t; j++) CHECK(scene_op(&c, S, j) >= 0, "scene fault-free op %d: %s", j, c.msg);
        ub[t] = (double *)malloc(sizeof(double) * 3 * 200);
        nb[t] = scene_disp(&c, S, ub[t]);
        amps_scene_free(&c, S);
    }
    nfin = nb[SOPS];
    memcpy(ufin, ub[SOPS], sizeof(double) * 3 * nfin);
    CHECK(t_al.live == 0, "scene: %ld blocks live", t_al.live);
    t_al.live = 0;
    /* create and prepare */
    for (k = 0;; k++) {
        amps_mesh *m;
        amps_ctx_init(&c);
        c.alloc_user = &t_al;
        m = amps_mesh_brick(&c, 2);
        arm(k);
        S = amps_scene_create(&c, m, NULL);
        disarm();
        if (S) {
            amps_scene_free(&c, S);
            printf("  scene create: %ld allocation points\n", k);
            break;
        }
        points++;
        if (k > 2000) break;
        CHECK(c.status == AMPS_ERR_OOM, "scene_create fail at %ld: %s", k, c.msg);
        CHECK(t_al.live == 0, "scene_create fail at %ld: %ld live", k, t_al.live);
        t_al.live = 0;
    }
    for (k = 0;; k++) {
        amps_status s;
        S = scene_open(&c);
        arm(k);
        s = amps_scene_prepare(&c, S);
        disarm();
        if (s == AMPS_OK) {
            amps_scene_free(&c, S);
            printf("  scene prepare: %ld allocation points\n", k);
            break;
        }
        points++;
        if (s != AMPS_ERR_OOM || k > 2000) {
            CHECK(0, "prepare: status %d at %ld: %s", (int)s, k, c.msg);
            amps_scene_free(&c, S);
            break;
        }
        CHECK(s == AMPS_ERR_OOM, "scene_prepare fail at %ld: %d %s", k, (int)s, c.msg);
        CHECK(scene_disp(&c, S, u) == nb[0] && t_reldiff(3 * nb[0], u, ub[0]) <= 1e-12,
              "scene_prepare fail at %ld: solve after", k);
        amps_scene_free(&c, S);
        CHECK(t_al.live == 0, "scene_prepare fail at %ld: %ld live", k, t_al.live);
        t_al.live = 0;
    }
    /* each operation (after a first solve) with its k-th allocation failing */
    for (t = 0; t < SOPS; t++) {
        for (k = 0;; k++) {
            amps_status s;
            amps_int nn;
            S = scene_open(&c);
            amps_scene_prepare(&c, S);
            for (j = 0; j < t; j++) scene_op(&c, S, j);
            nn = amps_scene_mesh(S)->nnode;
            arm(k);
            s = scene_op(&c, S, t);
            disarm();
            if (s >= 0) {
                amps_scene_free(&c, S);
                t_al.live = 0;
                printf("  scene op %2d: %ld allocation points\n", t, k);
                break;
            }
            points++;
            if (s != AMPS_ERR_OOM || k > 2000) {
                CHECK(0, "scene op %d: status %d at fault %ld: %s", t, (int)s, k, c.msg);
                amps_scene_free(&c, S);
                t_al.live = 0;
                break;
            }
            CHECK(s == AMPS_ERR_OOM, "scene op %d fail at %ld: status %d: %s", t, k, (int)s, c.msg);
            CHECK(amps_scene_mesh(S)->nnode == nn && amps_mesh_check(&c, amps_scene_mesh(S)) == AMPS_OK,
                  "scene op %d fail at %ld: mesh changed", t, k);
            /* the state without the operation (a solve: the state it was solving) */
            CHECK(scene_disp(&c, S, u) == nb[t] && t_reldiff(3 * nb[t], u, ub[t]) <= 1e-10,
                  "scene op %d fail at %ld: solve after the failure differs from the state before it (%.2e)", t, k,
                  t_reldiff(3 * nb[t], u, ub[t]));
            for (j = t; j < SOPS; j++) scene_op(&c, S, j);
            CHECK(scene_disp(&c, S, u) == nfin && t_reldiff(3 * nfin, u, ufin) <= 1e-10,
                  "scene op %d fail at %ld: finishing: %.2e", t, k, t_reldiff(3 * nfin, u, ufin));
            amps_scene_free(&c, S);
            CHECK(t_al.live == 0, "scene op %d fail at %ld: %ld live", t, k, t_al.live);
            t_al.live = 0;
        }
    }
    for (t = 0; t <= SOPS; t++) free(ub[t]);
}

/* A stroke (one batch of 3 cuts) on a scene with default capacities, its k-th allocation
   failing: the scene is as before it, and the stroke made again gives the fault-free result. */
static amps_scene *stroke_scene(amps_ctx *c) {
    amps_mesh *m;
    amps_scene *S;
    amps_int v;
    double f[3] = {0.3, 0.1, -0.2};
    amps_ctx_init(c);
    c->alloc_user = &t_al;
    c->nthreads = 1;
    m = amps_mesh_brick(c, 2);
    S = amps_scene_create(c, m, NULL);
    amps_scene_set_material(c, S, 1000, 0.3);
    amps_scene_fix_where(c, S, 2, AMPS_LT, 0.01, NULL);
    CHECK(amps_scene_prepare(c, S) == AMPS_OK, "stroke scene: prepare: %s", c->msg);
    for (v = 0; v < amps_scene_mesh(S)->nnode; v++)
        if (amps_scene_mesh(S)->xyz[3 * v + 2] > 1.99) amps_scene_force(c, S, v, f);
    return S;
}

static void test_stroke_oom(void) {
    double pts[6] = {0.5, -0.1, 1.2, 0.5, 1.1, 1.2}, blade[3] = {0, 0, 1}, *ref, *u;
    amps_ctx c;
    amps_scene *S = stroke_scene(&c);
    amps_int n, nn;
    long k, points = 0;
    CHECK(amps_scene_stroke(&c, S, 2, pts, blade, 0.3, NULL) == AMPS_OK && amps_scene_solve(&c, S) == AMPS_OK,
          "stroke, fault-free: %s", c.msg);
    n = 3 * amps_scene_mesh(S)->nnode;
    ref = (double *)malloc(sizeof(double) * (size_t)n);
    u = (double *)malloc(sizeof(double) * (size_t)n);
    memcpy(ref, amps_scene_displacements(S), sizeof(double) * (size_t)n);
    amps_scene_free(&c, S);
    t_al.live = 0;
    for (k = 0; k < 2000; k++) {
        amps_status s;
        S = stroke_scene(&c);
        nn = amps_scene_mesh(S)->nnode;
        arm(k);
        s = amps_scene_stroke(&c, S, 2, pts, blade, 0.3, NULL);
        disarm();
        if (s == AMPS_OK) {
            amps_scene_free(&c, S);
            t_al.live = 0;
            break;
        }
        points++;
        CHECK(s == AMPS_ERR_OOM && amps_scene_mesh(S)->nnode == nn, "stroke fail at %ld: status %d, %ld nodes", k,
              (int)s, (long)amps_scene_mesh(S)->nnode);
        CHECK(amps_scene_stroke(&c, S, 2, pts, blade, 0.3, NULL) == AMPS_OK && amps_scene_solve(&c, S) == AMPS_OK &&
                      3 * amps_scene_mesh(S)->nnode == n,
              "stroke fail at %ld: again: %s", k, c.msg);
        if (3 * amps_scene_mesh(S)->nnode == n) {
            memcpy(u, amps_scene_displacements(S), sizeof(double) * (size_t)n);
            CHECK(t_reldiff((int)n, u, ref) <= 1e-10, "stroke fail at %ld: again differs %.2e", k,
                  t_reldiff((int)n, u, ref));
        }
        amps_scene_free(&c, S);
        CHECK(t_al.live == 0, "stroke fail at %ld: %ld live", k, t_al.live);
        t_al.live = 0;
    }
    printf("  stroke: %ld allocation points\n", points);
    /* the second cut of a batch failing: the batch is undone (the first cut too) */
    for (k = 0, points = 0; k < 2000; k++) {
        amps_status s;
        double p[3], nrm[3] = {0.3, 1, 0.2};
        amps_int vc;
        S = stroke_scene(&c);
        nn = amps_scene_mesh(S)->nnode;
        memcpy(p, amps_scene_mesh(S)->xyz + 3 * 22, sizeof(p));
        CHECK(amps_scene_begin_batch(&c, S) == AMPS_OK && amps_scene_cut(&c, S, 22, p, nrm, &vc) == AMPS_OK,
              "batch: first cut: %s", c.msg);
        memcpy(p, amps_scene_mesh(S)->xyz + 3 * 13, sizeof(p));
        arm(k);
        s = amps_scene_cut(&c, S, 13, p, nrm, &vc);
        disarm();
        if (s != AMPS_ERR_OOM) {
            CHECK(s == AMPS_OK, "batch: second cut: %s", c.msg);
            amps_scene_free(&c, S);
            t_al.live = 0;
            break;
        }
        points++;
        CHECK(s == AMPS_ERR_OOM && amps_scene_mesh(S)->nnode == nn && amps_scene_commit(&c, S) == AMPS_OK &&
                      amps_scene_solve(&c, S) == AMPS_OK,
              "batch cut fail at %ld: status %d, %ld nodes (%ld before the batch): %s", k, (int)s,
              (long)amps_scene_mesh(S)->nnode, (long)nn, c.msg);
        CHECK(amps_scene_stroke(&c, S, 2, pts, blade, 0.3, NULL) == AMPS_OK && amps_scene_solve(&c, S) == AMPS_OK &&
                      3 * amps_scene_mesh(S)->nnode == n &&
                      t_reldiff((int)n, amps_scene_displacements(S), ref) <= 1e-10,
              "batch cut fail at %ld: the stroke after it differs", k);
        amps_scene_free(&c, S);
        CHECK(t_al.live == 0, "batch cut fail at %ld: %ld live", k, t_al.live);
        t_al.live = 0;
    }
    printf("  the second cut of a batch: %ld allocation points\n", points);
    /* a cut in a batch that must grow the mesh's node storage, failing: the batch (a material
       change before it) is undone and closed */
    for (k = 0, points = 0; k < 2000; k++) {
        amps_status s;
        double p[3], nrm[3] = {0.3, 1, 0.2}, E0;
        amps_int vc, v, t10 = 10;
        amps_int nn1;
        amps_ctx_init(&c);
        c.alloc_user = &t_al;
        c.nthreads = 1;
        S = amps_scene_create(&c, amps_mesh_beam(&c, 3), NULL);
        amps_scene_fix_where(&c, S, 2, AMPS_LT, 0.01, NULL);
        CHECK(amps_scene_dynamics(&c, S, 0.05, 0, 0) == AMPS_OK && amps_scene_prepare(&c, S) == AMPS_OK,
              "growth: scene: %s", c.msg);
        t_seed(7);
        nn1 = amps_scene_mesh(S)->nnode; /* cut until the mesh's node storage is full after one growth (the
                                            scene's, grown by another rule, has room) */
        for (v = 0;
             (amps_scene_mesh(S)->nnode < amps_scene_mesh(S)->node_cap || amps_scene_mesh(S)->nnode == nn1) && v < 5000;
             v++) {
            amps_int w = t_int((int)amps_scene_mesh(S)->nnode);
            int d;
            for (d = 0; d < 3; d++) {
                p[d] = amps_scene_mesh(S)->xyz[3 * w + d];
                nrm[d] = t_unif() - 0.5;
            }
            (void)amps_scene_cut(&c, S, w, p, nrm, &vc);
        }
        nrm[0] = 0, nrm[1] = 1, nrm[2] = 0;
        nn = amps_scene_mesh(S)->nnode;
        E0 = amps_scene_mesh(S)->E[t10];
        CHECK(nn == amps_scene_mesh(S)->node_cap && amps_scene_begin_batch(&c, S) == AMPS_OK &&
                      amps_scene_set_tet_material(&c, S, t10, 5.0, 0.25) == AMPS_OK,
              "growth: the mesh full (%ld of %ld nodes), a batch: %s", (long)nn, (long)amps_scene_mesh(S)->node_cap,
              c.msg);
        for (v = 0; v < nn; v++) { /* a node the plane y = y_v splits (tet centroids on both sides) */
            const amps_mesh *m = amps_scene_mesh(S);
            amps_int deg, j, below = 0;
            const amps_int *inc = amps_mesh_incident(m, v, &deg);
            for (j = 0; j < deg; j++) {
                double yc = 0;
                int q;
                for (q = 0; q < 4; q++) yc += 0.25 * m->xyz[3 * m->tet[4 * inc[j] + q] + 1];
                below += yc < m->xyz[3 * v + 1];
            }
            if (!amps_scene_is_fixed(S, v) && below > 0 && below < deg) break;
        }
        memcpy(p, amps_scene_mesh(S)->xyz + 3 * v, sizeof(p));
        arm(k);
        s = amps_scene_cut(&c, S, v, p, nrm, &vc);
        disarm();
        if (s != AMPS_ERR_OOM) {
            CHECK(s == AMPS_OK || s == AMPS_WARN_NOOP, "growth: the cut: %s", c.msg);
            amps_scene_free(&c, S);
            t_al.live = 0;
            break;
        }
        points++;
        CHECK(amps_scene_mesh(S)->nnode == nn && amps_scene_mesh(S)->E[t10] == E0 &&
                      amps_scene_cancel_batch(&c, S) == AMPS_ERR_STATE,
              "growth: cut fail at %ld: the batch was not undone (E %g, was %g)", k, amps_scene_mesh(S)->E[t10], E0);
        amps_scene_free(&c, S);
        CHECK(t_al.live == 0, "growth: cut fail at %ld: %ld live", k, t_al.live);
        t_al.live = 0;
    }
    CHECK(points > 0, "growth: no allocation failed");
    printf("  a cut growing the mesh in a batch: %ld allocation points\n", points);
    /* the first corotational step failing, then made again */
    for (k = -1, points = 0; k < 2000; k++) {
        amps_status s;
        S = stroke_scene(&c);
        CHECK(amps_scene_dynamics(&c, S, 0.05, 0.1, 0.02) == AMPS_OK && amps_scene_corotational(&c, S, 1) == AMPS_OK,
              "corotational scene: %s", c.msg);
        arm(k);
        s = amps_scene_step(&c, S, 1);
        disarm();
        if (k >= 0 && s == AMPS_OK) {
            amps_scene_free(&c, S);
            t_al.live = 0;
            break;
        }
        if (k >= 0) {
            points++;
            CHECK(s == AMPS_ERR_OOM, "corotational step fail at %ld: status %d", k, (int)s);
            s = amps_scene_step(&c, S, 1);
        }
        CHECK(s == AMPS_OK && amps_scene_step(&c, S, 1) == AMPS_OK, "corotational step fail at %ld: again: %s", k,
              c.msg);
        nn = 3 * amps_scene_mesh(S)->nnode;
        if (k < 0) memcpy(u, amps_scene_displacements(S), sizeof(double) * (size_t)nn);
        else
            CHECK(t_reldiff((int)nn, amps_scene_displacements(S), u) <= 1e-12,
                  "corotational step fail at %ld: differs %.2e", k, t_reldiff((int)nn, amps_scene_displacements(S), u));
        amps_scene_free(&c, S);
        CHECK(t_al.live == 0, "corotational step fail at %ld: %ld live", k, t_al.live);
        t_al.live = 0;
    }
    printf("  the first corotational step: %ld allocation points\n", points);
    free(ref);
    free(u);
}

/* ---------------------------------- readers ---------------------------------- */

static void test_readers(void) {
    static const char node[] = "5 3 0 0\n0 0 0 0\n1 1 0 0\n2 0 1 0\n3 0 0 1\n4 1 1 1\n";
    static const char ele[] = "2 4 0\n0 0 1 2 3\n1 1 2 3 4\n";
    static const char msh2[] =
            "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n5\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n5 1 1 1\n$EndNodes\n"
            "$Elements\n3\n1 15 2 0 1 1\n2 4 2 0 1 1 2 3 4\n3 4 2 0 1 2 3 4 5\n$EndElements\n";
    static const char msh4[] =
            "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n1 5 1 5\n3 1 0 5\n1\n2\n3\n4\n5\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n1 1 1\n$EndNodes\n"
            "$Elements\n1 2 1 2\n3 1 4 2\n1 1 2 3 4\n2 2 3 4 5\n$EndElements\n";
    static const char medit[] =
            "MeshVersionFormatted 2\nDimension 3\nVertices\n5\n0 0 0 0\n1 0 0 0\n0 1 0 0\n0 0 1 0\n1 1 1 0\n"
            "Tetrahedra\n2\n1 2 3 4 0\n2 3 4 5 0\nEnd\n";
    int r;
    for (r = 0; r < 4; r++) {
        long k;
        int fails = 0;
        for (k = 0;; k++) {
            amps_ctx c;
            amps_mesh *m;
            amps_ctx_init(&c);
            c.alloc_user = &t_al;
            arm(k);
            if (r == 0)
                m = amps_mesh_read_tetgen_mem(&c, node, sizeof(node) - 1, "a.node", ele, sizeof(ele) - 1, "a.ele");
            else if (r == 1) m = amps_mesh_read_gmsh_mem(&c, msh2, sizeof(msh2) - 1, "a.msh");
            else if (r == 2) m = amps_mesh_read_gmsh_mem(&c, msh4, sizeof(msh4) - 1, "b.msh");
            else m = amps_mesh_read_medit_mem(&c, medit, sizeof(medit) - 1, "a.mesh");
            disarm();
            if (m) {
                CHECK(m->nnode == 5 && m->ntet == 2, "reader %d: %ld nodes %ld tets", r, (long)m->nnode, (long)m->ntet);
                amps_mesh_free(&c, m);
                CHECK(t_al.live == 0, "reader %d: %ld live", r, t_al.live);
                break;
            }
            points++;
            fails++;
            if (c.status != AMPS_ERR_OOM || k > 2000) {
                CHECK(0, "reader %d: %s", r, c.msg);
                break;
            }
            CHECK(c.status == AMPS_ERR_OOM && t_al.live == 0, "reader %d fail at %ld: status %d (%s), live %ld", r, k,
                  (int)c.status, c.msg, t_al.live);
            t_al.live = 0;
        }
        CHECK(fails > 0, "reader %d never allocated", r);
        printf("  reader %d: %d allocation points\n", r, fails);
    }
}

int main(void) {
    amps_ctx c;
    amps_mesh *m;
    amps_int *dof, n;
    unsigned char *fixed;
    amps_ctx_init(&c); /* uncounted */
    m = amps_mesh_beam(&c, 4);
    base_K = t_fixed_stiffness(&c, m, &fixed, &dof, &n);
    base_F = amps_analyze(&c, base_K, AMPS_UPPER, NULL);
    CHECK(base_F && amps_factorize(&c, base_F, base_K) == AMPS_OK, "base factor");
    test_engine();
    test_scene();
    test_stroke_oom();
    test_readers();
    printf("  allocation failures injected: %ld\n", points);
    amps_factor_free(&c, base_F);
    amps_csc_free(&c, base_K);
    amps_mesh_free(&c, m);
    free(fixed);
    free(dof);
    return amps_t_end("test_alloc_update");
}
