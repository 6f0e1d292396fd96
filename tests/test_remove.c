/* Densities, regions, lumped mass and element removal of the mesh layer: singularity avoidance
   on hand-built vertex and edge cases (ties included), random removal sequences on a brick
   checked with the from-scratch singularity queries, node separation, exact undo, assembly
   after removal against a mesh built without the removed tets, and bad input. */
#include <string.h>
#include "t_alloc.h"
#define AMPS_IMPLEMENTATION
#include "amps.h"
#include "amps_test.h"

/* ---- snapshots of the mesh arrays ---- */

typedef struct t_snap {
    amps_int nnode, ntet, nremoved;
    amps_int *tet, *inc, *ptr, *len, *org, *reg;
    unsigned char *rem;
    double *rho, *E;
} t_snap;

static void *t_dup(const void *p, size_t n) {
    void *q = malloc(n ? n : 1);
    memcpy(q, p, n);
    return q;
}
static t_snap t_take(const amps_mesh *m) {
    t_snap s;
    size_t nt = (size_t)m->ntet, nn = (size_t)m->nnode;
    s.nnode = m->nnode;
    s.ntet = m->ntet;
    s.nremoved = m->nremoved;
    s.tet = (amps_int *)t_dup(m->tet, sizeof(amps_int) * 4 * nt);
    s.inc = (amps_int *)t_dup(m->inc, sizeof(amps_int) * 4 * nt);
    s.ptr = (amps_int *)t_dup(m->inc_ptr, sizeof(amps_int) * nn);
    s.len = (amps_int *)t_dup(m->inc_len, sizeof(amps_int) * nn);
    s.org = (amps_int *)t_dup(m->origin, sizeof(amps_int) * nn);
    s.reg = (amps_int *)t_dup(m->region, sizeof(amps_int) * nt);
    s.rem = (unsigned char *)t_dup(m->removed, nt);
    s.rho = (double *)t_dup(m->rho, sizeof(double) * nt);
    s.E = (double *)t_dup(m->E, sizeof(double) * nt);
    return s;
}
static int t_same(const t_snap *s, const amps_mesh *m) {
    size_t nt = (size_t)m->ntet, nn = (size_t)m->nnode;
    return s->nnode == m->nnode && s->ntet == m->ntet && s->nremoved == m->nremoved &&
           !memcmp(s->tet, m->tet, sizeof(amps_int) * 4 * nt) && !memcmp(s->inc, m->inc, sizeof(amps_int) * 4 * nt) &&
           !memcmp(s->ptr, m->inc_ptr, sizeof(amps_int) * nn) && !memcmp(s->len, m->inc_len, sizeof(amps_int) * nn) &&
           !memcmp(s->org, m->origin, sizeof(amps_int) * nn) && !memcmp(s->reg, m->region, sizeof(amps_int) * nt) &&
           !memcmp(s->rem, m->removed, nt) && !memcmp(s->rho, m->rho, sizeof(double) * nt) &&
           !memcmp(s->E, m->E, sizeof(double) * nt);
}
static void t_drop(t_snap *s) {
    free(s->tet);
    free(s->inc);
    free(s->ptr);
    free(s->len);
    free(s->org);
    free(s->reg);
    free(s->rem);
    free(s->rho);
    free(s->E);
}

static double t_volume(const amps_mesh *m, amps_int t) {
    double X[12], G[12];
    amps_mesh_tet_coords(m, t, X);
    return fabs(amps_tet_gradients(X, G));
}

static int t_has(const amps_mesh *m, amps_int t, amps_int v) {
    const amps_int *tv = m->tet + 4 * t;
    return tv[0] == v || tv[1] == v || tv[2] == v || tv[3] == v;
}

