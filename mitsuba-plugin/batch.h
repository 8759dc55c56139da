/* batch.h: host-side batches of the diffraction plugin (diffraction.cpp).
 *
 * The plugin's queries travel to the Rust core (rust-core/include/stam.h) as
 * float buffers: this header stages Mitsuba arrays into such buffers (one
 * lane per query: the scalar variants' path; JIT variants run the core's
 * programs, jit_path.h), makes the one path-vertex call per batch, and
 * loads the results back into Mitsuba types. No physics: only copies, layout changes and the luminance
 * that monochromatic variants take of the core's RGB output.
 */
#pragma once

#include <mitsuba/core/spectrum.h>
#include <mitsuba/render/interaction.h>

#include <algorithm>
#include <cstdint>
#include <memory>
#include <vector>

#include "../rust-core/include/stam.h"

NAMESPACE_BEGIN(mitsuba)
NAMESPACE_BEGIN(diffraction_detail)

// ---------------------------------------------------------------------------
// Host-side batch evaluation (AoS float buffers, no Mitsuba types)
// ---------------------------------------------------------------------------

enum class Channels { Rgb, Mono, Spectral };

struct CoreFree {
    void operator()(StamBrdf *b) const { stam_brdf_free(b); }
};
using CorePtr = std::unique_ptr<StamBrdf, CoreFree>;

/// One batch of queries and results. Inputs are AoS (as the core wants them),
/// outputs are SoA (one contiguous run of n floats per channel) so that JIT
/// variants can load each channel as one array.
struct Batch {
    size_t n = 0;
    // Inputs
    std::vector<float> wi;   // 3 n, core frame
    std::vector<float> wo;   // 3 n, core frame (eval / pdf queries)
    std::vector<float> lam;  // n * nw, lane-major (spectral only)
    std::vector<float> rnd;  // 3 n (sampling only)
    bool want_f = false, want_pdf = false, want_sample = false;
    // Outputs (SoA)
    std::vector<float> f;      // nc * n: f(wi, wo), NOT multiplied by cos
    std::vector<float> pdf;    // n: pdf(wo), mixture over wavelengths
    std::vector<float> s_wo;   // 3 * n: sampled direction, core frame
    std::vector<float> s_pdf;  // n: pdf of the sample (mixture probability if coherent)
    std::vector<float> s_coh;  // n: 1 if the coherent lobe was sampled
    std::vector<float> s_val;  // nc * n: f at s_wo, or coherent reflectance
};

/// Temporaries of one batch (AoS outputs of the core). Scalar variants keep
/// one per thread, so that a call allocates nothing once the buffers have
/// grown (a dozen malloc/free pairs per call were ~8% of a scalar render).
struct Scratch {
    std::vector<float> aos, wo, val;
    std::vector<uint8_t> coh;
};

/// Luminance of a linear sRGB triple, with the core's weights (stam.h): the
/// core gamut-maps its RGB outputs at constant luminance with these, so a
/// monochromatic variant sees exactly the luminance the core preserved.
inline float luminance(const float *rgb) {
    return (float) STAM_SRGB_LUMINANCE_R * rgb[0] + (float) STAM_SRGB_LUMINANCE_G * rgb[1] +
           (float) STAM_SRGB_LUMINANCE_B * rgb[2];
}

/// AoS (k per lane) -> SoA; Mono takes the luminance of the core's RGB.
inline void to_soa(const float *aos, size_t n, size_t k, Channels ch, float *soa) {
    if (ch == Channels::Mono) {
        for (size_t i = 0; i < n; ++i)
            soa[i] = luminance(aos + 3 * i);
        return;
    }
    for (size_t i = 0; i < n; ++i)
        for (size_t c = 0; c < k; ++c)
            soa[c * n + i] = aos[i * k + c];
}

