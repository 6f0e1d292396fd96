/* Fill-reducing orderings: amps_order (all methods, block compression, validation), amps_amd and
   amps_nd. Fill is measured with CHOLMOD (ref_nnzL, our permutation as GIVEN) against CHOLMOD's
   AMD and METIS orderings. Allocation failures are injected through AMPS_MALLOC. */
#include <stdlib.h>
#include <string.h>

/* Allocator that fails the k-th allocation when armed (for failure-path tests). */
typedef struct t_alloc {
    long count, fail_at, live;
} t_alloc;
static void *t_malloc(size_t sz, void *u) {
    t_alloc *a = (t_alloc *)u;
    if (a) {
        if (a->fail_at >= 0 && a->count++ == a->fail_at) return NULL;
        a->live++;
    }
    return malloc(sz);
}
static void *t_realloc(void *p, size_t sz, void *u) {
    t_alloc *a = (t_alloc *)u;
    if (a && a->fail_at >= 0 && a->count++ == a->fail_at) return NULL;
    if (a && !p) a->live++;
    return realloc(p, sz);
}
static void t_free(void *p, void *u) {
    t_alloc *a = (t_alloc *)u;
    if (a && p) a->live--;
    free(p);
}
#define AMPS_MALLOC(sz, u) t_malloc((sz), (u))
#define AMPS_REALLOC(p, sz, u) t_realloc((p), (sz), (u))
#define AMPS_FREE(p, u) t_free((p), (u))

#define AMPS_IMPLEMENTATION
#include "amps.h"
#include "amps_test.h"
#include "fe_util.h"
#include "cholmod_ref.h"

/* Symmetric test matrix: upper CSC (sorted, duplicates summed) plus its lower and full copies. */
typedef struct tmat {
    int n;
    int *up, *ui, *lp, *li, *fp, *fi;
    double *ux;
    double *xyz; /* 3 per node (n/3 nodes) or NULL */
} tmat;

/* CSC of the entries (ti, tj) of an n x n matrix; duplicates summed, rows ascending. */
static void t_csc(int n, int nz, const int *ti, const int *tj, const double *tx, int **P, int **I, double **X) {
    int *cp = (int *)calloc((size_t)n + 1, sizeof(int)), *rp = (int *)calloc((size_t)n + 1, sizeof(int));
    int *ord = (int *)malloc(sizeof(int) * (nz + 1)), *ci = (int *)malloc(sizeof(int) * (nz + 1));
    int *mark = (int *)malloc(sizeof(int) * (n + 1)), *w = (int *)malloc(sizeof(int) * (n + 1)),
        *ord2 = (int *)malloc(sizeof(int) * (nz + 1));
    double *cx = (double *)malloc(sizeof(double) * (nz + 1));
    int k, j, q = 0;
    for (k = 0; k < nz; k++) {
        rp[ti[k] + 1]++;
        cp[tj[k] + 1]++;
    }
    for (j = 0; j < n; j++) {
        rp[j + 1] += rp[j];
        cp[j + 1] += cp[j];
    }
    memcpy(w, rp, sizeof(int) * n);
    for (k = 0; k < nz; k++) ord[w[ti[k]]++] = k; /* by row */
    memcpy(w, cp, sizeof(int) * n);
    for (k = 0; k < nz; k++) ord2[w[tj[ord[k]]]++] = ord[k]; /* stable by column: rows ascending */
    for (j = 0; j < n; j++) mark[j] = -1;
    for (j = 0; j < n; j++) {
        int start = q;
        for (k = cp[j]; k < cp[j + 1]; k++) {
            int e = ord2[k], i = ti[e];
            if (mark[i] >= start) cx[mark[i]] += tx ? tx[e] : 1.0;
            else {
                mark[i] = q;
                ci[q] = i;
                cx[q++] = tx ? tx[e] : 1.0;
            }
        }
        rp[j] = start;
    }
    rp[n] = q;
    *P = rp;
    *I = ci;
    if (X) *X = cx;
    else free(cx);
    free(cp);
    free(ord);
    free(ord2);
    free(mark);
    free(w);
}

/* Builds upper/lower/full copies from upper triplets. */
static tmat t_from_upper(int n, int nz, const int *ti, const int *tj, const double *tx) {
    tmat m;
    int k, *fi = (int *)malloc(sizeof(int) * (2 * nz + 1)), *fj = (int *)malloc(sizeof(int) * (2 * nz + 1)), nf = 0;
    memset(&m, 0, sizeof m);
    m.n = n;
    t_csc(n, nz, ti, tj, tx, &m.up, &m.ui, &m.ux);
    t_csc(n, nz, tj, ti, NULL, &m.lp, &m.li, NULL);
    for (k = 0; k < nz; k++) {
        fi[nf] = ti[k];
        fj[nf++] = tj[k];
        if (ti[k] != tj[k]) {
            fi[nf] = tj[k];
            fj[nf++] = ti[k];
        }
    }
    t_csc(n, nf, fi, fj, NULL, &m.fp, &m.fi, NULL);
    free(fi);
    free(fj);
    return m;
}

static tmat t_fe(fe_mesh *mesh) {
    int *dof = (int *)malloc(sizeof(int) * 3 * mesh->nn), *ti, *tj, n, nz;
    double *tx;
    tmat m;
    n = fe_number(mesh, NULL, dof);
    nz = fe_assemble(mesh, dof, 1.0, 0.3, &ti, &tj, &tx);
    m = t_from_upper(n, nz, ti, tj, tx);
    m.xyz = (double *)malloc(sizeof(double) * 3 * mesh->nn);
    memcpy(m.xyz, mesh->xyz, sizeof(double) * 3 * mesh->nn);
    free(dof);
    free(ti);
    free(tj);
    free(tx);
    return m;
}

static void t_free_mat(tmat *m) {
    free(m->up);
    free(m->ui);
    free(m->ux);
    free(m->lp);
    free(m->li);
    free(m->fp);
    free(m->fi);
    free(m->xyz);
}

