/* Stage 9 accelerator: grey levels sampled through each candidate's homography, and the read of
 * its cells into bits (visloc.markers.bits: sample_quads, read_cells).
 *
 * Every operation is the one the numpy version does, in the same order, in double precision
 * (built with -ffp-contract=off, so no fused multiply-adds), so both give the same samples and
 * the same bits:
 *
 * - the homography of the unit square onto the quad in closed form (bits.square_to_quad);
 * - each point (u, v) of the unit square mapped through it, clamped to [-1, size] (the image's
 *   edge pixels repeat beyond it; NaN goes to -1), read by bilinear interpolation and rounded
 *   to a whole grey level;
 * - a cell's mean, Otsu's split of the cell and ring means, each cell's bit as the majority of
 *   its samples, the border and quiet-zone checks and the margin (bits.read_bits).
 *
 * sample_quads(gray, height, width, quads, uv) -> bytes (K x P uint8)
 * read_cells(gray, height, width, quads, uv, n, m, border, border_error_rate, min_contrast,
 *            min_quiet_zone) -> (samples, cells, valid, bits, margin, contrast, threshold)
 *     quads: K x 4 (x, y) float64; uv: P (u, v) float64 points, for read_cells the n x n cells
 *     then the 4 n + 4 ring cells, m points each.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

/* bits.square_to_quad for one quad q[8] = x0 y0 x1 y1 x2 y2 x3 y3: H row-major. */
static void square_to_quad(const double *q, double *H) {
    double x0 = q[0], y0 = q[1], x1 = q[2], y1 = q[3], x2 = q[4], y2 = q[5], x3 = q[6], y3 = q[7];
    double dx1 = x1 - x2, dx2 = x3 - x2, dx3 = x0 - x1 + x2 - x3;
    double dy1 = y1 - y2, dy2 = y3 - y2, dy3 = y0 - y1 + y2 - y3;
    double den = dx1 * dy2 - dx2 * dy1;
    if (fabs(den) < 1e-12) den = 1e-12;
    double g = (dx3 * dy2 - dx2 * dy3) / den;
    double h = (dx1 * dy3 - dx3 * dy1) / den;
    H[0] = x1 - x0 + g * x1;
    H[1] = x3 - x0 + h * x3;
    H[2] = x0;
    H[3] = y1 - y0 + g * y1;
    H[4] = y3 - y0 + h * y3;
    H[5] = y0;
    H[6] = g;
    H[7] = h;
    H[8] = 1.0;
}

static inline double clamp_coord(double x, double size) {
    if (isnan(x) || x < -1.0) return -1.0;
    return x > size ? size : x;
}

static inline int64_t clamp_index(int64_t i, int64_t size) { return i < 0 ? 0 : (i >= size ? size - 1 : i); }

/* The P points uv mapped through H, read bilinearly and rounded: out[P]. */
static void sample_one(const uint8_t *g, int64_t h, int64_t w, const double *H, const double *uv, int64_t P,
                       uint8_t *out) {
    for (int64_t p = 0; p < P; p++) {
        double u = uv[2 * p], v = uv[2 * p + 1];
        double xn = H[0] * u + H[1] * v + H[2];
        double yn = H[3] * u + H[4] * v + H[5];
        double wn = H[6] * u + H[7] * v + H[8];
        double x = clamp_coord(xn / wn, (double)w), y = clamp_coord(yn / wn, (double)h);
        double x0 = floor(x), y0 = floor(y);
        double fx = x - x0, fy = y - y0;
        int64_t ix = (int64_t)x0, iy = (int64_t)y0;
        int64_t xa = clamp_index(ix, w), xb = clamp_index(ix + 1, w);
        int64_t ya = clamp_index(iy, h), yb = clamp_index(iy + 1, h);
        double a = g[ya * w + xa], b = g[ya * w + xb], c = g[yb * w + xa], d = g[yb * w + xb];
        double val = (a * (1 - fx) + b * fx) * (1 - fy) + (c * (1 - fx) + d * fx) * fy;
        out[p] = (uint8_t)floor(val + 0.5);
    }
}

/* One quad q[8]: its homography, then sample_one. */
static void sample_quad(const uint8_t *g, int64_t h, int64_t w, const double *q, const double *uv, int64_t P,
                        uint8_t *out) {
    double H[9];
    square_to_quad(q, H);
    sample_one(g, h, w, H, uv, P, out);
}

