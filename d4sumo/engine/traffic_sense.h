/* Who is ahead of each car of one platoon among SUMO's traffic, and who follows its rear car: neighbours._TrafficSense's
 * step in C++ (part of _sumo_calls.cpp, included once from it, inside its namespace), each of SUMO's answers the one
 * libsumo's Python gives and each gap the same sum of the same doubles, so the same pairs, ids, positions and speeds.
 *
 * traffic_pairs(ids, lengths, min_gaps, names, x, v) -> (pairs, names, xs, vs): ids the platoon's SUMO ids, lengths and
 * min_gaps theirs, names the episode's (vehicle_ids), x and v this step's positions and speeds; pairs (leader, follower,
 * gap) index the names, positions and speeds returned: the platoon's, then each traffic car met (its front bumper from
 * its gap). */

const double LOOK_M = 1000.0; /* lanes.FREE_ROAD_GAP_M: how far SUMO is asked to look */

struct Step { /* the step's cars: the platoon's, then the traffic met (names, xs, vs: new lists), and the pairs */
    PyObject *pairs = NULL, *names = NULL, *xs = NULL, *vs = NULL;
    Py_ssize_t first_traffic = 0;                         /* the index of the first traffic car */
    std::vector<std::pair<std::string, double>> traffic; /* each traffic car met, its front bumper */

    ~Step() { Py_XDECREF(pairs), Py_XDECREF(names), Py_XDECREF(xs), Py_XDECREF(vs); }

    /* _TrafficSense's other(): a traffic car's index, added where it is new (its speed SUMO's) */
    Py_ssize_t other(const std::string &vid, double front_m) {
        for (size_t j = 0; j < traffic.size(); j++)
            if (traffic[j].first == vid)
                return first_traffic + (Py_ssize_t)j;
        Py_ssize_t index = PyList_GET_SIZE(names);
        double speed = getters[WORLD_SPEED](vid); /* before any reference is held: SUMO's error may be thrown */
        PyObject *name = PyUnicode_FromStringAndSize(vid.data(), (Py_ssize_t)vid.size());
        int failed = name == NULL || PyList_Append(names, name) < 0 || append(xs, front_m) < 0 || append(vs, speed) < 0;
        Py_XDECREF(name);
        if (failed)
            return -1;
        traffic.emplace_back(vid, front_m);
        return index;
    }

    double front(Py_ssize_t t) const { return traffic[(size_t)(t - first_traffic)].second; }

    int pair(Py_ssize_t a, Py_ssize_t b, double gap) {
        PyObject *p = Py_BuildValue("(nnd)", a, b, gap);
        int status = p == NULL ? -1 : PyList_Append(pairs, p);
        Py_XDECREF(p);
        return status;
    }

    static int append(PyObject *list, double value) {
        PyObject *f = PyFloat_FromDouble(value);
        int status = f == NULL ? -1 : PyList_Append(list, f);
        Py_XDECREF(f);
        return status;
    }
};

int read_doubles(PyObject *sequence, std::vector<double> &out, Py_ssize_t n, const char *what) {
    PyObject *fast = PySequence_Fast(sequence, what);
    if (fast == NULL)
        return -1;
    int status = PySequence_Fast_GET_SIZE(fast) == n ? 0 : -1;
    if (status < 0)
        PyErr_Format(PyExc_TypeError, "%s: %zd floats", what, n);
    for (Py_ssize_t i = 0; i < n && status == 0; i++) {
        out[(size_t)i] = PyFloat_AsDouble(PySequence_Fast_GET_ITEM(fast, i));
        status = out[(size_t)i] == -1.0 && PyErr_Occurred() ? -1 : 0;
    }
    Py_DECREF(fast);
    return status;
}

