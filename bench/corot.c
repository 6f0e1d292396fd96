/* Corotational dynamics (paper "GPU-accelerated surgery simulation for opening a brain fissure",
   Corotational FEM, Appendix A-B) per step, side by side on one scenario:
     amps     amps.h's corotational step (PCG on the assembled A_R preconditioned by the engine's
              exact solve with the current linear A in the frame of the node rotations, or by
              symmetric Gauss-Seidel where the cost model finds it cheaper; never re-factors), and between
              steps BENCH_HAPTIC (default 20) haptic calls (amps_scene_solve_reactions) with the
              pins moved by that fraction of a step's travel each
     cholmod  CHOLMOD re-factorization of the step's A_R (cholmod_analyze once per pattern,
              cholmod_factorize and one solve each sampled step), assembly of A_R timed apart
     jacobi   Jacobi-PCG on the assembled A_R at 1e-6, 1e-8, 1e-10 (paper 003's solver)
     linear   one linear dynamics step of the same scenario (amps_scene_step, the factor-once path)
   The reference is CHOLMOD's solve of the same A_R and b with two refinement steps; errors are
   ||w+ - w_ref|| / ||w_ref|| on the free equations.
   Cases: beam (5 x 5 x 60 cantilever sagging under gravity: the volume ratio of both models),
   bunny (bench/data/bunny20k: a grasper at the top turned through 90 degrees), brain
   (bench/data/brain: two spatulas on the fissure walls pushed apart, fracture in the fissure
   region 2, the spatula reactions every step).
   usage: corot <beam|bunny|brain> <steps> <every> <out.csv> [<data dir>]
   BENCH_CPU=1 times with the calling thread's CPU time (robust to a loaded machine; run with
   OMP_NUM_THREADS=1 then), BENCH_FRACTURE=0 turns the brain's fracture off, BENCH_TRACE=1 prints
   each step's times (whole step, rotations and assembly, PCG), iterations and products. */
#define _POSIX_C_SOURCE 200809L
#define AMPS_IMPLEMENTATION
#include "amps.h"
#include <cholmod.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <math.h>
#include <time.h>

/* Seconds: wall clock, or the thread's CPU time with BENCH_CPU=1. */
static double now(void) {
#ifdef CLOCK_THREAD_CPUTIME_ID
    static int cpu = -1;
    if (cpu < 0) cpu = getenv("BENCH_CPU") && atoi(getenv("BENCH_CPU"));
    if (cpu) {
        struct timespec ts;
        clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
        return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
    }
#endif
    return amps_now();
}

static void die(const char *what, const char *msg) {
    fprintf(stderr, "corot: %s: %s\n", what, msg);
    exit(1);
}
static void *xalloc(size_t n) {
    void *p = calloc(n ? n : 1, 1);
    if (!p) die("calloc", "out of memory");
    return p;
}
static int cmpd(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}
static double quant(const double *v, int n, double q) {
    double *c;
    double r;
    if (n <= 0) return 0;
    c = (double *)xalloc(sizeof(double) * (size_t)n);
    memcpy(c, v, sizeof(double) * (size_t)n);
    qsort(c, (size_t)n, sizeof(double), cmpd);
    r = c[(int)(q * (n - 1) + 0.5)];
    free(c);
    return r;
}

/* ---- the scenarios ---- */

typedef struct scen {
    int kind; /* 0 beam, 1 bunny, 2 brain */
    double dt, alpha, beta, lo[3], hi[3], c[3];
    amps_int npin, *pin; /* pinned nodes (grasper, spatulas) */
    int *side;           /* brain: -1 / +1 wall of each pinned node */
    int steps;
} scen;

