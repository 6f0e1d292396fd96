/* A haptic loop and a visual loop on one model, in two POSIX threads.

   usage: haptic_loop [-t seconds] [-o outdir] [-w workers] [mesh.node|.msh|.mesh]
   Model: a soft 1 x 1 x 2 brick (amps_mesh_brick), or the given mesh, held at its bottom face
   (z near its minimum). The "tool": the 4 nodes nearest the centre of the top face, pinned and
   moved along a smooth path (press down and slide sideways).
     haptic thread, 1 kHz: reads the device (the tool path), evaluates the latest published
       haptic model there (amps_haptic_eval: r = r0 + H (g - g0), a 12 x 12 product), sums the
       tool force and hands the position to the visual thread. It never calls the scene;
     visual thread, 60 Hz, the only thread that calls the scene: pins the tool at the latest
       device position, the displacements of the surface nodes (amps_update_solve_watched), one
       line per 15th frame (frame, max surface displacement, tool force), a VTU file every 30th
       frame if -o outdir is given (surface displacements; interior zero); then the haptic model
       of the new state (amps_scene_haptic_build) into the back buffer, published by a pointer
       swap. Its amps calls hand their parallel work to a host job system (examples/jobs.h, -w
       workers, default 2; 0: none) through ctx->enqueue_task / finish_task.
   The threads share one mutex, held for the swap and the stop flag (visual thread) or one
   evaluation and a copy of the position (haptic thread): microseconds.
   At the end: the achieved rates, the haptic period (median, 99th percentile, worst) and the
   missed haptic deadlines.
   Build: make examples (or cc -std=c99 -O2 -I. examples/haptic_loop.c -lpthread -lm). */
#ifndef _POSIX_C_SOURCE
#define _POSIX_C_SOURCE 200809L /* clock_nanosleep, clock_gettime */
#endif
#define AMPS_IMPLEMENTATION
#include "amps.h"
#define JOBS_IMPLEMENTATION
#include "jobs.h"
#include <pthread.h>
#include <time.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <math.h>

#define NTOOL 4
#define HAPTIC_NS 1000000L /* 1 ms */
#define VISUAL_NS (1000000000L / 60)

typedef struct shared {
    pthread_mutex_t lock; /* held only for the model's swap, one evaluation, a copy of 3 doubles */
    amps_scene *S;        /* called by the visual thread only (after the setup) */
    amps_int tool[NTOOL];
    double amp;           /* tool path amplitude */
    amps_haptic model[2]; /* the haptic thread reads *front, the visual thread builds the other */
    amps_haptic *front;
    double device[3]; /* latest tool position (haptic thread writes, under lock) */
    double force[3];  /* latest tool force (haptic thread writes, under lock) */
    int stop;         /* 1: both loops end (read and written under lock) */
    /* surface watch set: watched equation k is component wdim[k] of node wnode[k] */
    amps_int nw, *widx, *wnode;
    int *wdim;
    const char *outdir;
    jobs_pool *pool; /* the visual loop's workers, or NULL */
    /* results */
    long hsteps, hmissed, frames;
    double hworst, hstep_max, hstep_sum;
    double *period; /* haptic periods (s), hcap of them at most */
    long nperiod, hcap;
} shared;

static int stopped(shared *sh) {
    int s;
    pthread_mutex_lock(&sh->lock);
    s = sh->stop;
    pthread_mutex_unlock(&sh->lock);
    return s;
}
static void stop_all(shared *sh) {
    pthread_mutex_lock(&sh->lock);
    sh->stop = 1;
    pthread_mutex_unlock(&sh->lock);
}

static double now_s(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}
static void add_ns(struct timespec *t, long ns) {
    t->tv_nsec += ns;
    while (t->tv_nsec >= 1000000000L) {
        t->tv_nsec -= 1000000000L;
        t->tv_sec++;
    }
}
static double ts_s(const struct timespec *t) { return (double)t->tv_sec + 1e-9 * (double)t->tv_nsec; }

