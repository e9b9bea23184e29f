/* Large neighbourhood search for MAPF (Li et al., IJCAI 2021: anytime MAPF via LNS): keep a
 * solution; repeatedly take a few agents out (a neighbourhood), replan them one after the other in
 * random order with SIPP (below) against everyone else's paths, and keep the new paths if their
 * sum of costs is lower. Neighbourhoods come from three rules, chosen by adaptive weights: the
 * agents met by a random walk that could shorten the most delayed agent's path, the agents passing
 * near a random intersection, and random agents.
 *
 * Agent i's path is p[0..c_i], c_i its cost (the time it reaches its goal for the last time); it
 * rests on its goal from c_i on. Occupancy: the (time, agent) visits of the steps t < c_j of the
 * paths, per vertex (sorted by time) and in a hash table keyed by (time, vertex), and per vertex the
 * time from which an agent rests there.
 */
#include <limits.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define LNS_HOOD 8               /* agents per neighbourhood (Li et al.'s default) */
#define LNS_REACTION 0.01        /* adaptive weights: w <- r * improvement + (1 - r) * w */
#define LNS_RULES 3

typedef struct { int t, agent; } Visit;
typedef struct { Visit *a; int n, cap; } Visits;
typedef struct { int v, t, iv, parent, child, f, h; } StNode;  /* t: arrival; iv: its safe interval */

typedef struct {
    int V, N;
    const int *adj, *start, *goal, *dist;   /* adj V x 4; dist N x V */
    int **path, *cost;              /* per agent: p[0..cost] */
    Visits *visits;                 /* per vertex */
    long long *occ_key; int *occ_agent, occ_size, occ_count;  /* (t, v) -> agent, -1 = empty slot */
    int *rest_from;                 /* per vertex: time its goal's agent rests from, INT_MAX if none */
    int *goal_agent;                /* per vertex: the agent whose goal it is, -1 if none */
    long long soc, iterations;
    uint64_t rng;
    double weight[LNS_RULES];
    int *hood, n_hood; char *in_hood, *tabu; int n_tabu;
    int *order;                     /* prioritized planning: the queue of agents still to plan (ring) */
    int queue_head, queue_n, queue_ready;
    int **saved_path, *saved_cost;
    int *intersections, n_intersections;
    int *bfs_queue; int *bfs_stamp, bfs_gen;
    /* SIPP: nodes, binary heap of node ids; the safe intervals of the vertices met by one search
     * (a pool: [lo, hi] and the earliest arrival found) */
    StNode *st; int st_n, st_cap;
    int *heap, heap_n, heap_cap;
    int *iv_lo, *iv_hi, *iv_best, *iv_before, iv_n, iv_cap;  /* before: the agent on it at lo - 1 */
    int *iv_first, *iv_count, *iv_stamp, generation;
    int expansion_cap, settle;      /* settle: the searched agent may rest on its goal from then on */
} Lns;

