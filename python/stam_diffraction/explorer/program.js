// program.js: a generic translator of the core's exported programs (the op
// list of stam.h's STAM_PROGRAM_FORMAT) into GLSL ES 3.00 functions, so that
// a WebGL2 fragment shader executes the same physics Dr.Jit executes in the
// plugin. No BRDF is written here: every operation comes from the array the
// core exported, and its meaning from stam.h (rust-core/src/program/
// interpret.rs is the reference executor):
//   - register i is instruction i's result; masks are 1 or 0, read as > 0;
//   - a region (If .. EndIf) runs only where its mask holds; every register
//     it defines reads 0 elsewhere (registers read after their region are
//     declared before it, as 0);
//   - Gather: table a at float index b, clamped into the table, NaN to 0,
//     truncated; the tables are packed into one R32F texture, where each
//     starts and how long it is a uniform (<name>_tab[a]: start, length),
//     so that materials whose programs differ only in their tables' values
//     and sizes share one compiled shader;
//   - Param: the parameter in slot a, a uniform named after the parameter
//     (p_<name>), so that the page moves it without building anything.
// The contract (op codes, the header's length and format, parameter names)
// comes from the server, read from stam.h by stam_diffraction.core.

'use strict';

// Width of the table texture (texels per row).
const TABLE_TEXTURE_WIDTH = 2048;

// The program of a little-endian float32 array, checked against the contract.
function decodeProgram(values, contract) {
  const v = values;
  if (v[0] !== contract.format) {
    throw new Error('program format ' + v[0] + ', this page reads ' + contract.format);
  }
  const nInputs = v[1], nOut = v[2], nCode = v[3], nTables = v[4], total = v[5], nParams = v[6];
  if (total !== v.length) {
    throw new Error('program length ' + v.length + ', its header says ' + total);
  }
  const h = contract.header_len;
  const outputs = Array.from(v.subarray(h, h + nOut));
  const dir = h + nOut;
  const tables = [];
  for (let t = 0; t < nTables; t++) {
    const at = v[dir + 2 * t], len = v[dir + 2 * t + 1];
    tables.push(v.subarray(at, at + len));
  }
  const parAt = dir + 2 * nTables;
  const params = [];
  for (let k = 0; k < nParams; k++) {
    params.push({name: contract.params[v[parAt + 2 * k]], value: v[parAt + 2 * k + 1]});
  }
  const codeAt = parAt + 2 * nParams;
  const code = [];
  for (let i = 0; i < nCode; i++) {
    const w = codeAt + 4 * i;
    code.push([v[w], v[w + 1], v[w + 2], v[w + 3]]);
  }
  return {nInputs, outputs, code, tables, params};
}

// A float32 value as an exact GLSL expression (its bits).
function glslConst(x) {
  const b = new DataView(new ArrayBuffer(4));
  b.setFloat32(0, x, true);
  const bits = b.getUint32(0, true);
  if (Number.isFinite(x) && Math.fround(x) === x && Number.isInteger(x) && Math.abs(x) < 1e6) {
    return x.toFixed(1);
  }
  return 'uintBitsToFloat(0x' + bits.toString(16).padStart(8, '0') + 'u)';
}

