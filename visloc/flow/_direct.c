/* Flow's sub-pixel stage in C (visloc.flow.direct.refine_motion): point selection and the
 * Gauss-Newton steps, operation for operation as the numpy version in direct.py computes them.
 *
 * align(first, second, h, w, margin, stride, keep, iterations, tol, a, b, tx, ty)
 *     -> (a, b, tx, ty, gain, offset, spread, ok)
 *     first, second: h x w float32 (the blurred frames); the similarity q = [[a, -b], [b, a]] p + t
 *     with p about the image centre ((w - 1) / 2, (h - 1) / 2); spread, the robust residual
 *     scale of the last step (1.4826 median |r|, grey levels). ok is 0 when a step was not
 *     finite or its normal equations singular (the caller keeps its starting motion).
 *
 * 1. the grid every stride px inside the margin; each point's squared central-difference
 *    gradient in float32; the points whose value is at least the threshold: of every fourth
 *    grid point's values (M), the smallest of the largest max(6, int(M keep));
 * 2. per step (inverse compositional: the Jacobian from the first frame's gradient, half the
 *    central difference): the second frame sampled bilinearly (border replicated) at each
 *    moved point; residual r = s - (gain T + offset); weights min(1, 2 spread / |r|),
 *    spread = 1.4826 median |r| (of every fourth point) + 1e-6; the 6 x 6 normal equations solved by Gaussian
 *    elimination with partial pivoting; the warp composed with the inverse of the step's,
 *    gain and offset added; stop when the translation moves less than tol px.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

static void swap_f(float *a, float *b) {
    float t = *a;
    *a = *b;
    *b = t;
}

/* The k-th smallest of v[0 .. n) (v is reordered). */
static float select_f(float *v, int64_t n, int64_t k) {
    int64_t lo = 0, hi = n - 1;
    while (lo < hi) {
        float pivot = v[lo + (hi - lo) / 2];
        int64_t i = lo, j = hi;
        while (i <= j) {
            while (v[i] < pivot) i++;
            while (v[j] > pivot) j--;
            if (i <= j) swap_f(&v[i++], &v[j--]);
        }
        if (k <= j) hi = j;
        else if (k >= i) lo = i;
        else return v[k];
    }
    return v[k];
}

static void swap_d(double *a, double *b) {
    double t = *a;
    *a = *b;
    *b = t;
}

static double select_d(double *v, int64_t n, int64_t k) {
    int64_t lo = 0, hi = n - 1;
    while (lo < hi) {
        double pivot = v[lo + (hi - lo) / 2];
        int64_t i = lo, j = hi;
        while (i <= j) {
            while (v[i] < pivot) i++;
            while (v[j] > pivot) j--;
            if (i <= j) swap_d(&v[i++], &v[j--]);
        }
        if (k <= j) hi = j;
        else if (k >= i) lo = i;
        else return v[k];
    }
    return v[k];
}

/* numpy.median of v[0 .. n) (v is reordered). */
static double median_d(double *v, int64_t n) {
    double upper = select_d(v, n, n / 2);
    if (n % 2) return upper;
    double lower = v[0];
    for (int64_t i = 1; i < n / 2; i++) /* the largest of the lower half */
        if (v[i] > lower) lower = v[i];
    return 0.5 * (lower + upper);
}

/* Bilinear sample of img (h x w) at (x, y), the border replicated. */
static inline double sample(const float *img, int64_t h, int64_t w, double x, double y) {
    /* floor by truncation (floor() is a library call without SSE4.1), within int64's range */
    x = x < -1e6 ? -1e6 : (x > 1e6 ? 1e6 : x);
    y = y < -1e6 ? -1e6 : (y > 1e6 ? 1e6 : y);
    int64_t x0 = (int64_t)x, y0 = (int64_t)y;
    x0 -= (double)x0 > x;
    y0 -= (double)y0 > y;
    double ax = x - (double)x0, ay = y - (double)y0;
    int64_t x1 = x0 + 1, y1 = y0 + 1;
    x0 = x0 < 0 ? 0 : (x0 > w - 1 ? w - 1 : x0);
    x1 = x1 < 0 ? 0 : (x1 > w - 1 ? w - 1 : x1);
    y0 = y0 < 0 ? 0 : (y0 > h - 1 ? h - 1 : y0);
    y1 = y1 < 0 ? 0 : (y1 > h - 1 ? h - 1 : y1);
    double top = (1.0 - ax) * img[y0 * w + x0] + ax * img[y0 * w + x1];
    double bottom = (1.0 - ax) * img[y1 * w + x0] + ax * img[y1 * w + x1];
    return (1.0 - ay) * top + ay * bottom;
}

