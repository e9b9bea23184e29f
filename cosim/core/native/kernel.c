/* The master's stepping kernel (`cosim.core.kernel`): FMUs stepped by C calls, Python components
 * handed back, read from the tables of `cosim.core.fast_loop.KernelTables`.
 *
 * Every table is a C-contiguous NumPy array; addresses (FMI functions, instances, value arrays,
 * the components' float64 buffers) are stored as int64. The arithmetic is the master's Python
 * loop's, in its order (`value * scale + offset`, the integer time base divided once by 1e9), and
 * the library is built with -ffp-contract=off and no fast-math (`native/load.py`), so both loops
 * give bit-identical values. See kernel.py for the return codes and the tables' columns.
 */
#include <math.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <string.h>
#if !defined(_WIN32)
#include <errno.h>
#include <sys/socket.h>
#include <sys/types.h>
#endif
#include "../../../planner/native/layout.h"

/* Return codes (first element of the result). */
enum { DONE = 0, HAND_BACK = 1, WATCH = 2, FAILED = 3, POLL = 4 };

/* Columns of the component table. */
enum {
    C_KIND, C_PERIOD, C_VERSION, C_HANDLE, C_STEP, C_FLAGS, C_LAST_TIME, C_LINK_FIRST, C_LINK_COUNT,
    C_SET_FIRST, C_SET_COUNT, C_GET_FIRST, C_GET_COUNT, C_CHECK_FIRST, C_CHECK_COUNT,
    C_IN_ADDRESS, C_IN_COUNT, C_OUT_ADDRESS, C_OUT_COUNT, C_RECORD, C_RECORD_OFFSET,
    C_RECORD_IN_FIRST, C_RECORD_IN_COUNT, COMPONENT_COLUMNS
};
enum { KIND_IDLE = 0, KIND_NATIVE = 1, KIND_PYTHON = 2, KIND_SWEEP = 3 };

/* Columns of the transfer-group table. */
enum {
    G_KIND, G_FUNCTION, G_REFERENCES, G_REFERENCE_COUNT, G_VALUE_COUNT, G_VALUES, G_DIRECT,
    G_SLOT_FIRST, G_SLOT_COUNT, G_SENT, G_SENT_REFERENCES, G_RUNS, GROUP_COLUMNS
};
/* Columns of a change-only group's run table (G_RUNS): after its count, per run of its values the
 * first position, the end, the producer (component whose steps change them; -1: none in the kernel)
 * and that producer's stamp when the run was last compared. */
enum { RUN_FROM, RUN_TO, RUN_PRODUCER, RUN_SEEN, RUN_COLUMNS };
/* FMI value types of a group: REAL double, INTEGER int32, BOOLEAN int32 (FMI 2.0) or bool (FMI 3.0),
 * then FMI 3.0's other numeric types. An INT64/UINT64 value beyond 2^53, which a double may not hold,
 * is read as NaN: the output check (which covers those outputs) stops there and Python names it. */
enum {
    KIND_REAL = 0, KIND_INTEGER = 1, KIND_BOOLEAN = 2, KIND_FLOAT32, KIND_INT8, KIND_UINT8, KIND_INT16,
    KIND_UINT16, KIND_UINT32, KIND_INT64, KIND_UINT64
};

/* Every integer of magnitude up to this is a double. */
#define EXACT_INTEGER ((int64_t)1 << 53)

/* Most components whose table the kernel copies onto its stack. */
#define MAX_COPIED 64

/* Elements of the result. */
enum { R_CODE, R_STEP, R_POSITION, R_COMPONENT, R_CALL, R_STATUS, R_KIND, RESULT_SIZE };

/* fmi2Set/Get<T>(instance, value references, count, values). */
typedef int (*Transfer2)(void *, const void *, size_t, void *);
/* fmi3Set/Get<T>(instance, value references, count, values, value count). */
typedef int (*Transfer3)(void *, const void *, size_t, void *, size_t);
/* A component stepped by one C call on its inputs x, y, theta (the lidar's sweep, `lidar_scan` of
 * cosim/world/native/world.c): (its struct, x, y, theta); it writes its own outputs. */
typedef void (*Sweep)(const void *, double, double, double);
/* A Python component's C step (C_STEP of a KIND_PYTHON row, 0: none): (its state, t) -> 0 when it
 * stepped (the kernel records its row), 1 when it hands the step to Python (the kernel returns
 * HAND_BACK there; its Python step goes on from where the C step stopped). */
typedef int64_t (*PythonStep)(void *, double);
/* fmi2DoStep(instance, t, h, noSetFMUStatePriorToCurrentPoint). */
typedef int (*Step2)(void *, double, double, int);
/* fmi3DoStep(instance, t, h, noSetFMUStatePriorToCurrentPoint, &eventHandlingNeeded,
 * &terminateSimulation, &earlyReturn, &lastSuccessfulTime). */
typedef int (*Step3)(void *, double, double, bool, bool *, bool *, bool *, double *);

/* The tables of one system (kernel.py's `Tables`, filled once per `KernelTables`). */
typedef struct {
    int64_t n;                       /* components (rows of `components`) */
    const int64_t *components;       /* n x COMPONENT_COLUMNS */
    const double *step_sizes;        /* n: each component's step [s] */
    const int64_t *link_addresses;   /* links x 3: source address, target address, kind (`gather`) */
    const double *link_numbers;      /* links x 2: scale, offset */
    const int64_t *groups;           /* groups x GROUP_COLUMNS */
    const int64_t *slot_addresses;   /* slots: buffer address of each value of a group */
    const double *slot_scales;       /* slots */
    const int64_t *checks;           /* checks x 3: address, 1 = infinite only, slot */
    double *history;                 /* recorded rows, per component at its C_RECORD_OFFSET */
    int64_t *rows;                   /* n: rows recorded so far */
    const int64_t *watch_addresses;  /* 3: nonzero = watching; address of x; address of y */
    const double *watch_numbers;     /* 6: goal x, y, radius^2; free zone x, y, radius^2 */
    int64_t *stamps;                 /* n + 1: [0] kernel calls so far; [1 + i] steps of component i */
} Tables;

