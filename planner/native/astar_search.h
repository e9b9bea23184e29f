/* The grid A* search of planner.astar shared by astar.c (the default settings), astar_general.c
 * (every other setting) and bidirectional.c: the constants, the heuristics, the heap keys, the
 * 4-ary heap, the search loop and a path's cells and lengths, all static inline, so each library
 * specialises the loop for the settings it handles.
 *
 * Every floating-point operation is the one planner/astar.py's documented search does, in its order
 * (the libraries are built with -ffp-contract=off, no fast-math), so plans are bit-identical to it;
 * the 4-ary heap pops equal keys in the same order, so the same nodes are expanded.
 */
#ifndef NAVCOSIM_ASTAR_SEARCH_H
#define NAVCOSIM_ASTAR_SEARCH_H

#include <math.h>
#include <stddef.h>
#include <stdint.h>

#define SQRT2 1.4142135623730951 /* math.sqrt(2.0) */

enum { NO_PATH = 0, FOUND = 1, HEAP_FULL = -1, ROUTE_FULL = -2, BAD_START = -3, BAD_GOAL = -4, NO_GENERAL = -5 };
enum { BLOCKED = 1 };
/* Heap keys pack f (2^-24 cell steps) over h (quarter cells, saturating at 2^16 - 1). */
#define H_BITS 16
#define F_SCALE 16777216.0
#define H_SCALE 4.0
#define H_MAX 65535
/* Indices of the parameters array (planner.astar.PARAMETERS). */
enum { P_WIDTH, P_HEURISTIC, P_TIE, P_DECREASE, P_H_SCALE, P_COST_WEIGHT, P_ROWS, P_COLS, P_RESOLUTION,
       P_ORIGIN_X, P_ORIGIN_Y };

/* (row, col) steps of the 8 moves, in the bit order of the move masks (planner.searchspace.MOVES). */
static const int64_t ROW_STEPS[8] = {-1, 1, 0, 0, -1, -1, 1, 1};
static const int64_t COL_STEPS[8] = {0, 0, -1, 1, -1, 1, -1, 1};
#define ALL_MOVES 0xFFu

/* The work arrays of one search direction (planner.searchspace.Workspace). */
typedef struct {
    double *g;        /* [size] g in cells */
    int32_t *parent;  /* nodes[0] */
    int32_t *stamp;   /* nodes[1]: generation = OPEN, generation + 1 = CLOSED */
    int32_t *expanded;/* nodes[2]: expanded nodes in closing order */
    int64_t *heap_key;
    int64_t *heap_node;
    int64_t capacity; /* entries the heap holds: its arrays' length - HEAP_SLACK */
} Work;

static inline int64_t absolute(int64_t value) { return value < 0 ? -value : value; }
static inline int64_t larger(int64_t a, int64_t b) { return a > b ? a : b; }

/* A path's padded node as its cell (row, col) into cell[0..1] and the cell's centre [m] into
 * point[0..1] (the map's row 0 at the top, y up). */
static inline void node_cell_and_point(int64_t node, const double *parameters, int64_t *cell, double *point) {
    int64_t width = (int64_t)parameters[P_WIDTH];
    double resolution = parameters[P_RESOLUTION];
    int64_t row = node / width - 1;
    int64_t col = node % width - 1;
    cell[0] = row;
    cell[1] = col;
    point[0] = parameters[P_ORIGIN_X] + ((double)col + 0.5) * resolution;
    point[1] = parameters[P_ORIGIN_Y] + ((parameters[P_ROWS] - 1.0 - (double)row) + 0.5) * resolution;
}

/* The length [m] of one move between neighbouring padded nodes: a side or a diagonal of a cell. */
static inline double move_length(int64_t node, int64_t other, int64_t width, double resolution) {
    int64_t difference = absolute(node - other);
    return difference == 1 || difference == width ? resolution : SQRT2 * resolution;
}

