/* Who follows whom among SUMO's traffic where the attacker changes lanes: neighbours._LateralTrafficSense's step in C++
 * (part of _sumo_calls.cpp, included once from it, inside its namespace, after traffic_sense.h), with lanes.lane_pairs
 * and lanes.occupied_lanes; each of SUMO's answers the one libsumo's Python gives and each number the same operations on
 * the same doubles, so the same pairs, ids, positions and speeds (tests/engine/test_traffic.py compares them).
 *
 * lateral_sense(ids, lengths, width_m, edging_m, longest_m, edging_sensed, as_0_21, platoon_lane, lanes, by_place) -> a
 * capsule of what one platoon's sensing holds (RouteLanes' lanes and by_place as the Python has them);
 * lateral_pairs(capsule, names, x, v, covered) -> (pairs, names, xs, vs), covered each platoon car's lanes this step. */

typedef std::string (*LaneOf)(const std::string &);
typedef std::vector<std::pair<std::string, double>> (*Neighbours)(const std::string &, int);
typedef std::vector<std::string> (*OnLane)(const std::string &);

LaneOf lane_id_;
Getter lateral_;
Neighbours neighbours_;
OnLane on_lane_;

const double CAR_WIDTH = 1.8;        /* lanes.CAR_WIDTH_M */
const double LANE_TOLERANCE = 1e-6;  /* lanes.LANE_TOLERANCE_M */

struct PlacedLane { double start; long place; };
struct Span { double start, end; std::string lane; };
typedef std::pair<std::string, double> Hit; /* SUMO's (vehicle, distance); an empty id: none */
struct Found { long a, b; double gap; };

struct Lateral {
    std::vector<std::string> ids;
    std::vector<double> lengths;
    double width, edging_m, longest_m;
    int edging_sensed, as_0_21;
    long platoon_lane;
    std::unordered_map<std::string, PlacedLane> lanes;
    std::map<long, std::vector<Span>> by_place;

    long in_platoon(const std::string &vid) const {
        for (size_t i = 0; i < ids.size(); i++)
            if (ids[i] == vid)
                return (long)i;
        return -1;
    }
    const PlacedLane *placed(const std::string &lane) const {
        auto it = lanes.find(lane);
        return it == lanes.end() ? NULL : &it->second;
    }
};

/* lanes.occupied_lanes */
std::vector<long> occupied(double y, double w) {
    double half = CAR_WIDTH / 2.0, left = y + half, right = y - half;
    double lowf = std::floor(right / w);
    long low = lowf > 0.0 ? (long)lowf : 0, high = (long)std::floor(left / w);
    std::vector<long> out;
    for (long j = low; j <= high; j++) {
        double top = (double)(j + 1) * w, bottom = (double)j * w;
        if ((top < left ? top : left) - (bottom > right ? bottom : right) > LANE_TOLERANCE)
            out.push_back(j);
    }
    return out;
}

/* lanes.lane_pairs(positions, lanes, lengths, apart) */
std::vector<Found> lane_pairs(const std::vector<double> &x, const std::vector<std::vector<long>> &covered,
                              const std::vector<double> &lengths, long apart) {
    std::map<long, std::vector<long>> by_lane;
    for (size_t i = 0; i < covered.size(); i++)
        for (long lane : covered[i])
            by_lane[lane].push_back((long)i);
    std::set<std::pair<long, long>> found;
    for (auto &entry : by_lane) {
        std::vector<long> &cars = entry.second;
        std::sort(cars.begin(), cars.end(), [&](long i, long j) { /* key (-positions[i], i) */
            double a = -x[(size_t)i], b = -x[(size_t)j];
            return a < b || (!(b < a) && i < j);
        });
        for (size_t k = 0; k + 1 < cars.size(); k++)
            found.insert({cars[k], cars[k + 1]});
    }
    std::vector<Found> pairs;
    for (auto &p : found)
        if (p.first < apart || p.second < apart)
            pairs.push_back({p.first, p.second, x[(size_t)p.first] - lengths[(size_t)p.first] - x[(size_t)p.second]});
    std::sort(pairs.begin(), pairs.end(), [&](const Found &p, const Found &q) { /* key (-positions[b], (a, b, gap)) */
        double a = -x[(size_t)p.b], b = -x[(size_t)q.b];
        if (a < b || b < a)
            return a < b;
        if (p.a != q.a)
            return p.a < q.a;
        if (p.b != q.b)
            return p.b < q.b;
        return p.gap < q.gap;
    });
    return pairs;
}