/* Mesh of the given tets over nn random points (each tet is nondegenerate with probability 1). */
static amps_mesh *t_hand(amps_ctx *ctx, amps_int nn, amps_int nt, const amps_int *tet) {
    double xyz[3 * 32];
    amps_int k;
    t_seed(7);
    for (k = 0; k < 3 * nn; k++) xyz[k] = t_unif();
    return amps_mesh_create(ctx, nn, xyz, nt, tet);
}

/* ---- density, regions, lumped mass ---- */

static void test_mass(void) {
    amps_ctx ctx;
    amps_mesh *m;
    double *mass, sum = 0, vol = 0, vol1 = 0;
    amps_int v, t, n1 = 0;
    t_snap s;
    amps_ctx_init(&ctx);
    m = amps_mesh_brick(&ctx, 3);
    CHECK(m && m->nremoved == 0, "brick");
    if (!m) return;
    for (t = 0; t < m->ntet; t++)
        CHECK(m->region[t] == 0 && m->rho[t] == 1.0 && m->removed[t] == 0, "defaults of tet %d", (int)t);
    mass = (double *)malloc(sizeof(double) * m->nnode);
    CHECK(amps_mesh_set_density(&ctx, m, 2.5) == AMPS_OK, "set density");
    amps_mesh_lumped_mass(m, mass);
    for (v = 0; v < m->nnode; v++) sum += mass[v];
    CHECK(fabs(sum - 2.5 * 2.0) < 1e-13, "lumped mass sums to rho * volume: %.17g", sum);
    /* two regions, different densities */
    for (t = 0; t < m->ntet; t++) {
        double X[12];
        amps_mesh_tet_coords(m, t, X);
        if (X[2] + X[5] + X[8] + X[11] < 4.0) {
            CHECK(amps_mesh_set_tet_region(&ctx, m, t, 1) == AMPS_OK, "set region");
            vol1 += t_volume(m, t);
            n1++;
        }
        vol += t_volume(m, t);
    }
    CHECK(n1 > 0 && n1 < m->ntet, "two regions");
    CHECK(amps_mesh_set_region_material(&ctx, m, 1, 7.0, 0.25, 4.0) == AMPS_OK, "region material");
    CHECK(amps_mesh_set_region_material(&ctx, m, 0, 3.0, 0.35, -1.0) == AMPS_OK, "region material keeping rho");
    for (t = 0; t < m->ntet; t++)
        CHECK(m->region[t] == 1 ? (m->E[t] == 7.0 && m->nu[t] == 0.25 && m->rho[t] == 4.0)
                                : (m->E[t] == 3.0 && m->nu[t] == 0.35 && m->rho[t] == 2.5),
              "material of tet %d", (int)t);
    amps_mesh_lumped_mass(m, mass);
    for (v = 0, sum = 0; v < m->nnode; v++) sum += mass[v];
    CHECK(fabs(sum - (4.0 * vol1 + 2.5 * (vol - vol1))) < 1e-13 && fabs(vol - 2.0) < 1e-13, "two-density mass %.17g",
          sum);
    /* bad input leaves the mesh unchanged */
    s = t_take(m);
    CHECK(amps_mesh_set_density(&ctx, m, -1.0) == AMPS_ERR_ARG, "negative density");
    CHECK(amps_mesh_set_density(&ctx, m, 0.0) == AMPS_ERR_ARG, "zero density");
    CHECK(amps_mesh_set_density(&ctx, m, NAN) == AMPS_ERR_VALUE, "NaN density");
    CHECK(amps_mesh_set_density(&ctx, m, INFINITY) == AMPS_ERR_VALUE, "Inf density");
    CHECK(amps_mesh_set_tet_density(&ctx, m, m->ntet, 1.0) == AMPS_ERR_INDEX, "tet out of range");
    CHECK(amps_mesh_set_tet_density(&ctx, m, 0, NAN) == AMPS_ERR_VALUE, "NaN tet density");
    CHECK(amps_mesh_set_region_material(&ctx, m, 5, 1.0, 0.3, 1.0) == AMPS_ERR_ARG &&
                  strstr(ctx.msg, "no tetrahedron has region 5"),
          "unknown region: %s", ctx.msg);
    CHECK(amps_mesh_set_region_material(&ctx, m, 1, 1.0, 0.3, NAN) == AMPS_ERR_VALUE, "region NaN density");
    CHECK(amps_mesh_set_region_material(&ctx, m, 1, -1.0, 0.3, 1.0) == AMPS_ERR_ARG, "region negative E");
    CHECK(amps_mesh_set_region_material(&ctx, m, 1, 1.0, 0.5, 1.0) == AMPS_ERR_ARG, "region nu 0.5");
    CHECK(amps_mesh_set_tet_region(&ctx, m, -1, 0) == AMPS_ERR_INDEX, "region tet out of range");
    CHECK(t_same(&s, m), "bad input left the mesh unchanged");
    CHECK(amps_mesh_check(&ctx, m) == AMPS_OK, "check: %s", ctx.msg);
    t_drop(&s);
    /* removed tets carry no mass */
    t = 5;
    CHECK(amps_mesh_remove(&ctx, m, 1, &t, AMPS_SINGULAR_IGNORE, NULL) == AMPS_OK, "remove");
    amps_mesh_lumped_mass(m, mass);
    for (v = 0, sum = 0; v < m->nnode; v++) sum += mass[v];
    CHECK(fabs(sum - (4.0 * vol1 + 2.5 * (vol - vol1)) + m->rho[5] * t_volume(m, 5)) < 1e-13, "mass after removal");
    free(mass);
    amps_mesh_free(&ctx, m);
}

