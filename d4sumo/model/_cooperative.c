/* A cooperative platoon's followers, one step at a time, out of the interpreter: the V2V beacons of a
 * channel that delivers every one at once (no latency, no loss, no lie), Rajamani's CACC (PATH), Ploeg's
 * CACC and the consensus controller on a perfect radar, each car's actuator.
 *
 * The reference is the Python of d4sumo.model (v2v.Channel.send, control.PathCACC/PloegCACC/ConsensusCACC
 * .observe, vehicle.acceleration_to_command, vehicle.Actuator.apply): this file does each operation in the
 * same order on the same doubles, so every command and speed is the same, bit for bit (built without
 * floating-point contraction; tests/model/test_cooperative_compiled.py compares them). Python's min(a, b) is b < a ?
 * b : a, and max(a, b) is b > a ? b : a; those are the comparisons below, NaN included.
 * d4sumo.model.cooperative decides which platoons it may play and builds it from their Python objects.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>

enum { LAW_CACC = 1, LAW_PLOEG = 2, LAW_CONSENSUS = 3 };

#define FREE_ROAD_GAP_M 1000.0 /* maneuvers.FREE_ROAD_GAP_M: nobody ahead */
#define CC_KP 1.0              /* control.CC_KP, CC_ACCEL_MPS2, CC_DECEL_MPS2: Plexe's cruise control */
#define CC_ACCEL_MPS2 1.5
#define CC_DECEL_MPS2 1.5

typedef struct {
    int law;
    double setpoint_m, target_mps, step_s, max_accel, max_decel; /* the controller's */
    double c[5]; /* CACC: a1..a5; Ploeg: h_s, kp, kd; consensus: b, k_leader_v1, k_leader, k_front, h_s */
    double u;    /* Ploeg's integrated command */
    /* its actuator (vehicle.Actuator) */
    double act_accel_max, act_decel_max, alpha, act_step_s, max_speed_mps, accel_mps2, coast;
} Follower;

typedef struct {
    PyObject_HEAD
    int cars;       /* the platoon's: the attacker and its followers */
    long every;     /* a beacon every this many steps */
    double step_s;  /* the channel's */
    int has_last;
    double *last, *x, *v, *acc; /* each car's speed a step ago; this step's position, speed, acceleration */
    int *heard;     /* whether a car's beacon was sent yet */
    double *b_time, *b_pos, *b_speed, *b_acc, *length; /* each car's newest beacon, and its length */
    Follower *f;    /* f[1] .. f[cars - 1] */
    PyObject *checked; /* platoon.checked_command: a command that is not one raises its error */
} Followers;

static double to_command(double a, double max_accel, double max_decel) {
    double u = a >= 0.0 ? a / max_accel : a / max_decel;
    return u > 1.0 ? 1.0 : (u < -1.0 ? -1.0 : u);
}

static double cruise_acceleration(double speed, double target) {
    double y = -CC_KP * (speed - target);
    double z = y > -CC_DECEL_MPS2 ? y : -CC_DECEL_MPS2; /* max(-CC_DECEL_MPS2, y) */
    return z < CC_ACCEL_MPS2 ? z : CC_ACCEL_MPS2;       /* min(CC_ACCEL_MPS2, z) */
}

static double below_target(double a, double speed, const Follower *f) {
    double limit = (f->target_mps - speed) / f->step_s;
    return limit < a ? limit : a;
}

static double apply(Follower *f, double u, double speed) {
    double target = u >= 0.0 ? u * f->act_accel_max : u * f->act_decel_max;
    f->accel_mps2 += (target - f->accel_mps2) * f->alpha;
    double drag = speed > 0.0 ? f->coast : 0.0;
    double v = drag != 0.0 ? speed + (f->accel_mps2 - drag) * f->act_step_s : speed + f->accel_mps2 * f->act_step_s;
    if (v < 0.0)
        v = 0.0;
    else if (v > f->max_speed_mps)
        v = f->max_speed_mps;
    else
        return v;
    f->accel_mps2 = (v - speed) / f->act_step_s + drag;
    return v;
}

