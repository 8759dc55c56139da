/* diffraction.cpp: Mitsuba 3.9 BSDF plugin for Stam's diffraction shader
 * (J. Stam, "Diffraction Shaders", SIGGRAPH 1999).
 *
 * This file contains no physics. It converts Mitsuba properties into the JSON
 * parameter object of the Rust core (rust-core/include/stam.h; params_json.h),
 * builds the local frame the core expects (twist, concentric tracks), and
 * forwards eval / pdf / sample to the core.
 *
 * Variants: scalar_* call the core's batch C ABI per query (batch.h stages
 * the arrays into host buffers, makes the call and loads the results back).
 * JIT variants (llvm_ad_*, cuda_ad_*) execute the core's programs
 * (stam_brdf_export_program: straight-line array code and its tables,
 * exported once per material) with Dr.Jit operations (program.h), so that
 * Dr.Jit traces them with its default flags: symbolic loops and calls,
 * dr.freeze, on LLVM and CUDA, with no host round trip (jit_path.h).
 *
 * Layout (as Mitsuba's roughconductor.cpp): the manual, the constructor,
 * traverse, parameters_changed, the BSDF methods, to_string, then the
 * private helpers and members.
 */

#include <mitsuba/core/fresolver.h>
#include <mitsuba/core/properties.h>
#include <mitsuba/core/spectrum.h>
#include <mitsuba/render/bsdf.h>
#include <mitsuba/render/interaction.h>
#include <mitsuba/render/mueller.h>
#include <mitsuba/render/shape.h>
#include <mitsuba/render/texture.h>

#include <cmath>
#include <cstdio>
#include <memory>
#include <mutex>
#include <sstream>
#include <string>
#include <typeinfo>
#include <vector>

#include "../rust-core/include/stam.h"
#include "batch.h"
#include "code_version.h"
#include "jit_path.h"
#include "params_json.h"
#include "plugin_params.h"
#include "shape_kind.h"
#include "param_textures.h"

NAMESPACE_BEGIN(mitsuba)

