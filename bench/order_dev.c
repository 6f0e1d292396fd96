/* Development numbers for amps.h's orderings: n, nnz(L) and ordering time of our AMD, our ND
   (with / without coordinates), AUTO, CHOLMOD's AMD and CHOLMOD's METIS, on the finite element
   matrices of tests/fe_util.h and on TetGen meshes of the Stanford bunny.
   Build:  gcc -std=c99 -O2 -I. -I/usr/include/suitesparse bench/order_dev.c -o build/order_dev -lcholmod -lm
   Bunny meshes (optional, looked up in bench/data/):
           tetgen -pq1.4a0.02 bunny.ply   -> bunny20k.node/.ele  (20,418 nodes)
           tetgen -pq1.4a0.003 bunny.ply  -> bunny50k.node/.ele  (51,129 nodes)
   Run:    build/order_dev [name-substring ...]   (nnz(L) of every ordering is counted by CHOLMOD) */
#define _POSIX_C_SOURCE 199309L
#define AMPS_IMPLEMENTATION
#include "amps.h"
#include <time.h>
#include "tests/fe_util.h"
#include "tests/cholmod_ref.h"

static double now(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec + 1e-9 * t.tv_nsec;
}

/* Upper CSC (sorted, duplicates summed) from upper triplets. */
static void csc_upper(int n, int nz, const int *ti, const int *tj, const double *tx, int **Ap, int **Ai, double **Ax) {
    int *cnt = (int *)calloc((size_t)n + 1, sizeof(int)), *p = (int *)malloc(sizeof(int) * (n + 1)), k, j, q;
    int *ri = (int *)malloc(sizeof(int) * (nz ? nz : 1)), *mark = (int *)malloc(sizeof(int) * (n ? n : 1));
    double *rx = (double *)malloc(sizeof(double) * (nz ? nz : 1));
    int *ci = (int *)malloc(sizeof(int) * (nz ? nz : 1)); double *cx = (double *)malloc(sizeof(double) * (nz ? nz : 1));
    int *cp = (int *)calloc((size_t)n + 1, sizeof(int));
    /* bucket by row, then by column: columns come out with ascending rows */
    for (k = 0; k < nz; k++) cnt[ti[k] + 1]++;
    for (j = 0; j < n; j++) cnt[j + 1] += cnt[j];
    memcpy(p, cnt, sizeof(int) * (n + 1));
    { int *ord = (int *)malloc(sizeof(int) * (nz ? nz : 1));
      for (k = 0; k < nz; k++) ord[p[ti[k]]++] = k;
      for (k = 0; k < nz; k++) cp[tj[k] + 1]++;
      for (j = 0; j < n; j++) cp[j + 1] += cp[j];
      memcpy(p, cp, sizeof(int) * (n + 1));
      for (q = 0; q < nz; q++) { k = ord[q]; ri[p[tj[k]]] = ti[k]; rx[p[tj[k]]++] = tx[k]; }
      free(ord); }
    /* merge duplicates */
    for (j = 0; j < n; j++) mark[j] = -1;
    q = 0;
    for (j = 0; j < n; j++) {
        int start = q;
        for (k = cp[j]; k < cp[j + 1]; k++) {
            if (mark[ri[k]] >= start) cx[mark[ri[k]]] += rx[k];
            else { mark[ri[k]] = q; ci[q] = ri[k]; cx[q++] = rx[k]; }
        }
        cnt[j] = start;
    }
    cnt[n] = q;
    *Ap = cnt; *Ai = ci; *Ax = cx;
    free(p); free(ri); free(rx); free(mark); free(cp);
}

static int load_tetgen(const char *base, fe_mesh *m) {
    char fn[512]; FILE *f; int k, a, b, c, d, idx, base0 = -1; double x, y, z;
    snprintf(fn, sizeof fn, "%s.node", base);
    if (!(f = fopen(fn, "r"))) return 0;
    if (fscanf(f, "%d %d %d %d", &m->nn, &a, &b, &c) != 4) { fclose(f); return 0; }
    m->xyz = (double *)malloc(sizeof(double) * 3 * m->nn);
    for (k = 0; k < m->nn; k++) {
        if (fscanf(f, "%d %lf %lf %lf", &idx, &x, &y, &z) != 4) { fclose(f); return 0; }
        if (base0 < 0) base0 = idx;
        m->xyz[3 * k] = x; m->xyz[3 * k + 1] = y; m->xyz[3 * k + 2] = z;
        for (a = 0; a < b + c; a++) if (fscanf(f, "%lf", &x) != 1) { fclose(f); return 0; }
    }
    fclose(f);
    snprintf(fn, sizeof fn, "%s.ele", base);
    if (!(f = fopen(fn, "r"))) return 0;
    if (fscanf(f, "%d %d %d", &m->nt, &a, &b) != 3 || a != 4) { fclose(f); return 0; }
    m->tet = (int *)malloc(sizeof(int) * 4 * m->nt);
    for (k = 0; k < m->nt; k++) {
        if (fscanf(f, "%d %d %d %d %d", &idx, &a, &b, &c, &d) != 5) { fclose(f); return 0; }
        m->tet[4 * k] = a - base0; m->tet[4 * k + 1] = b - base0; m->tet[4 * k + 2] = c - base0; m->tet[4 * k + 3] = d - base0;
    }
    fclose(f);
    return 1;
}

