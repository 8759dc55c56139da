/* diffraction.cpp: Mitsuba 3.9 BSDF plugin for Stam's diffraction shader
 * (J. Stam, "Diffraction Shaders", SIGGRAPH 1999).
 *
 * This file contains no physics. It converts Mitsuba properties into the JSON
 * parameter object of the Rust core (rust-core/include/stam.h; params_json.h),
 * builds the local frame the core expects (twist, concentric tracks), and
 * forwards eval / pdf / sample to the core's batch C ABI (batch.h stages the
 * arrays into host buffers, makes the call and loads the results back).
 *
 * Variants: scalar_* call the core per query; llvm_ad_* run in Dr.Jit's
 * evaluated mode (dr.JitFlag.SymbolicLoops / SymbolicCalls off) and call the
 * core once per batch; cuda_ad_* compile but refuse construction (the core is
 * CPU code). See scripts/stam_mitsuba.py for the Python-side setup.
 *
 * Layout (as Mitsuba's roughconductor.cpp): the manual, the constructor,
 * traverse, parameters_changed, the BSDF methods, to_string, then the
 * private helpers and members.
 */

#include <mitsuba/core/properties.h>
#include <mitsuba/core/spectrum.h>
#include <mitsuba/render/bsdf.h>
#include <mitsuba/render/interaction.h>

#include <cmath>
#include <cstdio>
#include <sstream>
#include <string>
#include <vector>

#include "../rust-core/include/stam.h"
#include "batch.h"
#include "params_json.h"

NAMESPACE_BEGIN(mitsuba)

/**!

.. _bsdf-diffraction:

Diffraction BSDF (:monosp:`diffraction`)
----------------------------------------

.. pluginparameters::

 * - surface
   - |string|
   - Microsurface model: ``gaussian``, ``fractal``, ``periodic`` or ``cd``
     (compact disc: a periodic surface with Stam's dimensions).
     (Default: none, required)
 * - sigma_um
   - |float|
   - Gaussian surfaces: rms height; fractal surfaces: rms height difference
     over ``lag_um``. Micrometres, in [1e-6, 100]. (Default: none, required)
   - |exposed|
 * - corr_um
   - |float|
   - Gaussian surfaces: isotropic correlation length T. Micrometres, in
     [1e-3, 1e5]. (Default: none; give either it or both ``corr_x_um`` and
     ``corr_y_um``)
   - |exposed|
 * - corr_x_um, corr_y_um
   - |float|
   - Gaussian surfaces: anisotropic correlation lengths along the tangent
     (x) and bitangent (y) (brushed metal). Micrometres, each in [1e-3, 1e5].
     (Default: none)
   - |exposed|
 * - hurst
   - |float|
   - Fractal surfaces: Hurst exponent H (dimensionless), in [0.001, 1].
     (Default: none, required)
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
   - Periodic surfaces: ``rect``, ``sine``, or a tabulated profile given as a
     string of 2 to 65536 comma-separated heights in micrometres over one
     period (passed to the core as ``{"heights_um": [...]}``).
     (Default: ``cd``: ``rect``; ``periodic``: none, required)
 * - height_um
   - |float|
   - Periodic surfaces, ``rect`` and ``sine`` profiles: bump height (rect),
     peak-to-peak height (sine). Micrometres, in (0, 100]. (Default: ``cd``:
     0.15; otherwise none, required)
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
     spectral index: ``aluminium``, ``silver``, ``gold``, ``copper``,
     ``chromium``. (Default: ``aluminium``)
   - |exposed| (the constant)
 * - eta, k
   - |float|
   - Alternative to ``fresnel``: a constant complex index of refraction
     eta + i k (dimensionless; eta in [1e-3, 100], k in [0, 100]; passed as
     ``"fresnel": {"eta": .., "k": ..}``). (Default: none; k: 0 when eta is
     given)
   - |exposed|
 * - series_tolerance
   - |float|
   - Gaussian surfaces: relative truncation tolerance of the Poisson series
     (dimensionless), in [1e-12, 0.1]. (Default: 1e-5)
   - |exposed|
 * - rgb_nodes
   - |int|
   - Gaussian and fractal surfaces: wavelength nodes of the RGB rule for
     smooth spectra, an integer in [4, 64]. (Default: 12 for Gaussian, 8 for
     fractal surfaces)
   - |exposed|
 * - twist
   - |float|
   - Rotation of the tangent frame about the normal, in degrees.
     (Default: 0)
   - |exposed|
 * - tracks
   - |string|
   - ``linear`` (the periodic direction is the shading tangent) or
     ``concentric``: the periodic direction is radial about (center_u,
     center_v) in the uv parametrisation and the grooves follow the circles.
     (Default: ``linear``)
 * - center_u, center_v
   - |float|
   - Centre of concentric tracks in uv space (uv units; only with
     ``tracks`` = ``concentric``). (Default: 0.5, 0.5)
   - |exposed| (concentric tracks)

Only the parameters given by the user are passed to the core, which applies
its own defaults (the ones above, from ``rust-core/src/models/<model>/params.rs``) and
validates names and ranges; its error messages are raised as exceptions.
The numeric parameters the user gives, ``twist`` always and ``center_u``,
``center_v`` with concentric tracks are exposed through ``mi.traverse``
(non-differentiable); changing them rebuilds the core material. ``docs/parameters.md`` has the
same table for the core's JSON keys.

Components: 0 = the diffracted (glossy) lobe; 1 = the coherent mirror lobe
(a delta component, present when the core reports one, e.g. Gaussian
surfaces).

In spectral variants the BSDF is evaluated at the path's wavelengths. The
core samples a direction with one of them (the hero), chosen uniformly by the
first sample, and returns the mean of the wavelengths' densities, which is
exactly the strategy's density (the unbiased multi-wavelength mixture). Each
query goes to the core's path-vertex calls in one call per batch
(``eval_pdf_sample`` builds the strategy once for the light direction and the
sample). Monochromatic variants take the luminance of the core's RGB output
(with the core's weights, ``STAM_SRGB_LUMINANCE_*`` in stam.h).

LLVM variants need evaluated mode: ``dr.set_flag(dr.JitFlag.SymbolicLoops,
False)`` and ``dr.set_flag(dr.JitFlag.SymbolicCalls, False)``, which
``scripts/stam_mitsuba.py``'s ``setup()`` does.

.. tabs::
    .. code-tab:: xml

        <bsdf type="diffraction">
            <string name="surface" value="cd"/>
            <string name="tracks" value="concentric"/>
            <string name="fresnel" value="aluminium"/>
        </bsdf>

    .. code-tab:: python

        'type': 'diffraction',
        'surface': 'gaussian',
        'sigma_um': 0.2,
        'corr_um': 2.0,
        'fresnel': 'gold'
*/

