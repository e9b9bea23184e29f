/* Multi-agent path finding on a 4-connected graph.
 *
 * First solution: LaCAM (Okumura, AAAI 2023), a depth-first search over configurations (one vertex
 * per agent) whose successors PIBT (Okumura et al., AIJ 2022) generates under constraints that a
 * lazily grown tree adds agent by agent, so every successor is eventually tried: complete. PIBT
 * swaps two agents that meet head-on at the mouth of a dead end, keeps agents resting in one-cell
 * dead ends and corridors out of the way of an agent whose goal lies further in, and breaks distance
 * ties along per-agent guides (all below). Once LaCAM stalls it shares the time (half each) with
 * prioritized planning with eviction (mapf_lns.h), which is sometimes the quicker where PIBT's greedy
 * steps need a deep search (agents that must pass each other in the one-cell aisles of a warehouse),
 * and with a local repair (decompose()): the agents still away at LaCAM's node nearest the goals,
 * stuck in knots far apart, are split into regions solved one by one as small instances.
 * Then, until the time limit, two improvers share the best solution (its sum of costs bounds both):
 * - LaCAM* (Okumura, IJCAI 2023): configurations met again link the search nodes, costs g are
 *   rewired along the links (Dijkstra-like), nodes with g + h >= the best sum of costs are pruned;
 *   when the search is exhausted the best solution is proven optimal;
 * - large neighbourhood search (mapf_lns.h), which is what brings the sum of costs near the bound
 *   on large instances.
 * Slices of LACAM_SLICE and LNS_SLICE seconds alternate.
 *
 * The graph is given as free vertices 0..V-1 with up to 4 neighbours each (-1 = none). A search
 * node's g is a sum of losses: a transition costs one per agent not staying on its goal, so
 * h = sum of goal distances is admissible, and a sum of losses never exceeds the sum of costs (each
 * agent's time until it reaches its goal for the last time) of the same plan.
 *
 * Memory: the distance tables (4 bytes per agent and vertex), the guides (1 byte per agent and
 * vertex) and everything the search keeps (per node its configuration, the
 * agents' PIBT priorities, order and yielding: 16 bytes per agent; constraints,
 * successor lists, the hash table, the open stack) are charged to a byte budget. When it is spent,
 * no node is added: before a solution prioritized planning goes on alone (its paths are not
 * charged; without its solution the solver reports the budget), after one LaCAM* only revisits known
 * nodes and can no longer prove optimality. The local repair's plan is charged while it is built;
 * its pieces and the restarts are solves of their own, each given what is left of the budget.
 */
#define _POSIX_C_SOURCE 199309L
#include <limits.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "mapf_lns.h"

#define LACAM_SLICE 0.002
#define LNS_SLICE 0.008
#define FIRST_SLICE 0.05  /* s: LaCAM's turn while it looks for a first solution */
#define STALL 200         /* nodes without a new least h: LaCAM no longer gets on alone */
#define PROBE_TIME 2.5    /* s: a restart's time */
#define MAX_PROBES 8

typedef struct { int *a; long long n, cap; } ivec;

typedef struct { int parent, agent, vertex, depth; } Constraint;

typedef struct {
    int parent;           /* search node it is reached from at cost g */
    long long g, h;
    ivec queue;           /* constraints still to try (indices into the pool) */
    long long head;       /* next one of queue */
    ivec next;            /* known successors (LaCAM*) */
} Node;

typedef struct {
    int V, N;
    const int *adj;       /* V x 4 */
    const int *goal, *start;
    int *dist;            /* N x V, -1 = unreachable */
    Node *nodes; int n_nodes, cap_nodes;
    int *cfg; float *pri; int *order;   /* rows of N per node (cfg: one spare row) */
    Constraint *pool; long long n_pool, cap_pool;
    int *table; long long table_size;   /* hash: node id or -1 */
    ivec open, work;
    int *occ_now, *occ_next, *nxt, *stamp; int gen;
    /* dead-end trees (see pockets()): per vertex the top of the tree hanging off the graph's core
     * that holds it (-1: in the core); per agent the agents whose goals lie deeper in its tree
     * (dep_list[dep_first[i] .. dep_first[i + 1] - 1]) and whether one of them is not home yet */
    int *top, *dep_first, *dep_list; char *deferred;
    /* one-cell corridors of the core (see corridors()): per vertex its corridor (-1: none) and place
     * 1..length in it; per corridor its length, the cells in order from cfirst, the vertices just
     * past both ends, and the agents whose goals lie in it, in order (gfirst) */
    int *chain, *cpos, *clen, *cfirst, *ccells, *cend, *gfirst, *gagent, n_chains;
    int *dfr, *cur_dfr;
    unsigned char *gdir;  /* guides: N x V, the neighbour index (adj) of the next vertex, 255 none */  /* per node and agent: 2 * (agent it yields to) + side to leave by, or -1 */
    uint64_t rng;
    double used, budget;  /* bytes */
    int truncated;        /* a node or constraint was refused for the budget */
    long long lower;      /* sum of the agents' goal distances */
    /* the best solution lives in lns (its paths, its sum of costs) */
    Lns lns; int solved; long long best;
    Lns pp;               /* prioritized planning's own tables (its solution is swapped into lns) */
    int goal_node; long long goal_g_taken;
    long long min_h; int improved_at, best_node;
    int nested;           /* 0 the solve asked for; 1 a restart (first solution only, one repair);
                           * 2 a piece of a repair (first solution only, no repair) */
    int probes, pp_turns; /* restarts made, prioritized planning's turns before a first solution */
    int repair_failed;    /* a local repair was tried and failed: restarts from then on */
    double setup_time;    /* s: the distance tables, guides and the rest before the search */
    int partial;          /* a piece's path ends nearer the goals, not on them */
    int tried_node;       /* decompose(): the best node last tried */
    uint64_t *radix;   /* 2 N: the priority sort's buffers */  /* the least h of a node so far, and the node count then */
    double first_time; int status;
    int *path; int length;
} Mapf;

static double now(void) { return clock_now(); }

static uint64_t rnd(Mapf *m) {  /* xorshift64 */
    m->rng ^= m->rng << 13; m->rng ^= m->rng >> 7; m->rng ^= m->rng << 17;
    return m->rng;
}

/* Grow *items (capacity *cap items of `size` bytes) to hold `need` items, charged to the budget. */
static int reserve(Mapf *m, void **items, long long *cap, long long need, size_t size) {
    if (need <= *cap) return 0;
    long long grown = *cap ? *cap : 4;
    while (grown < need) grown *= 2;
    double more = (double)(grown - *cap) * (double)size;
    if (m->used + more > m->budget) { m->truncated = 1; return -1; }
    void *moved = realloc(*items, (size_t)grown * size);
    if (!moved) { m->truncated = 1; return -1; }
    *items = moved;
    *cap = grown;
    m->used += more;
    return 0;
}

static int push(Mapf *m, ivec *v, int x) {
    if (reserve(m, (void **)&v->a, &v->cap, v->n + 1, sizeof(int)) < 0) return -1;
    v->a[v->n++] = x;
    return 0;
}

/* Breadth-first distances d (V, -1 = unreachable) to vertex `goal`. */
static void bfs(const Mapf *m, int goal, int *d, int *queue) {
    for (int v = 0; v < m->V; v++) d[v] = -1;
    int head = 0, tail = 0;
    d[goal] = 0;
    queue[tail++] = goal;
    while (head < tail) {
        int v = queue[head++];
        for (int k = 0; k < 4; k++) {
            int u = m->adj[4 * v + k];
            if (u >= 0 && d[u] < 0) { d[u] = d[v] + 1; queue[tail++] = u; }
        }
    }
}

static int *config(Mapf *m, int node) { return m->cfg + (size_t)node * m->N; }

static uint64_t hash(const int *q, int n) {
    uint64_t h = 1469598103934665603ULL;
    for (int i = 0; i < n; i++) { h ^= (uint64_t)(unsigned)q[i]; h *= 1099511628211ULL; }
    return h ^ (h >> 29);
}

