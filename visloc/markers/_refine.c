/* Stage 8 accelerator: sub-pixel edge refinement of quads on the grey image.
 *
 * The algorithm of visloc.markers.refine.refine_quads, one quad after another: grey levels
 * along `count` normals across each side (offsets -r .. r px), black and white levels as the
 * medians of the innermost and outermost samples (quads with a side of BEND_MIN_SIDE px or
 * more: each side's own, where the light varies significantly, or always with `force`:
 * side_levels), the edge on each profile from the area of
 * the normalised step (e = r + 1/2 - sum v), profiles without a clean step dropped, weighted
 * total-least-squares lines (outliers of the last pass's first fit dropped), corners at their
 * intersections; `iterations` passes, each centred on the previous pass's lines, then more
 * (up to `max_iterations`) while each pass shrank the largest corner move by SHRINK, until no
 * corner moves more than `tol` px (a pass that did not shrink it is not taken; outliers dropped
 * on each of those passes). See
 * refine.py for the reasoning. Grey levels are read through the camera's response (`lut`: the
 * linear intensity of each grey level, visloc.markers.response) before they are interpolated.
 * One difference: samples are interpolated bilinearly in double precision here, where the
 * numpy version reads them through cv2.remap (coordinates rounded to 1/32 px); the corners of
 * the two agree to about 0.01 px.
 *
 * refine_quads(gray, height, width, quads, radii, iterations, count, end_gap, lut, bend, force[, max_iterations,
 *              tol, bend_radius, noisy_bend_radius]) -> (corners, ok)
 *     (bend: stage 8b, bend_one, on every quad refined, its profiles at most bend_radius px to either side,
 *     noisy_bend_radius on a quad whose end samples' noise is NOISY of its contrast or more)
 *     gray: uint8 (H, W) bytes; quads: float64 (K, 4, 2); radii: int64 (K,); lut: float64 (256,),
 *     increasing; returns float64 (K, 4, 2) corners (the input where refinement failed) and
 *     uint8 (K,) flags, as bytes.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "_lines.h"

typedef struct {
    const uint8_t *g;
    int64_t h, w;
    const double *lut; /* linear intensity of each grey level */
} image;

/* The grey level whose linear intensity is v (the lut inverted, linear between entries). */
static double to_grey(const double *lut, double v) {
    int lo = 0, hi = 255;
    if (v <= lut[0]) return 0;
    if (v >= lut[255]) return 255;
    while (hi - lo > 1) {
        int mid = (lo + hi) / 2;
        if (lut[mid] <= v)
            lo = mid;
        else
            hi = mid;
    }
    return lo + (v - lut[lo]) / (lut[hi] - lut[lo]);
}

/* Bilinear grey level at (x, y), pixel centres at integers, borders replicated. */
static double sample(const image *im, double x, double y) {
    /* beyond a pixel outside the image every point reads the border: clamp first, so the
     * integer conversions below stay defined for any x, y (NaN reads the corner pixel) */
    x = isnan(x) || x < -1.0 ? -1.0 : (x > (double)im->w ? (double)im->w : x);
    y = isnan(y) || y < -1.0 ? -1.0 : (y > (double)im->h ? (double)im->h : y);
    double fx = floor(x), fy = floor(y);
    double ax = x - fx, ay = y - fy;
    int64_t x0 = (int64_t)fx, y0 = (int64_t)fy, x1 = x0 + 1, y1 = y0 + 1;
    if (x0 < 0) x0 = 0;
    if (x0 > im->w - 1) x0 = im->w - 1;
    if (x1 < 0) x1 = 0;
    if (x1 > im->w - 1) x1 = im->w - 1;
    if (y0 < 0) y0 = 0;
    if (y0 > im->h - 1) y0 = im->h - 1;
    if (y1 < 0) y1 = 0;
    if (y1 > im->h - 1) y1 = im->h - 1;
    const uint8_t *r0 = im->g + y0 * im->w, *r1 = im->g + y1 * im->w;
    const double *L = im->lut;
    return (1 - ay) * ((1 - ax) * L[r0[x0]] + ax * L[r0[x1]]) + ay * ((1 - ax) * L[r1[x0]] + ax * L[r1[x1]]);
}

/* Bilinear grey levels at n points (x0 + o dx, y0 + o dy), o = 0 .. n-1, into out: without
 * the border clamps when all of them are at least a pixel inside the image. */
