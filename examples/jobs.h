/* jobs.h - a small host job system of the kind engines use, wired into amps.h through the task
   callbacks of amps_ctx (enqueue_task, finish_task; see THREAD SAFETY in amps.h).

   A fixed set of worker threads (pthreads) takes range tasks from one queue. A range task
   [0, n) is split into chunks of at least min_range, more chunks than threads, and whoever is
   free claims the next one (under the pool's mutex), so a worker the OS has descheduled delays
   only the chunk it holds. The thread that calls jobs_finish helps: it runs unclaimed chunks of
   the task it waits for (as worker 0), then sleeps until the chunks others hold are done.

     jobs_pool *P = jobs_create(2);    2 worker threads; worker ids 1, 2 (0: the helping caller)
     jobs_attach(P, &ctx);             ctx->enqueue_task/finish_task/task_user/worker_count
     ... amps calls with ctx ...
     jobs_destroy(P);                  after the last task finished

   Contract: one thread at a time submits to and finishes on a pool (worker id 0 is that
   thread's); a task's chunks run exactly once each, in any order, on any of the pool's threads;
   jobs_finish returns when all of them ran. When every task slot is in use, jobs_enqueue
   returns NULL (not queued: the caller runs the range itself). C99 + POSIX threads; no
   allocation after jobs_create.
   In exactly one file: #define JOBS_IMPLEMENTATION before #include "jobs.h" (after amps.h). */
#ifndef JOBS_H
#define JOBS_H
#include "amps.h"

#define JOBS_MAX_WORKERS 16
#define JOBS_MAX_TASKS 64 /* task slots: queued or not yet finished */

typedef struct jobs_pool jobs_pool;

/* A pool of nworkers threads (1..JOBS_MAX_WORKERS), or NULL if the threads cannot start. */
jobs_pool *jobs_create(int nworkers);
/* Stops and joins the workers and frees the pool; no task may be pending. */
void jobs_destroy(jobs_pool *P);
/* Sets ctx's task callbacks to the pool (worker_count: the workers + the helping caller). */
void jobs_attach(jobs_pool *P, amps_ctx *ctx);
/* amps_enqueue_task_fn: queues task over [0, n); user is the pool. NULL if no slot is free. */
void *jobs_enqueue(amps_task_fn *task, amps_int n, amps_int min_range, void *task_ctx, void *user);
/* amps_finish_task_fn: runs unclaimed chunks of handle, then waits for the rest; frees the slot. */
void jobs_finish(void *handle, void *user);
/* Chunks run by the pool's threads (not the caller) since jobs_create. */
long jobs_chunks_by_workers(jobs_pool *P);

#ifdef JOBS_IMPLEMENTATION
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

typedef struct jobs__arg {
    struct jobs_pool *P;
    int id;
} jobs__arg;

typedef struct jobs__task {
    amps_task_fn *fn;
    void *ctx;
    amps_int n, chunk, next; /* next: first unclaimed index */
    amps_int left;           /* chunks not yet finished */
    int used;
    struct jobs__task *qnext; /* queue link (tasks with unclaimed chunks) */
} jobs__task;

struct jobs_pool {
    pthread_mutex_t lock;
    pthread_cond_t work; /* workers: a chunk to claim, or stop */
    pthread_cond_t done; /* the finishing caller: a task's last chunk finished */
    pthread_t th[JOBS_MAX_WORKERS];
    jobs__arg arg[JOBS_MAX_WORKERS];
    int nworkers, nstarted, stop;
    jobs__task slot[JOBS_MAX_TASKS];
    jobs__task *head, *tail;
    long by_workers;
};

/* Claims the next chunk of t (lock held): its range in [*b, *e); dequeues t when none is left. */
static void jobs__claim(jobs_pool *P, jobs__task *t, amps_int *b, amps_int *e) {
    *b = t->next;
    *e = t->n - t->next > t->chunk ? t->next + t->chunk : t->n;
    t->next = *e;
    if (t->next >= t->n) { /* no chunk left: out of the queue */
        jobs__task **pp = &P->head, *prev = NULL;
        while (*pp && *pp != t) prev = *pp, pp = &(*pp)->qnext;
        if (*pp) *pp = t->qnext;
        if (P->tail == t) P->tail = prev;
        t->qnext = NULL;
    }
}

/* Runs [b, e) of t unlocked, then counts it done (lock held again on return). */
static void jobs__run(jobs_pool *P, jobs__task *t, amps_int b, amps_int e, int id) {
    pthread_mutex_unlock(&P->lock);
    t->fn(b, e, id, t->ctx);
    pthread_mutex_lock(&P->lock);
    if (id > 0) P->by_workers++;
    if (--t->left == 0) pthread_cond_broadcast(&P->done);
}