static double command(Followers *self, int i, double gap, double now) {
    Follower *f = &self->f[i];
    double speed = self->v[i], lead = self->v[i - 1];
    int seen = gap < FREE_ROAD_GAP_M, front = i - 1;
    double a;
    switch (f->law) {
    case LAW_CACC:
        if (!seen)
            return to_command(cruise_acceleration(speed, f->target_mps), f->max_accel, f->max_decel);
        if (!self->heard[front] || !self->heard[0])
            return 0.0;
        a = f->c[0] * self->b_acc[front] + f->c[1] * self->b_acc[0] + f->c[2] * (speed - self->b_speed[front])
            + f->c[3] * (speed - self->b_speed[0]) + f->c[4] * (f->setpoint_m - gap);
        return to_command(below_target(a, speed, f), f->max_accel, f->max_decel);
    case LAW_PLOEG: {
        if (!seen) {
            f->u = cruise_acceleration(speed, f->target_mps);
            return to_command(f->u, f->max_accel, f->max_decel);
        }
        if (!self->heard[front])
            return 0.0;
        double h = f->c[0];
        double spacing_error = gap - (f->setpoint_m + h * speed);
        double speed_error = lead - speed - h * self->acc[i];
        f->u += (-f->u + f->c[1] * spacing_error + f->c[2] * speed_error + self->b_acc[front]) / h * f->step_s;
        f->u = below_target(f->u, speed, f);
        return to_command(f->u, f->max_accel, f->max_decel);
    }
    case LAW_CONSENSUS: {
        for (int j = 0; j < i; j++) /* a beacon of every car ahead */
            if (!self->heard[j])
                return 0.0;
        double acting = now + f->step_s;
        double own = self->x[i] + speed * f->step_s;
        double spacing = f->c[4] * self->b_speed[0] + f->setpoint_m;
        int sources[2] = {0, i - 1};
        double gains[2] = {i == 1 ? f->c[1] : f->c[2], f->c[3]};
        int n = i == 1 ? 1 : 2;
        double spacing_error = 0.0;
        for (int g = 0; g < n; g++) {
            int j = sources[g];
            double desired = 0.0; /* Python's sum() of floats before 3.12: in order, from 0 */
            for (int k = j; k < i; k++)
                desired += spacing + self->length[k];
            double distance = fabs(self->b_pos[j] + (acting - self->b_time[j]) * self->b_speed[j] - own);
            spacing_error += gains[g] * (distance - desired);
        }
        a = -f->c[0] * (speed - self->b_speed[0]) + spacing_error / (double)n;
        return to_command(below_target(a, speed, f), f->max_accel, f->max_decel);
    }
    }
    return NAN;
}

static int read_floats(PyObject *list, double *out, int n, const char *what) {
    if (!PyList_Check(list) || PyList_GET_SIZE(list) < n) {
        PyErr_Format(PyExc_TypeError, "%s: a list of at least %d floats", what, n);
        return -1;
    }
    for (int j = 0; j < n; j++) {
        out[j] = PyFloat_AsDouble(PyList_GET_ITEM(list, j));
        if (out[j] == -1.0 && PyErr_Occurred())
            return -1;
    }
    return 0;
}

static int append_float(PyObject *list, double value) {
    PyObject *item = PyFloat_FromDouble(value);
    if (item == NULL)
        return -1;
    int status = PyList_Append(list, item);
    Py_DECREF(item);
    return status;
}

/* advance(k, positions, speeds, pairs, commands, new_speeds): step k's beacons, then each follower's
 * command and its speed at the step's end, appended to commands and new_speeds (Platoon.advance's lists). */
static PyObject *Followers_advance(Followers *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 6) {
        PyErr_SetString(PyExc_TypeError, "advance(k, positions, speeds, pairs, commands, new_speeds)");
        return NULL;
    }
    long k = PyLong_AsLong(args[0]);
    if (k == -1 && PyErr_Occurred())
        return NULL;
    PyObject *pairs = args[3], *commands = args[4], *new_speeds = args[5];
    int n = self->cars;
    if (read_floats(args[1], self->x, n, "positions") < 0 || read_floats(args[2], self->v, n, "speeds") < 0)
        return NULL;
    if (!PyList_Check(pairs) || PyList_GET_SIZE(pairs) < n - 1 || !PyList_Check(commands) || !PyList_Check(new_speeds)) {
        PyErr_SetString(PyExc_TypeError, "pairs, commands and new_speeds: lists");
        return NULL;
    }
    const double *last = self->has_last ? self->last : self->v; /* Platoon._accelerations: 0 at the first step */
    for (int j = 0; j < n; j++)
        self->acc[j] = (self->v[j] - last[j]) / self->step_s;
    memcpy(self->last, self->v, n * sizeof(double));
    self->has_last = 1;
    double now = k * self->step_s;
    if (k % self->every == 0) { /* v2v.Channel.send: each car's beacon, straight into its receivers' inboxes */
        for (int s = 0; s < n; s++) {
            self->heard[s] = 1;
            self->b_time[s] = now;
            self->b_pos[s] = self->x[s];
            self->b_speed[s] = self->v[s];
            self->b_acc[s] = self->acc[s];
        }
    }
    for (int i = 1; i < n; i++) {
        PyObject *pair = PyList_GET_ITEM(pairs, i - 1);
        if (!PyTuple_Check(pair) || PyTuple_GET_SIZE(pair) != 3) {
            PyErr_SetString(PyExc_TypeError, "pairs: (leader, follower, gap) tuples");
            return NULL;
        }
        double gap = PyFloat_AsDouble(PyTuple_GET_ITEM(pair, 2));
        if (gap == -1.0 && PyErr_Occurred())
            return NULL;
        double c = command(self, i, gap, now);
        if (!(c >= -1.0 && c <= 1.0)) { /* not a command (NaN): its error, as the Python says it */
            PyObject *result = PyObject_CallFunction(self->checked, "dil", c, i, k);
            if (result == NULL)
                return NULL;
            c = PyFloat_AsDouble(result);
            Py_DECREF(result);
            if (c == -1.0 && PyErr_Occurred())
                return NULL;
        }
        if (append_float(commands, c) < 0 || append_float(new_speeds, apply(&self->f[i], c, self->v[i])) < 0)
            return NULL;
    }
    Py_RETURN_NONE;
}