static void sample_line(const image *im, double x0, double y0, double dx, double dy, int64_t n, double *out) {
    double xe = x0 + (double)(n - 1) * dx, ye = y0 + (double)(n - 1) * dy;
    if (!(x0 >= 0 && xe >= 0 && y0 >= 0 && ye >= 0 && x0 < im->w - 1 && xe < im->w - 1 && y0 < im->h - 1 &&
          ye < im->h - 1)) { /* NaN too: the clamped reads */
        for (int64_t o = 0; o < n; o++) out[o] = sample(im, x0 + (double)o * dx, y0 + (double)o * dy);
        return;
    }
    for (int64_t o = 0; o < n; o++) {
        double x = x0 + (double)o * dx, y = y0 + (double)o * dy;
        int64_t xi = (int64_t)x, yi = (int64_t)y; /* floor: both are >= 0 here */
        double ax = x - (double)xi, ay = y - (double)yi;
        const uint8_t *r0 = im->g + yi * im->w + xi, *r1 = r0 + im->w;
        const double *L = im->lut;
        out[o] = (1 - ay) * ((1 - ax) * L[r0[0]] + ax * L[r0[1]]) + ay * ((1 - ax) * L[r1[0]] + ax * L[r1[1]]);
    }
}

/* The element of rank k (0-based) of v[0..n-1] (v is reordered): quickselect with a
 * median-of-three pivot and branchless three-way partitions (below the pivot, equal to it,
 * above it), so runs of equal values (flat profiles) shrink the range at once. Two to three
 * times the speed of a Hoare partition's data-dependent branches on the 4 n end samples. */
static double select_rank(double *v, int64_t n, int64_t k) {
    int64_t lo = 0, hi = n; /* the element is in v[lo .. hi) */
    while (hi - lo > 1) {
        double a = v[lo], b = v[lo + (hi - lo) / 2], c = v[hi - 1];
        double pivot = a < b ? (b < c ? b : (a < c ? c : a)) : (a < c ? a : (b < c ? c : b));
        int64_t s = lo;
        for (int64_t i = lo; i < hi; i++) { /* v[lo .. s) < pivot */
            double x = v[i];
            v[i] = v[s];
            v[s] = x;
            s += x < pivot;
        }
        if (k < s) {
            hi = s;
            continue;
        }
        int64_t e = s;
        for (int64_t i = s; i < hi; i++) { /* v[s .. e) == pivot */
            double x = v[i];
            v[i] = v[e];
            v[e] = x;
            e += x <= pivot;
        }
        if (k < e) return pivot;
        if (e == lo) break; /* a NaN pivot orders nothing: no order to find, stop */
        lo = e;
    }
    return v[k];
}

/* The median (upper middle) of v[0 .. n); `sorted` is n doubles of scratch. */
static double median_of(const double *v, int64_t n, double *sorted) {
    memcpy(sorted, v, (size_t)n * sizeof(double));
    return select_rank(sorted, n, n / 2);
}

/* The noise of a quad's end samples v[4 n] (four sides of n profiles): 1.4826 x the median
 * absolute difference of neighbouring profiles' samples along a side, over sqrt 2 (a smooth
 * change of the light along a side leaves it alone). `sorted` is 4 n doubles of scratch. */
static double noise_of(const double *v, int64_t n, double *sorted) {
    int64_t k = 0;
    for (int s = 0; s < 4; s++)
        for (int64_t m = 1; m < n; m++) sorted[k++] = fabs(v[s * n + m] - v[s * n + m - 1]);
    return k ? 1.4826 / sqrt(2.0) * select_rank(sorted, k, k / 2) : 0.0;
}

/* (force: the line whatever the difference.) One side's level (black from the innermost samples `ends` of its n profiles, or white from
 * the outermost) at each profile, into out[n]: the line along the side through the medians of
 * its first and second half (each at its half's middle) where their difference is significant
 * (over LEVEL_Z standard errors of a difference of medians, from the quad's spread `sd`: the
 * light varies along the side: vignetting, shading), else the side's median where it differs
 * significantly from the quad's level `quad`, else `quad` (with few or noisy samples the
 * quad's level is the better estimate). `sorted` is n doubles of scratch. */
