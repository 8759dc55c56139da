/* param_textures.h: textures on the diffraction plugin's material
 * parameters (diffraction.cpp), in the JIT variants: a Gaussian surface's
 * `sigma_um` (scratch and wear maps) and a grating's `height_um` (a compact
 * disc whose groove depth varies; rect and sine profiles). The core's
 * programs read these parameters (`Op::Param`) and are built for every
 * value up to the texture's largest (a Gaussian's `sigma_um_max`, a sine
 * profile's `height_um_max`; a rect profile's powers are a closed form in
 * the height); this header gives each lane the texture's value there.
 * Which parameters take a texture, on which materials, what the material
 * is then built for and the range of each point's value are the core's
 * (stam_param_takes_texture, stam_texture_plan).
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
    /// range its values are clamped into (the core's: stam_texture_plan).
    struct Entry {
        std::string name;
        uint32_t id;
        ref<Texture> texture;
        ScalarFloat floor = 0.f, max = 0.f;
    };
    std::vector<Entry> entries;

    /// Takes the property `name` when it is a texture on a parameter that
    /// can have one (false: not one of those; the core decides which)
    bool take(const Properties &props, const std::string &name) {
        if (!stam_param_takes_texture(name.c_str()))
            return false;
        entries.push_back({ name, (uint32_t) param_id(name),
                            props.get_unbounded_texture<Texture>(name) });
        return true;
    }

    /// The parameters that take a texture, for messages: the plugin's twist
    /// and the core's ("'twist', 'sigma_um' and 'height_um'")
    static std::string textured_names() {
        std::vector<std::string> names{ "'twist'" };
        for (uint32_t id = 0; id < STAM_PARAMS; ++id)
            if (stam_param_takes_texture(stam_param_name(id)))
                names.push_back("'" + std::string(stam_param_name(id)) + "'");
        std::string out;
        for (size_t i = 0; i < names.size(); ++i)
            out += (i == 0 ? "" : i + 1 == names.size() ? " and " : ", ") + names[i];
        return out;
    }

    bool owns(const std::string &key) const {
        return std::any_of(entries.begin(), entries.end(),
                           [&](const Entry &e) { return e.name == key; });
    }

    /// Checks where each texture may go and adds the core's parameters
    /// (stam_texture_plan: the texture's mean as the parameter, where one
    /// value is needed, such as the sampling's constants; the largest value
    /// the programs are built for, unless given) and the range each point's
    /// value is clamped into.
    void attach(std::vector<Param> &params) {
        for (Entry &e : entries) {
            if constexpr (!dr::is_jit_v<Float>) {
                throw ParamError("parameter '" + e.name + "' takes a texture only in the JIT "
                                 "variants (llvm_ad_*, cuda_ad_*); in the scalar variants give "
                                 "a number");
            } else {
                refuse_nan(e.name, e.texture.get(), false);
                double largest_value = shortest(largest(e)),
                       mean = shortest(dr::slice(dr::detach(e.texture->mean()), 0));
                char err[1024] = { 0 };
                char *answer = stam_texture_plan(build_json(params).c_str(), e.name.c_str(),
                                                 largest_value, mean, err, sizeof err);
                if (!answer)
                    throw ParamError(err);
                JsonValue plan = parse_json(answer);
                stam_text_free(answer);
                const JsonValue *add = plan.get("add"), *range = plan.get("range");
                if (!add || !range || range->items.size() != 2)
                    throw ParamError("the core's texture plan of '" + e.name + "' is incomplete");
                for (const auto &[key, value] : add->members)
                    params.push_back(number(key.c_str(), value.number, param_id(key)));
                e.floor = (ScalarFloat) range->items[0].number;
                e.max = (ScalarFloat) range->items[1].number;
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
