/* stam.h: C ABI of the Stam diffraction BRDF core (Rust library `stam`).
 *
 * Directions wi, wo: 3 floats per direction (x, y, z) in the local shading
 * frame (z = normal, x = tangent = the periodic direction of gratings, y =
 * bitangent), unit length, pointing away from the surface. Wavelengths in
 * nanometres. Lengths in the parameter JSON are micrometres.
 *
 * Every function is safe to call with any float values (NaN, below the
 * horizon, lambda = 0): outputs are finite and non-negative (0 where the BRDF
 * is undefined). NULL material pointers produce zeros. No function panics
 * or aborts; construction errors are reported through `err`.
 */
#ifndef STAM_H
#define STAM_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef struct StamBrdf StamBrdf;

/* Build a material from JSON parameters (see docs/parameters.md). Returns NULL
 * on error and writes a NUL-terminated message naming the bad key and its
 * accepted range into err (truncated to err_len bytes; err may be NULL). */
StamBrdf *stam_brdf_new(const char *params_json, char *err, size_t err_len);
/* stam_brdf_new for a host that reads keys of its own before the core sees
 * the JSON (a renderer's frame parameters, say): host_keys_json is a JSON
 * array of them (NULL: none). An unknown key's message then lists them among
 * the accepted keys and may suggest one ("did you mean 'twist'?"), so the
 * host need not parse the message. A host_keys_json that is not an array of
 * strings is refused. */
StamBrdf *stam_brdf_new_for_host(const char *params_json, const char *host_keys_json,
                                 char *err, size_t err_len);

/* Free a material (NULL is ignored). */
void stam_brdf_free(StamBrdf *brdf);

/* f(wi, wo; lambda) in 1/sr, NOT multiplied by cos, WITHOUT the coherent
 * delta lobe. n pairs; lambda_nm has one wavelength per pair. */
void stam_brdf_eval_spectral(const StamBrdf *b, size_t n, const float *wi, const float *wo,
                             const float *lambda_nm, float *out);

/* The same projected to linear sRGB (3 floats per pair), D65-weighted: a flat
 * spectrum maps to (1, 1, 1). Colours purer than the sRGB primaries (the
 * nearly monochromatic orders of gratings) are desaturated into the gamut at
 * constant luminance, so every channel is >= 0 and Y is exact. */
void stam_brdf_eval_rgb(const StamBrdf *b, size_t n, const float *wi, const float *wo,
                        float *out_rgb);

/* The polarisation of the reflection from wi to wo at lambda_nm (one
 * wavelength per pair): (b, c, s), 3 floats per pair, of the reflection's
 * Mueller matrix divided by its unpolarised value,
 * [[1, b, 0, 0], [b, 1, 0, 0], [0, 0, c, s], [0, 0, -s, c]], in the
 * conventions of Mitsuba's mueller::specular_reflection (Stokes bases
 * perpendicular to the plane of incidence of wi on the pair's half vector;
 * the host rotates them into its own). b^2 + c^2 + s^2 = 1. Surfaces whose
 * value is F^2 G K give the Fresnel reflection's at the half vector (a
 * constant reflectance: a perfect conductor's, (0, -1, 0)). Returns 1; 0
 * with out zero-filled for a NULL argument or a material without such a
 * polarisation (rigorous gratings: see stam_brdf_mueller). */
int stam_brdf_polarization(const StamBrdf *b, size_t n, const float *wi, const float *wo,
                           const float *lambda_nm, float *out);

/* The Mueller matrix of the reflection of light arriving from `from` and
 * leaving along `to` (unit directions in the material's frame, one
 * wavelength per pair), 22 floats per pair: the 4x4 matrix over its [0][0]
 * (the unpolarised value), row-major, then the Stokes basis vector (3) of
 * the incident direction of travel -from and that of `to`. Each basis
 * vector is perpendicular to its direction; the second axis of a basis is
 * d x (the first), the conventions of Mitsuba's mueller.h, so a host rotates
 * the matrix into its own bases (mueller::rotate_mueller_basis). Surfaces
 * whose value is F^2 G K: stam_brdf_polarization's matrix, its bases normal
 * to the plane of reflection on the half vector. Rigorous gratings: each
 * order's matrix from the solver's complex amplitudes, mixed over the
 * orders as f mixes them, in bases tied to the grooves (y x d); the first
 * call builds the grating's polarised table (seconds, progress on stderr,
 * cached on disk). Returns 1; 0 with out zero-filled for a NULL argument
 * or a material without a matrix (a rigorous grating with a cover). No JIT
 * program yet: JIT hosts depolarize rigorous gratings. */
