/* A world's own calls in C, for the column's step loop (column.h): what a world that can be called without Python
 * hands it in a capsule named WORLD_CALLS_CAPSULE (SUMO's: d4sumo/engine/_sumo_calls.cpp). Each call returns 0, or
 * -1 with a Python error set; a car is known by the handle make_id gave (free_id frees it). C, for C and C++ alike. */
#ifndef D4SUMO_WORLD_CALLS_H
#define D4SUMO_WORLD_CALLS_H

#define WORLD_CALLS_CAPSULE "d4sumo.world_calls"

enum { WORLD_LANE_POSITION = 0, WORLD_DISTANCE = 1, WORLD_SPEED = 2 }; /* what `get` reads of a car */

typedef struct {
    void *(*make_id)(const char *id);
    void (*free_id)(void *id);
    int (*get)(int what, void *id, double *out);
    int (*set_speed)(void *id, double speed);
    int (*step)(void);
} WorldCalls;

#endif
