/* bench/load: amps.h step times on a shared machine (bench/load.sh runs the configurations
   under each load and reports the ratios).

   usage: load run <mesh> <cut|deform> <steps> <conf> <load> <out.csv>
            the cut or deformation sequence of bench/harness (bench.h) on amps.h alone, primal
            form, background re-factorization off; conf: 1 (ctx.nthreads = 1), thr2 (2
            participants on amps' own workers, the default back end), omp2 (2 OpenMP threads,
            AMPS_BACKEND_OPENMP), jobs2 (2 workers of the example job system, examples/jobs.h,
            through ctx->enqueue_task / finish_task; the caller helps). Appends one row per step:
            case,load,conf,step,time (seconds: the change plus the solve) and prints the median.
          load tick [seconds]
            the haptic-loop load: a 1 kHz loop (absolute deadlines) that works 0.3 ms (spins on
            the clock) and sleeps until the next period; runs until killed or seconds passed.
          load scn <mesh.node> <ncuts>
            prints a bunny incision scenario for tools/amps_replay: ncuts cuts along x through
            the plane z = 0 in the upper body (y up), one solve after each, two pins pulling the
            sides apart, the base (lowest 3% in y) fixed.
   Build: see bench/run.sh (-fopenmp, -lpthread). */
#ifndef _POSIX_C_SOURCE
#define _POSIX_C_SOURCE 200809L /* clock_nanosleep */
#endif
#define AMPS_IMPLEMENTATION
#include "../amps.h"
#include "bench.h"
#define JOBS_IMPLEMENTATION
#include "../examples/jobs.h"
#include <time.h>

static int run(int argc, char **argv) {
    const char *spec = argv[2], *conf = argv[5], *load = argv[6];
    int cut = !strcmp(argv[3], "cut"), steps = atoi(argv[4]), st, n = 0, v, maxdeg = 0;
    amps_ctx ctx;
    amps_scene_opts so;
    amps_scene *S;
    amps_mesh *M;
    bench_scen sc;
    bench_step s;
    jobs_pool *P = NULL;
    double *t;
    char name[256];
    FILE *csv;
    if (argc < 8) return 2;
    amps_ctx_init(&ctx);
    if (!strcmp(conf, "1")) ctx.nthreads = 1;
    else if (!strcmp(conf, "thr2")) ctx.nthreads = 2;
    else if (!strcmp(conf, "omp2")) {
        ctx.nthreads = 2;
        ctx.backend = AMPS_BACKEND_OPENMP;
    } else if (!strcmp(conf, "jobs2")) {
        if (!(P = jobs_create(2))) bench_die("jobs_create", "cannot start the workers");
        jobs_attach(P, &ctx);
        ctx.nthreads = 2;
    } else bench_die("conf", "not 1, thr2, omp2 or jobs2");
    bench_mesh_name(spec, name, sizeof(name));
    M = bench_mesh(&ctx, spec);
    bench_scen_init(&sc, M, spec, cut, steps);
    if (amps_mesh_reserve(&ctx, M, sc.cap) != AMPS_OK) bench_die("amps_mesh_reserve", ctx.msg);
    for (v = 0; v < sc.nn0; v++)
        if (amps_mesh_degree(M, v) > maxdeg) maxdeg = (int)amps_mesh_degree(M, v);
    s.moved = (amps_int *)bench_alloc(sizeof(amps_int) * (size_t)(maxdeg + 1));
    amps_scene_opts_default(&so);
    so.update.refactor = AMPS_REFACTOR_OFF;
    S = bench_scen_scene(&ctx, &sc, spec, &so);
    if (amps_scene_solve(&ctx, S) != AMPS_OK) bench_die("first solve", ctx.msg);
    t = (double *)bench_alloc(sizeof(double) * (size_t)(steps + 1));
    if (!(csv = fopen(argv[7], "a"))) bench_die(argv[7], "cannot append");
    for (st = 1; st <= steps && bench_scen_next(&ctx, &sc, M, &s); st++) {
        double t0 = amps_now();
        amps_status rc = bench_scen_apply(&ctx, S, &sc, &s);
        if (rc == AMPS_OK || rc == AMPS_WARN_NOOP) rc = amps_scene_solve(&ctx, S);
        t[n] = amps_now() - t0;
        if (rc < 0) bench_die("step", ctx.msg);
        fprintf(csv, "%s_%s,%s,%s,%d,%.6e\n", argv[3], name, load, conf, st, t[n]);
        n++;
    }
    fclose(csv);
    printf("%s %s %s %s: %d steps, median %.3f ms\n", name, argv[3], load, conf, n, n ? 1e3 * bench_median(t, n) : 0.0);
    amps_scene_free(&ctx, S);
    amps_mesh_free(&ctx, M);
    bench_scen_free(&sc);
    jobs_destroy(P);
    free(t);
    free(s.moved);
    return 0;
}

