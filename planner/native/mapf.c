/* Multi-agent path finding on a 4-connected graph: LaCAM (a search over configurations, each
 * successor made by PIBT under a growing set of constraints) with the LaCAM* improvement phase
 * (edges between known configurations, g rewired along them, pruning by g + h >= best cost).
 *
 * The graph is given as free vertices 0..V-1 with up to 4 neighbours each (-1 = none). A
 * configuration is one vertex per agent. Search node cost g is the sum of losses: a transition
 * costs one per agent that is not staying on its goal, so h = sum of goal distances is admissible.
 *
 * Memory: each search node keeps its configuration, the agents' PIBT priorities and their order
 * (12 bytes per agent); a byte budget caps the nodes (the search then only revisits known ones).
 */
#define _POSIX_C_SOURCE 199309L
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

typedef struct { int *a; int n, cap; } ivec;

static int iv_push(ivec *v, int x) {
    if (v->n == v->cap) {
        int cap = v->cap ? 2 * v->cap : 4;
        int *grown = realloc(v->a, (size_t)cap * sizeof(int));
        if (!grown) return -1;
        v->a = grown;
        v->cap = cap;
    }
    v->a[v->n++] = x;
    return 0;
}

typedef struct { int parent, agent, vertex, depth; } Constraint;

typedef struct {
    int parent;           /* search node it is reached from at cost g */
    long long g, h;
    ivec queue;           /* constraints still to try (indices into the pool) */
    int head;             /* next one of queue */
    ivec next;            /* known successors (LaCAM*) */
} Node;

typedef struct {
    int V, N;
    const int *adj;       /* V x 4 */
    const int *goal;
    int *dist;            /* N x V, -1 = unreachable */
    Node *nodes; int n_nodes, cap_nodes, max_nodes;
    int *cfg; float *pri; int *order;   /* n_nodes x N each */
    Constraint *pool; long long n_pool, cap_pool;
    int *table; long long table_size;   /* hash: node id or -1 */
    int *occ_now, *occ_next, *nxt, *stamp; int gen;
    uint64_t rng;
    /* result */
    int goal_node; double first_time; int status;
    int *path; int length;
} Mapf;

