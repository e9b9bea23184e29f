/* Hybrid A*: the search loop of planner/hybrid_search.py, the curves of planner/reeds_shepp.py and
 * planner/dubins.py and the collision check of planner/hybrid_geometry.py, in C (native/load.py
 * builds and loads it). The operations and their order are those of the Python/numba versions
 * these replaced, so the results are the same bit for bit.
 *
 * Nodes are continuous poses (x, y, theta); the closed set is keyed on (row, col, heading bin).
 * Each popped node is expanded with every motion primitive; at the first pop, every
 * `analytic_interval` pops and at every pop near the goal, an obstacle-checked Reeds-Shepp (or
 * Dubins) curve to the goal is tried and ends the search when it is free (analytic expansion). */
#include <stdlib.h>
#include <string.h>

#include "hybrid_curves.h"
#include "layout.h"

/* Search outcomes (planner/hybrid_search.py names them). */
#define HY_FOUND_AT_GOAL 1  /* a primitive ended within the goal tolerance */
#define HY_FOUND_ANALYTIC 2 /* an analytic curve reached the goal exactly */
#define HY_EXHAUSTED 0      /* OPEN became empty */
#define HY_ITERATION_CAP -1 /* max_iterations expansions without reaching the goal */
#define HY_NO_MEMORY -3     /* the closed-set index could not grow */
/* Farther than this many turning radii from the goal, the heuristic uses the Euclidean distance in
 * place of the curve length (both are lower bounds of the path length). */
#define HY_CURVE_HEURISTIC_RANGE 6.0

/* ---- the order in which candidate curves are tried: cheapest first, exact ties in enumeration order ---- */

/* out[0:n] = the indices of a[0:n] by increasing value, equal values in index order (a stable
 * insertion sort: a few dozen candidates). NaN never occurs (costs are sums of finite lengths). */
void hy_argsort(const double *a, int64_t n, int64_t *out) {
    for (int64_t k = 0; k < n; k++) {
        int64_t position = k;
        while (position > 0 && a[out[position - 1]] > a[k]) {
            out[position] = out[position - 1];
            position--;
        }
        out[position] = k;
    }
}

/* ---- the search ---- */

typedef struct {
    /* the map (inflated) and the obstacle-aware distance to the goal [m] per cell (rows x cols) */
    const uint8_t *occupied;
    int64_t rows, cols;
    double resolution, origin_x, origin_y;
    const double *distance;
    double start[3], goal[3];
    /* motion primitives: P of them, samples P x M x 3 local poses, sample_count[P] */
    const double *prim_cost;
    const int64_t *prim_direction;
    const double *prim_samples;
    const int64_t *prim_sample_count;
    int64_t primitives, max_samples;
    int64_t heading_bins;
    double radius;
    int64_t forward_only; /* 0: Reeds-Shepp curves (reverse allowed), 1: Dubins */
    double reverse_cost, steering_cost, switch_cost;
    int64_t analytic_interval;
    double analytic_distance, goal_tolerance, heading_tolerance, collision_step;
    int64_t max_iterations;
    /* node arrays with room for max_iterations x P + 1 nodes; closed starts all 0 */
    double *node_x, *node_y, *node_theta, *node_g;
    int64_t *node_parent, *node_primitive, *node_direction;
    uint8_t *closed;
    double *heap_f, *heap_h;
    int64_t *heap_node;
    uint8_t *explored; /* rows x cols, starts all 0: the cells of expanded nodes */
    /* results */
    int64_t status, final_node, expanded, analytic_count;
    double analytic_cost;
    double analytic_curvature[5], analytic_length[5];
} HySearch;

/* Candidate buffers of the curves (letters, signed lengths: K x 5) and of analytic expansion. */
typedef struct {
    int64_t letters[HY_RS_MAX_CANDIDATES * 5];
    double lengths[HY_RS_MAX_CANDIDATES * 5];
    double costs[HY_RS_MAX_CANDIDATES];
    int64_t order[HY_RS_MAX_CANDIDATES];
} HyScratch;

