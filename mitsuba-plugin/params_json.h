/* params_json.h: JSON text of the core's parameter object (stam_brdf_new)
 * from the plugin's properties: string escaping, numbers that read back
 * exactly, and the comma-separated height list of a tabulated profile.
 */
#pragma once

#include <mitsuba/mitsuba.h>

#include <cstdio>
#include <cstdlib>
#include <string>
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

/// Parse "0.1, 0.2,0.3" into numbers; false if it is not such a list.
inline bool parse_number_list(const std::string &s, std::vector<double> &out) {
    const char *p = s.c_str();
    out.clear();
    while (true) {
        while (*p == ' ' || *p == '\t' || *p == '\n')
            ++p;
        char *end = nullptr;
        double v = std::strtod(p, &end);
        if (end == p)
            return false;
        out.push_back(v);
        p = end;
        while (*p == ' ' || *p == '\t' || *p == '\n')
            ++p;
        if (*p == '\0')
            return !out.empty();
        if (*p != ',')
            return false;
        ++p;
    }
}

NAMESPACE_END(diffraction_detail)
NAMESPACE_END(mitsuba)
