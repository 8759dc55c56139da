/* Calls every function of stam.h through the header, as a C renderer would,
 * and checks what C can see: NULL + message on bad parameters, finite and
 * non-negative outputs, unit sampled directions. Returns 0 on success, or
 * the number of the first failed check with a message in `report`. */
#include "stam.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define CHECK(id, cond, ...)                                  \
    do {                                                      \
        if (!(cond)) {                                        \
            snprintf(report, report_len, __VA_ARGS__);        \
            return id;                                        \
        }                                                     \
    } while (0)

static int finite_nonneg(const float *v, size_t n) {
    for (size_t i = 0; i < n; ++i)
        if (!(isfinite(v[i]) && v[i] >= 0.0f)) return 0;
    return 1;
}

static int in_unit_interval(const float *v, size_t n) {
    for (size_t i = 0; i < n; ++i)
        if (!(v[i] >= 0.0f && v[i] <= 1.0f)) return 0;
    return 1;
}

/* Deterministic uniforms in [0, 1): the high 24 bits of a 32-bit LCG. */
static float next_uniform(uint32_t *state) {
    *state = *state * 1664525u + 1013904223u;
    return (float)(*state >> 8) * (1.0f / 16777216.0f);
}

/* Checks of stam_brdf_coherent_probability at the lanes wi, lambda of
 * stam_c_caller_run (lanes 0, 1 above the horizon, 2 below, 3 NaN): a
 * probability in [0, 1]; 0 where the BRDF is undefined; > 0 wherever the
 * coherent lobe reflects (a delta lobe is only estimated by sampling it);
 * 0 for materials without STAM_FLAG_HAS_COHERENT; and, at lanes 0 and 1,
 * the probability with which stam_brdf_sample picks the coherent lobe and
 * the pdf it reports for such samples (K samples each, spectral and RGB). */
static int check_coherent_probability(const StamBrdf *b, const float *wi, const float *lambda,
                                      char *report, size_t report_len) {
    enum { N = 4, K = 1024 };
    float p[N], p_rgb[N], refl[N], refl_rgb[3 * N];
    stam_brdf_coherent_probability(b, N, wi, lambda, p);
    stam_brdf_coherent_probability(b, N, wi, NULL, p_rgb);
    CHECK(30, in_unit_interval(p, N) && in_unit_interval(p_rgb, N),
          "coherent_probability outside [0, 1]: %g %g %g %g / RGB %g %g %g %g", p[0], p[1], p[2],
          p[3], p_rgb[0], p_rgb[1], p_rgb[2], p_rgb[3]);
    CHECK(31, p[2] == 0.0f && p[3] == 0.0f && p_rgb[2] == 0.0f && p_rgb[3] == 0.0f,
          "coherent_probability not 0 below the horizon / for a NaN direction");
    stam_brdf_coherent_spectral(b, N, wi, lambda, refl);
    stam_brdf_coherent_rgb(b, N, wi, refl_rgb);
    for (int i = 0; i < N; ++i) {
        CHECK(32, !(refl[i] > 0.0f) || p[i] > 0.0f,
              "lane %d: coherent reflectance %g but probability 0 (spectral)", i, refl[i]);
        CHECK(32, !(refl_rgb[3 * i] + refl_rgb[3 * i + 1] + refl_rgb[3 * i + 2] > 0.0f) ||
                      p_rgb[i] > 0.0f,
              "lane %d: coherent reflectance but probability 0 (RGB)", i);
    }
    if (!(stam_brdf_flags(b) & STAM_FLAG_HAS_COHERENT))
        CHECK(33, p[0] == 0.0f && p[1] == 0.0f && p_rgb[0] == 0.0f && p_rgb[1] == 0.0f,
              "coherent_probability > 0 without STAM_FLAG_HAS_COHERENT");

    float wi_k[3 * K], lam_k[K], rnd_k[3 * K], wo_k[3 * K], pdf_k[K], p_k[K];
    uint8_t coh_k[K];
    for (int lane = 0; lane < 2; ++lane) {
        for (int rgb_mode = 0; rgb_mode < 2; ++rgb_mode) {
            uint32_t state = 12345u + (uint32_t)(2 * lane + rgb_mode);
            for (int k = 0; k < K; ++k) {
                memcpy(wi_k + 3 * k, wi + 3 * lane, 3 * sizeof(float));
                lam_k[k] = lambda[lane];
                for (int j = 0; j < 3; ++j) rnd_k[3 * k + j] = next_uniform(&state);
            }
            const float *lam = rgb_mode ? NULL : lam_k;
            stam_brdf_coherent_probability(b, K, wi_k, lam, p_k);
            stam_brdf_sample(b, K, wi_k, lam, rnd_k, wo_k, pdf_k, coh_k);
            const float expected = rgb_mode ? p_rgb[lane] : p[lane];
            int drawn = 0;
            for (int k = 0; k < K; ++k) {
                CHECK(34, p_k[k] == expected, "coherent_probability differs between calls: %g %g",
                      p_k[k], expected);
                if (coh_k[k]) {
                    ++drawn;
                    CHECK(35, pdf_k[k] == p_k[k],
                          "a coherent sample's pdf %g is not coherent_probability %g", pdf_k[k],
                          p_k[k]);
                }
            }
            /* The fraction of coherent samples is P within 5 standard
             * deviations (deterministic uniforms: no flakiness), and 0 or
             * all exactly when P is 0 or 1. */
            const double P = expected, frac = (double)drawn / K;
            CHECK(36, fabs(frac - P) <= 5.0 * sqrt(P * (1.0 - P) / K) + 0.5 / K,
                  "lane %d (%s): %d of %d samples coherent, coherent_probability %g", lane,
                  rgb_mode ? "RGB" : "spectral", drawn, K, P);
        }
    }
    /* NULL material: zeros. */
    p[0] = 1.0f;
    stam_brdf_coherent_probability(NULL, N, wi, lambda, p);
    CHECK(37, p[0] == 0.0f, "NULL material must give probability 0");
    return 0;
}

