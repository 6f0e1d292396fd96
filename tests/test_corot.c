/* Corotational FEM (paper "GPU-accelerated surgery simulation for opening a brain fissure",
   Corotational FEM and Appendix A-B): the rotation kernel against a long double one-sided Jacobi
   SVD written here (random, near-singular, rank 1 and 2, reflected F), and the corotational step
   of the scene against CHOLMOD's solve of the step's A_R and b assembled here from scratch. */
static int t_identity = 0; /* 1: the scene takes every R_e = I (the hook of amps.h) */
#define AMPS_TEST_COROT_IDENTITY t_identity
/* Gauss-Seidel slabs of 16 nodes (3,000 by default), so that the small meshes here run the
   sweeps on several slabs and an interface, and the threads test on 16 slabs. */
#define AMPS__CR_SLAB 16
#define AMPS_IMPLEMENTATION
#include "amps.h"
#include "amps_test.h"
#include "cholmod_ref.h"
#include "scene_ref.h"
#include <string.h>

/* ---- reference SVD: one-sided Jacobi in long double ---- */

/* F = U diag(s) V^T (row-major 3x3), s descending >= 0, U and V orthogonal (either sign). */
static void ref_svd(const double F[9], long double U[9], long double s[3], long double V[9]) {
    long double W[9], Vt[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1}, n[3];
    int sweep, p, q, i, k, ord[3] = {0, 1, 2};
    for (i = 0; i < 9; i++) W[i] = F[i];
    for (sweep = 0; sweep < 60; sweep++) {
        int rot = 0;
        for (p = 0; p < 2; p++)
            for (q = p + 1; q < 3; q++) {
                long double al = 0, be = 0, ga = 0, z, t, c, sn;
                for (i = 0; i < 3; i++) {
                    al += W[3 * i + p] * W[3 * i + p];
                    be += W[3 * i + q] * W[3 * i + q];
                    ga += W[3 * i + p] * W[3 * i + q];
                }
                if (ga == 0 || fabsl(ga) <= 1e-19L * sqrtl(al * be)) continue;
                rot = 1;
                z = (be - al) / (2 * ga);
                t = (z >= 0 ? 1 : -1) / (fabsl(z) + sqrtl(1 + z * z));
                c = 1 / sqrtl(1 + t * t);
                sn = c * t;
                for (i = 0; i < 3; i++) {
                    long double wp = W[3 * i + p], wq = W[3 * i + q], vp = Vt[3 * i + p], vq = Vt[3 * i + q];
                    W[3 * i + p] = c * wp - sn * wq;
                    W[3 * i + q] = sn * wp + c * wq;
                    Vt[3 * i + p] = c * vp - sn * vq;
                    Vt[3 * i + q] = sn * vp + c * vq;
                }
            }
        if (!rot) break;
    }
    for (k = 0; k < 3; k++) n[k] = sqrtl(W[k] * W[k] + W[3 + k] * W[3 + k] + W[6 + k] * W[6 + k]);
    for (p = 0; p < 2; p++)
        for (q = 0; q < 2 - p; q++)
            if (n[ord[q]] < n[ord[q + 1]]) {
                k = ord[q];
                ord[q] = ord[q + 1];
                ord[q + 1] = k;
            }
    for (k = 0; k < 3; k++) {
        s[k] = n[ord[k]];
        for (i = 0; i < 3; i++) {
            V[3 * i + k] = Vt[3 * i + ord[k]];
            U[3 * i + k] = s[k] > 0 ? W[3 * i + ord[k]] / s[k] : 0;
        }
    }
    /* complete U where singular values vanish: u3 = u1 x u2 (rank 2) */
    if (!(s[2] > 1e-30L * s[0])) {
        U[2] = U[3] * U[7] - U[6] * U[4];
        U[5] = U[6] * U[1] - U[0] * U[7];
        U[8] = U[0] * U[4] - U[3] * U[1];
    }
}

static long double det3l(const long double A[9]) {
    return A[0] * (A[4] * A[8] - A[5] * A[7]) - A[1] * (A[3] * A[8] - A[5] * A[6]) + A[2] * (A[3] * A[7] - A[4] * A[6]);
}

/* R_ref = U diag(1, 1, det(U V^T)) V^T; *gap receives min over pairs of (s_i + s'_j) with s'_3 =
   sign(det F) s_3: the scale at which R is sensitive to F; *best the maximum of tr(R^T F). */
static void ref_rotation(const double F[9], double R[9], double *gap, double *best) {
    long double U[9], s[3], V[9], d, s3;
    int i, j;
    ref_svd(F, U, s, V);
    d = det3l(U) * det3l(V) < 0 ? -1 : 1;
    for (i = 0; i < 3; i++)
        for (j = 0; j < 3; j++)
            R[3 * i + j] =
                    (double)(U[3 * i] * V[3 * j] + U[3 * i + 1] * V[3 * j + 1] + d * U[3 * i + 2] * V[3 * j + 2]);
    s3 = d * s[2];
    *gap = (double)(s[1] + s3 < s[0] + s[1] ? s[1] + s3 : s[0] + s[1]);
    *best = (double)(s[0] + s[1] + s3);
}

/* F = D_s D_m^-1 of x against X. */
static void t_deform(const double X[12], const double x[12], double F[9]) {
    double G[12];
    int i, j, a;
    amps_tet_gradients(X, G);
    for (i = 0; i < 3; i++)
        for (j = 0; j < 3; j++) {
            F[3 * i + j] = 0;
            for (a = 1; a < 4; a++) F[3 * i + j] += (x[3 * a + i] - x[i]) * G[3 * a + j];
        }
}

/* Random orthogonal matrix (det = sign) from a random unit quaternion. */
static void t_rot(double Q[9], int sign) {
    double q[4], l = 0;
    int k;
    for (k = 0; k < 4; k++) {
        q[k] = 2 * t_unif() - 1;
        l += q[k] * q[k];
    }
    l = sqrt(l);
    for (k = 0; k < 4; k++) q[k] /= l;
    Q[0] = 1 - 2 * (q[2] * q[2] + q[3] * q[3]);
    Q[1] = 2 * (q[1] * q[2] - q[0] * q[3]);
    Q[2] = 2 * (q[1] * q[3] + q[0] * q[2]);
    Q[3] = 2 * (q[1] * q[2] + q[0] * q[3]);
    Q[4] = 1 - 2 * (q[1] * q[1] + q[3] * q[3]);
    Q[5] = 2 * (q[2] * q[3] - q[0] * q[1]);
    Q[6] = 2 * (q[1] * q[3] - q[0] * q[2]);
    Q[7] = 2 * (q[2] * q[3] + q[0] * q[1]);
    Q[8] = 1 - 2 * (q[1] * q[1] + q[2] * q[2]);
    if (sign < 0)
        for (k = 0; k < 3; k++) Q[3 * k + 2] = -Q[3 * k + 2];
}

/* F = P diag(s) Q^T with random orthogonal P, Q. */
static void t_make_F(const double s[3], int sign, double F[9]) {
    double P[9], Q[9];
    int i, j, k;
    t_rot(P, 1);
    t_rot(Q, sign);
    for (i = 0; i < 3; i++)
        for (j = 0; j < 3; j++) {
            F[3 * i + j] = 0;
            for (k = 0; k < 3; k++) F[3 * i + j] += P[3 * i + k] * s[k] * Q[3 * j + k];
        }
}

/* One F through amps_tet_rotation (a random reference tet, x = F X + c): R orthogonal with det 1,
   tr(R^T F) maximal, and R = R_ref to 1e-13 s1 / gap where R is well-defined. */
static void check_rotation(const double F[9], const char *what) {
    double X[12], x[12], Fm[9], R[9], Rr[9], gap, best, tr = 0, e = 0, o = 0, dt, sc = 0, c[3];
    int a, i, j, k;
    do {
        for (a = 0; a < 12; a++) X[a] = 2 * t_unif() - 1;
    } while (fabs(amps_tet_gradients(X, x)) < 0.05);
    for (i = 0; i < 3; i++) c[i] = 4 * t_unif() - 2;
    for (a = 0; a < 4; a++)
        for (i = 0; i < 3; i++) {
            x[3 * a + i] = c[i];
            for (j = 0; j < 3; j++) x[3 * a + i] += F[3 * i + j] * X[3 * a + j];
        }
    t_deform(X, x, Fm);
    dt = amps_tet_rotation(X, x, R);
    ref_rotation(Fm, Rr, &gap, &best);
    for (i = 0; i < 9; i++) {
        tr += R[i] * Fm[i];
        e = fmax(e, fabs(R[i] - Rr[i]));
        sc = fmax(sc, fabs(Fm[i]));
    }
    for (i = 0; i < 3; i++)
        for (j = 0; j < 3; j++) {
            double s = 0;
            for (k = 0; k < 3; k++) s += R[3 * k + i] * R[3 * k + j];
            o = fmax(o, fabs(s - (i == j)));
        }
    CHECK(o < 1e-14, "%s: R^T R - I = %.3g", what, o);
    CHECK(R[0] * (R[4] * R[8] - R[5] * R[7]) - R[1] * (R[3] * R[8] - R[5] * R[6]) + R[2] * (R[3] * R[7] - R[4] * R[6]) >
                  0.5,
          "%s: det R < 0", what);
    CHECK(fabs(tr - best) <= 1e-13 * (sc > 1 ? sc : 1) + 1e-12 * fabs(best), "%s: tr(R^T F) %.17g, max %.17g", what, tr,
          best);
    if (gap > 1e-6 * sc) CHECK(e <= 1e-13 * sc / gap + 1e-14, "%s: |R - R_ref| = %.3g (gap %.3g)", what, e, gap);
    {
        long double d = (long double)Fm[0] * ((long double)Fm[4] * Fm[8] - (long double)Fm[5] * Fm[7]) -
                        (long double)Fm[1] * ((long double)Fm[3] * Fm[8] - (long double)Fm[5] * Fm[6]) +
                        (long double)Fm[2] * ((long double)Fm[3] * Fm[7] - (long double)Fm[4] * Fm[6]);
        CHECK(fabsl(dt - d) <= 1e-13L * (sc * sc * sc + 1), "%s: det F %.17g, ref %.17Lg", what, dt, d);
    }
}

