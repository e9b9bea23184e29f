/* Kernels of a fleet (cosim.world.fleet, cosim.navigation.fleet): the robots' contacts, their
 * judging, and the fleet's Python components stepped in one call a block, on one thread or the
 * machine's cores. A library of its own (world.c's kernels are those of every run), loaded by
 * cosim.world.kernels.fleet_library, which registers world.c's position checks and lidar sweep
 * with it (`fleet_use_world`): the fleet's judging and lidars call those of the world.c library
 * the rest of the run uses.
 *
 * Built by native/load.py (C99, -ffp-contract=off, no fast-math): every floating-point operation
 * is the one the Python docstrings describe, in the same order. */
#ifdef __linux__
#define _GNU_SOURCE /* sched_getcpu, pthread_setaffinity_np (and POSIX's pthreads under -std=c99) */
#include <sched.h>
#else
#define _POSIX_C_SOURCE 200809L /* pthreads and getpid under -std=c99 */
#endif
#include <math.h>
#include <pthread.h>
#include <stdint.h>
#include <stdlib.h>
#include <unistd.h>

#include "geometry.h"
#include "pyhypot.h"
#include "world.h"
#include "../../../planner/native/layout.h"

/* world.c's functions, registered once before any call here. */
static int64_t (*check_positions)(Monitor *m, int64_t n);
static void (*sweep)(const Lidar *s, double x, double y, double theta);

void fleet_use_world(int64_t (*check)(Monitor *m, int64_t n), void (*scan)(const Lidar *s, double x, double y, double theta))
{
    check_positions = check;
    sweep = scan;
}

/* ------------------------------------------------------------- fleet contacts (fleet.py) */

/* `FleetContacts.steps`'s gaps: robots at positions[k] (steps + 1 rows of n x 2) before step k and
 * positions[k + 1] after it; for each step k and pair p (robots first[p], second[p]) the least gap
 * [m] over the step, gap[k * pairs + p] (the distance at the closest approach of the linearly
 * moving offset minus reach[p]), and the gap at the step's end, end_gap[k * pairs + p]. The
 * operations of the NumPy description it replaced, in its order, element by element: the offsets
 * b - a, w = d1 - d0, s* = -(d0.w) / (w.w) where w.w > 0 (else 0) clipped to [0, 1], then
 * hypot(d0 + s* w) - reach (hypot: NumPy's is the C library's).
 *
 * Both are +inf instead for a pair that is certainly farther apart during the step than
 * floor[a] and floor[b] and 0 (the callers' minimum clearances: such a gap changes neither, nor
 * any contact): on each axis the offset stays at least the smaller of its magnitudes at the ends
 * when it keeps its sign, and the distance is at least the larger axis's bound (taken 1e-12
 * relative low, far more than the rounding). */
/* The gap over the step and at its end of the robots a and b moving from before to after (the
 * rows of `fleet_gaps`), +inf both when certainly farther apart than floor_a, floor_b and 0. */
static inline void pair_gaps(const double *before, const double *after, int64_t a, int64_t b, double reach,
                             double floor_a, double floor_b, double *gap, double *end_gap)
{
    double d0x = before[2 * b] - before[2 * a], d0y = before[2 * b + 1] - before[2 * a + 1];
    double d1x = after[2 * b] - after[2 * a], d1y = after[2 * b + 1] - after[2 * a + 1];
    double low_x = d0x * d1x > 0.0 ? py_min(fabs(d0x), fabs(d1x)) : 0.0;
    double low_y = d0y * d1y > 0.0 ? py_min(fabs(d0y), fabs(d1y)) : 0.0;
    double low = py_max(low_x, low_y) * (1.0 - 1e-12) - reach;
    if (low > 0.0 && low > floor_a && low > floor_b) {
        *gap = INFINITY;
        *end_gap = INFINITY;
        return;
    }
    double wx = d1x - d0x, wy = d1y - d0y;
    double ww = wx * wx + wy * wy;
    double dw = d0x * wx + d0y * wy;
    double s_star = 0.0;
    if (ww > 0.0)
        s_star = -dw / ww;
    if (s_star < 0.0)
        s_star = 0.0;
    else if (s_star > 1.0)
        s_star = 1.0;
    *gap = hypot(d0x + s_star * wx, d0y + s_star * wy) - reach;
    *end_gap = hypot(d1x, d1y) - reach;
}