#if defined(__GNUC__)
#define HOT static inline __attribute__((always_inline))
#define APART static __attribute__((noinline))
#else
#define HOT static inline
#define APART static
#endif

#define AT(table, row, columns, column) ((table)[(row) * (columns) + (column)])
#define COMPONENT(t, i, column) AT((t)->components, (i), COMPONENT_COLUMNS, (column))
#define GROUP(t, g, column) AT((t)->groups, (g), GROUP_COLUMNS, (column))

static inline double load_f64(int64_t address) { return *(const double *)(intptr_t)address; }
static inline void store_f64(int64_t address, double value) { *(double *)(intptr_t)address = value; }
static inline void *pointer(int64_t address) { return (void *)(intptr_t)address; }

HOT int64_t transfer(int64_t function, int64_t handle, int64_t references, int64_t count,
                     int64_t values, int64_t value_count, int64_t version) {
    if (version == 2) {
        return ((Transfer2)(intptr_t)function)(pointer(handle), pointer(references), (size_t)count,
                                              pointer(values));
    }
    return ((Transfer3)(intptr_t)function)(pointer(handle), pointer(references), (size_t)count,
                                          pointer(values), (size_t)value_count);
}

/* A run of links (`gather`): count values to target, from source `stride` values apart. Not
 * inlined: `gather` is, in three places, and the library is compiled on a first run. */
APART void copy_run(double *target, const double *source, int64_t count, int64_t stride) {
    if (stride == 1) {
        memcpy(target, source, sizeof(double) * (size_t)count);
        return;
    }
    for (int64_t m = 0; m < count; m++) {
        target[m] = source[m * stride];
    }
}

/* Copy the component's connected inputs from their producers' outputs. A link of kind 3 is a run
 * of plain links to consecutive targets, from sources link_numbers[j * 2 + 1] values apart (1:
 * consecutive, 2: one column of a two-column array): link_numbers[j * 2] values. */
HOT void gather(const Tables *t, int64_t i) {
    int64_t first = COMPONENT(t, i, C_LINK_FIRST), end = first + COMPONENT(t, i, C_LINK_COUNT);
    for (int64_t j = first; j < end; j++) {
        const int64_t *link = &t->link_addresses[j * 3];
        if (link[2] == 3) {
            copy_run(pointer(link[1]), pointer(link[0]), (int64_t)t->link_numbers[j * 2],
                     (int64_t)t->link_numbers[j * 2 + 1]);
            continue;
        }
        double value = load_f64(link[0]);
        if (link[2] == 1) {
            value = value * t->link_numbers[j * 2];
        } else if (link[2] == 2) {
            value = value * t->link_numbers[j * 2] + t->link_numbers[j * 2 + 1];
        }
        store_f64(link[1], value);
    }
}

/* A setter group of float64 scalars (one value per reference) that sends only what changed: its
 * G_SENT array holds [0] the kernel call (t->stamps[0]) of its last comparison of every value, 0:
 * the rest is not valid, [1 .. count] the values last sent, [count + 1 .. 2 count] room for the
 * changed values, and G_SENT_REFERENCES room for their references. An FMU input keeps the value
 * last set (FMI 2.0 and 3.0: set before a step, held after), so setting a value again that is bit
 * for bit the one it holds does nothing, and leaving it out changes nothing. The caller forgets what
 * was sent (the flag to 0) whenever something else may have set the FMU's inputs or restored its
 * state: `run_blocks` does at its start, unless its caller says nothing else does (between its
 * kernel calls only Python components step). A failed call forgets what was sent.
 *
 * Within one kernel call a value changes only where the kernel's links copy a producer's output
 * that changed, which it does only when the producer steps: with a run table (G_RUNS, see
 * RUN_COLUMNS) the group compares every value at its first set of a call, then at each later set
 * only the runs whose producer stepped since they were last compared (t->stamps[1 + producer]):
 * a plan's 2000 waypoints from a planner stepped at 10 Hz, a scan's ranges between scans, values
 * no link of the kernel feeds, are not compared at each of an FMU's steps. */
#define SAME_RUN 32 /* values `set_changed` compares at once */

/* Compare the values [from, to) with the last sent: the changed ones (into `last` too) appended at
 * `m` to the changed values and their references; returns the new count. */
APART int64_t note_changes(const uint64_t *now, uint64_t *last, const uint32_t *references, int64_t from,
                           int64_t to, uint64_t *changed, uint32_t *changed_references, int64_t m) {
    for (int64_t start = from; start < to; start += SAME_RUN) {
        int64_t end = start + SAME_RUN < to ? start + SAME_RUN : to;
        if (memcmp(now + start, last + start, sizeof(double) * (size_t)(end - start)) == 0) {
            continue; /* the usual case for a plan's waypoints: one comparison of the whole run */
        }
        for (int64_t j = start; j < end; j++) {
            uint64_t value = now[j];
            if (value != last[j]) {
                last[j] = value;
                changed_references[m] = references[j];
                changed[m] = value;
                m += 1;
            }
        }
    }
    return m;
}

/* Every run's producer stamp as seen now (its values are compared, or sent, at this set). */
static inline void note_seen(const Tables *t, int64_t *runs) {
    for (int64_t r = 0; runs != NULL && r < runs[0]; r++) {
        int64_t *run = runs + 1 + r * RUN_COLUMNS;
        run[RUN_SEEN] = run[RUN_PRODUCER] >= 0 ? t->stamps[1 + run[RUN_PRODUCER]] : 0;
    }
}

