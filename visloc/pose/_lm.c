/* Levenberg-Marquardt refinement of camera poses on the reprojection error, compiled.
 *
 * visloc.pose.gauss_newton.levenberg_marquardt step for step (see it for the reasoning): the
 * report's parameters [tx ty tz phi theta psi] with R = Rz(psi) Ry(theta) Rx(phi), residuals
 * f (projected - observed) in pixels, the analytic Jacobian (translation directly, rotation
 * through a small rotation w = W d(angles) acting as w x q), the normal equations as the
 * 7 x 7 matrix M = [J | r]^T [J | r], Marquardt's damping lam diag(J^T J), and the stopping
 * rules shared by all starts (a start far above the lowest one stops earlier). A singular
 * damped system is solved with the pseudo-inverse, as the numpy version does.
 *
 * levenberg_marquardt(params, X, xy, fx, fy, max_iter, rtol, rtol_other, max_iter_other, atol)
 *     params: float64 (S, 6); X: float64 (3, N); xy: float64 (2, N) normalized image
 *     coordinates; returns (params (S, 6), cost (S,), M (S, 7, 7)) as bytes of float64.
 *
 * group_rms(params, X, xy, fx, fy, group)
 *     The RMS reprojection error (px) of each run of ``group`` points (a marker's corners)
 *     under each start: bytes of float64 (S, N / group), inf where a point of the run is not in
 *     front of the camera (visloc.pose.gauss_newton.reprojection_rms).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

typedef struct {
    const double *X, *xy; /* (3, N), (2, N) */
    int64_t n;
    double fx, fy;
} problem;

/* R = Rz(psi) Ry(theta) Rx(phi) of the parameters p (report Appendix G). */
static void rotation(const double p[6], double R[3][3]) {
    double cph = cos(p[3]), sph = sin(p[3]), cth = cos(p[4]), sth = sin(p[4]), cps = cos(p[5]), sps = sin(p[5]);
    double r[3][3] = {{cps * cth, cps * sth * sph - sps * cph, cps * sth * cph + sps * sph},
                      {sps * cth, sps * sth * sph + cps * cph, sps * sth * cph - cps * sph},
                      {-sth, cth * sph, cth * cph}};
    memcpy(R, r, sizeof(r));
}

/* M = E^T E for the parameters p (E = [J | r], 2N rows); M[6][6] = inf when a point is not
 * in front of the camera. */
static void normal_matrix(const problem *pr, const double p[6], double M[7][7]) {
    double R[3][3], cps = cos(p[5]), sps = sin(p[5]);
    rotation(p, R);
    /* columns: Euler rates -> rotation vector (R[2][0] = -sin theta) */
    double W[3][3] = {{R[0][0], -sps, 0.0}, {R[1][0], cps, 0.0}, {R[2][0], 0.0, 1.0}};
    memset(M, 0, sizeof(double) * 49);
    const int64_t n = pr->n;
    int behind = 0;
    for (int64_t i = 0; i < n; i++) {
        double X0 = pr->X[i], X1 = pr->X[n + i], X2 = pr->X[2 * n + i];
        double qx = R[0][0] * X0 + R[0][1] * X1 + R[0][2] * X2;
        double qy = R[1][0] * X0 + R[1][1] * X1 + R[1][2] * X2;
        double qz = R[2][0] * X0 + R[2][1] * X1 + R[2][2] * X2;
        double z = qz + p[2];
        if (!(z > 0.0)) {
            behind = 1;
            continue;
        }
        double iz = 1.0 / z;
        double u = (qx + p[0]) * iz, v = (qy + p[1]) * iz;
        double fu = pr->fx * iz, fv = pr->fy * iz;
        /* rows du and dv of E: translation, rotation ((q x a) . W and (q x b) . W), residual */
        double ga[3] = {-u * qy, u * qx + qz, -qy}, gb[3] = {-v * qy - qz, v * qx, qx};
        double eu[7], ev[7];
        eu[0] = fu;
        eu[1] = 0.0;
        eu[2] = -u * fu;
        ev[0] = 0.0;
        ev[1] = fv;
        ev[2] = -v * fv;
        for (int c = 0; c < 3; c++) {
            eu[3 + c] = (ga[0] * W[0][c] + ga[1] * W[1][c] + ga[2] * W[2][c]) * fu;
            ev[3 + c] = (gb[0] * W[0][c] + gb[1] * W[1][c] + gb[2] * W[2][c]) * fv;
        }
        eu[6] = (u - pr->xy[i]) * pr->fx;
        ev[6] = (v - pr->xy[n + i]) * pr->fy;
        for (int a = 0; a < 7; a++)
            for (int b = a; b < 7; b++) M[a][b] += eu[a] * eu[b] + ev[a] * ev[b];
    }
    for (int a = 0; a < 7; a++)
        for (int b = 0; b < a; b++) M[a][b] = M[b][a];
    if (behind) M[6][6] = INFINITY;
}

