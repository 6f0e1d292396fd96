/* bench/frameloop: the frame loop of a surgical simulator (examples/frame_loop.c) on a model.

   usage: frameloop <mesh> <frames> <frames.csv> <summary.csv> [idle]
     mesh: beam:<h> | brick:<R> | path to a TetGen .node / .msh / .mesh file
   Setup as in bench/harness (the base held, the opposing forces). The grasper: the 4 free nodes
   highest along the up axis, pinned. A haptic thread at 1 kHz (absolute deadlines, 1 ms apart):
   under the lock, the grasper's pins moved by a tremor, amps_scene_solve_reactions, the reactions
   read. Frames, back to back, each after 20 haptic steps: first <idle> frames (default 20)
   without cuts, then <frames> frames each with a stroke of the scalpel (amps_scene_stroke: a
   spiral in the plane across the up axis at 55% of its height, blade along the up axis, radius
   0.6 h and 0.9 h of path per frame, h = (bounding box volume / nodes)^(1/3): 1-2 nodes cut)
   and the grasper moved, in one batch committed in two phases (begin under the lock, run
   outside it, end under it), then the visual solve of 256 surface nodes (amps_scene_solve_watched).
   Measured: per frame the wall time, the time under the lock, |S u C| and the swaps; the haptic
   period (between successive haptic updates) median, p99 and max; swaps inside haptic steps.
   Appends per-frame rows to frames.csv and one row to summary.csv. */
#ifndef _POSIX_C_SOURCE
#define _POSIX_C_SOURCE 200809L /* clock_nanosleep */
#endif
#define AMPS_IMPLEMENTATION
#include "../amps.h"
#include "bench.h"
#include <pthread.h>
#include <time.h>

#define NGRASP 4
#define HAPTIC_PER_FRAME 20

typedef struct shared {
    pthread_mutex_t lock;
    pthread_cond_t step_done; /* a haptic step ended */
    amps_scene *S;
    amps_ctx hctx;
    amps_int grasp[NGRASP];
    double gu[3]; /* the grasper's displacement set by the frame */
    long steps, frame_at, cap;
    double *period, t_last;
    long swaps;          /* re-factorizations swapped in during a haptic step */
    amps_update_job job; /* the visual solve's job */
    double *y, *xw;
    amps_int ylen;
    int stop, failed;
} shared;

static void *haptic(void *arg) {
    shared *sh = (shared *)arg;
    struct timespec next;
    clock_gettime(CLOCK_MONOTONIC, &next);
    for (;;) {
        amps_update_stats s0, s1;
        double u[3], r[3];
        int k, bad = 0;
        next.tv_nsec += 1000000L;
        if (next.tv_nsec >= 1000000000L) {
            next.tv_nsec -= 1000000000L;
            next.tv_sec++;
        }
        clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &next, NULL);
        { /* a missed deadline is not caught up: the next one is 1 ms after now */
            struct timespec now;
            clock_gettime(CLOCK_MONOTONIC, &now);
            if (now.tv_sec > next.tv_sec || (now.tv_sec == next.tv_sec && now.tv_nsec > next.tv_nsec)) next = now;
        }
        pthread_mutex_lock(&sh->lock);
        if (sh->stop) {
            pthread_cond_broadcast(&sh->step_done);
            pthread_mutex_unlock(&sh->lock);
            break;
        }
        amps_update_get_stats(amps_scene_engine(sh->S), &s0);
        for (k = 0; k < 3; k++) u[k] = sh->gu[k] * (1.0 + 0.02 * sin(0.05 * (double)sh->steps));
        for (k = 0; k < NGRASP && !bad; k++) bad = amps_scene_pin(&sh->hctx, sh->S, sh->grasp[k], u) != AMPS_OK;
        if (!bad) bad = amps_scene_solve_reactions(&sh->hctx, sh->S) != AMPS_OK;
        for (k = 0; k < NGRASP; k++) amps_scene_reaction(&sh->hctx, sh->S, sh->grasp[k], r);
        if (bad) {
            fprintf(stderr, "haptic: %s\n", sh->hctx.msg);
            sh->failed = sh->stop = 1;
        }
        amps_update_get_stats(amps_scene_engine(sh->S), &s1);
        sh->swaps += s1.nrefactor - s0.nrefactor;
        {
            double t = amps_now();
            if (sh->t_last > 0 && sh->steps < sh->cap) sh->period[sh->steps] = t - sh->t_last;
            sh->t_last = t;
        }
        sh->steps++;
        pthread_cond_broadcast(&sh->step_done);
        pthread_mutex_unlock(&sh->lock);
    }
    return NULL;
}