static int find(Mapf *m, const int *q, long long *slot) {
    long long mask = m->table_size - 1, s = (long long)(hash(q, m->N) & (uint64_t)mask);
    while (m->table[s] >= 0) {
        if (!memcmp(config(m, m->table[s]), q, (size_t)m->N * sizeof(int))) { *slot = s; return m->table[s]; }
        s = (s + 1) & mask;
    }
    *slot = s;
    return -1;
}

static int grow_table(Mapf *m) {
    long long size = m->table_size * 2;
    if (m->used + (double)(size - m->table_size) * sizeof(int) > m->budget) { m->truncated = 1; return -1; }
    int *table = malloc((size_t)size * sizeof(int));
    if (!table) { m->truncated = 1; return -1; }
    for (long long s = 0; s < size; s++) table[s] = -1;
    for (int id = 0; id < m->n_nodes; id++) {
        long long s = (long long)(hash(config(m, id), m->N) & (uint64_t)(size - 1));
        while (table[s] >= 0) s = (s + 1) & (size - 1);
        table[s] = id;
    }
    free(m->table);
    m->table = table;
    m->used += (double)(size - m->table_size) * sizeof(int);
    m->table_size = size;
    return 0;
}

static long long cost(Mapf *m, const int *from, const int *to) {
    long long c = 0;
    for (int i = 0; i < m->N; i++) c += !(from[i] == m->goal[i] && to[i] == m->goal[i]);
    return c;
}

static long long heuristic(Mapf *m, const int *q) {
    long long h = 0;
    for (int i = 0; i < m->N; i++) h += m->dist[(size_t)i * m->V + q[i]];
    return h;
}

static int push_constraint(Mapf *m, int parent, int agent, int vertex, int depth) {
    if (reserve(m, (void **)&m->pool, &m->cap_pool, m->n_pool + 1, sizeof(Constraint)) < 0) return -1;
    Constraint c = {parent, agent, vertex, depth};
    m->pool[m->n_pool] = c;
    return (int)m->n_pool++;
}

/* Agents by priority, highest first (qsort has no context argument: a file-level pointer). */
static const float *sort_pri;
static int cmp_pri(const void *a, const void *b) {
    float pa = sort_pri[*(const int *)a], pb = sort_pri[*(const int *)b];
    return (pa < pb) - (pa > pb);
}

/* Room for one more node (and the spare configuration row after it); -1 if over the budget. */
static int grow_nodes(Mapf *m) {
    if (m->n_nodes + 1 < m->cap_nodes) return 0;
    int cap = m->cap_nodes ? 2 * m->cap_nodes : 16;
    size_t N = (size_t)m->N;
    double per_node = (double)(sizeof(Node) + 4 * N * sizeof(int));
    /* nodes the budget still pays for, leaving the hash table room to double (4 slots a node) and a
     * tenth for constraints and successor lists (taking it all stopped the search at the next
     * doubling of the hash table) */
    double room = 0.9 * (m->budget - m->used) / (per_node + 4.0 * sizeof(int));
    if (cap - m->cap_nodes > room) cap = m->cap_nodes + (int)room;  /* the last growth: what is left */
    if (cap <= m->n_nodes + 1) { m->truncated = 1; return -1; }
    double more = (double)(cap - m->cap_nodes) * per_node;
    Node *nodes = realloc(m->nodes, (size_t)cap * sizeof(Node));
    if (nodes) m->nodes = nodes;
    int *cfg = realloc(m->cfg, (size_t)cap * N * sizeof(int));
    if (cfg) m->cfg = cfg;
    float *pri = realloc(m->pri, (size_t)cap * N * sizeof(float));
    if (pri) m->pri = pri;
    int *order = realloc(m->order, (size_t)cap * N * sizeof(int));
    if (order) m->order = order;
    int *dfr = realloc(m->dfr, (size_t)cap * N * sizeof(int));
    if (dfr) m->dfr = dfr;
    if (!nodes || !cfg || !pri || !order || !dfr) { m->truncated = 1; return -1; }
    m->cap_nodes = cap;
    m->used += more;
    return 0;
}

static void yielding(Mapf *m, const int *q, const int *prev, int *out);

/* A new search node for configuration q (already copied at slot n_nodes). */
static int new_node(Mapf *m, int parent, long long g) {
    int id = m->n_nodes, N = m->N;
    int *q = config(m, id);
    float *p = m->pri + (size_t)id * N;
    if (parent >= 0) {
        const float *pp = m->pri + (size_t)parent * N;
        for (int i = 0; i < N; i++) p[i] = q[i] != m->goal[i] ? pp[i] + 1.0f : pp[i] - (float)(int)pp[i];
    } else {
        for (int i = 0; i < N; i++) p[i] = (float)m->dist[(size_t)i * m->V + q[i]] / (float)(m->V + 1);
    }
    yielding(m, q, parent >= 0 ? m->dfr + (size_t)parent * N : NULL, m->dfr + (size_t)id * N);
    int *order = m->order + (size_t)id * N;
    if (m->radix) {
        /* radix sort by priority, highest first: a priority is a float >= 0, whose bits order as
         * unsigned integers do; ties keep the agents' index order */
        uint64_t *a = m->radix, *b = m->radix + N;
        for (int i = 0; i < N; i++) {
            uint32_t bits;
            memcpy(&bits, &p[i], sizeof(bits));
            a[i] = ((uint64_t)~bits << 32) | (uint32_t)i;
        }
        for (int shift = 32; shift < 64; shift += 8) {
            int count[257] = {0};
            for (int i = 0; i < N; i++) count[((a[i] >> shift) & 255) + 1]++;
            for (int k = 0; k < 256; k++) count[k + 1] += count[k];
            for (int i = 0; i < N; i++) b[count[(a[i] >> shift) & 255]++] = a[i];
            uint64_t *t = a; a = b; b = t;
        }
        for (int i = 0; i < N; i++) order[i] = (int)(a[i] & 0xffffffffu);
    } else {
        for (int i = 0; i < N; i++) order[i] = i;
        sort_pri = p;
        qsort(order, (size_t)N, sizeof(int), cmp_pri);
    }
    Node *node = &m->nodes[id];
    memset(node, 0, sizeof(*node));
    node->parent = parent;
    node->g = g;
    node->h = heuristic(m, q);
    int root = push_constraint(m, -1, -1, -1, 0);
    if (root < 0 || push(m, &node->queue, root) < 0) { free(node->queue.a); return -1; }
    m->n_nodes++;
    return id;
}

/* -- dead-end trees ------------------------------------------------------------------------------
 * Pruning the vertices of degree one, again and again, leaves the graph's core (the vertices on a
 * cycle or between two) and trees hanging off it: dead ends. A dead end one cell wide fills from
 * the bottom: an agent resting on its goal there walls off every goal deeper in, and an agent that
 * must get deeper cannot pass it. PIBT pushes it deeper (ahead of the agent with priority), so the
 * agent whose goal lies beyond it never gets there. Hence: while an agent whose goal lies deeper in
 * the same tree (a descendant of this agent's goal) is not home, this agent is deferred: it keeps
 * out of the tree (its cells rank after every other cell, among themselves by distance) and swaps
 * out of the way (below) of an agent that comes in. Trees that are a whole component have no core to
 * wait in and are left alone. */