int stam_brdf_mueller(const StamBrdf *b, size_t n, const float *from, const float *to,
                      const float *lambda_nm, float *out);

/* Reflectance of the coherent (mirror) delta lobe: F^2 exp(-g) for Gaussian
 * surfaces, 0 otherwise. */
void stam_brdf_coherent_spectral(const StamBrdf *b, size_t n, const float *wi,
                                 const float *lambda_nm, float *out);
void stam_brdf_coherent_rgb(const StamBrdf *b, size_t n, const float *wi, float *out_rgb);

/* Importance sampling. rnd: 3 uniforms in [0,1) per sample. lambda_nm: one
 * wavelength per sample (spectral mode) or NULL (RGB mode: a mixture serving
 * all visible wavelengths, with the matching mixture pdf). Writes wo (3 per
 * sample), pdf (solid-angle density of the whole strategy at wo; 0 when the
 * sample failed) and coherent[i] = 1 when the coherent delta lobe was chosen
 * (then wo is the mirror direction and pdf holds that lobe's discrete
 * probability). */
void stam_brdf_sample(const StamBrdf *b, size_t n, const float *wi, const float *lambda_nm,
                      const float *rnd, float *wo, float *pdf, uint8_t *coherent);

/* Solid-angle pdf of stam_brdf_sample at wo (non-coherent part); lambda_nm as
 * in stam_brdf_sample (NULL = RGB mode). The pdf returned by stam_brdf_sample
 * is this function at the returned (f32) wo. */
void stam_brdf_pdf(const StamBrdf *b, size_t n, const float *wi, const float *wo,
                   const float *lambda_nm, float *pdf);

/* Discrete probability with which stam_brdf_sample picks the coherent lobe
 * (what it reports as pdf for coherent samples); lambda_nm as above. */
void stam_brdf_coherent_probability(const StamBrdf *b, size_t n, const float *wi,
                                    const float *lambda_nm, float *out);

/* Spectral paths carrying N wavelengths lambda_1..lambda_N (e.g. hero
 * wavelength sampling): draw wo with ONE wavelength lambda_j, where j is
 * uniform among the N (or lambda_1 when the path's wavelengths are already
 * in random order), and weight every wavelength i by the mixture density
 *     p(wo) = (1/N) sum_i stam_brdf_pdf(wi, wo, lambda_i)
 * i.e. contribution_i = f(wi, wo; lambda_i) cos(theta_o) / p(wo). When the
 * coherent lobe was chosen (coherent = 1, wo = mirror direction) use
 *     P = (1/N) sum_i stam_brdf_coherent_probability(wi, lambda_i)
 * and contribution_i = coherent_reflectance(lambda_i) / P. This is the
 * one-sample mixture (balance heuristic) over the N per-wavelength
 * strategies: unbiased for every wavelength, including those whose lobes
 * the sampling wavelength does not cover (the defensive cosine share of
 * every strategy keeps p > 0 wherever f > 0). Dividing by the sampling
 * wavelength's pdf alone is unbiased too but has a large variance where the
 * other wavelengths' lobes lie (diffraction orders move with lambda). */

/* Path-vertex queries: what a path tracer asks at one vertex, each in one
 * call, for paths carrying nw wavelengths (lambda_nm: nw per lane,
 * lane-major, 1 <= nw <= 64) or RGB (lambda_nm = NULL, nw ignored). A lane
 * has nc values: nw, or 3 for RGB. The sampling strategy is, for nw
 * wavelengths, the one-sample mixture described above (the core picks the
 * sampling wavelength with rnd[0]); for RGB, stam_brdf_sample's RGB mode.
 *
 * eval_pdf: f (nc per lane, without cos and the coherent lobe; NULL to
 * skip) and pdf (the strategy's solid-angle density at wo; NULL to skip).
 *
 * sample: wo, pdf, coherent as in stam_brdf_sample, and value (nc per lane,
 * NULL to skip): f at wo for a glossy sample, whose pdf is the strategy's
 * density at the returned wo (stam_brdf_eval_pdf_vertex's pdf there); the
 * coherent lobe's reflectance for a coherent one, whose pdf is the
 * strategy's probability of that lobe. So the sample's weight is
 * value cos(theta_o) / pdf (glossy) or value / pdf (coherent). A failed
 * sample has pdf 0 and value 0. */