// The host-side helpers (batch.h, params_json.h)
using diffraction_detail::Batch;
using diffraction_detail::BatchIO;
using diffraction_detail::CorePtr;
using diffraction_detail::json_escape;
using diffraction_detail::json_number;
using diffraction_detail::parse_number_list;
using diffraction_detail::run_batch;
using diffraction_detail::Scratch;

template <typename Float, typename Spectrum>
class Diffraction final : public BSDF<Float, Spectrum> {
public:
    MI_IMPORT_BASE(BSDF, m_flags, m_components)
    MI_IMPORT_TYPES()

    enum class Tracks { Linear, Concentric };

    using IO = BatchIO<Float, Spectrum>;

    Diffraction(const Properties &props) : Base(props) {
        if constexpr (dr::is_cuda_v<Float>)
            Throw("diffraction: CUDA variants are not supported (the Rust core "
                  "runs on the CPU): use an llvm_ad_* or scalar_* variant.");
        static_assert(!IO::IsSpectral || IO::NW == IO::NC, "unexpected spectrum layout");

        // Plugin-level parameters are handled here; everything else is
        // forwarded to the core under its own name (the core refuses
        // unknown keys with a message naming them).
        size_t count = 0;
        for (auto it = props.begin(); it != props.end(); ++it)
            ++count;
        m_params.reserve(count); // never reallocated: traverse() hands out pointers

        bool has_center = false;
        for (auto it = props.begin(); it != props.end(); ++it) {
            std::string name(it->name());
            using PType = Properties::Type;
            PType type = it->type();

            if (name == "twist") {
                m_twist = (ScalarFloat) it->template get<double>();
            } else if (name == "tracks") {
                std::string t = it->template get<std::string>();
                if (t == "linear")
                    m_tracks = Tracks::Linear;
                else if (t == "concentric")
                    m_tracks = Tracks::Concentric;
                else
                    Throw("diffraction: tracks = \"%s\": must be \"linear\" or "
                          "\"concentric\"", t);
            } else if (name == "center_u") {
                m_center_u = (ScalarFloat) it->template get<double>();
                has_center = true;
            } else if (name == "center_v") {
                m_center_v = (ScalarFloat) it->template get<double>();
                has_center = true;
            } else if (type == PType::Float || type == PType::Integer) {
                double v = it->template get<double>();
                Param p;
                p.name = name;
                p.kind = Param::Number;
                p.given = v;
                p.value = (ScalarFloat) v;
                // eta, k: nested under "fresnel"
                if (name == "eta" || name == "k")
                    p.group = "fresnel";
                m_params.push_back(p);
            } else if (type == PType::String) {
                std::string s = it->template get<std::string>();
                Param p;
                p.name = name;
                std::vector<double> heights;
                if (name == "profile" && s != "rect" && s != "sine" &&
                    parse_number_list(s, heights)) {
                    p.kind = Param::Json;
                    std::string j = "{\"heights_um\": [";
                    for (size_t i = 0; i < heights.size(); ++i)
                        j += (i ? ", " : "") + json_number(heights[i]);
                    p.text = j + "]}";
                } else {
                    p.kind = Param::String;
                    p.text = s;
                }
                m_params.push_back(p);
            } else if (type == PType::Bool) {
                Param p;
                p.name = name;
                p.kind = Param::Bool;
                p.text = it->template get<bool>() ? "true" : "false";
                m_params.push_back(p);
            } else {
                Throw("diffraction: parameter \"%s\" has type %s; only numbers "
                      "and strings are accepted (no textures)",
                      name, property_type_name(type));
            }
        }

        if (has_center && m_tracks != Tracks::Concentric)
            Throw("diffraction: center_u/center_v only apply to "
                  "tracks=\"concentric\"");
        bool has_fresnel = false, has_eta_k = false;
        for (const Param &p : m_params) {
            has_fresnel |= p.name == "fresnel";
            has_eta_k |= p.group == "fresnel";
        }
        if (has_fresnel && has_eta_k)
            Throw("diffraction: give either \"fresnel\" or \"eta\"/\"k\", not both");

        rebuild_core();

        // Flags and components, declared once
        m_has_coherent = (m_core_flags & STAM_FLAG_HAS_COHERENT) != 0;
        uint32_t glossy = +BSDFFlags::GlossyReflection | +BSDFFlags::FrontSide;
        if ((m_core_flags & STAM_FLAG_ANISOTROPIC) || m_twist != 0.f ||
            m_tracks == Tracks::Concentric)
            glossy |= +BSDFFlags::Anisotropic;
        m_components.clear();
        m_components.push_back(glossy);
        if (m_has_coherent)
            m_components.push_back(+BSDFFlags::DeltaReflection | +BSDFFlags::FrontSide);
        m_flags = 0;
        for (uint32_t c : m_components)
            m_flags |= c;
    }

