/* Lines shared by the compiled stages 6-7 (_quads.c) and 8 (_refine.c): a weighted
 * total-least-squares line and the corners of the quadrilateral four lines bound, as
 * visloc.markers.corners.fit_lines and quad_from_lines compute them, and the packing of
 * both stages' (corners, ok) result. */
#ifndef VISLOC_LINES_H
#define VISLOC_LINES_H

#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>

/* a x + b y = c (unit normal) through m points (px, py) with weights w (NULL: all 1). */
static void tls_line(const double *px, const double *py, const double *w, int64_t m, double line[3]) {
    double sw = 0, mx = 0, my = 0;
    for (int64_t i = 0; i < m; i++) {
        double wi = w ? w[i] : 1.0;
        sw += wi;
        mx += wi * px[i];
        my += wi * py[i];
    }
    if (sw < 1e-12) sw = 1e-12;
    mx /= sw;
    my /= sw;
    double sxx = 0, syy = 0, sxy = 0;
    for (int64_t i = 0; i < m; i++) {
        double wi = w ? w[i] : 1.0, qx = px[i] - mx, qy = py[i] - my;
        sxx += wi * qx * qx;
        syy += wi * qy * qy;
        sxy += wi * qx * qy;
    }
    double theta = 0.5 * atan2(2 * sxy, sxx - syy); /* direction of the major axis */
    line[0] = -sin(theta);
    line[1] = cos(theta);
    line[2] = line[0] * mx + line[1] * my;
}

/* Corner k of four lines in order is where sides k-1 and k meet; 0 when two are parallel. */
static int quad_corners(const double lines[4][3], double corners[8]) {
    for (int k = 0; k < 4; k++) {
        const double *l1 = lines[(k + 3) % 4], *l2 = lines[k];
        double det = l1[0] * l2[1] - l1[1] * l2[0];
        if (fabs(det) < 1e-12) return 0;
        corners[2 * k] = (l1[2] * l2[1] - l1[1] * l2[2]) / det;
        corners[2 * k + 1] = (l1[0] * l2[2] - l1[2] * l2[0]) / det;
        if (!isfinite(corners[2 * k]) || !isfinite(corners[2 * k + 1])) return 0;
    }
    return 1;
}

/* (corners, ok) when the work buffer and both bytes objects were allocated, else NULL with a
 * MemoryError; drops the references to corners and ok and frees work either way. */
static PyObject *corners_result(PyObject *corners, PyObject *ok, double *work) {
    PyObject *result = work && corners && ok ? Py_BuildValue("(OO)", corners, ok) : PyErr_NoMemory();
    Py_XDECREF(corners);
    Py_XDECREF(ok);
    free(work);
    return result;
}

#endif