/* Symmetric 6 x 6 eigen-decomposition by Jacobi rotations: A -> diag, V columns vectors. */
static void jacobi6(double A[6][6], double V[6][6]) {
    for (int i = 0; i < 6; i++)
        for (int j = 0; j < 6; j++) V[i][j] = i == j;
    for (int sweep = 0; sweep < 60; sweep++) {
        double off = 0;
        for (int i = 0; i < 6; i++)
            for (int j = i + 1; j < 6; j++) off += A[i][j] * A[i][j];
        if (off < 1e-300) break;
        for (int p = 0; p < 6; p++)
            for (int q = p + 1; q < 6; q++) {
                if (A[p][q] == 0.0) continue;
                double theta = 0.5 * (A[q][q] - A[p][p]) / A[p][q];
                double t = (theta >= 0 ? 1.0 : -1.0) / (fabs(theta) + sqrt(theta * theta + 1.0));
                double c = 1.0 / sqrt(t * t + 1.0), s = t * c;
                for (int k = 0; k < 6; k++) { /* A <- J^T A J */
                    double akp = A[k][p], akq = A[k][q];
                    A[k][p] = c * akp - s * akq;
                    A[k][q] = s * akp + c * akq;
                }
                for (int k = 0; k < 6; k++) {
                    double apk = A[p][k], aqk = A[q][k];
                    A[p][k] = c * apk - s * aqk;
                    A[q][k] = s * apk + c * aqk;
                }
                for (int k = 0; k < 6; k++) {
                    double vkp = V[k][p], vkq = V[k][q];
                    V[k][p] = c * vkp - s * vkq;
                    V[k][q] = s * vkp + c * vkq;
                }
            }
    }
}

/* x = A^-1 b by Gaussian elimination with partial pivoting; the pseudo-inverse (eigenvalues
 * below 6 eps of the largest dropped, numpy's default) when A is singular. */
static void solve6(const double A_in[6][6], const double b_in[6], double x[6]) {
    double A[6][7];
    for (int i = 0; i < 6; i++) {
        memcpy(A[i], A_in[i], 6 * sizeof(double));
        A[i][6] = b_in[i];
    }
    int singular = 0;
    for (int c = 0; c < 6 && !singular; c++) {
        int piv = c;
        for (int r = c + 1; r < 6; r++)
            if (fabs(A[r][c]) > fabs(A[piv][c])) piv = r;
        if (A[piv][c] == 0.0) {
            singular = 1;
            break;
        }
        if (piv != c)
            for (int k = 0; k < 7; k++) {
                double t = A[c][k];
                A[c][k] = A[piv][k];
                A[piv][k] = t;
            }
        for (int r = c + 1; r < 6; r++) {
            double m = A[r][c] / A[c][c];
            for (int k = c; k < 7; k++) A[r][k] -= m * A[c][k];
        }
    }
    if (!singular) {
        for (int r = 5; r >= 0; r--) {
            double s = A[r][6];
            for (int k = r + 1; k < 6; k++) s -= A[r][k] * x[k];
            x[r] = s / A[r][r];
        }
        return;
    }
    double S[6][6], V[6][6];
    memcpy(S, A_in, sizeof(S));
    jacobi6(S, V);
    double top = 0;
    for (int i = 0; i < 6; i++)
        if (fabs(S[i][i]) > top) top = fabs(S[i][i]);
    for (int i = 0; i < 6; i++) x[i] = 0;
    for (int k = 0; k < 6; k++) {
        if (!(fabs(S[k][k]) > 6 * 2.220446049250313e-16 * top)) continue;
        double proj = 0;
        for (int i = 0; i < 6; i++) proj += V[i][k] * b_in[i];
        proj /= S[k][k];
        for (int i = 0; i < 6; i++) x[i] += V[i][k] * proj;
    }
}

