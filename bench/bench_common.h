/* bench/bench_common.h: the scenario shared by the benchmark programs (include after amps.h with
   AMPS_IMPLEMENTATION in the program).

   Meshes: beam:<h> (5 x 5 x h grid), brick:<R> (1 x 1 x 2, (R+1)^2 (2R+1) nodes), or a TetGen
   .node / .msh / .mesh file. Material E = 1000, nu = 0.3. The nodes in the lowest 4% of the long
   axis (beam, brick: z; a file: y, the bunny's base) are fixed.
   Step sequences:
   cut:    an advancing planar cut: the nodes within half a mesh spacing of the plane x = centre,
           from the far end of the long axis inward, each cut by the plane x = its own x (a node
           whose plane would leave a side empty is skipped), with opposing forces (+-1 in x) on
           up to 20 nodes near the start of the cut pulling the two sides apart;
   deform: the same path nodes pinned one per step with displacement -1% of the long extent
           along the long axis.
   The sequence is generated on a plain mesh (bscen_next), then replayed on every solver. */
#ifndef BENCH_COMMON_H
#define BENCH_COMMON_H
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <math.h>
#include "bench_util.h"

#define BENCH_E 1000.0
#define BENCH_NU 0.3

static void bench_die(const char *what, const char *msg) {
    fprintf(stderr, "bench: %s: %s\n", what, msg);
    exit(1);
}

static void *bench_alloc(size_t n) {
    void *p = calloc(n ? n : 1, 1);
    if (!p) bench_die("calloc", "out of memory");
    return p;
}

static amps_mesh *bench_mesh(amps_ctx *ctx, const char *spec) {
    amps_mesh *m;
    if (!strncmp(spec, "beam:", 5)) m = amps_mesh_beam(ctx, atoi(spec + 5));
    else if (!strncmp(spec, "brick:", 6)) m = amps_mesh_brick(ctx, atoi(spec + 6));
    else m = amps_mesh_read(ctx, spec);
    if (!m) bench_die(spec, ctx->msg);
    amps_mesh_set_material(ctx, m, BENCH_E, BENCH_NU);
    return m;
}

typedef struct bscen {
    int cut, nn0, axis, npath, ip, cap;
    double lo[3], hi[3], xc, h, tol;
    unsigned char *fixed0;      /* by creation node */
    int *path;                  /* cut / pin order */
    double *force;              /* 3 per node (cap nodes) */
    unsigned char *pinned;      /* per node */
    double *pinval;             /* 3 per node */
} bscen;

/* one step of the sequence: the node cut (plane through p, normal x) or pinned (to u) */
typedef struct bstep {
    int node, vc, nmoved;       /* vc: the copy a cut made; moved: the tets now using vc */
    double p[3], u[3];
    amps_int *moved;
} bstep;

static void bscen_init(bscen *sc, const amps_mesh *m, const char *spec, int cut, int steps) {
    int v, d, nn0 = (int)m->nnode;
    memset(sc, 0, sizeof(*sc));
    sc->cut = cut; sc->nn0 = nn0; sc->cap = nn0 + steps + 16;
    for (d = 0; d < 3; d++) { sc->lo[d] = 1e300; sc->hi[d] = -1e300; }
    for (v = 0; v < nn0; v++) for (d = 0; d < 3; d++) {
        if (m->xyz[3 * v + d] < sc->lo[d]) sc->lo[d] = m->xyz[3 * v + d];
        if (m->xyz[3 * v + d] > sc->hi[d]) sc->hi[d] = m->xyz[3 * v + d];
    }
    sc->axis = !strncmp(spec, "beam:", 5) || !strncmp(spec, "brick:", 6) ? 2 : 1;
    sc->fixed0 = (unsigned char *)bench_alloc((size_t)nn0);
    for (v = 0; v < nn0; v++)
        sc->fixed0[v] = m->xyz[3 * v + sc->axis] < sc->lo[sc->axis] + 0.04 * (sc->hi[sc->axis] - sc->lo[sc->axis]) + 1e-12;
    sc->xc = 0.5 * (sc->lo[0] + sc->hi[0]);
    sc->h = pow((sc->hi[0] - sc->lo[0]) * (sc->hi[1] - sc->lo[1]) * (sc->hi[2] - sc->lo[2]) / nn0, 1.0 / 3.0);
    sc->tol = 0.5 * sc->h;
    sc->path = (int *)bench_alloc(sizeof(int) * (size_t)nn0);
    for (v = 0; v < nn0; v++) if (fabs(m->xyz[3 * v] - sc->xc) <= sc->tol && !sc->fixed0[v]) sc->path[sc->npath++] = v;
    bu_sort_path(m, sc->path, sc->npath, sc->axis, sc->axis == 2 ? 1 : 2);   /* descending long axis */
    sc->force = (double *)bench_alloc(sizeof(double) * 3 * (size_t)sc->cap);
    sc->pinned = (unsigned char *)bench_alloc((size_t)sc->cap);
    sc->pinval = (double *)bench_alloc(sizeof(double) * 3 * (size_t)sc->cap);
    if (cut && sc->npath > 0) {
        const double *p0 = m->xyz + 3 * sc->path[0];
        int added = 0;
        for (v = 0; v < nn0 && added < 20; v++) {
            const double *q = m->xyz + 3 * v;
            double dist = sqrt((q[1] - p0[1]) * (q[1] - p0[1]) + (q[2] - p0[2]) * (q[2] - p0[2]));
            if (sc->fixed0[v] || fabs(q[0] - sc->xc) < sc->tol || dist > 3 * sc->h) continue;
            sc->force[3 * v] = q[0] < sc->xc ? -1.0 : 1.0;
            added++;
        }
    }
}

