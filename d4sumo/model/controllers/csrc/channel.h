/* The V2V channel: beacons sent, lost, delayed, lied about (part of _followers.c, included once from it). */

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