/**!

.. _bsdf-diffraction:

Diffraction BSDF (:monosp:`diffraction`)
----------------------------------------

.. pluginparameters::

 * - surface
   - |string|
   - Microsurface model: ``gaussian``, ``fractal``, ``periodic``, ``cd``
     (compact disc: a periodic surface with Stam's dimensions) or
     ``heightmap`` (a measured or synthetic height map, ``docs/heightmap.md``).
     (Default: none, required)
   - |exposed| (as a string, see below)
 * - sigma_um
   - |float| or |texture|
   - Gaussian surfaces: rms height (JIT variants: also a texture, point by point,
     up to its largest value or ``sigma_um_max``; one holding NaN is refused);
     fractal surfaces: rms height difference over ``lag_um``. Micrometres, in
     [1e-6, 100]. (Default: none, required)
   - |exposed|, |differentiable|
 * - corr_um
   - |float|
   - Gaussian surfaces: isotropic correlation length T. Micrometres, in
     [1e-3, 1e5]. (Default: none; give either it or both ``corr_x_um`` and
     ``corr_y_um``)
   - |exposed|
 * - corr_x_um, corr_y_um
   - |float|
   - Gaussian surfaces: anisotropic correlation lengths along the tangent
     (x, the tracks' periodic direction) and bitangent (y) (brushed metal).
     Micrometres, each in [1e-3, 1e5]. (Default: none)
   - |exposed|
 * - hurst
   - |float|
   - Fractal surfaces: Hurst exponent H (dimensionless), in [0.001, 1]. (Default: none, required)
   - |exposed|
 * - lag_um
   - |float|
   - Fractal surfaces: lag L over which the rms height difference is
     ``sigma_um``. Micrometres, in [1e-3, 1e5]. (Default: none, required)
   - |exposed|
 * - period_um
   - |float|
   - Periodic surfaces: period of the profile along the tangent (track
     pitch). Micrometres, in [0.05, 1000]. (Default: ``cd``: 2.5;
     ``periodic``: none, required)
   - |exposed|
 * - coherence_um
   - |float|
   - Periodic surfaces: coherence length l of the illumination. Micrometres,
     in [1.5 period, 1e4]. (Default: ``cd``: 50, at least 1.5 periods;
     ``periodic``: none, required)
   - |exposed|
 * - profile
   - |string|
   - Periodic surfaces: ``rect``, ``sine``, or a tabulated profile: 2 to
     65536 heights in micrometres, uniform over one period, written
     ``"0, 0.1, 0.2"``, ``"[0, 0.1, 0.2]"`` or ``{"heights_um": [0, 0.1,
     0.2]}``; finite, |h| <= 100. (Default: ``cd``: ``rect``; ``periodic``:
     none, required)
   - |exposed| (as a string)
 * - height_um
   - |float|
   - Periodic surfaces, ``rect`` and ``sine`` profiles: bump height (rect),
     peak-to-peak height (sine). Micrometres, in (0, 100]. JIT variants: also
     a texture (a groove-depth map), point by point; a sine profile's
     programs are built up to its largest value or ``height_um_max``.
     (Default: ``cd``: 0.15; otherwise none, required)
   - |exposed|
 * - width_um
   - |float|
   - Periodic surfaces, ``rect`` profile: bump width per period.
     Micrometres, in (0, period]. (Default: ``cd``: 0.5, at most the period;
     otherwise none, required)
   - |exposed|
 * - fresnel
   - |float| or |string|
   - Reflectance F^2 as a constant in (0, 1], or a metal with a measured
     spectral index: ``aluminium`` (also ``aluminum``, ``al``), ``silver``
     (``ag``), ``gold`` (``au``), ``copper`` (``cu``), ``chromium`` (``cr``).
     (Default: ``aluminium``)
   - |exposed| (a number, or a string)
 * - eta, k
   - |float|
   - Instead of ``fresnel``: a constant complex index of refraction
     eta + i k (dimensionless; eta in [1e-3, 100], k in [0, 100]; passed as
     ``"fresnel": {"eta": .., "k": ..}``). ``k`` needs ``eta``; ``eta``
     alone is a dielectric (k = 0: eta 1.5 reflects 4 % at normal
     incidence); metals need both. (Default: none; k: 0 when eta is given)
   - |exposed|
 * - energy
   - |string|
   - ``conserving``: Stam's f scaled by m(wi, lambda) m(wo, lambda) so
     that no direction reflects more light than it receives (reciprocal;
     the table is built from the material on its first use, 0.1-0.4 s;
     ``docs/energy.md``); ``stam``: the paper's formula, which near grazing
     directions can reflect several times what it receives. AD variants: a
     parameter's first gradient rebuilds the material once with the table's
     derivative along it, which gradients then follow (``docs/inverse.md``). (Default:
     ``conserving``; ``stam`` with a ``sigma_um`` texture or ``orders``
     ``rigorous``, which conserves energy by itself)
   - |exposed| (a string)
 * - orders
   - |string|
   - Periodic surfaces: where each diffraction order's power comes from.
     ``kirchhoff``: Stam's formula (scalar theory times Fresnel);
     ``rigorous``: Maxwell's equations, each order's efficiency from the
     core's rigorous solver, tabulated once per grating and metal (seconds,
     kept on disk; ``docs/rigorous.md``). Rigorous orders need ``fresnel``
     as a metal or ``eta``/``k``, conserve energy by themselves (no
     ``energy``), and run in every variant (JIT: periods up to about
     4 um).
     (Default: ``kirchhoff``)
   - |exposed| (a string)
 * - fourier_orders
   - |int|
   - ``orders`` ``rigorous``: Fourier orders N each side that the solver
     retains, an integer in [5, 200]. (Default: 20, more for periods above
     2.5 um / ``cover_eta``)
   - |exposed|
 * - cover_eta
   - |float|
   - ``orders`` ``rigorous``: refractive index of a transparent cover over
     the grating (a real disc's polycarbonate: 1.58), in [1, 3]: a mirror
     reflection on top, the orders diffracted inside and let out through
     it. (Default: 1, no cover)
   - |exposed|
 * - file
   - |string|
   - Height maps: the map, a ``.npy`` array, an OpenEXR ``.exr``, TIFF
     ``.tif`` or gray PNG ``.png`` image or a ``.csv`` table of heights
     (one channel, rows along y, 16 to 4096 samples each way), found as a
     bitmap's ``filename`` is (against the scene's folder and Mitsuba's
     search path). (Default: none, required)
   - |exposed| (a string)
 * - pixel_um
   - |float|
   - Height maps: spacing of the map's samples. Micrometres, in
     [1e-4, 100]; coarser than 0.09 um loses light scattered far from the
     mirror at short wavelengths (a warning). (Default: none, required)
   - |exposed|
 * - height_scale_um
   - |float|
   - Height maps: micrometres per unit of the map's values, in
     [1e-9, 1e6]. (Default: 1)
   - |exposed|
 * - tile_px
   - |int|
   - Height maps: edge of the Welch tiles that average the map's spectrum,
     a power of two in [16, 512], at most the map's smaller edge. (Default:
     20 correlation lengths of the map, 32 to 256)
   - |exposed|
 * - series_tolerance
   - |float|
   - Gaussian surfaces: relative truncation tolerance of the Poisson series
     (dimensionless), in [1e-12, 0.1]. (Default: 1e-5)
   - |exposed|
 * - rgb_nodes
   - |int|
   - Gaussian, fractal and height-map surfaces: wavelength nodes of the RGB
     rule for smooth spectra, an integer in [4, 64]. (Default: 12 for
     Gaussian, 8 for fractal, 24 for height-map surfaces)
   - |exposed|
 * - twist
   - |float| or |texture|
   - Rotation of the tangent frame (the tracks' periodic direction, the
     brushing direction) about the normal, in degrees, in [-360, 360]; a
     texture (a twist map, finite values) turns it point by point. (Default: 0)
   - |exposed|, |differentiable|
 * - tracks
   - |string|
   - How the tangent frame follows the shape. ``linear``: straight tracks
     along the shape's u direction (a rectangle's or a mesh's dp/du; on a
     ``disk``, whose uv is polar, its object x axis). ``concentric``: circular
     tracks about a centre, the periodic direction radial (a compact disc):
     on a ``disk`` about the point (2 center_u - 1, 2 center_v - 1) of its
     object space (its centre by default), on other shapes about (center_u,
     center_v) in uv space (a rectangle's centre by default; exact for any
     planar uv map, first order on curved ones). A mesh without texture
     coordinates defines neither: rendering it raises an error (for
     anisotropic materials; isotropic ones ignore the frame).
     (Default: ``linear``)
   - |exposed| (as a string)
 * - center_u, center_v
   - |float|
   - Centre of concentric tracks, in uv units (only with ``tracks`` =
     ``concentric``): (0.5, 0.5) is the middle of a rectangle, a disk and a
     mesh whose uv covers the unit square. (Default: 0.5, 0.5)
   - |exposed| (concentric tracks)

Only the parameters given by the user are passed to the core, which applies
its own defaults (the ones above, from ``rust-core/src/models/<model>/params.rs``) and
validates names and ranges; its error messages are raised as exceptions
naming the parameter (an unknown key's message lists every accepted key, the
plugin's own included, and the closest one). ``docs/parameters.md`` has the
same table for the core's JSON keys; ``docs/guide.md`` says what each
parameter does to the look and gives values of real objects.

Values that are accepted but almost surely a unit mistake or a degenerate
model (e.g. ``sigma_um`` = 100 meant as nanometres, far into the Beckmann
limit; a grating period that lets no diffraction order out) are reported as
warnings in Mitsuba's log, once per material (the core's
``stam_brdf_warnings``), and listed in the object's string form.

Every parameter is exposed through ``mi.traverse``: the ones the user
gives, ``twist`` and ``tracks`` always, ``center_u``, ``center_v`` with
concentric tracks, and the core's defaults of the keys left out (a compact
disc's ``period_um``, ``coherence_um``, ``profile``, ``height_um``,
``width_um``; a default ``fresnel``, ``energy``, ...: the values the core
took, ``stam_brdf_params_json``), with the flags they have when written. A
default stays out of the core's JSON until it is changed (the material is
built from the user's keys alone). In the AD variants (``llvm_ad_*``,
``cuda_ad_*``) the numbers the material's programs read are differentiable (the Gaussian
model's ``sigma_um`` and correlation lengths, the fractal's ``sigma_um``
and ``lag_um``, a constant ``fresnel``, ``eta`` and ``k``, ``twist`` of anisotropic
materials, a grating's period, coherence, height and width;
docs/inverse.md); the others are non-differentiable. Mitsuba's traversal carries numbers
and registered types but no strings, so the string parameters travel as a
``mi.Properties`` whose plugin name is the value: ``params['fresnel'] =
'gold'`` works (Mitsuba converts the string), and
``params['fresnel'].plugin_name()`` reads it. ``params.update()`` rebuilds
the core material (except, in JIT variants, when only differentiable
numbers changed, each by at most 2%: the programs and kernels stay, the
values reach them from memory); a refused update raises, naming the parameter, and
leaves the material exactly as it was (values, frame and core), so later
updates work. An update may not add or remove the coherent lobe (the
component layout is fixed at construction).

Components: 0 = the diffracted (glossy) lobe; 1 = the coherent mirror lobe
(a delta component, present when the core reports one, e.g. Gaussian
surfaces).

The BSDF is one-sided, like Mitsuba's conductors: it reflects light arriving
on the side the normal points to and is black from behind; wrap it in
``twosided`` for sheets seen from both sides. In polarized variants the
result is a Mueller matrix: the unpolarized value times the Fresnel
reflection's polarization at the pair's half vector (from the core: natively
in scalar variants, its program in JIT ones), in Mitsuba's Stokes bases, as
roughconductor's (docs/polarisation.md); rigorous gratings give each
order's matrix from the solver's amplitudes in scalar variants and still
depolarize in JIT ones. RGB variants receive the core's
D65-weighted linear sRGB integral; colours purer than the sRGB primaries (the nearly
monochromatic orders of gratings) are desaturated into the gamut at
constant luminance, so RGB renders of gratings are paler than spectral ones.

In spectral variants the BSDF is evaluated at the path's wavelengths. The
core samples a direction with one of them (the hero), chosen uniformly by the
first sample, and returns the mean of the wavelengths' densities, which is
exactly the strategy's density (the unbiased multi-wavelength mixture). Each
query goes to the core's path-vertex calls in one call per batch
(``eval_pdf_sample`` builds the strategy once for the light direction and the
sample). Monochromatic variants take the luminance of the core's RGB output
(with the core's weights, ``STAM_SRGB_LUMINANCE_*`` in stam.h).

JIT variants (``llvm_ad_*``, ``cuda_ad_*``) run the programs the core exports
for the material (``stam_brdf_export_program``) as Dr.Jit operations: they
work with Dr.Jit's default flags (symbolic loops and calls, ``dr.freeze``).
Their sampling is the programs' strategy (in spectral variants: one of the
path's wavelengths picked by the first sample, the pdf the mean of the
wavelengths' densities, as above).

.. tabs::
    .. code-tab:: xml

        <shape type="disk">
            <bsdf type="diffraction">
                <string name="surface" value="cd"/>
                <string name="tracks" value="concentric"/>
                <string name="fresnel" value="aluminium"/>
            </bsdf>
        </shape>

    .. code-tab:: python

        'type': 'diffraction',
        'surface': 'gaussian',
        'sigma_um': 0.03,
        'corr_um': 1.0,
        'fresnel': 'gold'
*/

