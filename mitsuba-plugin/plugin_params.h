/* plugin_params.h: the diffraction plugin's parameters as the user gave
 * them (diffraction.cpp), and the core's defaults of those not given
 * (stam_brdf_params_json), so that mi.traverse exposes every parameter:
 * each one's kind, its value as mi.traverse exposes it, and the core's
 * JSON built from them (params_json.h has the JSON helpers). No physics.
 */
#pragma once

#include <mitsuba/core/properties.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <ostream>
#include <string>
#include <vector>

#include "../rust-core/include/stam.h"
#include "params_json.h"

NAMESPACE_BEGIN(mitsuba)
NAMESPACE_BEGIN(diffraction_detail)

/// A parameter forwarded to the core
template <typename Float> struct PluginParam {
    using ScalarFloat = dr::scalar_t<Float>;
    enum Kind { Number, String, Bool, Json } kind = Number;
    std::string name;
    std::string group;       // non-empty: nested in an object of that name
    double given = 0.0;      // number as given by the user
    ScalarFloat value = 0.f; // number as exposed by traverse() (scalar variants)
    /// JIT variants: the number as traverse() exposes it, differentiable
    /// where the material's programs read it (STAM_PARAM_* `id`)
    Float diff = 0.f;
    int id = -1;
    bool from_texture = false; // set from a texture (param_textures.h), not traversed
    std::string text;   // string value, or raw JSON
    std::string source; // String, Json: the user's string
    /// String, Json: the user's string as the plugin name of a Properties,
    /// the registered type that carries it through mi.traverse (which has
    /// no strings)
    Properties holder;
    /// Not given by the user: the core's default (add_defaults), left out
    /// of the core's JSON while it holds that value, so that the core is
    /// built from the user's keys alone until the default is changed
    bool is_default = false;
    double default_value = 0.0; // Number
    std::string default_text;   // String

    /// A default that nobody changed
    bool at_default() const {
        if (!is_default)
            return false;
        return kind == Number ? value == (ScalarFloat) default_value : source == default_text;
    }

    /// A number given as `v`, forwarded under `name` (STAM_PARAM_* `id`)
    static PluginParam number(const std::string &name, double v, int id) {
        PluginParam p;
        p.name = name;
        p.kind = Number;
        p.given = v;
        p.value = (ScalarFloat) v;
        p.diff = Float(p.value);
        p.id = id;
        return p;
    }
};

/// The STAM_PARAM_* id of a numeric parameter's name (the core's
/// stam_param_name), -1 for none
inline int param_id(const std::string &name) {
    for (uint32_t id = 0; id < STAM_PARAMS; ++id)
        if (name == stam_param_name(id))
            return (int) id;
    return -1;
}

/// The number a JIT variant's parameter holds (one value)
template <typename Float>
dr::scalar_t<Float> scalar_of(const Float &v, const std::string &name) {
    if constexpr (dr::is_jit_v<Float>) {
        if (dr::width(v) != 1)
            throw ParamError("parameter '" + name + "' must be a single value (" +
                             std::to_string(dr::width(v)) + " given)");
        return dr::slice(dr::detach(v), 0);
    } else {
        DRJIT_MARK_USED(name);
        return v;
    }
}

/// A string parameter's kind and core text from the user's string
template <typename Float> void set_text(PluginParam<Float> &p, const std::string &s) {
    std::vector<double> heights;
    if (p.name == "profile" && s != "rect" && s != "sine" && parse_profile_heights(s, heights)) {
        p.kind = PluginParam<Float>::Json;
        std::string j = "{\"heights_um\": [";
        for (size_t i = 0; i < heights.size(); ++i)
            j += (i ? ", " : "") + json_number(heights[i]);
        p.text = j + "]}";
    } else {
        p.kind = PluginParam<Float>::String;
        p.text = s;
    }
    p.source = s;
    p.holder.set_plugin_name(s);
}

/// A number's JSON: the user's value unless traverse() changed it
template <typename Float> std::string number_text(const PluginParam<Float> &p) {
    if ((dr::scalar_t<Float>) p.given == p.value)
        return json_number(p.given);
    char buf[32];
    std::snprintf(buf, sizeof(buf), "%.9g", (double) p.value);
    return buf;
}