/* Blocks until the haptic thread has made HAPTIC_PER_FRAME steps since the last frame. */
static void wait_haptic(shared *sh) {
    pthread_mutex_lock(&sh->lock);
    while (!sh->stop && sh->steps - sh->frame_at < HAPTIC_PER_FRAME) pthread_cond_wait(&sh->step_done, &sh->lock);
    sh->frame_at = sh->steps;
    pthread_mutex_unlock(&sh->lock);
}

typedef struct frame_info {
    double t_frame, t_locked, t_end; /* wall, under the lock, commit_end */
    amps_int ncut, nsys, nrefactor;
    int undone; /* the commit found the model loose and undid the batch */
} frame_info;

/* The scalpel's spiral at frame f (cutting frames only): p = c + R(f) (cos a, sin a). */
static void spiral(const bench_model *B, double h, int f, double p[3]) {
    int a1 = (B->up + 1) % 3, a2 = (B->up + 2) % 3;
    double ext = fmin(B->hi[a1] - B->lo[a1], B->hi[a2] - B->lo[a2]), R = 0.08 * ext + 0.004 * ext * f, ang = 0;
    int k;
    for (k = 0; k < f; k++) ang += 0.9 * h / (0.08 * ext + 0.004 * ext * k);
    p[B->up] = B->lo[B->up] + 0.55 * (B->hi[B->up] - B->lo[B->up]);
    p[a1] = 0.5 * (B->lo[a1] + B->hi[a1]) + R * cos(ang);
    p[a2] = 0.5 * (B->lo[a2] + B->hi[a2]) + R * sin(ang);
}

static int frame(shared *sh, amps_ctx *ctx, const bench_model *B, double h, int f, int cut, frame_info *fi) {
    double t0 = amps_now(), t1, tl, pts[6], blade[3] = {0, 0, 0};
    amps_scene_stroke_result r;
    amps_update_stats st;
    amps_status s = AMPS_OK;
    int k;
    memset(&r, 0, sizeof(r));
    blade[B->up] = 1;
    pthread_mutex_lock(&sh->lock);
    sh->gu[B->up] = 0.002 * (B->hi[B->up] - B->lo[B->up]) * (1 + 0.3 * sin(0.1 * f));
    if (cut) {
        spiral(B, h, f, pts);
        spiral(B, h, f + 1, pts + 3);
        s = amps_scene_begin_batch(ctx, sh->S);
        if (s == AMPS_OK) s = amps_scene_stroke(ctx, sh->S, 2, pts, blade, 0.6 * h, &r);
    }
    for (k = 0; k < NGRASP && s == AMPS_OK; k++) s = amps_scene_pin(ctx, sh->S, sh->grasp[k], sh->gu);
    if (s == AMPS_OK) s = amps_scene_commit_begin(ctx, sh->S);
    pthread_mutex_unlock(&sh->lock);
    tl = amps_now() - t0;
    if (s != AMPS_OK) return 1;
    amps_scene_commit_run(sh->S); /* outside the lock: the haptic thread goes on */
    pthread_mutex_lock(&sh->lock);
    t1 = amps_now();
    s = amps_scene_commit_end(ctx, sh->S);
    fi->t_end = amps_now() - t1;
    if (s == AMPS_ERR_SINGULAR_UPDATE) { /* a piece the mechanism test missed: the batch undone */
        fi->undone = 1;
        r.ncut = 0;
        s = AMPS_OK;
    }
    /* the visual solve in two phases too (the engine's watched job; the watch set is the
       scene's, set by the first amps_scene_solve_watched) */
    if (s == AMPS_OK) s = amps_update_watched_begin(ctx, amps_scene_engine(sh->S), &sh->job, sh->y, sh->ylen, sh->xw);
    amps_update_get_stats(amps_scene_engine(sh->S), &st);
    pthread_mutex_unlock(&sh->lock);
    tl += amps_now() - t1;
    if (s != AMPS_OK) return 1;
    amps_update_watched_run(&sh->job);
    pthread_mutex_lock(&sh->lock);
    t1 = amps_now();
    amps_update_watched_end(amps_scene_engine(sh->S), &sh->job);
    pthread_mutex_unlock(&sh->lock);
    fi->t_frame = amps_now() - t0;
    fi->t_locked = tl + amps_now() - t1;
    fi->ncut = r.ncut;
    fi->nsys = st.nsys;
    fi->nrefactor = st.nrefactor;
    return s < 0;
}

