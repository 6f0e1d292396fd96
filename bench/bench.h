/* bench/bench.h: the model, the step sequences and the helpers shared by the benchmark programs
   (include after amps.h, with AMPS_IMPLEMENTATION defined in the program).

   Meshes (spec): beam:<h> (5 x 5 x h grid), brick:<R> (1 x 1 x 2, (R+1)^2 (2R+1) nodes), or a
   TetGen .node / .msh / .mesh file. Material E = 1000, nu = 0.3. The base: the nodes in the
   lowest 4% of the up axis (beam, brick: z; a file: y, the bunny's base) are fixed.
   The advancing planar cut: its path is the nodes within half a mesh spacing h of the plane
   x = centre, not fixed, from the far end of the up axis inward (then by the third axis); a cut
   step cuts the next path node by the plane x = its own x (a node whose plane would leave a side
   empty is skipped). Opposing forces (+-1 in x) on up to 20 nodes within 3 h of the start of the
   path, off the plane, pull the two sides apart.
   Step sequences of bench/harness (bench_scen):
   cut:    the advancing cut;
   deform: the same path nodes pinned one per step with displacement -1% of the up extent along
           the up axis.
   The sequence is generated on a plain mesh (bench_scen_next), then replayed on every solver. */
#ifndef BENCH_H
#define BENCH_H
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <math.h>

#define BENCH_E 1000.0
#define BENCH_NU 0.3

/* ---- errors, memory, order statistics, CSV ---- */

static inline void bench_die(const char *what, const char *msg) {
    fprintf(stderr, "bench: %s: %s\n", what, msg);
    exit(1);
}

/* n zeroed bytes (at least 1); exits when out of memory */
static inline void *bench_alloc(size_t n) {
    void *p = calloc(n ? n : 1, 1);
    if (!p) bench_die("calloc", "out of memory");
    return p;
}

