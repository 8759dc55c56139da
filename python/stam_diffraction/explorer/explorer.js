// explorer.js: the explorer page (docs/explorer.md). Controls from the core's
// parameter reference; the material's programs from the server (the core's
// exports), translated by program.js into a WebGL2 fragment shader, which
// renders a sphere, a disc or a flat patch under a small light and two strip
// lights. What is written here is geometry (cameras, frames, lights), the
// page, and the tone map: the BRDF is the programs'.
//
// Query string (tests, links): material=<JSON of the core's params>,
// frame=<JSON {twist, tracks}>, view=sphere|disc|patch (views=a,b,c: a
// test renders each), mode=rgb|spectral,
// wavelengths=N, res=N, light=azimuth,elevation (degrees), strips=N (samples
// per strip, 0: off), test=<name> (render once to a float framebuffer, read
// it back and post it to /api/result under <name>), set=key:value,... (a
// test: move run-time parameters within the drift before reading back),
// frames=N (spectral: the mean of N frames, their wavelengths shifted),
// rebuild=<JSON params> (a test: after the first material, time a change
// to these from the request to the new picture).

'use strict';

const VIEWS = {
  // camera position, target, up, vertical field of view (degrees), the
  // shape, and the light's azimuth and elevation (degrees) a view starts
  // with: the highlight on the sphere, the orders around the disc's mirror
  // direction, the patch's lobe seen from above.
  sphere: {eye: [0, -3.4, 1.3], at: [0, 0, 0], up: [0, 0, 1], fov: 36, shape: 0, light: [-60, 35]},
  disc: {eye: [0, -2.5, 2.1], at: [0, 0, 0], up: [0, 0, 1], fov: 42, shape: 1, light: [80, 42]},
  patch: {eye: [0, 0, 3.6], at: [0, 0, 0], up: [0, 1, 0], fov: 34, shape: 2, light: [0, 62]},
};
const LIGHT = {distance: 3.0, intensity: 9.0};
const STRIPS = {z: 2.3, y: [1.2, 2.2], halfLength: 2.0, width: 0.18, radiance: 4.0};

const q = new URLSearchParams(location.search);
const state = {
  contract: null, reference: null, surface: 'cd', params: {}, frame: {tracks: 'concentric', twist: 0},
  mode: q.get('mode') || 'rgb', wavelengths: +(q.get('wavelengths') || 16),
  view: q.get('view') || 'disc', azimuth: null, elevation: null, exposure: 1.0,
  strips: q.has('strips') ? +q.get('strips') : 3, res: +(q.get('res') || 512),
  material: null, gl: null, shader: null, shaders: new Map(), built: {}, accumulated: 0,
  dirty: true,
  test: q.get('test'),
};
// The light: the query's, else the view's own.
function viewLight() {
  const light = q.has('light') ? q.get('light').split(',').map(Number)
    : (VIEWS[state.view] || VIEWS.disc).light;
  [state.azimuth, state.elevation] = light;
}
viewLight();

const $ = (id) => document.getElementById(id);

function setStatus(text, error) {
  const s = $('status');
  s.textContent = text;
  s.className = error ? 'error' : '';
}

async function getJson(url, body) {
  const r = await fetch(url, body === undefined ? {} : {
    method: 'POST', headers: {'Content-Type': 'application/json'}, body: JSON.stringify(body)});
  const data = await r.json();
  if (!r.ok) throw new Error(data.error || r.statusText);
  return data;
}

function floatsOf(b64) {
  const bin = atob(b64);
  const bytes = new Uint8Array(bin.length);
  for (let i = 0; i < bin.length; i++) bytes[i] = bin.charCodeAt(i);
  return new Float32Array(bytes.buffer);
}

// ---------------------------------------------------------------- controls

function surfaceKeys(surface) {
  const s = state.reference.core.surfaces.find((x) => x.surface === surface);
  const own = s ? s.keys : [];
  const material = state.reference.core.material.filter(
    (k) => !['surface', 'gradients', 'fresnel.eta', 'fresnel.k'].includes(k.key));
  return own.concat(material);
}

function choices(doc) {
  const found = [...(doc.accepted || '').matchAll(/"([^"]+)"/g)].map((m) => m[1]);
  return [...new Set(found)];
}

const METALS = ['aluminium', 'silver', 'gold', 'copper', 'chromium'];