static amps_scene *make_scene(amps_ctx *ctx, scen *sc, const char *dir, int corot, int fracture) {
    char p[512];
    amps_mesh *m;
    amps_scene *S;
    amps_int v;
    int d;
    if (sc->kind == 0) m = amps_mesh_beam(ctx, 60);
    else {
        snprintf(p, sizeof(p), "%s/%s.1.node", dir, sc->kind == 1 ? "bunny20k" : "brain");
        m = amps_mesh_read(ctx, p);
    }
    if (!m) die("mesh", ctx->msg);
    for (d = 0; d < 3; d++) sc->lo[d] = 1e300, sc->hi[d] = -1e300;
    for (v = 0; v < m->nnode; v++)
        for (d = 0; d < 3; d++) {
            sc->lo[d] = fmin(sc->lo[d], m->xyz[3 * v + d]);
            sc->hi[d] = fmax(sc->hi[d], m->xyz[3 * v + d]);
        }
    for (d = 0; d < 3; d++) sc->c[d] = 0.5 * (sc->lo[d] + sc->hi[d]);
    S = amps_scene_create(ctx, m, NULL);
    if (!S) die("scene", ctx->msg);
    if (sc->kind == 0) {
        double g[3] = {-0.3, 0, 0};
        amps_scene_set_material(ctx, S, 1e4, 0.3);
        amps_scene_fix_where(ctx, S, 2, AMPS_LT, 0.5, NULL);
        amps_scene_gravity(ctx, S, g);
        sc->dt = 1.0, sc->alpha = 0.1, sc->beta = 0.01;
    } else if (sc->kind == 1) {
        double h = sc->hi[1] - sc->lo[1], ctr[3], r = 0.12 * h;
        amps_scene_set_material(ctx, S, 1e3, 0.4);
        amps_scene_set_density(ctx, S, 1.0);
        amps_scene_fix_where(ctx, S, 1, AMPS_LT, sc->lo[1] + 0.04 * h, NULL);
        ctr[0] = sc->c[0];
        ctr[1] = sc->hi[1] - 0.1 * h;
        ctr[2] = sc->c[2];
        sc->pin = (amps_int *)xalloc(sizeof(amps_int) * (size_t)m->nnode);
        sc->npin = amps_scene_nodes_near_segment(ctx, S, ctr, ctr, r, sc->pin, m->nnode);
        sc->dt = 0.01, sc->alpha = 2.0, sc->beta = 0.001;
    } else {
        amps_scene_set_region(ctx, S, 1, 1000, 0.4, 1000);
        amps_scene_set_region(ctx, S, 2, 100, 0.4, 1000);
        amps_scene_fix_where(ctx, S, 2, AMPS_LT, sc->lo[2] + 0.01 * (sc->hi[2] - sc->lo[2]), NULL);
        sc->pin = (amps_int *)xalloc(sizeof(amps_int) * (size_t)m->nnode);
        sc->side = (int *)xalloc(sizeof(int) * (size_t)m->nnode);
        for (v = 0, sc->npin = 0; v < m->nnode; v++) {
            const double *X = m->xyz + 3 * v;
            if (fabs(fabs(X[0]) - 0.02) < 1e-6 && X[2] > 0.35 && fabs(X[1]) < 0.12) {
                sc->side[sc->npin] = X[0] < 0 ? -1 : 1;
                sc->pin[sc->npin++] = v;
            }
        }
        amps_scene_fracture(ctx, S, 0);
        if (fracture && !(getenv("BENCH_FRACTURE") && !atoi(getenv("BENCH_FRACTURE"))))
            amps_scene_fracture_region(ctx, S, 2, 60.0);
        sc->dt = 0.01, sc->alpha = 1.0, sc->beta = 0.001;
    }
    if (amps_scene_dynamics(ctx, S, sc->dt, sc->alpha, sc->beta) != AMPS_OK) die("dynamics", ctx->msg);
    if (corot && amps_scene_corotational(ctx, S, 1) != AMPS_OK) die("corotational", ctx->msg);
    return S;
}

/* The pins of step k (before it): the bunny's grasper turned by 90 k / steps degrees about x
   through the mesh centre; the spatulas moved apart by 0.04 k / steps each. */