#define LEVEL_Z 3.0
static void side_levels(const double *ends, int64_t n, double quad, double sd, int force, double *sorted, double *out) {
    int64_t h1 = n / 2, h2 = n - h1;
    double level = quad;
    if (h1 >= 2) {
        double c1 = 0.5 * (double)(h1 - 1), c2 = (double)h1 + 0.5 * (double)(h2 - 1);
        double m1 = median_of(ends, h1, sorted), m2 = median_of(ends + h1, h2, sorted);
        if (force || fabs(m2 - m1) > LEVEL_Z * 1.2533 * sd * sqrt(2.0 / (double)h1)) {
            for (int64_t m = 0; m < n; m++) out[m] = m1 + (m2 - m1) * ((double)m - c1) / (c2 - c1);
            return;
        }
        double side = median_of(ends, n, sorted);
        if (fabs(side - quad) > LEVEL_Z * 1.2533 * sd / sqrt((double)n)) level = side;
    }
    for (int64_t m = 0; m < n; m++) out[m] = level;
}

/* The edge on a profile of 2 r + 1 samples, relative to its centre, px, positive outward:
 * refine.py's area of the step normalised between lo and lo + span. */
static double step_offset(const double *pr, int64_t width, double lo, double span, int64_t r) {
    double area = 0;
    for (int64_t o = 0; o < width; o++) {
        double v = (pr[o] - lo) / span;
        area += v < 0 ? 0 : (v > 1 ? 1 : v);
    }
    return (double)r + 0.5 - area;
}

/* Weighted least-squares fit of off = c0 + c1 t + c2 t^2 (c2 = 0 unless the curvature is over
 * 3 standard errors: a straight, noisy edge stays a line); 0 when the system is singular. */
static int fit_curve(const double *t, const double *off, const double *w, int64_t n, double c[3]) {
    double g[3][3] = {{0}}, b[3] = {0}, sw = 0;
    for (int64_t m = 0; m < n; m++) {
        if (w[m] <= 0) continue;
        double f[3] = {1.0, t[m], t[m] * t[m]};
        for (int i = 0; i < 3; i++) {
            b[i] += w[m] * f[i] * off[m];
            for (int j = 0; j < 3; j++) g[i][j] += w[m] * f[i] * f[j];
        }
        sw += w[m];
    }
    double det = g[0][0] * (g[1][1] * g[2][2] - g[1][2] * g[2][1]) - g[0][1] * (g[1][0] * g[2][2] - g[1][2] * g[2][0]) +
                 g[0][2] * (g[1][0] * g[2][1] - g[1][1] * g[2][0]);
    if (sw >= 6 && fabs(det) > 1e-12) {
        for (int k = 0; k < 3; k++) { /* Cramer's rule */
            double a[3][3];
            memcpy(a, g, sizeof(a));
            for (int i = 0; i < 3; i++) a[i][k] = b[i];
            c[k] = (a[0][0] * (a[1][1] * a[2][2] - a[1][2] * a[2][1]) - a[0][1] * (a[1][0] * a[2][2] - a[1][2] * a[2][0]) +
                    a[0][2] * (a[1][0] * a[2][1] - a[1][1] * a[2][0])) / det;
        }
        double ss = 0;
        for (int64_t m = 0; m < n; m++) {
            double r = off[m] - c[0] - c[1] * t[m] - c[2] * t[m] * t[m];
            ss += w[m] * r * r;
        }
        double c2_var = ss / (sw - 3) * (g[0][0] * g[1][1] - g[0][1] * g[1][0]) / det;
        if (c2_var >= 0 && fabs(c[2]) >= 3.0 * sqrt(c2_var)) return 1;
    }
    double d2 = g[0][0] * g[1][1] - g[0][1] * g[1][0];
    if (fabs(d2) < 1e-12) return 0;
    c[0] = (b[0] * g[1][1] - g[0][1] * b[1]) / d2;
    c[1] = (g[0][0] * b[1] - b[0] * g[1][0]) / d2;
    c[2] = 0;
    return 1;
}

/* Stage 8b: corner s where the tangents of the curves of sides s - 1 (at its end) and s (at
 * its start) meet; the curves are offsets c0 + c1 t + c2 t^2 along each side's normal from
 * the quad `cur`. 0 where two tangents are parallel. */
