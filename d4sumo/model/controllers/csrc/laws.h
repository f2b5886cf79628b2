/* The radar, the laws and the actuator (part of _followers.c, included once from it). */

static double to_command(double a, double max_accel, double max_decel) {
    double u = a >= 0.0 ? a / max_accel : a / max_decel;
    return u > 1.0 ? 1.0 : (u < -1.0 ? -1.0 : u);
}

/* cacc.cruise_acceleration: Plexe's cruise control */
static double plexe_cruise(double speed, double target) {
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

/* fmu.FmuController.observe: the FMU's step on what the radar measured, through the functions fmpy loaded; a failed
 * call is the Python's error, raised by fail() (then NaN, with the error set) */
static const char *said_at(const char *format, double t, int status, const char *word) {
    static char text[160];
    char at[64];
    PyOS_snprintf(at, sizeof at, "%g", t); /* Python's f"{t:g}" */
    PyOS_snprintf(text, sizeof text, format, at, status, word);
    return text;
}

typedef int (*Fmi2Real)(void *, const unsigned int *, size_t, double *);
typedef int (*Fmi2Step)(void *, double, double, int);
typedef int (*Fmi3Float64)(void *, const unsigned int *, size_t, double *, size_t);
typedef int (*Fmi3Step)(void *, double, double, bool, bool *, bool *, bool *, double *);

static double fmu_command(Follower *f, double gap, double speed, double lead) {
    double in[3] = {gap, speed, lead}, out[2] = {0.0, 0.0}, t = f->fmu_time, last = 0.0;
    int status;
    if (f->fmi == 2) {
        status = ((Fmi2Real)f->set_real)(f->instance, f->in_vr, 3, in);
        status = status > 1 ? status : ((Fmi2Step)f->do_step)(f->instance, t, f->step_s, 1);
        status = status > 1 ? status : ((Fmi2Real)f->get_real)(f->instance, f->out_vr, (size_t)f->n_out, out);
    } else {
        status = ((Fmi3Float64)f->set_real)(f->instance, f->in_vr, 3, in, 3);
        if (status <= 1) {
            bool event = false, terminate = false, early = false;
            status = ((Fmi3Step)f->do_step)(f->instance, t, f->step_s, true, &event, &terminate, &early, &last);
            if (status <= 1 && terminate) {
                Py_XDECREF(PyObject_CallFunction(f->fmu_fail, "s", said_at("the FMU asked to terminate the simulation at %s s", t, 0, "")));
                return NAN;
            }
        }
        status = status > 1 ? status : ((Fmi3Float64)f->get_real)(f->instance, f->out_vr, (size_t)f->n_out, out, (size_t)f->n_out);
    }
    if (status > 1) {
        static const char *const said[] = {"ok", "warning", "discard", "error", "fatal", "pending"};
        Py_XDECREF(PyObject_CallFunction(f->fmu_fail, "s", said_at("an FMI call failed at %s s (status %d: %s)", t, status,
                                                                   said[status < 5 ? status : 5])));
        return NAN;
    }
    f->fmu_time = t + f->step_s;
    if (f->has_mode)
        f->mode = out[1];
    return f->fmu_acceleration ? to_command(out[0], f->max_accel, f->max_decel) : out[0];
}

#include "as_run.h" /* the switching law as its authors' code ran it */

static double command(Followers *self, int i, Reading r, double now) {
    Follower *f = &self->f[i];
    double speed = self->v[i], gap = r.gap, lead = r.lead, a;
    int seen = r.seen;
    const Beacon *ahead = newest(self, i, i - 1), *leader = newest(self, i, 0);
    switch (f->law) {
    case LAW_SWITCHING:
    case LAW_TIMEGAP: { /* the FMU's law, on what the radar measured */
        double *v = f->sw.v;
        if (f->run.every) { /* as its authors' code ran it */
            double u;
            as_run_command(f, gap, speed, lead, 1, &u);
            f->mode = v[VR_MODE];
            return u;
        }
        v[VR_GAP_M] = gap, v[VR_SPEED_MPS] = speed, v[VR_LEAD_SPEED_MPS] = lead;
        switching_step(&f->sw, f->step_s);
        f->mode = v[VR_MODE];
        return v[VR_COMMAND];
    }
    case LAW_CACC:
        if (!seen)
            return to_command(plexe_cruise(speed, f->target_mps), f->max_accel, f->max_decel);
        if (f->fallback_mps != 0.0 && fallback(f, ahead, gap, speed, lead, seen, &a))
            return to_command(below_target(a, speed, f), f->max_accel, f->max_decel);
        if (ahead == NULL || leader == NULL)
            return 0.0;
        a = f->c[0] * ahead->accel_mps2 + f->c[1] * leader->accel_mps2 + f->c[2] * (speed - ahead->speed_mps)
            + f->c[3] * (speed - leader->speed_mps) + f->c[4] * (f->setpoint_m - gap);
        return to_command(below_target(a, speed, f), f->max_accel, f->max_decel);
    case LAW_PLOEG: {
        if (!seen) {
            f->u = plexe_cruise(speed, f->target_mps);
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
    case LAW_FMU:
        return fmu_command(f, gap, speed, lead);
    case LAW_IDM: { /* laws/idm.py's observe: pow() is what Python's ** calls; a speed is never below 0 */
        double free = f->target_mps > 0.0 ? 1.0 - pow(speed / f->target_mps, f->c[2]) : -1.0;
        if (!seen)
            return to_command(f->c[1] * free, f->max_accel, f->max_decel);
        double closing = speed * f->c[0] - speed * (lead - speed) / f->c[3];
        double wanted = f->setpoint_m + (closing > 0.0 ? closing : 0.0); /* max(0.0, closing) */
        double touching = 1e-3 > gap ? 1e-3 : gap;                    /* max(gap, 1e-3) */
        /* c[4] is 2, read at run time: a constant 2.0 lets the compiler square without pow(), an ulp off it at times */
        return to_command(f->c[1] * (free - pow(wanted / touching, f->c[4])), f->max_accel, f->max_decel);
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