    void traverse(TraversalCallback *cb) override {
        Base::traverse(cb);
        for (Param &p : m_params)
            if (p.kind == Param::Number)
                cb->put(p.name, p.value, ParamFlags::NonDifferentiable);
        cb->put("twist", m_twist, ParamFlags::NonDifferentiable);
        if (m_tracks == Tracks::Concentric) {
            cb->put("center_u", m_center_u, ParamFlags::NonDifferentiable);
            cb->put("center_v", m_center_v, ParamFlags::NonDifferentiable);
        }
    }

    void parameters_changed(const std::vector<std::string> &keys) override {
        Base::parameters_changed(keys);
        rebuild_core();
        if (((m_core_flags & STAM_FLAG_HAS_COHERENT) != 0) != m_has_coherent)
            Throw("diffraction: the change adds or removes the coherent lobe; "
                  "the component layout is fixed at construction");
        // Anisotropy is a hint to integrators: follow the core
        if (m_core_flags & STAM_FLAG_ANISOTROPIC) {
            m_components[0] |= +BSDFFlags::Anisotropic;
            m_flags |= +BSDFFlags::Anisotropic;
        }
    }

    // -----------------------------------------------------------------------
    // BSDF interface
    // -----------------------------------------------------------------------

    std::pair<BSDFSample3f, Spectrum> sample(const BSDFContext &ctx,
                                             const SurfaceInteraction3f &si,
                                             Float sample1, const Point2f &sample2,
                                             Mask active) const override {
        MI_MASKED_FUNCTION(ProfilerPhase::BSDFSample, active);
        auto [bs, weight] = sample_impl(ctx, si, sample1, sample2, active);
        return { bs, depolarizer<Spectrum>(weight) };
    }