// The host-side helpers (batch.h, params_json.h)
using diffraction_detail::Batch;
using diffraction_detail::BatchIO;
using diffraction_detail::CorePtr;
using diffraction_detail::json_escape;
using diffraction_detail::build_json;
using diffraction_detail::check_frame_params;
using diffraction_detail::describe;
using diffraction_detail::lines_of;
using diffraction_detail::tracks_are_linear;
using diffraction_detail::json_number;
using diffraction_detail::number_text;
using diffraction_detail::set_text;
using diffraction_detail::JitPath;
using diffraction_detail::param_id;
using diffraction_detail::scalar_of;
using diffraction_detail::shape_kind;
using diffraction_detail::mesh_without_uv_message;
using diffraction_detail::track_direction;
using diffraction_detail::to_core;
using diffraction_detail::from_core;
using diffraction_detail::registered_mesh_without_uv;
using diffraction_detail::UvShape;
using diffraction_detail::PolarDisk;
using diffraction_detail::MeshWithoutUv;
using diffraction_detail::ParamError;
using diffraction_detail::parse_profile_heights;
using diffraction_detail::run_batch;
using diffraction_detail::Scratch;

template <typename Float, typename Spectrum>
class Diffraction final : public BSDF<Float, Spectrum> {
public:
    MI_IMPORT_BASE(BSDF, m_flags, m_components)
    MI_IMPORT_TYPES(Shape, Texture)

    enum class Tracks { Linear, Concentric };

    using IO = BatchIO<Float, Spectrum>;
    using Param = diffraction_detail::PluginParam<Float>; // a parameter forwarded to the core
    using Jit = JitPath<Float, Spectrum>;
    using TableArrays = typename Jit::TableArrays;

    /// The plugin's own keys, which the core does not know, as a JSON array
    /// (the core lists them in an unknown key's message: stam_brdf_new_for_host).
    static const char *plugin_keys_json() {
        return R"(["eta", "k", "twist", "tracks", "center_u", "center_v"])";
    }

    Diffraction(const Properties &props) : Base(props) {
        static_assert(!IO::IsSpectral || IO::NW == IO::NC, "unexpected spectrum layout");

        // Plugin-level parameters are handled here; everything else is
        // forwarded to the core under its own name (the core refuses
        // unknown keys with a message naming them).
        // m_params grows only here (the user's keys, then the core's
        // defaults): traverse() hands out pointers into it

        try {
            bool has_center = false;
            for (auto it = props.begin(); it != props.end(); ++it) {
                std::string name(it->name());
                using PType = Properties::Type;
                PType type = it->type();

                if (name == "twist" && type == PType::Object) {
                    // A twist map (degrees; any texture, unbounded, no NaN)
                    m_twist_texture = props.get_unbounded_texture<Texture>("twist");
                    m_textures.refuse_nan("twist", m_twist_texture.get(), true);
                } else if (type == PType::Object && m_textures.take(props, name)) {
                    // sigma_um, height_um: a texture (param_textures.h)
                } else if (name == "twist") {
                    m_twist = (ScalarFloat) it->template get<double>();
                    m_twist_diff = Float(m_twist);
                } else if (name == "tracks") {
                    set_tracks(it->template get<std::string>());
                } else if (name == "center_u") {
                    m_center_u = (ScalarFloat) it->template get<double>();
                    has_center = true;
                } else if (name == "center_v") {
                    m_center_v = (ScalarFloat) it->template get<double>();
                    has_center = true;
                } else if (type == PType::Float || type == PType::Integer) {
                    Param p = Param::number(name, it->template get<double>(), param_id(name));
                    // eta, k: nested under "fresnel"
                    if (name == "eta" || name == "k")
                        p.group = "fresnel";
                    m_params.push_back(p);
                } else if (type == PType::String) {
                    Param p;
                    p.name = name;
                    std::string text = it->template get<std::string>();
                    // A height map's file, found as a bitmap's is: against
                    // the scene's folder and the resolver's search path
                    if (name == "file")
                        text = file_resolver()->resolve(text).string();
                    set_text(p, text);
                    m_params.push_back(p);
                } else if (type == PType::Bool) {
                    Param p;
                    p.name = name;
                    p.kind = Param::Bool;
                    p.text = it->template get<bool>() ? "true" : "false";
                    m_params.push_back(p);
                } else if (type == PType::Object) {
                    throw ParamError("parameter '" + name + "' cannot take a texture (of the "
                                     "material's parameters only " +
                                     m_textures.textured_names() + " can)");
                } else {
                    throw ParamError("parameter '" + name + "' has type " +
                                     std::string(property_type_name(type)) +
                                     "; only numbers and strings are accepted");
                }
            }
            if (has_center && m_tracks != Tracks::Concentric)
                throw ParamError("parameters 'center_u' and 'center_v' only apply to "
                                 "tracks = \"concentric\"");
            bool has_fresnel = false, has_eta = false, has_k = false;
            for (const Param &p : m_params) {
                has_fresnel |= p.name == "fresnel";
                has_eta |= p.name == "eta";
                has_k |= p.name == "k";
            }
            if (has_fresnel && (has_eta || has_k))
                throw ParamError("give either 'fresnel' or 'eta'/'k', not both");
            if (has_k && !has_eta)
                throw ParamError("parameter 'k' needs 'eta' (the complex index eta + i k; "
                                 "eta in " + diffraction_detail::core_accepted("fresnel.eta") + ")");

            m_textures.attach(m_params);
            check_frame();
            commit(build_core());
            // The core's defaults of the keys not given, exposed by traverse()
            // (left out of the core's JSON while unchanged: the same core)
            diffraction_detail::add_defaults(m_params, stam_brdf_params_json(m_core.get()));
            update_param_array();
        } catch (const ParamError &e) {
            Throw("diffraction: %s", e.what());
        }

        // Flags and components, declared once
        m_has_coherent = (m_core_flags & STAM_FLAG_HAS_COHERENT) != 0;
        uint32_t glossy = +BSDFFlags::GlossyReflection | +BSDFFlags::FrontSide;
        if ((m_core_flags & STAM_FLAG_ANISOTROPIC) || m_twist != 0.f || m_twist_texture ||
            m_tracks == Tracks::Concentric)
            glossy |= +BSDFFlags::Anisotropic;
        m_components.clear();
        m_components.push_back(glossy);
        if (m_has_coherent)
            m_components.push_back(+BSDFFlags::DeltaReflection | +BSDFFlags::FrontSide);
        m_flags = 0;
        for (uint32_t c : m_components)
            m_flags |= c;
        m_saved = snapshot();
        log_warnings();
    }

    void traverse(TraversalCallback *cb) override {
        Base::traverse(cb);
        for (Param &p : m_params) {
            if (p.from_texture)
                continue;
            if (p.kind == Param::Number && dr::is_jit_v<Float>)
                cb->put(p.name, p.diff, reads(p.id) ? ParamFlags::Differentiable
                                                    : ParamFlags::NonDifferentiable);
            else if (p.kind == Param::Number)
                cb->put(p.name, p.value, ParamFlags::NonDifferentiable);
            else if (p.kind == Param::String || p.kind == Param::Json)
                cb->put(p.name, p.holder, ParamFlags::NonDifferentiable);
        }
        m_textures.traverse(cb);
        if (m_twist_texture)
            cb->put("twist", m_twist_texture, ParamFlags::Differentiable);
        else if constexpr (dr::is_jit_v<Float>)
            cb->put("twist", m_twist_diff,
                    (m_components[0] & +BSDFFlags::Anisotropic) ? ParamFlags::Differentiable
                                                                : ParamFlags::NonDifferentiable);
        else
            cb->put("twist", m_twist, ParamFlags::NonDifferentiable);
        cb->put("tracks", m_tracks_holder, ParamFlags::NonDifferentiable);
        if (m_tracks == Tracks::Concentric) {
            cb->put("center_u", m_center_u, ParamFlags::NonDifferentiable);
            cb->put("center_v", m_center_v, ParamFlags::NonDifferentiable);
        }
    }

