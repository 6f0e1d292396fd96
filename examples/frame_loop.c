/* A surgical-style frame loop: a scalpel, a grasper and a haptic thread on one block of tissue.

   usage: frame_loop [-f frames]
   Model: a 12 x 12 x 4 block (amps_mesh_grid, 13 x 13 x 5 nodes), fixed at its bottom face.
     haptic thread (1 kHz): moves the grasper's pin by a small tremor, amps_scene_solve_reactions
       (the dense system alone: O(|S u C|^2), never a swap), reads the grasper's force;
     frame (main thread), every 20 haptic steps:
       under the lock   a batch: the scalpel's stroke along a curve on the top face (1-2 nodes
                        cut, amps_scene_stroke), the grasper moved (amps_scene_pin), then
                        amps_scene_commit_begin;
       without the lock amps_scene_commit_run (the expensive part of the commit, while the
                        haptic thread goes on);
       under the lock   amps_scene_commit_end and the visual solve of the top face
                        (amps_scene_solve_watched, which may swap a re-factorization in).
   One line per 10th frame; at the end the worst haptic step and a check of the watched
   displacements against a full solve.
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
    pthread_mutex_t lock; /* guards every scene call except amps_scene_commit_run */
    amps_scene *S;
    amps_ctx hctx;        /* the haptic thread's context */
    amps_int grasper;     /* the pinned node */
    double grasp[3];      /* its displacement set by the frame */
    double force[3];      /* its latest reaction */
    long steps, frame_at; /* haptic steps so far; at the start of the frame */
    double worst;         /* longest haptic step (s) */
    int stop, failed;
} shared;

