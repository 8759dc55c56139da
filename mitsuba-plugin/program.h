/* program.h: the generic executor of the core's programs (diffraction.cpp).
 *
 * The core describes what a tracing renderer must compute as a *program*:
 * straight-line SSA code over float lanes (register i = the result of
 * instruction i) and the tables it reads (rust-core/src/program/, docs/jit.md;
 * exported by stam_brdf_export_program). This header decodes and checks such
 * a program (decode_program: every operand defined before its use and of the
 * right kind, every table inside the array, as the core's own `decode`), and
 * executes it with Dr.Jit operations, one per instruction (Program::run), so
 * that Dr.Jit traces it like any other code: symbolic loops and calls,
 * dr.freeze, LLVM and CUDA alike. A region of the program (If .. EndIf)
 * runs inside dr::if_stmt, so that a packet or warp none of whose lanes
 * needs it skips it. No physics: which operations, in which order, on which
 * tables, is the core's.
 */
#pragma once

#include <drjit/array.h>
#include <drjit/if_stmt.h>
#include <drjit/math.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <memory>
#include <stdexcept>
#include <string>
#include <tuple>
#include <unordered_map>
#include <vector>

#include "../rust-core/include/stam.h"

namespace mitsuba {
namespace diffraction_detail {
namespace program {

namespace dr = ::drjit;

/// Version of the array layout and of the operation set (stam.h).
constexpr uint32_t Format = STAM_PROGRAM_FORMAT;
/// Values before the outputs.
constexpr size_t HeaderLen = STAM_PROGRAM_HEADER_LEN;

/// Operation codes (stam.h's STAM_OP_*).
enum class Op : uint32_t {
    Input = STAM_OP_INPUT, Const = STAM_OP_CONST, Add = STAM_OP_ADD, Sub = STAM_OP_SUB,
    Mul = STAM_OP_MUL, Div = STAM_OP_DIV, Min = STAM_OP_MIN, Max = STAM_OP_MAX,
    Fma = STAM_OP_FMA, Neg = STAM_OP_NEG, Abs = STAM_OP_ABS, Sqrt = STAM_OP_SQRT,
    Exp = STAM_OP_EXP, Log = STAM_OP_LOG, Sin = STAM_OP_SIN, Cos = STAM_OP_COS,
    Atan2 = STAM_OP_ATAN2, Floor = STAM_OP_FLOOR, Lt = STAM_OP_LT, Le = STAM_OP_LE,
    Gt = STAM_OP_GT, Ge = STAM_OP_GE, Eq = STAM_OP_EQ, Finite = STAM_OP_FINITE,
    And = STAM_OP_AND, Or = STAM_OP_OR, Not = STAM_OP_NOT, Select = STAM_OP_SELECT,
    Gather = STAM_OP_GATHER, Param = STAM_OP_PARAM, If = STAM_OP_IF, EndIf = STAM_OP_END_IF
};
constexpr uint32_t OpCount = STAM_OPS;

/// The registers an operation reads (Gather reads only its index, b; If its
/// mask, a; EndIf names its If in a, which is no read).
inline size_t arity(Op op) {
    switch (op) {
        case Op::Input: case Op::Const: case Op::Param: case Op::EndIf: return 0;
        case Op::Neg: case Op::Abs: case Op::Sqrt: case Op::Exp: case Op::Log:
        case Op::Sin: case Op::Cos: case Op::Floor: case Op::Finite: case Op::Not:
        case Op::Gather: case Op::If:
            return 1;
        case Op::Fma: case Op::Select: return 3;
        default: return 2;
    }
}

/// Whether the result is a mask (else a float).
inline bool gives_mask(Op op) {
    switch (op) {
        case Op::Lt: case Op::Le: case Op::Gt: case Op::Ge: case Op::Eq:
        case Op::Finite: case Op::And: case Op::Or: case Op::Not:
            return true;
        default: return false;
    }
}

/// Whether operand k of op is a mask (else a float).
inline bool wants_mask(Op op, size_t k) {
    switch (op) {
        case Op::And: case Op::Or: case Op::Not: case Op::If: return true;
        case Op::Select: return k == 0;
        default: return false;
    }
}

struct Instr {
    Op op;
    uint32_t a, b, c; // registers; Input: the input; Const: a's bits; Gather: table,
                      // index; Param: the slot in the parameter section; If: mask,
                      // and (set by decode_program) its region's number
    float value;      // Const
    /// The registers it reads: a, b, c by arity; Gather: b.
    uint32_t operand(size_t k) const {
        if (op == Op::Gather)
            return b;
        return k == 0 ? a : (k == 1 ? b : c);
    }
};

/// A region (If .. EndIf): where it ends, the registers from outside that
/// it reads (live-ins) and those it defines that are read after it
/// (live-outs), floats and masks apart.
struct Region {
    uint32_t end = 0;
    std::vector<uint32_t> in_f, in_m, out_f, out_m;
};

/// A decoded, checked program: its code, outputs and where its tables lie
/// in the float array it came from.
struct Code {
    uint32_t n_inputs = 0;
    std::vector<Instr> code;
    std::vector<uint32_t> outputs;
    std::vector<size_t> table_offset, table_len; // into the array
    /// The parameter section: slot k's id (STAM_PARAM_*) and the value the
    /// program was built with (Param reads slot k)
    std::vector<uint32_t> param_id;
    std::vector<float> param_value;
    /// After instruction i, the registers whose last reader it was (so that
    /// the executor drops them: Dr.Jit then holds only the live ones).
    std::vector<std::vector<uint32_t>> last_use;
    std::vector<Region> regions;
    size_t gathers = 0;
    /// Where each table starts in the buffer the caller loads (Program).
    std::vector<uint32_t> table_base;
    /// Where the program's tables start in that buffer's table directory
    /// (TableStorage: one entry per table, its start and last index)
    uint32_t dir_offset = 0;
};

/// Thrown for an array that is not a well-formed program.
struct Malformed : std::runtime_error {
    using std::runtime_error::runtime_error;
};

/// The program of a float array made by the core (`Program::encode`),
/// checked as the core's `decode` checks it: the format, every integer
/// exact, every operand a register defined before its use and of the kind
/// the operation takes, every input and table in range, the outputs floats.
/// Throws Malformed (saying what is wrong) for anything else.
inline Code decode_program(const float *v, size_t len) {
    auto fail = [](const std::string &what) -> void {
        throw Malformed("malformed program array: " + what);
    };
    auto int_at = [&](size_t i, const char *what) -> uint32_t {
        float x = v[i];
        if (!(x >= 0.f && x < 16777216.f) || x != std::floor(x))
            fail(std::string(what) + " is not an integer in [0, 2^24) (value " +
                 std::to_string(x) + " at " + std::to_string(i) + ")");
        return (uint32_t) x;
    };
    if (!v || len < HeaderLen)
        fail("shorter than its header (" + std::to_string(len) + " values)");
    if (int_at(0, "the format") != Format)
        fail("format " + std::to_string(v[0]) + ", this plugin reads format " +
             std::to_string(Format) + " (rebuild the plugin with its core)");
    Code p;
    p.n_inputs = int_at(1, "the input count");
    size_t n_out = int_at(2, "the output count"), n_code = int_at(3, "the instruction count"),
           n_tab = int_at(4, "the table count"), total = int_at(5, "the length"),
           n_par = int_at(6, "the parameter count");
    if (total != len)
        fail("its header says " + std::to_string(total) + " values, the array has " +
             std::to_string(len));
    size_t dir = HeaderLen + n_out, par_at = dir + 2 * n_tab, code_at = par_at + 2 * n_par,
           data_at = code_at + 4 * n_code;
    if (data_at > total)
        fail("its code runs past its end");
    for (size_t t = 0; t < n_tab; ++t) {
        size_t off = int_at(dir + 2 * t, "a table offset"),
               n = int_at(dir + 2 * t + 1, "a table length");
        if (off < data_at || off + n > total)
            fail("table " + std::to_string(t) + " lies outside the table data");
        p.table_offset.push_back(off);
        p.table_len.push_back(n);
    }
    for (size_t k = 0; k < n_par; ++k) {
        uint32_t id = int_at(par_at + 2 * k, "a parameter id");
        if (id >= STAM_PARAMS)
            fail("parameter " + std::to_string(k) + " has the unknown id " + std::to_string(id));
        p.param_id.push_back(id);
        p.param_value.push_back(v[par_at + 2 * k + 1]);
    }
    // Per register: 0 float, 1 mask, 2 a region's marker (read by nothing).
    std::vector<uint8_t> kind;
    std::vector<size_t> last(n_code, 0);
    // Per instruction: the innermost region it lies in (its number + 1; 0:
    // none); per region: its If and the region it lies in (same coding).
    std::vector<uint32_t> inside(n_code, 0), region_if, parent;
    std::vector<uint32_t> open;
    p.code.reserve(n_code);
    for (size_t i = 0; i < n_code; ++i) {
        size_t at = code_at + 4 * i;
        uint32_t code = int_at(at, "an operation code");
        if (code >= OpCount)
            fail("unknown operation " + std::to_string(code) + " at instruction " +
                 std::to_string(i));
        Instr ins;
        ins.op = (Op) code;
        ins.value = 0.f;
        if (ins.op == Op::Const) {
            ins.value = v[at + 1];
            ins.a = 0;
        } else {
            ins.a = int_at(at + 1, "an operand");
        }
        ins.b = int_at(at + 2, "an operand");
        ins.c = int_at(at + 3, "an operand");
        if (ins.op == Op::Input && ins.a >= p.n_inputs)
            fail("instruction " + std::to_string(i) + " reads input " +
                 std::to_string(ins.a) + " of " + std::to_string(p.n_inputs));
        if (ins.op == Op::Param && ins.a >= n_par)
            fail("instruction " + std::to_string(i) + " reads parameter slot " +
                 std::to_string(ins.a) + " of " + std::to_string(n_par));
        if (ins.op == Op::Gather && ins.a >= n_tab)
            fail("instruction " + std::to_string(i) + " reads table " +
                 std::to_string(ins.a) + " of " + std::to_string(n_tab));
        if ((ins.op == Op::Input || ins.op == Op::Const || ins.op == Op::Param) && !open.empty())
            fail("instruction " + std::to_string(i) + " (an input, constant or parameter) "
                 "lies inside a region");
        for (size_t k = 0; k < arity(ins.op); ++k) {
            uint32_t r = ins.operand(k);
            if (r >= i || kind[r] != (wants_mask(ins.op, k) ? 1 : 0))
                fail("instruction " + std::to_string(i) + " reads register " +
                     std::to_string(r) + (r >= i ? ", not defined before it"
                                                 : ", of the wrong kind (mask or float)"));
        }
        inside[i] = open.empty() ? 0 : open.back() + 1;
        if (ins.op == Op::If) {
            ins.b = (uint32_t) region_if.size();
            open.push_back(ins.b);
            region_if.push_back((uint32_t) i);
            parent.push_back(inside[i]);
            p.regions.emplace_back();
        } else if (ins.op == Op::EndIf) {
            if (open.empty() || region_if[open.back()] != ins.a)
                fail("instruction " + std::to_string(i) + " ends a region that is not the "
                     "innermost open one");
            p.regions[open.back()].end = (uint32_t) i;
            open.pop_back();
            inside[i] = open.empty() ? 0 : open.back() + 1;
        }
        p.gathers += ins.op == Op::Gather;
        kind.push_back(ins.op == Op::If || ins.op == Op::EndIf ? 2 : gives_mask(ins.op));
        p.code.push_back(ins);
    }
    if (!open.empty())
        fail("a region is not closed");
    // Whether region g (number + 1; 0: the whole program) holds instruction
    // k; a read at k of register r: each region holding k but not r reads r
    // from outside (a live-in), each holding r but not k has r read after
    // it (a live-out); its last use, for the executor, is the end of the
    // outermost region holding k but not r.
    auto holds = [&](uint32_t g, size_t k) {
        return g == 0 || (region_if[g - 1] < k && k <= p.regions[g - 1].end);
    };
    auto note_read = [&](uint32_t r, size_t k) {
        size_t at = k;
        for (uint32_t g = k < n_code ? inside[k] : 0; !holds(g, r); g = parent[g - 1]) {
            Region &reg = p.regions[g - 1];
            (kind[r] ? reg.in_m : reg.in_f).push_back(r);
            at = reg.end;
        }
        for (uint32_t g = inside[r]; !holds(g, k); g = parent[g - 1]) {
            Region &reg = p.regions[g - 1];
            (kind[r] ? reg.out_m : reg.out_f).push_back(r);
        }
        last[r] = std::max(last[r], at);
    };
    for (size_t i = 0; i < n_code; ++i)
        for (size_t k = 0; k < arity(p.code[i].op); ++k)
            note_read(p.code[i].operand(k), i);
    for (size_t k = 0; k < n_out; ++k) {
        uint32_t r = int_at(HeaderLen + k, "an output register");
        if (r >= n_code || kind[r] != 0)
            fail("output " + std::to_string(k) + " is not a float register");
        p.outputs.push_back(r);
        note_read(r, n_code);
        last[r] = n_code; // kept to the end
    }
    for (Region &reg : p.regions)
        for (auto *regs : { &reg.in_f, &reg.in_m, &reg.out_f, &reg.out_m }) {
            std::sort(regs->begin(), regs->end());
            regs->erase(std::unique(regs->begin(), regs->end()), regs->end());
        }
    p.last_use.assign(n_code, {});
    for (size_t r = 0; r < n_code; ++r)
        if (last[r] < n_code && last[r] > r)
            p.last_use[last[r]].push_back((uint32_t) r);
    return p;
}

/// The array an export function of the core writes (`write(out, capacity)`,
/// its length returned), sized with out = nullptr; empty where it has none.
template <typename Write> std::vector<float> exported(Write write) {
    size_t n = write(nullptr, 0);
    std::vector<float> v(n);
    if (n && write(v.data(), n) != n)
        throw Malformed("the core wrote a program of another length than it announced");
    return v;
}

/// The program of `kind` exported by the core material b; an empty vector
/// where the material has none.
inline std::vector<float> export_program(const StamBrdf *b, uint32_t kind) {
    return exported([&](float *out, size_t n) { return stam_brdf_export_program(b, kind, out, n); });
}

/// The core's polarisation program (stam_brdf_export_polarization_program),
/// empty where the material has none
inline std::vector<float> export_polarization_program(const StamBrdf *b) {
    return exported(
        [&](float *out, size_t n) { return stam_brdf_export_polarization_program(b, out, n); });
}

/// The core's mixture program (STAM_MIXTURE_*, with STAM_PROGRAM_AT_BUILT
/// where wanted) over `n_wavelengths` as an array, empty where it has none
inline std::vector<float> export_mixture_program(const StamBrdf *b, uint32_t kind,
                                                 uint32_t n_wavelengths) {
    return exported([&](float *out, size_t n) {
        return stam_brdf_export_mixture_program(b, kind, n_wavelengths, out, n);
    });
}

/// The host values of the tables of several programs, each distinct table
/// once (programs of one material share some: the spectral Gaussian's eval
/// and pdf read the same 281,502-value series table), and a directory: per
/// table of each program, where it starts and its last index. `Tables`
/// loads both for Dr.Jit.
class TableStorage {
public:
    /// Where `n` values equal to `src` start in the storage (appended unless
    /// an equal table is there already), before the directory.
    uint32_t add(const float *src, size_t n) {
        uint64_t h = 1469598103934665603ull ^ n; // FNV-1a over the bits
        const unsigned char *bytes = (const unsigned char *) src;
        for (size_t i = 0; i < n * sizeof(float); ++i)
            h = (h ^ bytes[i]) * 1099511628211ull;
        auto range = m_index.equal_range(h);
        for (auto it = range.first; it != range.second; ++it)
            if (it->second.second == n &&
                (n == 0 || std::memcmp(m_values.data() + it->second.first, src,
                                       n * sizeof(float)) == 0))
                return it->second.first;
        if (m_values.size() + n >= (size_t(1) << 30))
            throw Malformed("tables of more than 2^30 values");
        uint32_t base = (uint32_t) m_values.size();
        m_values.insert(m_values.end(), src, src + n);
        m_index.emplace(h, std::make_pair(base, n));
        return base;
    }

