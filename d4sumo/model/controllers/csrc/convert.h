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

/* A step's pairs (leader, follower, gap): each follower's gap (self->gap). In the column pair i - 1 is follower i's;
 * with ``ahead`` the nearest pair behind a car is its (the attacker's too; the first of equal gaps, as Platoon.advance's
 * ahead), its speed ahead the leader's in ``speeds`` (a traffic car's too), nobody ahead a free road at its own speed. */
static int read_pairs(Followers *self, PyObject *pairs_, PyObject *speeds_) {
    int n = self->cars;
    PyObject *pairs = PySequence_Fast(pairs_, "pairs: a sequence of (leader, follower, gap)");
    if (pairs == NULL)
        return -1;
    Py_ssize_t count = PySequence_Fast_GET_SIZE(pairs);
    int status = !self->ahead && count < n - 1 ? -1 : 0;
    if (status < 0)
        PyErr_SetString(PyExc_TypeError, "pairs: one for every follower");
    for (int i = 0; i < n && self->ahead; i++) /* the attacker's too: a careful driver's (`cautious`) */
        self->gap[i] = FREE_ROAD_GAP_M, self->lead[i] = -1.0; /* the leader's index, until its speed is read */
    for (Py_ssize_t j = 0; j < (self->ahead ? count : n - 1) && status == 0; j++) {
        PyObject *pair = PySequence_Fast(PySequence_Fast_GET_ITEM(pairs, j), "pairs: (leader, follower, gap)");
        if (pair == NULL || PySequence_Fast_GET_SIZE(pair) != 3) {
            if (pair != NULL)
                PyErr_SetString(PyExc_TypeError, "pairs: (leader, follower, gap)");
            status = -1;
        } else if (!self->ahead) {
            status = as_double(PySequence_Fast_GET_ITEM(pair, 2), &self->gap[j + 1], "a pair's gap");
        } else {
            long a = PyLong_AsLong(PySequence_Fast_GET_ITEM(pair, 0)), b = PyLong_AsLong(PySequence_Fast_GET_ITEM(pair, 1));
            double gap;
            if ((a == -1 || b == -1) && PyErr_Occurred())
                status = -1;
            else if (a < 0) { /* (the Python would read a speed from the end of its list) */
                PyErr_Format(PyExc_IndexError, "a pair's leader %ld: no such car", a);
                status = -1;
            }
            else if (b >= 0 && b < n && (status = as_double(PySequence_Fast_GET_ITEM(pair, 2), &gap, "a pair's gap")) == 0
                     && (self->lead[b] < 0.0 || gap < self->gap[b]))
                self->gap[b] = gap, self->lead[b] = (double)a;
        }
        Py_XDECREF(pair);
    }
    Py_DECREF(pairs);
    if (status < 0 || !self->ahead)
        return status;
    PyObject *speeds = PySequence_Fast(speeds_, "speeds");
    if (speeds == NULL)
        return -1;
    for (int i = 0; i < n && status == 0; i++) {
        Py_ssize_t a = self->lead[i] < 0.0 ? i : (Py_ssize_t)self->lead[i];
        if (a < 0 || a >= PySequence_Fast_GET_SIZE(speeds)) {
            PyErr_Format(PyExc_IndexError, "a pair's leader %zd: no such car", a);
            status = -1;
        } else {
            status = as_double(PySequence_Fast_GET_ITEM(speeds, a), &self->lead[i], "a speed");
        }
    }
    Py_DECREF(speeds);
    return status;
}

/* A step's caps: each car's highest command (what its signal allows; the attacker's where it is stepped here), or None
 * (no cap); caps None: none. */
static int read_caps(Followers *self, PyObject *caps_) {
    self->capped = caps_ != Py_None;
    if (!self->capped)
        return 0;
    PyObject *caps = PySequence_Fast(caps_, "caps: a cap or None for every car");
    if (caps == NULL)
        return -1;
    int status = PySequence_Fast_GET_SIZE(caps) == self->cars ? 0 : -1;
    if (status < 0)
        PyErr_SetString(PyExc_TypeError, "caps: a cap or None for every car");
    for (int i = 0; i < self->cars && status == 0; i++) {
        PyObject *cap = PySequence_Fast_GET_ITEM(caps, i);
        self->has_cap[i] = cap != Py_None;
        if (self->has_cap[i])
            status = as_double(cap, &self->cap[i], "a cap");
    }
    Py_DECREF(caps);
    return status;
}
