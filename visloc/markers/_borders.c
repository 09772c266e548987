/* Stage 4 accelerator: outer borders of the ink regions that enclose a hole.
 *
 * Suzuki & Abe's border following (1985), the algorithm behind OpenCV's findContours, run on
 * a 1-px zero-padded int32 copy of the binary image: ink (non-zero) is 8-connected, holes are
 * 4-connected. Every border is traced (the marks are what keeps the raster scan exact), but
 * only the points of outer borders are stored, and only the outer borders that are the
 * parent of at least one hole border, with a length inside [min_len, max_len], are returned.
 *
 * The points come out as OpenCV's CHAIN_APPROX_NONE gives them: the start pixel (the
 * region's first pixel in raster order) first, then every border pixel in tracing order.
 * The result is packed (one int32 array of points, one of offsets), so thousands of texture
 * borders cost no Python objects; OpenCV's Python binding allocates one array per border,
 * which is most of its time on textured frames.
 *
 * enclosing_borders(binary, height, width, min_len, max_len)
 *     -> (points: bytes of int32 (x, y) pairs, offsets: bytes of int64 (K + 1), n_outer: int)
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

typedef struct {
    int64_t *v;
    size_t n, cap;
} vec64;

static int push64(vec64 *a, int64_t x) {
    if (a->n == a->cap) {
        size_t cap = a->cap ? 2 * a->cap : 1024;
        int64_t *v = (int64_t *)realloc(a->v, cap * sizeof(int64_t));
        if (!v) return -1;
        a->v = v;
        a->cap = cap;
    }
    a->v[a->n++] = x;
    return 0;
}

typedef struct {
    int32_t *v;
    size_t n, cap;
} vec32;

static int reserve32(vec32 *a, size_t extra) {
    if (a->n + extra > a->cap) {
        size_t cap = a->cap ? a->cap : 4096;
        while (cap < a->n + extra) cap *= 2;
        int32_t *v = (int32_t *)realloc(a->v, cap * sizeof(int32_t));
        if (!v) return -1;
        a->v = v;
        a->cap = cap;
    }
    return 0;
}

/* Per border (index = NBD - 2): parent NBD, outer flag, first point and point count of
 * outer borders (points of hole borders are not kept), and whether a hole has it as parent. */
typedef struct {
    vec64 parent, outer, start, count, holes;
} borders;

/* Neighbour offsets in OpenCV's chain-code order: 0 right, then counter-clockwise on screen
 * (1 up-right, 2 up, 3 up-left, 4 left, 5 down-left, 6 down, 7 down-right), twice over so
 * that a search may run past 7 without a modulo. */
static void deltas(int64_t step, int64_t d[16], int dx[8], int dy[8]) {
    static const int cx[8] = {1, 1, 0, -1, -1, -1, 0, 1};
    static const int cy[8] = {0, -1, -1, -1, 0, 1, 1, 1};
    for (int k = 0; k < 8; k++) {
        dx[k] = cx[k];
        dy[k] = cy[k];
        d[k] = d[k + 8] = cy[k] * step + cx[k];
    }
}

/* Follow one border from the pixel at index p0 (x0, y0 in padded coordinates), marking it
 * with nbd as Suzuki & Abe's step 3 does; store its points when `pts` is not NULL.
 * Returns the number of points, -1 on memory failure. */
static int64_t follow(int32_t *f, int64_t p0, int x0, int y0, int is_hole, int32_t nbd,
                      const int64_t d[16], const int dx[8], const int dy[8], vec32 *pts) {
    int s, s_end;
    int64_t p1, p3, p4;
    int64_t n = 0;
    int x = x0, y = y0;
    /* 3.1: clockwise from the neighbour that started the border (left of an outer border's
     * start, right of a hole border's) for the first non-zero neighbour */
    s_end = s = is_hole ? 0 : 4;
    do {
        s = (s - 1) & 7;
        p1 = p0 + d[s];
    } while (f[p1] == 0 && s != s_end);
    if (s == s_end) { /* an isolated pixel */
        f[p0] = -nbd;
        if (pts) {
            if (reserve32(pts, 2)) return -1;
            pts->v[pts->n++] = x0 - 1;
            pts->v[pts->n++] = y0 - 1;
        }
        return 1;
    }
    p3 = p0;
    for (;;) {
        /* 3.3: counter-clockwise around p3 from the neighbour after the previous pixel */
        s_end = s;
        for (;;) {
            p4 = p3 + d[++s];
            if (f[p4] != 0) break;
        }
        s &= 7;
        /* 3.4: the right neighbour of p3 was examined and is 0 -> negative mark */
        if ((unsigned)(s - 1) < (unsigned)s_end)
            f[p3] = -nbd;
        else if (f[p3] == 1)
            f[p3] = nbd;
        if (pts) {
            if (reserve32(pts, 2)) return -1;
            pts->v[pts->n++] = x - 1;
            pts->v[pts->n++] = y - 1;
        }
        n++;
        x += dx[s];
        y += dy[s];
        /* 3.5: back at the start, about to repeat the first step: done */
        if (p4 == p0 && p3 == p1) break;
        p3 = p4;
        s = (s + 4) & 7;
    }
    return n;
}

/* The padded int32 image is kept between calls (page faults on a fresh 1 MB buffer cost
 * more than the scan); taken and given back with the GIL held, so concurrent calls from other
 * threads simply allocate their own. */
static int32_t *cache = NULL;
static size_t cache_size = 0;

/* The raster scan of Suzuki & Abe's algorithm 1 over the padded image f (h x w inside a
 * frame of zeros, row stride `step`). Returns -1 on memory failure. */
