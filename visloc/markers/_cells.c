/* Stages 9-10 accelerator: the read of sampled cells into bits (visloc.markers.bits.read_cells)
 * and their match against the dictionary (bits.decode).
 *
 * For each candidate, from its cells' grey-level samples and its ring's means (as
 * bits.sample_cells gives them): each cell's mean, Otsu's split of the cell and ring means, each
 * cell's bit as the majority of its samples, the border and quiet-zone checks and the margin:
 * bits.read_bits (one threshold per marker), operation for operation in its order and in double
 * precision (built with -ffp-contract=off, so no fused multiply-adds), so both give the same bits.
 *
 * read_samples(samples, ring, K, n, m, border, border_error_rate, min_contrast, min_quiet_zone)
 *     -> (valid, bits, margin|contrast|threshold)
 *     samples: K x n x n x m uint8; ring: K x (4 n + 4) float64.
 *
 * And the maps of the cells' samples (bits.sample_cells and bits.cell_white_fractions read them
 * with cv2.remap):
 *
 * quad_maps(quads, K, uv, P) -> (mx, my)
 *     the image points of the P unit-square points uv (2 x P float32: the u row, then the v
 *     row) on each quad (K x 4 x 2 float64), K x P float32 each: bits.square_to_quad in double
 *     precision, cast to float, the points mapped in single precision as bits._map_points maps
 *     them, operation for operation: the same maps.
 *
 * And the dictionary match (bits.decode):
 *
 * match_codes(bits, K, codes, max_bits, out, ok) -> bool
 *     bits: K x s2 uint8 (0/1); codes: N x 4 uint64 (the dictionary's, id then rotation);
 *     per candidate the first closest code (np.argmin's pick): its id, the corner shift
 *     (4 - rotation) % 4 and distance into out (3 x K Py_ssize_t), whether that is at most
 *     max_bits into ok (K bytes); False when a bit is neither 0 nor 1 (the caller raises).
 *
 * And the sums over the samples read through those maps:
 *
 * sample_means(raw, K, C, m) -> means
 *     raw: K x C x m uint8 (m samples of each of C cells); the K x C float64 means (the whole
 *     sum over m, bits.sample_cells).
 * white_fractions(values, threshold, K, n, per_side) -> fractions
 *     values: K x (n per_side) x (n per_side) uint8, the samples of each of n x n cells in
 *     per_side x per_side blocks; threshold: K float64. The K x n x n float64 share of each
 *     cell's samples above its marker's threshold (bits.cell_white_fractions).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#if defined(__SSE2__) || defined(_M_X64)
#include <emmintrin.h>
#endif

/* v[0 .. n) in ascending order (finite values): insertion sort, several times faster than
 * qsort's callbacks on the 40-150 values of a candidate's cells and ring */
static void sort_doubles(double *v, int64_t n) {
    for (int64_t i = 1; i < n; i++) {
        double x = v[i];
        int64_t j = i;
        for (; j > 0 && v[j - 1] > x; j--) v[j] = v[j - 1];
        v[j] = x;
    }
}

typedef struct {
    int64_t n, m, border;
    double border_error_rate, min_contrast, min_quiet_zone;
} read_params;

/* bits.read_bits (shading off) for one candidate: its cells' samples s[n * n * m] and ring
 * means ring[4 n + 4]; valid, bits[(n - 2 border)^2], margin, contrast, threshold. work: 2 L
 * doubles. */