void fleet_gaps(const double *positions, int64_t steps, int64_t n, const int64_t *first, const int64_t *second,
                int64_t pairs, const double *reach, const double *floor_, double *gap, double *end_gap)
{
    for (int64_t k = 0; k < steps; k++) {
        const double *before = positions + 2 * n * k, *after = positions + 2 * n * (k + 1);
        for (int64_t p = 0; p < pairs; p++) {
            int64_t a = first[p], b = second[p];
            pair_gaps(before, after, a, b, reach[p], floor_[a], floor_[b], &gap[k * pairs + p],
                      &end_gap[k * pairs + p]);
        }
    }
}

/* NumPy's minimum: NaN when either is. */
static inline double nan_min(double a, double b)
{
    return isnan(a) || isnan(b) ? NAN : (b < a ? b : a);
}

/* `FleetContacts.steps` of fleet.py, the NumPy steps it replaced in one pass: `fleet_gaps` of the
 * steps (floors: the minimum clearances at the call), each pair's least gap into both robots'
 * min_clearance (NumPy's minimum), and the steps in which a contact began -- a gap <= 0 while the
 * pair was not touching (touching[p], 0 or 1, updated to whether its gap at each step's end is
 * <= 0) -- into began, (step, pair) in NumPy's nonzero order (by step, then pair). `floor_` is
 * scratch of n. Returns how many began (at most steps x pairs). */
int64_t fleet_contacts(const double *positions, int64_t steps, int64_t n, const int64_t *first,
                       const int64_t *second, int64_t pairs, const double *reach, double *min_clearance,
                       double *floor_, uint8_t *touching, int64_t *began)
{
    int64_t count = 0;
    for (int64_t r = 0; r < n; r++)
        floor_[r] = min_clearance[r];
    for (int64_t k = 0; k < steps; k++) {
        const double *before = positions + 2 * n * k, *after = positions + 2 * n * (k + 1);
        for (int64_t p = 0; p < pairs; p++) {
            int64_t a = first[p], b = second[p];
            double gap, end_gap;
            pair_gaps(before, after, a, b, reach[p], floor_[a], floor_[b], &gap, &end_gap);
            min_clearance[a] = nan_min(min_clearance[a], gap);
            min_clearance[b] = nan_min(min_clearance[b], gap);
            if (gap <= 0.0 && !touching[p]) {
                began[2 * count] = k;
                began[2 * count + 1] = p;
                count++;
            }
            touching[p] = end_gap <= 0.0;
        }
    }
    return count;
}

/* ------------------------------------------------------- judging a fleet's robots (fleet.py) */

/* One robot of `fleet_judge`: its position checks, the numbers of its outcome and of its deadlock
 * rule that a block's steps change (kept here from block to block while it is judged here), and
 * what ended its judging in the last block. */
typedef struct {
    Monitor *monitor; /* its `world_check_positions` (points for at least a block's steps) */
    int64_t active;   /* judged by `fleet_judge` (else left alone) */
    double last_x, last_y;                          /* out: the position after the last step judged */
    double distance, recovery_time, stopped_time;   /* its RobotOutcome's, added to */
    double deadlocked_at;                           /* its RobotOutcome's (NaN: None) */
    double best, best_time, progress_deadlocked_at; /* its Progress (NaN: None) */
    double deadlock_after, goal_x, goal_y;          /* the Progress's setting; the current goal */
    double time;                                    /* its monitor's outcome time: the last step checked */
    double stopped_speed, progress, recover;        /* fleet.py's STOPPED_SPEED, PROGRESS, MODE_RECOVER */
    double moved;          /* out: the distance moved in the step of the event */
    int64_t event, reason; /* out: that step (n: none) and why (CHECK_*) */
} Judge;