/// The core's JSON parameter object; `gradients`: the parameters that have
/// carried a gradient, which the core's programs follow smoothly (its
/// energy table's derivatives along them; a grating's RGB reading C1 along
/// its period and coherence length)
template <typename Float>
std::string build_json(const std::vector<PluginParam<Float>> &params,
                       const std::vector<std::string> &gradients = {}) {
    using P = PluginParam<Float>;
    std::string top, nested;
    for (const P &p : params) {
        if (p.at_default())
            continue; // the core's own default
        std::string v;
        switch (p.kind) {
            case P::Number:
                if (!std::isfinite(p.value))
                    throw ParamError("parameter '" + p.name + "' must be finite");
                v = number_text(p);
                break;
            case P::String: v = json_escape(p.text); break;
            case P::Bool:
            case P::Json: v = p.text; break;
        }
        std::string &dst = p.group.empty() ? top : nested;
        dst += (dst.empty() ? "" : ", ") + json_escape(p.name) + ": " + v;
    }
    if (!nested.empty())
        top += (top.empty() ? "" : ", ") + json_escape("fresnel") + ": {" + nested + "}";
    if (!gradients.empty()) {
        std::string list;
        for (const std::string &name : gradients)
            list += (list.empty() ? "" : ", ") + json_escape(name);
        top += (top.empty() ? "" : ", ") + json_escape("gradients") + ": [" + list + "]";
    }
    return "{" + top + "}";
}

/// Adds to `names` the number parameters that carry a gradient (JIT
/// variants), which the core's programs are asked to follow smoothly
/// (build_json); returns whether any was new
template <typename Float>
bool add_gradient_names(const std::vector<PluginParam<Float>> &params,
                        std::vector<std::string> &names) {
    bool added = false;
    for (const PluginParam<Float> &p : params)
        if (p.kind == PluginParam<Float>::Number && dr::grad_enabled(p.diff) &&
            std::find(names.begin(), names.end(), p.name) == names.end()) {
            names.push_back(p.name);
            added = true;
        }
    return added;
}

/// The parameters as the object's string form lists them ("  name = value,")
template <typename Float>
void describe(std::ostream &os, const std::vector<PluginParam<Float>> &params) {
    for (const PluginParam<Float> &p : params) {
        os << "  " << p.name << " = ";
        if (p.from_texture)
            os << number_text(p) << " (from the texture)";
        else if (p.kind == PluginParam<Float>::Number)
            os << number_text(p);
        else if (p.kind == PluginParam<Float>::String)
            os << json_escape(p.text);
        else
            os << p.text;
        if (p.at_default())
            os << " (default)";
        os << "," << std::endl;
    }
}

/// The core's value of parameter `p` in its resolved parameters (eta and k
/// nested in "fresnel"), or null
inline const JsonValue *resolved_value(const JsonValue &resolved, const std::string &name,
                                       const std::string &group) {
    if (group.empty())
        return resolved.get(name);
    const JsonValue *g = resolved.get(group);
    return g && g->type == JsonValue::Object ? g->get(name) : nullptr;
}

/// Adds as parameters the core's defaults of the keys the user did not
/// give (`resolved`: stam_brdf_params_json), numbers and strings, so that
/// mi.traverse exposes them as if given: a compact disc's period_um,
/// coherence_um, profile, height_um and width_um, a default fresnel (or k
/// beside a given eta), energy, series_tolerance, rgb_nodes. Arrays and
/// objects (gradients, a tabulated profile) are not. Left at their values,
/// they stay out of the core's JSON (PluginParam::at_default).
template <typename Float>
void add_defaults(std::vector<PluginParam<Float>> &params, const std::string &resolved_json) {
    using P = PluginParam<Float>;
    JsonValue resolved = parse_json(resolved_json);
    auto given = [&](const char *name) {
        return std::any_of(params.begin(), params.end(),
                           [&](const P &p) { return p.name == name; });
    };
    std::vector<P> added;
    auto add = [&](const std::string &name, const JsonValue &v, const std::string &group) {
        if (v.type == JsonValue::Number) {
            P p = P::number(name, v.number, param_id(name));
            p.group = group;
            p.is_default = true;
            p.default_value = v.number;
            added.push_back(p);
        } else if (v.type == JsonValue::String) {
            P p;
            p.name = name;
            set_text(p, v.text);
            p.is_default = true;
            p.default_text = v.text;
            added.push_back(p);
        }
    };
    for (const auto &[key, v] : resolved.members) {
        if (key == "surface" || key == "gradients" || given(key.c_str()))
            continue;
        if (key == "fresnel" && v.type == JsonValue::Object) {
            // a complex index: the plugin's eta and k
            for (const auto &[name, part] : v.members)
                if (!given(name.c_str()))
                    add(name, part, "fresnel");
        } else if (key != "fresnel" || !(given("eta") || given("k"))) {
            add(key, v, "");
        }
    }
    params.insert(params.end(), added.begin(), added.end());
}