/* top and the dependents of every agent; -1 out of memory. */
static int pockets(Mapf *m) {
    int V = m->V, N = m->N, *degree = malloc((size_t)V * sizeof(int)), *parent = malloc((size_t)V * sizeof(int));
    int *queue = malloc((size_t)V * sizeof(int)), *owner = malloc((size_t)V * sizeof(int));
    m->top = malloc((size_t)V * sizeof(int));
    m->dep_first = calloc((size_t)N + 1, sizeof(int));
    m->deferred = calloc((size_t)N, 1);
    int ok = degree && parent && queue && owner && m->top && m->dep_first && m->deferred;
    if (ok) {
        int head = 0, tail = 0;
        for (int v = 0; v < V; v++) {
            degree[v] = 0;
            for (int k = 0; k < 4; k++) degree[v] += m->adj[4 * v + k] >= 0;
            parent[v] = -2;  /* -2: in the core */
            owner[v] = -1;
            if (degree[v] == 1) queue[tail++] = v;
        }
        while (head < tail) {  /* prune: parent = the one neighbour left when it went */
            int v = queue[head++];
            parent[v] = -1;
            for (int k = 0; k < 4; k++) {
                int u = m->adj[4 * v + k];
                if (u < 0 || parent[u] != -2) continue;
                parent[v] = u;
                if (--degree[u] == 1) queue[tail++] = u;
            }
        }
        /* tops in reverse pruning order (a parent is pruned after its children) */
        for (int v = 0; v < V; v++) m->top[v] = -1;
        for (int k = tail - 1; k >= 0; k--) {
            int v = queue[k], p = parent[v];
            m->top[v] = p >= 0 && parent[p] == -2 ? v : p >= 0 ? m->top[p] : -2;  /* -2: a whole tree */
        }
        for (int v = 0; v < V; v++) if (m->top[v] == -2) m->top[v] = -1;
        for (int i = 0; i < N; i++) owner[m->goal[i]] = i;
        for (int pass = 0; pass < 2; pass++) {  /* count, then fill */
            for (int j = 0; j < N; j++) {
                if (m->top[m->goal[j]] < 0) continue;
                for (int u = parent[m->goal[j]]; u >= 0 && parent[u] != -2; u = parent[u]) {
                    int k = owner[u];
                    if (k < 0) continue;
                    if (pass == 0) m->dep_first[k + 1]++;
                    else m->dep_list[m->dep_first[k] + degree[k]++] = j;  /* degree: reused as fill count */
                }
            }
            if (pass == 0) {
                for (int i = 0; i < N; i++) m->dep_first[i + 1] += m->dep_first[i];
                m->dep_list = malloc((size_t)(m->dep_first[N] + 1) * sizeof(int));
                if (!m->dep_list) { ok = 0; break; }
                for (int i = 0; i < N && i < V; i++) degree[i] = 0;
                if (N > V) { ok = 0; break; }
            }
        }
    }
    free(degree); free(parent); free(queue); free(owner);
    return ok ? 0 : -1;
}

/* Which agents are deferred in configuration q. */
static void defer(Mapf *m, const int *q) {
    for (int k = 0; k < m->N; k++) {
        char d = 0;
        for (int e = m->dep_first[k]; e < m->dep_first[k + 1] && !d; e++) d = q[m->dep_list[e]] != m->goal[m->dep_list[e]];
        m->deferred[k] = d;
    }
}

/* -- one-cell corridors ----------------------------------------------------------------------------
 * The same holds in a corridor of the core open at both ends (the aisles between a warehouse's
 * shelves): an agent whose goal lies in it beyond another one's goal, seen from the side it comes
 * in by, cannot pass the other one; PIBT pushes that one ahead of it, past its goal, from where it
 * can come back only round the block (for ever pushing the first one back out of its goal). So when
 * an agent not home (the leader) is in such a corridor or just before it heading in, and goals of
 * others lie between it and its goal, those others yield: they leave the corridor by the leader's
 * side (the corridor's cells rank after every other cell, falling towards that side, and the
 * crossings at its ends just before them, so that they wait beyond a crossing, not on it), swap out
 * of the leader's way, and stay out until the leader is home. A yielding agent makes no one else
 * yield, so no two agents wait for each other. Unlike the dead ends this depends on where the leader
 * came from, so it is kept per search node. */

/* Find the corridors (chains of cells of degree two whose neighbours are in the core) and the goals
 * in them; -1 out of memory. */
static int corridors(Mapf *m) {
    int V = m->V, N = m->N, *seq = malloc((size_t)V * sizeof(int)), *owner = malloc((size_t)V * sizeof(int));
    m->chain = malloc((size_t)V * sizeof(int));
    m->cpos = malloc((size_t)V * sizeof(int));
    m->ccells = malloc((size_t)V * sizeof(int));
    m->clen = malloc((size_t)V * sizeof(int));
    m->cfirst = malloc((size_t)V * sizeof(int));
    m->cend = malloc((size_t)2 * V * sizeof(int));
    m->gfirst = calloc((size_t)V + 1, sizeof(int));
    m->gagent = malloc((size_t)N * sizeof(int));
    int ok = seq && owner && m->chain && m->cpos && m->ccells && m->clen && m->cfirst && m->cend && m->gfirst && m->gagent;
    if (ok) {
        for (int v = 0; v < V; v++) owner[v] = -1;
        for (int i = 0; i < N; i++) owner[m->goal[i]] = i;
        for (int v = 0; v < V; v++) {  /* -2: a corridor cell not yet placed */
            int degree = 0, inner = m->top[v] < 0;
            for (int k = 0; k < 4; k++) {
                int u = m->adj[4 * v + k];
                if (u >= 0) { degree++; inner &= m->top[u] < 0; }
            }
            m->chain[v] = degree == 2 && inner ? -2 : -1;
        }
        int used = 0;
        for (int v = 0; v < V; v++) {
            if (m->chain[v] != -2) continue;
            int ends[2], n = 0, cycle = 0, half[2] = {0, 0};
            for (int side = 0; side < 2 && !cycle; side++) {  /* walk both ways from v */
                int prev = v, cur = -1;
                for (int k = 0, seen = 0; k < 4; k++) if (m->adj[4 * v + k] >= 0 && seen++ == side) cur = m->adj[4 * v + k];
                while (cur != v && m->chain[cur] == -2) {
                    seq[n++] = cur;
                    half[side]++;
                    int next = -1;
                    for (int k = 0; k < 4; k++) { int u = m->adj[4 * cur + k]; if (u >= 0 && u != prev) next = u; }
                    prev = cur;
                    cur = next;
                }
                if (cur == v) cycle = 1;
                ends[side] = cur;
            }
            if (cycle) {  /* a ring of corridor cells alone: no ends to leave by */
                m->chain[v] = -1;
                for (int k = 0; k < n; k++) m->chain[seq[k]] = -1;
                continue;
            }
            int c = m->n_chains++, length = n + 1;
            m->cfirst[c] = used;
            m->clen[c] = length;
            m->cend[2 * c] = ends[0];       /* before place 1 */
            m->cend[2 * c + 1] = ends[1];   /* after place length */
            for (int k = half[0] - 1; k >= 0; k--) m->ccells[used++] = seq[k];
            m->ccells[used++] = v;
            for (int k = half[0]; k < n; k++) m->ccells[used++] = seq[k];
            for (int k = 0; k < length; k++) {
                int u = m->ccells[m->cfirst[c] + k];
                m->chain[u] = c;
                m->cpos[u] = k + 1;
            }
        }
        for (int c = 0, g = 0; c < m->n_chains; c++) {
            m->gfirst[c] = g;
            for (int k = 0; k < m->clen[c]; k++) {
                int a = owner[m->ccells[m->cfirst[c] + k]];
                if (a >= 0) m->gagent[g++] = a;
            }
            m->gfirst[c + 1] = g;
        }
    }
    free(seq); free(owner);
    return ok ? 0 : -1;
}

/* The yielding of configuration q (row out) from its parent's (prev, NULL at the root). */
static void yielding(Mapf *m, const int *q, const int *prev, int *out) {
    int N = m->N;
    for (int k = 0; k < N; k++) {
        out[k] = prev ? prev[k] : -1;
        if (out[k] >= 0 && q[out[k] >> 1] == m->goal[out[k] >> 1]) out[k] = -1;  /* the leader is home */
    }
    for (int a = 0; a < N; a++) {
        int g = m->goal[a], c = m->chain[g], v = q[a];
        if (c < 0 || v == g || out[a] >= 0) continue;
        const int *d = m->dist + (size_t)a * m->V;
        int at;  /* the leader's place: in the corridor, or just before an end heading in */
        if (m->chain[v] == c) at = m->cpos[v];
        else if (v == m->cend[2 * c] && d[m->ccells[m->cfirst[c]]] < d[v]) at = 0;
        else if (v == m->cend[2 * c + 1] && d[m->ccells[m->cfirst[c] + m->clen[c] - 1]] < d[v]) at = m->clen[c] + 1;
        else continue;
        int to = m->cpos[g], lo = at < to ? at : to, hi = at < to ? to : at;
        for (int e = m->gfirst[c]; e < m->gfirst[c + 1]; e++) {
            int k = m->gagent[e], place = m->cpos[m->goal[k]];
            if (k != a && place > lo && place < hi && out[k] < 0) out[k] = 2 * a + (at > to);
        }
    }
}

