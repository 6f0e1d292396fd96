/* Counting allocator for the tests: tracks live blocks and can fail the k-th allocation.
   Include before amps.h; it defines AMPS_MALLOC/AMPS_REALLOC/AMPS_FREE. Pass &t_al as
   ctx.alloc_user to count (a NULL user pointer allocates without counting). */
#ifndef T_ALLOC_H
#define T_ALLOC_H
#include <stdlib.h>

typedef struct t_alloc_state {
    long live;    /* blocks allocated and not yet freed */
    long calls;   /* successful malloc/realloc calls so far */
    long fail_at; /* the call with this index (0-based, counted from now on) fails; -1 = never */
} t_alloc_state;
static t_alloc_state t_al = {0, 0, -1};

static int t_alloc_fails(t_alloc_state *s) {
    if (s->fail_at == 0) {
        s->fail_at = -1;
        return 1;
    }
    if (s->fail_at > 0) s->fail_at--;
    return 0;
}
static void *t_malloc(size_t sz, void *u) {
    t_alloc_state *s = (t_alloc_state *)u;
    void *p;
    if (s && t_alloc_fails(s)) return NULL;
    p = malloc(sz);
    if (s && p) {
        s->live++;
        s->calls++;
    }
    return p;
}
static void *t_realloc(void *p, size_t sz, void *u) {
    t_alloc_state *s = (t_alloc_state *)u;
    void *q;
    if (s && t_alloc_fails(s)) return NULL;
    q = realloc(p, sz);
    if (s && q) {
        if (!p) s->live++;
        s->calls++;
    }
    return q;
}
static void t_free(void *p, void *u) {
    t_alloc_state *s = (t_alloc_state *)u;
    if (s && p) s->live--;
    free(p);
}
#define AMPS_MALLOC(sz, u) t_malloc((sz), (u))
#define AMPS_REALLOC(p, sz, u) t_realloc((p), (sz), (u))
#define AMPS_FREE(p, u) t_free((p), (u))
#endif
