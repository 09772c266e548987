/* The controller's feedback law at each step, compiled.
 *
 * visloc.control.controller.Controller._feedback_values operation for operation, in the same
 * order (built without fused multiply-adds), so that both give the same floats on Python 3.11
 * (later Pythons' sum() of floats is compensated, the Python version's rounding then differs
 * in the last bits): u = u0 - K [x; integral] (report eq. 4.5) with the set-point part of
 * tau_x and tau_y bounded (report §4.4) and the thrust change bounded, the integrators advanced
 * by conditional integration (report §4.2.3) on the bounds active before the step, then u again
 * with the new integrals.
 *
 * feedback(x, integral, step, K, K_setpoint, torque_bound, limit, u0, zone, rate_zone)
 *     -> (u, integral), lists of 4 floats
 *     x: 12 floats (the pilot-frame error state), integral: 4 floats, step: s;
 *     K: float64 (4, 16) bytes, K_setpoint: float64 (2, 10) bytes (rows tau_x, tau_y on the
 *     columns 0-5 and 12-15); torque_bound: 2 floats; limit: N; u0, zone, rate_zone: 4 floats.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>

#include "../_floats.h"

static const int POSITION_INDEX[10] = {0, 1, 2, 3, 4, 5, 12, 13, 14, 15};

typedef struct {
    const double *K, *Ks; /* (4, 16), (2, 10) */
    double bound[2], limit, u0[4];
} law;

/* -(row . v) over n entries, summed from the first as Python's sum() does. */
static double neg_dot(const double *row, const double *v, int n) {
    double acc = 0.0;
    for (int i = 0; i < n; i++)
        acc += row[i] * v[i];
    return -acc;
}

/* min(max(v, -b), b) with Python's min and max (the first argument kept unless the second
 * compares beyond it). */
static double bounded(double v, double b) {
    double m = v;
    if (-b > m)
        m = -b;
    if (b < m)
        m = b;
    return m;
}

/* u0 + du for the error state x (12) and integrals (4); which bounds were active in clipped
 * (y torque's set-point part, x torque's, thrust). */
static void inputs(const law *c, const double x[12], const double integral[4], double u[4], int clipped[3]) {
    double xa[16], xs[10], du[4];
    for (int i = 0; i < 12; i++)
        xa[i] = x[i];
    for (int i = 0; i < 4; i++)
        xa[12 + i] = integral[i];
    for (int r = 0; r < 4; r++)
        du[r] = neg_dot(c->K + 16 * r, xa, 16); /* report eq. (4.5): u = -K x */
    for (int i = 0; i < 10; i++)
        xs[i] = xa[POSITION_INDEX[i]];
    double sx = neg_dot(c->Ks, xs, 10), sy = neg_dot(c->Ks + 10, xs, 10); /* the set-point part */
    double tx = bounded(sx, c->bound[0]), ty = bounded(sy, c->bound[1]); /* §4.4 */
    du[1] = (du[1] - sx) + tx;
    du[2] = (du[2] - sy) + ty;
    double thrust = du[0];
    du[0] = bounded(thrust, c->limit);
    for (int i = 0; i < 4; i++)
        u[i] = c->u0[i] + du[i];
    clipped[0] = ty != sy, clipped[1] = tx != sx, clipped[2] = du[0] != thrust;
}

static PyObject *feedback(PyObject *self, PyObject *args) {
    PyObject *x_obj, *i_obj, *b_obj, *u0_obj, *z_obj, *w_obj;
    const char *K, *Ks;
    Py_ssize_t nK, nKs;
    double x[12], integral[4], zone[4], rate_zone[4], step, u[4];
    int clipped[3];
    law c;
    if (!PyArg_ParseTuple(args, "OOdy#y#OdOOO", &x_obj, &i_obj, &step, &K, &nK, &Ks, &nKs, &b_obj, &c.limit, &u0_obj,
                          &z_obj, &w_obj))
        return NULL;
    if (nK != 64 * (Py_ssize_t)sizeof(double) || nKs != 20 * (Py_ssize_t)sizeof(double)) {
        PyErr_SetString(PyExc_ValueError, "K must be float64 (4, 16) and K_setpoint float64 (2, 10) bytes");
        return NULL;
    }
    if (floats(x_obj, x, 12, "x") < 0 || floats(i_obj, integral, 4, "integral") < 0 ||
        floats(b_obj, c.bound, 2, "torque_bound") < 0 || floats(u0_obj, c.u0, 4, "u0") < 0 ||
        floats(z_obj, zone, 4, "zone") < 0 || floats(w_obj, rate_zone, 4, "rate_zone") < 0)
        return NULL;
    c.K = (const double *)K, c.Ks = (const double *)Ks;
    inputs(&c, x, integral, u, clipped);
    /* report §4.2.3: integrate unless the axis's command is clipped or it moves outside its zone */
    const double e[4] = {x[0], x[1], x[2], x[8]}, rate[4] = {x[3], x[4], x[5], x[11]};
    for (int i = 0; i < 4; i++) {
        int held = (i < 3 && clipped[i]) || (fabs(e[i]) > zone[i] && fabs(rate[i]) > rate_zone[i]);
        if (!held)
            integral[i] = integral[i] + e[i] * step;
    }
    inputs(&c, x, integral, u, clipped);
    PyObject *u_list = float_list(u, 4), *i_list = float_list(integral, 4);
    if (u_list == NULL || i_list == NULL) {
        Py_XDECREF(u_list);
        Py_XDECREF(i_list);
        return NULL;
    }
    return Py_BuildValue("(NN)", u_list, i_list);
}

static PyMethodDef methods[] = {
    {"feedback", feedback, METH_VARARGS,
     "feedback(x, integral, step, K, K_setpoint, torque_bound, limit, u0, zone, rate_zone) -> (u, integral)\n\n"
     "See visloc.control.controller.Controller._feedback_values."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_feedback", "The controller's feedback law, compiled.", -1,
                                    methods, NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__feedback(void) { return PyModule_Create(&module); }
