/* The private message formatter amps__vfmt against the C library's snprintf: every conversion
   the library uses, extreme and random values, truncation. */
#define AMPS_IMPLEMENTATION
#include "amps.h"
#include "amps_test.h"
#include <string.h>
#include <stdarg.h>
#include <limits.h>
#include <float.h>

static int g_bad = 0;

/* Formats with both and compares (size: buffer size given to both). */
static void t_cmp(size_t size, const char *fmt, ...) {
    char a[400], b[400];
    va_list ap, aq;
    va_start(ap, fmt);
    va_copy(aq, ap);
    memset(a, 'x', sizeof(a));
    amps__vfmt(a, size, fmt, ap);
    vsnprintf(b, size, fmt, aq);
    va_end(aq);
    va_end(ap);
    if (strcmp(a, b) && g_bad++ < 20) CHECK(0, "'%s': amps '%s', libc '%s'", fmt, a, b);
    else CHECK(1, "-");
}

/* A double of random magnitude 10^-30 .. 10^30, sign, and digit count (ties and round values too). */
static double t_rand_double(void) {
    double v = t_unif(), m = pow(10.0, t_int(61) - 30);
    switch (t_int(4)) {
    case 0: v = floor(v * 1e6) / 1e3; break;         /* few digits */
    case 1: v = (floor(v * 2e6) + 0.5) / 1e6; break; /* a 7th-digit tie, roughly */
    case 2: v = (double)(t_int(100000)); break;
    default: break;
    }
    return (t_int(2) ? -v : v) * m;
}

int main(void) {
    static const double special[] = {0.0,       -0.0,     1.0,      -1.0,      0.5,  1.5,   2.5,       9.5,
                                     0.05,      99999.95, 999999.5, 9999995.0, 1e-5, 1e-4,  1e-3,      123456.0,
                                     1234567.0, 1e15,     1e16,     1e17,      1e21, 1e100, 1e300,     1e-300,
                                     4.9e-324,  DBL_MAX,  DBL_MIN,  0.1,       0.2,  0.3,   1.0 / 3.0, 2.0 / 3.0,
                                     12.5,      0.125,    1e-310,   123.456e10};
    static const char *dfmt[] = {"%g", "%.3g", "%e", "%.0f", "%.3f", "%.1g", "%.0g", "%.0e", "%f", "%.12g"};
    size_t i, k;
    int r;
    t_seed(11);
    for (i = 0; i < sizeof(special) / sizeof(*special); i++)
        for (k = 0; k < sizeof(dfmt) / sizeof(*dfmt); k++) {
            if (!strcmp(dfmt[k], "%f") && fabs(special[i]) > 1e15) continue; /* > 15 significant digits */
            if (!strcmp(dfmt[k], "%.0f") && fabs(special[i]) > 1e15) continue;
            if (!strcmp(dfmt[k], "%.3f") && fabs(special[i]) > 1e12) continue;
            t_cmp(400, dfmt[k], special[i]);
            t_cmp(400, dfmt[k], -special[i]);
        }
    t_cmp(400, "%g %e %.0f %g", (double)NAN, (double)INFINITY, -(double)INFINITY, -(double)NAN);
    for (r = 0; r < 100000; r++) {
        double v = t_rand_double();
        t_cmp(400, "%g|%.3g|%e", v, v, v);
        if (fabs(v) < 1e9) t_cmp(400, "%.0f|%.3f", v, v);
    }
    t_cmp(400, "%d %d %d %ld %ld %lld %lld %lu %llu %u", 0, INT_MIN, INT_MAX, LONG_MIN, LONG_MAX, LLONG_MIN, LLONG_MAX,
          ULONG_MAX, ULLONG_MAX, 7u);
    t_cmp(400, "%s: [%s] %c 100%% %s", "amps_fn", "", 'q', "tail");
    t_cmp(400, "amps_factorize: matrix not positive definite: pivot %.3g at column %lld (diagonal %.3g)", -1.5e-13,
          17LL, 2.0);
    t_cmp(400, "need %.0f entries, cap_vpool is %.0f", 123456789012.0, 1e6);
    for (k = 1; k < 40; k += 3) t_cmp(k, "%s:%lld: %s %g", "file.msh", 123456LL, "expected $EndNodes", 3.25);
    t_cmp(1, "%d", 5);
    return amps_t_end("test_fmt");
}