void stam_brdf_eval_pdf_vertex(const StamBrdf *b, size_t n, const float *wi, const float *wo,
                               const float *lambda_nm, size_t nw, float *f, float *pdf);
void stam_brdf_sample_vertex(const StamBrdf *b, size_t n, const float *wi,
                             const float *lambda_nm, size_t nw, const float *rnd, float *wo,
                             float *pdf, uint8_t *coherent, float *value);

/* Both at once (a path tracer's vertex: f and pdf towards the sampled
 * light, then a BSDF sample), sharing the lane's strategy: (wo, f, pdf) as
 * in stam_brdf_eval_pdf_vertex, (rnd, s_wo, s_pdf, s_coherent, s_value) as
 * (rnd, wo, pdf, coherent, value) in stam_brdf_sample_vertex. */
void stam_brdf_eval_pdf_sample_vertex(const StamBrdf *b, size_t n, const float *wi,
                                      const float *wo, const float *lambda_nm, size_t nw,
                                      const float *rnd, float *f, float *pdf, float *s_wo,
                                      float *s_pdf, uint8_t *s_coherent, float *s_value);

/* Flags describing the material, for renderers. */
#define STAM_FLAG_HAS_COHERENT 1u   /* a coherent delta lobe can be non-zero */
#define STAM_FLAG_ANISOTROPIC 2u    /* f depends on the azimuth of the frame */
#define STAM_FLAG_SPECTRALLY_VARYING 4u
uint32_t stam_brdf_flags(const StamBrdf *b);

/* Luminance weights of linear sRGB (the Y row of sRGB -> XYZ): the RGB
 * outputs are gamut-mapped at constant luminance with these weights. */
#define STAM_SRGB_LUMINANCE_R 0.2126
#define STAM_SRGB_LUMINANCE_G 0.7152
#define STAM_SRGB_LUMINANCE_B 0.0722

/* Programs for renderers that trace their code (Dr.Jit's symbolic loops
 * and calls, dr.freeze, CUDA; docs/jit.md): straight-line array operations
 * and the tables they read, which compute what the functions above compute.
 * The array's layout and operation codes: STAM_PROGRAM_FORMAT below (and
 * docs/jit.md). Each kind takes its inputs and gives its outputs in this
 * order (directions in the local frame, lambda in nm, u uniforms in
 * [0, 1)):
 *   EVAL_RGB          wi[3] wo[3]        -> f R, G, B (no cos, no coherent lobe)
 *   EVAL_SPECTRAL     wi[3] wo[3] lambda -> f
 *   PDF_RGB           wi[3] wo[3]        -> glossy density at wo (RGB strategy)
 *   PDF_SPECTRAL      wi[3] wo[3] lambda -> glossy density (lambda's strategy)
 *   SAMPLE_RGB        wi[3] u[3]         -> wo[3], coherent (1 or 0)
 *   SAMPLE_SPECTRAL   wi[3] u[3] lambda  -> wo[3], coherent
 *   COHERENT_RGB      wi[3]              -> coherent R, G, B, its probability
 *   COHERENT_SPECTRAL wi[3] lambda       -> coherent reflectance, probability
 * A glossy sample's density is PDF's at its wo; a coherent one's is the
 * probability. Returns the number of floats, 0 when the material has no
 * program of that kind or b is NULL; writes them to out only when out is
 * not NULL and capacity suffices (call with out = NULL to size it). */
#define STAM_PROGRAM_EVAL_RGB 0u
#define STAM_PROGRAM_EVAL_SPECTRAL 1u
#define STAM_PROGRAM_PDF_RGB 2u
#define STAM_PROGRAM_PDF_SPECTRAL 3u
#define STAM_PROGRAM_SAMPLE_RGB 4u
#define STAM_PROGRAM_SAMPLE_SPECTRAL 5u
#define STAM_PROGRAM_COHERENT_RGB 6u
#define STAM_PROGRAM_COHERENT_SPECTRAL 7u
#define STAM_PROGRAM_KINDS 8u
/* Added to a kind's code: that kind's program for a renderer that runs it
 * only while every parameter it reads has the value it was built with (the
 * parameter section's; no texture, no gradient, no update since). It may
 * leave out what only follows a parameter's change (the Gaussian RGB table's
 * derivative channels); the same inputs and outputs. The call returns 0
 * where that program would be the plain one. */