/* ---- hand-built singular cases ---- */

/* Vertex 0 in a chain T0 - T1 - T2 - T3: T0, T1 share a face, T1, T2 share only the edge
   (0, 4) (a singular edge), T2, T3 a face, T3, T4 the face (5, 6, 7). Removing T1 leaves vertex
   0 with the groups {T0} and {T2, T3}; removing T1 and T3 leaves a tie {T0}, {T2}. */
static const amps_int VCHAIN[20] = {0, 1, 2, 3, 0, 2, 3, 4, 0, 4, 5, 6, 0, 5, 6, 7, 5, 6, 7, 8};

static void test_vertex_case(void) {
    amps_ctx ctx;
    amps_mesh *m;
    amps_mesh_removal r;
    amps_int t[2], sv[8];
    t_snap s;
    amps_ctx_init(&ctx);
    m = t_hand(&ctx, 9, 5, VCHAIN);
    CHECK(m != NULL, "chain: %s", ctx.msg);
    if (!m) return;
    CHECK(amps_mesh_singular_vertices(&ctx, m, NULL) == 0, "no singular vertex at the start");
    CHECK(amps_mesh_singular_edges(&ctx, m, sv) == 1 && sv[0] == 0 && sv[1] == 4, "edge (0, 4) singular");
    s = t_take(m);
    /* ignore: the singular vertex stays, and the from-scratch query finds it */
    t[0] = 1;
    CHECK(amps_mesh_remove(&ctx, m, 1, t, AMPS_SINGULAR_IGNORE, &r) == AMPS_OK && r.ntet == 1, "ignore");
    CHECK(amps_mesh_singular_vertices(&ctx, m, sv) == 1 && sv[0] == 0, "vertex 0 singular");
    CHECK(amps_mesh_check(&ctx, m) == AMPS_OK, "check: %s", ctx.msg);
    CHECK(amps_mesh_unremove(&ctx, m, &r) == AMPS_OK && t_same(&s, m), "unremove exact");
    CHECK(amps_mesh_unremove(&ctx, m, &r) == AMPS_ERR_ARG, "second unremove refused");
    /* remove: the larger group {T2, T3} stays */
    CHECK(amps_mesh_remove(&ctx, m, 1, t, AMPS_SINGULAR_REMOVE, &r) == AMPS_OK, "remove: %s", ctx.msg);
    CHECK(r.ntet == 2 && r.tets[0] == 1 && r.tets[1] == 0 && r.nsep == 0, "removed T1 then T0 (%d)", (int)r.ntet);
    CHECK(r.norphan == 3 && r.orphans[0] == 1 && r.orphans[1] == 2 && r.orphans[2] == 3, "orphans 1 2 3");
    CHECK(m->nremoved == 2 && m->removed[0] && m->removed[1] && !m->removed[2], "flags");
    CHECK(amps_mesh_singular_vertices(&ctx, m, NULL) == 0 && amps_mesh_singular_edges(&ctx, m, NULL) == 0,
          "nothing singular");
    CHECK(amps_mesh_check(&ctx, m) == AMPS_OK, "check: %s", ctx.msg);
    CHECK(amps_mesh_unremove(&ctx, m, &r) == AMPS_OK && t_same(&s, m), "unremove exact");
    /* tie: {T0} and {T2} of one tet each; the lowest tet index (T0) stays */
    t[0] = 3;
    t[1] = 1;
    CHECK(amps_mesh_remove(&ctx, m, 2, t, AMPS_SINGULAR_REMOVE, &r) == AMPS_OK, "tie: %s", ctx.msg);
    CHECK(r.ntet == 3 && r.tets[0] == 3 && r.tets[1] == 1 && r.tets[2] == 2 && !m->removed[0], "tie keeps T0");
    CHECK(amps_mesh_unremove(&ctx, m, &r) == AMPS_OK && t_same(&s, m), "unremove exact");
    /* separation: {T0}, not the larger group, gets a copy of vertex 0 */
    t[0] = 1;
    CHECK(amps_mesh_remove(&ctx, m, 1, t, AMPS_SINGULAR_SEPARATE, &r) == AMPS_OK, "separate: %s", ctx.msg);
    CHECK(r.ntet == 1 && r.nsep == 1 && r.sep_node[0] == 0 && r.sep_copy[0] == 9 && m->nnode == 10, "one copy");
    CHECK(r.sep_ptr[0] == 0 && r.sep_ptr[1] == 1 && r.sep_tets[0] == 0, "T0 moved");
    CHECK(t_has(m, 0, 9) && !t_has(m, 0, 0) && t_has(m, 2, 0) && t_has(m, 3, 0) && m->origin[9] == 0, "copy used");
    CHECK(m->xyz[27] == m->xyz[0] && m->xyz[28] == m->xyz[1] && m->xyz[29] == m->xyz[2], "copy coordinates");
    CHECK(amps_mesh_singular_vertices(&ctx, m, NULL) == 0 && amps_mesh_singular_edges(&ctx, m, NULL) == 0,
          "nothing singular");
    CHECK(amps_mesh_check(&ctx, m) == AMPS_OK, "check: %s", ctx.msg);
    CHECK(amps_mesh_unremove(&ctx, m, &r) == AMPS_OK && t_same(&s, m), "unremove separation exact");
    /* bad input: mesh unchanged */
    t[0] = 5;
    CHECK(amps_mesh_remove(&ctx, m, 1, t, AMPS_SINGULAR_REMOVE, &r) == AMPS_ERR_INDEX, "out of range");
    t[0] = -1;
    CHECK(amps_mesh_remove(&ctx, m, 1, t, AMPS_SINGULAR_REMOVE, &r) == AMPS_ERR_INDEX, "negative");
    t[0] = t[1] = 2;
    CHECK(amps_mesh_remove(&ctx, m, 2, t, AMPS_SINGULAR_REMOVE, &r) == AMPS_ERR_ARG, "given twice");
    CHECK(amps_mesh_remove(&ctx, m, 0, t, AMPS_SINGULAR_REMOVE, &r) == AMPS_ERR_ARG, "n = 0");
    CHECK(amps_mesh_remove(&ctx, m, 1, t, (amps_singular_policy)7, &r) == AMPS_ERR_ARG, "bad policy");
    CHECK(t_same(&s, m), "bad input left the mesh unchanged");
    t[0] = 4;
    CHECK(amps_mesh_remove(&ctx, m, 1, t, AMPS_SINGULAR_REMOVE, &r) == AMPS_OK, "remove T4");
    t_drop(&s);
    s = t_take(m);
    CHECK(amps_mesh_remove(&ctx, m, 1, t, AMPS_SINGULAR_REMOVE, &r) == AMPS_ERR_ARG &&
                  strstr(ctx.msg, "already removed"),
          "removed twice: %s", ctx.msg);
    t[0] = 0;
    t[1] = 4;
    CHECK(amps_mesh_remove(&ctx, m, 2, t, AMPS_SINGULAR_REMOVE, &r) == AMPS_ERR_ARG, "one of two removed");
    CHECK(t_same(&s, m), "mesh unchanged");
    t_drop(&s);
    amps_mesh_free(&ctx, m);
}