/* How far vertex v is from where agent i wants to be: its goal distance, plus V in its goal's dead-end
 * tree while it is deferred; while it yields, V plus the way out (by the leader's side) in its goal's
 * corridor. */
static int want(const Mapf *m, int i, int v) {
    int d = m->dist[(size_t)i * m->V + v];
    if (m->cur_dfr && m->cur_dfr[i] >= 0) {
        int c = m->chain[m->goal[i]];
        if (m->chain[v] == c) return m->V + (m->cur_dfr[i] & 1 ? m->clen[c] + 1 - m->cpos[v] : m->cpos[v]);
        if (v == m->cend[2 * c] || v == m->cend[2 * c + 1]) return m->V;  /* wait beyond the crossing */
        return d;
    }
    return m->deferred[i] && m->top[v] >= 0 && m->top[v] == m->top[m->goal[i]] ? d + m->V : d;
}

/* -- guides ---------------------------------------------------------------------------------------
 * Among an agent's shortest ways PIBT takes any; in a grid of one-cell aisles (a warehouse) agents
 * heading opposite ways then meet head-on in the same aisle, where only a long detour or a deep
 * search parts them. So each agent gets a guide: one shortest path from its start, chosen greedily
 * (agents in random order) at every step to run against as few earlier guides as possible, on the
 * edge used the other way. PIBT breaks distance ties towards the guide's next vertex. */
static int guide_next(const Mapf *m, int i, int v) {
    if (!m->gdir) return -1;
    unsigned char k = m->gdir[(size_t)i * m->V + v];
    return k < 4 ? m->adj[4 * v + k] : -1;
}

/* The guides, if the budget pays for them (else none); -1 out of memory. */
static int guides(Mapf *m) {
    double size = (double)m->N * m->V, bytes = size + 4.0 * m->V * sizeof(int) + m->N * sizeof(int);
    if (m->used + bytes > m->budget) return 0;
    int *flow = calloc((size_t)4 * m->V, sizeof(int)), *order = malloc((size_t)m->N * sizeof(int));
    m->gdir = malloc((size_t)m->N * m->V);
    if (!flow || !order || !m->gdir) { free(flow); free(order); return -1; }
    m->used += size;
    memset(m->gdir, 255, (size_t)m->N * m->V);
    for (int i = 0; i < m->N; i++) order[i] = i;
    for (int k = m->N - 1; k > 0; k--) { int r = (int)(rnd(m) % (uint64_t)(k + 1)), t = order[k]; order[k] = order[r]; order[r] = t; }
    for (int r = 0; r < m->N; r++) {
        int i = order[r];
        const int *d = m->dist + (size_t)i * m->V;
        for (int v = m->start[i]; v != m->goal[i]; ) {
            int best = -1, best_k = -1, against = INT_MAX, ties = 0;
            for (int k = 0; k < 4; k++) {
                int u = m->adj[4 * v + k];
                if (u < 0 || d[u] != d[v] - 1) continue;
                int back = 0;
                for (int e = 0; e < 4; e++) if (m->adj[4 * u + e] == v) back = flow[4 * u + e];
                if (back < against) { against = back; best = u; best_k = k; ties = 1; }
                else if (back == against && rnd(m) % (uint64_t)++ties == 0) { best = u; best_k = k; }
            }
            flow[4 * v + best_k]++;
            m->gdir[(size_t)i * m->V + v] = (unsigned char)best_k;
            v = best;
        }
    }
    free(flow); free(order);
    return 0;
}

/* -- PIBT with swaps ------------------------------------------------------------------------------
 * Plain PIBT cannot pass two agents heading in opposite directions through a corridor: the one with
 * priority pushes the other back one step at a time, for ever. The swap (Okumura 2024, "Engineering
 * LaCAM*") detects this and lets the agents pass at the corridor's nearest branching: the agent with
 * priority walks backwards and pulls the other one after it, until it can step aside.
 * A corridor here is a chain of vertices with one way on; dead-end cells on which an agent rests at
 * its goal do not count as a way on (that agent need not move). */

/* The way on from v (coming from `back`): the one other usable neighbour, -1 if none, -2 if two or
 * more (a branching, where two agents can pass each other). */
static int way_on(const Mapf *m, int v, int back) {
    int on = -1, ways = 0;
    for (int k = 0; k < 4; k++) {
        int u = m->adj[4 * v + k];
        if (u < 0 || u == back) continue;
        int degree = 0;
        for (int e = 0; e < 4; e++) degree += m->adj[4 * u + e] >= 0;
        int a = m->occ_now[u];
        if (degree == 1 && a >= 0 && m->goal[a] == u) continue;
        on = u;
        ways++;
    }
    return ways >= 2 ? -2 : on;
}

/* Would `pusher` (at vp) pushing `puller` (at vq) ahead of it drive it into a dead end it wants to
 * come back out of? The push is followed along the corridor (one way on); a branching lets the puller
 * step aside, and PIBT resolves pushes through corridors open at both ends. */
static int swap_needed(const Mapf *m, int puller, int vp, int vq) {
    if (want(m, puller, vp) >= want(m, puller, vq)) return 0;
    if (m->cur_dfr && m->cur_dfr[puller] >= 0 && m->chain[vq] == m->chain[m->goal[puller]]) return 1;  /* it must come out this way */  /* the puller does not want to go where the pusher is */
    for (int steps = 0; steps < m->V; steps++) {
        int on = way_on(m, vq, vp);
        if (on == -2) return 0;
        if (on == -1) return 1;
        vp = vq;
        vq = on;
    }
    return 0;
}

/* Is there a branching behind vq (walking away from vp) where the two agents can pass? */
static int swap_possible(const Mapf *m, int vp, int vq) {
    int origin = vp;
    for (int steps = 0; vq != origin && steps < m->V; steps++) {
        int on = way_on(m, vq, vp);
        if (on == -2) return 1;
        if (on == -1) return 0;
        vp = vq;
        vq = on;
    }
    return 0;
}

/* The agent that agent i should swap with (-1 if none): the one on its best next vertex, if pushing
 * it on would drive it into a dead end that it wants to leave past i. */
static int swap_partner(const Mapf *m, const int *q, int i, int best) {
    int here = q[i], k = m->occ_now[best];
    if (k >= 0 && k != i && m->nxt[k] < 0 && swap_needed(m, k, here, best) && swap_possible(m, best, here))
        return k;
    return -1;
}

/* PIBT step of agent i (current config q; j the agent that pushed i, -1 if none). */
static int pibt(Mapf *m, const int *q, int i, int j) {
    int cand[5], key[5], n = 0, here = q[i];
    for (int k = 0; k < 4; k++) if (m->adj[4 * here + k] >= 0) cand[n++] = m->adj[4 * here + k];
    cand[n++] = here;
    /* shuffle, then stable insertion sort by (distance, off the guide, occupied now): random ties */
    for (int k = n - 1; k > 0; k--) {  /* multiply-shift: a division here cost a sixth of PIBT */
        int r = (int)(((rnd(m) >> 32) * (uint64_t)(k + 1)) >> 32), t = cand[k];
        cand[k] = cand[r]; cand[r] = t;
    }
    int guide = guide_next(m, i, here);
    for (int a = 0; a < n; a++) key[a] = 4 * want(m, i, cand[a]) + 2 * (cand[a] != guide) + (m->occ_now[cand[a]] >= 0);
    for (int a = 1; a < n; a++) {
        int v = cand[a], kv = key[a], b = a - 1;
        while (b >= 0 && key[b] > kv) { cand[b + 1] = cand[b]; key[b + 1] = key[b]; b--; }
        cand[b + 1] = v;
        key[b + 1] = kv;
    }
    int partner = swap_partner(m, q, i, cand[0]);
    if (partner >= 0)  /* walk backwards: the farthest vertex first */
        for (int a = 0, b = n - 1; a < b; a++, b--) { int t = cand[a]; cand[a] = cand[b]; cand[b] = t; }
    for (int a = 0; a < n; a++) {
        int u = cand[a];
        if (m->occ_next[u] >= 0) continue;
        if (j >= 0 && u == q[j]) continue;
        int k = m->occ_now[u];
        if (k >= 0 && k != i && m->nxt[k] == here) continue;  /* swap with a decided agent */
        m->nxt[i] = u;
        m->occ_next[u] = i;
        if (k >= 0 && k != i && m->nxt[k] < 0 && !pibt(m, q, k, i)) continue;
        /* the partner follows into the vertex i leaves */
        if (a == 0 && partner >= 0 && m->nxt[partner] < 0 && m->occ_next[here] < 0) {
            m->nxt[partner] = here;
            m->occ_next[here] = partner;
        }
        return 1;
    }
    m->nxt[i] = here;
    m->occ_next[here] = i;
    return 0;
}