/* Checks of stam_brdf_export_program (stam.h; layout: format 4): every
 * kind sized with out = NULL, nothing written into a buffer that is too
 * small (4 floats, or one short), the whole array written into one of the
 * returned size and nothing past it; the header: format 4, the kind's
 * numbers of inputs and outputs, the total length, sections that fit in
 * the array, output registers and table offsets inside it. Every kind
 * exists for every material (the JIT variants run nothing else); a kind
 * out of range and the NULL material give 0. */
static int check_export_program(const StamBrdf *b, char *report, size_t report_len) {
    /* Inputs and outputs of each kind (stam_program_io: the header's
     * table); none for a kind that is not one. */
    uint32_t io[STAM_PROGRAM_KINDS][2];
    for (uint32_t kind = 0; kind < STAM_PROGRAM_KINDS; ++kind)
        CHECK(42, stam_program_io(kind, 0, &io[kind][0], &io[kind][1]) == 1,
              "no inputs and outputs for kind %u", kind);
    {
        uint32_t in = 99, out = 99;
        CHECK(42, stam_program_io(STAM_PROGRAM_KINDS, 0, &in, &out) == 0 && in == 99 &&
                      stam_program_io(STAM_MIXTURE_KINDS, 4, &in, &out) == 0 &&
                      stam_program_io(STAM_MIXTURE_PDF, STAM_MIXTURE_MAX_WAVELENGTHS + 1, NULL,
                                      NULL) == 0 &&
                      stam_program_io(STAM_MIXTURE_COHERENT, 4, &in, &out) == 1 && in == 7 &&
                      out == 5,
              "stam_program_io out of range, or the mixture's: %u %u", in, out);
    }
    size_t exported = 0;
    CHECK(42, STAM_PROGRAM_EVAL_RGB == 0u && STAM_PROGRAM_COHERENT_SPECTRAL == 7u &&
                  STAM_PROGRAM_KINDS == 8u,
          "program kind codes");
    for (uint32_t kind = 0; kind < STAM_PROGRAM_KINDS; ++kind) {
        const size_t n = stam_brdf_export_program(b, kind, NULL, 0);
        CHECK(42, stam_brdf_export_program(NULL, kind, NULL, 0) == 0, "program %u of NULL", kind);
        CHECK(42, stam_brdf_export_program(b, kind, NULL, 1000000) == n,
              "program %u: out = NULL with a capacity gave another size", kind);
        CHECK(42, n > 0, "no program of kind %u (every kind exists for every material)", kind);
        ++exported;
        CHECK(43, n >= 8 + 4, "program %u: %zu floats, less than a header and one instruction",
              kind, n);
        float small[4] = {-1.0f, -1.0f, -1.0f, -1.0f};
        CHECK(43, stam_brdf_export_program(b, kind, small, 4) == n && small[0] == -1.0f &&
                      small[3] == -1.0f,
              "program %u written into a buffer of 4 floats", kind);
        float *prog = malloc((n + 1) * sizeof(float));
        CHECK(43, prog != NULL, "out of memory");
        for (size_t i = 0; i <= n; ++i) prog[i] = -1.0f;
        const int short_ok = stam_brdf_export_program(b, kind, prog, n - 1) == n &&
                             prog[0] == -1.0f && prog[n - 2] == -1.0f;
        const int sized_ok = stam_brdf_export_program(b, kind, prog, n + 1) == n &&
                             prog[n] == -1.0f;
        /* Header: format, inputs, outputs, instructions, tables, total,
         * parameters (counts read as integers only once they are known to
         * lie in [0, n]). */
        const float *h = prog;
        int layout_ok = sized_ok && h[0] == 4.0f && h[1] == (float)io[kind][0] &&
                        h[2] == (float)io[kind][1] && h[5] == (float)n;
        for (int j = 2; layout_ok && j < 7; ++j)
            layout_ok = h[j] >= 0.0f && h[j] <= (float)n && h[j] == floorf(h[j]);
        const size_t n_out = layout_ok ? (size_t)h[2] : 0, n_code = layout_ok ? (size_t)h[3] : 0,
                     n_tab = layout_ok ? (size_t)h[4] : 0, n_par = layout_ok ? (size_t)h[6] : 0;
        const size_t code_at = 8 + n_out + 2 * n_tab + 2 * n_par;
        layout_ok = layout_ok && n_code > 0 && code_at + 4 * n_code <= n;
        for (size_t k = 0; layout_ok && k < n_out; ++k)
            layout_ok = h[8 + k] >= 0.0f && h[8 + k] < (float)n_code;
        for (size_t t = 0; layout_ok && t < n_tab; ++t) {
            const float off = h[8 + n_out + 2 * t], len = h[8 + n_out + 2 * t + 1];
            layout_ok = off >= (float)(code_at + 4 * n_code) && off <= (float)n && len >= 0.0f &&
                        len <= (float)n && (size_t)off + (size_t)len <= n;
        }
        const float head[6] = {h[0], h[1], h[2], h[3], h[4], h[5]};
        free(prog);
        CHECK(44, short_ok, "program %u written into a buffer one float short", kind);
        CHECK(44, sized_ok, "program %u: not %zu floats, or written past them", kind, n);
        CHECK(45, layout_ok,
              "program %u header: format %g, inputs %g, outputs %g, instructions %g, tables %g, "
              "length %g of %zu",
              kind, head[0], head[1], head[2], head[3], head[4], head[5], n);
    }
    CHECK(46, exported == STAM_PROGRAM_KINDS, "%zu program kinds exported", exported);
    const uint32_t bad_kinds[3] = {STAM_PROGRAM_KINDS, 1000u, 0xFFFFFFFFu};
    for (int i = 0; i < 3; ++i) {
        float small[4] = {-1.0f, -1.0f, -1.0f, -1.0f};
        CHECK(47, stam_brdf_export_program(b, bad_kinds[i], small, 4) == 0 &&
                      stam_brdf_export_program(b, bad_kinds[i], NULL, 0) == 0 && small[0] == -1.0f,
              "a program for the kind %u", bad_kinds[i]);
    }
    return 0;
}