/* `_judge_block` of fleet.py for each active robot r of the block's n steps (starts robots x 2:
 * the positions before the first step; positions n x robots x 2 after each step, modes n x robots
 * the avoidance mode held in it, ends and lengths [s] of the steps), up to the step in which it
 * reached its goal or collided, or the step its checks leave to Python (CHECK_PYTHON: nothing of
 * that step taken into account), the same operations in the same order (Python's hypot): the
 * positions checked in one `world_check_positions` call, then per step the distance moved, the
 * recovery time, the stopped time and the deadlock rule (`Progress.update`; in the step of an
 * event its distance and recovery time only). A robot that ends so is no longer active; its index
 * goes to `ended`. Returns how many did. Its monitor must not read a moving world. */
int64_t fleet_judge(Judge *judges, int64_t robots, const double *starts, const double *positions,
                    const double *modes, const double *ends, const double *lengths, int64_t n, int64_t *ended)
{
    int64_t count = 0;
    for (int64_t r = 0; r < robots; r++) {
        Judge *j = judges + r;
        if (!j->active)
            continue;
        Monitor *m = j->monitor;
        if (n > m->capacity || n < 1) {
            j->last_x = starts[2 * r];
            j->last_y = starts[2 * r + 1];
            j->event = 0;
            j->reason = CHECK_PYTHON;
            j->active = 0;
            ended[count++] = r;
            continue;
        }
        double *xs = (double *)m->points, *ys = xs + m->capacity, *times = ys + m->capacity;
        for (int64_t k = 0; k < n; k++) {
            xs[k] = positions[2 * (k * robots + r)];
            ys[k] = positions[2 * (k * robots + r) + 1];
            times[k] = ends[k];
        }
        int64_t event = check_positions(m, n);
        int64_t reason = m->reason;
        int64_t stop = reason == CHECK_PYTHON ? event : (event < n ? event + 1 : n);
        double bx = starts[2 * r], by = starts[2 * r + 1], moved = 0.0;
        double distance = j->distance, recovery = j->recovery_time, stopped = j->stopped_time;
        double dead = j->deadlocked_at, best = j->best, best_time = j->best_time;
        double progress_dead = j->progress_deadlocked_at;
        for (int64_t k = 0; k < stop; k++) {
            double x = xs[k], y = ys[k], h = lengths[k];
            moved = py_hypot(x - bx, y - by);
            bx = x;
            by = y;
            distance += moved;
            if (modes[k * robots + r] == j->recover)
                recovery += h;
            if (k == event)
                break;
            if (moved < j->stopped_speed * h)
                stopped += h;
            double remaining = py_hypot(j->goal_x - x, j->goal_y - y), t = ends[k];
            if (remaining < best - j->progress) {
                best = remaining;
                best_time = t;
                progress_dead = NAN;
            } else if (isnan(progress_dead) && t - best_time >= j->deadlock_after - 1e-9) {
                progress_dead = best_time;
            }
            dead = progress_dead;
        }
        j->last_x = bx;
        j->last_y = by;
        j->distance = distance;
        j->recovery_time = recovery;
        j->stopped_time = stopped;
        j->deadlocked_at = dead;
        j->best = best;
        j->best_time = best_time;
        j->progress_deadlocked_at = progress_dead;
        j->moved = moved;
        j->event = event;
        j->reason = reason;
        if (reason == CHECK_GOING) {
            j->time = times[n - 1];
        } else {
            j->active = 0;
            ended[count++] = r;
        }
    }
    return count;
}

/* ------------------------------------ a fleet's Python components in one call a block (fleet.py) */

