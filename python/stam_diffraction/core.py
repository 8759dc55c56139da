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


def _header_program_kinds(path=HEADER):
    """{NAME: code} of the macros STAM_PROGRAM_<NAME> in stam.h."""
    with open(path) as f:
        text = f.read()
    return {name: int(value) for name, value in
            re.findall(r'^#define\s+STAM_PROGRAM_([A-Z_]+)\s+(\d+)u?\b', text, re.M)}


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
# (inputs, outputs) of each kind, indexed by its code (the table above).
PROGRAM_IO = {PROGRAM_EVAL_RGB: (6, 3), PROGRAM_EVAL_SPECTRAL: (7, 1),
              PROGRAM_PDF_RGB: (6, 1), PROGRAM_PDF_SPECTRAL: (7, 1),
              PROGRAM_SAMPLE_RGB: (6, 4), PROGRAM_SAMPLE_SPECTRAL: (7, 4),
              PROGRAM_COHERENT_RGB: (3, 4), PROGRAM_COHERENT_SPECTRAL: (4, 2)}

# The program array (format 4; rust-core/src/program/encode.rs): a header of
# PROGRAM_HEADER_LEN values (format, inputs, outputs, instructions, tables,
# total length, parameters, 0), the output registers, (offset, length) per
# table, (id, value) per parameter (PROGRAM_PARAMS; a Param's a is its slot
# in this list), four values per instruction (op code, a, b, c; a Const's a
# is its value; an If's a is its mask, an EndIf's a its If), then the
# tables' values. Integers are stored as floats.
PROGRAM_FORMAT = 4
PROGRAM_HEADER_LEN = 8
# Operation codes, in code order (rust-core/src/program/mod.rs, enum Op).
PROGRAM_OPS = ('Input', 'Const', 'Add', 'Sub', 'Mul', 'Div', 'Min', 'Max', 'Fma', 'Neg',
               'Abs', 'Sqrt', 'Exp', 'Log', 'Sin', 'Cos', 'Atan2', 'Floor', 'Lt', 'Le', 'Gt',
               'Ge', 'Eq', 'Finite', 'And', 'Or', 'Not', 'Select', 'Gather', 'Param', 'If',
               'EndIf')
# Parameter ids, in code order (rust-core/src/program/mod.rs, enum ParamId;
# stam.h's STAM_PARAM_*): the material parameters' names.
PROGRAM_PARAMS = ('sigma_um', 'corr_um', 'corr_x_um', 'corr_y_um', 'lag_um', 'period_um',
                  'height_um', 'width_um', 'coherence_um', 'twist', 'fresnel', 'eta', 'k')
_OP = {name: code for code, name in enumerate(PROGRAM_OPS)}
_GIVES_MASK = frozenset(_OP[n] for n in ('Lt', 'Le', 'Gt', 'Ge', 'Eq', 'Finite', 'And', 'Or',
                                         'Not'))
# (EndIf names its If in a: no read.)
_ARITY = dict([(_OP[n], 0) for n in ('Input', 'Const', 'Param', 'EndIf')]
              + [(_OP[n], 1) for n in ('Neg', 'Abs', 'Sqrt', 'Exp', 'Log', 'Sin', 'Cos',
                                       'Floor', 'Finite', 'Not', 'Gather', 'If')]
              + [(_OP[n], 2) for n in ('Add', 'Sub', 'Mul', 'Div', 'Min', 'Max', 'Atan2',
                                       'Lt', 'Le', 'Gt', 'Ge', 'Eq', 'And', 'Or')]
              + [(_OP[n], 3) for n in ('Fma', 'Select')])

