/* Rendering data, picking and selection of the scene: after every cut of random sequences (a brick
   and a TetGen mesh) the incremental boundary triangles equal a from-scratch extraction
   (amps_mesh_boundary, itself checked against a sort of all faces), are oriented outward
   (signed volumes; the divergence theorem gives the mesh volume) and the change record matches
   the mesh (new nodes, moved tets, added / removed ids); the face hook after a tet leaves the
   incidence; the node-to-equation map and the watched positions; the nearest node equals brute
   force; fixing by box / sphere equals fixing the nodes brute force selects, with displacements
   equal to CHOLMOD's; bad inputs are clear errors that change nothing; the reader messages. */
#include "t_alloc.h"
#define AMPS_IMPLEMENTATION
#include "amps.h"
#include "amps_test.h"
#include "cholmod_ref.h"
#include "scene_ref.h"
#include <string.h>

/* ---- boundary from scratch, independently: all faces sorted by their node triple ---- */

typedef struct tface {
    amps_int k[3], fc;
} tface;

static int tface_cmp(const void *a, const void *b) {
    const tface *x = (const tface *)a, *y = (const tface *)b;
    int q;
    for (q = 0; q < 3; q++)
        if (x->k[q] != y->k[q]) return x->k[q] < y->k[q] ? -1 : 1;
    return 0;
}

/* Boundary faces (4t+f) of m in ascending order into out; returns their number. */
static int brute_boundary(const amps_mesh *m, amps_int *out) {
    tface *f = (tface *)malloc(sizeof(tface) * 4 * (size_t)m->ntet);
    amps_int *fl = (amps_int *)malloc(sizeof(amps_int) * 4 * (size_t)m->ntet);
    int t, q, n = 0, k, nb = 0;
    for (t = 0; t < m->ntet; t++)
        for (q = 0; q < 4; q++) {
            amps_int a[3], x;
            int j = 0, r;
            for (r = 0; r < 4; r++)
                if (r != q) a[j++] = m->tet[4 * t + r];
            if (a[0] > a[1]) x = a[0], a[0] = a[1], a[1] = x;
            if (a[1] > a[2]) x = a[1], a[1] = a[2], a[2] = x;
            if (a[0] > a[1]) x = a[0], a[0] = a[1], a[1] = x;
            memcpy(f[n].k, a, sizeof(a));
            f[n++].fc = 4 * t + q;
        }
    qsort(f, (size_t)n, sizeof(tface), tface_cmp);
    for (k = 0; k < n; k++)
        if (!((k > 0 && !tface_cmp(f + k, f + k - 1)) || (k + 1 < n && !tface_cmp(f + k, f + k + 1))))
            fl[nb++] = f[k].fc;
    for (k = 1; k < nb; k++) { /* insertion sort by face */
        amps_int v = fl[k];
        int j = k;
        while (j > 0 && fl[j - 1] > v) fl[j] = fl[j - 1], j--;
        fl[j] = v;
    }
    memcpy(out, fl, sizeof(amps_int) * (size_t)nb);
    free(f);
    free(fl);
    return nb;
}

static double orient(const double *x, amps_int a, amps_int b, amps_int c, amps_int d) {
    double e1[3], e2[3], e3[3];
    int q;
    for (q = 0; q < 3; q++) {
        e1[q] = x[3 * b + q] - x[3 * a + q];
        e2[q] = x[3 * c + q] - x[3 * a + q];
        e3[q] = x[3 * d + q] - x[3 * a + q];
    }
    return (e1[1] * e2[2] - e1[2] * e2[1]) * e3[0] + (e1[2] * e2[0] - e1[0] * e2[2]) * e3[1] +
           (e1[0] * e2[1] - e1[1] * e2[0]) * e3[2];
}

/* amps_mesh_boundary against brute force; outward orientation; the enclosed volume. */
static void check_scratch(amps_ctx *ctx, const amps_mesh *m, const char *what) {
    amps_int nb = amps_mesh_boundary(ctx, m, NULL, NULL), k, q;
    amps_int *tri = (amps_int *)malloc(sizeof(amps_int) * 3 * (nb + 1)),
             *fc = (amps_int *)malloc(sizeof(amps_int) * (nb + 1));
    amps_int *ref = (amps_int *)malloc(sizeof(amps_int) * 4 * (size_t)m->ntet);
    amps_int nr = brute_boundary(m, ref);
    double vol = 0, enc = 0;
    int bad_or = 0, bad_nodes = 0;
    CHECK(amps_mesh_boundary(ctx, m, tri, fc) == nb && nb == nr, "%s: %ld boundary triangles, brute force %ld", what,
          (long)nb, (long)nr);
    for (k = 0; k < nb && k < nr; k++)
        CHECK(fc[k] == ref[k], "%s: triangle %ld face %ld vs %ld", what, (long)k, (long)fc[k], (long)ref[k]);
    for (k = 0; k < nb; k++) {
        amps_int t = fc[k] / 4, f = fc[k] % 4, d = m->tet[4 * t + f];
        int hits = 0;
        for (q = 0; q < 4; q++)
            if (q != f)
                hits += m->tet[4 * t + q] == tri[3 * k] || m->tet[4 * t + q] == tri[3 * k + 1] ||
                        m->tet[4 * t + q] == tri[3 * k + 2];
        bad_nodes += hits != 3;
        bad_or += !(orient(m->xyz, tri[3 * k], tri[3 * k + 1], tri[3 * k + 2], d) < 0);
        { /* x0 . ((x1 - x0) x (x2 - x0)) / 6 = x0 . (x1 x x2) / 6 */
            const double *a = m->xyz + 3 * tri[3 * k], *b = m->xyz + 3 * tri[3 * k + 1],
                         *c = m->xyz + 3 * tri[3 * k + 2];
            enc += (a[0] * (b[1] * c[2] - b[2] * c[1]) + a[1] * (b[2] * c[0] - b[0] * c[2]) +
                    a[2] * (b[0] * c[1] - b[1] * c[0])) /
                   6;
        }
    }
    for (k = 0; k < m->ntet; k++) {
        double X[12], G[12];
        amps_mesh_tet_coords(m, k, X);
        vol += fabs(amps_tet_gradients(X, G));
    }
    CHECK(bad_nodes == 0, "%s: %d triangles not on their face", what, bad_nodes);
    CHECK(bad_or == 0, "%s: %d triangles not oriented outward", what, bad_or);
    CHECK(fabs(enc - vol) <= 1e-10 * vol, "%s: enclosed volume %.15g vs mesh volume %.15g", what, enc, vol);
    free(tri);
    free(fc);
    free(ref);
}