static inline void hy_cell(const HySearch *s, double x, double y, int64_t *row, int64_t *col) {
    *col = (int64_t)floor((x - s->origin_x) / s->resolution);
    *row = s->rows - 1 - (int64_t)floor((y - s->origin_y) / s->resolution);
}

/* Closed-set key of (row, col, heading bin); bins are centred on multiples of 2pi/bins. */
static inline int64_t hy_state_key(int64_t row, int64_t col, double theta, int64_t cols, int64_t heading_bins) {
    int64_t heading_bin = (int64_t)rint(hy_py_mod(theta, HY_TWO_PI) / (HY_TWO_PI / (double)heading_bins));
    heading_bin %= heading_bins;
    if (heading_bin < 0) heading_bin += heading_bins; /* Python's modulo (never negative here) */
    return (row * cols + col) * heading_bins + heading_bin;
}

/* Obstacle-free curve length [m] from a pose to the goal: Reeds-Shepp, or Dubins if forward only. */
static double hy_curve_length_to_goal(const HySearch *s, double x, double y, double theta, HyScratch *scratch) {
    double nx, ny, nphi;
    hy_normalize(x, y, theta, s->goal[0], s->goal[1], s->goal[2], s->radius, &nx, &ny, &nphi);
    if (!s->forward_only) return hy_rs_shortest(nx, ny, nphi, scratch->letters, scratch->lengths, 5) * s->radius;
    return hy_dubins_shortest(nx, ny, nphi, scratch->letters, scratch->lengths, 5) * s->radius;
}

static double hy_heuristic(const HySearch *s, double x, double y, double theta, HyScratch *scratch) {
    int64_t row, col;
    hy_cell(s, x, y, &row, &col);
    if (row < 0 || row >= s->rows || col < 0 || col >= s->cols) return INFINITY;
    double distance = s->distance[row * s->cols + col];
    double euclidean = hypot(s->goal[0] - x, s->goal[1] - y);
    /* far from the goal the curve is about the Euclidean distance, which `distance` almost always
     * exceeds; the curve costs ~15 us, so it is skipped there */
    if (euclidean > HY_CURVE_HEURISTIC_RANGE * s->radius) return hy_max(distance, euclidean);
    return hy_max(distance, hy_curve_length_to_goal(s, x, y, theta, scratch));
}

/* Closed-set index: open addressing on int64 state keys (-1 = empty slot), grown at half load. */
#define HY_INDEX_START 4096
#define HY_HASH 0x9E3779B97F4A7C15ULL /* Fibonacci hashing: spreads consecutive keys */

typedef struct {
    int64_t *keys, *nodes;
    int64_t capacity, used;
} HyIndex;

static int hy_index_init(HyIndex *index, int64_t capacity) {
    index->keys = malloc((size_t)capacity * sizeof(int64_t));
    index->nodes = malloc((size_t)capacity * sizeof(int64_t));
    index->capacity = capacity;
    index->used = 0;
    if (!index->keys || !index->nodes) {
        free(index->keys), free(index->nodes);
        return 0;
    }
    for (int64_t slot = 0; slot < capacity; slot++) index->keys[slot] = -1;
    return 1;
}

/* The slot holding `key`, or the empty slot where it belongs. */
static inline uint64_t hy_index_slot(const HyIndex *index, int64_t key) {
    uint64_t mask = (uint64_t)index->capacity - 1;
    uint64_t slot = (((uint64_t)key * HY_HASH) >> 20) & mask;
    while (index->keys[slot] != -1 && index->keys[slot] != key) slot = (slot + 1) & mask;
    return slot;
}

/* Rehash into twice the slots; 0 when out of memory (the index is left as it was). */
static int hy_index_grow(HyIndex *index) {
    HyIndex grown;
    if (!hy_index_init(&grown, 2 * index->capacity)) return 0;
    for (int64_t slot = 0; slot < index->capacity; slot++) {
        if (index->keys[slot] != -1) {
            uint64_t target = hy_index_slot(&grown, index->keys[slot]);
            grown.keys[target] = index->keys[slot];
            grown.nodes[target] = index->nodes[slot];
        }
    }
    grown.used = index->used;
    free(index->keys), free(index->nodes);
    *index = grown;
    return 1;
}