static int curved_corners(const double cur[8], const double normal[4][2], const double cf[4][3], double out[8]) {
    for (int s = 0; s < 4; s++) {
        int p = (s + 3) % 4, nx = (s + 1) % 4;
        const double *cp = cf[p], *cs = cf[s];
        double dpx = cur[2 * s] - cur[2 * p], dpy = cur[2 * s + 1] - cur[2 * p + 1];
        double dsx = cur[2 * nx] - cur[2 * s], dsy = cur[2 * nx + 1] - cur[2 * s + 1];
        double end = cp[0] + cp[1] + cp[2], slope_p = cp[1] + 2 * cp[2];
        double ax = cur[2 * s] + end * normal[p][0], ay = cur[2 * s + 1] + end * normal[p][1];
        double dax = dpx + slope_p * normal[p][0], day = dpy + slope_p * normal[p][1];
        double bx = cur[2 * s] + cs[0] * normal[s][0], by = cur[2 * s + 1] + cs[0] * normal[s][1];
        double dbx = dsx + cs[1] * normal[s][0], dby = dsy + cs[1] * normal[s][1];
        double den = dax * dby - day * dbx;
        if (fabs(den) < 1e-9) return 0;
        double u = ((bx - ax) * dby - (by - ay) * dbx) / den;
        out[2 * s] = ax + u * dax;
        out[2 * s + 1] = ay + u * day;
    }
    return 1;
}

/* Stage 8b on a refined quad q (4, 2), in place: along BEND_COUNT normals per side (ends
 * BEND_GAP left out) the edge offsets from the straight side, fitted as curves (fit_curve,
 * outliers of a first fit dropped), meet at the new corners (curved_corners). As
 * refine.bend_corners. `work` holds 4 BEND_COUNT (5 + 2 r + 1) doubles. */
#define BEND_COUNT 40
#define BEND_GAP 0.08
/* Markers with no side this long (px) keep straight sides: a lens bends a short side by a
 * small fraction of a pixel (the bend grows with the square of the length). */
#define SHRINK 0.8 /* a pass beyond `iterations` must shrink the largest corner move by this, or is not taken (refine.py) */
#define BEND_MIN_SIDE 40.0

static double longest_side(const double q[8]) {
    double best = 0;
    for (int s = 0; s < 4; s++) {
        double d = hypot(q[2 * ((s + 1) % 4)] - q[2 * s], q[2 * ((s + 1) % 4) + 1] - q[2 * s + 1]);
        if (d > best) best = d;
    }
    return best;
}
#define NOISY 0.1 /* refine.py's _NOISY */