/* h in cells for a (row, col) offset to the goal; kind: planner.astar.HEURISTICS. */
static inline double heuristic_cells(int64_t row_offset, int64_t col_offset, int64_t kind) {
    int64_t dr = absolute(row_offset);
    int64_t dc = absolute(col_offset);
    if (kind == 3) { /* the longer offset plus (sqrt 2 - 1) times the shorter, selected without a branch */
        int64_t longer = dr > dc ? dr : dc, shorter = dr > dc ? dc : dr;
        return (double)longer + (SQRT2 - 1.0) * (double)shorter;
    }
    if (kind == 0) return (double)(dr + dc);
    if (kind == 1) return sqrt((double)(dr * dr + dc * dc));
    if (kind == 2) return (double)larger(dr, dc);
    if (kind == 4) return sqrt((double)(dr * dr + dc * dc)) + 2.0 * (double)larger(dr, dc);
    return 0.0;
}

/* One int64 key: f on a 2^-24 cell grid in the high bits, h (quarter cells) below for low_h ties. */
static inline int64_t heap_key_of(double f, double h, int64_t tie_breaker) {
    int64_t key = (int64_t)((uint64_t)(int64_t)(f * F_SCALE + 0.5) << H_BITS);
    if (tie_breaker == 2) {
        int64_t low = (int64_t)(h * H_SCALE + 0.5);
        key += low < H_MAX ? low : H_MAX;
    }
    return key;
}

/* OPEN is a 4-ary min-heap of keys and nodes (two arrays) that keeps NO_KEY in the HEAP_SLACK slots
 * after its last entry: every entry with a child then has four, the missing ones never the smallest,
 * so a pop compares four keys per level without a branch (a branch on how many children there are
 * is mispredicted at the bottom of the heap). A heap buffer of c entries holds c - HEAP_SLACK. */
#define NO_KEY INT64_MAX
#define HEAP_SLACK 3

/* An empty heap: NO_KEY in its first HEAP_SLACK slots. */
static inline void heap_clear(int64_t *heap_key) {
    for (int slot = 0; slot < HEAP_SLACK; slot++) heap_key[slot] = NO_KEY;
}

/* Push (the caller checks the capacity); the new size. */
static inline int64_t heap_push(int64_t *restrict heap_key, int64_t *restrict heap_node, int64_t size, int64_t key,
                                int64_t node) {
    heap_key[size + HEAP_SLACK] = NO_KEY;
    int64_t index = size;
    while (index > 0) {
        int64_t parent = (index - 1) >> 2;
        if (heap_key[parent] <= key) break;
        heap_key[index] = heap_key[parent];
        heap_node[index] = heap_node[parent];
        index = parent;
    }
    heap_key[index] = key;
    heap_node[index] = node;
    return size + 1;
}

/* Remove the top; *size shrinks by one. The hole sinks along the smallest children (the first of
 * equal ones, by a branch-free tournament), then the last entry rises into it. */
static inline __attribute__((always_inline)) int64_t heap_pop(int64_t *restrict heap_key, int64_t *restrict heap_node,
                                                              int64_t *size_io) {
    int64_t top = heap_node[0];
    int64_t size = *size_io - 1;
    *size_io = size;
    int64_t key = heap_key[size];
    int64_t node = heap_node[size];
    heap_key[size] = NO_KEY;
    if (size == 0) return top; /* the top was the last entry */
    int64_t index = 0;
    for (int64_t first = 1; first < size; first = 4 * index + 1) {
        int64_t key0 = heap_key[first], key1 = heap_key[first + 1];
        int64_t key2 = heap_key[first + 2], key3 = heap_key[first + 3];
        int64_t child_a = key1 < key0 ? first + 1 : first;
        int64_t key_a = key1 < key0 ? key1 : key0;
        int64_t child_b = key3 < key2 ? first + 3 : first + 2;
        int64_t key_b = key3 < key2 ? key3 : key2;
        int64_t child = key_b < key_a ? child_b : child_a;
        heap_key[index] = key_b < key_a ? key_b : key_a;
        heap_node[index] = heap_node[child];
        index = child;
    }
    while (index > 0) {
        int64_t parent = (index - 1) >> 2;
        int64_t parent_key = heap_key[parent];
        if (parent_key < key) break;
        heap_key[index] = parent_key;
        heap_node[index] = heap_node[parent];
        index = parent;
    }
    heap_key[index] = key;
    heap_node[index] = node;
    return top;
}