/* Edge (0, 1) in T0 = (0,1,2,3), T1 = (0,1,3,4), T2 = (0,1,4,5): removing T1 leaves T0 and T2
   sharing only the edge (no vertex is singular). */
static const amps_int ECHAIN[12] = {0, 1, 2, 3, 0, 1, 3, 4, 0, 1, 4, 5};

static void test_edge_case(void) {
    amps_ctx ctx;
    amps_mesh *m;
    amps_mesh_removal r;
    amps_int t = 1, se[4], k;
    t_snap s;
    amps_ctx_init(&ctx);
    m = t_hand(&ctx, 6, 3, ECHAIN);
    CHECK(m != NULL, "edge chain: %s", ctx.msg);
    if (!m) return;
    s = t_take(m);
    CHECK(amps_mesh_remove(&ctx, m, 1, &t, AMPS_SINGULAR_IGNORE, &r) == AMPS_OK, "ignore");
    CHECK(amps_mesh_singular_vertices(&ctx, m, NULL) == 0, "no singular vertex");
    CHECK(amps_mesh_singular_edges(&ctx, m, se) == 1 && se[0] == 0 && se[1] == 1, "edge (0, 1) singular");
    CHECK(amps_mesh_unremove(&ctx, m, &r) == AMPS_OK && t_same(&s, m), "unremove");
    /* tie: T0 (the lowest index) stays */
    CHECK(amps_mesh_remove(&ctx, m, 1, &t, AMPS_SINGULAR_REMOVE, &r) == AMPS_OK, "remove: %s", ctx.msg);
    CHECK(r.ntet == 2 && r.tets[1] == 2 && !m->removed[0], "T2 removed");
    CHECK(r.norphan == 2 && r.orphans[0] == 4 && r.orphans[1] == 5, "orphans 4 5");
    CHECK(amps_mesh_singular_edges(&ctx, m, NULL) == 0 && amps_mesh_check(&ctx, m) == AMPS_OK, "clean");
    CHECK(amps_mesh_unremove(&ctx, m, &r) == AMPS_OK && t_same(&s, m), "unremove");
    /* separation: T2 gets copies of 0 and of 1 (after the first copy vertex 1 is singular) */
    CHECK(amps_mesh_remove(&ctx, m, 1, &t, AMPS_SINGULAR_SEPARATE, &r) == AMPS_OK, "separate: %s", ctx.msg);
    CHECK(r.ntet == 1 && r.nsep == 2 && m->nnode == 8, "two copies (%d)", (int)r.nsep);
    for (k = 0; k < r.nsep; k++)
        CHECK(r.sep_ptr[k + 1] - r.sep_ptr[k] == 1 && r.sep_tets[r.sep_ptr[k]] == 2 &&
                      m->origin[r.sep_copy[k]] == r.sep_node[k],
              "separation %d", (int)k);
    CHECK(t_has(m, 0, 0) && t_has(m, 0, 1) && !t_has(m, 2, 0) && !t_has(m, 2, 1), "T2 on its own vertices");
    CHECK(amps_mesh_singular_vertices(&ctx, m, NULL) == 0 && amps_mesh_singular_edges(&ctx, m, NULL) == 0,
          "nothing singular");
    CHECK(amps_mesh_check(&ctx, m) == AMPS_OK, "check: %s", ctx.msg);
    CHECK(amps_mesh_unremove(&ctx, m, &r) == AMPS_OK && t_same(&s, m), "unremove separation exact");
    t_drop(&s);
    amps_mesh_free(&ctx, m);
}