/* Not inlined (see `copy_run`). */
APART int64_t set_changed(const Tables *t, int64_t g, int64_t handle, int64_t version, int64_t values) {
    int64_t count = GROUP(t, g, G_REFERENCE_COUNT);
    double *sent = pointer(GROUP(t, g, G_SENT));
    int64_t *runs = GROUP(t, g, G_RUNS) != 0 ? pointer(GROUP(t, g, G_RUNS)) : NULL;
    double call = (double)t->stamps[0];
    const uint64_t *now = pointer(values);
    uint64_t *last = (uint64_t *)(sent + 1);
    int64_t status;
    if (sent[0] == 0.0) {
        status = transfer(GROUP(t, g, G_FUNCTION), handle, GROUP(t, g, G_REFERENCES), count, values, count,
                          version);
        if (status <= 1) {
            memcpy(last, now, sizeof(double) * (size_t)count);
            sent[0] = call;
            note_seen(t, runs);
        }
        return status;
    }
    const uint32_t *references = pointer(GROUP(t, g, G_REFERENCES));
    uint32_t *changed_references = pointer(GROUP(t, g, G_SENT_REFERENCES));
    uint64_t *changed = last + count;
    int64_t m = 0;
    if (runs == NULL || sent[0] != call) { /* every value: no run table, or the call's first set */
        m = note_changes(now, last, references, 0, count, changed, changed_references, 0);
        sent[0] = call;
        note_seen(t, runs);
    } else {
        for (int64_t r = 0; r < runs[0]; r++) {
            int64_t *run = runs + 1 + r * RUN_COLUMNS;
            if (run[RUN_PRODUCER] < 0 || t->stamps[1 + run[RUN_PRODUCER]] == run[RUN_SEEN]) {
                continue;
            }
            run[RUN_SEEN] = t->stamps[1 + run[RUN_PRODUCER]];
            m = note_changes(now, last, references, run[RUN_FROM], run[RUN_TO], changed, changed_references, m);
        }
    }
    if (m == 0) {
        return 0;
    }
    status = transfer(GROUP(t, g, G_FUNCTION), handle, (int64_t)(intptr_t)changed_references, m,
                      (int64_t)(intptr_t)changed, m, version);
    if (status > 1) {
        sent[0] = 0.0;
    }
    return status;
}

/* A setter group's values into its FMI value array, converted (not inlined: `set_inputs` is, in
 * two places, and the library is compiled on a first run). */
APART void fill_values(const Tables *t, int64_t g, int64_t version) {
    int64_t kind = GROUP(t, g, G_KIND), values = GROUP(t, g, G_VALUES);
    int64_t first_slot = GROUP(t, g, G_SLOT_FIRST), count = GROUP(t, g, G_SLOT_COUNT);
    for (int64_t position = 0; position < count; position++) {
        int64_t s = first_slot + position;
        double value = load_f64(t->slot_addresses[s]);
        if (t->slot_scales[s] != 1.0) {
            value = value * t->slot_scales[s];
        }
        void *array = pointer(values);
        switch (kind) {
        case KIND_REAL: ((double *)array)[position] = value; break;
        case KIND_INTEGER: ((int32_t *)array)[position] = (int32_t)(int64_t)rint(value); break;
        case KIND_BOOLEAN:
            if (version == 2) {
                ((int32_t *)array)[position] = value != 0.0 ? 1 : 0;
            } else {
                ((uint8_t *)array)[position] = value != 0.0 ? 1 : 0;
            }
            break;
        case KIND_FLOAT32: ((float *)array)[position] = (float)value; break;
        case KIND_INT8: ((int8_t *)array)[position] = (int8_t)(int64_t)rint(value); break;
        case KIND_UINT8: ((uint8_t *)array)[position] = (uint8_t)(int64_t)rint(value); break;
        case KIND_INT16: ((int16_t *)array)[position] = (int16_t)(int64_t)rint(value); break;
        case KIND_UINT16: ((uint16_t *)array)[position] = (uint16_t)(int64_t)rint(value); break;
        case KIND_UINT32: ((uint32_t *)array)[position] = (uint32_t)(int64_t)rint(value); break;
        case KIND_INT64: ((int64_t *)array)[position] = (int64_t)rint(value); break;
        default: ((uint64_t *)array)[position] = (uint64_t)rint(value); break;
        }
    }
}

/* Copy the inputs into the FMI value arrays (converting), then call the setters: the status of
 * the first failing call (> 1, its group's kind in *kind), or 0. */
HOT int64_t set_inputs(const Tables *t, int64_t i, int64_t *kind_out) {
    int64_t handle = COMPONENT(t, i, C_HANDLE), version = COMPONENT(t, i, C_VERSION);
    int64_t first = COMPONENT(t, i, C_SET_FIRST), end = first + COMPONENT(t, i, C_SET_COUNT);
    for (int64_t g = first; g < end; g++) {
        int64_t kind = GROUP(t, g, G_KIND), values = GROUP(t, g, G_VALUES);
        if (GROUP(t, g, G_DIRECT) == 0) {
            fill_values(t, g, version);
        }
        int64_t status;
        if (GROUP(t, g, G_SENT) != 0) {
            status = set_changed(t, g, handle, version, values);
        } else {
            status = transfer(GROUP(t, g, G_FUNCTION), handle, GROUP(t, g, G_REFERENCES),
                              GROUP(t, g, G_REFERENCE_COUNT), values, GROUP(t, g, G_VALUE_COUNT), version);
        }
        if (status > 1) {
            *kind_out = kind;
            return status;
        }
    }
    return 0;
}

/* A getter group's FMI value array into the output buffer, converted (not inlined, as
 * `fill_values`). */