static amps_csc t_view(const tmat *m, amps_stype st) {
    amps_csc A;
    A.nrow = A.ncol = m->n;
    A.p = st == AMPS_UPPER ? m->up : st == AMPS_LOWER ? m->lp : m->fp;
    A.i = st == AMPS_UPPER ? m->ui : st == AMPS_LOWER ? m->li : m->fi;
    A.x = NULL;
    return A;
}

static int t_is_perm(int n, const int *p) {
    char *seen = (char *)calloc((size_t)n + 1, 1);
    int k, ok = 1;
    for (k = 0; k < n && ok; k++) {
        if (p[k] < 0 || p[k] >= n || seen[p[k]]) ok = 0;
        else seen[p[k]] = 1;
    }
    free(seen);
    return ok;
}

/* nnz(L) of A (upper) under perm, counted by CHOLMOD. */
static double t_fill(const tmat *m, const int *perm) { return ref_nnzL(m->n, m->up, m->ui, m->ux, perm, 0, NULL); }

static int t_order(amps_ctx *ctx, const tmat *m, amps_stype st, amps_ordering meth, int block, const double *xyz,
                   int *perm) {
    amps_order_opts o;
    amps_csc A = t_view(m, st);
    memset(&o, 0, sizeof o);
    o.method = meth;
    o.block = block;
    o.coords = xyz;
    return amps_order(ctx, &A, st, &o, perm);
}

static const char *mname(amps_ordering m) {
    static const char *s[] = {"AUTO", "NATURAL", "GIVEN", "AMD", "ND", "METIS"};
    return s[m];
}

static void test_methods(void) {
    fe_mesh mesh = fe_brick(4);
    tmat m = t_fe(&mesh);
    amps_ctx ctx;
    int *perm = (int *)malloc(sizeof(int) * m.n), *ref = (int *)malloc(sizeof(int) * m.n), k, b, st;
    amps_ordering meths[] = {AMPS_ORDER_AUTO, AMPS_ORDER_NATURAL, AMPS_ORDER_AMD, AMPS_ORDER_ND};
    int blocks[] = {0, 1, 3};
    amps_ctx_init(&ctx);
    for (k = 0; k < 4; k++)
        for (b = 0; b < 3; b++) {
            for (st = -1; st <= 1; st++) {
                int r = t_order(&ctx, &m, (amps_stype)st, meths[k], blocks[b], NULL, perm);
                CHECK(r == AMPS_OK && t_is_perm(m.n, perm), "%s block %d stype %d: status %d (%s)", mname(meths[k]),
                      blocks[b], st, r, ctx.msg);
                if (st == -1) memcpy(ref, perm, sizeof(int) * m.n);
                else
                    CHECK(!memcmp(ref, perm, sizeof(int) * m.n), "%s block %d: stype %d gives another ordering",
                          mname(meths[k]), blocks[b], st);
            }
            if (meths[k] == AMPS_ORDER_ND || meths[k] == AMPS_ORDER_AUTO) {
                int r = t_order(&ctx, &m, AMPS_UPPER, meths[k], blocks[b], blocks[b] == 3 ? m.xyz : NULL, perm);
                CHECK(r == AMPS_OK && t_is_perm(m.n, perm), "%s block %d with coordinates: %d (%s)", mname(meths[k]),
                      blocks[b], r, ctx.msg);
            }
        }
    CHECK(t_order(&ctx, &m, AMPS_UPPER, AMPS_ORDER_NATURAL, 0, NULL, perm) == AMPS_OK, "natural");
    for (k = 0; k < m.n; k++)
        if (perm[k] != k) break;
    CHECK(k == m.n, "NATURAL is not the identity (perm[%d] = %d)", k, perm[k]);
    /* default options (opts NULL) */
    {
        amps_csc A = t_view(&m, AMPS_UPPER);
        CHECK(amps_order(&ctx, &A, AMPS_UPPER, NULL, perm) == AMPS_OK && t_is_perm(m.n, perm), "opts NULL: %s",
              ctx.msg);
    }
    /* amps_amd / amps_nd on the full graph and on one triangle */
    CHECK(amps_amd(&ctx, m.n, m.fp, m.fi, perm) == AMPS_OK && t_is_perm(m.n, perm), "amps_amd: %s", ctx.msg);
    memcpy(ref, perm, sizeof(int) * m.n);
    CHECK(amps_amd(&ctx, m.n, m.up, m.ui, perm) == AMPS_OK && !memcmp(ref, perm, sizeof(int) * m.n),
          "amps_amd upper != full");
    CHECK(amps_nd(&ctx, m.n, m.fp, m.fi, NULL, perm) == AMPS_OK && t_is_perm(m.n, perm), "amps_nd: %s", ctx.msg);
    {
        double *x = (double *)malloc(sizeof(double) * 3 * m.n);
        for (k = 0; k < m.n; k++) memcpy(x + 3 * k, m.xyz + 3 * (k / 3), sizeof(double) * 3);
        CHECK(amps_nd(&ctx, m.n, m.fp, m.fi, x, perm) == AMPS_OK && t_is_perm(m.n, perm), "amps_nd xyz: %s", ctx.msg);
        free(x);
    }
    /* deterministic */
    CHECK(t_order(&ctx, &m, AMPS_UPPER, AMPS_ORDER_ND, 3, NULL, perm) == AMPS_OK, "nd");
    memcpy(ref, perm, sizeof(int) * m.n);
    CHECK(t_order(&ctx, &m, AMPS_UPPER, AMPS_ORDER_ND, 3, NULL, perm) == AMPS_OK &&
                  !memcmp(ref, perm, sizeof(int) * m.n),
          "ND is not deterministic");
    free(perm);
    free(ref);
    t_free_mat(&m);
    fe_free(&mesh);
}

