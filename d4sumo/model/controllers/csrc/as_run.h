/* The paper's controller as its authors' code ran it (part of _followers.c, included once from it): their switching rule,
 * their PIDs, their control period (control.SwitchingController.command_as_run, control.CodePID), for a follower and for
 * their attacker, each operation the Python's in the same order. */

/* control.CodePID.step: the error filtered (first order), the trapezoid of the last two errors integrated and clamped,
 * the filtered error's difference over the period; the output clipped */
static double code_pid(CodePid *p, double error) {
    p->prev_filtered = p->filtered;
    p->filtered = p->filter_s > 0.0 ? p->period_s / p->filter_s * (error - p->filtered) + p->filtered : error;
    double de = 0.0;
    if (p->has_prev) {
        de = (p->filtered - p->prev_filtered) / p->period_s;
        double i = p->integral + (error + p->prev_error) * p->period_s / 2.0;
        p->integral = i > p->clamp ? p->clamp : (i < -p->clamp ? -p->clamp : i);
    }
    p->prev_error = error;
    p->has_prev = 1;
    double out = p->kp * error + p->kd * de + p->ki * p->integral;
    return out > p->limit ? p->limit : (out < -p->limit ? -p->limit : out);
}

/* SwitchingController._select_mode_code: the code's rule (comparisons within the tolerances count as at the threshold) */
static double code_mode(Follower *f, double gap, double lead, double desired) {
    double *v = f->sw.v;
    AsRun *r = &f->run;
    if (v[VR_MODE] == MODE_CC) {
        if (gap < desired + r->engage_m - GAP_TOLERANCE_M && lead < v[VR_TARGET_SPEED_MPS] - SPEED_TOLERANCE_MPS) {
            v[VR_MODE] = MODE_ACC;
            if (!r->code_cruise) /* d4sumo's cruise PID re-engages without a derivative kick */
                f->sw.has_prev = 0;
        }
    } else if (gap > desired + r->release_m + GAP_TOLERANCE_M
               || lead > v[VR_TARGET_SPEED_MPS] + v[VR_EPS_V_MPS] - SPEED_TOLERANCE_MPS + 2 * SPEED_TOLERANCE_MPS) {
        v[VR_MODE] = MODE_CC;
    }
    f->sw.mode_known = 1;
    return v[VR_MODE];
}

/* SwitchingController.command_as_run: one call (every step; it acts once a control period and holds its pedal between).
 * Returns 1 and the pedal in *u; 0 where, at a control step, it would act but ``act`` is 0 (their attacker attacking:
 * the caller sets the pedal it holds, run.held). */
static int as_run_command(Follower *f, double gap, double speed, double lead, int act, double *u) {
    AsRun *r = &f->run;
    long calls = r->calls++;
    if (calls % r->every) { /* between two actions the pedal holds */
        *u = r->held;
        return 1;
    }
    /* the measured acceleration: the speed's change over the last control period */
    double measured = r->has_prev_speed ? (speed - r->prev_speed) / r->period_s : 0.0;
    r->prev_speed = speed, r->has_prev_speed = 1;
    if (calls == 0 && r->first_zero) {
        *u = r->held = 0.0;
        return 1;
    }
    if (!act)
        return 0;
    const double *v = f->sw.v;
    double desired = switching_desired(&f->sw, speed);
    double mode = r->code_rule ? code_mode(f, gap, lead, desired) : switching_mode(&f->sw, gap, speed, desired);
    double a;
    if (mode == MODE_ACC)
        a = v[VR_ACC_KP] * (gap - desired) + v[VR_ACC_KV] * (lead - speed);
    else if (r->code_cruise)
        a = code_pid(&r->cruise, v[VR_TARGET_SPEED_MPS] - speed);
    else
        a = cruise_acceleration(&f->sw, speed, f->step_s); /* its step: the control period */
    *u = r->held = r->low_pid ? code_pid(&r->low, a - measured) : to_command(a, f->max_accel, f->max_decel);
    return 1;
}