/* (f, h, node) of a orders before that of b: by f, then h, then node (which is unique). */
static inline int hy_before(double f_a, double h_a, int64_t node_a, double f_b, double h_b, int64_t node_b) {
    if (f_a != f_b) return f_a < f_b;
    if (h_a != h_b) return h_a < h_b;
    return node_a < node_b;
}

/* Push onto the binary min-heap of (f, h, node); the order is total (nodes are unique), so the pops
 * come in the same order as from any other priority queue. Returns the new size. */
static int64_t hy_heap_push(HySearch *s, int64_t size, double f, double h, int64_t node) {
    double *heap_f = s->heap_f, *heap_h = s->heap_h;
    int64_t *heap_node = s->heap_node;
    int64_t index = size;
    while (index > 0) {
        int64_t parent = (index - 1) >> 1;
        if (!hy_before(f, h, node, heap_f[parent], heap_h[parent], heap_node[parent])) break;
        heap_f[index] = heap_f[parent];
        heap_h[index] = heap_h[parent];
        heap_node[index] = heap_node[parent];
        index = parent;
    }
    heap_f[index] = f;
    heap_h[index] = h;
    heap_node[index] = node;
    return size + 1;
}

/* Remove the smallest entry: its node; *size shrinks by one. */
static int64_t hy_heap_pop(HySearch *s, int64_t *size) {
    double *heap_f = s->heap_f, *heap_h = s->heap_h;
    int64_t *heap_node = s->heap_node;
    int64_t top = heap_node[0];
    int64_t n = --*size;
    double f = heap_f[n], h = heap_h[n];
    int64_t node = heap_node[n];
    int64_t index = 0;
    for (;;) {
        int64_t child = 2 * index + 1;
        if (child >= n) break;
        if (child + 1 < n && hy_before(heap_f[child + 1], heap_h[child + 1], heap_node[child + 1], heap_f[child],
                                       heap_h[child], heap_node[child]))
            child++;
        if (!hy_before(heap_f[child], heap_h[child], heap_node[child], f, h, node)) break;
        heap_f[index] = heap_f[child];
        heap_h[index] = heap_h[child];
        heap_node[index] = heap_node[child];
        index = child;
    }
    heap_f[index] = f;
    heap_h[index] = h;
    heap_node[index] = node;
    return top;
}

/* Cheapest collision-free curve from (x, y, theta), driven after `direction`, to the goal: its
 * segments into s->analytic_*, its cost into *cost; returns the segment count (5) or 0 (none free).
 * Candidates are tried cheapest first; candidates of exactly equal cost (mirror images: a goal
 * right behind, facing back) in the order they were enumerated. */
