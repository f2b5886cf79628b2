/* The step loop of the paper's column, out of the interpreter (part of _followers.c, included once from it).
 *
 * engine.loop.play hands it the episodes left where each is one platoon stepped in C (`Followers`, its attacker too)
 * in the paper's column (car i follows car i - 1: no lane change, no traffic, no traffic lights), its followers
 * commanded here or driven by SUMO's models. Each step does
 * what the Python's command_alone and sense_alone do, in their order, on the same doubles: every episode's
 * commands (followers_step) and their speeds set; the world's step; every episode's cars read, its gaps
 * (maneuvers.Maneuver.pairs: the leader's position less its length less the follower's), a collision (a gap below
 * the collision gap: platoon.collisions_at) or its end distance. The world's calls (a SUMO's or the ballistic
 * world's set_speed, step, get_position, get_speed) are called as the Python calls them, or where the world gives
 * its own calls in C (world_calls.h: SUMO's C++ functions, d4sumo/engine/_sumo_calls.cpp), those. An episode that ends is
 * handed to on_end, which ends it as the Python does (its cars removed, its result made) before the next is sensed.
 */

#include "world_calls.h"

typedef struct { /* an episode the loop plays */
    long e;
    Followers *f;
    PyObject *ids;    /* its cars' ids (a tuple of str) */
    PyObject **args;  /* each car's (id,): a getter's arguments */
    double *lengths;  /* the column's: the length of each follower's leader */
    int *commanded, ncommanded; /* the cars it commands: the attacker and the followers SUMO does not drive */
    Py_buffer x, v, commands, modes; /* rows by step: positions and speeds (steps + 1, n), commands (steps,
                                        ncommanded), modes (steps, with_mode) */
    int has_modes;
    double x0;        /* the attacker's position where it was first sensed alone: its end distance's origin */
    int live;
    void **handles;   /* with a world's own calls: each car's handle */
    double *offsets;  /* ... and where its position is offset + distance driven (None: the lane position), the offsets */
} Played;

static int row_buffer(PyObject *array, Py_buffer *view, Py_ssize_t rows, Py_ssize_t width, const char *what) {
    if (PyObject_GetBuffer(array, view, PyBUF_WRITABLE | PyBUF_C_CONTIGUOUS | PyBUF_FORMAT) < 0)
        return -1;
    if (view->ndim != 2 || view->shape[0] != rows || view->shape[1] != width || view->itemsize != 8
        || strcmp(view->format, "d") != 0) {
        PyBuffer_Release(view);
        view->obj = NULL;
        PyErr_Format(PyExc_ValueError, "%s: a C-contiguous float64 array of (%zd, %zd)", what, rows, width);
        return -1;
    }
    return 0;
}

static void release_played(Played *p, Py_ssize_t count, int n, const WorldCalls *calls) {
    for (Py_ssize_t j = 0; j < count; j++) {
        for (int i = 0; p[j].handles != NULL && i < n; i++)
            if (p[j].handles[i] != NULL)
                calls->free_id(p[j].handles[i]);
        PyMem_Free(p[j].handles);
        PyMem_Free(p[j].offsets);
        PyBuffer_Release(&p[j].x), PyBuffer_Release(&p[j].v), PyBuffer_Release(&p[j].commands);
        if (p[j].has_modes)
            PyBuffer_Release(&p[j].modes);
        for (int i = 0; p[j].args != NULL && i < n; i++)
            Py_XDECREF(p[j].args[i]);
        PyMem_Free(p[j].args);
        PyMem_Free(p[j].lengths);
        PyMem_Free(p[j].commanded);
    }
    PyMem_Free(p);
}

