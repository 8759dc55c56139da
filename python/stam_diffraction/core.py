"""stam_diffraction.core: the core's C ABI (stam.h) through ctypes.

    from stam_diffraction import core
    with core.Brdf({'surface': 'cd'}) as b:
        rgb = b.eval_rgb(wi, wo)                 # (..., 3), 1/sr, without cos
        f = b.eval_spectral(wi, wo, 550.0)       # (...)

The library is the core's shared library: libstam.so shipped in the package
when it is installed from the wheel, target/release/libstam.so (`make core`)
in a source checkout, or the file named by the environment variable
STAM_CORE_LIB. It is loaded on first use (SRGB_LUMINANCE is read from stam.h,
also shipped in the package).

Arrays: a direction is 3 numbers in the core's local frame (z = normal, x = the
periodic direction of gratings), so wi, wo have shape (..., 3); wavelengths
(nm) and the sampling uniforms (..., 3) broadcast against them. The leading
("batch") shapes broadcast like numpy's, and results have the broadcast batch
shape (plus 3 for RGB). Inputs go to the core as float32 (the ABI's type);
results come back as float64 arrays holding those float32 values.

Methods follow the header's functions one to one (stam_brdf_<method>;
resolved_params is stam_brdf_params_json); see stam.h for the exact contract
of each. parameter_reference() is the reference of every surface's keys
(stam_parameter_reference: units, ranges, defaults).

Programs (stam_brdf_export_program): what a renderer that traces its code
(Dr.Jit) executes; Brdf.export_program(kind) hands one out as a float32 array
and run_program(array, inputs) executes it with numpy, in float32, with the
operations' exact semantics (the core's CPU executor,
rust-core/src/program/interpret.rs), so that scripts and tests can run the
programs without Mitsuba:

    with core.Brdf({'surface': 'cd'}) as b:
        prog = b.export_program(core.PROGRAM_SAMPLE_RGB)    # None if it has none
        out = core.run_program(prog, np.concatenate([wi, u], axis=-1))  # (..., 4)
"""

import collections
import ctypes
import json
import operator
import os
import re

import numpy as np

from ._layout import CORE_LIB as DEFAULT_LIB, HEADER

# Bytes of the construction error message buffer (the message names the bad
# key and its accepted range; the core truncates to this length).
ERR_LEN = 1024

# Flags of stam_brdf_flags (stam.h).
FLAG_HAS_COHERENT = 1
FLAG_ANISOTROPIC = 2
FLAG_SPECTRALLY_VARYING = 4


def _header_luminance(path=HEADER):
    """(R, G, B) weights of the macros STAM_SRGB_LUMINANCE_R/G/B in stam.h."""
    with open(path) as f:
        text = f.read()
    found = dict(re.findall(r'^#define\s+STAM_SRGB_LUMINANCE_([RGB])\s+(\S+)', text, re.M))
    if set(found) != {'R', 'G', 'B'}:
        raise RuntimeError('stam_diffraction.core: %s lacks STAM_SRGB_LUMINANCE_R/G/B' % path)
    return tuple(float(found[c]) for c in 'RGB')


# Luminance weights of linear sRGB, as the core uses them (its RGB outputs are
# gamut-mapped at constant luminance Y = SRGB_LUMINANCE . rgb).
SRGB_LUMINANCE = np.array(_header_luminance())
SRGB_LUMINANCE.setflags(write=False)


def _header_macros(prefix, path=HEADER):
    """{NAME: value} of the integer macros STAM_<prefix><NAME> in stam.h."""
    with open(path) as f:
        text = f.read()
    return {name: int(value) for name, value in
            re.findall(r'^#define\s+STAM_%s([A-Z0-9_]+)\s+(\d+)u?(?=\s|$)' % prefix, text, re.M)}


def _header_program_kinds(path=HEADER):
    """{NAME: code} of the macros STAM_PROGRAM_<NAME> in stam.h (the kinds;
    not the array's FORMAT and HEADER_LEN)."""
    return {name: code for name, code in _header_macros('PROGRAM_', path).items()
            if name not in ('FORMAT', 'HEADER_LEN')}


_KINDS = _header_program_kinds()
_KIND_NAMES = ('EVAL_RGB', 'EVAL_SPECTRAL', 'PDF_RGB', 'PDF_SPECTRAL', 'SAMPLE_RGB',
               'SAMPLE_SPECTRAL', 'COHERENT_RGB', 'COHERENT_SPECTRAL', 'KINDS', 'AT_BUILT')
if set(_KINDS) != set(_KIND_NAMES):
    raise RuntimeError('stam_diffraction.core: %s has the program kinds %s, not %s'
                       % (HEADER, sorted(_KINDS), sorted(_KIND_NAMES)))

