/* Mesh layer of the FEM scene: P1 element, mesh construction, assembly against fe_util.h,
   stresses, node selection and the topology of cuts (including allocation failures). */
#include <string.h>
#include "t_alloc.h"
#define AMPS_IMPLEMENTATION
#include "amps.h"
#include "amps_test.h"
#include "fe_util.h"

/* ---- helpers ---- */

/* y = A x for symmetric A given by its upper triangle (CSC). */
static void t_symv(const amps_csc *A, const double *x, double *y) {
    amps_int j, p;
    for (j = 0; j < A->nrow; j++) y[j] = 0;
    for (j = 0; j < A->ncol; j++)
        for (p = A->p[j]; p < A->p[j + 1]; p++) {
            amps_int i = A->i[p];
            y[i] += A->x[p] * x[j];
            if (i != j) y[j] += A->x[p] * x[i];
        }
}

/* Well-shaped random tet: perturbed regular-ish tet, random orientation and placement. */
static void t_rand_tet(double X[12]) {
    static const double R[12] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1};
    int k;
    for (k = 0; k < 12; k++) X[k] = R[k] + 0.3 * (t_unif() - 0.5) + (k % 3 == 0 ? 5.0 : -2.0);
    if (t_int(2)) { /* swap nodes 1, 2: other orientation */
        for (k = 0; k < 3; k++) {
            double s = X[3 + k];
            X[3 + k] = X[6 + k];
            X[6 + k] = s;
        }
    }
}

/* 6 rigid modes of the 4 nodes of X (3 translations, 3 infinitesimal rotations). */
static void t_rigid(const double X[12], int mode, double u[12]) {
    int a;
    for (a = 0; a < 4; a++) {
        const double *x = X + 3 * a;
        double *w = u + 3 * a;
        w[0] = w[1] = w[2] = 0;
        if (mode < 3) w[mode] = 1;
        else if (mode == 3) {
            w[1] = -x[2];
            w[2] = x[1];
        } else if (mode == 4) {
            w[0] = x[2];
            w[2] = -x[0];
        } else {
            w[0] = -x[1];
            w[1] = x[0];
        }
    }
}

static double t_maxabs(int n, const double *x) {
    double m = 0;
    int i;
    for (i = 0; i < n; i++)
        if (fabs(x[i]) > m) m = fabs(x[i]);
    return m;
}

/* fe_util mesh with the same nodes and tets as m. */
static fe_mesh t_fe_of(const amps_mesh *m) {
    fe_mesh f;
    int k;
    f.nn = (int)m->nnode;
    f.nt = (int)m->ntet;
    f.xyz = (double *)malloc(sizeof(double) * 3 * f.nn);
    f.tet = (int *)malloc(sizeof(int) * 4 * f.nt);
    for (k = 0; k < 3 * f.nn; k++) f.xyz[k] = m->xyz[k];
    for (k = 0; k < 4 * f.nt; k++) f.tet[k] = (int)m->tet[k];
    return f;
}

/* Checks the CSC upper-triangle structure and compares to fe_util's triplets (dense). */
static void t_compare_assembly(amps_ctx *ctx, const amps_mesh *m, const amps_int *dof, amps_int ndof, double E,
                               double nu, const char *what) {
    fe_mesh f = t_fe_of(m);
    int *fdof = (int *)malloc(sizeof(int) * 3 * f.nn), *ti, *tj, nz, k, ok = 1;
    double *tx, *D1 = (double *)calloc((size_t)ndof * ndof, sizeof(double)),
                *D2 = (double *)calloc((size_t)ndof * ndof, sizeof(double));
    unsigned char *pat = (unsigned char *)calloc((size_t)ndof * ndof, 1);
    amps_csc *A;
    amps_int j, p, npat = 0;
    for (k = 0; k < 3 * f.nn; k++) fdof[k] = (int)dof[k];
    nz = fe_assemble(&f, fdof, E, nu, &ti, &tj, &tx);
    for (k = 0; k < nz; k++) {
        D2[(size_t)ti[k] * ndof + tj[k]] += tx[k];
        if (!pat[(size_t)ti[k] * ndof + tj[k]]) {
            pat[(size_t)ti[k] * ndof + tj[k]] = 1;
            npat++;
        }
    }
    A = amps_mesh_assemble(ctx, m, dof, ndof);
    CHECK(A != NULL, "%s: assemble failed: %s", what, ctx->msg);
    if (A) {
        CHECK(A->nrow == ndof && A->ncol == ndof && A->p[0] == 0, "%s: dimensions", what);
        for (j = 0; j < ndof; j++) {
            if (A->p[j + 1] < A->p[j]) ok = 0;
            for (p = A->p[j]; p < A->p[j + 1]; p++) {
                amps_int i = A->i[p];
                if (i < 0 || i > j || (p > A->p[j] && i <= A->i[p - 1])) ok = 0;
                else D1[(size_t)i * ndof + j] += A->x[p];
            }
        }
        CHECK(ok, "%s: rows not sorted / not upper", what);
        CHECK(A->p[ndof] == npat, "%s: nnz %lld, element coupling pattern has %lld", what, (long long)A->p[ndof],
              (long long)npat);
        {
            double md = 0, mx = t_maxabs(ndof * ndof, D2);
            size_t q;
            for (q = 0; q < (size_t)ndof * ndof; q++)
                if (fabs(D1[q] - D2[q]) > md) md = fabs(D1[q] - D2[q]);
            CHECK(md <= 1e-13 * mx, "%s: max diff %g (max entry %g)", what, md, mx);
        }
        amps_csc_free(ctx, A);
    }
    free(ti);
    free(tj);
    free(tx);
    free(D1);
    free(D2);
    free(pat);
    free(fdof);
    fe_free(&f);
}

/* ---- element ---- */