/* Solve A d = rhs (6 x 6, A overwritten) by Gaussian elimination with partial pivoting. */
static int solve6(double A[6][6], double rhs[6], double d[6]) {
    for (int c = 0; c < 6; c++) {
        int p = c;
        for (int r = c + 1; r < 6; r++)
            if (fabs(A[r][c]) > fabs(A[p][c])) p = r;
        if (A[p][c] == 0.0) return -1;
        if (p != c) {
            for (int k = 0; k < 6; k++) swap_d(&A[p][k], &A[c][k]);
            swap_d(&rhs[p], &rhs[c]);
        }
        for (int r = c + 1; r < 6; r++) {
            double f = A[r][c] / A[c][c];
            for (int k = c; k < 6; k++) A[r][k] -= f * A[c][k];
            rhs[r] -= f * rhs[c];
        }
    }
    for (int c = 5; c >= 0; c--) {
        double s = rhs[c];
        for (int k = c + 1; k < 6; k++) s -= A[c][k] * d[k];
        d[c] = s / A[c][c];
    }
    return 0;
}

typedef struct {
    double a, b, tx, ty, gain, offset, spread; /* spread: of the last step's residuals */
} similarity;

/* Steps of inverse-compositional Gauss-Newton from s over the n points (px, py about the
 * centre, template T, its gradient gx, gy); 0, or -1 on failure. work: 2 n doubles. */
static int steps(const float *second, int64_t h, int64_t w, double cx, double cy, const float *px,
                 const float *py, const float *T, const float *gx, const float *gy, int64_t n,
                 int64_t iterations, double tol, similarity *s, double *work) {
    double *r = work, *absr = work + n;
    for (int64_t it = 0; it < iterations; it++) {
        double A[6][6], g[6], d[6];
        for (int64_t i = 0; i < n; i++) {
            double qx = s->a * px[i] - s->b * py[i] + s->tx + cx;
            double qy = s->b * px[i] + s->a * py[i] + s->ty + cy;
            r[i] = sample(second, h, w, qx, qy) - (s->gain * T[i] + s->offset);
        }
        int64_t m = 0;
        for (int64_t i = 0; i < n; i += 4) absr[m++] = fabs(r[i]); /* every fourth point's */
        double spread = 1.4826 * median_d(absr, m) + 1e-6;
        s->spread = spread;
        /* the normal equations' upper triangle and right side, accumulated in scalars (a J[6]
         * on the stack made the compiler mix 8- and 16-byte moves: store-forwarding stalls) */
        double h00 = 0, h01 = 0, h02 = 0, h03 = 0, h04 = 0, h05 = 0, h11 = 0, h12 = 0, h13 = 0, h14 = 0, h15 = 0;
        double h22 = 0, h23 = 0, h24 = 0, h25 = 0, h33 = 0, h34 = 0, h35 = 0, h44 = 0, h45 = 0, h55 = 0;
        double g0 = 0, g1 = 0, g2 = 0, g3 = 0, g4 = 0, g5 = 0;
        for (int64_t i = 0; i < n; i++) {
            double ar = fabs(r[i]), cut = 2.0 * spread;
            double wt = ar <= cut ? 1.0 : cut / ar; /* min(1, 2 spread / max(|r|, 1e-12)): spread > 0 */
            double j2 = s->gain * gx[i], j3 = s->gain * gy[i], j4 = T[i];
            double j0 = j2 * px[i] + j3 * py[i], j1 = j3 * px[i] - j2 * py[i];
            double w0 = wt * j0, w1 = wt * j1, w2 = wt * j2, w3 = wt * j3, w4 = wt * j4, w5 = wt;
            h00 += w0 * j0; h01 += w0 * j1; h02 += w0 * j2; h03 += w0 * j3; h04 += w0 * j4; h05 += w0;
            h11 += w1 * j1; h12 += w1 * j2; h13 += w1 * j3; h14 += w1 * j4; h15 += w1;
            h22 += w2 * j2; h23 += w2 * j3; h24 += w2 * j4; h25 += w2;
            h33 += w3 * j3; h34 += w3 * j4; h35 += w3;
            h44 += w4 * j4; h45 += w4;
            h55 += w5;
            g0 += w0 * r[i]; g1 += w1 * r[i]; g2 += w2 * r[i]; g3 += w3 * r[i]; g4 += w4 * r[i]; g5 += w5 * r[i];
        }
        double upper[21] = {h00, h01, h02, h03, h04, h05, h11, h12, h13, h14, h15,
                            h22, h23, h24, h25, h33, h34, h35, h44, h45, h55};
        for (int j = 0, u = 0; j < 6; j++)
            for (int k = j; k < 6; k++, u++) A[j][k] = A[k][j] = upper[u];
        g[0] = g0; g[1] = g1; g[2] = g2; g[3] = g3; g[4] = g4; g[5] = g5;
        if (solve6(A, g, d)) return -1;
        for (int j = 0; j < 6; j++)
            if (!isfinite(d[j])) return -1;
        /* the warp composed with the inverse of the step's: A M^-1, t - A M^-1 dt, with
         * M = [[1 + da, -db], [db, 1 + da]] */
        double ma = 1.0 + d[0], mb = d[1], det = ma * ma + mb * mb;
        if (!(det > 0.0)) return -1;
        double ia = ma / det, ib = -mb / det; /* M^-1 = [[ia, -ib], [ib, ia]] */
        double na = s->a * ia - s->b * ib, nb = s->a * ib + s->b * ia;
        double ntx = s->tx - (na * d[2] - nb * d[3]), nty = s->ty - (nb * d[2] + na * d[3]);
        double moved = fabs(ntx - s->tx) + fabs(nty - s->ty);
        s->a = na;
        s->b = nb;
        s->tx = ntx;
        s->ty = nty;
        s->gain += d[4];
        s->offset += d[5];
        if (moved < tol) break;
    }
    return 0;
}

