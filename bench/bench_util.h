/* bench/bench_util.h: helpers shared by the benchmark programs (include after amps.h).
   Mesh loading (beam:<h> | brick:<R> | file), the held base, the advancing planar cut (the
   path of bench/harness), surface nodes, order statistics and CSV output. */
#ifndef BENCH_UTIL_H
#define BENCH_UTIL_H
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <math.h>

static inline int bu_cmpd(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}
/* q-quantile of v[0..n-1] (sorts v): the element at floor(q (n - 1) + 0.5); median: q = 0.5. */
static inline double bu_quantile(double *v, int n, double q) {
    if (n <= 0) return 0;
    qsort(v, (size_t)n, sizeof(double), bu_cmpd);
    return v[(int)(q * (n - 1) + 0.5)];
}
static inline double bu_median(double *v, int n) {
    if (n <= 0) return 0;
    qsort(v, (size_t)n, sizeof(double), bu_cmpd);
    return v[n / 2];
}

/* beam:<h> | brick:<R> | a mesh file (amps_mesh_read); NULL with ctx->msg on failure. */
static inline amps_mesh *bu_load_mesh(amps_ctx *ctx, const char *spec) {
    if (!strncmp(spec, "beam:", 5)) return amps_mesh_beam(ctx, atoi(spec + 5));
    if (!strncmp(spec, "brick:", 6)) return amps_mesh_brick(ctx, atoi(spec + 6));
    return amps_mesh_read(ctx, spec);
}
/* Short name of a mesh spec for file names and tables: beam_64, brick_14, bunny20k. */
static inline void bu_mesh_name(const char *spec, char *out, size_t len) {
    const char *b = strrchr(spec, '/');
    char *p;
    snprintf(out, len, "%s", b ? b + 1 : spec);
    if ((p = strstr(out, ".1.node")) != NULL) *p = 0;
    if ((p = strchr(out, ':')) != NULL) *p = '_';
}

/* The long axis, held at its low end: beam, brick: z (2); files (the bunny): y (1), its base. */
static inline int bu_up_axis(const char *spec) {
    return !strncmp(spec, "beam:", 5) || !strncmp(spec, "brick:", 6) ? 2 : 1;
}
static inline void bu_bbox(const amps_mesh *m, double lo[3], double hi[3]) {
    amps_int v;
    int d;
    for (d = 0; d < 3; d++) { lo[d] = 1e300; hi[d] = -1e300; }
    for (v = 0; v < m->nnode; v++)
        for (d = 0; d < 3; d++) {
            if (m->xyz[3 * v + d] < lo[d]) lo[d] = m->xyz[3 * v + d];
            if (m->xyz[3 * v + d] > hi[d]) hi[d] = m->xyz[3 * v + d];
        }
}
/* Scene options from the environment: AMPS_REFINE=<steps>, AMPS_DUAL (dual formulation),
   AMPS_GUARD=<tol> (accuracy guard); unset: the defaults. */
static inline void bu_scene_opts(amps_scene_opts *so) {
    amps_scene_opts_default(so);
    if (getenv("AMPS_REFINE")) so->update.refine = atoi(getenv("AMPS_REFINE"));
    if (getenv("AMPS_DUAL")) so->update.formulation = AMPS_FORM_DUAL;
    if (getenv("AMPS_GUARD")) so->update.guard_tol = atof(getenv("AMPS_GUARD"));
}
/* fixed[v] = 1 for the nodes within 4% of the extent of the low end of axis (calloc'ed). */
static inline unsigned char *bu_base(const amps_mesh *m, int axis, const double lo[3], const double hi[3]) {
    amps_int v;
    unsigned char *fixed = (unsigned char *)calloc((size_t)m->nnode + 1, 1);
    if (fixed)
        for (v = 0; v < m->nnode; v++) fixed[v] = m->xyz[3 * v + axis] < lo[axis] + 0.04 * (hi[axis] - lo[axis]) + 1e-12;
    return fixed;
}
/* Fixes the nodes with fixed[v] in scene S. */
static inline amps_status bu_fix(amps_ctx *ctx, amps_scene *S, amps_int nnode, const unsigned char *fixed) {
    amps_int *fl = (amps_int *)malloc(sizeof(amps_int) * ((size_t)nnode + 1)), nf = 0, v;
    amps_status s;
    if (!fl) return AMPS_ERR_OOM;
    for (v = 0; v < nnode; v++) if (fixed[v]) fl[nf++] = v;
    s = amps_scene_fix(ctx, S, nf, fl);
    free(fl);
    return s;
}