static void set_pins(amps_ctx *ctx, amps_scene *S, const scen *sc, double k) {
    const amps_mesh *m = amps_scene_mesh(S);
    double f = (k < sc->steps ? k : sc->steps) / sc->steps;
    amps_int j;
    for (j = 0; j < sc->npin; j++) {
        amps_int v = sc->pin[j];
        const double *X = m->xyz + 3 * v;
        double g[3] = {0, 0, 0};
        if (amps_mesh_degree(m, v) == 0) continue;
        if (sc->kind == 1) {
            double th = 1.5707963267948966 * f, y = X[1] - sc->c[1], z = X[2] - sc->c[2];
            g[1] = sc->c[1] + y * cos(th) - z * sin(th) - X[1];
            g[2] = sc->c[2] + y * sin(th) + z * cos(th) - X[2];
        } else g[0] = 0.04 * f * sc->side[j];
        amps_scene_pin(ctx, S, v, g);
    }
}

/* ---- the step's A_R and b assembled from scratch ---- */

typedef struct sys {
    int n;             /* free equations */
    int *map;          /* engine equation -> free index or -1 */
    cholmod_sparse *A; /* the reduced A_R (upper) */
    double *rhs, *wc;  /* b_F - A_FC w_C; w at every equation (w_C prescribed, w_F start) */
    double t_assemble;
} sys;