# Kinds of program (STAM_PROGRAM_* of stam.h, read from it). Inputs and outputs
# of each, in this order (directions in the local frame, lambda in nm, u
# uniforms in [0, 1)):
#   EVAL_RGB          wi[3] wo[3]        -> f R, G, B (no cos, no coherent lobe)
#   EVAL_SPECTRAL     wi[3] wo[3] lambda -> f
#   PDF_RGB           wi[3] wo[3]        -> glossy density at wo (RGB strategy)
#   PDF_SPECTRAL      wi[3] wo[3] lambda -> glossy density (lambda's strategy)
#   SAMPLE_RGB        wi[3] u[3]         -> wo[3], coherent (1 or 0)
#   SAMPLE_SPECTRAL   wi[3] u[3] lambda  -> wo[3], coherent
#   COHERENT_RGB      wi[3]              -> coherent R, G, B, its probability
#   COHERENT_SPECTRAL wi[3] lambda       -> coherent reflectance, probability
# (program_io gives each kind's numbers of inputs and outputs.)
PROGRAM_EVAL_RGB = _KINDS['EVAL_RGB']
PROGRAM_EVAL_SPECTRAL = _KINDS['EVAL_SPECTRAL']
PROGRAM_PDF_RGB = _KINDS['PDF_RGB']
PROGRAM_PDF_SPECTRAL = _KINDS['PDF_SPECTRAL']
PROGRAM_SAMPLE_RGB = _KINDS['SAMPLE_RGB']
PROGRAM_SAMPLE_SPECTRAL = _KINDS['SAMPLE_SPECTRAL']
PROGRAM_COHERENT_RGB = _KINDS['COHERENT_RGB']
PROGRAM_COHERENT_SPECTRAL = _KINDS['COHERENT_SPECTRAL']
PROGRAM_KINDS = _KINDS['KINDS']
# Added to a kind: its program for a renderer that keeps every parameter at its
# built value (no texture, no gradient); None where it is the plain program.
PROGRAM_AT_BUILT = _KINDS['AT_BUILT']

# Mixture programs (STAM_MIXTURE_* of stam.h, read from it): a spectral
# renderer's one-sample mixture over the N wavelengths of a path, each
# wavelength's strategy an equally weighted component (export_mixture_program):
#   MIXTURE_PDF       wi[3] wo[3] lambda[N] -> the mixture's glossy density
#   MIXTURE_SAMPLE    wi[3] u[3] lambda[N]  -> wo[3], coherent (u0 picks lambda_j)
#   MIXTURE_COHERENT  wi[3] lambda[N]       -> N reflectances, the probability
_MIXTURE = _header_macros('MIXTURE_')
MIXTURE_PDF = _MIXTURE['PDF']
MIXTURE_SAMPLE = _MIXTURE['SAMPLE']
MIXTURE_COHERENT = _MIXTURE['COHERENT']
MIXTURE_KINDS = _MIXTURE['KINDS']
MIXTURE_MAX_WAVELENGTHS = _MIXTURE['MAX_WAVELENGTHS']

# How far (relative) a renderer may move a parameter a program reads before
# it builds the material anew (stam.h's STAM_PROGRAM_MAX_DRIFT, read from it).
def _header_float(name, path=HEADER):
    with open(path) as f:
        found = re.findall(r'^#define\s+STAM_%s\s+(\S+)' % name, f.read(), re.M)
    if len(found) != 1:
        raise RuntimeError('stam_diffraction.core: %s lacks STAM_%s' % (path, name))
    return float(found[0])


PROGRAM_MAX_DRIFT = _header_float('PROGRAM_MAX_DRIFT')

# The program array (stam.h: STAM_PROGRAM_FORMAT, read from it): a header of
# PROGRAM_HEADER_LEN values (format, inputs, outputs, instructions, tables,
# total length, parameters, 0), the output registers, (offset, length) per
# table, (id, value) per parameter (PROGRAM_PARAMS; a Param's a is its slot
# in this list), four values per instruction (op code, a, b, c; a Const's a
# is its value; an If's a is its mask, an EndIf's a its If), then the
# tables' values. Integers are stored as floats.
_LAYOUT = _header_macros('PROGRAM_')
PROGRAM_FORMAT = _LAYOUT['FORMAT']
PROGRAM_HEADER_LEN = _LAYOUT['HEADER_LEN']


def _header_names(prefix, count, spell):
    """The names of the macros STAM_<prefix>* of stam.h in code order
    (0 .. STAM_<count> - 1, each once), spelt by `spell`."""
    codes = {code: name for name, code in _header_macros(prefix).items()}
    n = _header_macros('')[count]
    if sorted(codes) != list(range(n)):
        raise RuntimeError('stam_diffraction.core: %s has the STAM_%s codes %s, not 0..%d'
                           % (HEADER, prefix, sorted(codes), n - 1))
    return tuple(spell(codes[k]) for k in range(n))


# Operation names in code order (stam.h's STAM_OP_*: STAM_OP_END_IF is
# 'EndIf').
PROGRAM_OPS = _header_names('OP_', 'OPS', lambda n: n.title().replace('_', ''))
# Parameter names in id order (stam.h's STAM_PARAM_*: STAM_PARAM_PERIOD_UM is
# 'period_um', as stam_param_name gives it).
PROGRAM_PARAMS = _header_names('PARAM_', 'PARAMS', str.lower)
_OP = {name: code for code, name in enumerate(PROGRAM_OPS)}
# A decoded program: n_inputs; outputs (registers); code, a list of
# (op, a, b, c) with a Const's a its float32 value, a Gather's a its table
# and a Param's a its parameter slot; tables, float32 arrays; params, a
# tuple of (name, float32 value) per slot (names: PROGRAM_PARAMS); array,
# the float32 array it was decoded from.
Program = collections.namedtuple('Program', 'n_inputs outputs code tables params array',
                                 defaults=((), None))