    /// The directory entries of one program's tables (their starts from
    /// `add` and lengths): returns where they start in the directory.
    uint32_t add_directory(const std::vector<uint32_t> &base, const std::vector<size_t> &len) {
        uint32_t at = (uint32_t) m_starts.size();
        for (size_t t = 0; t < base.size(); ++t) {
            m_starts.push_back(base[t]);
            m_lasts.push_back((uint32_t) (len[t] ? len[t] - 1 : 0));
        }
        return at;
    }

    /// The tables' values, one after the other.
    const std::vector<float> &values() const { return m_values; }
    /// Per directory entry (a table of a program, `add_directory`): its
    /// start in `values()`, and its last index.
    const std::vector<uint32_t> &starts() const { return m_starts; }
    const std::vector<uint32_t> &lasts() const { return m_lasts; }

private:
    std::vector<float> m_values;
    std::vector<uint32_t> m_starts, m_lasts;
    std::unordered_multimap<uint64_t, std::pair<uint32_t, size_t>> m_index;
};

/// A TableStorage loaded for Dr.Jit: the tables' values in one array (device
/// memory on CUDA; never empty), and each directory entry as an array of
/// width 1 in memory. The programs read where a table starts and ends from
/// those, not as constants of their code, so that two materials whose
/// programs differ only in their tables' numbers and sizes trace to the same
/// code, which Dr.Jit compiles once for both (a symbolic call traces every
/// material alive, and passes such width-1 values to each material's code
/// as its data; docs/jit.md). Read so, they cost a scalar load each; read
/// from a directory array at a constant index, they were two vector gathers
/// per table read (the disc's llvm_ad_rgb render took 3.6x roughconductor's
/// time against 2.1x; docs/plugin_speed.md).
/// `Buffer`: the array type of the values (Mitsuba's DynamicBuffer<Float>).
template <typename Buffer> struct Tables {
    using FloatD = dr::detached_t<Buffer>;
    using UInt32D = dr::uint32_array_t<FloatD>;

    Buffer values;
    /// Per directory entry (table): its start in `values` and its last index.
    std::vector<UInt32D> start;
    std::vector<FloatD> last;

    static Tables load(const TableStorage &storage) {
        Tables out;
        const std::vector<float> &v = storage.values();
        out.values = v.empty() ? dr::zeros<Buffer>(1) : dr::load<Buffer>(v.data(), v.size());
        for (uint32_t start : storage.starts())
            out.start.push_back(dr::opaque<UInt32D>(start));
        for (uint32_t last : storage.lasts())
            out.last.push_back(dr::opaque<FloatD>((float) last));
        return out;
    }

    void traverse_1_cb_ro(void *p, void (*fn)(void *, uint64_t, const char *,
                                               const char *)) const {
        dr::traverse_1_fn_ro(values, p, fn);
        dr::traverse_1_fn_ro(start, p, fn);
        dr::traverse_1_fn_ro(last, p, fn);
    }
    void traverse_1_cb_rw(void *p, uint64_t (*fn)(void *, uint64_t, const char *,
                                                   const char *)) {
        dr::traverse_1_fn_rw(values, p, fn);
        dr::traverse_1_fn_rw(start, p, fn);
        dr::traverse_1_fn_rw(last, p, fn);
    }
};

/// A program ready to run with Dr.Jit arrays of type Float (an LLVM or CUDA
/// array; AD arrays differentiate through it). Its tables live in a buffer
/// the caller holds (several programs share one, so that a material has a
/// single device array to load and to traverse for dr.freeze).
/// The values of the parameters a program reads (`Op::Param`): `array`,
/// STAM_PARAMS values by STAM_PARAM_* id (width 0: the program's own
/// values); `per_point[id]`, where not empty, that parameter per lane.
/// `at_built`: every value is the one the programs were built with, none
/// per point or carrying a gradient (the caller's promise), so that the
/// programs for that case (STAM_PROGRAM_AT_BUILT) may run.
template <typename Float> struct ParamInputs {
    Float array;
    Float per_point[STAM_PARAMS];
    bool at_built = false;

    bool any_per_point() const {
        for (const Float &v : per_point)
            if (dr::width(v) != 0)
                return true;
        return false;
    }
};

template <typename Float> class Program {
public:
    using Mask = dr::mask_t<Float>;
    using UInt32 = dr::uint32_array_t<Float>;

    Program() = default;

    /// Decode `v` (throws Malformed); its tables go to `storage` (host
    /// values, loaded into the device buffer by the caller).
    Program(const std::vector<float> &v, TableStorage &storage) {
        Code code = decode_program(v.data(), v.size());
        for (size_t t = 0; t < code.table_offset.size(); ++t)
            code.table_base.push_back(
                storage.add(v.data() + code.table_offset[t], code.table_len[t]));
        code.dir_offset = storage.add_directory(code.table_base, code.table_len);
        m_code = std::make_shared<const Code>(std::move(code));
    }

    bool valid() const { return !c().code.empty() || !c().outputs.empty(); }
    size_t n_inputs() const { return c().n_inputs; }
    size_t n_outputs() const { return c().outputs.size(); }
    size_t n_instructions() const { return c().code.size(); }
    size_t n_gathers() const { return c().gathers; }
    /// The ids (STAM_PARAM_*) of the parameters the program reads, and the
    /// values it was built with.
    const std::vector<uint32_t> &param_ids() const { return c().param_id; }
    const std::vector<float> &param_values() const { return c().param_value; }

    /// The outputs for `inputs` (n_inputs arrays), one Dr.Jit operation per
    /// instruction; `tables` is the buffer the constructor's storage was
    /// loaded into. `params.array` (STAM_PARAMS values, indexed by
    /// STAM_PARAM_* id) gives the values of the parameters the program reads
    /// (read from memory: changing them changes no kernel; gradients flow
    /// back into them); width 0: the program's own values, as constants.
    /// `params.per_point[id]`, where not empty, gives that parameter's value
    /// per lane instead (a texture's).
    template <typename Storage>
    std::vector<Float> run(const std::vector<Float> &inputs, const Storage &tables,
                           const ParamInputs<Float> &params = {}) const {
        const Code &code = c();
        if (inputs.size() != code.n_inputs)
            throw std::runtime_error("program: " + std::to_string(inputs.size()) +
                                     " inputs given, it takes " +
                                     std::to_string(code.n_inputs));
        const size_t n = code.code.size();
        std::vector<Float> f(n);
        std::vector<Mask> m(n);
        if (n)
            run_range(m_code, 0, n, f, m, inputs, tables, params);
        std::vector<Float> out;
        out.reserve(code.outputs.size());
        for (uint32_t r : code.outputs)
            out.push_back(f[r]);
        return out;
    }

private:
    /// The live-ins or live-outs of a region, as the state of dr::if_stmt
    /// (traversed by Dr.Jit: its floats, then its masks).
    struct RegionState {
        std::vector<Float> f;
        std::vector<Mask> m;
        void traverse_1_cb_ro(void *p, void (*fn)(void *, uint64_t, const char *,
                                                   const char *)) const {
            for (const Float &x : f)
                dr::traverse_1_fn_ro(x, p, fn);
            for (const Mask &x : m)
                dr::traverse_1_fn_ro(x, p, fn);
        }
        void traverse_1_cb_rw(void *p, uint64_t (*fn)(void *, uint64_t, const char *,
                                                       const char *)) {
            for (Float &x : f)
                dr::traverse_1_fn_rw(x, p, fn);
            for (Mask &x : m)
                dr::traverse_1_fn_rw(x, p, fn);
        }
    };

    /// Instructions lo .. hi - 1 of `code` into the registers f and m; a
    /// region runs inside dr::if_stmt on its live-ins, returning its
    /// live-outs, 0 (false) on the lanes its mask excludes. Its body owns
    /// what it uses (the code, the tables, the parameters, a register file
    /// of its own): Dr.Jit may call it again after this returns (to
    /// differentiate it in reverse mode) and, in evaluated mode, hands it
    /// the live-ins of the mask's lanes only.
    template <typename Storage>
    static void run_range(const std::shared_ptr<const Code> &code_ptr, size_t lo, size_t hi,
                          std::vector<Float> &f, std::vector<Mask> &m,
                          const std::vector<Float> &inputs, const Storage &tables,
                          const ParamInputs<Float> &params) {
        const Code &code = *code_ptr;
        for (size_t i = lo; i < hi; ++i) {
            const Instr &in = code.code[i];
            if (in.op == Op::If) {
                const Region &reg = code.regions[in.b];
                RegionState live_in;
                // A differentiable live-in of width 1 (a parameter, or a
                // value of parameters alone) enters at the lanes' width:
                // with width-1 values carrying gradients through a symbolic
                // if_stmt, Dr.Jit 1.5's reverse mode came out about n times
                // too large over n lanes (a grating's period, height, width
                // and coherence length in the RGB programs; forward mode
                // was right; tests/test_gradients.py). The broadcast's
                // adjoint, outside the region, sums over the lanes once.
                size_t lanes = dr::width(m[in.a]);
                for (uint32_t r : reg.in_f)
                    lanes = std::max(lanes, dr::width(f[r]));
                for (uint32_t r : reg.in_f) {
                    if constexpr (dr::is_diff_v<Float>)
                        if (lanes > 1 && dr::width(f[r]) == 1 && dr::grad_enabled(f[r])) {
                            live_in.f.push_back(f[r] + dr::zeros<Float>(lanes));
                            continue;
                        }
                    live_in.f.push_back(f[r]);
                }
                for (uint32_t r : reg.in_m)
                    live_in.m.push_back(m[r]);
                auto body = [code_ptr, region = in.b, start = i, tables,
                             params](const RegionState &x) {
                    const Code &cd = *code_ptr;
                    const Region &rg = cd.regions[region];
                    std::vector<Float> rf(cd.code.size());
                    std::vector<Mask> rm(cd.code.size());
                    for (size_t k = 0; k < rg.in_f.size(); ++k)
                        rf[rg.in_f[k]] = x.f[k];
                    for (size_t k = 0; k < rg.in_m.size(); ++k)
                        rm[rg.in_m[k]] = x.m[k];
                    run_range(code_ptr, start + 1, rg.end, rf, rm, {}, tables, params);
                    RegionState out;
                    for (uint32_t r : rg.out_f)
                        out.f.push_back(rf[r]);
                    for (uint32_t r : rg.out_m)
                        out.m.push_back(rm[r]);
                    return out;
                };
                auto skipped = [n_f = reg.out_f.size(), n_m = reg.out_m.size()](
                                   const RegionState &) {
                    RegionState out;
                    out.f.assign(n_f, Float(0.f));
                    out.m.assign(n_m, Mask(false));
                    return out;
                };
                // By value: Dr.Jit keeps the functions (as it deduces
                // their types) for the reverse pass.
                RegionState res = dr::if_stmt(std::make_tuple(std::move(live_in)), m[in.a],
                                              std::move(body), std::move(skipped));
                for (size_t k = 0; k < reg.out_f.size(); ++k)
                    f[reg.out_f[k]] = res.f[k];
                for (size_t k = 0; k < reg.out_m.size(); ++k)
                    m[reg.out_m[k]] = res.m[k];
                i = reg.end;
                drop(code, i, f, m);
                continue;
            }
            const Float &fa = f[in.a], &fb = f[in.b], &fc = f[in.c];
            // sin, cos, exp and log: on CUDA, Dr.Jit's native f32 versions run
            // on the GPU's multi-function unit, whose error is absolute (sin:
            // ~5e-7 over [-pi, pi]), a relative error of 3e-4 in a grating's
            // sin^2 at the small phases of grazing directions (measured on an
            // H200, docs/jit.md); there the programs take Dr.Jit's polynomial
            // versions, the ones the LLVM backend runs.
            constexpr bool native = !dr::is_cuda_v<Float>;
            switch (in.op) {
                case Op::Input: f[i] = inputs[in.a]; break;
                case Op::Const: f[i] = Float(in.value); break;
                case Op::Add: f[i] = fa + fb; break;
                case Op::Sub: f[i] = fa - fb; break;
                case Op::Mul: f[i] = fa * fb; break;
                case Op::Div: f[i] = fa / fb; break;
                case Op::Min: f[i] = dr::minimum(fa, fb); break;
                case Op::Max: f[i] = dr::maximum(fa, fb); break;
                case Op::Fma: f[i] = dr::fmadd(fa, fb, fc); break;
                case Op::Neg: f[i] = -fa; break;
                case Op::Abs: f[i] = dr::abs(fa); break;
                case Op::Sqrt: f[i] = dr::sqrt(fa); break;
                case Op::Exp: f[i] = dr::exp<Float, native>(fa); break;
                case Op::Log: f[i] = dr::log<Float, native>(fa); break;
                case Op::Sin: f[i] = dr::sin<Float, native>(fa); break;
                case Op::Cos: f[i] = dr::cos<Float, native>(fa); break;
                case Op::Atan2: f[i] = dr::atan2(fa, fb); break;
                case Op::Floor: f[i] = dr::floor(fa); break;
                case Op::Lt: m[i] = fa < fb; break;
                case Op::Le: m[i] = fa <= fb; break;
                case Op::Gt: m[i] = fa > fb; break;
                case Op::Ge: m[i] = fa >= fb; break;
                case Op::Eq: m[i] = fa == fb; break;
                case Op::Finite: m[i] = dr::isfinite(fa); break;
                case Op::And: m[i] = m[in.a] && m[in.b]; break;
                case Op::Or: m[i] = m[in.a] || m[in.b]; break;
                case Op::Not: m[i] = !m[in.a]; break;
                case Op::Select: f[i] = dr::select(m[in.a], fb, fc); break;
                case Op::Gather: f[i] = gather(code, in.a, fb, tables); break;
                case Op::Param: {
                    uint32_t id = code.param_id[in.a];
                    if (dr::width(params.per_point[id]) != 0)
                        f[i] = params.per_point[id];
                    else if (dr::width(params.array) == STAM_PARAMS)
                        f[i] = dr::gather<Float>(params.array, UInt32(id));
                    else
                        f[i] = Float(code.param_value[in.a]);
                    break;
                }
                case Op::If: case Op::EndIf: break; // If: above; EndIf: a region's end
            }
            drop(code, i, f, m);
        }
    }

    /// Drops the registers whose last reader was instruction i (so that
    /// Dr.Jit holds only the live ones).
    static void drop(const Code &code, size_t i, std::vector<Float> &f, std::vector<Mask> &m) {
        for (uint32_t r : code.last_use[i]) {
            f[r] = Float();
            m[r] = Mask();
        }
    }

    /// Table t at the index x: NaN to 0, clamped into [0, len - 1],
    /// truncated (the core's Op::Gather), so that no lane reads outside it.
    /// Where the table starts and its last index come from memory
    /// (`Tables`), not from constants in the code.
    template <typename Storage>
    static Float gather(const Code &code, uint32_t t, const Float &x, const Storage &tables) {
        if (code.table_len[t] == 0)
            return Float(0.f);
        using FloatD = dr::detached_t<Float>;
        using UInt32D = dr::uint32_array_t<FloatD>;
        size_t entry = code.dir_offset + t;
        FloatD xd = dr::detach<false>(x);
        FloatD xi = dr::clip(dr::select(dr::isnan(xd), 0.f, xd), 0.f, tables.last[entry]);
        UInt32 idx = UInt32(UInt32D(xi) + tables.start[entry]);
        return dr::gather<Float>(tables.values, idx);
    }

    /// The decoded code (null for a default-constructed program), shared
    /// with the regions' bodies, which may outlive this object's call.
    const Code &c() const {
        static const Code empty;
        return m_code ? *m_code : empty;
    }

    std::shared_ptr<const Code> m_code;
};

} // namespace program
} // namespace diffraction_detail
} // namespace mitsuba