#define STAM_PROGRAM_AT_BUILT 256u
size_t stam_brdf_export_program(const StamBrdf *b, uint32_t kind, float *out,
                                size_t capacity);

/* The programs of a spectral renderer's one-sample mixture over the N
 * wavelengths a path carries (1 <= N <= STAM_MIXTURE_MAX_WAVELENGTHS): each
 * wavelength's strategy (the SPECTRAL kinds') one equally weighted
 * component, as the vertex calls above (nw wavelengths). Same array, same
 * STAM_PROGRAM_AT_BUILT flag; inputs and outputs:
 *   MIXTURE_PDF       wi[3] wo[3] lambda[N] -> the mixture's glossy density
 *                                              (the mean of PDF_SPECTRAL's)
 *   MIXTURE_SAMPLE    wi[3] u[3] lambda[N]  -> wo[3], coherent: u0 picks
 *                     wavelength j = floor(N u0), then SAMPLE_SPECTRAL at
 *                     lambda_j with u0 remapped to N u0 - j
 *   MIXTURE_COHERENT  wi[3] lambda[N]       -> each wavelength's coherent
 *                     reflectance (N), the mixture's probability (the mean)
 * Returns 0 where the material has no spectral programs, N is out of range
 * or b is NULL; sized and written as stam_brdf_export_program. */
#define STAM_MIXTURE_PDF 0u
#define STAM_MIXTURE_SAMPLE 1u
#define STAM_MIXTURE_COHERENT 2u
#define STAM_MIXTURE_KINDS 3u
#define STAM_MIXTURE_MAX_WAVELENGTHS 16u
size_t stam_brdf_export_mixture_program(const StamBrdf *b, uint32_t kind, uint32_t n_wavelengths,
                                        float *out, size_t capacity);

/* The program of stam_brdf_polarization: wi[3] wo[3] lambda -> b, c, s, as
 * that function gives them (the same generic source; a measured metal's index
 * read linearly from its values at each whole nanometre of 360-830 nm). The
 * JIT polarized variants run it. Returns 0 where stam_brdf_polarization
 * returns 0 (rigorous gratings) or b is NULL; sized and written as
 * stam_brdf_export_program. */
size_t stam_brdf_export_polarization_program(const StamBrdf *b, float *out, size_t capacity);

/* The numbers of inputs and outputs of program kind `kind` (STAM_PROGRAM_*,
 * n_wavelengths 0: the tables above) or of mixture kind `kind`
 * (STAM_MIXTURE_*) over n_wavelengths, written where the pointers are not
 * NULL: what a host checks an exported program against. Returns 1, or 0
 * (nothing written) for a kind or count that is not one. */
int stam_program_io(uint32_t kind, uint32_t n_wavelengths, uint32_t *inputs, uint32_t *outputs);

/* Material parameters a program reads through its parameter op (Param,
 * code 29): the array's parameter section lists (id, value) pairs, the
 * value the program was built with; a renderer may substitute its own
 * (a differentiated or textured value, the same units). Ids are stable;
 * new ones are appended. */
#define STAM_PARAM_SIGMA_UM 0u
#define STAM_PARAM_CORR_UM 1u /* an isotropic surface's (both axes) */
#define STAM_PARAM_CORR_X_UM 2u
#define STAM_PARAM_CORR_Y_UM 3u
#define STAM_PARAM_LAG_UM 4u
#define STAM_PARAM_PERIOD_UM 5u
#define STAM_PARAM_HEIGHT_UM 6u
#define STAM_PARAM_WIDTH_UM 7u
#define STAM_PARAM_COHERENCE_UM 8u
#define STAM_PARAM_TWIST 9u
#define STAM_PARAM_FRESNEL 10u /* the constant reflectance */
#define STAM_PARAM_ETA 11u
#define STAM_PARAM_K 12u
#define STAM_PARAMS 13u

/* How far (relative) a renderer may move a parameter a program reads
 * before it builds the material anew: within this the programs stay within
 * 1e-4 of the changed material's (1.1e-3 for the Gaussian RGB table of
 * isotropic metals); beyond it their tables and planned orders may not. */
#define STAM_PROGRAM_MAX_DRIFT 0.02