static double now_s(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static int tick(double seconds) {
    struct timespec next;
    double t0 = now_s();
    volatile double sink = 0;
    clock_gettime(CLOCK_MONOTONIC, &next);
    while (seconds <= 0 || now_s() - t0 < seconds) {
        double w = now_s();
        while (now_s() - w < 3e-4) sink += 1;
        next.tv_nsec += 1000000L;
        if (next.tv_nsec >= 1000000000L) {
            next.tv_nsec -= 1000000000L;
            next.tv_sec++;
        }
        clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &next, NULL);
    }
    return sink < 0; /* 0; reads sink */
}

/* The incision: among the nodes within 0.035 of the height of z = 0 and in the upper 45% in y,
   the one nearest the plane in each of ncuts bins along x. */
static int scn(const char *path, int ncuts) {
    amps_ctx ctx;
    amps_mesh *m;
    double lo[3], hi[3], best[2] = {1e300, 1e300};
    int *pick, k, pin[2] = {-1, -1};
    amps_int v;
    amps_ctx_init(&ctx);
    if (!(m = amps_mesh_read(&ctx, path))) bench_die(path, ctx.msg);
    bench_bbox(m, lo, hi);
    pick = (int *)bench_alloc(sizeof(int) * (size_t)ncuts);
    for (k = 0; k < ncuts; k++) pick[k] = -1;
    for (v = 0; v < m->nnode; v++) {
        const double *x = m->xyz + 3 * v;
        double dz = fabs(x[2]);
        if (x[1] < lo[1] + 0.55 * (hi[1] - lo[1])) continue;
        if (dz < 0.035 * (hi[2] - lo[2])) {
            int b = (int)((x[0] - lo[0]) / (hi[0] - lo[0]) * ncuts);
            if (b >= ncuts) b = ncuts - 1;
            if (pick[b] < 0 || dz < fabs(m->xyz[3 * pick[b] + 2])) pick[b] = (int)v;
        }
        if (x[1] > lo[1] + 0.6 * (hi[1] - lo[1]))
            for (k = 0; k < 2; k++) { /* pins near (centre x, z = -+0.13 of the depth) */
                double ex = x[0] - 0.5 * (lo[0] + hi[0]), ez = x[2] - (k ? 0.13 : -0.13) * (hi[2] - lo[2]);
                if (ex * ex + ez * ez < best[k]) best[k] = ex * ex + ez * ez, pin[k] = (int)v;
            }
    }
    printf("# bunny incision (bench/load scn <mesh> %d): cuts along x through z = 0, a solve after each\n", ncuts);
    printf("mesh %s\nmaterial 3000 0.45\nfix y lt %g\n", strrchr(path, '/') ? strrchr(path, '/') + 1 : path,
           lo[1] + 0.03 * (hi[1] - lo[1])); /* the scenario sits beside its mesh */
    printf("pin %d 0 0 %g\npin %d 0 0 %g\nsolve\n", pin[0], -0.005 * (hi[2] - lo[2]), pin[1], 0.005 * (hi[2] - lo[2]));
    for (k = 0; k < ncuts; k++)
        if (pick[k] >= 0) {
            const double *x = m->xyz + 3 * pick[k];
            printf("cut %d %.9g %.9g %.9g 0 0 1\nsolve\n", pick[k], x[0], x[1], x[2]);
        }
    free(pick);
    amps_mesh_free(&ctx, m);
    return 0;
}

int main(int argc, char **argv) {
    int r = 2;
    if (argc >= 8 && !strcmp(argv[1], "run")) r = run(argc, argv);
    else if (argc >= 2 && !strcmp(argv[1], "tick")) r = tick(argc > 2 ? atof(argv[2]) : 0);
    else if (argc >= 4 && !strcmp(argv[1], "scn")) r = scn(argv[2], atoi(argv[3]));
    if (r == 2)
        fprintf(stderr, "usage: load run <mesh> <cut|deform> <steps> <1|thr2|omp2|jobs2> <load> <out.csv>\n"
                        "       load tick [seconds]\n       load scn <mesh.node> <ncuts>\n");
    return r;
}
