/* SUMO's own calls for the column's step loop in C (model/controllers/csrc/column.h): libsumo's C++ functions
 * (Simulation::step, Vehicle::getLanePosition, getDistance, getSpeed, setSpeed), found in the very library the
 * Python module libsumo runs (so on its one simulation), called without Python's wrapping of each call: a car's
 * position or speed costs about 15 ns where the Python call costs about 150 ns. The same functions the Python
 * wrappers call, so the same doubles. Also who is ahead of a platoon among traffic (`traffic_pairs`: neighbours'
 * _TrafficSense, its every step, with Vehicle::getLeader, getFollower, getSpeed, getLength and getMinGap), and who
 * follows whom in every lane where the attacker changes lanes among traffic (`lateral_pairs`: _LateralTrafficSense's,
 * with getNeighbors, getLaneID, getLateralLanePosition and Lane::getLastStepVehicleIDs too).
 *
 * bind(path of libsumo's _libsumo.so, libsumo.TraCIException, libsumo.FatalTraCIError) returns a capsule of `WorldCalls` (csrc/world_calls.h),
 * or None where this libsumo does not expose them as this build names them (another compiler's C++ library, another
 * platform): the loop then calls libsumo as the Python does. An error of SUMO's is raised as libsumo's Python wrapper
 * raises it: libsumo.TraCIException for libsumo's own, libsumo.FatalTraCIError for any other, SUMO's message.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include "world_calls.h" /* d4sumo/model/controllers/csrc: what the loop reads */

#if defined(__linux__) && defined(_GLIBCXX_USE_CXX11_ABI) && _GLIBCXX_USE_CXX11_ABI
#define DIRECT 1
#include <cxxabi.h>
#include <dlfcn.h>
#include <cstring>
#include <exception>
#include <string>
#include <typeinfo>
#include <algorithm>
#include <cmath>
#include <map>
#include <memory>
#include <set>
#include <unordered_map>
#include <utility>
#include <vector>

namespace {

typedef double (*Getter)(const std::string &);
typedef void (*Setter)(const std::string &, double);
typedef void (*Stepper)(double);
typedef std::pair<std::string, double> (*Search)(const std::string &, double);

Getter getters[3]; /* WORLD_LANE_POSITION, WORLD_DISTANCE, WORLD_SPEED */
Getter length_, min_gap_;  /* Vehicle::getLength, getMinGap */
Search leader_, follower_; /* Vehicle::getLeader, getFollower */
Setter set_speed_;
Stepper step_;
PyObject *traci_exception; /* libsumo.TraCIException: SUMO's answer to a call it refuses (a car it does not know) */
PyObject *fatal_error;     /* libsumo.FatalTraCIError: any other error of SUMO's, as libsumo's wrappers raise it */

/* libsumo's names as g++ mangles them with the C++11 string (libstdc++'s __cxx11 ABI, which libsumo's wheels use) */
const char *const GETTER_NAMES[3] = {
    "_ZN7libsumo7Vehicle15getLanePositionERKNSt7__cxx1112basic_stringIcSt11char_traitsIcESaIcEEE",
    "_ZN7libsumo7Vehicle11getDistanceERKNSt7__cxx1112basic_stringIcSt11char_traitsIcESaIcEEE",
    "_ZN7libsumo7Vehicle8getSpeedERKNSt7__cxx1112basic_stringIcSt11char_traitsIcESaIcEEE",
};
const char *const SET_SPEED_NAME = "_ZN7libsumo7Vehicle8setSpeedERKNSt7__cxx1112basic_stringIcSt11char_traitsIcESaIcEEEd";
const char *const STEP_NAME = "_ZN7libsumo10Simulation4stepEd";
const char *const LENGTH_NAME = "_ZN7libsumo7Vehicle9getLengthERKNSt7__cxx1112basic_stringIcSt11char_traitsIcESaIcEEE";
const char *const MIN_GAP_NAME = "_ZN7libsumo7Vehicle9getMinGapERKNSt7__cxx1112basic_stringIcSt11char_traitsIcESaIcEEE";
const char *const LEADER_NAME = "_ZN7libsumo7Vehicle9getLeaderERKNSt7__cxx1112basic_stringIcSt11char_traitsIcESaIcEEEd";
const char *const FOLLOWER_NAME = "_ZN7libsumo7Vehicle11getFollowerERKNSt7__cxx1112basic_stringIcSt11char_traitsIcESaIcEEEd";
const char *const LANE_ID_NAME = "_ZN7libsumo7Vehicle9getLaneIDERKNSt7__cxx1112basic_stringIcSt11char_traitsIcESaIcEEE";
const char *const LATERAL_NAME = "_ZN7libsumo7Vehicle22getLateralLanePositionERKNSt7__cxx1112basic_stringIcSt11char_traitsIcESaIcEEE";
const char *const NEIGHBOURS_NAME = "_ZN7libsumo7Vehicle12getNeighborsERKNSt7__cxx1112basic_stringIcSt11char_traitsIcESaIcEEEi";
const char *const ON_LANE_NAME = "_ZN7libsumo4Lane21getLastStepVehicleIDsERKNSt7__cxx1112basic_stringIcSt11char_traitsIcESaIcEEE";

/* the error libsumo's Python wrapper raises for the exception being handled: TraCIException for libsumo's own, else
 * FatalTraCIError; what libsumo's wrappers say of one that is no std::exception */
int raised(const char *what) {
    const std::type_info *type = abi::__cxa_current_exception_type();
    int traci = type != NULL && std::strcmp(type->name(), "N7libsumo14TraCIExceptionE") == 0;
    PyErr_SetString(traci ? traci_exception : fatal_error, what);
    return -1;
}

struct PythonError {}; /* thrown where a Python error is set already: it is returned as it is */

/* call(): 0, or -1 with SUMO's error (or the Python error already set) raised as libsumo's Python raises it */
template <class Call> int guarded(Call &&call) {
    try {
        call();
        return 0;
    } catch (const PythonError &) {
        return -1;
    } catch (const std::exception &e) {
        return raised(e.what());
    } catch (...) {
        return raised("unknown exception");
    }
}

extern "C" {

static void *make_id(const char *id) {
    try {
        return new std::string(id);
    } catch (...) {
        PyErr_NoMemory();
        return NULL;
    }
}

static void free_id(void *id) { delete static_cast<std::string *>(id); }

static int get(int what, void *id, double *out) {
    return guarded([&] { *out = getters[what](*static_cast<std::string *>(id)); });
}

static int set_speed(void *id, double speed) {
    return guarded([&] { set_speed_(*static_cast<std::string *>(id), speed); });
}

static int step(void) {
    return guarded([] { step_(0.0); });
}

} /* extern "C" */

WorldCalls calls = {make_id, free_id, get, set_speed, step};

#include "traffic_sense.h"
#include "lateral_sense.h"

} /* namespace */
#endif