static void bend_one(const image *im, double q[8], int64_t r, int64_t narrow, int force, double *work) {
    const int64_t width = 2 * r + 1, n = BEND_COUNT, n4 = 4 * BEND_COUNT;
    double *p_in = work, *p_out = work + n4, *sorted = work + 2 * n4, *off = work + 3 * n4, *w = work + 4 * n4;
    double *prof = work + 5 * n4;
    double t[BEND_COUNT], normal[4][2], levels[2 * BEND_COUNT];
    for (int64_t m = 0; m < n; m++) t[m] = BEND_GAP + (1 - 2 * BEND_GAP) * (double)m / (double)(n - 1);
    for (int s = 0; s < 4; s++) {
        const double *a = q + 2 * s, *b = q + 2 * ((s + 1) % 4);
        double dx = b[0] - a[0], dy = b[1] - a[1], len = hypot(dx, dy);
        if (len < 1e-9) return;
        normal[s][0] = dy / len;
        normal[s][1] = -dx / len;
        for (int64_t m = 0; m < n; m++) {
            double *pr = prof + (s * n + m) * width;
            double bx = a[0] + t[m] * dx, by = a[1] + t[m] * dy;
            sample_line(im, bx - (double)r * normal[s][0], by - (double)r * normal[s][1], normal[s][0], normal[s][1],
                        width, pr);
            p_in[s * n + m] = pr[0];
            p_out[s * n + m] = pr[width - 1];
        }
    }
    double lo_q = median_of(p_in, n4, sorted), hi_q = median_of(p_out, n4, sorted);
    double sd_lo = noise_of(p_in, n, sorted), sd_hi = noise_of(p_out, n, sorted);
    int64_t c0 = 0, wd = width, rr = r; /* the samples of each profile used: wd from c0, half-width rr */
    if (narrow > 0 && r > narrow && (sd_lo > sd_hi ? sd_lo : sd_hi) >= NOISY * (hi_q - lo_q)) {
        /* noise a large part of the contrast: the central 2 narrow + 1 samples (refine.py's _narrowed) */
        c0 = r - narrow;
        wd = 2 * narrow + 1;
        rr = narrow;
        for (int64_t j = 0; j < n4; j++) {
            p_in[j] = prof[j * width + c0];
            p_out[j] = prof[j * width + c0 + wd - 1];
        }
        lo_q = median_of(p_in, n4, sorted);
        hi_q = median_of(p_out, n4, sorted);
        sd_lo = noise_of(p_in, n, sorted);
        sd_hi = noise_of(p_out, n, sorted);
    }
    double cf[4][3], out[8];
    for (int s = 0; s < 4; s++) {
        double *lo = levels, *hi = levels + n; /* levels as refine_one reads those of large quads */
        side_levels(p_in + s * n, n, lo_q, sd_lo, force, sorted, lo);
        side_levels(p_out + s * n, n, hi_q, sd_hi, force, sorted, hi);
        for (int64_t m = 0; m < n; m++) {
            int64_t j = s * n + m;
            double span = hi[m] - lo[m] > 1e-6 ? hi[m] - lo[m] : 1e-6;
            off[j] = step_offset(prof + j * width + c0, wd, lo[m], span, rr);
            w[j] = (p_out[j] - p_in[j]) > 0.5 * (hi[m] - lo[m]) && fabs(off[j]) < (double)rr;
        }
        double *o = off + s * n, *ws = w + s * n;
        if (!fit_curve(t, o, ws, n, cf[s])) return;
        double ss = 0, sw = 0; /* drop the first fit's outliers and fit again */
        for (int64_t m = 0; m < n; m++) {
            double e = o[m] - cf[s][0] - cf[s][1] * t[m] - cf[s][2] * t[m] * t[m];
            ss += ws[m] * e * e;
            sw += ws[m];
        }
        double rms = sqrt(ss / (sw > 4 ? sw - 3 : 1));
        for (int64_t m = 0; m < n; m++) {
            double e = fabs(o[m] - cf[s][0] - cf[s][1] * t[m] - cf[s][2] * t[m] * t[m]);
            ws[m] *= e < 2.5 * rms + 0.05;
        }
        if (!fit_curve(t, o, ws, n, cf[s])) return;
    }
    if (!curved_corners(q, (const double(*)[2])normal, (const double(*)[3])cf, out)) return;
    for (int c = 0; c < 8; c++)
        if (!(fabs(out[c] - q[c]) < 1.0 + (double)rr)) return; /* NaN too */
    memcpy(q, out, sizeof(out));
}

/* Refine one quad q (4, 2) in place; 1 on success (q is left as given otherwise; a pass
 * beyond `iterations` that fails leaves the previous pass's corners). `work` holds
 * 4 * count * (7 + 2 r + 1) doubles. */