    Spectrum eval(const BSDFContext &ctx, const SurfaceInteraction3f &si,
                  const Vector3f &wo, Mask active) const override {
        MI_MASKED_FUNCTION(ProfilerPhase::BSDFEvaluate, active);
        auto [value, pdf] = eval_pdf_impl(ctx, si, wo, true, false, active);
        DRJIT_MARK_USED(pdf);
        return depolarizer<Spectrum>(value);
    }

    Float pdf(const BSDFContext &ctx, const SurfaceInteraction3f &si,
              const Vector3f &wo, Mask active) const override {
        MI_MASKED_FUNCTION(ProfilerPhase::BSDFEvaluate, active);
        return eval_pdf_impl(ctx, si, wo, false, true, active).second;
    }

    std::pair<Spectrum, Float> eval_pdf(const BSDFContext &ctx,
                                        const SurfaceInteraction3f &si,
                                        const Vector3f &wo,
                                        Mask active) const override {
        MI_MASKED_FUNCTION(ProfilerPhase::BSDFEvaluate, active);
        auto [value, pdf] = eval_pdf_impl(ctx, si, wo, true, true, active);
        return { depolarizer<Spectrum>(value), pdf };
    }

    std::tuple<Spectrum, Float, BSDFSample3f, Spectrum>
    eval_pdf_sample(const BSDFContext &ctx, const SurfaceInteraction3f &si,
                    const Vector3f &wo, Float sample1, const Point2f &sample2,
                    Mask active) const override {
        MI_MASKED_FUNCTION(ProfilerPhase::BSDFSample, active);
        Query q = make_query(ctx, si, &wo, &sample1, &sample2, true, true, active);
        return { depolarizer<Spectrum>(q.value), q.pdf, q.bs,
                 depolarizer<Spectrum>(q.weight) };
    }

    std::string to_string() const override {
        std::ostringstream oss;
        oss << "Diffraction[" << std::endl;
        for (const Param &p : m_params) {
            oss << "  " << p.name << " = ";
            if (p.kind == Param::Number)
                oss << number_text(p);
            else if (p.kind == Param::String)
                oss << json_escape(p.text);
            else
                oss << p.text;
            oss << "," << std::endl;
        }
        oss << "  twist = " << m_twist << "," << std::endl
            << "  tracks = " << (m_tracks == Tracks::Linear ? "linear" : "concentric");
        if (m_tracks == Tracks::Concentric)
            oss << "," << std::endl
                << "  center_u = " << m_center_u << "," << std::endl
                << "  center_v = " << m_center_v;
        oss << "," << std::endl
            << "  core_json = " << m_json << "," << std::endl
            << "  coherent_lobe = " << (m_has_coherent ? "true" : "false") << std::endl
            << "]";
        return oss.str();
    }

    MI_DECLARE_CLASS(Diffraction)

private:
    /// A parameter forwarded to the core
    struct Param {
        enum Kind { Number, String, Bool, Json } kind = Number;
        std::string name;
        std::string group;  // non-empty: nested in an object of that name
        double given = 0.0; // number as given by the user
        ScalarFloat value = 0.f; // number as exposed by traverse()
        std::string text;   // string value, or raw JSON
    };

    /// Everything one call can ask of the core, in the local frame
    struct Query {
        UnpolarizedSpectrum value;  // f * cos at wo
        Float pdf;                  // pdf at wo
        BSDFSample3f bs;
        UnpolarizedSpectrum weight; // sample weight
    };

    std::string number_text(const Param &p) const {
        // The user's value unless traverse() changed it
        if ((ScalarFloat) p.given == p.value)
            return json_number(p.given);
        char buf[32];
        std::snprintf(buf, sizeof(buf), "%.9g", (double) p.value);
        return buf;
    }

