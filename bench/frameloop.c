/* bench/frameloop: the frame loop of a surgical simulator (examples/frame_loop.c) on a model.

   usage: frameloop <mesh> <frames> <frames.csv> <summary.csv> [idle]
     mesh: beam:<h> | brick:<R> | path to a TetGen .node / .msh / .mesh file
   Setup as in bench/harness (the base held, the opposing forces). The grasper: the 4 free nodes
   highest along the up axis, pinned. A haptic thread at 1 kHz (absolute deadlines, 1 ms apart)
   that never calls the scene: the device position (the grasper's displacement set by the frame
   times a tremor), the latest published haptic model evaluated there (amps_haptic_eval), the
   position handed to the frame, all under a tiny mutex that the frame holds only for a pointer
   swap and a copy of 3 doubles. Frames, back to back, each after 20 haptic steps: first <idle>
   frames (default 20) without cuts, then <frames> frames each with a stroke of the scalpel
   (amps_scene_stroke: a spiral in the plane across the up axis at 55% of its height, blade along
   the up axis, radius 0.6 h and 0.9 h of path per frame, h = (bounding box volume / nodes)^(1/3):
   1-2 nodes cut) and the grasper pinned at the latest device position, in one batch and one
   commit, then the visual solve of 256 surface nodes (amps_scene_solve_watched), then the
   haptic model of the new state built (amps_scene_haptic_build) and published.
   Measured: per frame the wall time and its parts (stroke + commit, visual solve, model build),
   |S u C| and the re-factorizations; a frame's time is its own work (from after its wait for the
   haptic steps to the model's publication). The cutting frame's median is over the frames whose
   stroke cut at least one node (a stroke that cuts none is reported apart: it is a frame with no
   cut, at the |S u C| that the cuts before it left); the haptic period (between successive haptic updates)
   median, p99 and max. Each haptic step is split into its wake-up delay (from its deadline, or
   the end of the step before if that was later, to the return of clock_nanosleep: the OS), its
   wait for the mutex and its own work (the evaluation); the periods over 1.5 ms are attributed
   to the part that made them long. At the end the last model is checked against the scene's
   haptic step (amps_scene_solve_reactions) at the last device position.
   Appends per-frame rows to frames.csv and one row to summary.csv.
   A simulator runs its haptic thread at a real-time priority where permitted (SCHED_FIFO:
   FRAMELOOP_FIFO=1 here, or pthread_setschedparam) and keeps it off the cores of the visual
   thread (pthread_setaffinity_np / taskset): amps.h sets neither. */
#ifndef _POSIX_C_SOURCE
#define _POSIX_C_SOURCE 200809L /* clock_nanosleep */
#endif
#define AMPS_IMPLEMENTATION
#include "../amps.h"
#include "bench.h"
#include <pthread.h>
#include <sched.h>
#include <time.h>

#define NGRASP 4
#define HAPTIC_PER_FRAME 20

typedef struct shared {
    pthread_mutex_t lock;     /* the model's pointer swap, the device position, the counters */
    pthread_cond_t step_done; /* a haptic step ended */
    amps_haptic model[2];     /* the haptic thread reads *front, the frame builds the other */
    amps_haptic *front;
    double gu[3];     /* the grasper's displacement the hand aims at (set by the frame) */
    double device[3]; /* the latest device position (haptic thread) */
    long steps, frame_at, cap;
    double *period, t_last;
    double *late, *wait, *work; /* per haptic step: wake-up delay, mutex wait, own work (s) */
    double t_done;              /* CLOCK_MONOTONIC end of the last haptic step */
    int stop;
} shared;

static double mono(void) {
    struct timespec now;
    clock_gettime(CLOCK_MONOTONIC, &now);
    return (double)now.tv_sec + 1e-9 * (double)now.tv_nsec;
}