static int refine_one(const image *im, double q[8], int64_t r, int iterations, int max_iterations, double tol,
                      int64_t count, double end_gap, int force, double *work) {
    const int64_t width = 2 * r + 1, n4 = 4 * count;
    double *p_in = work, *p_out = work + n4, *sorted = work + 2 * n4, *ex = work + 3 * n4, *ey = work + 4 * n4;
    double *wt = work + 5 * n4, *res = work + 6 * n4, *prof = work + 7 * n4;
    double cur[8], last_move = HUGE_VAL;
    int converging = 1, it;
    memcpy(cur, q, sizeof(cur));
    for (it = 0; it < max_iterations; it++) {
        double normal[4][2];
        for (int s = 0; s < 4; s++) { /* sample every profile */
            const double *a = cur + 2 * s, *b = cur + 2 * ((s + 1) % 4);
            double dx = b[0] - a[0], dy = b[1] - a[1];
            double len = hypot(dx, dy);
            if (len < 1e-9) len = 1e-9;
            double nx = dy / len, ny = -dx / len; /* clockwise quad, y down: outward */
            normal[s][0] = nx;
            normal[s][1] = ny;
            for (int64_t m = 0; m < count; m++) {
                double t = count > 1 ? end_gap + (1 - 2 * end_gap) * (double)m / (double)(count - 1) : end_gap;
                double bx = a[0] + t * dx, by = a[1] + t * dy;
                double *pr = prof + (s * count + m) * width;
                sample_line(im, bx - (double)r * nx, by - (double)r * ny, nx, ny, width, pr);
                p_in[s * count + m] = pr[0];
                p_out[s * count + m] = pr[width - 1];
                ex[s * count + m] = bx; /* profile centre, moved to the edge below */
                ey[s * count + m] = by;
            }
        }
        double lo = median_of(p_in, n4, sorted), hi = median_of(p_out, n4, sorted);
        if (!(to_grey(im->lut, hi) - to_grey(im->lut, lo) >= 4.0)) goto failed; /* no contrast (grey levels) */
        int long_sides = longest_side(cur) >= BEND_MIN_SIDE;
        double sd_lo = long_sides ? noise_of(p_in, count, sorted) : 0.0;
        double sd_hi = long_sides ? noise_of(p_out, count, sorted) : 0.0;
        double lines[4][3];
        for (int s = 0; s < 4; s++) {
            int64_t n_good = 0;
            double *px = ex + s * count, *py = ey + s * count, *w = wt + s * count;
            double *lo_s = res, *hi_s = res + count; /* levels profile by profile */
            if (long_sides) { /* large quads: the light along each side where it varies significantly */
                side_levels(p_in + s * count, count, lo, sd_lo, force, sorted, lo_s);
                side_levels(p_out + s * count, count, hi, sd_hi, force, sorted, hi_s);
            } else { /* small ones: the whole quad's (fewer samples per side: noisier) */
                for (int64_t m = 0; m < count; m++) {
                    lo_s[m] = lo;
                    hi_s[m] = hi;
                }
            }
            for (int64_t m = 0; m < count; m++) {
                double span = hi_s[m] - lo_s[m] > 1e-6 ? hi_s[m] - lo_s[m] : 1e-6;
                double e = step_offset(prof + (s * count + m) * width, width, lo_s[m], span, r);
                int j = s * count + m;
                w[m] = (p_out[j] - p_in[j]) > 0.5 * (hi_s[m] - lo_s[m]) && fabs(e) < (double)r;
                n_good += w[m] > 0;
                px[m] += e * normal[s][0];
                py[m] += e * normal[s][1];
            }
            if (n_good < 3) goto failed;
            tls_line(px, py, w, count, lines[s]);
            if (it >= iterations - 1) { /* drop the outliers of the first fit and fit again */
                double *l = lines[s], sw = 0, ss = 0;
                for (int64_t m = 0; m < count; m++) {
                    res[m] = fabs(px[m] * l[0] + py[m] * l[1] - l[2]);
                    sw += w[m];
                    ss += w[m] * res[m] * res[m];
                }
                double rms = sqrt(ss / (sw > 1 ? sw : 1));
                double *w2 = res; /* residuals are read before being overwritten */
                double sw2 = 0;
                for (int64_t m = 0; m < count; m++) {
                    w2[m] = w[m] * (res[m] < 2.5 * rms + 0.05);
                    sw2 += w2[m];
                }
                tls_line(px, py, sw2 >= 3 ? w2 : w, count, lines[s]);
            }
            if (lines[s][0] * normal[s][0] + lines[s][1] * normal[s][1] < 0)
                for (int c = 0; c < 3; c++) lines[s][c] = -lines[s][c];
        }
        double next[8], move = 0;
        if (!quad_corners((const double(*)[3])lines, next)) goto failed;
        for (int c = 0; c < 8; c++) {
            double d = fabs(next[c] - cur[c]);
            if (!(d <= move)) move = d; /* NaN propagates */
        }
        if (!(move <= 2.0 * (double)r + 1.0)) goto failed;
        /* passes beyond `iterations` only while every pass shrank the move (blur); where noise
         * moves the sides about as much each pass, or a side walks off, the last one is kept */
        int shrank = move <= SHRINK * last_move;
        if (it >= iterations && !shrank) break;
        memcpy(cur, next, sizeof(cur));
        converging &= shrank;
        if (it >= iterations - 1 && (move <= tol || !converging)) break;
        last_move = move;
    }
    memcpy(q, cur, sizeof(cur));
    return 1;
failed: /* the first `iterations` passes must all stand; a later one that fails is not taken */
    if (it < iterations) return 0;
    memcpy(q, cur, sizeof(cur));
    return 1;
}