/* int(text): Python's own parse of a lane's index, its ValueError where the text is none */
long python_int(const std::string &text) {
    PyObject *digits = PyUnicode_FromStringAndSize(text.data(), (Py_ssize_t)text.size());
    PyObject *number = digits == NULL ? NULL : PyLong_FromUnicodeObject(digits, 10);
    long value = number == NULL ? -1 : PyLong_AsLong(number);
    Py_XDECREF(digits);
    Py_XDECREF(number);
    if (value == -1 && PyErr_Occurred())
        throw PythonError();
    return value;
}

struct Sensed {
    std::vector<Found> pairs;
    std::vector<std::string> traffic;
    std::vector<double> xs, vs;
};

/* _LateralTrafficSense._pairs */
Sensed lateral_place(const Lateral &s, const std::set<std::string> &near, const std::vector<double> &x,
                     const std::vector<double> &v, const std::vector<std::vector<long>> &covered_) {
    Sensed out;
    std::vector<long> across;
    std::vector<double> along;
    for (const std::string &t : near) { /* sorted, as Python sorts them */
        if (s.in_platoon(t) >= 0)
            continue;
        std::string lane_id = lane_id_(t);
        const PlacedLane *lane = s.placed(lane_id);
        PlacedLane legacy;
        if (lane == NULL && s.as_0_21) { /* a car off the route's one edge, at its own lane's position, as 0.21 had it */
            legacy = {0.0, python_int(lane_id.substr(lane_id.rfind('_') + 1)) - s.platoon_lane};
            lane = &legacy;
        }
        if (lane != NULL) {
            out.traffic.push_back(t);
            along.push_back(lane->start + getters[WORLD_LANE_POSITION](t));
            across.push_back(lane->place);
        }
    }
    out.xs = x;
    out.xs.insert(out.xs.end(), along.begin(), along.end());
    out.vs = v;
    std::vector<double> lengths = s.lengths;
    std::vector<std::vector<long>> covered = covered_;
    for (const std::string &t : out.traffic)
        out.vs.push_back(getters[WORLD_SPEED](t));
    for (const std::string &t : out.traffic)
        lengths.push_back(length_(t));
    for (size_t j = 0; j < out.traffic.size(); j++)
        covered.push_back(occupied(((double)across[j] + 0.5) * s.width + lateral_(out.traffic[j]), s.width));
    long n = (long)s.ids.size();
    for (const Found &p : lane_pairs(out.xs, covered, lengths, n))
        if (p.gap < LOOK_M || (p.a > p.b ? p.a : p.b) < n)
            out.pairs.push_back(p);
    return out;
}

/* _LateralTrafficSense._past_edge: (car, distance), or an empty id */
Hit past_edge(const Lateral &s, double start, long place, bool leaders, double at, double bound) {
    auto found = s.by_place.find(place);
    if (found == s.by_place.end())
        return Hit("", 0.0);
    const std::vector<Span> &spans = found->second;
    for (size_t k = 0; k < spans.size(); k++) {
        const Span &span = leaders ? spans[k] : spans[spans.size() - 1 - k];
        if (leaders ? span.start <= start : span.start >= start)
            continue;
        if ((leaders ? span.start - at - s.longest_m : at - span.end) > bound)
            return Hit("", 0.0);
        std::vector<std::string> cars = on_lane_(span.lane);
        if (!cars.empty()) {
            const std::string &car = leaders ? cars.front() : cars.back();
            double front = span.start + getters[WORLD_LANE_POSITION](car);
            return Hit(car, leaders ? front - length_(car) - at : at - front);
        }
    }
    return Hit("", 0.0);
}