static void test_rotation_kernel(void) {
    double F[9], s[3], X[12] = {0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1}, x[12], R[9];
    int k, i, sign;
    t_seed(21);
    for (k = 0; k < 2000; k++) { /* random F, both orientations */
        sign = k % 2 ? -1 : 1;
        for (i = 0; i < 9; i++) F[i] = 4 * t_unif() - 2;
        if (sign < 0)
            for (i = 0; i < 3; i++) F[3 * i] = -F[3 * i];
        check_rotation(F, "random");
    }
    for (k = 0; k < 3000; k++) { /* prescribed singular values: near-singular, rank 1/2, clusters, reflected */
        int kind = k % 10;
        double sc = pow(10.0, 6 * t_unif() - 3);
        sign = (k / 10) % 2 ? -1 : 1;
        s[0] = 1;
        s[1] = t_unif();
        s[2] = t_unif() * s[1];
        if (kind == 1) s[2] = 1e-9 * t_unif();            /* near-singular */
        if (kind == 2) s[2] = 0;                          /* rank 2 */
        if (kind == 3) s[1] = s[2] = 0;                   /* rank 1 */
        if (kind == 4) s[1] = s[2] = 1e-12;               /* nearly rank 1 */
        if (kind == 5) s[1] = s[0], s[2] = 0.3;           /* double largest */
        if (kind == 6) s[2] = s[1] = 0.4;                 /* double smallest */
        if (kind == 7) s[0] = s[1] = s[2] = 1;            /* a rotation (reflection) */
        if (kind == 8) s[1] = 1 - 1e-9, s[2] = 1 - 2e-9;  /* nearly a rotation */
        if (kind == 9) s[0] = 1e8, s[1] = 1, s[2] = 1e-8; /* badly conditioned */
        for (i = 0; i < 3; i++) s[i] *= sc;
        t_make_F(s, sign, F);
        check_rotation(F, kind == 1 ? "near-singular" : kind == 2 ? "rank 2" : kind == 3 ? "rank 1" : "prescribed");
    }
    /* F = 0 and a degenerate reference give I */
    for (i = 0; i < 12; i++) x[i] = 0.5;
    amps_tet_rotation(X, x, R);
    CHECK(R[0] == 1 && R[4] == 1 && R[8] == 1 && R[1] == 0 && R[5] == 0, "F = 0: R = I");
    memcpy(x, X, sizeof(x));
    x[11] = 0; /* flat deformed tet: det F = 0, R still a rotation */
    CHECK(fabs(amps_tet_rotation(X, x, R)) < 1e-15, "flat: det F = 0");
    X[11] = 0; /* degenerate reference */
    CHECK(amps_tet_rotation(X, x, R) == 0.0 && R[0] == 1 && R[4] == 1 && R[8] == 1, "degenerate X: R = I, 0");
    X[11] = 1;
    x[0] = NAN;
    amps_tet_rotation(X, x, R);
    CHECK(R[0] == 1 && R[4] == 1 && R[8] == 1, "NaN: R = I");
}

/* ---- the corotational step against a reference assembled here ---- */

/* What the test knows of a scene: fixed file nodes, pins, forces (shadow), gravity, time step. */
typedef struct cref {
    shadow sh;
    double g[3], dt, alpha, beta;
} cref;

/* Ke = V B^T C B of reference tet X (E, nu), written out here. Returns V. */
static double ref_ke(const double X[12], double E, double nu, double Ke[144]) {
    double G[12], B[72], C[36], CB[72], V, lam = E * nu / ((1 + nu) * (1 - 2 * nu)), mu = E / (2 * (1 + nu));
    int a, i, j, k;
    V = fabs(amps_tet_gradients(X, G));
    memset(B, 0, sizeof(B));
    memset(C, 0, sizeof(C));
    for (a = 0; a < 4; a++) {
        const double *g = G + 3 * a;
        B[0 * 12 + 3 * a] = g[0];
        B[1 * 12 + 3 * a + 1] = g[1];
        B[2 * 12 + 3 * a + 2] = g[2];
        B[3 * 12 + 3 * a] = g[1];
        B[3 * 12 + 3 * a + 1] = g[0];
        B[4 * 12 + 3 * a + 1] = g[2];
        B[4 * 12 + 3 * a + 2] = g[1];
        B[5 * 12 + 3 * a] = g[2];
        B[5 * 12 + 3 * a + 2] = g[0];
    }
    for (i = 0; i < 3; i++) {
        for (j = 0; j < 3; j++) C[6 * i + j] = lam;
        C[6 * i + i] += 2 * mu;
        C[6 * (i + 3) + i + 3] = mu;
    }
    for (i = 0; i < 6; i++)
        for (j = 0; j < 12; j++) {
            CB[12 * i + j] = 0;
            for (k = 0; k < 6; k++) CB[12 * i + j] += C[6 * i + k] * B[12 * k + j];
        }
    for (i = 0; i < 12; i++)
        for (j = 0; j < 12; j++) {
            Ke[12 * i + j] = 0;
            for (k = 0; k < 6; k++) Ke[12 * i + j] += V * B[12 * k + i] * CB[12 * k + j];
        }
    return V;
}

/* One corotational step from (u, vel) of mesh m assembled from scratch: R_e by the reference SVD
   (identity: R = I), K_R = sum R_e Ke R_e^T, g = sum R_e Ke (R_e^T x_e - X_e), A_R = cM M + cK K_R,
   A_R w+ = M w + dt (f + M g_grav - g) with the pins w_P = (g_P - u_P) / dt eliminated, solved by
   CHOLMOD. uo, wo, react (3 per node) receive u+, w+ and (A_R w+ - b)_P / dt. 0 on success. */