static void *haptic(void *arg) {
    shared *sh = (shared *)arg;
    struct timespec ms = {0, 1000000L};
    for (;;) {
        double t0, u[3];
        long k;
        pthread_mutex_lock(&sh->lock);
        if (sh->stop) {
            pthread_mutex_unlock(&sh->lock);
            break;
        }
        t0 = amps_now();
        k = sh->steps;
        u[0] = sh->grasp[0] + 0.002 * sin(0.7 * (double)k); /* tremor */
        u[1] = sh->grasp[1];
        u[2] = sh->grasp[2];
        if (amps_scene_pin(&sh->hctx, sh->S, sh->grasper, u) != AMPS_OK ||
            amps_scene_solve_reactions(&sh->hctx, sh->S) != AMPS_OK ||
            amps_scene_reaction(&sh->hctx, sh->S, sh->grasper, sh->force) != AMPS_OK) {
            fprintf(stderr, "haptic: %s\n", sh->hctx.msg);
            sh->failed = sh->stop = 1;
        }
        sh->steps++;
        if (amps_now() - t0 > sh->worst) sh->worst = amps_now() - t0;
        pthread_mutex_unlock(&sh->lock);
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

/* Waits (without the lock) until the haptic thread made HAPTIC_PER_FRAME steps in this frame. */
static void wait_haptic(shared *sh) {
    struct timespec ms = {0, 500000L};
    for (;;) {
        int done;
        pthread_mutex_lock(&sh->lock);
        done = sh->stop || sh->steps - sh->frame_at >= HAPTIC_PER_FRAME;
        if (done) sh->frame_at = sh->steps;
        pthread_mutex_unlock(&sh->lock);
        if (done) return;
        nanosleep(&ms, NULL);
    }
}

/* One frame: the batch under the lock, Steps 1-2 outside it, the end and the visual solve. */
static int frame(shared *sh, amps_ctx *ctx, int f, amps_int *ncut) {
    double pts[6], blade[3] = {0, 0, 1};
    amps_scene_stroke_result r;
    amps_status s;
    memset(&r, 0, sizeof(r));
    scalpel(1.0 * f, pts);
    scalpel(1.0 * (f + 1), pts + 3);
    pthread_mutex_lock(&sh->lock);
    sh->grasp[0] = 0.01 * f;
    sh->grasp[2] = 0.005 * f;
    s = amps_scene_begin_batch(ctx, sh->S);
    if (s == AMPS_OK) s = amps_scene_stroke(ctx, sh->S, 2, pts, blade, 0.45, &r);
    if (s == AMPS_OK) s = amps_scene_pin(ctx, sh->S, sh->grasper, sh->grasp);
    if (s == AMPS_OK) s = amps_scene_commit_begin(ctx, sh->S);
    pthread_mutex_unlock(&sh->lock);
    if (s != AMPS_OK) return 1;
    amps_scene_commit_run(sh->S); /* the haptic thread goes on meanwhile */
    pthread_mutex_lock(&sh->lock);
    s = amps_scene_commit_end(ctx, sh->S);
    if (s == AMPS_OK) s = amps_scene_solve_watched(ctx, sh->S);
    pthread_mutex_unlock(&sh->lock);
    *ncut += r.ncut;
    return s < 0;
}

int main(int argc, char **argv) {
    amps_ctx ctx;
    shared sh;
    pthread_t th;
    amps_int top[NX * NX], k, ncut = 0;
    int nframes = 60, f, a;
    double *uw, err = 0, un = 0;
    for (a = 1; a < argc; a++) {
        if (!strcmp(argv[a], "-f") && a + 1 < argc) nframes = atoi(argv[++a]);
        else {
            fprintf(stderr, "usage: frame_loop [-f frames]\n");
            return 2;
        }
    }
    amps_ctx_init(&ctx);
    memset(&sh, 0, sizeof(sh));
    amps_ctx_init(&sh.hctx);
    sh.S = amps_scene_create(&ctx, amps_mesh_grid(&ctx, NX, NX, NZ, 1.0, 1.0, 1.0), NULL);
    if (!sh.S || amps_scene_set_material(&ctx, sh.S, 3000.0, 0.45) ||
        amps_scene_fix_where(&ctx, sh.S, 2, AMPS_LT, 0.5, NULL)) {
        fprintf(stderr, "frame_loop: %s\n", ctx.msg);
        return 1;
    }
    for (k = 0; k < NX * NX; k++) top[k] = (NZ - 1) * NX * NX + k; /* the visual set: the top face */
    sh.grasper = (NZ - 1) * NX * NX + 10 * NX + 10;
    if (amps_scene_pin(&ctx, sh.S, sh.grasper, sh.grasp) || amps_scene_watch(&ctx, sh.S, NX * NX, top) ||
        amps_scene_solve(&ctx, sh.S) < 0) {
        fprintf(stderr, "frame_loop: %s\n", ctx.msg);
        return 1;
    }
    pthread_mutex_init(&sh.lock, NULL);
    if (pthread_create(&th, NULL, haptic, &sh)) return 1;
    for (f = 0; f < nframes && !sh.failed; f++) {
        double t0 = amps_now();
        if (frame(&sh, &ctx, f, &ncut)) {
            fprintf(stderr, "frame %d: %s\n", f, ctx.msg);
            sh.failed = 1;
            break;
        }
        if (f % 10 == 0) {
            amps_update_stats st;
            pthread_mutex_lock(&sh.lock);
            amps_update_get_stats(amps_scene_engine(sh.S), &st);
            printf("frame %3d: %ld nodes cut so far, |S u C| %ld, grasper force %.4f, frame %.2f ms\n", f, (long)ncut,
                   (long)st.nsys, sh.force[2], 1e3 * (amps_now() - t0));
            pthread_mutex_unlock(&sh.lock);
        }
        wait_haptic(&sh);
    }
    pthread_mutex_lock(&sh.lock);
    sh.stop = 1;
    pthread_mutex_unlock(&sh.lock);
    pthread_join(th, NULL);
    /* the watched displacements against a full solve */
    uw = (double *)malloc(sizeof(double) * 3 * NX * NX);
    if (amps_scene_solve_watched(&ctx, sh.S) < 0) sh.failed = 1;
    memcpy(uw, amps_scene_displacements(sh.S) + 3 * top[0], sizeof(double) * 3 * NX * NX);
    if (amps_scene_solve(&ctx, sh.S) < 0) sh.failed = 1;
    for (k = 0; k < 3 * NX * NX; k++) {
        double d = amps_scene_displacements(sh.S)[3 * top[0] + k];
        err = fmax(err, fabs(uw[k] - d));
        un = fmax(un, fabs(d));
    }
    printf("frames %d, nodes cut %ld, haptic steps %ld (worst %.3f ms), watched vs full solve %.1e\n", f, (long)ncut,
           sh.steps, 1e3 * sh.worst, un > 0 ? err / un : err);
    free(uw);
    amps_scene_free(&ctx, sh.S);
    pthread_mutex_destroy(&sh.lock);
    return sh.failed || !(err <= 1e-8 * un);
}
