/* Typed callers of compiled twins' step functions: one CPython call instead of a ctypes call.
 *
 * A ctypes foreign call converts each argument through its argtypes and costs about 1 us; these
 * callers take the C function's address, its state's address and the doubles, and call it
 * directly (about 0.1 us). They add no arithmetic: each double is passed exactly as Python holds
 * it, and the C function is the same compiled code ctypes calls, so results are the same bits.
 *
 * Each caller's name is its C signature: the return type, then the arguments, with
 * d = double, i = int32_t, q = int64_t, p = a pointer passed as a Python int, v = void.
 * Nothing here checks that an address points to a function of that signature: the Python side
 * (pressor.plumbing.native_call) picks the caller from the ctypes declaration of the function.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <stdint.h>

static int arity(Py_ssize_t n, Py_ssize_t want, const char *name) {
    if (n == want) return 1;
    PyErr_Format(PyExc_TypeError, "%s takes %zd arguments (%zd given)", name, want, n);
    return 0;
}

/* int32_t f(void *state, double) */
static PyObject *i_pd(PyObject *self, PyObject *const *a, Py_ssize_t n) {
    (void)self;
    if (!arity(n, 3, "i_pd")) return NULL;
    int32_t (*f)(void *, double) = (int32_t(*)(void *, double))PyLong_AsVoidPtr(a[0]);
    void *s = PyLong_AsVoidPtr(a[1]);
    double x = PyFloat_AsDouble(a[2]);
    if (PyErr_Occurred()) return NULL;
    return PyLong_FromLong((long)f(s, x));
}

/* void f(void *state, double) */
static PyObject *v_pd(PyObject *self, PyObject *const *a, Py_ssize_t n) {
    (void)self;
    if (!arity(n, 3, "v_pd")) return NULL;
    void (*f)(void *, double) = (void (*)(void *, double))PyLong_AsVoidPtr(a[0]);
    void *s = PyLong_AsVoidPtr(a[1]);
    double x = PyFloat_AsDouble(a[2]);
    if (PyErr_Occurred()) return NULL;
    f(s, x);
    Py_RETURN_NONE;
}

/* double f(void *state, double, double, double, double, double) */
static PyObject *d_pddddd(PyObject *self, PyObject *const *a, Py_ssize_t n) {
    (void)self;
    if (!arity(n, 7, "d_pddddd")) return NULL;
    double (*f)(void *, double, double, double, double, double) =
        (double (*)(void *, double, double, double, double, double))PyLong_AsVoidPtr(a[0]);
    void *s = PyLong_AsVoidPtr(a[1]);
    double x0 = PyFloat_AsDouble(a[2]), x1 = PyFloat_AsDouble(a[3]), x2 = PyFloat_AsDouble(a[4]);
    double x3 = PyFloat_AsDouble(a[5]), x4 = PyFloat_AsDouble(a[6]);
    if (PyErr_Occurred()) return NULL;
    return PyFloat_FromDouble(f(s, x0, x1, x2, x3, x4));
}

/* double f(void *state, double, double, double, void *out) */
static PyObject *d_pdddp(PyObject *self, PyObject *const *a, Py_ssize_t n) {
    (void)self;
    if (!arity(n, 6, "d_pdddp")) return NULL;
    double (*f)(void *, double, double, double, void *) =
        (double (*)(void *, double, double, double, void *))PyLong_AsVoidPtr(a[0]);
    void *s = PyLong_AsVoidPtr(a[1]);
    double x0 = PyFloat_AsDouble(a[2]), x1 = PyFloat_AsDouble(a[3]), x2 = PyFloat_AsDouble(a[4]);
    void *out = PyLong_AsVoidPtr(a[5]);
    if (PyErr_Occurred()) return NULL;
    return PyFloat_FromDouble(f(s, x0, x1, x2, out));
}

/* int32_t f(void *state, double, int64_t, double) */
static PyObject *i_pdqd(PyObject *self, PyObject *const *a, Py_ssize_t n) {
    (void)self;
    if (!arity(n, 5, "i_pdqd")) return NULL;
    int32_t (*f)(void *, double, int64_t, double) =
        (int32_t(*)(void *, double, int64_t, double))PyLong_AsVoidPtr(a[0]);
    void *s = PyLong_AsVoidPtr(a[1]);
    double x0 = PyFloat_AsDouble(a[2]);
    int64_t k = (int64_t)PyLong_AsLongLong(a[3]);
    double x1 = PyFloat_AsDouble(a[4]);
    if (PyErr_Occurred()) return NULL;
    return PyLong_FromLong((long)f(s, x0, k, x1));
}

#define FAST(name) {#name, (PyCFunction)(void (*)(void))name, METH_FASTCALL, NULL}
static PyMethodDef methods[] = {
    FAST(i_pd), FAST(v_pd), FAST(d_pddddd), FAST(d_pdddp), FAST(i_pdqd), {NULL, NULL, 0, NULL}};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_pressor_native_call",
                                    "Typed callers of compiled twins (native_call.c).", -1,
                                    methods};

PyMODINIT_FUNC PyInit__pressor_native_call(void) { return PyModule_Create(&module); }
