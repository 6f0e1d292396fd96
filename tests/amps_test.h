/* Tiny assertion harness shared by the tests: CHECK counts, END prints "name: N passed, N failed". */
#ifndef AMPS_TEST_H
#define AMPS_TEST_H
#include <stdio.h>
#include <stdlib.h>
#include <math.h>

static int amps_t_pass = 0, amps_t_fail = 0;

#define CHECK(cond, ...)                                         \
    do {                                                         \
        if (cond) {                                              \
            amps_t_pass++;                                       \
        } else {                                                 \
            amps_t_fail++;                                       \
            fprintf(stderr, "FAIL %s:%d: ", __FILE__, __LINE__); \
            fprintf(stderr, __VA_ARGS__);                        \
            fprintf(stderr, "\n");                               \
        }                                                        \
    } while (0)

/* Prints the per-program summary line and returns the exit code. */
static int amps_t_end(const char *name) {
    printf("%s: %d passed, %d failed\n", name, amps_t_pass, amps_t_fail);
    return amps_t_fail ? 1 : 0;
}

/* Deterministic RNG (xorshift64*), so failures reproduce. */
static unsigned long long amps_t_rng = 88172645463325252ULL;
static inline void t_seed(unsigned long long s) { amps_t_rng = s * 2654435761ULL + 1; }
static inline unsigned long long t_rand(void) {
    amps_t_rng ^= amps_t_rng >> 12;
    amps_t_rng ^= amps_t_rng << 25;
    amps_t_rng ^= amps_t_rng >> 27;
    return amps_t_rng * 2685821657736338717ULL;
}
static inline double t_unif(void) { return (double)(t_rand() >> 11) * (1.0 / 9007199254740992.0); }
static inline int t_int(int n) { return (int)(t_rand() % (unsigned long long)n); }

static inline double t_norm(int n, const double *x) {
    double s = 0;
    int i;
    for (i = 0; i < n; i++) s += x[i] * x[i];
    return sqrt(s);
}
static inline double t_reldiff(int n, const double *x, const double *y) {
    double s = 0, t = 0;
    int i;
    for (i = 0; i < n; i++) {
        s += (x[i] - y[i]) * (x[i] - y[i]);
        t += y[i] * y[i];
    }
    return t > 0 ? sqrt(s / t) : sqrt(s);
}
/* ||x - y|| / max(||y||, floor) over n entries. */
static inline double t_relerr_floor(int n, const double *x, const double *y, double floor) {
    double s = 0, t = 0;
    int i;
    for (i = 0; i < n; i++) {
        s += (x[i] - y[i]) * (x[i] - y[i]);
        t += y[i] * y[i];
    }
    t = sqrt(t);
    return sqrt(s) / (t > floor ? t : floor);
}
#ifndef AMPS_NO_FEM
/* K (upper triangle) of mesh m with the nodes below z = 0.5 fixed; *fixed (1 per node), *dof
   (3 per node, -1 for fixed) and *n (equations) receive the numbering. */
static inline amps_csc *t_fixed_stiffness(amps_ctx *ctx, const amps_mesh *m, unsigned char **fixed, amps_int **dof,
                                          amps_int *n) {
    amps_int v;
    *fixed = (unsigned char *)calloc((size_t)m->nnode, 1);
    *dof = (amps_int *)malloc(sizeof(amps_int) * 3 * (size_t)m->nnode);
    for (v = 0; v < m->nnode; v++) (*fixed)[v] = m->xyz[3 * v + 2] < 0.5;
    *n = amps_mesh_number_dofs(m, *fixed, *dof);
    return amps_mesh_assemble(ctx, m, *dof, *n);
}
#endif
#ifdef AMPS_TEST_HOST_TASKS
/* The whole suite on the host-callback back end: every context the tests initialize runs its
   kernels on the test job system (tests/jobs_test.h), mode AMPS_TEST_TASK_MODE (1..4, default 2:
   4 pthread workers). amps.h's own calls are compiled before this macro and keep the real one. */
#include "jobs_test.h"
static void t_ctx_init_tasks(amps_ctx *c) {
    const char *m = getenv("AMPS_TEST_TASK_MODE");
    int mode = m && m[0] >= '1' && m[0] <= '4' ? m[0] - '0' : T_JOBS_POOL;
    (amps_ctx_init)(c);
    if (c) t_jobs_ctx(c, mode);
}
#define amps_ctx_init(c) t_ctx_init_tasks(c)
#endif
#endif