/* ---- the scene's incremental boundary and change record against the mesh ---- */

typedef struct mirror {
    amps_int *tri, *face, n, cap; /* what a renderer keeps by id */
    amps_int *tet0, ntet;         /* the tets at the last take */
    amps_int nnode0;
} mirror;

static void mirror_snapshot(mirror *w, const amps_mesh *m) {
    w->ntet = m->ntet;
    w->tet0 = (amps_int *)realloc(w->tet0, sizeof(amps_int) * 4 * m->ntet);
    memcpy(w->tet0, m->tet, sizeof(amps_int) * 4 * m->ntet);
    w->nnode0 = m->nnode;
}

/* The whole table into the mirror (what a renderer does on a reset). */
static void mirror_load(mirror *w, const amps_scene *S) {
    const amps_int *tri, *face;
    amps_int nid = amps_scene_boundary(S, &tri, &face);
    w->cap = nid;
    w->tri = (amps_int *)realloc(w->tri, sizeof(amps_int) * 3 * (nid + 1));
    w->face = (amps_int *)realloc(w->face, sizeof(amps_int) * (nid + 1));
    memcpy(w->tri, tri, sizeof(amps_int) * 3 * nid);
    memcpy(w->face, face, sizeof(amps_int) * nid);
    mirror_snapshot(w, amps_scene_mesh(S));
}

/* Takes the changes, applies them to the mirror and compares with the mesh and the scene. */
static void take_and_check(amps_ctx *ctx, amps_scene *S, mirror *w, const char *what, int step) {
    const amps_mesh *m = amps_scene_mesh(S);
    amps_scene_changes c;
    const amps_int *tri, *face;
    amps_int nid, k, q, live = 0, nb;
    amps_int *fc = (amps_int *)malloc(sizeof(amps_int) * 4 * (size_t)m->ntet), *byface;
    int bad = 0;
    CHECK(amps_scene_take_changes(ctx, S, &c) == AMPS_OK, "%s step %d: take: %s", what, step, ctx->msg);
    nid = amps_scene_boundary(S, &tri, &face);
    if (nid > w->cap) {
        w->tri = (amps_int *)realloc(w->tri, sizeof(amps_int) * 3 * nid);
        w->face = (amps_int *)realloc(w->face, sizeof(amps_int) * nid);
        for (k = w->cap; k < nid; k++) w->face[k] = -1;
        w->cap = nid;
    }
    if (c.reset) {
        for (k = 0; k < w->cap; k++) w->face[k] = -1;
        CHECK(c.nremoved == 0, "%s: reset with removals", what);
    } else { /* new nodes and moved tets against the snapshot */
        unsigned char *mv = (unsigned char *)calloc((size_t)m->ntet, 1);
        int nmv = 0;
        CHECK(c.nnew == m->nnode - w->nnode0, "%s step %d: %ld new nodes, mesh grew by %ld", what, step, (long)c.nnew,
              (long)(m->nnode - w->nnode0));
        for (k = 0; k < c.nnew; k++)
            CHECK(c.new_nodes[k] == w->nnode0 + k, "%s step %d: new node %ld", what, step, (long)k);
        for (k = 0; k < c.nmoved; k++) {
            CHECK(c.moved_tets[k] >= 0 && c.moved_tets[k] < m->ntet && !mv[c.moved_tets[k]],
                  "%s: moved tet listed twice", what);
            mv[c.moved_tets[k]] = 1;
        }
        for (k = 0; k < m->ntet; k++) { /* live tets (a removed one may keep a copy's node unlisted) */
            int diff = memcmp(m->tet + 4 * k, w->tet0 + 4 * k, 4 * sizeof(amps_int)) != 0;
            if (m->removed && m->removed[k]) {
                nmv += mv[k]; /* listed or not */
                continue;
            }
            nmv += diff;
            if (diff != mv[k]) bad++;
        }
        CHECK(bad == 0 && nmv == c.nmoved, "%s step %d: moved tets: %d wrong, %d changed, %ld listed", what, step, bad,
              nmv, (long)c.nmoved);
        free(mv);
        bad = 0;
        for (k = 0; k < c.nremoved; k++) {
            amps_int id = c.removed[k];
            if (id < 0 || id >= w->cap || w->face[id] < 0) bad++;
            else w->face[id] = -1;
        }
        CHECK(bad == 0, "%s step %d: %d removed ids not shown", what, step, bad);
    }
    bad = 0;
    for (k = 0; k < c.nadded; k++) {
        amps_int id = c.added[k];
        if (id < 0 || id >= nid || w->face[id] >= 0) {
            bad++;
            continue;
        }
        w->face[id] = face[id];
        memcpy(w->tri + 3 * id, tri + 3 * id, 3 * sizeof(amps_int));
    }
    CHECK(bad == 0, "%s step %d: %d added ids already shown or out of range", what, step, bad);
    bad = 0;
    for (k = 0; k < w->cap; k++) { /* the mirror equals the scene's table */
        amps_int sf = k < nid ? face[k] : -1;
        if (w->face[k] != sf) bad++;
        else if (sf >= 0)
            for (q = 0; q < 3; q++) bad += w->tri[3 * k + q] != tri[3 * k + q];
        if (sf >= 0) live++;
    }
    CHECK(bad == 0, "%s step %d: the renderer's copy differs from the scene at %d ids", what, step, bad);
    nb = amps_mesh_boundary(ctx, m, NULL, fc);
    byface = (amps_int *)malloc(sizeof(amps_int) * 4 * (size_t)m->ntet);
    for (k = 0; k < 4 * m->ntet; k++) byface[k] = -1;
    for (k = 0; k < nid; k++)
        if (face[k] >= 0) byface[face[k]] = k;
    bad = 0;
    for (k = 0; k < nb; k++) {
        amps_int id = byface[fc[k]], t3[3];
        if (id < 0) {
            bad++;
            continue;
        }
        amps__face_tri(m, fc[k] / 4, (int)(fc[k] % 4), t3);
        for (q = 0; q < 3; q++) bad += t3[q] != tri[3 * id + q];
    }
    CHECK(live == nb && bad == 0, "%s step %d: incremental %ld triangles, from scratch %ld, %d differ", what, step,
          (long)live, (long)nb, bad);
    mirror_snapshot(w, m);
    free(fc);
    free(byface);
}