static int ref_corot(amps_ctx *ctx, const amps_mesh *m, const cref *w, const double *u, const double *vel, int identity,
                     double *uo, double *wo, double *react) {
    int nn = (int)m->nnode, v, d, n, nf = 0, k, j, p, nz = 0, nt = 0, ok, a, c;
    unsigned char *fixed = (unsigned char *)calloc(nn + 1, 1);
    amps_int *dof = (amps_int *)malloc(sizeof(amps_int) * 3 * nn), *ti, *tj;
    double *mass = (double *)malloc(sizeof(double) * (nn + 1)), *gel = (double *)calloc(3 * nn + 1, sizeof(double));
    double cM = 1 + w->alpha * w->dt, cK = w->beta * w->dt + w->dt * w->dt, *b, *gv, *ax, *rhs, *x, *tx, *ue;
    int *map;
    amps_csc *A, *Rd;
    for (v = 0; v < nn; v++) fixed[v] = w->sh.fixed0[m->origin[v]];
    n = (int)amps_mesh_number_dofs(m, fixed, dof);
    amps_mesh_lumped_mass(m, mass);
    ti = (amps_int *)malloc(sizeof(amps_int) * (78 * m->ntet + n + 1));
    tj = (amps_int *)malloc(sizeof(amps_int) * (78 * m->ntet + n + 1));
    tx = (double *)malloc(sizeof(double) * (78 * m->ntet + n + 1));
    for (k = 0; k < m->ntet; k++) {
        double X[12], xx[12], F[9], R[9], gap, best, Ke[144], KR[144], T[144], dl[12], kd[12];
        amps_int e[12];
        if (m->removed && m->removed[k]) continue;
        amps_mesh_tet_coords(m, k, X);
        for (a = 0; a < 12; a++) xx[a] = X[a] + u[3 * m->tet[4 * k + a / 3] + a % 3];
        t_deform(X, xx, F);
        ref_rotation(F, R, &gap, &best);
        if (identity)
            for (a = 0; a < 9; a++) R[a] = a % 4 == 0;
        ref_ke(X, m->E[k], m->nu[k], Ke);
        for (a = 0; a < 12; a++) /* T = Ke Rb^T, KR = Rb T */
            for (c = 0; c < 12; c++) {
                double s = 0;
                for (j = 0; j < 3; j++) s += Ke[12 * a + 3 * (c / 3) + j] * R[3 * (c % 3) + j];
                T[12 * a + c] = s;
            }
        for (a = 0; a < 12; a++)
            for (c = 0; c < 12; c++) {
                double s = 0;
                for (j = 0; j < 3; j++) s += R[3 * (a % 3) + j] * T[12 * (3 * (a / 3) + j) + c];
                KR[12 * a + c] = s;
            }
        for (a = 0; a < 4; a++) /* dl = R^T x - X (per node), g_e = Rb Ke dl */
            for (j = 0; j < 3; j++) {
                dl[3 * a + j] = -X[3 * a + j];
                for (c = 0; c < 3; c++) dl[3 * a + j] += R[3 * c + j] * xx[3 * a + c];
            }
        for (a = 0; a < 12; a++) {
            kd[a] = 0;
            for (c = 0; c < 12; c++) kd[a] += Ke[12 * a + c] * dl[c];
        }
        for (a = 0; a < 4; a++)
            for (j = 0; j < 3; j++)
                for (c = 0; c < 3; c++) gel[3 * m->tet[4 * k + a] + j] += R[3 * j + c] * kd[3 * a + c];
        for (a = 0; a < 12; a++) e[a] = dof[3 * m->tet[4 * k + a / 3] + a % 3];
        for (a = 0; a < 12; a++)
            for (c = 0; c < 12; c++)
                if (e[a] >= 0 && e[c] >= 0 && e[a] <= e[c]) {
                    ti[nz] = e[a];
                    tj[nz] = e[c];
                    tx[nz++] = cK * KR[12 * a + c];
                }
        nt++;
    }
    b = (double *)calloc(n + 1, sizeof(double));
    gv = (double *)calloc(n + 1, sizeof(double));
    ax = (double *)calloc(n + 1, sizeof(double));
    ue = (double *)calloc(n + 1, sizeof(double));
    map = (int *)calloc(n + 1, sizeof(int));
    for (v = 0; v < nn; v++)
        for (d = 0; d < 3; d++) {
            int e = (int)dof[3 * v + d];
            if (e < 0) continue;
            ti[nz] = tj[nz] = e;
            tx[nz++] = cM * mass[v];
            b[e] = mass[v] * vel[3 * v + d] + w->dt * (w->sh.force[3 * v + d] + mass[v] * w->g[d] - gel[3 * v + d]);
            if (w->sh.pinned[v]) {
                map[e] = -1;
                gv[e] = (w->sh.pinval[3 * v + d] - u[3 * v + d]) / w->dt;
            }
        }
    A = amps_csc_from_triplets(ctx, n, nz, ti, tj, tx, AMPS_UPPER);
    for (k = 0; k < n; k++) map[k] = map[k] < 0 ? -1 : nf++;
    rhs = (double *)calloc(nf + 1, sizeof(double));
    x = (double *)calloc(nf + 1, sizeof(double));
    amps_csc_symv(A, AMPS_UPPER, gv, ax);
    for (k = 0; k < n; k++)
        if (map[k] >= 0) rhs[map[k]] = b[k] - ax[k];
    for (nz = 0, j = 0; j < n; j++)
        for (p = A->p[j]; p < A->p[j + 1]; p++)
            if (map[A->i[p]] >= 0 && map[j] >= 0) {
                ti[nz] = map[A->i[p]];
                tj[nz] = map[j];
                tx[nz++] = A->x[p];
            }
    Rd = amps_csc_from_triplets(ctx, nf, nz, ti, tj, tx, AMPS_UPPER);
    ok = Rd && (nf == 0 || ref_solve_refined(nf, Rd->p, Rd->i, Rd->x, rhs, x, 2, NULL) == 0);
    for (k = 0; k < n; k++) ue[k] = map[k] < 0 ? gv[k] : x[map[k]];
    amps_csc_symv(A, AMPS_UPPER, ue, ax);
    for (v = 0; v < nn; v++)
        for (d = 0; d < 3; d++) {
            int e = (int)dof[3 * v + d];
            double s = e >= 0 ? ue[e] : 0.0;
            wo[3 * v + d] = s;
            uo[3 * v + d] = u[3 * v + d] + w->dt * s;
            react[3 * v + d] = (e >= 0 && w->sh.pinned[v]) ? (ax[e] - b[e]) / w->dt : 0.0;
        }
    amps_csc_free(ctx, A);
    amps_csc_free(ctx, Rd);
    free(fixed);
    free(dof);
    free(mass);
    free(gel);
    free(ti);
    free(tj);
    free(tx);
    free(b);
    free(gv);
    free(ax);
    free(ue);
    free(map);
    free(rhs);
    free(x);
    return ok ? 0 : 1;
}

static double worst_err = 0;
static int n_gs = 0, n_engine = 0; /* steps whose PCG ended with each preconditioner */

/* One step of S against ref_corot from the scene's state before it. */
static void check_step(amps_ctx *ctx, amps_scene *S, cref *w, const char *what, int step) {
    const amps_mesh *m = amps_scene_mesh(S);
    int nn = (int)m->nnode, v;
    size_t sz = sizeof(double) * 3 * (size_t)nn;
    double *u0 = (double *)malloc(sz), *w0 = (double *)malloc(sz), *ur = (double *)malloc(sz),
           *wr = (double *)malloc(sz);
    double *rr = (double *)calloc(3 * nn, sizeof(double)), *rs = (double *)calloc(3 * nn, sizeof(double)), eu, ew, er;
    amps_scene_step_stats st;
    amps_status s;
    memcpy(u0, amps_scene_displacements(S), sz);
    memcpy(w0, amps_scene_velocities(S), sz);
    CHECK(ref_corot(ctx, m, w, u0, w0, t_identity, ur, wr, rr) == 0, "%s step %d: reference failed", what, step);
    s = amps_scene_step(ctx, S, 1);
    CHECK(s == AMPS_OK, "%s step %d: step: %s", what, step, ctx->msg);
    for (v = 0; v < nn; v++) amps_scene_reaction(ctx, S, v, rs + 3 * v);
    eu = t_relerr_floor(3 * nn, amps_scene_displacements(S), ur, 1e-300);
    ew = t_relerr_floor(3 * nn, amps_scene_velocities(S), wr, 1e-12);
    er = t_relerr_floor(3 * nn, rs, rr, 1e-12 + t_norm(3 * nn, rr) + 1e-9 * t_norm(3 * nn, wr));
    amps_scene_step_info(S, &st);
    CHECK(eu < 1e-8 && ew < 1e-8, "%s step %d: error u %.2e w %.2e (%ld iterations, relres %.2e)", what, step, eu, ew,
          (long)st.iterations, st.relres);
    CHECK(er < 1e-8, "%s step %d: reactions error %.2e", what, step, er);
    CHECK(st.corotational == 1 && st.relres <= 1e-10, "%s step %d: stats %d %.2e", what, step, st.corotational,
          st.relres);
    if (ew > worst_err) worst_err = ew;
    if (eu > worst_err) worst_err = eu;
    if (st.iterations > st.iterations_gs) n_engine++;
    else n_gs++;
    free(u0);
    free(w0);
    free(ur);
    free(wr);
    free(rr);
    free(rs);
}

/* p rotated by angle about the unit axis ax through c. */
static void t_arc(const double ax[3], double angle, const double c[3], const double p[3], double out[3]) {
    double r[3], cs = cos(angle), sn = sin(angle), d;
    int i;
    for (i = 0; i < 3; i++) r[i] = p[i] - c[i];
    d = ax[0] * r[0] + ax[1] * r[1] + ax[2] * r[2];
    out[0] = c[0] + r[0] * cs + (ax[1] * r[2] - ax[2] * r[1]) * sn + ax[0] * d * (1 - cs);
    out[1] = c[1] + r[1] * cs + (ax[2] * r[0] - ax[0] * r[2]) * sn + ax[1] * d * (1 - cs);
    out[2] = c[2] + r[2] * cs + (ax[0] * r[1] - ax[1] * r[0]) * sn + ax[2] * d * (1 - cs);
}

static amps_int live_tet(const amps_mesh *m) {
    amps_int k, t;
    for (k = 0; k < 50; k++) {
        t = t_int((int)m->ntet);
        if (!(m->removed && m->removed[t])) return t;
    }
    return -1;
}

/* Random sequence on a 3 x 3 x nz grid fixed at z = 0: steps (each checked), cuts, removals,
   pins of the far end moving in large arcs about a random axis, releases, forces, gravity. */