function controlRow(doc, value, onChange) {
  const row = document.createElement('div');
  row.className = 'row' + (value === undefined ? ' unset' : '');
  const label = document.createElement('label');
  label.textContent = doc.key;
  label.title = doc.meaning + (doc.note ? ' (' + doc.note + ')' : '') + '; accepted ' +
                (doc.accepted || '') + (doc.default !== null && doc.default !== undefined
                  ? '; default ' + JSON.stringify(doc.default) : '');
  row.appendChild(label);
  let input;
  const opts = doc.key === 'fresnel' ? METALS.concat(['constant', 'eta, k']) : choices(doc);
  if (doc.key === 'fresnel') {
    input = document.createElement('span');
    const sel = document.createElement('select');
    opts.forEach((o) => sel.add(new Option(o, o)));
    const a = document.createElement('input');
    a.type = 'number';
    a.step = 'any';
    const b = a.cloneNode();
    const kind = typeof value === 'number' ? 'constant' : (value && typeof value === 'object')
      ? 'eta, k' : (value || 'aluminium');
    sel.value = METALS.includes(kind) || kind === 'constant' || kind === 'eta, k' ? kind : 'aluminium';
    if (typeof value === 'number') a.value = value;
    if (value && typeof value === 'object') { a.value = value.eta; b.value = value.k || 0; }
    const sync = () => {
      a.style.display = sel.value === 'constant' || sel.value === 'eta, k' ? '' : 'none';
      b.style.display = sel.value === 'eta, k' ? '' : 'none';
      a.style.width = b.style.width = '48%';
      a.title = sel.value === 'constant' ? 'F^2 in (0, 1]' : 'eta';
      b.title = 'k';
    };
    sync();
    const emit = () => {
      sync();
      if (sel.value === 'constant') onChange(a.value === '' ? undefined : +a.value);
      else if (sel.value === 'eta, k') {
        onChange(a.value === '' ? undefined : {eta: +a.value, k: +(b.value || 0)});
      } else onChange(sel.value);
    };
    sel.onchange = a.onchange = b.onchange = emit;
    input.append(sel, a, b);
  } else if (opts.length && doc.key !== 'profile' || (doc.key === 'profile')) {
    input = document.createElement('select');
    input.add(new Option(doc.default !== null && doc.default !== undefined
      ? '(default ' + doc.default + ')' : '(unset)', ''));
    (doc.key === 'profile' ? ['rect', 'sine'] : opts).forEach((o) => input.add(new Option(o, o)));
    input.value = value === undefined ? '' : value;
    input.onchange = () => onChange(input.value === '' ? undefined : input.value);
  } else if (doc.key === 'file') {
    // A path the server opens (relative to its folder); the maps it found
    // under scenes/heightmaps are offered.
    input = document.createElement('input');
    input.type = 'text';
    input.value = value || '';
    const list = document.createElement('datalist');
    list.id = 'height-maps';
    (state.reference.height_maps || []).forEach((f) => list.appendChild(new Option(f, f)));
    input.setAttribute('list', list.id);
    row.appendChild(list);
    input.onchange = () => onChange(input.value || undefined);
  } else {
    input = document.createElement('input');
    input.type = 'number';
    input.step = doc.integer ? '1' : 'any';
    if (doc.min !== null && doc.min !== undefined) input.min = doc.min;
    if (doc.max !== null && doc.max !== undefined) input.max = doc.max;
    input.placeholder = doc.default !== null && doc.default !== undefined ? String(doc.default) : '';
    input.value = value === undefined ? '' : value;
    const typed = (live) => {
      // A number the browser cannot read ("nan", "1e"): said beside it
      if (input.validity.badInput) {
        row.querySelector('.err').textContent = 'not a number: the material keeps ' +
          (value === undefined ? 'its default' : value);
        return;
      }
      row.querySelector('.err').textContent = '';
      onChange(input.value === '' ? undefined : +input.value, live);
    };
    input.oninput = () => typed(true);
    input.onchange = () => typed(false);
    // Dragging: the wheel scales the value by 2% a notch (a program's drift).
    input.onwheel = (e) => {
      if (input.value === '') return;
      e.preventDefault();
      const f = e.deltaY < 0 ? 1.02 : 1 / 1.02;
      let v = +input.value * f;
      if (doc.integer) v = Math.round(v + (f > 1 ? 1 : -1));
      if (input.max !== '') v = Math.min(v, +input.max);
      if (input.min !== '') v = Math.max(v, +input.min);
      input.value = +v.toPrecision(5);
      onChange(+input.value, true);
    };
  }
  row.appendChild(input);
  const unit = document.createElement('span');
  unit.className = 'unit';
  unit.textContent = doc.unit || '';
  row.appendChild(unit);
  // The core's message about this key, beside it
  const err = document.createElement('div');
  err.className = 'err';
  row.appendChild(err);
  row.dataset.key = doc.key;
  return row;
}

// Shows `message` beside the control of the key it names (the core's
// messages name the key: "parameter 'sigma_um' ..."), else in the status
// line; the picture of the last good material stays.
function showError(message) {
  for (const e of document.querySelectorAll('.row .err')) e.textContent = '';
  const keys = [...message.matchAll(/'([A-Za-z_.]+)'/g)].map((m) => m[1]);
  for (const key of keys) {
    const row = document.querySelector('.row[data-key="' + key.split('.')[0] + '"]');
    if (row) {
      row.querySelector('.err').textContent = message;
      state.errorBeside = row.dataset.key;
      setStatus('not built: ' + key + ' (see beside it); the picture is the last good material\'s',
                true);
      return;
    }
  }
  setStatus(message, true);
}