/* One copy of a gather: `count` values into consecutive inputs from outputs `stride` values apart,
 * each the connection's value: the output times `scale` when `multiply`, plus `offset` when `add`
 * (the operations of fast_loop.py's `transfer_expression`, without its no-op terms). */
typedef struct {
    const double *source;
    double *target;
    int64_t count, stride;
    int64_t multiply, add;
    double scale, offset;
} BlockCopy;

/* One Python component of `_PythonSteps` (fleet.py), in the master's order, or the copies into
 * the components that read them (BLOCK_COPIES, last): due at step k when k % period == 0, its
 * inputs gathered by copies[first_copy .. first_copy + copies), then stepped by its kind. */
typedef struct {
    int64_t period;
    int64_t kind; /* BLOCK_* */
    int64_t first_copy, copies;
    const Lidar *lidar;      /* BLOCK_LIDAR: its sweep's struct */
    const double *inputs;    /* BLOCK_LIDAR: its inputs x, y, theta, robots_x[j], robots_y[j] */
    double *robot_rows;      /* BLOCK_LIDAR: the other robots' circles (robots rows cx, cy, r) */
    int64_t robots;
    int64_t (*c_step)(void *, double); /* BLOCK_C_STEP: its C step (nonzero: Python goes on) */
    void *state;
} BlockStep;

enum { BLOCK_PYTHON = 0, BLOCK_LIDAR = 1, BLOCK_C_STEP = 2, BLOCK_COPIES = 3 };

/* One due component's gather, then its lidar sweep or C step; nonzero when its C step hands it to
 * Python. */
static int64_t block_step(const BlockStep *s, const BlockCopy *copies, double t)
{
    for (int64_t c = s->first_copy; c < s->first_copy + s->copies; c++) {
        const BlockCopy *copy = copies + c;
        const double *source = copy->source;
        double *target = copy->target;
        int64_t stride = copy->stride;
        if (!copy->multiply && !copy->add) {
            for (int64_t j = 0; j < copy->count; j++)
                target[j] = source[j * stride];
        } else {
            for (int64_t j = 0; j < copy->count; j++) {
                double value = source[j * stride];
                if (copy->multiply)
                    value = value * copy->scale;
                if (copy->add)
                    value = value + copy->offset;
                target[j] = value;
            }
        }
    }
    if (s->kind == BLOCK_LIDAR) {
        const double *in = s->inputs;
        for (int64_t j = 0; j < s->robots; j++) {
            s->robot_rows[3 * j] = in[3 + j];
            s->robot_rows[3 * j + 1] = in[3 + s->robots + j];
        }
        sweep(s->lidar, in[0], in[1], in[2]);
    } else if (s->kind == BLOCK_C_STEP) {
        return s->c_step(s->state, t) != 0;
    }
    return 0;
}

/* The steps of `n` components due at step k (time t [s]) from `start` on: for each, its gather,
 * then a lidar's step (`Lidar.step`: the other robots' circles at the positions on its inputs, a
 * sweep from the pose on them) or a C step (`PlannerComponent.kernel_step`). Returns the first
 * component Python must step (BLOCK_PYTHON: nothing of it done; BLOCK_C_STEP: gathered, its C step
 * handed over), or n when all are done. */
int64_t fleet_python_block(const BlockStep *steps, int64_t n, int64_t start, int64_t k, double t,
                           const BlockCopy *copies)
{
    for (int64_t i = start; i < n; i++) {
        const BlockStep *s = steps + i;
        if (k % s->period)
            continue;
        if (s->kind == BLOCK_PYTHON)
            return i;
        if (block_step(s, copies, t))
            return i;
    }
    return n;
}


/* ------------------------------- the same on the machine's cores (a fleet's robots side by side) */