static double time_cholmod(int n, int *Ap, int *Ai, double *Ax, int method) {
    cholmod_common c; cholmod_sparse *A; int *P = (int *)malloc(sizeof(int) * n); double t;
    cholmod_start(&c);
    A = ref_sparse(n, Ap, Ai, Ax, &c);
    t = now();
    if (method == CHOLMOD_AMD) cholmod_amd(A, NULL, 0, P, &c);
    else cholmod_metis(A, NULL, 0, 1, P, &c);
    t = now() - t;
    cholmod_free_sparse(&A, &c); cholmod_finish(&c); free(P);
    return t;
}

static void run(const char *name, fe_mesh *m) {
    int n, nz, *ti, *tj, *Ap, *Ai, *dof = (int *)malloc(sizeof(int) * 3 * m->nn), *perm;
    double *tx, *Ax, t, ref_amd, ref_metis, f, t_amd, t_metis;
    amps_ctx ctx; amps_csc A; amps_order_opts o;
    int variant;
    const char *vname[] = {"AMD blk3", "AMD dof", "ND xyz", "ND graph", "AUTO xyz", "AUTO"};
    amps_ctx_init(&ctx);
    n = fe_number(m, NULL, dof);
    nz = fe_assemble(m, dof, 1.0, 0.3, &ti, &tj, &tx);
    csc_upper(n, nz, ti, tj, tx, &Ap, &Ai, &Ax);
    perm = (int *)malloc(sizeof(int) * n);
    A.nrow = A.ncol = n; A.p = Ap; A.i = Ai; A.x = Ax;
    ref_amd = ref_nnzL(n, Ap, Ai, Ax, NULL, CHOLMOD_AMD, NULL);
    ref_metis = ref_nnzL(n, Ap, Ai, Ax, NULL, CHOLMOD_METIS, NULL);
    t_amd = time_cholmod(n, Ap, Ai, Ax, CHOLMOD_AMD);
    t_metis = time_cholmod(n, Ap, Ai, Ax, CHOLMOD_METIS);
    printf("%-14s n=%7d nnz(A)=%9d | CHOLMOD AMD %11.0f %7.3fs | CHOLMOD METIS %11.0f %7.3fs\n", name, n, Ap[n], ref_amd,
           t_amd, ref_metis, t_metis);
    for (variant = 0; variant < 6; variant++) {
        amps_status s;
        memset(&o, 0, sizeof o);
        o.block = 3;
        o.method = variant < 2 ? AMPS_ORDER_AMD : variant < 4 ? AMPS_ORDER_ND : AMPS_ORDER_AUTO;
        o.coords = (variant == 2 || variant == 4) ? m->xyz : NULL;
        t = now();
        if (variant == 1) s = amps_amd(&ctx, n, Ap, Ai, perm); /* upper only: amps_amd symmetrizes */
        else s = amps_order(&ctx, &A, AMPS_UPPER, &o, perm);
        t = now() - t;
        if (s) { printf("  %-9s error %s\n", vname[variant], ctx.msg); continue; }
        f = ref_nnzL(n, Ap, Ai, Ax, perm, 0, NULL);
        printf("  %-9s nnz(L) %11.0f %7.3fs   /AMD %.3f  /METIS %.3f\n", vname[variant], f, t, f / ref_amd, f / ref_metis);
    }
    fflush(stdout);
    free(ti); free(tj); free(tx); free(Ap); free(Ai); free(Ax); free(perm); free(dof);
}

static int want(int argc, char **argv, const char *name) {
    int k;
    if (argc < 2) return 1;
    for (k = 1; k < argc; k++) if (strstr(name, argv[k])) return 1;
    return 0;
}

int main(int argc, char **argv) {
    (void)ref_solve; /* shared header helper not needed here */
    int hs[] = {16, 64, 256, 1024}, Rs[] = {4, 8, 12, 16, 20}, k;
    char name[64];
    fe_mesh m;
    for (k = 0; k < 4; k++) {
        snprintf(name, sizeof name, "beam h=%d", hs[k]);
        if (!want(argc, argv, name)) continue;
        m = fe_beam(hs[k]); run(name, &m); fe_free(&m);
    }
    for (k = 0; k < 5; k++) {
        snprintf(name, sizeof name, "brick R=%d", Rs[k]);
        if (!want(argc, argv, name)) continue;
        m = fe_brick(Rs[k]); run(name, &m); fe_free(&m);
    }
    if (want(argc, argv, "bunny20k") && load_tetgen("bench/data/bunny20k", &m)) { run("bunny20k", &m); fe_free(&m); }
    if (want(argc, argv, "bunny50k") && load_tetgen("bench/data/bunny50k", &m)) { run("bunny50k", &m); fe_free(&m); }
    return 0;
}