function buildControls() {
  const sel = $('surface');
  if (!sel.options.length) {
    state.reference.core.surfaces.forEach((s) => sel.add(new Option(s.surface, s.surface)));
    sel.onchange = () => {
      state.surface = sel.value;
      state.params = Object.assign({}, state.reference.presets[sel.value]);
      state.frame = Object.assign({tracks: 'linear', twist: 0},
                                  state.reference.preset_frames[sel.value] || {});
      buildControls();
      requestBuild(0);
    };
  }
  sel.value = state.surface;
  const box = $('params');
  box.innerHTML = '';
  for (const doc of surfaceKeys(state.surface)) {
    box.appendChild(controlRow(doc, state.params[doc.key], (v, live) => {
      if (v === undefined) delete state.params[doc.key];
      else state.params[doc.key] = v;
      paramChanged(doc.key, live);
    }));
  }
  const frame = $('frame');
  frame.innerHTML = '';
  for (const doc of state.reference.frame) {
    const d = Object.assign({}, doc, {
      accepted: doc.accepted ? doc.accepted.map((x) => '"' + x + '"').join(', ') : ''});
    frame.appendChild(controlRow(d, state.frame[doc.key], (v) => {
      state.frame[doc.key] = v === undefined ? doc.default : v;
      showMaterialText();
      state.dirty = true;
    }));
  }
  const render = $('render');
  render.innerHTML = '';
  const knob = (key, doc, apply) => render.appendChild(controlRow(
    Object.assign({key, meaning: key, accepted: '', default: null}, doc), state[key],
    (v) => { state[key] = v === undefined ? state[key] : v; apply(); state.dirty = true; }));
  knob('view', {accepted: '"sphere", "disc", "patch"', meaning: 'what the material covers'}, () => {
    viewLight();
    buildControls();
  });
  knob('mode', {accepted: '"rgb", "spectral"', meaning: 'the core\'s RGB programs, or its spectral ' +
       'programs at N wavelengths weighted by the CIE 1931 observer under D65'}, () => requestBuild(0));
  knob('wavelengths', {integer: true, min: 1, max: 64, meaning: 'spectral mode: wavelengths per pixel'},
       () => { if (state.mode === 'spectral') requestBuild(300); });
  knob('azimuth', {unit: 'deg', min: -180, max: 180, meaning: 'light azimuth (drag on the picture)'}, () => {});
  knob('elevation', {unit: 'deg', min: 1, max: 90, meaning: 'light elevation'}, () => {});
  // (the strips are passes, not code: a new count redraws, compiles nothing)
  knob('strips', {integer: true, min: 0, max: 16, meaning: 'samples per strip light (0: off)'}, () => {});
  knob('exposure', {min: 0.001, max: 1000, meaning: 'linear scale before the sRGB curve'}, () => {});
  knob('res', {integer: true, min: 64, max: 2048, meaning: 'canvas size in pixels'}, () => resize());
}

// Parameters the programs read at run time move their uniform at once;
// beyond the programs' drift (or any other parameter) the core rebuilds.
function paramChanged(key, live) {
  const built = state.built[key];
  const v = state.params[key];
  if (built !== undefined && state.uniforms && typeof v === 'number' && built.value !== 0) {
    state.uniforms[key] = v;
    state.dirty = true;
    if (Math.abs(v / built.value - 1) <= state.contract.max_drift) {
      showMaterialText();
      return;
    }
  }
  requestBuild(live ? 400 : 0);
}

let buildTimer = null;
let buildSerial = 0;
function requestBuild(delay) {
  clearTimeout(buildTimer);
  buildTimer = setTimeout(build, delay);
}

function showMaterialText() {
  if (!state.material) return;
  // The server's forms of the built material; the frame and drifted
  // parameters as they stand now.
  const dict = Object.assign({}, state.material.dict);
  for (const [k, v] of Object.entries(state.params)) {
    if (typeof v === 'number') dict[k] = v;
  }
  if (state.frame.twist) dict.twist = +state.frame.twist; else delete dict.twist;
  if (state.frame.tracks && state.frame.tracks !== 'linear') dict.tracks = state.frame.tracks;
  else delete dict.tracks;
  $('dict').textContent = JSON.stringify(dict, null, 1).replace(/\n\s*/g, ' ');
  const lines = ['<bsdf type="diffraction">'];
  for (const [k, v] of Object.entries(dict)) {
    if (k === 'type') continue;
    const doc = surfaceKeys(state.surface).find((d) => d.key === k);
    const kind = typeof v === 'string' ? 'string' : typeof v === 'boolean' ? 'boolean'
      : doc && doc.integer ? 'integer' : 'float';
    lines.push('    <' + kind + ' name="' + k + '" value="' + v + '"/>');
  }
  lines.push('</bsdf>');
  $('xml').textContent = lines.join('\n');
}

// ---------------------------------------------------------------- material

async function build() {
  const serial = ++buildSerial;
  const started = performance.now();
  const tick = setInterval(() => setStatus('building the material\'s tables and programs in the core... ' +
    ((performance.now() - started) / 1000).toFixed(1) + ' s'), 250);
  try {
    state.timing = {requested: performance.now()};
    const m = await getJson('/api/material', {params: state.params, mode: state.mode,
                                              wavelengths: state.wavelengths, frame: state.frame});
    if (serial !== buildSerial) return;
    for (const e of document.querySelectorAll('.row .err')) e.textContent = '';
    state.material = m;
    $('warnings').textContent = (m.warnings || []).join(' ');
    showMaterialText();
    compile();
  } catch (e) {
    if (serial === buildSerial) showError(String(e.message || e));
    // (a test reads where the message stands and which material stays)
    if (state.test) {
      postResult({error: String(e.message || e), beside: state.errorBeside || null,
                  kept: state.material ? state.material.resolved : null,
                  canvas_kept: !!state.shader});
    }
  } finally {
    clearInterval(tick);
  }
}

const VERTEX = `#version 300 es
in vec2 p; void main() { gl_Position = vec4(p, 0.0, 1.0); }`;

