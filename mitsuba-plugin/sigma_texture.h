/* sigma_texture.h: a texture on the diffraction plugin's `sigma_um`
 * (diffraction.cpp): a Gaussian surface whose rms height varies point by
 * point (scratch and wear maps). The core builds the material's programs
 * for every sigma up to the texture's largest value (`sigma_um_max`,
 * docs/parameters.md) and the programs read sigma as their parameter, which
 * this header gives per lane. No physics.
 */
#pragma once

#include <mitsuba/render/interaction.h>
#include <mitsuba/render/texture.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "../rust-core/include/stam.h"
#include "plugin_params.h"

NAMESPACE_BEGIN(mitsuba)
NAMESPACE_BEGIN(diffraction_detail)

/// Smallest sigma a texture gives the programs (um): values at or below 0
/// (a smooth point) read as this.
constexpr float SigmaTextureFloor = 1e-6f;

template <typename Float, typename Spectrum> struct SigmaTexture {
    MI_IMPORT_TYPES(Texture)
    using Param = PluginParam<Float>;

    ref<Texture> texture;
    /// The largest sigma the programs serve; the texture's values are
    /// clamped to it.
    ScalarFloat max = 0.f;

    explicit operator bool() const { return (bool) texture; }

    /// Checks where the texture may go and adds the core's parameters:
    /// `sigma_um` (the texture's mean, where one value is needed) and
    /// `sigma_um_max` (the texture's largest value, unless given).
    void attach(std::vector<Param> &params) {
        if constexpr (!dr::is_jit_v<Float>) {
            throw ParamError("parameter 'sigma_um' takes a texture only in the JIT variants "
                             "(llvm_ad_*, cuda_ad_*); in the scalar variants give a number");
        } else {
            auto find = [&](const char *name) {
                return std::find_if(params.begin(), params.end(),
                                    [&](const Param &p) { return p.name == name; });
            };
            auto surface = find("surface");
            if (surface == params.end() || surface->text != "gaussian")
                throw ParamError("parameter 'sigma_um' takes a texture only on surface "
                                 "\"gaussian\"; other surfaces take a number");
            auto given = find("sigma_um_max");
            double max_um = given != params.end() ? given->given : (double) largest();
            max = (ScalarFloat) max_um;
            if (!(max > 0.f))
                throw ParamError("parameter 'sigma_um': the texture's largest value is " +
                                 std::to_string(max) + "; it must be positive somewhere");
            double mean = (double) dr::slice(dr::detach(texture->mean()), 0);
            if (given == params.end())
                params.push_back(number("sigma_um_max", max_um, -1));
            // (the core wants sigma_um <= sigma_um_max, in double)
            mean = std::isfinite(mean) ? std::clamp(mean, (double) SigmaTextureFloor, max_um)
                                       : max_um;
            params.push_back(number("sigma_um", mean, STAM_PARAM_SIGMA_UM));
        }
    }

    /// sigma_um per lane: the texture's value, clamped into [floor, max]
    /// (NaN: the floor)
    Float at(const SurfaceInteraction3f &si, Mask active) const {
        Float v = texture->eval_1(si, active);
        return dr::clip(dr::select(dr::isnan(v), SigmaTextureFloor, v), SigmaTextureFloor, max);
    }

private:
    static Param number(const char *name, double v, int id) {
        Param p;
        p.name = name;
        p.kind = Param::Number;
        p.given = v;
        p.value = (ScalarFloat) v;
        p.diff = Float(p.value);
        p.id = id;
        p.from_texture = true;
        return p;
    }

    /// The texture's largest value: at every texel centre of a bitmap
    /// (where a bilinear filter's maximum lies; up to 2048 per axis), on a
    /// 256 x 256 grid for other textures.
    ScalarFloat largest() const {
        ScalarVector2i res = texture->resolution();
        auto axis = [](int r) { return (uint32_t) (r > 1 ? std::min(r, 2048) : 256); };
        uint32_t nx = axis(res.x()), ny = axis(res.y());
        UInt32 idx = dr::arange<UInt32>(nx * ny);
        SurfaceInteraction3f si = dr::zeros<SurfaceInteraction3f>(nx * ny);
        si.uv = Point2f((Float(idx % nx) + .5f) / (ScalarFloat) nx,
                        (Float(idx / nx) + .5f) / (ScalarFloat) ny);
        Float v = dr::detach(texture->eval_1(si, true));
        v = dr::select(dr::isfinite(v), v, 0.f);
        return dr::slice(dr::max(v), 0);
    }
};

NAMESPACE_END(diffraction_detail)
NAMESPACE_END(mitsuba)