_lib = None


def library_path():
    return os.environ.get('STAM_CORE_LIB', DEFAULT_LIB)


def lib():
    """The loaded core library (ctypes.CDLL), with the header's signatures."""
    global _lib
    if _lib is not None:
        return _lib
    path = library_path()
    if not os.path.exists(path):
        raise FileNotFoundError('stam_diffraction.core: %s not found (`make core` in a '
                                'source checkout), or set STAM_CORE_LIB' % path)
    L = ctypes.CDLL(path)
    vp, sz, fp = ctypes.c_void_p, ctypes.c_size_t, ctypes.POINTER(ctypes.c_float)
    u8p = ctypes.POINTER(ctypes.c_uint8)
    dp = ctypes.POINTER(ctypes.c_double)
    sig = {
        'stam_brdf_new': (vp, [ctypes.c_char_p, ctypes.c_char_p, sz]),
        'stam_brdf_free': (None, [vp]),
        'stam_brdf_eval_spectral': (None, [vp, sz, fp, fp, fp, fp]),
        'stam_brdf_eval_rgb': (None, [vp, sz, fp, fp, fp]),
        'stam_brdf_polarization': (ctypes.c_int, [vp, sz, fp, fp, fp, fp]),
        'stam_brdf_mueller': (ctypes.c_int, [vp, sz, fp, fp, fp, fp]),
        'stam_brdf_coherent_spectral': (None, [vp, sz, fp, fp, fp]),
        'stam_brdf_coherent_rgb': (None, [vp, sz, fp, fp]),
        'stam_brdf_sample': (None, [vp, sz, fp, fp, fp, fp, fp, u8p]),
        'stam_brdf_pdf': (None, [vp, sz, fp, fp, fp, fp]),
        'stam_brdf_coherent_probability': (None, [vp, sz, fp, fp, fp]),
        'stam_brdf_eval_pdf_vertex': (None, [vp, sz, fp, fp, fp, sz, fp, fp]),
        'stam_brdf_sample_vertex': (None, [vp, sz, fp, fp, sz, fp, fp, fp, u8p, fp]),
        'stam_brdf_eval_pdf_sample_vertex': (None, [vp, sz, fp, fp, fp, sz, fp, fp, fp, fp,
                                                    fp, u8p, fp]),
        'stam_brdf_flags': (ctypes.c_uint32, [vp]),
        'stam_brdf_memory_bytes': (sz, [vp]),
        'stam_brdf_export_program': (sz, [vp, ctypes.c_uint32, fp, sz]),
        'stam_brdf_export_mixture_program': (sz, [vp, ctypes.c_uint32, ctypes.c_uint32, fp, sz]),
        'stam_program_io': (ctypes.c_int, [ctypes.c_uint32, ctypes.c_uint32,
                                           ctypes.POINTER(ctypes.c_uint32),
                                           ctypes.POINTER(ctypes.c_uint32)]),
        'stam_brdf_warnings': (ctypes.c_char_p, [vp]),
        'stam_brdf_params_json': (ctypes.c_char_p, [vp]),
        'stam_parameter_reference': (ctypes.c_char_p, []),
        'stam_version': (ctypes.c_char_p, []),
        'stam_rigorous_solve': (ctypes.c_void_p, [ctypes.c_char_p, ctypes.c_char_p, sz]),
        'stam_text_free': (None, [ctypes.c_void_p]),
        'stam_param_name': (ctypes.c_char_p, [ctypes.c_uint32]),
        'stam_program_run': (ctypes.c_int, [fp, sz, fp, sz, fp, sz, fp, _ELEMENTARY, _REGION,
                                            vp, ctypes.c_char_p, sz]),
        'stam_program_run_f64': (ctypes.c_int, [fp, sz, dp, sz, dp, sz, dp, ctypes.c_char_p,
                                                sz]),
    }
    for name, (res, args) in sig.items():
        fn = getattr(L, name)
        fn.restype = res
        fn.argtypes = args
    _lib = L
    return L


def rigorous_solve(**request):
    """Rigorous grating efficiencies (stam_rigorous_solve): keyword arguments
    as the request's keys (period_um, profile, height_um, width_um,
    heights_um, slices, fresnel, cover_eta, lambda_nm, theta_deg, phi_deg,
    orders, rule); returns the answer as a dict. Raises ValueError with the
    core's message on bad input."""
    L = lib()
    err = ctypes.create_string_buffer(1024)
    ptr = L.stam_rigorous_solve(json.dumps(request).encode(), err, len(err))
    if not ptr:
        raise ValueError(err.value.decode())
    try:
        return json.loads(ctypes.string_at(ptr).decode())
    finally:
        L.stam_text_free(ptr)


def version():
    """The core's version string (stam_version)."""
    return lib().stam_version().decode()