static amps_mesh *read_box(amps_ctx *ctx) {
    char node[512], ele[512];
    const char *f = __FILE__, *sl = strrchr(f, '/');
    int n = sl ? (int)(sl - f + 1) : 0;
    snprintf(node, sizeof(node), "%.*sdata/box.node", n, f);
    snprintf(ele, sizeof(ele), "%.*sdata/box.ele", n, f);
    return amps_mesh_read_tetgen(ctx, node, ele);
}

/* A random node on a random plane through it, with some takes skipped (changes accumulate). */
static void cut_sequence(amps_mesh *m, int ncut, int prepared, const char *what) {
    amps_ctx ctx;
    amps_scene *S;
    mirror w;
    int step, cuts = 0;
    amps_ctx_init(&ctx);
    memset(&w, 0, sizeof(w));
    check_scratch(&ctx, m, what);
    S = amps_scene_create(&ctx, m, NULL);
    CHECK(amps_scene_fix_where(&ctx, S, 2, AMPS_LT, 0.3, NULL) == AMPS_OK, "fix");
    if (prepared) CHECK(amps_scene_prepare(&ctx, S) == AMPS_OK, "%s: prepare: %s", what, ctx.msg);
    take_and_check(&ctx, S, &w, what, 0);
    for (step = 1; step <= ncut; step++) {
        const amps_mesh *mm = amps_scene_mesh(S);
        amps_int v = (amps_int)t_int(mm->nnode), vc;
        double nrm[3], p[3];
        amps_status s;
        int k;
        for (k = 0; k < 3; k++) {
            nrm[k] = t_unif() - 0.5;
            p[k] = mm->xyz[3 * v + k] + 0.01 * (t_unif() - 0.5);
        }
        s = amps_scene_cut(&ctx, S, v, p, nrm, &vc);
        CHECK(s == AMPS_OK || s == AMPS_WARN_NOOP || s == AMPS_ERR_SINGULAR_UPDATE, "%s cut %d: %s", what, step,
              ctx.msg);
        cuts += s == AMPS_OK;
        if (t_int(3) != 0 || step == ncut) take_and_check(&ctx, S, &w, what, step);
    }
    check_scratch(&ctx, amps_scene_mesh(S), what);
    CHECK(cuts > ncut / 4, "%s: only %d of %d cuts went through", what, cuts, ncut);
    if (prepared) CHECK(amps_scene_solve(&ctx, S) == AMPS_OK, "%s: solve after the cuts: %s", what, ctx.msg);
    { /* two takes in a row: the second reports nothing */
        amps_scene_changes c;
        amps_scene_take_changes(&ctx, S, &c);
        CHECK(amps_scene_take_changes(&ctx, S, &c) == AMPS_OK && !c.reset && c.nadded == 0 && c.nremoved == 0 &&
                      c.nnew == 0 && c.nmoved == 0,
              "%s: a second take reports changes", what);
    }
    amps_scene_free(&ctx, S);
    free(w.tri);
    free(w.face);
    free(w.tet0);
}

/* A batch undone at its commit (its cuts split the column, its releases leave the top loose):
   the change record lists no moved tet and no new node. During a two-phase commit
   amps_scene_ndof counts the batch's equations. */