static void test_given(void) {
    fe_mesh mesh = fe_grid(3, 3, 3, 1, 1, 1);
    tmat m = t_fe(&mesh);
    amps_ctx ctx;
    amps_order_opts o;
    amps_csc A = t_view(&m, AMPS_UPPER);
    int n = m.n, *g = (int *)malloc(sizeof(int) * n), *perm = (int *)malloc(sizeof(int) * n), k, r;
    amps_ctx_init(&ctx);
    memset(&o, 0, sizeof o);
    o.method = AMPS_ORDER_GIVEN;
    for (k = 0; k < n; k++) g[k] = n - 1 - k;
    o.perm = g;
    CHECK(amps_order(&ctx, &A, AMPS_UPPER, &o, perm) == AMPS_OK && !memcmp(perm, g, sizeof(int) * n),
          "GIVEN not returned as is");
    o.block = 3; /* GIVEN is used as is whatever the block */
    CHECK(amps_order(&ctx, &A, AMPS_UPPER, &o, perm) == AMPS_OK && !memcmp(perm, g, sizeof(int) * n),
          "GIVEN with block 3");
    o.block = 0;
    for (k = 0; k < n; k++) perm[k] = -7;
    g[5] = g[9]; /* duplicate */
    r = amps_order(&ctx, &A, AMPS_UPPER, &o, perm);
    CHECK(r == AMPS_ERR_ARG && strstr(ctx.msg, "perm[5]") && strstr(ctx.msg, "perm[9]"), "duplicate: %d '%s'", r,
          ctx.msg);
    for (k = 0; k < n && perm[k] == -7; k++) {}
    CHECK(k == n, "perm changed by a failed call");
    g[5] = n; /* out of range */
    r = amps_order(&ctx, &A, AMPS_UPPER, &o, perm);
    CHECK(r == AMPS_ERR_INDEX && strstr(ctx.msg, "perm[5]") && strstr(ctx.msg, "out of range"), "out of range: %d '%s'",
          r, ctx.msg);
    g[5] = -1;
    r = amps_order(&ctx, &A, AMPS_UPPER, &o, perm);
    CHECK(r == AMPS_ERR_INDEX && strstr(ctx.msg, "perm[5] = -1"), "negative: %d '%s'", r, ctx.msg);
    o.perm = NULL;
    CHECK(amps_order(&ctx, &A, AMPS_UPPER, &o, perm) == AMPS_ERR_ARG, "GIVEN without perm");
    for (k = 0; k < n && perm[k] == -7; k++) {}
    CHECK(k == n, "perm changed by a failed call");
    free(g);
    free(perm);
    t_free_mat(&m);
    fe_free(&mesh);
}

/* A node's DOFs 3v, 3v+1, 3v+2 stay consecutive and ascending. */
static int t_blocks_ok(int n, const int *perm) {
    int k;
    for (k = 0; k + 2 < n; k += 3)
        if (perm[k] % 3 != 0 || perm[k + 1] != perm[k] + 1 || perm[k + 2] != perm[k] + 2) return 0;
    return 1;
}

static void test_blocks(void) {
    fe_mesh mesh = fe_beam(12);
    tmat m = t_fe(&mesh);
    amps_ctx ctx;
    int *perm = (int *)malloc(sizeof(int) * m.n), b, k, r;
    amps_ordering meths[] = {AMPS_ORDER_AUTO, AMPS_ORDER_AMD, AMPS_ORDER_ND};
    amps_ctx_init(&ctx);
    for (k = 0; k < 3; k++)
        for (b = 0; b <= 3; b += 3) {
            r = t_order(&ctx, &m, AMPS_UPPER, meths[k], b, b ? m.xyz : NULL, perm);
            CHECK(r == AMPS_OK && t_is_perm(m.n, perm) && t_blocks_ok(m.n, perm),
                  "%s block %d: node DOFs not consecutive", mname(meths[k]), b);
        }
    /* block 3 on a matrix whose nodes are not cliques still keeps nodes together */
    {
        int n = 9, ti[] = {0, 3, 6, 1, 4, 2}, tj[] = {0, 4, 8, 5, 7, 8};
        tmat s = t_from_upper(n, 6, ti, tj, NULL);
        for (k = 0; k < 3; k++) {
            r = t_order(&ctx, &s, AMPS_UPPER, meths[k], 3, NULL, perm);
            CHECK(r == AMPS_OK && t_is_perm(n, perm) && t_blocks_ok(n, perm), "%s: sparse nodes not kept together",
                  mname(meths[k]));
        }
        r = t_order(&ctx, &s, AMPS_UPPER, AMPS_ORDER_AMD, 2, NULL, perm);
        CHECK(r == AMPS_ERR_ARG && strstr(ctx.msg, "multiple"), "n %% block != 0: %d '%s'", r, ctx.msg);
        r = t_order(&ctx, &s, AMPS_UPPER, AMPS_ORDER_AMD, 9, NULL, perm);
        CHECK(r == AMPS_OK && t_is_perm(n, perm), "block = n");
        t_free_mat(&s);
    }
    free(perm);
    t_free_mat(&m);
    fe_free(&mesh);
}

static void test_metis(void) {
    fe_mesh mesh = fe_grid(3, 3, 3, 1, 1, 1);
    tmat m = t_fe(&mesh);
    amps_ctx ctx;
    int *perm = (int *)malloc(sizeof(int) * m.n), k, r;
    amps_ctx_init(&ctx);
    for (k = 0; k < m.n; k++) perm[k] = -3;
    r = t_order(&ctx, &m, AMPS_UPPER, AMPS_ORDER_METIS, 3, NULL, perm);
#ifdef AMPS_USE_METIS
    CHECK(r == AMPS_OK && t_is_perm(m.n, perm), "METIS: %d %s", r, ctx.msg);
#else
    CHECK(r == AMPS_ERR_UNSUPPORTED && strstr(ctx.msg, "AMPS_USE_METIS"), "METIS in default build: %d '%s'", r,
          ctx.msg);
    CHECK(perm[0] == -3, "perm changed");
#endif
    free(perm);
    t_free_mat(&m);
    fe_free(&mesh);
}