def parameter_reference():
    """The parameter reference (stam_parameter_reference): a dict with
    'material' (the keys every surface reads) and 'surfaces' (a list of
    {'surface': name, 'keys': [...]}), each key a dict of 'key', 'meaning',
    'unit' ('um' or ''), 'min', 'max' (None where none or relative to
    another key), 'min_open', 'integer', 'accepted' (in words), 'required',
    'default' (None: none) and 'note', from the ranges the core's parameter
    readers check (docs/parameters.md)."""
    return json.loads(lib().stam_parameter_reference().decode())


def _f32(a):
    return np.ascontiguousarray(a, dtype=np.float32)


def _ptr(a):
    """Pointer to a contiguous array's data (uint8, float32 or float64), or
    NULL for None."""
    if a is None:
        return None
    ctype = {np.dtype(np.uint8): ctypes.c_uint8,
             np.dtype(np.float64): ctypes.c_double}.get(a.dtype, ctypes.c_float)
    return a.ctypes.data_as(ctypes.POINTER(ctype))


def _vectors(a, name):
    a = np.asarray(a, dtype=np.float64)
    if a.ndim == 0 or a.shape[-1] != 3:
        raise ValueError('stam_diffraction.core: %s must have shape (..., 3), not %s'
                         % (name, a.shape))
    return a