static void *haptic(void *arg) {
    shared *sh = (shared *)arg;
    struct timespec next;
    double g[3 * NGRASP], r[3 * NGRASP];
    clock_gettime(CLOCK_MONOTONIC, &next);
    for (;;) {
        double u[3], t_dl, t_woke, t_got, t;
        int k;
        next.tv_nsec += 1000000L;
        if (next.tv_nsec >= 1000000000L) {
            next.tv_nsec -= 1000000000L;
            next.tv_sec++;
        }
        clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &next, NULL);
        { /* a missed deadline is not caught up: the next one is 1 ms after now */
            struct timespec now;
            clock_gettime(CLOCK_MONOTONIC, &now);
            t_dl = (double)next.tv_sec + 1e-9 * (double)next.tv_nsec;
            t_woke = (double)now.tv_sec + 1e-9 * (double)now.tv_nsec;
            if (sh->t_done > t_dl) t_dl = sh->t_done; /* a deadline missed by the last step: no sleep */
            if (now.tv_sec > next.tv_sec || (now.tv_sec == next.tv_sec && now.tv_nsec > next.tv_nsec)) next = now;
        }
        pthread_mutex_lock(&sh->lock);
        t_got = mono();
        if (sh->stop) {
            pthread_cond_broadcast(&sh->step_done);
            pthread_mutex_unlock(&sh->lock);
            break;
        }
        for (k = 0; k < 3; k++) u[k] = sh->gu[k] * (1.0 + 0.02 * sin(0.05 * (double)sh->steps));
        for (k = 0; k < sh->front->n && k < NGRASP; k++) memcpy(g + 3 * k, u, sizeof(u)); /* every pin: the grasper */
        if (sh->front->n <= NGRASP) amps_haptic_eval(sh->front, g, r); /* r: the forces to the device */
        memcpy(sh->device, u, sizeof(u));
        t = mono();
        if (sh->t_last > 0 && sh->steps < sh->cap) {
            sh->period[sh->steps] = t - sh->t_last;
            sh->late[sh->steps] = t_woke > t_dl ? t_woke - t_dl : 0.0;
            sh->wait[sh->steps] = t_got - t_woke;
            sh->work[sh->steps] = t - t_got;
        }
        sh->t_done = sh->t_last = t;
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
    double t_frame, t_locked;          /* wall; the mutex held by the frame */
    double t_commit, t_watch, t_build; /* stroke, pins and commit; visual solve; model build */
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

/* The haptic periods over 1.5 ms, each attributed to the largest of its wake-up delay, mutex
   wait and own work; and the cutting frames' parts (median and max). */
static void haptic_report(const shared *sh, const frame_info *fc, int frames) {
    long k, np = (sh->steps < sh->cap ? sh->steps : sh->cap), nl = 0, by[3] = {0, 0, 0};
    double sum[3] = {0, 0, 0}, mx[3] = {0, 0, 0}, *tb = (double *)bench_alloc(sizeof(double) * (size_t)frames * 4);
    static const char *part[3] = {"wake-up delay (OS)", "mutex wait", "own work"};
    static const char *fpart[4] = {"stroke + commit", "visual solve", "model build", "mutex held"};
    int f, i;
    for (k = 1; k < np; k++) {
        double c[3];
        c[0] = sh->late[k], c[1] = sh->wait[k], c[2] = sh->work[k];
        for (i = 0; i < 3; i++)
            if (c[i] > mx[i]) mx[i] = c[i];
        if (sh->period[k] <= 1.5e-3) continue;
        nl++;
        i = c[0] >= c[1] && c[0] >= c[2] ? 0 : c[1] >= c[2] ? 1 : 2;
        by[i]++;
        for (i = 0; i < 3; i++) sum[i] += c[i];
    }
    printf("  haptic periods over 1.5 ms: %ld of %ld; made long by", nl, np - 1);
    for (i = 0; i < 3; i++)
        printf("%s %s %ld (sum %.1f ms, worst step %.3f ms)", i ? "," : "", part[i], by[i], 1e3 * sum[i], 1e3 * mx[i]);
    printf("\n  haptic step parts, median / p99:");
    for (i = 0; i < 3; i++) {
        const double *src = i == 0 ? sh->late : i == 1 ? sh->wait : sh->work;
        double *c = (double *)bench_alloc(sizeof(double) * (size_t)np);
        memcpy(c, src + 1, sizeof(double) * (size_t)(np - 1));
        printf("%s %s %.4f / %.4f ms", i ? "," : "", part[i], 1e3 * bench_median(c, (int)np - 1),
               1e3 * bench_quantile(c, (int)np - 1, 0.99));
        free(c);
    }
    printf("\n  cutting frames, median (max):");
    for (f = 0; f < frames; f++) {
        tb[f] = fc[f].t_commit;
        tb[frames + f] = fc[f].t_watch;
        tb[2 * frames + f] = fc[f].t_build;
        tb[3 * frames + f] = fc[f].t_locked;
    }
    for (i = 0; i < 4; i++)
        printf("%s %s %.3f ms (%.3f)", i ? "," : "", fpart[i], 1e3 * bench_median(tb + i * frames, frames),
               1e3 * bench_quantile(tb + i * frames, frames, 1.0));
    printf("\n");
    free(tb);
}

static int frame(shared *sh, amps_ctx *ctx, amps_scene *S, const bench_model *B, double h, int f, int cut,
                 const amps_int *grasp, frame_info *fi) {
    double t0 = amps_now(), t1, tl, u[3], pts[6], blade[3] = {0, 0, 0};
    amps_scene_stroke_result r;
    amps_update_stats st;
    amps_haptic *back = sh->front == &sh->model[0] ? &sh->model[1] : &sh->model[0];
    amps_status s = AMPS_OK;
    int k;
    memset(&r, 0, sizeof(r));
    blade[B->up] = 1;
    pthread_mutex_lock(&sh->lock);
    sh->gu[B->up] = 0.002 * (B->hi[B->up] - B->lo[B->up]) * (1 + 0.3 * sin(0.1 * f)); /* where the hand goes */
    memcpy(u, sh->device, sizeof(u));
    pthread_mutex_unlock(&sh->lock);
    tl = amps_now() - t0;
    s = amps_scene_begin_batch(ctx, S);
    if (cut) {
        spiral(B, h, f, pts);
        spiral(B, h, f + 1, pts + 3);
        if (s == AMPS_OK) s = amps_scene_stroke(ctx, S, 2, pts, blade, 0.6 * h, &r);
    }
    for (k = 0; k < NGRASP && s == AMPS_OK; k++) s = amps_scene_pin(ctx, S, grasp[k], u);
    if (s == AMPS_OK) s = amps_scene_commit(ctx, S);
    if (s == AMPS_ERR_SINGULAR_UPDATE) { /* a piece the mechanism test missed: the batch undone */
        fi->undone = 1;
        r.ncut = 0;
        s = AMPS_OK;
    }
    t1 = amps_now();
    fi->t_commit = t1 - t0 - tl;
    if (s == AMPS_OK) s = amps_scene_solve_watched(ctx, S);
    fi->t_watch = amps_now() - t1;
    t1 = amps_now();
    if (s >= 0) s = amps_scene_haptic_build(ctx, S, back);
    fi->t_build = amps_now() - t1;
    if (s < 0) return 1;
    t1 = amps_now();
    pthread_mutex_lock(&sh->lock);
    sh->front = back; /* published */
    pthread_mutex_unlock(&sh->lock);
    amps_update_get_stats(amps_scene_engine(S), &st);
    fi->t_frame = amps_now() - t0;
    fi->t_locked = tl + amps_now() - t1;
    fi->ncut = r.ncut;
    fi->nsys = st.nsys;
    fi->nrefactor = st.nrefactor;
    return 0;
}

int main(int argc, char **argv) {
    amps_ctx ctx;
    bench_model B;
    shared sh;
    pthread_t th;
    const char *spec;
    char name[256];
    int frames, idle = 20, f, k, v, ns, undone = 0, failed = 0, ncf = 0, nnf = 0;
    double h, *tf_idle, *tf_cut, *tf_none, *tb_cut, vol = 1, p50, p99, pmax, fi_med, fc_med, fn_med, tb_med;
    double zero[3] = {0, 0, 0};
    double rm[3 * NGRASP], rs[3 * NGRASP], g[3 * NGRASP], dr = 0, nr = 0;
    amps_int *surf, watch[256], ncut = 0, nw, grasp[NGRASP];
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
    amps_haptic_init(&sh.model[0]);
    amps_haptic_init(&sh.model[1]);
    sh.front = &sh.model[0];
    /* the grasper: the NGRASP highest free, unloaded nodes */
    for (k = 0; k < NGRASP; k++) {
        int best = -1, j;
        for (v = 0; v < B.nn; v++) {
            int taken = 0;
            for (j = 0; j < k; j++) taken |= grasp[j] == v;
            if (B.fixed[v] || taken || B.force[3 * v] != 0.0) continue;
            if (best < 0 || B.m->xyz[3 * v + B.up] > B.m->xyz[3 * best + B.up]) best = v;
        }
        grasp[k] = best;
        if (amps_scene_pin(&ctx, B.S, best, zero) != AMPS_OK) bench_die("pin", ctx.msg);
    }
    /* the visual set: 256 surface nodes, evenly spread over the surface list */
    surf = (amps_int *)bench_alloc(sizeof(amps_int) * (size_t)B.nn);
    ns = bench_surface_nodes(B.m, surf);
    nw = ns < 256 ? ns : 256;
    for (k = 0; k < nw; k++) watch[k] = surf[(size_t)k * (size_t)ns / (size_t)nw];
    if (amps_scene_watch(&ctx, B.S, nw, watch) != AMPS_OK || amps_scene_solve(&ctx, B.S) < 0 ||
        amps_scene_solve_watched(&ctx, B.S) < 0 || amps_scene_haptic_build(&ctx, B.S, sh.front) != AMPS_OK)
        bench_die("first solve", ctx.msg);
    sh.cap = 40L * (frames + idle) * HAPTIC_PER_FRAME + 1000;
    sh.period = (double *)bench_alloc(sizeof(double) * (size_t)sh.cap);
    sh.late = (double *)bench_alloc(sizeof(double) * (size_t)sh.cap);
    sh.wait = (double *)bench_alloc(sizeof(double) * (size_t)sh.cap);
    sh.work = (double *)bench_alloc(sizeof(double) * (size_t)sh.cap);
    fi = (frame_info *)bench_alloc(sizeof(frame_info) * (size_t)(frames + idle));
    memset(fi, 0, sizeof(frame_info) * (size_t)(frames + idle));
    tf_idle = (double *)bench_alloc(sizeof(double) * (size_t)idle);
    tf_cut = (double *)bench_alloc(sizeof(double) * (size_t)frames);
    tf_none = (double *)bench_alloc(sizeof(double) * (size_t)frames);
    tb_cut = (double *)bench_alloc(sizeof(double) * (size_t)frames);
    pthread_mutex_init(&sh.lock, NULL);
    pthread_cond_init(&sh.step_done, NULL);
    if (pthread_create(&th, NULL, haptic, &sh)) bench_die("thread", "pthread_create failed");
    if (getenv("FRAMELOOP_FIFO")) { /* the haptic thread alone at SCHED_FIFO priority 10, if permitted */
        struct sched_param sp;
        memset(&sp, 0, sizeof(sp));
        sp.sched_priority = 10;
        printf("  haptic thread SCHED_FIFO 10: %s\n", pthread_setschedparam(th, SCHED_FIFO, &sp) ? "refused" : "set");
    }
    for (f = 0; f < idle + frames; f++) {
        wait_haptic(&sh);
        if (frame(&sh, &ctx, B.S, &B, h, f - idle, f >= idle, grasp, fi + f)) {
            fprintf(stderr, "frame %d: %s\n", f, ctx.msg);
            failed = 1;
            break;
        }
        ncut += fi[f].ncut;
        undone += fi[f].undone;
    }
    pthread_mutex_lock(&sh.lock);
    sh.stop = 1;
    pthread_mutex_unlock(&sh.lock);
    pthread_join(th, NULL);
    if (failed) return 1;
    /* the last model at the last device position against the scene's haptic step there */
    for (k = 0; k < sh.front->n; k++) memcpy(g + 3 * k, sh.device, sizeof(sh.device));
    amps_haptic_eval(sh.front, g, rm);
    for (k = 0; k < NGRASP; k++)
        if (amps_scene_pin(&ctx, B.S, grasp[k], sh.device) != AMPS_OK) bench_die("pin", ctx.msg);
    if (amps_scene_solve_reactions(&ctx, B.S) != AMPS_OK) bench_die("reactions", ctx.msg);
    for (k = 0; k < sh.front->n; k++) amps_scene_reaction(&ctx, B.S, sh.front->node[k], rs + 3 * k);
    for (k = 0; k < 3 * sh.front->n; k++) {
        dr = fmax(dr, fabs(rm[k] - rs[k]));
        nr = fmax(nr, fabs(rs[k]));
    }
    csv = bench_csv(argv[3], "mesh,frame,cutting,ncut,t_frame,t_locked,t_commit,nsys,nrefactor,t_watch,t_build");
    for (f = 0; f < idle + frames; f++) {
        if (csv)
            fprintf(csv, "%s,%d,%d,%ld,%.6e,%.6e,%.6e,%ld,%ld,%.6e,%.6e\n", name, f - idle, f >= idle, (long)fi[f].ncut,
                    fi[f].t_frame, fi[f].t_locked, fi[f].t_commit, (long)fi[f].nsys, (long)fi[f].nrefactor,
                    fi[f].t_watch, fi[f].t_build);
        if (f < idle) tf_idle[f] = fi[f].t_frame;
        else if (fi[f].ncut > 0) {
            tf_cut[ncf] = fi[f].t_frame;
            tb_cut[ncf++] = fi[f].t_build;
        } else tf_none[nnf++] = fi[f].t_frame;
    }
    if (csv) fclose(csv);
    {
        long np = (sh.steps < sh.cap ? sh.steps : sh.cap) - 1;
        double *pp = (double *)bench_alloc(sizeof(double) * (size_t)(np > 0 ? np : 1));
        memcpy(pp, sh.period + 1, sizeof(double) * (size_t)np); /* a copy: haptic_report reads them per step */
        p50 = bench_median(pp, (int)np);
        p99 = bench_quantile(pp, (int)np, 0.99);
        pmax = bench_quantile(pp, (int)np, 1.0);
        free(pp);
    }
    fi_med = bench_median(tf_idle, idle);
    fc_med = ncf > 0 ? bench_median(tf_cut, ncf) : 0;
    tb_med = ncf > 0 ? bench_median(tb_cut, ncf) : 0;
    fn_med = nnf > 0 ? bench_median(tf_none, nnf) : 0;
    printf("%s: %d nodes, %d frames (%d idle), %ld nodes cut (%d strokes undone), |S u C| at the end %ld, "
           "re-factorizations %ld\n",
           name, B.nn, frames, idle, (long)ncut, undone, (long)fi[idle + frames - 1].nsys,
           (long)fi[idle + frames - 1].nrefactor);
    printf("  haptic: %ld steps, period median %.3f ms, p99 %.3f ms, max %.3f ms (the thread never calls the scene)\n",
           sh.steps, 1e3 * p50, 1e3 * p99, 1e3 * pmax);
    printf("  frame: idle median %.2f ms, cutting (%d frames with 1+ nodes cut) median %.2f ms (%.2fx), of which the "
           "model build %.3f ms; strokes that cut nothing (%d frames) median %.2f ms (%.2fx)\n",
           1e3 * fi_med, ncf, 1e3 * fc_med, fc_med / fi_med, 1e3 * tb_med, nnf, 1e3 * fn_med, fn_med / fi_med);
    printf("  last model vs the scene's haptic step: %.1e relative\n", nr > 0 ? dr / nr : dr);
    haptic_report(&sh, fi + idle, frames);
    csv = bench_csv(argv[4], "mesh,nodes,frames,idle,ncut,nsys_end,nrefactor,haptic_steps,haptic_p50,haptic_p99,"
                             "haptic_max,frame_idle,frame_cut,frame_ratio,frame_build,frame_nocut");
    if (csv) {
        fprintf(csv, "%s,%d,%d,%d,%ld,%ld,%ld,%ld,%.6e,%.6e,%.6e,%.6e,%.6e,%.4f,%.6e,%.6e\n", name, B.nn, frames, idle,
                (long)ncut, (long)fi[idle + frames - 1].nsys, (long)fi[idle + frames - 1].nrefactor, sh.steps, p50, p99,
                pmax, fi_med, fc_med, fc_med / fi_med, tb_med, fn_med);
        fclose(csv);
    }
    amps_haptic_free(&ctx, &sh.model[0]);
    amps_haptic_free(&ctx, &sh.model[1]);
    pthread_mutex_destroy(&sh.lock);
    pthread_cond_destroy(&sh.step_done);
    return !(dr <= 1e-8 * nr);
}