// One pass of the picture: the light a pass adds (the small light, or one
// sample of a strip light) or the mirror lobe's view of the strips, at one
// wavelength in spectral mode. The shader calls each program at one place:
// SwiftShader took 100 s to compile a Gaussian's eval called in a loop, and
// 0.4 s called once. Passes add up in a float framebuffer.
function fragmentSource(glsl, spectral, hasCoherent) {
  const evalCall = spectral ? `
vec3 brdf(vec3 wi, vec3 wo) {
  float x[7] = float[7](wi.x, wi.y, wi.z, wo.x, wo.y, wo.z, u_lambda);
  float y[1];
  stam_eval(x, y);
  return y[0] * u_weight;
}
vec3 mirror_lobe(vec3 wi) {
  float x[4] = float[4](wi.x, wi.y, wi.z, u_lambda);
  float y[2];
  ${hasCoherent ? 'stam_coherent(x, y);' : 'y[0] = 0.0;'}
  return y[0] * u_weight;
}` : `
vec3 brdf(vec3 wi, vec3 wo) {
  float x[6] = float[6](wi.x, wi.y, wi.z, wo.x, wo.y, wo.z);
  float y[3];
  stam_eval(x, y);
  return vec3(y[0], y[1], y[2]);
}
vec3 mirror_lobe(vec3 wi) {
  float x[3] = float[3](wi.x, wi.y, wi.z);
  float y[4];
  ${hasCoherent ? 'stam_coherent(x, y);' : 'y[0] = y[1] = y[2] = 0.0;'}
  return vec3(y[0], y[1], y[2]);
}`;
  return `#version 300 es
precision highp float;
precision highp int;
precision highp sampler2D;
uniform highp sampler2D u_tables;
uniform vec2 u_res;
uniform int u_shape;
uniform vec3 u_eye, u_right, u_up, u_fwd;
// The pass: u_kind 0 a light at u_light (intensity u_light_I; u_light_n
// its emitting normal, 0 for the small light), 1 the mirror lobe.
uniform int u_kind, u_first;
uniform vec3 u_light, u_light_n;
uniform float u_light_I, u_twist;
uniform int u_concentric, u_output;
uniform float u_lambda;
uniform vec3 u_weight;
out vec4 color;
${glsl}
${evalCall}
const float STRIP_Z = ${STRIPS.z.toFixed(3)}, STRIP_HALF = ${STRIPS.halfLength.toFixed(3)},
            STRIP_W = ${STRIPS.width.toFixed(3)}, STRIP_L = ${STRIPS.radiance.toFixed(3)};
const float STRIP_Y0 = ${STRIPS.y[0].toFixed(3)}, STRIP_Y1 = ${STRIPS.y[1].toFixed(3)};
// The shape the pixel sees: its point, normal and tangent (the core's x
// before the twist: concentric tracks radial, linear ones along u).
bool hit(vec3 o, vec3 d, out vec3 p, out vec3 n, out vec3 s) {
  if (u_shape == 0) {
    float b = dot(o, d), c = dot(o, o) - 1.0, h = b * b - c;
    if (h < 0.0) return false;
    float t = -b - sqrt(h);
    if (t <= 0.0) return false;
    p = o + t * d;
    n = normalize(p);
    vec2 e = vec2(-p.y, p.x);
    s = dot(e, e) > 1e-12 ? normalize(vec3(e, 0.0)) : vec3(1.0, 0.0, 0.0);
    return true;
  }
  if (abs(d.z) < 1e-9) return false;
  float t = -o.z / d.z;
  if (t <= 0.0) return false;
  p = o + t * d;
  float r = length(p.xy);
  if (u_shape == 1 && (r > 1.2 || r < 0.2)) return false;
  if (u_shape == 2 && (abs(p.x) > 1.0 || abs(p.y) > 1.0)) return false;
  n = vec3(0.0, 0.0, 1.0);
  s = (u_concentric == 1 && r > 1e-6) ? vec3(p.xy / r, 0.0) : vec3(1.0, 0.0, 0.0);
  return true;
}
void main() {
  vec2 ndc = gl_FragCoord.xy / u_res * 2.0 - 1.0;
  vec3 d = normalize(u_fwd + ndc.x * u_right + ndc.y * u_up);
  vec3 p, n, s0;
  vec3 L = vec3(0.0);
  vec3 wi = vec3(0.0), wo = vec3(0.0);
  float factor = 0.0;
  if (hit(u_eye, d, p, n, s0)) {
    vec3 s = s0 * cos(u_twist) + cross(n, s0) * sin(u_twist);
    mat3 toLocal = transpose(mat3(s, cross(n, s), n));
    vec3 v = normalize(u_eye - p);
    wi = toLocal * v;
    vec3 e = u_light - p;
    float e2 = dot(e, e);
    vec3 el = e / sqrt(e2);
    wo = toLocal * el;
    float I = u_light_I * (dot(u_light_n, u_light_n) > 0.0 ? max(0.0, -dot(u_light_n, el)) : 1.0);
    if (wi.z > 0.0 && wo.z > 0.0) factor = I * wo.z / e2;
    if (u_kind == 0) {
      if (factor > 0.0) L = brdf(wi, wo) * factor;
    } else {
      vec3 r = reflect(-v, n);
      if (wi.z > 0.0 && r.z > 0.0) {
        vec3 h = p + (STRIP_Z - p.z) / r.z * r;
        if (abs(h.x) < STRIP_HALF && (abs(h.y - STRIP_Y0) < 0.5 * STRIP_W ||
                                      abs(h.y - STRIP_Y1) < 0.5 * STRIP_W)) {
          L = mirror_lobe(wi) * STRIP_L;
        }
      }
    }
  } else if (u_first == 1) {
    L = vec3(0.02, 0.021, 0.025) * (1.0 + 0.5 * ndc.y);
  }
  if (u_output == 1) color = vec4(wi, 1.0);
  else if (u_output == 2) color = vec4(wo, 1.0);
  else if (u_output == 3) color = vec4(factor, 0.0, 0.0, 1.0);
  else color = vec4(L, 1.0);
}`;
}