/* Within one step k the due components fall into chains (`_BlockProgram.make`): a chain's
 * components read (through their gathers) only outputs of the FMUs, which no step of this call
 * writes, and of components of the same chain; each writes only its own inputs, outputs and state
 * (a lidar's circles, scratch and ranges; a planner's costmap, its scratch and step state); the
 * maps they share are read-only. So the chains may step side by side, each in the master's order on
 * one thread, up to its first component handed to Python. The hand-backs are returned one at a
 * time in the master's order, and a chain goes on after Python has stepped the one it handed back.
 * No two chains touch the same memory: each component's operations, and so its results, are those
 * of `fleet_python_block`, bit for bit. A component stepped by Python only (BLOCK_PYTHON) may read
 * anything: the chains before it are done before it is handed back, those after it start after. */

typedef struct BlockPool BlockPool;

/* `_BlockProgram`'s steps in chains, and the stretch of a step under way. */
typedef struct {
    const BlockStep *steps; /* n entries: the components in the master's order, the feeds last */
    int64_t n;
    const BlockCopy *copies;
    const int64_t *members; /* the chained entries (neither BLOCK_PYTHON nor the feeds), chain by chain */
    const int64_t *firsts;  /* chains + 1: chain c is members[firsts[c] .. firsts[c + 1]), in order */
    int64_t chains;
    int64_t *cursor;        /* chains, scratch: where each chain stopped (a hand-back, or `end`) */
    int64_t *due;           /* chains, scratch: the chains with a component due in the stretch */
    BlockPool *pool;        /* NULL: one thread */
    int64_t min_chains;     /* fewer chains due in a stretch: all stepped on the calling thread */
    /* The stretch under way (`open`): step k at t, the components up to `end` (a BLOCK_PYTHON
     * component due, or the feeds), the chains from `start` on. */
    int64_t open, k, start, end;
    double t;
} BlockProgram;

/* Chain c's due components from `from` up to the stretch's end: the first handed to Python, or
 * the end. */
static int64_t block_chain(const BlockProgram *p, int64_t c, int64_t from)
{
    for (int64_t m = p->firsts[c]; m < p->firsts[c + 1]; m++) {
        int64_t i = p->members[m];
        if (i < from)
            continue;
        if (i >= p->end)
            break;
        const BlockStep *s = p->steps + i;
        if (p->k % s->period)
            continue;
        if (block_step(s, p->copies, p->t))
            return i;
    }
    return p->end;
}

/* A call of the master's stepping kernel (`navcosim_step_kernel` of cosim/core/native/kernel.c,
 * reached through its address) on one set of its tables: `block_pool_kernels` runs a fleet's
 * kernel split by robots (fleet.py's `_SplitKernel`) on the pool's threads. */
typedef int64_t (*KernelCall)(int64_t, int64_t, int64_t, int64_t, int64_t, int64_t, const void *, int64_t *);
typedef struct {
    KernelCall function;
    int64_t first_step, steps, start_ns, h_ns;
    const void *tables;
    int64_t *result;
} KernelJob;

/* Worker threads (the calling thread is one more): a job is a program's due chains of a stretch,
 * each taken by whichever thread is free, or kernel calls (`kernels`, each taken so). Every field
 * is read and written under `lock`. */
struct BlockPool {
    pthread_mutex_t lock;
    pthread_cond_t wake, finished;
    pthread_t *threads;
    int64_t count;      /* the workers started */
    int64_t generation; /* counts the jobs: a worker sleeps until it changes, or `stop` */
    int stop;
    BlockProgram *job;
    KernelJob *kernels; /* a job of kernel calls (`block_pool_kernels`) instead of chains */
    int64_t due_count, front, back, done; /* the job's chains p->due[0 .. due_count): those left, done */
    pid_t pid;                      /* the process of the threads (a forked child has none) */
    int64_t away_from;              /* Linux: the CPU the workers are kept off (-1: none) */
};

/* Step the job's chains left, the calling thread from the first on, the workers from the last back
 * (each robot's memory mostly stays in one CPU's cache from step to step); called with the lock
 * held, returns with it held. */