/// After a rebuild, the defaults nobody changed take the core's new values
/// (a compact disc's coherence length and width follow its period); a
/// value that did not move is left alone (with any gradient it carries)
template <typename Float>
void refresh_defaults(std::vector<PluginParam<Float>> &params, const std::string &resolved_json) {
    using P = PluginParam<Float>;
    JsonValue resolved = parse_json(resolved_json);
    for (P &p : params) {
        if (!p.at_default())
            continue;
        const JsonValue *v = resolved_value(resolved, p.name, p.group);
        if (!v)
            continue; // does not apply now (a rect's width with a sine profile)
        if (p.kind == P::Number && v->type == JsonValue::Number &&
            (dr::scalar_t<Float>) v->number != p.value) {
            p.default_value = p.given = v->number;
            p.value = (dr::scalar_t<Float>) v->number;
            p.diff = Float(p.value);
        } else if (p.kind != P::Number && v->type == JsonValue::String &&
                   v->text != p.default_text) {
            set_text(p, v->text);
            p.default_text = v->text;
        }
    }
}

/// The plugin's frame parameters: finite, twist within a turn
inline void check_frame_params(double twist, double center_u, double center_v) {
    if (!std::isfinite(twist) || std::abs(twist) > 360.0)
        throw ParamError("parameter 'twist' = " + json_number(twist) +
                         " is out of range: accepted [-360, 360] degrees");
    if (!std::isfinite(center_u) || !std::isfinite(center_v))
        throw ParamError("parameters 'center_u' and 'center_v' must be finite");
}

/// What the core accepts for `key` of its parameter reference
/// (stam_parameter_reference; "fresnel.eta": "[0.001, 100]"), for the
/// plugin's messages; "" for a key it does not list
inline std::string core_accepted(const std::string &key) {
    static const JsonValue reference = parse_json(stam_parameter_reference());
    if (const JsonValue *keys = reference.get("material"))
        for (const JsonValue &k : keys->items) {
            const JsonValue *name = k.get("key"), *accepted = k.get("accepted");
            if (name && accepted && name->text == key)
                return accepted->text;
        }
    return "";
}

/// `tracks`: true for "linear", false for "concentric"; ParamError else
inline bool tracks_are_linear(const std::string &t) {
    if (t != "linear" && t != "concentric")
        throw ParamError("parameter 'tracks' = \"" + excerpt(t) +
                         "\": must be \"linear\" or \"concentric\"");
    return t == "linear";
}

/// The lines of a text (no trailing newline expected)
inline std::vector<std::string> lines_of(const std::string &text) {
    std::vector<std::string> out;
    for (size_t pos = 0; pos < text.size();) {
        size_t nl = std::min(text.find('\n', pos), text.size());
        out.push_back(text.substr(pos, nl - pos));
        pos = nl + 1;
    }
    return out;
}

/// JIT variants: every parameter the material's programs read, by
/// STAM_PARAM_* id, as one array in memory (Program::run's `params`): the
/// user's value where given (mi.traverse's, with its gradient), else the
/// programs' own. Being read from memory, a new value changes no kernel.
template <typename Float> class ParamArray {
public:
    using UInt32 = dr::uint32_array_t<Float>;

    /// The array for the programs' built values `built` (NaN: not read) and
    /// the user's parameters; returns whether the built values' programs
    /// (STAM_PROGRAM_AT_BUILT) came into or out of use.
    bool update(std::vector<float> built, const std::vector<PluginParam<Float>> &params) {
        using P = PluginParam<Float>;
        Float a = dr::zeros<Float>(STAM_PARAMS);
        for (uint32_t id = 0; id < STAM_PARAMS; ++id)
            if (!std::isnan(built[id]))
                dr::scatter(a, Float(built[id]), UInt32(id));
        bool at_built = true;
        for (const P &p : params)
            if (p.kind == P::Number && p.id >= 0 && !std::isnan(built[p.id])) {
                dr::scatter(a, p.diff, UInt32((uint32_t) p.id));
                at_built &= p.value == built[p.id];
            }
        dr::make_opaque(a);
        m_array = a;
        m_built = std::move(built);
        bool changed = at_built != m_at_built;
        m_at_built = at_built;
        return changed;
    }

    /// The value the programs were built with of parameter `id` (NaN: not
    /// read, or nothing built)
    float built(int id) const {
        return id >= 0 && (size_t) id < m_built.size() ? m_built[id] : std::nanf("");
    }

    /// Every value is the built one and none carries a gradient: the built
    /// values' programs may run
    bool at_built() const { return m_at_built && !dr::grad_enabled(m_array); }

    const Float &array() const { return m_array; }
    Float &array() { return m_array; }

private:
    Float m_array;
    std::vector<float> m_built;
    bool m_at_built = false;
};

NAMESPACE_END(diffraction_detail)
NAMESPACE_END(mitsuba)
