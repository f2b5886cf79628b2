/* A cooperative platoon's followers, one step at a time, out of the interpreter: each follower's radar
 * (range, noise, latency), the V2V channel (beacon interval, latency, loss, a liar's beacons), Rajamani's
 * CACC (PATH), Ploeg's CACC and the consensus controller, the mitigation, and each car's actuator.
 *
 * The reference is the Python of d4sumo.model (sensing.Radar.observe, v2v.Channel.send,
 * control.PathCACC/PloegCACC/ConsensusCACC.observe, control.Fallback.check, vehicle.acceleration_to_command,
 * vehicle.Actuator.apply): this file does each operation in the same order on the same doubles, so every
 * command, mode and speed is the same, bit for bit (built without floating-point contraction;
 * tests/model/test_cooperative_compiled.py compares them). What draws random numbers (a radar's noise, a
 * link's losses) or lies (the message attack) is the Python's own objects, called from here in the order
 * the Python calls them. Python's min(a, b) is b < a ? b : a, and max(a, b) is b > a ? b : a; those are the
 * comparisons below, NaN included. d4sumo.model.cooperative decides which platoons it may play and builds
 * it from their Python objects.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <string.h>

enum { LAW_CACC = 1, LAW_PLOEG = 2, LAW_CONSENSUS = 3 };

#define FREE_ROAD_GAP_M 1000.0 /* maneuvers.FREE_ROAD_GAP_M: nobody ahead */
#define CC_KP 1.0              /* control.CC_KP, CC_ACCEL_MPS2, CC_DECEL_MPS2: Plexe's cruise control */
#define CC_ACCEL_MPS2 1.5
#define CC_DECEL_MPS2 1.5

typedef struct { /* a beacon (v2v.Message) */
    int sender;
    double time_s, position_m, speed_mps, accel_mps2, length_m;
} Beacon;

typedef struct { /* a beacon in flight to a receiver */
    long due;
    int receiver;
    Beacon beacon;
} Flight;

typedef struct { /* a radar's reading: gap, speed ahead, whether a car is ahead in range */
    double gap, lead;
    int seen;
} Reading;

typedef struct {
    int law;
    double setpoint_m, target_mps, step_s, max_accel, max_decel; /* the controller's */
    double c[5]; /* CACC: a1..a5; Ploeg: h_s, kp, kd; consensus: b, k_leader_v1, k_leader, k_front, h_s */
    double u;    /* Ploeg's integrated command */
    double fallback_mps, fallback_headway_s, mode; /* the mitigation (fallback_mps 0: none), its mode */
    /* its actuator (vehicle.Actuator) */
    double act_accel_max, act_decel_max, alpha, act_step_s, max_speed_mps, accel_mps2, coast;
    /* its radar (sensing.Radar; perfect: none of it) */
    int perfect;
    double range_m, gap_noise_m, speed_noise_mps;
    PyObject *normal; /* its generator's normal() */
    Reading *readings; /* the newest delay + 1, oldest first from `first` */
    int kept, first, capacity;
} Follower;

