/* jit_path.h: the JIT variants' path of the diffraction plugin (diffraction.cpp).
 *
 * In llvm_ad_* and cuda_ad_* the plugin evaluates, samples and takes the pdf
 * of a material by running the programs the core exports for it
 * (stam_brdf_export_program; rust-core/src/material/program.rs) with Dr.Jit
 * operations (program.h). This header holds the four programs a variant
 * runs and drives them: which kind for which variant, the inputs in the
 * order stam.h gives, spectral variants' per-wavelength eval (the sampling,
 * pdf and coherent lobe of their wavelengths' mixture are the core's
 * mixture programs, stam_brdf_export_mixture_program), the luminance of
 * monochromatic variants. No physics: the frame
 * (twist, tracks) and the BSDF contract (cosines, masks, sample weights)
 * are diffraction.cpp's, the formulas the core's.
 */
#pragma once

#include <mitsuba/core/spectrum.h>
#include <mitsuba/render/interaction.h>

#include <algorithm>
#include <cmath>
#include <ostream>
#include <string>
#include <vector>

#include "../rust-core/include/stam.h"
#include "params_json.h"
#include "program.h"

NAMESPACE_BEGIN(mitsuba)
NAMESPACE_BEGIN(diffraction_detail)

template <typename Float, typename Spectrum> class JitPath {
public:
    MI_IMPORT_TYPES()
    using Prog = program::Program<Float>;
    using TableArrays = program::Tables<DynamicBuffer<Float>>;
    /// Values of the material's parameters (program.h's ParamInputs: by
    /// STAM_PARAM_* id, and per point where a texture gives one)
    using Params = program::ParamInputs<Float>;

    static constexpr bool IsSpectral = is_spectral_v<Spectrum>;
    static constexpr bool IsMono = is_monochromatic_v<Spectrum>;
    static constexpr size_t NW = IsSpectral ? dr::size_v<Wavelength> : 0;

    JitPath() = default;

    /// The programs of the kinds this variant runs (RGB kinds for RGB and
    /// monochromatic variants; for spectral ones the spectral eval and the
    /// mixture programs over the path's NW wavelengths), each checked
    /// against the inputs and outputs stam.h gives its kind; their tables
    /// stay host values until `load_tables`. Throws ParamError naming the
    /// kinds the core does not export for the material.
    static JitPath build(const StamBrdf *core) {
        JitPath j;
        constexpr bool sp = IsSpectral;
        static_assert(NW <= STAM_MIXTURE_MAX_WAVELENGTHS, "more wavelengths than the core mixes");
        struct Kind {
            uint32_t code;
            bool mixture;
            const char *name;
            Prog *dst, *at_built;
        };
        const Kind kinds[] = {
            { sp ? STAM_PROGRAM_EVAL_SPECTRAL : STAM_PROGRAM_EVAL_RGB, false,
              sp ? "EVAL_SPECTRAL" : "EVAL_RGB", &j.m_eval, &j.m_eval_at_built },
            { sp ? STAM_MIXTURE_PDF : STAM_PROGRAM_PDF_RGB, sp, sp ? "MIXTURE_PDF" : "PDF_RGB",
              &j.m_pdf, &j.m_pdf_at_built },
            { sp ? STAM_MIXTURE_SAMPLE : STAM_PROGRAM_SAMPLE_RGB, sp,
              sp ? "MIXTURE_SAMPLE" : "SAMPLE_RGB", &j.m_sample, &j.m_sample_at_built },
            { sp ? STAM_MIXTURE_COHERENT : STAM_PROGRAM_COHERENT_RGB, sp,
              sp ? "MIXTURE_COHERENT" : "COHERENT_RGB", &j.m_coherent, &j.m_coherent_at_built },
        };
        const uint32_t n_wavelengths = sp ? (uint32_t) NW : 0u;
        auto exported = [&](const Kind &k, uint32_t flags) {
            return k.mixture ? program::export_mixture_program(core, k.code | flags, n_wavelengths)
                             : program::export_program(core, k.code | flags);
        };
        // The kind's inputs and outputs as the core's header gives them
        // (stam_program_io), against the program's own
        auto checked = [&](const Kind &k, const std::vector<float> &v) {
            Prog p(v, j.m_host_tables);
            uint32_t inputs = 0, outputs = 0;
            stam_program_io(k.code, k.mixture ? n_wavelengths : 0u, &inputs, &outputs);
            if (p.n_inputs() != inputs || p.n_outputs() != outputs)
                throw program::Malformed(
                    std::string(k.name) + " takes " + std::to_string(p.n_inputs()) +
                    " inputs and gives " + std::to_string(p.n_outputs()) +
                    " outputs, stam.h says " + std::to_string(inputs) + " and " +
                    std::to_string(outputs));
            return p;
        };
        std::string missing;
        try {
            for (const Kind &k : kinds) {
                std::vector<float> v = exported(k, 0);
                if (v.empty()) {
                    missing += (missing.empty() ? "" : ", ") + std::string(k.name);
                    continue;
                }
                *k.dst = checked(k, v);
                // Where the core has one, the kind's program for the built
                // parameters (run while they are: `Params::at_built`)
                v = exported(k, STAM_PROGRAM_AT_BUILT);
                if (!v.empty())
                    *k.at_built = checked(k, v);
            }
        } catch (const program::Malformed &e) {
            throw ParamError(std::string("the core's program is unusable (a plugin built "
                                         "against another core?): ") + e.what());
        }
        // Polarized variants: the polarisation's program, where the material
        // has one (wi, wo, lambda -> b, c, s)
        if constexpr (is_polarized_v<Spectrum>) {
            std::vector<float> v = program::export_polarization_program(core);
            if (!v.empty()) {
                j.m_polarization = Prog(v, j.m_host_tables);
                if (j.m_polarization.n_inputs() != 7 || j.m_polarization.n_outputs() != 3)
                    throw ParamError("the core's polarization program takes " +
                                     std::to_string(j.m_polarization.n_inputs()) +
                                     " inputs and gives " +
                                     std::to_string(j.m_polarization.n_outputs()) +
                                     " outputs, not 7 and 3 (a plugin built against another "
                                     "core?)");
            }
        }
        if (!missing.empty())
            throw ParamError("the core exports no program of kind " + missing +
                             " for this material, which the JIT variants run; render it "
                             "in a scalar_* variant (docs/parameters.md says which "
                             "materials the JIT variants do not run yet)");
        return j;
    }

    /// Every program's tables (`program::Tables`), which the material keeps
    /// and traverses for dr.freeze.
    TableArrays load_tables() const { return TableArrays::load(m_host_tables); }

    /// The ids (STAM_PARAM_*) of the parameters the programs read: the
    /// material's parameters whose values flow into them (differentiable)
    std::vector<uint32_t> param_ids() const {
        std::vector<uint32_t> ids;
        for (const Prog *p : { &m_eval, &m_pdf, &m_sample, &m_coherent })
            for (uint32_t id : p->param_ids())
                if (std::find(ids.begin(), ids.end(), id) == ids.end())
                    ids.push_back(id);
        return ids;
    }

    /// The value the programs were built with of each parameter they read,
    /// by id (NaN for the others)
    std::vector<float> built_values() const {
        std::vector<float> v(STAM_PARAMS, std::nanf(""));
        for (const Prog *p : { &m_eval, &m_pdf, &m_sample, &m_coherent })
            for (size_t k = 0; k < p->param_ids().size(); ++k)
                v[p->param_ids()[k]] = p->param_values()[k];
        return v;
    }

    /// "eval N ops M gathers, ..., tables K values" (the object's string form)
    void describe(std::ostream &os, size_t table_values) const {
        const char *names[] = { "eval", "pdf", "sample", "coherent" };
        const Prog *progs[] = { &m_eval, &m_pdf, &m_sample, &m_coherent };
        for (size_t k = 0; k < 4; ++k)
            os << names[k] << " " << progs[k]->n_instructions() << " ops "
               << progs[k]->n_gathers() << " gathers, ";
        if (m_eval_at_built.valid())
            os << "eval at the built parameters " << m_eval_at_built.n_instructions()
               << " ops " << m_eval_at_built.n_gathers() << " gathers, ";
        os << "tables " << table_values << " values";
    }

    /// f(wi, wo) without cos (core frame), at each of the path's
    /// wavelengths (spectral) or in RGB
    UnpolarizedSpectrum f(const Vector3f &wi, const Vector3f &wo, const Wavelength &wl,
                          const TableArrays &tables, const Params &params) const {
        if constexpr (IsSpectral) {
            UnpolarizedSpectrum f;
            for (size_t j = 0; j < NW; ++j)
                f[j] = pick(m_eval, m_eval_at_built, params)
                           .run(inputs(wi, &wo, { wl[j] }), tables, params)[0];
            return f;
        } else {
            DRJIT_MARK_USED(wl);
            return from_rgb(
                pick(m_eval, m_eval_at_built, params).run(inputs(wi, &wo, {}), tables, params));
        }
    }

    /// The glossy density at wo; spectral: the density of the wavelengths'
    /// mixture (the core's MIXTURE_PDF)
    Float pdf(const Vector3f &wi, const Vector3f &wo, const Wavelength &wl,
              const TableArrays &tables, const Params &params) const {
        return pick(m_pdf, m_pdf_at_built, params)
            .run(inputs(wi, &wo, wavelengths(wl)), tables, params)[0];
    }

    /// A direction from the SAMPLE program (core frame) and whether it is
    /// the coherent lobe's; spectral: the mixture's (MIXTURE_SAMPLE, whose
    /// sample1 picks one of the path's wavelengths)
    std::pair<Vector3f, Mask> sample(const Vector3f &wi, const Float &sample1,
                                     const Point2f &sample2, const Wavelength &wl,
                                     const TableArrays &tables, const Params &params) const {
        std::vector<Float> extra{ sample1, sample2.x(), sample2.y() };
        for (const Float &l : wavelengths(wl))
            extra.push_back(l);
        std::vector<Float> o =
            pick(m_sample, m_sample_at_built, params).run(inputs(wi, nullptr, extra), tables, params);
        return { Vector3f(o[0], o[1], o[2]), o[3] > .5f };
    }

    /// The coherent lobe at wi: its reflectance and the probability that
    /// `sample` picks it (spectral: each wavelength's reflectance and the
    /// mixture's probability, MIXTURE_COHERENT)
    std::pair<UnpolarizedSpectrum, Float> coherent(const Vector3f &wi, const Wavelength &wl,
                                                   const TableArrays &tables,
                                                   const Params &params) const {
        std::vector<Float> o = pick(m_coherent, m_coherent_at_built, params)
                                   .run(inputs(wi, nullptr, wavelengths(wl)), tables, params);
        if constexpr (IsSpectral) {
            UnpolarizedSpectrum r;
            for (size_t j = 0; j < NW; ++j)
                r[j] = o[j];
            return { r, o[NW] };
        } else {
            return { from_rgb(o), o[3] };
        }
    }

    /// Polarized variants: whether the material has a polarisation (not
    /// rigorous gratings), and its (b, c, s) for the reflection from wi to
    /// wo (any frame: the program reads the half vector's cosine) at each of
    /// the path's wavelengths (monochromatic variants: at 550 nm), from the
    /// core's program (stam_brdf_export_polarization_program)
    bool has_polarization() const { return m_polarization.valid(); }
    std::array<UnpolarizedSpectrum, 3> polarization(const Vector3f &wi, const Vector3f &wo,
                                                    const Wavelength &wl,
                                                    const TableArrays &tables,
                                                    const Params &params) const {
        std::array<UnpolarizedSpectrum, 3> out;
        for (size_t j = 0; j < dr::size_v<UnpolarizedSpectrum>; ++j) {
            Float lambda;
            if constexpr (IsSpectral)
                lambda = wl[j];
            else
                lambda = Float(550.f);
            std::vector<Float> o = m_polarization.run(inputs(wi, &wo, { lambda }), tables, params);
            for (size_t c = 0; c < 3; ++c)
                out[c][j] = o[c];
        }
        DRJIT_MARK_USED(wl);
        return out;
    }

private:
    /// The kind's program for the built parameters where there is one and
    /// the parameters are those (`params.at_built`), else the plain one
    static const Prog &pick(const Prog &plain, const Prog &at_built, const Params &params) {
        return params.at_built && at_built.valid() ? at_built : plain;
    }

    /// The path's wavelengths as inputs (none in RGB and monochromatic
    /// variants)
    static std::vector<Float> wavelengths(const Wavelength &wl) {
        std::vector<Float> v;
        if constexpr (IsSpectral)
            for (size_t j = 0; j < NW; ++j)
                v.push_back(wl[j]);
        DRJIT_MARK_USED(wl);
        return v;
    }

    /// The inputs of a program: the directions (core frame), then extras
    static std::vector<Float> inputs(const Vector3f &a, const Vector3f *b,
                                     const std::vector<Float> &extra) {
        std::vector<Float> in{ a.x(), a.y(), a.z() };
        if (b)
            in.insert(in.end(), { b->x(), b->y(), b->z() });
        in.insert(in.end(), extra.begin(), extra.end());
        return in;
    }

    /// A program's RGB outputs as the variant's spectrum (monochromatic:
    /// their luminance, with the core's weights, as batch.h)
    static UnpolarizedSpectrum from_rgb(const std::vector<Float> &o) {
        if constexpr (IsMono) {
            UnpolarizedSpectrum r;
            r[0] = (float) STAM_SRGB_LUMINANCE_R * o[0] + (float) STAM_SRGB_LUMINANCE_G * o[1] +
                   (float) STAM_SRGB_LUMINANCE_B * o[2];
            return r;
        } else {
            return UnpolarizedSpectrum(o[0], o[1], o[2]);
        }
    }

    Prog m_eval, m_pdf, m_sample, m_coherent;
    /// Each kind's program for the built parameters, where the core has one
    Prog m_eval_at_built, m_pdf_at_built, m_sample_at_built, m_coherent_at_built;
    /// Polarized variants: the polarisation's program (none: depolarize)
    Prog m_polarization;
    program::TableStorage m_host_tables;
};

NAMESPACE_END(diffraction_detail)
NAMESPACE_END(mitsuba)
