/* The rigid-body model's right-hand side and one RK4 step, compiled.
 *
 * visloc.model.rigid_body.rhs_values and rk4_values operation for operation, in the same order
 * (built without fused multiply-adds), so that both give the same floats: report eqs.
 * (2.1)-(2.4) / (A.5)-(A.16) with the Z-Y-X Euler rates of eq. (2.7), the optional gyroscopic
 * term (Euler's equation, see visloc.model.rigid_body.derivatives) and an external force on the
 * CoG (its acceleration force / mass added to eq. 2.2).
 *
 * rhs(s, u, force, mass, g, ixx, iyy, izz, gyroscopic) -> list of 12 floats
 *     s: 12 floats (the state), u: 4 floats ([T, tau_x, tau_y, tau_z]), force: 3 floats or None.
 * rk4(s, u, force, h, mass, g, ixx, iyy, izz, gyroscopic) -> list of 12 floats
 *     The state after one classic RK4 step of h seconds with u and force held.
 *
 * No argument checks beyond the sizes: a non-finite state gives non-finite floats (the caller
 * judges them), where the Python version raises inside math's functions.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>

#include "../_floats.h"

typedef struct {
    double mass, g, inertia[3];
    int gyroscopic;
    int has_force;
    double force[3];
} model;

/* d state / dt of the state s (12) under inputs u (4). */
static void derivative(const double s[12], const double u[4], const model *m, double out[12]) {
    double phi = s[6], theta = s[7], psi = s[8], p = s[9], q = s[10], r = s[11];
    double cf = cos(phi), sf = sin(phi);
    double ct = cos(theta), st = sin(theta);
    double cp = cos(psi), sp = sin(psi);
    double a = u[0] / m->mass;
    double mx = u[1], my = u[2], mz = u[3]; /* report eq. (A.14)-(A.16) */
    if (m->gyroscopic) { /* moment - omega x (J omega) */
        double jx = m->inertia[0] * p, jy = m->inertia[1] * q, jz = m->inertia[2] * r;
        double nx = mx - (q * jz - r * jy), ny = my - (r * jx - p * jz), nz = mz - (p * jy - q * jx);
        mx = nx, my = ny, mz = nz;
    }
    double tt = st / ct;
    out[0] = s[3], out[1] = s[4], out[2] = s[5]; /* report eq. (2.1) */
    out[3] = -(sf * sp + cf * cp * st) * a;      /* report eq. (2.2): -R e3 T / m + g e3 */
    out[4] = -(cf * st * sp - cp * sf) * a;
    out[5] = m->g - ct * cf * a;
    out[6] = p + (sf * q + cf * r) * tt; /* report eq. (2.3) with Q(lambda) of eq. (2.7) */
    out[7] = cf * q - sf * r;
    out[8] = (sf * q + cf * r) / ct;
    out[9] = mx / m->inertia[0], out[10] = my / m->inertia[1], out[11] = mz / m->inertia[2];
    if (m->has_force) {
        out[3] = out[3] + m->force[0] / m->mass;
        out[4] = out[4] + m->force[1] / m->mass;
        out[5] = out[5] + m->force[2] / m->mass;
    }
}

/* The state, inputs and model of a call; -1 with an exception set on bad arguments. */
static int parse(PyObject *s_obj, PyObject *u_obj, PyObject *f_obj, int gyroscopic, double s[12], double u[4],
                 model *m) {
    if (floats(s_obj, s, 12, "s") < 0 || floats(u_obj, u, 4, "u") < 0)
        return -1;
    m->gyroscopic = gyroscopic;
    m->has_force = f_obj != Py_None;
    if (m->has_force && floats(f_obj, m->force, 3, "force") < 0)
        return -1;
    return 0;
}

static PyObject *rhs(PyObject *self, PyObject *args) {
    PyObject *s_obj, *u_obj, *f_obj;
    double s[12], u[4], out[12];
    model m;
    int gyroscopic;
    if (!PyArg_ParseTuple(args, "OOOdddddp", &s_obj, &u_obj, &f_obj, &m.mass, &m.g, &m.inertia[0], &m.inertia[1],
                          &m.inertia[2], &gyroscopic))
        return NULL;
    if (parse(s_obj, u_obj, f_obj, gyroscopic, s, u, &m) < 0)
        return NULL;
    derivative(s, u, &m, out);
    return float_list(out, 12);
}

static PyObject *rk4(PyObject *self, PyObject *args) {
    PyObject *s_obj, *u_obj, *f_obj;
    double s[12], u[4], k1[12], k2[12], k3[12], k4[12], tmp[12], out[12], h;
    model m;
    int gyroscopic;
    if (!PyArg_ParseTuple(args, "OOOddddddp", &s_obj, &u_obj, &f_obj, &h, &m.mass, &m.g, &m.inertia[0],
                          &m.inertia[1], &m.inertia[2], &gyroscopic))
        return NULL;
    if (parse(s_obj, u_obj, f_obj, gyroscopic, s, u, &m) < 0)
        return NULL;
    double half = 0.5 * h, sixth = h / 6.0;
    derivative(s, u, &m, k1);
    for (int i = 0; i < 12; i++)
        tmp[i] = s[i] + half * k1[i];
    derivative(tmp, u, &m, k2);
    for (int i = 0; i < 12; i++)
        tmp[i] = s[i] + half * k2[i];
    derivative(tmp, u, &m, k3);
    for (int i = 0; i < 12; i++)
        tmp[i] = s[i] + h * k3[i];
    derivative(tmp, u, &m, k4);
    for (int i = 0; i < 12; i++)
        out[i] = s[i] + sixth * (((k1[i] + 2.0 * k2[i]) + 2.0 * k3[i]) + k4[i]);
    return float_list(out, 12);
}

static PyMethodDef methods[] = {
    {"rhs", rhs, METH_VARARGS,
     "rhs(s, u, force, mass, g, ixx, iyy, izz, gyroscopic) -> list of 12 floats\n\n"
     "See visloc.model.rigid_body.rhs_values."},
    {"rk4", rk4, METH_VARARGS,
     "rk4(s, u, force, h, mass, g, ixx, iyy, izz, gyroscopic) -> list of 12 floats\n\n"
     "See visloc.model.rigid_body.rk4_values."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_rigid", "The rigid-body model's derivative and RK4 step.",
                                    -1, methods, NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__rigid(void) { return PyModule_Create(&module); }
