/* Python numbers to doubles and back, as the Python has them (part of _followers.c, included once from it). */

static int as_double(PyObject *o, double *out, const char *what) { /* a float (np.float64 too) or an int, as is */
    if (!PyFloat_Check(o) && !(PyLong_Check(o) && !PyBool_Check(o))) {
        PyErr_Format(PyExc_TypeError, "%s: a float, not %.100s", what, Py_TYPE(o)->tp_name);
        return -1;
    }
    *out = PyFloat_AsDouble(o);
    return *out == -1.0 && PyErr_Occurred() ? -1 : 0;
}

static int read_floats(PyObject *sequence, double *out, int n, const char *what) {
    PyObject *fast = PySequence_Fast(sequence, what);
    if (fast == NULL)
        return -1;
    int status = 0;
    if (PySequence_Fast_GET_SIZE(fast) < n) {
        PyErr_Format(PyExc_TypeError, "%s: at least %d floats", what, n);
        status = -1;
    }
    for (int j = 0; j < n && status == 0; j++)
        status = as_double(PySequence_Fast_GET_ITEM(fast, j), &out[j], what);
    Py_DECREF(fast);
    return status;
}

static int append_float(PyObject *list, double value) {
    PyObject *item = PyFloat_FromDouble(value);
    if (item == NULL)
        return -1;
    int status = PyList_Append(list, item);
    Py_DECREF(item);
    return status;
}

static int read_tuple(PyObject *tuple, double *out, Py_ssize_t n, const char *what) {
    if (!PyTuple_Check(tuple) || PyTuple_GET_SIZE(tuple) != n) {
        PyErr_Format(PyExc_TypeError, "%s: a tuple of %zd numbers", what, n);
        return -1;
    }
    for (Py_ssize_t j = 0; j < n; j++) {
        out[j] = PyFloat_AsDouble(PyTuple_GET_ITEM(tuple, j));
        if (out[j] == -1.0 && PyErr_Occurred())
            return -1;
    }
    return 0;
}