static int scan(int32_t *f, Py_ssize_t h, Py_ssize_t w, int64_t step, borders *b, vec32 *pts) {
    int64_t d[16];
    int dx[8], dy[8];
    deltas(step, d, dx, dy);
    int32_t nbd = 1;
    for (int y = 1; y <= h; y++) {
        int32_t lnbd = 1; /* the frame: a hole border (NBD 1) */
        int32_t *row = f + y * step;
        int x = 1;
        for (;;) {
            while (row[x] == 0 && x <= w) x++; /* the column after the last is 0 */
            if (x > w) break;
            /* x starts a run of ink (its left neighbour is 0); walk it to its end */
            for (;;) {
                int32_t v = row[x];
                int is_hole;
                if (v == 1 && row[x - 1] == 0)
                    is_hole = 0;
                else if (v >= 1 && row[x + 1] == 0) {
                    is_hole = 1;
                    if (v > 1) lnbd = v;
                } else {
                    if (v != 1) lnbd = v < 0 ? -v : v;
                    if (row[++x] == 0) break;
                    continue;
                }
                nbd++;
                /* step 2: the parent from the border met last (lnbd) */
                int64_t parent = 1; /* the frame */
                if (lnbd >= 2) {
                    int same = b->outer.v[lnbd - 2] == !is_hole;
                    parent = same ? b->parent.v[lnbd - 2] : lnbd;
                }
                int64_t start = (int64_t)pts->n / 2;
                int64_t n = follow(f, (int64_t)y * step + x, x, y, is_hole, nbd, d, dx, dy, is_hole ? NULL : pts);
                if (n < 0 || push64(&b->parent, parent) || push64(&b->outer, !is_hole) ||
                    push64(&b->start, is_hole ? -1 : start) || push64(&b->count, n) || push64(&b->holes, 0))
                    return -1;
                if (is_hole && parent >= 2) b->holes.v[parent - 2] = 1;
                /* step 4 */
                v = row[x];
                if (v != 1) lnbd = v < 0 ? -v : v;
                if (row[++x] == 0) break;
            }
        }
    }
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
    const int64_t step = (int64_t)w + 2;
    const size_t size = (size_t)(h + 2) * (size_t)step;
    int32_t *f = NULL;
    if (cache && cache_size >= size) {
        f = cache;
        cache = NULL;
    } else {
        f = (int32_t *)malloc(size * sizeof(int32_t));
    }
    borders b;
    memset(&b, 0, sizeof(b));
    vec32 pts = {0};
    vec64 sel = {0};
    int failed = f == NULL;
    Py_ssize_t n_outer = 0;
    if (!failed) {
        const uint8_t *src = (const uint8_t *)buf.buf;
        Py_BEGIN_ALLOW_THREADS
        memset(f, 0, (size_t)step * sizeof(int32_t));
        memset(f + (h + 1) * step, 0, (size_t)step * sizeof(int32_t));
        for (Py_ssize_t r = 0; r < h; r++) {
            int32_t *row = f + (r + 1) * step;
            const uint8_t *s = src + r * w;
            row[0] = row[w + 1] = 0;
            for (Py_ssize_t c = 0; c < w; c++) row[c + 1] = s[c] != 0;
        }
        failed = scan(f, h, w, step, &b, &pts) != 0;
        for (size_t k = 0; !failed && k < b.outer.n; k++) {
            if (!b.outer.v[k]) continue;
            n_outer++;
            if (b.holes.v[k] && b.count.v[k] >= min_len && b.count.v[k] <= max_len && push64(&sel, (int64_t)k))
                failed = 1;
        }
        Py_END_ALLOW_THREADS
    }
    PyBuffer_Release(&buf);
    if (f && !cache) {
        cache = f;
        cache_size = size;
    } else {
        free(f);
    }
    PyObject *result = NULL;
    if (failed) {
        PyErr_NoMemory();
    } else {
        int64_t total = 0;
        for (size_t i = 0; i < sel.n; i++) total += b.count.v[sel.v[i]];
        PyObject *points = PyBytes_FromStringAndSize(NULL, (Py_ssize_t)(total * 2 * sizeof(int32_t)));
        PyObject *offsets = PyBytes_FromStringAndSize(NULL, (Py_ssize_t)((sel.n + 1) * sizeof(int64_t)));
        if (points && offsets) {
            int32_t *po = (int32_t *)PyBytes_AS_STRING(points);
            int64_t *oo = (int64_t *)PyBytes_AS_STRING(offsets);
            int64_t at = 0;
            /* OpenCV lists the borders last found first */
            for (size_t i = 0; i < sel.n; i++) {
                int64_t k = sel.v[sel.n - 1 - i];
                int64_t cnt = b.count.v[k];
                oo[i] = at;
                memcpy(po + 2 * at, pts.v + 2 * b.start.v[k], (size_t)cnt * 2 * sizeof(int32_t));
                at += cnt;
            }
            oo[sel.n] = at;
            result = Py_BuildValue("(NNn)", points, offsets, n_outer);
        } else {
            Py_XDECREF(points);
            Py_XDECREF(offsets);
        }
    }
    free(pts.v);
    free(sel.v);
    free(b.parent.v);
    free(b.outer.v);
    free(b.start.v);
    free(b.count.v);
    free(b.holes.v);
    return result;
}

static PyMethodDef methods[] = {
    {"enclosing_borders", enclosing_borders, METH_VARARGS,
     "enclosing_borders(binary, height, width, min_len, max_len) -> (points, offsets, n_outer)\n\n"
     "Outer borders (8-connected ink) that enclose a hole, packed; see visloc.markers.contours."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_borders", "Stage 4 border follower.", -1, methods,
                                    NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__borders(void) { return PyModule_Create(&module); }