APART void read_values(const Tables *t, int64_t g, int64_t version) {
    int64_t kind = GROUP(t, g, G_KIND), values = GROUP(t, g, G_VALUES);
    int64_t first_slot = GROUP(t, g, G_SLOT_FIRST), count = GROUP(t, g, G_SLOT_COUNT);
    for (int64_t position = 0; position < count; position++) {
        int64_t s = first_slot + position;
        double value;
        const void *array = pointer(values);
        switch (kind) {
        case KIND_REAL: value = ((const double *)array)[position]; break;
        case KIND_INTEGER: value = (double)((const int32_t *)array)[position]; break;
        case KIND_BOOLEAN:
            value = version == 2 ? (double)((const int32_t *)array)[position]
                                 : (double)((const uint8_t *)array)[position];
            break;
        case KIND_FLOAT32: value = (double)((const float *)array)[position]; break;
        case KIND_INT8: value = (double)((const int8_t *)array)[position]; break;
        case KIND_UINT8: value = (double)((const uint8_t *)array)[position]; break;
        case KIND_INT16: value = (double)((const int16_t *)array)[position]; break;
        case KIND_UINT16: value = (double)((const uint16_t *)array)[position]; break;
        case KIND_UINT32: value = (double)((const uint32_t *)array)[position]; break;
        case KIND_INT64: {
            int64_t number = ((const int64_t *)array)[position];
            value = number > EXACT_INTEGER || number < -EXACT_INTEGER ? NAN : (double)number;
            break;
        }
        default: {
            uint64_t number = ((const uint64_t *)array)[position];
            value = number > (uint64_t)EXACT_INTEGER ? NAN : (double)number;
            break;
        }
        }
        if (t->slot_scales[s] != 1.0) {
            value = value * t->slot_scales[s];
        }
        store_f64(t->slot_addresses[s], value);
    }
}

/* Call the getters, then copy the FMI value arrays into the output buffer (converting). */
HOT int64_t get_outputs(const Tables *t, int64_t i, int64_t *kind_out) {
    int64_t handle = COMPONENT(t, i, C_HANDLE), version = COMPONENT(t, i, C_VERSION);
    int64_t first = COMPONENT(t, i, C_GET_FIRST), end = first + COMPONENT(t, i, C_GET_COUNT);
    for (int64_t g = first; g < end; g++) {
        int64_t kind = GROUP(t, g, G_KIND), values = GROUP(t, g, G_VALUES);
        int64_t status = transfer(GROUP(t, g, G_FUNCTION), handle, GROUP(t, g, G_REFERENCES),
                                  GROUP(t, g, G_REFERENCE_COUNT), values, GROUP(t, g, G_VALUE_COUNT),
                                  version);
        if (status > 1) {
            *kind_out = kind;
            return status;
        }
        if (GROUP(t, g, G_DIRECT) == 0) {
            read_values(t, g, version);
        }
    }
    return 0;
}

/* Slot of the first checked output that is NaN or infinite (infinite only when the check says
 * so), or -1. value - value is NaN exactly when value is NaN or infinite, so the usual case (a
 * finite value) costs one subtraction and one comparison, without reading the check's kind. */
HOT int64_t check_outputs(const Tables *t, int64_t i) {
    int64_t first = COMPONENT(t, i, C_CHECK_FIRST), end = first + COMPONENT(t, i, C_CHECK_COUNT);
    const int64_t *checks = t->checks;
    for (int64_t c = first; c < end; c++) {
        double value = load_f64(checks[c * 3]);
        if (value - value != 0.0 && (checks[c * 3 + 1] == 0 || fabs(value) == INFINITY)) {
            return checks[c * 3 + 2];
        }
    }
    return -1;
}

/* Keep the component's inputs then outputs as its next row: of the inputs those from
 * C_RECORD_IN_FIRST, C_RECORD_IN_COUNT of them (all, or the scalars: the other columns are left as
 * they were). */
HOT void record(const Tables *t, int64_t i) {
    if (COMPONENT(t, i, C_RECORD) == 0) {
        return;
    }
    int64_t n_in = COMPONENT(t, i, C_IN_COUNT), n_out = COMPONENT(t, i, C_OUT_COUNT);
    int64_t in_first = COMPONENT(t, i, C_RECORD_IN_FIRST), in_count = COMPONENT(t, i, C_RECORD_IN_COUNT);
    double *row = t->history + COMPONENT(t, i, C_RECORD_OFFSET) + t->rows[i] * (n_in + n_out);
    const double *inputs = pointer(COMPONENT(t, i, C_IN_ADDRESS));
    const double *outputs = pointer(COMPONENT(t, i, C_OUT_ADDRESS));
    memcpy(row + in_first, inputs + in_first, sizeof(double) * (size_t)in_count);
    memcpy(row + n_in, outputs, sizeof(double) * (size_t)n_out);
    t->rows[i] += 1;
}

/* doStep, then FMI 3.0's terminateSimulation flag: the failing call (1 doStep, 3 asked to
 * terminate) with its status, or -1. */
HOT int64_t advance(const Tables *t, int64_t i, double time, double h, int64_t *status_out) {
    int64_t handle = COMPONENT(t, i, C_HANDLE), function = COMPONENT(t, i, C_STEP);
    int64_t status;
    if (COMPONENT(t, i, C_VERSION) == 2) {
        status = ((Step2)(intptr_t)function)(pointer(handle), time, h, 1);
    } else {
        bool *flags = pointer(COMPONENT(t, i, C_FLAGS));
        status = ((Step3)(intptr_t)function)(pointer(handle), time, h, true, flags, flags + 1, flags + 2,
                                            pointer(COMPONENT(t, i, C_LAST_TIME)));
    }
    if (status > 1) {
        *status_out = status;
        return 1;
    }
    if (COMPONENT(t, i, C_VERSION) == 3 && ((const uint8_t *)pointer(COMPONENT(t, i, C_FLAGS)))[1] != 0) {
        *status_out = 0;
        return 3;
    }
    return -1;
}

