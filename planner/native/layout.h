/* A kernel library's description of the tables that Python mirrors with ctypes, so that a test
 * (tests/test_c_layouts.py) holds each mirror to the C side: every library that shares a struct
 * or numbered columns with Python defines
 *
 *     int64_t navcosim_layout(const char **names, int64_t *values, int64_t capacity)
 *
 * with the macros below. It fills up to `capacity` (name, value) pairs and returns how many it
 * has: "sizeof T" (bytes of struct T), "T.field" (offsetof), and named constants (enum members,
 * column numbers, status codes) under their C names.
 */
#ifndef NAVCOSIM_LAYOUT_H
#define NAVCOSIM_LAYOUT_H

#include <stddef.h>
#include <stdint.h>

#define LAYOUT_ENTRY(label, value)                                                                  \
    do {                                                                                            \
        if (n < capacity) {                                                                         \
            names[n] = (label);                                                                     \
            values[n] = (int64_t)(value);                                                           \
        }                                                                                           \
        n++;                                                                                        \
    } while (0)
#define LAYOUT_SIZE(T) LAYOUT_ENTRY("sizeof " #T, sizeof(T))
#define LAYOUT_FIELD(T, field) LAYOUT_ENTRY(#T "." #field, offsetof(T, field))
#define LAYOUT_CONSTANT(name) LAYOUT_ENTRY(#name, (name))

int64_t navcosim_layout(const char **names, int64_t *values, int64_t capacity);

#endif
