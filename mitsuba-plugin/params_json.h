/* params_json.h: JSON text of the core's parameter object (stam_brdf_new)
 * from the plugin's properties: string escaping, numbers that read back
 * exactly, the height list of a tabulated profile in its three written
 * forms, and the core's unknown-key message completed with the plugin's
 * own keys; and a small reader of the core's resolved parameters
 * (stam_brdf_params_json), whose defaults the plugin exposes.
 */
#pragma once

#include <mitsuba/mitsuba.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

NAMESPACE_BEGIN(mitsuba)
NAMESPACE_BEGIN(diffraction_detail)

inline std::string json_escape(const std::string &s) {
    std::string out = "\"";
    for (char ch : s) {
        unsigned char c = (unsigned char) ch;
        if (c == '"' || c == '\\') {
            out += '\\';
            out += ch;
        } else if (c < 0x20) {
            char buf[8];
            std::snprintf(buf, sizeof(buf), "\\u%04x", c);
            out += buf;
        } else {
            out += ch;
        }
    }
    return out + "\"";
}

/// Shortest decimal form that reads back as the same double
inline std::string json_number(double v) {
    char buf[40];
    for (int prec = 15; prec <= 17; ++prec) {
        std::snprintf(buf, sizeof(buf), "%.*g", prec, v);
        if (std::strtod(buf, nullptr) == v)
            break;
    }
    return buf;
}

/// A parameter the plugin refuses: the message names it (no "diffraction:"
/// prefix, which the caller adds once).
struct ParamError : std::runtime_error {
    using std::runtime_error::runtime_error;
};