/* The successor of node s under constraint c into out; 1 if it is a valid configuration. */
static int generate(Mapf *m, int s, int c, int *out) {
    int N = m->N, ok = 1;
    const int *q = config(m, s), *order = m->order + (size_t)s * N;
    for (int i = 0; i < N; i++) { m->occ_now[q[i]] = i; m->nxt[i] = -1; }
    defer(m, q);
    m->cur_dfr = m->dfr + (size_t)s * N;
    for (int k = c; k >= 0 && m->pool[k].agent >= 0; k = m->pool[k].parent) {
        int i = m->pool[k].agent, u = m->pool[k].vertex;
        if (m->occ_next[u] >= 0) { ok = 0; break; }
        int other = m->occ_now[u];
        if (other >= 0 && other != i && m->nxt[other] == q[i]) { ok = 0; break; }
        m->nxt[i] = u;
        m->occ_next[u] = i;
    }
    for (int r = 0; ok && r < N; r++) {
        int i = order[r];
        if (m->nxt[i] < 0) pibt(m, q, i, -1);
    }
    /* full check: a fallback "stay" may land on a vertex a constraint took */
    if (ok) {
        m->gen++;
        for (int i = 0; i < N && ok; i++) {
            int u = m->nxt[i];
            if (m->stamp[u] == m->gen) ok = 0;
            m->stamp[u] = m->gen;
            int k = m->occ_now[u];
            if (k >= 0 && k != i && m->nxt[k] == q[i]) ok = 0;
        }
    }
    for (int i = 0; i < N; i++) {
        m->occ_now[q[i]] = -1;
        if (m->nxt[i] >= 0) m->occ_next[m->nxt[i]] = -1;
        out[i] = m->nxt[i];
    }
    return ok;
}

static long long bound(const Mapf *m) { return m->solved ? m->best : LLONG_MAX; }

/* Lower g along known edges from node `from` (Dijkstra-like relaxation on a worklist); a node whose
 * g dropped below the bound goes back on the open stack, since its successors may now improve. */
static void rewire(Mapf *m, int from) {
    ivec *work = &m->work;
    work->n = 0;
    if (push(m, work, from) < 0) return;
    while (work->n > 0) {
        int u = work->a[--work->n];
        for (long long e = 0; e < m->nodes[u].next.n; e++) {
            int w = m->nodes[u].next.a[e];
            long long g = m->nodes[u].g + cost(m, config(m, u), config(m, w));
            if (g < m->nodes[w].g) {
                m->nodes[w].g = g;
                m->nodes[w].parent = u;
                if (push(m, work, w) < 0) return;
                if (g + m->nodes[w].h < bound(m) && m->nodes[w].head < m->nodes[w].queue.n) push(m, &m->open, w);
            }
        }
    }
}

static int is_goal(Mapf *m, const int *q) {
    for (int i = 0; i < m->N; i++) if (q[i] != m->goal[i]) return 0;
    return 1;
}

enum { LACAM_DEADLINE, LACAM_EXHAUSTED, LACAM_FOUND, LACAM_BUDGET };

/* Run the LaCAM(*) loop until `deadline`, an exhausted open stack, or (with stop_at_goal) the goal
 * configuration's first node; LACAM_BUDGET if the budget refused a node before any solution. */
static int lacam(Mapf *m, double deadline, int stop_at_goal) {
    int N = m->N, cand[5];
    long long slot;
    for (long long iterations = 0; m->open.n > 0; iterations++) {
        if ((iterations & 63) == 63 && now() > deadline) return LACAM_DEADLINE;
        int s = m->open.a[m->open.n - 1];
        Node *ns = &m->nodes[s];
        if (ns->g + ns->h >= bound(m) || ns->head >= ns->queue.n) { m->open.n--; continue; }
        int c = ns->queue.a[ns->head++];
        Constraint con = m->pool[c];
        if (con.depth < N) {
            int i = m->order[(size_t)s * N + con.depth], v = config(m, s)[i], n = 0;
            for (int k = 0; k < 4; k++) if (m->adj[4 * v + k] >= 0) cand[n++] = m->adj[4 * v + k];
            cand[n++] = v;
            for (int k = n - 1; k > 0; k--) { int r = (int)(rnd(m) % (uint64_t)(k + 1)), t = cand[k]; cand[k] = cand[r]; cand[r] = t; }
            for (int k = 0; k < n; k++) {
                int id = push_constraint(m, c, i, cand[k], con.depth + 1);
                if (id < 0 || push(m, &m->nodes[s].queue, id) < 0) break;  /* truncated */
            }
        }
        /* the candidate configuration goes into the spare row after the last node */
        int *q = config(m, m->n_nodes);
        if (!generate(m, s, c, q)) continue;
        int t = find(m, q, &slot);
        long long step = cost(m, config(m, s), q);
        if (t >= 0) {
            push(m, &m->nodes[s].next, t);
            if (m->nodes[s].g + step < m->nodes[t].g) {
                m->nodes[t].g = m->nodes[s].g + step;
                m->nodes[t].parent = s;
                rewire(m, t);
            }
            push(m, &m->open, t);  /* revisit it (LaCAM*) */
            continue;
        }
        if ((2 * (long long)(m->n_nodes + 1) > m->table_size && grow_table(m) < 0) || grow_nodes(m) < 0) {
            if (!m->solved && m->goal_node < 0) return LACAM_BUDGET;
            continue;  /* budget spent: only known nodes from here on */
        }
        q = config(m, m->n_nodes);  /* the rows may have moved (realloc kept the spare row) */
        find(m, q, &slot);          /* the table may have grown */
        int id = new_node(m, s, m->nodes[s].g + step);
        if (id < 0) { if (!m->solved && m->goal_node < 0) return LACAM_BUDGET; continue; }
        m->table[slot] = id;
        if (m->nodes[id].h < m->min_h) { m->min_h = m->nodes[id].h; m->improved_at = m->n_nodes; m->best_node = id; }
        push(m, &m->nodes[s].next, id);
        push(m, &m->open, id);
        if (m->goal_node < 0 && is_goal(m, q)) {
            m->goal_node = id;
            if (stop_at_goal) return LACAM_FOUND;
        }
    }
    return LACAM_EXHAUSTED;
}

/* If LaCAM*'s goal node got a cheaper path than last taken: its sum of costs, and it becomes the
 * best solution if lower. -1 out of memory. */
static int take_lacam_solution(Mapf *m) {
    if (m->goal_node < 0 || m->nodes[m->goal_node].g >= m->goal_g_taken) return 0;
    m->goal_g_taken = m->nodes[m->goal_node].g;
    int length = 0;
    for (int k = m->goal_node; k >= 0; k = m->nodes[k].parent) length++;
    int *rows = malloc((size_t)length * m->N * sizeof(int));
    if (!rows) return -1;
    int row = length - 1;
    for (int k = m->goal_node; k >= 0; k = m->nodes[k].parent, row--)
        memcpy(rows + (size_t)row * m->N, config(m, k), (size_t)m->N * sizeof(int));
    long long soc = 0;
    for (int i = 0; i < m->N; i++) {
        int last = 0;
        for (int t = 0; t < length; t++) if (rows[(size_t)t * m->N + i] != m->goal[i]) last = t + 1;
        soc += last;
    }
    int status = 0;
    if (!m->solved || soc < m->best) {
        status = lns_load(&m->lns, rows, length);
        if (status == 0) { m->solved = 1; m->best = m->lns.soc; }
    }
    free(rows);
    return status;
}

