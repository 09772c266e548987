/* Stage 3 accelerator: the adaptive local-mean threshold in one pass over the image.
 *
 * The same binary image, pixel for pixel, as
 *     cv2.adaptiveThreshold(gray, 255, ADAPTIVE_THRESH_MEAN_C, THRESH_BINARY_INV, window, offset)
 * which runs a box filter (the window's mean, rounded to the nearest grey level, the image's
 * edge pixels repeated beyond it) and then a scalar table look-up per pixel: a pixel is ink
 * (255) when  gray - round(mean) <= -floor(offset).
 *
 * Here the window sums come from running column sums (one add and one subtract of a row per
 * row) and a prefix sum along each row, and the rounded mean is never formed: with
 * N = window^2, S the window's sum and k = gray + floor(offset),
 *     round(S / N) >= k   <=>   2 S >= (2 k - 1) N
 * (S / N is never exactly halfway between two integers: N is odd), so the test is integer
 * arithmetic without a division.
 *
 * mean_threshold(gray, out, height, width, window, idelta)
 *     gray: C-contiguous uint8 buffer (height x width); out: writable buffer of the same size.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stdint.h>
#include <stdlib.h>

/* col: w + 2 r column sums (the first and last r repeat the edge columns); prefix: w + 2 r + 1.
 * Unsigned 32-bit sums: a window's sum is a difference of two prefix sums, exact modulo 2^32. */
#if defined(__GNUC__) && defined(__x86_64__) && !defined(__clang__)
__attribute__((target_clones("avx2", "default")))
#endif
static void threshold(const uint8_t *src, uint8_t *dst, int64_t h, int64_t w, int64_t window, int64_t idelta,
                      uint32_t *col, uint32_t *prefix) {
    const int64_t r = window / 2, pw = w + 2 * r;
    const uint32_t n = (uint32_t)(window * window);
    uint32_t *c = col + r; /* c[x] for image column x */
    for (int64_t x = 0; x < w; x++) c[x] = 0;
    for (int64_t dy = -r; dy <= r; dy++) {
        const uint8_t *row = src + (dy < 0 ? 0 : (dy > h - 1 ? h - 1 : dy)) * w;
        for (int64_t x = 0; x < w; x++) c[x] += row[x];
    }
    for (int64_t y = 0; y < h; y++) {
        if (y > 0) { /* the window moves down a row: add the new bottom row, drop the old top */
            int64_t yi = y + r > h - 1 ? h - 1 : y + r, yo = y - r - 1 < 0 ? 0 : y - r - 1;
            const uint8_t *in = src + yi * w, *out = src + yo * w;
            for (int64_t x = 0; x < w; x++) c[x] += (uint32_t)in[x] - (uint32_t)out[x];
        }
        for (int64_t i = 0; i < r; i++) { /* the edge columns repeated */
            col[i] = c[0];
            c[w + i] = c[w - 1];
        }
        uint32_t acc = 0;
        prefix[0] = 0;
        for (int64_t i = 0; i < pw; i++) prefix[i + 1] = acc += col[i];
        const uint8_t *s = src + y * w;
        uint8_t *d = dst + y * w;
        const uint32_t *lo = prefix, *hi = prefix + 2 * r + 1;
        for (int64_t x = 0; x < w; x++) {
            int32_t sum2 = (int32_t)(2 * (hi[x] - lo[x]));     /* 2 S */
            int32_t k2 = 2 * ((int32_t)s[x] + (int32_t)idelta) - 1; /* 2 k - 1 */
            d[x] = sum2 >= k2 * (int32_t)n ? 255 : 0;
        }
    }
}

static PyObject *mean_threshold(PyObject *self, PyObject *args) {
    (void)self;
    Py_buffer src, dst;
    Py_ssize_t h, w, window, idelta;
    if (!PyArg_ParseTuple(args, "y*w*nnnn", &src, &dst, &h, &w, &window, &idelta)) return NULL;
    const char *bad = NULL;
    if (h < 1 || w < 1 || src.len != h * w || dst.len != h * w)
        bad = "gray and out must both hold height x width bytes";
    else if (window < 3 || window % 2 == 0)
        bad = "window must be an odd integer >= 3";
    else if (window > 255 || idelta < -1024 || idelta > 1024)
        bad = "window must be <= 255 and |offset| <= 1024";
    uint32_t *col = NULL, *prefix = NULL;
    if (!bad) {
        col = (uint32_t *)malloc((size_t)(w + window) * sizeof(uint32_t));
        prefix = (uint32_t *)malloc((size_t)(w + window + 1) * sizeof(uint32_t));
    }
    if (!bad && col && prefix) {
        Py_BEGIN_ALLOW_THREADS
        threshold((const uint8_t *)src.buf, (uint8_t *)dst.buf, h, w, window, idelta, col, prefix);
        Py_END_ALLOW_THREADS
    }
    free(col);
    free(prefix);
    PyBuffer_Release(&src);
    PyBuffer_Release(&dst);
    if (bad) {
        PyErr_SetString(PyExc_ValueError, bad);
        return NULL;
    }
    if (!col || !prefix) return PyErr_NoMemory();
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"mean_threshold", mean_threshold, METH_VARARGS,
     "mean_threshold(gray, out, height, width, window, idelta): out = 255 where gray - round(window mean) <= "
     "-idelta, else 0 (cv2.adaptiveThreshold, MEAN_C, BINARY_INV, offset floored)."},
    {NULL, NULL, 0, NULL}};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_threshold", NULL, -1, methods, NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__threshold(void) { return PyModule_Create(&module); }