inline bool is_space(char c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r'; }

/// s without leading and trailing white space
inline std::string trimmed(const std::string &s) {
    size_t a = 0, b = s.size();
    while (a < b && is_space(s[a]))
        ++a;
    while (b > a && is_space(s[b - 1]))
        --b;
    return s.substr(a, b - a);
}

/// The start of a long value, for messages
inline std::string excerpt(const std::string &s, size_t max_len = 40) {
    return s.size() <= max_len ? s : s.substr(0, max_len) + "...";
}

/// Parse "0.1, 0.2,0.3" into numbers; false if it is not such a list.
/// Non-finite numbers ("nan", "inf") are parsed: the caller refuses them.
inline bool parse_number_list(const std::string &s, std::vector<double> &out) {
    const char *p = s.c_str();
    out.clear();
    while (true) {
        while (is_space(*p))
            ++p;
        char *end = nullptr;
        double v = std::strtod(p, &end);
        if (end == p)
            return false;
        out.push_back(v);
        p = end;
        while (is_space(*p))
            ++p;
        if (*p == '\0')
            return !out.empty();
        if (*p != ',')
            return false;
        ++p;
    }
}

/// The forms of the `profile` parameter, for messages.
inline const char *profile_forms() {
    return "\"rect\", \"sine\", or the heights of one period in micrometres "
           "written as \"0, 0.1, 0.2\", \"[0, 0.1, 0.2]\" or "
           "{\"heights_um\": [0, 0.1, 0.2]}";
}

/// A tabulated profile written as a string: "h0, h1, ...", "[h0, h1, ...]"
/// or {"heights_um": [h0, h1, ...]} (the core's JSON form). Returns false
/// when `s` is none of these (a profile name); throws ParamError, naming
/// the parameter, when it is one of them but malformed or holds a NaN or
/// an infinite height.
inline bool parse_profile_heights(const std::string &s, std::vector<double> &out) {
    std::string t = trimmed(s);
    if (t.empty())
        throw ParamError(std::string("parameter 'profile' is empty (accepted: ") +
                         profile_forms() + ")");
    auto refuse = [&](const std::string &why) {
        throw ParamError("parameter 'profile' = \"" + excerpt(t) + "\": " + why +
                         " (accepted: " + profile_forms() + ")");
    };
    std::string list = t;
    if (t.front() == '{') {
        // {"heights_um": [ ... ]}
        size_t key = t.find("\"heights_um\"");
        size_t colon = key == std::string::npos ? key : t.find(':', key);
        size_t open = colon == std::string::npos ? colon : t.find('[', colon);
        size_t close = t.rfind(']');
        bool ok = open != std::string::npos && close != std::string::npos && close > open &&
                  trimmed(t.substr(1, key - 1)).empty() &&
                  trimmed(t.substr(key + 12, colon - key - 12)).empty() &&
                  trimmed(t.substr(colon + 1, open - colon - 1)).empty() &&
                  trimmed(t.substr(close + 1)) == "}";
        if (!ok)
            refuse("an object profile must be exactly {\"heights_um\": [h0, h1, ...]}");
        list = t.substr(open + 1, close - open - 1);
    } else if (t.front() == '[') {
        if (t.back() != ']')
            refuse("a bracketed list must end with ']'");
        list = t.substr(1, t.size() - 2);
    } else {
        char first = t.front();
        bool numeric = std::string("+-.0123456789").find(first) != std::string::npos;
        if (!numeric && !parse_number_list(t, out))
            return false; // a name: "rect", "sine", or one the core refuses by name
    }
    if (!parse_number_list(list, out))
        refuse("not a comma-separated list of numbers");
    for (size_t i = 0; i < out.size(); ++i)
        if (!std::isfinite(out[i]))
            refuse("height " + std::to_string(i) + " is " +
                   (std::isnan(out[i]) ? std::string("NaN") : std::string("infinite")) +
                   "; heights must be finite numbers (micrometres)");
    return true;
}

/// A JSON value as the core writes it (stam_brdf_params_json): enough of
/// JSON to read the resolved parameters (objects keep their members' order)
struct JsonValue {
    enum Type { Null, Bool, Number, String, Array, Object } type = Null;
    bool boolean = false;
    double number = 0.0;
    std::string text;
    std::vector<JsonValue> items;
    std::vector<std::pair<std::string, JsonValue>> members;

    const JsonValue *get(const std::string &key) const {
        for (const auto &m : members)
            if (m.first == key)
                return &m.second;
        return nullptr;
    }
};

/// Parses JSON text; throws ParamError where it is not JSON
inline JsonValue parse_json(const std::string &text) {
    struct Parser {
        const std::string &s;
        size_t i = 0;
        [[noreturn]] void fail(const char *what) {
            throw ParamError(std::string("the core's parameters are not JSON (") + what +
                             " at " + std::to_string(i) + ")");
        }
        void space() {
            while (i < s.size() && is_space(s[i]))
                ++i;
        }
        bool eat(char c) {
            space();
            if (i < s.size() && s[i] == c) {
                ++i;
                return true;
            }
            return false;
        }
        bool word(const char *w) {
            size_t n = std::char_traits<char>::length(w);
            if (s.compare(i, n, w) != 0)
                return false;
            i += n;
            return true;
        }
        std::string string() {
            if (!eat('"'))
                fail("a string expected");
            std::string out;
            while (i < s.size() && s[i] != '"') {
                char c = s[i++];
                if (c != '\\') {
                    out += c;
                    continue;
                }
                if (i >= s.size())
                    fail("an escape cut short");
                char e = s[i++];
                switch (e) {
                    case 'n': out += '\n'; break;
                    case 't': out += '\t'; break;
                    case 'r': out += '\r'; break;
                    case 'b': out += '\b'; break;
                    case 'f': out += '\f'; break;
                    case 'u': {
                        if (i + 4 > s.size())
                            fail("a \\u escape cut short");
                        unsigned long cp = std::strtoul(s.substr(i, 4).c_str(), nullptr, 16);
                        i += 4;
                        // UTF-8 of the code point (the core escapes only
                        // control characters)
                        if (cp < 0x80) {
                            out += (char) cp;
                        } else if (cp < 0x800) {
                            out += (char) (0xC0 | (cp >> 6));
                            out += (char) (0x80 | (cp & 0x3F));
                        } else {
                            out += (char) (0xE0 | (cp >> 12));
                            out += (char) (0x80 | ((cp >> 6) & 0x3F));
                            out += (char) (0x80 | (cp & 0x3F));
                        }
                        break;
                    }
                    default: out += e;
                }
            }
            if (!eat('"'))
                fail("an unterminated string");
            return out;
        }
        JsonValue value() {
            JsonValue v;
            space();
            if (i >= s.size())
                fail("a value expected");
            char c = s[i];
            if (c == '{') {
                ++i;
                v.type = JsonValue::Object;
                if (eat('}'))
                    return v;
                do {
                    std::string key = string();
                    if (!eat(':'))
                        fail("':' expected");
                    v.members.emplace_back(key, value());
                } while (eat(','));
                if (!eat('}'))
                    fail("'}' expected");
            } else if (c == '[') {
                ++i;
                v.type = JsonValue::Array;
                if (eat(']'))
                    return v;
                do
                    v.items.push_back(value());
                while (eat(','));
                if (!eat(']'))
                    fail("']' expected");
            } else if (c == '"') {
                v.type = JsonValue::String;
                v.text = string();
            } else if (word("true") || word("false")) {
                v.type = JsonValue::Bool;
                v.boolean = s[i - 1] == 'e' && s[i - 2] == 'u';
            } else if (word("null")) {
                v.type = JsonValue::Null;
            } else {
                char *end = nullptr;
                v.type = JsonValue::Number;
                v.number = std::strtod(s.c_str() + i, &end);
                if (end == s.c_str() + i)
                    fail("a value expected");
                i = (size_t) (end - s.c_str());
            }
            return v;
        }
    } parser{ text };
    JsonValue v = parser.value();
    parser.space();
    if (parser.i != text.size())
        parser.fail("text after the value");
    return v;
}

NAMESPACE_END(diffraction_detail)
NAMESPACE_END(mitsuba)