// The tone map: the accumulated radiance, scaled, through the sRGB curve.
const DISPLAY = `#version 300 es
precision highp float;
uniform highp sampler2D u_sum;
uniform float u_exposure;
out vec4 color;
float srgb(float x) { x = clamp(x, 0.0, 1.0);
  return x <= 0.0031308 ? 12.92 * x : 1.055 * pow(x, 1.0 / 2.4) - 0.055; }
void main() {
  vec3 c = texelFetch(u_sum, ivec2(gl_FragCoord.xy), 0).rgb * u_exposure;
  color = vec4(srgb(c.r), srgb(c.g), srgb(c.b), 1.0);
}`;

function glProgram(gl, fragment) {
  const sh = (type, text) => {
    const x = gl.createShader(type);
    gl.shaderSource(x, text);
    gl.compileShader(x);
    return x;
  };
  const fs = sh(gl.FRAGMENT_SHADER, fragment);
  const prog = gl.createProgram();
  gl.attachShader(prog, sh(gl.VERTEX_SHADER, VERTEX));
  gl.attachShader(prog, fs);
  gl.bindAttribLocation(prog, 0, 'p');
  gl.linkProgram(prog);
  if (!gl.getProgramParameter(prog, gl.LINK_STATUS)) {
    throw new Error('shader: ' + (gl.getShaderInfoLog(fs) || gl.getProgramInfoLog(prog)).slice(0, 600));
  }
  return prog;
}

function compile() {
  const m = state.material;
  if (!m) return;
  const gl = state.gl;
  const started = performance.now();
  if (state.timing) state.timing.received = started;
  const named = [];
  const progs = {};
  for (const [name, b64] of Object.entries(m.programs)) {
    if (b64) {
      progs[name] = decodeProgram(floatsOf(b64), state.contract);
      named.push(['stam_' + name, progs[name]]);
    }
  }
  if (!progs.eval) {
    setStatus('this material has no ' + m.mode + ' eval program', true);
    return;
  }
  if (state.timing) state.timing.decoded = performance.now();
  const g = programsGlsl(named, 'u_tables', state.contract);
  if (state.timing) state.timing.translated = performance.now();
  const spectral = m.mode === 'spectral';
  const src = fragmentSource(g.source, spectral, !!progs.coherent);
  state.source = src;
  // Shaders by source: a material whose programs differ from one seen
  // before only in numbers (their tables, their parameters) reuses its
  // compiled shader, as Dr.Jit reuses its kernels.
  let cached = state.shaders.get(src);
  const reused = !!cached;
  if (!cached) {
    try {
      cached = {prog: glProgram(gl, src), locs: {}};
    } catch (e) {
      setStatus(e.message, true);
      if (state.test) postResult({error: e.message});
      return;
    }
    state.shaders.set(src, cached);
    if (state.shaders.size > SHADER_CACHE) {
      const [oldest, old] = state.shaders.entries().next().value;
      if (!state.shader || old.prog !== state.shader.prog) {
        gl.deleteProgram(old.prog);
        state.shaders.delete(oldest);
      }
    }
  }

  const prog = cached.prog, locs = cached.locs;
  // The tables, one R32F texture.
  // (one texture object for every material: its storage respecified)
  const tex = floatTexture(gl, 0, gl.R32F, gl.RED, g.width, g.height, g.tables, state.tableTex);
  state.tableTex = tex;
  if (state.timing) state.timing.uploaded = performance.now();
  const loc = (name) => (name in locs ? locs[name] : (locs[name] = gl.getUniformLocation(prog, name)));
  state.shader = {prog, tex, loc, params: g.params, spectral, reused, directories: g.directories,
                  ops: named.reduce((a, [, p]) => a + p.code.length, 0),
                  tableBytes: 4 * g.tables.length};
  // What the programs were built with; a drifted parameter's uniform.
  state.built = {};
  state.uniforms = {};
  for (const [, p] of named) {
    for (const par of p.params) state.built[par.name] = par;
  }
  for (const k of g.params) {
    state.uniforms[k] = typeof state.params[k] === 'number' ? state.params[k] : state.built[k].value;
  }
  // A first draw of one pixel, in the passes' state, compiles the shader
  // for the GPU (SwiftShader: here); the frame clears it.
  ensureTarget();
  gl.bindFramebuffer(gl.FRAMEBUFFER, state.target.fb);
  gl.enable(gl.BLEND);
  gl.enable(gl.SCISSOR_TEST);
  gl.scissor(0, 0, 1, 1);
  drawPass(passes(0)[0], 1);
  gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.FLOAT, new Float32Array(4));
  gl.disable(gl.SCISSOR_TEST);
  gl.disable(gl.BLEND);
  gl.bindFramebuffer(gl.FRAMEBUFFER, null);
  state.compileMs = performance.now() - started;
  state.dirty = true;
  setStatus(statusLine());
  if (state.test && q.has('rebuild') && !state.rebuildStarted) {
    // rebuild=<JSON params>: a change that needs the core, timed from the
    // request to the new picture on the canvas (build, shader, one picture)
    state.rebuildStarted = performance.now();
    state.params = JSON.parse(q.get('rebuild'));
    build();
    return;
  }
  if (state.test && state.rebuildStarted && state.rebuildMs === undefined) {
    state.accumulated = 0;
    state.passList = passes(0);
    state.next = 0;
    state.timing.ready = performance.now();
    renderSome(true);
    display();
    gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, new Uint8Array(4));
    state.rebuildMs = performance.now() - state.rebuildStarted;
    state.timing.shown = performance.now();
  }
  if (state.test) {
    // set=key:value,...: move parameters as a control would before reading
    // back (a test of the run-time path: within the drift, a uniform).
    const moved = {};
    for (const kv of (q.get('set') || '').split(',').filter(Boolean)) {
      const [k, v] = kv.split(':');
      const built = state.built[k];
      if (!built || Math.abs(+v / built.value - 1) > state.contract.max_drift) {
        postResult({error: 'set: ' + k + ' is not a run-time parameter within the drift'});
        return;
      }
      state.params[k] = +v;
      state.uniforms[k] = +v;
      moved[k] = +v;
    }
    state.moved = moved;
    runTest();
  }
}