/* the step, as _TrafficSense.__call__ takes it (see there for the why of each rule); 0, or -1 with an error set */
int sense(Step &s, const std::vector<std::string> &ids, const std::vector<double> &x, const std::vector<double> &lengths,
          const std::vector<double> &min_gaps) {
    size_t n = ids.size();
    auto in_platoon = [&](const std::string &vid) -> Py_ssize_t {
        for (size_t i = 0; i < n; i++)
            if (ids[i] == vid)
                return (Py_ssize_t)i;
        return -1;
    };
    for (size_t b = 0; b < n; b++) {
        std::pair<std::string, double> hit = leader_(ids[b], LOOK_M);
        if (b && hit.first == ids[b - 1]) { /* the car ahead in the column */
            if (s.pair((Py_ssize_t)b - 1, (Py_ssize_t)b, x[b - 1] - lengths[b - 1] - x[b]) < 0)
                return -1;
            continue;
        }
        if (hit.first.empty())
            continue; /* nobody ahead */
        Py_ssize_t a = in_platoon(hit.first);
        if (a >= 0) { /* another car of the platoon */
            if (s.pair(a, (Py_ssize_t)b, x[(size_t)a] - lengths[(size_t)a] - x[b]) < 0)
                return -1;
            continue;
        }
        double gap = hit.second + min_gaps[b];
        if (gap >= LOOK_M)
            continue;
        Py_ssize_t t = s.other(hit.first, x[b] + gap + length_(hit.first));
        if (t < 0 || s.pair(t, (Py_ssize_t)b, gap) < 0)
            return -1;
        for (int k = 0; b && k < 64; k++) { /* traffic between two platoon cars: the first of it follows the car ahead */
            const std::string name = s.traffic[(size_t)(t - s.first_traffic)].first;
            std::pair<std::string, double> ahead = leader_(name, LOOK_M);
            if (ahead.first.empty() || (in_platoon(ahead.first) >= 0 && ahead.first != ids[b - 1]))
                break;
            gap = ahead.second + min_gap_(name);
            if (ahead.first == ids[b - 1]) {
                if (s.pair((Py_ssize_t)b - 1, t, gap) < 0)
                    return -1;
                break;
            }
            t = s.other(ahead.first, s.front(t) + gap + length_(ahead.first));
            if (t < 0)
                return -1;
        }
    }
    std::pair<std::string, double> behind = follower_(ids[n - 1], LOOK_M);
    if (!behind.first.empty() && in_platoon(behind.first) < 0) {
        double gap = behind.second + min_gap_(behind.first);
        if (gap < LOOK_M) {
            Py_ssize_t t = s.other(behind.first, x[n - 1] - lengths[n - 1] - gap);
            if (t < 0 || s.pair((Py_ssize_t)n - 1, t, gap) < 0)
                return -1;
        }
    }
    return 0;
}

extern "C" PyObject *traffic_pairs(PyObject *module, PyObject *const *args, Py_ssize_t nargs) {
    (void)module;
    if (leader_ == NULL) {
        PyErr_SetString(PyExc_RuntimeError, "traffic_pairs before bind gave SUMO's calls");
        return NULL;
    }
    if (nargs != 6 || !PyTuple_Check(args[0])) {
        PyErr_SetString(PyExc_TypeError, "traffic_pairs(ids, lengths, min_gaps, names, x, v)");
        return NULL;
    }
    Py_ssize_t n = PyTuple_GET_SIZE(args[0]);
    if (n < 1) {
        PyErr_SetString(PyExc_ValueError, "a platoon of one car or more");
        return NULL;
    }
    std::vector<std::string> ids((size_t)n);
    for (Py_ssize_t i = 0; i < n; i++) {
        Py_ssize_t size;
        const char *id = PyUnicode_AsUTF8AndSize(PyTuple_GET_ITEM(args[0], i), &size);
        if (id == NULL)
            return NULL;
        ids[(size_t)i].assign(id, (size_t)size);
    }
    std::vector<double> lengths((size_t)n), min_gaps((size_t)n), x((size_t)n);
    if (read_doubles(args[1], lengths, n, "lengths") < 0 || read_doubles(args[2], min_gaps, n, "min_gaps") < 0
        || read_doubles(args[4], x, n, "x") < 0)
        return NULL;
    Step s;
    s.pairs = PyList_New(0), s.names = PySequence_List(args[3]), s.xs = PySequence_List(args[4]), s.vs = PySequence_List(args[5]);
    if (s.pairs == NULL || s.names == NULL || s.xs == NULL || s.vs == NULL)
        return NULL;
    s.first_traffic = PyList_GET_SIZE(s.names);
    if (PyList_GET_SIZE(s.xs) != s.first_traffic || PyList_GET_SIZE(s.vs) != s.first_traffic) {
        PyErr_SetString(PyExc_ValueError, "a name, a position and a speed for every car");
        return NULL;
    }
    if (guarded([&] {
            if (sense(s, ids, x, lengths, min_gaps) < 0)
                throw PythonError();
        }) < 0)
        return NULL;
    return Py_BuildValue("(OOOO)", s.pairs, s.names, s.xs, s.vs);
}
