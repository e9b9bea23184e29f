/* The bidirectional A* of planner.bidirectional (its search, and the path through the meeting edge):
 * the heuristics, heap keys and 4-ary heap of the grid A* (astar_search.h), in a library of its own
 * that planner.bidirectional loads, so a run that searches one way only does not compile it. */
#include "astar_search.h"

typedef struct {
    Work work;
    int32_t generation;
    int64_t size;
    int64_t searched;
} Side;

/* best: mu [cells]; meet[1] forward, meet[2] backward meeting nodes. */
typedef struct {
    double mu;
    int64_t meet[3];
} Best;

/* Pop and expand one node of one side; -1 = heap full, 0 = popped a stale entry or expanded, 1 = empty. */
static int64_t expand(const uint8_t *moves, int64_t width, int64_t target, int backward, int64_t heuristic,
                      double h_scale, int64_t tie_breaker, int decrease_key, const double *cost,
                      double cost_weight, Side *side, const Side *other_side, Best *best, int mine) {
    double *g = side->work.g;
    int32_t *parent = side->work.parent;
    int32_t *stamp = side->work.stamp;
    const double *other_g = other_side->work.g;
    const int32_t *other_stamp = other_side->work.stamp;
    const int32_t other_generation = other_side->generation;
    const int32_t generation = side->generation;
    const int32_t closed = generation + 1;
    if (side->size == 0) return 1;
    int64_t node = heap_pop(side->work.heap_key, side->work.heap_node, &side->size);
    if (stamp[node] == closed) return 0;
    stamp[node] = closed;
    side->work.expanded[side->searched] = (int32_t)node;
    side->searched++;
    double g_node = g[node];
    int64_t row_offset = node / width - target / width;
    int64_t col_offset = node % width - target % width;
    unsigned allowed = moves[node];
    for (int k = 0; k < 8; k++) {
        if (!((allowed >> k) & 1u)) continue;
        int64_t offset = ROW_STEPS[k] * width + COL_STEPS[k];
        int64_t neighbour = node + offset;
        int32_t seen = stamp[neighbour];
        if (seen == closed) continue;
        double step = ROW_STEPS[k] != 0 && COL_STEPS[k] != 0 ? SQRT2 : 1.0;
        if (cost_weight != 0.0) step *= 1.0 + cost_weight * cost[backward ? node : neighbour];
        double g_new = g_node + step;
        int32_t other = other_stamp[neighbour];
        int reached_by_other = other == other_generation || other == other_generation + 1;
        if (reached_by_other && g_new + other_g[neighbour] < best->mu) {
            best->mu = g_new + other_g[neighbour];
            best->meet[mine] = node;
            best->meet[3 - mine] = neighbour;
        }
        if (seen == generation) {
            if (g_new >= g[neighbour]) continue;
            g[neighbour] = g_new;
            parent[neighbour] = (int32_t)node;
            if (!decrease_key) continue;
        } else {
            stamp[neighbour] = generation;
            g[neighbour] = g_new;
            parent[neighbour] = (int32_t)node;
        }
        if (side->size == side->work.capacity) return -1;
        double h = heuristic_cells(row_offset + ROW_STEPS[k], col_offset + COL_STEPS[k], heuristic) * h_scale;
        side->size =
            heap_push(side->work.heap_key, side->work.heap_node, side->size, heap_key_of(g_new + h, h, tie_breaker),
                      neighbour);
    }
    return 0;
}

static void root(int64_t width, int64_t node, int64_t target, int64_t heuristic, double h_scale,
                 int64_t tie_breaker, Side *side) {
    side->work.g[node] = 0.0;
    side->work.parent[node] = (int32_t)node;
    side->work.stamp[node] = side->generation;
    heap_clear(side->work.heap_key);
    double h = heuristic_cells(node / width - target / width, node % width - target % width, heuristic) * h_scale;
    side->size = heap_push(side->work.heap_key, side->work.heap_node, 0, heap_key_of(h, h, tie_breaker), node);
}

/* planner.bidirectional.bidirectional_search. out: searched forward, searched backward, meet forward,
 * meet backward; *mu [cells]. Each side's heap: keys and nodes of `capacity` entries (capacity -
 * HEAP_SLACK in use). Returns 1 found, 0 none, -1 a heap is full (enlarge both, search again). */