static void random_sequence(const char *what, int nz, int nops, unsigned long long seed, amps_int maxit) {
    amps_ctx ctx;
    amps_scene *S;
    amps_mesh *m;
    cref w;
    int op, v, step = 0, ncut = 0, nrem = 0;
    double ax[3], c[3] = {1, 1, 0}, angle = 0, l;
    memset(&w, 0, sizeof(w));
    n_gs = n_engine = 0;
    amps_ctx_init(&ctx);
    t_seed(seed);
    m = amps_mesh_grid(&ctx, 3, 3, nz, 1, 1, 1);
    amps_mesh_set_density(&ctx, m, 1.0);
    w.sh.fixed0 = (unsigned char *)calloc(m->nnode, 1);
    for (v = 0; v < m->nnode; v++) w.sh.fixed0[v] = m->xyz[3 * v + 2] < 0.5;
    shadow_grow(&w.sh, (int)m->nnode);
    w.dt = 0.05;
    w.alpha = 0.2;
    w.beta = 0.02;
    S = amps_scene_create(&ctx, m, NULL);
    amps_scene_fix_where(&ctx, S, 2, AMPS_LT, 0.5, NULL);
    CHECK(amps_scene_dynamics(&ctx, S, w.dt, w.alpha, w.beta) == AMPS_OK, "%s: dynamics", what);
    CHECK(amps_scene_corotational(&ctx, S, 1) == AMPS_OK, "%s: corotational: %s", what, ctx.msg);
    if (maxit) CHECK(amps_scene_corotational_tol(&ctx, S, 1e-10, maxit) == AMPS_OK, "%s: cap", what);
    ax[0] = t_unif() - 0.5;
    ax[1] = t_unif() - 0.5;
    ax[2] = 0.2 * (t_unif() - 0.5);
    l = sqrt(ax[0] * ax[0] + ax[1] * ax[1] + ax[2] * ax[2]);
    for (v = 0; v < 3; v++) ax[v] /= l;
    for (op = 0; op < nops; op++) {
        const amps_mesh *mm = amps_scene_mesh(S);
        int kind = t_int(10);
        shadow_grow(&w.sh, (int)mm->nnode + 1);
        if (kind <= 3) check_step(&ctx, S, &w, what, step++);
        else if (kind == 4) { /* cut */ double p[3], nrm[3] = {t_unif() - 0.5, t_unif() - 0.5, t_unif() - 0.5};
            amps_int vc;
            v = t_int((int)mm->nnode);
            if (amps_mesh_degree(mm, v) == 0 || w.sh.fixed0[mm->origin[v]]) continue;
            memcpy(p, mm->xyz + 3 * v, sizeof(p));
            if (amps_scene_cut(&ctx, S, v, p, nrm, &vc) == AMPS_OK && vc >= 0) {
                shadow_grow(&w.sh, (int)vc + 1);
                ncut++;
            }
        } else if (kind == 5) { /* removal */
            amps_int t = live_tet(mm);
            amps_mesh_removal rr;
            if (t >= 0 && amps_scene_remove(&ctx, S, 1, &t, AMPS_SINGULAR_REMOVE, &rr) == AMPS_OK) {
                int q, k;
                nrem++;
                for (k = 0; k < rr.ntet; k++)
                    for (q = 0; q < 4; q++) {
                        amps_int x = mm->tet[4 * rr.tets[k] + q];
                        if (amps_mesh_degree(mm, x) == 0) w.sh.pinned[x] = 0;
                    }
            }
        } else if (kind <= 7) { /* the far end's pins move on by 10-30 degrees */
            angle += (10 + 20 * t_unif()) * 3.14159265358979 / 180;
            for (v = 0; v < mm->nnode; v++) {
                double q[3], g[3];
                int d;
                if (mm->xyz[3 * v + 2] < nz - 1.5 || amps_mesh_degree(mm, v) == 0) continue;
                if (!w.sh.pinned[v] && t_int(3) == 0) continue;
                t_arc(ax, angle, c, mm->xyz + 3 * v, q);
                for (d = 0; d < 3; d++) g[d] = q[d] - mm->xyz[3 * v + d];
                if (amps_scene_pin(&ctx, S, (amps_int)v, g) == AMPS_OK) {
                    w.sh.pinned[v] = 1;
                    memcpy(w.sh.pinval + 3 * v, g, sizeof(g));
                }
            }
        } else if (kind == 8) { /* release */
            for (v = 0; v < mm->nnode && !w.sh.pinned[v]; v++) {}
            if (v < mm->nnode && amps_scene_release(&ctx, S, (amps_int)v) == AMPS_OK) w.sh.pinned[v] = 0;
        } else { /* gravity or a force */
            if (t_int(2)) {
                double g[3] = {0.05 * (t_unif() - 0.5), 0.05 * (t_unif() - 0.5), -0.1 * t_unif()};
                CHECK(amps_scene_gravity(&ctx, S, g) == AMPS_OK, "%s: gravity", what);
                memcpy(w.g, g, sizeof(g));
            } else {
                double f[3] = {0.1 * (t_unif() - 0.5), 0.1 * (t_unif() - 0.5), 0.1 * (t_unif() - 0.5)};
                v = t_int((int)mm->nnode);
                if (!w.sh.fixed0[mm->origin[v]] && amps_scene_force(&ctx, S, (amps_int)v, f) == AMPS_OK)
                    memcpy(w.sh.force + 3 * v, f, sizeof(f));
            }
        }
    }
    check_step(&ctx, S, &w, what, step++);
    {
        amps_scene_step_stats st;
        amps_scene_step_info(S, &st);
        CHECK(!maxit || st.factored > 0, "%s: a cap of %ld iterations never stalled", what, (long)maxit);
        printf("  %-16s steps %d, cuts %d, removals %d, final angle %.0f deg, worst error %.2e; preconditioner: "
               "Gauss-Seidel %d steps, engine %d, A_R factored %ld times\n",
               what, step, ncut, nrem, angle * 180 / 3.14159265358979, worst_err, n_gs, n_engine, (long)st.factored);
    }
    amps_scene_free(&ctx, S);
    shadow_free(&w.sh);
}


/* max |x| over n entries. */
static double t_max(int n, const double *x) {
    double s = 0;
    int i;
    for (i = 0; i < n; i++) s = fmax(s, fabs(x[i]));
    return s;
}

/* With every R_e = I (the test hook) the corotational step is the linear step: the same
   displacements, velocities and reactions to 1e-12, through pins, gravity, a cut, a removal
   (the PCG run to 1e-14, so that it holds for either preconditioner). */
static void test_identity_is_linear(void) {
    amps_ctx ctx;
    amps_scene *S[2];
    int k, v, i, nn;
    double worst = 0, wr = 0;
    amps_ctx_init(&ctx);
    t_identity = 1;
    for (i = 0; i < 2; i++) {
        double g[3] = {0.01, 0, -0.05};
        S[i] = amps_scene_create(&ctx, amps_mesh_grid(&ctx, 3, 3, 7, 1, 1, 1), NULL);
        amps_scene_fix_where(&ctx, S[i], 2, AMPS_LT, 0.5, NULL);
        amps_scene_dynamics(&ctx, S[i], 0.05, 0.1, 0.01);
        amps_scene_gravity(&ctx, S[i], g);
        if (i) CHECK(amps_scene_corotational(&ctx, S[i], 1) == AMPS_OK, "identity: corotational");
        if (i) CHECK(amps_scene_corotational_tol(&ctx, S[i], 1e-14, 0) == AMPS_OK, "identity: tolerance");
    }
    for (k = 0; k < 16; k++) {
        for (i = 0; i < 2; i++) {
            const amps_mesh *m = amps_scene_mesh(S[i]);
            if (k == 3) {
                double p[3] = {1, 1, 3}, n[3] = {0, 0.3, 1};
                CHECK(amps_scene_cut(&ctx, S[i], 1 + 3 * (1 + 3 * 3), p, n, NULL) == AMPS_OK, "identity: cut");
            }
            if (k == 6) {
                amps_int t = 100;
                CHECK(amps_scene_remove(&ctx, S[i], 1, &t, AMPS_SINGULAR_REMOVE, NULL) == AMPS_OK, "identity: remove");
            }
            for (v = 0; v < m->nnode; v++)
                if (m->xyz[3 * v + 2] > 5.5 && amps_mesh_degree(m, v) > 0 && k < 10) {
                    double g[3] = {0.05 * k, -0.02 * k, 0.01 * k};
                    amps_scene_pin(&ctx, S[i], v, g);
                } else if (k == 10 && amps_scene_is_pinned(S[i], v) && v % 2) amps_scene_release(&ctx, S[i], v);
            CHECK(amps_scene_step(&ctx, S[i], 1) == AMPS_OK, "identity: step %d: %s", k, ctx.msg);
        }
        nn = (int)amps_scene_mesh(S[0])->nnode;
        worst = fmax(worst,
                     t_relerr_floor(3 * nn, amps_scene_displacements(S[1]), amps_scene_displacements(S[0]), 1e-300));
        worst = fmax(worst, t_relerr_floor(3 * nn, amps_scene_velocities(S[1]), amps_scene_velocities(S[0]), 1e-300));
        for (v = 0; v < nn; v++) {
            double r0[3], r1[3];
            amps_scene_reaction(&ctx, S[0], v, r0);
            amps_scene_reaction(&ctx, S[1], v, r1);
            for (i = 0; i < 3; i++) wr = fmax(wr, fabs(r0[i] - r1[i]));
        }
    }
    CHECK(worst < 1e-12, "identity: corotational with R = I differs from linear by %.2e", worst);
    CHECK(wr < 1e-12, "identity: reactions differ by %.2e", wr);
    printf("  R = I against the linear step: %.2e (reactions %.2e)\n", worst, wr);
    t_identity = 0;
    for (i = 0; i < 2; i++) amps_scene_free(&ctx, S[i]);
}

/* A cut model pinned at every node to a rigid motion (90 degrees about an oblique axis plus a
   translation): corotational elastic forces (the reactions once at rest) and stresses vanish to
   1e-12; linear FEM has large ones. */
/* Pins every node of S to its place turned by 90 degrees about the unit axis ax through c and
   shifted by tv; 0 or the first failing status. */
static amps_status pin_rigid_turn(amps_ctx *ctx, amps_scene *S, const double ax[3], const double c[3],
                                  const double tv[3]) {
    const amps_mesh *m = amps_scene_mesh(S);
    amps_int v;
    int d;
    for (v = 0; v < m->nnode; v++) {
        double q[3], g[3];
        amps_status s;
        t_arc(ax, 3.14159265358979323846 / 2, c, m->xyz + 3 * v, q);
        for (d = 0; d < 3; d++) g[d] = q[d] + tv[d] - m->xyz[3 * v + d];
        if ((s = amps_scene_pin(ctx, S, v, g)) != AMPS_OK) return s;
    }
    return AMPS_OK;
}