HOT int64_t finish(int64_t *result, int64_t code, int64_t step, int64_t position, int64_t component,
                      int64_t call, int64_t status, int64_t kind) {
    result[R_CODE] = code;
    result[R_STEP] = step;
    result[R_POSITION] = position;
    result[R_COMPONENT] = component;
    result[R_CALL] = call;
    result[R_STATUS] = status;
    result[R_KIND] = kind;
    return code;
}

/* Set inputs, step, get and check outputs, record: FAILED (result filled) or DONE. */
HOT int64_t step_native(const Tables *t, int64_t i, int64_t k, double time, int64_t *result,
                           bool set_first) {
    int64_t status = 0, kind = 0, call;
    if (set_first) {
        status = set_inputs(t, i, &kind);
        if (status > 1) {
            return finish(result, FAILED, k, i, i, 0, status, kind);
        }
    }
    call = advance(t, i, time, t->step_sizes[i], &status);
    if (call >= 0) {
        return finish(result, FAILED, k, i, i, call, status, 0);
    }
    status = get_outputs(t, i, &kind);
    if (status > 1) {
        return finish(result, FAILED, k, i, i, 2, status, kind);
    }
    int64_t slot = check_outputs(t, i);
    if (slot >= 0) {
        return finish(result, FAILED, k, i, i, 4, slot, 0);
    }
    t->stamps[1 + i] += 1;
    record(t, i);
    return DONE;
}

/* A sweep component's step: its C call on its first three inputs, then its row. */
HOT void step_sweep(const Tables *t, int64_t i) {
    const double *inputs = pointer(COMPONENT(t, i, C_IN_ADDRESS));
    ((Sweep)(intptr_t)COMPONENT(t, i, C_STEP))(pointer(COMPONENT(t, i, C_HANDLE)), inputs[0], inputs[1], inputs[2]);
    t->stamps[1 + i] += 1;
    record(t, i);
}

/* Whether a signal came: the socket `fd` (Python's signal wakeup socket, `cosim.core.interrupt`)
 * holds a byte, which stays for Python to take. A polled sweep with C_FLAGS 2 (its C_LAST_TIME the
 * socket) returns only then: where a sweep with C_FLAGS 1 returns each time for the caller to look
 * for a signal, and finds one exactly when the socket holds a byte. Without sockets: always. */
static bool signal_came(int64_t fd) {
#if defined(_WIN32)
    (void)fd;
    return true;
#else
    char byte;
    return recv((int)fd, &byte, 1, MSG_PEEK | MSG_DONTWAIT) != -1 || (errno != EAGAIN && errno != EWOULDBLOCK);
#endif
}

/* Whether the watched position has used half of the free circle (its centre's distance at least
 * half the radius, or not finite), where the caller's look (`before_block` of `run_blocks`: the
 * robot run's `SafeCircle.watch`) draws a new circle round it: a polled sweep with C_FLAGS 2
 * returns then too, so the circle is drawn again where a sweep with C_FLAGS 1 had it drawn. */
static bool circle_half_used(const Tables *t) {
    if (t->watch_addresses[0] == 0) {
        return false;
    }
    double dx = load_f64(t->watch_addresses[1]) - t->watch_numbers[3];
    double dy = load_f64(t->watch_addresses[2]) - t->watch_numbers[4];
    return !(4.0 * (dx * dx + dy * dy) < t->watch_numbers[5]);
}

/* A Python component's C step (C_STEP): its inputs gathered, the call, its row when it stepped;
 * the call's result (0: stepped, else Python's). */
APART int64_t step_python(const Tables *t, int64_t i, double time) {
    gather(t, i);
    int64_t handed = ((PythonStep)(intptr_t)COMPONENT(t, i, C_STEP))(pointer(COMPONENT(t, i, C_HANDLE)), time);
    t->stamps[1 + i] += 1; /* its outputs may have changed (handed back or not) */
    if (handed == 0) {
        record(t, i);
    }
    return handed;
}

/* Whether component i steps at step k (k % period == 0; a 64-bit division costs tens of cycles,
 * so not for the components stepped every step). */
HOT bool due(const Tables *t, int64_t i, int64_t k) {
    int64_t period = COMPONENT(t, i, C_PERIOD);
    return period == 1 || k % period == 0;
}

/* Step from component `first_position` of step `first_step` up to the end of step
 * `first_step + steps - 1`; the result (7 int64) as kernel.py's `step_kernel` returns it. */