/* The tool path at time t (s): press down to amp in 1 s, slide sideways by +-amp in 2 s. */
static void tool_path(double amp, double t, double u[3]) {
    const double pi = 3.14159265358979323846;
    u[0] = amp * sin(pi * t);
    u[1] = 0.0;
    u[2] = -0.5 * amp * (1.0 - cos(2.0 * pi * t));
}

/* 1 kHz: each period (absolute deadlines, so the rate does not drift) reads the tool position
   and evaluates its force. A deadline is missed when a step ends after the start of the next
   period; the loop then skips the periods it missed. */
static void *haptic_thread(void *arg) {
    shared *sh = (shared *)arg;
    struct timespec next;
    double t0, prev = -1, g[3 * NTOOL], r[3 * NTOOL];
    amps_int k;
    clock_gettime(CLOCK_MONOTONIC, &next);
    t0 = ts_s(&next);
    while (!stopped(sh)) {
        double u[3], f[3] = {0, 0, 0}, wake, done;
        add_ns(&next, HAPTIC_NS);
        clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &next, NULL);
        wake = now_s();
        if (prev >= 0 && wake - prev > sh->hworst) sh->hworst = wake - prev;
        if (prev >= 0 && sh->nperiod < sh->hcap) sh->period[sh->nperiod++] = wake - prev;
        prev = wake;
        tool_path(sh->amp, ts_s(&next) - t0, u);
        pthread_mutex_lock(&sh->lock);
        /* every pinned node is a tool node: g = u at each (the model's nodes, ascending) */
        for (k = 0; k < sh->front->n && k < NTOOL; k++) memcpy(g + 3 * k, u, sizeof(u));
        if (sh->front->n <= NTOOL && amps_haptic_eval(sh->front, g, r) == AMPS_OK)
            for (k = 0; k < sh->front->n; k++) {
                f[0] += r[3 * k];
                f[1] += r[3 * k + 1];
                f[2] += r[3 * k + 2];
            }
        memcpy(sh->force, f, sizeof(f));
        memcpy(sh->device, u, sizeof(u));
        pthread_mutex_unlock(&sh->lock);
        /* f would go to the haptic device here */
        done = now_s();
        sh->hsteps++;
        sh->hstep_sum += done - wake;
        if (done - wake > sh->hstep_max) sh->hstep_max = done - wake;
        if (done > ts_s(&next) + 1e-9 * HAPTIC_NS) {
            sh->hmissed++;
            while (ts_s(&next) + 1e-9 * HAPTIC_NS < done) add_ns(&next, HAPTIC_NS);
        }
    }
    return NULL;
}

/* 60 Hz: the tool pinned where the device is, the surface displacements (the backward solve
   over closure_L(surface) costs about as much as a full solve: milliseconds on a large model,
   which the haptic thread never waits for), the haptic model of the new state published. */
