/* A platoon's followers, one step at a time, out of the interpreter: each follower's radar (range, noise,
 * latency), the V2V channel (beacon interval, latency, loss, a liar's beacons), the paper's switching ACC
 * (its printed form) and its time-gap variant, the IDM, Rajamani's CACC (PATH), Ploeg's CACC and the consensus controller, the
 * mitigation, and
 * each car's actuator.
 *
 * The reference is the Python of d4sumo.model (sensing.Radar.observe, v2v.Channel.send,
 * control.SwitchingController.command, cacc.PathCACC/PloegCACC/ConsensusCACC.observe, cacc.Fallback.check,
 * vehicle.acceleration_to_command, vehicle.Actuator.apply): these files do each operation in the same order
 * on the same doubles, so every command, mode and speed is the same, bit for bit (built without
 * floating-point contraction; tests/model/controllers/test_compiled.py compares them over random states, radars,
 * channels and lies). The switching law is the one the FMUs d4sumo ships run (fmus/switching.h), written
 * once in C. What draws random numbers (a radar's noise, a link's losses) or lies (the message attack) is
 * the Python's own objects, called from here in the order the Python calls them. Python's min(a, b) is
 * b < a ? b : a, and max(a, b) is b > a ? b : a; those are the comparisons, NaN included.
 * d4sumo.model.controllers.compiled decides which platoons it may play and builds it from their Python objects.
 *
 * csrc/followers.h: the types; csrc/convert.h: numbers in and out; csrc/laws.h: the radar, the laws, the actuator;
 * csrc/channel.h: the beacons; csrc/making.h: what it reads as it is made; csrc/column.h: the paper's column's step loop.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdbool.h>
#include <stdint.h>
#include <string.h>

#include "switching.h" /* the paper's law, as the FMUs run it */
#include "followers.h"
#include "convert.h"
#include "laws.h"
#include "channel.h"

/* platoon.Platoon.advance's attacker without a motion: its attack's pedal, or where the attack is NaN its cruise control
 * (control.CruiseControl, afresh at each new cruise window; among traffic the lesser of it and the spacing law of a careful
 * driver, control.CautiousDriver) through vehicle.acceleration_to_command, capped by its signal where it obeys one;
 * with the authors' code's options, their controller on a free road, which holds the attack's pedal of each control
 * period where it attacks (Platoon._attacker_command); its speed at the step's end through its actuator */
static int attacker_step(Followers *self, long k, double *command_out, double *speed_out) {
    Follower *a = &self->f[0];
    if (k < 0 || k >= self->attack_steps) {
        PyErr_Format(PyExc_IndexError, "step %ld of an attack of %zd steps", k, self->attack_steps);
        return -1;
    }
    double u = self->attack_u[k], speed = self->v[0];
    if (self->attacker_every) { /* the authors' attacker: the attack's pedal at this control period's start */
        double attack = self->attack_u[k - k % self->attacker_every];
        if (!as_run_command(a, FREE_ROAD_GAP_M, speed, speed, attack != attack, &u))
            u = a->run.held = attack;
    } else if (u != u) { /* NaN: no attack here, the attacker cruises like everyone else */
        if (self->attacking) { /* a new cruise window: the PID starts afresh (no kick, no stale integral) */
            a->sw.integral = 0.0;
            a->sw.has_prev = 0;
            self->attacking = 0;
        }
        double cruise = cruise_acceleration(&a->sw, speed, a->step_s);
        if (self->cautious) { /* the lesser of its cruise and the spacing law on the car ahead */
            double spacing = self->cautious_kp * (self->gap[0] - self->cautious_s0 - self->cautious_h * speed)
                             + self->cautious_kv * (self->lead[0] - speed);
            cruise = spacing < cruise ? spacing : cruise;
        }
        u = to_command(cruise, a->max_accel, a->max_decel);
    } else {
        self->attacking = 1;
    }
    if (self->capped && self->has_cap[0] && self->cap[0] < u) /* min(u, the cap): what its signal allows */
        u = self->cap[0];
    *command_out = u;
    *speed_out = apply(a, u, speed);
    return 0;
}

/* Step k from this step's positions, speeds and gaps (self->x, v, gap): the step's beacons, then each car's command
 * and its speed at the step's end (the attacker's first, where it is stepped here) into commands and new_speeds, and
 * the modes of the followers that record one into modes; returns how many commands, -1 with an error set. */