static void test_element(void) {
    int trial, a, b, k, mode;
    t_seed(1);
    for (trial = 0; trial < 50; trial++) {
        double X[12], Ke[144], Kf[144], G[12], Bm[72], C[36], CB[72], vol, svol, E = 0.5 + t_unif() * 100,
                                                                                 nu = -0.5 + t_unif() * 0.99;
        double asym = 0, md = 0, mx, worst = 0, u[12], f[12], energy;
        t_rand_tet(X);
        vol = amps_tet_stiffness(X, E, nu, Ke);
        fe_tet_K(X, E, nu, Kf);
        svol = amps_tet_gradients(X, G);
        CHECK(vol > 0 && fabs(fabs(svol) - vol) <= 1e-15 * vol, "volume %g vs %g", vol, svol);
        mx = t_maxabs(144, Ke);
        for (a = 0; a < 12; a++)
            for (b = 0; b < 12; b++) {
                if (fabs(Ke[12 * a + b] - Ke[12 * b + a]) > asym) asym = fabs(Ke[12 * a + b] - Ke[12 * b + a]);
                if (fabs(Ke[12 * a + b] - Kf[12 * a + b]) > md) md = fabs(Ke[12 * a + b] - Kf[12 * a + b]);
            }
        CHECK(asym == 0, "Ke not symmetric: %g", asym);
        CHECK(md <= 1e-12 * mx, "Ke differs from fe_util: %g", md);
        /* barycentric gradients: N_a(x_b) = delta_ab */
        for (a = 0; a < 4; a++)
            for (b = 0; b < 4; b++) {
                double n = (a == 0) + G[3 * a] * (X[3 * b] - X[0]) + G[3 * a + 1] * (X[3 * b + 1] - X[1]) +
                           G[3 * a + 2] * (X[3 * b + 2] - X[2]);
                if (fabs(n - (a == b)) > worst) worst = fabs(n - (a == b));
            }
        CHECK(worst < 1e-12, "barycentric gradients off by %g", worst);
        /* Ke = V B^T C B through the small building blocks */
        amps_tet_B(G, Bm);
        amps_elasticity(E, nu, C);
        for (a = 0; a < 6; a++)
            for (b = 0; b < 12; b++) {
                double s = 0;
                for (k = 0; k < 6; k++) s += C[6 * a + k] * Bm[12 * k + b];
                CB[12 * a + b] = s;
            }
        md = 0;
        for (a = 0; a < 12; a++)
            for (b = 0; b < 12; b++) {
                double s = 0;
                for (k = 0; k < 6; k++) s += Bm[12 * k + a] * CB[12 * k + b];
                if (fabs(vol * s - Ke[12 * a + b]) > md) md = fabs(vol * s - Ke[12 * a + b]);
            }
        CHECK(md <= 1e-12 * mx, "Ke != V B^T C B: %g", md);
        /* null space: the 6 rigid modes */
        worst = 0;
        for (mode = 0; mode < 6; mode++) {
            t_rigid(X, mode, u);
            for (a = 0; a < 12; a++) {
                double s = 0;
                for (b = 0; b < 12; b++) s += Ke[12 * a + b] * u[b];
                f[a] = s;
            }
            if (t_norm(12, f) / (mx * t_norm(12, u)) > worst) worst = t_norm(12, f) / (mx * t_norm(12, u));
        }
        CHECK(worst < 1e-13, "rigid mode not in null space: %g", worst);
        /* non-rigid field: positive energy; also positive after removing the rigid part */
        for (a = 0; a < 12; a++) u[a] = t_unif() - 0.5;
        for (mode = 0; mode < 6; mode++) { /* u += rigid mode: energy unchanged */
            double r[12];
            t_rigid(X, mode, r);
            for (a = 0; a < 12; a++) u[a] += (t_unif() - 0.5) * r[a];
        }
        energy = 0;
        for (a = 0; a < 12; a++)
            for (b = 0; b < 12; b++) energy += u[a] * Ke[12 * a + b] * u[b];
        CHECK(energy > 1e-8 * mx * t_norm(12, u) * t_norm(12, u), "non-rigid field has energy %g", energy);
    }
    /* a stretch in x is not rigid: energy = V E' eps^2 with eps = 1 for u = (x, 0, 0) */
    {
        double X[12] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1}, Ke[144], u[12] = {0}, en = 0, eps[6];
        double nu = 0.25, E = 3, lam = E * nu / ((1 + nu) * (1 - 2 * nu)), mu = E / (2 * (1 + nu));
        for (a = 0; a < 4; a++) u[3 * a] = X[3 * a];
        CHECK(fabs(amps_tet_stiffness(X, E, nu, Ke) - 1.0 / 6) < 1e-16, "unit tet volume");
        for (a = 0; a < 12; a++)
            for (b = 0; b < 12; b++) en += u[a] * Ke[12 * a + b] * u[b];
        CHECK(fabs(en - (lam + 2 * mu) / 6) < 1e-14, "stretch energy %g vs %g", en, (lam + 2 * mu) / 6);
        amps_tet_strain(X, u, eps);
        CHECK(fabs(eps[0] - 1) < 1e-15 && t_maxabs(5, eps + 1) < 1e-15, "stretch strain");
    }
    /* degenerate tets give volume 0 and zero outputs */
    {
        double X[12] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0}, Ke[144], G[12], s[6], vm = 1, pr[3],
               u[12] = {1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12};
        CHECK(amps_tet_stiffness(X, 1, 0.3, Ke) == 0 && t_maxabs(144, Ke) == 0, "flat tet stiffness");
        CHECK(amps_tet_gradients(X, G) == 0 && t_maxabs(12, G) == 0, "flat tet gradients");
        CHECK(amps_tet_stress(X, 1, 0.3, u, s, &vm, pr) == 0 && t_maxabs(6, s) == 0 && vm == 0, "flat tet stress");
    }
}

/* ---- symmetric 3x3 eigenvalues ---- */

/* Reference eigenvalues by cyclic Jacobi rotations, sorted descending. */
static void t_jacobi(const double s[6], double lam[3]) {
    double A[3][3] = {{s[0], s[3], s[5]}, {s[3], s[1], s[4]}, {s[5], s[4], s[2]}};
    int it, p, q, r;
    for (it = 0; it < 100; it++)
        for (p = 0; p < 3; p++)
            for (q = p + 1; q < 3; q++) {
                double th, c, sn, t;
                if (A[p][q] == 0) continue;
                th = (A[q][q] - A[p][p]) / (2 * A[p][q]);
                t = (th >= 0 ? 1 : -1) / (fabs(th) + sqrt(th * th + 1));
                c = 1 / sqrt(t * t + 1);
                sn = t * c;
                for (r = 0; r < 3; r++) {
                    double a = A[r][p], b = A[r][q];
                    A[r][p] = c * a - sn * b;
                    A[r][q] = sn * a + c * b;
                }
                for (r = 0; r < 3; r++) {
                    double a = A[p][r], b = A[q][r];
                    A[p][r] = c * a - sn * b;
                    A[q][r] = sn * a + c * b;
                }
            }
    lam[0] = A[0][0];
    lam[1] = A[1][1];
    lam[2] = A[2][2];
    for (p = 0; p < 3; p++)
        for (q = p + 1; q < 3; q++)
            if (lam[q] > lam[p]) {
                double t = lam[p];
                lam[p] = lam[q];
                lam[q] = t;
            }
}

static void test_eig(void) {
    int trial, k;
    double worst = 0;
    t_seed(2);
    for (trial = 0; trial < 2000; trial++) {
        double s[6], l1[3], l2[3], sc = pow(10.0, (double)(t_int(41) - 20)), nrm = 0;
        for (k = 0; k < 6; k++) s[k] = (t_unif() - 0.5) * sc;
        if (trial % 5 == 1) s[3] = s[4] = s[5] = 0; /* diagonal */
        if (trial % 5 == 2) {
            s[1] = s[0];
            s[4] = s[5] = 0;
            s[3] = 0;
        } /* repeated */
        if (trial % 5 == 3) {
            s[3] *= 1e-9;
            s[4] *= 1e-9;
            s[5] *= 1e-9;
        } /* nearly diagonal */
        if (trial % 5 == 4) {
            s[1] = s[0] * (1 + 1e-14);
            s[3] = s[0] * 1e-12;
            s[4] = s[5] = 0;
        } /* nearly repeated */
        amps_sym3_eig(s, l1);
        t_jacobi(s, l2);
        for (k = 0; k < 6; k++) nrm += s[k] * s[k] * (k < 3 ? 1 : 2);
        nrm = sqrt(nrm);
        for (k = 0; k < 3; k++)
            if (fabs(l1[k] - l2[k]) / nrm > worst) worst = fabs(l1[k] - l2[k]) / nrm;
        CHECK(l1[0] >= l1[1] && l1[1] >= l1[2], "eigenvalues not descending");
    }
    CHECK(worst < 1e-12, "closed-form eigenvalues vs Jacobi: relative error %g", worst);
    {
        double s1[6] = {3, 3, 3, 0, 0, 0}, s2[6] = {2, 1, 1, 0, 0, 0}, s3[6] = {1e300, -1e300, 0, 1e300, 0, 0},
               s4[6] = {0, 0, 0, 0, 0, 0}, l[3];
        double s5[6] = {0, 0, 0, 1, 0, 0};
        amps_sym3_eig(s1, l);
        CHECK(l[0] == 3 && l[1] == 3 && l[2] == 3, "3I: %g %g %g", l[0], l[1], l[2]);
        amps_sym3_eig(s2, l);
        CHECK(l[0] == 2 && l[1] == 1 && l[2] == 1, "diag(2,1,1)");
        s2[3] = 1e-30;
        amps_sym3_eig(s2, l);
        CHECK(fabs(l[0] - 2) < 1e-15 && fabs(l[1] - 1) < 1e-15 && fabs(l[2] - 1) < 1e-15, "diag(2,1,1) + tiny shear");
        amps_sym3_eig(s3, l);
        CHECK(fabs(l[0] - sqrt(2.0) * 1e300) < 1e286 && fabs(l[1]) < 1e286 && fabs(l[2] + sqrt(2.0) * 1e300) < 1e286,
              "huge: %g %g %g", l[0], l[1], l[2]);
        amps_sym3_eig(s4, l);
        CHECK(l[0] == 0 && l[1] == 0 && l[2] == 0, "zero");
        amps_sym3_eig(s5, l);
        CHECK(fabs(l[0] - 1) < 1e-15 && fabs(l[1]) < 1e-15 && fabs(l[2] + 1) < 1e-15, "shear: %g %g %g", l[0], l[1],
              l[2]);
        s5[2] = s5[2] / 0.0 * 0.0; /* NaN */
        amps_sym3_eig(s5, l);
        CHECK(l[0] != l[0] && l[2] != l[2], "NaN input gives NaN");
    }
}