int64_t navcosim_step_kernel(int64_t first_step, int64_t steps, int64_t first_position, int64_t start_ns,
                             int64_t h_ns, int64_t jacobi, const Tables *tables, int64_t *result) {
    /* Copies the FMI calls cannot reach (their addresses never leave this function), so the
     * compiler need not read them again after each call: the tables' pointers, and the component
     * table of a plan of up to MAX_COPIED components (on the stack). */
    Tables local = *tables;
    int64_t n = local.n;
    int64_t components[MAX_COPIED * COMPONENT_COLUMNS];
    if (n <= MAX_COPIED) {
        memcpy(components, tables->components, sizeof(int64_t) * (size_t)(n * COMPONENT_COLUMNS));
        local.components = components;
    }
    const Tables *t = &local;
    t->stamps[0] += 1; /* a new call: each change-only group compares every value once (`set_changed`) */
    int64_t k = first_step;
    int64_t position = first_position;
    int64_t end = first_step + steps;
    bool watching = t->watch_addresses[0] != 0;
    while (k < end) {
        result[R_STEP] = k; /* the step under way, for a caller whose FMU ends the process in it */
        double time = (double)(start_ns + k * h_ns) / 1e9;
        if (jacobi) {
            for (int64_t i = 0; i < n; i++) {
                if (COMPONENT(t, i, C_KIND) != KIND_IDLE && due(t, i, k)) {
                    if (COMPONENT(t, i, C_KIND) == KIND_PYTHON) {
                        return finish(result, HAND_BACK, k, i, i, 0, 0, 0);
                    }
                    gather(t, i);
                    if (COMPONENT(t, i, C_KIND) == KIND_SWEEP) {
                        continue;
                    }
                    int64_t kind = 0, status = set_inputs(t, i, &kind);
                    if (status > 1) {
                        return finish(result, FAILED, k, i, i, 0, status, kind);
                    }
                }
            }
            for (int64_t i = 0; i < n; i++) {
                if (COMPONENT(t, i, C_KIND) == KIND_NATIVE && due(t, i, k)) {
                    if (step_native(t, i, k, time, result, false) == FAILED) {
                        return FAILED;
                    }
                } else if (COMPONENT(t, i, C_KIND) == KIND_SWEEP && due(t, i, k)) {
                    step_sweep(t, i);
                }
            }
        } else {
            while (position < n) {
                int64_t i = position;
                if (COMPONENT(t, i, C_KIND) != KIND_IDLE && due(t, i, k)) {
                    if (COMPONENT(t, i, C_KIND) == KIND_PYTHON) {
                        if (COMPONENT(t, i, C_STEP) == 0) {
                            return finish(result, HAND_BACK, k, i, i, 0, 0, 0);
                        }
                        if (step_python(t, i, time) != 0) {
                            return finish(result, HAND_BACK, k, i, i, 0, 0, 0);
                        }
                        position += 1;
                        continue;
                    }
                    /* A polled sweep (C_FLAGS 1; 2: only when a signal came): the caller looks
                     * first, unless the call starts here. */
                    if (COMPONENT(t, i, C_KIND) == KIND_SWEEP && COMPONENT(t, i, C_FLAGS) != 0 &&
                        (k != first_step || i != first_position) &&
                        (COMPONENT(t, i, C_FLAGS) == 1 || signal_came(COMPONENT(t, i, C_LAST_TIME)) ||
                         circle_half_used(t))) {
                        return finish(result, POLL, k, i, i, 0, 0, 0);
                    }
                    gather(t, i);
                    if (COMPONENT(t, i, C_KIND) == KIND_SWEEP) {
                        step_sweep(t, i);
                    } else if (step_native(t, i, k, time, result, true) == FAILED) {
                        return FAILED;
                    }
                }
                position += 1;
            }
        }
        position = 0;
        k += 1;
        if (watching) {
            double x = load_f64(t->watch_addresses[1]);
            double y = load_f64(t->watch_addresses[2]);
            if (x - x != 0.0 || y - y != 0.0) {
                return finish(result, WATCH, k, 0, -1, 0, 0, 0);
            }
            double dx = x - t->watch_numbers[0], dy = y - t->watch_numbers[1];
            if (dx * dx + dy * dy <= t->watch_numbers[2]) {
                return finish(result, WATCH, k, 0, -1, 0, 0, 0);
            }
            dx = x - t->watch_numbers[3];
            dy = y - t->watch_numbers[4];
            if (dx * dx + dy * dy >= t->watch_numbers[5]) {
                return finish(result, WATCH, k, 0, -1, 0, 0, 0);
            }
        }
    }
    return finish(result, DONE, k, 0, -1, 0, 0, 0);
}

/* ---- The recording's message records (`cosim.core.kernel.pack_records`) ----------------------
 * A block of held messages becomes MCAP Message records here, in write order, with the bytes the
 * per-message path writes: a record of a fixed-layout stream (a /signals channel, /odom, /tf,
 * /pose) is its template (head and CDR payload) with the head's sequence, log and publish time,
 * the payload's stamps (int32 sec, uint32 nanosec of the time) and its float64 fields written in;
 * a raw message (any other payload) is a head and its payload bytes. */

/* MCAP Message record: opcode u8, record length u64, channel u16, sequence u32, log time u64,
 * publish time u64 (packed, little-endian), then the payload. */
enum {
    MESSAGE_HEAD_BYTES = 31, MESSAGE_FIELD_BYTES = 22, HEAD_LENGTH = 1, HEAD_CHANNEL = 9,
    HEAD_SEQUENCE = 11, HEAD_LOG_TIME = 15, HEAD_PUBLISH_TIME = 23, OPCODE_MESSAGE = 5
};
/* Columns of the stream table (one row per stream number of the block). */
enum {
    P_KIND, P_CHANNEL, P_SEQUENCE, P_SIZE, P_TEMPLATE, P_TIMES, P_MATRIX, P_MATRIX_COLUMNS,
    P_STAMP_COUNT, P_STAMP_FIRST, P_STAMP_SECOND, P_FIELD_FIRST, P_FIELD_COUNT, STREAM_COLUMNS
};
enum { STREAM_NONE = 0, STREAM_FIXED = 1, STREAM_RAW = 2 };
/* Most streams of one block (signal channels, the pose's three, raw). */
enum { MAX_STREAMS = 1024 };
/* Columns of the field table: the record's byte offset, the matrix column, how many float64. */
enum { F_OFFSET, F_COLUMN, F_COUNT, FIELD_COLUMNS };
/* Columns of the raw table (one row per raw message, in the order they were held). */
enum { RAW_CHANNEL, RAW_SEQUENCE, RAW_TIME, RAW_START, RAW_SIZE, RAW_COLUMNS };

static inline void put_u64(uint8_t *at, uint64_t value) { memcpy(at, &value, 8); }
static inline void put_u32(uint8_t *at, uint32_t value) { memcpy(at, &value, 4); }
static inline void put_u16(uint8_t *at, uint16_t value) { memcpy(at, &value, 2); }