static void bscen_free(bscen *sc) {
    free(sc->fixed0); free(sc->path); free(sc->force); free(sc->pinned); free(sc->pinval);
}

/* A scene over a fresh copy of the mesh with the scenario's material, fixed nodes and forces. */
static amps_scene *bscen_scene(amps_ctx *ctx, const bscen *sc, const char *spec, const amps_scene_opts *so) {
    amps_mesh *m = bench_mesh(ctx, spec);
    amps_scene *S = amps_scene_create(ctx, m, so);
    amps_int *fl = (amps_int *)bench_alloc(sizeof(amps_int) * (size_t)sc->nn0), nf = 0, v;
    if (!S) bench_die("amps_scene_create", ctx->msg);
    amps_scene_set_material(ctx, S, BENCH_E, BENCH_NU);
    for (v = 0; v < sc->nn0; v++) if (sc->fixed0[v]) fl[nf++] = v;
    amps_scene_fix(ctx, S, nf, fl);
    for (v = 0; v < sc->nn0; v++) if (sc->force[3 * v] != 0) amps_scene_force(ctx, S, v, sc->force + 3 * v);
    free(fl);
    return S;
}

/* Next step of the sequence, applied to the plain mesh M (cut) or to the scenario (pin).
   s->moved needs room for the largest node degree. Returns 0 when the path is exhausted. */
static int bscen_next(amps_ctx *ctx, bscen *sc, amps_mesh *M, bstep *s) {
    s->nmoved = 0; s->vc = -1;
    while (sc->ip < sc->npath) {
        s->node = sc->path[sc->ip++];
        memcpy(s->p, M->xyz + 3 * s->node, sizeof(s->p));
        if (sc->cut) {
            double nrm[3] = {1, 0, 0};
            amps_int vc, nm;
            amps_status st = amps_mesh_cut(ctx, M, s->node, s->p, nrm, &vc, s->moved, &nm);
            if (st == AMPS_WARN_NOOP) continue;
            if (st != AMPS_OK) bench_die("amps_mesh_cut", ctx->msg);
            s->vc = (int)vc; s->nmoved = (int)nm;
            return 1;
        }
        memset(s->u, 0, sizeof(s->u));
        s->u[sc->axis] = -0.01 * (sc->hi[sc->axis] - sc->lo[sc->axis]);
        sc->pinned[s->node] = 1;
        memcpy(sc->pinval + 3 * s->node, s->u, sizeof(s->u));
        return 1;
    }
    return 0;
}

/* Takes a step back (the solvers found the cut singular). */
static void bscen_undo(amps_ctx *ctx, bscen *sc, amps_mesh *M, const bstep *s) {
    if (sc->cut) amps_mesh_uncut(ctx, M, s->node, s->vc, s->moved, s->nmoved);
    else sc->pinned[s->node] = 0;
}

/* The step on a scene (the change only; the caller solves). */
static amps_status bscen_apply(amps_ctx *ctx, amps_scene *S, const bscen *sc, const bstep *s) {
    if (sc->cut) {
        double nrm[3] = {1, 0, 0};
        return amps_scene_cut(ctx, S, s->node, s->p, nrm, NULL);
    }
    return amps_scene_pin(ctx, S, s->node, s->u);
}

/* ---- the current system in explicit form ----
   Equations: the DOFs of the current mesh minus the fixed nodes' (amps_mesh_number_dofs: node
   order, so the numbering of old DOFs never changes and a cut's copy appends 3). Pinned DOFs
   (con) stay in the numbering with their values g; the reduced system is
   K_FF x_F = b_F, b = f - K g, F = unpinned equations. */
typedef struct bsys {
    int nn, n;
    amps_int *dof;              /* 3 per node, -1 fixed */
    amps_csc *K;                /* upper triangle */
    amps_csc *Kf;               /* both triangles (column j = row j) */
    double *f, *g, *b;
    unsigned char *con;
    double nb;                  /* ||b_F|| */
} bsys;