/* ---- meshes ---- */

static int t_face_cmp(const void *a, const void *b) {
    const long long *x = (const long long *)a, *y = (const long long *)b;
    int k;
    for (k = 0; k < 3; k++)
        if (x[k] != y[k]) return x[k] < y[k] ? -1 : 1;
    return 0;
}

/* Counts faces used once (boundary) and checks no face is used more than twice. */
static long long t_boundary_faces(const amps_mesh *m, int *ok) {
    long long *F = (long long *)malloc(sizeof(long long) * 3 * 4 * m->ntet), nb = 0;
    amps_int t;
    int f, k, l, i;
    for (t = 0; t < m->ntet; t++)
        for (f = 0; f < 4; f++) {
            long long *x = F + 3 * (4 * t + f);
            for (k = 0, i = 0; k < 4; k++)
                if (k != f) x[i++] = m->origin[m->tet[4 * t + k]];
            for (k = 0; k < 3; k++)
                for (l = k + 1; l < 3; l++)
                    if (x[l] < x[k]) {
                        long long s = x[k];
                        x[k] = x[l];
                        x[l] = s;
                    }
        }
    qsort(F, (size_t)(4 * m->ntet), 3 * sizeof(long long), t_face_cmp);
    *ok = 1;
    for (i = 0; i < 4 * m->ntet;) {
        int j = i + 1;
        while (j < 4 * m->ntet && !t_face_cmp(F + 3 * i, F + 3 * j)) j++;
        if (j - i == 1) nb++;
        if (j - i > 2) *ok = 0;
        i = j;
    }
    free(F);
    return nb;
}

static double t_total_volume(const amps_mesh *m) {
    double v = 0, X[12], G[12];
    amps_int t;
    for (t = 0; t < m->ntet; t++) {
        amps_mesh_tet_coords(m, t, X);
        v += fabs(amps_tet_gradients(X, G));
    }
    return v;
}

static void test_mesh_create(void) {
    amps_ctx ctx;
    amps_mesh *m;
    int ok;
    amps_int h, R;
    amps_ctx_init(&ctx);
    for (h = 2; h <= 5; h++) {
        m = amps_mesh_beam(&ctx, h);
        CHECK(m && m->nnode == 25 * h && m->ntet == 96 * (h - 1) && m->nfile == m->nnode, "beam %d counts", (int)h);
        if (!m) continue;
        CHECK(amps_mesh_check(&ctx, m) == AMPS_OK, "beam check: %s", ctx.msg);
        CHECK(fabs(t_total_volume(m) - 16.0 * (h - 1)) < 1e-12, "beam volume");
        /* conforming: each interior face in 2 tets; the surface has 2 * (2*16 + 16 (h-1)) triangles */
        CHECK(t_boundary_faces(m, &ok) == 2 * (32 + 16 * (h - 1)) && ok, "beam %d not conforming", (int)h);
        CHECK(m->E[0] == 1.0 && m->nu[m->ntet - 1] == 0.3, "default material");
        amps_mesh_free(&ctx, m);
    }
    for (R = 1; R <= 3; R++) {
        m = amps_mesh_brick(&ctx, R);
        CHECK(m && m->nnode == (R + 1) * (R + 1) * (2 * R + 1) && m->ntet == 12 * R * R * R, "brick %d counts", (int)R);
        if (!m) continue;
        CHECK(fabs(t_total_volume(m) - 2.0) < 1e-12, "brick volume %g", t_total_volume(m));
        CHECK(t_boundary_faces(m, &ok) == 2 * 10 * R * R && ok, "brick %d not conforming", (int)R);
        CHECK(m->xyz[3 * (m->nnode - 1) + 2] == 2.0, "brick length");
        amps_mesh_free(&ctx, m);
    }
    CHECK(amps_mesh_beam(&ctx, 1) == NULL && ctx.status == AMPS_ERR_ARG, "beam h=1");
    CHECK(amps_mesh_brick(&ctx, 0) == NULL && ctx.status == AMPS_ERR_ARG, "brick R=0");
    CHECK(amps_mesh_grid(&ctx, 2, 2, 2, 1, 0, 1) == NULL && ctx.status == AMPS_ERR_ARG, "zero spacing");

    /* creation from arrays: validation */
    {
        double xyz[15] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 1, 1, 1};
        amps_int tet[8] = {0, 1, 2, 3, 1, 2, 3, 4}; /* tet 1 has the other orientation */
        amps_int bad[8] = {0, 1, 2, 3, 1, 2, 3, 5};
        amps_int flat[8] = {0, 1, 2, 3, 0, 1, 2, 2};
        amps_int nearflat[8] = {0, 1, 2, 3, 1, 2, 3, 4};
        double xyz2[15];
        m = amps_mesh_create(&ctx, 5, xyz, 2, tet);
        CHECK(m && amps_mesh_check(&ctx, m) == AMPS_OK, "create: %s", ctx.msg);
        if (m) {
            amps_int deg;
            const amps_int *inc = amps_mesh_incident(m, 2, &deg);
            CHECK(deg == 2 && inc[0] == 0 && inc[1] == 1 && amps_mesh_degree(m, 0) == 1 && amps_mesh_degree(m, 4) == 1,
                  "incidence");
            CHECK(amps_mesh_incident(m, 5, &deg) == NULL && deg == 0 && amps_mesh_degree(m, -1) == 0,
                  "incidence of invalid node");
            CHECK(amps_mesh_set_material(&ctx, m, 0, 0.3) == AMPS_ERR_ARG, "E = 0");
            CHECK(amps_mesh_set_material(&ctx, m, 1, 0.5) == AMPS_ERR_ARG, "nu = 0.5");
            CHECK(amps_mesh_set_material(&ctx, m, 1, -1) == AMPS_ERR_ARG, "nu = -1");
            CHECK(amps_mesh_set_material(&ctx, m, xyz[0] / 0.0 * 0.0, 0.3) == AMPS_ERR_VALUE, "E = NaN");
            CHECK(amps_mesh_set_tet_material(&ctx, m, 2, 1, 0.3) == AMPS_ERR_INDEX, "tet 2 out of range");
            CHECK(m->E[0] == 1.0 && m->nu[0] == 0.3, "failed calls leave the material");
            CHECK(amps_mesh_set_material(&ctx, m, 200, -0.2) == AMPS_OK && m->E[1] == 200 && m->nu[1] == -0.2,
                  "set all");
            CHECK(amps_mesh_set_tet_material(&ctx, m, 1, 5, 0.49) == AMPS_OK && m->E[1] == 5 && m->E[0] == 200,
                  "set one");
            amps_mesh_free(&ctx, m);
        }
        CHECK(!amps_mesh_create(&ctx, 5, xyz, 2, bad) && ctx.status == AMPS_ERR_INDEX &&
                      strstr(ctx.msg, "tetrahedron 1"),
              "index: %s", ctx.msg);
        CHECK(!amps_mesh_create(&ctx, 5, xyz, 2, flat) && ctx.status == AMPS_ERR_MESH &&
                      strstr(ctx.msg, "tetrahedron 1"),
              "flat: %s", ctx.msg);
        /* node 4 at distance d above the centroid of face 1 2 3: volume ~ 0.1 d L^3 */
        memcpy(xyz2, xyz, sizeof(xyz));
        xyz2[12] = xyz2[13] = xyz2[14] = 1.0 / 3 + 1e-6 / sqrt(3.0);
        m = amps_mesh_create(&ctx, 5, xyz2, 2, nearflat);
        CHECK(m != NULL, "thin but valid tet rejected: %s", ctx.msg);
        amps_mesh_free(&ctx, m);
        xyz2[12] = xyz2[13] = xyz2[14] = 1.0 / 3 + 1e-13;
        CHECK(!amps_mesh_create(&ctx, 5, xyz2, 2, nearflat) && ctx.status == AMPS_ERR_MESH &&
                      strstr(ctx.msg, "tetrahedron 1"),
              "near-flat: %s", ctx.msg);
        memcpy(xyz2, xyz, sizeof(xyz));
        xyz2[7] = xyz2[7] / 0.0;
        CHECK(!amps_mesh_create(&ctx, 5, xyz2, 2, tet) && ctx.status == AMPS_ERR_VALUE && strstr(ctx.msg, "node 2"),
              "inf: %s", ctx.msg);
        CHECK(!amps_mesh_create(&ctx, 5, xyz, 0, tet) && ctx.status == AMPS_ERR_MESH, "no tets");
        CHECK(!amps_mesh_create(&ctx, -1, xyz, 1, tet) && ctx.status == AMPS_ERR_ARG, "negative count");
        CHECK(!amps_mesh_create(&ctx, 5, NULL, 1, tet) && ctx.status == AMPS_ERR_ARG, "NULL xyz");
        /* a node in no tet is allowed; it gets no equations */
        m = amps_mesh_create(&ctx, 5, xyz, 1, tet);
        CHECK(m && amps_mesh_degree(m, 4) == 0, "isolated node");
        if (m) {
            amps_int dof[15];
            CHECK(amps_mesh_number_dofs(m, NULL, dof) == 12 && dof[12] == -1 && dof[11] == 11,
                  "number_dofs with isolated node");
            amps_mesh_free(&ctx, m);
        }
    }
}

