/* The plugin's program decoder (mitsuba-plugin/program.h) on a float32 file:
 * prints "ok <instructions> <gathers> <outputs>" (exit 0) or
 * "malformed: <reason>" (exit 1). Built and run by tests/test_jit.py, which
 * feeds it the core's programs and corrupted copies of them: a malformed
 * array must be refused with an exception, never crash. Host code only. */
#include <cstdio>
#include <vector>

#include "../../mitsuba-plugin/program.h"

int main(int argc, char **argv) {
    if (argc != 2)
        return 3;
    FILE *f = std::fopen(argv[1], "rb");
    if (!f)
        return 3;
    std::vector<float> v;
    float x;
    while (std::fread(&x, sizeof(float), 1, f) == 1)
        v.push_back(x);
    std::fclose(f);
    try {
        auto code = mitsuba::diffraction_detail::program::decode_program(v.data(), v.size());
        std::printf("ok %zu %zu %zu\n", code.code.size(), code.gathers, code.outputs.size());
        return 0;
    } catch (const mitsuba::diffraction_detail::program::Malformed &e) {
        std::printf("malformed: %s\n", e.what());
        return 1;
    }
}