function statusLine() {
  const s = state.shader;
  return state.material.mode + ' programs: ' + s.ops + ' operations, ' +
    (s.tableBytes / 1e6).toFixed(1) + ' MB of tables; core build ' +
    state.material.build_s.toFixed(2) + ' s, shader ' + (state.compileMs / 1000).toFixed(1) + ' s' +
    (s.reused ? ' (compiled before)' : '') +
    (state.frameMs ? '; ' + (1000 / state.frameMs).toFixed(1) + ' frames/s (' +
     state.passCount + ' passes; ' + (state.renderer || 'this browser\'s WebGL') + ')' : '');
}

// ---------------------------------------------------------------- drawing

function sub(a, b) { return [a[0] - b[0], a[1] - b[1], a[2] - b[2]]; }
function cross(a, b) { return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]; }
function norm(a) { const l = Math.hypot(...a); return a.map((x) => x / l); }

function camera(view, aspect) {
  const fwd = norm(sub(view.at, view.eye));
  const right = norm(cross(fwd, view.up));
  const up = cross(right, fwd);
  const h = Math.tan(view.fov * Math.PI / 360);
  return {eye: view.eye, fwd, right: right.map((x) => x * h * aspect), up: up.map((x) => x * h)};
}

function lightPosition() {
  const a = state.azimuth * Math.PI / 180, e = state.elevation * Math.PI / 180;
  return [LIGHT.distance * Math.cos(e) * Math.cos(a), LIGHT.distance * Math.cos(e) * Math.sin(a),
          LIGHT.distance * Math.sin(e)];
}

// The passes of one picture: per wavelength (spectral) the small light, the
// strip lights' samples along their centre lines and the mirror lobe.
// Spectral mode: frame 0 takes the server's wavelengths (the midpoints of
// N equal bins) and weights; each later frame shifts them within their bins
// (a golden-ratio sequence) with weights from the server's 1 nm table of the
// weights' density (each frame normalised to white), and the frames average: the picture converges to the
// integral over wavelength, so that orders narrower than a bin fill in.
function wavelengths(frame) {
  const m = state.material;
  if (frame === 0) return m.wavelengths_nm.map((l, j) => ({lambda: l, weight: m.rgb_weights[j]}));
  const [lo, hi] = m.band_nm, n = m.wavelengths_nm.length, step = (hi - lo) / n;
  const shift = (0.5 + frame * 0.6180339887) % 1;
  const d = m.rgb_density, d0 = m.density_from_nm;
  const waves = Array.from({length: n}, (_, j) => {
    const lambda = lo + (j + shift) * step;
    const x = Math.min(Math.max(lambda - d0, 0), d.length - 1.000001);
    const i = Math.floor(x), t = x - i;
    return {lambda, weight: [0, 1, 2].map((c) => d[i][c] + (d[i + 1][c] - d[i][c]) * t)};
  });
  // Each frame white-balanced, as the server's midpoints are (a reflectance
  // of 1 gives (1, 1, 1)): a frame's few samples of the observer would
  // otherwise tint it by 10-15% at 8 wavelengths.
  for (let c = 0; c < 3; c++) {
    const sum = waves.reduce((a, w) => a + w.weight[c], 0);
    waves.forEach((w) => { w.weight[c] /= sum; });
  }
  return waves;
}

function passes(frame) {
  const m = state.material;
  const waves = m.mode === 'spectral' ? wavelengths(frame || 0) : [{lambda: 0, weight: [1, 1, 1]}];
  const out = [];
  const K = state.strips;
  for (const w of waves) {
    out.push(Object.assign({kind: 0, light: lightPosition(), I: LIGHT.intensity, n: [0, 0, 0]}, w));
    for (const y of STRIPS.y) {
      for (let k = 0; k < K; k++) {
        const x = STRIPS.halfLength * (2 * (k + 0.5) / K - 1);
        out.push(Object.assign({kind: 0, light: [x, y, STRIPS.z], n: [0, 0, -1],
                                I: STRIPS.radiance * STRIPS.width * 2 * STRIPS.halfLength / K}, w));
      }
    }
    if (K > 0) out.push(Object.assign({kind: 1, light: lightPosition(), I: 0, n: [0, 0, 0]}, w));
  }
  return out;
}