/* amps_mesh_check detects each kind of corruption (fields are restored after each case). */
static void test_check(void) {
    amps_ctx ctx;
    amps_mesh *m;
    amps_int s, moved[32], nm, vc;
    double p[3] = {0.5, 0.5, 0.5}, n[3] = {1, 0, 0}, x;
    amps_ctx_init(&ctx);
    m = amps_mesh_grid(&ctx, 2, 2, 2, 1, 1, 1);
    if (!m) {
        CHECK(0, "grid");
        return;
    }
    amps_mesh_cut(&ctx, m, 0, p, n, &vc, moved, &nm);
    CHECK(amps_mesh_check(&ctx, m) == AMPS_OK, "valid mesh: %s", ctx.msg);
#define T_BREAK(field, val, what)                                                   \
    do {                                                                            \
        s = field;                                                                  \
        field = val;                                                                \
        CHECK(amps_mesh_check(&ctx, m) == AMPS_ERR_MESH, "check misses: %s", what); \
        field = s;                                                                  \
    } while (0)
    T_BREAK(m->tet[5], 99, "node out of range");
    T_BREAK(m->tet[5], m->tet[4], "repeated node");
    T_BREAK(m->origin[3], 2, "origin of a file node");
    T_BREAK(m->origin[8], 8, "origin of a copy");
    T_BREAK(m->inc_len[3], m->inc_len[3] + 1, "slot overlap");
    T_BREAK(m->inc_len[3], 4 * m->ntet, "slot out of range");
    T_BREAK(m->inc_len[3], m->inc_len[3] - 1, "entry missing");
    T_BREAK(m->inc[m->inc_ptr[7]], m->inc[m->inc_ptr[7] + 1], "not ascending");
    T_BREAK(m->inc[m->inc_ptr[7]], 77, "invalid tet");
    T_BREAK(m->inc[m->inc_ptr[8]], m->inc[m->inc_ptr[0]], "tet without the node");
    T_BREAK(m->nfile, m->nnode + 1, "counts");
#undef T_BREAK
    x = m->xyz[3 * 8];
    m->xyz[3 * 8] = 5;
    CHECK(amps_mesh_check(&ctx, m) == AMPS_ERR_MESH, "check misses a moved copy");
    m->xyz[3 * 8] = x;
    CHECK(amps_mesh_check(&ctx, m) == AMPS_OK, "restored");
    amps_mesh_free(&ctx, m);
}

static void test_select(void) {
    amps_ctx ctx;
    amps_mesh *m;
    amps_int out[200], n, k;
    int ok = 1;
    unsigned char fixed[100];
    amps_int dof[300];
    amps_ctx_init(&ctx);
    m = amps_mesh_beam(&ctx, 4);
    if (!m) {
        CHECK(0, "beam");
        return;
    }
    n = amps_mesh_select(&ctx, m, 2, AMPS_LT, 0.5, out);
    CHECK(n == 25, "fix z lt 0.5: %d", (int)n);
    for (k = 0; k < n; k++)
        if (out[k] != k) ok = 0;
    CHECK(ok, "z lt 0.5 selects nodes 0..24");
    CHECK(amps_mesh_select(&ctx, m, 2, AMPS_GT, 2.5, NULL) == 25, "z gt 2.5");
    CHECK(amps_mesh_select(&ctx, m, 0, AMPS_LT, 1.0, NULL) == 20, "x lt 1 (strict)");
    CHECK(amps_mesh_select(&ctx, m, 1, AMPS_GT, -1, NULL) == 100, "y gt -1");
    CHECK(amps_mesh_select(&ctx, m, 3, AMPS_LT, 0, NULL) == -1 && ctx.status == AMPS_ERR_ARG &&
                  strstr(ctx.msg, "axis 3"),
          "bad axis: %s", ctx.msg);
    memset(fixed, 0, sizeof(fixed));
    n = amps_mesh_select(&ctx, m, 2, AMPS_LT, 0.5, out);
    for (k = 0; k < n; k++) fixed[out[k]] = 1;
    CHECK(amps_mesh_number_dofs(m, fixed, dof) == 225 && dof[0] == -1 && dof[74] == -1 && dof[75] == 0 &&
                  dof[299] == 224,
          "number_dofs");
    amps_mesh_free(&ctx, m);
}

/* ---- assembly ---- */

