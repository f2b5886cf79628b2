/* The paper's switching ACC (d4sumo.model.controllers.control.SwitchingController, its printed form), in C for the
 * FMUs d4sumo ships (fmi2.c, fmi3.c) and for the followers d4sumo steps in C (d4sumo/model/controllers/_followers.c),
 * which also run its time-gap variant (control.TimeGapController: the desired gap s0 + h v; the FMUs keep
 * the printed law, h unused). Every operation is the Python's, in the same order, in IEEE doubles: its
 * commands equal the Python controller's. */
#ifndef D4SUMO_SWITCHING_H
#define D4SUMO_SWITCHING_H

/* value references: the inputs, the outputs, then the parameters */
enum {
    VR_GAP_M, VR_SPEED_MPS, VR_LEAD_SPEED_MPS,               /* inputs */
    VR_COMMAND, VR_MODE,                                       /* outputs: the pedal in [-1, 1], 0 CC / 1 ACC */
    VR_SETPOINT_M, VR_TARGET_SPEED_MPS,                        /* the scenario's */
    VR_MAX_ACCEL_MPS2, VR_MAX_DECEL_MPS2,                      /* the car's */
    VR_CRUISE_KP, VR_CRUISE_KI, VR_CRUISE_KD, VR_CRUISE_INTEGRAL_CLAMP, VR_CRUISE_OUTPUT_LIMIT_MPS2,
    VR_ACC_KP, VR_ACC_KV, VR_EPS_X_M, VR_EPS_V_MPS,           /* the gains (d4sumo's SwitchingParams) */
    N_VARIABLES
};

/* the FMU's GUID (FMI 2.0) and instantiation token (FMI 3.0): a new one with every change of the law */
#define D4SUMO_GUID "{d4sumo-switching-1}"

#define GAP_TOLERANCE_M 1e-6
#define SPEED_TOLERANCE_MPS 1e-6
#define MODE_CC 0.0
#define MODE_ACC 1.0

typedef struct {
    double v[N_VARIABLES];
    double integral, prev_error;
    int has_prev, mode_known;
    int time_gap;      /* the time-gap variant: the desired gap is s0 + time_gap_s v (not an FMU variable) */
    double time_gap_s;
} Switching;

static void switching_defaults(Switching *s) {
    static const double defaults[N_VARIABLES] = {
        [VR_GAP_M] = 1e9, [VR_SPEED_MPS] = 0.0, [VR_LEAD_SPEED_MPS] = 0.0, [VR_COMMAND] = 0.0, [VR_MODE] = MODE_CC,
        [VR_SETPOINT_M] = 7.0, [VR_TARGET_SPEED_MPS] = 25.0, [VR_MAX_ACCEL_MPS2] = 3.5, [VR_MAX_DECEL_MPS2] = 8.0,
        [VR_CRUISE_KP] = 0.4, [VR_CRUISE_KI] = 0.01, [VR_CRUISE_KD] = 0.1, [VR_CRUISE_INTEGRAL_CLAMP] = 20.0,
        [VR_CRUISE_OUTPUT_LIMIT_MPS2] = 3.0, [VR_ACC_KP] = 0.9304, [VR_ACC_KV] = 2.1599, [VR_EPS_X_M] = 1.0,
        [VR_EPS_V_MPS] = 1.0,
    };
    for (int i = 0; i < N_VARIABLES; i++) s->v[i] = defaults[i];
    s->integral = 0.0;
    s->prev_error = 0.0;
    s->has_prev = 0;
    s->mode_known = 0;
    s->time_gap = 0;
    s->time_gap_s = 0.0;
}

/* CruiseControl.acceleration: a PID on speed, its integral and its output clamped */
static double cruise_acceleration(Switching *s, double speed, double step) {
    const double *v = s->v;
    double e = v[VR_TARGET_SPEED_MPS] - speed;
    double i = s->integral + e * step;
    double clamp = v[VR_CRUISE_INTEGRAL_CLAMP], limit = v[VR_CRUISE_OUTPUT_LIMIT_MPS2];
    i = i > clamp ? clamp : (i < -clamp ? -clamp : i);
    s->integral = i;
    double d = s->has_prev ? (e - s->prev_error) / step : 0.0;
    s->prev_error = e;
    s->has_prev = 1;
    double a = v[VR_CRUISE_KP] * e + v[VR_CRUISE_KI] * i + v[VR_CRUISE_KD] * d;
    return a > limit ? limit : (a < -limit ? -limit : a);
}

/* SwitchingController.select_mode: the mode Eq. 1 selects for this gap and speed (with hysteresis), its cruise PID
 * re-engaging without a kick where it hands over to the ACC */
static double switching_mode(Switching *s, double gap, double speed, double desired) {
    double *v = s->v;
    double cc_speed = v[VR_TARGET_SPEED_MPS] + v[VR_EPS_V_MPS] - SPEED_TOLERANCE_MPS;
    double acc_speed = v[VR_TARGET_SPEED_MPS] + SPEED_TOLERANCE_MPS;
    double mode;
    if (gap >= desired + v[VR_EPS_X_M] - GAP_TOLERANCE_M || speed >= cc_speed) {
        mode = MODE_CC;
    } else if (gap <= desired + GAP_TOLERANCE_M && speed <= acc_speed) {
        mode = MODE_ACC;
    } else if (s->mode_known) {
        mode = v[VR_MODE];
    } else {
        mode = MODE_CC;  /* inside the hysteresis band at start: cruise */
    }
    if (mode != v[VR_MODE] && mode == MODE_ACC) s->has_prev = 0;  /* the cruise PID re-engages without a kick */
    v[VR_MODE] = mode;
    s->mode_known = 1;
    return mode;
}

/* the gap the ACC keeps: the setpoint d (Eq. 1), or s0 + h v for the time-gap variant */
static double switching_desired(const Switching *s, double speed) {
    return s->time_gap ? s->v[VR_SETPOINT_M] + s->time_gap_s * speed : s->v[VR_SETPOINT_M];
}

/* SwitchingController.command over one step of ``step`` seconds: the mode (Eq. 1, with hysteresis), the
 * law it selects, the pedal that asks for that acceleration */
static void switching_step(Switching *s, double step) {
    double *v = s->v;
    double gap = v[VR_GAP_M], speed = v[VR_SPEED_MPS], lead = v[VR_LEAD_SPEED_MPS];
    double desired = switching_desired(s, speed);
    double a = switching_mode(s, gap, speed, desired) == MODE_CC ? cruise_acceleration(s, speed, step)
               : v[VR_ACC_KP] * (gap - desired) + v[VR_ACC_KV] * (lead - speed);
    double u = a >= 0.0 ? a / v[VR_MAX_ACCEL_MPS2] : a / v[VR_MAX_DECEL_MPS2];
    v[VR_COMMAND] = u > 1.0 ? 1.0 : (u < -1.0 ? -1.0 : u);
}

#endif