static void assemble(amps_ctx *ctx, amps_scene *S, const scen *sc, cholmod_common *cc, sys *y) {
    const amps_mesh *m = amps_scene_mesh(S);
    const double *u = amps_scene_displacements(S), *w = amps_scene_velocities(S);
    amps_int N = amps_scene_ndof(S), nn = m->nnode, v, t, *dof = (amps_int *)xalloc(sizeof(amps_int) * 3 * nn);
    double cM = 1 + sc->alpha * sc->dt, cK = sc->beta * sc->dt + sc->dt * sc->dt, *mass, *gel, *b, t0 = now();
    double grav[3] = {sc->kind == 0 ? -0.3 : 0, 0, 0};
    unsigned char *con = (unsigned char *)xalloc((size_t)N);
    cholmod_triplet *T;
    int d, a, c, i, k;
    mass = (double *)xalloc(sizeof(double) * nn);
    gel = (double *)xalloc(sizeof(double) * 3 * nn);
    b = (double *)xalloc(sizeof(double) * N);
    y->map = (int *)xalloc(sizeof(int) * N);
    y->wc = (double *)xalloc(sizeof(double) * N);
    amps_mesh_lumped_mass(m, mass);
    for (v = 0; v < nn; v++) {
        if (amps_scene_node_dofs(ctx, S, v, dof + 3 * v) != AMPS_OK) dof[3 * v] = dof[3 * v + 1] = dof[3 * v + 2] = -1;
        for (d = 0; d < 3; d++) {
            amps_int e = dof[3 * v + d];
            if (e < 0) continue;
            if (amps_scene_is_pinned(S, v) || amps_mesh_degree(m, v) == 0) con[e] = 1;
            y->wc[e] = amps_mesh_degree(m, v) == 0 ? 0.0 : w[3 * v + d];
        }
    }
    for (v = 0; v < nn; v++) /* the pins' w = (g - u) / dt: from the scene's pin targets */
        if (amps_scene_is_pinned(S, v) && amps_mesh_degree(m, v) > 0)
            for (d = 0; d < 3; d++) y->wc[dof[3 * v + d]] = (S->node.pin_value[3 * v + d] - u[3 * v + d]) / sc->dt;
    for (i = 0, y->n = 0; i < N; i++) y->map[i] = con[i] ? -1 : y->n++;
    y->rhs = (double *)xalloc(sizeof(double) * (y->n + 1));
    T = cholmod_allocate_triplet(y->n, y->n, 78 * (size_t)m->ntet + y->n, 1, CHOLMOD_REAL, cc);
    for (t = 0; t < m->ntet; t++) {
        double X[12], x[12], R[9], Ke[144], KR[144], dl[12], kd[12];
        amps_int e[12];
        if (m->removed && m->removed[t]) continue;
        amps_mesh_tet_coords(m, t, X);
        for (a = 0; a < 12; a++) x[a] = X[a] + u[3 * m->tet[4 * t + a / 3] + a % 3];
        amps_tet_rotation(X, x, R);
        amps_mesh_tet_stiffness(m, t, Ke);
        for (a = 0; a < 4; a++) /* KR_ab = R K_ab R^T; dl = R^T x - X */
            for (c = 0; c < 4; c++) {
                double B[9];
                int p, q, r;
                for (p = 0; p < 3; p++)
                    for (q = 0; q < 3; q++) {
                        B[3 * p + q] = 0;
                        for (r = 0; r < 3; r++) B[3 * p + q] += Ke[12 * (3 * a + p) + 3 * c + r] * R[3 * q + r];
                    }
                for (p = 0; p < 3; p++)
                    for (q = 0; q < 3; q++) {
                        double s = 0;
                        for (r = 0; r < 3; r++) s += R[3 * p + r] * B[3 * r + q];
                        KR[12 * (3 * a + p) + 3 * c + q] = s;
                    }
            }
        for (a = 0; a < 4; a++)
            for (d = 0; d < 3; d++)
                dl[3 * a + d] = R[d] * x[3 * a] + R[3 + d] * x[3 * a + 1] + R[6 + d] * x[3 * a + 2] - X[3 * a + d];
        for (a = 0; a < 12; a++) {
            kd[a] = 0;
            for (c = 0; c < 12; c++) kd[a] += Ke[12 * a + c] * dl[c];
        }
        for (a = 0; a < 4; a++)
            for (d = 0; d < 3; d++)
                gel[3 * m->tet[4 * t + a] + d] +=
                        R[3 * d] * kd[3 * a] + R[3 * d + 1] * kd[3 * a + 1] + R[3 * d + 2] * kd[3 * a + 2];
        for (a = 0; a < 12; a++) e[a] = dof[3 * m->tet[4 * t + a / 3] + a % 3];
        for (a = 0; a < 12; a++)
            for (c = 0; c < 12; c++) {
                double val = cK * KR[12 * a + c];
                if (e[a] < 0 || e[c] < 0) continue;
                if (y->map[e[a]] >= 0 && y->map[e[c]] >= 0) {
                    if (y->map[e[a]] <= y->map[e[c]]) {
                        k = (int)T->nnz++;
                        ((int *)T->i)[k] = y->map[e[a]];
                        ((int *)T->j)[k] = y->map[e[c]];
                        ((double *)T->x)[k] = val;
                    }
                } else if (y->map[e[a]] >= 0) y->rhs[y->map[e[a]]] -= val * y->wc[e[c]];
            }
    }
    for (v = 0; v < nn; v++)
        for (d = 0; d < 3; d++) {
            amps_int e = dof[3 * v + d];
            if (e < 0) continue;
            b[e] = mass[v] * w[3 * v + d] + sc->dt * (mass[v] * grav[d] - gel[3 * v + d]);
            if (y->map[e] < 0) continue;
            y->rhs[y->map[e]] += b[e];
            k = (int)T->nnz++;
            ((int *)T->i)[k] = ((int *)T->j)[k] = y->map[e];
            ((double *)T->x)[k] = cM * mass[v];
        }
    y->A = cholmod_triplet_to_sparse(T, 0, cc);
    cholmod_free_triplet(&T, cc);
    y->t_assemble = now() - t0;
    free(dof);
    free(con);
    free(mass);
    free(gel);
    free(b);
}

/* y = A x for the upper-stored symmetric A. */
static void symv(const cholmod_sparse *A, const double *x, double *y) {
    const int *p = (const int *)A->p, *ii = (const int *)A->i;
    const double *ax = (const double *)A->x;
    int n = (int)A->ncol, j, q;
    for (j = 0; j < n; j++) y[j] = 0;
    for (j = 0; j < n; j++)
        for (q = p[j]; q < p[j + 1]; q++) {
            int i = ii[q];
            y[i] += ax[q] * x[j];
            if (i != j) y[j] += ax[q] * x[i];
        }
}