/* (e, followers, ids, lengths, x, v, commands, modes or None, x0, offsets or None) */
static int take_played(PyObject *item, Played *p, int n, Py_ssize_t steps, const WorldCalls *calls) {
    PyObject *x, *v, *commands, *modes, *lengths, *offsets;
    if (!PyArg_ParseTuple(item, "lO!O!O!OOOOdO", &p->e, &FollowersType, &p->f, &PyTuple_Type, &p->ids, &PyTuple_Type,
                          &lengths, &x, &v, &commands, &modes, &p->x0, &offsets))
        return -1;
    Followers *f = p->f;
    if (f->cars != n || !f->has_attacker || PyTuple_GET_SIZE(p->ids) != n || PyTuple_GET_SIZE(lengths) != n - 1) {
        PyErr_SetString(PyExc_ValueError, "an episode: its platoon stepped here, its attacker too, an id for every car, "
                                          "a length for every follower's leader");
        return -1;
    }
    p->args = PyMem_Calloc((size_t)n, sizeof(PyObject *));
    p->lengths = PyMem_Calloc((size_t)n, sizeof(double));
    p->commanded = PyMem_Calloc((size_t)n, sizeof(int));
    if (p->args == NULL || p->lengths == NULL || p->commanded == NULL) {
        PyErr_NoMemory();
        return -1;
    }
    if (read_tuple(lengths, p->lengths, n - 1, "lengths") < 0)
        return -1;
    for (int i = 0; i < n; i++)
        if (i == 0 || f->f[i].law != LAW_SUMO)
            p->commanded[p->ncommanded++] = i;
    for (int i = 0; i < n; i++)
        if ((p->args[i] = PyTuple_Pack(1, PyTuple_GET_ITEM(p->ids, i))) == NULL)
            return -1;
    if (calls != NULL) {
        p->handles = PyMem_Calloc((size_t)n, sizeof(void *));
        if (p->handles == NULL) {
            PyErr_NoMemory();
            return -1;
        }
        for (int i = 0; i < n; i++) {
            const char *id = PyUnicode_AsUTF8(PyTuple_GET_ITEM(p->ids, i));
            if (id == NULL || (p->handles[i] = calls->make_id(id)) == NULL)
                return -1;
        }
        if (offsets != Py_None) {
            p->offsets = PyMem_Calloc((size_t)n, sizeof(double));
            if (p->offsets == NULL) {
                PyErr_NoMemory();
                return -1;
            }
            if (read_tuple(offsets, p->offsets, n, "offsets") < 0)
                return -1;
        }
    }
    if (row_buffer(x, &p->x, steps + 1, n, "x") < 0 || row_buffer(v, &p->v, steps + 1, n, "v") < 0
        || row_buffer(commands, &p->commands, steps, p->ncommanded, "commands") < 0)
        return -1;
    p->has_modes = modes != Py_None;
    if ((f->with_mode > 0) != p->has_modes) {
        PyErr_SetString(PyExc_ValueError, "modes: an array where the platoon records them, else None");
        return -1;
    }
    if (p->has_modes && row_buffer(modes, &p->modes, steps, f->with_mode, "modes") < 0)
        return -1;
    p->live = 1;
    return 0;
}

static int read_car(PyObject *getter, PyObject *args, double *out) {
    return take_double(PyObject_Call(getter, args, NULL), out);
}

/* car i's position and speed: through the world's own calls where it gave them, else its Python calls */
static int sense_car(const WorldCalls *calls, Played *p, int i, PyObject *get_position, PyObject *get_speed, double *x,
                     double *v) {
    if (calls == NULL)
        return read_car(get_position, p->args[i], x) < 0 || read_car(get_speed, p->args[i], v) < 0 ? -1 : 0;
    double d;
    if (calls->get(p->offsets ? WORLD_DISTANCE : WORLD_LANE_POSITION, p->handles[i], &d) < 0)
        return -1;
    *x = p->offsets ? p->offsets[i] + d : d; /* as route_position's departed[vid] + get_distance(vid) */
    return calls->get(WORLD_SPEED, p->handles[i], v);
}

/* ends an episode: on_end(e, steps_done, error or None, collided) */
static int end_played(PyObject *on_end, Played *p, long steps_done, PyObject *error, int collided) {
    p->live = 0;
    PyObject *r = PyObject_CallFunction(on_end, "llOO", p->e, steps_done, error ? error : Py_None,
                                        collided ? Py_True : Py_False);
    Py_XDECREF(r);
    return r == NULL ? -1 : 0;
}

/* play_column(k, steps, step, set_speed, get_position, get_speed, episodes, on_end, collision_gap_m, end_m, calls):
 * steps k to steps of the episodes (each `take_played`'s, in the Python's order), from their rows at k; returns the
 * step reached (steps, or where none is left). end_m 0: no end distance. calls: the world's own (a capsule of
 * `WorldCalls`, in place of step, set_speed, get_position and get_speed), or None. */
