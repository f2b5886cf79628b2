/* What a Followers reads as it is made (part of _followers.c, included once from it): each follower's law, a cruise
 * control's state carried on from a batch, the authors' code's options, the attacker stepped with the followers, an FMU
 * follower's instance. */

/* A cruise control's state carried on from a batch (`batch.PlatoonBatch.detach`): (integral, the last error or None,
 * and a flag: the mode a switching follower is in, or whether the attacker attacked at the last step; then, for a
 * follower, whether its mode is known) */
static int cruise_state(PyObject *state, Switching *sw, double *flag, int *known) {
    PyObject *prev;
    int mode_known = 0;
    if (!PyArg_ParseTuple(state, "dOd|p", &sw->integral, &prev, flag, &mode_known))
        return -1;
    sw->has_prev = prev != Py_None;
    if (sw->has_prev && (sw->prev_error = PyFloat_AsDouble(prev)) == -1.0 && PyErr_Occurred())
        return -1;
    if (known != NULL)
        *known = mode_known;
    return 0;
}

static int code_pid_state(PyObject *state, CodePid *p) { /* control.CodePID: its numbers and state, as it is */
    PyObject *prev;
    if (!PyTuple_Check(state)) {
        PyErr_SetString(PyExc_TypeError, "a PID of the authors' code: a tuple of its numbers and state");
        return -1;
    }
    if (!PyArg_ParseTuple(state, "ddddddddOdd", &p->kp, &p->ki, &p->kd, &p->period_s, &p->filter_s, &p->clamp, &p->limit,
                          &p->integral, &prev, &p->filtered, &p->prev_filtered))
        return -1;
    p->has_prev = prev != Py_None;
    return p->has_prev && (p->prev_error = PyFloat_AsDouble(prev)) == -1.0 && PyErr_Occurred() ? -1 : 0;
}

/* the switching law with the authors' code's options (control.SwitchingController._as_run_setup), as it is: (every,
 * calls, period_s, held, the speed at its last action or None, code_rule, code_cruise, low_pid, first_zero, engage_m,
 * release_m, its code cruise PID or None, its low-level PID or None: `code_pid_state`) */
static int as_run_state(PyObject *state, AsRun *r) {
    PyObject *prev, *cruise, *low;
    if (!PyTuple_Check(state)) {
        PyErr_SetString(PyExc_TypeError, "the authors' options: a tuple of their numbers and state");
        return -1;
    }
    if (!PyArg_ParseTuple(state, "llddOppppddOO", &r->every, &r->calls, &r->period_s, &r->held, &prev, &r->code_rule,
                          &r->code_cruise, &r->low_pid, &r->first_zero, &r->engage_m, &r->release_m, &cruise, &low))
        return -1;
    if (r->every < 1 || r->calls < 0 || (cruise == Py_None) == r->code_cruise || (low == Py_None) == r->low_pid) {
        PyErr_SetString(PyExc_ValueError, "the authors' options: every >= 1, calls >= 0, a PID for each option that has one");
        return -1;
    }
    r->has_prev_speed = prev != Py_None;
    if (r->has_prev_speed && (r->prev_speed = PyFloat_AsDouble(prev)) == -1.0 && PyErr_Occurred())
        return -1;
    return (r->code_cruise && code_pid_state(cruise, &r->cruise) < 0) || (r->low_pid && code_pid_state(low, &r->low) < 0) ? -1 : 0;
}

/* an FMU follower's instance: (FMI version, instance, its SetReal/SetFloat64, DoStep and GetReal/GetFloat64 as addresses,
 * its inputs' references (3), its outputs' (1 or 2), whether its first output is an acceleration, its clock, fail) */
