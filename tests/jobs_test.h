/* A host task system for the tests (include after amps.h): the enqueue_task/finish_task
   callbacks of amps_ctx in four modes:
     T_JOBS_INLINE  enqueue runs every sub-range at once, on the calling thread;
     T_JOBS_POOL    T_JOBS_NWORK pthread workers take sub-ranges from a queue; finish runs the
                    ones still queued on the calling thread (worker T_JOBS_NWORK), then waits;
     T_JOBS_DELAY   T_JOBS_POOL, each sub-range delayed by a random 0..1 ms first;
     T_JOBS_REFUSE  enqueue returns NULL (not queued).
   t_jobs_ctx(ctx, mode) sets a context to use it (worker_count T_JOBS_NWORK + 1). The pool is
   started on first use and stopped at exit. */
#ifndef JOBS_TEST_H
#define JOBS_TEST_H
#include <pthread.h>
#include <stdlib.h>
#include <time.h>

#define T_JOBS_NWORK 4
enum { T_JOBS_INLINE = 1, T_JOBS_POOL = 2, T_JOBS_DELAY = 3, T_JOBS_REFUSE = 4 };

typedef struct t_jgroup {
    amps_task_fn *fn;
    void *ctx;
    amps_int n, step, next, done; /* items, sub-range length, next unclaimed item, items run */
    int delay;
    struct t_jgroup *link; /* queue */
} t_jgroup;

static pthread_mutex_t t_jobs_mu = PTHREAD_MUTEX_INITIALIZER;
static pthread_cond_t t_jobs_work = PTHREAD_COND_INITIALIZER, t_jobs_fin = PTHREAD_COND_INITIALIZER;
static struct {
    pthread_t th[T_JOBS_NWORK];
    int started, stop;
    unsigned long long seed;
    t_jgroup *head, *tail;
} t_jobs;
static const int t_jobs_modes[T_JOBS_REFUSE + 1] = {0, 1, 2, 3, 4}; /* user pointers */

/* Claims the next sub-range of g (under mu); removes g from the queue when none is left. */
static int t_jobs_claim(t_jgroup *g, amps_int *b, amps_int *e) {
    if (g->next >= g->n) return 0;
    *b = g->next;
    *e = g->n - g->next < g->step ? g->n : g->next + g->step;
    g->next = *e;
    if (g->next >= g->n) { /* unlink */
        t_jgroup **pp = &t_jobs.head, *prev = NULL;
        while (*pp && *pp != g) prev = *pp, pp = &(*pp)->link;
        if (*pp) {
            *pp = g->link;
            if (t_jobs.tail == g) t_jobs.tail = prev;
        }
    }
    return 1;
}

/* Runs [b, e) of g on worker w outside the lock, then records it. */
static void t_jobs_run(t_jgroup *g, amps_int b, amps_int e, int w) {
    if (g->delay) {
        struct timespec ts;
        unsigned long long r;
        pthread_mutex_lock(&t_jobs_mu);
        t_jobs.seed = t_jobs.seed * 6364136223846793005ULL + 1442695040888963407ULL;
        r = t_jobs.seed >> 33;
        pthread_mutex_unlock(&t_jobs_mu);
        ts.tv_sec = 0;
        ts.tv_nsec = (long)(r % 1000) * 1000L; /* 0..1 ms */
        if (r % 3 == 0) nanosleep(&ts, NULL);  /* a third of the sub-ranges */
    }
    g->fn(b, e, w, g->ctx);
    pthread_mutex_lock(&t_jobs_mu);
    g->done += e - b;
    if (g->done == g->n) pthread_cond_broadcast(&t_jobs_fin);
    pthread_mutex_unlock(&t_jobs_mu);
}

static void *t_jobs_worker(void *arg) {
    int w = (int)(size_t)arg;
    pthread_mutex_lock(&t_jobs_mu);
    for (;;) {
        amps_int b, e;
        t_jgroup *g;
        while (!t_jobs.stop && !t_jobs.head) pthread_cond_wait(&t_jobs_work, &t_jobs_mu);
        if (t_jobs.stop) break;
        g = t_jobs.head;
        if (!t_jobs_claim(g, &b, &e)) continue;
        pthread_mutex_unlock(&t_jobs_mu);
        t_jobs_run(g, b, e, w);
        pthread_mutex_lock(&t_jobs_mu);
    }
    pthread_mutex_unlock(&t_jobs_mu);
    return NULL;
}

static void t_jobs_stop(void) {
    int i;
    pthread_mutex_lock(&t_jobs_mu);
    t_jobs.stop = 1;
    pthread_cond_broadcast(&t_jobs_work);
    pthread_mutex_unlock(&t_jobs_mu);
    for (i = 0; i < T_JOBS_NWORK; i++) pthread_join(t_jobs.th[i], NULL);
}

static void *t_jobs_enqueue(amps_task_fn *task, amps_int n, amps_int min_range, void *task_ctx, void *user) {
    int mode = *(const int *)user;
    t_jgroup *g;
    if (mode == T_JOBS_REFUSE) return NULL;
    if (mode == T_JOBS_INLINE) {
        amps_int b;
        for (b = 0; b < n; b += min_range) task(b, n - b < min_range ? n : b + min_range, 0, task_ctx);
        return &t_jobs; /* any non-NULL handle */
    }
    g = (t_jgroup *)calloc(1, sizeof(t_jgroup));
    if (!g) return NULL; /* not queued */
    g->fn = task;
    g->ctx = task_ctx;
    g->n = n;
    g->step = min_range > 0 ? min_range : 1;
    g->delay = mode == T_JOBS_DELAY;
    pthread_mutex_lock(&t_jobs_mu);
    if (!t_jobs.started) {
        int i;
        t_jobs.started = 1;
        t_jobs.seed = 12345;
        for (i = 0; i < T_JOBS_NWORK; i++) pthread_create(&t_jobs.th[i], NULL, t_jobs_worker, (void *)(size_t)i);
        atexit(t_jobs_stop);
    }
    if (t_jobs.tail) t_jobs.tail->link = g;
    else t_jobs.head = g;
    t_jobs.tail = g;
    pthread_cond_broadcast(&t_jobs_work);
    pthread_mutex_unlock(&t_jobs_mu);
    return g;
}

static void t_jobs_finish(void *handle, void *user) {
    t_jgroup *g = (t_jgroup *)handle;
    amps_int b, e;
    (void)user;
    if (handle == (void *)&t_jobs) return; /* inline */
    pthread_mutex_lock(&t_jobs_mu);
    while (t_jobs_claim(g, &b, &e)) { /* help: run what is still queued */
        pthread_mutex_unlock(&t_jobs_mu);
        t_jobs_run(g, b, e, T_JOBS_NWORK);
        pthread_mutex_lock(&t_jobs_mu);
    }
    while (g->done < g->n) pthread_cond_wait(&t_jobs_fin, &t_jobs_mu);
    pthread_mutex_unlock(&t_jobs_mu);
    free(g);
}

/* ctx runs its kernels on the test job system in mode (T_JOBS_*). */
static void t_jobs_ctx(amps_ctx *ctx, int mode) {
    ctx->enqueue_task = t_jobs_enqueue;
    ctx->finish_task = t_jobs_finish;
    ctx->task_user = (void *)&t_jobs_modes[mode];
    ctx->worker_count = T_JOBS_NWORK + 1;
}
#endif
