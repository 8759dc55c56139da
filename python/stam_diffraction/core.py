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

Methods follow the header's functions one to one (stam_brdf_<method>); see
stam.h for the exact contract of each.
"""

import ctypes
import json
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
        'stam_brdf_export_table': (sz, [vp, fp, sz]),
        'stam_brdf_warnings': (ctypes.c_char_p, [vp]),
        'stam_version': (ctypes.c_char_p, []),
    }
    for name, (res, args) in sig.items():
        fn = getattr(L, name)
        fn.restype = res
        fn.argtypes = args
    _lib = L
    return L


def version():
    """The core's version string (stam_version)."""
    return lib().stam_version().decode()


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

    def export_table(self):
        """The JIT export (stam_brdf_export_table; layout and rule in
        docs/jit.md) as a float32 array, or None when the material has none
        (only Gaussian surfaces with Stam's formula have one)."""
        n = int(self._lib.stam_brdf_export_table(self._handle(), None, 0))
        if n == 0:
            return None
        out = np.empty(n, dtype=np.float32)
        written = int(self._lib.stam_brdf_export_table(self._handle(), _ptr(out), n))
        if written != n:
            raise RuntimeError('stam_diffraction.core: export_table wrote %d of %d' % (written, n))
        return out

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