static PyObject *levenberg_marquardt(PyObject *self, PyObject *args) {
    (void)self;
    Py_buffer pb, Xb, xyb;
    double fx, fy, rtol, rtol_other, atol;
    int max_iter, max_iter_other;
    if (!PyArg_ParseTuple(args, "y*y*y*ddiddid", &pb, &Xb, &xyb, &fx, &fy, &max_iter, &rtol, &rtol_other,
                          &max_iter_other, &atol))
        return NULL;
    Py_ssize_t S = pb.len / (6 * (Py_ssize_t)sizeof(double));
    int64_t n = Xb.len / (3 * (int64_t)sizeof(double));
    PyObject *result = NULL;
    if (pb.len != S * 6 * (Py_ssize_t)sizeof(double) || Xb.len != n * 3 * (int64_t)sizeof(double) ||
        xyb.len != n * 2 * (int64_t)sizeof(double) || S < 1 || n < 1) {
        PyErr_SetString(PyExc_ValueError, "params (S, 6), X (3, N) and xy (2, N) float64 expected");
        goto done;
    }
    PyObject *po = PyBytes_FromStringAndSize((const char *)pb.buf, pb.len);
    PyObject *co = PyBytes_FromStringAndSize(NULL, S * (Py_ssize_t)sizeof(double));
    PyObject *mo = PyBytes_FromStringAndSize(NULL, S * 49 * (Py_ssize_t)sizeof(double));
    double *work = (double *)malloc((size_t)S * (6 + 49 + 3) * sizeof(double));
    if (!po || !co || !mo || !work) {
        Py_XDECREF(po);
        Py_XDECREF(co);
        Py_XDECREF(mo);
        free(work);
        PyErr_NoMemory();
        goto done;
    }
    double *x = (double *)PyBytes_AS_STRING(po), *cost = (double *)PyBytes_AS_STRING(co);
    double(*M)[7][7] = (double(*)[7][7])PyBytes_AS_STRING(mo);
    double *xn = work, *lam = work + 6 * S, *rt = work + 7 * S, *pred = work + 8 * S;
    double(*Mn)[7][7] = (double(*)[7][7])(work + 9 * S);
    char *active = (char *)malloc((size_t)S);
    if (!active) {
        Py_DECREF(po);
        Py_DECREF(co);
        Py_DECREF(mo);
        free(work);
        PyErr_NoMemory();
        goto done;
    }
    problem pr = {(const double *)Xb.buf, (const double *)xyb.buf, n, fx, fy};
    Py_BEGIN_ALLOW_THREADS
    for (Py_ssize_t i = 0; i < S; i++) {
        normal_matrix(&pr, x + 6 * i, M[i]);
        cost[i] = M[i][6][6];
        lam[i] = 1e-3;
        active[i] = isfinite(cost[i]) != 0;
    }
    for (int it = 0; it < max_iter; it++) {
        double best = INFINITY;
        for (Py_ssize_t i = 0; i < S; i++) {
            double step[6] = {0, 0, 0, 0, 0, 0}, g[6];
            pred[i] = 0;
            if (active[i]) {
                double damped[6][6];
                for (int a = 0; a < 6; a++) {
                    g[a] = M[i][a][6]; /* J^T r */
                    for (int b = 0; b < 6; b++) damped[a][b] = M[i][a][b];
                    damped[a][a] += M[i][a][a] * lam[i];
                }
                solve6((const double(*)[6])damped, g, step);
                for (int a = 0; a < 6; a++) pred[i] += step[a] * g[a];
            }
            for (int a = 0; a < 6; a++) xn[6 * i + a] = x[6 * i + a] - step[a];
            if (cost[i] < best) best = cost[i];
        }
        int any = 0;
        for (Py_ssize_t i = 0; i < S; i++) {
            rt[i] = cost[i] <= 1.5 * best ? rtol : rtol_other;
            if (active[i] && (pred[i] <= rt[i] * cost[i] + atol || (it >= max_iter_other && cost[i] > best)))
                active[i] = 0; /* another step would change (next to) nothing */
            any |= active[i];
        }
        if (!any) break;
        for (Py_ssize_t i = 0; i < S; i++) {
            if (!active[i]) continue;
            normal_matrix(&pr, xn + 6 * i, Mn[i]);
            double cn = Mn[i][6][6];
            if (cn < cost[i]) { /* false for nan */
                if (cost[i] - cn <= rt[i] * cost[i]) active[i] = 0;
                memcpy(x + 6 * i, xn + 6 * i, 6 * sizeof(double));
                memcpy(M[i], Mn[i], sizeof(M[i]));
                cost[i] = cn;
                lam[i] = lam[i] * 0.1 > 1e-9 ? lam[i] * 0.1 : 1e-9;
            } else {
                lam[i] *= 10.0;
                if (lam[i] > 1e6) active[i] = 0;
            }
        }
    }
    Py_END_ALLOW_THREADS
    free(active);
    free(work);
    result = Py_BuildValue("(NNN)", po, co, mo);
done:
    PyBuffer_Release(&pb);
    PyBuffer_Release(&Xb);
    PyBuffer_Release(&xyb);
    return result;
}