static int followers_step(Followers *self, long k, double *commands, double *new_speeds, double *modes) {
    int n = self->cars, out = 0;
    double now = 0.0;
    if (self->channel) { /* Platoon._accelerations (0 at the first step), then the step's beacons */
        const double *last = self->has_last ? self->last : self->v;
        for (int j = 0; j < n; j++)
            self->acc[j] = (self->v[j] - last[j]) / self->step_s;
        memcpy(self->last, self->v, n * sizeof(double));
        self->has_last = 1;
        now = k * self->step_s;
        if (send(self, k) < 0)
            return -1;
    }
    if (self->has_attacker && attacker_step(self, k, &commands[0], &new_speeds[0]) < 0)
        return -1;
    out = self->has_attacker;
    for (int i = 1; i < n; i++) {
        double gap = self->gap[i];
        Follower *f = &self->f[i];
        if (f->law == LAW_SUMO)
            continue;
        Reading r = {gap, self->ahead ? self->lead[i] : self->v[i - 1], gap < FREE_ROAD_GAP_M};
        if (!f->perfect && sense(f, gap, self->v[i], r.lead, &r) < 0)
            return -1;
        double c = command(self, i, r, now);
        if (f->law == LAW_FMU && PyErr_Occurred()) /* its call failed */
            return -1;
        if (!(c >= -1.0 && c <= 1.0)) { /* not a command (NaN): its error, as the Python says it */
            if (take_double(PyObject_CallFunction(self->checked, "dil", c, i, k), &c) < 0)
                return -1;
        }
        if (self->capped && self->has_cap[i] && self->cap[i] < c) /* min(c, the cap): what its signal allows */
            c = self->cap[i];
        new_speeds[out] = apply(f, c, self->v[i]);
        commands[out++] = c;
    }
    for (int i = 1, m = 0; i < n; i++)
        if (self->f[i].has_mode)
            modes[m++] = self->f[i].mode;
    return out;
}

/* advance(k, positions, speeds, pairs, commands, new_speeds, modes[, caps]): step k's beacons, then each follower's
 * command and its speed at the step's end, appended to commands and new_speeds (Platoon.advance's lists),
 * and the modes of the followers that run the mitigation, appended to modes as one list; caps: each follower's
 * highest command (its signal's, `signals.SignalDriver.limit`), or None. */
static PyObject *Followers_advance(Followers *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 7 && nargs != 8) {
        PyErr_SetString(PyExc_TypeError, "advance(k, positions, speeds, pairs, commands, new_speeds, modes[, caps])");
        return NULL;
    }
    if (self->last == NULL) {
        PyErr_SetString(PyExc_RuntimeError, "Followers was not made (its __init__)");
        return NULL;
    }
    long k = PyLong_AsLong(args[0]);
    if (k == -1 && PyErr_Occurred())
        return NULL;
    PyObject *commands = args[4], *new_speeds = args[5], *modes = args[6];
    int n = self->cars;
    if (read_floats(args[1], self->x, n, "positions") < 0 || read_floats(args[2], self->v, n, "speeds") < 0)
        return NULL;
    if (!PyList_Check(commands) || !PyList_Check(new_speeds) || !PyList_Check(modes)) {
        PyErr_SetString(PyExc_TypeError, "commands, new_speeds and modes: lists");
        return NULL;
    }
    if (read_pairs(self, args[3], args[2]) < 0) /* each follower's gap and speed ahead, read before any Python runs */
        return NULL;
    if (read_caps(self, nargs == 8 ? args[7] : Py_None) < 0)
        return NULL;
    double *out = self->out; /* commands, new speeds, modes */
    int count = followers_step(self, k, out, out + n, out + 2 * n);
    if (count < 0)
        return NULL;
    for (int j = 0; j < count; j++)
        if (append_float(commands, out[j]) < 0 || append_float(new_speeds, out[n + j]) < 0)
            return NULL;
    if (self->with_mode) {
        PyObject *row = PyList_New(0);
        if (row == NULL)
            return NULL;
        for (int m = 0; m < self->with_mode; m++) {
            if (append_float(row, out[2 * n + m]) < 0) {
                Py_DECREF(row);
                return NULL;
            }
        }
        int status = PyList_Append(modes, row);
        Py_DECREF(row);
        if (status < 0)
            return NULL;
    }
    Py_RETURN_NONE;
}

/* It holds Python objects (the lie, the generators' draws, Channel.sent): the cycle collector sees them. */
static int Followers_traverse(Followers *self, visitproc visit, void *arg) {
    Py_VISIT(self->falsify);
    Py_VISIT(self->message);
    Py_VISIT(self->sent);
    Py_VISIT(self->checked);
    for (Py_ssize_t j = 0; self->random != NULL && j < self->links; j++)
        Py_VISIT(self->random[j]);
    for (int i = 0; self->f != NULL && i < self->cars; i++) {
        Py_VISIT(self->f[i].normal);
        Py_VISIT(self->f[i].fmu_fail);
    }
    return 0;
}