    /// Transactional: either every change is taken and the core rebuilt, or
    /// the material keeps exactly its previous parameters, frame and core,
    /// and the exception says why.
    void parameters_changed(const std::vector<std::string> &keys) override {
        Base::parameters_changed(keys);
        try {
            if (update_without_rebuild(keys)) {
                m_saved = snapshot();
                return;
            }
            // Strings arrive as the plugin name of their Properties holder
            for (Param &p : m_params)
                if ((p.kind == Param::String || p.kind == Param::Json) &&
                    std::string(p.holder.plugin_name()) != p.source)
                    set_text(p, std::string(p.holder.plugin_name()));
            if (std::string(m_tracks_holder.plugin_name()) != tracks_name(m_tracks))
                set_tracks(std::string(m_tracks_holder.plugin_name()));
            if constexpr (dr::is_jit_v<Float>) {
                for (Param &p : m_params)
                    if (p.kind == Param::Number)
                        p.value = scalar_of(p.diff, p.name);
                m_twist = scalar_of(m_twist_diff, "twist");
                diffraction_detail::add_gradient_names(m_params, m_gradients);
            }
            check_frame();
            Core core = build_core();
            if (((core.flags & STAM_FLAG_HAS_COHERENT) != 0) != m_has_coherent)
                throw ParamError(std::string("the change ") +
                                 (m_has_coherent ? "removes" : "adds") +
                                 " the coherent lobe; the component layout is fixed at "
                                 "construction (create a new BSDF instead)");
            commit(std::move(core));
        } catch (const std::exception &e) {
            restore(m_saved);
            Throw("diffraction: update refused, the material keeps its previous "
                  "parameters: %s", e.what());
        }
        m_saved = snapshot();
        // Anisotropy is a hint to integrators: follow the core and the frame
        if ((m_core_flags & STAM_FLAG_ANISOTROPIC) || m_twist != 0.f || m_twist_texture ||
            m_tracks == Tracks::Concentric) {
            m_components[0] |= +BSDFFlags::Anisotropic;
            m_flags |= +BSDFFlags::Anisotropic;
        }
        log_warnings();
    }

    // -----------------------------------------------------------------------
    // BSDF interface
    // -----------------------------------------------------------------------

    std::pair<BSDFSample3f, Spectrum> sample(const BSDFContext &ctx,
                                             const SurfaceInteraction3f &si,
                                             Float sample1, const Point2f &sample2,
                                             Mask active) const override {
        MI_MASKED_FUNCTION(ProfilerPhase::BSDFSample, active);
        Query q = make_query(ctx, si, nullptr, &sample1, &sample2, false, false, active);
        return { q.bs, as_spectrum(ctx, si, q.bs.wo, q.weight) };
    }

    Spectrum eval(const BSDFContext &ctx, const SurfaceInteraction3f &si,
                  const Vector3f &wo, Mask active) const override {
        MI_MASKED_FUNCTION(ProfilerPhase::BSDFEvaluate, active);
        return as_spectrum(ctx, si, wo,
                           make_query(ctx, si, &wo, nullptr, nullptr, true, false, active).value);
    }

    Float pdf(const BSDFContext &ctx, const SurfaceInteraction3f &si,
              const Vector3f &wo, Mask active) const override {
        MI_MASKED_FUNCTION(ProfilerPhase::BSDFEvaluate, active);
        return make_query(ctx, si, &wo, nullptr, nullptr, false, true, active).pdf;
    }

    std::pair<Spectrum, Float> eval_pdf(const BSDFContext &ctx,
                                        const SurfaceInteraction3f &si,
                                        const Vector3f &wo,
                                        Mask active) const override {
        MI_MASKED_FUNCTION(ProfilerPhase::BSDFEvaluate, active);
        Query q = make_query(ctx, si, &wo, nullptr, nullptr, true, true, active);
        return { as_spectrum(ctx, si, wo, q.value), q.pdf };
    }

    std::tuple<Spectrum, Float, BSDFSample3f, Spectrum>
    eval_pdf_sample(const BSDFContext &ctx, const SurfaceInteraction3f &si,
                    const Vector3f &wo, Float sample1, const Point2f &sample2,
                    Mask active) const override {
        MI_MASKED_FUNCTION(ProfilerPhase::BSDFSample, active);
        Query q = make_query(ctx, si, &wo, &sample1, &sample2, true, true, active);
        return { as_spectrum(ctx, si, wo, q.value), q.pdf, q.bs,
                 as_spectrum(ctx, si, q.bs.wo, q.weight) };
    }

    std::string to_string() const override {
        std::ostringstream oss;
        oss << "Diffraction[" << std::endl;
        describe(oss, m_params);
        m_textures.describe(oss);
        oss << "  twist = ";
        if (m_twist_texture)
            oss << string::indent(m_twist_texture) << "," << std::endl;
        else
            oss << m_twist << "," << std::endl;
        oss << "  tracks = " << tracks_name(m_tracks);
        if (m_tracks == Tracks::Concentric)
            oss << "," << std::endl
                << "  center_u = " << m_center_u << "," << std::endl
                << "  center_v = " << m_center_v;
        oss << "," << std::endl
            << "  core_json = " << m_json << "," << std::endl
            << "  coherent_lobe = " << (m_has_coherent ? "true" : "false");
        if (!m_warnings.empty())
            oss << "," << std::endl << "  warnings = " << json_escape(m_warnings);
        if constexpr (dr::is_jit_v<Float>) {
            oss << "," << std::endl << "  jit_programs = ";
            m_jit.describe(oss, dr::width(m_tables.values));
        }
        oss << std::endl << "]";
        return oss.str();
    }

    MI_DECLARE_CLASS(Diffraction)

private:
    /// What parameters_changed restores when it refuses an update
    struct State {
        std::vector<Param> params;
        ScalarFloat twist = 0.f, center_u = 0.5f, center_v = 0.5f;
        Tracks tracks = Tracks::Linear;
        bool tracks_given = false;
    };