static void test_undone_batch(void) {
    amps_ctx ctx;
    amps_scene *S;
    mirror w;
    amps_int k, vc;
    double u0[3] = {0, 0, 0}, p[3] = {0.5, 0.5, 1}, n[3] = {0, 0, 1};
    amps_ctx_init(&ctx);
    memset(&w, 0, sizeof(w));
    S = amps_scene_create(&ctx, amps_mesh_grid(&ctx, 2, 2, 3, 1, 1, 1), NULL);
    CHECK(amps_scene_fix_where(&ctx, S, 2, AMPS_LT, 0.5, NULL) == AMPS_OK, "undone: fix");
    for (k = 8; k < 12; k++) amps_scene_pin(&ctx, S, k, u0);
    CHECK(amps_scene_solve(&ctx, S) == AMPS_OK, "undone: solve: %s", ctx.msg);
    take_and_check(&ctx, S, &w, "undone batch", 0);
    CHECK(amps_scene_begin_batch(&ctx, S) == AMPS_OK, "undone: begin");
    for (k = 4; k < 8; k++) amps_scene_cut(&ctx, S, k, p, n, &vc);
    for (k = 8; k < 12; k++) amps_scene_release(&ctx, S, k);
    CHECK(amps_scene_commit(&ctx, S) == AMPS_ERR_SINGULAR_UPDATE, "undone: the loose batch was committed");
    take_and_check(&ctx, S, &w, "undone batch", 1);
    amps_scene_free(&ctx, S);
    { /* amps_scene_ndof during a two-phase commit */
        amps_int d[3], nd;
        S = amps_scene_create(&ctx, amps_mesh_grid(&ctx, 5, 5, 4, 1, 1, 1), NULL);
        amps_scene_fix_where(&ctx, S, 2, AMPS_LT, 0.5, NULL);
        CHECK(amps_scene_prepare(&ctx, S) == AMPS_OK && amps_scene_begin_batch(&ctx, S) == AMPS_OK &&
                      amps_scene_cut(&ctx, S, 62, amps_scene_mesh(S)->xyz + 3 * 62, n, &vc) == AMPS_OK &&
                      amps_scene_commit_begin(&ctx, S) == AMPS_OK,
              "ndof: batch: %s", ctx.msg);
        nd = amps_scene_ndof(S);
        CHECK(amps_scene_node_dofs(&ctx, S, vc, d) == AMPS_OK && d[0] >= 0 && d[2] < nd,
              "ndof during a two-phase commit: %ld, the copy's equations %ld..%ld", (long)nd, (long)d[0], (long)d[2]);
        amps_scene_commit_run(S);
        CHECK(amps_scene_commit_end(&ctx, S) == AMPS_OK && amps_scene_ndof(S) == nd, "ndof after the commit");
        amps_scene_free(&ctx, S);
    }
    free(w.tri);
    free(w.face);
    free(w.tet0);
}

/* Random batches of cuts (also of the copies) and removals with node separation, cancelled or
   committed (with the top pins released, a commit a mechanism refusal may undo), with takes in
   between at random: after each take the
   change record matches the mesh (the moved tets are exactly the live tets whose nodes changed
   since the last take) and the boundary equals the mesh's. */
static void test_batch_records(unsigned long long seed) {
    amps_ctx ctx;
    amps_scene *S;
    mirror w;
    amps_int k, vc, top[3] = {-1, -1, -1};
    int round, nsep = 0, ncancel = 0, nrefused = 0, ntop = 0;
    double u0[3] = {0, 0, 0};
    amps_ctx_init(&ctx);
    memset(&w, 0, sizeof(w));
    t_seed(seed);
    S = amps_scene_create(&ctx, amps_mesh_brick(&ctx, 3), NULL);
    CHECK(amps_scene_fix_where(&ctx, S, 2, AMPS_LT, 0.01, NULL) == AMPS_OK, "records: fix");
    for (k = 0; k < amps_scene_mesh(S)->nnode && ntop < 3; k++) /* three pins on top: releasing them is refused */
        if (amps_scene_mesh(S)->xyz[3 * k + 2] > 1.99 && (ntop == 0 || k > top[ntop - 1] + 2)) top[ntop++] = k;
    for (k = 0; k < ntop; k++) amps_scene_pin(&ctx, S, top[k], u0);
    CHECK(amps_scene_solve(&ctx, S) == AMPS_OK, "records: solve: %s", ctx.msg);
    take_and_check(&ctx, S, &w, "records", 0);
    for (round = 1; round <= 40; round++) {
        const amps_mesh *m = amps_scene_mesh(S);
        int nop = 1 + t_int(5), op, how = t_int(3);
        amps_status st;
        CHECK(amps_scene_begin_batch(&ctx, S) == AMPS_OK, "records: begin: %s", ctx.msg);
        for (op = 0; op < nop; op++) {
            if (t_int(2)) { /* a cut of a random node (copies included) */
                amps_int v = t_int((int)m->nnode);
                double nrm[3] = {t_unif() - 0.5, t_unif() - 0.5, t_unif() - 0.5};
                if (amps_mesh_degree(m, v) > 0) (void)amps_scene_cut(&ctx, S, v, m->xyz + 3 * v, nrm, &vc);
            } else { /* 1-3 random live tets, separating */
                amps_int t[3];
                amps_mesh_removal r;
                int q, n = 1 + t_int(3);
                for (q = 0; q < n; q++) {
                    do t[q] = t_int((int)m->ntet);
                    while (m->removed[t[q]]);
                    if (q > 0 && (t[q] == t[0] || (q == 2 && t[2] == t[1]))) n = q;
                }
                if (amps_scene_remove(&ctx, S, n, t, AMPS_SINGULAR_SEPARATE, &r) == AMPS_OK) nsep += (int)r.nsep;
            }
        }
        if (how == 0) {
            CHECK(amps_scene_cancel_batch(&ctx, S) == AMPS_OK, "records: cancel: %s", ctx.msg);
            ncancel++;
        } else if (how == 1 && ntop == 3) { /* the top pins released */
            for (k = 0; k < 3; k++) amps_scene_release(&ctx, S, top[k]);
            st = amps_scene_commit(&ctx, S);
            nrefused += st == AMPS_ERR_SINGULAR_UPDATE;
            CHECK(st == AMPS_OK || st == AMPS_ERR_SINGULAR_UPDATE, "records: commit: %s", ctx.msg);
            if (st == AMPS_OK) ntop = 0; /* released for good */
        } else {
            st = amps_scene_commit(&ctx, S);
            CHECK(st == AMPS_OK || st == AMPS_ERR_SINGULAR_UPDATE, "records: commit: %s", ctx.msg);
        }
        CHECK(amps_mesh_check(&ctx, m) == AMPS_OK, "records round %d: mesh: %s", round, ctx.msg);
        if (t_int(10) < 7 || round == 40) take_and_check(&ctx, S, &w, "records", round);
    }
    printf("  batch records (seed %llu): %d separations, %d cancelled, %d refused\n", seed, nsep, ncancel, nrefused);
    amps_scene_free(&ctx, S);
    free(w.tri);
    free(w.face);
    free(w.tet0);
}