static PyObject *group_rms(PyObject *self, PyObject *args) {
    (void)self;
    Py_buffer pb, Xb, xyb;
    double fx, fy;
    int group;
    if (!PyArg_ParseTuple(args, "y*y*y*ddi", &pb, &Xb, &xyb, &fx, &fy, &group)) return NULL;
    PyObject *result = NULL;
    Py_ssize_t S = pb.len / (6 * (Py_ssize_t)sizeof(double));
    Py_ssize_t n = Xb.len / (3 * (Py_ssize_t)sizeof(double));
    if (group < 1 || n % group || xyb.len != 2 * n * (Py_ssize_t)sizeof(double) ||
        pb.len != S * 6 * (Py_ssize_t)sizeof(double)) {
        PyErr_SetString(PyExc_ValueError, "group_rms: params (S, 6), X (3, N), xy (2, N), N a multiple of group");
        goto done;
    }
    Py_ssize_t m = n / group;
    PyObject *out = PyBytes_FromStringAndSize(NULL, S * m * (Py_ssize_t)sizeof(double));
    if (!out) goto done;
    double *rms = (double *)PyBytes_AS_STRING(out);
    const double *P = pb.buf, *X = Xb.buf, *xy = xyb.buf;
    for (Py_ssize_t s = 0; s < S; s++) {
        const double *p = P + 6 * s;
        double R[3][3];
        rotation(p, R);
        for (Py_ssize_t g = 0; g < m; g++) {
            double sum = 0.0;
            for (Py_ssize_t i = g * group; i < (g + 1) * group; i++) {
                double X0 = X[i], X1 = X[n + i], X2 = X[2 * n + i];
                double z = R[2][0] * X0 + R[2][1] * X1 + R[2][2] * X2 + p[2];
                if (!(z > 1e-9)) {
                    sum = INFINITY;
                    break;
                }
                double du = ((R[0][0] * X0 + R[0][1] * X1 + R[0][2] * X2 + p[0]) / z - xy[i]) * fx;
                double dv = ((R[1][0] * X0 + R[1][1] * X1 + R[1][2] * X2 + p[1]) / z - xy[n + i]) * fy;
                sum += du * du + dv * dv;
            }
            double r = sqrt(sum / group);
            rms[s * m + g] = isfinite(r) ? r : INFINITY;
        }
    }
    result = out;
done:
    PyBuffer_Release(&pb);
    PyBuffer_Release(&Xb);
    PyBuffer_Release(&xyb);
    return result;
}

static PyMethodDef methods[] = {
    {"levenberg_marquardt", levenberg_marquardt, METH_VARARGS,
     "levenberg_marquardt(params, X, xy, fx, fy, max_iter, rtol, rtol_other, max_iter_other, atol)\n"
     "    -> (params, cost, M)\n\nSee visloc.pose.gauss_newton.levenberg_marquardt."},
    {"group_rms", group_rms, METH_VARARGS,
     "group_rms(params, X, xy, fx, fy, group) -> rms (S, N / group)\n\nSee visloc.pose.gauss_newton.reprojection_rms."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_lm", "Levenberg-Marquardt pose refinement.", -1,
                                    methods, NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__lm(void) { return PyModule_Create(&module); }