static double now(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

static uint64_t rnd(Mapf *m) {  /* xorshift64 */
    m->rng ^= m->rng << 13; m->rng ^= m->rng >> 7; m->rng ^= m->rng << 17;
    return m->rng;
}

static void bfs(Mapf *m, int agent, int *queue) {
    int *d = m->dist + (size_t)agent * m->V;
    for (int v = 0; v < m->V; v++) d[v] = -1;
    int head = 0, tail = 0;
    d[m->goal[agent]] = 0;
    queue[tail++] = m->goal[agent];
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
    int *table = malloc((size_t)size * sizeof(int));
    if (!table) return -1;
    for (long long s = 0; s < size; s++) table[s] = -1;
    for (int id = 0; id < m->n_nodes; id++) {
        long long s = (long long)(hash(config(m, id), m->N) & (uint64_t)(size - 1));
        while (table[s] >= 0) s = (s + 1) & (size - 1);
        table[s] = id;
    }
    free(m->table);
    m->table = table;
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
    if (m->n_pool == m->cap_pool) {
        long long cap = m->cap_pool ? 2 * m->cap_pool : 1024;
        Constraint *grown = realloc(m->pool, (size_t)cap * sizeof(Constraint));
        if (!grown) return -1;
        m->pool = grown;
        m->cap_pool = cap;
    }
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
    int *order = m->order + (size_t)id * N;
    for (int i = 0; i < N; i++) order[i] = i;
    sort_pri = p;
    qsort(order, (size_t)N, sizeof(int), cmp_pri);
    Node *node = &m->nodes[id];
    memset(node, 0, sizeof(*node));
    node->parent = parent;
    node->g = g;
    node->h = heuristic(m, q);
    if (iv_push(&node->queue, push_constraint(m, -1, -1, -1, 0)) < 0) return -1;
    m->n_nodes++;
    return id;
}

/* PIBT step of agent i (current config q, priority order decides who calls first). */
static int pibt(Mapf *m, const int *q, const int *dist_base, int i, int j) {
    int cand[5], n = 0, here = q[i];
    const int *d = dist_base + (size_t)i * m->V;
    for (int k = 0; k < 4; k++) if (m->adj[4 * here + k] >= 0) cand[n++] = m->adj[4 * here + k];
    cand[n++] = here;
    /* shuffle, then stable insertion sort by (distance, occupied now): random ties */
    for (int k = n - 1; k > 0; k--) { int r = (int)(rnd(m) % (uint64_t)(k + 1)), t = cand[k]; cand[k] = cand[r]; cand[r] = t; }
    for (int a = 1; a < n; a++) {
        int v = cand[a], key = 2 * d[v] + (m->occ_now[v] >= 0), b = a - 1;
        while (b >= 0 && 2 * d[cand[b]] + (m->occ_now[cand[b]] >= 0) > key) { cand[b + 1] = cand[b]; b--; }
        cand[b + 1] = v;
    }
    for (int a = 0; a < n; a++) {
        int u = cand[a];
        if (m->occ_next[u] >= 0) continue;
        if (j >= 0 && u == q[j]) continue;
        int k = m->occ_now[u];
        if (k >= 0 && k != i && m->nxt[k] == here) continue;  /* swap with a decided agent */
        m->nxt[i] = u;
        m->occ_next[u] = i;
        if (k >= 0 && k != i && m->nxt[k] < 0 && !pibt(m, q, dist_base, k, i)) continue;
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
        if (m->nxt[i] < 0) pibt(m, q, m->dist, i, -1);
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

static int grow_nodes(Mapf *m) {
    if (m->n_nodes < m->cap_nodes) return 0;
    int cap = m->cap_nodes * 2;
    if (cap > m->max_nodes) cap = m->max_nodes;
    if (cap <= m->n_nodes) return -1;
    size_t N = (size_t)m->N;
    Node *nodes = realloc(m->nodes, (size_t)cap * sizeof(Node));
    if (nodes) m->nodes = nodes;
    int *cfg = realloc(m->cfg, (size_t)(cap + 1) * N * sizeof(int));
    if (cfg) m->cfg = cfg;
    float *pri = realloc(m->pri, (size_t)cap * N * sizeof(float));
    if (pri) m->pri = pri;
    int *order = realloc(m->order, (size_t)cap * N * sizeof(int));
    if (order) m->order = order;
    if (!nodes || !cfg || !pri || !order) return -1;
    m->cap_nodes = cap;
    return 0;
}

/* Lower g along known edges from node `from` (Dijkstra-like relaxation on a worklist). */
static void rewire(Mapf *m, ivec *work, int from) {
    work->n = 0;
    iv_push(work, from);
    while (work->n > 0) {
        int u = work->a[--work->n];
        Node *nu = &m->nodes[u];
        for (int e = 0; e < nu->next.n; e++) {
            int w = nu->next.a[e];
            long long g = nu->g + cost(m, config(m, u), config(m, w));
            if (g < m->nodes[w].g) {
                m->nodes[w].g = g;
                m->nodes[w].parent = u;
                iv_push(work, w);
                nu = &m->nodes[u];
            }
        }
    }
}

static int is_goal(Mapf *m, const int *q) {
    for (int i = 0; i < m->N; i++) if (q[i] != m->goal[i]) return 0;
    return 1;
}

/* Status: 1 solved and proven optimal (sum of losses), 2 solved (time limit), 0 time limit with no
 * solution, -1 unsolvable (search exhausted or an agent cannot reach its goal), -3 out of memory. */
static void search(Mapf *m, const int *start, double time_limit, double t0) {
    int N = m->N;
    ivec open = {0}, work = {0};
    long long lower = 0;
    m->status = -3;
    if (grow_nodes(m) < 0) goto done;
    memcpy(config(m, 0), start, (size_t)N * sizeof(int));
    if (new_node(m, -1, 0) < 0) goto done;
    long long slot;
    find(m, start, &slot);
    m->table[slot] = 0;
    lower = m->nodes[0].h;
    if (is_goal(m, start)) { m->goal_node = 0; m->first_time = now() - t0; }
    if (iv_push(&open, 0) < 0) goto done;
    int cand[5];
    long long iterations = 0;
    while (open.n > 0) {
        if ((++iterations & 63) == 0 && now() - t0 > time_limit) break;
        if (m->goal_node >= 0 && m->nodes[m->goal_node].g <= lower) break;  /* optimal */
        int s = open.a[open.n - 1];
        Node *ns = &m->nodes[s];
        if (m->goal_node >= 0 && ns->g + ns->h >= m->nodes[m->goal_node].g) { open.n--; continue; }
        if (ns->head >= ns->queue.n) { open.n--; continue; }
        int c = ns->queue.a[ns->head++];
        Constraint con = m->pool[c];
        if (con.depth < N) {
            int i = m->order[(size_t)s * N + con.depth], v = config(m, s)[i], n = 0;
            for (int k = 0; k < 4; k++) if (m->adj[4 * v + k] >= 0) cand[n++] = m->adj[4 * v + k];
            cand[n++] = v;
            for (int k = n - 1; k > 0; k--) { int r = (int)(rnd(m) % (uint64_t)(k + 1)), t = cand[k]; cand[k] = cand[r]; cand[r] = t; }
            for (int k = 0; k < n; k++) {
                int id = push_constraint(m, c, i, cand[k], con.depth + 1);
                if (id < 0 || iv_push(&m->nodes[s].queue, id) < 0) goto done;
            }
        }
        /* the candidate configuration goes into the slot after the last node */
        int *q = config(m, m->n_nodes);
        if (!generate(m, s, c, q)) continue;
        int t = find(m, q, &slot);
        long long step = cost(m, config(m, s), q);
        if (t >= 0) {
            iv_push(&m->nodes[s].next, t);
            if (m->nodes[s].g + step < m->nodes[t].g) {
                m->nodes[t].g = m->nodes[s].g + step;
                m->nodes[t].parent = s;
                rewire(m, &work, t);
            }
            if (iv_push(&open, t) < 0) goto done;  /* revisit it (LaCAM*) */
            continue;
        }
        if (m->n_nodes + 1 >= m->max_nodes) continue;  /* budget spent: only known nodes */
        if (grow_nodes(m) < 0) continue;
        q = config(m, m->n_nodes);  /* may have moved */
        if (2 * (long long)(m->n_nodes + 1) > m->table_size) {
            if (grow_table(m) < 0) goto done;
            find(m, q, &slot);
        }
        int id = new_node(m, s, m->nodes[s].g + step);
        if (id < 0) goto done;
        m->table[slot] = id;
        iv_push(&m->nodes[s].next, id);
        if (iv_push(&open, id) < 0) goto done;
        if (m->goal_node < 0 && is_goal(m, q)) { m->goal_node = id; m->first_time = now() - t0; }
    }
    if (m->goal_node >= 0)
        m->status = (open.n == 0 || m->nodes[m->goal_node].g <= lower) ? 1 : 2;
    else
        m->status = open.n == 0 ? -1 : 0;
done:
    free(open.a);
    free(work.a);
}

/* Solve: adj (V x 4), starts/goals (N vertices). Returns a handle to read the result from. */
void *mapf_solve(int V, const int *adj, int N, const int *start, const int *goal, double time_limit,
                 unsigned long long seed, double memory_bytes) {
    double t0 = now();
    Mapf *m = calloc(1, sizeof(Mapf));
    if (!m) return NULL;
    m->V = V; m->N = N; m->adj = adj; m->goal = goal;
    m->rng = seed * 2654435761ULL + 88172645463325252ULL;
    m->goal_node = -1; m->first_time = -1.0; m->status = -3;
    m->dist = malloc((size_t)N * V * sizeof(int));
    int *queue = malloc((size_t)V * sizeof(int));
    m->occ_now = malloc((size_t)V * sizeof(int));
    m->occ_next = malloc((size_t)V * sizeof(int));
    m->stamp = calloc((size_t)V, sizeof(int));
    m->nxt = malloc((size_t)N * sizeof(int));
    m->table_size = 1 << 12;
    m->table = malloc((size_t)m->table_size * sizeof(int));
    double per_node = 12.0 * N + sizeof(Node) + 64.0;
    m->max_nodes = memory_bytes / per_node > 2e9 ? 2000000000 : (int)(memory_bytes / per_node);
    m->cap_nodes = 0;
    if (!m->dist || !queue || !m->occ_now || !m->occ_next || !m->stamp || !m->nxt || !m->table) {
        free(queue);
        return m;
    }
    m->cap_nodes = 1;
    if (m->max_nodes < 2) m->max_nodes = 2;
    m->nodes = malloc(sizeof(Node));
    m->cfg = malloc(2 * (size_t)N * sizeof(int));
    m->pri = malloc((size_t)N * sizeof(float));
    m->order = malloc((size_t)N * sizeof(int));
    for (long long s = 0; s < m->table_size; s++) m->table[s] = -1;
    for (int v = 0; v < V; v++) { m->occ_now[v] = -1; m->occ_next[v] = -1; }
    int reachable = 1;
    for (int i = 0; i < N; i++) {
        bfs(m, i, queue);
        if (m->dist[(size_t)i * V + start[i]] < 0) reachable = 0;
    }
    free(queue);
    if (!m->nodes || !m->cfg || !m->pri || !m->order) return m;
    if (!reachable) { m->status = -1; return m; }
    search(m, start, time_limit, t0);
    if (m->goal_node >= 0) {
        int length = 0;
        for (int k = m->goal_node; k >= 0; k = m->nodes[k].parent) length++;
        m->path = malloc((size_t)length * N * sizeof(int));
        if (!m->path) { m->status = -3; return m; }
        m->length = length;
        int row = length - 1;
        for (int k = m->goal_node; k >= 0; k = m->nodes[k].parent, row--)
            memcpy(m->path + (size_t)row * N, config(m, k), (size_t)N * sizeof(int));
    }
    return m;
}

int mapf_status(const void *handle) { return handle ? ((const Mapf *)handle)->status : -3; }
int mapf_length(const void *handle) { return handle ? ((const Mapf *)handle)->length : 0; }
double mapf_first_time(const void *handle) { return handle ? ((const Mapf *)handle)->first_time : -1.0; }
int mapf_nodes(const void *handle) { return handle ? ((const Mapf *)handle)->n_nodes : 0; }

/* Copy the solution (length x N vertices) and the agents' goal distances from their starts. */
void mapf_copy(const void *handle, int *path, int *start_distance, const int *start) {
    const Mapf *m = handle;
    if (m->path) memcpy(path, m->path, (size_t)m->length * m->N * sizeof(int));
    for (int i = 0; i < m->N; i++) start_distance[i] = m->dist ? m->dist[(size_t)i * m->V + start[i]] : -1;
}

void mapf_free(void *handle) {
    Mapf *m = handle;
    if (!m) return;
    for (int k = 0; k < m->n_nodes; k++) { free(m->nodes[k].queue.a); free(m->nodes[k].next.a); }
    free(m->nodes); free(m->cfg); free(m->pri); free(m->order); free(m->pool); free(m->table);
    free(m->dist); free(m->occ_now); free(m->occ_next); free(m->stamp); free(m->nxt); free(m->path);
    free(m);
}