// GLSL source of a decoded program as `void name(in float x[N], out float
// y[M])`, reading its tables from `sampler` at the places the uniform
// `name_tab` gives. Returns {source, directory (start, length per table,
// from texel `tableBase`), tables (the packed values, a Float32Array),
// params (the names it reads)}.
function programGlsl(prog, name, sampler, tableBase, contract) {
  const op = contract.ops;
  const code = prog.code;
  const n = code.length;
  // Regions: the If that encloses each instruction (innermost), and where
  // each region ends (its EndIf, or the program's end).
  const region = new Int32Array(n).fill(-1);
  const depthOf = new Int32Array(n);
  const stack = [];
  for (let i = 0; i < n; i++) {
    const o = code[i][0];
    if (o === op.EndIf) {
      stack.pop();
    }
    region[i] = stack.length ? stack[stack.length - 1] : -1;
    depthOf[i] = stack.length;
    if (o === op.If) {
      stack.push(i);
    }
  }
  // A register read outside the region that defines it (or an output) is
  // declared at the top, as 0: "reads 0 on the lanes the region skips".
  const hoist = new Uint8Array(n);
  const inside = (r, i) => {
    // Is instruction i inside region r's body (r an If)?
    for (let q = region[i]; q >= 0; q = region[q]) {
      if (q === r) {
        return true;
      }
    }
    return false;
  };
  const operands = (ins) => {
    const o = ins[0];
    if (o === op.Input || o === op.Const || o === op.Param || o === op.EndIf) return [];
    if (o === op.If) return [ins[1]];
    if (o === op.Gather) return [ins[2]];
    if (o === op.Fma || o === op.Select) return [ins[1], ins[2], ins[3]];
    const unary = [op.Neg, op.Abs, op.Sqrt, op.Exp, op.Log, op.Sin, op.Cos, op.Floor, op.Finite,
                   op.Not];
    return unary.includes(o) ? [ins[1]] : [ins[1], ins[2]];
  };
  for (let i = 0; i < n; i++) {
    for (const r of operands(code[i])) {
      if (region[r] >= 0 && !inside(region[r], i)) {
        hoist[r] = 1;
      }
    }
  }
  for (const r of prog.outputs) {
    if (region[r] >= 0) hoist[r] = 1;
  }
  // Tables: packed one after another.
  const directory = new Int32Array(2 * Math.max(prog.tables.length, 1));
  let total = 0;
  prog.tables.forEach((t, k) => {
    directory[2 * k] = tableBase + total;
    directory[2 * k + 1] = t.length;
    total += t.length;
  });
  const packed = new Float32Array(total);
  let at = 0;
  for (const t of prog.tables) {
    packed.set(t, at);
    at += t.length;
  }
  const lines = [];
  const r = (k) => 'r' + k;
  const hoisted = [];
  for (let i = 0; i < n; i++) {
    if (hoist[i]) hoisted.push(r(i) + ' = 0.0');
  }
  lines.push('void ' + name + '(in float x[' + Math.max(prog.nInputs, 1) + '], out float y[' +
             prog.outputs.length + ']) {');
  for (let k = 0; k < hoisted.length; k += 16) {
    lines.push('  float ' + hoisted.slice(k, k + 16).join(', ') + ';');
  }
  const mask = (k) => '(' + r(k) + ' > 0.0)';
  const flag = (e) => '((' + e + ') ? 1.0 : 0.0)';
  const unaryFn = {[op.Sqrt]: 'sqrt', [op.Exp]: 'exp', [op.Log]: 'log', [op.Sin]: 'sin',
                   [op.Cos]: 'cos', [op.Floor]: 'floor', [op.Abs]: 'abs'};
  const binary = {[op.Add]: '+', [op.Sub]: '-', [op.Mul]: '*', [op.Div]: '/'};
  const compare = {[op.Lt]: '<', [op.Le]: '<=', [op.Gt]: '>', [op.Ge]: '>=', [op.Eq]: '=='};
  const params = new Set();
  for (let i = 0; i < n; i++) {
    const [o, a, b, c] = code[i];
    const pad = '  '.repeat(depthOf[i] + 1);
    let e;
    if (o === op.If) {
      lines.push(pad + 'if ' + mask(a) + ' {');
      continue;
    }
    if (o === op.EndIf) {
      lines.push('  '.repeat(depthOf[i]) + '}');
      continue;
    }
    if (o === op.Input) e = 'x[' + a + ']';
    else if (o === op.Const) e = glslConst(a);
    else if (o === op.Param) {
      const p = prog.params[a].name;
      params.add(p);
      e = 'p_' + p;
    } else if (o in binary) e = r(a) + ' ' + binary[o] + ' ' + r(b);
    else if (o === op.Min) e = 'min(' + r(a) + ', ' + r(b) + ')';
    else if (o === op.Max) e = 'max(' + r(a) + ', ' + r(b) + ')';
    else if (o === op.Fma) e = r(a) + ' * ' + r(b) + ' + ' + r(c);
    else if (o === op.Neg) e = '-' + r(a);
    else if (o in unaryFn) e = unaryFn[o] + '(' + r(a) + ')';
    else if (o === op.Atan2) e = 'stam_atan2(' + r(a) + ', ' + r(b) + ')';
    else if (o in compare) e = flag(r(a) + ' ' + compare[o] + ' ' + r(b));
    else if (o === op.Finite) e = flag('!isnan(' + r(a) + ') && !isinf(' + r(a) + ')');
    else if (o === op.And) e = flag(mask(a) + ' && ' + mask(b));
    else if (o === op.Or) e = flag(mask(a) + ' || ' + mask(b));
    else if (o === op.Not) e = flag('!' + mask(a));
    else if (o === op.Select) e = mask(a) + ' ? ' + r(b) + ' : ' + r(c);
    else if (o === op.Gather) {
      e = 'stam_gather(' + sampler + ', ' + name + '_tab[' + a + '], ' + r(b) + ')';
    } else {
      throw new Error('unknown operation code ' + o + ' at instruction ' + i);
    }
    lines.push(pad + (hoist[i] ? '' : 'float ') + r(i) + ' = ' + e + ';');
  }
  // Regions without an EndIf run to the program's end.
  for (let d = stack.length; d > 0; d--) {
    lines.push('  '.repeat(d) + '}');
  }
  prog.outputs.forEach((reg, k) => lines.push('  y[' + k + '] = ' + r(reg) + ';'));
  lines.push('}');
  const decl = 'uniform ivec2 ' + name + '_tab[' + Math.max(prog.tables.length, 1) + '];\n';
  return {source: decl + lines.join('\n'), directory, tables: packed, params: Array.from(params)};
}