/* A reached neighbour (its g and parent set) into OPEN: as the candidate that skips the heap when its
 * key is <= every key in OPEN (NO_KEY when OPEN is empty) and no candidate is waiting, else into the
 * heap (the smaller of it and the candidate stays the candidate). Returns 0 when the heap is full. */
static inline __attribute__((always_inline)) int enter_open(int64_t neighbour, int64_t key, int64_t *next_node,
                                                            int64_t *next_key, int64_t *restrict heap_key,
                                                            int64_t *restrict heap_node, int64_t *size,
                                                            int64_t capacity) {
    if (*next_node < 0) {
        if (key <= heap_key[0]) {
            *next_node = neighbour;
            *next_key = key;
            return 1;
        }
    } else if (key < *next_key) {
        int64_t swap_key = key, swap_node = neighbour;
        key = *next_key;
        neighbour = *next_node;
        *next_key = swap_key;
        *next_node = swap_node;
    }
    if (*size == capacity) return 0;
    *size = heap_push(heap_key, heap_node, *size, key, neighbour);
    return 1;
}

/* The search loop, specialised by the compiler for each (heuristic, weighted) pair it is inlined with. */
static inline __attribute__((always_inline)) int64_t search_loop(
    const uint8_t *restrict moves, const double *restrict cost, int64_t width, int64_t heuristic,
    int64_t tie_breaker, int decrease_key, double h_scale, double cost_weight, int weighted, int64_t start,
    int64_t goal, int32_t generation, const Work *work, int64_t *searched_out) {
    double *restrict g = work->g;
    int32_t *restrict parent = work->parent;
    int32_t *restrict stamp = work->stamp;
    int32_t *restrict expanded = work->expanded;
    int64_t *restrict heap_key = work->heap_key;
    int64_t *restrict heap_node = work->heap_node;
    const int64_t capacity = work->capacity;
    int64_t offsets[8];
    double steps[8];
    for (int k = 0; k < 8; k++) {
        offsets[k] = ROW_STEPS[k] * width + COL_STEPS[k];
        steps[k] = ROW_STEPS[k] != 0 && COL_STEPS[k] != 0 ? SQRT2 : 1.0;
    }
    int64_t goal_row = goal >= 0 ? goal / width : 0;
    int64_t goal_col = goal >= 0 ? goal % width : 0;
    const int32_t closed = generation + 1;

    g[start] = 0.0;
    parent[start] = (int32_t)start;
    stamp[start] = generation;
    int64_t size = 0;
    heap_clear(heap_key);
    int64_t next_node = start; /* the candidate that skips the heap; -1 = none */
    int64_t next_key = 0;
    int64_t searched = 0;
/* Open `neighbour`, move k of `node`, at g_new (both passes below): its stamp, g and parent, and
 * its OPEN entry; the search ends with HEAP_FULL when OPEN cannot take it. */
#define OPEN_NEIGHBOUR(neighbour, k, g_new)                                                                 \
    do {                                                                                                    \
        stamp[neighbour] = generation;                                                                      \
        g[neighbour] = (g_new);                                                                             \
        parent[neighbour] = (int32_t)node;                                                                  \
        double h_ = heuristic_cells(row_offset + ROW_STEPS[k], col_offset + COL_STEPS[k], heuristic) * h_scale; \
        if (!enter_open(neighbour, heap_key_of((g_new) + h_, h_, tie_breaker), &next_node, &next_key, heap_key, \
                        heap_node, &size, capacity)) {                                                      \
            *searched_out = searched;                                                                       \
            return HEAP_FULL;                                                                               \
        }                                                                                                   \
    } while (0)
    for (;;) {
        int64_t node;
        if (next_node >= 0) {
            node = next_node;
            next_node = -1;
        } else if (size > 0) {
            node = heap_pop(heap_key, heap_node, &size);
            if (stamp[node] == closed) continue; /* a stale entry left behind by a decrease-key */
        } else {
            *searched_out = searched;
            return NO_PATH;
        }
        stamp[node] = closed;
        expanded[searched] = (int32_t)node;
        searched++;
        if (node == goal) {
            *searched_out = searched;
            return FOUND;
        }
        double g_node = g[node];
        /* 32-bit division (nodes and width are < 2^31): a 64-bit one costs several times more */
        int64_t row = (uint32_t)node / (uint32_t)width;
        int64_t row_offset = row - goal_row;
        int64_t col_offset = node - row * width - goal_col;
        unsigned allowed = moves[node];
        if (allowed == ALL_MOVES) {
            /* Open ground: which neighbours are CLOSED, in OPEN or new follows a pattern here that
             * the branch predictor learns, so a branch per neighbour is the cheaper way. */
            for (unsigned bits = allowed; bits; bits &= bits - 1) { /* lowest first: table order */
                int k = __builtin_ctz(bits);
                int64_t neighbour = node + offsets[k];
                int32_t seen = stamp[neighbour];
                if (seen == closed) continue;
                double step = steps[k];
                if (weighted) step *= 1.0 + cost_weight * cost[neighbour];
                double g_new = g_node + step;
                if (seen == generation) {
                    if (g_new >= g[neighbour]) continue;
                    if (!decrease_key) { /* plannerAStarGrid: the key in OPEN does not change */
                        g[neighbour] = g_new;
                        parent[neighbour] = (int32_t)node;
                        continue;
                    }
                }
                OPEN_NEIGHBOUR(neighbour, k, g_new);
            }
            continue;
        }
        /* Among walls (corridors, doorways) that pattern is irregular: first decide for every move,
         * without a branch, whether it improves its neighbour (not CLOSED, and new or with a lower g
         * than in OPEN), then walk the improving ones only. The same neighbours in the same order as
         * above, so the same search. */
        unsigned improving = 0;
        double g_news[8];
        for (unsigned bits = allowed; bits; bits &= bits - 1) {
            int k = __builtin_ctz(bits);
            int64_t neighbour = node + offsets[k];
            int32_t seen = stamp[neighbour];
            double step = steps[k];
            if (weighted) step *= 1.0 + cost_weight * cost[neighbour];
            double g_new = g_node + step;
            g_news[k] = g_new;
            /* g of a node not in OPEN is read but not used */
            unsigned better = (seen != closed) & ((seen != generation) | !(g_new >= g[neighbour]));
            improving |= better << k;
        }
        for (; improving; improving &= improving - 1) {
            int k = __builtin_ctz(improving);
            int64_t neighbour = node + offsets[k];
            double g_new = g_news[k];
            if (!decrease_key && stamp[neighbour] == generation) {
                g[neighbour] = g_new;
                parent[neighbour] = (int32_t)node;
                continue;
            }
            OPEN_NEIGHBOUR(neighbour, k, g_new);
        }
    }
#undef OPEN_NEIGHBOUR
}

/* A search with the settings of `parameters` (planner.astar.PARAMETERS); *searched the expanded count. */
typedef int64_t (*SearchFunction)(const uint8_t *moves, const double *cost, const double *parameters,
                                  int64_t start, int64_t goal, int32_t generation, const Work *work,
                                  int64_t *searched);

#endif
