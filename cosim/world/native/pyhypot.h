/* Python's two-argument math.hypot (CPython 3.11), so C code whose results go where Python's did
 * (the distance driven, the clearance bounds of cosim/navigation/outcome.py) gives the same bits.
 * The C library's hypot differs from it in the last bit for about one pair in a thousand.
 *
 * The algorithm: the larger magnitude m = f * 2^e (frexp, 0.5 <= f < 1) sets a power-of-two scale
 * 2^-e that makes both coordinates < 1 without rounding; each scaled square is split exactly into
 * a high and a low part (Dekker's product: Veltkamp's split at 2^27 + 1), the high parts summed
 * onto 1.0 with the rounding error of each addition kept (Knuth's fast two-sum, exact since the
 * running sum is >= 1 and each square < 1), the low parts and those errors summed apart. The root
 * h of the sum (minus the 1.0) is then corrected once by Newton's step h + (s - h^2) / (2 h), with
 * s - h^2 computed the same exact way, and scaled back. An infinity wins over a NaN; a maximum
 * below 2^-1024 (where 2^-e would overflow) takes a plainer way: both divided by the maximum.
 * Built with -ffp-contract=off (native/load.py): no product is fused into an addition. */
#ifndef COSIM_WORLD_PYHYPOT_H
#define COSIM_WORLD_PYHYPOT_H

#include <math.h>

/* x * y exactly as *high + *low (|x|, |y| < 1 here: no overflow of the split). */
static inline void py_hypot_product(double x, double y, double *high, double *low)
{
    const double veltkamp = 134217729.0; /* 2^27 + 1 */
    double tx = x * veltkamp, ty = y * veltkamp;
    double x_high = tx - (tx - x), x_low = x - x_high;
    double y_high = ty - (ty - y), y_low = y - y_high;
    double p = x_high * y_high;
    double q = x_high * y_low + x_low * y_high;
    double z = p + q;
    *high = z;
    *low = p - z + q + x_low * y_low;
}

/* sqrt(a^2 + b^2) of two finite magnitudes 0 <= a, b <= m, m = max(a, b) > 0. */
static inline double py_hypot_scaled(double a, double b, double m)
{
    int exponent;
    frexp(m, &exponent);
    if (exponent < -1023) {
        /* 2^-e would overflow: the coordinates are divided by m instead, their squares summed
         * onto 1.0 with the rounding errors kept, and no correction step. */
        double sum = 1.0, errors = 0.0;
        double coordinates[2] = {a, b};
        for (int i = 0; i < 2; i++) {
            double x = coordinates[i] / m;
            x = x * x;
            double before = sum;
            sum += x;
            errors += before - sum + x;
        }
        return m * sqrt(sum - 1.0 + errors);
    }
    double scale = ldexp(1.0, -exponent);
    double sum = 1.0, low_parts = 0.0, sum_errors = 0.0;
    double coordinates[2] = {a * scale, b * scale};
    for (int i = 0; i < 2; i++) {
        double high, low;
        py_hypot_product(coordinates[i], coordinates[i], &high, &low);
        double total = sum + high;
        sum_errors += sum - total + high;
        sum = total;
        low_parts += low;
    }
    double h = sqrt(sum - 1.0 + (low_parts + sum_errors));
    double high, low;
    py_hypot_product(-h, h, &high, &low);
    double total = sum + high;
    sum_errors += sum - total + high;
    sum = total;
    low_parts += low;
    double residual = sum - 1.0 + (low_parts + sum_errors);
    h += residual / (2.0 * h);
    return h / scale;
}

static inline double py_hypot(double x, double y)
{
    double a = fabs(x), b = fabs(y);
    double m = 0.0;
    if (a > m)
        m = a;
    if (b > m)
        m = b;
    if (isinf(m))
        return m;
    if (isnan(a) || isnan(b))
        return NAN;
    if (m == 0.0)
        return m;
    return py_hypot_scaled(a, b, m);
}

#endif
