/* Stage 5 accelerator: the candidate filter of visloc.markers.contours.filter_candidates.
 *
 * The same tests in the same order, for packed contours: length bounds, area and
 * compactness, a four-vertex polygon approximation (Douglas-Peucker as cv2.approxPolyDP
 * computes it for closed curves, a coarser try when a spur gives five to eight vertices, with
 * most of the contour on the quad's sides), convexity (as cv2.isContourConvex: collinear
 * edges do not count as convex), shortest side, distance from the image border, solidity
 * (area over the convex hull's area). Areas are the shoelace sums cv2.contourArea computes;
 * the hull is Andrew's monotone chain (its area is the hull's, whatever the algorithm).
 *
 * filter_quads(points, offsets, width, height, params) -> (kept, quads)
 *     points: int32 (x, y) pairs; offsets: int64 (K + 1); params: (min_len, max_len,
 *     approx_rate, min_side, min_solidity, min_compactness, border_distance); returns the
 *     indices (int64) of the contours kept and their quads (int32 (k, 4, 2)), as bytes.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

typedef struct {
    int32_t x, y;
} pt;

typedef struct {
    int64_t start, end;
} range;

/* |shoelace area| of a closed polygon, as cv2.contourArea (not oriented). */
static double polygon_area(const pt *p, int64_t n) {
    double a = 0;
    if (n < 3) return 0;
    pt prev = p[n - 1];
    for (int64_t i = 0; i < n; i++) {
        a += (double)prev.x * p[i].y - (double)prev.y * p[i].x;
        prev = p[i];
    }
    return fabs(a) * 0.5;
}

static int cmp_pt(const void *a, const void *b) {
    const pt *p = (const pt *)a, *q = (const pt *)b;
    if (p->x != q->x) return p->x < q->x ? -1 : 1;
    return p->y < q->y ? -1 : (p->y > q->y);
}

static int64_t cross(pt o, pt a, pt b) {
    return (int64_t)(a.x - o.x) * (b.y - o.y) - (int64_t)(a.y - o.y) * (b.x - o.x);
}

/* Area of the convex hull of n points (sorted copy in `tmp`, hull in `hull`, 2 n + 1 entries). */
static double hull_area(const pt *p, int64_t n, pt *tmp, pt *hull) {
    memcpy(tmp, p, (size_t)n * sizeof(pt));
    qsort(tmp, (size_t)n, sizeof(pt), cmp_pt);
    int64_t k = 0;
    for (int64_t i = 0; i < n; i++) { /* lower hull */
        while (k >= 2 && cross(hull[k - 2], hull[k - 1], tmp[i]) <= 0) k--;
        hull[k++] = tmp[i];
    }
    for (int64_t i = n - 2, t = k + 1; i >= 0; i--) { /* upper hull */
        while (k >= t && cross(hull[k - 2], hull[k - 1], tmp[i]) <= 0) k--;
        hull[k++] = tmp[i];
    }
    return polygon_area(hull, k > 1 ? k - 1 : k);
}

/* Douglas-Peucker approximation of a closed contour, following cv2.approxPolyDP's steps:
 * two far-apart points from three sweeps, the recursion on a stack of slices, then the
 * removal of vertices on nearly straight runs. Returns the vertex count (written to dst,
 * n entries); `stack` holds n + 2 slices. */
