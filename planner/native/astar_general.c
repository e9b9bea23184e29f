/* The grid A* of planner.astar for the settings astar.c does not search itself (its needs_general:
 * all but planner.plan's defaults, the thesis's heuristic and those with a cost gradient): the
 * search loop of astar_search.h specialised for each heuristic, and for the cost gradient. A
 * library of its own, built and loaded by planner.astar the first time such settings are asked
 * for, which registers navcosim_astar_general_search with astar.c's library. */
#include "astar_search.h"

#define SEARCH(H, W)                                                                                          \
    search_loop(moves, cost, width, H, tie_breaker, decrease_key, h_scale, cost_weight, W, start, goal,       \
                generation, work, searched)

int64_t navcosim_astar_general_search(const uint8_t *moves, const double *cost, const double *parameters,
                                      int64_t start, int64_t goal, int32_t generation, const Work *work,
                                      int64_t *searched) {
    int64_t width = (int64_t)parameters[P_WIDTH];
    int64_t heuristic = (int64_t)parameters[P_HEURISTIC];
    int64_t tie_breaker = (int64_t)parameters[P_TIE];
    int decrease_key = parameters[P_DECREASE] != 0.0;
    double h_scale = parameters[P_H_SCALE];
    double cost_weight = parameters[P_COST_WEIGHT];
    if (cost_weight != 0.0) return SEARCH(heuristic, 1);
    switch (heuristic) { /* constant heuristics: the compiler drops the others' code from the loop */
    case 3: return SEARCH(3, 0);
    case 0: return SEARCH(0, 0);
    case 1: return SEARCH(1, 0);
    case 2: return SEARCH(2, 0);
    case 4: return SEARCH(4, 0);
    default: return SEARCH(5, 0);
    }
}