function drawPass(pass, first, output) {
  const gl = state.gl, s = state.shader;
  gl.useProgram(s.prog);
  const w = state.res, h = state.res;
  gl.viewport(0, 0, w, h);
  const view = VIEWS[state.view] || VIEWS.disc;
  const cam = camera(view, w / h);
  gl.uniform2f(s.loc('u_res'), w, h);
  gl.uniform1i(s.loc('u_shape'), view.shape);
  gl.uniform3fv(s.loc('u_eye'), cam.eye);
  gl.uniform3fv(s.loc('u_fwd'), cam.fwd);
  gl.uniform3fv(s.loc('u_right'), cam.right);
  gl.uniform3fv(s.loc('u_up'), cam.up);
  gl.uniform1i(s.loc('u_kind'), pass.kind);
  gl.uniform1i(s.loc('u_first'), first ? 1 : 0);
  gl.uniform3fv(s.loc('u_light'), pass.light);
  gl.uniform3fv(s.loc('u_light_n'), pass.n);
  gl.uniform1f(s.loc('u_light_I'), pass.I);
  gl.uniform1f(s.loc('u_lambda'), pass.lambda);
  gl.uniform3fv(s.loc('u_weight'), pass.weight);
  gl.uniform1f(s.loc('u_twist'), (+state.frame.twist || 0) * Math.PI / 180);
  gl.uniform1i(s.loc('u_concentric'), state.frame.tracks === 'concentric' ? 1 : 0);
  gl.uniform1i(s.loc('u_output'), output || 0);
  gl.uniform1i(s.loc('u_tables'), 0);
  for (const k of s.params) gl.uniform1f(s.loc('p_' + k), state.uniforms[k]);
  for (const [name, dir] of Object.entries(s.directories)) gl.uniform2iv(s.loc(name + '_tab'), dir);
  gl.activeTexture(gl.TEXTURE0);
  gl.bindTexture(gl.TEXTURE_2D, s.tex);
  gl.drawArrays(gl.TRIANGLES, 0, 3);
}

// A float texture on texture unit `unit`, read texel by texel.
function floatTexture(gl, unit, internal, format, width, height, data, reuse) {
  const tex = reuse || gl.createTexture();
  gl.activeTexture(gl.TEXTURE0 + unit);
  gl.bindTexture(gl.TEXTURE_2D, tex);
  gl.texImage2D(gl.TEXTURE_2D, 0, internal, width, height, 0, format, gl.FLOAT, data);
  gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
  gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.NEAREST);
  return tex;
}

// The float framebuffer the passes add into.
function ensureTarget() {
  const gl = state.gl, n = state.res;
  if (state.target && state.target.n === n) return;
  if (state.target) {
    gl.deleteFramebuffer(state.target.fb);
    gl.deleteTexture(state.target.tex);
  }
  const tex = floatTexture(gl, 1, gl.RGBA32F, gl.RGBA, n, n, null);
  const fb = gl.createFramebuffer();
  gl.bindFramebuffer(gl.FRAMEBUFFER, fb);
  gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.TEXTURE_2D, tex, 0);
  const ok = gl.checkFramebufferStatus(gl.FRAMEBUFFER) === gl.FRAMEBUFFER_COMPLETE;
  gl.bindFramebuffer(gl.FRAMEBUFFER, null);
  if (!ok) throw new Error('this browser cannot render into float textures');
  state.target = {fb, tex, n};
}

// Rows of pixels a draw covers: a pass is drawn in bands, so that software
// WebGL (seconds per pass at 512 px) never holds the page for long.
const BAND_ROWS = 64;
// Compiled shaders kept (by source).
const SHADER_CACHE = 8;
// Spectral frames averaged (each with its wavelengths shifted in their bins).
const SPECTRAL_FRAMES = 32;

// Adds the next bands of passes into the framebuffer: as many as fit in
// about 30 ms (all: every one), then returns.
function renderSome(all) {
  const gl = state.gl;
  ensureTarget();
  gl.bindFramebuffer(gl.FRAMEBUFFER, state.target.fb);
  const bands = Math.ceil(state.res / BAND_ROWS);
  if (state.next === 0) {
    if (!state.accumulated) {
      gl.clearColor(0, 0, 0, 0);
      gl.clear(gl.COLOR_BUFFER_BIT);
    }
    state.frameStarted = performance.now();
  }
  gl.enable(gl.BLEND);
  gl.blendFunc(gl.ONE, gl.ONE);
  gl.enable(gl.SCISSOR_TEST);
  const list = state.passList;
  const total = list.length * bands;
  const t0 = performance.now();
  while (state.next < total && (all || performance.now() - t0 < 30)) {
    const pass = Math.floor(state.next / bands), band = state.next % bands;
    gl.scissor(0, band * BAND_ROWS, state.res, BAND_ROWS);
    drawPass(list[pass], pass === 0);
    state.next++;
    if (!all) gl.finish();
  }
  gl.disable(gl.SCISSOR_TEST);
  gl.disable(gl.BLEND);
  gl.bindFramebuffer(gl.FRAMEBUFFER, null);
  if (state.next >= total) {
    gl.finish();
    state.frameMs = performance.now() - state.frameStarted;
    state.passCount = list.length;
    return true;
  }
  return false;
}

function display() {
  const gl = state.gl;
  if (!state.displayProg) state.displayProg = glProgram(gl, DISPLAY);
  gl.useProgram(state.displayProg);
  gl.viewport(0, 0, state.res, state.res);
  gl.activeTexture(gl.TEXTURE1);
  gl.bindTexture(gl.TEXTURE_2D, state.target.tex);
  gl.uniform1i(gl.getUniformLocation(state.displayProg, 'u_sum'), 1);
  // The mean of the frames added so far
  gl.uniform1f(gl.getUniformLocation(state.displayProg, 'u_exposure'),
               state.exposure / (state.accumulated + (state.passList.done ? 1 : 0) || 1));
  gl.drawArrays(gl.TRIANGLES, 0, 3);
}

function loop() {
  if (state.shader && !state.test) {
    if (state.dirty) {
      state.dirty = false;
      state.accumulated = 0;
      state.passList = passes(0);
      state.next = 0;
    } else if (state.passList && state.passList.done && state.shader.spectral &&
               state.accumulated + 1 < SPECTRAL_FRAMES) {
      // The next spectral frame, added to the ones before
      state.accumulated++;
      state.passList = passes(state.accumulated);
      state.next = 0;
    }
    if (state.passList && !state.passList.done) {
      // (display() divides the sum by the frames it holds: those done, and
      // the one under way counts once it is)
      state.passList.done = renderSome(false);
      if (state.passList.done || !state.accumulated) display();
      if (state.passList.done) setStatus(statusLine());
    }
  }
  requestAnimationFrame(loop);
}