static void *jobs__worker(void *arg) {
    jobs__arg *a = (jobs__arg *)arg;
    jobs_pool *P = a->P;
    pthread_mutex_lock(&P->lock);
    for (;;) {
        amps_int b, e;
        jobs__task *t;
        while (!P->head && !P->stop) pthread_cond_wait(&P->work, &P->lock);
        if (P->stop) break;
        t = P->head;
        jobs__claim(P, t, &b, &e);
        jobs__run(P, t, b, e, a->id);
    }
    pthread_mutex_unlock(&P->lock);
    return NULL;
}

jobs_pool *jobs_create(int nworkers) {
    jobs_pool *P;
    int k;
    if (nworkers < 1 || nworkers > JOBS_MAX_WORKERS) return NULL;
    P = (jobs_pool *)calloc(1, sizeof(*P));
    if (!P) return NULL;
    pthread_mutex_init(&P->lock, NULL);
    pthread_cond_init(&P->work, NULL);
    pthread_cond_init(&P->done, NULL);
    P->nworkers = nworkers;
    for (k = 0; k < nworkers; k++) {
        P->arg[k].P = P;
        P->arg[k].id = k + 1;
        if (pthread_create(&P->th[k], NULL, jobs__worker, &P->arg[k])) break;
        P->nstarted++;
    }
    if (P->nstarted < nworkers) {
        jobs_destroy(P);
        return NULL;
    }
    return P;
}

void jobs_destroy(jobs_pool *P) {
    int k;
    if (!P) return;
    pthread_mutex_lock(&P->lock);
    P->stop = 1;
    pthread_cond_broadcast(&P->work);
    pthread_mutex_unlock(&P->lock);
    for (k = 0; k < P->nstarted; k++) pthread_join(P->th[k], NULL);
    pthread_mutex_destroy(&P->lock);
    pthread_cond_destroy(&P->work);
    pthread_cond_destroy(&P->done);
    free(P);
}

void jobs_attach(jobs_pool *P, amps_ctx *ctx) {
    ctx->enqueue_task = jobs_enqueue;
    ctx->finish_task = jobs_finish;
    ctx->task_user = P;
    ctx->worker_count = P->nworkers + 1;
}

void *jobs_enqueue(amps_task_fn *task, amps_int n, amps_int min_range, void *task_ctx, void *user) {
    jobs_pool *P = (jobs_pool *)user;
    jobs__task *t = NULL;
    amps_int parts = 4 * (amps_int)(P->nworkers + 1), chunk;
    int k;
    if (n <= 0) return NULL;
    if (min_range < 1) min_range = 1;
    chunk = (n + parts - 1) / parts;
    if (chunk < min_range) chunk = min_range;
    if (chunk >= n) return NULL; /* one chunk: cheaper inline */
    pthread_mutex_lock(&P->lock);
    for (k = 0; k < JOBS_MAX_TASKS && !t; k++)
        if (!P->slot[k].used) t = &P->slot[k];
    if (t) {
        t->used = 1;
        t->fn = task;
        t->ctx = task_ctx;
        t->n = n;
        t->chunk = chunk;
        t->next = 0;
        t->left = (n + chunk - 1) / chunk;
        t->qnext = NULL;
        if (P->tail) P->tail->qnext = t;
        else P->head = t;
        P->tail = t;
        pthread_cond_broadcast(&P->work);
    }
    pthread_mutex_unlock(&P->lock);
    return t;
}

void jobs_finish(void *handle, void *user) {
    jobs_pool *P = (jobs_pool *)user;
    jobs__task *t = (jobs__task *)handle;
    pthread_mutex_lock(&P->lock);
    while (t->next < t->n) { /* help: the unclaimed chunks of this task */
        amps_int b, e;
        jobs__claim(P, t, &b, &e);
        jobs__run(P, t, b, e, 0);
    }
    while (t->left > 0) pthread_cond_wait(&P->done, &P->lock);
    t->used = 0;
    pthread_mutex_unlock(&P->lock);
}

long jobs_chunks_by_workers(jobs_pool *P) {
    long c;
    pthread_mutex_lock(&P->lock);
    c = P->by_workers;
    pthread_mutex_unlock(&P->lock);
    return c;
}
#endif /* JOBS_IMPLEMENTATION */
#endif /* JOBS_H */