class Brdf:
    """One material of the core (stam_brdf_new .. stam_brdf_free).

    params: a dict (serialised to JSON) or a JSON string, in the core's names
    and units (docs/parameters.md). Raises ValueError with the core's message
    (which names the refused key) when the core refuses the parameters."""

    def __init__(self, params):
        text = params if isinstance(params, str) else json.dumps(params)
        self.params_json = text
        self._lib = lib()
        err = ctypes.create_string_buffer(ERR_LEN)
        self._ptr = self._lib.stam_brdf_new(text.encode(), err, ERR_LEN)
        if not self._ptr:
            raise ValueError(err.value.decode(errors='replace'))

    # -- lifetime -------------------------------------------------------------

    def close(self):
        """Free the material (idempotent)."""
        ptr, self._ptr = getattr(self, '_ptr', None), None
        if ptr:
            self._lib.stam_brdf_free(ptr)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __del__(self):
        self.close()

    def _handle(self):
        if not self._ptr:
            raise ValueError('stam_diffraction.core: the material is closed')
        return self._ptr

    def __repr__(self):
        return 'stam_diffraction.core.Brdf(%s%s)' % (self.params_json,
                                                     '' if self._ptr else ', closed')

    # -- properties -------------------------------------------------------------

    def flags(self):
        """FLAG_HAS_COHERENT | FLAG_ANISOTROPIC | FLAG_SPECTRALLY_VARYING bits."""
        return int(self._lib.stam_brdf_flags(self._handle()))

    def memory_bytes(self):
        return int(self._lib.stam_brdf_memory_bytes(self._handle()))

    def export_program(self, kind):
        """The program of `kind` (PROGRAM_EVAL_RGB .. PROGRAM_COHERENT_SPECTRAL,
        plus PROGRAM_AT_BUILT for the built parameters' program;
        stam_brdf_export_program) as a float32 array for run_program, or
        None when the material has none of that kind or the kind is not one."""
        kind = operator.index(kind)
        if not 0 <= kind < 2 ** 32:
            return None
        return self._exported(lambda out, n: self._lib.stam_brdf_export_program(
            self._handle(), kind, out, n))

    def export_mixture_program(self, kind, n_wavelengths):
        """The mixture program of `kind` (MIXTURE_PDF, MIXTURE_SAMPLE,
        MIXTURE_COHERENT, plus PROGRAM_AT_BUILT) over `n_wavelengths` (1 ..
        MIXTURE_MAX_WAVELENGTHS; stam_brdf_export_mixture_program) as a float32
        array for run_program, or None where the material has none."""
        kind, n_wavelengths = operator.index(kind), operator.index(n_wavelengths)
        if not (0 <= kind < 2 ** 32 and 0 <= n_wavelengths < 2 ** 32):
            return None
        return self._exported(lambda out, n: self._lib.stam_brdf_export_mixture_program(
            self._handle(), kind, n_wavelengths, out, n))

    def _exported(self, export):
        """The array `export(out, capacity)` writes, sized with out = NULL."""
        n = int(export(None, 0))
        if n == 0:
            return None
        out = np.empty(n, dtype=np.float32)
        written = int(export(_ptr(out), n))
        if written != n:
            raise RuntimeError('stam_diffraction.core: a program export wrote %d of %d'
                               % (written, n))
        return out

    def resolved_params(self):
        """Every parameter the material reads with the value it took,
        defaults filled in (stam_brdf_params_json), as a dict: e.g. the
        compact disc's period_um, coherence_um, height_um and width_um, the
        default fresnel 'aluminium'. Brdf(b.resolved_params()) is the same
        material."""
        return json.loads(self._lib.stam_brdf_params_json(self._handle()).decode())

    def warnings(self):
        """The plausibility warnings of the parameters (stam_brdf_warnings):
        a list of sentences, each naming its parameter; [] when none."""
        text = self._lib.stam_brdf_warnings(self._handle()).decode()
        return text.split('\n') if text else []

    # -- evaluation -------------------------------------------------------------

    @staticmethod
    def _batch(*shapes):
        shape = np.broadcast_shapes(*shapes)
        return shape, int(np.prod(shape, dtype=np.int64))

    @staticmethod
    def _lanes(a, shape, n, tail=()):
        """a broadcast to shape + tail, flattened to n lanes, float32."""
        return _f32(np.broadcast_to(a, shape + tail).reshape((n,) + tail))

    def eval_rgb(self, wi, wo):
        """f(wi, wo) in linear sRGB (1/sr, without cos and the coherent lobe):
        shape (..., 3)."""
        wi, wo = _vectors(wi, 'wi'), _vectors(wo, 'wo')
        shape, n = self._batch(wi.shape[:-1], wo.shape[:-1])
        out = np.zeros((n, 3), np.float32)
        self._lib.stam_brdf_eval_rgb(self._handle(), n, _ptr(self._lanes(wi, shape, n, (3,))),
                                     _ptr(self._lanes(wo, shape, n, (3,))), _ptr(out))
        return out.astype(np.float64).reshape(shape + (3,))

    def eval_spectral(self, wi, wo, lambda_nm):
        """f(wi, wo; lambda) (1/sr, without cos and the coherent lobe)."""
        wi, wo = _vectors(wi, 'wi'), _vectors(wo, 'wo')
        lam = np.asarray(lambda_nm, dtype=np.float64)
        shape, n = self._batch(wi.shape[:-1], wo.shape[:-1], lam.shape)
        out = np.zeros(n, np.float32)
        self._lib.stam_brdf_eval_spectral(
            self._handle(), n, _ptr(self._lanes(wi, shape, n, (3,))),
            _ptr(self._lanes(wo, shape, n, (3,))), _ptr(self._lanes(lam, shape, n)), _ptr(out))
        return out.astype(np.float64).reshape(shape)

    def polarization(self, wi, wo, lambda_nm):
        """The polarisation of the reflection from wi to wo at lambda
        (stam_brdf_polarization): (b, c, s), shape (..., 3), of its Mueller
        matrix over the unpolarised value, [[1, b, 0, 0], [b, 1, 0, 0],
        [0, 0, c, s], [0, 0, -s, c]] in the conventions of Mitsuba's
        mueller.specular_reflection; None for a material without one
        (rigorous gratings: see `mueller`)."""
        wi, wo = _vectors(wi, 'wi'), _vectors(wo, 'wo')
        lam = np.asarray(lambda_nm, dtype=np.float64)
        shape, n = self._batch(wi.shape[:-1], wo.shape[:-1], lam.shape)
        out = np.zeros((n, 3), np.float32)
        has = self._lib.stam_brdf_polarization(
            self._handle(), n, _ptr(self._lanes(wi, shape, n, (3,))),
            _ptr(self._lanes(wo, shape, n, (3,))), _ptr(self._lanes(lam, shape, n)), _ptr(out))
        if not has and n:
            return None
        return out.astype(np.float64).reshape(shape + (3,))

    def mueller(self, light_from, light_to, lambda_nm):
        """The Mueller matrix of the reflection of light arriving from
        `light_from` and leaving along `light_to` at lambda
        (stam_brdf_mueller): (matrix over its [0][0], shape (..., 4, 4);
        Stokes basis vector of the incident direction of travel
        -light_from, (..., 3); that of light_to, (..., 3)), in Mitsuba's
        conventions (the second axis of a basis is d x the first). None for
        a material without one (a rigorous grating with a cover)."""
        wi, wo = _vectors(light_from, 'light_from'), _vectors(light_to, 'light_to')
        lam = np.asarray(lambda_nm, dtype=np.float64)
        shape, n = self._batch(wi.shape[:-1], wo.shape[:-1], lam.shape)
        out = np.zeros((n, 22), np.float32)
        has = self._lib.stam_brdf_mueller(
            self._handle(), n, _ptr(self._lanes(wi, shape, n, (3,))),
            _ptr(self._lanes(wo, shape, n, (3,))), _ptr(self._lanes(lam, shape, n)), _ptr(out))
        if not has and n:
            return None
        out = out.astype(np.float64)
        return (out[:, :16].reshape(shape + (4, 4)), out[:, 16:19].reshape(shape + (3,)),
                out[:, 19:].reshape(shape + (3,)))

    def coherent_rgb(self, wi):
        """Reflectance of the coherent (mirror) delta lobe in linear sRGB: (..., 3)."""
        wi = _vectors(wi, 'wi')
        shape, n = self._batch(wi.shape[:-1])
        out = np.zeros((n, 3), np.float32)
        self._lib.stam_brdf_coherent_rgb(self._handle(), n,
                                         _ptr(self._lanes(wi, shape, n, (3,))), _ptr(out))
        return out.astype(np.float64).reshape(shape + (3,))

    def coherent_spectral(self, wi, lambda_nm):
        """Reflectance of the coherent (mirror) delta lobe at lambda."""
        wi = _vectors(wi, 'wi')
        lam = np.asarray(lambda_nm, dtype=np.float64)
        shape, n = self._batch(wi.shape[:-1], lam.shape)
        out = np.zeros(n, np.float32)
        self._lib.stam_brdf_coherent_spectral(self._handle(), n,
                                              _ptr(self._lanes(wi, shape, n, (3,))),
                                              _ptr(self._lanes(lam, shape, n)), _ptr(out))
        return out.astype(np.float64).reshape(shape)

    # -- sampling ---------------------------------------------------------------

    def _optional_lambda(self, lambda_nm, shapes):
        """(batch shape, n, float32 lanes or None) for an optional wavelength."""
        if lambda_nm is None:
            shape, n = self._batch(*shapes)
            return shape, n, None
        lam = np.asarray(lambda_nm, dtype=np.float64)
        shape, n = self._batch(*shapes, lam.shape)
        return shape, n, self._lanes(lam, shape, n)

    def sample(self, wi, rnd, lambda_nm=None):
        """Importance sampling with 3 uniforms in [0, 1) per sample (rnd: (..., 3));
        lambda_nm: one wavelength per sample, or None for the RGB mode.
        Returns (wo (..., 3), pdf (...), coherent (...) bool): pdf is the
        solid-angle density of the whole strategy at wo (0 for a failed
        sample), or the lobe's discrete probability where coherent is True."""
        wi, rnd = _vectors(wi, 'wi'), _vectors(rnd, 'rnd')
        shape, n, lam = self._optional_lambda(lambda_nm, (wi.shape[:-1], rnd.shape[:-1]))
        wo = np.zeros((n, 3), np.float32)
        pdf = np.zeros(n, np.float32)
        coh = np.zeros(n, np.uint8)
        self._lib.stam_brdf_sample(self._handle(), n, _ptr(self._lanes(wi, shape, n, (3,))),
                                   _ptr(lam), _ptr(self._lanes(rnd, shape, n, (3,))),
                                   _ptr(wo), _ptr(pdf), _ptr(coh))
        return (wo.astype(np.float64).reshape(shape + (3,)),
                pdf.astype(np.float64).reshape(shape), coh.astype(bool).reshape(shape))

    def pdf(self, wi, wo, lambda_nm=None):
        """Solid-angle pdf of sample() at wo (its non-coherent part); lambda_nm
        as in sample()."""
        wi, wo = _vectors(wi, 'wi'), _vectors(wo, 'wo')
        shape, n, lam = self._optional_lambda(lambda_nm, (wi.shape[:-1], wo.shape[:-1]))
        out = np.zeros(n, np.float32)
        self._lib.stam_brdf_pdf(self._handle(), n, _ptr(self._lanes(wi, shape, n, (3,))),
                                _ptr(self._lanes(wo, shape, n, (3,))), _ptr(lam), _ptr(out))
        return out.astype(np.float64).reshape(shape)

    def coherent_probability(self, wi, lambda_nm=None):
        """Probability with which sample() picks the coherent lobe."""
        wi = _vectors(wi, 'wi')
        shape, n, lam = self._optional_lambda(lambda_nm, (wi.shape[:-1],))
        out = np.zeros(n, np.float32)
        self._lib.stam_brdf_coherent_probability(self._handle(), n,
                                                 _ptr(self._lanes(wi, shape, n, (3,))),
                                                 _ptr(lam), _ptr(out))
        return out.astype(np.float64).reshape(shape)

    # -- path-vertex queries ------------------------------------------------------

    def _vertex_lambda(self, lambda_nm, shapes):
        """(batch shape, n, nw, nc, float32 lanes (n, nw) or None). lambda_nm:
        (..., nw) wavelengths per lane, or None for RGB (nc = 3)."""
        if lambda_nm is None:
            shape, n = self._batch(*shapes)
            return shape, n, 0, 3, None
        lam = np.asarray(lambda_nm, dtype=np.float64)
        if lam.ndim == 0:
            raise ValueError('stam_diffraction.core: vertex wavelengths must have shape (..., nw)')
        nw = lam.shape[-1]
        shape, n = self._batch(*shapes, lam.shape[:-1])
        return shape, n, nw, nw, self._lanes(lam, shape, n, (nw,))

    def eval_pdf_vertex(self, wi, wo, lambda_nm=None):
        """(f (..., nc), pdf (...)) of a path vertex carrying the wavelengths
        lambda_nm (..., nw) (nc = nw), or RGB for None (nc = 3)."""
        wi, wo = _vectors(wi, 'wi'), _vectors(wo, 'wo')
        shape, n, nw, nc, lam = self._vertex_lambda(lambda_nm, (wi.shape[:-1], wo.shape[:-1]))
        f = np.zeros((n, nc), np.float32)
        pdf = np.zeros(n, np.float32)
        self._lib.stam_brdf_eval_pdf_vertex(
            self._handle(), n, _ptr(self._lanes(wi, shape, n, (3,))),
            _ptr(self._lanes(wo, shape, n, (3,))), _ptr(lam), nw, _ptr(f), _ptr(pdf))
        return f.astype(np.float64).reshape(shape + (nc,)), pdf.astype(np.float64).reshape(shape)

    def sample_vertex(self, wi, rnd, lambda_nm=None):
        """(wo (..., 3), pdf (...), coherent (...), value (..., nc)) of a path
        vertex's sample; lambda_nm as in eval_pdf_vertex."""
        wi, rnd = _vectors(wi, 'wi'), _vectors(rnd, 'rnd')
        shape, n, nw, nc, lam = self._vertex_lambda(lambda_nm, (wi.shape[:-1], rnd.shape[:-1]))
        wo = np.zeros((n, 3), np.float32)
        pdf = np.zeros(n, np.float32)
        coh = np.zeros(n, np.uint8)
        value = np.zeros((n, nc), np.float32)
        self._lib.stam_brdf_sample_vertex(
            self._handle(), n, _ptr(self._lanes(wi, shape, n, (3,))), _ptr(lam), nw,
            _ptr(self._lanes(rnd, shape, n, (3,))), _ptr(wo), _ptr(pdf), _ptr(coh), _ptr(value))
        return (wo.astype(np.float64).reshape(shape + (3,)), pdf.astype(np.float64).reshape(shape),
                coh.astype(bool).reshape(shape), value.astype(np.float64).reshape(shape + (nc,)))

    def eval_pdf_sample_vertex(self, wi, wo, rnd, lambda_nm=None):
        """eval_pdf_vertex(wi, wo) and sample_vertex(wi, rnd) in one call:
        (f, pdf, s_wo, s_pdf, s_coherent, s_value)."""
        wi, wo, rnd = _vectors(wi, 'wi'), _vectors(wo, 'wo'), _vectors(rnd, 'rnd')
        shape, n, nw, nc, lam = self._vertex_lambda(
            lambda_nm, (wi.shape[:-1], wo.shape[:-1], rnd.shape[:-1]))
        f = np.zeros((n, nc), np.float32)
        pdf = np.zeros(n, np.float32)
        s_wo = np.zeros((n, 3), np.float32)
        s_pdf = np.zeros(n, np.float32)
        s_coh = np.zeros(n, np.uint8)
        s_value = np.zeros((n, nc), np.float32)
        self._lib.stam_brdf_eval_pdf_sample_vertex(
            self._handle(), n, _ptr(self._lanes(wi, shape, n, (3,))),
            _ptr(self._lanes(wo, shape, n, (3,))), _ptr(lam), nw,
            _ptr(self._lanes(rnd, shape, n, (3,))), _ptr(f), _ptr(pdf), _ptr(s_wo),
            _ptr(s_pdf), _ptr(s_coh), _ptr(s_value))
        return (f.astype(np.float64).reshape(shape + (nc,)), pdf.astype(np.float64).reshape(shape),
                s_wo.astype(np.float64).reshape(shape + (3,)),
                s_pdf.astype(np.float64).reshape(shape), s_coh.astype(bool).reshape(shape),
                s_value.astype(np.float64).reshape(shape + (nc,)))