/* The name of parameter id `id` (the material's JSON key, e.g. "period_um"
 * for STAM_PARAM_PERIOD_UM); "" for an unknown id. A static string. */
const char *stam_param_name(uint32_t id);

/* The program array (what stam_brdf_export_program writes; docs/jit.md):
 * STAM_PROGRAM_HEADER_LEN header values (STAM_PROGRAM_FORMAT, inputs,
 * outputs, instructions, tables, total length, parameters, 0), the output
 * registers, (offset, length) per table, (STAM_PARAM_* id, value) per
 * parameter, four values per instruction (STAM_OP_* code, a, b, c;
 * register i is instruction i's result), then the tables' values; integers
 * stored as floats. Operation codes (their operands registers unless said;
 * a mask is 1 or 0, read as > 0): */
#define STAM_PROGRAM_FORMAT 4u
#define STAM_PROGRAM_HEADER_LEN 8u
#define STAM_OP_INPUT 0u /* input a */
#define STAM_OP_CONST 1u /* the float whose bits are a */
#define STAM_OP_ADD 2u
#define STAM_OP_SUB 3u
#define STAM_OP_MUL 4u
#define STAM_OP_DIV 5u
#define STAM_OP_MIN 6u
#define STAM_OP_MAX 7u
#define STAM_OP_FMA 8u /* a * b + c, rounded once */
#define STAM_OP_NEG 9u
#define STAM_OP_ABS 10u
#define STAM_OP_SQRT 11u
#define STAM_OP_EXP 12u
#define STAM_OP_LOG 13u /* natural logarithm */
#define STAM_OP_SIN 14u
#define STAM_OP_COS 15u
#define STAM_OP_ATAN2 16u /* the angle of (b, a) */
#define STAM_OP_FLOOR 17u
#define STAM_OP_LT 18u /* masks (1 or 0) from floats */
#define STAM_OP_LE 19u
#define STAM_OP_GT 20u
#define STAM_OP_GE 21u
#define STAM_OP_EQ 22u
#define STAM_OP_FINITE 23u /* a mask: a is neither NaN nor infinite */
#define STAM_OP_AND 24u /* masks from masks */
#define STAM_OP_OR 25u
#define STAM_OP_NOT 26u
#define STAM_OP_SELECT 27u /* mask a ? b : c */
#define STAM_OP_GATHER 28u /* table a at float index b (clamped into the table, NaN to 0, truncated) */
#define STAM_OP_PARAM 29u /* the parameter in slot a */
#define STAM_OP_IF 30u /* a region that runs where mask a holds (no value) */
#define STAM_OP_END_IF 31u /* the end of the region whose IF is register a */
#define STAM_OPS 32u

/* The core's CPU executor of a program array, for checks outside a
 * renderer: `lanes` lanes of inputs (lane-major, n_inputs floats each) into
 * outputs (lane-major, n_outputs each), every operation as a renderer's f32
 * kernel computes it (a region's registers are 0 on the lanes it does not
 * run on). param_values: NULL for the values the program was built with,
 * else one per parameter slot (n_param_values must be the program's
 * count). Optional hooks, called with `user`:
 *   elementary(user, op, n, a, b, out): STAM_OP_EXP, LOG, SIN, COS or ATAN2
 *     (b NULL but for ATAN2) of n lanes into out, returning 1, or 0 to
 *     leave it to the executor (a test passes its renderer's functions);
 *   on_region(user, position, first_lane, n, runs): at each IF (register
 *     `position`), whether each of n lanes from first_lane runs the region
 *     (1 or 0; its mask and every enclosing region's). Lanes are run in
 *     batches, so a region is reported once per batch.
 * Returns 1, or 0 with the reason in err (the array is not a valid program
 * of this format, a NULL array, a wrong parameter count). */
typedef int (*stam_program_elementary)(void *user, uint32_t op, size_t lanes, const float *a,
                                       const float *b, float *out);
typedef void (*stam_program_region)(void *user, size_t position, size_t first_lane,
                                    size_t lanes, const uint8_t *runs);
int stam_program_run(const float *program, size_t program_len, const float *inputs,
                     size_t lanes, const float *param_values, size_t n_param_values,
                     float *outputs, stam_program_elementary elementary,
                     stam_program_region on_region, void *user, char *err, size_t err_len);
/* stam_program_run in f64 arithmetic (to tell a program's logic from f32
 * rounding), without hooks. */