/* nnz(L) of our AMD within 5% of CHOLMOD's AMD. */
static void test_amd_fill(void) {
    int hs[] = {16, 64, 256}, Rs[] = {4, 8, 12}, k, b;
    amps_ctx ctx;
    amps_ctx_init(&ctx);
    for (k = 0; k < 6; k++) {
        fe_mesh mesh = k < 3 ? fe_beam(hs[k]) : fe_brick(Rs[k - 3]);
        tmat m = t_fe(&mesh);
        int *perm = (int *)malloc(sizeof(int) * m.n);
        double ref = ref_nnzL(m.n, m.up, m.ui, m.ux, NULL, CHOLMOD_AMD, NULL), f;
        for (b = 0; b < 3; b++) {
            int r = b < 2 ? t_order(&ctx, &m, AMPS_UPPER, AMPS_ORDER_AMD, 3 * b, NULL, perm)
                          : amps_amd(&ctx, m.n, m.up, m.ui, perm);
            f = r == AMPS_OK ? t_fill(&m, perm) : -1;
            CHECK(f > 0 && f <= 1.05 * ref, "%s %d (%s): nnz(L) %.0f vs CHOLMOD AMD %.0f (ratio %.3f)",
                  k < 3 ? "beam" : "brick", k < 3 ? hs[k] : Rs[k - 3],
                  b == 0   ? "amps_order block 0"
                  : b == 1 ? "amps_order block 3"
                           : "amps_amd",
                  f, ref, f / ref);
        }
        free(perm);
        t_free_mat(&m);
        fe_free(&mesh);
    }
}

/* nnz(L) of our ND within 1.15x of CHOLMOD's METIS; AUTO no worse than the better of AMD and ND. */
static void test_nd_fill(void) {
    amps_ctx ctx;
    int k, c;
    amps_ctx_init(&ctx);
    for (k = 0; k < 2; k++) {
        fe_mesh mesh = k == 0 ? fe_brick(14) : fe_beam(256);
        tmat m = t_fe(&mesh);
        int *perm = (int *)malloc(sizeof(int) * m.n);
        double ref = ref_nnzL(m.n, m.up, m.ui, m.ux, NULL, CHOLMOD_METIS, NULL), f, fa, fn = 0;
        for (c = 0; c < 2; c++) {
            int r = t_order(&ctx, &m, AMPS_UPPER, AMPS_ORDER_ND, 3, c ? m.xyz : NULL, perm);
            f = r == AMPS_OK ? t_fill(&m, perm) : -1;
            CHECK(f > 0 && f <= 1.15 * ref, "%s ND %s: nnz(L) %.0f vs CHOLMOD METIS %.0f (ratio %.3f)",
                  k ? "beam 256" : "brick 14", c ? "with coordinates" : "graph only", f, ref, f / ref);
            if (c) fn = f;
        }
        CHECK(t_order(&ctx, &m, AMPS_UPPER, AMPS_ORDER_AMD, 3, NULL, perm) == AMPS_OK, "amd");
        fa = t_fill(&m, perm);
        CHECK(t_order(&ctx, &m, AMPS_UPPER, AMPS_ORDER_AUTO, 3, m.xyz, perm) == AMPS_OK, "auto");
        f = t_fill(&m, perm);
        CHECK(f <= 1.0001 * (fa < fn ? fa : fn), "AUTO %.0f vs AMD %.0f, ND %.0f", f, fa, fn);
        free(perm);
        t_free_mat(&m);
        fe_free(&mesh);
    }
}

/* Block-diagonal union of two meshes (disconnected graph), a dense row, a diagonal matrix,
   n = 0 and n = 1. */