struct Beside { long b; int mode; std::vector<Hit> found; };

/* _LateralTrafficSense._edging */
std::set<std::string> edging_cars(const Lateral &s, const std::vector<Beside> &beside, const std::vector<Found> &pairs,
                                  const std::set<std::string> &near, const std::vector<double> &x,
                                  const std::vector<std::pair<bool, bool>> &unseen) {
    size_t n = s.ids.size();
    std::vector<double> ahead(n, LOOK_M), behind(n, LOOK_M);
    for (const Found &p : pairs) {
        if (p.b < (long)n)
            ahead[(size_t)p.b] = p.gap < ahead[(size_t)p.b] ? p.gap : ahead[(size_t)p.b];
        if (p.a < (long)n)
            behind[(size_t)p.a] = p.gap < behind[(size_t)p.a] ? p.gap : behind[(size_t)p.a];
    }
    std::set<std::string> edging;
    for (const Beside &side_of : beside) {
        size_t b = (size_t)side_of.b;
        int mode = side_of.mode, side = mode & 1 ? -1 : 1;
        bool leaders = (mode & 2) != 0;
        Search step = leaders ? leader_ : follower_;
        double bound = leaders ? ahead[b] : behind[b];
        const PlacedLane *own = s.placed(lane_id_(s.ids[b]));
        if (own == NULL)
            continue;
        long lane = own->place + side;
        if (mode == 2) { /* once a car: its own lane past its edge */
            const bool looks[2] = {unseen[b].first, unseen[b].second};
            const double ats[2] = {x[b], x[b] - s.lengths[b]}, bounds[2] = {ahead[b], behind[b]};
            for (int k = 0; k < 2; k++) {
                if (!looks[k])
                    continue;
                Hit own_past = past_edge(s, own->start, own->place, k == 0, ats[k], bounds[k]);
                if (!own_past.first.empty())
                    edging.insert(own_past.first);
            }
        }
        std::vector<Hit> starts = side_of.found;
        if (side_of.found.empty()) {
            Hit past = past_edge(s, own->start, lane, leaders, x[b] - (leaders ? 0.0 : s.lengths[b]), bound);
            if (!past.first.empty()) {
                edging.insert(past.first);
                starts.push_back(past);
            }
        }
        for (const Hit &start : starts) {
            std::string car = start.first;
            double distance = start.second;
            for (int k = 0; k < 64; k++) {
                const PlacedLane *at = s.placed(lane_id_(car));
                if (at == NULL)
                    break;
                Hit hit("", 0.0);
                if (at->place == lane) {
                    if (!near.count(car) && s.in_platoon(car) < 0 && std::fabs(lateral_(car)) >= s.edging_m)
                        edging.insert(car);
                    hit = step(car, LOOK_M);
                } else { /* reaching into the lane from the one beyond: the lane's next car from it */
                    std::vector<Hit> nearest = neighbours_(car, (leaders ? 2 : 0) + (lane < at->place ? 1 : 0));
                    if (!nearest.empty())
                        hit = nearest.front();
                }
                if (hit.first.empty())
                    break;
                car = hit.first, distance = distance + hit.second;
                if (distance > bound)
                    break;
            }
        }
    }
    for (const std::string &vid : s.ids)
        edging.erase(vid);
    return edging;
}