    std::string build_json() const {
        std::string top, nested;
        for (const Param &p : m_params) {
            std::string v;
            switch (p.kind) {
                case Param::Number:
                    if (!std::isfinite(p.value))
                        Throw("diffraction: parameter \"%s\" must be finite", p.name);
                    v = number_text(p);
                    break;
                case Param::String: v = json_escape(p.text); break;
                case Param::Bool:
                case Param::Json: v = p.text; break;
            }
            std::string &dst = p.group.empty() ? top : nested;
            dst += (dst.empty() ? "" : ", ") + json_escape(p.name) + ": " + v;
        }
        if (!nested.empty())
            top += (top.empty() ? "" : ", ") + json_escape("fresnel") + ": {" + nested + "}";
        return "{" + top + "}";
    }

    void rebuild_core() {
        if (!std::isfinite(m_twist) || !std::isfinite(m_center_u) ||
            !std::isfinite(m_center_v))
            Throw("diffraction: twist, center_u and center_v must be finite");
        std::string json = build_json();
        char err[1024] = { 0 };
        StamBrdf *core = stam_brdf_new(json.c_str(), err, sizeof(err));
        if (!core)
            Throw("diffraction: %s", err[0] ? err : "the core refused the parameters");
        m_core.reset(core);
        m_json = std::move(json);
        m_core_flags = stam_brdf_flags(core);
        double t = (double) m_twist * M_PI / 180.0;
        m_cos_twist = (ScalarFloat) std::cos(t);
        m_sin_twist = (ScalarFloat) std::sin(t);
    }

    /// Rotation (c, s) of the core's tangent in the local (xy) plane: core
    /// x = (c, s, 0), core y = (-s, c, 0).
    std::pair<Float, Float> frame_rotation(const SurfaceInteraction3f &si) const {
        if (m_tracks == Tracks::Linear)
            return { Float(m_cos_twist), Float(m_sin_twist) };
        // Groove direction: tangent of the circle |uv - centre| = const,
        // mapped to the surface by (dp_du, dp_dv); periodic direction = groove x n.
        Float du = si.uv.x() - m_center_u, dv = si.uv.y() - m_center_v;
        Vector3f g = si.sh_frame.to_local(si.dp_du * (-dv) + si.dp_dv * du);
        Float len = dr::sqrt(dr::square(g.x()) + dr::square(g.y()));
        Mask ok = len > 1e-20f && dr::isfinite(len);
        Float inv = dr::select(ok, dr::rcp(len), 0.f);
        // Degenerate (centre, or no uv parametrisation): the shading tangent
        Float c0 = dr::select(ok, g.y() * inv, 1.f),
              s0 = dr::select(ok, -g.x() * inv, 0.f);
        return { c0 * m_cos_twist - s0 * m_sin_twist,
                 s0 * m_cos_twist + c0 * m_sin_twist };
    }

    static Vector3f to_core(const Vector3f &w, const Float &c, const Float &s) {
        return { c * w.x() + s * w.y(), -s * w.x() + c * w.y(), w.z() };
    }
    static Vector3f from_core(const Vector3f &v, const Float &c, const Float &s) {
        return { c * v.x() - s * v.y(), s * v.x() + c * v.y(), v.z() };
    }