static void Followers_dealloc(Followers *self) {
    PyMem_Free(self->last);
    PyMem_Free(self->heard);
    PyMem_Free(self->f);
    Py_XDECREF(self->checked);
    Py_TYPE(self)->tp_free((PyObject *)self);
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

/* Followers(step_s, every, lengths, laws, checked): laws, one per follower from v1, each
 * (law, (setpoint_m, target_mps, step_s, max_accel, max_decel), its gains (5), u, its actuator (7)). */
static int Followers_init(Followers *self, PyObject *args, PyObject *kwds) {
    double step_s;
    long every;
    PyObject *lengths, *laws, *checked;
    if (!PyArg_ParseTuple(args, "dlO!O!O", &step_s, &every, &PyList_Type, &lengths, &PyList_Type, &laws, &checked))
        return -1;
    int n = (int)PyList_GET_SIZE(lengths);
    if (n < 2 || PyList_GET_SIZE(laws) != n - 1 || every < 1) {
        PyErr_SetString(PyExc_ValueError, "a length for every car, a law for every follower, every >= 1");
        return -1;
    }
    self->cars = n;
    self->every = every;
    self->step_s = step_s;
    self->has_last = 0;
    self->last = PyMem_Calloc(9 * (size_t)n, sizeof(double));
    self->heard = PyMem_Calloc((size_t)n, sizeof(int));
    self->f = PyMem_Calloc((size_t)n, sizeof(Follower));
    if (self->last == NULL || self->heard == NULL || self->f == NULL) {
        PyErr_NoMemory();
        return -1;
    }
    double *d = self->last;
    self->x = d + n, self->v = d + 2 * n, self->acc = d + 3 * n, self->b_time = d + 4 * n, self->b_pos = d + 5 * n;
    self->b_speed = d + 6 * n, self->b_acc = d + 7 * n, self->length = d + 8 * n;
    if (read_floats(lengths, self->length, n, "lengths") < 0)
        return -1;
    for (int i = 1; i < n; i++) {
        Follower *f = &self->f[i];
        PyObject *own, *gains, *actuator;
        if (!PyArg_ParseTuple(PyList_GET_ITEM(laws, i - 1), "iO!O!dO!", &f->law, &PyTuple_Type, &own, &PyTuple_Type, &gains,
                              &f->u, &PyTuple_Type, &actuator))
            return -1;
        double o[5], a[7];
        if (read_tuple(own, o, 5, "the controller") < 0 || read_tuple(gains, f->c, 5, "its gains") < 0
            || read_tuple(actuator, a, 7, "its actuator") < 0)
            return -1;
        if (f->law < LAW_CACC || f->law > LAW_CONSENSUS) {
            PyErr_Format(PyExc_ValueError, "no law %d", f->law);
            return -1;
        }
        f->setpoint_m = o[0], f->target_mps = o[1], f->step_s = o[2], f->max_accel = o[3], f->max_decel = o[4];
        f->act_accel_max = a[0], f->act_decel_max = a[1], f->alpha = a[2], f->act_step_s = a[3], f->max_speed_mps = a[4];
        f->accel_mps2 = a[5], f->coast = a[6];
    }
    Py_INCREF(checked);
    Py_XSETREF(self->checked, checked);
    return 0;
}

static PyMethodDef Followers_methods[] = {
    {"advance", (PyCFunction)(void (*)(void))Followers_advance, METH_FASTCALL,
     "advance(k, positions, speeds, pairs, commands, new_speeds): step k of the followers"},
    {NULL, NULL, 0, NULL},
};

static PyTypeObject FollowersType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "d4sumo.model._cooperative.Followers",
    .tp_doc = "A cooperative platoon's followers and its channel, stepped in C (see d4sumo.model.cooperative)",
    .tp_basicsize = sizeof(Followers),
    .tp_flags = Py_TPFLAGS_DEFAULT,
    .tp_new = PyType_GenericNew,
    .tp_init = (initproc)Followers_init,
    .tp_dealloc = (destructor)Followers_dealloc,
    .tp_methods = Followers_methods,
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_cooperative", "A cooperative platoon's followers, stepped in C.", -1, NULL,
};

PyMODINIT_FUNC PyInit__cooperative(void) {
    if (PyType_Ready(&FollowersType) < 0)
        return NULL;
    PyObject *m = PyModule_Create(&module);
    if (m == NULL)
        return NULL;
    Py_INCREF(&FollowersType);
    if (PyModule_AddObject(m, "Followers", (PyObject *)&FollowersType) < 0) {
        Py_DECREF(&FollowersType);
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