/* The advancing planar cut of bench/harness: the nodes within half a mesh spacing h of the
   plane x = xc (the centre), not fixed, ordered by descending up-axis coordinate, then the
   third axis; each cut step cuts the next path node by the plane x = its own x. With wrap set,
   a used-up path starts again with the plane normal along the next axis (pass counts the
   restarts), so nodes are cut repeatedly. */
typedef struct bu_cut {
    int *path, npath, ip, wrap, pass;
    double xc, tol, h;
} bu_cut;

/* Sorts the nodes path[0:n] by descending coordinate ax, then ascending ax2 (insertion sort):
   the order in which the advancing cut visits them. */
static inline void bu_sort_path(const amps_mesh *m, int *path, int n, int ax, int ax2) {
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

static inline int bu_cut_init(bu_cut *c, const amps_mesh *m, const unsigned char *fixed, int axis, const double lo[3], const double hi[3]) {
    int nn = (int)m->nnode, v, ax2 = axis == 2 ? 1 : 2;
    c->xc = 0.5 * (lo[0] + hi[0]);
    c->h = pow((hi[0] - lo[0]) * (hi[1] - lo[1]) * (hi[2] - lo[2]) / nn, 1.0 / 3.0);
    c->tol = 0.5 * c->h;
    c->npath = 0; c->ip = 0; c->wrap = 0; c->pass = 0;
    c->path = (int *)malloc(sizeof(int) * ((size_t)nn + 1));
    if (!c->path) return -1;
    for (v = 0; v < nn; v++) if (fabs(m->xyz[3 * v] - c->xc) <= c->tol && !fixed[v]) c->path[c->npath++] = v;
    bu_sort_path(m, c->path, c->npath, axis, ax2);
    return 0;
}

/* Opposing unit forces (-x / +x) on up to 20 nodes within 3 h of the start of the cut, off the
   plane, one per side of it; force (3 per node, at least nnode) receives them too. */
static inline void bu_cut_forces(amps_ctx *ctx, amps_scene *S, const amps_mesh *m, const unsigned char *fixed,
                                 const bu_cut *c, double *force) {
    const double *p0;
    int v, added = 0;
    if (c->npath <= 0) return;
    p0 = m->xyz + 3 * c->path[0];
    for (v = 0; v < (int)m->nnode && added < 20; v++) {
        const double *q = m->xyz + 3 * v;
        double dist = sqrt((q[1] - p0[1]) * (q[1] - p0[1]) + (q[2] - p0[2]) * (q[2] - p0[2]));
        if (fixed[v] || fabs(q[0] - c->xc) < c->tol || dist > 3 * c->h) continue;
        force[3 * v] = q[0] < c->xc ? -1.0 : 1.0;
        amps_scene_force(ctx, S, v, force + 3 * v);
        added++;
    }
}

/* One cut step: the plane through the next path node that the cut actually splits. *node gets
   the node cut; AMPS_WARN_NOOP when the path is exhausted (with wrap: when it has none). */
static inline amps_status bu_cut_next(amps_ctx *ctx, amps_scene *S, bu_cut *c, int *node) {
    amps_status s = AMPS_WARN_NOOP;
    while (s == AMPS_WARN_NOOP && (c->ip < c->npath || (c->wrap && c->npath > 0))) {
        double p[3], nrm[3] = {0, 0, 0};
        amps_int vc;
        if (c->ip >= c->npath) { c->ip = 0; c->pass++; }
        nrm[c->pass % 3] = 1;
        *node = c->path[c->ip++];
        memcpy(p, amps_scene_mesh(S)->xyz + 3 * *node, sizeof(p));
        s = amps_scene_cut(ctx, S, *node, p, nrm, &vc);
    }
    return s;
}

/* The model every program here starts from: the mesh of spec, its base held (bu_base along the
   up axis), E = 1000, nu = 0.3, the advancing cut's path and its opposing forces set. so: the
   scene options (NULL: bu_scene_opts). 0 on success; otherwise 1 with the reason on stderr. */
typedef struct bu_model {
    amps_mesh *m;
    amps_scene *S;
    unsigned char *fixed;
    double *force, lo[3], hi[3];
    int up, nn;
    bu_cut cp;
} bu_model;
static inline int bu_model_init(amps_ctx *ctx, const char *spec, const amps_scene_opts *so, bu_model *b) {
    amps_scene_opts o;
    memset(b, 0, sizeof(*b));
    if (!(b->m = bu_load_mesh(ctx, spec))) { fprintf(stderr, "%s: %s\n", spec, ctx->msg); return 1; }
    b->nn = (int)b->m->nnode;
    bu_bbox(b->m, b->lo, b->hi);
    b->up = bu_up_axis(spec);
    b->fixed = bu_base(b->m, b->up, b->lo, b->hi);
    if (so) o = *so; else bu_scene_opts(&o);
    b->S = amps_scene_create(ctx, b->m, &o);
    b->force = (double *)calloc(3 * (size_t)b->nn, sizeof(double));
    if (!b->S || !b->fixed || !b->force) { fprintf(stderr, "%s: %s\n", spec, ctx->msg); return 1; }
    amps_scene_set_material(ctx, b->S, 1000.0, 0.3);
    bu_fix(ctx, b->S, b->nn, b->fixed);
    if (bu_cut_init(&b->cp, b->m, b->fixed, b->up, b->lo, b->hi)) { fprintf(stderr, "%s: out of memory\n", spec); return 1; }
    bu_cut_forces(ctx, b->S, b->m, b->fixed, &b->cp, b->force);
    return 0;
}
/* ncuts steps of the advancing cut (a failed cut is reported and skipped); returns the cuts done. */
static inline int bu_cuts(amps_ctx *ctx, bu_model *b, int ncuts) {
    int k, done = 0;
    for (k = 0; k < ncuts; k++) {
        int node;
        amps_status s = bu_cut_next(ctx, b->S, &b->cp, &node);
        if (s == AMPS_WARN_NOOP) break;
        if (s != AMPS_OK) fprintf(stderr, "cut at %d: %s\n", node, ctx->msg);
        else done++;
    }
    return done;
}

/* Surface nodes: the nodes of the boundary faces (faces of exactly one tet). Writes them to out
   (room for nnode), ascending; returns their number (-1 out of memory). */
static inline int bu_cmp_face(const void *a, const void *b) {
    const amps_int *x = (const amps_int *)a, *y = (const amps_int *)b;
    int k;
    for (k = 0; k < 3; k++) if (x[k] != y[k]) return x[k] < y[k] ? -1 : 1;
    return 0;
}
static inline int bu_surface_nodes(const amps_mesh *m, amps_int *out) {
    size_t nf = 4 * (size_t)m->ntet, f, g;
    amps_int *fc = (amps_int *)malloc(sizeof(amps_int) * 3 * (nf + 1)), t, v;
    unsigned char *on = (unsigned char *)calloc((size_t)m->nnode + 1, 1);
    int k, cnt = 0;
    if (!fc || !on) { free(fc); free(on); return -1; }
    for (t = 0; t < m->ntet; t++)
        for (k = 0; k < 4; k++) {
            amps_int *q = fc + 3 * (4 * (size_t)t + (size_t)k), a, b, c, w;
            a = m->tet[4 * t + (k + 1) % 4]; b = m->tet[4 * t + (k + 2) % 4]; c = m->tet[4 * t + (k + 3) % 4];
            if (a > b) { w = a; a = b; b = w; }
            if (b > c) { w = b; b = c; c = w; }
            if (a > b) { w = a; a = b; b = w; }
            q[0] = a; q[1] = b; q[2] = c;
        }
    qsort(fc, nf, 3 * sizeof(amps_int), bu_cmp_face);
    for (f = 0; f < nf; f = g) {
        for (g = f + 1; g < nf && !bu_cmp_face(fc + 3 * f, fc + 3 * g); g++) {}
        if (g - f == 1) for (k = 0; k < 3; k++) on[fc[3 * f + (size_t)k]] = 1;
    }
    for (v = 0; v < m->nnode; v++) if (on[v]) out[cnt++] = v;
    free(fc); free(on);
    return cnt;
}

/* Opens path for appending; writes header first if the file is new or empty. */
static inline FILE *bu_csv(const char *path, const char *header) {
    FILE *f = fopen(path, "a");
    if (!f) return NULL;
    fseek(f, 0, SEEK_END);
    if (ftell(f) == 0) fprintf(f, "%s\n", header);
    return f;
}
#endif