static void test_rigid_motion(void) {
    amps_ctx ctx;
    int lin;
    double ax[3] = {1, 2, -1.5}, c[3] = {0.3, -0.2, 0.5}, tv[3] = {0.7, -1.1, 2.0}, l;
    amps_ctx_init(&ctx);
    l = sqrt(ax[0] * ax[0] + ax[1] * ax[1] + ax[2] * ax[2]);
    ax[0] /= l;
    ax[1] /= l;
    ax[2] /= l;
    for (lin = 0; lin < 2; lin++) {
        amps_scene *S = amps_scene_create(&ctx, amps_mesh_grid(&ctx, 3, 3, 4, 1, 1, 1), NULL);
        const amps_mesh *m;
        double p[3] = {1, 1, 1.5}, n[3] = {0.2, 0.1, 1}, *vm, rmax = 0, smax;
        amps_int v;
        amps_scene_set_material(&ctx, S, 10.0, 0.35);
        amps_scene_dynamics(&ctx, S, 0.1, 0.1, 0.01);
        if (!lin) amps_scene_corotational(&ctx, S, 1);
        m = amps_scene_mesh(S);
        for (v = 0; v < m->nnode; v++) {
            double g[3] = {0, 0, 0};
            amps_scene_pin(&ctx, S, v, g);
        }
        CHECK(amps_scene_cut(&ctx, S, 1 + 3 * (1 + 3 * 1), p, n, &v) == AMPS_OK, "rigid: cut: %s", ctx.msg);
        CHECK(pin_rigid_turn(&ctx, S, ax, c, tv) == AMPS_OK, "rigid: pin: %s", ctx.msg);
        CHECK(amps_scene_step(&ctx, S, 3) == AMPS_OK, "rigid: steps: %s", ctx.msg);
        for (v = 0; v < m->nnode; v++) {
            double r[3];
            amps_scene_reaction(&ctx, S, v, r);
            rmax = fmax(rmax, t_max(3, r));
        }
        vm = (double *)malloc(sizeof(double) * m->ntet);
        amps_scene_stress(&ctx, S, NULL, vm, NULL);
        smax = t_max((int)m->ntet, vm);
        if (!lin) {
            CHECK(rmax < 1e-12 && smax < 1e-12, "rigid: corotational elastic force %.2e, stress %.2e", rmax, smax);
            printf("  rigid motion: corotational force %.2e, stress %.2e;", rmax, smax);
        } else {
            CHECK(rmax > 0.1 && smax > 0.1, "rigid: linear elastic force %.2e, stress %.2e", rmax, smax);
            printf(" linear %.2e, %.2e\n", rmax, smax);
        }
        free(vm);
        amps_scene_free(&ctx, S);
    }
}

/* Volume sum_t V_t det F_t of the deformed mesh (live tets). */
static double deformed_volume(const amps_scene *S) {
    const amps_mesh *m = amps_scene_mesh(S);
    const double *u = amps_scene_displacements(S);
    double vol = 0;
    amps_int t;
    for (t = 0; t < m->ntet; t++) {
        double X[12], x[12], R[9], G[12];
        int a;
        if (m->removed && m->removed[t]) continue;
        amps_mesh_tet_coords(m, t, X);
        for (a = 0; a < 12; a++) x[a] = X[a] + u[3 * m->tet[4 * t + a / 3] + a % 3];
        vol += fabs(amps_tet_gradients(X, G)) * amps_tet_rotation(X, x, R);
    }
    return vol;
}

/* A 2 x 2 x 13 bar fixed at z = 0, its far end pinned and carried along circular arcs to a 90 degree
   bend: the corotational volume stays within 1%; linear FEM's grows. */
static void test_bent_bar(void) {
    amps_ctx ctx;
    int lin, k, nstep = 40;
    double L = 13, vol0 = 52, err[2];
    amps_ctx_init(&ctx);
    for (lin = 0; lin < 2; lin++) {
        amps_scene *S = amps_scene_create(&ctx, amps_mesh_grid(&ctx, 3, 3, 14, 1, 1, 1), NULL);
        const amps_mesh *m = amps_scene_mesh(S);
        amps_scene_set_material(&ctx, S, 100.0, 0.3);
        amps_scene_fix_where(&ctx, S, 2, AMPS_LT, 0.5, NULL);
        amps_scene_dynamics(&ctx, S, 0.05, 1.0, 0.05);
        if (!lin) amps_scene_corotational(&ctx, S, 1);
        for (k = 1; k <= nstep + 100; k++) { /* 40 steps of bending, 100 of rest */
            double th = 1.5707963267948966 * (k < nstep ? k : nstep) / nstep, rr = L / th, cy, cz;
            amps_int v;
            cy = 1 + rr * (1 - cos(th));
            cz = rr * sin(th);
            for (v = 0; v < m->nnode; v++) {
                const double *X = m->xyz + 3 * v;
                double g[3];
                if (X[2] < L - 0.5) continue;
                /* the end section (offset (ox, oy) from the axis) turned by th about x */
                g[0] = 0;
                g[1] = cy + (X[1] - 1) * cos(th) - X[1];
                g[2] = cz - (X[1] - 1) * sin(th) - X[2];
                amps_scene_pin(&ctx, S, v, g);
            }
            CHECK(amps_scene_step(&ctx, S, 1) >= 0, "bar: step %d: %s", k, ctx.msg);
        }
        err[lin] = deformed_volume(S) / vol0 - 1;
        amps_scene_free(&ctx, S);
    }
    CHECK(fabs(err[0]) < 0.01, "bar: corotational volume change %.3g", err[0]);
    CHECK(fabs(err[1]) > 5 * fabs(err[0]), "bar: linear volume change %.3g not above corotational %.3g", err[1],
          err[0]);
    printf("  bar bent by 90 degrees: volume change corotational %.2e, linear %.2e\n", err[0], err[1]);
}

/* Live tets of S whose det F is below thr. */
static int tets_below(const amps_scene *S, double thr) {
    const amps_mesh *m = amps_scene_mesh(S);
    int n = 0, a;
    amps_int t;
    for (t = 0; t < m->ntet; t++) {
        double X[12], x[12], R[9];
        if (m->removed && m->removed[t]) continue;
        amps_mesh_tet_coords(m, t, X);
        for (a = 0; a < 12; a++) x[a] = X[a] + amps_scene_displacements(S)[3 * m->tet[4 * t + a / 3] + a % 3];
        n += amps_tet_rotation(X, x, R) < thr;
    }
    return n;
}

/* A unit cube of 6 tets fixed at z = 0: its top corner pinned and pushed through the base (tets
   inverted), released: every tet recovers a positive volume. */
static void test_inverted(void) {
    amps_ctx ctx;
    amps_scene *S;
    const amps_mesh *m;
    amps_int v, top = 7;
    int k, ninv, neg;
    double g[3] = {-0.3, -0.2, -1.6};
    amps_ctx_init(&ctx);
    S = amps_scene_create(&ctx, amps_mesh_grid(&ctx, 2, 2, 2, 1, 1, 1), NULL);
    m = amps_scene_mesh(S);
    amps_scene_fix_where(&ctx, S, 2, AMPS_LT, 0.5, NULL);
    amps_scene_dynamics(&ctx, S, 0.05, 2.0, 0.02);
    amps_scene_corotational(&ctx, S, 1);
    for (v = 4; v < 8; v++) {
        double z[3] = {0, 0, 0};
        if (v != top) amps_scene_pin(&ctx, S, v, z);
    }
    CHECK(amps_scene_pin(&ctx, S, top, g) == AMPS_OK, "inverted: pin");
    CHECK(amps_scene_step(&ctx, S, 2) == AMPS_OK, "inverted: push: %s", ctx.msg);
    ninv = tets_below(S, 0.0);
    CHECK(ninv > 0, "inverted: no tet inverted");
    for (v = 4; v < 8; v++) amps_scene_release(&ctx, S, v);
    for (k = 0; k < 300; k++) CHECK(amps_scene_step(&ctx, S, 1) == AMPS_OK, "inverted: step %d: %s", k, ctx.msg);
    neg = tets_below(S, 0.5);
    CHECK(neg == 0, "inverted: %d of %ld tets still inverted or crushed after the release", neg, (long)m->ntet);
    printf("  inverted: %d tets pushed through, all recovered: %s\n", ninv, neg ? "no" : "yes");
    amps_scene_free(&ctx, S);
}

/* Bad input changes nothing: statics, after the first step, bad tolerances; the iteration cap. */
static void test_bad_input(void) {
    amps_ctx ctx;
    amps_scene *S;
    amps_scene_step_stats st = {0, 0, 0, 0, 0, 0, 0, 0, 0, 0};
    double g[3] = {0, 0.5, 0.5};
    amps_ctx_init(&ctx);
    S = amps_scene_create(&ctx, amps_mesh_grid(&ctx, 3, 3, 5, 1, 1, 1), NULL);
    amps_scene_fix_where(&ctx, S, 2, AMPS_LT, 0.5, NULL);
    CHECK(amps_scene_corotational(&ctx, NULL, 1) == AMPS_ERR_ARG, "bad: NULL");
    CHECK(amps_scene_corotational(&ctx, S, 1) == AMPS_ERR_STATE, "bad: statics accepted");
    amps_scene_dynamics(&ctx, S, 0.05, 0.1, 0.01);
    CHECK(amps_scene_corotational_tol(&ctx, S, 0, 10) == AMPS_ERR_VALUE, "bad: tol 0");
    CHECK(amps_scene_corotational_tol(&ctx, S, NAN, 10) == AMPS_ERR_VALUE, "bad: tol NaN");
    CHECK(amps_scene_corotational_tol(&ctx, S, 1e-8, -1) == AMPS_ERR_VALUE, "bad: maxit -1");
    CHECK(amps_scene_step_info(S, NULL) == AMPS_ERR_ARG, "bad: info NULL");
    CHECK(amps_scene_step(&ctx, S, 1) == AMPS_OK, "bad: linear step");
    CHECK(amps_scene_corotational(&ctx, S, 1) == AMPS_ERR_STATE, "bad: after the first step accepted");
    CHECK(amps_scene_step(&ctx, S, 1) == AMPS_OK && amps_scene_step_info(S, &st) == AMPS_OK && !st.corotational,
          "bad: the refused call turned the mode on");
    amps_scene_free(&ctx, S);
    /* the cap: the work of one iteration with the engine's preconditioner is not enough for a
       tolerance below the rounding; the stalled step factors A_R, still misses it, and is taken
       with a warning */
    S = amps_scene_create(&ctx, amps_mesh_grid(&ctx, 3, 3, 5, 1, 1, 1), NULL);
    amps_scene_fix_where(&ctx, S, 2, AMPS_LT, 0.5, NULL);
    amps_scene_dynamics(&ctx, S, 0.05, 0.1, 0.01);
    amps_scene_corotational(&ctx, S, 1);
    CHECK(amps_scene_corotational_tol(&ctx, S, 1e-30, 1) == AMPS_OK, "bad: tol");
    amps_scene_pin(&ctx, S, 40, g);
    CHECK(amps_scene_step(&ctx, S, 1) == AMPS_WARN_INACCURATE, "cap: first step: %s", ctx.msg);
    g[0] = 2;
    amps_scene_pin(&ctx, S, 40, g);
    CHECK(amps_scene_step(&ctx, S, 1) == AMPS_WARN_INACCURATE, "cap: no warning: %s", ctx.msg);
    CHECK(amps_scene_step_info(S, &st) == AMPS_OK && st.iterations >= 1 && st.relres > 1e-30 && st.relres < 1e-13 &&
                  st.factored >= 1,
          "cap: stats %ld %.2e, %ld factored", (long)st.iterations, st.relres, (long)st.factored);
    amps_scene_free(&ctx, S);
}