/* amps_mesh_beam / amps_mesh_brick are fe_util's meshes node for node and tet for tet; their
   assembled matrices agree (dof from fe_number, bottom or x = 0 face fixed). */
static void test_fe_util_meshes(void) {
    amps_ctx ctx;
    int which, k;
    amps_ctx_init(&ctx);
    for (which = 0; which < 4; which++) {
        fe_mesh f = which < 2 ? fe_beam(3 + 2 * which) : fe_brick(which - 1);
        amps_mesh *m = which < 2 ? amps_mesh_beam(&ctx, 3 + 2 * which) : amps_mesh_brick(&ctx, which - 1);
        int *fixed = (int *)calloc((size_t)f.nn, sizeof(int)), *fdof = (int *)malloc(sizeof(int) * 3 * f.nn), ndof,
            same = 1;
        amps_int *dof = (amps_int *)malloc(sizeof(amps_int) * 3 * f.nn);
        double *x1 = (double *)malloc(sizeof(double) * 3 * f.nn);
        CHECK(m && m->nnode == f.nn && m->ntet == f.nt, "mesh %d counts", which);
        if (!m || m->nnode != f.nn || m->ntet != f.nt) {
            fe_free(&f);
            free(fixed);
            free(fdof);
            free(dof);
            free(x1);
            amps_mesh_free(&ctx, m);
            continue;
        }
        for (k = 0; k < 3 * f.nn; k++) x1[k] = m->xyz[k];
        CHECK(t_reldiff(3 * f.nn, x1, f.xyz) == 0, "mesh %d coordinates", which);
        for (k = 0; k < 4 * f.nt; k++)
            if (m->tet[k] != f.tet[k]) same = 0;
        CHECK(same, "mesh %d tets", which);
        for (k = 0; k < f.nn; k++) fixed[k] = which < 2 ? f.xyz[3 * k + 2] == 0 : f.xyz[3 * k] == 0;
        ndof = fe_number(&f, fixed, fdof);
        for (k = 0; k < 3 * f.nn; k++) dof[k] = fdof[k];
        amps_mesh_set_material(&ctx, m, 3.0, 0.35);
        t_compare_assembly(&ctx, m, dof, ndof, 3.0, 0.35, which < 2 ? "fe_beam" : "fe_brick");
        fe_free(&f);
        free(fixed);
        free(fdof);
        free(dof);
        free(x1);
        amps_mesh_free(&ctx, m);
    }
}

static void test_assembly(void) {
    amps_ctx ctx;
    amps_mesh *m;
    amps_int *dof, ndof, k, n;
    unsigned char *fixed;
    amps_ctx_init(&ctx);
    t_seed(3);
    /* beam, bottom fixed, node order */
    m = amps_mesh_beam(&ctx, 5);
    if (!m) {
        CHECK(0, "beam");
        return;
    }
    amps_mesh_set_material(&ctx, m, 1000, 0.3);
    dof = (amps_int *)malloc(sizeof(amps_int) * 3 * m->nnode);
    fixed = (unsigned char *)calloc((size_t)m->nnode, 1);
    for (k = 0; k < m->nnode; k++) fixed[k] = m->xyz[3 * k + 2] < 0.5;
    ndof = amps_mesh_number_dofs(m, fixed, dof);
    t_compare_assembly(&ctx, m, dof, ndof, 1000, 0.3, "beam fixed bottom");
    /* random equation numbering with some DOFs (single components) eliminated */
    n = 0;
    for (k = 0; k < 3 * m->nnode; k++) dof[k] = (t_int(7) == 0) ? -1 : n++;
    for (k = 3 * m->nnode - 1; k > 0; k--) {
        amps_int j = t_int((int)k + 1), s = dof[k];
        dof[k] = dof[j];
        dof[j] = s;
    }
    t_compare_assembly(&ctx, m, dof, n, 1000, 0.3, "beam random numbering");
    /* errors: out-of-range and duplicate equations */
    ndof = amps_mesh_number_dofs(m, NULL, dof);
    dof[5] = ndof;
    CHECK(!amps_mesh_assemble(&ctx, m, dof, ndof) && ctx.status == AMPS_ERR_INDEX, "dof out of range");
    dof[5] = 4;
    CHECK(!amps_mesh_assemble(&ctx, m, dof, ndof) && ctx.status == AMPS_ERR_ARG && strstr(ctx.msg, "equation 4"),
          "duplicate: %s", ctx.msg);
    CHECK(!amps_mesh_assemble(&ctx, m, dof, -1) && ctx.status == AMPS_ERR_ARG, "negative ndof");
    /* a gap in the numbering gives an empty column */
    ndof = amps_mesh_number_dofs(m, NULL, dof);
    for (k = 0; k < 3 * m->nnode; k++) dof[k] += 1;
    {
        amps_csc *A = amps_mesh_assemble(&ctx, m, dof, ndof + 1);
        CHECK(A && A->p[1] == 0 && A->p[2] == 1, "empty column 0");
        amps_csc_free(&ctx, A);
    }
    free(dof);
    free(fixed);
    amps_mesh_free(&ctx, m);

    /* brick, x = 0 face fixed, other material */
    m = amps_mesh_brick(&ctx, 3);
    if (!m) {
        CHECK(0, "brick");
        return;
    }
    amps_mesh_set_material(&ctx, m, 2.5, 0.45);
    dof = (amps_int *)malloc(sizeof(amps_int) * 3 * m->nnode);
    fixed = (unsigned char *)calloc((size_t)m->nnode, 1);
    for (k = 0; k < m->nnode; k++) fixed[k] = m->xyz[3 * k] < 1e-9;
    ndof = amps_mesh_number_dofs(m, fixed, dof);
    t_compare_assembly(&ctx, m, dof, ndof, 2.5, 0.45, "brick fixed x=0");
    ndof = amps_mesh_number_dofs(m, NULL, dof);
    t_compare_assembly(&ctx, m, dof, ndof, 2.5, 0.45, "brick free");
    /* per-tet material: doubling E everywhere doubles K */
    {
        amps_csc *A = amps_mesh_assemble(&ctx, m, dof, ndof), *B;
        amps_int t;
        double md = 0;
        for (t = 0; t < m->ntet; t++) amps_mesh_set_tet_material(&ctx, m, t, 5.0, 0.45);
        B = amps_mesh_assemble(&ctx, m, dof, ndof);
        if (A && B)
            for (k = 0; k < A->p[ndof]; k++)
                if (fabs(B->x[k] - 2 * A->x[k]) > md) md = fabs(B->x[k] - 2 * A->x[k]);
        CHECK(A && B && md < 1e-12, "per-tet material: %g", md);
        amps_csc_free(&ctx, A);
        amps_csc_free(&ctx, B);
    }
    free(dof);
    free(fixed);
    amps_mesh_free(&ctx, m);
}

/* ---- patch test and uniaxial stress ---- */