/* Jacobi-PCG from x (in place) to ||b - A x|| <= tol ||b||; returns the iterations. */
static int jacobi_pcg(const cholmod_sparse *A, const double *b, double *x, double tol, int maxit) {
    int n = (int)A->ncol, i, it = 0, j, q;
    double *d = (double *)xalloc(sizeof(double) * n), *r = (double *)xalloc(sizeof(double) * n);
    double *z = (double *)xalloc(sizeof(double) * n), *p = (double *)xalloc(sizeof(double) * n);
    double *Ap = (double *)xalloc(sizeof(double) * n), bn = 0, rz = 0, rn;
    for (j = 0; j < n; j++)
        for (q = ((const int *)A->p)[j]; q < ((const int *)A->p)[j + 1]; q++)
            if (((const int *)A->i)[q] == j) d[j] = ((const double *)A->x)[q];
    symv(A, x, Ap);
    for (i = 0; i < n; i++) {
        r[i] = b[i] - Ap[i];
        bn += b[i] * b[i];
    }
    bn = sqrt(bn);
    for (rn = 0, i = 0; i < n; i++) rn += r[i] * r[i];
    while (sqrt(rn) > tol * bn && it < maxit) {
        double rz1 = 0, pap = 0, al;
        for (i = 0; i < n; i++) {
            z[i] = r[i] / d[i];
            rz1 += r[i] * z[i];
        }
        for (i = 0; i < n; i++) p[i] = z[i] + (it ? rz1 / rz : 0.0) * p[i];
        rz = rz1;
        symv(A, p, Ap);
        for (i = 0; i < n; i++) pap += p[i] * Ap[i];
        al = rz / pap;
        for (rn = 0, i = 0; i < n; i++) {
            x[i] += al * p[i];
            r[i] -= al * Ap[i];
            rn += r[i] * r[i];
        }
        it++;
    }
    free(d);
    free(r);
    free(z);
    free(p);
    free(Ap);
    return it;
}

static double relerr(int n, const double *x, const double *y) {
    double s = 0, t = 0;
    int i;
    for (i = 0; i < n; i++) {
        s += (x[i] - y[i]) * (x[i] - y[i]);
        t += y[i] * y[i];
    }
    return t > 0 ? sqrt(s / t) : sqrt(s);
}

/* Volume of the deformed mesh over that of the reference. */
static double volume_ratio(const amps_scene *S) {
    const amps_mesh *m = amps_scene_mesh(S);
    const double *u = amps_scene_displacements(S);
    double v0 = 0, v1 = 0;
    amps_int t;
    for (t = 0; t < m->ntet; t++) {
        double X[12], x[12], G[12], R[9], V;
        int a;
        if (m->removed && m->removed[t]) continue;
        amps_mesh_tet_coords(m, t, X);
        for (a = 0; a < 12; a++) x[a] = X[a] + u[3 * m->tet[4 * t + a / 3] + a % 3];
        V = fabs(amps_tet_gradients(X, G));
        v0 += V;
        v1 += V * amps_tet_rotation(X, x, R);
    }
    return v1 / v0;
}