/* _LateralTrafficSense.__call__, after the platoon's lanes were sensed */
Sensed lateral_step(const Lateral &s, const std::vector<double> &x, const std::vector<double> &v,
                    const std::vector<std::vector<long>> &covered) {
    std::set<std::string> near;
    std::vector<Beside> beside;
    std::vector<std::pair<bool, bool>> unseen;
    for (size_t b = 0; b < s.ids.size(); b++) {
        Hit leader = leader_(s.ids[b], LOOK_M), follower = follower_(s.ids[b], LOOK_M);
        unseen.push_back({leader.first.empty(), follower.first.empty()});
        for (const Hit *hit : {&leader, &follower})
            if (!hit->first.empty())
                near.insert(hit->first);
        for (int mode = 0; mode < 4; mode++) {
            std::vector<Hit> found = neighbours_(s.ids[b], mode);
            for (const Hit &other : found)
                near.insert(other.first);
            beside.push_back({(long)b, mode, found});
        }
    }
    Sensed found = lateral_place(s, near, x, v, covered);
    if (s.edging_sensed) {
        std::set<std::string> edging = edging_cars(s, beside, found.pairs, near, x, unseen);
        if (!edging.empty()) {
            edging.insert(near.begin(), near.end());
            found = lateral_place(s, edging, x, v, covered);
        }
    }
    return found;
}

void free_lateral(PyObject *capsule) { delete static_cast<Lateral *>(PyCapsule_GetPointer(capsule, "d4sumo.lateral_sense")); }

int read_strings(PyObject *sequence, std::vector<std::string> &out, const char *what) {
    PyObject *fast = PySequence_Fast(sequence, what);
    if (fast == NULL)
        return -1;
    for (Py_ssize_t i = 0; i < PySequence_Fast_GET_SIZE(fast); i++) {
        Py_ssize_t size;
        const char *text = PyUnicode_AsUTF8AndSize(PySequence_Fast_GET_ITEM(fast, i), &size);
        if (text == NULL) {
            Py_DECREF(fast);
            return -1;
        }
        out.emplace_back(text, (size_t)size);
    }
    Py_DECREF(fast);
    return 0;
}

extern "C" PyObject *lateral_sense(PyObject *module, PyObject *args) {
    (void)module;
    PyObject *ids, *lengths, *lanes, *by_place;
    auto s = std::unique_ptr<Lateral>(new Lateral());
    if (lane_id_ == NULL) {
        PyErr_SetString(PyExc_RuntimeError, "lateral_sense before bind gave SUMO's calls");
        return NULL;
    }
    if (!PyArg_ParseTuple(args, "OOdddpplO!O!", &ids, &lengths, &s->width, &s->edging_m, &s->longest_m, &s->edging_sensed,
                          &s->as_0_21, &s->platoon_lane, &PyDict_Type, &lanes, &PyDict_Type, &by_place))
        return NULL;
    if (read_strings(ids, s->ids, "ids") < 0)
        return NULL;
    s->lengths.resize(s->ids.size());
    if (read_doubles(lengths, s->lengths, (Py_ssize_t)s->ids.size(), "lengths") < 0)
        return NULL;
    PyObject *key, *value;
    Py_ssize_t pos = 0;
    while (PyDict_Next(lanes, &pos, &key, &value)) { /* lane -> (start, place, index) */
        double start;
        long place, index;
        const char *lane = PyUnicode_AsUTF8(key);
        if (lane == NULL || !PyArg_ParseTuple(value, "dll", &start, &place, &index))
            return NULL;
        s->lanes[lane] = {start, place};
    }
    pos = 0;
    while (PyDict_Next(by_place, &pos, &key, &value)) { /* place -> [(start, end, lane), ...], in order */
        long place = PyLong_AsLong(key);
        PyObject *fast = PySequence_Fast(value, "by_place");
        if ((place == -1 && PyErr_Occurred()) || fast == NULL) {
            Py_XDECREF(fast);
            return NULL;
        }
        std::vector<Span> &spans = s->by_place[place];
        for (Py_ssize_t i = 0; i < PySequence_Fast_GET_SIZE(fast); i++) {
            const char *lane;
            Span span;
            if (!PyArg_ParseTuple(PySequence_Fast_GET_ITEM(fast, i), "dds", &span.start, &span.end, &lane)) {
                Py_DECREF(fast);
                return NULL;
            }
            span.lane = lane;
            spans.push_back(span);
        }
        Py_DECREF(fast);
    }
    PyObject *capsule = PyCapsule_New(s.get(), "d4sumo.lateral_sense", free_lateral);
    if (capsule != NULL)
        s.release();
    return capsule;
}