static int init_fmu(Follower *f, PyObject *fmu) {
    unsigned long long instance, set_real, do_step, get_real;
    PyObject *in_vr, *out_vr;
    PyObject *fail;
    if (!PyArg_ParseTuple(fmu, "iKKKKO!O!pdO", &f->fmi, &instance, &set_real, &do_step, &get_real, &PyTuple_Type, &in_vr,
                          &PyTuple_Type, &out_vr, &f->fmu_acceleration, &f->fmu_time, &fail))
        return -1;
    Py_INCREF(fail);
    Py_XSETREF(f->fmu_fail, fail);
    f->n_out = (int)PyTuple_GET_SIZE(out_vr);
    if ((f->fmi != 2 && f->fmi != 3) || !instance || !set_real || !do_step || !get_real || PyTuple_GET_SIZE(in_vr) != 3
        || f->n_out < 1 || f->n_out > 2 || f->has_mode != (f->n_out == 2)) {
        PyErr_SetString(PyExc_ValueError, "an FMU: version 2 or 3, its instance and functions, 3 inputs, 1 or 2 outputs");
        return -1;
    }
    f->instance = (void *)(uintptr_t)instance, f->set_real = (void *)(uintptr_t)set_real;
    f->do_step = (void *)(uintptr_t)do_step, f->get_real = (void *)(uintptr_t)get_real;
    for (int j = 0; j < 3 + f->n_out; j++) {
        PyObject *ref = j < 3 ? PyTuple_GET_ITEM(in_vr, j) : PyTuple_GET_ITEM(out_vr, j - 3);
        unsigned long value = PyLong_AsUnsignedLong(ref);
        if (value == (unsigned long)-1 && PyErr_Occurred())
            return -1;
        (j < 3 ? f->in_vr : f->out_vr)[j < 3 ? j : j - 3] = (unsigned int)value;
    }
    return 0;
}

/* a follower's law (the Followers' laws): (law, whether its mode is recorded, (setpoint_m, target_mps, step_s, max_accel,
 * max_decel), its gains, u, (fallback_mps, fallback_headway_s), its actuator (7), its radar or None[, its state: the
 * switching law's cruise (`cruise_state`) or an FMU's instance (`init_fmu`)[, the authors' options: `as_run_state`]]);
 * ``sumo``: whether a follower SUMO drives may be one (the attacker stepped here, no channel) */
static int init_follower(Followers *self, Follower *f, PyObject *law, int sumo) {
    PyObject *own, *gains, *mitigation, *actuator, *radar, *state = Py_None, *run = Py_None;
    if (!PyArg_ParseTuple(law, "ipO!O!dO!O!O|OO", &f->law, &f->has_mode, &PyTuple_Type, &own, &PyTuple_Type, &gains, &f->u,
                          &PyTuple_Type, &mitigation, &PyTuple_Type, &actuator, &radar, &state, &run))
        return -1;
    int switching = f->law == LAW_SWITCHING || f->law == LAW_TIMEGAP;
    if (f->law == LAW_SUMO && (self->channel || !sumo)) {
        PyErr_SetString(PyExc_ValueError, "a follower SUMO drives: with the attacker stepped here, without a channel");
        return -1;
    }
    int alone = switching || f->law == LAW_IDM || f->law == LAW_FMU || f->law == LAW_SUMO; /* needs no channel */
    if (f->law < LAW_SUMO || f->law > LAW_FMU || (!alone && !self->channel) || (run != Py_None && !switching)) {
        PyErr_Format(PyExc_ValueError, "no law %d%s%s", f->law, self->channel ? "" : " without a channel",
                     run != Py_None ? " with the authors' options" : "");
        return -1;
    }
    double o[5], m[2], a[7];
    if (read_tuple(own, o, 5, "the controller") < 0 || read_tuple(gains, f->c, switching ? 9 + (f->law == LAW_TIMEGAP) : 5, "its gains") < 0
        || read_tuple(mitigation, m, 2, "its mitigation") < 0 || read_tuple(actuator, a, 7, "its actuator") < 0)
        return -1;
    f->setpoint_m = o[0], f->target_mps = o[1], f->step_s = o[2], f->max_accel = o[3], f->max_decel = o[4];
    f->fallback_mps = m[0], f->fallback_headway_s = m[1], f->mode = 0.0;
    self->with_mode += f->has_mode;
    if (switching) { /* its FMU's variables: the scenario's, the car's, the gains (and the time gap) */
        double *v = f->sw.v;
        switching_defaults(&f->sw);
        v[VR_SETPOINT_M] = o[0], v[VR_TARGET_SPEED_MPS] = o[1], v[VR_MAX_ACCEL_MPS2] = o[3], v[VR_MAX_DECEL_MPS2] = o[4];
        const int gain[9] = {VR_CRUISE_KP, VR_CRUISE_KI, VR_CRUISE_KD, VR_CRUISE_INTEGRAL_CLAMP, VR_CRUISE_OUTPUT_LIMIT_MPS2,
                             VR_ACC_KP, VR_ACC_KV, VR_EPS_X_M, VR_EPS_V_MPS};
        for (int g = 0; g < 9; g++)
            v[gain[g]] = f->c[g];
        f->sw.time_gap = f->law == LAW_TIMEGAP;
        f->sw.time_gap_s = f->law == LAW_TIMEGAP ? f->c[9] : 0.0;
        if (state != Py_None && cruise_state(state, &f->sw, &f->sw.v[VR_MODE], &f->sw.mode_known) < 0)
            return -1;
        if (run != Py_None && as_run_state(run, &f->run) < 0)
            return -1;
        f->mode = v[VR_MODE];
    }
    if (f->law == LAW_FMU && init_fmu(f, state) < 0)
        return -1;
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
    return 0;
}

