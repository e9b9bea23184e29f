/* Grid A* of chapter 3 (planner.astar): heuristics 3.1-3.4 and 3.6 and the thesis's improvements.
 * Loaded with native.load; the Python side (planner/astar.py) documents the data layout, the heap
 * keys and the status codes. (The bidirectional search is bidirectional.c's, a library
 * planner.bidirectional loads.)
 *
 * The search loop (astar_search.h) is compiled here for the settings of a scenario's planner (the
 * thesis's heuristic; any with a cost gradient) and planner.plan's defaults only; every other
 * setting is searched by astar_general.c's library, which planner.astar builds and loads the first
 * time such settings are asked for (it compiles the loop seven times, most of what building both
 * files costs) and registers here (navcosim_astar_set_general).
 */
#include "astar_search.h"
#include "layout.h"

double navcosim_heuristic_cells(int64_t row_offset, int64_t col_offset, int64_t kind) {
    return heuristic_cells(row_offset, col_offset, kind);
}

int64_t navcosim_heap_key_of(double f, double h, int64_t tie_breaker) { return heap_key_of(f, h, tie_breaker); }

/* The search of the settings needs_general names: astar_general.c's, once planner.astar has loaded it. */
static SearchFunction general_search = NULL;

void navcosim_astar_set_general(SearchFunction function) { general_search = function; }

/* Whether `parameters` need the general search: not the settings of astar.c's own loops, those a
 * scenario's planner searches with (the thesis's heuristic of the "modified" configuration, and any
 * heuristic with a cost gradient, as its replanning does) and planner.plan's defaults (octile with 8
 * neighbours or Manhattan with 4, the low_h tie breaker, decrease-key, h_scale 1). */
static inline int needs_general(const double *parameters) {
    double heuristic = parameters[P_HEURISTIC];
    if (parameters[P_COST_WEIGHT] != 0.0 || heuristic == 4.0) return 0;
    return !(parameters[P_TIE] == 2.0 && parameters[P_DECREASE] != 0.0 && parameters[P_H_SCALE] == 1.0 &&
             (heuristic == 3.0 || heuristic == 0.0));
}

int64_t navcosim_astar_needs_general(const double *parameters) { return needs_general(parameters); }

static int64_t search(const uint8_t *moves, const double *cost, const double *parameters, int64_t start,
                      int64_t goal, int32_t generation, const Work *work, int64_t *searched) {
    int64_t width = (int64_t)parameters[P_WIDTH];
    if (needs_general(parameters)) /* NO_GENERAL until planner.astar has registered it */
        return general_search != NULL ? general_search(moves, cost, parameters, start, goal, generation, work, searched)
                                      : NO_GENERAL;
    int64_t heuristic = (int64_t)parameters[P_HEURISTIC];
    if (parameters[P_COST_WEIGHT] != 0.0) /* the cost gradient, every other setting as given */
        return search_loop(moves, cost, width, heuristic, (int64_t)parameters[P_TIE], parameters[P_DECREASE] != 0.0,
                           parameters[P_H_SCALE], parameters[P_COST_WEIGHT], 1, start, goal, generation, work, searched);
    if (heuristic == 4) /* the thesis's heuristic, its other settings as given */
        return search_loop(moves, cost, width, 4, (int64_t)parameters[P_TIE], parameters[P_DECREASE] != 0.0,
                           parameters[P_H_SCALE], 0.0, 0, start, goal, generation, work, searched);
    /* the defaults with every setting a constant; h * 1.0 is h, so the product is left out without
     * changing a bit */
    if (heuristic == 3)
        return search_loop(moves, cost, width, 3, 2, 1, 1.0, 0.0, 0, start, goal, generation, work, searched);
    return search_loop(moves, cost, width, 0, 2, 1, 1.0, 0.0, 0, start, goal, generation, work, searched);
}

/* planner.astar.astar_search: A* (or Dijkstra with heuristic 5 and goal -1) on a padded flat grid.
 * nodes: int32 [3, size]; heap: int64 [2, capacity] (capacity - HEAP_SLACK entries in use). Returns the
 * status; *searched the expanded count. */