static void test_edge_cases(void) {
    amps_ctx ctx;
    amps_ordering meths[] = {AMPS_ORDER_AUTO, AMPS_ORDER_NATURAL, AMPS_ORDER_AMD, AMPS_ORDER_ND};
    int k, b, r, perm1[1] = {-5};
    amps_ctx_init(&ctx);
    { /* n = 0 and n = 1 */
        int p0[1] = {0}, p1[2] = {0, 1}, i1[1] = {0};
        amps_csc A;
        amps_order_opts o;
        memset(&o, 0, sizeof o);
        A.nrow = A.ncol = 0;
        A.p = p0;
        A.i = NULL;
        A.x = NULL;
        for (k = 0; k < 4; k++) {
            o.method = meths[k];
            CHECK(amps_order(&ctx, &A, AMPS_UPPER, &o, perm1) == AMPS_OK && perm1[0] == -5, "n = 0 %s: %s",
                  mname(meths[k]), ctx.msg);
        }
        CHECK(amps_amd(&ctx, 0, p0, NULL, perm1) == AMPS_OK && amps_nd(&ctx, 0, p0, NULL, NULL, perm1) == AMPS_OK,
              "n = 0");
        A.nrow = A.ncol = 1;
        A.p = p1;
        A.i = i1;
        for (k = 0; k < 4; k++) {
            o.method = meths[k];
            perm1[0] = -5;
            CHECK(amps_order(&ctx, &A, AMPS_UPPER, &o, perm1) == AMPS_OK && perm1[0] == 0, "n = 1 %s", mname(meths[k]));
        }
        perm1[0] = -5;
        CHECK(amps_amd(&ctx, 1, p1, i1, perm1) == AMPS_OK && perm1[0] == 0, "amps_amd n = 1");
        perm1[0] = -5;
        CHECK(amps_nd(&ctx, 1, p1, i1, NULL, perm1) == AMPS_OK && perm1[0] == 0, "amps_nd n = 1");
    }
    { /* two disconnected bricks, plus isolated nodes; and a diagonal matrix */
        fe_mesh a = fe_brick(5), c;
        int *dof, *ti, *tj, n1, nz1, n, nz, j;
        double *tx, *xyz;
        tmat m;
        dof = (int *)malloc(sizeof(int) * 3 * a.nn);
        n1 = fe_number(&a, NULL, dof);
        nz1 = fe_assemble(&a, dof, 1, 0.3, &ti, &tj, &tx);
        n = 2 * n1 + 6; /* + two isolated nodes */
        ti = (int *)realloc(ti, sizeof(int) * (2 * nz1 + 6));
        tj = (int *)realloc(tj, sizeof(int) * (2 * nz1 + 6));
        tx = (double *)realloc(tx, sizeof(double) * (2 * nz1 + 6));
        for (k = 0; k < nz1; k++) {
            ti[nz1 + k] = ti[k] + n1;
            tj[nz1 + k] = tj[k] + n1;
            tx[nz1 + k] = tx[k];
        }
        nz = 2 * nz1;
        for (k = 2 * n1; k < n; k++) {
            ti[nz] = tj[nz] = k;
            tx[nz++] = 1;
        }
        m = t_from_upper(n, nz, ti, tj, tx);
        xyz = (double *)malloc(sizeof(double) * n);
        for (k = 0; k < a.nn; k++)
            for (j = 0; j < 3; j++) {
                xyz[3 * k + j] = a.xyz[3 * k + j];
                xyz[3 * (a.nn + k) + j] = a.xyz[3 * k + j] + (j == 0 ? 5 : 0);
            }
        for (j = 0; j < 6; j++) xyz[6 * a.nn + j] = -1;
        m.xyz = xyz;
        {
            int *perm = (int *)malloc(sizeof(int) * n);
            for (k = 0; k < 4; k++)
                for (b = 0; b <= 3; b += 3) {
                    r = t_order(&ctx, &m, AMPS_UPPER, meths[k], b, b ? m.xyz : NULL, perm);
                    CHECK(r == AMPS_OK && t_is_perm(n, perm) && (b == 0 || t_blocks_ok(n, perm)),
                          "disconnected %s block %d: %d %s", mname(meths[k]), b, r, ctx.msg);
                }
            /* ND orders each brick about as well as alone */
            r = t_order(&ctx, &m, AMPS_UPPER, AMPS_ORDER_ND, 3, NULL, perm);
            CHECK(r == AMPS_OK && t_fill(&m, perm) <= 1.15 * ref_nnzL(n, m.up, m.ui, m.ux, NULL, CHOLMOD_METIS, NULL),
                  "disconnected ND fill");
            free(perm);
        }
        t_free_mat(&m);
        /* diagonal only */
        for (k = 0; k < 30; k++) {
            ti[k] = tj[k] = k;
            tx[k] = 1;
        }
        m = t_from_upper(30, 30, ti, tj, tx);
        {
            int perm[30];
            for (k = 0; k < 4; k++)
                for (b = 0; b <= 3; b += 3) {
                    r = t_order(&ctx, &m, AMPS_UPPER, meths[k], b, NULL, perm);
                    CHECK(r == AMPS_OK && t_is_perm(30, perm), "diagonal %s block %d: %d %s", mname(meths[k]), b, r,
                          ctx.msg);
                }
            CHECK(amps_amd(&ctx, 30, m.up, m.ui, perm) == AMPS_OK && t_is_perm(30, perm), "amps_amd diagonal");
            CHECK(amps_nd(&ctx, 30, m.up, m.ui, NULL, perm) == AMPS_OK && t_is_perm(30, perm), "amps_nd diagonal");
        }
        t_free_mat(&m);
        /* a dense row: node coupled to every DOF of a brick goes last with AMD, fill stays close to CHOLMOD's */
        c = fe_brick(6);
        free(dof);
        free(ti);
        free(tj);
        free(tx);
        dof = (int *)malloc(sizeof(int) * 3 * c.nn);
        n1 = fe_number(&c, NULL, dof);
        nz1 = fe_assemble(&c, dof, 1, 0.3, &ti, &tj, &tx);
        n = n1 + 1;
        ti = (int *)realloc(ti, sizeof(int) * (nz1 + n));
        tj = (int *)realloc(tj, sizeof(int) * (nz1 + n));
        tx = (double *)realloc(tx, sizeof(double) * (nz1 + n));
        for (k = 0; k < n; k++) {
            ti[nz1 + k] = k;
            tj[nz1 + k] = n1;
            tx[nz1 + k] = 1;
        }
        m = t_from_upper(n, nz1 + n, ti, tj, tx);
        {
            int *perm = (int *)malloc(sizeof(int) * n);
            double ref = ref_nnzL(n, m.up, m.ui, m.ux, NULL, CHOLMOD_AMD, NULL);
            r = amps_amd(&ctx, n, m.up, m.ui, perm);
            CHECK(r == AMPS_OK && t_is_perm(n, perm) && perm[n - 1] == n1, "dense row not last: %d", perm[n - 1]);
            CHECK(t_fill(&m, perm) <= 1.05 * ref, "dense row: AMD fill %.0f vs CHOLMOD %.0f", t_fill(&m, perm), ref);
            for (k = 0; k < 4; k++) {
                r = t_order(&ctx, &m, AMPS_LOWER, meths[k], 0, NULL, perm);
                CHECK(r == AMPS_OK && t_is_perm(n, perm), "dense row %s: %d %s", mname(meths[k]), r, ctx.msg);
            }
            r = t_order(&ctx, &m, AMPS_UPPER, AMPS_ORDER_ND, 0, NULL, perm);
            CHECK(r == AMPS_OK && t_fill(&m, perm) <= 1.3 * ref, "dense row ND fill %.0f vs CHOLMOD AMD %.0f",
                  t_fill(&m, perm), ref);
            free(perm);
        }
        t_free_mat(&m);
        free(dof);
        free(ti);
        free(tj);
        free(tx);
        fe_free(&a);
        fe_free(&c);
    }
}