# A decoded program: n_inputs; outputs (registers); code, a list of
# (op, a, b, c) with a Const's a its float32 value, a Gather's a its table
# and a Param's a its parameter slot; tables, float32 arrays; params, a
# tuple of (name, float32 value) per slot (names: PROGRAM_PARAMS).
Program = collections.namedtuple('Program', 'n_inputs outputs code tables params',
                                 defaults=((),))

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
    sig = {
        'stam_brdf_new': (vp, [ctypes.c_char_p, ctypes.c_char_p, sz]),
        'stam_brdf_free': (None, [vp]),
        'stam_brdf_eval_spectral': (None, [vp, sz, fp, fp, fp, fp]),
        'stam_brdf_eval_rgb': (None, [vp, sz, fp, fp, fp]),
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
        'stam_brdf_warnings': (ctypes.c_char_p, [vp]),
        'stam_brdf_params_json': (ctypes.c_char_p, [vp]),
        'stam_parameter_reference': (ctypes.c_char_p, []),
        'stam_version': (ctypes.c_char_p, []),
        'stam_rigorous_solve': (ctypes.c_void_p, [ctypes.c_char_p, ctypes.c_char_p, sz]),
        'stam_text_free': (None, [ctypes.c_void_p]),
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
    """Pointer to a contiguous array's data, or NULL for None."""
    if a is None:
        return None
    ctype = ctypes.c_uint8 if a.dtype == np.uint8 else ctypes.c_float
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
        n = int(self._lib.stam_brdf_export_program(self._handle(), kind, None, 0))
        if n == 0:
            return None
        out = np.empty(n, dtype=np.float32)
        written = int(self._lib.stam_brdf_export_program(self._handle(), kind, _ptr(out), n))
        if written != n:
            raise RuntimeError('stam_diffraction.core: export_program wrote %d of %d'
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


def decode_program(array):
    """The Program of an array of export_program, checked as the core's
    decode checks it (rust-core/src/program/encode.rs): format, length,
    sections inside the array, parameters known ids (each once) with finite
    values, every Param reading one, every operand a register defined
    before its use and of the right kind (float or mask; a region's markers
    read by nothing), regions (If .. EndIf) nested with no Input, Const or
    Param inside, outputs floats. Raises ValueError otherwise."""
    v = np.asarray(array)
    if v.ndim != 1:
        raise ValueError('stam_diffraction.core: a program is a 1-D array, not %s' % (v.shape,))
    v = v.astype(np.float32, copy=False)

    def bad(what):
        return ValueError('stam_diffraction.core: not a program array: %s' % what)

    def integer(x, what):
        x = float(x)
        if not (0.0 <= x < 16777216.0 and x == int(x)):
            raise bad('%s is %r, not an integer below 2^24' % (what, x))
        return int(x)

    if len(v) < PROGRAM_HEADER_LEN:
        raise bad('%d values, shorter than the header' % len(v))
    if integer(v[0], 'the format') != PROGRAM_FORMAT:
        raise bad('format %g, not %d' % (v[0], PROGRAM_FORMAT))
    n_inputs, n_out, n_code, n_tab, total, n_par = (integer(v[i], 'header value %d' % i)
                                                    for i in range(1, 7))
    if total != len(v):
        raise bad('length %d, the header says %d' % (len(v), total))
    if v[7] != 0:
        raise bad('header value 7 is %r, not 0' % float(v[7]))
    directory = PROGRAM_HEADER_LEN + n_out
    par_at = directory + 2 * n_tab
    code_at = par_at + 2 * n_par
    code_end = code_at + 4 * n_code
    if code_end > total:
        raise bad('%d instructions and %d tables do not fit' % (n_code, n_tab))
    tables = []
    for t in range(n_tab):
        off = integer(v[directory + 2 * t], 'table %d offset' % t)
        length = integer(v[directory + 2 * t + 1], 'table %d length' % t)
        if off < code_end or off + length > total:
            raise bad('table %d at %d..%d' % (t, off, off + length))
        tables.append(v[off:off + length].copy())
    params = []
    for k in range(n_par):
        pid = integer(v[par_at + 2 * k], 'parameter %d id' % k)
        if pid >= len(PROGRAM_PARAMS) or PROGRAM_PARAMS[pid] in (n for n, _ in params):
            raise bad('parameter %d has the id %d' % (k, pid))
        value = np.float32(v[par_at + 2 * k + 1])
        if not np.isfinite(value):
            raise bad('parameter %d (%s) is %r' % (k, PROGRAM_PARAMS[pid], float(value)))
        params.append((PROGRAM_PARAMS[pid], value))
    code, is_mask, open_ifs = [], [], []
    for i in range(n_code):
        w = v[code_at + 4 * i:code_at + 4 * i + 4]
        op = integer(w[0], 'op code %d' % i)
        if op >= len(PROGRAM_OPS):
            raise bad('op code %d at instruction %d' % (op, i))
        a = np.float32(w[1]) if op == _OP['Const'] else integer(w[1], 'operand a of %d' % i)
        b, c = integer(w[2], 'operand b of %d' % i), integer(w[3], 'operand c of %d' % i)
        if op == _OP['Input'] and a >= n_inputs:
            raise bad('instruction %d reads input %d of %d' % (i, a, n_inputs))
        if op == _OP['Gather'] and a >= n_tab:
            raise bad('instruction %d gathers from table %d of %d' % (i, a, n_tab))
        if op == _OP['Param'] and a >= n_par:
            raise bad('instruction %d reads parameter %d of %d' % (i, a, n_par))
        if op in (_OP['Input'], _OP['Const'], _OP['Param']) and open_ifs:
            raise bad('instruction %d (%s) lies inside a region' % (i, PROGRAM_OPS[op]))
        if op == _OP['EndIf'] and (not open_ifs or open_ifs.pop() != a):
            raise bad('instruction %d ends a region that is not the innermost open one' % i)
        operands = [b] if op == _OP['Gather'] else [a, b, c][:_ARITY[op]]
        for k, r in enumerate(operands):
            wants_mask = (op in (_OP['And'], _OP['Or'], _OP['Not'], _OP['If'])
                          or (op == _OP['Select'] and k == 0))
            if r >= i or is_mask[r] != wants_mask:
                raise bad('instruction %d (%s) reads register %d' % (i, PROGRAM_OPS[op], r))
        if op == _OP['If']:
            open_ifs.append(i)
        # None: a region's marker, which nothing reads.
        is_mask.append(None if op in (_OP['If'], _OP['EndIf']) else op in _GIVES_MASK)
        code.append((op, a, b, c))
    if open_ifs:
        raise bad('a region is not closed')
    outputs = []
    for k in range(n_out):
        r = integer(v[PROGRAM_HEADER_LEN + k], 'output %d' % k)
        if r >= n_code or is_mask[r] is not False:
            raise bad('output %d is register %d' % (k, r))
        outputs.append(r)
    return Program(n_inputs, tuple(outputs), code, tables, tuple(params))


def _fma32(a, b, c):
    """a * b + c rounded once to float32 (f32::mul_add): the product is exact
    in float64; the float64 sum, made round-to-odd with its exact error
    (TwoSum), then rounds to float32 as the exact value would."""
    a, b, c = (np.asarray(x, dtype=np.float64) for x in (a, b, c))
    p = a * b
    s = p + c
    bv = s - p
    err = (p - (s - bv)) + (c - bv)
    even = (np.asarray(s).view(np.int64) & 1) == 0
    fix = (err != 0) & np.isfinite(err) & even
    s = np.where(fix, np.nextafter(s, np.where(err > 0, np.inf, -np.inf)), s)
    return s.astype(np.float32)


def run_program(program, inputs, params=None, on_region=None):
    """Runs a program (an array of Brdf.export_program, or a decoded
    Program) on lanes of inputs (..., n_inputs): float32 outputs (...,
    n_outputs). params: {name: value} overriding the values the program's
    parameters were built with (names: PROGRAM_PARAMS; a name the program
    does not read is an error); Param gives the value (float32) to every
    lane. Every operation as the core's executor
    (rust-core/src/program/interpret.rs) does it, in float32: +, -, *, /,
    sqrt, floor correctly rounded; min/max return the other operand where
    one is NaN (the sign of a zero they return is unspecified, as there);
    Fma rounds once; comparisons give masks (1 or 0) that And/Or/Not/Select
    read as > 0; Gather reads table a at index b clamped into [0, len - 1]
    (NaN to 0), then truncated (an empty table gives 0). exp, log, sin, cos
    and atan2 are taken in float64 and rounded to float32: correctly
    rounded but for rare ties, as the C library's float32 functions the
    core calls are to within an ulp. A region (If .. EndIf) is computed on
    every lane and its registers set to 0 (False) on the lanes its masks
    exclude, which is what skipping them gives. on_region(position, mask),
    where given, is called at each If with its position in the code and the
    lanes it holds on (its mask and every enclosing one's; scripts/
    program_regions.py counts what a SIMD packet runs from them)."""
    p = program if isinstance(program, Program) else decode_program(program)
    x = np.asarray(inputs, dtype=np.float32)
    if x.ndim == 0 or x.shape[-1] != p.n_inputs:
        raise ValueError('stam_diffraction.core: the program takes inputs (..., %d), not %s'
                         % (p.n_inputs, x.shape))
    shape = x.shape[:-1]
    x = x.reshape(-1, p.n_inputs)
    values = [value for _, value in p.params]
    names = [name for name, _ in p.params]
    for name, value in (params or {}).items():
        if name not in names:
            raise ValueError('stam_diffraction.core: the program reads no parameter %r (it reads %s)'
                             % (name, ', '.join(names) or 'none'))
        values[names.index(name)] = np.float32(value)
    # Registers are dropped after their last reader (memory: the live
    # registers times the lanes, not the program's length).
    reads = [[b] if op == _OP['Gather'] else [a, b, c][:_ARITY[op]] for op, a, b, c in p.code]
    last = {}
    for i, rs in enumerate(reads):
        for r in rs:
            last[r] = i
    for r in p.outputs:
        last[r] = len(p.code)
    dead_after = collections.defaultdict(list)
    for r, i in last.items():
        dead_after[i].append(r)
    regs = []
    f32 = np.float32

    def f64(v):
        return np.asarray(v, dtype=np.float64)

    # Per open region: where it and every region around it hold.
    masks = []
    with np.errstate(all='ignore'):
        for op, a, b, c in p.code:
            name = PROGRAM_OPS[op]
            r = regs
            if name in ('If', 'EndIf'):
                if name == 'If':
                    masks.append(masks[-1] & r[a] if masks else r[a])
                    if on_region is not None:
                        on_region(len(regs), masks[-1])
                else:
                    masks.pop()
                regs.append(np.zeros((), f32))
                continue
            if name == 'Input':
                v = x[:, a]
            elif name == 'Const':
                v = np.asarray(a, dtype=f32)
            elif name == 'Param':
                v = np.asarray(values[a], dtype=f32)
            elif name == 'Add':
                v = r[a] + r[b]
            elif name == 'Sub':
                v = r[a] - r[b]
            elif name == 'Mul':
                v = r[a] * r[b]
            elif name == 'Div':
                v = r[a] / r[b]
            elif name == 'Min':
                v = np.fmin(r[a], r[b])
            elif name == 'Max':
                v = np.fmax(r[a], r[b])
            elif name == 'Fma':
                v = _fma32(r[a], r[b], r[c])
            elif name == 'Neg':
                v = -r[a]
            elif name == 'Abs':
                v = np.abs(r[a])
            elif name == 'Sqrt':
                v = np.sqrt(r[a])
            elif name == 'Exp':
                v = np.exp(f64(r[a]))
            elif name == 'Log':
                v = np.log(f64(r[a]))
            elif name == 'Sin':
                v = np.sin(f64(r[a]))
            elif name == 'Cos':
                v = np.cos(f64(r[a]))
            elif name == 'Atan2':
                v = np.arctan2(f64(r[a]), f64(r[b]))
            elif name == 'Floor':
                v = np.floor(r[a])
            elif name == 'Lt':
                v = r[a] < r[b]
            elif name == 'Le':
                v = r[a] <= r[b]
            elif name == 'Gt':
                v = r[a] > r[b]
            elif name == 'Ge':
                v = r[a] >= r[b]
            elif name == 'Eq':
                v = r[a] == r[b]
            elif name == 'Finite':
                v = np.isfinite(r[a])
            elif name == 'And':
                v = r[a] & r[b]
            elif name == 'Or':
                v = r[a] | r[b]
            elif name == 'Not':
                v = ~r[a]
            elif name == 'Select':
                v = np.where(r[a], r[b], r[c])
            else:  # Gather
                t = p.tables[a]
                i = np.asarray(r[b], dtype=np.float64)
                i = np.where(np.isnan(i), 0.0, np.clip(i, 0.0, max(len(t), 1) - 1))
                v = t[i.astype(np.int64)] if len(t) else np.zeros(i.shape, f32)
            if masks:
                v = np.where(masks[-1], v, False if op in _GIVES_MASK else 0.0)
            regs.append(np.asarray(v, dtype=bool if op in _GIVES_MASK else f32))
            for r in dead_after.get(len(regs) - 1, ()):
                regs[r] = None
    out = np.stack([np.broadcast_to(regs[k], (len(x),)) for k in p.outputs], axis=-1) \
        if p.outputs else np.zeros((len(x), 0), f32)
    return out.astype(f32).reshape(shape + (len(p.outputs),))