static void test_patch(void) {
    amps_ctx ctx;
    amps_mesh *m;
    amps_int *dof, ndof, v, t;
    amps_csc *K;
    double A[9], b[3], *u, *f, eps[6], worst = 0, fmax = 0, fint = 0, sum[3] = {0, 0, 0};
    int k;
    amps_ctx_init(&ctx);
    t_seed(4);
    m = amps_mesh_brick(&ctx, 3);
    if (!m) {
        CHECK(0, "brick");
        return;
    }
    amps_mesh_set_material(&ctx, m, 7, 0.3);
    for (k = 0; k < 9; k++) A[k] = t_unif() - 0.5;
    for (k = 0; k < 3; k++) b[k] = t_unif();
    u = (double *)malloc(sizeof(double) * 3 * m->nnode);
    f = (double *)malloc(sizeof(double) * 3 * m->nnode);
    dof = (amps_int *)malloc(sizeof(amps_int) * 3 * m->nnode);
    for (v = 0; v < m->nnode; v++)
        for (k = 0; k < 3; k++)
            u[3 * v + k] = A[3 * k] * m->xyz[3 * v] + A[3 * k + 1] * m->xyz[3 * v + 1] +
                           A[3 * k + 2] * m->xyz[3 * v + 2] + b[k];
    /* constant strain = sym(A) in every tet */
    for (t = 0; t < m->ntet; t++) {
        double X[12], ue[12];
        int a, c;
        amps_mesh_tet_coords(m, t, X);
        for (a = 0; a < 4; a++)
            for (c = 0; c < 3; c++) ue[3 * a + c] = u[3 * m->tet[4 * t + a] + c];
        amps_tet_strain(X, ue, eps);
        {
            double want[6] = {A[0], A[4], A[8], A[1] + A[3], A[5] + A[7], A[2] + A[6]};
            for (c = 0; c < 6; c++)
                if (fabs(eps[c] - want[c]) > worst) worst = fabs(eps[c] - want[c]);
        }
    }
    CHECK(worst < 1e-13, "patch: strain not constant (%g)", worst);
    /* zero residual at interior nodes */
    ndof = amps_mesh_number_dofs(m, NULL, dof);
    K = amps_mesh_assemble(&ctx, m, dof, ndof);
    if (K) {
        t_symv(K, u, f);
        for (v = 0; v < m->nnode; v++) {
            const double *x = m->xyz + 3 * v;
            int interior =
                    x[0] > 1e-9 && x[0] < 1 - 1e-9 && x[1] > 1e-9 && x[1] < 1 - 1e-9 && x[2] > 1e-9 && x[2] < 2 - 1e-9;
            for (k = 0; k < 3; k++) {
                if (interior && fabs(f[3 * v + k]) > fint) fint = fabs(f[3 * v + k]);
                if (fabs(f[3 * v + k]) > fmax) fmax = fabs(f[3 * v + k]);
                sum[k] += f[3 * v + k];
            }
        }
        CHECK(fmax > 1e-3, "patch: boundary forces expected");
        CHECK(fint < 1e-12 * fmax, "patch: interior residual %g (boundary %g)", fint, fmax);
        CHECK(t_maxabs(3, sum) < 1e-12 * fmax, "patch: net force %g", t_maxabs(3, sum));
        amps_csc_free(&ctx, K);
    } else CHECK(0, "assemble: %s", ctx.msg);

    /* uniaxial stress s along z: u = (-nu s/E x, -nu s/E y, s/E z) */
    {
        double E = 7, nu = 0.3, s = -2.5, *vm = (double *)malloc(sizeof(double) * m->ntet);
        double *pr = (double *)malloc(sizeof(double) * 3 * m->ntet),
               *sig = (double *)malloc(sizeof(double) * 6 * m->ntet);
        double err = 0;
        for (v = 0; v < m->nnode; v++) {
            u[3 * v] = -nu * s / E * m->xyz[3 * v];
            u[3 * v + 1] = -nu * s / E * m->xyz[3 * v + 1];
            u[3 * v + 2] = s / E * m->xyz[3 * v + 2];
        }
        CHECK(amps_mesh_stress(&ctx, m, u, sig, vm, pr) == AMPS_OK, "mesh stress");
        for (t = 0; t < m->ntet; t++) {
            double want[6] = {0, 0, s, 0, 0, 0};
            for (k = 0; k < 6; k++)
                if (fabs(sig[6 * t + k] - want[k]) > err) err = fabs(sig[6 * t + k] - want[k]);
            if (fabs(vm[t] - fabs(s)) > err) err = fabs(vm[t] - fabs(s));
            if (fabs(pr[3 * t] - 0) > err) err = fabs(pr[3 * t]);
            if (fabs(pr[3 * t + 1] - 0) > err) err = fabs(pr[3 * t + 1]);
            if (fabs(pr[3 * t + 2] - s) > err) err = fabs(pr[3 * t + 2] - s);
        }
        CHECK(err < 1e-13, "uniaxial stress error %g", err);
        /* single tet, tension, and a pure shear for von Mises = sqrt(3) tau */
        {
            double X[12], ue[12], sg[6], vmt, prt[3], tau = 0.7, G = E / (2 * (1 + nu));
            int a;
            t_rand_tet(X);
            for (a = 0; a < 4; a++) {
                ue[3 * a] = -nu * 3 / E * X[3 * a];
                ue[3 * a + 1] = -nu * 3 / E * X[3 * a + 1];
                ue[3 * a + 2] = 3 / E * X[3 * a + 2];
            }
            amps_tet_stress(X, E, nu, ue, sg, &vmt, prt);
            CHECK(fabs(sg[2] - 3) < 1e-13 && fabs(vmt - 3) < 1e-13 && fabs(prt[0] - 3) < 1e-13 && fabs(prt[2]) < 1e-13,
                  "tension");
            for (a = 0; a < 4; a++) {
                ue[3 * a] = tau / G * X[3 * a + 1];
                ue[3 * a + 1] = 0;
                ue[3 * a + 2] = 0;
            }
            amps_tet_stress(X, E, nu, ue, sg, &vmt, NULL);
            CHECK(fabs(sg[3] - tau) < 1e-13 && fabs(vmt - sqrt(3.0) * tau) < 1e-13, "shear: sxy %g vm %g", sg[3], vmt);
        }
        free(vm);
        free(pr);
        free(sig);
    }
    free(u);
    free(f);
    free(dof);
    amps_mesh_free(&ctx, m);
}

/* ---- cuts ---- */

typedef struct t_snap {
    amps_int nnode, ntet, cap;
    amps_int *tet, *inc, *ptr, *len, *org;
} t_snap;
static t_snap t_snap_take(const amps_mesh *m) {
    t_snap s;
    s.nnode = m->nnode;
    s.ntet = m->ntet;
    s.cap = m->node_cap;
    s.tet = (amps_int *)malloc(sizeof(amps_int) * 4 * m->ntet);
    memcpy(s.tet, m->tet, sizeof(amps_int) * 4 * m->ntet);
    s.inc = (amps_int *)malloc(sizeof(amps_int) * 4 * m->ntet);
    memcpy(s.inc, m->inc, sizeof(amps_int) * 4 * m->ntet);
    s.ptr = (amps_int *)malloc(sizeof(amps_int) * m->nnode);
    memcpy(s.ptr, m->inc_ptr, sizeof(amps_int) * m->nnode);
    s.len = (amps_int *)malloc(sizeof(amps_int) * m->nnode);
    memcpy(s.len, m->inc_len, sizeof(amps_int) * m->nnode);
    s.org = (amps_int *)malloc(sizeof(amps_int) * m->nnode);
    memcpy(s.org, m->origin, sizeof(amps_int) * m->nnode);
    return s;
}
static int t_snap_same(const t_snap *s, const amps_mesh *m) {
    return s->nnode == m->nnode && s->ntet == m->ntet && !memcmp(s->tet, m->tet, sizeof(amps_int) * 4 * m->ntet) &&
           !memcmp(s->inc, m->inc, sizeof(amps_int) * 4 * m->ntet) &&
           !memcmp(s->ptr, m->inc_ptr, sizeof(amps_int) * m->nnode) &&
           !memcmp(s->len, m->inc_len, sizeof(amps_int) * m->nnode) &&
           !memcmp(s->org, m->origin, sizeof(amps_int) * m->nnode);
}
static void t_snap_free(t_snap *s) {
    free(s->tet);
    free(s->inc);
    free(s->ptr);
    free(s->len);
    free(s->org);
}