/* ---- random sequences on a brick ---- */

static void t_random_sequence(amps_singular_policy pol, unsigned long long seed) {
    amps_ctx ctx;
    amps_mesh *m;
    amps_mesh_removal r;
    amps_int step, live, t[2], bad = 0, badv = 0, bade = 0, badu = 0, badsep = 0, k, extra = 0, nsep = 0;
    amps_ctx_init(&ctx);
    m = amps_mesh_brick(&ctx, 3);
    if (!m) {
        CHECK(0, "brick");
        return;
    }
    t_seed(seed);
    for (step = 0; step < 40 && m->nremoved < m->ntet - 8; step++) {
        int n = 1 + t_int(2), i;
        t_snap s;
        for (i = 0; i < n; i++) {
            do t[i] = t_int((int)m->ntet);
            while (m->removed[t[i]] || (i == 1 && t[1] == t[0]));
        }
        s = t_take(m);
        if (amps_mesh_remove(&ctx, m, n, t, pol, &r) != AMPS_OK) {
            bad++;
            t_drop(&s);
            continue;
        }
        if (amps_mesh_unremove(&ctx, m, &r) != AMPS_OK || !t_same(&s, m)) badu++;
        t_drop(&s);
        if (amps_mesh_remove(&ctx, m, n, t, pol, &r) != AMPS_OK) bad++;
        if (amps_mesh_check(&ctx, m) != AMPS_OK) bad++;
        extra += r.ntet - n;
        nsep += r.nsep;
        if (amps_mesh_singular_vertices(&ctx, m, NULL) != 0) badv++;
        if (amps_mesh_singular_edges(&ctx, m, NULL) != 0) bade++;
        for (k = 0; k < r.nsep; k++) { /* each separated group on its own vertex */
            amps_int j;
            for (j = r.sep_ptr[k]; j < r.sep_ptr[k + 1]; j++)
                if (!m->removed[r.sep_tets[j]] && !t_has(m, r.sep_tets[j], r.sep_copy[k]) &&
                    m->origin[r.sep_copy[k]] == m->origin[r.sep_node[k]])
                    badsep++;
        }
    }
    for (k = 0, live = 0; k < m->ntet; k++) live += !m->removed[k];
    CHECK(bad == 0 && badu == 0, "policy %d: %d failures, %d inexact undos: %s", (int)pol, (int)bad, (int)badu,
          ctx.msg);
    CHECK(badv == 0 && bade == 0, "policy %d: singular vertices after %d steps, edges after %d", (int)pol, (int)badv,
          (int)bade);
    CHECK(badsep == 0, "policy %d: separated tets not on their copy", (int)pol);
    CHECK(live == m->ntet - m->nremoved && m->nremoved > 0, "policy %d: removed count", (int)pol);
    if (pol == AMPS_SINGULAR_SEPARATE) CHECK(m->nnode > m->nfile && nsep > 0, "separations made copies");
    else CHECK(extra > 0 && nsep == 0, "singularity avoidance removed more tets");
    if (getenv("T_VERBOSE"))
        printf("policy %d: %d steps, %d removed (%d by avoidance), %d separations, %d nodes\n", (int)pol, (int)step,
               (int)m->nremoved, (int)extra, (int)nsep, (int)m->nnode);
    amps_mesh_free(&ctx, m);
}