int main(int argc, char **argv) {
    static const char *names[3] = {"beam", "bunny", "brain"};
    static const double tols[3] = {1e-6, 1e-8, 1e-10};
    amps_ctx ctx;
    scen sc, sl;
    amps_scene *S, *L;
    cholmod_common cc;
    cholmod_factor *F = NULL;
    int kind, steps, every, k, ns = 0, nre = 0, ti, fn = -1;
    size_t fnz = 0;
    double *t_amps, *t_solve, *t_lin, *it_amps, *t_chol, *t_asm, *t_jac[3], *it_jac[3], *e_jac[3], *e_amps, rr_max = 0;
    double vol_c, vol_l, react_t = 0, react_f = 0, *t_hap;
    int nhap = getenv("BENCH_HAPTIC") ? atoi(getenv("BENCH_HAPTIC")) : 20, khap = 0;
    const char *dir = argc > 5 ? argv[5] : "bench/data";
    FILE *csv;
    if (argc < 5) die("usage", "corot <beam|bunny|brain> <steps> <every> <out.csv> [<data dir>]");
    for (kind = 0; kind < 3 && strcmp(argv[1], names[kind]); kind++) {}
    if (kind == 3) die(argv[1], "unknown case");
    steps = atoi(argv[2]);
    every = atoi(argv[3]) > 0 ? atoi(argv[3]) : 1;
    amps_ctx_init(&ctx);
    memset(&sc, 0, sizeof(sc));
    sc.kind = kind;
    sc.steps = kind == 0 ? 1 : steps;
    sl = sc;
    S = make_scene(&ctx, &sc, dir, 1, 1);
    L = make_scene(&ctx, &sl, dir, 0, 0); /* the linear step alone: no fracture removals in its time */
    t_amps = (double *)xalloc(sizeof(double) * steps);
    t_lin = (double *)xalloc(sizeof(double) * steps);
    t_hap = (double *)xalloc(sizeof(double) * ((size_t)steps * (size_t)(nhap > 0 ? nhap : 1) + 1));
    t_solve = (double *)xalloc(sizeof(double) * steps);
    it_amps = (double *)xalloc(sizeof(double) * steps);
    t_chol = (double *)xalloc(sizeof(double) * steps);
    t_asm = (double *)xalloc(sizeof(double) * steps);
    e_amps = (double *)xalloc(sizeof(double) * steps);
    for (ti = 0; ti < 3; ti++) {
        t_jac[ti] = (double *)xalloc(sizeof(double) * steps);
        it_jac[ti] = (double *)xalloc(sizeof(double) * steps);
        e_jac[ti] = (double *)xalloc(sizeof(double) * steps);
    }
    cholmod_start(&cc);
    amps_scene_prepare(&ctx, S);
    amps_scene_prepare(&ctx, L);
    for (k = 0; k < steps; k++) {
        double t0;
        amps_scene_step_stats st = {0, 0, 0, 0, 0, 0, 0, 0, 0, 0};
        sys y;
        int sample = k % every == every - 1, i;
        amps_status s;
        set_pins(&ctx, S, &sc, k + 1);
        set_pins(&ctx, L, &sl, k + 1);
        if (sample) { /* the references from the state before the step */
            cholmod_dense *B, *X, *Rr = NULL;
            double *ref, one[2] = {1, 0}, mone[2] = {-1, 0};
            int it;
            memset(&y, 0, sizeof(y));
            assemble(&ctx, S, &sc, &cc, &y);
            t_asm[ns] = y.t_assemble;
            if (!F || y.n != fn || y.A->nzmax > fnz) {
                if (F) cholmod_free_factor(&F, &cc);
                F = cholmod_analyze(y.A, &cc);
                fn = y.n;
                fnz = y.A->nzmax;
                nre++;
            }
            B = cholmod_zeros(y.n, 1, CHOLMOD_REAL, &cc);
            memcpy(B->x, y.rhs, sizeof(double) * y.n);
            t0 = now();
            if (!cholmod_factorize(y.A, F, &cc)) die("cholmod_factorize", "failed");
            X = cholmod_solve(CHOLMOD_A, F, B, &cc);
            t_chol[ns] = now() - t0;
            for (it = 0; it < 2; it++) { /* refinement: the reference */
                cholmod_dense *D;
                Rr = cholmod_copy_dense(B, &cc);
                cholmod_sdmult(y.A, 0, mone, one, X, Rr, &cc);
                D = cholmod_solve(CHOLMOD_A, F, Rr, &cc);
                for (i = 0; i < y.n; i++) ((double *)X->x)[i] += ((double *)D->x)[i];
                cholmod_free_dense(&D, &cc);
                cholmod_free_dense(&Rr, &cc);
            }
            ref = (double *)X->x;
            for (ti = 0; ti < 3; ti++) {
                double *x = (double *)xalloc(sizeof(double) * (y.n + 1));
                amps_int e, N = amps_scene_ndof(S);
                for (e = 0; e < N; e++)
                    if (y.map[e] >= 0) x[y.map[e]] = y.wc[e];
                t0 = now();
                it_jac[ti][ns] = jacobi_pcg(y.A, y.rhs, x, tols[ti], 100000);
                t_jac[ti][ns] = now() - t0;
                e_jac[ti][ns] = relerr(y.n, x, ref);
                free(x);
            }
            t0 = now();
            s = amps_scene_step(&ctx, S, 1);
            t_amps[k] = now() - t0;
            {
                const double *w = amps_scene_velocities(S);
                const amps_mesh *m = amps_scene_mesh(S);
                double *x = (double *)xalloc(sizeof(double) * (y.n + 1));
                amps_int v, dd[3];
                for (v = 0; v < m->nnode; v++)
                    if (amps_scene_node_dofs(&ctx, S, v, dd) == AMPS_OK)
                        for (i = 0; i < 3; i++)
                            if (dd[i] >= 0 && dd[i] < amps_scene_ndof(S) && y.map[dd[i]] >= 0)
                                x[y.map[dd[i]]] = w[3 * v + i];
                e_amps[ns] = relerr(y.n, x, ref);
                free(x);
            }
            cholmod_free_dense(&B, &cc);
            cholmod_free_dense(&X, &cc);
            cholmod_free_sparse(&y.A, &cc);
            free(y.map);
            free(y.rhs);
            free(y.wc);
            ns++;
        } else {
            t0 = now();
            s = amps_scene_step(&ctx, S, 1);
            t_amps[k] = now() - t0;
        }
        if (s < 0) die("amps_scene_step", ctx.msg);
        amps_scene_step_info(S, &st);
        it_amps[k] = (double)st.iterations;
        t_solve[k] = getenv("BENCH_CPU") ? t_amps[k] : st.t_rotation + st.t_solve;
        if (st.relres > rr_max) rr_max = st.relres;
        if (getenv("BENCH_TRACE"))
            fprintf(stderr, "trace %d: total %.2f rot %.2f solve %.2f it %d gs %d prod %d relres %.1e\n", k,
                    1e3 * t_amps[k], 1e3 * st.t_rotation, 1e3 * st.t_solve, (int)st.iterations, (int)st.iterations_gs,
                    (int)st.products, st.relres);
        if (sc.npin > 0) { /* the reactions of the pins (spatulas, grasper) */
            double r[3], sum = 0;
            amps_int j;
            t0 = now();
            for (j = 0; j < sc.npin; j++) {
                amps_scene_reaction(&ctx, S, sc.pin[j], r);
                sum += sc.kind == 2 ? sc.side[j] * r[0] : sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]);
            }
            react_t += now() - t0;
            react_f = sum;
            for (i = 1; i <= nhap && k + 1 < steps; i++) { /* the haptic loop: pins towards the next step's */
                set_pins(&ctx, S, &sc, k + 1 + (double)i / nhap);
                t0 = now();
                if (amps_scene_solve_reactions(&ctx, S) < 0) die("amps_scene_solve_reactions", ctx.msg);
                t_hap[khap++] = now() - t0;
            }
        }
        t0 = now();
        if (amps_scene_step(&ctx, L, 1) < 0) die("linear step", ctx.msg);
        t_lin[k] = now() - t0;
        if (k % 25 == 24 || k == steps - 1)
            printf("%s step %d: amps %.2f ms (%ld it, relres %.1e), linear %.2f ms, fractured %ld, reaction %.3g\n",
                   names[kind], k + 1, 1e3 * t_amps[k], (long)st.iterations, st.relres, 1e3 * t_lin[k],
                   (long)amps_scene_fractured(S, NULL), react_f);
    }
    vol_c = volume_ratio(S);
    vol_l = volume_ratio(L);
    {
        amps_int tot;
        amps_scene_fractured(S, &tot);
        printf("%s: %ld nodes, %ld tets, %ld equations; volume ratio corotational %.4f, linear %.4f; fractured %ld;"
               " reaction readout %.2f us per step\n",
               names[kind], (long)amps_scene_mesh(S)->nnode, (long)amps_scene_mesh(S)->ntet, (long)amps_scene_ndof(S),
               vol_c, vol_l, (long)tot, 1e6 * react_t / steps);
    }
    csv = fopen(argv[4], "a");
    if (!csv) die(argv[4], "cannot open");
    fseek(csv, 0, SEEK_END);
    if (ftell(csv) == 0) fprintf(csv, "case,method,median_ms,p90_ms,iter_median,iter_max,err_max,samples,extra\n");
    fprintf(csv, "%s,amps_corot_step,%.4f,%.4f,%.0f,%.0f,%.3g,%d,relres_max=%.2g vol=%.4f\n", names[kind],
            1e3 * quant(t_amps, steps, 0.5), 1e3 * quant(t_amps, steps, 0.9), quant(it_amps, steps, 0.5),
            quant(it_amps, steps, 1.0), quant(e_amps, ns, 1.0), ns, rr_max, vol_c);
    fprintf(csv, "%s,amps_corot_solve_part,%.4f,%.4f,,,,%d,rotations+assembly+PCG of the step\n", names[kind],
            1e3 * quant(t_solve, steps, 0.5), 1e3 * quant(t_solve, steps, 0.9), steps);
    fprintf(csv, "%s,linear_step,%.4f,%.4f,,,,%d,vol=%.4f\n", names[kind], 1e3 * quant(t_lin, steps, 0.5),
            1e3 * quant(t_lin, steps, 0.9), steps, vol_l);
    if (khap > 0) {
        double hm = quant(t_hap, khap, 0.5), h99 = quant(t_hap, khap, 0.99);
        fprintf(csv, "%s,amps_haptic_call,%.4f,%.4f,,,,%d,rate_hz=%.0f p99_ms=%.4f\n", names[kind], 1e3 * hm,
                1e3 * quant(t_hap, khap, 0.9), khap, hm > 0 ? 1.0 / hm : 0.0, 1e3 * h99);
        printf("%s: haptic calls between steps: %d, median %.3f ms (%.0f Hz), p99 %.3f ms\n", names[kind], khap,
               1e3 * hm, hm > 0 ? 1.0 / hm : 0.0, 1e3 * h99);
    }
    free(t_hap);
    fprintf(csv, "%s,cholmod_refactor,%.4f,%.4f,,,,%d,assembly_ms=%.3f analyses=%d\n", names[kind],
            1e3 * quant(t_chol, ns, 0.5), 1e3 * quant(t_chol, ns, 0.9), ns, 1e3 * quant(t_asm, ns, 0.5), nre);
    for (ti = 0; ti < 3; ti++)
        fprintf(csv, "%s,jacobi_pcg_%.0e,%.4f,%.4f,%.0f,%.0f,%.3g,%d,\n", names[kind], tols[ti],
                1e3 * quant(t_jac[ti], ns, 0.5), 1e3 * quant(t_jac[ti], ns, 0.9), quant(it_jac[ti], ns, 0.5),
                quant(it_jac[ti], ns, 1.0), quant(e_jac[ti], ns, 1.0), ns);
    fclose(csv);
    printf("%s: median corotational step %.2f ms (the whole amps_scene_step; of it the solve part %.2f ms: rotations, "
           "assembly, PCG), linear step %.2f ms (ratio %.1f; solve part %.1f), cholmod refactor %.2f ms (+ assembly "
           "%.2f ms; amps step %.1fx faster than both, solve part %.1fx faster than the refactor), jacobi 1e-10 %.2f "
           "ms; amps iterations median %.0f max %.0f, error max %.2g\n",
           names[kind], 1e3 * quant(t_amps, steps, 0.5), 1e3 * quant(t_solve, steps, 0.5),
           1e3 * quant(t_lin, steps, 0.5), quant(t_amps, steps, 0.5) / quant(t_lin, steps, 0.5),
           quant(t_solve, steps, 0.5) / quant(t_lin, steps, 0.5), 1e3 * quant(t_chol, ns, 0.5),
           1e3 * quant(t_asm, ns, 0.5), (quant(t_chol, ns, 0.5) + quant(t_asm, ns, 0.5)) / quant(t_amps, steps, 0.5),
           quant(t_chol, ns, 0.5) / quant(t_solve, steps, 0.5), 1e3 * quant(t_jac[2], ns, 0.5),
           quant(it_amps, steps, 0.5), quant(it_amps, steps, 1.0), quant(e_amps, ns, 1.0));
    if (F) cholmod_free_factor(&F, &cc);
    cholmod_finish(&cc);
    amps_scene_free(&ctx, S);
    amps_scene_free(&ctx, L);
    return 0;
}