/* amps_update_solve_rhs: x_F = K^_FF^-1 rhs_F, x_C = 0, the engine's solution and forces as they
   were; on a cut and pinned beam (the scene's engine). */
static void test_solve_rhs(void) {
    amps_ctx ctx;
    amps_scene *S;
    amps_update *U;
    amps_int N, k, e;
    double f[3] = {0.1, 0.2, -0.1}, g[3] = {0.05, 0, 0}, p[3] = {2, 2, 3}, nrm[3] = {0.2, 0, 1}, *rhs, *x, *y, *x0;
    double res = 0, rn = 0, xc = 0;
    amps_ctx_init(&ctx);
    S = amps_scene_create(&ctx, amps_mesh_beam(&ctx, 8), NULL);
    amps_scene_fix_where(&ctx, S, 2, AMPS_LT, 0.5, NULL);
    amps_scene_force(&ctx, S, 150, f);
    amps_scene_pin(&ctx, S, 180, g);
    CHECK(amps_scene_cut(&ctx, S, 2 + 5 * (2 + 5 * 3), p, nrm, NULL) == AMPS_OK, "solve_rhs: cut");
    CHECK(amps_scene_solve(&ctx, S) == AMPS_OK, "solve_rhs: solve");
    U = amps_scene_engine(S);
    N = amps_update_dim(U);
    rhs = (double *)malloc(sizeof(double) * N);
    x = (double *)malloc(sizeof(double) * N);
    y = (double *)malloc(sizeof(double) * N);
    x0 = (double *)malloc(sizeof(double) * N);
    memcpy(x0, amps_update_solution(U), sizeof(double) * N);
    for (k = 0; k < N; k++) rhs[k] = t_unif() - 0.5;
    CHECK(amps_update_solve_rhs(&ctx, U, rhs, x) == AMPS_OK, "solve_rhs: %s", ctx.msg);
    amps__kmul(U, x, y);
    for (k = 0; k < N; k++) {
        e = U->aug.pos[k];
        if (e >= 0 && (U->aug.kind[e] & AMPS__UCON)) xc = fmax(xc, fabs(x[k]));
        else {
            res += (y[k] - rhs[k]) * (y[k] - rhs[k]);
            rn += rhs[k] * rhs[k];
        }
    }
    CHECK(sqrt(res / rn) < 1e-12 && xc == 0.0, "solve_rhs: residual %.2e, x_C %.2e", sqrt(res / rn), xc);
    CHECK(!memcmp(x0, amps_update_solution(U), sizeof(double) * N), "solve_rhs: the solution changed");
    CHECK(amps_update_solve_rhs(&ctx, U, rhs, rhs) == AMPS_OK && !memcmp(rhs, x, sizeof(double) * N),
          "solve_rhs: in place differs");
    CHECK(amps_update_solve(&ctx, U, y) == AMPS_OK && !memcmp(x0, y, sizeof(double) * N),
          "solve_rhs: the next solve changed (forces touched)");
    CHECK(amps_update_solve_rhs(&ctx, NULL, rhs, x) == AMPS_ERR_ARG, "solve_rhs: NULL engine");
    free(rhs);
    free(x);
    free(y);
    free(x0);
    amps_scene_free(&ctx, S);
}

/* The step on 1, 2 and 3 threads gives the same bits (with the deterministic re-factorization
   policy): a beam large enough for the parallel passes (rotations, the assembly of A_R, its
   products, the fracture criterion), its end turned by pins through an arc, gravity, a cut in the
   middle (a rebuilt pattern of A_R), then fracture at 0.9 of the largest principal stress (the
   live tets lie under it after the step). */
static void test_threads_bitwise(void) {
    double *ref = NULL, smax = 0;
    size_t nref = 0;
    amps_int nrem = 0, over = 0;
    int nt;
    for (nt = 1; nt <= 3; nt++) {
        amps_ctx ctx;
        amps_scene *S;
        const amps_mesh *m;
        amps_int v, vc, fixed[25], nfix = 0;
        double ax[3] = {1, 0, 0}, c[3] = {2, 2, 90}, gv[3] = {0, -9.81, 0}, p[3] = {2, 2, 50}, n[3] = {0.3, 1, 0.1};
        int step, d;
        amps_scene_opts so;
        amps_ctx_init(&ctx);
        ctx.nthreads = nt;
        amps_scene_opts_default(&so);
        so.update.refactor = AMPS_REFACTOR_COUNT; /* AUTO's re-factorizations depend on the clock */
        S = amps_scene_create(&ctx, amps_mesh_beam(&ctx, 91), &so);
        CHECK(S != NULL, "threads: scene: %s", ctx.msg);
        if (!S) return;
        m = amps_scene_mesh(S);
        CHECK(m->nnode > 2048 && m->ntet > 2048, "threads: the beam is too small for the parallel passes");
        for (v = 0; v < m->nnode; v++)
            if (m->xyz[3 * v + 2] == 0) fixed[nfix++] = v;
        amps_scene_set_material(&ctx, S, 1000.0, 0.3);
        CHECK(amps_scene_fix(&ctx, S, nfix, fixed) == AMPS_OK && amps_scene_gravity(&ctx, S, gv) == AMPS_OK &&
                      amps_scene_dynamics(&ctx, S, 0.05, 0.1, 0.01) == AMPS_OK &&
                      amps_scene_corotational(&ctx, S, 1) == AMPS_OK,
              "threads: setup: %s", ctx.msg);
        for (step = 0; step < 8; step++) {
            for (v = 0; v < m->nfile; v++)
                if (m->xyz[3 * v + 2] == 90) {
                    double q[3], g[3];
                    t_arc(ax, 0.1 * (step + 1), c, m->xyz + 3 * v, q);
                    for (d = 0; d < 3; d++) g[d] = q[d] - m->xyz[3 * v + d];
                    amps_scene_pin(&ctx, S, v, g);
                }
            if (step == 3)
                CHECK(amps_scene_cut(&ctx, S, 2 + 5 * (2 + 5 * 50), p, n, &vc) == AMPS_OK, "threads: cut: %s", ctx.msg);
            if (step == 6) { /* fracture at 0.9 of the largest corotational principal stress */
                double *pr = (double *)malloc(sizeof(double) * 3 * (size_t)m->ntet);
                amps_int t;
                CHECK(amps_scene_stress(&ctx, S, NULL, NULL, pr) == AMPS_OK, "threads: stress: %s", ctx.msg);
                for (t = 0, smax = 0; t < 3 * m->ntet; t++) smax = fmax(smax, 0.9 * fabs(pr[t]));
                CHECK(amps_scene_fracture(&ctx, S, smax) == AMPS_OK, "threads: fracture: %s", ctx.msg);
                free(pr);
            }
            CHECK(amps_scene_step(&ctx, S, 1) == AMPS_OK, "threads: step: %s", ctx.msg);
            if (step == 6) { /* the live tets lie under the threshold in the state the step ended in */
                amps_int t;
                for (t = 0, over = 0; t < m->ntet; t++) {
                    double sg[6], p3[3];
                    if (m->removed && m->removed[t]) continue;
                    amps__cr_sigma(S, t, S->dyn.cr_G + 12 * t, NULL, sg);
                    amps_sym3_eig(sg, p3);
                    over += fabs(p3[0]) > smax || fabs(p3[2]) > smax;
                }
                CHECK(m->nremoved > 0 && over == 0, "threads: fracture removed %ld, left %ld over the threshold",
                      (long)m->nremoved, (long)over);
            }
        }
        if (nt == 1) {
            nref = 3 * (size_t)m->nnode;
            nrem = m->nremoved;
            ref = (double *)malloc(sizeof(double) * 2 * nref);
            memcpy(ref, amps_scene_displacements(S), sizeof(double) * nref);
            memcpy(ref + nref, amps_scene_velocities(S), sizeof(double) * nref);
        } else {
            CHECK(3 * (size_t)m->nnode == nref && m->nremoved == nrem &&
                          !memcmp(ref, amps_scene_displacements(S), sizeof(double) * nref) &&
                          !memcmp(ref + nref, amps_scene_velocities(S), sizeof(double) * nref),
                  "threads: %d threads differ from 1 in the bits of u or w, or in the fracture", nt);
        }
        amps_scene_free(&ctx, S);
    }
    printf("  1, 2 and 3 threads: the same bits (%ld tets fractured)\n", (long)nrem);
    free(ref);
}