# -- programs -------------------------------------------------------------------


def _program_array(program):
    """The float32 array of a program (an array, or a decoded Program)."""
    if isinstance(program, Program):
        return program.array
    v = np.asarray(program)
    if v.ndim != 1:
        raise ValueError('stam_diffraction.core: a program is a 1-D array, not %s' % (v.shape,))
    return np.ascontiguousarray(v, dtype=np.float32)


def program_io(kind, n_wavelengths=0):
    """(inputs, outputs) of program kind `kind` (n_wavelengths 0: PROGRAM_*)
    or of mixture kind `kind` over n_wavelengths (MIXTURE_*), as stam.h gives
    them (stam_program_io); None for a kind or count that is not one."""
    kind, n_wavelengths = operator.index(kind), operator.index(n_wavelengths)
    if not (0 <= kind < 2 ** 32 and 0 <= n_wavelengths < 2 ** 32):
        return None
    n_in, n_out = ctypes.c_uint32(), ctypes.c_uint32()
    if not lib().stam_program_io(kind, n_wavelengths, ctypes.byref(n_in), ctypes.byref(n_out)):
        return None
    return n_in.value, n_out.value


def decode_program(array):
    """The Program of an array of export_program, after the core's own
    checks (stam_program_run's: rust-core/src/program/encode.rs `decode`):
    format, length, sections inside the array, parameters known ids (each
    once) with finite values, every Param reading one, every operand a
    register defined before its use and of the right kind (float or mask; a
    region's markers read by nothing), regions (If .. EndIf) nested with no
    Input, Const or Param inside, outputs floats. Raises ValueError
    otherwise, with the core's reason."""
    v = _program_array(array)
    err = ctypes.create_string_buffer(ERR_LEN)
    # No lanes: the core only checks the array.
    if not lib().stam_program_run(_ptr(v), len(v), None, 0, None, 0, None, _ELEMENTARY(),
                                  _REGION(), None, err, len(err)):
        raise ValueError('stam_diffraction.core: %s' % err.value.decode())
    n_inputs, n_out, n_code, n_tab, _, n_par = (int(x) for x in v[1:7])
    directory = PROGRAM_HEADER_LEN + n_out
    par_at = directory + 2 * n_tab
    code_at = par_at + 2 * n_par
    tables = [v[int(v[directory + 2 * t]):][:int(v[directory + 2 * t + 1])].copy()
              for t in range(n_tab)]
    params = tuple((PROGRAM_PARAMS[int(v[par_at + 2 * k])], np.float32(v[par_at + 2 * k + 1]))
                   for k in range(n_par))
    words = v[code_at:code_at + 4 * n_code].reshape(n_code, 4)
    const = _OP['Const']
    code = [(int(w[0]), w[1] if int(w[0]) == const else int(w[1]), int(w[2]), int(w[3]))
            for w in words]
    outputs = tuple(int(r) for r in v[PROGRAM_HEADER_LEN:PROGRAM_HEADER_LEN + n_out])
    return Program(n_inputs, outputs, code, tables, params, v)


