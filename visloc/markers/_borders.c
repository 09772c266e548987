/* Stage 4 accelerator: outer borders of the ink regions that enclose a hole.
 *
 * What cv2.findContours(RETR_CCOMP, CHAIN_APPROX_NONE) gives for those regions, point for
 * point, without following the thousands of texture borders around them:
 *
 * 1. the ink (non-zero) runs of each row are labelled with union-find, joining the runs of
 *    the row above that touch them, diagonally too (8-connected); a label is its region's
 *    first run in raster order, so it also names the region's topmost-leftmost pixel;
 * 2. a region of R runs with A touching pairs of runs (in consecutive rows) has A - R + 1
 *    holes (4-connected white components it encloses): the run-length form of its Euler
 *    number, 1 - holes = R - A;
 * 3. each region with a hole has its outer border followed from its first pixel as Suzuki &
 *    Abe's algorithm (OpenCV's) does: clockwise from the left neighbour for the second
 *    point, then counter-clockwise around each border pixel from the one after the previous,
 *    until the first two points come round again. Borders longer than max_len are dropped
 *    as soon as they are.
 *
 * The borders come out in OpenCV's order (last found first), packed: one int32 array of
 * points and one of offsets, so no Python object is made per border.
 *
 * enclosing_borders(binary, height, width, min_len, max_len)
 *     -> (points: bytes of int32 (x, y) pairs, offsets: bytes of int64 (K + 1))
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

typedef struct {
    int32_t *x0, *x1, *parent, *pairs;
    int64_t n, cap;
} runs;

static int add_run(runs *r, int32_t x0, int32_t x1) {
    if (r->n == r->cap) {
        int64_t cap = r->cap ? 2 * r->cap : 65536;
        int32_t **arrays[4] = {&r->x0, &r->x1, &r->parent, &r->pairs};
        for (int k = 0; k < 4; k++) {
            int32_t *a = (int32_t *)realloc(*arrays[k], (size_t)cap * sizeof(int32_t));
            if (!a) return -1;
            *arrays[k] = a;
        }
        r->cap = cap;
    }
    r->x0[r->n] = x0;
    r->x1[r->n] = x1;
    r->parent[r->n] = (int32_t)r->n;
    r->pairs[r->n] = 0;
    r->n++;
    return 0;
}

static int32_t find(int32_t *parent, int32_t i) {
    while (parent[i] != i) {
        parent[i] = parent[parent[i]]; /* path halving */
        i = parent[i];
    }
    return i;
}

typedef struct {
    int32_t *v;
    int64_t n, cap;
} vec32;

static int push_point(vec32 *a, int32_t x, int32_t y) {
    if (a->n + 2 > a->cap) {
        int64_t cap = a->cap ? 2 * a->cap : 8192;
        int32_t *v = (int32_t *)realloc(a->v, (size_t)cap * sizeof(int32_t));
        if (!v) return -1;
        a->v = v;
        a->cap = cap;
    }
    a->v[a->n++] = x;
    a->v[a->n++] = y;
    return 0;
}

/* Chain-code directions as OpenCV numbers them: 0 right, then counter-clockwise on screen. */
static const int DX[8] = {1, 1, 0, -1, -1, -1, 0, 1};
static const int DY[8] = {0, -1, -1, -1, 0, 1, 1, 1};

static inline int ink_at(const uint8_t *g, int64_t w, int64_t h, int64_t x, int64_t y) {
    return x >= 0 && y >= 0 && x < w && y < h && g[y * w + x] != 0;
}

/* The outer border from the region's first pixel (x0, y0), appended to pts; its length, or
 * -1 when it passed max_len (nothing kept), -2 on memory failure. */
static int64_t follow(const uint8_t *g, int64_t w, int64_t h, int64_t x0, int64_t y0, int64_t max_len, vec32 *pts) {
    int64_t start = pts->n;
    int s = 4, s_end = 4;
    int64_t x1 = 0, y1 = 0;
    do { /* clockwise from the left neighbour (0, as the region starts there) */
        s = (s - 1) & 7;
        x1 = x0 + DX[s];
        y1 = y0 + DY[s];
    } while (!ink_at(g, w, h, x1, y1) && s != s_end);
    if (s == s_end) { /* an isolated pixel */
        if (push_point(pts, (int32_t)x0, (int32_t)y0)) return -2;
        return 1;
    }
    int64_t x3 = x0, y3 = y0, n = 0;
    for (;;) {
        int64_t x4, y4;
        for (;;) { /* counter-clockwise from the neighbour after the previous pixel */
            s = (s + 1) & 7;
            x4 = x3 + DX[s];
            y4 = y3 + DY[s];
            if (ink_at(g, w, h, x4, y4)) break;
        }
        if (n == max_len) { /* one more point than allowed */
            pts->n = start;
            return -1;
        }
        if (push_point(pts, (int32_t)x3, (int32_t)y3)) return -2;
        n++;
        if (x4 == x0 && y4 == y0 && x3 == x1 && y3 == y1) break;
        x3 = x4;
        y3 = y4;
        s = (s + 4) & 7;
    }
    return n;
}

/* The first x >= e in row[.. w) whose pixel is not of the run's colour (w if none): eight
 * pixels at a time (a zero byte found with the usual "has a zero byte" bit trick). */
static inline int64_t run_end(const uint8_t *row, int64_t e, int64_t w, int ink) {
#if (defined(__GNUC__) || defined(__clang__)) && defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
    const uint64_t ones = 0x0101010101010101ULL, highs = 0x8080808080808080ULL;
    while (e + 8 <= w) {
        uint64_t v;
        memcpy(&v, row + e, 8);
        uint64_t t = ink ? (v - ones) & ~v & highs : v;
        if (t) return e + (__builtin_ctzll(t) >> 3); /* little-endian: the lowest byte first */
        e += 8;
    }
#endif
    while (e < w && (row[e] != 0) == ink) e++;
    return e;
}