static Mapf *solve_core(int V, const int *adj, int N, const int *start, const int *goal, double time_limit,
                        uint64_t seed, double memory_bytes, int nested);
void mapf_free(void *handle);

static int uf_find(int *up, int x) {
    while (up[x] != x) { up[x] = up[up[x]]; x = up[x]; }
    return x;
}

/* -- local repair ----------------------------------------------------------------------------------
 * Where LaCAM stalls on a large instance most agents are home and the others are stuck in knots far
 * apart (in a warehouse: agents that must pass each other in one-cell aisles, between agents resting
 * on their goals). The search cannot untie twenty knots at once, but each knot alone is a small
 * instance. So from the configuration nearest the goals (the first node on LaCAM's way to its least
 * h that is within a quarter of it), in rounds: every agent not home gets a region (the cells
 * within `radius` steps of a shortest path from where it is to its goal); overlapping regions merge;
 * each region with the agents in it (those home too) is solved alone on its cells (LaCAM and
 * prioritized planning, first solution only, PIECE_TIME at most), every agent outside the regions
 * resting on its goal. A piece not solved still moves on to its LaCAM's configuration nearest the
 * goals if that is nearer than where it started. The regions are disjoint and hold every agent that
 * moves, so the pieces go side by side while the agents of the others wait: the plan grows by the
 * longest piece and the next round starts where it ends, nearer the goals (the sum of distances
 * drops every round, so the rounds end). A round that moves no piece doubles the radius (up to
 * MAX_RADIUS). The plan: LaCAM's path to the configuration, then the rounds. 1 solved (the plan is
 * in lns), 0 not (time, or no piece moved at the largest radius), -1 out of memory.
 * If the repair fails, restarts (the whole instance again with another seed: other guides and ties,
 * other knots, and one repair of its own) take turns with prioritized planning. */
#define MIN_RADIUS 3
#define MAX_RADIUS 6
#define PIECE_TIME 0.1  /* s: a piece not solved by then is likely not solvable in its region */

typedef struct {
    int *up, *owner, *depth, *queue, *local, *cells, *agents, *group, *sadj, *sstart, *sgoal, *at, *stamp, *first;
    Mapf **subs;
    int *here;  /* the configuration a round starts from */
} Repair;

/* One round from configuration q: appends the rows of the pieces solved to *rows (length *n_rows,
 * capacity *cap); 1 if a piece was solved, 0 if none, -1 out of memory. */
static int repair_round(Mapf *m, Repair *r, const int *q, int R, double deadline, int **rows, long long *n_rows,
                        long long *cap) {
    int V = m->V, N = m->N, result = 0, gen = 0;
    for (int v = 0; v < V; v++) { r->owner[v] = -1; r->local[v] = -1; r->stamp[v] = 0; }
    for (int i = 0; i < N; i++) { r->up[i] = i; r->at[i] = -1; r->subs[i] = NULL; }
    for (int i = 0; i < N; i++) {
        if (q[i] == m->goal[i]) continue;
        const int *d = m->dist + (size_t)i * V;
        int head = 0, tail = 0;
        gen++;
        for (int v = q[i];; ) {  /* sources: a shortest path; then breadth first to depth R */
            r->stamp[v] = gen; r->depth[v] = 0; r->queue[tail++] = v;
            if (v == m->goal[i]) break;
            int next = -1;
            for (int k = 0; k < 4 && next < 0; k++) { int u = m->adj[4 * v + k]; if (u >= 0 && d[u] == d[v] - 1) next = u; }
            v = next;
        }
        while (head < tail) {
            int v = r->queue[head++];
            if (r->owner[v] < 0) r->owner[v] = i;
            else { int a = uf_find(r->up, r->owner[v]), b = uf_find(r->up, i); if (a != b) r->up[a] = b; }
            if (r->depth[v] >= R) continue;
            for (int k = 0; k < 4; k++) {
                int u = m->adj[4 * v + k];
                if (u >= 0 && r->stamp[u] != gen) { r->stamp[u] = gen; r->depth[u] = r->depth[v] + 1; r->queue[tail++] = u; }
            }
        }
    }
    for (int i = 0; i < N; i++) r->group[i] = r->owner[q[i]] >= 0 ? uf_find(r->up, r->owner[q[i]]) : -1;
    int longest = 1, used_cells = 0;
    for (int root = 0; root < N; root++) {
        if (q[root] == m->goal[root] || uf_find(r->up, root) != root) continue;
        int nv = 0, na = 0, *mine = r->cells + used_cells;
        r->first[root] = used_cells;
        for (int v = 0; v < V; v++)
            if (r->owner[v] >= 0 && uf_find(r->up, r->owner[v]) == root) { r->local[v] = nv; mine[nv++] = v; }
        used_cells += nv;
        for (int c = 0; c < nv; c++)
            for (int k = 0; k < 4; k++) { int u = m->adj[4 * mine[c] + k]; r->sadj[4 * c + k] = u >= 0 ? r->local[u] : -1; }
        for (int i = 0; i < N; i++)
            if (r->group[i] == root) { r->agents[na] = i; r->sstart[na] = r->local[q[i]]; r->sgoal[na] = r->local[m->goal[i]]; na++; }
        for (int c = 0; c < nv; c++) r->local[mine[c]] = -1;
        double left = deadline - now();
        if (left <= 0) break;
        Mapf *sub = solve_core(nv, r->sadj, na, r->sstart, r->sgoal, left < PIECE_TIME ? left : PIECE_TIME, rnd(m),
                               m->budget - m->used, 2);
        if (!sub) { result = -1; break; }
        if (sub->length <= 0) { mapf_free(sub); continue; }  /* this knot waits for a later round */
        r->subs[root] = sub;
        result = 1;
        if (sub->length > longest) longest = sub->length;
        for (int k = 0; k < na; k++) r->at[r->agents[k]] = k;  /* the agent's index in its piece */
    }
    if (result == 1) {
        if (reserve(m, (void **)rows, cap, (*n_rows + longest - 1) * N, sizeof(int)) < 0) result = -1;
        for (int t = 1; result == 1 && t < longest; t++, (*n_rows)++)
            for (int i = 0; i < N; i++) {
                int v = q[i], g = r->group[i];
                Mapf *sub = g >= 0 ? r->subs[g] : NULL;
                if (sub) v = r->cells[r->first[g] + sub->path[(size_t)(t < sub->length ? t : sub->length - 1) * sub->N + r->at[i]]];
                (*rows)[(size_t)*n_rows * N + i] = v;
            }
    }
    for (int i = 0; i < N; i++) if (r->subs[i]) mapf_free(r->subs[i]);
    return result;
}