static inline int bench_cmpd(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

/* q-quantile of v[0..n-1] (sorts v): the element at floor(q (n - 1) + 0.5). */
static inline double bench_quantile(double *v, int n, double q) {
    if (n <= 0) return 0;
    qsort(v, (size_t)n, sizeof(double), bench_cmpd);
    return v[(int)(q * (n - 1) + 0.5)];
}

/* median of v[0..n-1] (sorts v): the element at n / 2. */
static inline double bench_median(double *v, int n) {
    if (n <= 0) return 0;
    qsort(v, (size_t)n, sizeof(double), bench_cmpd);
    return v[n / 2];
}

/* Opens path for appending; writes header first if the file is new or empty. NULL on failure. */
static inline FILE *bench_csv(const char *path, const char *header) {
    FILE *f = fopen(path, "a");
    if (!f) return NULL;
    fseek(f, 0, SEEK_END);
    if (ftell(f) == 0) fprintf(f, "%s\n", header);
    return f;
}

/* ---- the model ---- */

/* The mesh of spec with material E = BENCH_E, nu = BENCH_NU; exits on failure. */
static inline amps_mesh *bench_mesh(amps_ctx *ctx, const char *spec) {
    amps_mesh *m;
    if (!strncmp(spec, "beam:", 5)) m = amps_mesh_beam(ctx, atoi(spec + 5));
    else if (!strncmp(spec, "brick:", 6)) m = amps_mesh_brick(ctx, atoi(spec + 6));
    else m = amps_mesh_read(ctx, spec);
    if (!m || amps_mesh_set_material(ctx, m, BENCH_E, BENCH_NU) != AMPS_OK) bench_die(spec, ctx->msg);
    return m;
}

/* Short name of a mesh spec for file names and tables: beam_64, brick_14, bunny20k. */
static inline void bench_mesh_name(const char *spec, char *out, size_t len) {
    const char *b = strrchr(spec, '/');
    char *p;
    snprintf(out, len, "%s", b ? b + 1 : spec);
    if ((p = strstr(out, ".1.node")) != NULL) *p = 0;
    if ((p = strchr(out, ':')) != NULL) *p = '_';
}

/* The up axis, held at its low end: beam, brick: z (2); files (the bunny): y (1), its base. */
static inline int bench_up_axis(const char *spec) {
    return !strncmp(spec, "beam:", 5) || !strncmp(spec, "brick:", 6) ? 2 : 1;
}

/* The bounding box [lo, hi] of the nodes. */
static inline void bench_bbox(const amps_mesh *m, double lo[3], double hi[3]) {
    amps_int v;
    int d;
    for (d = 0; d < 3; d++) {
        lo[d] = 1e300;
        hi[d] = -1e300;
    }
    for (v = 0; v < m->nnode; v++)
        for (d = 0; d < 3; d++) {
            if (m->xyz[3 * v + d] < lo[d]) lo[d] = m->xyz[3 * v + d];
            if (m->xyz[3 * v + d] > hi[d]) hi[d] = m->xyz[3 * v + d];
        }
}

/* Scene options from the environment: AMPS_REFINE=<steps>, AMPS_DUAL (dual formulation),
   AMPS_GUARD=<tol> (accuracy guard); unset: the defaults. */
static inline void bench_scene_opts(amps_scene_opts *so) {
    amps_scene_opts_default(so);
    if (getenv("AMPS_REFINE")) so->update.refine = atoi(getenv("AMPS_REFINE"));
    if (getenv("AMPS_DUAL")) so->update.formulation = AMPS_FORM_DUAL;
    if (getenv("AMPS_GUARD")) so->update.guard_tol = atof(getenv("AMPS_GUARD"));
}

/* fixed[v] = 1 for the nodes within 4% of the extent of the low end of axis (the caller frees). */
static inline unsigned char *bench_base(const amps_mesh *m, int axis, const double lo[3], const double hi[3]) {
    amps_int v;
    unsigned char *fixed = (unsigned char *)bench_alloc((size_t)m->nnode);
    for (v = 0; v < m->nnode; v++) fixed[v] = m->xyz[3 * v + axis] < lo[axis] + 0.04 * (hi[axis] - lo[axis]) + 1e-12;
    return fixed;
}

/* Fixes the nodes v < nnode with fixed[v] in scene S. */
static inline amps_status bench_fix(amps_ctx *ctx, amps_scene *S, amps_int nnode, const unsigned char *fixed) {
    amps_int *fl = (amps_int *)bench_alloc(sizeof(amps_int) * (size_t)nnode), nf = 0, v;
    amps_status s;
    for (v = 0; v < nnode; v++)
        if (fixed[v]) fl[nf++] = v;
    s = amps_scene_fix(ctx, S, nf, fl);
    free(fl);
    return s;
}

/* ---- the advancing planar cut ----
   With wrap set, a used-up path starts again with the plane normal along the next axis (pass
   counts the restarts), so nodes are cut repeatedly. */
typedef struct bench_cut {
    int *path, npath, ip, wrap, pass;
    double xc, tol, h;
} bench_cut;

/* Sorts the nodes path[0:n] by descending coordinate ax, then ascending ax2 (insertion sort):
   the order in which the advancing cut visits them. */
static inline void bench_sort_path(const amps_mesh *m, int *path, int n, int ax, int ax2) {
    int i, j;
    for (i = 1; i < n; i++) {
        int pv = path[i];
        for (j = i - 1; j >= 0; j--) {
            const double *a = m->xyz + 3 * path[j], *b = m->xyz + 3 * pv;
            if (a[ax] > b[ax] + 1e-9 || (fabs(a[ax] - b[ax]) <= 1e-9 && a[ax2] <= b[ax2])) break;
            path[j + 1] = path[j];
        }
        path[j + 1] = pv;
    }
}

/* The path of the cut of mesh m (box [lo, hi], up axis, fixed nodes): centre xc, spacing h,
   tolerance h / 2. */
static inline void bench_cut_init(bench_cut *c, const amps_mesh *m, const unsigned char *fixed, int axis,
                                  const double lo[3], const double hi[3]) {
    int nn = (int)m->nnode, v;
    c->xc = 0.5 * (lo[0] + hi[0]);
    c->h = pow((hi[0] - lo[0]) * (hi[1] - lo[1]) * (hi[2] - lo[2]) / nn, 1.0 / 3.0);
    c->tol = 0.5 * c->h;
    c->npath = 0;
    c->ip = 0;
    c->wrap = 0;
    c->pass = 0;
    c->path = (int *)bench_alloc(sizeof(int) * (size_t)nn);
    for (v = 0; v < nn; v++)
        if (fabs(m->xyz[3 * v] - c->xc) <= c->tol && !fixed[v]) c->path[c->npath++] = v;
    bench_sort_path(m, c->path, c->npath, axis, axis == 2 ? 1 : 2);
}

/* The opposing forces of the cut into force (3 per node, at least nnode, zero elsewhere), and
   into scene S unless S is NULL. */
static inline void bench_cut_forces(amps_ctx *ctx, amps_scene *S, const amps_mesh *m, const unsigned char *fixed,
                                    const bench_cut *c, double *force) {
    const double *p0;
    int v, added = 0;
    if (c->npath <= 0) return;
    p0 = m->xyz + 3 * c->path[0];
    for (v = 0; v < (int)m->nnode && added < 20; v++) {
        const double *q = m->xyz + 3 * v;
        double dist = sqrt((q[1] - p0[1]) * (q[1] - p0[1]) + (q[2] - p0[2]) * (q[2] - p0[2]));
        if (fixed[v] || fabs(q[0] - c->xc) < c->tol || dist > 3 * c->h) continue;
        force[3 * v] = q[0] < c->xc ? -1.0 : 1.0;
        if (S) amps_scene_force(ctx, S, v, force + 3 * v);
        added++;
    }
}

/* One cut step on scene S: the plane through the next path node that the cut actually splits.
   *node gets the node cut; AMPS_WARN_NOOP when the path is exhausted (with wrap: when it has none). */
static inline amps_status bench_cut_next(amps_ctx *ctx, amps_scene *S, bench_cut *c, int *node) {
    amps_status s = AMPS_WARN_NOOP;
    while (s == AMPS_WARN_NOOP && (c->ip < c->npath || (c->wrap && c->npath > 0))) {
        double p[3], nrm[3] = {0, 0, 0};
        amps_int vc;
        if (c->ip >= c->npath) {
            c->ip = 0;
            c->pass++;
        }
        nrm[c->pass % 3] = 1;
        *node = c->path[c->ip++];
        memcpy(p, amps_scene_mesh(S)->xyz + 3 * *node, sizeof(p));
        s = amps_scene_cut(ctx, S, *node, p, nrm, &vc);
    }
    return s;
}

/* The model bench/haptic, watch and refactor start from: the scene of spec (bench_mesh), its
   base held, the cut's path and its opposing forces set. so: the scene options (NULL:
   bench_scene_opts). Exits on failure. */
typedef struct bench_model {
    amps_mesh *m;
    amps_scene *S;
    unsigned char *fixed;
    double *force, lo[3], hi[3];
    int up, nn;
    bench_cut cp;
} bench_model;

static inline void bench_model_init(amps_ctx *ctx, const char *spec, const amps_scene_opts *so, bench_model *b) {
    amps_scene_opts o;
    memset(b, 0, sizeof(*b));
    b->m = bench_mesh(ctx, spec);
    b->nn = (int)b->m->nnode;
    bench_bbox(b->m, b->lo, b->hi);
    b->up = bench_up_axis(spec);
    b->fixed = bench_base(b->m, b->up, b->lo, b->hi);
    if (so) o = *so;
    else bench_scene_opts(&o);
    b->S = amps_scene_create(ctx, b->m, &o);
    if (!b->S) bench_die(spec, ctx->msg);
    b->force = (double *)bench_alloc(sizeof(double) * 3 * (size_t)b->nn);
    amps_scene_set_material(ctx, b->S, BENCH_E, BENCH_NU);
    bench_fix(ctx, b->S, b->nn, b->fixed);
    bench_cut_init(&b->cp, b->m, b->fixed, b->up, b->lo, b->hi);
    bench_cut_forces(ctx, b->S, b->m, b->fixed, &b->cp, b->force);
}

/* ncuts steps of the advancing cut (a failed cut is reported and skipped); returns the cuts done. */
static inline int bench_cuts(amps_ctx *ctx, bench_model *b, int ncuts) {
    int k, done = 0;
    for (k = 0; k < ncuts; k++) {
        int node;
        amps_status s = bench_cut_next(ctx, b->S, &b->cp, &node);
        if (s == AMPS_WARN_NOOP) break;
        if (s != AMPS_OK) fprintf(stderr, "cut at %d: %s\n", node, ctx->msg);
        else done++;
    }
    return done;
}

/* Surface nodes: the nodes of the boundary faces (faces of exactly one tet). Writes them to out
   (room for nnode), ascending; returns their number. */
static inline int bench_cmp_face(const void *a, const void *b) {
    const amps_int *x = (const amps_int *)a, *y = (const amps_int *)b;
    int k;
    for (k = 0; k < 3; k++)
        if (x[k] != y[k]) return x[k] < y[k] ? -1 : 1;
    return 0;
}

static inline void bench_swap(amps_int *a, amps_int *b) {
    amps_int t = *a;
    *a = *b;
    *b = t;
}

static inline int bench_surface_nodes(const amps_mesh *m, amps_int *out) {
    size_t nf = 4 * (size_t)m->ntet, f, g;
    amps_int *fc = (amps_int *)bench_alloc(sizeof(amps_int) * 3 * nf), t, v;
    unsigned char *on = (unsigned char *)bench_alloc((size_t)m->nnode);
    int k, cnt = 0;
    for (t = 0; t < m->ntet; t++)
        for (k = 0; k < 4; k++) {
            amps_int *q = fc + 3 * (4 * (size_t)t + (size_t)k), a, b, c;
            a = m->tet[4 * t + (k + 1) % 4];
            b = m->tet[4 * t + (k + 2) % 4];
            c = m->tet[4 * t + (k + 3) % 4];
            if (a > b) bench_swap(&a, &b);
            if (b > c) bench_swap(&b, &c);
            if (a > b) bench_swap(&a, &b);
            q[0] = a;
            q[1] = b;
            q[2] = c;
        }
    qsort(fc, nf, 3 * sizeof(amps_int), bench_cmp_face);
    for (f = 0; f < nf; f = g) {
        for (g = f + 1; g < nf && !bench_cmp_face(fc + 3 * f, fc + 3 * g); g++) {}
        if (g - f == 1)
            for (k = 0; k < 3; k++) on[fc[3 * f + (size_t)k]] = 1;
    }
    for (v = 0; v < m->nnode; v++)
        if (on[v]) out[cnt++] = v;
    free(fc);
    free(on);
    return cnt;
}

/* ---- the step sequences of bench/harness ---- */
typedef struct bench_scen {
    int cut, nn0, axis, cap; /* cap: node capacity (nn0 + steps + 16) */
    double lo[3], hi[3];
    bench_cut cp;          /* the path: cut / pin order */
    unsigned char *fixed0; /* by creation node */
    double *force;         /* 3 per node (cap nodes) */
    unsigned char *pinned; /* per node */
    double *pinval;        /* 3 per node */
} bench_scen;

/* one step of the sequence: the node cut (plane through p, normal x) or pinned (to u) */
typedef struct bench_step {
    int node, vc, nmoved; /* vc: the copy a cut made; moved: the tets now using vc */
    double p[3], u[3];
    amps_int *moved;
} bench_step;

static inline void bench_scen_init(bench_scen *sc, const amps_mesh *m, const char *spec, int cut, int steps) {
    memset(sc, 0, sizeof(*sc));
    sc->cut = cut;
    sc->nn0 = (int)m->nnode;
    sc->cap = sc->nn0 + steps + 16;
    bench_bbox(m, sc->lo, sc->hi);
    sc->axis = bench_up_axis(spec);
    sc->fixed0 = bench_base(m, sc->axis, sc->lo, sc->hi);
    bench_cut_init(&sc->cp, m, sc->fixed0, sc->axis, sc->lo, sc->hi);
    sc->force = (double *)bench_alloc(sizeof(double) * 3 * (size_t)sc->cap);
    sc->pinned = (unsigned char *)bench_alloc((size_t)sc->cap);
    sc->pinval = (double *)bench_alloc(sizeof(double) * 3 * (size_t)sc->cap);
    if (cut) bench_cut_forces(NULL, NULL, m, sc->fixed0, &sc->cp, sc->force);
}

static inline void bench_scen_free(bench_scen *sc) {
    free(sc->fixed0);
    free(sc->cp.path);
    free(sc->force);
    free(sc->pinned);
    free(sc->pinval);
}

/* A scene over a fresh copy of the mesh with the scenario's material, fixed nodes and forces. */
static inline amps_scene *bench_scen_scene(amps_ctx *ctx, const bench_scen *sc, const char *spec,
                                           const amps_scene_opts *so) {
    amps_scene *S = amps_scene_create(ctx, bench_mesh(ctx, spec), so);
    amps_int v;
    if (!S) bench_die("amps_scene_create", ctx->msg);
    amps_scene_set_material(ctx, S, BENCH_E, BENCH_NU);
    bench_fix(ctx, S, sc->nn0, sc->fixed0);
    for (v = 0; v < sc->nn0; v++)
        if (sc->force[3 * v] != 0) amps_scene_force(ctx, S, v, sc->force + 3 * v);
    return S;
}

/* Next step of the sequence, applied to the plain mesh M (cut) or to the scenario (pin).
   s->moved needs room for the largest node degree. Returns 0 when the path is exhausted. */
static inline int bench_scen_next(amps_ctx *ctx, bench_scen *sc, amps_mesh *M, bench_step *s) {
    s->nmoved = 0;
    s->vc = -1;
    while (sc->cp.ip < sc->cp.npath) {
        s->node = sc->cp.path[sc->cp.ip++];
        memcpy(s->p, M->xyz + 3 * s->node, sizeof(s->p));
        if (sc->cut) {
            double nrm[3] = {1, 0, 0};
            amps_int vc, nm;
            amps_status st = amps_mesh_cut(ctx, M, s->node, s->p, nrm, &vc, s->moved, &nm);
            if (st == AMPS_WARN_NOOP) continue;
            if (st != AMPS_OK) bench_die("amps_mesh_cut", ctx->msg);
            s->vc = (int)vc;
            s->nmoved = (int)nm;
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
static inline void bench_scen_undo(amps_ctx *ctx, bench_scen *sc, amps_mesh *M, const bench_step *s) {
    if (sc->cut) amps_mesh_uncut(ctx, M, s->node, s->vc, s->moved, s->nmoved);
    else sc->pinned[s->node] = 0;
}

/* The step on a scene (the change only; the caller solves). */
static inline amps_status bench_scen_apply(amps_ctx *ctx, amps_scene *S, const bench_scen *sc, const bench_step *s) {
    if (sc->cut) {
        double nrm[3] = {1, 0, 0};
        return amps_scene_cut(ctx, S, s->node, s->p, nrm, NULL);
    }
    return amps_scene_pin(ctx, S, s->node, s->u);
}

/* ---- the current system of bench/harness in explicit form ----
   Equations: the DOFs of the current mesh minus the fixed nodes' (amps_mesh_number_dofs: node
   order, so the numbering of old DOFs never changes and a cut's copy appends 3). Pinned DOFs
   (con) stay in the numbering with their values g; the reduced system is
   K_FF x_F = b_F, b = f - K g, F = unpinned equations. */
typedef struct bench_sys {
    int nn, n;
    amps_int *dof; /* 3 per node, -1 fixed */
    amps_csc *K;   /* upper triangle */
    amps_csc *Kf;  /* both triangles (column j = row j) */
    double *f, *g, *b;
    unsigned char *con;
    double nb; /* ||b_F|| */
} bench_sys;

/* both triangles of a symmetric matrix given by its upper triangle */
static inline amps_csc *bench_sym_full(amps_ctx *ctx, const amps_csc *U) {
    amps_int n = U->ncol, j, p, *cnt = (amps_int *)bench_alloc(sizeof(amps_int) * ((size_t)n + 1));
    amps_csc *A;
    for (j = 0; j < n; j++)
        for (p = U->p[j]; p < U->p[j + 1]; p++) {
            cnt[j]++;
            if (U->i[p] != j) cnt[U->i[p]]++;
        }
    A = amps_csc_alloc(ctx, n, n, 2 * U->p[n], 1);
    if (!A) bench_die("amps_csc_alloc", ctx->msg);
    A->p[0] = 0;
    for (j = 0; j < n; j++) A->p[j + 1] = A->p[j] + cnt[j];
    for (j = 0; j < n; j++) cnt[j] = A->p[j];
    /* rows ascend: entries (i < j) of column j come from the upper part in column order */
    for (j = 0; j < n; j++)
        for (p = U->p[j]; p < U->p[j + 1]; p++) {
            amps_int i = U->i[p];
            A->i[cnt[j]] = i;
            A->x[cnt[j]++] = U->x[p];
            if (i != j) {
                A->i[cnt[i]] = j;
                A->x[cnt[i]++] = U->x[p];
            }
        }
    free(cnt);
    /* column j got its own upper entries first (rows <= j) and then rows > j in ascending j: sorted */
    return A;
}

/* y = A x for A with both triangles (OpenMP over columns = rows) */
static inline void bench_spmv(const amps_csc *A, const double *x, double *y) {
    amps_int j;
#pragma omp parallel for schedule(static) if (A->p[A->ncol] > 200000)
    for (j = 0; j < A->ncol; j++) {
        amps_int p;
        double s = 0;
        for (p = A->p[j]; p < A->p[j + 1]; p++) s += A->x[p] * x[A->i[p]];
        y[j] = s;
    }
}

/* b = f - K g and nb = ||b_F|| from f, g, con and Kf (t: n doubles of scratch). */
static inline void bench_sys_rhs(bench_sys *S, double *t) {
    int i;
    bench_spmv(S->Kf, S->g, t);
    S->nb = 0;
    for (i = 0; i < S->n; i++) {
        S->b[i] = S->f[i] - t[i];
        if (!S->con[i]) S->nb += S->b[i] * S->b[i];
    }
    S->nb = sqrt(S->nb);
}

static inline void bench_sys_build(amps_ctx *ctx, const bench_scen *sc, const amps_mesh *M, bench_sys *S) {
    int v, d, nn = (int)M->nnode;
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
    for (v = 0; v < nn; v++)
        for (d = 0; d < 3; d++) {
            amps_int e = S->dof[3 * v + d];
            if (e < 0) continue;
            S->f[e] = v < sc->cap ? sc->force[3 * v + d] : 0;
            if (v < sc->cap && sc->pinned[v]) {
                S->con[e] = 1;
                S->g[e] = sc->pinval[3 * v + d];
            }
        }
    bench_sys_rhs(S, t);
    free(t);
    free(fixed);
}

static inline void bench_sys_free(amps_ctx *ctx, bench_sys *S) {
    amps_csc_free(ctx, S->K);
    amps_csc_free(ctx, S->Kf);
    free(S->dof);
    free(S->f);
    free(S->g);
    free(S->b);
    free(S->con);
}

/* equation vector of node displacements (3 per node) */
static inline void bench_sys_from_disp(const bench_sys *S, const double *disp, double *x) {
    int v, d;
    for (v = 0; v < S->nn; v++)
        for (d = 0; d < 3; d++)
            if (S->dof[3 * v + d] >= 0) x[S->dof[3 * v + d]] = disp[3 * v + d];
}

/* ||(K x - f)_F|| / ||b_F|| for x with x_C = g; work has n doubles */
static inline double bench_sys_relres(const bench_sys *S, const double *x, double *work) {
    int i;
    double r = 0;
    bench_spmv(S->Kf, x, work);
    for (i = 0; i < S->n; i++)
        if (!S->con[i]) r += (work[i] - S->f[i]) * (work[i] - S->f[i]);
    return S->nb > 0 ? sqrt(r) / S->nb : sqrt(r);
}

/* ||x_F - xref_F|| / ||xref_F|| */
static inline double bench_sys_relerr(const bench_sys *S, const double *x, const double *xref) {
    int i;
    double e = 0, r = 0;
    for (i = 0; i < S->n; i++)
        if (!S->con[i]) {
            e += (x[i] - xref[i]) * (x[i] - xref[i]);
            r += xref[i] * xref[i];
        }
    return r > 0 ? sqrt(e / r) : sqrt(e);
}
#endif