static PyObject *align(PyObject *self, PyObject *args) {
    (void)self;
    Py_buffer fb, sb;
    Py_ssize_t h, w, margin, stride, iterations;
    double keep, tol;
    similarity s = {0, 0, 0, 0, 1.0, 0.0, 0.0};
    if (!PyArg_ParseTuple(args, "y*y*nnnndnddddd", &fb, &sb, &h, &w, &margin, &stride, &keep, &iterations, &tol,
                          &s.a, &s.b, &s.tx, &s.ty))
        return NULL;
    Py_ssize_t bytes = h * w * (Py_ssize_t)sizeof(float);
    if (h < 2 * margin + 3 || w < 2 * margin + 3 || margin < 1 || stride < 1 || iterations < 1 || fb.len != bytes ||
        sb.len != bytes || !(keep > 0.0 && keep <= 1.0)) {
        PyBuffer_Release(&fb);
        PyBuffer_Release(&sb);
        PyErr_SetString(PyExc_ValueError, "align: bad frame sizes or options");
        return NULL;
    }
    const float *first = (const float *)fb.buf, *second = (const float *)sb.buf;
    int64_t ny = (h - 2 * margin + stride - 1) / stride, nx = (w - 2 * margin + stride - 1) / stride;
    int64_t N = ny * nx;
    float *mag = (float *)malloc((size_t)N * sizeof(float) * 2);
    float *pts = (float *)malloc((size_t)N * sizeof(float) * 5); /* x, y, T, gx, gy of the kept */
    double *work = (double *)malloc((size_t)N * sizeof(double) * 2);
    int failed = !mag || !pts || !work, ok = 0;
    Py_BEGIN_ALLOW_THREADS
    if (!failed) {
        float *scratch = mag + N;
        float *px = pts, *py = pts + N, *T = pts + 2 * N, *gxs = pts + 3 * N, *gys = pts + 4 * N;
        double cx = (w - 1) / 2.0, cy = (h - 1) / 2.0;
        int64_t k = 0;
        for (int64_t y = margin; y < h - margin; y += stride)
            for (int64_t x = margin; x < w - margin; x += stride) {
                const float *row = first + y * w;
                float gx = row[x + 1] - row[x - 1];
                float gy = first[(y + 1) * w + x] - first[(y - 1) * w + x];
                mag[k++] = gx * gx + gy * gy;
            }
        /* the threshold: of every fourth grid point's, the smallest of the keep share */
        int64_t m = 0;
        for (int64_t i = 0; i < N; i += 4) scratch[m++] = mag[i];
        int64_t m_keep = (int64_t)((double)m * keep);
        if (m_keep < 6) m_keep = 6;
        float thr = m_keep < m ? select_f(scratch, m, m - m_keep) : -1.0f;
        int64_t n = 0;
        k = 0;
        for (int64_t y = margin; y < h - margin; y += stride)
            for (int64_t x = margin; x < w - margin; x += stride, k++) {
                if (!(mag[k] >= thr)) continue;
                px[n] = (float)((double)x - cx); /* half-integers: exact */
                py[n] = (float)((double)y - cy);
                T[n] = first[y * w + x];
                gxs[n] = 0.5f * (first[y * w + x + 1] - first[y * w + x - 1]); /* float32, as numpy */
                gys[n] = 0.5f * (first[(y + 1) * w + x] - first[(y - 1) * w + x]);
                n++;
            }
        ok = steps(second, h, w, cx, cy, px, py, T, gxs, gys, n, iterations, tol, &s, work) == 0;
    }
    Py_END_ALLOW_THREADS
    PyBuffer_Release(&fb);
    PyBuffer_Release(&sb);
    free(mag);
    free(pts);
    free(work);
    if (failed) return PyErr_NoMemory();
    return Py_BuildValue("(dddddddi)", s.a, s.b, s.tx, s.ty, s.gain, s.offset, s.spread, ok);
}

static PyMethodDef methods[] = {
    {"align", align, METH_VARARGS,
     "align(first, second, h, w, margin, stride, keep, iterations, tol, a, b, tx, ty)\n"
     "-> (a, b, tx, ty, gain, offset, spread, ok); see visloc.flow.direct."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_direct", "Flow's sub-pixel stage.", -1, methods,
                                    NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__direct(void) { return PyModule_Create(&module); }
