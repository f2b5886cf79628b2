/* The followers' types (part of _followers.c, included once from it) and the Python's draws. */

enum { LAW_SUMO = 0, LAW_CACC = 1, LAW_PLOEG = 2, LAW_CONSENSUS = 3, LAW_SWITCHING = 4, LAW_TIMEGAP = 5, LAW_IDM = 6, LAW_FMU = 7 };

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

typedef struct { /* the authors' PID (control.CodePID): its gains, period, filter, clamps and state */
    double kp, ki, kd, period_s, filter_s, clamp, limit, integral, prev_error, filtered, prev_filtered;
    int has_prev; /* whether it was called before (prev_error not None) */
} CodePid;

typedef struct { /* the switching law as the authors' code ran it (control.SwitchingController.command_as_run) */
    long every, calls;       /* steps between two actions (0: the law as printed); calls so far */
    double period_s, held;   /* the control period; the pedal it holds between actions */
    double prev_speed;       /* its speed at its last action (has_prev_speed), for the measured acceleration */
    int has_prev_speed, code_rule, code_cruise, low_pid, first_zero; /* its options (SwitchingParams) */
    double engage_m, release_m; /* the code rule's margins: engage, engage + release */
    CodePid cruise, low;     /* the code's cruise PID (code_cruise) and its low-level PID (low_pid) */
} AsRun;

typedef struct {
    int law; /* LAW_SUMO: SUMO drives it, nothing here */
    double setpoint_m, target_mps, step_s, max_accel, max_decel; /* the controller's */
    /* CACC: a1..a5; Ploeg: h_s, kp, kd; consensus: b, k_leader_v1, k_leader, k_front, h_s; IDM: time_gap_s, accel_mps2,
     * delta, 2 sqrt(a b) (as its constructor computed it), 2 (the gap term's exponent); switching: its
     * SwitchingParams' cruise_kp, cruise_ki, cruise_kd, cruise_integral_clamp, cruise_output_limit_mps2, acc_kp,
     * acc_kv, eps_x_m, eps_v_mps; time gap: those, and time_gap_s */
    double c[10];
    Switching sw; /* the switching law's state and variables, as its FMU's (switching.h) */
    AsRun run;    /* the switching law with the authors' code's options (run.every 0: as printed) */
    int has_mode; /* whether its mode is recorded: the switching law's, or the mitigation's */
    double u;    /* Ploeg's integrated command */
    double fallback_mps, fallback_headway_s, mode; /* the mitigation (fallback_mps 0: none), its mode */
    /* its actuator (vehicle.Actuator) */
    double act_accel_max, act_decel_max, alpha, act_step_s, max_speed_mps, accel_mps2, coast;
    /* an FMU's instance (LAW_FMU: fmu.FmuController, its library loaded by fmpy): FMI 2 or 3, its functions, the
     * references of its inputs (gap, own speed, speed ahead) and outputs (command or acceleration, then mode), its clock */
    int fmi, n_out, fmu_acceleration;
    void *instance, *set_real, *do_step, *get_real;
    unsigned int in_vr[3], out_vr[2];
    double fmu_time;
    PyObject *fmu_fail; /* fail(message): raises its error as the Python names it (`compiled`) */
    /* its radar (sensing.Radar; perfect: none of it) */
    int perfect;
    double range_m, gap_noise_m, speed_noise_mps;
    PyObject *normal; /* its generator's normal() */
    Reading *readings; /* the newest delay + 1, oldest first from `first` */
    int kept, first, capacity;
} Follower;

typedef struct {
    PyObject_HEAD
    int channel;    /* whether the platoon exchanges beacons (none: the rest of the channel's fields are unused) */
    int cars;       /* the platoon's: the attacker and its followers */
    long every;     /* a beacon every this many steps */
    long delay;     /* steps from a beacon's sending to its delivery */
    double step_s;  /* the channel's */
    int direct;     /* no latency, no loss: each beacon straight into its receivers' inboxes */
    double loss;
    int has_last;
    double *last, *x, *v, *acc, *gap, *length; /* each car's speed a step ago; this step's position, speed, acceleration,
                                                gap to the car ahead; length */
    double *out;    /* a step's commands, new speeds and modes (3 n) */
    int ahead;      /* whether each follower follows the nearest car its pairs put ahead (else the car before it) */
    double *lead;   /* with ahead: each follower's speed ahead (its own where nobody is ahead) */
    int capped;     /* whether this step's commands are capped (a signal's driver: `read_caps`) */
    double *cap;    /* each follower's highest command this step, where has_cap */
    int *has_cap;
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
    Follower *f;    /* f[1] .. f[cars - 1]; f[0] the attacker's cruise control and actuator, where it is stepped here */
    int has_attacker; /* whether the attacker is stepped here too: its attack, and its cruise where the attack is NaN */
    long attacker_every; /* the authors' attacker (f[0] their controller, on a free road): a pedal each this many steps; 0: not */
    int cautious;     /* among traffic, where it does not attack: a careful driver (control.CautiousDriver) behind what is
                         ahead of it (gap[0], lead[0]: with ahead), its cruise f[0]'s */
    double cautious_s0, cautious_h, cautious_kp, cautious_kv; /* its standstill gap, time gap, and spacing gains */
    double *attack_u; /* its pedal at each step (NaN: it cruises) */
    Py_ssize_t attack_steps;
    int attacking;  /* whether it attacked at the last step (a new cruise window starts its PID afresh) */
    int with_mode;  /* how many followers have a mode recorded */
    PyObject *checked; /* platoon.checked_command: a command that is not one raises its error */
} Followers;

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