static int cmp_double(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

typedef struct {
    int64_t n, m, border;
    double border_error_rate, min_contrast, min_quiet_zone;
} read_params;

/* bits.read_bits (shading off) for one candidate whose samples s[L * m] are read: the cell
 * means cells[n * n], and valid, bits[s * s], margin, contrast, threshold. work: 2 L doubles. */
static void read_one(const uint8_t *s, const read_params *pr, double *cells, uint8_t *valid, uint8_t *bits,
                     double *margin, double *contrast, double *threshold, double *work) {
    int64_t n = pr->n, m = pr->m, L = n * n + 4 * n + 4, b = pr->border;
    double *vals = work, *sorted = work + L;
    for (int64_t c = 0; c < L; c++) {
        int64_t sum = 0;
        for (int64_t k = 0; k < m; k++) sum += s[c * m + k];
        vals[c] = (double)sum / (double)m;
    }
    memcpy(cells, vals, (size_t)(n * n) * sizeof(double));
    /* Otsu (bits.otsu_threshold): sorted values, running sums, the first best split */
    memcpy(sorted, vals, (size_t)L * sizeof(double));
    qsort(sorted, (size_t)L, sizeof(double), cmp_double);
    for (int64_t i = 1; i < L; i++) sorted[i] = sorted[i - 1] + sorted[i]; /* cumulative, in place */
    double best = -1.0, dark = 0.0, bright = 0.0;
    for (int64_t k = 1; k < L; k++) {
        double m0 = sorted[k - 1] / (double)k;
        double m1 = (sorted[L - 1] - sorted[k - 1]) / (double)(L - k);
        double d = m1 - m0;
        double between = (double)(k * (L - k)) * (d * d);
        if (between > best) {
            best = between;
            dark = m0;
            bright = m1;
        }
    }
    double t = 0.5 * (dark + bright);
    *threshold = t;
    *contrast = bright - dark;
    int64_t ft = (int64_t)floor(t), border_white = 0, size = n - 2 * b;
    double low = INFINITY;
    for (int64_t i = 0; i < n; i++) {
        for (int64_t j = 0; j < n; j++) {
            int64_t c = i * n + j;
            int white;
            if (m > 1) {
                int64_t above = 0;
                for (int64_t k = 0; k < m; k++) above += (int64_t)s[c * m + k] > ft;
                white = 2 * above == m ? vals[c] > t : 2 * above > m;
            } else {
                white = vals[c] > t;
            }
            int inner = i >= b && i < n - b && j >= b && j < n - b;
            if (inner) {
                bits[(i - b) * size + (j - b)] = (uint8_t)white;
                double dist = fabs(vals[c] - t);
                if (dist < low) low = dist;
            } else {
                border_white += white;
            }
        }
    }
    int ok = *contrast >= pr->min_contrast &&
             border_white <= (int64_t)(pr->border_error_rate * (double)(size * size));
    if (pr->min_quiet_zone > 0) {
        int64_t bright_ring = 0;
        for (int64_t c = n * n; c < L; c++) bright_ring += vals[c] > t;
        ok = ok && (double)bright_ring / (double)(L - n * n) >= pr->min_quiet_zone;
    }
    *valid = (uint8_t)ok;
    double half = 0.5 * *contrast;
    double mg = low / (half > 1e-6 ? half : 1e-6);
    *margin = mg < 1.0 ? mg : 1.0;
}

/* Parse gray, height, width, quads, uv; fills the buffers and K, P. 0 on success. */
static int parse_common(Py_buffer *gray, Py_ssize_t h, Py_ssize_t w, Py_buffer *quads, Py_buffer *uv, Py_ssize_t *K,
                        Py_ssize_t *P) {
    const char *bad = NULL;
    if (h <= 0 || w <= 0 || gray->len != h * w) bad = "gray: expected height x width bytes";
    else if (quads->len % (8 * (Py_ssize_t)sizeof(double))) bad = "quads: expected K x 4 x 2 float64";
    else if (uv->len % (2 * (Py_ssize_t)sizeof(double))) bad = "uv: expected P x 2 float64";
    if (bad) {
        PyErr_SetString(PyExc_ValueError, bad);
        return -1;
    }
    *K = quads->len / (8 * (Py_ssize_t)sizeof(double));
    *P = uv->len / (2 * (Py_ssize_t)sizeof(double));
    const double *q = (const double *)quads->buf;
    for (Py_ssize_t i = 0; i < 8 * *K; i++) {
        if (!isfinite(q[i])) {
            PyErr_SetString(PyExc_ValueError, "quads: every corner must be finite");
            return -1;
        }
    }
    return 0;
}

static PyObject *sample_quads(PyObject *self, PyObject *args) {
    (void)self;
    Py_buffer gray, quads, uv;
    Py_ssize_t h, w, K, P;
    if (!PyArg_ParseTuple(args, "y*nny*y*", &gray, &h, &w, &quads, &uv)) return NULL;
    PyObject *out = NULL;
    if (parse_common(&gray, h, w, &quads, &uv, &K, &P) == 0) {
        out = PyBytes_FromStringAndSize(NULL, K * P);
        if (out) {
            uint8_t *o = (uint8_t *)PyBytes_AS_STRING(out);
            const double *q = (const double *)quads.buf;
            Py_BEGIN_ALLOW_THREADS
            for (Py_ssize_t k = 0; k < K; k++)
                sample_quad((const uint8_t *)gray.buf, h, w, q + 8 * k, (const double *)uv.buf, P, o + k * P);
            Py_END_ALLOW_THREADS
        }
    }
    PyBuffer_Release(&gray);
    PyBuffer_Release(&quads);
    PyBuffer_Release(&uv);
    return out;
}

static PyObject *read_cells(PyObject *self, PyObject *args) {
    (void)self;
    Py_buffer gray, quads, uv;
    Py_ssize_t h, w, K, P;
    read_params pr;
    if (!PyArg_ParseTuple(args, "y*nny*y*nnnddd", &gray, &h, &w, &quads, &uv, &pr.n, &pr.m, &pr.border,
                          &pr.border_error_rate, &pr.min_contrast, &pr.min_quiet_zone))
        return NULL;
    PyObject *result = NULL;
    if (parse_common(&gray, h, w, &quads, &uv, &K, &P) == 0) {
        int64_t n = pr.n, m = pr.m, L = n * n + 4 * n + 4, s = n - 2 * pr.border;
        if (n < 3 || m < 1 || pr.border < 1 || s < 1 || P != L * m) {
            PyErr_SetString(PyExc_ValueError, "read_cells: uv must hold m points for each of the n x n cells and "
                                              "the 4 n + 4 ring cells, with n > 2 border");
        } else {
            PyObject *samples = PyBytes_FromStringAndSize(NULL, K * P);
            PyObject *cells = PyBytes_FromStringAndSize(NULL, K * n * n * (Py_ssize_t)sizeof(double));
            PyObject *valid = PyBytes_FromStringAndSize(NULL, K);
            PyObject *bits = PyBytes_FromStringAndSize(NULL, K * s * s);
            PyObject *scal = PyBytes_FromStringAndSize(NULL, 3 * K * (Py_ssize_t)sizeof(double));
            double *work = (double *)malloc((size_t)(2 * L) * sizeof(double));
            if (samples && cells && valid && bits && scal && work) {
                uint8_t *so = (uint8_t *)PyBytes_AS_STRING(samples), *vo = (uint8_t *)PyBytes_AS_STRING(valid);
                uint8_t *bo = (uint8_t *)PyBytes_AS_STRING(bits);
                double *co = (double *)PyBytes_AS_STRING(cells), *sc = (double *)PyBytes_AS_STRING(scal);
                const double *q = (const double *)quads.buf;
                Py_BEGIN_ALLOW_THREADS
                for (Py_ssize_t k = 0; k < K; k++) {
                    sample_quad((const uint8_t *)gray.buf, h, w, q + 8 * k, (const double *)uv.buf, P, so + k * P);
                    read_one(so + k * P, &pr, co + k * n * n, vo + k, bo + k * s * s, sc + k, sc + K + k,
                             sc + 2 * K + k, work);
                }
                Py_END_ALLOW_THREADS
                result = Py_BuildValue("(OOOOO)", samples, cells, valid, bits, scal);
            } else {
                PyErr_NoMemory();
            }
            Py_XDECREF(samples);
            Py_XDECREF(cells);
            Py_XDECREF(valid);
            Py_XDECREF(bits);
            Py_XDECREF(scal);
            free(work);
        }
    }
    PyBuffer_Release(&gray);
    PyBuffer_Release(&quads);
    PyBuffer_Release(&uv);
    return result;
}

static PyMethodDef methods[] = {
    {"sample_quads", sample_quads, METH_VARARGS,
     "sample_quads(gray, height, width, quads, uv) -> bytes\n\n"
     "Grey levels at the unit-square points uv through each quad's homography; see visloc.markers.bits."},
    {"read_cells", read_cells, METH_VARARGS,
     "read_cells(gray, height, width, quads, uv, n, m, border, border_error_rate, min_contrast, min_quiet_zone)\n"
     "-> (samples, cells, valid, bits, margin|contrast|threshold)\n\n"
     "bits.sample_cells and bits.read_bits (shading off) in one pass; see visloc.markers.bits."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_cells", "Stage 9 cell sampling and reading.", -1,
                                    methods, NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__cells(void) { return PyModule_Create(&module); }