/* The hooks of stam_program_run: counting, and leaving the work to the
 * executor (so the outputs must not change). */
struct hook_counts {
    size_t elementary, regions;
};
static int count_elementary(void *user, uint32_t op, size_t lanes, const float *a, const float *b,
                            float *out) {
    (void)op, (void)lanes, (void)a, (void)b, (void)out;
    ((struct hook_counts *)user)->elementary++;
    return 0;
}
static void count_region(void *user, size_t position, size_t first_lane, size_t lanes,
                         const uint8_t *runs) {
    (void)position, (void)first_lane, (void)lanes, (void)runs;
    ((struct hook_counts *)user)->regions++;
}

/* Checks of stam_program_run, stam_program_run_f64 and stam_param_name:
 * the eval program run on two lanes (normal and oblique mirror pairs) is
 * finite and within 1e-3 of stam_brdf_eval_spectral, in f32 and f64, with
 * and without hooks that decline (the same outputs, the hooks called);
 * its parameters at their stored values give the same as none given; a
 * wrong parameter count, a NULL or broken array are refused with a
 * message; parameter names. */
static int check_program_run(const StamBrdf *b, char *report, size_t report_len) {
    enum { L = 2 };
    const float x[7 * L] = {0.0f, 0.0f, 1.0f, 0.0f, 0.0f, 1.0f, 550.0f,
                            0.6f, 0.0f, 0.8f, -0.6f, 0.0f, 0.8f, 450.0f};
    const float wi[3 * L] = {0.0f, 0.0f, 1.0f, 0.6f, 0.0f, 0.8f};
    const float wo[3 * L] = {0.0f, 0.0f, 1.0f, -0.6f, 0.0f, 0.8f};
    const float lambda[L] = {550.0f, 450.0f};
    double x64[7 * L];
    for (int i = 0; i < 7 * L; ++i) x64[i] = x[i];
    float native[L], f[L], f_hooked[L], f_params[L];
    double f64[L];
    char err[256];
    stam_brdf_eval_spectral(b, L, wi, wo, lambda, native);
    const size_t n = stam_brdf_export_program(b, STAM_PROGRAM_EVAL_SPECTRAL, NULL, 0);
    CHECK(57, n > 0, "no spectral eval program");
    float *prog = malloc(n * sizeof(float));
    CHECK(57, prog != NULL, "out of memory");
    stam_brdf_export_program(b, STAM_PROGRAM_EVAL_SPECTRAL, prog, n);
    struct hook_counts counts = {0, 0};
    const int ran = stam_program_run(prog, n, x, L, NULL, 0, f, NULL, NULL, NULL, err, sizeof err);
    const int ran_hooked = stam_program_run(prog, n, x, L, NULL, 0, f_hooked, count_elementary,
                                            count_region, &counts, err, sizeof err);
    const int ran64 = stam_program_run_f64(prog, n, x64, L, NULL, 0, f64, err, sizeof err);
    /* The stored parameter values, given back (slots from the header). */
    const size_t n_par = (size_t)prog[6], par_at = 8 + (size_t)prog[2] + 2 * (size_t)prog[4];
    float params[STAM_PARAMS];
    for (size_t k = 0; k < n_par && k < STAM_PARAMS; ++k) params[k] = prog[par_at + 2 * k + 1];
    const int ran_params = n_par <= STAM_PARAMS &&
                           stam_program_run(prog, n, x, L, params, n_par, f_params, NULL, NULL,
                                            NULL, err, sizeof err);
    const int wrong_count =
        stam_program_run(prog, n, x, L, params, n_par + 1, f, NULL, NULL, NULL, err, sizeof err);
    const int wrong_count_named = strstr(err, "n_param_values") != NULL;
    prog[0] = 5.0f; /* another format */
    const int broken = stam_program_run(prog, n, x, L, NULL, 0, f, NULL, NULL, NULL, err,
                                        sizeof err);
    free(prog);
    CHECK(58, ran && ran_hooked && ran64 && ran_params, "stam_program_run failed: %s", err);
    for (int i = 0; i < L; ++i) {
        const float tol = 1e-3f * fabsf(native[i]) + 1e-6f;
        CHECK(59, isfinite(f[i]) && fabsf(f[i] - native[i]) <= tol &&
                      fabs(f64[i] - native[i]) <= tol,
              "lane %d: program %g (f64 %g), eval_spectral %g", i, f[i], f64[i], native[i]);
        CHECK(60, f_hooked[i] == f[i] && f_params[i] == f[i],
              "lane %d: declining hooks or the stored parameters changed %g to %g / %g", i, f[i],
              f_hooked[i], f_params[i]);
    }
    CHECK(61, counts.elementary > 0, "the elementary hook was never called");
    CHECK(62, !wrong_count && wrong_count_named, "a wrong parameter count was accepted");
    CHECK(63, !broken && err[0] != '\0', "a broken program array was run");
    CHECK(64, stam_program_run(NULL, 0, x, L, NULL, 0, f, NULL, NULL, NULL, err, sizeof err) == 0 &&
                  strstr(err, "NULL") != NULL,
          "a NULL program was run");
    CHECK(65, strcmp(stam_param_name(STAM_PARAM_PERIOD_UM), "period_um") == 0 &&
                  strcmp(stam_param_name(STAM_PARAM_SIGMA_UM), "sigma_um") == 0 &&
                  stam_param_name(STAM_PARAMS)[0] == '\0',
          "parameter names");
    return 0;
}