static int64_t approx_closed(const pt *src, int64_t count, double eps, pt *dst, range *stack) {
    int64_t top = 0, new_count = 0, pos = 0;
    range slice = {0, 0}, right = {0, 0};
    pt start_pt = {-1000000, -1000000}, end_pt, p;
    int le_eps = 0;
    if (count == 0) return 0;
    eps *= eps;
    /* 1. approximately the two farthest points */
    right.start = 0;
    for (int it = 0; it < 3; it++) {
        double max_dist = 0;
        pos = (pos + right.start) % count;
        start_pt = src[pos];
        if (++pos >= count) pos = 0;
        for (int64_t j = 1; j < count; j++) {
            p = src[pos];
            if (++pos >= count) pos = 0;
            double dx = p.x - start_pt.x, dy = p.y - start_pt.y, dist = dx * dx + dy * dy;
            if (dist > max_dist) {
                max_dist = dist;
                right.start = j;
            }
        }
        le_eps = max_dist <= eps;
    }
    /* 2. the stack */
    if (!le_eps) {
        right.end = slice.start = pos % count;
        slice.end = right.start = (right.start + slice.start) % count;
        stack[top++] = right;
        stack[top++] = slice;
    } else {
        dst[new_count++] = start_pt;
    }
    /* 3. recursion */
    while (top > 0) {
        slice = stack[--top];
        end_pt = src[slice.end];
        pos = slice.start;
        start_pt = src[pos];
        if (++pos >= count) pos = 0;
        if (pos != slice.end) {
            double dx = end_pt.x - start_pt.x, dy = end_pt.y - start_pt.y, max_dist = 0;
            while (pos != slice.end) {
                p = src[pos];
                if (++pos >= count) pos = 0;
                double dist = fabs((p.y - start_pt.y) * dx - (p.x - start_pt.x) * dy);
                if (dist > max_dist) {
                    max_dist = dist;
                    right.start = (pos + count - 1) % count;
                }
            }
            le_eps = max_dist * max_dist <= eps * (dx * dx + dy * dy);
        } else {
            le_eps = 1;
            start_pt = src[slice.start];
        }
        if (le_eps) {
            dst[new_count++] = start_pt;
        } else {
            right.end = slice.end;
            slice.end = right.start;
            stack[top++] = right;
            stack[top++] = slice;
        }
    }
    /* 4. drop vertices on nearly straight runs */
    count = new_count;
    pos = count - 1;
    start_pt = dst[pos];
    if (++pos >= count) pos = 0;
    int64_t wpos = pos;
    p = dst[pos];
    if (++pos >= count) pos = 0;
    for (int64_t i = 0; i < count && new_count > 2; i++) {
        end_pt = dst[pos];
        if (++pos >= count) pos = 0;
        double dx = end_pt.x - start_pt.x, dy = end_pt.y - start_pt.y;
        double dist = fabs((p.x - start_pt.x) * dy - (p.y - start_pt.y) * dx);
        double inner = (double)(p.x - start_pt.x) * (end_pt.x - p.x) + (double)(p.y - start_pt.y) * (end_pt.y - p.y);
        if (dist * dist <= 0.5 * eps * (dx * dx + dy * dy) && dx != 0 && dy != 0 && inner >= 0) {
            new_count--;
            dst[wpos] = end_pt;
            if (++wpos >= count) wpos = 0;
            start_pt = end_pt;
            i++;
            p = dst[pos];
            if (++pos >= count) pos = 0;
        } else {
            dst[wpos] = p;
            if (++wpos >= count) wpos = 0;
            start_pt = p;
            p = end_pt;
        }
    }
    return new_count;
}

/* As cv2.isContourConvex: every turn the same way, none straight. */
static int is_convex(const pt *p, int64_t n) {
    pt prev = p[(n - 2 + n) % n], cur = p[n - 1];
    int64_t dx0 = cur.x - prev.x, dy0 = cur.y - prev.y;
    int orientation = 0;
    for (int64_t i = 0; i < n; i++) {
        prev = cur;
        cur = p[i];
        int64_t dx = cur.x - prev.x, dy = cur.y - prev.y;
        int64_t dxdy0 = dx * dy0, dydx0 = dy * dx0;
        orientation |= dydx0 > dxdy0 ? 1 : (dydx0 < dxdy0 ? 2 : 3);
        if (orientation == 3) return 0;
        dx0 = dx;
        dy0 = dy;
    }
    return 1;
}

/* Fraction of the contour's points within tol px of the closed quad's sides. */
static double on_sides(const pt *c, int64_t n, const pt *q, double tol) {
    int64_t near = 0;
    for (int64_t i = 0; i < n; i++) {
        double best = INFINITY;
        for (int s = 0; s < 4; s++) {
            double ax = q[s].x, ay = q[s].y, bx = q[(s + 1) % 4].x - ax, by = q[(s + 1) % 4].y - ay;
            double len2 = bx * bx + by * by;
            double t = ((c[i].x - ax) * bx + (c[i].y - ay) * by) / (len2 > 1e-12 ? len2 : 1e-12);
            t = t < 0 ? 0 : (t > 1 ? 1 : t);
            double dx = c[i].x - (ax + t * bx), dy = c[i].y - (ay + t * by), d = dx * dx + dy * dy;
            if (d < best) best = d;
        }
        near += best <= tol * tol;
    }
    return (double)near / (double)n;
}

typedef struct {
    double min_len, max_len, approx_rate, min_side, min_solidity, min_compactness, border;
} params;