static int attack_signal(Followers *self, PyObject *u) { /* the attacker's pedal at each step (NaN: it cruises) */
    Py_ssize_t steps = PyList_GET_SIZE(u);
    self->attack_u = PyMem_Calloc((size_t)steps + 1, sizeof(double));
    if (self->attack_u == NULL) {
        PyErr_NoMemory();
        return -1;
    }
    self->attack_steps = steps;
    self->has_attacker = 1;
    return read_floats(u, self->attack_u, (int)steps, "the attack");
}

/* the attacker: (attack_u, (cruise_kp, cruise_ki, cruise_kd, cruise_integral_clamp, cruise_output_limit_mps2),
 * (target_mps, step_s, max_accel, max_decel), its actuator (7)[, its cruise's state: `cruise_state`[, among traffic a
 * careful driver's (setpoint_m, time_gap_s, acc_kp, acc_kv) or None]]); or, with the
 * authors' code's options, (attack_u, steps between two of its actions, its controller: a follower's switching law with
 * those options, no radar, no mode recorded (`init_follower`)) */
static int init_attacker(Followers *self, PyObject *attacker) {
    PyObject *u, *gains, *own, *actuator, *state = Py_None;
    if (PyTuple_Check(attacker) && PyTuple_GET_SIZE(attacker) == 3) { /* the authors' attacker */
        PyObject *law;
        Follower *f = &self->f[0];
        if (!PyArg_ParseTuple(attacker, "O!lO!", &PyList_Type, &u, &self->attacker_every, &PyTuple_Type, &law)
            || init_follower(self, f, law, 0) < 0)
            return -1;
        if (self->attacker_every < 1 || !f->run.every || !f->perfect || f->has_mode) {
            PyErr_SetString(PyExc_ValueError, "the authors' attacker: every >= 1, their switching law, no radar, no mode");
            return -1;
        }
        return attack_signal(self, u);
    }
    PyObject *cautious = Py_None;
    if (!PyArg_ParseTuple(attacker, "O!O!O!O!|OO", &PyList_Type, &u, &PyTuple_Type, &gains, &PyTuple_Type, &own,
                          &PyTuple_Type, &actuator, &state, &cautious))
        return -1;
    self->cautious = cautious != Py_None;
    if (self->cautious && (!self->ahead || !PyArg_ParseTuple(cautious, "dddd", &self->cautious_s0, &self->cautious_h,
                                                             &self->cautious_kp, &self->cautious_kv))) {
        if (!PyErr_Occurred())
            PyErr_SetString(PyExc_ValueError, "a careful driver follows whoever is ahead (ahead)");
        return -1;
    }
    double g[5], o[4], a[7];
    if (read_tuple(gains, g, 5, "the attacker's cruise gains") < 0 || read_tuple(own, o, 4, "the attacker") < 0
        || read_tuple(actuator, a, 7, "the attacker's actuator") < 0 || attack_signal(self, u) < 0)
        return -1;
    Follower *f = &self->f[0];
    switching_defaults(&f->sw);
    double *v = f->sw.v;
    v[VR_TARGET_SPEED_MPS] = o[0], v[VR_CRUISE_KP] = g[0], v[VR_CRUISE_KI] = g[1], v[VR_CRUISE_KD] = g[2];
    v[VR_CRUISE_INTEGRAL_CLAMP] = g[3], v[VR_CRUISE_OUTPUT_LIMIT_MPS2] = g[4];
    f->step_s = o[1], f->max_accel = o[2], f->max_decel = o[3];
    f->act_accel_max = a[0], f->act_decel_max = a[1], f->alpha = a[2], f->act_step_s = a[3], f->max_speed_mps = a[4];
    f->accel_mps2 = a[5], f->coast = a[6];
    double attacking = 0.0;
    if (state != Py_None && cruise_state(state, &f->sw, &attacking, NULL) < 0)
        return -1;
    self->attacking = attacking != 0.0;
    return 0;
}
