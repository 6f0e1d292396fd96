/* examples/jobs.h, the example host job system: every index of a range task runs exactly once,
   on a worker below ctx.worker_count, also when chunks are delayed and many tasks are in flight;
   a full slot table refuses to queue (NULL). */
#ifndef _POSIX_C_SOURCE
#define _POSIX_C_SOURCE 200809L
#endif
#define AMPS_IMPLEMENTATION
#include "amps.h"
#define JOBS_IMPLEMENTATION
#include "../examples/jobs.h"
#include "amps_test.h"
#include <string.h>
#include <time.h>

typedef struct tcount {
    int *hits; /* per index */
    int badw;  /* worker ids out of range */
    int nw;    /* worker_count */
    int delay; /* 1: some chunks sleep up to 0.2 ms */
} tcount;

static void t_task(amps_int b, amps_int e, int worker, void *ctx) {
    tcount *c = (tcount *)ctx;
    amps_int i;
    if (worker < 0 || worker >= c->nw) c->badw = 1; /* a benign race: only ever set to 1 */
    if (c->delay && (b * 7919) % 5 == 0) {
        struct timespec ts = {0, 1000L * (long)((b * 31) % 200)};
        nanosleep(&ts, NULL);
    }
    for (i = b; i < e; i++) c->hits[i]++; /* the chunks are disjoint */
}

int main(void) {
    jobs_pool *P = jobs_create(3);
    amps_ctx ctx;
    int k, rep;
    CHECK(P != NULL, "jobs_create failed");
    if (!P) return amps_t_end("test_jobs");
    amps_ctx_init(&ctx);
    jobs_attach(P, &ctx);
    CHECK(ctx.worker_count == 4 && ctx.enqueue_task == jobs_enqueue && ctx.finish_task == jobs_finish,
          "jobs_attach: worker_count %d", ctx.worker_count);
    for (rep = 0; rep < 300; rep++) { /* one task at a time, with and without delays */
        amps_int n = 1 + (amps_int)t_int(5000), minr = 1 + (amps_int)t_int(64), i;
        tcount c;
        void *h;
        int bad = 0;
        c.hits = (int *)calloc((size_t)n, sizeof(int));
        c.badw = 0;
        c.nw = ctx.worker_count;
        c.delay = rep % 3 == 0;
        h = ctx.enqueue_task(t_task, n, minr, &c, ctx.task_user);
        if (h) ctx.finish_task(h, ctx.task_user);
        else t_task(0, n, 0, &c);
        for (i = 0; i < n; i++) bad += c.hits[i] != 1;
        CHECK(bad == 0 && !c.badw, "rep %d (n %d, min %d): %d indices not run once, bad worker %d", rep, (int)n,
              (int)minr, bad, c.badw);
        free(c.hits);
    }
    { /* many in flight, finished in reverse order; the slot table full: NULL */
        tcount c[JOBS_MAX_TASKS + 1];
        void *h[JOBS_MAX_TASKS + 1];
        int bad = 0, nnull = 0;
        amps_int i;
        for (k = 0; k <= JOBS_MAX_TASKS; k++) {
            c[k].hits = (int *)calloc(1000, sizeof(int));
            c[k].badw = 0;
            c[k].nw = ctx.worker_count;
            c[k].delay = 1;
            h[k] = jobs_enqueue(t_task, 1000, 8, &c[k], P);
            if (!h[k]) {
                nnull++;
                t_task(0, 1000, 0, &c[k]);
            }
        }
        CHECK(nnull == 1 && h[JOBS_MAX_TASKS] == NULL, "full slot table: %d not queued", nnull);
        for (k = JOBS_MAX_TASKS; k >= 0; k--)
            if (h[k]) jobs_finish(h[k], P);
        for (k = 0; k <= JOBS_MAX_TASKS; k++) {
            for (i = 0; i < 1000; i++) bad += c[k].hits[i] != 1;
            bad += c[k].badw;
            free(c[k].hits);
        }
        CHECK(bad == 0, "in flight: %d indices not run once", bad);
        CHECK(jobs_chunks_by_workers(P) > 0, "the workers ran no chunk");
    }
    CHECK(jobs_enqueue(t_task, 5, 8, NULL, P) == NULL, "a single chunk was queued");
    jobs_destroy(P);
    return amps_t_end("test_jobs");
}