static double clock_now(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

static uint64_t lns_rnd(Lns *l) {
    l->rng ^= l->rng << 13; l->rng ^= l->rng >> 7; l->rng ^= l->rng << 17;
    return l->rng;
}

static int lns_at(const Lns *l, int agent, int t) {
    return t < l->cost[agent] ? l->path[agent][t] : l->goal[agent];
}

static long long st_key(const Lns *l, int v, int t) { return (long long)t * l->V + v; }

static uint64_t slot_of(long long key, int size) {
    uint64_t h = (uint64_t)key * 0x9E3779B97F4A7C15ULL;
    return (h ^ (h >> 31)) & (uint64_t)(size - 1);
}

static int occ_find(const Lns *l, long long key) {
    uint64_t mask = (uint64_t)l->occ_size - 1;
    for (uint64_t s = slot_of(key, l->occ_size);; s = (s + 1) & mask) {
        if (l->occ_agent[s] < 0) return -1;
        if (l->occ_key[s] == key) return (int)s;
    }
}

static int occ_put(Lns *l, long long key, int agent) {
    if (2 * (l->occ_count + 1) > l->occ_size) {
        int size = 2 * l->occ_size;
        long long *keys = malloc((size_t)size * sizeof(long long));
        int *agents = malloc((size_t)size * sizeof(int));
        if (!keys || !agents) { free(keys); free(agents); return -1; }
        for (int s = 0; s < size; s++) agents[s] = -1;
        for (int s = 0; s < l->occ_size; s++) {
            if (l->occ_agent[s] < 0) continue;
            uint64_t t = slot_of(l->occ_key[s], size);
            while (agents[t] >= 0) t = (t + 1) & (uint64_t)(size - 1);
            keys[t] = l->occ_key[s]; agents[t] = l->occ_agent[s];
        }
        free(l->occ_key); free(l->occ_agent);
        l->occ_key = keys; l->occ_agent = agents; l->occ_size = size;
    }
    uint64_t s = slot_of(key, l->occ_size);
    while (l->occ_agent[s] >= 0) s = (s + 1) & (uint64_t)(l->occ_size - 1);
    l->occ_key[s] = key;
    l->occ_agent[s] = agent;
    l->occ_count++;
    return 0;
}

/* Linear probing's deletion: later entries of the probe run shift back into the hole. */
static void occ_remove(Lns *l, long long key) {
    int hole = occ_find(l, key);
    if (hole < 0) return;
    uint64_t mask = (uint64_t)l->occ_size - 1, i = (uint64_t)hole;
    for (uint64_t j = (i + 1) & mask; l->occ_agent[j] >= 0; j = (j + 1) & mask) {
        uint64_t home = slot_of(l->occ_key[j], l->occ_size);
        if (((j - home) & mask) >= ((j - i) & mask)) {  /* home not in (i, j]: it may fill i */
            l->occ_key[i] = l->occ_key[j];
            l->occ_agent[i] = l->occ_agent[j];
            i = j;
        }
    }
    l->occ_agent[i] = -1;
    l->occ_count--;
}

/* A vertex's visits are kept sorted by time (its safe intervals are read off them in order). */
static int visits_first_after(const Visits *list, int t) {  /* first index with time > t */
    int lo = 0, hi = list->n;
    while (lo < hi) { int mid = (lo + hi) / 2; if (list->a[mid].t <= t) lo = mid + 1; else hi = mid; }
    return lo;
}

static int visits_add(Visits *list, int t, int agent) {
    if (list->n == list->cap) {
        int cap = list->cap ? 2 * list->cap : 4;
        Visit *grown = realloc(list->a, (size_t)cap * sizeof(Visit));
        if (!grown) return -1;
        list->a = grown;
        list->cap = cap;
    }
    int k = visits_first_after(list, t);
    memmove(list->a + k + 1, list->a + k, (size_t)(list->n - k) * sizeof(Visit));
    list->a[k].t = t;
    list->a[k].agent = agent;
    list->n++;
    return 0;
}

static void lns_unvisit(Lns *l, int agent, int steps) {
    for (int t = 0; t < steps; t++) {
        occ_remove(l, st_key(l, l->path[agent][t], t));
        Visits *list = &l->visits[l->path[agent][t]];
        for (int k = visits_first_after(list, t - 1); k < list->n && list->a[k].t == t; k++)
            if (list->a[k].agent == agent) {
                memmove(list->a + k, list->a + k + 1, (size_t)(list->n - k - 1) * sizeof(Visit));
                list->n--;
                break;
            }
    }
}

/* Enter agent's path into the tables; -1 (tables unchanged) if out of memory. */
static int lns_occupy(Lns *l, int agent) {
    for (int t = 0; t < l->cost[agent]; t++)
        if (visits_add(&l->visits[l->path[agent][t]], t, agent) < 0
            || occ_put(l, st_key(l, l->path[agent][t], t), agent) < 0) { lns_unvisit(l, agent, t + 1); return -1; }
    l->rest_from[l->goal[agent]] = l->cost[agent];
    l->soc += l->cost[agent];
    return 0;
}

static void lns_vacate(Lns *l, int agent) {
    lns_unvisit(l, agent, l->cost[agent]);
    l->rest_from[l->goal[agent]] = INT_MAX;
    l->soc -= l->cost[agent];
}

/* The agent at vertex v at time t, -1 if none (agent i itself is never in the tables then). */
static int lns_occupant(const Lns *l, int v, int t) {
    int s = occ_find(l, st_key(l, v, t));
    return s < 0 ? -1 : l->occ_agent[s];
}

/* Replace agent's path by a copy of p[0..cost]. */
static int lns_set_path(Lns *l, int agent, const int *p, int cost) {
    int *copy = malloc((size_t)(cost + 1) * sizeof(int));
    if (!copy) return -1;
    memcpy(copy, p, (size_t)(cost + 1) * sizeof(int));
    free(l->path[agent]);
    l->path[agent] = copy;
    l->cost[agent] = cost;
    return 0;
}

/* Load a solution given as `length` configurations (rows of N vertices). */
static int lns_load(Lns *l, const int *rows, int length) {
    for (int i = 0; i < l->N; i++) if (l->path[i]) lns_vacate(l, i);
    int *column = malloc((size_t)length * sizeof(int));
    if (!column) return -1;
    for (int i = 0; i < l->N; i++) {
        int cost = 0;
        for (int t = 0; t < length; t++) {
            column[t] = rows[(size_t)t * l->N + i];
            if (column[t] != l->goal[i]) cost = t + 1;
        }
        if (lns_set_path(l, i, column, cost) < 0 || lns_occupy(l, i) < 0) { free(column); return -1; }
    }
    free(column);
    return 0;
}

static int lns_init(Lns *l, int V, int N, const int *adj, const int *start, const int *goal, const int *dist,
                    uint64_t seed) {
    memset(l, 0, sizeof(*l));
    l->V = V; l->N = N; l->adj = adj; l->start = start; l->goal = goal; l->dist = dist;
    l->rng = seed * 0x9E3779B97F4A7C15ULL + 1442695040888963407ULL;
    for (int r = 0; r < LNS_RULES; r++) l->weight[r] = 1.0;
    l->path = calloc((size_t)N, sizeof(int *));
    l->saved_path = calloc((size_t)N, sizeof(int *));
    l->cost = calloc((size_t)N, sizeof(int));
    l->saved_cost = calloc((size_t)N, sizeof(int));
    l->hood = malloc((size_t)N * sizeof(int));
    l->order = malloc((size_t)N * sizeof(int));
    l->in_hood = calloc((size_t)N, 1);
    l->tabu = calloc((size_t)N, 1);
    l->visits = calloc((size_t)V, sizeof(Visits));
    l->rest_from = malloc((size_t)V * sizeof(int));
    l->goal_agent = malloc((size_t)V * sizeof(int));
    l->intersections = malloc((size_t)V * sizeof(int));
    l->bfs_queue = malloc((size_t)V * sizeof(int));
    l->bfs_stamp = calloc((size_t)V, sizeof(int));
    l->iv_first = malloc((size_t)V * sizeof(int));
    l->iv_count = malloc((size_t)V * sizeof(int));
    l->iv_stamp = calloc((size_t)V, sizeof(int));
    l->occ_size = 1 << 12;
    l->occ_key = malloc((size_t)l->occ_size * sizeof(long long));
    l->occ_agent = malloc((size_t)l->occ_size * sizeof(int));
    /* a replanned agent that needs more expansions than this is given up: the neighbourhood fails,
     * the old paths stay, and the time goes to other neighbourhoods */
    l->expansion_cap = 20 * V + 100000;
    if (!l->path || !l->saved_path || !l->cost || !l->saved_cost || !l->hood || !l->order || !l->in_hood || !l->tabu
        || !l->visits || !l->rest_from || !l->intersections || !l->bfs_queue || !l->bfs_stamp || !l->iv_first
        || !l->iv_count || !l->iv_stamp || !l->goal_agent || !l->occ_key || !l->occ_agent) return -1;
    for (int k = 0; k < l->occ_size; k++) l->occ_agent[k] = -1;
    for (int v = 0; v < V; v++) {
        l->rest_from[v] = INT_MAX;
        l->goal_agent[v] = -1;
        int degree = 0;
        for (int k = 0; k < 4; k++) degree += adj[4 * v + k] >= 0;
        if (degree >= 3) l->intersections[l->n_intersections++] = v;
    }
    for (int i = 0; i < N; i++) { l->goal_agent[goal[i]] = i; l->order[i] = i; }
    for (int k = N - 1; k > 0; k--) {
        int r = (int)(lns_rnd(l) % (uint64_t)(k + 1)), t = l->order[k];
        l->order[k] = l->order[r]; l->order[r] = t;
    }
    return 0;
}

static void lns_free(Lns *l) {
    for (int i = 0; l->path && i < l->N; i++) { free(l->path[i]); if (l->saved_path) free(l->saved_path[i]); }
    for (int v = 0; l->visits && v < l->V; v++) free(l->visits[v].a);
    free(l->path); free(l->saved_path); free(l->cost); free(l->saved_cost); free(l->hood); free(l->order); free(l->in_hood);
    free(l->tabu); free(l->visits); free(l->rest_from); free(l->goal_agent); free(l->intersections); free(l->bfs_queue);
    free(l->bfs_stamp); free(l->occ_key); free(l->occ_agent); free(l->st); free(l->heap);
    free(l->iv_lo); free(l->iv_hi); free(l->iv_best); free(l->iv_before); free(l->iv_first); free(l->iv_count); free(l->iv_stamp);
}

/* -- safe interval path planning ------------------------------------------------------------------
 * SIPP (Phillips & Likhachev, ICRA 2011): the times a vertex is free of the other agents form safe
 * intervals (maximal runs of free time steps); a search state is a (vertex, safe interval) pair
 * reached at its earliest time, since an agent that arrives earlier in an interval can wait there
 * until any later time of it. A move from v (interval [lo, hi], reached at t) to a neighbour u
 * leaves v at some time d in [t, hi] and enters one of u's intervals at d + 1, at the earliest such
 * time that is not a swap with an agent going u -> v. The goal is the agent's goal vertex in its
 * last interval (free for ever). The states are few (one per interval, not one per time step), so a
 * search is quick on long paths and proves quickly that there is no path at all. */

/* Room for `more` further intervals in the pool; -1 if out of memory. */
static int iv_reserve(Lns *l, int more) {
    if (l->iv_n + more <= l->iv_cap) return 0;
    int cap = l->iv_cap ? 2 * l->iv_cap : 4096;
    while (cap < l->iv_n + more) cap *= 2;
    int *lo = realloc(l->iv_lo, (size_t)cap * sizeof(int));
    if (lo) l->iv_lo = lo;
    int *hi = realloc(l->iv_hi, (size_t)cap * sizeof(int));
    if (hi) l->iv_hi = hi;
    int *best = realloc(l->iv_best, (size_t)cap * sizeof(int));
    if (best) l->iv_best = best;
    int *before = realloc(l->iv_before, (size_t)cap * sizeof(int));
    if (before) l->iv_before = before;
    if (!lo || !hi || !best || !before) return -1;
    l->iv_cap = cap;
    return 0;
}

/* The safe intervals of v in this search: pool entries iv_first[v] .. + iv_count[v], by time; -1 if
 * out of memory. Unsafe: the times other agents visit v, and from the time an agent rests there. */
static int intervals(Lns *l, int v) {
    if (l->iv_stamp[v] == l->generation) return 0;
    const Visits *list = &l->visits[v];
    if (iv_reserve(l, list->n + 1) < 0) return -1;
    int rest = l->rest_from[v], from = 0, n = 0, before = -1;
    l->iv_first[v] = l->iv_n;
    for (int k = 0; k <= list->n; k++) {
        int until = k < list->n ? list->a[k].t - 1 : INT_MAX;  /* the free run before the next visit */
        if (rest != INT_MAX && until >= rest) until = rest - 1;
        if (until >= from) {
            l->iv_lo[l->iv_n + n] = from;
            l->iv_hi[l->iv_n + n] = until;
            l->iv_best[l->iv_n + n] = INT_MAX;
            l->iv_before[l->iv_n + n] = before;
            n++;
        }
        if (k < list->n) { from = list->a[k].t + 1; before = list->a[k].agent; }
        if (from >= rest) break;
    }
    l->iv_n += n;
    l->iv_count[v] = n;
    l->iv_stamp[v] = l->generation;
    return 0;
}

/* Heap order: f = max(t + goal distance, settle) ascending (consistent: the agent cannot rest on
 * its goal before settle), then nearer the goal first, then later t first. Where settle dominates f
 * (a goal others pass late) the ties are many: nearest first heads for the goal. */
static int st_before(const Lns *l, int a, int b) {
    const StNode *x = &l->st[a], *y = &l->st[b];
    return x->f < y->f || (x->f == y->f && (x->h < y->h || (x->h == y->h && x->t > y->t)));
}

static int st_push(Lns *l, int agent, int v, int t, int iv, int parent) {
    if (l->st_n == l->st_cap) {
        int cap = l->st_cap ? 2 * l->st_cap : 1024;
        StNode *grown = realloc(l->st, (size_t)cap * sizeof(StNode));
        if (!grown) return -1;
        l->st = grown; l->st_cap = cap;
    }
    if (l->heap_n == l->heap_cap) {
        int cap = l->heap_cap ? 2 * l->heap_cap : 1024;
        int *grown = realloc(l->heap, (size_t)cap * sizeof(int));
        if (!grown) return -1;
        l->heap = grown; l->heap_cap = cap;
    }
    int id = l->st_n++;
    int h = l->dist[(size_t)agent * l->V + v];
    l->st[id].v = v; l->st[id].t = t; l->st[id].iv = iv; l->st[id].parent = parent; l->st[id].h = h;
    l->st[id].f = t + h < l->settle ? l->settle : t + h;
    l->iv_best[iv] = t;
    int k = l->heap_n++;
    while (k > 0 && st_before(l, id, l->heap[(k - 1) / 2])) { l->heap[k] = l->heap[(k - 1) / 2]; k = (k - 1) / 2; }
    l->heap[k] = id;
    return 0;
}

static int st_pop(Lns *l) {
    int top = l->heap[0], last = l->heap[--l->heap_n], k = 0;
    for (;;) {
        int child = 2 * k + 1;
        if (child >= l->heap_n) break;
        if (child + 1 < l->heap_n && st_before(l, l->heap[child + 1], l->heap[child])) child++;
        if (!st_before(l, l->heap[child], last)) break;
        l->heap[k] = l->heap[child];
        k = child;
    }
    if (l->heap_n > 0) l->heap[k] = last;
    return top;
}

/* Shortest path of `agent` from `start` against the paths in the tables (its own is not there),
 * into path[agent] (a new array). 0 found, 1 none (or none within the expansion cap), 2 deadline,
 * -1 out of memory. */
static int st_astar(Lns *l, int agent, int start, double deadline) {
    l->st_n = 0; l->heap_n = 0; l->iv_n = 0;
    l->generation++;
    int goal = l->goal[agent];
    const int *d = l->dist + (size_t)agent * l->V;
    if (intervals(l, goal) < 0 || intervals(l, start) < 0) return -1;
    int last = l->iv_first[goal] + l->iv_count[goal] - 1;
    if (l->iv_count[goal] == 0 || l->iv_hi[last] != INT_MAX) return 1;  /* someone rests there */
    l->settle = l->iv_lo[last];
    if (l->iv_count[start] == 0 || l->iv_lo[l->iv_first[start]] != 0) return 1;  /* taken at time 0 */
    if (st_push(l, agent, start, 0, l->iv_first[start], -1) < 0) return -1;
    for (int expanded = 0; l->heap_n > 0 && expanded < l->expansion_cap; expanded++) {
        if ((expanded & 1023) == 1023 && clock_now() > deadline) return 2;
        int id = st_pop(l);
        StNode node = l->st[id];
        if (node.t > l->iv_best[node.iv]) continue;  /* reached earlier since it was pushed */
        int hi = l->iv_hi[node.iv];
        if (node.v == goal && hi == INT_MAX) {
            int *out = malloc((size_t)(node.t + 1) * sizeof(int));
            if (!out) return -1;
            for (int k = id; k >= 0; k = l->st[k].parent) {
                int until = k == id ? node.t + 1 : l->st[l->st[k].child].t;
                for (int t = l->st[k].t; t < until; t++) out[t] = l->st[k].v;
                if (l->st[k].parent >= 0) l->st[l->st[k].parent].child = k;
            }
            l->path[agent] = out;
            l->cost[agent] = node.t;
            return 0;
        }
        for (int k = 0; k < 4; k++) {
            int u = l->adj[4 * node.v + k];
            if (u < 0 || d[u] < 0) continue;
            if (intervals(l, u) < 0) return -1;
            int first = l->iv_first[u], count = l->iv_count[u];
            /* leave v at a time in [node.t, hi]: enter u at a time in [node.t + 1, hi + 1] */
            int latest = hi == INT_MAX ? INT_MAX : hi + 1;
            int lo = first, hi_j = first + count;  /* the first interval ending at node.t + 1 or later */
            while (lo < hi_j) { int mid = (lo + hi_j) / 2; if (l->iv_hi[mid] < node.t + 1) lo = mid + 1; else hi_j = mid; }
            for (int j = lo; j < first + count; j++) {
                if (l->iv_lo[j] > latest) break;
                int arrive = l->iv_lo[j] > node.t + 1 ? l->iv_lo[j] : node.t + 1;
                int end = l->iv_hi[j] < latest ? l->iv_hi[j] : latest;
                /* not a swap with an agent going u -> v: only possible when u was taken the step
                 * before, i.e. arriving at the interval's start; then one step later */
                int other = l->iv_before[j];
                if (arrive == l->iv_lo[j] && other >= 0 && lns_at(l, other, arrive) == node.v) arrive++;
                if (arrive > end || arrive >= l->iv_best[j]) continue;
                if (st_push(l, agent, u, arrive, j, id) < 0) return -1;
            }
        }
    }
    return 1;
}

/* -- neighbourhoods ------------------------------------------------------------------------------- */

static void hood_add(Lns *l, int agent) {
    if (agent < 0 || l->in_hood[agent] || l->n_hood >= LNS_HOOD) return;
    l->in_hood[agent] = 1;
    l->hood[l->n_hood++] = agent;
}

static int resting_at(const Lns *l, int v, int t) {
    return l->rest_from[v] <= t ? l->goal_agent[v] : -1;
}

/* The agents met by random walks in space-time from the most delayed agent's path that could still
 * reach its goal earlier than it now does. */
static void hood_random_walk(Lns *l) {
    int chosen = -1, worst = -1;
    if (l->n_tabu >= l->N) { memset(l->tabu, 0, (size_t)l->N); l->n_tabu = 0; }
    for (int i = 0; i < l->N; i++) {
        int delay = l->cost[i] - l->dist[(size_t)i * l->V + l->path[i][0]];
        if (!l->tabu[i] && delay > worst) { worst = delay; chosen = i; }
    }
    l->tabu[chosen] = 1;
    l->n_tabu++;
    hood_add(l, chosen);
    if (l->cost[chosen] == 0) return;
    const int *d = l->dist + (size_t)chosen * l->V;
    for (int walk = 0; walk < 16 && l->n_hood < LNS_HOOD; walk++) {
        int t = (int)(lns_rnd(l) % (uint64_t)l->cost[chosen]), v = l->path[chosen][t];
        for (int step = 0; step < l->cost[chosen] && l->n_hood < LNS_HOOD; step++) {
            int options[5], n = 0;
            for (int k = 0; k <= 4; k++) {
                int u = k < 4 ? l->adj[4 * v + k] : v;
                if (u >= 0 && t + 1 + d[u] < l->cost[chosen]) options[n++] = u;
            }
            if (n == 0) break;
            v = options[lns_rnd(l) % (uint64_t)n];
            t++;
            hood_add(l, lns_occupant(l, v, t));
            hood_add(l, resting_at(l, v, t));
        }
    }
}

/* The agents whose paths pass the cells nearest (breadth first) to a random intersection. */
static void hood_intersection(Lns *l) {
    if (l->n_intersections == 0) return;
    int head = 0, tail = 0, seed = l->intersections[lns_rnd(l) % (uint64_t)l->n_intersections];
    l->bfs_gen++;
    l->bfs_queue[tail++] = seed;
    l->bfs_stamp[seed] = l->bfs_gen;
    /* a few hundred cells around it at most: past that the agents found are no longer near it */
    while (head < tail && l->n_hood < LNS_HOOD && head < 4 * LNS_HOOD * LNS_HOOD) {
        int v = l->bfs_queue[head++];
        const Visits *list = &l->visits[v];
        for (int k = 0; k < list->n; k++) hood_add(l, list->a[k].agent);
        hood_add(l, resting_at(l, v, INT_MAX - 1));
        for (int k = 0; k < 4; k++) {
            int u = l->adj[4 * v + k];
            if (u >= 0 && l->bfs_stamp[u] != l->bfs_gen) { l->bfs_stamp[u] = l->bfs_gen; l->bfs_queue[tail++] = u; }
        }
    }
}

static int pick_rule(Lns *l) {
    double total = 0.0;
    for (int r = 0; r < LNS_RULES; r++) total += l->weight[r];
    double x = (double)(lns_rnd(l) >> 11) * (1.0 / 9007199254740992.0) * total;
    for (int r = 0; r < LNS_RULES - 1; r++) { if (x < l->weight[r]) return r; x -= l->weight[r]; }
    return LNS_RULES - 1;
}

/* One LNS iteration: 1 improved, 0 not, 2 deadline, -1 out of memory (the solution is kept). */
static int lns_iterate(Lns *l, double deadline) {
    int rule = pick_rule(l);
    l->n_hood = 0;
    if (rule == 0) hood_random_walk(l);
    else if (rule == 1) hood_intersection(l);
    while (l->n_hood < LNS_HOOD && l->n_hood < l->N) hood_add(l, (int)(lns_rnd(l) % (uint64_t)l->N));
    for (int k = l->n_hood - 1; k > 0; k--) {   /* random planning order */
        int r = (int)(lns_rnd(l) % (uint64_t)(k + 1)), t = l->hood[k];
        l->hood[k] = l->hood[r]; l->hood[r] = t;
    }
    long long before = l->soc, rest = 0;
    for (int k = 0; k < l->n_hood; k++) {
        int i = l->hood[k];
        lns_vacate(l, i);
        l->saved_path[i] = l->path[i];
        l->saved_cost[i] = l->cost[i];
        rest += l->dist[(size_t)i * l->V + l->path[i][0]];
    }
    int planned = 0, status = 0;   /* the first `planned` members hold new, entered paths */
    for (; planned < l->n_hood; planned++) {
        int i = l->hood[planned];
        rest -= l->dist[(size_t)i * l->V + l->path[i][0]];
        status = st_astar(l, i, l->saved_path[i][0], deadline);
        if (status != 0) break;
        if (lns_occupy(l, i) < 0) { status = -1; break; }
        if (l->soc + rest >= before) { status = 1; planned++; break; }  /* cannot beat the old paths */
    }
    int improved = status == 0 && l->soc < before;
    l->iterations++;
    for (int k = 0; k < l->n_hood; k++) {
        int i = l->hood[k];
        if (improved) {
            free(l->saved_path[i]);
        } else {
            /* the old paths go back; the visit lists held them before, so no list grows here */
            if (k < planned) lns_vacate(l, i);
            if (l->path[i] != l->saved_path[i]) free(l->path[i]);
            l->path[i] = l->saved_path[i];
            l->cost[i] = l->saved_cost[i];
            lns_occupy(l, i);
        }
        l->saved_path[i] = NULL;
        l->in_hood[i] = 0;
    }
    double gain = improved ? (double)(before - l->soc) : 0.0;
    l->weight[rule] = LNS_REACTION * gain + (1.0 - LNS_REACTION) * l->weight[rule];
    return status == -1 || status == 2 ? status : improved;
}

/* Prioritized planning with eviction: the agents are planned one after the other from a queue
 * (see lns_order_by_blocking), each by SIPP against the ones planned. An agent that finds no
 * path takes out the planned agents in its way and is planned again at once; they go to the back of
 * the queue. In its way, first: the agents on its start's cells in the first steps (it was walled
 * in) and the ones resting on a shortest path of it; if it still finds none: the ones that meet that
 * path followed without waiting (on its cells at the same time steps, swapping with it, resting
 * there by then). Few are taken out at first: each one taken out must be planned again. SIPP fails
 * only where there is no path (or past the expansion cap), so a failure is a real blockade. */

static void queue_push(Lns *l, int agent) { l->order[(l->queue_head + l->queue_n++) % l->N] = agent; }

static void queue_push_front(Lns *l, int agent) {
    l->queue_head = (l->queue_head + l->N - 1) % l->N;
    l->order[l->queue_head] = agent;
    l->queue_n++;
}

static void evict(Lns *l, int agent) {
    if (agent < 0 || l->in_hood[agent] || !l->path[agent]) return;
    l->in_hood[agent] = 1;  /* marks the agents evicted for one failure */
    l->hood[l->n_hood++] = agent;
    lns_vacate(l, agent);
    free(l->path[agent]);
    l->path[agent] = NULL;
    l->cost[agent] = 0;
}

static void evict_blockers(Lns *l, int agent, int harder) {
    const int *d = l->dist + (size_t)agent * l->V;
    int start = l->start[agent], goal = l->goal[agent], v = start, t = 0;
    l->n_hood = 0;
    for (int s = 0; s <= 2 && !harder; s++) {
        evict(l, lns_occupant(l, start, s));
        evict(l, resting_at(l, start, s));
        for (int k = 0; k < 4; k++) {
            int u = l->adj[4 * start + k];
            if (u >= 0) { evict(l, lns_occupant(l, u, s)); evict(l, resting_at(l, u, s)); }
        }
    }
    for (;;) {  /* a shortest path, ties broken at random */
        evict(l, resting_at(l, v, harder ? t : INT_MAX - 1));
        if (harder) evict(l, lns_occupant(l, v, t));
        if (v == goal) break;
        int options[4], n = 0;
        for (int k = 0; k < 4; k++) {
            int u = l->adj[4 * v + k];
            if (u >= 0 && d[u] == d[v] - 1) options[n++] = u;
        }
        int u = options[lns_rnd(l) % (uint64_t)n], other = lns_occupant(l, u, t);
        if (harder && other >= 0 && lns_at(l, other, t + 1) == v) evict(l, other);  /* a swap */
        v = u;
        t++;
    }
    for (int k = l->n_hood - 1; k > 0; k--) {
        int r = (int)(lns_rnd(l) % (uint64_t)(k + 1)), t = l->hood[k];
        l->hood[k] = l->hood[r]; l->hood[r] = t;
    }
    for (int k = 0; k < l->n_hood; k++) {
        l->in_hood[l->hood[k]] = 0;
        queue_push(l, l->hood[k]);
    }
    l->n_hood = 0;
}

/* The first planning order: agents whose goal lies on many others' shortest paths last (resting
 * there early would wall them off; planned last, they wait until the others have passed), agents
 * whose start lies on many others' paths first (they leave it before the others come); ties in the
 * random order of lns_init. Counts over one shortest path per agent. -1 out of memory. */
static const long long *order_key;
static int cmp_order(const void *a, const void *b) {
    long long x = order_key[*(const int *)a], y = order_key[*(const int *)b];
    return (x > y) - (x < y);
}

static int lns_order_by_blocking(Lns *l) {
    int *through = calloc((size_t)l->V, sizeof(int));
    long long *key = malloc((size_t)l->N * sizeof(long long));
    if (!through || !key) { free(through); free(key); return -1; }
    for (int i = 0; i < l->N; i++) {
        const int *d = l->dist + (size_t)i * l->V;
        for (int v = l->start[i];; ) {
            through[v]++;
            if (v == l->goal[i]) break;
            for (int k = 0; k < 4; k++) {
                int u = l->adj[4 * v + k];
                if (u >= 0 && d[u] == d[v] - 1) { v = u; break; }
            }
        }
    }
    for (int r = 0; r < l->N; r++) {  /* the random position breaks ties */
        int i = l->order[r];
        key[i] = ((long long)(through[l->goal[i]] - through[l->start[i]]) << 32) + r;
    }
    order_key = key;
    qsort(l->order, (size_t)l->N, sizeof(int), cmp_order);
    free(through);
    free(key);
    return 0;
}

/* Plan from the queue until it is empty (1: every agent has a path, the solution is in the tables),
 * `pause` (2; a later call resumes), or out of memory (-1). A search under way runs until
 * `deadline`. */
static int lns_prioritized(Lns *l, double pause, double deadline) {
    if (!l->queue_ready) {  /* the first call: every agent, in the order above */
        if (lns_order_by_blocking(l) < 0) return -1;
        l->queue_n = l->N;
        l->queue_ready = 1;
    }
    while (l->queue_n > 0) {
        if (clock_now() > pause) return 2;
        int i = l->order[l->queue_head];
        l->queue_head = (l->queue_head + 1) % l->N;
        l->queue_n--;
        int status = st_astar(l, i, l->start[i], deadline);
        if (status == 1) {
            evict_blockers(l, i, 0);
            status = st_astar(l, i, l->start[i], deadline);
        }
        if (status == 1) {
            evict_blockers(l, i, 1);
            status = st_astar(l, i, l->start[i], deadline);
        }
        if (status == 1) { queue_push(l, i); continue; }  /* still none: to the back of the queue */
        if (status == 2) { queue_push_front(l, i); return 2; }
        if (status != 0 || lns_occupy(l, i) < 0) return -1;
    }
    return 1;
}