/* One contour: 1 and its quad when it is a candidate. Work arrays of 2 n + 2 entries. */
static int keep_one(const pt *c, int64_t n, const params *pr, int64_t w, int64_t h, pt *approx, range *stack,
                    pt *tmp, pt *hull, pt quad[4]) {
    if (n < pr->min_len || n > pr->max_len) return 0;
    double area = polygon_area(c, n);
    /* compactness 16 A / n^2: a cheap reject before the polygon approximation */
    if (area < pr->min_side * pr->min_side || 16.0 * area < pr->min_compactness * (double)n * (double)n) return 0;
    int64_t m = approx_closed(c, n, pr->approx_rate * (double)n, approx, stack);
    double hull_a = -1.0;
    if (m > 4 && m <= 8) { /* a small spur (noise touching the border): look coarser */
        hull_a = hull_area(c, n, tmp, hull);
        if (area < pr->min_solidity * hull_a) return 0;
        m = approx_closed(c, n, 2 * pr->approx_rate * (double)n, approx, stack);
        if (m == 4 && on_sides(c, n, approx, 0.02 * (double)n + 1.0) < 0.8) return 0;
    } else if (m < 4) { /* a thin quad (seen edge-on): the tolerance exceeded its width; a
                         * quarter of the width estimated as 2 A / n instead */
        m = approx_closed(c, n, 0.5 * area / (double)n, approx, stack);
    }
    if (m != 4 || !is_convex(approx, 4)) return 0;
    double min2 = INFINITY;
    for (int s = 0; s < 4; s++) {
        double dx = approx[(s + 1) % 4].x - approx[s].x, dy = approx[(s + 1) % 4].y - approx[s].y;
        if (dx * dx + dy * dy < min2) min2 = dx * dx + dy * dy;
    }
    if (min2 < pr->min_side * pr->min_side) return 0;
    for (int s = 0; s < 4; s++) {
        if (approx[s].x < pr->border || approx[s].y < pr->border) return 0;
        if (approx[s].x > w - 1 - pr->border || approx[s].y > h - 1 - pr->border) return 0;
    }
    if (hull_a < 0) hull_a = hull_area(c, n, tmp, hull);
    if (hull_a <= 0 || area / hull_a < pr->min_solidity) return 0;
    memcpy(quad, approx, 4 * sizeof(pt));
    return 1;
}

static PyObject *filter_quads(PyObject *self, PyObject *args) {
    (void)self;
    Py_buffer pts, offs;
    Py_ssize_t w, h;
    params pr;
    if (!PyArg_ParseTuple(args, "y*y*nn(ddddddd)", &pts, &offs, &w, &h, &pr.min_len, &pr.max_len, &pr.approx_rate,
                          &pr.min_side, &pr.min_solidity, &pr.min_compactness, &pr.border))
        return NULL;
    const pt *p = (const pt *)pts.buf;
    const int64_t *o = (const int64_t *)offs.buf;
    Py_ssize_t k = offs.len / (Py_ssize_t)sizeof(int64_t) - 1;
    const char *bad = NULL;
    if (k < 0 || offs.len % (Py_ssize_t)sizeof(int64_t))
        bad = "offsets: expected K + 1 int64 values";
    for (Py_ssize_t i = 0; !bad && i < k; i++)
        if (o[0] < 0 || o[i + 1] < o[i] || o[i + 1] * (int64_t)sizeof(pt) > pts.len)
            bad = "points/offsets: every contour must lie inside the points buffer";
    if (bad) {
        PyBuffer_Release(&pts);
        PyBuffer_Release(&offs);
        PyErr_SetString(PyExc_ValueError, bad);
        return NULL;
    }
    int64_t n_max = 1;
    for (Py_ssize_t i = 0; i < k; i++)
        if (o[i + 1] - o[i] > n_max) n_max = o[i + 1] - o[i];
    pt *approx = (pt *)malloc((size_t)(n_max + 2) * sizeof(pt));
    pt *tmp = (pt *)malloc((size_t)(n_max + 2) * sizeof(pt));
    pt *hull = (pt *)malloc((size_t)(2 * n_max + 2) * sizeof(pt));
    range *stack = (range *)malloc((size_t)(n_max + 2) * sizeof(range));
    int64_t *kept = (int64_t *)malloc((size_t)(k + 1) * sizeof(int64_t));
    pt *quads = (pt *)malloc((size_t)(4 * k + 4) * sizeof(pt));
    PyObject *result = NULL;
    if (approx && tmp && hull && stack && kept && quads) {
        Py_ssize_t n_kept = 0;
        Py_BEGIN_ALLOW_THREADS
        for (Py_ssize_t i = 0; i < k; i++)
            if (keep_one(p + o[i], o[i + 1] - o[i], &pr, w, h, approx, stack, tmp, hull, quads + 4 * n_kept))
                kept[n_kept++] = i;
        Py_END_ALLOW_THREADS
        result = Py_BuildValue("(y#y#)", (const char *)kept, n_kept * (Py_ssize_t)sizeof(int64_t), (const char *)quads,
                               n_kept * 4 * (Py_ssize_t)sizeof(pt));
    } else {
        PyErr_NoMemory();
    }
    free(approx);
    free(tmp);
    free(hull);
    free(stack);
    free(kept);
    free(quads);
    PyBuffer_Release(&pts);
    PyBuffer_Release(&offs);
    return result;
}

static PyMethodDef methods[] = {
    {"filter_quads", filter_quads, METH_VARARGS,
     "filter_quads(points, offsets, width, height, params) -> (kept, quads)\n\n"
     "Stage 5 for packed contours; see visloc.markers.contours.filter_candidates."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_filter", "Stage 5: the candidate filter.", -1, methods,
                                    NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__filter(void) { return PyModule_Create(&module); }