    /// The value (f cos, or a sample's weight) of the reflection from
    /// si.wi to wo (local frame) as the variant's Spectrum. Polarized
    /// variants: a Mueller matrix, the value times the core's polarisation
    /// of the reflection (the Fresnel reflection's at the half vector, in
    /// the conventions of Mitsuba's mueller::specular_reflection; scalar
    /// variants: stam_brdf_polarization, JIT ones: its program), its Stokes
    /// bases rotated into the implicit ones of the directions the light
    /// travels along, as Mitsuba's roughconductor does. Rigorous gratings:
    /// the core's matrix of their orders in scalar variants
    /// (rigorous_mueller); JIT variants depolarize them.
    Spectrum as_spectrum(const BSDFContext &ctx, const SurfaceInteraction3f &si,
                         const Vector3f &wo, const UnpolarizedSpectrum &value) const {
        if constexpr (!is_polarized_v<Spectrum>) {
            DRJIT_MARK_USED(ctx);
            DRJIT_MARK_USED(si);
            DRJIT_MARK_USED(wo);
            return depolarizer<Spectrum>(value);
        } else {
            Vector3f sum = si.wi + wo;
            // (b, c, s) per wavelength
            std::array<UnpolarizedSpectrum, 3> pol;
            if constexpr (dr::is_jit_v<Float>) {
                if (!m_jit.has_polarization())
                    return depolarizer<Spectrum>(value);
                pol = m_jit.polarization(si.wi, wo, si.wavelengths, m_tables,
                                         jit_params(si, Mask(true)));
            } else {
                constexpr size_t NW = dr::size_v<UnpolarizedSpectrum>;
                if (!m_core || !(dr::squared_norm(sum) > 0.f))
                    return depolarizer<Spectrum>(value);
                float wi3[3 * NW], wo3[3 * NW], lambda[NW], out[3 * NW];
                for (size_t j = 0; j < NW; ++j) {
                    for (size_t d = 0; d < 3; ++d) {
                        wi3[3 * j + d] = si.wi[d];
                        wo3[3 * j + d] = wo[d];
                    }
                    lambda[j] = si.wavelengths[j];
                }
                if (!stam_brdf_polarization(m_core.get(), NW, wi3, wo3, lambda, out))
                    return rigorous_mueller(ctx, si, wo, value);
                for (size_t j = 0; j < NW; ++j)
                    for (size_t c = 0; c < 3; ++c)
                        pol[c][j] = out[3 * j + c];
            }
            UnpolarizedSpectrum vb = value * pol[0], vc = value * pol[1], vs = value * pol[2],
                                zero(0.f);
            Spectrum m(value, vb, zero, zero,
                       vb, value, zero, zero,
                       zero, zero, vc, vs,
                       zero, zero, -vs, vc);
            // The light arrives along -towards and leaves along away (which
            // of wi and wo is which follows the transport mode).
            Mask radiance = Mask(ctx.mode == TransportMode::Radiance);
            Vector3f towards = dr::select(radiance, wo, si.wi),
                     away = dr::select(radiance, si.wi, wo);
            Vector3f h = dr::normalize(sum);
            // The matrix's s axes: normal to the plane of reflection; along
            // the normal (no plane), or where wi + wo is 0 (f is 0), any axis.
            Vector3f s_in = dr::cross(h, -towards), s_out = dr::cross(h, away);
            Mask planar = dr::squared_norm(s_in) > 0.f && dr::squared_norm(s_out) > 0.f;
            s_in = dr::select(planar, dr::normalize(s_in), Vector3f(1.f, 0.f, 0.f));
            s_out = dr::select(planar, dr::normalize(s_out), Vector3f(1.f, 0.f, 0.f));
            return mueller::rotate_mueller_basis(m, -towards, s_in, mueller::stokes_basis(-towards),
                                                 away, s_out, mueller::stokes_basis(away));
        }
    }

    /// Scalar polarized variants, a material whose matrix is its own
    /// (rigorous gratings): the core's Mueller matrix (stam_brdf_mueller,
    /// each order's from the solver's amplitudes) for the light's path,
    /// times the value, its bases (the core's, in the core's frame) rotated
    /// into Mitsuba's. Depolarizes where the core has none (a cover).
    Spectrum rigorous_mueller(const BSDFContext &ctx, const SurfaceInteraction3f &si,
                              const Vector3f &wo, const UnpolarizedSpectrum &value) const {
        if constexpr (!is_polarized_v<Spectrum> || dr::is_jit_v<Float>) {
            DRJIT_MARK_USED(ctx);
            DRJIT_MARK_USED(si);
            DRJIT_MARK_USED(wo);
            return depolarizer<Spectrum>(value);
        } else {
            constexpr size_t NW = dr::size_v<UnpolarizedSpectrum>;
            // The light arrives along -towards and leaves along away.
            bool radiance = ctx.mode == TransportMode::Radiance;
            Vector3f towards = radiance ? wo : si.wi, away = radiance ? si.wi : wo;
            auto [c, s] = frame_rotation(si, Mask(true));
            Vector3f from_c = to_core(towards, c, s), to_c = to_core(away, c, s);
            float from3[3 * NW], to3[3 * NW], lambda[NW], out[22 * NW];
            for (size_t j = 0; j < NW; ++j) {
                for (size_t d = 0; d < 3; ++d) {
                    from3[3 * j + d] = from_c[d];
                    to3[3 * j + d] = to_c[d];
                }
                lambda[j] = si.wavelengths[j];
            }
            if (!m_core || !stam_brdf_mueller(m_core.get(), NW, from3, to3, lambda, out))
                return depolarizer<Spectrum>(value);
            Spectrum m;
            for (size_t r = 0; r < 4; ++r)
                for (size_t k = 0; k < 4; ++k)
                    for (size_t j = 0; j < NW; ++j)
                        m(r, k)[j] = value[j] * out[22 * j + 4 * r + k];
            // One pair of bases for all wavelengths (they depend on the
            // directions alone)
            Vector3f s_in = from_core(Vector3f(out[16], out[17], out[18]), c, s),
                     s_out = from_core(Vector3f(out[19], out[20], out[21]), c, s);
            return mueller::rotate_mueller_basis(m, -towards, s_in, mueller::stokes_basis(-towards),
                                                 away, s_out, mueller::stokes_basis(away));
        }
    }

    /// A core material built from the current parameters, not yet in use
    struct Core {
        CorePtr ptr;
        std::string json;
        uint32_t flags = 0;
        std::string warnings;
        Jit jit; // JIT variants: the core's programs (jit_path.h)
    };

    /// Everything one call can ask of the core, in the local frame
    struct Query {
        UnpolarizedSpectrum value;  // f * cos at wo
        Float pdf;                  // pdf at wo
        BSDFSample3f bs;
        UnpolarizedSpectrum weight; // sample weight
    };

    static const char *tracks_name(Tracks t) {
        return t == Tracks::Linear ? "linear" : "concentric";
    }

    void set_tracks(const std::string &t) {
        m_tracks = tracks_are_linear(t) ? Tracks::Linear : Tracks::Concentric;
        m_tracks_holder.set_plugin_name(tracks_name(m_tracks));
        m_tracks_given = true;
    }

    /// Whether the material's programs read the parameter `id` (JIT
    /// variants: its value, and gradients, flow into them)
    bool reads(int id) const {
        if constexpr (dr::is_jit_v<Float>) {
            std::vector<uint32_t> ids = m_jit.param_ids();
            return id >= 0 && std::find(ids.begin(), ids.end(), (uint32_t) id) != ids.end();
        } else {
            DRJIT_MARK_USED(id);
            return false;
        }
    }

    /// JIT variants: the parameter array for the current programs
    /// (plugin_params.h); the built values' programs into or out of use
    /// change the code (code_version.h)
    void update_param_array() {
        if constexpr (dr::is_jit_v<Float>)
            if (m_param_array.update(m_jit.built_values(), m_params))
                m_code_version.bump();
    }

    /// JIT variants, an update that changes only parameters the programs
    /// read, each by at most MaxDriftWithoutRebuild of the value they were
    /// built with: the programs stay (and with them the kernels), the new
    /// values reach them through the parameter array. Else (false) the
    /// material is rebuilt.
    bool update_without_rebuild(const std::vector<std::string> &keys) {
        if constexpr (dr::is_jit_v<Float>) {
            // A parameter's first gradient: rebuilt with programs that follow
            // it smoothly (the energy table's derivative along it, ...)
            std::vector<std::string> names = m_gradients;
            if (keys.empty() || diffraction_detail::add_gradient_names(m_params, names))
                return false;
            for (const std::string &k : keys) {
                if (k == "twist" || m_textures.owns(k))
                    continue; // read per point, or from memory
                auto it = std::find_if(m_params.begin(), m_params.end(),
                                       [&](const Param &p) { return p.name == k; });
                if (it == m_params.end() || it->kind != Param::Number)
                    return false;
                // A parameter the programs do not read (built value NaN)
                // fails the comparison too
                ScalarFloat v = scalar_of(it->diff, it->name);
                if (!(std::abs(v / m_param_array.built(it->id) - 1.f) <= MaxDriftWithoutRebuild))
                    return false;
            }
            for (Param &p : m_params)
                if (p.kind == Param::Number)
                    p.value = scalar_of(p.diff, p.name);
            m_twist = scalar_of(m_twist_diff, "twist");
            check_frame();
            update_param_array();
            settle_twist();
            return true;
        } else {
            DRJIT_MARK_USED(keys);
            return false;
        }
    }