/* One kernel call of `block_pool_kernels`. */
static void run_kernel_job(const KernelJob *call)
{
    call->function(call->first_step, call->steps, 0, call->start_ns, call->h_ns, 0, call->tables, call->result);
}

static void block_pool_take(BlockPool *pool, int caller)
{
    BlockProgram *p = pool->job;
    while (pool->front < pool->back) {
        int64_t task = caller ? pool->front++ : --pool->back;
        KernelJob *kernels = pool->kernels;
        pthread_mutex_unlock(&pool->lock);
        if (kernels)
            run_kernel_job(kernels + task);
        else
            p->cursor[p->due[task]] = block_chain(p, p->due[task], p->start);
        pthread_mutex_lock(&pool->lock);
        if (++pool->done == pool->due_count)
            pthread_cond_signal(&pool->finished);
    }
}

static void *block_worker(void *argument)
{
    BlockPool *pool = argument;
    pthread_mutex_lock(&pool->lock);
    int64_t seen = pool->generation;
    for (;;) {
        while (pool->generation == seen && !pool->stop)
            pthread_cond_wait(&pool->wake, &pool->lock);
        if (pool->stop)
            break;
        seen = pool->generation;
        block_pool_take(pool, 0);
    }
    pthread_mutex_unlock(&pool->lock);
    return NULL;
}

void block_pool_free(BlockPool *pool);

/* A pool of `workers` threads; NULL when none could be started. */
BlockPool *block_pool_new(int64_t workers)
{
    if (workers < 1)
        return NULL;
    BlockPool *pool = calloc(1, sizeof(BlockPool));
    if (!pool)
        return NULL;
    pool->threads = calloc((size_t)workers, sizeof(pthread_t));
    if (!pool->threads) {
        free(pool);
        return NULL;
    }
    pthread_mutex_init(&pool->lock, NULL);
    pthread_cond_init(&pool->wake, NULL);
    pthread_cond_init(&pool->finished, NULL);
    pool->pid = getpid();
    pool->away_from = -1;
    for (int64_t w = 0; w < workers; w++) {
        if (pthread_create(pool->threads + w, NULL, block_worker, pool) != 0)
            break;
        pool->count++;
    }
    if (!pool->count) {
        block_pool_free(pool);
        return NULL;
    }
    return pool;
}

/* Stops and joins the pool's threads (none in a forked child: only its memory is freed). */
void block_pool_free(BlockPool *pool)
{
    if (!pool)
        return;
    if (pool->pid == getpid()) {
        pthread_mutex_lock(&pool->lock);
        pool->stop = 1;
        pthread_cond_broadcast(&pool->wake);
        pthread_mutex_unlock(&pool->lock);
        for (int64_t w = 0; w < pool->count; w++)
            pthread_join(pool->threads[w], NULL);
        pthread_mutex_destroy(&pool->lock);
        pthread_cond_destroy(&pool->wake);
        pthread_cond_destroy(&pool->finished);
    }
    free(pool->threads);
    free(pool);
}

/* The workers kept off the calling thread's CPU: woken where it runs they would wait for it (the
 * scheduler places a woken thread beside its waker when no CPU is idle). */
static void block_pool_place(BlockPool *pool)
{
#ifdef __linux__
    int cpu = sched_getcpu();
    if (cpu >= 0 && cpu != pool->away_from) {
        cpu_set_t allowed;
        if (sched_getaffinity(0, sizeof allowed, &allowed) == 0 && CPU_COUNT(&allowed) > 1) {
            CPU_CLR(cpu, &allowed);
            for (int64_t w = 0; w < pool->count; w++)
                pthread_setaffinity_np(pool->threads[w], sizeof allowed, &allowed);
        }
        pool->away_from = cpu;
    }
#else
    (void)pool;
#endif
}

/* The pool's `n` tasks (the due chains of `job`, or the kernel calls `kernels`) on its workers and
 * this thread, returning once all are done. */