int main(int argc, char **argv) {
    amps_ctx ctx;
    bench_model B;
    shared sh;
    pthread_t th;
    const char *spec;
    char name[256];
    int frames, idle = 20, f, k, v, ns, undone = 0;
    double h, *tf_idle, *tf_cut, *tl_cut, vol = 1, p50, p99, pmax, fi_med, fc_med, tl_med;
    amps_int *surf, watch[256], ncut = 0, nw;
    frame_info *fi;
    FILE *csv;
    if (argc < 5) {
        fprintf(stderr, "usage: frameloop <beam:h|brick:R|file> <frames> <frames.csv> <summary.csv> [idle]\n");
        return 2;
    }
    spec = argv[1];
    frames = atoi(argv[2]);
    if (argc > 5) idle = atoi(argv[5]);
    if (frames < 1 || idle < 1) return 2;
    bench_mesh_name(spec, name, sizeof(name));
    amps_ctx_init(&ctx);
    bench_model_init(&ctx, spec, NULL, &B);
    for (k = 0; k < 3; k++) vol *= B.hi[k] - B.lo[k];
    h = cbrt(vol / B.nn);
    memset(&sh, 0, sizeof(sh));
    amps_ctx_init(&sh.hctx);
    sh.S = B.S;
    /* the grasper: the NGRASP highest free, unloaded nodes */
    for (k = 0; k < NGRASP; k++) {
        int best = -1, j;
        for (v = 0; v < B.nn; v++) {
            int taken = 0;
            for (j = 0; j < k; j++) taken |= sh.grasp[j] == v;
            if (B.fixed[v] || taken || B.force[3 * v] != 0.0) continue;
            if (best < 0 || B.m->xyz[3 * v + B.up] > B.m->xyz[3 * best + B.up]) best = v;
        }
        sh.grasp[k] = best;
        if (amps_scene_pin(&ctx, sh.S, best, sh.gu) != AMPS_OK) bench_die("pin", ctx.msg);
    }
    /* the visual set: 256 surface nodes, evenly spread over the surface list */
    surf = (amps_int *)bench_alloc(sizeof(amps_int) * (size_t)B.nn);
    ns = bench_surface_nodes(B.m, surf);
    nw = ns < 256 ? ns : 256;
    for (k = 0; k < nw; k++) watch[k] = surf[(size_t)k * (size_t)ns / (size_t)nw];
    if (amps_scene_watch(&ctx, sh.S, nw, watch) != AMPS_OK || amps_scene_solve(&ctx, sh.S) < 0 ||
        amps_scene_solve_watched(&ctx, sh.S) < 0)
        bench_die("first solve", ctx.msg);
    sh.ylen = 3 * (amps_int)B.nn + 3 * 4 * (amps_int)(frames + idle) + 64; /* the order after every cut */
    sh.y = (double *)bench_alloc(sizeof(double) * (size_t)sh.ylen * 2);
    sh.xw = (double *)bench_alloc(sizeof(double) * 3 * 256);
    sh.cap = 40L * (frames + idle) * HAPTIC_PER_FRAME + 1000;
    sh.period = (double *)bench_alloc(sizeof(double) * (size_t)sh.cap);
    fi = (frame_info *)bench_alloc(sizeof(frame_info) * (size_t)(frames + idle));
    tf_idle = (double *)bench_alloc(sizeof(double) * (size_t)idle);
    tf_cut = (double *)bench_alloc(sizeof(double) * (size_t)frames);
    tl_cut = (double *)bench_alloc(sizeof(double) * (size_t)frames);
    pthread_mutex_init(&sh.lock, NULL);
    pthread_cond_init(&sh.step_done, NULL);
    if (pthread_create(&th, NULL, haptic, &sh)) bench_die("thread", "pthread_create failed");
    for (f = 0; f < idle + frames && !sh.failed; f++) {
        wait_haptic(&sh);
        if (frame(&sh, &ctx, &B, h, f - idle, f >= idle, fi + f)) {
            fprintf(stderr, "frame %d: %s\n", f, ctx.msg);
            sh.failed = 1;
            break;
        }
        ncut += fi[f].ncut;
        undone += fi[f].undone;
    }
    pthread_mutex_lock(&sh.lock);
    sh.stop = 1;
    pthread_mutex_unlock(&sh.lock);
    pthread_join(th, NULL);
    if (sh.failed) return 1;
    csv = bench_csv(argv[3], "mesh,frame,cutting,ncut,t_frame,t_locked,t_end,nsys,nrefactor");
    for (f = 0; f < idle + frames; f++) {
        if (csv)
            fprintf(csv, "%s,%d,%d,%ld,%.6e,%.6e,%.6e,%ld,%ld\n", name, f - idle, f >= idle, (long)fi[f].ncut,
                    fi[f].t_frame, fi[f].t_locked, fi[f].t_end, (long)fi[f].nsys, (long)fi[f].nrefactor);
        if (f < idle) tf_idle[f] = fi[f].t_frame;
        else {
            tf_cut[f - idle] = fi[f].t_frame;
            tl_cut[f - idle] = fi[f].t_locked;
        }
    }
    if (csv) fclose(csv);
    {
        long np = (sh.steps < sh.cap ? sh.steps : sh.cap) - 1;
        double *pp = sh.period + 1;
        p50 = bench_median(pp, (int)np);
        p99 = bench_quantile(pp, (int)np, 0.99);
        pmax = bench_quantile(pp, (int)np, 1.0);
    }
    fi_med = bench_median(tf_idle, idle);
    fc_med = bench_median(tf_cut, frames);
    tl_med = bench_median(tl_cut, frames);
    printf("%s: %d nodes, %d frames (%d idle), %ld nodes cut (%d strokes undone), |S u C| at the end %ld, "
           "re-factorizations %ld\n",
           name, B.nn, frames, idle, (long)ncut, undone, (long)fi[idle + frames - 1].nsys,
           (long)fi[idle + frames - 1].nrefactor);
    printf("  haptic: %ld steps, period median %.3f ms, p99 %.3f ms, max %.3f ms, swaps in haptic steps %ld\n",
           sh.steps, 1e3 * p50, 1e3 * p99, 1e3 * pmax, sh.swaps);
    printf("  frame: idle median %.2f ms, cutting median %.2f ms (%.2fx), of which under the lock %.2f ms\n",
           1e3 * fi_med, 1e3 * fc_med, fc_med / fi_med, 1e3 * tl_med);
    csv = bench_csv(argv[4], "mesh,nodes,frames,idle,ncut,nsys_end,nrefactor,haptic_steps,haptic_p50,haptic_p99,"
                             "haptic_max,haptic_swaps,frame_idle,frame_cut,frame_ratio,frame_locked");
    if (csv) {
        fprintf(csv, "%s,%d,%d,%d,%ld,%ld,%ld,%ld,%.6e,%.6e,%.6e,%ld,%.6e,%.6e,%.4f,%.6e\n", name, B.nn, frames, idle,
                (long)ncut, (long)fi[idle + frames - 1].nsys, (long)fi[idle + frames - 1].nrefactor, sh.steps, p50, p99,
                pmax, sh.swaps, fi_med, fc_med, fc_med / fi_med, tl_med);
        fclose(csv);
    }
    pthread_mutex_destroy(&sh.lock);
    pthread_cond_destroy(&sh.step_done);
    return 0;
}