int stam_program_run_f64(const float *program, size_t program_len, const double *inputs,
                         size_t lanes, const double *param_values, size_t n_param_values,
                         double *outputs, char *err, size_t err_len);

/* Plausibility warnings of the material's parameters, one per line (no
 * trailing newline), "" when there are none or b is NULL: values that were
 * accepted but are almost surely a unit mistake or make the model
 * degenerate (e.g. sigma_um = 100, far into the Beckmann limit; a period
 * too short for any diffraction order). Each line names the parameter.
 * The string is owned by the material and lives until stam_brdf_free. */
const char *stam_brdf_warnings(const StamBrdf *b);

/* The material's parameters as a JSON object: every key it reads with the
 * value it took, defaults filled in (e.g. {"surface": "cd"} gives its
 * period_um, coherence_um, profile, height_um, width_um, fresnel, energy
 * and gradients); stam_brdf_new of this text builds the same material. A
 * key given in one of two forms keeps its form (corr_um, or corr_x_um and
 * corr_y_um). "" when b is NULL. The string is owned by the material and
 * lives until stam_brdf_free. */
const char *stam_brdf_params_json(const StamBrdf *b);

/* The parameter reference (docs/parameters.md) as a JSON object, from the
 * range constants the parameter readers check: {"version", "units",
 * "material": [key...], "surfaces": [{"surface": name, "keys": [key...]}]},
 * each key {"key", "meaning", "unit" ("um" or ""), "min", "max" (numbers,
 * null where none or relative to another key), "min_open", "integer",
 * "accepted" (in words), "required", "default" (null: none), "note"}; the
 * material's keys apply to every surface ("fresnel.eta": a key of the
 * object form of fresnel). Static storage. */
const char *stam_parameter_reference(void);

/* Textures on the material's numbers (JIT hosts: a value per point, which
 * the programs read as STAM_PARAM_*). stam_param_takes_texture: 1 where the
 * parameter `name` takes a texture on some material ('sigma_um' of a
 * Gaussian surface, 'height_um' of a rect or sine profile), else 0 (NULL
 * included). stam_texture_plan: how a material takes a texture on `name`.
 * `params_json` is the material's parameters without that key, `largest`
 * and `mean` the texture's largest finite value and its mean. Returns JSON
 * {"param": its STAM_PARAM_* id, "add": {key: number, ...}, the keys to add
 * to the material's parameters (the parameter itself at the mean clamped
 * into range; the largest value the programs are built for, 'sigma_um_max'
 * or 'height_um_max', unless given), "range": [lo, hi], into which each
 * point's value is clamped (NaN: lo)}, freed with stam_text_free; NULL with
 * the reason in err, naming the parameter, where the material cannot take
 * the texture. */
int stam_param_takes_texture(const char *name);
char *stam_texture_plan(const char *params_json, const char *name, double largest, double mean,
                        char *err, size_t err_len);

/* Bytes of memory the material holds (tables included; a Gaussian surface's
   RGB table once the first RGB evaluation has built it). */
size_t stam_brdf_memory_bytes(const StamBrdf *b);

/* Rigorous grating efficiencies (the Fourier modal method, docs/rigorous.md).
 * request_json: {"period_um", "profile": "rect"|"sine"|"tabulated",
 * "height_um", "width_um" (rect), "heights_um" (tabulated), "slices" (16),
 * "fresnel": a metal's name or {"eta", "k"}, "cover_eta" (1), "lambda_nm",
 * "theta_deg", "phi_deg" (0: plane of incidence across the grooves),
 * "orders" (N = 40: orders -N..N), "rule": "li"|"laurent"}. Returns JSON
 * {"orders", "reflected": [order...], "transmitted": [order...],
 * "reflectance": [s, p], "transmittance": [s, p]}, each order {"m",
 * "direction" (unit, z down into the substrate), "efficiency": [s, p],
 * "jones": 2x2 of [re, im], rows outgoing s/p, columns incident s/p}, to be
 * freed with stam_text_free; NULL with the message in err on bad input. */
char *stam_rigorous_solve(const char *request_json, char *err, size_t err_len);

/* Frees a string returned by stam_rigorous_solve or stam_texture_plan (NULL
 * is ignored). */
void stam_text_free(char *text);

/* Library version string, e.g. "0.1.0" (static storage). */
const char *stam_version(void);

#ifdef __cplusplus
}
#endif

#endif /* STAM_H */