static int Followers_clear(Followers *self) {
    Py_CLEAR(self->falsify);
    Py_CLEAR(self->message);
    Py_CLEAR(self->sent);
    Py_CLEAR(self->checked);
    for (Py_ssize_t j = 0; self->random != NULL && j < self->links; j++)
        Py_CLEAR(self->random[j]);
    for (int i = 0; self->f != NULL && i < self->cars; i++) {
        Py_CLEAR(self->f[i].normal);
        Py_CLEAR(self->f[i].fmu_fail);
    }
    return 0;
}

static void Followers_dealloc(Followers *self) {
    PyObject_GC_UnTrack(self);
    Followers_clear(self);
    for (int i = 0; self->f != NULL && i < self->cars; i++)
        PyMem_Free(self->f[i].readings);
    PyMem_Free(self->random);
    PyMem_Free(self->last);
    PyMem_Free(self->sources);
    PyMem_Free(self->inbox);
    PyMem_Free(self->flights);
    PyMem_Free(self->f);
    PyMem_Free(self->attack_u);
    Py_TYPE(self)->tp_free((PyObject *)self);
}

#include "making.h" /* what Followers reads as it is made: a cruise's state, the attacker, an FMU */

/* Followers(channel, lengths, sources, randoms, lie, laws, checked[, attacker]):
 *   channel  (step_s, every, delay, loss), or None: no beacons (sources empty, no randoms, no lie)
 *   lengths  each car's [m]
 *   sources  each follower's, from v1: its sources in the order the channel draws its links' losses
 *   randoms  each link's generator's random(), in that order (with loss), else []
 *   lie      (falsify, liar, Message, Channel.sent), or None
 *   attacker None (the Python plays it), or what `init_attacker` reads
 *   ahead    whether each follower follows the nearest car its pairs put ahead of it (a lane change, traffic: no
 *            channel), not the car before it in the column (`read_pairs`)
 *   laws     each follower's, from v1: (law (0: SUMO drives it, its numbers zeros), whether its mode is recorded, (setpoint_m, target_mps, step_s,
 *            max_accel, max_decel), its gains (9 for the switching law, 10 for its time-gap variant, else 5), u, (fallback_mps,
 *            fallback_headway_s), its actuator (7), its radar: None (perfect) or (range_m, gap_noise_m,
 *            speed_noise_mps, delay steps, normal), then its state (`init_follower`)) */