int64_t navcosim_bidirectional_search(const uint8_t *moves, const double *cost, const double *parameters,
                                      int64_t start, int64_t goal, int64_t size, double *g_forward,
                                      int32_t *nodes_forward, int64_t generation_forward,
                                      int64_t *heap_key_forward, int64_t *heap_node_forward,
                                      int64_t capacity_forward, double *g_backward, int32_t *nodes_backward,
                                      int64_t generation_backward, int64_t *heap_key_backward,
                                      int64_t *heap_node_backward, int64_t capacity_backward, int64_t *out,
                                      double *mu) {
    int64_t width = (int64_t)parameters[P_WIDTH];
    int64_t heuristic = (int64_t)parameters[P_HEURISTIC];
    int64_t tie_breaker = (int64_t)parameters[P_TIE];
    int decrease_key = parameters[P_DECREASE] != 0.0;
    double h_scale = parameters[P_H_SCALE];
    double cost_weight = parameters[P_COST_WEIGHT];
    Side forward = {{g_forward, nodes_forward, nodes_forward + size, nodes_forward + 2 * size, heap_key_forward,
                     heap_node_forward, capacity_forward - HEAP_SLACK},
                    (int32_t)generation_forward, 0, 0};
    Side backward = {{g_backward, nodes_backward, nodes_backward + size, nodes_backward + 2 * size,
                      heap_key_backward, heap_node_backward, capacity_backward - HEAP_SLACK},
                     (int32_t)generation_backward, 0, 0};
    Best best = {INFINITY, {0, -1, -1}};
    out[0] = out[1] = 0;
    out[2] = out[3] = -1;
    *mu = 0.0;
    if (forward.work.capacity <= 0 || backward.work.capacity <= 0) return -1;
    root(width, start, goal, heuristic, h_scale, tie_breaker, &forward);
    root(width, goal, start, heuristic, h_scale, tie_breaker, &backward);
    if (start == goal) {
        forward.work.expanded[0] = (int32_t)start;
        out[0] = 1;
        out[2] = start;
        return 1;
    }
    while (forward.size > 0 && backward.size > 0) {
        double top_forward = (double)(forward.work.heap_key[0] >> H_BITS) / F_SCALE;
        double top_backward = (double)(backward.work.heap_key[0] >> H_BITS) / F_SCALE;
        if (top_forward >= best.mu || top_backward >= best.mu) break;
        int64_t status;
        if (forward.size > backward.size)
            status = expand(moves, width, start, 1, heuristic, h_scale, tie_breaker, decrease_key, cost, cost_weight,
                            &backward, &forward, &best, 2);
        else
            status = expand(moves, width, goal, 0, heuristic, h_scale, tie_breaker, decrease_key, cost, cost_weight,
                            &forward, &backward, &best, 1);
        if (status < 0) {
            out[0] = forward.searched;
            out[1] = backward.searched;
            return -1;
        }
    }
    out[0] = forward.searched;
    out[1] = backward.searched;
    if (best.mu == INFINITY) return 0;
    out[2] = best.meet[1];
    out[3] = best.meet[2];
    *mu = best.mu;
    return 1;
}

/* planner.bidirectional.join_paths, given the node count: fills cells [count, 2], path [count, 2] [m];
 * returns the length [m]. count: navcosim_join_count. */
int64_t navcosim_join_count(const int32_t *parent_forward, const int32_t *parent_backward, int64_t start,
                            int64_t goal, int64_t meet_forward, int64_t meet_backward) {
    int64_t forward_count = 1;
    int64_t node = meet_forward;
    while (node != start) {
        node = parent_forward[node];
        forward_count++;
    }
    int64_t backward_count = 0;
    if (meet_backward >= 0) {
        backward_count = 1;
        node = meet_backward;
        while (node != goal) {
            node = parent_backward[node];
            backward_count++;
        }
    }
    return forward_count + backward_count;
}

double navcosim_join_paths(const int32_t *parent_forward, const int32_t *parent_backward, int64_t start,
                           int64_t meet_forward, int64_t meet_backward, int64_t count, const double *parameters,
                           int64_t *cells, double *path) {
    int64_t forward_count = 1;
    int64_t node = meet_forward;
    while (node != start) {
        node = parent_forward[node];
        forward_count++;
    }
    /* cells' first column holds the node sequence until the second pass converts it */
    node = meet_forward;
    for (int64_t index = forward_count - 1; index >= 0; index--) {
        cells[2 * index] = node;
        node = parent_forward[node];
    }
    node = meet_backward;
    for (int64_t index = forward_count; index < count; index++) {
        cells[2 * index] = node;
        node = parent_backward[node];
    }
    int64_t width = (int64_t)parameters[P_WIDTH];
    double resolution = parameters[P_RESOLUTION];
    double length = 0.0;
    int64_t previous = 0;
    for (int64_t index = 0; index < count; index++) {
        node = cells[2 * index];
        node_cell_and_point(node, parameters, cells + 2 * index, path + 2 * index);
        if (index > 0) length += move_length(node, previous, width, resolution);
        previous = node;
    }
    return length;
}