static void block_pool_run(BlockPool *pool, BlockProgram *job, KernelJob *kernels, int64_t n)
{
    block_pool_place(pool);
    pthread_mutex_lock(&pool->lock);
    pool->job = job;
    pool->kernels = kernels;
    pool->due_count = n;
    pool->front = pool->done = 0;
    pool->back = n;
    pool->generation++;
    pthread_cond_broadcast(&pool->wake);
    block_pool_take(pool, 1);
    while (pool->done < pool->due_count)
        pthread_cond_wait(&pool->finished, &pool->lock);
    pool->job = NULL;
    pool->kernels = NULL;
    pthread_mutex_unlock(&pool->lock);
}

/* The `n` kernel calls side by side, this thread taking them from the first on, the pool's workers
 * from the last back (all on this thread without a pool of this process); each call's result in
 * its own `result`. The calls must touch disjoint memory (tables, buffers, FMU instances). */
void block_pool_kernels(BlockPool *pool, KernelJob *calls, int64_t n)
{
    if (!pool || n < 2 || pool->pid != getpid()) {
        for (int64_t j = 0; j < n; j++)
            run_kernel_job(calls + j);
        return;
    }
    block_pool_run(pool, NULL, calls, n);
}

/* The chains of the stretch from p->start: the due ones on the pool's threads and this one (on this
 * one alone with fewer than p->min_chains, or no pool of this process), each to its first
 * hand-back. */
static void block_stretch(BlockProgram *p)
{
    int64_t due = 0;
    for (int64_t c = 0; c < p->chains; c++) {
        p->cursor[c] = p->end;
        for (int64_t m = p->firsts[c]; m < p->firsts[c + 1]; m++) {
            int64_t i = p->members[m];
            if (i >= p->start && i < p->end && !(p->k % p->steps[i].period)) {
                p->due[due++] = c;
                break;
            }
        }
    }
    BlockPool *pool = p->pool;
    if (!pool || due < p->min_chains || due < 2 || pool->pid != getpid()) {
        for (int64_t d = 0; d < due; d++)
            p->cursor[p->due[d]] = block_chain(p, p->due[d], p->start);
        return;
    }
    block_pool_run(pool, p, NULL, due);
}

/* The first chain's stop before the stretch's end (the next hand-back, in the master's order), or
 * the end. */
static int64_t block_next_hand_back(const BlockProgram *p)
{
    int64_t first = p->end;
    for (int64_t c = 0; c < p->chains; c++)
        if (p->cursor[c] < first)
            first = p->cursor[c];
    return first;
}

/* `fleet_python_block` for the program `p`, its chains side by side: the same returns (the index of
 * the next component Python must step, or n), the same calls from Python (`start` 0, then the
 * index after each returned). A chain that handed back the component before `start` goes on from
 * `start` (on this thread); the others' cursors stand. */
int64_t fleet_python_block_threads(BlockProgram *p, int64_t start, int64_t k, double t)
{
    int64_t n = p->n;
    if (start == 0 || p->k != k || p->t != t)
        p->open = 0;
    if (p->open) {
        for (int64_t c = 0; c < p->chains; c++)
            if (p->cursor[c] == start - 1)
                p->cursor[c] = block_chain(p, c, start);
    }
    for (;;) {
        if (p->open) {
            int64_t next = block_next_hand_back(p);
            if (next < p->end)
                return next;
            p->open = 0;
            start = p->end;
            if (start >= n - 1)
                break;
            return start; /* (a BLOCK_PYTHON component due: its index) */
        }
        int64_t end = start;
        while (end < n - 1 && !(p->steps[end].kind == BLOCK_PYTHON && !(k % p->steps[end].period)))
            end++;
        p->k = k;
        p->t = t;
        p->start = start;
        p->end = end;
        p->open = 1;
        block_stretch(p);
    }
    /* The feeds (the last entry, never handed back). */
    if (start < n && !(k % p->steps[n - 1].period))
        block_step(p->steps + n - 1, p->copies, t);
    return n;
}