static int decompose(Mapf *m, double deadline) {
    int V = m->V, N = m->N, result = 0, R = MIN_RADIUS;
    Repair r = {
        malloc((size_t)N * sizeof(int)), malloc((size_t)V * sizeof(int)), malloc((size_t)V * sizeof(int)),
        malloc((size_t)V * sizeof(int)), malloc((size_t)V * sizeof(int)), malloc((size_t)V * sizeof(int)),
        malloc((size_t)N * sizeof(int)), malloc((size_t)N * sizeof(int)), malloc((size_t)4 * V * sizeof(int)),
        malloc((size_t)N * sizeof(int)), malloc((size_t)N * sizeof(int)), malloc((size_t)N * sizeof(int)),
        malloc((size_t)V * sizeof(int)), malloc((size_t)N * sizeof(int)), calloc((size_t)N, sizeof(Mapf *)),
        malloc((size_t)N * sizeof(int)),
    };
    int *rows = NULL;
    long long n_rows = 0, cap = 0;
    if (!r.up || !r.owner || !r.depth || !r.queue || !r.local || !r.cells || !r.agents || !r.group || !r.sadj
        || !r.sstart || !r.sgoal || !r.at || !r.stamp || !r.first || !r.subs || !r.here) { result = -1; goto done; }
    /* LaCAM's path to the best node wanders long near it: the plan starts from the first node on the
     * path that is nearly as near the goals (h within a quarter of the least) */
    int prefix = 0, from = m->best_node;
    long long near = m->nodes[m->best_node].h + m->nodes[m->best_node].h / 4;
    for (int k = m->best_node; k >= 0; k = m->nodes[k].parent) if (m->nodes[k].h <= near) from = k;
    for (int k = from; k >= 0; k = m->nodes[k].parent) prefix++;
    if (reserve(m, (void **)&rows, &cap, (long long)prefix * N, sizeof(int)) < 0) { result = -1; goto done; }
    n_rows = prefix;
    long long row = prefix - 1;
    for (int k = from; k >= 0; k = m->nodes[k].parent, row--)
        memcpy(rows + (size_t)row * N, config(m, k), (size_t)N * sizeof(int));
    while (now() < deadline) {
        const int *q = rows + (size_t)(n_rows - 1) * N;
        if (is_goal(m, q)) {
            if (lns_load(&m->lns, rows, (int)n_rows) < 0) { result = -1; break; }
            m->solved = 1;
            m->best = m->lns.soc;
            result = 1;
            break;
        }
        memcpy(r.here, q, (size_t)N * sizeof(int));  /* the rows may move */
        int done = repair_round(m, &r, r.here, R, deadline, &rows, &n_rows, &cap);
        if (done < 0) { result = -1; break; }
        if (done == 1) R = MIN_RADIUS;
        else if ((R *= 2) > MAX_RADIUS) break;
    }
done:
    free(r.up); free(r.owner); free(r.depth); free(r.queue); free(r.local); free(r.cells); free(r.agents);
    free(r.group); free(r.sadj); free(r.sstart); free(r.sgoal); free(r.at); free(r.stamp); free(r.first); free(r.subs); free(r.here);
    m->used -= (double)cap * sizeof(int);
    free(rows);
    return result;
}

/* Status: 1 solved and proven optimal, 2 solved (stopped by the time limit), 0 time limit with no
 * solution, -1 unsolvable (search exhausted or an agent cannot reach its goal), -3 out of memory. */
static void search(Mapf *m, const int *start, double deadline, double t0) {
    m->status = -3;
    if (grow_nodes(m) < 0) return;
    memcpy(config(m, 0), start, (size_t)m->N * sizeof(int));
    if (new_node(m, -1, 0) < 0) return;
    long long slot;
    find(m, start, &slot);
    m->table[slot] = 0;
    if (push(m, &m->open, 0) < 0) return;
    /* LaCAM alone while its nodes get nearer the goals (a new least h within the last STALL nodes: PIBT
     * is on its way), else LaCAM and prioritized planning in slices, half the time each while both can
     * go on: with SIPP planning is sometimes the quicker of the two where PIBT needs a deep search */
    m->min_h = m->nodes[0].h;
    m->improved_at = 0;
    int outcome = LACAM_FOUND, planned = 0, repaired = 0;
    double lacam_time = 0.0, planning_time = 0.0;
    if (is_goal(m, start)) m->goal_node = 0;
    while (m->goal_node < 0 && !planned && now() < deadline) {
        double began = now();
        int progressing = m->n_nodes - m->improved_at < STALL;
        if (lacam_time < INFINITY && (progressing || lacam_time <= planning_time)) {
            outcome = lacam(m, began + FIRST_SLICE < deadline ? began + FIRST_SLICE : deadline, 1);
            lacam_time += now() - began;
            if (outcome == LACAM_FOUND || (outcome == LACAM_EXHAUSTED && !m->truncated)) break;
            if (outcome != LACAM_DEADLINE) lacam_time = INFINITY;  /* budget spent: planning alone */
        } else if (m->nested < 2 && m->best_node != m->tried_node && !m->repair_failed) {
            /* stalled at a new least h: local repair, on planning's time */
            m->tried_node = m->best_node;
            int done = decompose(m, deadline);
            planning_time += now() - began;
            if (done == 1) { repaired = 1; break; }
            if (done < 0) m->tried_node = INT_MAX;  /* out of memory: no more tries */
            if (done == 0) m->repair_failed = 1;
            if (m->nested == 1) break;  /* a restart makes one try */
        } else if (m->nested == 0 && m->repair_failed && m->probes <= m->pp_turns / 4 && m->probes < MAX_PROBES
                   && (double)m->N * m->V * (sizeof(int) + 1) < 0.5 * (m->budget - m->used)
                   && deadline - began > 0.1 + 4.0 * m->setup_time) {
            /* the repair failed: where LaCAM's knots are too tangled, a restart (another seed: other
             * guides and ties) often leaves knots that untie; its repair gets up to PROBE_TIME. It
             * needs its own distance tables and guides, and room for its search, from the budget, and
             * time for more than setting them up */
            m->probes++;
            double left = deadline - began;
            Mapf *probe = solve_core(m->V, m->adj, m->N, m->start, m->goal, left < PROBE_TIME ? left : PROBE_TIME,
                                     rnd(m), m->budget - m->used, 1);
            planning_time += 0.5 * (now() - began);  /* half of it was LaCAM's */
            if (probe && probe->length > 0) {
                int loaded = lns_load(&m->lns, probe->path, probe->length);
                mapf_free(probe);
                if (loaded < 0) return;
                m->solved = 1;
                m->best = m->lns.soc;
                repaired = 1;
                break;
            }
            mapf_free(probe);
        } else if (planning_time < INFINITY) {
            m->pp_turns++;
            int done = lns_prioritized(&m->pp, began + FIRST_SLICE, deadline);
            planning_time += now() - began;
            planned = done == 1;
            if (done == -1) planning_time = INFINITY;  /* out of memory: LaCAM alone from here */
        } else {
            break;  /* neither can go on */
        }
    }
    if (m->goal_node < 0 && !planned && !repaired) {
        m->status = outcome == LACAM_BUDGET ? -3 : outcome == LACAM_EXHAUSTED && !m->truncated ? -1 : 0;
        return;
    }
    m->first_time = now() - t0;
    if (planned) {
        Lns swap = m->lns; m->lns = m->pp; m->pp = swap;
        m->solved = 1;
        m->best = m->lns.soc;
    } else if (!repaired && take_lacam_solution(m) < 0) {
        return;
    }
    if (m->nested) { m->status = 2; return; }
    /* LaCAM's first solution can be far from the bound where planning's would be near it: planning
     * goes on in turns with the improvers, for as long again as the first solution took (at least
     * 30 % of the time limit), and its solution replaces the best one if cheaper */
    int lacam_open = outcome != LACAM_EXHAUSTED, lns_alive = 1, optimal = 0;
    int planning = !planned && planning_time < INFINITY;
    double planning_left = m->first_time > 0.3 * (deadline - t0) ? m->first_time : 0.3 * (deadline - t0);
    while (now() < deadline) {
        if (m->best <= m->lower) { optimal = 1; break; }
        if (planning) {
            double began = now(), until = began + LNS_SLICE;
            int done = lns_prioritized(&m->pp, until < deadline ? until : deadline, deadline);
            planning_left -= now() - began;
            if (done == 1 && m->pp.soc < m->best) {
                Lns swap = m->lns; m->lns = m->pp; m->pp = swap;
                m->best = m->lns.soc;
            }
            if (done != 2 || planning_left <= 0) planning = 0;
        }
        if (lacam_open) {
            double until = now() + LACAM_SLICE;
            outcome = lacam(m, until < deadline ? until : deadline, 0);
            if (take_lacam_solution(m) < 0) lns_alive = 0;
            if (outcome == LACAM_EXHAUSTED) {
                lacam_open = 0;
                if (!m->truncated) { optimal = 1; break; }
            }
        }
        if (lns_alive) {
            double until = now() + LNS_SLICE;
            if (until > deadline) until = deadline;
            while (now() < until) {
                int done = lns_iterate(&m->lns, until);
                if (done == -1) { lns_alive = 0; break; }
            }
            m->best = m->lns.soc;
        }
        if (!lacam_open && !lns_alive) break;
    }
    if (m->best <= m->lower) optimal = 1;
    m->status = optimal ? 1 : 2;
}

/* Solve: adj (V x 4), starts/goals (N vertices). Returns a handle to read the result from. */
void *mapf_solve(int V, const int *adj, int N, const int *start, const int *goal, double time_limit,
                 unsigned long long seed, double memory_bytes) {
    return solve_core(V, adj, N, start, goal, time_limit, seed, memory_bytes, 0);
}