# stam_program_run's hooks (stam.h: stam_program_elementary, stam_program_region).
_ELEMENTARY = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_uint32, ctypes.c_size_t,
                               ctypes.POINTER(ctypes.c_float), ctypes.POINTER(ctypes.c_float),
                               ctypes.POINTER(ctypes.c_float))
_REGION = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_size_t, ctypes.c_size_t,
                           ctypes.c_size_t, ctypes.POINTER(ctypes.c_uint8))
_ELEMENTARY_NAMES = {_OP[n]: n.lower() for n in ('Exp', 'Log', 'Sin', 'Cos', 'Atan2')}


def run_program(program, inputs, params=None, on_region=None, dtype=np.float32,
                elementary=None):
    """Runs a program (an array of Brdf.export_program, or a decoded
    Program) on lanes of inputs (..., n_inputs): outputs (..., n_outputs)
    of `dtype`. The core's CPU executor (stam_program_run: every operation
    as a renderer's float32 kernel computes it; a region's registers are 0
    on the lanes it does not run on); dtype=np.float64 runs the same
    operations in float64 (stam_program_run_f64), to tell a program's logic
    from float32 rounding. params: {name: value} overriding the values the
    program's parameters were built with (names: PROGRAM_PARAMS; a name the
    program does not read is an error), the same for every lane.
    elementary: {name: f} for some of 'exp', 'log', 'sin', 'cos' (f(a)) and
    'atan2' (f(a, b)), functions of float32 arrays used in place of the
    core's (a test passes Dr.Jit's own). on_region(position, mask), where
    given, is called at each If with its position in the code and the
    lanes it runs on (its mask and every enclosing one's; scripts/
    program_regions.py counts what a SIMD packet runs from them). The last
    two only with float32."""
    p = program if isinstance(program, Program) else decode_program(program)
    dtype = np.dtype(dtype)
    if dtype not in (np.float32, np.float64):
        raise ValueError('stam_diffraction.core: run_program runs float32 or float64, not %s'
                         % dtype)
    if dtype == np.float64 and (elementary or on_region):
        raise ValueError('stam_diffraction.core: elementary and on_region need float32')
    x = np.asarray(inputs, dtype=dtype)
    if x.ndim == 0 or x.shape[-1] != p.n_inputs:
        raise ValueError('stam_diffraction.core: the program takes inputs (..., %d), not %s'
                         % (p.n_inputs, x.shape))
    shape = x.shape[:-1]
    x = np.ascontiguousarray(x.reshape(-1, p.n_inputs))
    names = [name for name, _ in p.params]
    values = np.array([value for _, value in p.params], dtype=dtype)
    for name, value in (params or {}).items():
        if name not in names:
            raise ValueError('stam_diffraction.core: the program reads no parameter %r (it reads %s)'
                             % (name, ', '.join(names) or 'none'))
        values[names.index(name)] = value
    lanes = len(x)
    out = np.zeros((lanes, len(p.outputs)), dtype=dtype)
    err = ctypes.create_string_buffer(ERR_LEN)
    v = p.array
    if dtype == np.float64:
        ok = lib().stam_program_run_f64(_ptr(v), len(v), _ptr(x), lanes, _ptr(values),
                                        len(values), _ptr(out), err, len(err))
    else:
        failure = []
        # Regions inside one that no lane of a batch runs are not reported
        # for that batch: none of its lanes runs them.
        masks = {i: np.zeros(lanes, dtype=bool) for i, c in enumerate(p.code)
                 if c[0] == _OP['If']} if on_region else {}

        def call_elementary(_user, op, n, a, b, result):
            f = (elementary or {}).get(_ELEMENTARY_NAMES.get(op))
            if f is None:
                return 0
            try:
                args = [np.ctypeslib.as_array(a, (n,))]
                if b:
                    args.append(np.ctypeslib.as_array(b, (n,)))
                np.ctypeslib.as_array(result, (n,))[:] = np.asarray(f(*args), dtype=np.float32)
                return 1
            except BaseException as e:  # never into the core: re-raised below
                failure.append(e)
                return 0

        def call_region(_user, position, first, n, runs):
            masks[position][first:first + n] = np.ctypeslib.as_array(runs, (n,)) != 0
        # (a hook's type called with nothing: the NULL function)
        hooks = (_ELEMENTARY(call_elementary) if elementary else _ELEMENTARY(),
                 _REGION(call_region) if on_region else _REGION())
        ok = lib().stam_program_run(_ptr(v), len(v), _ptr(x), lanes, _ptr(values), len(values),
                                    _ptr(out), hooks[0], hooks[1], None, err, len(err))
        if failure:
            raise failure[0]
        for position in sorted(masks):
            on_region(position, masks[position])
    if not ok:
        raise ValueError('stam_diffraction.core: %s' % err.value.decode())
    return out.reshape(shape + (len(p.outputs),))