function resize() {
  const c = $('canvas');
  c.width = c.height = state.res;
  state.dirty = true;
}

// ---------------------------------------------------------------- tests

function postResult(body) {
  return fetch('/api/result', {method: 'POST', headers: {'Content-Type': 'application/json'},
                               body: JSON.stringify(Object.assign({name: state.test}, body))})
    .then(() => { document.title = 'done: ' + state.test; });
}

function b64(floats) {
  const bytes = new Uint8Array(floats.buffer);
  let s = '';
  for (let i = 0; i < bytes.length; i += 0x8000) {
    s += String.fromCharCode.apply(null, bytes.subarray(i, i + 0x8000));
  }
  return btoa(s);
}

// Renders the directions (1 wi, 2 wo), the small light's factor I cos / d^2
// (3) and the radiance (every pass) into the float framebuffer and posts
// them, with the times of the shader's compile and of one whole picture.
function runTest() {
  const gl = state.gl, n = state.res;
  const out = {width: n, height: n, compile_ms: state.compileMs, ops: state.shader.ops,
               renderer: state.renderer, moved: state.moved, rebuild_ms: state.rebuildMs, timing: state.timing,
               reused: state.shader.reused, build_s: state.material.build_s, uniforms: state.uniforms, source: q.has('source') ? state.source : undefined,
               xml: $('xml').textContent, dict: $('dict').textContent};
  const read = (scale) => {
    const px = new Float32Array(4 * n * n);
    gl.readPixels(0, 0, n, n, gl.RGBA, gl.FLOAT, px);
    if (scale) px.forEach((x, i) => { px[i] = x * scale; });
    return b64(px);
  };
  // frames=N: the mean of N spectral frames (their wavelengths shifted)
  const frames = state.shader.spectral ? Math.max(1, +(q.get('frames') || 1)) : 1;
  ensureTarget();
  out.views = {};
  for (const view of (q.get('views') || state.view).split(',')) {
    state.view = view;
    viewLight();
    const v = {light: [state.azimuth, state.elevation]};
    for (const [name, mode] of [['wi', 1], ['wo', 2], ['factor', 3]]) {
      gl.bindFramebuffer(gl.FRAMEBUFFER, state.target.fb);
      drawPass(passes(0)[0], true, mode);
      v[name] = read();
    }
    const t0 = performance.now();
    for (let f = 0; f < frames; f++) {
      state.accumulated = f;
      state.passList = passes(f);
      state.next = 0;
      renderSome(true);
    }
    gl.bindFramebuffer(gl.FRAMEBUFFER, state.target.fb);
    v.radiance = read(1 / frames);
    state.frameStarted = t0 + (performance.now() - t0) * (1 - 1 / frames);
    v.frame_ms = performance.now() - state.frameStarted;
    v.passes = state.passList.length;
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    out.views[view] = v;
  }
  display();
  out.gl_error = gl.getError();
  postResult(out);
}

// ---------------------------------------------------------------- start

async function main() {
  const c = $('canvas');
  c.width = c.height = state.res;
  const gl = c.getContext('webgl2', {antialias: false, preserveDrawingBuffer: true});
  if (!gl) {
    setStatus('this browser has no WebGL2', true);
    if (state.test) postResult({error: 'no WebGL2'});
    return;
  }
  gl.getExtension('EXT_color_buffer_float');
  gl.getExtension('EXT_float_blend');
  const dbg = gl.getExtension('WEBGL_debug_renderer_info');
  state.renderer = dbg ? gl.getParameter(dbg.UNMASKED_RENDERER_WEBGL) : gl.getParameter(gl.RENDERER);
  state.gl = gl;
  const buf = gl.createBuffer();
  gl.bindBuffer(gl.ARRAY_BUFFER, buf);
  gl.bufferData(gl.ARRAY_BUFFER, new Float32Array([-1, -1, 3, -1, -1, 3]), gl.STATIC_DRAW);
  gl.enableVertexAttribArray(0);
  gl.vertexAttribPointer(0, 2, gl.FLOAT, false, 0, 0);
  [state.contract, state.reference] = await Promise.all([getJson('/api/contract'),
                                                          getJson('/api/reference')]);
  if (q.has('material')) {
    state.params = JSON.parse(q.get('material'));
    state.surface = state.params.surface;
    state.frame = Object.assign({tracks: 'linear', twist: 0}, JSON.parse(q.get('frame') || '{}'));
  } else {
    state.params = Object.assign({}, state.reference.presets[state.surface]);
  }
  buildControls();
  let drag = null;
  c.onmousedown = (e) => { drag = [e.clientX, e.clientY, state.azimuth, state.elevation]; };
  window.onmouseup = () => { drag = null; };
  c.onmousemove = (e) => {
    if (!drag) return;
    state.azimuth = ((drag[2] + (e.clientX - drag[0]) * 0.5 + 540) % 360) - 180;
    state.elevation = Math.min(89, Math.max(1, drag[3] - (e.clientY - drag[1]) * 0.3));
    state.dirty = true;
  };
  document.querySelectorAll('button[data-copy]').forEach((b) => {
    b.onclick = () => navigator.clipboard.writeText($(b.dataset.copy).textContent);
  });
  requestAnimationFrame(loop);
  build();
}

main().catch((e) => {
  setStatus(String(e.message || e), true);
  if (state.test) postResult({error: String(e.message || e)});
});