static int Followers_init(Followers *self, PyObject *args, PyObject *kwds) {
    (void)kwds;
    PyObject *channel, *lengths, *sources, *randoms, *lie_, *laws, *checked, *attacker = Py_None;
    if (!PyArg_ParseTuple(args, "OO!O!O!OO!O|Op", &channel, &PyList_Type, &lengths, &PyList_Type, &sources,
                          &PyList_Type, &randoms, &lie_, &PyList_Type, &laws, &checked, &attacker, &self->ahead))
        return -1;
    if (self->last != NULL) {
        PyErr_SetString(PyExc_RuntimeError, "made once");
        return -1;
    }
    int n = (int)PyList_GET_SIZE(lengths);
    self->channel = channel != Py_None;
    if (!self->channel)
        self->step_s = 1.0, self->every = 1, self->delay = 0, self->loss = 0.0;
    else if (!PyTuple_Check(channel) || !PyArg_ParseTuple(channel, "dlld", &self->step_s, &self->every, &self->delay, &self->loss)) {
        if (!PyErr_Occurred())
            PyErr_SetString(PyExc_TypeError, "channel: (step_s, every, delay, loss) or None");
        return -1;
    }
    if (n < 2 || PyList_GET_SIZE(laws) != n - 1 || PyList_GET_SIZE(sources) != n - 1 || self->every < 1 || self->delay < 0) {
        PyErr_SetString(PyExc_ValueError, "a length for every car, sources and a law for every follower, every >= 1, delay >= 0");
        return -1;
    }
    if (self->ahead && self->channel) {
        PyErr_SetString(PyExc_ValueError, "followers who follow whoever is ahead: without a channel");
        return -1;
    }
    self->cars = n;
    self->direct = self->delay == 0 && self->loss == 0.0;
    self->last = PyMem_Calloc(11 * (size_t)n, sizeof(double));
    self->sources = PyMem_Calloc(2 * (size_t)n * n + 4 * (size_t)n, sizeof(int)); /* sources, n_sources, is_sender, heard, sent_now, has_cap */
    self->inbox = PyMem_Calloc((size_t)n * (n + 1), sizeof(Beacon));
    self->f = PyMem_Calloc((size_t)n, sizeof(Follower));
    self->flights_capacity = 4 * (Py_ssize_t)n * n;
    self->flights = PyMem_Calloc((size_t)self->flights_capacity, sizeof(Flight));
    Py_ssize_t links = PyList_GET_SIZE(randoms);
    self->random = PyMem_Calloc((size_t)links + 1, sizeof(PyObject *));
    if (self->last == NULL || self->sources == NULL || self->inbox == NULL || self->f == NULL || self->flights == NULL
        || self->random == NULL) {
        PyErr_NoMemory();
        return -1;
    }
    double *d = self->last;
    self->x = d + n, self->v = d + 2 * n, self->acc = d + 3 * n, self->length = d + 4 * n, self->gap = d + 5 * n;
    self->out = d + 6 * n, self->lead = d + 9 * n, self->cap = d + 10 * n;
    self->n_sources = self->sources + n * n, self->is_sender = self->n_sources + n, self->heard = self->is_sender + n;
    self->sent_now = self->heard + n * n, self->has_cap = self->sent_now + n;
    self->step_beacons = self->inbox + n * n;
    if (read_floats(lengths, self->length, n, "lengths") < 0)
        return -1;
    Py_ssize_t drawn = 0;
    for (int i = 1; i < n; i++) {
        PyObject *own = PyList_GET_ITEM(sources, i - 1);
        if (!PyTuple_Check(own) || PyTuple_GET_SIZE(own) > i) {
            PyErr_SetString(PyExc_TypeError, "sources: a tuple of cars ahead for every follower");
            return -1;
        }
        self->n_sources[i] = (int)PyTuple_GET_SIZE(own);
        for (int j = 0; j < self->n_sources[i]; j++) {
            long s = PyLong_AsLong(PyTuple_GET_ITEM(own, j));
            if (s < 0 || s >= i) {
                if (!PyErr_Occurred())
                    PyErr_SetString(PyExc_ValueError, "a source is a car ahead");
                return -1;
            }
            self->sources[i * n + j] = (int)s;
            self->is_sender[s] = 1;
        }
        drawn += self->n_sources[i];
    }
    if (!self->direct && self->loss != 0.0 && links != drawn) {
        PyErr_SetString(PyExc_ValueError, "a generator for every link");
        return -1;
    }
    for (Py_ssize_t j = 0; j < links; j++) {
        self->random[j] = PyList_GET_ITEM(randoms, j);
        Py_INCREF(self->random[j]);
    }
    self->links = links;
    if (lie_ == Py_None) {
        Py_INCREF(Py_None);
        self->falsify = Py_None;
    } else if (!PyArg_ParseTuple(lie_, "OiOO!", &self->falsify, &self->liar, &self->message, &PyList_Type, &self->sent)) {
        self->falsify = NULL, self->message = NULL, self->sent = NULL;
        return -1;
    } else {
        Py_INCREF(self->falsify), Py_INCREF(self->message), Py_INCREF(self->sent);
        if (self->liar < 0 || self->liar >= n || !self->is_sender[self->liar]) {
            PyErr_SetString(PyExc_ValueError, "the liar is a car somebody hears");
            return -1;
        }
    }
    for (int i = 1; i < n; i++) {
        if (init_follower(self, &self->f[i], PyList_GET_ITEM(laws, i - 1), attacker != Py_None) < 0)
            return -1;
    }
    if (attacker != Py_None && init_attacker(self, attacker) < 0)
        return -1;
    Py_INCREF(checked);
    Py_XSETREF(self->checked, checked);
    return 0;
}

static PyMethodDef Followers_methods[] = {
    {"advance", (PyCFunction)(void (*)(void))Followers_advance, METH_FASTCALL,
     "advance(k, positions, speeds, pairs, commands, new_speeds, modes): step k of the followers"},
    {NULL, NULL, 0, NULL},
};

static PyTypeObject FollowersType = {
    PyVarObject_HEAD_INIT(NULL, 0)
    .tp_name = "d4sumo.model.controllers._followers.Followers",
    .tp_doc = "A platoon's followers and its channel, stepped in C (see d4sumo.model.controllers.compiled)",
    .tp_basicsize = sizeof(Followers),
    .tp_flags = Py_TPFLAGS_DEFAULT | Py_TPFLAGS_HAVE_GC,
    .tp_traverse = (traverseproc)Followers_traverse,
    .tp_clear = (inquiry)Followers_clear,
    .tp_new = PyType_GenericNew,
    .tp_init = (initproc)Followers_init,
    .tp_dealloc = (destructor)Followers_dealloc,
    .tp_methods = Followers_methods,
};

#include "column.h" /* the column's step loop */

static PyMethodDef module_methods[] = {
    {"play_column", (PyCFunction)(void (*)(void))play_column, METH_FASTCALL,
     "play_column(k, steps, step, set_speed, get_position, get_speed, episodes, on_end, collision_gap_m, end_m): "
     "the column's step loop (csrc/column.h)"},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_followers", "A platoon's followers, stepped in C.", -1, module_methods, NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__followers(void) {
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