/* The face hook after tets leave the incidence lists (an element removal): the faces they
   exposed appear, theirs disappear. */
static void test_removed_hook(void) {
    amps_ctx ctx;
    amps_scene *S;
    amps_mesh *m;
    mirror w;
    amps_int rm[3], k, j;
    int r;
    amps_ctx_init(&ctx);
    memset(&w, 0, sizeof(w));
    S = amps_scene_create(&ctx, amps_mesh_brick(&ctx, 3), NULL);
    take_and_check(&ctx, S, &w, "removal", 0);
    m = (amps_mesh *)amps_scene_mesh(S);
    rm[0] = 0;           /* a corner tet */
    rm[1] = m->ntet / 2; /* an interior one */
    rm[2] = m->ntet / 2 + 1;
    for (r = 0; r < 3; r++) {
        int q;
        for (q = 0; q < 4; q++) { /* take tet rm[r] out of the incidence of its nodes */
            amps_int v = m->tet[4 * rm[r] + q], *inc = m->inc + m->inc_ptr[v], n = m->inc_len[v];
            for (k = 0, j = 0; k < n; k++)
                if (inc[k] != rm[r]) inc[j++] = inc[k];
            m->inc_len[v] = j;
        }
        amps__scene_faces_changed(&ctx, S, rm + r, 1);
        if (r != 1) take_and_check(&ctx, S, &w, "removal", r + 1);
    }
    amps_scene_free(&ctx, S);
    free(w.tri);
    free(w.face);
    free(w.tet0);
}

/* ---- node map, watched positions ---- */

static void test_node_map(void) {
    amps_ctx ctx;
    amps_scene *S;
    amps_int dof[3], v, nw, k;
    const amps_int *wn;
    const double *x;
    int bad = 0;
    double p[3] = {0.5, 0.5, 1.0}, nrm[3] = {0, 0, 1}, f[3] = {0.1, 0.2, -0.3}, *pos;
    amps_int watch[2], vc;
    amps_ctx_init(&ctx);
    S = amps_scene_create(&ctx, amps_mesh_brick(&ctx, 2), NULL);
    amps_scene_fix_where(&ctx, S, 2, AMPS_LT, 0.1, NULL);
    CHECK(amps_scene_node_dofs(&ctx, S, 0, dof) == AMPS_ERR_STATE, "node dofs before the factorization");
    watch[0] = 9 * 2 + 4; /* the node at (0.5, 0.5, 1) */
    watch[1] = 9 * 4 + 8;
    CHECK(amps_scene_watch(&ctx, S, 2, watch) == AMPS_OK, "watch");
    amps_scene_force(&ctx, S, 9 * 4 + 8, f);
    CHECK(amps_scene_cut(&ctx, S, watch[0], p, nrm, &vc) == AMPS_OK && vc >= 0, "cut: %s", ctx.msg);
    CHECK(amps_scene_solve(&ctx, S) == AMPS_OK, "solve: %s", ctx.msg);
    x = amps_update_solution(amps_scene_engine(S));
    for (v = 0; v < amps_scene_mesh(S)->nnode; v++) {
        int d;
        CHECK(amps_scene_node_dofs(&ctx, S, v, dof) == AMPS_OK, "node dofs");
        for (d = 0; d < 3; d++) {
            if (amps_scene_is_fixed(S, v)) bad += dof[d] != -1;
            else
                bad += dof[d] < 0 || dof[d] >= amps_scene_ndof(S) ||
                       x[dof[d]] != amps_scene_displacements(S)[3 * v + d];
        }
    }
    CHECK(bad == 0, "node dofs disagree with the solution at %d DOFs", bad);
    CHECK(amps_scene_node_dofs(&ctx, S, vc, dof) == AMPS_OK && dof[0] >= amps_scene_ndof(S) - 3,
          "the copy's equations");
    CHECK(amps_scene_node_dofs(&ctx, S, -1, dof) == AMPS_ERR_INDEX, "node dofs out of range");
    CHECK(amps_scene_node_dofs(&ctx, S, amps_scene_mesh(S)->nnode, dof) == AMPS_ERR_INDEX, "node dofs out of range");
    wn = amps_scene_watched(S, &nw);
    CHECK(nw == 3 && wn && wn[2] == vc, "watched: %ld nodes", (long)nw);
    f[0] = -0.4;
    amps_scene_force(&ctx, S, 9 * 4 + 8, f);
    CHECK(amps_scene_solve_watched(&ctx, S) == AMPS_OK, "solve watched: %s", ctx.msg);
    pos = (double *)malloc(sizeof(double) * 3 * nw);
    CHECK(amps_scene_watched_positions(&ctx, S, pos) == AMPS_OK, "watched positions");
    for (k = 0; k < nw; k++) {
        double q[3];
        amps_scene_positions(&ctx, S, 1, wn + k, q);
        CHECK(q[0] == pos[3 * k] && q[1] == pos[3 * k + 1] && q[2] == pos[3 * k + 2], "watched position %ld", (long)k);
    }
    CHECK(amps_scene_solve(&ctx, S) == AMPS_OK, "solve");
    for (k = 0; k < nw; k++) {
        double q[3];
        amps_scene_positions(&ctx, S, 1, wn + k, q);
        CHECK(fabs(q[0] - pos[3 * k]) + fabs(q[1] - pos[3 * k + 1]) + fabs(q[2] - pos[3 * k + 2]) <= 1e-12,
              "watched position %ld against the full solve", (long)k);
    }
    CHECK(amps_scene_is_pinned(S, 3) == 0 && amps_scene_is_fixed(S, 0) == 1 && amps_scene_is_fixed(S, -1) == 0 &&
                  amps_scene_is_fixed(NULL, 0) == 0,
          "state queries");
    amps_scene_pin(&ctx, S, 3 + 9 * 3, p);
    CHECK(amps_scene_is_pinned(S, 3 + 9 * 3) == 1, "pinned");
    CHECK(amps_scene_node_dofs(&ctx, S, 3 + 9 * 3, dof) == AMPS_OK && dof[0] >= 0, "a pinned node keeps equations");
    free(pos);
    amps_scene_free(&ctx, S);
}