/* Message records of the `n` messages whose stream numbers `order` lists, into `out` (`capacity`
 * bytes): each message's byte offset, channel and log time into `offsets`, `channels`, `times`.
 * The i-th message of a stream takes the stream's i-th time and matrix row (the i-th raw message
 * the raw table's i-th row); sequences count up from each stream's first. Returns the bytes
 * written, or -1 when they would not fit or a stream number has no stream. */
int64_t navcosim_pack_records(int64_t n, const int64_t *order, int64_t stream_count, const int64_t *streams,
                              const int64_t *fields, const int64_t *raw, const uint8_t *blob,
                              uint8_t *out, int64_t capacity, int64_t *offsets, int64_t *channels,
                              uint64_t *times) {
    int64_t cursor[MAX_STREAMS];
    if (stream_count > MAX_STREAMS) {
        return -1;
    }
    memset(cursor, 0, sizeof(cursor));
    int64_t raw_cursor = 0, at = 0;
    for (int64_t i = 0; i < n; i++) {
        int64_t s = order[i];
        if (s < 0 || s >= stream_count) {
            return -1;
        }
        const int64_t *stream = &streams[s * STREAM_COLUMNS];
        uint8_t *record = out + at;
        if (stream[P_KIND] == STREAM_RAW) {
            const int64_t *message = &raw[raw_cursor * RAW_COLUMNS];
            raw_cursor += 1;
            int64_t size = message[RAW_SIZE];
            if (at + MESSAGE_HEAD_BYTES + size > capacity) {
                return -1;
            }
            uint64_t t = (uint64_t)message[RAW_TIME];
            record[0] = OPCODE_MESSAGE;
            put_u64(record + HEAD_LENGTH, (uint64_t)(MESSAGE_FIELD_BYTES + size));
            put_u16(record + HEAD_CHANNEL, (uint16_t)message[RAW_CHANNEL]);
            put_u32(record + HEAD_SEQUENCE, (uint32_t)message[RAW_SEQUENCE]);
            put_u64(record + HEAD_LOG_TIME, t);
            put_u64(record + HEAD_PUBLISH_TIME, t);
            memcpy(record + MESSAGE_HEAD_BYTES, blob + message[RAW_START], (size_t)size);
            offsets[i] = at;
            channels[i] = message[RAW_CHANNEL];
            times[i] = t;
            at += MESSAGE_HEAD_BYTES + size;
            continue;
        }
        if (stream[P_KIND] != STREAM_FIXED) {
            return -1;
        }
        int64_t size = stream[P_SIZE];
        if (at + size > capacity) {
            return -1;
        }
        int64_t row = cursor[s]++;
        uint64_t t = ((const uint64_t *)pointer(stream[P_TIMES]))[row];
        memcpy(record, pointer(stream[P_TEMPLATE]), (size_t)size);
        put_u32(record + HEAD_SEQUENCE, (uint32_t)(stream[P_SEQUENCE] + row));
        put_u64(record + HEAD_LOG_TIME, t);
        put_u64(record + HEAD_PUBLISH_TIME, t);
        uint32_t sec = (uint32_t)(int32_t)(t / 1000000000u), nanosec = (uint32_t)(t % 1000000000u);
        for (int64_t j = 0; j < stream[P_STAMP_COUNT]; j++) {
            int64_t offset = stream[P_STAMP_FIRST + j];
            put_u32(record + offset, sec);
            put_u32(record + offset + 4, nanosec);
        }
        const double *values = (const double *)pointer(stream[P_MATRIX]) + row * stream[P_MATRIX_COLUMNS];
        int64_t first = stream[P_FIELD_FIRST], end = first + stream[P_FIELD_COUNT];
        for (int64_t f = first; f < end; f++) {
            const int64_t *field = &fields[f * FIELD_COLUMNS];
            memcpy(record + field[F_OFFSET], values + field[F_COLUMN], (size_t)(8 * field[F_COUNT]));
        }
        offsets[i] = at;
        channels[i] = stream[P_CHANNEL];
        times[i] = t;
        at += size;
    }
    return at;
}

/* sizeof(Tables), so the Python side can check its mirror of the struct. */
int64_t navcosim_tables_size(void) { return (int64_t)sizeof(Tables); }

