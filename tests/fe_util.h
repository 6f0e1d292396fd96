/* Test-side finite element helpers: structured beam/brick tetrahedral meshes and P1
   elasticity assembly into triplets, independent of amps.h's own FEM section. */
#ifndef FE_UTIL_H
#define FE_UTIL_H
#include <stdlib.h>
#include <string.h>
#include <math.h>

typedef struct fe_mesh {
    int nn, nt;
    double *xyz;
    int *tet;
} fe_mesh;

/* Structured grid nx*ny*nz nodes, spacing hx,hy,hz; each hex split into 6 tets (Kuhn). */
static fe_mesh fe_grid(int nx, int ny, int nz, double hx, double hy, double hz) {
    static const int kt[6][4] = {{0, 1, 3, 7}, {0, 1, 5, 7}, {0, 2, 3, 7}, {0, 2, 6, 7}, {0, 4, 5, 7}, {0, 4, 6, 7}};
    fe_mesh m;
    int i, j, k, c, t, nt = 0;
    m.nn = nx * ny * nz;
    m.nt = 6 * (nx - 1) * (ny - 1) * (nz - 1);
    m.xyz = (double *)malloc(sizeof(double) * 3 * m.nn);
    m.tet = (int *)malloc(sizeof(int) * 4 * (m.nt ? m.nt : 1));
    for (k = 0; k < nz; k++)
        for (j = 0; j < ny; j++)
            for (i = 0; i < nx; i++) {
                int v = i + nx * (j + ny * k);
                m.xyz[3 * v] = i * hx;
                m.xyz[3 * v + 1] = j * hy;
                m.xyz[3 * v + 2] = k * hz;
            }
    for (k = 0; k + 1 < nz; k++)
        for (j = 0; j + 1 < ny; j++)
            for (i = 0; i + 1 < nx; i++) {
                int cn[8];
                for (c = 0; c < 8; c++) cn[c] = (i + (c & 1)) + nx * ((j + ((c >> 1) & 1)) + ny * (k + ((c >> 2) & 1)));
                for (t = 0; t < 6; t++) {
                    int q;
                    for (q = 0; q < 4; q++) m.tet[4 * nt + q] = cn[kt[t][q]];
                    nt++;
                }
            }
    return m;
}
static fe_mesh fe_beam(int h) { return fe_grid(5, 5, h, 1.0, 1.0, 1.0); }
static fe_mesh fe_brick(int R) { return fe_grid(R + 1, R + 1, 2 * R + 1, 1.0 / R, 1.0 / R, 1.0 / R); }
static void fe_free(fe_mesh *m) {
    free(m->xyz);
    free(m->tet);
}

/* 12x12 P1 elasticity stiffness of tet X (4 nodes x 3 coords): Ke = vol * B^T C B. */
static void fe_tet_K(const double *X, double E, double nu, double *Ke) {
    double J[9], inv[9], det, g[4][3], B[6][12], C[6][6], CB[6][12], vol, lam, mu;
    int a, b, r, c;
    for (a = 0; a < 3; a++)
        for (b = 0; b < 3; b++) J[3 * a + b] = X[3 * (b + 1) + a] - X[a];
    det = J[0] * (J[4] * J[8] - J[5] * J[7]) - J[1] * (J[3] * J[8] - J[5] * J[6]) + J[2] * (J[3] * J[7] - J[4] * J[6]);
    inv[0] = (J[4] * J[8] - J[5] * J[7]) / det;
    inv[1] = (J[2] * J[7] - J[1] * J[8]) / det;
    inv[2] = (J[1] * J[5] - J[2] * J[4]) / det;
    inv[3] = (J[5] * J[6] - J[3] * J[8]) / det;
    inv[4] = (J[0] * J[8] - J[2] * J[6]) / det;
    inv[5] = (J[2] * J[3] - J[0] * J[5]) / det;
    inv[6] = (J[3] * J[7] - J[4] * J[6]) / det;
    inv[7] = (J[1] * J[6] - J[0] * J[7]) / det;
    inv[8] = (J[0] * J[4] - J[1] * J[3]) / det;
    vol = fabs(det) / 6.0;
    /* grad of barycentric N_{b+1} = row b of inv; N_0 = -(sum) */
    for (c = 0; c < 3; c++) {
        g[0][c] = 0;
        for (b = 0; b < 3; b++) {
            g[b + 1][c] = inv[3 * b + c];
            g[0][c] -= inv[3 * b + c];
        }
    }
    memset(B, 0, sizeof(B));
    for (a = 0; a < 4; a++) {
        B[0][3 * a] = g[a][0];
        B[1][3 * a + 1] = g[a][1];
        B[2][3 * a + 2] = g[a][2];
        B[3][3 * a] = g[a][1];
        B[3][3 * a + 1] = g[a][0];
        B[4][3 * a + 1] = g[a][2];
        B[4][3 * a + 2] = g[a][1];
        B[5][3 * a] = g[a][2];
        B[5][3 * a + 2] = g[a][0];
    }
    lam = E * nu / ((1 + nu) * (1 - 2 * nu));
    mu = E / (2 * (1 + nu));
    memset(C, 0, sizeof(C));
    for (a = 0; a < 3; a++) {
        for (b = 0; b < 3; b++) C[a][b] = lam;
        C[a][a] += 2 * mu;
        C[a + 3][a + 3] = mu;
    }
    for (r = 0; r < 6; r++)
        for (c = 0; c < 12; c++) {
            double s = 0;
            for (a = 0; a < 6; a++) s += C[r][a] * B[a][c];
            CB[r][c] = s;
        }
    for (r = 0; r < 12; r++)
        for (c = 0; c < 12; c++) {
            double s = 0;
            for (a = 0; a < 6; a++) s += B[a][r] * CB[a][c];
            Ke[12 * r + c] = vol * s;
        }
}

/* Node v is fixed if fixed[v]. dof[3v+d] = equation number or -1. Returns ndof. */
static int fe_number(const fe_mesh *m, const int *fixed, int *dof) {
    int v, d, n = 0;
    for (v = 0; v < m->nn; v++)
        for (d = 0; d < 3; d++) dof[3 * v + d] = (fixed && fixed[v]) ? -1 : n++;
    return n;
}

/* Upper-triangle triplets (row <= col) of the assembled stiffness; arrays are malloc'ed. */
static int fe_assemble(const fe_mesh *m, const int *dof, double E, double nu, int **ti, int **tj, double **tx) {
    int t, a, b, nz = 0;
    double X[12], Ke[144];
    *ti = (int *)malloc(sizeof(int) * 78 * (m->nt ? m->nt : 1));
    *tj = (int *)malloc(sizeof(int) * 78 * (m->nt ? m->nt : 1));
    *tx = (double *)malloc(sizeof(double) * 78 * (m->nt ? m->nt : 1));
    for (t = 0; t < m->nt; t++) {
        for (a = 0; a < 4; a++)
            for (b = 0; b < 3; b++) X[3 * a + b] = m->xyz[3 * m->tet[4 * t + a] + b];
        fe_tet_K(X, E, nu, Ke);
        for (a = 0; a < 12; a++)
            for (b = 0; b < 12; b++) {
                int r = dof[3 * m->tet[4 * t + a / 3] + a % 3], c = dof[3 * m->tet[4 * t + b / 3] + b % 3];
                if (r < 0 || c < 0 || r > c) continue;
                (*ti)[nz] = r;
                (*tj)[nz] = c;
                (*tx)[nz] = Ke[12 * a + b];
                nz++;
            }
    }
    return nz;
}
#endif