/* Checks of stam_brdf_export_mixture_program: the mixture pdf over 4
 * wavelengths (inputs wi, wo, lambda[4]; one output) run on a lane is the
 * mean of PDF_SPECTRAL's at each wavelength (run the same way), within
 * 1e-6 relative; N out of range, a kind out of range and NULL give 0. */
static float run_one(const StamBrdf *b, int mixture, uint32_t kind, uint32_t n_wl,
                     const float *x, char *err, size_t err_len) {
    const size_t n = mixture ? stam_brdf_export_mixture_program(b, kind, n_wl, NULL, 0)
                             : stam_brdf_export_program(b, kind, NULL, 0);
    float *prog = n ? malloc(n * sizeof(float)) : NULL, out = -1.0f;
    if (prog == NULL) return -1.0f;
    if (mixture)
        stam_brdf_export_mixture_program(b, kind, n_wl, prog, n);
    else
        stam_brdf_export_program(b, kind, prog, n);
    if (!stam_program_run(prog, n, x, 1, NULL, 0, &out, NULL, NULL, NULL, err, err_len))
        out = -1.0f;
    free(prog);
    return out;
}

static int check_mixture_program(const StamBrdf *b, char *report, size_t report_len) {
    const float wl[4] = {420.0f, 510.0f, 600.0f, 690.0f};
    float x[10] = {0.3f, 0.1f, 0.9486833f, -0.2f, 0.05f, 0.9783149f};
    char err[256];
    for (int j = 0; j < 4; ++j) x[6 + j] = wl[j];
    const float mixed = run_one(b, 1, STAM_MIXTURE_PDF, 4, x, err, sizeof err);
    float mean = 0.0f;
    for (int j = 0; j < 4; ++j) {
        float one[7] = {x[0], x[1], x[2], x[3], x[4], x[5], wl[j]};
        mean += 0.25f * run_one(b, 0, STAM_PROGRAM_PDF_SPECTRAL, 0, one, err, sizeof err);
    }
    CHECK(73, mixed > 0.0f && fabsf(mixed - mean) <= 1e-6f * mean,
          "mixture pdf %g against the mean of the wavelengths' %g (%s)", mixed, mean, err);
    CHECK(74, STAM_MIXTURE_KINDS == 3u && STAM_MIXTURE_MAX_WAVELENGTHS == 16u &&
                  stam_brdf_export_mixture_program(b, STAM_MIXTURE_PDF, 0, NULL, 0) == 0 &&
                  stam_brdf_export_mixture_program(b, STAM_MIXTURE_PDF, 17, NULL, 0) == 0 &&
                  stam_brdf_export_mixture_program(b, STAM_MIXTURE_KINDS, 4, NULL, 0) == 0 &&
                  stam_brdf_export_mixture_program(NULL, STAM_MIXTURE_PDF, 4, NULL, 0) == 0 &&
                  stam_brdf_export_mixture_program(b, STAM_MIXTURE_COHERENT, 16, NULL, 0) > 0,
          "mixture programs out of range");
    return 0;
}