int64_t navcosim_astar_search(const uint8_t *moves, const double *cost, const double *parameters, int64_t start,
                              int64_t goal, int64_t generation, double *g, int32_t *nodes, int64_t size,
                              int64_t *heap, int64_t capacity, int64_t *searched) {
    *searched = 0;
    if (capacity <= HEAP_SLACK) return HEAP_FULL;
    Work work = {g, nodes, nodes + size, nodes + 2 * size, heap, heap + capacity, capacity - HEAP_SLACK};
    return search(moves, cost, parameters, start, goal, (int32_t)generation, &work, searched);
}

/* Padded node of the cell that holds (x, y) [m], or -1: outside the map, NaN, or a blocked cell. */
static int64_t endpoint_node(const uint8_t *blocked, const double *parameters, double x, double y) {
    double resolution = parameters[P_RESOLUTION];
    double column = floor((x - parameters[P_ORIGIN_X]) / resolution);
    double row_from_bottom = floor((y - parameters[P_ORIGIN_Y]) / resolution);
    double rows = parameters[P_ROWS];
    if (!(0.0 <= column && column < parameters[P_COLS] && 0.0 <= row_from_bottom && row_from_bottom < rows))
        return -1; /* also NaN, which fails every comparison */
    int64_t node = ((int64_t)rows - (int64_t)row_from_bottom) * (int64_t)parameters[P_WIDTH] + (int64_t)column + 1;
    if (blocked[node] == BLOCKED) return -1;
    return node;
}

int64_t navcosim_endpoint_node(const uint8_t *blocked, const double *parameters, double x, double y) {
    return endpoint_node(blocked, parameters, x, y);
}

/* The work arrays of planner.searchspace.Workspace (planner.astar.WorkState). */
typedef struct {
    double *g;
    int32_t *nodes; /* [3, size] */
    int64_t size;   /* padded cells */
    int64_t *heap;  /* [2, capacity] */
    int64_t capacity;
    double *path;   /* [path_rows, 2] x, y [m] */
    int64_t *cells; /* [path_rows, 2] row, col */
    int64_t path_rows;
    int64_t generation; /* of the last search */
} WorkState;

/* One prepared grid A* of planner.planning.GridSearch, every pointer set once (planner.astar.Query). */
typedef struct {
    const uint8_t *moves;
    const uint8_t *blocked;
    const double *cost;
    const double *parameters;
    WorkState *work;
    /* the answer */
    int64_t searched;
    int64_t count;
    double length;
} Query;

#define STAMP_LIMIT (2147483647 - 7) /* planner.searchspace._STAMP_LIMIT */

/* planner.astar.astar_plan: a fresh generation (Workspace.next_generation), endpoints, search and
 * path in one call. Returns the status; the query's searched, count (path nodes: on ROUTE_FULL the
 * rows needed) and length [m]. */
int64_t navcosim_astar_plan(Query *q, double start_x, double start_y, double goal_x, double goal_y) {
    const double *parameters = q->parameters;
    WorkState *state = q->work;
    q->searched = 0;
    q->count = 0;
    q->length = 0.0;
    state->generation += 2;
    if (state->generation >= STAMP_LIMIT) {
        int32_t *stamp = state->nodes + state->size;
        for (int64_t i = 0; i < state->size; i++) stamp[i] = 0;
        state->generation = 2;
    }
    int64_t start = endpoint_node(q->blocked, parameters, start_x, start_y);
    if (start < 0) return BAD_START;
    int64_t goal = endpoint_node(q->blocked, parameters, goal_x, goal_y);
    if (goal < 0) return BAD_GOAL;
    Work work = {state->g,    state->nodes + 0,           state->nodes + state->size,
                 state->nodes + 2 * state->size, state->heap, state->heap + state->capacity,
                 state->capacity - HEAP_SLACK};
    if (work.capacity <= 0) return HEAP_FULL;
    int64_t status = search(q->moves, q->cost, parameters, start, goal, (int32_t)state->generation, &work,
                            &q->searched);
    if (status != FOUND) return status;
    const int32_t *parent = work.parent;
    int64_t count = 1;
    int64_t node = goal;
    while (node != start) {
        node = parent[node];
        count++;
    }
    q->count = count;
    if (count > state->path_rows) return ROUTE_FULL;
    int64_t width = (int64_t)parameters[P_WIDTH];
    double resolution = parameters[P_RESOLUTION];
    double length = 0.0;
    node = goal;
    for (int64_t index = count - 1; index >= 0; index--) {
        node_cell_and_point(node, parameters, state->cells + 2 * index, state->path + 2 * index);
        int64_t previous = parent[node];
        if (node != start) length += move_length(previous, node, width, resolution);
        node = previous;
    }
    q->length = length;
    return FOUND;
}