    /// JIT variants: the twist in memory (a literal would make a kernel per
    /// value), keeping a gradient the user gave it
    void settle_twist() {
        if constexpr (dr::is_jit_v<Float>) {
            if (dr::grad_enabled(m_twist_diff))
                dr::make_opaque(m_twist_diff);
            else
                m_twist_diff = dr::opaque<Float>(m_twist);
        }
    }

    /// The twist's rotation (cos, sin): differentiable in JIT variants where
    /// the twist carries a gradient
    std::pair<Float, Float> twist_rotation(const SurfaceInteraction3f &si, Mask active) const {
        if (m_twist_texture) {
            // The twist map's value at the point, in degrees
            auto [s, c] = dr::sincos(m_twist_texture->eval_1(si, active) *
                                     (dr::Pi<ScalarFloat> / 180.f));
            return { c, s };
        }
        if constexpr (dr::is_jit_v<Float>) {
            // From memory (no kernel per value), differentiable
            auto [s, c] = dr::sincos(m_twist_diff * (dr::Pi<ScalarFloat> / 180.f));
            return { c, s };
        }
        return { Float(m_cos_twist), Float(m_sin_twist) };
    }

    /// The plugin's frame parameters: finite, twist within a turn
    void check_frame() const { check_frame_params(m_twist, m_center_u, m_center_v); }

    State snapshot() const {
        return State{ m_params, m_twist, m_center_u, m_center_v, m_tracks, m_tracks_given };
    }

    /// Back to a snapshot, in place: traverse() handed out pointers into
    /// m_params, so its elements are assigned, never reallocated.
    void restore(const State &s) {
        for (size_t i = 0; i < m_params.size() && i < s.params.size(); ++i)
            m_params[i] = s.params[i];
        m_twist = s.twist;
        m_twist_diff = Float(m_twist);
        settle_twist();
        m_center_u = s.center_u;
        m_center_v = s.center_v;
        m_tracks = s.tracks;
        m_tracks_given = s.tracks_given;
        m_tracks_holder.set_plugin_name(tracks_name(m_tracks));
    }

    /// A core material from the current parameters; throws ParamError with
    /// the core's message (which lists the plugin's keys too) when refused.
    Core build_core() const {
        Core c;
        c.json = build_json(m_params, m_gradients);
        char err[4096] = { 0 };
        c.ptr.reset(stam_brdf_new_for_host(c.json.c_str(), plugin_keys_json(), err, sizeof(err)));
        if (!c.ptr)
            throw ParamError(err[0] ? err : "the core refused the parameters");
        c.flags = stam_brdf_flags(c.ptr.get());
        c.warnings = stam_brdf_warnings(c.ptr.get());
        if constexpr (dr::is_jit_v<Float>)
            c.jit = Jit::build(c.ptr.get());
        return c;
    }

    void commit(Core &&c) {
        // Defaults nobody changed follow the new core's (plugin_params.h)
        diffraction_detail::refresh_defaults(m_params, stam_brdf_params_json(c.ptr.get()));
        m_core = std::move(c.ptr);
        m_json = std::move(c.json);
        m_core_flags = c.flags;
        m_pending_warnings = std::move(c.warnings);
        if constexpr (dr::is_jit_v<Float>) {
            m_tables = c.jit.load_tables();
            m_jit = std::move(c.jit);
            m_code_version.bump(); // code_version.h
            update_param_array();
            settle_twist();
        }
        double t = (double) m_twist * M_PI / 180.0;
        m_cos_twist = (ScalarFloat) std::cos(t);
        m_sin_twist = (ScalarFloat) std::sin(t);
    }

    /// The core's plausibility warnings, logged once per material (again
    /// only when an update changes them)
    void log_warnings() {
        if (m_pending_warnings == m_warnings)
            return;
        m_warnings = m_pending_warnings;
        for (const std::string &line : lines_of(m_warnings))
            Log(Warn, "diffraction: %s", line);
    }

    /// How the shape of each lane defines the tracks. Throws for a mesh
    /// without texture coordinates (active lanes only).
    UInt32 shape_kinds(const SurfaceInteraction3f &si, Mask active) const {
        std::string bad_mesh;
        auto kind_of = [&bad_mesh](const Shape *shape) -> uint32_t {
            uint32_t kind = shape_kind(shape);
            if (kind == MeshWithoutUv)
                bad_mesh = shape->id();
            return kind;
        };
        UInt32 kind;
        if constexpr (dr::is_jit_v<Float>) {
            if (jit_flag(JitFlag::SymbolicScope) || jit_flag(JitFlag::FreezingScope)) {
                // Recorded code has no values to look at: the shape's type
                // through Mitsuba's vectorised getter; a mesh without uv
                // that carries this material is found among the registered
                // shapes while the code is recorded.
                check_registered_meshes();
                if (jit_flag(JitFlag::FreezingScope)) {
                    UInt32 type = si.shape->shape_type(active);
                    return dr::select(type == (uint32_t) +ShapeType::Disk,
                                      UInt32((uint32_t) PolarDisk), UInt32((uint32_t) UvShape));
                }
                // The registered shapes' kinds from one array that every
                // diffraction material reads: Mitsuba's shape_type() getter
                // makes an array of its own per call, so that two materials
                // of otherwise identical code traced different code, which
                // Dr.Jit compiled twice (two compact discs of other twists
                // beside a diffuse floor: 87,435 operations against 44,384
                // for one)
                return dr::gather<UInt32>(registered_shape_kinds(),
                                          UInt32::borrow(si.shape.index()), active);
            }
            kind = dr::dispatch(
                si.shape,
                [&kind_of](const Shape *shape, Mask lanes) {
                    return dr::select(lanes, UInt32(kind_of(shape)), UInt32(0u));
                },
                active);
        } else {
            kind = active ? kind_of(si.shape) : (uint32_t) UvShape;
        }
        if (dr::any(active && kind == (uint32_t) MeshWithoutUv))
            throw_mesh_without_uv(bad_mesh);
        return kind;
    }

    /// Per registry id of the variant's shapes, its kind (PolarDisk or
    /// UvShape), one array shared by the materials while the shapes stay
    /// the same (made anew when they change; dropped with the last
    /// material, before Dr.Jit shuts down)
    static UInt32 registered_shape_kinds() {
        const char *variant = Shape::Variant, *domain = Shape::Domain;
        uint32_t bound = jit_registry_id_bound(variant, domain);
        std::vector<uint32_t> kinds(bound + 1, (uint32_t) UvShape);
        for (uint32_t id = 1; id <= bound; ++id) {
            auto *shape = (const Shape *) jit_registry_ptr(variant, domain, id);
            if (shape && shape->shape_type() == +ShapeType::Disk)
                kinds[id] = PolarDisk;
        }
        std::lock_guard<std::mutex> guard(s_shared.mutex);
        if (!s_shared.kinds || kinds != s_shared.kind_values) {
            s_shared.kinds = std::make_unique<UInt32>(dr::load<UInt32>(kinds.data(), kinds.size()));
            s_shared.kind_values = std::move(kinds);
        }
        return *s_shared.kinds;
    }