/* A scene rotated rigidly by pins (every node pinned to a 90 degree turn about ax and a shift,
   3 steps: u is that motion, w = 0), then every node but the bottom face released. */
static amps_scene *haptic_scene(amps_ctx *ctx, const double ax[3]) {
    amps_scene_opts so;
    amps_scene *S;
    const amps_mesh *m;
    double c[3] = {0.3, -0.2, 0.5}, tv[3] = {0.7, -1.1, 2.0};
    amps_int v;
    amps_scene_opts_default(&so);
    so.update.refactor = AMPS_REFACTOR_COUNT;
    S = amps_scene_create(ctx, amps_mesh_grid(ctx, 3, 3, 4, 1, 1, 1), &so);
    if (!S) return NULL;
    amps_scene_set_material(ctx, S, 10.0, 0.35);
    amps_scene_dynamics(ctx, S, 0.1, 0.1, 0.01);
    amps_scene_corotational(ctx, S, 1);
    m = amps_scene_mesh(S);
    pin_rigid_turn(ctx, S, ax, c, tv);
    amps_scene_step(ctx, S, 3);
    for (v = 0; v < m->nnode; v++)
        if (m->xyz[3 * v + 2] != 0) amps_scene_release(ctx, S, v);
    return S;
}

/* Moves the bottom pins of S by dg from their targets. */
static void haptic_move(amps_ctx *ctx, amps_scene *S, const double *g0, const double dg[3]) {
    const amps_mesh *m = amps_scene_mesh(S);
    amps_int v;
    int d;
    for (v = 0; v < m->nnode; v++)
        if (m->xyz[3 * v + 2] == 0) {
            double g[3];
            for (d = 0; d < 3; d++) g[d] = g0[3 * v + d] + dg[d];
            amps_scene_pin(ctx, S, v, g);
        }
}

/* The haptic path of the corotational mode: on a model in a rigid 90 degree turn (every R_e the
   same Q, so A_R = Q A Q^T) the reactions' response to pin moves between steps is that of the
   next step (scenes stepped with the pins at g1 and at g2), to the PCG tolerance; the haptic
   model (amps_scene_haptic_build) gives the same affine function. */
static void test_haptic(void) {
    amps_ctx ctx;
    double ax[3] = {1, 2, -1.5}, d1[3] = {0.01, 0, 0.005}, d2[3] = {-0.004, 0.012, 0}, l, *g0, *rh1, *rh2, *rs1, *rs2,
           *rm, *gp, num = 0, den = 0, em = 0;
    amps_scene *A, *B;
    const amps_mesh *m;
    amps_haptic h;
    amps_int v, nn, k;
    int d;
    amps_ctx_init(&ctx);
    l = sqrt(ax[0] * ax[0] + ax[1] * ax[1] + ax[2] * ax[2]);
    for (d = 0; d < 3; d++) ax[d] /= l;
    A = haptic_scene(&ctx, ax);
    CHECK(A != NULL, "haptic: scene: %s", ctx.msg);
    if (!A) return;
    m = amps_scene_mesh(A);
    nn = m->nnode;
    g0 = (double *)calloc(3 * (size_t)nn, sizeof(double));
    rh1 = (double *)calloc(3 * (size_t)nn, sizeof(double));
    rh2 = (double *)calloc(3 * (size_t)nn, sizeof(double));
    rs1 = (double *)calloc(3 * (size_t)nn, sizeof(double));
    rs2 = (double *)calloc(3 * (size_t)nn, sizeof(double));
    rm = (double *)calloc(3 * (size_t)nn, sizeof(double));
    gp = (double *)calloc(3 * (size_t)nn, sizeof(double));
    for (v = 0; v < nn; v++)
        for (d = 0; d < 3; d++) g0[3 * v + d] = amps_scene_displacements(A)[3 * v + d];
    /* the haptic calls at g1 and g2, and the model built at g1 evaluated at g2 */
    haptic_move(&ctx, A, g0, d1);
    CHECK(amps_scene_solve_reactions(&ctx, A) == AMPS_OK, "haptic: call: %s", ctx.msg);
    for (v = 0; v < nn; v++) amps_scene_reaction(&ctx, A, v, rh1 + 3 * v);
    amps_haptic_init(&h);
    CHECK(amps_scene_haptic_build(&ctx, A, &h) == AMPS_OK, "haptic: build: %s", ctx.msg);
    haptic_move(&ctx, A, g0, d2);
    CHECK(amps_scene_solve_reactions(&ctx, A) == AMPS_OK, "haptic: call: %s", ctx.msg);
    for (v = 0; v < nn; v++) amps_scene_reaction(&ctx, A, v, rh2 + 3 * v);
    for (k = 0; k < h.n; k++)
        for (d = 0; d < 3; d++) gp[3 * k + d] = g0[3 * h.node[k] + d] + d2[d];
    amps_haptic_eval(&h, gp, rm);
    for (k = 0; k < h.n; k++)
        for (d = 0; d < 3; d++) em = fmax(em, fabs(rm[3 * k + d] - rh2[3 * h.node[k] + d]));
    /* the steps at g1 and g2 */
    for (k = 0; k < 2; k++) {
        B = haptic_scene(&ctx, ax);
        haptic_move(&ctx, B, g0, k ? d2 : d1);
        CHECK(amps_scene_step(&ctx, B, 1) == AMPS_OK, "haptic: step: %s", ctx.msg);
        for (v = 0; v < nn; v++) amps_scene_reaction(&ctx, B, v, (k ? rs2 : rs1) + 3 * v);
        amps_scene_free(&ctx, B);
    }
    for (k = 0; k < 3 * nn; k++) {
        double a = rh2[k] - rh1[k], b = rs2[k] - rs1[k];
        num += (a - b) * (a - b);
        den += b * b;
    }
    CHECK(den > 0 && sqrt(num / den) < 1e-8, "haptic: response %.2e from the steps'", sqrt(num / den));
    CHECK(em <= 1e-9 * t_max(3 * (int)nn, rh2), "haptic: the model differs from the call by %.2e", em);
    printf("  haptic between corotational steps (rigid 90 degree turn): response %.2e from the steps', model %.2e\n",
           den > 0 ? sqrt(num / den) : -1.0, em);
    amps_haptic_free(&ctx, &h);
    amps_scene_free(&ctx, A);
    free(g0);
    free(rh1);
    free(rh2);
    free(rs1);
    free(rs2);
    free(rm);
    free(gp);
}

/* The node frames of the haptic path (amps__cr_pin_frames: per pinned node, from its incidence
   list) equal those of the node pass (amps__cr_pass mode 3) bit for bit, for the pins of the
   step and for a node pinned after it; the sheared model's frames differ from node to node. */
static void test_pin_frames(void) {
    amps_ctx ctx;
    amps_scene *S;
    const amps_mesh *m;
    amps_int v, nn, extra = -1, npin = 0;
    double *Rh, spread = 0, em = 0;
    int d;
    amps_ctx_init(&ctx);
    S = amps_scene_create(&ctx, amps_mesh_grid(&ctx, 3, 3, 6, 1, 1, 0.4), NULL);
    CHECK(S != NULL, "pin frames: scene: %s", ctx.msg);
    if (!S) return;
    m = amps_scene_mesh(S);
    nn = m->nnode;
    amps_scene_set_material(&ctx, S, 10.0, 0.35);
    amps_scene_dynamics(&ctx, S, 0.1, 0.1, 0.01);
    amps_scene_corotational(&ctx, S, 1);
    for (v = 0; v < nn; v++) /* bottom held, top pushed sideways: a shear with rotations */
        if (m->xyz[3 * v + 2] < 0.1 || m->xyz[3 * v + 2] > 1.9) {
            int top = m->xyz[3 * v + 2] > 1.9;
            double g[3] = {top ? 0.8 : 0.0, 0, top ? -0.3 : 0.0};
            amps_scene_pin(&ctx, S, v, g);
        } else if (extra < 0 && m->xyz[3 * v + 2] > 1.5) extra = v;
    CHECK(amps_scene_step(&ctx, S, 4) == AMPS_OK, "pin frames: steps: %s", ctx.msg);
    CHECK(amps_scene_solve_reactions(&ctx, S) == AMPS_OK, "pin frames: haptic call: %s", ctx.msg);
    CHECK(amps_scene_pin(&ctx, S, extra, amps_scene_displacements(S) + 3 * extra) == AMPS_OK, "pin frames: pin: %s",
          ctx.msg);
    CHECK(amps_scene_solve_reactions(&ctx, S) == AMPS_OK, "pin frames: haptic call: %s", ctx.msg);
    Rh = (double *)malloc(sizeof(double) * 9 * (size_t)nn);
    memcpy(Rh, S->dyn.cr_Rn, sizeof(double) * 9 * (size_t)nn);
    amps__cr_pass(S, 3);
    for (v = 0; v < nn; v++) {
        if (!S->node.pinned[v]) continue;
        npin++;
        for (d = 0; d < 9; d++) {
            em = fmax(em, fabs(Rh[9 * v + d] - S->dyn.cr_Rn[9 * v + d]));
            spread = fmax(spread, fabs(S->dyn.cr_Rn[9 * v + d] - S->dyn.cr_Rn[9 * extra + d]));
        }
    }
    CHECK(npin > 0 && S->node.pinned[extra], "pin frames: %ld pins", (long)npin);
    CHECK(em == 0.0, "pin frames: the haptic path's frames differ from the node pass's by %.2e", em);
    CHECK(spread > 1e-3, "pin frames: the frames do not vary (%.2e): the test shows nothing", spread);
    printf("  node frames of the haptic path: %ld pinned nodes, equal to the node pass's (frames vary by %.2f)\n",
           (long)npin, spread);
    free(Rh);
    amps_scene_free(&ctx, S);
}