static PyObject *bind(PyObject *module, PyObject *args) {
    (void)module;
    const char *path;
    PyObject *exception, *fatal;
    if (!PyArg_ParseTuple(args, "sOO", &path, &exception, &fatal))
        return NULL;
#ifdef DIRECT
    void *library = dlopen(path, RTLD_NOW | RTLD_NOLOAD); /* the one Python loaded: its simulation */
    if (library == NULL)
        Py_RETURN_NONE;
    for (int i = 0; i < 3; i++)
        getters[i] = (Getter)dlsym(library, GETTER_NAMES[i]);
    set_speed_ = (Setter)dlsym(library, SET_SPEED_NAME);
    step_ = (Stepper)dlsym(library, STEP_NAME);
    length_ = (Getter)dlsym(library, LENGTH_NAME), min_gap_ = (Getter)dlsym(library, MIN_GAP_NAME);
    leader_ = (Search)dlsym(library, LEADER_NAME), follower_ = (Search)dlsym(library, FOLLOWER_NAME);
    lane_id_ = (LaneOf)dlsym(library, LANE_ID_NAME), lateral_ = (Getter)dlsym(library, LATERAL_NAME);
    neighbours_ = (Neighbours)dlsym(library, NEIGHBOURS_NAME), on_lane_ = (OnLane)dlsym(library, ON_LANE_NAME);
    dlclose(library); /* it stays loaded: Python holds it */
    if (!getters[0] || !getters[1] || !getters[2] || !set_speed_ || !step_ || !length_ || !min_gap_ || !leader_ || !follower_
        || !lane_id_ || !lateral_ || !neighbours_ || !on_lane_)
        Py_RETURN_NONE;
    Py_INCREF(exception);
    Py_XSETREF(traci_exception, exception);
    Py_INCREF(fatal);
    Py_XSETREF(fatal_error, fatal);
    return PyCapsule_New(&calls, WORLD_CALLS_CAPSULE, NULL);
#else
    (void)path, (void)exception, (void)fatal;
    Py_RETURN_NONE;
#endif
}

static PyMethodDef methods[] = {
    {"bind", bind, METH_VARARGS,
     "bind(path of libsumo's _libsumo.so, libsumo.TraCIException, libsumo.FatalTraCIError): SUMO's calls, or None"},
#ifdef DIRECT
    {"traffic_pairs", (PyCFunction)(void (*)(void))traffic_pairs, METH_FASTCALL,
     "traffic_pairs(ids, lengths, min_gaps, names, x, v): neighbours._TrafficSense's step, once bind gave SUMO's calls"},
    {"lateral_sense", lateral_sense, METH_VARARGS,
     "lateral_sense(ids, lengths, width_m, edging_m, longest_m, edging_sensed, as_0_21, platoon_lane, lanes, by_place)"},
    {"lateral_pairs", (PyCFunction)(void (*)(void))lateral_pairs, METH_FASTCALL,
     "lateral_pairs(sense, names, x, v, covered): neighbours._LateralTrafficSense's step"},
#endif
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_sumo_calls", "libsumo's C++ calls for the step loop in C.", -1, methods, NULL, NULL, NULL, NULL,
};

PyMODINIT_FUNC PyInit__sumo_calls(void) { return PyModule_Create(&module); }