static Mapf *solve_core(int V, const int *adj, int N, const int *start, const int *goal, double time_limit,
                        uint64_t seed, double memory_bytes, int nested) {
    double t0 = now();
    Mapf *m = calloc(1, sizeof(Mapf));
    if (!m) return NULL;
    m->V = V; m->N = N; m->adj = adj; m->goal = goal; m->start = start;
    m->rng = seed * 2654435761ULL + 88172645463325252ULL;
    m->goal_node = -1; m->goal_g_taken = LLONG_MAX; m->first_time = -1.0; m->status = -3;
    m->budget = memory_bytes;
    m->nested = nested;
    m->tried_node = -1;
    /* tables over the budget: one row, for the lower bound and the reachability verdict alone */
    m->table_size = 1 << 10;
    double tables = (double)N * V * sizeof(int) + (double)m->table_size * sizeof(int);
    int fits = tables <= m->budget;
    m->used = fits ? tables : (double)V * sizeof(int);
    m->dist = malloc((size_t)(fits ? N : 1) * V * sizeof(int));
    int *queue = malloc((size_t)V * sizeof(int));
    m->occ_now = malloc((size_t)V * sizeof(int));
    m->occ_next = malloc((size_t)V * sizeof(int));
    m->stamp = calloc((size_t)V, sizeof(int));
    m->nxt = malloc((size_t)N * sizeof(int));
    m->radix = malloc((size_t)2 * N * sizeof(uint64_t));  /* NULL: qsort instead */
    m->table = malloc((size_t)m->table_size * sizeof(int));
    int ready = m->dist && queue && m->occ_now && m->occ_next && m->stamp && m->nxt && m->table
                && lns_init(&m->lns, V, N, adj, start, goal, NULL, seed) == 0
                && lns_init(&m->pp, V, N, adj, start, goal, NULL, seed) == 0 && pockets(m) == 0 && corridors(m) == 0;
    if (!ready) { free(queue); return m; }
    for (long long s = 0; s < m->table_size; s++) m->table[s] = -1;
    for (int v = 0; v < V; v++) { m->occ_now[v] = -1; m->occ_next[v] = -1; }
    int reachable = 1;
    for (int i = 0; i < N; i++) {
        int *d = m->dist + (fits ? (size_t)i * V : 0);
        bfs(m, goal[i], d, queue);
        if (d[start[i]] < 0) reachable = 0;
        else m->lower += d[start[i]];
    }
    free(queue);
    m->lns.dist = m->dist;
    m->pp.dist = m->dist;
    if (!reachable) { m->status = -1; return m; }
    if (!fits) { m->truncated = 1; m->status = -3; return m; }
    if (guides(m) < 0) { m->status = -3; return m; }
    m->setup_time = now() - t0;
    search(m, start, t0 + time_limit, t0);
    if (m->solved) {
        int makespan = 0;
        for (int i = 0; i < N; i++) if (m->lns.cost[i] > makespan) makespan = m->lns.cost[i];
        m->path = malloc((size_t)(makespan + 1) * N * sizeof(int));
        if (!m->path) { m->status = -3; return m; }
        m->length = makespan + 1;
        for (int t = 0; t <= makespan; t++)
            for (int i = 0; i < N; i++) m->path[(size_t)t * N + i] = lns_at(&m->lns, i, t);
    } else if (nested == 2 && m->n_nodes > 0 && m->nodes[m->best_node].h < m->nodes[0].h) {
        /* a piece not solved: LaCAM's way to its node nearest the goals, a step on (partial) */
        int length = 0, from = m->best_node;  /* the first node on the way that is as near */
        for (int k = m->best_node; k >= 0; k = m->nodes[k].parent) if (m->nodes[k].h <= m->nodes[m->best_node].h) from = k;
        for (int k = from; k >= 0; k = m->nodes[k].parent) length++;
        m->path = malloc((size_t)length * N * sizeof(int));
        if (!m->path) return m;
        m->length = length;
        m->partial = 1;
        int row = length - 1;
        for (int k = from; k >= 0; k = m->nodes[k].parent, row--)
            memcpy(m->path + (size_t)row * N, config(m, k), (size_t)N * sizeof(int));
    }
    return m;
}


int mapf_status(const void *handle) { return handle ? ((const Mapf *)handle)->status : -3; }
int mapf_length(const void *handle) { return handle ? ((const Mapf *)handle)->length : 0; }
double mapf_first_time(const void *handle) { return handle ? ((const Mapf *)handle)->first_time : -1.0; }
int mapf_nodes(const void *handle) { return handle ? ((const Mapf *)handle)->n_nodes : 0; }
double mapf_bytes(const void *handle) { return handle ? ((const Mapf *)handle)->used : 0.0; }
long long mapf_lns_iterations(const void *handle) { return handle ? ((const Mapf *)handle)->lns.iterations : 0; }

long long mapf_lower(const void *handle) { return handle ? ((const Mapf *)handle)->lower : 0; }

/* Copy the solution: length x N vertices. */
void mapf_copy(const void *handle, int *path) {
    const Mapf *m = handle;
    if (m->path) memcpy(path, m->path, (size_t)m->length * m->N * sizeof(int));
}

void mapf_free(void *handle) {
    Mapf *m = handle;
    if (!m) return;
    for (int k = 0; k < m->n_nodes; k++) { free(m->nodes[k].queue.a); free(m->nodes[k].next.a); }
    free(m->nodes); free(m->cfg); free(m->pri); free(m->order); free(m->pool); free(m->table);
    free(m->open.a); free(m->work.a);
    free(m->chain); free(m->cpos); free(m->clen); free(m->cfirst); free(m->ccells); free(m->cend); free(m->gfirst);
    free(m->gagent); free(m->dfr); free(m->gdir);
    free(m->top); free(m->dep_first); free(m->dep_list); free(m->deferred);
    free(m->dist); free(m->occ_now); free(m->occ_next); free(m->stamp); free(m->nxt); free(m->path); free(m->radix);
    lns_free(&m->lns);
    lns_free(&m->pp);
    free(m);
}

/* One agent's shortest path by the solver's SIPP against fixed paths of other agents (tests): agent
 * k < n_others follows others[offset[k] .. offset[k + 1] - 1] and then rests on its last vertex.
 * Writes up to `room` vertices of the path into out; returns its cost (arrival at the goal for
 * good), -1 if there is none, -2 out of memory. */
int mapf_single_path(int V, const int *adj, int n_others, const int *others, const int *offset, int start,
                     int goal, int *out, int room) {
    int N = n_others + 1, result = -2;
    int *starts = malloc((size_t)N * sizeof(int)), *goals = malloc((size_t)N * sizeof(int));
    int *dist = malloc((size_t)N * V * sizeof(int)), *queue = malloc((size_t)V * sizeof(int));
    Mapf m;
    memset(&m, 0, sizeof(m));
    m.V = V; m.adj = adj;
    Lns l;
    memset(&l, 0, sizeof(l));
    if (!starts || !goals || !dist || !queue) goto done;
    for (int k = 0; k < n_others; k++) { starts[k] = others[offset[k]]; goals[k] = others[offset[k + 1] - 1]; }
    starts[n_others] = start; goals[n_others] = goal;
    for (int k = 0; k < N; k++) bfs(&m, goals[k], dist + (size_t)k * V, queue);
    if (lns_init(&l, V, N, adj, starts, goals, dist, 0) < 0) goto done;
    for (int k = 0; k < n_others; k++)
        if (lns_set_path(&l, k, others + offset[k], offset[k + 1] - offset[k] - 1) < 0 || lns_occupy(&l, k) < 0) goto done;
    result = -1;
    if (dist[(size_t)n_others * V + start] < 0) goto done;
    int status = st_astar(&l, n_others, start, INFINITY);
    if (status == -1) result = -2;
    if (status != 0) goto done;
    result = l.cost[n_others];
    for (int t = 0; t <= result && t < room; t++) out[t] = l.path[n_others][t];
done:
    lns_free(&l);
    free(starts); free(goals); free(dist); free(queue);
    return result;
}