// The helpers every translated program calls (the Gather and Atan2
// semantics of stam.h), once per shader.
const PROGRAM_PRELUDE = `
float stam_gather(highp sampler2D t, ivec2 table, float x) {
  int i = isnan(x) ? 0 : int(clamp(x, 0.0, float(table.y - 1)));
  int k = table.x + i;
  return texelFetch(t, ivec2(k % ${TABLE_TEXTURE_WIDTH}, k / ${TABLE_TEXTURE_WIDTH}), 0).r;
}
// The angle of (b, a) (atan2(a, b)); GLSL leaves atan(0, 0) undefined.
float stam_atan2(float a, float b) {
  if (a == 0.0 && b == 0.0) return (b < 0.0 || (1.0 / b) < 0.0) ? 3.14159265 : 0.0;
  return atan(a, b);
}
`;

// Several programs' GLSL over one table texture: {source (prelude, the
// parameters' uniforms, each function), directories ({glslName: the values
// of its _tab uniform}), tables (Float32Array, padded to whole rows),
// width, height, params (names)}. `named`: [[glslName, decodedProgram],
// ...].
function programsGlsl(named, sampler, contract) {
  const parts = [];
  const tableParts = [];
  const directories = {};
  const params = new Set();
  let base = 0;
  for (const [name, prog] of named) {
    const g = programGlsl(prog, name, sampler, base, contract);
    parts.push(g.source);
    tableParts.push(g.tables);
    directories[name] = g.directory;
    base += g.tables.length;
    g.params.forEach((p) => params.add(p));
  }
  const width = TABLE_TEXTURE_WIDTH;
  const height = Math.max(1, Math.ceil(base / width));
  const tables = new Float32Array(width * height);
  let at = 0;
  for (const t of tableParts) {
    tables.set(t, at);
    at += t.length;
  }
  const uniforms = Array.from(params).map((p) => 'uniform float p_' + p + ';').join('\n');
  return {source: PROGRAM_PRELUDE + uniforms + '\n' + parts.join('\n'), directories, tables,
          width, height, params: Array.from(params)};
}

if (typeof module !== 'undefined') {
  module.exports = {decodeProgram, programGlsl, programsGlsl, glslConst, TABLE_TEXTURE_WIDTH};
}
