/* A surgical-style frame loop: a scalpel, a grasper and a haptic thread on one block of tissue.

   usage: frame_loop [-f frames]
   Model: a 12 x 12 x 4 block (amps_mesh_grid, 13 x 13 x 5 nodes), fixed at its bottom face.
     haptic thread (1 kHz): reads the device (here: the grasper's path plus a tremor), evaluates
       the latest published haptic model at it (amps_haptic_eval: r = r0 + H (g - g0), a 3 x 3
       product for the one pinned node), sends the force to the device and hands the position to
       the frame. It never calls the scene, so nothing the frame does (cuts, commits, swaps of a
       re-factorization, the visual solve) delays it;
     frame (main thread), every 20 haptic steps, the only thread that calls the scene: a batch:
       the scalpel's stroke along a curve on the top face (1-2 nodes cut, amps_scene_stroke), the
       grasper pinned at the latest device position (amps_scene_pin), one commit
       (amps_scene_commit); the visual solve of the top face (amps_scene_solve_watched); the
       haptic model of the new system built into the back buffer (amps_scene_haptic_build) and
       published by a pointer swap.
   The two threads share a tiny mutex, held for the swap (frame) or one evaluation and a copy of
   the position (haptic thread): microseconds. One line per 10th frame; at the end the worst
   haptic step and a check of the watched displacements against a full solve.
   Scheduling is the engine's job, not the library's: on a loaded machine the haptic thread is
   descheduled for milliseconds (bench/RESULTS.md 8d: wake-up delays to 16 ms at p99 under load,
   0.05 ms at SCHED_FIFO). A simulator gives the haptic thread a real-time priority where it is
   permitted (pthread_setschedparam(th, SCHED_FIFO, {.sched_priority = 10}) or `chrt -f 10`)
   and a core of its own (pthread_setaffinity_np / taskset, the visual thread elsewhere).
   Build: make examples (or cc -std=c99 -O2 -I. examples/frame_loop.c -lpthread -lm). */
#ifndef _POSIX_C_SOURCE
#define _POSIX_C_SOURCE 200809L /* nanosleep */
#endif
#define AMPS_IMPLEMENTATION
#include "amps.h"
#include <pthread.h>
#include <time.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <math.h>

#define NX 13
#define NZ 5
#define HAPTIC_PER_FRAME 20

typedef struct shared {
    pthread_mutex_t swap; /* held only for the model's pointer swap or one evaluation */
    amps_haptic model[2]; /* the haptic thread reads *front, the frame builds the other */
    amps_haptic *front;
    double device[3];     /* the grasper's latest device position (haptic thread) */
    double force[3];      /* its latest force */
    long steps, frame_at; /* haptic steps so far; at the start of the frame */
    double worst;         /* longest haptic step (s) */
    int stop;
} shared;

/* The grasper's path (the hand's motion) at haptic step k. */
static void device_path(long k, double u[3]) {
    double s = (double)k / HAPTIC_PER_FRAME;        /* in frames */
    u[0] = 0.01 * s + 0.002 * sin(0.7 * (double)k); /* a drift and a tremor */
    u[1] = 0.0;
    u[2] = 0.005 * s;
}

static void *haptic(void *arg) {
    shared *sh = (shared *)arg;
    struct timespec ms = {0, 1000000L};
    for (;;) {
        double t0 = amps_now(), u[3], r[3];
        int stop;
        pthread_mutex_lock(&sh->swap);
        device_path(sh->steps, u);
        /* the model has one pinned node, the grasper: g = u (3 entries) */
        if (amps_haptic_eval(sh->front, u, r) == AMPS_OK) memcpy(sh->force, r, sizeof(r));
        memcpy(sh->device, u, sizeof(u));
        sh->steps++;
        stop = sh->stop;
        pthread_mutex_unlock(&sh->swap);
        /* r would go to the haptic device here */
        if (amps_now() - t0 > sh->worst) sh->worst = amps_now() - t0;
        if (stop) break;
        nanosleep(&ms, NULL);
    }
    return NULL;
}

/* The scalpel's path on the top face (z = NZ - 1) at parameter s. */
static void scalpel(double s, double p[3]) {
    p[0] = 6.0 + 4.6 * sin(0.11 * s);
    p[1] = 6.0 + 4.6 * sin(0.17 * s + 1.0);
    p[2] = NZ - 1;
}

/* Waits until the haptic thread made HAPTIC_PER_FRAME steps in this frame. */
static void wait_haptic(shared *sh) {
    struct timespec ms = {0, 500000L};
    for (;;) {
        int done;
        pthread_mutex_lock(&sh->swap);
        done = sh->stop || sh->steps - sh->frame_at >= HAPTIC_PER_FRAME;
        if (done) sh->frame_at = sh->steps;
        pthread_mutex_unlock(&sh->swap);
        if (done) return;
        nanosleep(&ms, NULL);
    }
}

/* Builds the model of the current system into the back buffer and publishes it. */
static amps_status publish(shared *sh, amps_ctx *ctx, amps_scene *S) {
    amps_haptic *back = sh->front == &sh->model[0] ? &sh->model[1] : &sh->model[0];
    amps_status s = amps_scene_haptic_build(ctx, S, back);
    if (s < 0) return s;
    pthread_mutex_lock(&sh->swap);
    sh->front = back;
    pthread_mutex_unlock(&sh->swap);
    return AMPS_OK;
}