static void test_invalid(void) {
    amps_ctx ctx;
    amps_order_opts o;
    int p[4] = {0, 1, 3, 4}, i[4] = {0, 0, 1, 2}, perm[3] = {-1, -1, -1}, r;
    amps_csc A;
    double bad[9] = {0, 0, 0, 1, 1, 1, 2, 2, 2};
    amps_ctx_init(&ctx);
    A.nrow = A.ncol = 3;
    A.p = p;
    A.i = i;
    A.x = NULL;
    memset(&o, 0, sizeof o);
    CHECK(amps_order(&ctx, NULL, AMPS_UPPER, NULL, perm) == AMPS_ERR_ARG && strstr(ctx.msg, "NULL"), "A NULL: %s",
          ctx.msg);
    CHECK(amps_order(&ctx, &A, AMPS_UPPER, NULL, NULL) == AMPS_ERR_ARG && strstr(ctx.msg, "perm"), "perm NULL: %s",
          ctx.msg);
    CHECK(amps_order(NULL, &A, AMPS_UPPER, NULL, NULL) == AMPS_ERR_ARG, "ctx NULL");
    CHECK(amps_order(&ctx, &A, (amps_stype)5, NULL, perm) == AMPS_ERR_ARG && strstr(ctx.msg, "stype"), "stype: %s",
          ctx.msg);
    o.method = (amps_ordering)42;
    CHECK(amps_order(&ctx, &A, AMPS_UPPER, &o, perm) == AMPS_ERR_ARG && strstr(ctx.msg, "method"), "method: %s",
          ctx.msg);
    o.method = AMPS_ORDER_AMD;
    o.block = -1;
    CHECK(amps_order(&ctx, &A, AMPS_UPPER, &o, perm) == AMPS_ERR_ARG && strstr(ctx.msg, "block"), "block: %s", ctx.msg);
    o.block = 0;
    A.nrow = 4;
    CHECK(amps_order(&ctx, &A, AMPS_UPPER, &o, perm) == AMPS_ERR_ARG && strstr(ctx.msg, "square"), "non-square: %s",
          ctx.msg);
    A.nrow = A.ncol = -1;
    CHECK(amps_order(&ctx, &A, AMPS_UPPER, &o, perm) == AMPS_ERR_ARG, "negative n");
    A.nrow = A.ncol = 3;
    i[3] = 3;
    r = amps_order(&ctx, &A, AMPS_UPPER, &o, perm);
    CHECK(r == AMPS_ERR_INDEX && strstr(ctx.msg, "row index 3") && strstr(ctx.msg, "column 2"), "index: %d '%s'", r,
          ctx.msg);
    i[3] = 2;
    r = amps_order(&ctx, &A, AMPS_LOWER, &o, perm);
    CHECK(r == AMPS_ERR_PATTERN && strstr(ctx.msg, "(0,1)") && strstr(ctx.msg, "lower"), "triangle: %d '%s'", r,
          ctx.msg);
    CHECK(amps_order(&ctx, &A, AMPS_FULL, &o, perm) == AMPS_OK && t_is_perm(3, perm), "full accepts one triangle");
    perm[0] = perm[1] = perm[2] = -1;
    p[1] = 5;
    r = amps_order(&ctx, &A, AMPS_UPPER, &o, perm);
    CHECK(r == AMPS_ERR_PATTERN && strstr(ctx.msg, "decrease"), "pointers: %d '%s'", r, ctx.msg);
    p[1] = 1;
    p[0] = 1;
    r = amps_order(&ctx, &A, AMPS_UPPER, &o, perm);
    CHECK(r == AMPS_ERR_PATTERN && strstr(ctx.msg, "p[0]"), "p[0]: %d '%s'", r, ctx.msg);
    p[0] = 0;
    A.p = NULL;
    CHECK(amps_order(&ctx, &A, AMPS_UPPER, &o, perm) == AMPS_ERR_ARG, "p NULL");
    A.p = p;
    A.i = NULL;
    CHECK(amps_order(&ctx, &A, AMPS_UPPER, &o, perm) == AMPS_ERR_ARG, "i NULL");
    A.i = i;
    o.method = AMPS_ORDER_ND;
    o.coords = bad;
    bad[4] = strtod("nan", NULL);
    r = amps_order(&ctx, &A, AMPS_UPPER, &o, perm);
    CHECK(r == AMPS_ERR_VALUE && strstr(ctx.msg, "node 1"), "NaN coordinate: %d '%s'", r, ctx.msg);
    CHECK(amps_nd(&ctx, 3, p, i, bad, perm) == AMPS_ERR_VALUE, "amps_nd NaN");
    CHECK(perm[0] == -1 && perm[1] == -1 && perm[2] == -1, "perm changed by failed calls");
    CHECK(amps_amd(&ctx, -1, p, i, perm) == AMPS_ERR_ARG && amps_nd(&ctx, -1, p, i, NULL, perm) == AMPS_ERR_ARG,
          "n < 0");
    CHECK(amps_amd(&ctx, 3, p, i, NULL) == AMPS_ERR_ARG && amps_nd(&ctx, 3, p, i, NULL, NULL) == AMPS_ERR_ARG,
          "perm NULL");
    CHECK(amps_amd(&ctx, 3, NULL, i, perm) == AMPS_ERR_ARG, "amps_amd Ap NULL");
    i[0] = -1;
    CHECK(amps_amd(&ctx, 3, p, i, perm) == AMPS_ERR_INDEX && amps_nd(&ctx, 3, p, i, NULL, perm) == AMPS_ERR_INDEX,
          "negative index");
}

/* Every allocation failure is reported as AMPS_ERR_OOM, leaks nothing and leaves perm alone. */
static void test_alloc_failures(void) {
    fe_mesh mesh = fe_brick(4);
    tmat m = t_fe(&mesh);
    amps_ctx ctx;
    t_alloc al;
    int *perm = (int *)malloc(sizeof(int) * m.n), k, variant, bad = 0, tried = 0;
    for (variant = 0; variant < 6; variant++) {
        long f;
        const char *prefix = variant < 4 ? "amps_order: " : variant == 4 ? "amps_amd: " : "amps_nd: ";
        for (f = 0;; f++) {
            int r;
            amps_ctx_init(&ctx);
            al.count = 0;
            al.fail_at = f;
            al.live = 0;
            ctx.alloc_user = &al;
            for (k = 0; k < m.n; k++) perm[k] = -9;
            switch (variant) {
            case 0: r = t_order(&ctx, &m, AMPS_UPPER, AMPS_ORDER_AMD, 0, NULL, perm); break;
            case 1: r = t_order(&ctx, &m, AMPS_UPPER, AMPS_ORDER_ND, 3, NULL, perm); break;
            case 2: r = t_order(&ctx, &m, AMPS_LOWER, AMPS_ORDER_ND, 3, m.xyz, perm); break;
            case 3: r = t_order(&ctx, &m, AMPS_FULL, AMPS_ORDER_AUTO, 1, NULL, perm); break;
            case 4: r = amps_amd(&ctx, m.n, m.up, m.ui, perm); break;
            default: r = amps_nd(&ctx, m.n, m.fp, m.fi, NULL, perm); break;
            }
            tried++;
            if (al.live != 0) {
                bad++;
                CHECK(0, "variant %d, failing allocation %ld: %ld blocks leaked", variant, f, al.live);
            }
            if (r == AMPS_OK) {
                CHECK(t_is_perm(m.n, perm), "variant %d: not a permutation after %ld allocations", variant, f);
                break;
            }
            for (k = 0; k < m.n && perm[k] == -9; k++) {}
            if (r != AMPS_ERR_OOM || ctx.status != AMPS_ERR_OOM || k < m.n || !strstr(ctx.msg, "memory") ||
                strncmp(ctx.msg, prefix, strlen(prefix))) {
                bad++;
                CHECK(0, "variant %d, failing allocation %ld: status %d, '%s', perm %s", variant, f, r, ctx.msg,
                      k < m.n ? "changed" : "unchanged");
            }
            if (bad > 5 || f > 100000) break;
        }
    }
    CHECK(bad == 0, "%d bad failure paths out of %d", bad, tried);
    free(perm);
    t_free_mat(&m);
    fe_free(&mesh);
}