/* A node in no tet (a stray point of the file) in the middle of the numbering: its row of A_R is
   empty; the steps equal those of the same mesh without it (to the PCG's tolerance). */
static void test_stray_node(void) {
    amps_ctx ctx;
    amps_mesh *g, *m[2];
    amps_scene *S[2];
    double *xyz, gv[3] = {0, -9.81, 0}, err = 0;
    amps_int *tet, k = 20, v, t, i;
    int step, d;
    amps_ctx_init(&ctx);
    g = amps_mesh_grid(&ctx, 3, 3, 6, 1, 1, 1);
    xyz = (double *)malloc(sizeof(double) * 3 * ((size_t)g->nnode + 1));
    tet = (amps_int *)malloc(sizeof(amps_int) * 4 * (size_t)g->ntet);
    for (v = 0; v <= g->nnode; v++) /* node k: the stray one, far away */
        for (d = 0; d < 3; d++) xyz[3 * v + d] = v == k ? 10.0 + d : g->xyz[3 * (v - (v > k)) + d];
    for (t = 0; t < 4 * g->ntet; t++) tet[t] = g->tet[t] + (g->tet[t] >= k);
    m[0] = g;
    m[1] = amps_mesh_create(&ctx, g->nnode + 1, xyz, g->ntet, tet);
    CHECK(m[1] != NULL, "stray: mesh: %s", ctx.msg);
    for (i = 0; i < 2 && m[1]; i++) {
        amps_mesh_set_density(&ctx, m[i], 1.0);
        S[i] = amps_scene_create(&ctx, m[i], NULL);
        CHECK(S[i] && amps_scene_fix_where(&ctx, S[i], 2, AMPS_LT, 0.5, NULL) == AMPS_OK &&
                      amps_scene_gravity(&ctx, S[i], gv) == AMPS_OK &&
                      amps_scene_dynamics(&ctx, S[i], 0.05, 0.1, 0.01) == AMPS_OK &&
                      amps_scene_corotational(&ctx, S[i], 1) == AMPS_OK,
              "stray: setup %ld: %s", (long)i, ctx.msg);
        for (step = 0; step < 6; step++)
            CHECK(amps_scene_step(&ctx, S[i], 1) == AMPS_OK, "stray: step %d: %s", step, ctx.msg);
    }
    if (m[1]) {
        const double *w0 = amps_scene_velocities(S[0]), *w1 = amps_scene_velocities(S[1]);
        double nw = 0;
        for (v = 0; v < g->nnode; v++)
            for (d = 0; d < 3; d++) {
                double a = w0[3 * v + d], b = w1[3 * (v + (v >= k)) + d];
                err = fabs(a - b) > err ? fabs(a - b) : err;
                nw = fabs(a) > nw ? fabs(a) : nw;
            }
        CHECK(err <= 1e-8 * nw && nw > 0 && amps_scene_velocities(S[1])[3 * k] == 0,
              "stray: velocities differ by %.2e (max %.2e)", err, nw);
        amps_scene_free(&ctx, S[0]);
        amps_scene_free(&ctx, S[1]);
    }
    free(xyz);
    free(tet);
}

/* A_R of the last step is symmetric to the bit: every block (v, w) of a row of v is the
   transpose of the block (w, v) of the row of w (each tet's pair computed once), v and w not
   held (a held node's row has its mass block only). */
static void check_symmetric(const amps_scene *S) {
    const amps__scene_dyn *D = &S->dyn;
    amps_int k, q, p, qe, pe, bad = 0, nblk = 0;
    int h, g, i;
    for (k = 0; k < D->crA.nnode; k++)
        for (h = 0; h < 2; h++)
            for (q = amps__cr_span(S, h, k, &qe); q < qe; q++) {
                amps_int w = D->crA.be[q] / 3, found = -1;
                if (S->node.dof[3 * D->crA.ord[k]] < 0 || S->node.dof[3 * D->crA.ord[w]] < 0) continue;
                for (g = 0; g < 2 && found < 0; g++)
                    for (p = amps__cr_span(S, g, w, &pe); p < pe; p++)
                        if (D->crA.be[p] == 3 * k) found = p;
                nblk++;
                if (found < 0) {
                    bad++;
                    continue;
                }
                for (i = 0; i < 9; i++)
                    if (D->crA.bx[9 * (size_t)q + i] != D->crA.bx[9 * (size_t)found + 3 * (i % 3) + i / 3]) {
                        bad++;
                        break;
                    }
            }
    CHECK(nblk > 0 && bad == 0, "A_R: %ld of %ld blocks not the transpose of their mirror", (long)bad, (long)nblk);
}

/* The Gauss-Seidel PCG with a node held in one of its equations only (the scene holds whole
   nodes; the engine's own constraints need not): after a step, equation 0 of a free node is
   flagged constrained and the step's A_R is solved for b = A_R y (y random, held entries kept):
   the PCG with Gauss-Seidel (the inverse of D with an identity row and column there) must reach
   the tolerance, keep the held value, and return y on the free entries. */
static void test_gs_partial(void) {
    amps_ctx ctx;
    amps_scene *S;
    amps__scene_dyn *D;
    amps_int v, N, n, e, it, k, held = -1;
    double g[3] = {0.02, 0.01, -0.05}, *b, *x, *y, bn, relres, err = 0, ny = 0;
    amps_ctx_init(&ctx);
    S = amps_scene_create(&ctx, amps_mesh_grid(&ctx, 3, 3, 7, 1, 1, 1), NULL);
    CHECK(S != NULL, "partial: scene: %s", ctx.msg);
    if (!S) return;
    amps_scene_fix_where(&ctx, S, 2, AMPS_LT, 0.5, NULL);
    amps_scene_dynamics(&ctx, S, 0.05, 0.1, 0.01);
    amps_scene_corotational(&ctx, S, 1);
    amps_scene_pin(&ctx, S, 60, g);
    CHECK(amps_scene_step(&ctx, S, 1) == AMPS_OK && amps_scene_step(&ctx, S, 1) == AMPS_OK, "partial: steps: %s",
          ctx.msg);
    D = &S->dyn;
    N = amps_update_dim(S->U);
    n = 3 * S->m->nnode;
    CHECK(D->crA.np > 1, "partial: one slab only (%ld)", (long)D->crA.np);
    check_symmetric(S);
    for (v = 0; v < S->m->nnode && held < 0; v++) /* a free node with its row of blocks */
        if (S->node.dof[3 * v] >= 0 && !D->cr_con[S->node.dof[3 * v]] && !S->node.pinned[v] && v > 20) held = v;
    D->cr_con[S->node.dof[3 * held]] = 1;
    amps__cr_held(S);
    k = D->crA.rank[held];
    CHECK(D->cr_cp[3 * k] && !D->cr_cp[3 * k + 1] && !D->cr_cp[3 * k + 2], "partial: not held in one entry");
    b = D->cr_vec;
    x = b + 3 * (size_t)D->cr_cap;
    y = (double *)malloc(sizeof(double) * (size_t)n);
    for (e = 0; e < n; e++) y[e] = D->cr_cp[e] && e != 3 * k ? 0.0 : sin(0.37 * (double)e + 1.0);
    amps__cr_mul(S, y, b);
    for (e = 0; e < n; e++) x[e] = D->cr_cp[e] ? y[e] : 0.0;
    D->crP.it[0] = 1000; /* the engine's last step "cost" 1000 iterations: Gauss-Seidel is taken */
    D->crP.it[1] = 0;
    it = amps__cr_pcg(&ctx, S, N, b, x, &bn, &relres);
    for (e = 0; e < n; e++) {
        err = fmax(err, fabs(x[e] - y[e]));
        ny = fmax(ny, fabs(y[e]));
    }
    CHECK(it > 0 && it <= 20 && D->info.iterations_gs == it && relres <= 1e-10,
          "partial: %ld iterations (%ld Gauss-Seidel), relres %.2e", (long)it, (long)D->info.iterations_gs, relres);
    CHECK(x[3 * k] == y[3 * k] && err <= 1e-6 * ny, "partial: solution off by %.2e (held %g against %g)", err, x[3 * k],
          y[3 * k]);
    printf("  a node held in one equation: Gauss-Seidel PCG %ld iterations, relres %.1e, error %.1e\n", (long)it,
           relres, err / ny);
    free(y);
    amps_scene_free(&ctx, S);
}

int main(void) {
    test_rotation_kernel();
    test_gs_partial();
    test_threads_bitwise();
    test_solve_rhs();
    test_identity_is_linear();
    test_rigid_motion();
    test_haptic();
    test_pin_frames();
    test_bent_bar();
    test_inverted();
    test_bad_input();
    test_stray_node();
    random_sequence("corot seq 1", 6, 60, 1, 0);
    random_sequence("corot seq 2", 8, 60, 2, 0);
    random_sequence("corot seq, cap 1", 6, 60, 4, 1);
    t_identity = 1;
    random_sequence("identity seq", 6, 40, 3, 0);
    t_identity = 0;
    return amps_t_end("test_corot");
}