/* The thin call of planner.planning.GridSearch: ctypes converts each argument at some cost (a call
 * of five arguments costs about three times one of none), so the query's address and endpoints
 * go in, and the answer comes out, through this block, packed and unpacked by one struct call
 * each. One block for every caller: like the work arrays that plan() shares between grids of one
 * size, it assumes one thread plans at a time (the kernels hold the GIL, ctypes.PyDLL, but a thread
 * switch can fall between packing, the call and unpacking). */
struct {
    int64_t query;     /* Query * */
    double endpoints[4]; /* start x, y, goal x, y [m] */
    int64_t status;
    int64_t searched;
    int64_t count;
    double length;
} navcosim_astar_io;

void navcosim_astar_call(void) {
    Query *q = (Query *)(intptr_t)navcosim_astar_io.query;
    const double *e = navcosim_astar_io.endpoints;
    navcosim_astar_io.status = navcosim_astar_plan(q, e[0], e[1], e[2], e[3]);
    navcosim_astar_io.searched = q->searched;
    navcosim_astar_io.count = q->count;
    navcosim_astar_io.length = q->length;
}

/* The tables Python mirrors (see layout.h). */
int64_t navcosim_layout(const char **names, int64_t *values, int64_t capacity)
{
    int64_t n = 0;
    LAYOUT_SIZE(WorkState);
    LAYOUT_FIELD(WorkState, g);
    LAYOUT_FIELD(WorkState, nodes);
    LAYOUT_FIELD(WorkState, size);
    LAYOUT_FIELD(WorkState, heap);
    LAYOUT_FIELD(WorkState, capacity);
    LAYOUT_FIELD(WorkState, path);
    LAYOUT_FIELD(WorkState, cells);
    LAYOUT_FIELD(WorkState, path_rows);
    LAYOUT_FIELD(WorkState, generation);
    LAYOUT_SIZE(Query);
    LAYOUT_FIELD(Query, moves);
    LAYOUT_FIELD(Query, blocked);
    LAYOUT_FIELD(Query, cost);
    LAYOUT_FIELD(Query, parameters);
    LAYOUT_FIELD(Query, work);
    LAYOUT_FIELD(Query, searched);
    LAYOUT_FIELD(Query, count);
    LAYOUT_FIELD(Query, length);
    LAYOUT_CONSTANT(NO_PATH);
    LAYOUT_CONSTANT(FOUND);
    LAYOUT_CONSTANT(HEAP_FULL);
    LAYOUT_CONSTANT(ROUTE_FULL);
    LAYOUT_CONSTANT(BAD_START);
    LAYOUT_CONSTANT(BAD_GOAL);
    LAYOUT_CONSTANT(NO_GENERAL);
    LAYOUT_CONSTANT(BLOCKED);
    LAYOUT_CONSTANT(H_BITS);
    LAYOUT_CONSTANT(F_SCALE);
    LAYOUT_CONSTANT(H_SCALE);
    LAYOUT_CONSTANT(H_MAX);
    LAYOUT_CONSTANT(P_WIDTH);
    LAYOUT_CONSTANT(P_HEURISTIC);
    LAYOUT_CONSTANT(P_TIE);
    LAYOUT_CONSTANT(P_DECREASE);
    LAYOUT_CONSTANT(P_H_SCALE);
    LAYOUT_CONSTANT(P_COST_WEIGHT);
    LAYOUT_CONSTANT(P_ROWS);
    LAYOUT_CONSTANT(P_COLS);
    LAYOUT_CONSTANT(P_RESOLUTION);
    LAYOUT_CONSTANT(P_ORIGIN_X);
    LAYOUT_CONSTANT(P_ORIGIN_Y);
    LAYOUT_CONSTANT(HEAP_SLACK);
    LAYOUT_CONSTANT(STAMP_LIMIT);
    return n;
}