/* Random symmetric patterns (sizes 1..400, some with dense rows, some with empty columns): every
   method returns a permutation, and AMD's fill stays near CHOLMOD's. */
static void test_random(void) {
    amps_ctx ctx;
    int trial, bad = 0, badfill = 0;
    amps_ordering meths[] = {AMPS_ORDER_AUTO, AMPS_ORDER_AMD, AMPS_ORDER_ND};
    amps_ctx_init(&ctx);
    t_seed(7);
    for (trial = 0; trial < 60; trial++) {
        int n = 1 + t_int(trial < 30 ? 40 : 400), deg = 1 + t_int(8), nz = 0, k, j, b, st, cap;
        int *ti, *tj;
        int *perm = (int *)malloc(sizeof(int) * n);
        double *xyz = (double *)malloc(sizeof(double) * 3 * n);
        tmat m;
        cap = n * (deg + 1) + 4 * n;
        ti = (int *)malloc(sizeof(int) * cap);
        tj = (int *)malloc(sizeof(int) * cap);
        for (j = 0; j < n; j++) {
            ti[nz] = tj[nz] = j;
            nz++;
            xyz[3 * j] = t_unif();
            xyz[3 * j + 1] = t_unif();
            xyz[3 * j + 2] = j;
            if (t_unif() < 0.1) continue; /* isolated-ish */
            for (k = 0; k < deg; k++) {
                int i = t_int(n);
                if (t_unif() < 0.7 && j > 0) i = j - 1 - t_int(j < 6 ? j : 6); /* banded part */
                ti[nz] = i < j ? i : j;
                tj[nz] = i < j ? j : i;
                nz++;
            }
            if (n > 50 && t_int(n) < 2) /* dense row */
                for (k = 0; k < n && nz < cap - n * (deg + 1); k += 1 + t_int(2)) {
                    ti[nz] = k < j ? k : j;
                    tj[nz] = k < j ? j : k;
                    nz++;
                }
        }
        m = t_from_upper(n, nz, ti, tj, NULL);
        for (k = 0; k < 3; k++)
            for (b = 0; b <= 1; b++) {
                st = t_int(3) - 1;
                if (t_order(&ctx, &m, (amps_stype)st, meths[k], b,
                            meths[k] != AMPS_ORDER_AMD && t_unif() < 0.5 ? xyz : NULL, perm) != AMPS_OK ||
                    !t_is_perm(n, perm)) {
                    bad++;
                    CHECK(0, "random trial %d (n %d) %s block %d: %s", trial, n, mname(meths[k]), b, ctx.msg);
                }
            }
        if (amps_amd(&ctx, n, m.up, m.ui, perm) != AMPS_OK || !t_is_perm(n, perm)) bad++;
        else if (t_fill(&m, perm) > 1.1 * ref_nnzL(n, m.up, m.ui, m.ux, NULL, CHOLMOD_AMD, NULL) + 10) badfill++;
        if (amps_nd(&ctx, n, m.fp, m.fi, xyz, perm) != AMPS_OK || !t_is_perm(n, perm)) bad++;
        free(ti);
        free(tj);
        free(perm);
        free(xyz);
        t_free_mat(&m);
    }
    CHECK(bad == 0, "%d random trials failed", bad);
    CHECK(badfill == 0, "%d random trials with AMD fill > 1.1 x CHOLMOD", badfill);
}

/* CHOLMOD solves a fixed-base brick with our ND ordering as accurately as with its own AMD. */
static void test_solve(void) {
    fe_mesh mesh = fe_brick(4);
    int *fixed = (int *)calloc((size_t)mesh.nn, sizeof(int)), *dof = (int *)malloc(sizeof(int) * 3 * mesh.nn), *ti, *tj,
        n, nz, k, *perm;
    double *tx, *b, *x1, *x2;
    tmat m;
    amps_ctx ctx;
    amps_ctx_init(&ctx);
    for (k = 0; k < mesh.nn; k++) fixed[k] = mesh.xyz[3 * k + 2] == 0.0;
    n = fe_number(&mesh, fixed, dof);
    nz = fe_assemble(&mesh, dof, 1.0, 0.3, &ti, &tj, &tx);
    m = t_from_upper(n, nz, ti, tj, tx);
    perm = (int *)malloc(sizeof(int) * n);
    b = (double *)malloc(sizeof(double) * n);
    x1 = (double *)malloc(sizeof(double) * n);
    x2 = (double *)malloc(sizeof(double) * n);
    for (k = 0; k < n; k++) b[k] = t_unif() - 0.5;
    CHECK(t_order(&ctx, &m, AMPS_UPPER, AMPS_ORDER_ND, 3, NULL, perm) == AMPS_OK, "nd");
    CHECK(ref_solve(n, m.up, m.ui, m.ux, perm, 1, b, x1) == 0 && ref_solve(n, m.up, m.ui, m.ux, NULL, 1, b, x2) == 0,
          "solves");
    CHECK(t_norm(n, x2) > 0 && t_reldiff(n, x1, x2) < 1e-10, "solution with our ordering differs: %g",
          t_reldiff(n, x1, x2));
    free(fixed);
    free(dof);
    free(ti);
    free(tj);
    free(tx);
    free(perm);
    free(b);
    free(x1);
    free(x2);
    t_free_mat(&m);
    fe_free(&mesh);
}