static void *visual_thread(void *arg) {
    shared *sh = (shared *)arg;
    amps_ctx ctx;
    amps_update *U = amps_scene_engine(sh->S);
    struct timespec next;
    const amps_mesh *m = amps_scene_mesh(sh->S);
    double *xw = (double *)malloc(sizeof(double) * (size_t)(sh->nw > 0 ? sh->nw : 1));
    double *disp = sh->outdir ? (double *)calloc(3 * (size_t)m->nnode, sizeof(double)) : NULL;
    amps_ctx_init(&ctx);
    if (sh->pool) jobs_attach(sh->pool, &ctx); /* the solves' parallel work goes to the pool */
    if (!xw || (sh->outdir && !disp)) {
        fprintf(stderr, "visual: out of memory\n");
        stop_all(sh);
    }
    clock_gettime(CLOCK_MONOTONIC, &next);
    while (!stopped(sh)) {
        amps_status s;
        double f[3], u[3], umax = 0;
        amps_int k;
        amps_haptic *back = sh->front == &sh->model[0] ? &sh->model[1] : &sh->model[0];
        add_ns(&next, VISUAL_NS);
        clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &next, NULL);
        pthread_mutex_lock(&sh->lock);
        memcpy(u, sh->device, sizeof(u));
        memcpy(f, sh->force, sizeof(f));
        pthread_mutex_unlock(&sh->lock);
        for (k = 0, s = AMPS_OK; k < NTOOL && s == AMPS_OK; k++) s = amps_scene_pin(&ctx, sh->S, sh->tool[k], u);
        if (s == AMPS_OK) s = amps_update_solve_watched(&ctx, U, xw);
        if (s >= 0) s = amps_scene_haptic_build(&ctx, sh->S, back);
        if (s < 0) {
            fprintf(stderr, "visual: %s\n", ctx.msg);
            stop_all(sh);
            break;
        }
        pthread_mutex_lock(&sh->lock);
        sh->front = back; /* published */
        pthread_mutex_unlock(&sh->lock);
        /* "render" the frame: the largest surface displacement (a node's 3 equations are consecutive) */
        for (k = 0; k + 2 < sh->nw; k += 3) {
            double a = 0;
            int d;
            for (d = 0; d < 3; d++) a += xw[k + d] * xw[k + d];
            if (a > umax) umax = a;
        }
        if (sh->frames % 15 == 0)
            printf("frame %4ld  max surface displacement %.4e  tool force (%+.4e, %+.4e, %+.4e)\n", sh->frames,
                   sqrt(umax), f[0], f[1], f[2]);
        if (disp && sh->frames % 30 == 0) {
            char path[1024];
            for (k = 0; k < sh->nw; k++) disp[3 * sh->wnode[k] + sh->wdim[k]] = xw[k];
            snprintf(path, sizeof(path), "%s/frame_%04ld.vtu", sh->outdir, sh->frames);
            if (amps_mesh_write_vtu(&ctx, path, m, disp, NULL, NULL) != AMPS_OK)
                fprintf(stderr, "visual: %s\n", ctx.msg);
        }
        sh->frames++;
    }
    free(xw);
    free(disp);
    return NULL;
}

/* Surface nodes (of faces that belong to one tet only) into on[v] = 1. */
static int face_cmp(const void *a, const void *b) {
    const amps_int *x = (const amps_int *)a, *y = (const amps_int *)b;
    int k;
    for (k = 0; k < 3; k++)
        if (x[k] != y[k]) return x[k] < y[k] ? -1 : 1;
    return 0;
}
static int cmp_double(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y;
}

static int surface_nodes(const amps_mesh *m, unsigned char *on) {
    size_t nf = 4 * (size_t)m->ntet, f, g;
    amps_int *fc = (amps_int *)malloc(sizeof(amps_int) * 3 * nf), t;
    int k;
    if (!fc) return -1;
    for (t = 0; t < m->ntet; t++)
        for (k = 0; k < 4; k++) {
            amps_int *q = fc + 3 * (4 * (size_t)t + (size_t)k), w;
            q[0] = m->tet[4 * t + (k + 1) % 4];
            q[1] = m->tet[4 * t + (k + 2) % 4];
            q[2] = m->tet[4 * t + (k + 3) % 4];
            if (q[0] > q[1]) {
                w = q[0];
                q[0] = q[1];
                q[1] = w;
            }
            if (q[1] > q[2]) {
                w = q[1];
                q[1] = q[2];
                q[2] = w;
            }
            if (q[0] > q[1]) {
                w = q[0];
                q[0] = q[1];
                q[1] = w;
            }
        }
    qsort(fc, nf, 3 * sizeof(amps_int), face_cmp);
    for (f = 0; f < nf; f = g) {
        for (g = f + 1; g < nf && !face_cmp(fc + 3 * f, fc + 3 * g); g++) {}
        if (g - f == 1)
            for (k = 0; k < 3; k++) on[fc[3 * f + (size_t)k]] = 1;
    }
    free(fc);
    return 0;
}