/* The tables Python mirrors (see layout.h). */
int64_t navcosim_layout(const char **names, int64_t *values, int64_t capacity)
{
    int64_t n = 0;
    LAYOUT_SIZE(Judge);
    LAYOUT_FIELD(Judge, monitor);
    LAYOUT_FIELD(Judge, active);
    LAYOUT_FIELD(Judge, last_x);
    LAYOUT_FIELD(Judge, last_y);
    LAYOUT_FIELD(Judge, distance);
    LAYOUT_FIELD(Judge, recovery_time);
    LAYOUT_FIELD(Judge, stopped_time);
    LAYOUT_FIELD(Judge, deadlocked_at);
    LAYOUT_FIELD(Judge, best);
    LAYOUT_FIELD(Judge, best_time);
    LAYOUT_FIELD(Judge, progress_deadlocked_at);
    LAYOUT_FIELD(Judge, deadlock_after);
    LAYOUT_FIELD(Judge, goal_x);
    LAYOUT_FIELD(Judge, goal_y);
    LAYOUT_FIELD(Judge, time);
    LAYOUT_FIELD(Judge, stopped_speed);
    LAYOUT_FIELD(Judge, progress);
    LAYOUT_FIELD(Judge, recover);
    LAYOUT_FIELD(Judge, moved);
    LAYOUT_FIELD(Judge, event);
    LAYOUT_FIELD(Judge, reason);
    LAYOUT_SIZE(BlockCopy);
    LAYOUT_FIELD(BlockCopy, source);
    LAYOUT_FIELD(BlockCopy, target);
    LAYOUT_FIELD(BlockCopy, count);
    LAYOUT_FIELD(BlockCopy, stride);
    LAYOUT_FIELD(BlockCopy, multiply);
    LAYOUT_FIELD(BlockCopy, add);
    LAYOUT_FIELD(BlockCopy, scale);
    LAYOUT_FIELD(BlockCopy, offset);
    LAYOUT_SIZE(BlockStep);
    LAYOUT_FIELD(BlockStep, period);
    LAYOUT_FIELD(BlockStep, kind);
    LAYOUT_FIELD(BlockStep, first_copy);
    LAYOUT_FIELD(BlockStep, copies);
    LAYOUT_FIELD(BlockStep, lidar);
    LAYOUT_FIELD(BlockStep, inputs);
    LAYOUT_FIELD(BlockStep, robot_rows);
    LAYOUT_FIELD(BlockStep, robots);
    LAYOUT_FIELD(BlockStep, c_step);
    LAYOUT_FIELD(BlockStep, state);
    LAYOUT_SIZE(BlockProgram);
    LAYOUT_FIELD(BlockProgram, steps);
    LAYOUT_FIELD(BlockProgram, n);
    LAYOUT_FIELD(BlockProgram, copies);
    LAYOUT_FIELD(BlockProgram, members);
    LAYOUT_FIELD(BlockProgram, firsts);
    LAYOUT_FIELD(BlockProgram, chains);
    LAYOUT_FIELD(BlockProgram, cursor);
    LAYOUT_FIELD(BlockProgram, due);
    LAYOUT_FIELD(BlockProgram, pool);
    LAYOUT_FIELD(BlockProgram, min_chains);
    LAYOUT_FIELD(BlockProgram, open);
    LAYOUT_FIELD(BlockProgram, k);
    LAYOUT_FIELD(BlockProgram, start);
    LAYOUT_FIELD(BlockProgram, end);
    LAYOUT_FIELD(BlockProgram, t);
    LAYOUT_CONSTANT(BLOCK_PYTHON);
    LAYOUT_CONSTANT(BLOCK_LIDAR);
    LAYOUT_CONSTANT(BLOCK_C_STEP);
    LAYOUT_CONSTANT(BLOCK_COPIES);
    return n;
}
