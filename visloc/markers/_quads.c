/* Stages 6-7 accelerator: radial-peak corner split and line fits for many contours.
 *
 * The algorithm of visloc.markers.corners_batch.fit_quads (report Appendix G, Figure G.1.D-F),
 * one contour after another in C instead of padded numpy arrays: the radial profile at every
 * f-th contour point (f = max(1, N // 128)), circular Gaussian smoothing, local maxima taken
 * greedily in height order with a circular gap, their prominence, the four most prominent
 * as corners (or the contour points nearest the polygon hint when that fails), padded side
 * groups, total-least-squares lines and their intersections. See corners_batch.py for the
 * reasoning behind each step; this file only mirrors it.
 *
 * fit_quads(points, offsets, hints, sigma, padding) -> (corners, ok)
 *     points: int32 (x, y) pairs of all contours; offsets: int64 (K + 1); hints: float64
 *     (K, 4, 2) or None; sigma <= 0 for the default N / 100; returns float64 (K, 4, 2)
 *     corners (NaN where not found) and uint8 (K,) flags, as bytes.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "_lines.h"

static double round9(double x) { return rint(x * 1e9) / 1e9; }

/* Indices (4, ascending, into the strided profile) of the corners from the radial profile
 * d (nf values); 0 when fewer than four significant peaks. Work arrays of nf entries. */
static int radial_peaks(const double *d, int64_t nf, double *avail, int64_t *chosen_pos, double *valley,
                        int64_t out[4]) {
    int64_t n_max = 0;
    for (int64_t j = 0; j < nf; j++) {
        double prev = d[(j - 1 + nf) % nf], next = d[(j + 1) % nf];
        int is_max = d[j] > prev && d[j] >= next;
        avail[j] = is_max ? d[j] : -INFINITY;
        n_max += is_max;
    }
    if (n_max < 4) return 0;
    int64_t gap = nf / 16 > 2 ? nf / 16 : 2;
    /* greedy in height order: take the highest, drop those within the gap (marks in avail) */
    char *taken = (char *)chosen_pos; /* reuse: flags first, positions after */
    memset(taken, 0, (size_t)nf);
    int64_t n_chosen = 0;
    for (;;) {
        int64_t best = -1;
        double top = -INFINITY;
        for (int64_t j = 0; j < nf; j++)
            if (avail[j] > top) {
                top = avail[j];
                best = j;
            }
        if (best < 0) break;
        taken[best] = 1;
        n_chosen++;
        for (int64_t j = 0; j < nf; j++) {
            int64_t c = j > best ? j - best : best - j;
            if (nf - c < c) c = nf - c;
            if (c < gap) avail[j] = -INFINITY;
        }
    }
    if (n_chosen < 4) return 0;
    /* chosen positions in circular order from the first; valley c = the lowest point from
     * peak c up to the next one */
    int64_t first = 0;
    while (!taken[first]) first++;
    int64_t *pos = (int64_t *)avail; /* avail is no longer needed */
    int64_t c = -1;
    for (int64_t t = 0; t < nf; t++) {
        int64_t p = (first + t) % nf;
        if (taken[p]) {
            c++;
            pos[c] = p;
            valley[c] = d[p];
        } else if (d[p] < valley[c]) {
            valley[c] = d[p];
        }
    }
    double mean = 0.0;
    for (int64_t j = 0; j < nf; j++) mean += d[j];
    mean /= (double)nf;
    const double floor = 0.01 * mean + 0.1;
    /* the four most prominent of the strong peaks (ties: the earlier one) */
    int64_t best4[4];
    double prom4[4];
    int n_strong = 0;
    for (int64_t k = 0; k < n_chosen; k++) {
        double v_prev = valley[(k - 1 + n_chosen) % n_chosen];
        double base = valley[k] > v_prev ? valley[k] : v_prev;
        double prom = d[pos[k]] - base;
        if (!(prom >= floor)) continue;
        /* insert into the top four, sorted by prominence, stable */
        int at = n_strong < 4 ? n_strong : 4;
        while (at > 0 && prom > prom4[at - 1]) at--;
        if (at < 4) {
            int last = n_strong < 4 ? n_strong : 3;
            for (int m = last; m > at; m--) {
                prom4[m] = prom4[m - 1];
                best4[m] = best4[m - 1];
            }
            prom4[at] = prom;
            best4[at] = pos[k];
        }
        n_strong++;
    }
    if (n_strong < 4) return 0;
    for (int i = 1; i < 4; i++) /* ascending */
        for (int j = i; j > 0 && best4[j] < best4[j - 1]; j--) {
            int64_t t = best4[j];
            best4[j] = best4[j - 1];
            best4[j - 1] = t;
        }
    memcpy(out, best4, sizeof(best4));
    return 1;
}