/* Ink runs of every row (row_start[y] .. row_start[y + 1]) labelled into regions, with the
 * number of runs of the row above each one touches. */
static int label(const uint8_t *g, int64_t h, int64_t w, runs *r, int64_t *row_start) {
    for (int64_t y = 0; y < h; y++) {
        const uint8_t *row = g + y * w;
        row_start[y] = r->n;
        int64_t x = row[0] != 0 ? 0 : run_end(row, 1, w, 0);
        while (x < w) {
            int64_t e = run_end(row, x + 1, w, 1);
            if (add_run(r, (int32_t)x, (int32_t)(e - 1))) return -1;
            x = e < w ? run_end(row, e + 1, w, 0) : w;
        }
        if (y == 0) continue;
        /* join with the row above; both lists are sorted */
        int64_t j = row_start[y - 1], j_end = row_start[y];
        for (int64_t i = row_start[y]; i < r->n; i++) {
            int32_t lo = r->x0[i] - 1, hi = r->x1[i] + 1; /* 8-connected: diagonals touch */
            while (j < j_end && r->x1[j] < lo) j++;
            int32_t root = (int32_t)i;
            for (int64_t k = j; k < j_end && r->x0[k] <= hi; k++) {
                r->pairs[i]++;
                int32_t rk = find(r->parent, (int32_t)k);
                if (root == i) { /* the first run it touches: join its region */
                    r->parent[i] = root = rk;
                } else if (rk != root) { /* two regions meet: the earlier root stays */
                    if (rk < root) {
                        r->parent[root] = rk;
                        root = rk;
                    } else {
                        r->parent[rk] = root;
                    }
                }
            }
        }
    }
    row_start[h] = r->n;
    return 0;
}

static PyObject *enclosing_borders(PyObject *self, PyObject *args) {
    (void)self;
    Py_buffer buf;
    Py_ssize_t h, w, min_len, max_len;
    if (!PyArg_ParseTuple(args, "y*nnnn", &buf, &h, &w, &min_len, &max_len)) return NULL;
    if (h <= 0 || w <= 0 || buf.len != h * w) {
        PyBuffer_Release(&buf);
        PyErr_Format(PyExc_ValueError, "binary: expected %zd x %zd = %zd bytes, got %zd", h, w, h * w,
                     buf.len);
        return NULL;
    }
    const uint8_t *g = (const uint8_t *)buf.buf;
    runs r = {0};
    vec32 pts = {0};
    int64_t *row_start = (int64_t *)malloc((size_t)(h + 1) * sizeof(int64_t));
    int64_t *holes = NULL;   /* per root: pairs - runs */
    int64_t *borders = NULL; /* per kept border: first point index */
    int64_t n_borders = 0;
    int failed = row_start == NULL;
    Py_BEGIN_ALLOW_THREADS
    if (!failed) failed = label(g, h, w, &r, row_start) != 0;
    if (!failed) {
        holes = (int64_t *)calloc((size_t)r.n + 1, sizeof(int64_t));
        borders = (int64_t *)malloc((size_t)(r.n + 1) * sizeof(int64_t));
        failed = !holes || !borders;
    }
    if (!failed) {
        for (int64_t i = 0; i < r.n; i++) {
            holes[find(r.parent, (int32_t)i)] += r.pairs[i] - 1;
        }
        /* the outer borders of the regions with a hole (pairs - runs + 1 > 0), last found first */
        int64_t y = h - 1;
        for (int64_t i = r.n - 1; i >= 0 && !failed; i--) {
            while (i < row_start[y]) y--;
            if (r.parent[i] != i || holes[i] + 1 <= 0) continue;
            int64_t first = pts.n / 2;
            int64_t n = follow(g, w, h, r.x0[i], y, max_len, &pts);
            if (n == -2) failed = 1;
            if (n < min_len) { /* too short, or too long (-1) */
                pts.n = 2 * first;
                continue;
            }
            borders[n_borders++] = first;
        }
    }
    Py_END_ALLOW_THREADS
    PyBuffer_Release(&buf);
    PyObject *result = NULL;
    if (failed) {
        PyErr_NoMemory();
    } else {
        PyObject *points = PyBytes_FromStringAndSize((const char *)pts.v, (Py_ssize_t)(pts.n * sizeof(int32_t)));
        PyObject *offsets = PyBytes_FromStringAndSize(NULL, (Py_ssize_t)((n_borders + 1) * sizeof(int64_t)));
        if (points && offsets) {
            int64_t *o = (int64_t *)PyBytes_AS_STRING(offsets);
            for (int64_t k = 0; k < n_borders; k++) o[k] = borders[k];
            o[n_borders] = pts.n / 2;
            result = Py_BuildValue("(NN)", points, offsets);
        } else {
            Py_XDECREF(points);
            Py_XDECREF(offsets);
        }
    }
    free(row_start);
    free(holes);
    free(borders);
    free(pts.v);
    free(r.x0);
    free(r.x1);
    free(r.parent);
    free(r.pairs);
    return result;
}

static PyMethodDef methods[] = {
    {"enclosing_borders", enclosing_borders, METH_VARARGS,
     "enclosing_borders(binary, height, width, min_len, max_len) -> (points, offsets)\n\n"
     "Outer borders (8-connected ink) that enclose a hole, packed; see visloc.markers.contours."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_borders", "Stage 4 border follower.", -1, methods,
                                    NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__borders(void) { return PyModule_Create(&module); }
