"""stam_accuracy: how the JIT path's values are compared with the core's
(tests/test_jit.py, scripts/gpu_check.py; docs/jit_measured.md, "Accuracy").

    import stam_accuracy as acc
    err = acc.relative_errors(got, ref)                 # spectral: (.., n)
    err = acc.relative_errors(got, ref, axis=0)         # RGB: channels first
    spread = acc.conditioning(lambda a, o, l: core(a, o, l), ref, (wi, wo, lam))
    assert np.max(err - spread) <= acc.SPECTRAL_TOL

The JIT variants see f32 directions and wavelengths. Where f is
ill-conditioned in them (a compact disc's narrow order flanks and grazing
order-0 tails: u = -(wi + wo) is a small difference of order-one numbers),
one ulp of an input moves f by up to ~1e-3, which no f32 evaluation can
beat: `conditioning` measures that spread with the core (f64) at inputs
moved by one f32 ulp, and the tolerances apply beyond it, pair by pair.
"""

import numpy as np

# Spectral: the 1e-4 relative, where f is above FLOOR of its peak.
SPECTRAL_TOL = 1e-4
# RGB: the core's documented error of its RGB rule, per model, of the pair's
# largest channel (docs/implementation.md: smooth kernels worst 3.3e-4
# against the 1 nm reference; gratings 0.31% against a reference that
# resolves their peaks); the JIT RGB and the core's eval_rgb are two
# evaluations of the same rule, each within it.
RGB_DOCUMENTED = {'gaussian': 3.5e-4, 'fractal': 3.5e-4, 'periodic': 3.1e-3,
                  'heightmap': 3.5e-4}  # docs/heightmap.md: 1e-5 (Gaussian map)
# Of the peak: below it, errors are measured against the floor.
FLOOR = 1e-6


def relative_errors(got, ref, axis=None, floor=FLOOR):
    """|got - ref| / max(scale, floor * peak); scale = |ref| (spectral) or the
    pair's largest channel (RGB, axis = the channel axis)."""
    scale = np.abs(ref) if axis is None else np.max(np.abs(ref), axis=axis, keepdims=True)
    peak = np.max(np.abs(ref))
    return np.abs(got - ref) / np.maximum(scale, floor * peak)


def as_f32(x):
    """The values an f32 array holds, as float64."""
    return np.asarray(x, dtype=np.float32).astype(np.float64)


def ulp_nudge(v, rng):
    """v (float32 values) with each component moved by one f32 ulp up or
    down, at random; as float64."""
    v32 = np.asarray(v, dtype=np.float32)
    up = rng.random(v32.shape) < 0.5
    return np.where(up, np.nextafter(v32, np.float32(np.inf)),
                    np.nextafter(v32, np.float32(-np.inf))).astype(np.float64)


def conditioning(core, ref, inputs, axis=None, nudges=4, seed=0):
    """The largest relative change of core(*inputs) (= ref) over `nudges`
    random one-ulp moves of every input, per value (as relative_errors)."""
    rng = np.random.default_rng(seed)
    return np.max([relative_errors(core(*[ulp_nudge(x, rng) for x in inputs]), ref, axis)
                   for _ in range(nudges)], axis=0)