static int64_t hy_analytic_expansion(HySearch *s, double x, double y, double theta, int64_t direction,
                                     HyScratch *scratch, double *cost_out) {
    const int64_t *letters = scratch->letters;
    const double *lengths = scratch->lengths;
    double *costs = scratch->costs;
    int64_t *order = scratch->order;
    double nx, ny, nphi;
    hy_normalize(x, y, theta, s->goal[0], s->goal[1], s->goal[2], s->radius, &nx, &ny, &nphi);
    int64_t count = s->forward_only ? hy_dubins_enumerate(nx, ny, nphi, scratch->letters, scratch->lengths, 5)
                                    : hy_rs_enumerate(nx, ny, nphi, scratch->letters, scratch->lengths, 5);
    for (int64_t k = 0; k < count; k++) {
        double cost = 0.0;
        int64_t previous = direction;
        for (int j = 0; j < 5; j++) {
            double length = lengths[k * 5 + j] * s->radius;
            if (length == 0.0) continue;
            int64_t sign = length > 0.0 ? 1 : -1;
            double multiplier = sign < 0 ? s->reverse_cost : 1.0;
            if (letters[k * 5 + j] != 0) multiplier *= 1.0 + s->steering_cost;
            cost += fabs(length) * multiplier;
            if (previous != 0 && sign != previous) cost += s->switch_cost;
            previous = sign;
        }
        costs[k] = cost;
    }
    hy_argsort(costs, count, order);
    double curvatures[5], signed_lengths[5];
    HyGrid grid = {s->occupied, s->rows, s->cols, s->resolution, s->origin_x, s->origin_y};
    for (int64_t rank = 0; rank < count; rank++) {
        int64_t k = order[rank];
        for (int j = 0; j < 5; j++) {
            curvatures[j] = (double)letters[k * 5 + j] / s->radius;
            signed_lengths[j] = lengths[k * 5 + j] * s->radius;
        }
        if (hy_segments_free(&grid, x, y, theta, curvatures, signed_lengths, 5, s->collision_step)) {
            for (int j = 0; j < 5; j++) {
                s->analytic_curvature[j] = curvatures[j];
                s->analytic_length[j] = signed_lengths[j];
            }
            *cost_out = costs[k];
            return 5;
        }
    }
    *cost_out = INFINITY;
    return 0;
}

static int64_t hy_finish(HySearch *s, HyIndex *index, int64_t status, int64_t node, int64_t expanded,
                         int64_t count, double cost) {
    free(index->keys), free(index->nodes);
    s->status = status;
    s->final_node = node;
    s->expanded = expanded;
    s->analytic_count = count;
    s->analytic_cost = cost;
    return status;
}

/* Run hybrid A* from s->start to s->goal; fills the results of `s` and returns the status. The path
 * is the parent chain of s->final_node followed by the analytic segments (if FOUND_ANALYTIC). */