/* The tables Python mirrors (see layout.h). */
int64_t navcosim_layout(const char **names, int64_t *values, int64_t capacity)
{
    int64_t n = 0;
    LAYOUT_SIZE(Tables);
    LAYOUT_FIELD(Tables, n);
    LAYOUT_FIELD(Tables, components);
    LAYOUT_FIELD(Tables, step_sizes);
    LAYOUT_FIELD(Tables, link_addresses);
    LAYOUT_FIELD(Tables, link_numbers);
    LAYOUT_FIELD(Tables, groups);
    LAYOUT_FIELD(Tables, slot_addresses);
    LAYOUT_FIELD(Tables, slot_scales);
    LAYOUT_FIELD(Tables, checks);
    LAYOUT_FIELD(Tables, history);
    LAYOUT_FIELD(Tables, rows);
    LAYOUT_FIELD(Tables, watch_addresses);
    LAYOUT_FIELD(Tables, watch_numbers);
    LAYOUT_FIELD(Tables, stamps);
    LAYOUT_CONSTANT(DONE);
    LAYOUT_CONSTANT(HAND_BACK);
    LAYOUT_CONSTANT(WATCH);
    LAYOUT_CONSTANT(FAILED);
    LAYOUT_CONSTANT(POLL);
    LAYOUT_CONSTANT(C_KIND);
    LAYOUT_CONSTANT(C_PERIOD);
    LAYOUT_CONSTANT(C_VERSION);
    LAYOUT_CONSTANT(C_HANDLE);
    LAYOUT_CONSTANT(C_STEP);
    LAYOUT_CONSTANT(C_FLAGS);
    LAYOUT_CONSTANT(C_LAST_TIME);
    LAYOUT_CONSTANT(C_LINK_FIRST);
    LAYOUT_CONSTANT(C_LINK_COUNT);
    LAYOUT_CONSTANT(C_SET_FIRST);
    LAYOUT_CONSTANT(C_SET_COUNT);
    LAYOUT_CONSTANT(C_GET_FIRST);
    LAYOUT_CONSTANT(C_GET_COUNT);
    LAYOUT_CONSTANT(C_CHECK_FIRST);
    LAYOUT_CONSTANT(C_CHECK_COUNT);
    LAYOUT_CONSTANT(C_IN_ADDRESS);
    LAYOUT_CONSTANT(C_IN_COUNT);
    LAYOUT_CONSTANT(C_OUT_ADDRESS);
    LAYOUT_CONSTANT(C_OUT_COUNT);
    LAYOUT_CONSTANT(C_RECORD);
    LAYOUT_CONSTANT(C_RECORD_OFFSET);
    LAYOUT_CONSTANT(C_RECORD_IN_FIRST);
    LAYOUT_CONSTANT(C_RECORD_IN_COUNT);
    LAYOUT_CONSTANT(COMPONENT_COLUMNS);
    LAYOUT_CONSTANT(KIND_IDLE);
    LAYOUT_CONSTANT(KIND_NATIVE);
    LAYOUT_CONSTANT(KIND_PYTHON);
    LAYOUT_CONSTANT(KIND_SWEEP);
    LAYOUT_CONSTANT(G_KIND);
    LAYOUT_CONSTANT(G_FUNCTION);
    LAYOUT_CONSTANT(G_REFERENCES);
    LAYOUT_CONSTANT(G_REFERENCE_COUNT);
    LAYOUT_CONSTANT(G_VALUE_COUNT);
    LAYOUT_CONSTANT(G_VALUES);
    LAYOUT_CONSTANT(G_DIRECT);
    LAYOUT_CONSTANT(G_SLOT_FIRST);
    LAYOUT_CONSTANT(G_SLOT_COUNT);
    LAYOUT_CONSTANT(G_SENT);
    LAYOUT_CONSTANT(G_SENT_REFERENCES);
    LAYOUT_CONSTANT(G_RUNS);
    LAYOUT_CONSTANT(RUN_FROM);
    LAYOUT_CONSTANT(RUN_TO);
    LAYOUT_CONSTANT(RUN_PRODUCER);
    LAYOUT_CONSTANT(RUN_SEEN);
    LAYOUT_CONSTANT(RUN_COLUMNS);
    LAYOUT_CONSTANT(GROUP_COLUMNS);
    LAYOUT_CONSTANT(KIND_REAL);
    LAYOUT_CONSTANT(KIND_INTEGER);
    LAYOUT_CONSTANT(KIND_BOOLEAN);
    LAYOUT_CONSTANT(KIND_FLOAT32);
    LAYOUT_CONSTANT(KIND_INT8);
    LAYOUT_CONSTANT(KIND_UINT8);
    LAYOUT_CONSTANT(KIND_INT16);
    LAYOUT_CONSTANT(KIND_UINT16);
    LAYOUT_CONSTANT(KIND_UINT32);
    LAYOUT_CONSTANT(KIND_INT64);
    LAYOUT_CONSTANT(KIND_UINT64);
    LAYOUT_CONSTANT(RESULT_SIZE);
    LAYOUT_CONSTANT(MESSAGE_HEAD_BYTES);
    LAYOUT_CONSTANT(MESSAGE_FIELD_BYTES);
    LAYOUT_CONSTANT(HEAD_LENGTH);
    LAYOUT_CONSTANT(HEAD_CHANNEL);
    LAYOUT_CONSTANT(HEAD_SEQUENCE);
    LAYOUT_CONSTANT(HEAD_LOG_TIME);
    LAYOUT_CONSTANT(HEAD_PUBLISH_TIME);
    LAYOUT_CONSTANT(OPCODE_MESSAGE);
    LAYOUT_CONSTANT(P_KIND);
    LAYOUT_CONSTANT(P_CHANNEL);
    LAYOUT_CONSTANT(P_SEQUENCE);
    LAYOUT_CONSTANT(P_SIZE);
    LAYOUT_CONSTANT(P_TEMPLATE);
    LAYOUT_CONSTANT(P_TIMES);
    LAYOUT_CONSTANT(P_MATRIX);
    LAYOUT_CONSTANT(P_MATRIX_COLUMNS);
    LAYOUT_CONSTANT(P_STAMP_COUNT);
    LAYOUT_CONSTANT(P_STAMP_FIRST);
    LAYOUT_CONSTANT(P_STAMP_SECOND);
    LAYOUT_CONSTANT(P_FIELD_FIRST);
    LAYOUT_CONSTANT(P_FIELD_COUNT);
    LAYOUT_CONSTANT(STREAM_COLUMNS);
    LAYOUT_CONSTANT(STREAM_NONE);
    LAYOUT_CONSTANT(STREAM_FIXED);
    LAYOUT_CONSTANT(STREAM_RAW);
    LAYOUT_CONSTANT(F_OFFSET);
    LAYOUT_CONSTANT(F_COLUMN);
    LAYOUT_CONSTANT(F_COUNT);
    LAYOUT_CONSTANT(FIELD_COLUMNS);
    LAYOUT_CONSTANT(RAW_CHANNEL);
    LAYOUT_CONSTANT(RAW_SEQUENCE);
    LAYOUT_CONSTANT(RAW_TIME);
    LAYOUT_CONSTANT(RAW_START);
    LAYOUT_CONSTANT(RAW_SIZE);
    LAYOUT_CONSTANT(RAW_COLUMNS);
    LAYOUT_CONSTANT(MAX_STREAMS);
    return n;
}