/* One frame: the stroke and the grasper in one commit, the visual solve, the haptic model. */
static int frame(shared *sh, amps_ctx *ctx, amps_scene *S, amps_int grasper, int f, amps_int *ncut) {
    double pts[6], blade[3] = {0, 0, 1}, u[3];
    amps_scene_stroke_result r;
    amps_status s;
    memset(&r, 0, sizeof(r));
    scalpel(1.0 * f, pts);
    scalpel(1.0 * (f + 1), pts + 3);
    pthread_mutex_lock(&sh->swap);
    memcpy(u, sh->device, sizeof(u));
    pthread_mutex_unlock(&sh->swap);
    s = amps_scene_begin_batch(ctx, S);
    if (s == AMPS_OK) s = amps_scene_stroke(ctx, S, 2, pts, blade, 0.45, &r);
    if (s == AMPS_OK) s = amps_scene_pin(ctx, S, grasper, u);
    if (s == AMPS_OK) s = amps_scene_commit(ctx, S);
    if (s == AMPS_OK) s = amps_scene_solve_watched(ctx, S);
    if (s >= 0) s = publish(sh, ctx, S);
    *ncut += r.ncut;
    return s < 0;
}

int main(int argc, char **argv) {
    amps_ctx ctx;
    amps_scene *S;
    shared sh;
    pthread_t th;
    amps_int top[NX * NX], k, ncut = 0, grasper = (NZ - 1) * NX * NX + 10 * NX + 10;
    int nframes = 60, f, a, failed = 0;
    double *uw, err = 0, un = 0, zero[3] = {0, 0, 0}, rm[3], rs[3];
    for (a = 1; a < argc; a++) {
        if (!strcmp(argv[a], "-f") && a + 1 < argc) nframes = atoi(argv[++a]);
        else {
            fprintf(stderr, "usage: frame_loop [-f frames]\n");
            return 2;
        }
    }
    amps_ctx_init(&ctx);
    memset(&sh, 0, sizeof(sh));
    amps_haptic_init(&sh.model[0]);
    amps_haptic_init(&sh.model[1]);
    sh.front = &sh.model[0];
    S = amps_scene_create(&ctx, amps_mesh_grid(&ctx, NX, NX, NZ, 1.0, 1.0, 1.0), NULL);
    if (!S || amps_scene_set_material(&ctx, S, 3000.0, 0.45) || amps_scene_fix_where(&ctx, S, 2, AMPS_LT, 0.5, NULL)) {
        fprintf(stderr, "frame_loop: %s\n", ctx.msg);
        return 1;
    }
    for (k = 0; k < NX * NX; k++) top[k] = (NZ - 1) * NX * NX + k; /* the visual set: the top face */
    if (amps_scene_pin(&ctx, S, grasper, zero) || amps_scene_watch(&ctx, S, NX * NX, top) ||
        amps_scene_solve(&ctx, S) < 0 || amps_scene_haptic_build(&ctx, S, sh.front)) {
        fprintf(stderr, "frame_loop: %s\n", ctx.msg);
        return 1;
    }
    pthread_mutex_init(&sh.swap, NULL);
    if (pthread_create(&th, NULL, haptic, &sh)) return 1;
    for (f = 0; f < nframes; f++) {
        double t0 = amps_now();
        if (frame(&sh, &ctx, S, grasper, f, &ncut)) {
            fprintf(stderr, "frame %d: %s\n", f, ctx.msg);
            failed = 1;
            break;
        }
        if (f % 10 == 0) {
            amps_update_stats st;
            amps_update_get_stats(amps_scene_engine(S), &st);
            printf("frame %3d: %ld nodes cut so far, |S u C| %ld, grasper force %.4f, frame %.2f ms\n", f, (long)ncut,
                   (long)st.nsys, sh.force[2], 1e3 * (amps_now() - t0));
        }
        wait_haptic(&sh);
    }
    pthread_mutex_lock(&sh.swap);
    sh.stop = 1;
    pthread_mutex_unlock(&sh.swap);
    pthread_join(th, NULL);
    /* the model at the last device position against the scene's haptic step there */
    amps_haptic_eval(sh.front, sh.device, rm);
    if (amps_scene_pin(&ctx, S, grasper, sh.device) || amps_scene_solve_reactions(&ctx, S) ||
        amps_scene_reaction(&ctx, S, grasper, rs))
        failed = 1;
    /* the watched displacements against a full solve */
    uw = (double *)malloc(sizeof(double) * 3 * NX * NX);
    if (amps_scene_solve_watched(&ctx, S) < 0) failed = 1;
    memcpy(uw, amps_scene_displacements(S) + 3 * top[0], sizeof(double) * 3 * NX * NX);
    if (amps_scene_solve(&ctx, S) < 0) failed = 1;
    for (k = 0; k < 3 * NX * NX; k++) {
        double d = amps_scene_displacements(S)[3 * top[0] + k];
        err = fmax(err, fabs(uw[k] - d));
        un = fmax(un, fabs(d));
    }
    {
        double dr = 0, nr = 0;
        for (k = 0; k < 3; k++) {
            dr = fmax(dr, fabs(rm[k] - rs[k]));
            nr = fmax(nr, fabs(rs[k]));
        }
        printf("frames %d, nodes cut %ld, haptic steps %ld (worst %.3f ms), watched vs full solve %.1e, haptic model "
               "vs scene reactions %.1e\n",
               f, (long)ncut, sh.steps, 1e3 * sh.worst, un > 0 ? err / un : err, nr > 0 ? dr / nr : dr);
        failed |= !(dr <= 1e-8 * nr);
    }
    free(uw);
    amps_haptic_free(&ctx, &sh.model[0]);
    amps_haptic_free(&ctx, &sh.model[1]);
    amps_scene_free(&ctx, S);
    pthread_mutex_destroy(&sh.swap);
    return failed || !(err <= 1e-8 * un);
}