static void read_one(const uint8_t *s, const double *ring, const read_params *pr, uint8_t *valid, uint8_t *bits,
                     double *margin, double *contrast, double *threshold, double *work) {
    int64_t n = pr->n, m = pr->m, L = n * n + 4 * n + 4, b = pr->border;
    double *vals = work, *sorted = work + L;
    for (int64_t c = 0; c < n * n; c++) {
        int64_t sum = 0;
        for (int64_t k = 0; k < m; k++) sum += s[c * m + k];
        vals[c] = (double)sum / (double)m;
    }
    memcpy(vals + n * n, ring, (size_t)(4 * n + 4) * sizeof(double));
    /* Otsu (bits.otsu_threshold): sorted values, running sums, the first best split */
    memcpy(sorted, vals, (size_t)L * sizeof(double));
    sort_doubles(sorted, L);
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

static PyObject *read_samples(PyObject *self, PyObject *args) {
    (void)self;
    Py_buffer samples, ring;
    Py_ssize_t K;
    read_params pr;
    if (!PyArg_ParseTuple(args, "y*y*nnnnddd", &samples, &ring, &K, &pr.n, &pr.m, &pr.border,
                          &pr.border_error_rate, &pr.min_contrast, &pr.min_quiet_zone))
        return NULL;
    PyObject *result = NULL;
    int64_t n = pr.n, m = pr.m, L = n * n + 4 * n + 4, s = n - 2 * pr.border;
    const char *bad = NULL;
    if (K < 0 || n < 3 || n > 64 || m < 1 || m > 4096 || pr.border < 1 || s < 1)
        bad = "read_samples: need K >= 0, 3 <= n <= 64, 1 <= m <= 4096 and n > 2 border >= 2";
    else if (samples.len != K * n * n * m || ring.len != K * (4 * n + 4) * (Py_ssize_t)sizeof(double))
        bad = "read_samples: expected K x n x n x m uint8 samples and K x (4 n + 4) float64 ring means";
    if (bad) {
        PyErr_SetString(PyExc_ValueError, bad);
    } else {
        PyObject *valid = PyBytes_FromStringAndSize(NULL, K);
        PyObject *bits = PyBytes_FromStringAndSize(NULL, K * s * s);
        PyObject *scal = PyBytes_FromStringAndSize(NULL, 3 * K * (Py_ssize_t)sizeof(double));
        double *work = (double *)malloc((size_t)(2 * L) * sizeof(double));
        if (valid && bits && scal && work) {
            uint8_t *vo = (uint8_t *)PyBytes_AS_STRING(valid), *bo = (uint8_t *)PyBytes_AS_STRING(bits);
            double *sc = (double *)PyBytes_AS_STRING(scal);
            const uint8_t *so = (const uint8_t *)samples.buf;
            const double *ro = (const double *)ring.buf;
            Py_BEGIN_ALLOW_THREADS
            for (Py_ssize_t k = 0; k < K; k++)
                read_one(so + k * n * n * m, ro + k * (4 * n + 4), &pr, vo + k, bo + k * s * s, sc + k, sc + K + k,
                         sc + 2 * K + k, work);
            Py_END_ALLOW_THREADS
            result = Py_BuildValue("(OOO)", valid, bits, scal);
        } else {
            PyErr_NoMemory();
        }
        Py_XDECREF(valid);
        Py_XDECREF(bits);
        Py_XDECREF(scal);
        free(work);
    }
    PyBuffer_Release(&samples);
    PyBuffer_Release(&ring);
    return result;
}

/* bits.square_to_quad of one quad q[8] ((x, y) of its corners 0-3), its operations in their order,
 * cast to single precision as bits._map_points casts it. */
static void square_to_quad(const double *q, float H[9]) {
    double x0 = q[0], y0 = q[1], x1 = q[2], y1 = q[3], x2 = q[4], y2 = q[5], x3 = q[6], y3 = q[7];
    double dx1 = x1 - x2, dx2 = x3 - x2, dx3 = x0 - x1 + x2 - x3;
    double dy1 = y1 - y2, dy2 = y3 - y2, dy3 = y0 - y1 + y2 - y3;
    double den = dx1 * dy2 - dx2 * dy1;
    if (fabs(den) < 1e-12) den = 1e-12;
    double g = (dx3 * dy2 - dx2 * dy3) / den, h = (dx1 * dy3 - dx3 * dy1) / den;
    H[0] = (float)(x1 - x0 + g * x1);
    H[1] = (float)(x3 - x0 + h * x3);
    H[2] = (float)x0;
    H[3] = (float)(y1 - y0 + g * y1);
    H[4] = (float)(y3 - y0 + h * y3);
    H[5] = (float)y0;
    H[6] = (float)g;
    H[7] = (float)h;
    H[8] = 1.0f;
}

/* The image points of the P unit-square points (u[p], v[p]) under H into mx, my:
 * ((h0 u + h1 v) + h2) / ((h6 u + h7 v) + h8) and the same for y, in single precision, four
 * points at a time with SSE where there is SSE (each lane the scalar operations). */
static void map_points(const float H[9], const float *u, const float *v, Py_ssize_t P, float *mx, float *my) {
    Py_ssize_t p = 0;
#if defined(__SSE2__) || defined(_M_X64)
    const __m128 h0 = _mm_set1_ps(H[0]), h1 = _mm_set1_ps(H[1]), h2 = _mm_set1_ps(H[2]);
    const __m128 h3 = _mm_set1_ps(H[3]), h4 = _mm_set1_ps(H[4]), h5 = _mm_set1_ps(H[5]);
    const __m128 h6 = _mm_set1_ps(H[6]), h7 = _mm_set1_ps(H[7]), h8 = _mm_set1_ps(H[8]);
    for (; p + 4 <= P; p += 4) {
        __m128 a = _mm_loadu_ps(u + p), b = _mm_loadu_ps(v + p);
        __m128 zn = _mm_add_ps(_mm_add_ps(_mm_mul_ps(h6, a), _mm_mul_ps(h7, b)), h8);
        _mm_storeu_ps(mx + p, _mm_div_ps(_mm_add_ps(_mm_add_ps(_mm_mul_ps(h0, a), _mm_mul_ps(h1, b)), h2), zn));
        _mm_storeu_ps(my + p, _mm_div_ps(_mm_add_ps(_mm_add_ps(_mm_mul_ps(h3, a), _mm_mul_ps(h4, b)), h5), zn));
    }
#endif
    for (; p < P; p++) {
        float zn = H[6] * u[p] + H[7] * v[p] + H[8];
        mx[p] = (H[0] * u[p] + H[1] * v[p] + H[2]) / zn;
        my[p] = (H[3] * u[p] + H[4] * v[p] + H[5]) / zn;
    }
}

static PyObject *quad_maps(PyObject *self, PyObject *args) {
    (void)self;
    Py_buffer quads, uv;
    Py_ssize_t K, P;
    if (!PyArg_ParseTuple(args, "y*ny*n", &quads, &K, &uv, &P)) return NULL;
    PyObject *mx = NULL, *my = NULL, *result = NULL;
    if (K < 0 || P < 0 || quads.len != K * 8 * (Py_ssize_t)sizeof(double) || uv.len != 2 * P * (Py_ssize_t)sizeof(float)) {
        PyErr_SetString(PyExc_ValueError, "quad_maps: expected K x 4 x 2 float64 quads and 2 x P float32 points");
    } else if ((mx = PyBytes_FromStringAndSize(NULL, K * P * (Py_ssize_t)sizeof(float))) != NULL &&
               (my = PyBytes_FromStringAndSize(NULL, K * P * (Py_ssize_t)sizeof(float))) != NULL) {
        const double *q = (const double *)quads.buf;
        const float *u = (const float *)uv.buf, *v = u + P;
        float *ox = (float *)PyBytes_AS_STRING(mx), *oy = (float *)PyBytes_AS_STRING(my);
        Py_BEGIN_ALLOW_THREADS
        for (Py_ssize_t k = 0; k < K; k++) {
            float H[9];
            square_to_quad(q + 8 * k, H);
            map_points(H, u, v, P, ox + k * P, oy + k * P);
        }
        Py_END_ALLOW_THREADS
        result = Py_BuildValue("(OO)", mx, my);
    }
    Py_XDECREF(mx);
    Py_XDECREF(my);
    PyBuffer_Release(&quads);
    PyBuffer_Release(&uv);
    return result;
}

static PyObject *sample_means(PyObject *self, PyObject *args) {
    (void)self;
    Py_buffer raw;
    Py_ssize_t K, C, m;
    if (!PyArg_ParseTuple(args, "y*nnn", &raw, &K, &C, &m)) return NULL;
    PyObject *out = NULL;
    if (K < 0 || C < 0 || m < 1 || raw.len != K * C * m) {
        PyErr_SetString(PyExc_ValueError, "sample_means: expected K x C x m uint8 samples, m >= 1");
    } else if ((out = PyBytes_FromStringAndSize(NULL, K * C * (Py_ssize_t)sizeof(double))) != NULL) {
        const uint8_t *r = (const uint8_t *)raw.buf;
        double *o = (double *)PyBytes_AS_STRING(out);
        Py_BEGIN_ALLOW_THREADS
        for (Py_ssize_t c = 0; c < K * C; c++) {
            uint32_t sum = 0;
            for (Py_ssize_t i = 0; i < m; i++) sum += r[c * m + i];
            o[c] = (double)sum / (double)m;
        }
        Py_END_ALLOW_THREADS
    }
    PyBuffer_Release(&raw);
    return out;
}

static PyObject *white_fractions(PyObject *self, PyObject *args) {
    (void)self;
    Py_buffer values, thr;
    Py_ssize_t K, n, ps;
    if (!PyArg_ParseTuple(args, "y*y*nnn", &values, &thr, &K, &n, &ps)) return NULL;
    PyObject *out = NULL;
    Py_ssize_t side = n * ps;
    if (K < 0 || n < 1 || ps < 1 || values.len != K * side * side || thr.len != K * (Py_ssize_t)sizeof(double)) {
        PyErr_SetString(PyExc_ValueError, "white_fractions: expected K x (n per_side)^2 uint8 values and K float64 thresholds");
    } else if ((out = PyBytes_FromStringAndSize(NULL, K * n * n * (Py_ssize_t)sizeof(double))) != NULL) {
        const uint8_t *v = (const uint8_t *)values.buf;
        const double *t = (const double *)thr.buf;
        double *o = (double *)PyBytes_AS_STRING(out);
        Py_BEGIN_ALLOW_THREADS
        for (Py_ssize_t k = 0; k < K; k++) {
            /* a grey level v is above t when v >= cut: the least whole number above t (none: NaN) */
            int cut = !(t[k] == t[k]) ? 256 : t[k] < 0.0 ? 0 : t[k] >= 255.0 ? 256 : (int)floor(t[k]) + 1;
            const uint8_t *vk = v + k * side * side;
            double *ok = o + k * n * n;
            for (Py_ssize_t cy = 0; cy < n; cy++)
                for (Py_ssize_t cx = 0; cx < n; cx++) {
                    int count = 0;
                    for (Py_ssize_t y = cy * ps; y < (cy + 1) * ps; y++) {
                        const uint8_t *r = vk + y * side + cx * ps;
                        for (Py_ssize_t x = 0; x < ps; x++) count += r[x] >= cut;
                    }
                    ok[cy * n + cx] = (double)count / (double)(ps * ps);
                }
        }
        Py_END_ALLOW_THREADS
    }
    PyBuffer_Release(&values);
    PyBuffer_Release(&thr);
    return out;
}

/* The number of set bits of v: the compiler's bit counting, else Kernighan's loop. */
#if defined(__GNUC__) || defined(__clang__)
#define POPCOUNT64(v) __builtin_popcountll(v)
#else
static int popcount_loop(uint64_t v) {
    int c = 0;
    for (; v; v &= v - 1) c++;
    return c;
}
#define POPCOUNT64(v) popcount_loop(v)
#endif

/* The index of the first of the nc codes closest to code, and its distance into *low. The
 * popcnt instruction where the processor has it (checked once at run time; without it the
 * compiler's bit counting is ten times slower), else that bit counting. */
#define CLOSEST_BODY                                  \
    Py_ssize_t best = 0;                              \
    int d0 = 65;                                      \
    for (Py_ssize_t j = 0; j < nc; j++) {             \
        int d = POPCOUNT64(code ^ c[j]);              \
        if (d < d0) {                                 \
            d0 = d;                                   \
            best = j;                                 \
        }                                             \
    }                                                 \
    *low = d0;                                        \
    return best;
#if (defined(__GNUC__) || defined(__clang__)) && (defined(__x86_64__) || defined(__i386__))
__attribute__((target("popcnt"))) static Py_ssize_t closest_popcnt(uint64_t code, const uint64_t *c, Py_ssize_t nc,
                                                                   int *low) {
    CLOSEST_BODY
}
#define HAVE_POPCNT_TARGET 1
#endif
static Py_ssize_t closest_generic(uint64_t code, const uint64_t *c, Py_ssize_t nc, int *low) { CLOSEST_BODY }

/* bits.decode: each candidate's s2 bits (0/1, cell i is bit i of its code) against the
 * dictionary's N x 4 codes (id, then rotation); the first closest code wins, as argmin picks
 * it. Written into out (3 x K Py_ssize_t: ids, corner shifts (4 - rotation) % 4, Hamming
 * distances) and ok (K bytes: distance at most max_bits); returns False (nothing written past
 * it) when a bit is neither 0 nor 1. */
static PyObject *match_codes(PyObject *self, PyObject *args) {
    (void)self;
    Py_buffer bits, codes, out, ok;
    Py_ssize_t K, max_bits;
    if (!PyArg_ParseTuple(args, "y*ny*nw*w*", &bits, &K, &codes, &max_bits, &out, &ok)) return NULL;
    PyObject *result = NULL;
    Py_ssize_t s2 = K > 0 ? bits.len / K : 0, nc = codes.len / (Py_ssize_t)sizeof(uint64_t);
    if (K < 1 || bits.len != K * s2 || s2 < 1 || s2 > 64 || nc < 4 || nc % 4 ||
        codes.len != nc * (Py_ssize_t)sizeof(uint64_t) || out.len != 3 * K * (Py_ssize_t)sizeof(Py_ssize_t) ||
        ok.len != K) {
        PyErr_SetString(PyExc_ValueError, "match_codes: expected K >= 1 x s2 uint8 bits (s2 <= 64), N x 4 uint64 "
                                          "codes, 3 x K intp and K bool outputs");
    } else {
        const uint8_t *b = (const uint8_t *)bits.buf;
        const uint64_t *c = (const uint64_t *)codes.buf;
        Py_ssize_t *io = (Py_ssize_t *)out.buf, *so = io + K, *ho = io + 2 * K;
        uint8_t *oo = (uint8_t *)ok.buf;
        int binary = 1;
        Py_ssize_t (*closest)(uint64_t, const uint64_t *, Py_ssize_t, int *) = closest_generic;
#ifdef HAVE_POPCNT_TARGET
        if (__builtin_cpu_supports("popcnt")) closest = closest_popcnt;
#endif
        Py_BEGIN_ALLOW_THREADS
        for (Py_ssize_t k = 0; k < K && binary; k++) {
            uint64_t code = 0;
            for (Py_ssize_t i = 0; i < s2; i++) {
                binary &= b[k * s2 + i] <= 1;
                code |= (uint64_t)(b[k * s2 + i] & 1) << i;
            }
            int low;
            Py_ssize_t best = closest(code, c, nc, &low);
            io[k] = best / 4;
            so[k] = (4 - best % 4) % 4;
            ho[k] = low;
            oo[k] = low <= max_bits;
        }
        Py_END_ALLOW_THREADS
        result = PyBool_FromLong(binary);
    }
    PyBuffer_Release(&bits);
    PyBuffer_Release(&codes);
    PyBuffer_Release(&out);
    PyBuffer_Release(&ok);
    return result;
}

static PyMethodDef methods[] = {
    {"read_samples", read_samples, METH_VARARGS,
     "read_samples(samples, ring, K, n, m, border, border_error_rate, min_contrast, min_quiet_zone)\n"
     "-> (valid, bits, margin|contrast|threshold)\n\n"
     "bits.read_bits (shading off) on sampled cells; see visloc.markers.bits.read_cells."},
    {"quad_maps", quad_maps, METH_VARARGS,
     "quad_maps(quads, K, uv, P) -> (mx, my)\n\n"
     "Image points (K x P float32 each) of unit-square points on each quad; see visloc.markers.bits._map_points."},
    {"match_codes", match_codes, METH_VARARGS,
     "match_codes(bits, K, codes, max_bits, out, ok) -> bool\n\n"
     "bits.decode on K x s2 uint8 bits against N x 4 uint64 codes into out (3 x K intp) and ok (K bool); "
     "False: a bit not 0 or 1."},
    {"sample_means", sample_means, METH_VARARGS,
     "sample_means(raw, K, C, m) -> K x C float64 means of m uint8 samples each; see visloc.markers.bits.sample_cells."},
    {"white_fractions", white_fractions, METH_VARARGS,
     "white_fractions(values, threshold, K, n, per_side) -> K x n x n float64; see visloc.markers.bits.cell_white_fractions."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_cells", "Stages 9-10: the maps of the cells' samples, their read into bits, the dictionary match.", -1,
                                    methods, NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__cells(void) { return PyModule_Create(&module); }