static PyObject *play_column(PyObject *module, PyObject *const *args, Py_ssize_t nargs) {
    (void)module;
    long k, steps;
    double crash_m, end_m;
    if (nargs != 11 || (k = PyLong_AsLong(args[0])) < 0 || (steps = PyLong_AsLong(args[1])) < k
        || !PyList_Check(args[6]) || PyList_GET_SIZE(args[6]) < 1) {
        if (!PyErr_Occurred())
            PyErr_SetString(PyExc_TypeError, "play_column(k, steps, step, set_speed, get_position, get_speed, episodes, "
                                             "on_end, collision_gap_m, end_m, calls): 0 <= k <= steps, a list of episodes");
        return NULL;
    }
    if (as_double(args[8], &crash_m, "collision_gap_m") < 0 || as_double(args[9], &end_m, "end_m") < 0)
        return NULL;
    PyObject *step = args[2], *set_speed = args[3], *get_position = args[4], *get_speed = args[5], *on_end = args[7];
    PyObject *list = args[6];
    const WorldCalls *calls = NULL;
    if (args[10] != Py_None && (calls = PyCapsule_GetPointer(args[10], WORLD_CALLS_CAPSULE)) == NULL)
        return NULL;
    Py_ssize_t count = PyList_GET_SIZE(list);
    PyObject *first = PyList_GET_ITEM(list, 0);
    if (!PyTuple_Check(first) || PyTuple_GET_SIZE(first) != 10 || !PyObject_TypeCheck(PyTuple_GET_ITEM(first, 1), &FollowersType)) {
        PyErr_SetString(PyExc_TypeError, "an episode: (e, followers, ids, lengths, x, v, commands, modes, x0, offsets)");
        return NULL;
    }
    int n = ((Followers *)PyTuple_GET_ITEM(first, 1))->cars;
    Played *played = PyMem_Calloc((size_t)count, sizeof(Played));
    if (played == NULL)
        return PyErr_NoMemory();
    Py_ssize_t taken = 0, live = 0;
    for (; taken < count; taken++) {
        PyObject *item = PyList_GET_ITEM(list, taken);
        if (!PyTuple_Check(item) || PyTuple_GET_SIZE(item) != 10 || !PyObject_TypeCheck(PyTuple_GET_ITEM(item, 1), &FollowersType)
            || ((Followers *)PyTuple_GET_ITEM(item, 1))->cars != n) {
            PyErr_SetString(PyExc_TypeError, "an episode: (e, followers, ids, lengths, x, v, commands, modes, x0, offsets), "
                                             "as many cars each");
            break;
        }
        if (take_played(item, &played[taken], n, steps, calls) < 0) {
            taken++; /* its buffers taken so far are released below */
            break;
        }
    }
    if (PyErr_Occurred()) {
        release_played(played, taken, n, calls);
        return NULL;
    }
    live = count;
    int failed = 0;
    for (; k < steps && live > 0 && !failed; k++) {
        for (Py_ssize_t j = 0; j < count && !failed; j++) { /* command_alone */
            Played *p = &played[j];
            if (!p->live)
                continue;
            Followers *f = p->f;
            const double *x = (double *)p->x.buf + k * n, *v = (double *)p->v.buf + k * n;
            memcpy(f->x, x, n * sizeof(double));
            memcpy(f->v, v, n * sizeof(double));
            for (int i = 1; i < n; i++)
                f->gap[i] = x[i - 1] - p->lengths[i - 1] - x[i];
            double *commands = (double *)p->commands.buf + k * p->ncommanded, *speeds = f->out + n;
            if (followers_step(f, k, commands, speeds, p->has_modes ? (double *)p->modes.buf + k * f->with_mode : f->out) < 0) {
                if (!PyErr_ExceptionMatches(PyExc_Exception)) { /* a Ctrl-C (KeyboardInterrupt) stops the run, as in the Python */
                    failed = 1;
                    continue;
                }
                PyObject *type, *value, *tb; /* its error ends it, as alone in the Python */
                PyErr_Fetch(&type, &value, &tb);
                PyErr_NormalizeException(&type, &value, &tb);
                if (tb != NULL)
                    PyException_SetTraceback(value, tb);
                live--;
                failed = end_played(on_end, p, k, value, 0) < 0;
                Py_XDECREF(type), Py_XDECREF(value), Py_XDECREF(tb);
                continue;
            }
            for (int j = 0; j < p->ncommanded && !failed; j++) {
                if (calls != NULL) {
                    failed = calls->set_speed(p->handles[p->commanded[j]], speeds[j]) < 0;
                    continue;
                }
                PyObject *r = PyObject_CallFunction(set_speed, "Od", PyTuple_GET_ITEM(p->ids, p->commanded[j]), speeds[j]);
                failed = r == NULL;
                Py_XDECREF(r);
            }
        }
        if (failed || live == 0)
            break;
        if (calls != NULL) {
            failed = calls->step() < 0 || PyErr_CheckSignals() < 0;
        } else {
            PyObject *r = PyObject_CallNoArgs(step);
            failed = r == NULL || PyErr_CheckSignals() < 0;
            Py_XDECREF(r);
        }
        for (Py_ssize_t j = 0; j < count && !failed; j++) { /* sense_alone */
            Played *p = &played[j];
            if (!p->live)
                continue;
            double *x = (double *)p->x.buf + (k + 1) * n, *v = (double *)p->v.buf + (k + 1) * n;
            for (int i = 0; i < n && !failed; i++)
                failed = sense_car(calls, p, i, get_position, get_speed, &x[i], &v[i]) < 0;
            if (failed)
                break;
            int collided = 0;
            for (int i = 1; i < n; i++)
                collided |= x[i - 1] - p->lengths[i - 1] - x[i] < crash_m;
            if (collided || (end_m != 0.0 && x[0] - p->x0 >= end_m)) {
                live--;
                failed = end_played(on_end, p, k + 1, NULL, collided) < 0;
            }
        }
    }
    release_played(played, count, n, calls);
    return failed ? NULL : PyLong_FromLong(k);
}