static PyObject *refine_quads(PyObject *self, PyObject *args) {
    (void)self;
    Py_buffer gray, quads, radii, lut;
    Py_ssize_t h, w, count;
    int iterations, bend, force, max_iterations = 0;
    double end_gap, tol = 0.0;
    Py_ssize_t bend_cap = 64; /* stage 8b's profile half-width at most (the quad's radius where smaller) */
    Py_ssize_t narrow = 0;    /* and on noisy quads (0: never narrower) */
    if (!PyArg_ParseTuple(args, "y*nny*y*indy*pp|idnn", &gray, &h, &w, &quads, &radii, &iterations, &count, &end_gap,
                          &lut, &bend, &force, &max_iterations, &tol, &bend_cap, &narrow))
        return NULL;
    if (max_iterations < iterations) max_iterations = iterations; /* 0 (not given): exactly `iterations` */
    Py_ssize_t k = quads.len / (8 * (Py_ssize_t)sizeof(double));
    const char *bad = NULL;
    if (h <= 0 || w <= 0 || gray.len != h * w)
        bad = "gray: expected height x width bytes";
    else if (quads.len != k * 8 * (Py_ssize_t)sizeof(double) || radii.len != k * (Py_ssize_t)sizeof(int64_t))
        bad = "quads/radii: expected K x 4 x 2 float64 and K int64 values";
    else if (count < 2 || count > 10000 || iterations < 1 || max_iterations > 100)
        bad = "count must be 2 to 10000 and iterations 1 to 100";
    else if (!(tol >= 0.0))
        bad = "tolerance must be >= 0";
    else if (!(end_gap >= 0.0 && end_gap < 0.5))
        bad = "end_gap must be in [0, 0.5)";
    else if (lut.len != 256 * (Py_ssize_t)sizeof(double))
        bad = "lut: expected 256 float64 values";
    else if (bend_cap < 1 || narrow < 0)
        bad = "bend radius must be at least 1 px (the noisy quads' 0 or more)";
    const int64_t *rad = (const int64_t *)radii.buf;
    int64_t r_max = 1;
    for (Py_ssize_t i = 0; !bad && i < k; i++) { /* bounded: the work buffer grows with it */
        if (rad[i] < 1 || rad[i] > 64) bad = "radius must be 1 to 64 px";
        if (rad[i] > r_max) r_max = rad[i];
    }
    const double *qv = (const double *)quads.buf;
    for (Py_ssize_t i = 0; !bad && i < 8 * k; i++) {
        if (!isfinite(qv[i])) bad = "quads: every corner must be finite";
    }
    PyObject *result = NULL;
    if (bad) {
        PyErr_SetString(PyExc_ValueError, bad);
    } else {
        int64_t per = count > BEND_COUNT ? count : BEND_COUNT;
        double *work = (double *)malloc((size_t)(4 * per * (7 + 2 * r_max + 1)) * sizeof(double));
        PyObject *corners = PyBytes_FromStringAndSize((const char *)quads.buf, quads.len);
        PyObject *ok = PyBytes_FromStringAndSize(NULL, k);
        if (work && corners && ok) {
            double *c = (double *)PyBytes_AS_STRING(corners);
            uint8_t *flag = (uint8_t *)PyBytes_AS_STRING(ok);
            image im = {(const uint8_t *)gray.buf, h, w, (const double *)lut.buf};
            Py_BEGIN_ALLOW_THREADS
            for (Py_ssize_t i = 0; i < k; i++) {
                flag[i] = (uint8_t)refine_one(&im, c + 8 * i, rad[i], iterations, max_iterations, tol, count, end_gap, force, work);
                if (flag[i] && bend && longest_side(c + 8 * i) >= BEND_MIN_SIDE)
                    bend_one(&im, c + 8 * i, rad[i] < bend_cap ? rad[i] : (int64_t)bend_cap, (int64_t)narrow, force,
                             work);
            }
            Py_END_ALLOW_THREADS
        }
        result = corners_result(corners, ok, work);
    }
    PyBuffer_Release(&gray);
    PyBuffer_Release(&quads);
    PyBuffer_Release(&radii);
    PyBuffer_Release(&lut);
    return result;
}

static PyMethodDef methods[] = {
    {"refine_quads", refine_quads, METH_VARARGS,
     "refine_quads(gray, height, width, quads, radii, iterations, count, end_gap, lut, bend, force[, max_iterations, tol,"
     " bend_radius, noisy_bend_radius])"
     " -> (corners, ok)\n\n"
     "Stage 8 for K quads; see visloc.markers.refine.refine_quads."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_refine", "Stage 8: sub-pixel edge refinement.", -1,
                                    methods, NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__refine(void) { return PyModule_Create(&module); }