/* both triangles of a symmetric matrix given by its upper triangle */
static amps_csc *bench_sym_full(amps_ctx *ctx, const amps_csc *U) {
    amps_int n = U->ncol, j, p, *cnt = (amps_int *)bench_alloc(sizeof(amps_int) * ((size_t)n + 1));
    amps_csc *A;
    for (j = 0; j < n; j++) for (p = U->p[j]; p < U->p[j + 1]; p++) { cnt[j]++; if (U->i[p] != j) cnt[U->i[p]]++; }
    A = amps_csc_alloc(ctx, n, n, 2 * U->p[n], 1);
    if (!A) bench_die("amps_csc_alloc", ctx->msg);
    A->p[0] = 0;
    for (j = 0; j < n; j++) A->p[j + 1] = A->p[j] + cnt[j];
    for (j = 0; j < n; j++) cnt[j] = A->p[j];
    /* rows ascend: entries (i < j) of column j come from the upper part in column order */
    for (j = 0; j < n; j++)
        for (p = U->p[j]; p < U->p[j + 1]; p++) {
            amps_int i = U->i[p];
            A->i[cnt[j]] = i; A->x[cnt[j]++] = U->x[p];
            if (i != j) { A->i[cnt[i]] = j; A->x[cnt[i]++] = U->x[p]; }
        }
    free(cnt);
    /* column j got its own upper entries first (rows <= j) and then rows > j in ascending j: sorted */
    return A;
}

/* y = A x for A with both triangles (OpenMP over columns = rows) */
static void bench_spmv(const amps_csc *A, const double *x, double *y) {
    amps_int j;
#pragma omp parallel for schedule(static) if (A->p[A->ncol] > 200000)
    for (j = 0; j < A->ncol; j++) {
        amps_int p;
        double s = 0;
        for (p = A->p[j]; p < A->p[j + 1]; p++) s += A->x[p] * x[A->i[p]];
        y[j] = s;
    }
}

static void bsys_build(amps_ctx *ctx, const bscen *sc, const amps_mesh *M, bsys *S) {
    int v, d, i, nn = (int)M->nnode;
    unsigned char *fixed = (unsigned char *)bench_alloc((size_t)nn);
    double *t;
    memset(S, 0, sizeof(*S));
    S->nn = nn;
    for (v = 0; v < nn; v++) fixed[v] = sc->fixed0[M->origin[v]];
    S->dof = (amps_int *)bench_alloc(sizeof(amps_int) * 3 * (size_t)nn);
    S->n = (int)amps_mesh_number_dofs(M, fixed, S->dof);
    S->K = amps_mesh_assemble(ctx, M, S->dof, S->n);
    if (!S->K) bench_die("amps_mesh_assemble", ctx->msg);
    S->Kf = bench_sym_full(ctx, S->K);
    S->f = (double *)bench_alloc(sizeof(double) * (size_t)S->n);
    S->g = (double *)bench_alloc(sizeof(double) * (size_t)S->n);
    S->b = (double *)bench_alloc(sizeof(double) * (size_t)S->n);
    S->con = (unsigned char *)bench_alloc((size_t)S->n);
    t = (double *)bench_alloc(sizeof(double) * (size_t)S->n);
    for (v = 0; v < nn; v++) for (d = 0; d < 3; d++) {
        amps_int e = S->dof[3 * v + d];
        if (e < 0) continue;
        S->f[e] = v < sc->cap ? sc->force[3 * v + d] : 0;
        if (v < sc->cap && sc->pinned[v]) { S->con[e] = 1; S->g[e] = sc->pinval[3 * v + d]; }
    }
    bench_spmv(S->Kf, S->g, t);
    S->nb = 0;
    for (i = 0; i < S->n; i++) { S->b[i] = S->f[i] - t[i]; if (!S->con[i]) S->nb += S->b[i] * S->b[i]; }
    S->nb = sqrt(S->nb);
    free(t); free(fixed);
}

static void bsys_free(amps_ctx *ctx, bsys *S) {
    amps_csc_free(ctx, S->K); amps_csc_free(ctx, S->Kf);
    free(S->dof); free(S->f); free(S->g); free(S->b); free(S->con);
}

/* equation vector of node displacements (3 per node) */
static void bsys_from_disp(const bsys *S, const double *disp, double *x) {
    int v, d;
    for (v = 0; v < S->nn; v++) for (d = 0; d < 3; d++) if (S->dof[3 * v + d] >= 0) x[S->dof[3 * v + d]] = disp[3 * v + d];
}

/* ||(K x - f)_F|| / ||b_F|| for x with x_C = g; work has n doubles */
static double bsys_relres(const bsys *S, const double *x, double *work) {
    int i;
    double r = 0;
    bench_spmv(S->Kf, x, work);
    for (i = 0; i < S->n; i++) if (!S->con[i]) r += (work[i] - S->f[i]) * (work[i] - S->f[i]);
    return S->nb > 0 ? sqrt(r) / S->nb : sqrt(r);
}

/* ||x_F - xref_F|| / ||xref_F|| */
static double bsys_relerr(const bsys *S, const double *x, const double *xref) {
    int i;
    double e = 0, r = 0;
    for (i = 0; i < S->n; i++) if (!S->con[i]) { e += (x[i] - xref[i]) * (x[i] - xref[i]); r += xref[i] * xref[i]; }
    return r > 0 ? sqrt(e / r) : sqrt(e);
}
#endif