static void test_random(void) {
    t_random_sequence(AMPS_SINGULAR_REMOVE, 11);
    t_random_sequence(AMPS_SINGULAR_REMOVE, 12);
    t_random_sequence(AMPS_SINGULAR_SEPARATE, 13);
    t_random_sequence(AMPS_SINGULAR_SEPARATE, 14);
}

/* ---- assembly, stress, DOFs and cuts after removal ---- */

static void test_assembly(void) {
    amps_ctx ctx;
    amps_mesh *m, *ref;
    amps_mesh_removal r;
    amps_int rm[6] = {3, 17, 40, 41, 90, 100}, *dof, *dof2, *keep, nd, nd2, t, k = 0, v, nm, vc, moved[64];
    amps_csc *A, *B;
    double *u, *vm, *pr, p[3] = {0.5, 0.5, 1.0}, nrm[3] = {0, 0, 1}, err = 0;
    int same;
    amps_ctx_init(&ctx);
    m = amps_mesh_brick(&ctx, 3);
    if (!m) {
        CHECK(0, "brick");
        return;
    }
    for (t = 0; t < m->ntet; t++) amps_mesh_set_tet_material(&ctx, m, t, 1.0 + 0.01 * (double)t, 0.3);
    CHECK(amps_mesh_remove(&ctx, m, 6, rm, AMPS_SINGULAR_REMOVE, &r) == AMPS_OK, "remove: %s", ctx.msg);
    keep = (amps_int *)malloc(sizeof(amps_int) * 4 * m->ntet);
    for (t = 0; t < m->ntet; t++)
        if (!m->removed[t]) memcpy(keep + 4 * k++, m->tet + 4 * t, 4 * sizeof(amps_int));
    ref = amps_mesh_create(&ctx, m->nnode, m->xyz, k, keep);
    for (t = 0, k = 0; ref && t < m->ntet; t++)
        if (!m->removed[t]) amps_mesh_set_tet_material(&ctx, ref, k++, m->E[t], m->nu[t]);
    dof = (amps_int *)malloc(sizeof(amps_int) * 3 * m->nnode);
    dof2 = (amps_int *)malloc(sizeof(amps_int) * 3 * m->nnode);
    nd = amps_mesh_number_dofs(m, NULL, dof);
    nd2 = ref ? amps_mesh_number_dofs(ref, NULL, dof2) : -1;
    CHECK(nd == nd2 && !memcmp(dof, dof2, sizeof(amps_int) * 3 * m->nnode), "same DOFs");
    for (k = 0; k < r.norphan; k++) CHECK(dof[3 * r.orphans[k]] == -1, "orphan %d has no DOF", (int)r.orphans[k]);
    A = amps_mesh_assemble(&ctx, m, dof, nd);
    B = ref ? amps_mesh_assemble(&ctx, ref, dof2, nd2) : NULL;
    same = A && B && A->p[nd] == B->p[nd] && !memcmp(A->p, B->p, sizeof(amps_int) * (size_t)(nd + 1)) &&
           !memcmp(A->i, B->i, sizeof(amps_int) * (size_t)A->p[nd]);
    if (same)
        for (k = 0; k < A->p[nd]; k++) err = fmax(err, fabs(A->x[k] - B->x[k]));
    CHECK(same && err <= 1e-14, "assembly after removal = assembly without the tets (err %g)", err);
    amps_csc_free(&ctx, A);
    amps_csc_free(&ctx, B);
    /* stress: zeros on removed tets */
    u = (double *)calloc(3 * (size_t)m->node_cap, sizeof(double));
    vm = (double *)malloc(sizeof(double) * m->ntet);
    pr = (double *)malloc(sizeof(double) * 3 * m->ntet);
    for (v = 0; v < m->nnode; v++) u[3 * v + 2] = 0.1 * m->xyz[3 * v + 2];
    CHECK(amps_mesh_stress(&ctx, m, u, NULL, vm, pr) == AMPS_OK, "stress");
    for (t = 0, k = 0; t < m->ntet; t++) k += m->removed[t] ? (vm[t] != 0 || pr[3 * t] != 0) : !(vm[t] > 0);
    CHECK(k == 0, "stress zero exactly on removed tets");
    /* a cut after a removal: incidence stays consistent; the removal can no longer be undone */
    v = 0;
    while (v < m->nfile && m->inc_len[v] < 3) v++;
    p[0] = m->xyz[3 * v];
    p[1] = m->xyz[3 * v + 1];
    p[2] = m->xyz[3 * v + 2];
    nrm[0] = 0.3;
    nrm[1] = 0.7;
    nrm[2] = 0.2;
    if (amps_mesh_cut(&ctx, m, v, p, nrm, &vc, moved, &nm) == AMPS_OK) {
        CHECK(amps_mesh_check(&ctx, m) == AMPS_OK, "check after cut: %s", ctx.msg);
        CHECK(amps_mesh_unremove(&ctx, m, &r) == AMPS_ERR_ARG, "unremove refused after a cut");
        CHECK(amps_mesh_uncut(&ctx, m, v, vc, moved, nm) == AMPS_OK && amps_mesh_check(&ctx, m) == AMPS_OK, "uncut");
    }
    free(u);
    free(vm);
    free(pr);
    free(dof);
    free(dof2);
    free(keep);
    amps_mesh_free(&ctx, ref);
    amps_mesh_free(&ctx, m);
}