static double t_side(const amps_mesh *m, amps_int t, const double p[3], const double n[3]) {
    double s = 0;
    int c;
    for (c = 0; c < 3; c++) {
        double x = 0.25 * (m->xyz[3 * m->tet[4 * t] + c] + m->xyz[3 * m->tet[4 * t + 1] + c] +
                           m->xyz[3 * m->tet[4 * t + 2] + c] + m->xyz[3 * m->tet[4 * t + 3] + c]);
        s += (x - p[c]) * n[c];
    }
    return s;
}

/* Cuts v and checks the result against a brute-force evaluation of the rule. */
static void t_cut_check(amps_ctx *ctx, amps_mesh *m, amps_int v, const double p[3], const double n[3],
                        const char *what) {
    amps_int deg, nm = -5, vc = -5, moved[256], want[256], nw = 0, k, before = m->nnode, ok = 1, keep;
    const amps_int *inc = amps_mesh_incident(m, v, &deg);
    amps_status s;
    for (k = 0; k < deg; k++)
        if (t_side(m, inc[k], p, n) < 0) want[nw++] = inc[k];
    keep = deg - nw;
    s = amps_mesh_cut(ctx, m, v, p, n, &vc, moved, &nm);
    if (nw == 0 || nw == deg) {
        CHECK(s == AMPS_WARN_NOOP && nm == 0 && vc == -1 && m->nnode == before, "%s: expected a no-op", what);
        return;
    }
    CHECK(s == AMPS_OK && vc == before && m->nnode == before + 1 && nm == nw, "%s: cut failed (%d: %s)", what, (int)s,
          ctx->msg);
    if (s != AMPS_OK) return;
    for (k = 0; k < nw; k++)
        if (moved[k] != want[k]) ok = 0;
    CHECK(ok, "%s: wrong tets moved", what);
    for (k = 0; k < nw; k++) {
        const amps_int *tv = m->tet + 4 * moved[k];
        if (!(tv[0] == vc || tv[1] == vc || tv[2] == vc || tv[3] == vc) || tv[0] == v || tv[1] == v || tv[2] == v ||
            tv[3] == v)
            ok = 0;
    }
    CHECK(ok, "%s: moved tets do not use the copy", what);
    CHECK(m->origin[vc] == m->origin[v] && m->xyz[3 * vc] == m->xyz[3 * v] && m->xyz[3 * vc + 2] == m->xyz[3 * v + 2],
          "%s: copy", what);
    CHECK(amps_mesh_degree(m, v) == keep && amps_mesh_degree(m, vc) == nw, "%s: degrees", what);
    CHECK(amps_mesh_check(ctx, m) == AMPS_OK, "%s: check: %s", what, ctx->msg);
}

static void test_cut(void) {
    amps_ctx ctx;
    amps_mesh *m;
    amps_int moved[64], nm, vc, k;
    amps_ctx_init(&ctx);
    /* two tets sharing the face 1 2 3 */
    {
        double xyz[15] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 1, 1, 1};
        amps_int tet[8] = {0, 1, 2, 3, 4, 1, 2, 3};
        double p[3] = {0.5, 0.5, 0.5}, n[3] = {1, 1, 1}, nn[3] = {-1, -1, -1}, far[3] = {-10, 0, 0}, x1[3] = {1, 0, 0};
        double pc[3] = {0.25, 0.25, 0.25}; /* centroid of tet 0: exact tie */
        t_snap sn;
        m = amps_mesh_create(&ctx, 5, xyz, 2, tet);
        if (!m) {
            CHECK(0, "create");
            return;
        }
        sn = t_snap_take(m);
        CHECK(amps_mesh_cut(&ctx, m, 1, far, x1, &vc, moved, &nm) == AMPS_WARN_NOOP && nm == 0 && vc == -1 &&
                      t_snap_same(&sn, m),
              "no-op: all on + side");
        CHECK(ctx.status == AMPS_WARN_NOOP && strstr(ctx.msg, "node 1"), "no-op message: %s", ctx.msg);
        CHECK(amps_mesh_cut(&ctx, m, 1, far, nn, &vc, moved, &nm) == AMPS_WARN_NOOP && t_snap_same(&sn, m),
              "no-op: all on - side");
        CHECK(amps_mesh_cut(&ctx, m, 0, p, n, &vc, moved, &nm) == AMPS_WARN_NOOP && t_snap_same(&sn, m),
              "no-op: degree 1");
        CHECK(amps_mesh_cut(&ctx, m, 1, pc, n, &vc, moved, &nm) == AMPS_WARN_NOOP && t_snap_same(&sn, m),
              "tie keeps v -> no-op");
        CHECK(amps_mesh_cut(&ctx, m, 5, p, n, &vc, moved, &nm) == AMPS_ERR_INDEX && t_snap_same(&sn, m), "invalid v");
        CHECK(amps_mesh_cut(&ctx, m, -1, p, n, &vc, moved, &nm) == AMPS_ERR_INDEX, "negative v");
        {
            double z[3] = {0, 0, 0}, nan3[3] = {0, 0, 0};
            nan3[1] = z[0] / z[0];
            CHECK(amps_mesh_cut(&ctx, m, 1, p, z, &vc, moved, &nm) == AMPS_ERR_ARG, "zero normal");
            CHECK(amps_mesh_cut(&ctx, m, 1, p, nan3, &vc, moved, &nm) == AMPS_ERR_VALUE, "NaN normal");
            CHECK(amps_mesh_cut(&ctx, m, 1, nan3, n, &vc, moved, &nm) == AMPS_ERR_VALUE, "NaN point");
        }
        CHECK(amps_mesh_cut(&ctx, m, 1, p, n, &vc, NULL, &nm) == AMPS_ERR_ARG && t_snap_same(&sn, m), "moved NULL");
        t_snap_free(&sn);
        /* tie at tet 0's centroid with normal -n: tet 1 (centroid on the + side of n) moves, tet 0 stays */
        CHECK(amps_mesh_cut(&ctx, m, 2, pc, nn, &vc, moved, &nm) == AMPS_OK && nm == 1 && moved[0] == 1 && vc == 5,
              "tie: %s", ctx.msg);
        CHECK(m->tet[4] == 4 && m->tet[6] == 5 && m->tet[2] == 2 && m->origin[5] == 2 && m->nfile == 5,
              "tets after cut");
        /* cut node 1 with the plane between the centroids: tet 0 moves */
        t_cut_check(&ctx, m, 1, p, n, "two tets node 1");
        CHECK(m->nnode == 7 && m->tet[1] == 6 && m->origin[6] == 1, "second cut");
        /* node 3: separated; a copy of a copy keeps the file origin */
        {
            double p2[3] = {0.4, 0.4, 0.4};
            t_cut_check(&ctx, m, 3, p2, nn, "two tets node 3");
        }
        CHECK(m->nnode == 8 && m->origin[7] == 3 && m->tet[7] == 7, "third cut moved tet 1");
        amps_mesh_free(&ctx, m);
    }
    /* beam: cut interior node with several planes, then the copy again */
    {
        double p[3], n[3];
        amps_int v = 2 + 5 * (2 + 5 * 2), c1;
        m = amps_mesh_beam(&ctx, 5);
        if (!m) {
            CHECK(0, "beam");
            return;
        }
        CHECK(amps_mesh_degree(m, v) == 24, "interior Kuhn node degree %d", (int)amps_mesh_degree(m, v));
        p[0] = 2;
        p[1] = 2;
        p[2] = 2;
        n[0] = 0;
        n[1] = 0;
        n[2] = 1;
        t_cut_check(&ctx, m, v, p, n, "beam z plane");
        CHECK(amps_mesh_degree(m, v) == 12, "half the tets stay");
        c1 = m->nnode - 1;
        n[0] = 1;
        n[1] = 0.3;
        n[2] = 0;
        t_cut_check(&ctx, m, c1, p, n, "beam cut the copy");
        CHECK(m->origin[m->nnode - 1] == v && m->nnode == 127, "copy of copy origin");
        n[0] = 0.2;
        n[1] = -1;
        n[2] = 0.1;
        t_cut_check(&ctx, m, v, p, n, "beam cut v again");
        for (k = 0; k < 40; k++) { /* random planes through random nodes */
            amps_int w = t_int((int)m->nnode);
            int c;
            for (c = 0; c < 3; c++) {
                p[c] = m->xyz[3 * w + c] + (t_unif() - 0.5);
                n[c] = t_unif() - 0.5;
            }
            t_cut_check(&ctx, m, w, p, n, "beam random");
        }
        amps_mesh_free(&ctx, m);
    }
    /* full crack through the beam at z = 2: the part above floats free */
    {
        double p[3] = {0, 0, 2}, n[3] = {0, 0, 1}, *u, *f, fmax = 0;
        amps_int v, *dof, ndof, ncut = 0;
        unsigned char *fixed;
        amps_csc *K;
        m = amps_mesh_beam(&ctx, 5);
        if (!m) {
            CHECK(0, "beam");
            return;
        }
        for (v = 0; v < 125; v++)
            if (m->xyz[3 * v + 2] == 2.0 && amps_mesh_cut(&ctx, m, v, p, n, &vc, moved, &nm) == AMPS_OK) ncut++;
        CHECK(ncut == 25 && m->nnode == 150 && amps_mesh_check(&ctx, m) == AMPS_OK, "crack: %d cuts", (int)ncut);
        dof = (amps_int *)malloc(sizeof(amps_int) * 3 * m->nnode);
        fixed = (unsigned char *)calloc((size_t)m->nnode, 1);
        u = (double *)calloc((size_t)(3 * m->nnode), sizeof(double));
        f = (double *)calloc((size_t)(3 * m->nnode), sizeof(double));
        for (v = 0; v < m->nnode; v++) fixed[v] = m->xyz[3 * v + 2] < 0.5;
        ndof = amps_mesh_number_dofs(m, fixed, dof);
        K = amps_mesh_assemble(&ctx, m, dof, ndof);
        /* translate the upper part (nodes at z > 2, and the layer z = 2 that the upper tets kept) */
        for (v = 0; v < m->nnode; v++)
            if (dof[3 * v] >= 0 && (m->xyz[3 * v + 2] > 2 || (m->xyz[3 * v + 2] == 2 && v < 125)))
                u[dof[3 * v + 1]] = 1;
        if (K) {
            t_symv(K, u, f);
            fmax = t_maxabs((int)ndof, f);
            CHECK(fmax < 1e-12, "crack: upper part not free (residual %g)", fmax);
            amps_csc_free(&ctx, K);
        } else CHECK(0, "assemble after cuts: %s", ctx.msg);
        free(dof);
        free(fixed);
        free(u);
        free(f);
        amps_mesh_free(&ctx, m);
    }
}