/* ---- picking ---- */

static amps_int brute_nearest(const amps_mesh *m, const double *p) {
    amps_int v, best = -1;
    double bd = HUGE_VAL;
    for (v = 0; v < m->nnode; v++) {
        const double *x = m->xyz + 3 * v;
        double d = (x[0] - p[0]) * (x[0] - p[0]) + (x[1] - p[1]) * (x[1] - p[1]) + (x[2] - p[2]) * (x[2] - p[2]);
        if (m->inc_len[v] > 0 && d < bd) bd = d, best = v;
    }
    return best;
}

static void test_nearest(amps_mesh *m, const char *what) {
    amps_ctx ctx;
    amps_scene *S;
    int k, bad = 0, round;
    amps_int v;
    double p[3], nan3[3] = {0, 0, 0};
    amps_ctx_init(&ctx);
    S = amps_scene_create(&ctx, m, NULL);
    for (round = 0; round < 2; round++) {
        const amps_mesh *mm = amps_scene_mesh(S);
        for (k = 0; k < 400; k++) {
            int q;
            double spread = k < 300 ? 1.2 : 6.0; /* inside and around, then far outside */
            if (k % 5 == 0) {                    /* exactly at a node: the smallest live index there */
                amps_int u = (amps_int)t_int(mm->nnode);
                memcpy(p, mm->xyz + 3 * u, sizeof(p));
            } else
                for (q = 0; q < 3; q++) p[q] = spread * (t_unif() - 0.5) + (q == 2 ? 1.0 : 0.5);
            CHECK(amps_scene_nearest_node(&ctx, S, p, &v) == AMPS_OK, "%s: nearest: %s", what, ctx.msg);
            bad += v != brute_nearest(mm, p);
        }
        CHECK(bad == 0, "%s round %d: %d nearest nodes differ from brute force", what, round, bad);
        for (k = 0; k < 30; k++) { /* copies: cuts at random nodes */
            amps_int u = (amps_int)t_int(mm->nnode);
            double nrm[3];
            int q;
            for (q = 0; q < 3; q++) nrm[q] = t_unif() - 0.5;
            amps_scene_cut(&ctx, S, u, mm->xyz + 3 * u, nrm, NULL);
        }
    }
    nan3[1] = NAN;
    CHECK(amps_scene_nearest_node(&ctx, S, nan3, &v) == AMPS_ERR_VALUE && v == -1 && strstr(ctx.msg, "NaN"),
          "nearest at NaN: %s", ctx.msg);
    CHECK(amps_scene_nearest_node(&ctx, NULL, p, &v) == AMPS_ERR_ARG, "nearest NULL scene");
    { /* beyond 1e150 the squared distances would overflow: refused, not answered -1 */
        double far[3] = {1e155, -1e155, 1e155}, a[3] = {-1e154, 0, 0};
        CHECK(amps_scene_nearest_node(&ctx, S, far, &v) == AMPS_ERR_VALUE && v == -1, "nearest beyond 1e150: %ld",
              (long)v);
        CHECK(amps_scene_nodes_near_segment(&ctx, S, a, far, 1.0, NULL, 0) == AMPS_ERR_VALUE,
              "segment beyond 1e150 accepted");
        far[0] = far[2] = 1e149;
        far[1] = -1e149;
        CHECK(amps_scene_nearest_node(&ctx, S, far, &v) == AMPS_OK && v >= 0, "nearest at 1e149: %s", ctx.msg);
    }
    amps_scene_free(&ctx, S);
}

/* ---- fixing by region ---- */