/* Every allocation of a removal with separations fails in turn: AMPS_ERR_OOM, mesh unchanged. */
static void test_oom(void) {
    amps_ctx ctx;
    amps_mesh *m;
    amps_mesh_removal r;
    amps_int t[3] = {140, 141, 148};
    long base, k, bad = 0, done = 0, live;
    amps_ctx_init(&ctx);
    ctx.alloc_user = &t_al;
    base = t_al.live;
    m = amps_mesh_brick(&ctx, 3);
    if (!m) {
        CHECK(0, "brick");
        return;
    }
    for (k = 0; k < 400 && !done; k++) {
        t_snap s = t_take(m);
        amps_status st;
        t_al.fail_at = k;
        st = amps_mesh_remove(&ctx, m, 3, t, AMPS_SINGULAR_SEPARATE, &r);
        t_al.fail_at = -1;
        if (st == AMPS_OK) done = 1;
        else if (st != AMPS_ERR_OOM || !t_same(&s, m) || amps_mesh_check(&ctx, m) != AMPS_OK) {
            bad++;
            if (getenv("T_VERBOSE")) printf("k %ld: status %d same %d: %s\n", k, (int)st, t_same(&s, m), ctx.msg);
        }
        t_drop(&s);
    }
    CHECK(done && bad == 0 && k > 3 && r.nsep > 0 && r.ntet > 3, "allocation failures: %ld bad of %ld", bad, k);
    CHECK(amps_mesh_singular_vertices(&ctx, m, NULL) == 0 && amps_mesh_singular_edges(&ctx, m, NULL) == 0,
          "clean after the successful try");
    live = t_al.live;
    t_al.fail_at = 0;
    CHECK(amps_mesh_singular_edges(&ctx, m, NULL) == -1 && ctx.status == AMPS_ERR_OOM, "query OOM");
    t_al.fail_at = -1;
    CHECK(t_al.live == live, "query OOM leaks nothing");
    amps_mesh_free(&ctx, m);
    CHECK(t_al.live == base, "no leak: %ld blocks", t_al.live - base);
}

int main(void) {
    test_mass();
    test_vertex_case();
    test_edge_case();
    test_random();
    test_assembly();
    test_oom();
    return amps_t_end("test_remove");
}