/// Run every requested query of a batch through the core's path-vertex
/// calls (one call when a lane asks for both, so that the core builds its
/// strategy once): spectral lanes pass their nw wavelengths (the core samples
/// with one of them and returns the mixture density over all, see stam.h);
/// RGB and Mono lanes pass none (Mono is the luminance of RGB).
inline void run_batch(const StamBrdf *core, Channels ch, size_t nw, Batch &b, Scratch &tmp) {
    const size_t n = b.n;
    const bool spectral = ch == Channels::Spectral;
    const float *lam = spectral ? b.lam.data() : nullptr;
    const size_t core_nw = spectral ? nw : 0,
                 core_nc = spectral ? nw : 3,        // floats per lane from the core
                 nc = ch == Channels::Mono ? 1 : core_nc;
    const bool eval = b.want_f || b.want_pdf;

    float *f = nullptr, *pdf = nullptr;
    if (eval) {
        tmp.aos.resize(core_nc * n);
        b.pdf.assign(n, 0.f);
        f = b.want_f ? tmp.aos.data() : nullptr;
        pdf = b.want_pdf ? b.pdf.data() : nullptr;
    }
    if (b.want_sample) {
        tmp.wo.resize(3 * n);
        b.s_pdf.resize(n);
        tmp.coh.resize(n);
        tmp.val.resize(core_nc * n);
    }
    if (eval && b.want_sample)
        stam_brdf_eval_pdf_sample_vertex(core, n, b.wi.data(), b.wo.data(), lam, core_nw,
                                         b.rnd.data(), f, pdf, tmp.wo.data(), b.s_pdf.data(),
                                         tmp.coh.data(), tmp.val.data());
    else if (eval)
        stam_brdf_eval_pdf_vertex(core, n, b.wi.data(), b.wo.data(), lam, core_nw, f, pdf);
    else if (b.want_sample)
        stam_brdf_sample_vertex(core, n, b.wi.data(), lam, core_nw, b.rnd.data(),
                                tmp.wo.data(), b.s_pdf.data(), tmp.coh.data(), tmp.val.data());

    if (b.want_f) {
        b.f.resize(nc * n);
        to_soa(tmp.aos.data(), n, core_nc, ch, b.f.data());
    }
    if (b.want_sample) {
        b.s_wo.resize(3 * n);
        to_soa(tmp.wo.data(), n, 3, Channels::Rgb, b.s_wo.data());
        b.s_coh.resize(n);
        for (size_t i = 0; i < n; ++i)
            b.s_coh[i] = tmp.coh[i] ? 1.f : 0.f;
        b.s_val.resize(nc * n);
        to_soa(tmp.val.data(), n, core_nc, ch, b.s_val.data());
    }
}

// ---------------------------------------------------------------------------
// Mitsuba / Dr.Jit arrays <-> host batches
// ---------------------------------------------------------------------------

template <typename Float, typename Spectrum>
struct BatchIO {
    MI_IMPORT_TYPES()

    static constexpr bool IsSpectral = is_spectral_v<Spectrum>;
    static constexpr bool IsMono = is_monochromatic_v<Spectrum>;
    static constexpr size_t NW = IsSpectral ? dr::size_v<Wavelength> : 0;
    static constexpr size_t NC = dr::size_v<UnpolarizedSpectrum>;
    static constexpr Channels Ch =
        IsSpectral ? Channels::Spectral : (IsMono ? Channels::Mono : Channels::Rgb);

    /// Copy the inputs of one query into the batch: wi_c, wo_c (core frame),
    /// the path's wavelengths (spectral variants) and, when do_sample, the
    /// three uniforms. Scalar variants only: JIT variants run the core's
    /// programs (jit_path.h).
    static void stage(Batch &b, const Vector3f &wi_c, const Vector3f &wo_c,
                      const SurfaceInteraction3f &si, const Float *sample1,
                      const Point2f *sample2, bool do_sample) {
        static_assert(!dr::is_jit_v<Float>, "the batch ABI serves scalar variants");
        b.n = 1;
        b.wi.assign({ wi_c.x(), wi_c.y(), wi_c.z() });
        b.wo.assign({ wo_c.x(), wo_c.y(), wo_c.z() });
        b.lam.clear();
        if constexpr (IsSpectral)
            for (size_t j = 0; j < NW; ++j)
                b.lam.push_back(si.wavelengths[j]);
        b.rnd.clear();
        if (do_sample)
            b.rnd.assign({ *sample1, sample2->x(), sample2->y() });
    }

    /// Channel k of a one-lane SoA host buffer
    static Float load(const std::vector<float> &soa, size_t k) { return soa[k]; }

    static UnpolarizedSpectrum load_spectrum(const std::vector<float> &soa) {
        UnpolarizedSpectrum r;
        for (size_t k = 0; k < NC; ++k)
            r[k] = load(soa, k);
        return r;
    }
};

NAMESPACE_END(diffraction_detail)
NAMESPACE_END(mitsuba)