static void fix_region_case(int ball, const char *what) {
    amps_ctx ctx;
    amps_scene *A, *B;
    const amps_mesh *m;
    amps_int *list, nl = 0, cnt = -1, v, load;
    double lo[3] = {-0.1, -0.1, -0.1}, hi[3] = {1.1, 0.6, 0.45}, c[3] = {0.5, 0.5, 0}, r = 0.55, f[3] = {0, 0.2, -0.5};
    double *u;
    shadow w;
    int bad = 0;
    amps_ctx_init(&ctx);
    A = amps_scene_create(&ctx, amps_mesh_brick(&ctx, 4), NULL);
    B = amps_scene_create(&ctx, amps_mesh_brick(&ctx, 4), NULL);
    m = amps_scene_mesh(A);
    list = (amps_int *)malloc(sizeof(amps_int) * m->nnode);
    for (v = 0; v < m->nnode; v++) {
        const double *x = m->xyz + 3 * v;
        int in = ball ? (x[0] - c[0]) * (x[0] - c[0]) + (x[1] - c[1]) * (x[1] - c[1]) + (x[2] - c[2]) * (x[2] - c[2]) <=
                                 r * r
                      : x[0] >= lo[0] && x[0] <= hi[0] && x[1] >= lo[1] && x[1] <= hi[1] && x[2] >= lo[2] &&
                                 x[2] <= hi[2];
        if (in) list[nl++] = v;
    }
    CHECK((ball ? amps_scene_fix_sphere(&ctx, A, c, r, &cnt) : amps_scene_fix_box(&ctx, A, lo, hi, &cnt)) == AMPS_OK,
          "%s: %s", what, ctx.msg);
    CHECK(cnt == nl && nl > 0, "%s: %ld fixed, brute force %ld", what, (long)cnt, (long)nl);
    CHECK(amps_scene_fix(&ctx, B, nl, list) == AMPS_OK, "fix by list");
    for (v = 0; v < m->nnode; v++) bad += amps_scene_is_fixed(A, v) != amps_scene_is_fixed(B, v);
    CHECK(bad == 0, "%s: %d nodes differ from the fix by list", what, bad);
    load = m->nnode - 1;
    amps_scene_force(&ctx, A, load, f);
    amps_scene_force(&ctx, B, load, f);
    CHECK(amps_scene_solve(&ctx, A) == AMPS_OK && amps_scene_solve(&ctx, B) == AMPS_OK, "%s: solve: %s", what, ctx.msg);
    memset(&w, 0, sizeof(w));
    shadow_grow(&w, m->nnode);
    w.fixed0 = (unsigned char *)calloc((size_t)m->nnode, 1);
    for (v = 0; v < nl; v++) w.fixed0[list[v]] = 1;
    memcpy(w.force + 3 * load, f, sizeof(f));
    u = (double *)malloc(sizeof(double) * 3 * m->nnode);
    scene_reference(&ctx, m, &w, 0, NULL, u, NULL, 0);
    CHECK(t_reldiff(3 * m->nnode, amps_scene_displacements(A), u) <= 1e-10, "%s: displacements vs CHOLMOD %.3e", what,
          t_reldiff(3 * m->nnode, amps_scene_displacements(A), u));
    CHECK(t_reldiff(3 * m->nnode, amps_scene_displacements(B), amps_scene_displacements(A)) == 0,
          "%s: same bits as the list", what);
    /* after the factorization: a clear error, nothing fixed */
    CHECK(amps_scene_fix_box(&ctx, A, lo, hi, &cnt) == AMPS_ERR_STATE && strstr(ctx.msg, "factored") && cnt == 0,
          "%s: box after the factorization: %s", what, ctx.msg);
    CHECK(amps_scene_fix_sphere(&ctx, A, c, 5.0, NULL) == AMPS_ERR_STATE, "%s: sphere after the factorization", what);
    CHECK(amps_scene_is_fixed(A, load) == 0, "%s: a node fixed after the factorization", what);
    shadow_free(&w);
    free(u);
    free(list);
    amps_scene_free(&ctx, A);
    amps_scene_free(&ctx, B);
}

static void test_fix_bad(void) {
    amps_ctx ctx;
    amps_scene *S;
    amps_int cnt = 7, v;
    double lo[3] = {0, 0, 0}, hi[3] = {1, 1, 1}, bad[3] = {0, NAN, 0}, inv[3] = {1, -1, 1};
    int nfix = 0;
    amps_ctx_init(&ctx);
    S = amps_scene_create(&ctx, amps_mesh_brick(&ctx, 2), NULL);
    CHECK(amps_scene_fix_box(&ctx, S, bad, hi, &cnt) == AMPS_ERR_VALUE && cnt == 0, "box NaN: %s", ctx.msg);
    CHECK(amps_scene_fix_box(&ctx, S, lo, inv, NULL) == AMPS_ERR_ARG && strstr(ctx.msg, "lo[1]"), "box inverted: %s",
          ctx.msg);
    CHECK(amps_scene_fix_box(&ctx, S, NULL, hi, NULL) == AMPS_ERR_ARG, "box NULL");
    CHECK(amps_scene_fix_sphere(&ctx, S, lo, -1, NULL) == AMPS_ERR_ARG && strstr(ctx.msg, "radius"), "negative radius");
    CHECK(amps_scene_fix_sphere(&ctx, S, lo, NAN, NULL) == AMPS_ERR_VALUE, "NaN radius");
    CHECK(amps_scene_fix_sphere(&ctx, S, bad, 1, NULL) == AMPS_ERR_VALUE, "NaN center");
    CHECK(amps_scene_fix_sphere(&ctx, NULL, lo, 1, NULL) == AMPS_ERR_ARG, "NULL scene");
    for (v = 0; v < amps_scene_mesh(S)->nnode; v++) nfix += amps_scene_is_fixed(S, v);
    CHECK(nfix == 0, "failed calls fixed %d nodes", nfix);
    CHECK(amps_scene_fix_sphere(&ctx, S, lo, 0, &cnt) == AMPS_OK && cnt == 1 && amps_scene_is_fixed(S, 0),
          "radius 0 fixes the node at the center");
    /* the material after the factorization */
    amps_scene_fix_where(&ctx, S, 2, AMPS_LT, 0.1, NULL);
    CHECK(amps_scene_prepare(&ctx, S) == AMPS_OK, "prepare");
    CHECK(amps_scene_set_material(&ctx, S, -5, 0.2) != AMPS_OK && amps_scene_mesh(S)->E[0] == 1.0,
          "bad material after the factorization: %s", ctx.msg);
    CHECK(amps_scene_set_material(&ctx, S, 5, 0.2) == AMPS_OK && amps_scene_mesh(S)->E[0] == 5.0,
          "material after the factorization (an update): %s", ctx.msg);
    amps_scene_free(&ctx, S);
}

/* ---- reader messages ---- */