/* One contour of n points p: corners (4, 2) clockwise, 1 when found. `work` holds 5 nf + 2 n
 * doubles. */
static int fit_one(const int32_t *p, int64_t n, const double *hint, double sigma, double padding, double *work,
                   double corners[8]) {
    int64_t f = n / 128 > 1 ? n / 128 : 1;
    int64_t nf = (n + f - 1) / f;
    double *dist = work, *sm = work + nf, *avail = work + 2 * nf, *valley = work + 3 * nf;
    int64_t *scratch = (int64_t *)(work + 4 * nf);
    double *side_x = work + 5 * nf, *side_y = work + 5 * nf + n; /* n each */
    double cx = 0, cy = 0;
    for (int64_t j = 0; j < nf; j++) {
        cx += p[2 * j * f];
        cy += p[2 * j * f + 1];
    }
    cx /= (double)nf;
    cy /= (double)nf;
    for (int64_t j = 0; j < nf; j++) dist[j] = hypot(p[2 * j * f] - cx, p[2 * j * f + 1] - cy);
    /* circular Gaussian smoothing */
    double s = sigma > 0 ? sigma / (double)f : ((double)nf / 100.0 > 1.0 ? (double)nf / 100.0 : 1.0);
    if (!(s < 1e6)) s = 1e6; /* NaN or huge: the conversion below stays defined (r is capped next) */
    int64_t r = (int64_t)ceil(3 * s);
    if (r > (nf - 1) / 2) r = (nf - 1) / 2;
    if (r >= 1) {
        double kern[2 * 512 + 1];
        if (r > 512) r = 512;
        double total = 0;
        for (int64_t o = -r; o <= r; o++) total += kern[o + r] = exp(-0.5 * (o / s) * (o / s));
        for (int64_t o = -r; o <= r; o++) kern[o + r] /= total;
        for (int64_t j = 0; j < nf; j++) {
            double acc = 0;
            for (int64_t o = -r; o <= r; o++) acc += dist[((j + o) % nf + nf) % nf] * kern[o + r];
            sm[j] = round9(acc);
        }
    } else {
        for (int64_t j = 0; j < nf; j++) sm[j] = round9(dist[j]);
    }
    int64_t peaks[4];
    int ok = radial_peaks(sm, nf, avail, scratch, valley, peaks);
    if (ok) {
        for (int i = 0; i < 4; i++) peaks[i] *= f;
    } else if (hint) { /* the contour points nearest the polygon's corners */
        for (int i = 0; i < 4; i++) {
            double best = INFINITY;
            peaks[i] = 0;
            for (int64_t j = 0; j < n; j++) {
                double dx = p[2 * j] - hint[2 * i], dy = p[2 * j + 1] - hint[2 * i + 1];
                double d2 = dx * dx + dy * dy;
                if (d2 < best) {
                    best = d2;
                    peaks[i] = j;
                }
            }
        }
        for (int i = 1; i < 4; i++)
            for (int j = i; j > 0 && peaks[j] < peaks[j - 1]; j--) {
                int64_t t = peaks[j];
                peaks[j] = peaks[j - 1];
                peaks[j - 1] = t;
            }
        ok = peaks[0] < peaks[1] && peaks[1] < peaks[2] && peaks[2] < peaks[3];
    }
    if (!ok) return 0;
    double lines[4][3];
    for (int side = 0; side < 4; side++) {
        int64_t a = peaks[side], b = peaks[(side + 1) % 4];
        int64_t length = ((b - a) % n + n) % n;
        double frac = padding >= 0.0 && padding <= 0.5 ? padding : 0.5; /* NaN too */
        int64_t pad = (int64_t)(frac * (double)length) + 1;
        int64_t size = length - 2 * pad + 1;
        if (size < 2) return 0;
        for (int64_t o = 0; o < size; o++) {
            const int32_t *q = p + 2 * ((a + pad + o) % n);
            side_x[o] = q[0];
            side_y[o] = q[1];
        }
        tls_line(side_x, side_y, NULL, size, lines[side]);
        double *l = lines[side];
        if (l[0] * cx + l[1] * cy > l[2]) { /* normals outward, then half a pixel out to the ink edge */
            l[0] = -l[0];
            l[1] = -l[1];
            l[2] = -l[2];
        }
        l[2] += 0.5;
    }
    if (!quad_corners((const double(*)[3])lines, corners)) return 0;
    double area2 = 0;
    for (int k = 0; k < 4; k++) {
        int m = (k + 1) % 4;
        area2 += corners[2 * k] * corners[2 * m + 1] - corners[2 * m] * corners[2 * k + 1];
    }
    if (area2 <= 0) { /* clockwise in the image, from the first corner */
        double t[2] = {corners[2], corners[3]};
        corners[2] = corners[6];
        corners[3] = corners[7];
        corners[6] = t[0];
        corners[7] = t[1];
    }
    return 1;
}

