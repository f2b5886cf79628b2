/* What a Followers reads as it is made (part of _followers.c, included once from it): a cruise control's state carried
 * on from a batch, the attacker stepped with the followers, an FMU follower's instance. */

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

/* the attacker (attack_u, (cruise_kp, cruise_ki, cruise_kd, cruise_integral_clamp, cruise_output_limit_mps2),
 * (target_mps, step_s, max_accel, max_decel), its actuator (7)[, its cruise's state: `cruise_state`]) */
static int init_attacker(Followers *self, PyObject *attacker) {
    PyObject *u, *gains, *own, *actuator, *state = Py_None;
    if (!PyArg_ParseTuple(attacker, "O!O!O!O!|O", &PyList_Type, &u, &PyTuple_Type, &gains, &PyTuple_Type, &own,
                          &PyTuple_Type, &actuator, &state))
        return -1;
    double g[5], o[4], a[7];
    if (read_tuple(gains, g, 5, "the attacker's cruise gains") < 0 || read_tuple(own, o, 4, "the attacker") < 0
        || read_tuple(actuator, a, 7, "the attacker's actuator") < 0)
        return -1;
    Py_ssize_t steps = PyList_GET_SIZE(u);
    self->attack_u = PyMem_Calloc((size_t)steps + 1, sizeof(double));
    if (self->attack_u == NULL) {
        PyErr_NoMemory();
        return -1;
    }
    if (read_floats(u, self->attack_u, (int)steps, "the attack") < 0)
        return -1;
    self->attack_steps = steps;
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
    self->has_attacker = 1;
    return 0;
}