static void test_messages(void) {
    amps_ctx ctx;
    char path[1200];
    int k;
    static const char hexmsh[] = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n9\n"
                                 "1 0 0 0\n2 1 0 0\n3 1 1 0\n4 0 1 0\n5 0 0 1\n6 1 0 1\n7 1 1 1\n8 0 1 1\n9 0.5 0.5 2\n"
                                 "$EndNodes\n$Elements\n3\n1 5 2 0 1 1 2 3 4 5 6 7 8\n2 7 2 0 1 5 6 7 8 9\n"
                                 "3 4 2 0 1 5 6 8 9\n$EndElements\n";
    amps_ctx_init(&ctx);
    /* the chained create keeps the reader's message */
    CHECK(amps_scene_create(&ctx, amps_mesh_read(&ctx, "/nonexistent/dir/model.msh"), NULL) == NULL &&
                  ctx.status == AMPS_ERR_IO && strstr(ctx.msg, "model.msh") && strstr(ctx.msg, "cannot open"),
          "chained create: %s", ctx.msg);
    amps_ctx_init(&ctx);
    CHECK(amps_scene_create(&ctx, NULL, NULL) == NULL && ctx.status == AMPS_ERR_ARG, "create NULL: %s", ctx.msg);
    /* hexahedra and pyramids are named */
    CHECK(amps_mesh_read_gmsh_mem(&ctx, hexmsh, sizeof(hexmsh) - 1, "hex.msh") == NULL && ctx.status == AMPS_ERR_MESH &&
                  strstr(ctx.msg, "1 hexahedron") && strstr(ctx.msg, "1 pyramid") && strstr(ctx.msg, "hex.msh"),
          "gmsh hexahedra: %s", ctx.msg);
    { /* the same in 4.1: a prism block of 2 */
        static const char msh4[] =
                "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n$Nodes\n1 7 1 7\n3 1 0 7\n1\n2\n3\n4\n5\n6\n7\n"
                "0 0 0\n1 0 0\n0 1 0\n0 0 1\n1 0 1\n0 1 1\n0 0 2\n$EndNodes\n"
                "$Elements\n2 3 1 3\n3 1 6 2\n1 1 2 3 4 5 6\n2 1 2 3 4 5 6\n3 1 4 1\n3 4 5 6 7\n"
                "$EndElements\n";
        CHECK(amps_mesh_read_gmsh_mem(&ctx, msh4, sizeof(msh4) - 1, "p.msh") == NULL && ctx.status == AMPS_ERR_MESH &&
                      strstr(ctx.msg, "2 prisms") && strstr(ctx.msg, "0 hexahedra"),
              "gmsh 4.1 prisms: %s", ctx.msg);
    }
    /* a long path keeps the reason */
    strcpy(path, "/nonexistent");
    for (k = 0; k < 60; k++) strcat(path, "/abcdefghijklmnop");
    strcat(path, "/liver.msh");
    CHECK(amps_mesh_read(&ctx, path) == NULL && strstr(ctx.msg, "cannot open") && strstr(ctx.msg, "liver.msh") &&
                  strstr(ctx.msg, "/nonexistent"),
          "long path: %s", ctx.msg);
}

/* Every allocation of the first take, a nearest-node query and a recorded cut failing in turn:
   a clear OOM or success, then a take that is consistent with the mesh, and nothing leaked. */
static void test_oom(void) {
    int k, fails = 0;
    for (k = 0; k < 40; k++) {
        amps_ctx ctx;
        amps_scene *S;
        amps_scene_changes c;
        mirror w;
        amps_int v, vc;
        amps_status s1, s2, s3;
        double p[3] = {0.5, 0.5, 1.0}, nrm[3] = {0.3, 0, 1};
        amps_ctx_init(&ctx);
        memset(&w, 0, sizeof(w));
        t_al.live = 0;
        ctx.alloc_user = &t_al;
        S = amps_scene_create(&ctx, amps_mesh_brick(&ctx, 2), NULL);
        amps_scene_fix_where(&ctx, S, 2, AMPS_LT, 0.1, NULL);
        amps_scene_prepare(&ctx, S);
        t_al.fail_at = k;
        s1 = amps_scene_take_changes(&ctx, S, &c);
        if (s1 == AMPS_OK) mirror_load(&w, S);
        s2 = amps_scene_nearest_node(&ctx, S, p, &v);
        s3 = amps_scene_cut(&ctx, S, s2 == AMPS_OK ? v : 9 * 2 + 4, p, nrm, &vc);
        fails += s1 != AMPS_OK || s2 != AMPS_OK || s3 != AMPS_OK;
        CHECK((s1 == AMPS_OK || s1 == AMPS_ERR_OOM) && (s2 == AMPS_OK || s2 == AMPS_ERR_OOM) &&
                      (s3 == AMPS_OK || s3 == AMPS_ERR_OOM),
              "oom %d: %d %d %d: %s", k, s1, s2, s3, ctx.msg);
        t_al.fail_at = -1;
        take_and_check(&ctx, S, &w, "oom", k);
        amps_scene_free(&ctx, S);
        CHECK(t_al.live == 0, "oom %d: %ld blocks leaked", k, t_al.live);
        free(w.tri);
        free(w.face);
        free(w.tet0);
    }
    CHECK(fails > 0, "no allocation failed");
}

int main(void) {
    amps_ctx ctx;
    amps_mesh *box;
    unsigned long long k;
    amps_ctx_init(&ctx);
    t_seed(19);
    cut_sequence(amps_mesh_brick(&ctx, 3), 40, 1, "brick:3");
    cut_sequence(amps_mesh_brick(&ctx, 2), 15, 0, "brick:2 unfactored");
    box = read_box(&ctx);
    CHECK(box != NULL, "tests/data/box: %s", ctx.msg);
    if (box) cut_sequence(box, 40, 1, "tetgen box");
    test_removed_hook();
    test_node_map();
    test_undone_batch();
    for (k = 1; k <= 6; k++) test_batch_records(k);
    test_nearest(amps_mesh_brick(&ctx, 4), "brick:4");
    box = read_box(&ctx);
    if (box) test_nearest(box, "tetgen box");
    fix_region_case(0, "fix box");
    fix_region_case(1, "fix sphere");
    test_fix_bad();
    test_messages();
    test_oom();
    return amps_t_end("test_render");
}
