/* param_textures.h: textures on the diffraction plugin's material
 * parameters (diffraction.cpp), in the JIT variants: a Gaussian surface's
 * `sigma_um` (scratch and wear maps) and a grating's `height_um` (a compact
 * disc whose groove depth varies; rect and sine profiles). The core's
 * programs read these parameters (`Op::Param`) and are built for every
 * value up to the texture's largest (a Gaussian's `sigma_um_max`, a sine
 * profile's `height_um_max`; a rect profile's powers are a closed form in
 * the height); this header gives each lane the texture's value there.
 * The twist map is diffraction.cpp's (a frame rotation, every variant);
 * maps holding NaN (a twist map: also infinities) are refused here. No
 * physics.
 */
#pragma once

#include <mitsuba/core/properties.h>
#include <mitsuba/render/interaction.h>
#include <mitsuba/render/texture.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "../rust-core/include/stam.h"
#include "plugin_params.h"

NAMESPACE_BEGIN(mitsuba)
NAMESPACE_BEGIN(diffraction_detail)

template <typename Float, typename Spectrum> struct ParamTextures {
    MI_IMPORT_TYPES(Texture)
    using Param = PluginParam<Float>;

    /// One textured parameter: its name, STAM_PARAM_* id, texture, and the
    /// range its values are clamped into.
    struct Entry {
        std::string name;
        uint32_t id;
        ref<Texture> texture;
        ScalarFloat floor = 0.f, max = 0.f;
    };
    std::vector<Entry> entries;

    /// Takes the property `name` when it is a texture on a parameter that
    /// can have one (false: not one of those).
    bool take(const Properties &props, const std::string &name) {
        uint32_t id = name == "sigma_um" ? STAM_PARAM_SIGMA_UM
                      : name == "height_um" ? STAM_PARAM_HEIGHT_UM
                                            : STAM_PARAMS;
        if (id == STAM_PARAMS)
            return false;
        // sigma: 1e-6 um (a mirror) for zero, negative and NaN values
        entries.push_back({ name, id, props.get_unbounded_texture<Texture>(name),
                            id == STAM_PARAM_SIGMA_UM ? 1e-6f : 0.f, 0.f });
        return true;
    }

    bool owns(const std::string &key) const {
        return std::any_of(entries.begin(), entries.end(),
                           [&](const Entry &e) { return e.name == key; });
    }

    /// Checks where each texture may go and adds the core's parameters: the
    /// texture's mean as the parameter (where one value is needed: the
    /// sampling's constants) and, for sigma and a sine profile's height,
    /// its largest value as `sigma_um_max` / `height_um_max` (unless
    /// given), which the programs are built for.
    void attach(std::vector<Param> &params) {
        for (Entry &e : entries) {
            if constexpr (!dr::is_jit_v<Float>) {
                throw ParamError("parameter '" + e.name + "' takes a texture only in the JIT "
                                 "variants (llvm_ad_*, cuda_ad_*); in the scalar variants give "
                                 "a number");
            } else {
                std::string surface = text_of(params, "surface"),
                            profile = text_of(params, "profile");
                refuse_nan(e.name, e.texture.get(), false);
                double max_um;
                bool sine = false;
                if (e.id == STAM_PARAM_SIGMA_UM) {
                    if (surface != "gaussian")
                        throw ParamError("parameter 'sigma_um' takes a texture only on surface "
                                         "\"gaussian\"; other surfaces take a number");
                    auto given = find(params, "sigma_um_max");
                    max_um = given != params.end() ? given->given : shortest(largest(e));
                    if (given == params.end())
                        params.push_back(number("sigma_um_max", max_um, -1));
                } else {
                    bool rect = profile == "rect" || (surface == "cd" && profile.empty());
                    if (!rect && profile != "sine")
                        throw ParamError("parameter 'height_um' takes a texture only with the "
                                         "rect and sine profiles (surface \"cd\", or "
                                         "\"periodic\" with profile \"rect\" or \"sine\")");
                    if (rect) {
                        max_um = shortest(largest(e));
                    } else {
                        auto given = find(params, "height_um_max");
                        max_um = given != params.end() ? given->given : shortest(largest(e));
                        if (given == params.end())
                            params.push_back(number("height_um_max", max_um, -1));
                    }
                    sine = !rect;
                }
                if (!(max_um > 0.0))
                    throw ParamError("parameter '" + e.name + "': the texture's largest value is " +
                                     std::to_string(max_um) + "; it must be positive somewhere");
                // sigma and a sine's height: what the programs are built
                // for; a rect's height: the core's upper bound (its powers
                // are a closed form)
                e.max = e.id == STAM_PARAM_SIGMA_UM || sine ? (ScalarFloat) max_um : 100.f;
                double mean = shortest(dr::slice(dr::detach(e.texture->mean()), 0));
                // (the core wants sigma_um <= sigma_um_max and height_um <=
                // height_um_max, in double)
                mean = std::isfinite(mean) && mean > 0.0
                           ? std::clamp(mean, (double) std::max(e.floor, 1e-6f), max_um)
                           : max_um;
                params.push_back(number(e.name.c_str(), mean, (int) e.id));
            }
        }
    }

    void traverse(TraversalCallback *cb) {
        for (Entry &e : entries)
            cb->put(e.name, e.texture, ParamFlags::Differentiable);
    }

    /// Each texture's value per lane, clamped into [floor, max] (NaN: the
    /// floor), as the programs' per-point parameters
    template <typename Params>
    void apply(Params &params, const SurfaceInteraction3f &si, Mask active) const {
        for (const Entry &e : entries) {
            Float v = e.texture->eval_1(si, active);
            params.per_point[e.id] =
                dr::clip(dr::select(dr::isnan(v), e.floor, v), e.floor, e.max);
        }
    }

    void describe(std::ostream &os) const {
        for (const Entry &e : entries)
            os << "  " << e.name << " = " << string::indent(e.texture) << "," << std::endl;
    }

private:
    static typename std::vector<Param>::iterator find(std::vector<Param> &params,
                                                      const char *name) {
        return std::find_if(params.begin(), params.end(),
                            [&](const Param &p) { return p.name == name; });
    }

    static std::string text_of(std::vector<Param> &params, const char *name) {
        auto it = find(params, name);
        return it == params.end() ? std::string() : it->text;
    }

    /// A float as the shortest decimal that reads back as it (0.4f as 0.4,
    /// not 0.4000000059604645), so that the core and the object's string
    /// form show the texture's values as the user wrote them.
    static double shortest(ScalarFloat x) {
        // 9 significant digits always read back as the float
        char b[32];
        for (int digits = 1;; ++digits) {
            std::snprintf(b, sizeof b, "%.*g", digits, (double) x);
            if (digits == 9 || (ScalarFloat) std::strtod(b, nullptr) == x)
                return std::strtod(b, nullptr);
        }
    }

    static Param number(const char *name, double v, int id) {
        Param p = Param::number(name, v, id);
        p.from_texture = true;
        return p;
    }

    /// The points at which a texture is looked at: every texel centre of a
    /// bitmap (where a bilinear filter's extremes lie; up to 2048 per
    /// axis), a 256 x 256 grid on other textures
    static std::pair<uint32_t, uint32_t> grid(const Texture *t) {
        ScalarVector2i res = t->resolution();
        auto axis = [](int r) { return (uint32_t) (r > 1 ? std::min(r, 2048) : 256); };
        return { axis(res.x()), axis(res.y()) };
    }

    /// JIT variants: the texture's values at the grid's points
    static Float grid_values(const Texture *t) {
        auto [nx, ny] = grid(t);
        UInt32 idx = dr::arange<UInt32>(nx * ny);
        SurfaceInteraction3f si = dr::zeros<SurfaceInteraction3f>(nx * ny);
        si.uv = Point2f((Float(idx % nx) + .5f) / (ScalarFloat) nx,
                        (Float(idx / nx) + .5f) / (ScalarFloat) ny);
        return dr::detach(t->eval_1(si, true));
    }

    /// The texture's largest finite value at the grid's points
    static ScalarFloat largest(const Entry &e) {
        Float v = grid_values(e.texture.get());
        v = dr::select(dr::isfinite(v), v, 0.f);
        return dr::slice(dr::max(v), 0);
    }

public:
    /// Refuses, naming the parameter, a texture with NaN values at the
    /// grid's points (and infinite ones where `refuse_infinite`): a map
    /// that holds no number there is a broken map, not a value to guess
    static void refuse_nan(const std::string &name, const Texture *t, bool refuse_infinite) {
        auto [nx, ny] = grid(t);
        size_t nan = 0, inf = 0;
        if constexpr (dr::is_jit_v<Float>) {
            Float v = grid_values(t);
            nan = (size_t) dr::slice(dr::count(dr::isnan(v)), 0);
            inf = (size_t) dr::slice(dr::count(dr::isinf(v)), 0);
        } else {
            SurfaceInteraction3f si = dr::zeros<SurfaceInteraction3f>();
            for (uint32_t j = 0; j < ny; ++j)
                for (uint32_t i = 0; i < nx; ++i) {
                    si.uv = Point2f((i + .5f) / (ScalarFloat) nx, (j + .5f) / (ScalarFloat) ny);
                    Float v = t->eval_1(si, true);
                    nan += std::isnan(v);
                    inf += std::isinf(v);
                }
        }
        size_t bad = nan + (refuse_infinite ? inf : 0);
        if (bad == 0)
            return;
        std::string what = nan && refuse_infinite && inf ? "NaN or infinite values"
                           : nan                          ? "NaN values"
                                                          : "infinite values";
        throw ParamError("parameter '" + name + "': the texture holds " + what + " (" +
                         std::to_string(bad) + " of the " + std::to_string((size_t) nx * ny) +
                         " points looked at); every value must be a number" +
                         (name == "twist" ? " (degrees)" : " (micrometres)"));
    }
};

NAMESPACE_END(diffraction_detail)
NAMESPACE_END(mitsuba)