    [[noreturn]] void throw_mesh_without_uv(const std::string &mesh) const {
        // Names the tracks only where the user chose them
        Throw("diffraction: %s",
              mesh_without_uv_message(m_tracks_given ? tracks_name(m_tracks) : nullptr, mesh));
    }

    /// JIT variants, recorded code: throws for a registered mesh without
    /// texture coordinates that carries this material
    void check_registered_meshes() const {
        std::string mesh = registered_mesh_without_uv<Shape>(this);
        if (!mesh.empty())
            throw_mesh_without_uv(mesh);
    }

    /// Rotation (c, s) of the core's tangent (the periodic direction of
    /// gratings, the x correlation length) in the local (xy) plane: core
    /// x = (c, s, 0), core y = (-s, c, 0). Then `twist`.
    std::pair<Float, Float> frame_rotation(const SurfaceInteraction3f &si, Mask active) const {
        // An isotropic core gives the same values in any frame
        if (!(m_core_flags & STAM_FLAG_ANISOTROPIC))
            return { Float(1.f), Float(0.f) };
        UInt32 kind = shape_kinds(si, active);
        Mask disk = kind == (uint32_t) PolarDisk;
        const bool linear = m_tracks == Tracks::Linear;
        auto [cos_t, sin_t] = twist_rotation(si, active);
        if (linear && dr::none_or<false>(disk && active))
            return { cos_t, sin_t };

        auto [c0, s0] = track_direction(si, disk, linear, m_center_u, m_center_v);
        return { c0 * cos_t - s0 * sin_t, s0 * cos_t + c0 * sin_t };
    }

    /// What a query asks and where: the lobes, the active lanes (eval: wi
    /// and wo above the surface; sample: wi), and wi, wo in the core's frame.
    struct Setup {
        bool glossy, delta, do_eval, do_sample;
        Mask active_e, active_s;
        Float c, s;   // the frame rotation (frame_rotation)
        Vector3f wi_c, wo_c;
    };

    /// Whether a value (a Dr.Jit array or a static array of them) holds a
    /// literal that carries no gradient
    template <typename T> static bool has_literal(const T &v) {
        if constexpr (dr::is_jit_v<T> && dr::depth_v<T> == 1) {
            return jit_var_state(v.index()) == VarState::Literal && !dr::grad_enabled(v);
        } else if constexpr (dr::is_array_v<T>) {
            for (size_t i = 0; i < dr::size_v<T>; ++i)
                if (has_literal(v.entry(i)))
                    return true;
            return false;
        } else {
            DRJIT_MARK_USED(v);
            return false;
        }
    }

    /// Its literals (without gradients) put in memory (dr::make_opaque)
    template <typename... Ts> static void in_memory(Ts &...vs) {
        auto one = [](auto &v, auto &self) -> void {
            using T = std::decay_t<decltype(v)>;
            if constexpr (dr::is_jit_v<T> && dr::depth_v<T> == 1) {
                if (has_literal(v))
                    dr::make_opaque(v);
            } else if constexpr (dr::is_array_v<T>) {
                for (size_t i = 0; i < dr::size_v<T>; ++i)
                    self(v.entry(i), self);
            }
        };
        (one(vs, one), ...);
    }

    /// The one place that answers eval, pdf and sample: wo / sample1 /
    /// sample2 may be null; want_value / want_pdf select the eval outputs.
    /// JIT variants run the core's programs (jit_path.h), scalar ones call
    /// the native core (batch.h).
    Query make_query(const BSDFContext &ctx, const SurfaceInteraction3f &si,
                     const Vector3f *wo, const Float *sample1, const Point2f *sample2,
                     bool want_value, bool want_pdf, Mask active) const {
        if constexpr (dr::is_jit_v<Float>) {
            // A call from Python with Python numbers (a loop over
            // directions): Dr.Jit would fold the literals into the kernel,
            // one kernel per value (a compact disc's RGB eval: 0.8 s per
            // call). In memory instead, they leave the kernel alone
            // (inside a symbolic scope values are symbols already).
            if (!jit_flag(JitFlag::SymbolicScope) &&
                (has_literal(si.wi) || (wo && has_literal(*wo)) || has_literal(si.uv) ||
                 has_literal(si.dp_du) || has_literal(si.sh_frame.n) ||
                 has_literal(si.sh_frame.s) || has_literal(si.wavelengths) ||
                 (sample1 && has_literal(*sample1)) || (sample2 && has_literal(*sample2)))) {
                SurfaceInteraction3f si_m = si;
                Vector3f wo_m = wo ? *wo : Vector3f(0.f);
                Float s1 = sample1 ? *sample1 : Float(0.f);
                Point2f s2 = sample2 ? *sample2 : Point2f(0.f);
                in_memory(si_m.wi, wo_m, si_m.uv, si_m.dp_du, si_m.dp_dv, si_m.sh_frame.s,
                          si_m.sh_frame.t, si_m.sh_frame.n, si_m.wavelengths, s1, s2);
                return answer(ctx, si_m, wo ? &wo_m : nullptr, sample1 ? &s1 : nullptr,
                              sample2 ? &s2 : nullptr, want_value, want_pdf, active);
            }
        }
        return answer(ctx, si, wo, sample1, sample2, want_value, want_pdf, active);
    }

    /// make_query's answer, its inputs as given
    Query answer(const BSDFContext &ctx, const SurfaceInteraction3f &si, const Vector3f *wo,
                 const Float *sample1, const Point2f *sample2, bool want_value, bool want_pdf,
                 Mask active) const {
        Query q;
        q.value = dr::zeros<UnpolarizedSpectrum>();
        q.pdf = dr::zeros<Float>();
        q.bs = dr::zeros<BSDFSample3f>();
        q.weight = dr::zeros<UnpolarizedSpectrum>();

        Setup st;
        st.glossy = ctx.is_enabled(BSDFFlags::GlossyReflection, 0);
        st.delta = m_has_coherent && ctx.is_enabled(BSDFFlags::DeltaReflection, 1);
        st.do_eval = wo && st.glossy && (want_value || want_pdf);
        st.do_sample = sample1 && sample2 && (st.glossy || st.delta);
        if (!st.do_eval && !st.do_sample)
            return q;

        st.active_e = active && Frame3f::cos_theta(si.wi) > 0.f;
        st.active_s = st.active_e;
        if (st.do_eval)
            st.active_e &= Frame3f::cos_theta(*wo) > 0.f;
        if (dr::none_or<false>(st.active_e || st.active_s))
            return q;

        std::tie(st.c, st.s) = frame_rotation(si, st.active_e || st.active_s);
        st.wi_c = to_core(si.wi, st.c, st.s);
        st.wo_c = st.do_eval ? to_core(*wo, st.c, st.s) : Vector3f(0.f, 0.f, 1.f);

        if constexpr (dr::is_jit_v<Float>)
            jit_query(st, si, wo, sample1, sample2, want_value, want_pdf, q);
        else
            native_query(st, si, wo, sample1, sample2, want_value, want_pdf, q);
        return q;
    }

    /// A sampled direction into q: wo (core frame), its density (glossy: the
    /// pdf; coherent: the lobe's probability), which lobe, and its value
    /// (glossy: f cos; coherent: the lobe's reflectance).
    void finish_sample(const Setup &st, const Vector3f &swo_c, const Float &spdf,
                       const Mask &coh, const UnpolarizedSpectrum &value, Query &q) const {
        Vector3f swo = from_core(swo_c, st.c, st.s);
        Mask ok = st.active_s && spdf > 0.f && Frame3f::cos_theta(swo) > 0.f &&
                  dr::select(coh, Mask(st.delta), Mask(st.glossy));
        q.bs.wo = swo;
        q.bs.pdf = dr::select(ok, spdf, 0.f);
        q.bs.eta = 1.f;
        q.bs.sampled_component = dr::select(coh, UInt32(1), UInt32(0));
        q.bs.sampled_type = dr::select(coh, UInt32(+BSDFFlags::DeltaReflection),
                                       UInt32(+BSDFFlags::GlossyReflection));
        q.weight = dr::select(ok, value * dr::rcp(spdf), 0.f);
    }