int64_t hy_search(HySearch *s) {
    HyScratch scratch;
    memset(&scratch, 0, sizeof scratch);
    HyGrid grid = {s->occupied, s->rows, s->cols, s->resolution, s->origin_x, s->origin_y};
    const double *goal = s->goal;
    HyIndex index;
    if (!hy_index_init(&index, HY_INDEX_START)) {
        s->status = HY_NO_MEMORY;
        return HY_NO_MEMORY;
    }
    s->node_x[0] = s->start[0], s->node_y[0] = s->start[1], s->node_theta[0] = s->start[2];
    s->node_g[0] = 0.0;
    s->node_parent[0] = -1;
    s->node_primitive[0] = -1;
    s->node_direction[0] = 0;
    int64_t nodes = 1;
    double h = hy_heuristic(s, s->start[0], s->start[1], s->start[2], &scratch);
    int64_t size = hy_heap_push(s, 0, h, h, 0);
    int64_t row, col;
    hy_cell(s, s->start[0], s->start[1], &row, &col);
    int64_t key = hy_state_key(row, col, s->start[2], s->cols, s->heading_bins);
    uint64_t slot = hy_index_slot(&index, key);
    index.keys[slot] = key;
    index.nodes[slot] = 0;
    index.used = 1;
    int64_t expanded = 0;
    while (size > 0) {
        int64_t node = hy_heap_pop(s, &size);
        if (s->closed[node]) continue;
        double x = s->node_x[node], y = s->node_y[node], theta = s->node_theta[node];
        hy_cell(s, x, y, &row, &col);
        key = hy_state_key(row, col, theta, s->cols, s->heading_bins);
        if (index.nodes[hy_index_slot(&index, key)] != node) continue; /* a cheaper pose took over */
        s->closed[node] = 1;
        s->explored[row * s->cols + col] = 1;
        expanded++;
        double distance = hypot(x - goal[0], y - goal[1]);
        if (distance <= s->goal_tolerance && fabs(hy_wrap_angle(theta - goal[2])) <= s->heading_tolerance)
            return hy_finish(s, &index, HY_FOUND_AT_GOAL, node, expanded, 0, 0.0);
        if (s->analytic_interval > 0 &&
            (expanded == 1 || expanded % s->analytic_interval == 0 || distance <= s->analytic_distance)) {
            double cost;
            int64_t count = hy_analytic_expansion(s, x, y, theta, s->node_direction[node], &scratch, &cost);
            if (count > 0)
                return hy_finish(s, &index, HY_FOUND_ANALYTIC, node, expanded, count, s->node_g[node] + cost);
        }
        if (expanded >= s->max_iterations) return hy_finish(s, &index, HY_ITERATION_CAP, node, expanded, 0, 0.0);
        double cos_t = cos(theta), sin_t = sin(theta);
        for (int64_t p = 0; p < s->primitives; p++) {
            const double *samples = s->prim_samples + p * s->max_samples * 3;
            int64_t sample_count = s->prim_sample_count[p];
            int free_path = 1;
            for (int64_t k = 0; k < sample_count; k++) {
                double sx = x + cos_t * samples[3 * k] - sin_t * samples[3 * k + 1];
                double sy = y + sin_t * samples[3 * k] + cos_t * samples[3 * k + 1];
                if (!hy_point_free(&grid, sx, sy)) {
                    free_path = 0;
                    break;
                }
            }
            if (!free_path) continue;
            const double *last = samples + 3 * (sample_count - 1);
            double new_x = x + cos_t * last[0] - sin_t * last[1];
            double new_y = y + sin_t * last[0] + cos_t * last[1];
            double new_theta = hy_wrap_angle(theta + last[2]);
            int64_t new_row, new_col;
            hy_cell(s, new_x, new_y, &new_row, &new_col);
            int64_t new_key = hy_state_key(new_row, new_col, new_theta, s->cols, s->heading_bins);
            double new_g = s->node_g[node] + s->prim_cost[p];
            if (s->node_direction[node] != 0 && s->prim_direction[p] != s->node_direction[node]) new_g += s->switch_cost;
            slot = hy_index_slot(&index, new_key);
            if (index.keys[slot] == new_key) {
                int64_t other = index.nodes[slot];
                if (s->closed[other] || s->node_g[other] <= new_g) continue;
            }
            h = hy_heuristic(s, new_x, new_y, new_theta, &scratch);
            if (h == INFINITY) continue;
            s->node_x[nodes] = new_x, s->node_y[nodes] = new_y, s->node_theta[nodes] = new_theta;
            s->node_g[nodes] = new_g;
            s->node_parent[nodes] = node;
            s->node_primitive[nodes] = p;
            s->node_direction[nodes] = s->prim_direction[p];
            if (index.keys[slot] != new_key) {
                index.keys[slot] = new_key;
                index.used++;
            }
            index.nodes[slot] = nodes;
            if (2 * index.used > index.capacity && !hy_index_grow(&index)) {
                return hy_finish(s, &index, HY_NO_MEMORY, -1, expanded, 0, 0.0);
            }
            size = hy_heap_push(s, size, new_g + h, h, nodes);
            nodes++;
        }
    }
    return hy_finish(s, &index, HY_EXHAUSTED, -1, expanded, 0, 0.0);
}

/* ---- the curves and the collision check for Python (planner/reeds_shepp.py, dubins.py, hybrid_geometry.py) ---- */

int64_t hy_reeds_shepp_enumerate(double x, double y, double phi, int64_t *letters, double *lengths, int64_t stride) {
    return hy_rs_enumerate(x, y, phi, letters, lengths, stride);
}

double hy_reeds_shepp_shortest(double x, double y, double phi, int64_t *letters, double *lengths, int64_t stride) {
    return hy_rs_shortest(x, y, phi, letters, lengths, stride);
}

int64_t hy_dubins_enumerate_normalized(double x, double y, double phi, int64_t *letters, double *lengths,
                                       int64_t stride) {
    return hy_dubins_enumerate(x, y, phi, letters, lengths, stride);
}