/* Clique, star, path and a 2D grid (no node blocks): valid orderings, and fill close to the
   obvious optimum (path, star) or to CHOLMOD's METIS (grid). */
static void test_shapes(void) {
    amps_ctx ctx;
    int shape, k, j, r;
    amps_ordering meths[] = {AMPS_ORDER_AUTO, AMPS_ORDER_AMD, AMPS_ORDER_ND};
    amps_ctx_init(&ctx);
    for (shape = 0; shape < 4; shape++) {
        int n = shape == 0 ? 150 : shape == 3 ? 3600 : 2000, nz = 0, cap = shape == 0 ? n * (n + 1) / 2 : 3 * n;
        int *ti = (int *)malloc(sizeof(int) * cap), *tj = (int *)malloc(sizeof(int) * cap),
            *perm = (int *)malloc(sizeof(int) * n);
        const char *name = shape == 0 ? "clique" : shape == 1 ? "star" : shape == 2 ? "path" : "grid 60x60";
        tmat m;
        for (j = 0; j < n; j++) {
            ti[nz] = tj[nz] = j;
            nz++;
            if (shape == 0)
                for (k = 0; k < j; k++) {
                    ti[nz] = k;
                    tj[nz++] = j;
                }
            if (shape == 1 && j > 0) {
                ti[nz] = 0;
                tj[nz++] = j;
            }
            if (shape == 2 && j > 0) {
                ti[nz] = j - 1;
                tj[nz++] = j;
            }
            if (shape == 3) {
                if (j % 60 > 0) {
                    ti[nz] = j - 1;
                    tj[nz++] = j;
                }
                if (j >= 60) {
                    ti[nz] = j - 60;
                    tj[nz++] = j;
                }
            }
        }
        m = t_from_upper(n, nz, ti, tj, NULL);
        for (k = 0; k < 3; k++) {
            double f;
            r = t_order(&ctx, &m, AMPS_UPPER, meths[k], shape == 3 ? 1 : 0, NULL, perm);
            f = r == AMPS_OK && t_is_perm(n, perm) ? t_fill(&m, perm) : -1;
            CHECK(f > 0, "%s %s: %d %s", name, mname(meths[k]), r, ctx.msg);
            if (shape == 0) CHECK(f == n * (n + 1.0) / 2, "clique %s fill %.0f", mname(meths[k]), f);
            if (shape == 1) CHECK(f == 2.0 * n - 1, "star %s fill %.0f (optimum %d)", mname(meths[k]), f, 2 * n - 1);
            if (shape == 2) CHECK(f <= 3.0 * n, "path %s fill %.0f", mname(meths[k]), f);
            if (shape == 3 && meths[k] == AMPS_ORDER_ND) {
                double ref = ref_nnzL(n, m.up, m.ui, m.ux, NULL, CHOLMOD_METIS, NULL);
                CHECK(f <= 1.15 * ref, "grid ND fill %.0f vs CHOLMOD METIS %.0f", f, ref);
            }
        }
        free(ti);
        free(tj);
        free(perm);
        t_free_mat(&m);
    }
}

/* The AMD, ND and AUTO orders are postorders of their elimination trees: amps_postorder of the
   tree amps_etree finds under the ordering is the identity, and that tree is the factor's. */
static void test_postordered(void) {
    amps_ctx ctx;
    int t, k, b;
    amps_ordering meths[] = {AMPS_ORDER_AUTO, AMPS_ORDER_AMD, AMPS_ORDER_ND};
    amps_ctx_init(&ctx);
    for (t = 0; t < 3; t++) {
        fe_mesh mesh = t == 0 ? fe_brick(4) : t == 1 ? fe_beam(8) : fe_brick(7);
        tmat m = t_fe(&mesh);
        int n = m.n, *perm = (int *)malloc(sizeof(int) * n), *iperm = (int *)malloc(sizeof(int) * n);
        int *par = (int *)malloc(sizeof(int) * n), *post = (int *)malloc(sizeof(int) * n),
            *w = (int *)malloc(sizeof(int) * 3 * n);
        amps_csc A = t_view(&m, AMPS_UPPER);
        for (k = 0; k < 3; k++)
            for (b = 1; b <= 3; b += 2) {
                amps_order_opts o;
                amps_factor *F;
                int j, ok = 1;
                CHECK(t_order(&ctx, &m, AMPS_UPPER, meths[k], b, b == 3 ? m.xyz : NULL, perm) == AMPS_OK, "%s: %s",
                      mname(meths[k]), ctx.msg);
                for (j = 0; j < n; j++) iperm[perm[j]] = j;
                amps_etree(n, m.fp, m.fi, perm, iperm, par, w);
                amps_postorder(n, par, post, w);
                for (j = 0; j < n; j++) ok = ok && post[j] == j;
                CHECK(ok, "mesh %d %s block %d: the ordering is not a postorder of its elimination tree", t,
                      mname(meths[k]), b);
                memset(&o, 0, sizeof o);
                o.method = AMPS_ORDER_GIVEN;
                o.perm = perm;
                F = amps_analyze(&ctx, &A, AMPS_UPPER, &o);
                CHECK(F && !memcmp(F->parent, par, sizeof(int) * n), "mesh %d %s block %d: factor's tree differs", t,
                      mname(meths[k]), b);
                amps_factor_free(&ctx, F);
            }
        free(perm);
        free(iperm);
        free(par);
        free(post);
        free(w);
        t_free_mat(&m);
        fe_free(&mesh);
    }
}

int main(void) {
    test_methods();
    test_given();
    test_blocks();
    test_metis();
    test_amd_fill();
    test_nd_fill();
    test_edge_cases();
    test_invalid();
    test_alloc_failures();
    test_random();
    test_shapes();
    test_solve();
    test_postordered();
    return amps_t_end("test_ordering");
}