/* stam_brdf_coherent_probability of the material params_json at n lanes,
 * for the Rust side to compare with Brdf::coherent_probability. Returns 0,
 * or -1 when the material is refused. */
int stam_c_caller_coherent_probability(const char *params_json, size_t n, const float *wi,
                                       const float *lambda_nm, float *out) {
    StamBrdf *b = stam_brdf_new(params_json, NULL, 0);
    if (b == NULL) return -1;
    stam_brdf_coherent_probability(b, n, wi, lambda_nm, out);
    stam_brdf_free(b);
    return 0;
}

int stam_c_caller_run(const char *params_json, char *report, size_t report_len) {
    char err[256];
    StamBrdf *bad = stam_brdf_new("{\"surface\":\"gaussian\",\"sigma_um\":-1,\"corr_um\":1}", err, sizeof err);
    CHECK(1, bad == NULL, "invalid parameters were accepted");
    CHECK(2, strstr(err, "sigma_um") != NULL, "error message does not name the key: %s", err);
    CHECK(3, stam_brdf_new(NULL, err, sizeof err) == NULL, "NULL json accepted");
    /* A host's own keys join an unknown key's message, with a suggestion;
     * a host key list that is not an array of strings is refused. */
    CHECK(66, stam_brdf_new_for_host("{\"surface\":\"cd\",\"twistt\":1}", "[\"twist\"]", err,
                                     sizeof err) == NULL &&
                  strstr(err, "twist)") != NULL && strstr(err, "did you mean 'twist'?") != NULL,
          "host keys in the message: %s", err);
    CHECK(67, stam_brdf_new_for_host("{\"surface\":\"cd\"}", "{}", err, sizeof err) == NULL &&
                  strstr(err, "host_keys_json") != NULL,
          "a bad host key list accepted: %s", err);
    {
        StamBrdf *h = stam_brdf_new_for_host("{\"surface\":\"cd\"}", NULL, err, sizeof err);
        CHECK(68, h != NULL, "stam_brdf_new_for_host without host keys: %s", err);
        stam_brdf_free(h);
    }
    /* A tiny error buffer must be truncated, NUL-terminated. */
    char tiny[4] = {'x', 'x', 'x', 'x'};
    CHECK(4, stam_brdf_new("{}", tiny, sizeof tiny) == NULL && tiny[3] == '\0', "truncation");

    StamBrdf *b = stam_brdf_new(params_json, err, sizeof err);
    CHECK(5, b != NULL, "construction failed: %s", err);

    enum { N = 4 };
    const float wi[3 * N] = {0.0f, 0.0f, 1.0f, 0.6f, 0.0f, 0.8f, 0.0f, 0.0f, -1.0f, NAN, 0.0f, 1.0f};
    const float wo[3 * N] = {0.0f, 0.0f, 1.0f, -0.6f, 0.0f, 0.8f, 0.0f, 0.0f, 1.0f, 0.0f, 0.0f, 1.0f};
    const float lambda[N] = {550.0f, 450.0f, 0.0f, NAN};
    float out[N], rgb[3 * N], wo_s[3 * N], pdf[N];
    uint8_t coherent[N];
    const float rnd[3 * N] = {0.1f, 0.2f, 0.3f, 0.5f, 0.5f, 0.5f, 0.9f, 0.1f, 0.7f, 0.3f, 0.8f, 0.2f};

    stam_brdf_eval_spectral(b, N, wi, wo, lambda, out);
    CHECK(6, finite_nonneg(out, N), "eval_spectral not finite/non-negative");
    CHECK(7, out[1] > 0.0f, "eval_spectral is zero at the mirror direction: %g", out[1]);
    CHECK(8, out[2] == 0.0f && out[3] == 0.0f, "below-horizon / NaN input not zero");
    stam_brdf_eval_rgb(b, N, wi, wo, rgb);
    CHECK(9, finite_nonneg(rgb, 3 * N) && rgb[3] + rgb[4] + rgb[5] > 0.0f, "eval_rgb");
    stam_brdf_coherent_spectral(b, N, wi, lambda, out);
    CHECK(10, finite_nonneg(out, N), "coherent_spectral");
    stam_brdf_coherent_rgb(b, N, wi, rgb);
    CHECK(11, finite_nonneg(rgb, 3 * N), "coherent_rgb");
    {
        /* Polarisation (b, c, s): finite at every lane, b^2 + c^2 + s^2 = 1
         * where the material has it (1), zeros where it has none (0:
         * rigorous gratings); 0 and zeros for a NULL material. */
        float pol[3 * N];
        int has = stam_brdf_polarization(b, N, wi, wo, lambda, pol);
        for (int i = 0; i < N; ++i) {
            float q = pol[3 * i] * pol[3 * i] + pol[3 * i + 1] * pol[3 * i + 1] +
                      pol[3 * i + 2] * pol[3 * i + 2];
            CHECK(75, isfinite(q) && (has ? fabsf(q - 1.0f) < 1e-4f : q == 0.0f),
                  "polarization lane %d: (%g, %g, %g), returned %d", i, pol[3 * i],
                  pol[3 * i + 1], pol[3 * i + 2], has);
        }
        /* Its program exists where it does and gives its values (lanes 0
         * and 1, in the band) within 1e-3 (a metal's index is read from
         * whole nanometres in the program). */
        const size_t np = stam_brdf_export_polarization_program(b, NULL, 0);
        CHECK(77, (np > 0) == (has == 1) &&
                      stam_brdf_export_polarization_program(NULL, NULL, 0) == 0,
              "polarization program: %zu floats, polarization returned %d", np, has);
        if (np > 0) {
            float *prog = malloc(np * sizeof(float));
            CHECK(77, prog != NULL, "out of memory");
            stam_brdf_export_polarization_program(b, prog, np);
            float x[7 * 2], o[3 * 2];
            for (int i = 0; i < 2; ++i) {
                for (int d = 0; d < 3; ++d) {
                    x[7 * i + d] = wi[3 * i + d];
                    x[7 * i + 3 + d] = wo[3 * i + d];
                }
                x[7 * i + 6] = lambda[i];
            }
            const int ran = stam_program_run(prog, np, x, 2, NULL, 0, o, NULL, NULL, NULL, err,
                                             sizeof err);
            free(prog);
            CHECK(78, ran, "polarization program did not run: %s", err);
            for (int i = 0; i < 6; ++i)
                CHECK(78, fabsf(o[i] - pol[i]) <= 1e-3f, "polarization program %d: %g, not %g",
                      i, o[i], pol[i]);
        }
        /* The Mueller matrix (22 floats a lane): finite, [0][0] = 1, unit
         * basis vectors perpendicular to their directions of travel, where
         * the material has one (every material here; rigorous gratings by
         * their own table), and zeros and 0 for a NULL material. Lanes
         * whose directions the core cannot take give a depolarizer. */
        float mm[22 * N];
        int has_m = stam_brdf_mueller(b, N, wo, wi, lambda, mm);
        CHECK(79, has_m == 1 || (has == 0 && has_m == 0), "mueller returned %d", has_m);
        for (int i = 0; has_m && i < N; ++i) {
            const float *m = mm + 22 * i;
            int finite = 1;
            for (int k = 0; k < 22; ++k)
                finite &= isfinite(m[k]);
            float s_in = m[16] * m[16] + m[17] * m[17] + m[18] * m[18];
            float s_out = m[19] * m[19] + m[20] * m[20] + m[21] * m[21];
            CHECK(79, finite && fabsf(m[0] - 1.0f) < 1e-5f && fabsf(s_in - 1.0f) < 1e-4f &&
                          fabsf(s_out - 1.0f) < 1e-4f,
                  "mueller lane %d: m00 %g, |s_in|^2 %g, |s_out|^2 %g", i, m[0], s_in, s_out);
            /* Perpendicular to -from (= -wo here) and to `to` (= wi), at
             * lanes with unit directions above the horizon (0 and 1). */
            if (i < 2) {
                float d_in = m[16] * wo[3 * i] + m[17] * wo[3 * i + 1] + m[18] * wo[3 * i + 2];
                float d_out = m[19] * wi[3 * i] + m[20] * wi[3 * i + 1] + m[21] * wi[3 * i + 2];
                CHECK(79, fabsf(d_in) < 1e-4f && fabsf(d_out) < 1e-4f,
                      "mueller lane %d bases not perpendicular: %g, %g", i, d_in, d_out);
            }
        }
        CHECK(80, stam_brdf_mueller(NULL, N, wo, wi, lambda, mm) == 0 && mm[0] == 0.0f &&
                      stam_brdf_mueller(b, N, NULL, wi, lambda, mm) == 0,
              "mueller of a NULL material or direction");
        CHECK(76, stam_brdf_polarization(NULL, N, wi, wo, lambda, pol) == 0 && pol[0] == 0.0f &&
                      stam_brdf_polarization(b, N, NULL, wo, lambda, pol) == 0,
              "polarization of a NULL material or direction");
    }

    stam_brdf_sample(b, N, wi, lambda, rnd, wo_s, pdf, coherent);
    CHECK(12, finite_nonneg(pdf, N), "sample pdf");
    for (int i = 0; i < N; ++i) {
        if (pdf[i] > 0.0f) {
            float len = sqrtf(wo_s[3 * i] * wo_s[3 * i] + wo_s[3 * i + 1] * wo_s[3 * i + 1] +
                              wo_s[3 * i + 2] * wo_s[3 * i + 2]);
            CHECK(13, fabsf(len - 1.0f) < 1e-4f, "sampled wo not unit: %g", len);
            CHECK(14, coherent[i] <= 1, "coherent flag not 0/1");
        }
    }
    stam_brdf_sample(b, N, wi, NULL, rnd, wo_s, pdf, coherent);
    CHECK(15, finite_nonneg(pdf, N), "RGB-mode sample pdf");
    stam_brdf_pdf(b, N, wi, wo, lambda, pdf);
    CHECK(16, finite_nonneg(pdf, N), "pdf");
    stam_brdf_pdf(b, N, wi, wo, NULL, pdf);
    CHECK(17, finite_nonneg(pdf, N), "RGB-mode pdf");
    {
        int code = check_coherent_probability(b, wi, lambda, report, report_len);
        if (code != 0) {
            stam_brdf_free(b);
            return code;
        }
    }

    /* Path-vertex calls: 2 wavelengths per lane (the lanes' pairs above). */
    {
        const float lam2[2 * N] = {550.0f, 600.0f, 450.0f, 700.0f, 0.0f, 550.0f, NAN, 500.0f};
        float f2[2 * N], p2[N], v2[2 * N], v3[3 * N];
        stam_brdf_eval_pdf_vertex(b, N, wi, wo, lam2, 2, f2, p2);
        CHECK(23, finite_nonneg(f2, 2 * N) && finite_nonneg(p2, N), "eval_pdf_vertex");
        CHECK(24, f2[2] > 0.0f && f2[3] > 0.0f && p2[1] > 0.0f, "eval_pdf_vertex zero at mirror");
        stam_brdf_eval_pdf_vertex(b, N, wi, wo, NULL, 0, v3, NULL);
        CHECK(25, finite_nonneg(v3, 3 * N), "eval_pdf_vertex RGB");
        stam_brdf_sample_vertex(b, N, wi, lam2, 2, rnd, wo_s, pdf, coherent, v2);
        CHECK(26, finite_nonneg(pdf, N) && finite_nonneg(v2, 2 * N), "sample_vertex");
        stam_brdf_sample_vertex(b, N, wi, NULL, 0, rnd, wo_s, pdf, NULL, v3);
        CHECK(27, finite_nonneg(pdf, N) && finite_nonneg(v3, 3 * N), "sample_vertex RGB");
        stam_brdf_sample_vertex(b, N, wi, lam2, 100, rnd, wo_s, pdf, coherent, NULL);
        CHECK(28, pdf[0] == 0.0f && pdf[1] == 0.0f, "nw out of range must give zeros");
        /* The combined call equals the two separate ones. */
        float f2b[2 * N], p2b[N], v2b[2 * N], wo_b[3 * N], pdf_b[N];
        uint8_t coh_b[N];
        stam_brdf_eval_pdf_vertex(b, N, wi, wo, lam2, 2, f2, p2);
        stam_brdf_sample_vertex(b, N, wi, lam2, 2, rnd, wo_s, pdf, coherent, v2);
        stam_brdf_eval_pdf_sample_vertex(b, N, wi, wo, lam2, 2, rnd, f2b, p2b, wo_b, pdf_b, coh_b, v2b);
        CHECK(29, memcmp(f2, f2b, sizeof f2) == 0 && memcmp(p2, p2b, sizeof p2) == 0 &&
                      memcmp(wo_s, wo_b, sizeof wo_b) == 0 && memcmp(pdf, pdf_b, sizeof pdf_b) == 0 &&
                      memcmp(coherent, coh_b, sizeof coh_b) == 0 && memcmp(v2, v2b, sizeof v2b) == 0,
              "eval_pdf_sample_vertex differs from the separate calls");
    }

    uint32_t flags = stam_brdf_flags(b);
    CHECK(18, flags < 8u, "unknown flag bits %u", flags);
    CHECK(19, stam_brdf_memory_bytes(b) > 0 && stam_brdf_memory_bytes(b) <= (4u << 20), "memory");
    CHECK(20, strlen(stam_version()) > 0, "version");

    {
        int code = check_export_program(b, report, report_len);
        if (code != 0) {
            stam_brdf_free(b);
            return code;
        }
    }
    {
        int code = check_program_run(b, report, report_len);
        if (code != 0) {
            stam_brdf_free(b);
            return code;
        }
    }
    {
        int code = check_mixture_program(b, report, report_len);
        if (code != 0) {
            stam_brdf_free(b);
            return code;
        }
    }

    /* Plausibility warnings: a unit mistake named, none for the paper's
     * disc, "" for NULL. */
    StamBrdf *w = stam_brdf_new("{\"surface\":\"gaussian\",\"sigma_um\":100,\"corr_um\":1000}",
                                err, sizeof err);
    CHECK(38, w != NULL && strstr(stam_brdf_warnings(w), "'sigma_um'") != NULL,
          "no warning naming sigma_um for sigma_um = 100");
    stam_brdf_free(w);
    w = stam_brdf_new("{\"surface\":\"cd\"}", err, sizeof err);
    CHECK(39, w != NULL && stam_brdf_warnings(w)[0] == '\0', "warnings for the paper's disc: %s",
          w ? stam_brdf_warnings(w) : "(refused)");
    stam_brdf_free(w);
    CHECK(40, stam_brdf_warnings(NULL) != NULL && stam_brdf_warnings(NULL)[0] == '\0',
          "NULL material's warnings");

    /* The resolved parameters: a JSON object that builds the same material
     * (the same values, the same resolved text); the disc's defaults
     * filled in; "" for NULL. */
    {
        const char *resolved = stam_brdf_params_json(b);
        CHECK(48, resolved != NULL && resolved[0] == '{', "params_json: %s",
              resolved ? resolved : "(NULL)");
        StamBrdf *again = stam_brdf_new(resolved, err, sizeof err);
        CHECK(49, again != NULL, "params_json does not build: %s", err);
        CHECK(50, strcmp(stam_brdf_params_json(again), resolved) == 0,
              "params_json of params_json differs: %s", stam_brdf_params_json(again));
        float rgb2[3 * N];
        stam_brdf_eval_rgb(b, N, wi, wo, rgb);
        stam_brdf_eval_rgb(again, N, wi, wo, rgb2);
        stam_brdf_free(again);
        CHECK(51, memcmp(rgb, rgb2, sizeof rgb) == 0, "params_json builds another material");
        w = stam_brdf_new("{\"surface\":\"cd\"}", err, sizeof err);
        CHECK(52, w != NULL && strstr(stam_brdf_params_json(w), "\"period_um\":2.5") != NULL &&
                      strstr(stam_brdf_params_json(w), "\"fresnel\":\"aluminium\"") != NULL,
              "the disc's defaults in params_json: %s", w ? stam_brdf_params_json(w) : "(refused)");
        stam_brdf_free(w);
        CHECK(53, stam_brdf_params_json(NULL) != NULL && stam_brdf_params_json(NULL)[0] == '\0',
              "NULL material's params_json");
    }

    /* The parameter reference: static JSON naming every surface's keys. */
    {
        const char *ref = stam_parameter_reference();
        CHECK(54, ref != NULL && ref[0] == '{' && strstr(ref, "\"surfaces\"") != NULL &&
                      strstr(ref, "\"coherence_um\"") != NULL && ref == stam_parameter_reference(),
              "parameter reference");
    }

    /* Rigorous efficiencies: an answer for a grating, a message naming the
     * bad key otherwise; the answer is freed by stam_text_free. */
    {
        char *answer = stam_rigorous_solve(
            "{\"period_um\":1,\"profile\":\"rect\",\"height_um\":1,\"width_um\":0.5,"
            "\"fresnel\":{\"eta\":0.22,\"k\":6.71},\"lambda_nm\":1000,\"theta_deg\":30,"
            "\"orders\":10}",
            err, sizeof err);
        CHECK(55, answer != NULL && strstr(answer, "\"reflected\"") != NULL && err[0] == '\0',
              "rigorous solve: %s", answer ? answer : err);
        stam_text_free(answer);
        answer = stam_rigorous_solve("{\"period_um\":-1}", err, sizeof err);
        CHECK(56, answer == NULL && strstr(err, "period_um") != NULL,
              "a bad rigorous request is refused by name: %s", err);
        stam_text_free(NULL);
    }

    /* Textures: which parameters take one, and the plan of one (the keys
     * to add, the range), or a message naming the parameter. */
    {
        CHECK(69, stam_param_takes_texture("sigma_um") == 1 &&
                      stam_param_takes_texture("height_um") == 1 &&
                      stam_param_takes_texture("corr_um") == 0 && stam_param_takes_texture(NULL) == 0,
              "stam_param_takes_texture");
        char *plan = stam_texture_plan("{\"surface\":\"gaussian\",\"corr_um\":2,\"fresnel\":0.9}",
                                       "sigma_um", 0.3, 0.1, err, sizeof err);
        CHECK(70, plan != NULL && strstr(plan, "\"sigma_um_max\":0.3") != NULL &&
                      strstr(plan, "\"range\":[1e-6,0.3]") != NULL &&
                      strstr(plan, "\"param\":0") != NULL && err[0] == '\0',
              "texture plan: %s", plan ? plan : err);
        stam_text_free(plan);
        plan = stam_texture_plan("{\"surface\":\"cd\"}", "sigma_um", 0.3, 0.1, err, sizeof err);
        CHECK(71, plan == NULL && strstr(err, "'sigma_um' takes a texture only") != NULL,
              "a misplaced texture is refused by name: %s", err);
        CHECK(72, stam_texture_plan(NULL, "sigma_um", 1, 1, err, sizeof err) == NULL &&
                      stam_texture_plan("{}", NULL, 1, 1, err, sizeof err) == NULL,
              "NULL inputs are refused");
    }

    /* NULL material: zeros, no crash. */
    stam_brdf_eval_spectral(NULL, N, wi, wo, lambda, out);
    CHECK(21, out[0] == 0.0f, "NULL material must give 0");
    CHECK(22, stam_brdf_flags(NULL) == 0u, "NULL flags");
    stam_brdf_free(b);
    stam_brdf_free(NULL);
    return 0;
}