    /// The one place that talks to the core. wo / sample1 / sample2 may be
    /// null; want_value / want_pdf select the eval outputs.
    Query make_query(const BSDFContext &ctx, const SurfaceInteraction3f &si,
                     const Vector3f *wo, const Float *sample1, const Point2f *sample2,
                     bool want_value, bool want_pdf, Mask active) const {
        Query q;
        q.value = dr::zeros<UnpolarizedSpectrum>();
        q.pdf = dr::zeros<Float>();
        q.bs = dr::zeros<BSDFSample3f>();
        q.weight = dr::zeros<UnpolarizedSpectrum>();

        const bool glossy = ctx.is_enabled(BSDFFlags::GlossyReflection, 0),
                   delta = m_has_coherent && ctx.is_enabled(BSDFFlags::DeltaReflection, 1);
        const bool do_eval = wo && glossy && (want_value || want_pdf),
                   do_sample = sample1 && sample2 && (glossy || delta);
        if (!do_eval && !do_sample)
            return q;

        Float cos_i = Frame3f::cos_theta(si.wi);
        Mask active_e = active && cos_i > 0.f, active_s = active_e;
        if (do_eval)
            active_e &= Frame3f::cos_theta(*wo) > 0.f;
        if (dr::none_or<false>(active_e || active_s))
            return q;

        auto [c, s] = frame_rotation(si);
        Vector3f wi_c = to_core(si.wi, c, s);
        Vector3f wo_c = do_eval ? to_core(*wo, c, s) : Vector3f(0.f, 0.f, 1.f);
        // Lanes outside the hemisphere: a below-horizon wi makes the core return 0
        wi_c = dr::select(active_e || active_s, wi_c, Vector3f(0.f, 0.f, -1.f));

        // Scalar variants reuse one batch and its temporaries per thread
        // (no allocation per call); JIT variants stage whole wavefronts.
        static thread_local Batch scalar_batch;
        static thread_local Scratch scalar_scratch;
        Batch jit_batch;
        Scratch jit_scratch;
        Batch &b = dr::is_jit_v<Float> ? jit_batch : scalar_batch;
        Scratch &tmp = dr::is_jit_v<Float> ? jit_scratch : scalar_scratch;
        b.want_f = do_eval && want_value;
        b.want_pdf = do_eval && want_pdf;
        b.want_sample = do_sample;

        // ---- Stage inputs, call the core, read outputs --------------------
        IO::stage(b, wi_c, wo_c, si, sample1, sample2, do_sample, active_e || active_s);
        run_batch(m_core.get(), IO::Ch, IO::NW, b, tmp);

        // ---- Eval / pdf ----------------------------------------------------
        if (do_eval) {
            Float cos_o = Frame3f::cos_theta(*wo);
            if (b.want_f) {
                UnpolarizedSpectrum f = IO::load_spectrum(b.f, b.n);
                q.value = dr::select(active_e, f * cos_o, 0.f);
            }
            if (b.want_pdf)
                q.pdf = dr::select(active_e, IO::load(b.pdf, 0, b.n), 0.f);
        }

        // ---- Sample --------------------------------------------------------
        if (do_sample) {
            Vector3f swo_c(IO::load(b.s_wo, 0, b.n), IO::load(b.s_wo, 1, b.n),
                           IO::load(b.s_wo, 2, b.n));
            Float spdf = IO::load(b.s_pdf, 0, b.n);
            Mask coh = IO::load(b.s_coh, 0, b.n) > .5f;
            UnpolarizedSpectrum sval = IO::load_spectrum(b.s_val, b.n);

            Vector3f swo = from_core(swo_c, c, s);
            Float cos_o = Frame3f::cos_theta(swo);
            Mask ok = active_s && spdf > 0.f && cos_o > 0.f &&
                      dr::select(coh, Mask(delta), Mask(glossy));

            q.bs.wo = swo;
            q.bs.pdf = dr::select(ok, spdf, 0.f);
            q.bs.eta = 1.f;
            q.bs.sampled_component = dr::select(coh, UInt32(1), UInt32(0));
            q.bs.sampled_type = dr::select(coh, UInt32(+BSDFFlags::DeltaReflection),
                                           UInt32(+BSDFFlags::GlossyReflection));
            Float inv_pdf = dr::select(ok, dr::rcp(spdf), 0.f);
            q.weight = sval * dr::select(coh, inv_pdf, cos_o * inv_pdf);
            q.weight = dr::select(ok, q.weight, 0.f);
        }
        return q;
    }

    std::pair<UnpolarizedSpectrum, Float>
    eval_pdf_impl(const BSDFContext &ctx, const SurfaceInteraction3f &si,
                  const Vector3f &wo, bool want_value, bool want_pdf, Mask active) const {
        Query q = make_query(ctx, si, &wo, nullptr, nullptr, want_value, want_pdf, active);
        return { q.value, q.pdf };
    }

    std::pair<BSDFSample3f, UnpolarizedSpectrum>
    sample_impl(const BSDFContext &ctx, const SurfaceInteraction3f &si, Float sample1,
                const Point2f &sample2, Mask active) const {
        Query q = make_query(ctx, si, nullptr, &sample1, &sample2, false, false, active);
        return { q.bs, q.weight };
    }

    // ---- Members ----------------------------------------------------------

    std::vector<Param> m_params;
    ScalarFloat m_twist = 0.f;
    Tracks m_tracks = Tracks::Linear;
    ScalarFloat m_center_u = 0.5f, m_center_v = 0.5f;

    ScalarFloat m_cos_twist = 1.f, m_sin_twist = 0.f;
    std::string m_json;
    CorePtr m_core;
    uint32_t m_core_flags = 0;
    bool m_has_coherent = false;

    MI_TRAVERSE_CB(Base)
};

MI_EXPORT_PLUGIN(Diffraction)
NAMESPACE_END(mitsuba)