    /// Scalar variants: the native core through the batch ABI.
    void native_query(const Setup &st, const SurfaceInteraction3f &si, const Vector3f *wo,
                      const Float *sample1, const Point2f *sample2, bool want_value,
                      bool want_pdf, Query &q) const {
        // One batch and its temporaries per thread (no allocation per call)
        static thread_local Batch b;
        static thread_local Scratch tmp;
        b.want_f = st.do_eval && want_value;
        b.want_pdf = st.do_eval && want_pdf;
        b.want_sample = st.do_sample;
        // Lanes outside the hemisphere: a below-horizon wi makes the core return 0
        Vector3f wi_c = dr::select(st.active_e || st.active_s, st.wi_c, Vector3f(0.f, 0.f, -1.f));
        IO::stage(b, wi_c, st.wo_c, si, sample1, sample2, st.do_sample);
        run_batch(m_core.get(), IO::Ch, IO::NW, b, tmp);

        if (st.do_eval) {
            if (b.want_f)
                q.value = dr::select(st.active_e,
                                     IO::load_spectrum(b.f) * Frame3f::cos_theta(*wo), 0.f);
            if (b.want_pdf)
                q.pdf = dr::select(st.active_e, IO::load(b.pdf, 0), 0.f);
        }
        if (st.do_sample) {
            Vector3f swo_c(IO::load(b.s_wo, 0), IO::load(b.s_wo, 1), IO::load(b.s_wo, 2));
            Mask coh = IO::load(b.s_coh, 0) > .5f;
            // The core's sample value: f (glossy) or the lobe's reflectance
            UnpolarizedSpectrum value = IO::load_spectrum(b.s_val);
            Float cos_o = Frame3f::cos_theta(from_core(swo_c, st.c, st.s));
            finish_sample(st, swo_c, IO::load(b.s_pdf, 0), coh,
                          dr::select(coh, value, value * cos_o), q);
        }
    }

    /// JIT variants: the values the programs read of the material's
    /// parameters (memory, textures at si's points where active)
    typename Jit::Params jit_params(const SurfaceInteraction3f &si, const Mask &active) const {
        typename Jit::Params params{ m_param_array.array(), {} };
        m_textures.apply(params, si, active);
        // The built values, from memory, without a gradient or a texture:
        // the core's programs for that case may run (jit_path.h)
        params.at_built = m_param_array.at_built() && !params.any_per_point();
        return params;
    }

    /// JIT variants: the core's programs as Dr.Jit operations, which Dr.Jit
    /// traces in every mode (symbolic loops and calls, dr.freeze, wavefront),
    /// on LLVM and CUDA, with no host round trip.
    void jit_query(const Setup &st, const SurfaceInteraction3f &si, const Vector3f *wo,
                   const Float *sample1, const Point2f *sample2, bool want_value,
                   bool want_pdf, Query &q) const {
        const Wavelength &wl = si.wavelengths;
        typename Jit::Params params = jit_params(si, st.active_e || st.active_s);
        if (st.do_eval) {
            if (want_value)
                q.value = dr::select(st.active_e,
                                     m_jit.f(st.wi_c, st.wo_c, wl, m_tables, params) *
                                         Frame3f::cos_theta(*wo),
                                     0.f);
            if (want_pdf)
                q.pdf = dr::select(st.active_e, m_jit.pdf(st.wi_c, st.wo_c, wl, m_tables, params), 0.f);
        }
        if (st.do_sample) {
            auto [swo_c, coh] = m_jit.sample(st.wi_c, *sample1, *sample2, wl, m_tables, params);
            // Glossy: f cos and the pdf, both at the sampled direction
            Float cos_o = Frame3f::cos_theta(from_core(swo_c, st.c, st.s));
            UnpolarizedSpectrum value = m_jit.f(st.wi_c, swo_c, wl, m_tables, params) * cos_o;
            Float spdf = m_jit.pdf(st.wi_c, swo_c, wl, m_tables, params);
            if (m_has_coherent) {
                // Coherent: the lobe's reflectance and its probability
                auto [r, p_c] = m_jit.coherent(st.wi_c, wl, m_tables, params);
                spdf = dr::select(coh, p_c, spdf);
                value = dr::select(coh, r, value);
            }
            finish_sample(st, swo_c, spdf, coh, value, q);
        }
    }

    // ---- Members ----------------------------------------------------------

    std::vector<Param> m_params;
    ScalarFloat m_twist = 0.f;
    ref<Texture> m_twist_texture;           // a twist map (then m_twist is 0)
    diffraction_detail::ParamTextures<Float, Spectrum> m_textures; // sigma, height maps (JIT)
    Float m_twist_diff = 0.f;               // JIT variants: `twist` through mi.traverse
    Tracks m_tracks = Tracks::Linear;
    Properties m_tracks_holder{ "linear" }; // `tracks` through mi.traverse
    bool m_tracks_given = false;            // `tracks` set by the user (messages)
    ScalarFloat m_center_u = 0.5f, m_center_v = 0.5f;
    State m_saved;                          // the last accepted parameters

    /// What the variant's materials share (registered_shape_kinds), and
    /// how many materials there are: the last one drops it
    struct Shared {
        std::mutex mutex;
        size_t materials = 0;
        std::unique_ptr<UInt32> kinds;
        std::vector<uint32_t> kind_values;
    };
    static inline Shared s_shared;
    struct SharedUse {
        SharedUse() {
            std::lock_guard<std::mutex> guard(s_shared.mutex);
            ++s_shared.materials;
        }
        ~SharedUse() {
            std::lock_guard<std::mutex> guard(s_shared.mutex);
            if (--s_shared.materials == 0) {
                s_shared.kinds.reset();
                s_shared.kind_values.clear();
            }
        }
        SharedUse(const SharedUse &) = delete;
        SharedUse &operator=(const SharedUse &) = delete;
    };
    SharedUse m_shared_use;

    ScalarFloat m_cos_twist = 1.f, m_sin_twist = 0.f;
    std::string m_json;
    CorePtr m_core;
    uint32_t m_core_flags = 0;
    bool m_has_coherent = false;
    std::vector<std::string> m_gradients; // carried a gradient: see build_json
    std::string m_warnings, m_pending_warnings; // logged, and of the core in use

    // JIT variants: the core's programs, and every program's tables in one
    // array (traversed, so that dr.freeze sees them)
    Jit m_jit;
    TableArrays m_tables;
    // Every parameter the programs read (plugin_params.h)
    diffraction_detail::ParamArray<Float> m_param_array;
    // Changes of the programs, shown to dr.freeze (code_version.h)
    diffraction_detail::CodeVersion<Float> m_code_version;
    /// An update moving a parameter the programs read by at most this
    /// (relative) keeps the programs (update_without_rebuild): the core's
    /// bound, within which they follow the rebuilt material (stam.h)
    static constexpr ScalarFloat MaxDriftWithoutRebuild = (ScalarFloat) STAM_PROGRAM_MAX_DRIFT;

    MI_TRAVERSE_CB_WITH_VERSION(Base, m_code_version, m_tables, m_param_array.array(),
                                m_twist_diff)
};

MI_EXPORT_PLUGIN(Diffraction)
NAMESPACE_END(mitsuba)