double hy_dubins_shortest_length(double x, double y, double phi, int64_t *letters, double *lengths,
                                 int64_t stride) {
    return hy_dubins_shortest(x, y, phi, letters, lengths, stride);
}

int64_t hy_segments_free_grid(const uint8_t *occupied, int64_t rows, int64_t cols, double resolution,
                              double origin_x, double origin_y, double x, double y, double theta,
                              const double *curvatures, const double *signed_lengths, int64_t count, double step) {
    HyGrid grid = {occupied, rows, cols, resolution, origin_x, origin_y};
    return hy_segments_free(&grid, x, y, theta, curvatures, signed_lengths, count, step);
}

/* The tables Python mirrors (see layout.h). */
int64_t navcosim_layout(const char **names, int64_t *values, int64_t capacity)
{
    int64_t n = 0;
    LAYOUT_SIZE(HySearch);
    LAYOUT_FIELD(HySearch, occupied);
    LAYOUT_FIELD(HySearch, rows);
    LAYOUT_FIELD(HySearch, cols);
    LAYOUT_FIELD(HySearch, resolution);
    LAYOUT_FIELD(HySearch, origin_x);
    LAYOUT_FIELD(HySearch, origin_y);
    LAYOUT_FIELD(HySearch, distance);
    LAYOUT_FIELD(HySearch, start);
    LAYOUT_FIELD(HySearch, goal);
    LAYOUT_FIELD(HySearch, prim_cost);
    LAYOUT_FIELD(HySearch, prim_direction);
    LAYOUT_FIELD(HySearch, prim_samples);
    LAYOUT_FIELD(HySearch, prim_sample_count);
    LAYOUT_FIELD(HySearch, primitives);
    LAYOUT_FIELD(HySearch, max_samples);
    LAYOUT_FIELD(HySearch, heading_bins);
    LAYOUT_FIELD(HySearch, radius);
    LAYOUT_FIELD(HySearch, forward_only);
    LAYOUT_FIELD(HySearch, reverse_cost);
    LAYOUT_FIELD(HySearch, steering_cost);
    LAYOUT_FIELD(HySearch, switch_cost);
    LAYOUT_FIELD(HySearch, analytic_interval);
    LAYOUT_FIELD(HySearch, analytic_distance);
    LAYOUT_FIELD(HySearch, goal_tolerance);
    LAYOUT_FIELD(HySearch, heading_tolerance);
    LAYOUT_FIELD(HySearch, collision_step);
    LAYOUT_FIELD(HySearch, max_iterations);
    LAYOUT_FIELD(HySearch, node_x);
    LAYOUT_FIELD(HySearch, node_y);
    LAYOUT_FIELD(HySearch, node_theta);
    LAYOUT_FIELD(HySearch, node_g);
    LAYOUT_FIELD(HySearch, node_parent);
    LAYOUT_FIELD(HySearch, node_primitive);
    LAYOUT_FIELD(HySearch, node_direction);
    LAYOUT_FIELD(HySearch, closed);
    LAYOUT_FIELD(HySearch, heap_f);
    LAYOUT_FIELD(HySearch, heap_h);
    LAYOUT_FIELD(HySearch, heap_node);
    LAYOUT_FIELD(HySearch, explored);
    LAYOUT_FIELD(HySearch, status);
    LAYOUT_FIELD(HySearch, final_node);
    LAYOUT_FIELD(HySearch, expanded);
    LAYOUT_FIELD(HySearch, analytic_count);
    LAYOUT_FIELD(HySearch, analytic_cost);
    LAYOUT_FIELD(HySearch, analytic_curvature);
    LAYOUT_FIELD(HySearch, analytic_length);
    LAYOUT_CONSTANT(HY_FOUND_AT_GOAL);
    LAYOUT_CONSTANT(HY_FOUND_ANALYTIC);
    LAYOUT_CONSTANT(HY_EXHAUSTED);
    LAYOUT_CONSTANT(HY_ITERATION_CAP);
    LAYOUT_CONSTANT(HY_NO_MEMORY);
    return n;
}