PyObject *float_list(const std::vector<double> &values) {
    PyObject *list = PyList_New((Py_ssize_t)values.size());
    for (size_t i = 0; list != NULL && i < values.size(); i++) {
        PyObject *f = PyFloat_FromDouble(values[i]);
        if (f == NULL) {
            Py_CLEAR(list);
            break;
        }
        PyList_SET_ITEM(list, (Py_ssize_t)i, f);
    }
    return list;
}

extern "C" PyObject *lateral_pairs(PyObject *module, PyObject *const *args, Py_ssize_t nargs) {
    (void)module;
    if (nargs != 5) {
        PyErr_SetString(PyExc_TypeError, "lateral_pairs(sense, names, x, v, covered)");
        return NULL;
    }
    Lateral *s = static_cast<Lateral *>(PyCapsule_GetPointer(args[0], "d4sumo.lateral_sense"));
    if (s == NULL)
        return NULL;
    Py_ssize_t n = (Py_ssize_t)s->ids.size();
    std::vector<double> x((size_t)n), v((size_t)n);
    if (read_doubles(args[2], x, n, "x") < 0 || read_doubles(args[3], v, n, "v") < 0)
        return NULL;
    std::vector<std::vector<long>> covered;
    PyObject *fast = PySequence_Fast(args[4], "covered: each car's lanes");
    if (fast == NULL)
        return NULL;
    for (Py_ssize_t i = 0; i < PySequence_Fast_GET_SIZE(fast) && !PyErr_Occurred(); i++) {
        PyObject *lanes = PySequence_Fast(PySequence_Fast_GET_ITEM(fast, i), "a car's lanes");
        if (lanes == NULL)
            break;
        covered.emplace_back();
        for (Py_ssize_t j = 0; j < PySequence_Fast_GET_SIZE(lanes); j++) {
            long lane = PyLong_AsLong(PySequence_Fast_GET_ITEM(lanes, j));
            if (lane == -1 && PyErr_Occurred())
                break;
            covered.back().push_back(lane);
        }
        Py_DECREF(lanes);
    }
    Py_DECREF(fast);
    if (PyErr_Occurred())
        return NULL;
    Sensed found;
    if (guarded([&] { found = lateral_step(*s, x, v, covered); }) < 0)
        return NULL;
    PyObject *pairs = PyList_New(0), *names = PySequence_List(args[1]), *xs = float_list(found.xs), *vs = float_list(found.vs);
    int failed = pairs == NULL || names == NULL || xs == NULL || vs == NULL;
    for (size_t k = 0; !failed && k < found.pairs.size(); k++) {
        PyObject *p = Py_BuildValue("(lld)", found.pairs[k].a, found.pairs[k].b, found.pairs[k].gap);
        failed = p == NULL || PyList_Append(pairs, p) < 0;
        Py_XDECREF(p);
    }
    for (size_t k = 0; !failed && k < found.traffic.size(); k++) {
        PyObject *name = PyUnicode_FromStringAndSize(found.traffic[k].data(), (Py_ssize_t)found.traffic[k].size());
        failed = name == NULL || PyList_Append(names, name) < 0;
        Py_XDECREF(name);
    }
    PyObject *out = failed ? NULL : Py_BuildValue("(OOOO)", pairs, names, xs, vs);
    Py_XDECREF(pairs), Py_XDECREF(names), Py_XDECREF(xs), Py_XDECREF(vs);
    return out;
}