typedef struct {
    PyObject_HEAD
    int cars;       /* the platoon's: the attacker and its followers */
    long every;     /* a beacon every this many steps */
    long delay;     /* steps from a beacon's sending to its delivery */
    double step_s;  /* the channel's */
    int direct;     /* no latency, no loss: each beacon straight into its receivers' inboxes */
    double loss;
    int has_last;
    double *last, *x, *v, *acc, *gap, *length; /* each car's speed a step ago; this step's position, speed, acceleration,
                                                gap to the car ahead; length */
    int *sources;   /* receiver i's sources: sources[i * cars + j], j < n_sources[i] */
    int *n_sources;
    PyObject **random; /* each link's generator's random() (with loss), in the order of `sources` */
    Py_ssize_t links;  /* how many */
    int *is_sender;
    int *heard;     /* heard[i * cars + s]: whether receiver i has a beacon of s */
    Beacon *inbox;  /* inbox[i * cars + s]: its newest */
    Beacon *step_beacons; /* this step's, by sender; a liar's may be none */
    int *sent_now;
    Flight *flights;
    Py_ssize_t head, tail, flights_capacity;
    PyObject *falsify, *message, *sent; /* the lie (None: nobody lies), the Message class, Channel.sent */
    int liar;
    Follower *f;    /* f[1] .. f[cars - 1] */
    int with_mode;  /* how many followers run the mitigation */
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

static int take_double(PyObject *value, double *out) { /* a new reference's value as a double, the reference released */
    if (value == NULL)
        return -1;
    *out = PyFloat_AsDouble(value);
    Py_DECREF(value);
    return *out == -1.0 && PyErr_Occurred() ? -1 : 0;
}

static int draw(PyObject *method, PyObject *args, double *out) { /* a generator's draw, as the Python makes it */
    return take_double(PyObject_CallObject(method, args), out);
}

static int normal(Follower *f, double sd, double *out) {
    PyObject *args = Py_BuildValue("(dd)", 0.0, sd);
    if (args == NULL)
        return -1;
    int status = draw(f->normal, args, out);
    Py_DECREF(args);
    return status;
}

/* sensing.Radar.observe: the reading the controller gets of the truth (gap, speed ahead) */
static int sense(Follower *f, double gap, double speed, double lead, Reading *out) {
    Reading r;
    if (gap > f->range_m || gap >= FREE_ROAD_GAP_M) {
        r.gap = FREE_ROAD_GAP_M, r.lead = speed, r.seen = 0;
    } else {
        double noise;
        if (f->gap_noise_m != 0.0) {
            if (normal(f, f->gap_noise_m, &noise) < 0)
                return -1;
            gap += noise;
        }
        if (f->speed_noise_mps != 0.0) {
            if (normal(f, f->speed_noise_mps, &noise) < 0)
                return -1;
            lead += noise;
        }
        r.gap = gap, r.lead = lead, r.seen = 1;
    }
    if (f->kept < f->capacity) { /* a deque of delay + 1: the oldest kept is the one it gets */
        f->readings[f->kept++] = r;
    } else {
        f->readings[f->first] = r;
        f->first = (f->first + 1) % f->capacity;
    }
    *out = f->readings[f->first];
    if (!out->seen)
        out->lead = speed;
    return 0;
}

/* control.Fallback.check: 1 and the ACC's acceleration while the channel is distrusted, else 0 */
static int fallback(Follower *f, const Beacon *ahead, double gap, double speed, double lead, int seen, double *a) {
    if (ahead == NULL || fabs(ahead->speed_mps - lead) <= f->fallback_mps || !seen) {
        f->mode = 0.0;
        return 0;
    }
    f->mode = 1.0;
    double h = f->fallback_headway_s;
    *a = -(speed - lead + 0.1 * (h * speed + 2.0 - gap)) / h;
    return 1;
}

static const Beacon *newest(Followers *self, int i, int s) {
    return self->heard[i * self->cars + s] ? &self->inbox[i * self->cars + s] : NULL;
}

static double command(Followers *self, int i, Reading r, double now) {
    Follower *f = &self->f[i];
    double speed = self->v[i], gap = r.gap, lead = r.lead, a;
    int seen = r.seen;
    const Beacon *ahead = newest(self, i, i - 1), *leader = newest(self, i, 0);
    switch (f->law) {
    case LAW_CACC:
        if (!seen)
            return to_command(cruise_acceleration(speed, f->target_mps), f->max_accel, f->max_decel);
        if (f->fallback_mps != 0.0 && fallback(f, ahead, gap, speed, lead, seen, &a))
            return to_command(below_target(a, speed, f), f->max_accel, f->max_decel);
        if (ahead == NULL || leader == NULL)
            return 0.0;
        a = f->c[0] * ahead->accel_mps2 + f->c[1] * leader->accel_mps2 + f->c[2] * (speed - ahead->speed_mps)
            + f->c[3] * (speed - leader->speed_mps) + f->c[4] * (f->setpoint_m - gap);
        return to_command(below_target(a, speed, f), f->max_accel, f->max_decel);
    case LAW_PLOEG: {
        if (!seen) {
            f->u = cruise_acceleration(speed, f->target_mps);
            return to_command(f->u, f->max_accel, f->max_decel);
        }
        if (f->fallback_mps != 0.0 && fallback(f, ahead, gap, speed, lead, seen, &a)) {
            f->u = below_target(a, speed, f);
            return to_command(f->u, f->max_accel, f->max_decel);
        }
        if (ahead == NULL)
            return 0.0;
        double h = f->c[0];
        double spacing_error = gap - (f->setpoint_m + h * speed);
        double speed_error = lead - speed - h * self->acc[i];
        f->u += (-f->u + f->c[1] * spacing_error + f->c[2] * speed_error + ahead->accel_mps2) / h * f->step_s;
        f->u = below_target(f->u, speed, f);
        return to_command(f->u, f->max_accel, f->max_decel);
    }
    case LAW_CONSENSUS: {
        if (f->fallback_mps != 0.0 && fallback(f, ahead, gap, speed, lead, seen, &a))
            return to_command(below_target(a, speed, f), f->max_accel, f->max_decel);
        if (ahead == NULL)
            return 0.0;
        for (int j = 0; j < i; j++) /* a beacon of every car ahead (its inbox holds no other) */
            if (newest(self, i, j) == NULL)
                return 0.0;
        double acting = now + f->step_s;
        double own = self->x[i] + speed * f->step_s;
        double spacing = f->c[4] * leader->speed_mps + f->setpoint_m;
        int sources[2] = {0, i - 1};
        double gains[2] = {i == 1 ? f->c[1] : f->c[2], f->c[3]};
        int n = i == 1 ? 1 : 2;
        double spacing_error = 0.0;
        for (int g = 0; g < n; g++) {
            const Beacon *m = newest(self, i, sources[g]);
            double desired = 0.0; /* Python's sum() of floats before 3.12: in order, from 0 */
            for (int k = sources[g]; k < i; k++)
                desired += spacing + newest(self, i, k)->length_m;
            double distance = fabs(m->position_m + (acting - m->time_s) * m->speed_mps - own);
            spacing_error += gains[g] * (distance - desired);
        }
        a = -f->c[0] * (speed - leader->speed_mps) + spacing_error / (double)n;
        return to_command(below_target(a, speed, f), f->max_accel, f->max_decel);
    }
    }
    return NAN;
}

static int read_attribute(PyObject *o, const char *name, double *out) {
    return take_double(PyObject_GetAttrString(o, name), out);
}

/* the liar's beacon of step k as it sends it: the lie's answer to the true one; 0 where it sends none */
static int lie(Followers *self, long k, Beacon *b) {
    PyObject *truth = PyObject_CallFunction(self->message, "iddddd", b->sender, b->time_s, b->position_m, b->speed_mps,
                                            b->accel_mps2, b->length_m);
    if (truth == NULL)
        return -1;
    PyObject *told = PyObject_CallFunction(self->falsify, "lO", k, truth);
    Py_DECREF(truth);
    if (told == NULL)
        return -1;
    PyObject *entry = Py_BuildValue("(lO)", k, told);
    int status = entry == NULL ? -1 : PyList_Append(self->sent, entry);
    Py_XDECREF(entry);
    if (status == 0 && told != Py_None) {
        PyObject *sender = PyObject_GetAttrString(told, "sender");
        long s = sender == NULL ? -1 : PyLong_AsLong(sender);
        Py_XDECREF(sender);
        if (s < 0 || s >= self->cars) {
            if (!PyErr_Occurred())
                PyErr_Format(PyExc_ValueError, "a beacon from car %ld, not of the platoon", s);
            status = -1;
        } else {
            b->sender = (int)s;
            if (read_attribute(told, "time_s", &b->time_s) < 0 || read_attribute(told, "position_m", &b->position_m) < 0
                || read_attribute(told, "speed_mps", &b->speed_mps) < 0 || read_attribute(told, "accel_mps2", &b->accel_mps2) < 0
                || read_attribute(told, "length_m", &b->length_m) < 0)
                status = -1;
        }
    }
    int sends = told != Py_None;
    Py_DECREF(told);
    return status < 0 ? -1 : sends;
}

static int fly(Followers *self, long due, int receiver, const Beacon *b) {
    if (self->tail == self->flights_capacity) {
        if (self->head > 0) { /* the delivered ones make room */
            memmove(self->flights, self->flights + self->head, (self->tail - self->head) * sizeof(Flight));
            self->tail -= self->head;
            self->head = 0;
        } else {
            Py_ssize_t capacity = 2 * self->flights_capacity;
            Flight *more = PyMem_Realloc(self->flights, capacity * sizeof(Flight));
            if (more == NULL) {
                PyErr_NoMemory();
                return -1;
            }
            self->flights = more, self->flights_capacity = capacity;
        }
    }
    Flight *flight = &self->flights[self->tail++];
    flight->due = due, flight->receiver = receiver, flight->beacon = *b;
    return 0;
}

/* v2v.Channel.send: step k's beacons (every `every` steps), and the deliveries due at it */
static int send(Followers *self, long k) {
    int n = self->cars;
    if (k % self->every == 0) {
        double time_s = k * self->step_s;
        for (int s = 0; s < n; s++) {
            if (!self->is_sender[s])
                continue;
            Beacon *b = &self->step_beacons[s];
            b->sender = s, b->time_s = time_s, b->position_m = self->x[s], b->speed_mps = self->v[s];
            b->accel_mps2 = self->acc[s], b->length_m = self->length[s];
            self->sent_now[s] = 1;
        }
        if (self->falsify != Py_None) {
            int sends = lie(self, k, &self->step_beacons[self->liar]);
            if (sends < 0)
                return -1;
            self->sent_now[self->liar] = sends;
        }
        PyObject **random = self->random;
        for (int i = 1; i < n; i++) {
            for (int j = 0; j < self->n_sources[i]; j++) {
                int s = self->sources[i * n + j];
                if (!self->direct && self->loss != 0.0) {
                    double p;
                    if (draw(*random++, NULL, &p) < 0)
                        return -1;
                    if (p < self->loss)
                        continue;
                }
                if (!self->sent_now[s])
                    continue;
                const Beacon *b = &self->step_beacons[s];
                if (self->direct) { /* into the inbox, by the sender it was sent as */
                    self->inbox[i * n + s] = *b;
                    self->heard[i * n + s] = 1;
                } else if (fly(self, k + self->delay, i, b) < 0) {
                    return -1;
                }
            }
        }
    }
    while (self->head < self->tail && self->flights[self->head].due <= k) {
        Flight *flight = &self->flights[self->head++];
        int at = flight->receiver * n + flight->beacon.sender; /* by the sender the beacon names */
        self->inbox[at] = flight->beacon;
        self->heard[at] = 1;
    }
    return 0;
}

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

/* advance(k, positions, speeds, pairs, commands, new_speeds, modes): step k's beacons, then each follower's
 * command and its speed at the step's end, appended to commands and new_speeds (Platoon.advance's lists),
 * and the modes of the followers that run the mitigation, appended to modes as one list. */
static PyObject *Followers_advance(Followers *self, PyObject *const *args, Py_ssize_t nargs) {
    if (nargs != 7) {
        PyErr_SetString(PyExc_TypeError, "advance(k, positions, speeds, pairs, commands, new_speeds, modes)");
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
    PyObject *pairs = PySequence_Fast(args[3], "pairs: a sequence of (leader, follower, gap)");
    if (pairs == NULL)
        return NULL;
    int status = PySequence_Fast_GET_SIZE(pairs) < n - 1 ? -1 : 0; /* each follower's gap, read before any Python runs */
    if (status < 0)
        PyErr_SetString(PyExc_TypeError, "pairs: one for every follower");
    for (int i = 1; i < n && status == 0; i++) {
        PyObject *pair = PySequence_Fast(PySequence_Fast_GET_ITEM(pairs, i - 1), "pairs: (leader, follower, gap)");
        if (pair == NULL || PySequence_Fast_GET_SIZE(pair) != 3) {
            if (pair != NULL)
                PyErr_SetString(PyExc_TypeError, "pairs: (leader, follower, gap)");
            status = -1;
        } else {
            status = as_double(PySequence_Fast_GET_ITEM(pair, 2), &self->gap[i], "a pair's gap");
        }
        Py_XDECREF(pair);
    }
    Py_DECREF(pairs);
    if (status < 0)
        return NULL;
    const double *last = self->has_last ? self->last : self->v; /* Platoon._accelerations: 0 at the first step */
    for (int j = 0; j < n; j++)
        self->acc[j] = (self->v[j] - last[j]) / self->step_s;
    memcpy(self->last, self->v, n * sizeof(double));
    self->has_last = 1;
    double now = k * self->step_s;
    if (send(self, k) < 0)
        return NULL;
    for (int i = 1; i < n; i++) {
        double gap = self->gap[i];
        Follower *f = &self->f[i];
        Reading r = {gap, self->v[i - 1], gap < FREE_ROAD_GAP_M};
        if (!f->perfect && sense(f, gap, self->v[i], self->v[i - 1], &r) < 0)
            return NULL;
        double c = command(self, i, r, now);
        if (!(c >= -1.0 && c <= 1.0)) { /* not a command (NaN): its error, as the Python says it */
            if (take_double(PyObject_CallFunction(self->checked, "dil", c, i, k), &c) < 0)
                return NULL;
        }
        if (append_float(commands, c) < 0 || append_float(new_speeds, apply(f, c, self->v[i])) < 0)
            return NULL;
    }
    if (self->with_mode) {
        PyObject *row = PyList_New(0);
        if (row == NULL)
            return NULL;
        for (int i = 1; i < n; i++) {
            if (self->f[i].fallback_mps != 0.0 && append_float(row, self->f[i].mode) < 0) {
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
    for (int i = 1; self->f != NULL && i < self->cars; i++)
        Py_VISIT(self->f[i].normal);
    return 0;
}

static int Followers_clear(Followers *self) {
    Py_CLEAR(self->falsify);
    Py_CLEAR(self->message);
    Py_CLEAR(self->sent);
    Py_CLEAR(self->checked);
    for (Py_ssize_t j = 0; self->random != NULL && j < self->links; j++)
        Py_CLEAR(self->random[j]);
    for (int i = 1; self->f != NULL && i < self->cars; i++)
        Py_CLEAR(self->f[i].normal);
    return 0;
}

static void Followers_dealloc(Followers *self) {
    PyObject_GC_UnTrack(self);
    Followers_clear(self);
    for (int i = 1; self->f != NULL && i < self->cars; i++)
        PyMem_Free(self->f[i].readings);
    PyMem_Free(self->random);
    PyMem_Free(self->last);
    PyMem_Free(self->sources);
    PyMem_Free(self->inbox);
    PyMem_Free(self->flights);
    PyMem_Free(self->f);
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

/* Followers(channel, lengths, sources, randoms, lie, laws, checked):
 *   channel  (step_s, every, delay, loss)
 *   lengths  each car's [m]
 *   sources  each follower's, from v1: its sources in the order the channel draws its links' losses
 *   randoms  each link's generator's random(), in that order (with loss), else []
 *   lie      (falsify, liar, Message, Channel.sent), or None
 *   laws     each follower's, from v1: (law, (setpoint_m, target_mps, step_s, max_accel, max_decel), its gains (5),
 *            u, (fallback_mps, fallback_headway_s), its actuator (7), its radar: None (perfect) or
 *            (range_m, gap_noise_m, speed_noise_mps, delay steps, normal)) */
static int Followers_init(Followers *self, PyObject *args, PyObject *kwds) {
    (void)kwds;
    PyObject *channel, *lengths, *sources, *randoms, *lie_, *laws, *checked;
    if (!PyArg_ParseTuple(args, "O!O!O!O!OO!O", &PyTuple_Type, &channel, &PyList_Type, &lengths, &PyList_Type, &sources,
                          &PyList_Type, &randoms, &lie_, &PyList_Type, &laws, &checked))
        return -1;
    if (self->last != NULL) {
        PyErr_SetString(PyExc_RuntimeError, "made once");
        return -1;
    }
    int n = (int)PyList_GET_SIZE(lengths);
    if (!PyArg_ParseTuple(channel, "dlld", &self->step_s, &self->every, &self->delay, &self->loss))
        return -1;
    if (n < 2 || PyList_GET_SIZE(laws) != n - 1 || PyList_GET_SIZE(sources) != n - 1 || self->every < 1 || self->delay < 0) {
        PyErr_SetString(PyExc_ValueError, "a length for every car, sources and a law for every follower, every >= 1, delay >= 0");
        return -1;
    }
    self->cars = n;
    self->direct = self->delay == 0 && self->loss == 0.0;
    self->last = PyMem_Calloc(6 * (size_t)n, sizeof(double));
    self->sources = PyMem_Calloc(2 * (size_t)n * n + 3 * (size_t)n, sizeof(int)); /* sources, n_sources, is_sender, heard, sent_now */
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
    self->n_sources = self->sources + n * n, self->is_sender = self->n_sources + n, self->heard = self->is_sender + n;
    self->sent_now = self->heard + n * n;
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
        Follower *f = &self->f[i];
        PyObject *own, *gains, *mitigation, *actuator, *radar;
        if (!PyArg_ParseTuple(PyList_GET_ITEM(laws, i - 1), "iO!O!dO!O!O", &f->law, &PyTuple_Type, &own, &PyTuple_Type, &gains,
                              &f->u, &PyTuple_Type, &mitigation, &PyTuple_Type, &actuator, &radar))
            return -1;
        double o[5], m[2], a[7];
        if (read_tuple(own, o, 5, "the controller") < 0 || read_tuple(gains, f->c, 5, "its gains") < 0
            || read_tuple(mitigation, m, 2, "its mitigation") < 0 || read_tuple(actuator, a, 7, "its actuator") < 0)
            return -1;
        if (f->law < LAW_CACC || f->law > LAW_CONSENSUS) {
            PyErr_Format(PyExc_ValueError, "no law %d", f->law);
            return -1;
        }
        f->setpoint_m = o[0], f->target_mps = o[1], f->step_s = o[2], f->max_accel = o[3], f->max_decel = o[4];
        f->fallback_mps = m[0], f->fallback_headway_s = m[1], f->mode = 0.0;
        self->with_mode += f->fallback_mps != 0.0;
        f->act_accel_max = a[0], f->act_decel_max = a[1], f->alpha = a[2], f->act_step_s = a[3], f->max_speed_mps = a[4];
        f->accel_mps2 = a[5], f->coast = a[6];
        f->perfect = radar == Py_None;
        if (!f->perfect) {
            long delay;
            if (!PyArg_ParseTuple(radar, "dddlO", &f->range_m, &f->gap_noise_m, &f->speed_noise_mps, &delay, &f->normal))
                return -1;
            Py_INCREF(f->normal);
            if (delay < 0 || delay > 100000) {
                PyErr_Format(PyExc_ValueError, "a radar's latency of %ld steps", delay);
                return -1;
            }
            f->capacity = (int)delay + 1;
            f->readings = PyMem_Calloc((size_t)f->capacity, sizeof(Reading));
            if (f->readings == NULL) {
                PyErr_NoMemory();
                return -1;
            }
        }
    }
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
    .tp_name = "d4sumo.model._cooperative.Followers",
    .tp_doc = "A cooperative platoon's followers and its channel, stepped in C (see d4sumo.model.cooperative)",
    .tp_basicsize = sizeof(Followers),
    .tp_flags = Py_TPFLAGS_DEFAULT | Py_TPFLAGS_HAVE_GC,
    .tp_traverse = (traverseproc)Followers_traverse,
    .tp_clear = (inquiry)Followers_clear,
    .tp_new = PyType_GenericNew,
    .tp_init = (initproc)Followers_init,
    .tp_dealloc = (destructor)Followers_dealloc,
    .tp_methods = Followers_methods,
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_cooperative", "A cooperative platoon's followers, stepped in C.", -1, NULL, NULL, NULL, NULL, NULL,
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