int main(int argc, char **argv) {
    amps_ctx ctx;
    amps_mesh *m = NULL;
    shared sh;
    pthread_t th, tv;
    double seconds = 3, lo[3] = {1e300, 1e300, 1e300}, hi[3] = {-1e300, -1e300, -1e300}, t0, el;
    double best[NTOOL];
    amps_int v, nn, *dof = NULL;
    unsigned char *fixed, *surf;
    int a, k, d, workers = 2;
    amps_ctx_init(&ctx);
    ctx.nthreads = 1; /* one thread per loop: the haptic step is tiny, and an OpenMP team's
                           wake-up (worse on a busy machine) would cost more than it saves */
    memset(&sh, 0, sizeof(sh));
    for (a = 1; a < argc; a++) {
        if (!strcmp(argv[a], "-t") && a + 1 < argc) seconds = atof(argv[++a]);
        else if (!strcmp(argv[a], "-o") && a + 1 < argc) sh.outdir = argv[++a];
        else if (!strcmp(argv[a], "-w") && a + 1 < argc) workers = atoi(argv[++a]);
        else if (argv[a][0] == '-') {
            fprintf(stderr, "usage: haptic_loop [-t seconds] [-o outdir] [-w workers] [mesh file]\n");
            return 2;
        } else if (!(m = amps_mesh_read(&ctx, argv[a]))) {
            fprintf(stderr, "%s\n", ctx.msg);
            return 1;
        }
    }
    if (!m) m = amps_mesh_brick(&ctx, 10); /* 1 x 1 x 2, 2541 nodes */
    if (!m) {
        fprintf(stderr, "%s\n", ctx.msg);
        return 1;
    }
    nn = m->nnode;
    for (v = 0; v < nn; v++)
        for (d = 0; d < 3; d++) {
            if (m->xyz[3 * v + d] < lo[d]) lo[d] = m->xyz[3 * v + d];
            if (m->xyz[3 * v + d] > hi[d]) hi[d] = m->xyz[3 * v + d];
        }
    sh.amp = 0.02 * (hi[2] - lo[2]);
    fixed = (unsigned char *)calloc((size_t)nn, 1);
    surf = (unsigned char *)calloc((size_t)nn, 1);
    dof = (amps_int *)malloc(sizeof(amps_int) * 3 * (size_t)nn);
    sh.widx = (amps_int *)malloc(sizeof(amps_int) * 3 * (size_t)nn);
    sh.wnode = (amps_int *)malloc(sizeof(amps_int) * 3 * (size_t)nn);
    sh.wdim = (int *)malloc(sizeof(int) * 3 * (size_t)nn);
    if (!fixed || !surf || !dof || !sh.widx || !sh.wnode || !sh.wdim || surface_nodes(m, surf)) {
        fprintf(stderr, "out of memory\n");
        return 1;
    }
    /* the bottom face held; the tool: the NTOOL free nodes nearest the centre of the top face */
    for (v = 0; v < nn; v++) fixed[v] = m->xyz[3 * v + 2] < lo[2] + 0.02 * (hi[2] - lo[2]);
    for (k = 0; k < NTOOL; k++) {
        sh.tool[k] = -1;
        best[k] = 1e300;
    }
    for (v = 0; v < nn; v++) {
        const double *x = m->xyz + 3 * v;
        double dx = x[0] - 0.5 * (lo[0] + hi[0]), dy = x[1] - 0.5 * (lo[1] + hi[1]), dz = x[2] - hi[2];
        double dist = dx * dx + dy * dy + dz * dz;
        if (fixed[v] || dist >= best[NTOOL - 1]) continue;
        for (k = NTOOL - 1; k > 0 && best[k - 1] > dist; k--) {
            best[k] = best[k - 1];
            sh.tool[k] = sh.tool[k - 1];
        }
        best[k] = dist;
        sh.tool[k] = v;
    }
    sh.S = amps_scene_create(&ctx, m, NULL); /* the scene owns m from here */
    if (!sh.S) {
        fprintf(stderr, "%s\n", ctx.msg);
        return 1;
    }
    amps_scene_set_material(&ctx, sh.S, 3000.0, 0.45); /* soft tissue: E = 3 kPa, nu = 0.45 */
    for (v = 0; v < nn; v++)
        if (fixed[v]) amps_scene_fix(&ctx, sh.S, 1, &v);
    for (k = 0; k < NTOOL; k++) {
        double u0[3] = {0, 0, 0};
        amps_scene_pin(&ctx, sh.S, sh.tool[k], u0);
    }
    t0 = now_s();
    amps_haptic_init(&sh.model[0]);
    amps_haptic_init(&sh.model[1]);
    sh.front = &sh.model[0];
    if (amps_scene_solve(&ctx, sh.S) != AMPS_OK || amps_scene_haptic_build(&ctx, sh.S, sh.front) != AMPS_OK) {
        fprintf(stderr, "%s\n", ctx.msg);
        return 1;
    }
    printf("model: %ld nodes, %ld equations, factored and solved in %.3f s; tool: %d nodes; %.1f s run\n", (long)nn,
           (long)amps_scene_ndof(sh.S), now_s() - t0, NTOOL, seconds);
    /* the scene's node-to-equation map (the engine's indices of each node's DOFs, -1: fixed) */
    for (v = 0; v < nn; v++)
        if (amps_scene_node_dofs(&ctx, sh.S, v, dof + 3 * v) != AMPS_OK) {
            fprintf(stderr, "%s\n", ctx.msg);
            return 1;
        }
    /* the watch set: every equation of the free surface nodes */
    for (v = 0; v < nn; v++)
        if (surf[v])
            for (d = 0; d < 3; d++)
                if (dof[3 * v + d] >= 0) {
                    sh.widx[sh.nw] = dof[3 * v + d];
                    sh.wnode[sh.nw] = v;
                    sh.wdim[sh.nw] = d;
                    sh.nw++;
                }
    if (amps_update_watch(&ctx, amps_scene_engine(sh.S), sh.nw, sh.widx) != AMPS_OK) {
        fprintf(stderr, "%s\n", ctx.msg);
        return 1;
    }
    sh.hcap = (long)(1000 * seconds) + 1000;
    sh.period = (double *)malloc(sizeof(double) * (size_t)sh.hcap);
    if (!sh.period || (workers > 0 && !(sh.pool = jobs_create(workers)))) {
        fprintf(stderr, "cannot start the job system\n");
        return 1;
    }
    pthread_mutex_init(&sh.lock, NULL);
    t0 = now_s();
    if (pthread_create(&th, NULL, haptic_thread, &sh) || pthread_create(&tv, NULL, visual_thread, &sh)) {
        fprintf(stderr, "cannot start the threads\n");
        return 1;
    }
    while (!stopped(&sh) && now_s() - t0 < seconds) {
        struct timespec ts = {0, 10000000L};
        nanosleep(&ts, NULL);
    }
    stop_all(&sh);
    pthread_join(th, NULL);
    pthread_join(tv, NULL);
    el = now_s() - t0;
    printf("haptic: %ld steps in %.2f s = %.1f Hz (target 1000), step mean %.3f ms, max %.3f ms, worst period %.3f ms, missed deadlines %ld\n",
           sh.hsteps, el, sh.hsteps / el, sh.hsteps ? 1e3 * sh.hstep_sum / sh.hsteps : 0.0, 1e3 * sh.hstep_max,
           1e3 * sh.hworst, sh.hmissed);
    printf("visual: %ld frames in %.2f s = %.1f Hz (target 60), %ld watched surface equations\n", sh.frames, el,
           sh.frames / el, (long)sh.nw);
    if (sh.nperiod > 0) {
        qsort(sh.period, (size_t)sh.nperiod, sizeof(double), cmp_double);
        printf("haptic period: median %.3f ms, p99 %.3f ms (target < 1.5 ms), worst %.3f ms; visual solves on %d "
               "job-system workers (%ld chunks ran on them)\n",
               1e3 * sh.period[sh.nperiod / 2], 1e3 * sh.period[(long)(0.99 * (double)(sh.nperiod - 1))],
               1e3 * sh.period[sh.nperiod - 1], workers, sh.pool ? jobs_chunks_by_workers(sh.pool) : 0L);
    }
    jobs_destroy(sh.pool);
    free(sh.period);
    pthread_mutex_destroy(&sh.lock);
    amps_haptic_free(&ctx, &sh.model[0]);
    amps_haptic_free(&ctx, &sh.model[1]);
    amps_scene_free(&ctx, sh.S);
    free(fixed);
    free(surf);
    free(dof);
    free(sh.widx);
    free(sh.wnode);
    free(sh.wdim);
    return 0;
}