static PyObject *fit_quads(PyObject *self, PyObject *args) {
    (void)self;
    Py_buffer pts, offs, hints;
    PyObject *hints_obj;
    double sigma, padding;
    if (!PyArg_ParseTuple(args, "y*y*Odd", &pts, &offs, &hints_obj, &sigma, &padding)) return NULL;
    int have_hints = hints_obj != Py_None;
    if (have_hints && PyObject_GetBuffer(hints_obj, &hints, PyBUF_SIMPLE) < 0) {
        PyBuffer_Release(&pts);
        PyBuffer_Release(&offs);
        return NULL;
    }
    const int32_t *p = (const int32_t *)pts.buf;
    const int64_t *o = (const int64_t *)offs.buf;
    Py_ssize_t k = offs.len / (Py_ssize_t)sizeof(int64_t) - 1;
    PyObject *result = NULL;
    const char *bad = NULL;
    if (k < 0 || offs.len % (Py_ssize_t)sizeof(int64_t))
        bad = "offsets: expected K + 1 int64 values";
    else if (have_hints && hints.len != k * 8 * (Py_ssize_t)sizeof(double))
        bad = "hints: expected K x 4 x 2 float64 values";
    else {
        for (Py_ssize_t i = 0; i < k && !bad; i++)
            if (o[i + 1] - o[i] < 4 || o[0] < 0 || 2 * o[i + 1] * (int64_t)sizeof(int32_t) > pts.len)
                bad = "points/offsets: every contour needs at least 4 points inside the points buffer";
    }
    if (bad) {
        PyErr_SetString(PyExc_ValueError, bad);
    } else {
        int64_t n_max = 0;
        for (Py_ssize_t i = 0; i < k; i++)
            if (o[i + 1] - o[i] > n_max) n_max = o[i + 1] - o[i];
        double *work = (double *)malloc((size_t)(7 * (n_max + 1)) * sizeof(double));
        PyObject *corners = PyBytes_FromStringAndSize(NULL, k * 8 * (Py_ssize_t)sizeof(double));
        PyObject *ok = PyBytes_FromStringAndSize(NULL, k);
        if (work && corners && ok) {
            double *c = (double *)PyBytes_AS_STRING(corners);
            uint8_t *flag = (uint8_t *)PyBytes_AS_STRING(ok);
            const double *h = have_hints ? (const double *)hints.buf : NULL;
            Py_BEGIN_ALLOW_THREADS
            for (Py_ssize_t i = 0; i < k; i++) {
                flag[i] = (uint8_t)fit_one(p + 2 * o[i], o[i + 1] - o[i], h ? h + 8 * i : NULL, sigma, padding,
                                           work, c + 8 * i);
                if (!flag[i])
                    for (int m = 0; m < 8; m++) c[8 * i + m] = NAN;
            }
            Py_END_ALLOW_THREADS
        }
        result = corners_result(corners, ok, work);
    }
    PyBuffer_Release(&pts);
    PyBuffer_Release(&offs);
    if (have_hints) PyBuffer_Release(&hints);
    return result;
}

static PyMethodDef methods[] = {
    {"fit_quads", fit_quads, METH_VARARGS,
     "fit_quads(points, offsets, hints, sigma, padding) -> (corners, ok)\n\n"
     "Stages 6-7 for packed contours; see visloc.markers.corners_batch.fit_quads."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_quads", "Stages 6-7: corners from contours.", -1,
                                    methods, NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__quads(void) { return PyModule_Create(&module); }