/* ---- allocation behaviour ---- */

static void test_alloc(void) {
    amps_ctx ctx;
    amps_mesh *m;
    amps_int moved[64], nm, vc, *dof, ndof, k;
    long base, calls;
    double p[3] = {2, 2, 2}, n[3] = {0, 0, 1};
    amps_status s;
    int fails;
    amps_ctx_init(&ctx);
    ctx.alloc_user = &t_al;
    base = t_al.live;
    /* no allocation when the capacity suffices */
    m = amps_mesh_beam(&ctx, 5);
    if (!m) {
        CHECK(0, "beam");
        return;
    }
    CHECK(amps_mesh_reserve(&ctx, m, m->nnode + 10) == AMPS_OK && m->node_cap == 135, "reserve");
    calls = t_al.calls;
    for (k = 0; k < 10; k++) {
        amps_int v = (1 + k % 3) + 5 * (1 + (k / 3) % 3) + 25 * (1 + k / 9);
        p[2] = m->xyz[3 * v + 2];
        amps_mesh_cut(&ctx, m, v, p, n, &vc, moved, &nm);
    }
    CHECK(m->nnode == 135 && t_al.calls == calls, "cuts within capacity allocated %ld times", t_al.calls - calls);
    /* growth failure leaves the mesh unchanged; the next cut grows */
    {
        t_snap sn = t_snap_take(m);
        amps_int v = 12 + 25 * 3;
        p[2] = 3;
        t_al.fail_at = 2; /* third array of the growth */
        s = amps_mesh_cut(&ctx, m, v, p, n, &vc, moved, &nm);
        CHECK(s == AMPS_ERR_OOM && t_snap_same(&sn, m) && m->node_cap == 135 && vc == -1 && nm == 0,
              "growth failure: %d", (int)s);
        CHECK(amps_mesh_check(&ctx, m) == AMPS_OK, "check after failed growth");
        t_al.fail_at = -1;
        s = amps_mesh_cut(&ctx, m, v, p, n, &vc, moved, &nm);
        CHECK(s == AMPS_OK && m->nnode == 136 && m->node_cap > 136 && amps_mesh_check(&ctx, m) == AMPS_OK, "growth");
        t_snap_free(&sn);
    }
    amps_mesh_free(&ctx, m);
    CHECK(t_al.live == base, "leak after cuts: %ld", t_al.live - base);
    /* every allocation failure in construction and assembly: clean NULL, nothing leaked */
    for (fails = 0, k = 0; k < 100; k++) {
        t_al.fail_at = k;
        m = amps_mesh_brick(&ctx, 2);
        t_al.fail_at = -1;
        if (m) break;
        fails++;
        if (ctx.status != AMPS_ERR_OOM || t_al.live != base) {
            CHECK(0, "brick failure %d: status %d, leak %ld", (int)k, (int)ctx.status, t_al.live - base);
            break;
        }
    }
    CHECK(m && fails > 5, "brick after %d failures", fails);
    if (!m) return;
    dof = (amps_int *)malloc(sizeof(amps_int) * 3 * m->nnode);
    ndof = amps_mesh_number_dofs(m, NULL, dof);
    for (fails = 0, k = 0; k < 100; k++) {
        long live = t_al.live;
        amps_csc *A;
        t_al.fail_at = k;
        A = amps_mesh_assemble(&ctx, m, dof, ndof);
        t_al.fail_at = -1;
        if (A) {
            amps_csc_free(&ctx, A);
            break;
        }
        fails++;
        if (ctx.status != AMPS_ERR_OOM || t_al.live != live) {
            CHECK(0, "assemble failure %d: leak", (int)k);
            break;
        }
    }
    CHECK(fails >= 5, "assemble failure paths: %d", fails);
    CHECK(amps_mesh_check(&ctx, m) == AMPS_OK, "check");
    free(dof);
    amps_mesh_free(&ctx, m);
    CHECK(t_al.live == base, "leak: %ld", t_al.live - base);
}

int main(void) {
    test_element();
    test_eig();
    test_mesh_create();
    test_check();
    test_select();
    test_fe_util_meshes();
    test_assembly();
    test_patch();
    test_cut();
    test_alloc();
    return amps_t_end("test_fem");
}
