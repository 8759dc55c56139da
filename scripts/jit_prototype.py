"""JIT prototype (docs/jit.md): the Gaussian rule "gaussian-v1" that the core
exports (stam_brdf_export_table) executed with Dr.Jit arrays, inside a Python
BSDF, in llvm_ad_rgb with Dr.Jit's DEFAULT flags (symbolic loops and calls).

    .venv/bin/python scripts/jit_prototype.py accuracy
    .venv/bin/python scripts/jit_prototype.py bench [--spp 48] [--processes 3]
    .venv/bin/python scripts/jit_prototype.py freeze
    .venv/bin/python scripts/jit_prototype.py chi2
    .venv/bin/python scripts/jit_prototype.py render <gaussian|gaussian4|roughconductor|native_evaluated> SPP

accuracy: max relative error of the Dr.Jit evaluation against the core
(ctypes) at random, grazing and near-mirror directions, spectral (f above
1e-6 of its peak) and RGB (the core's eval_rgb, which uses its per-material
node table; the prototype sums the exported rule's nodes directly).
bench: render time of a 128x128 path-traced sphere filling most of the frame
with the prototype against roughconductor (Beckmann, alpha = 2 sigma / T),
same variant and mode, each render in a fresh process; ratios printed
(native_evaluated: the native plugin in today's evaluated mode, for context).
freeze: dr.freeze of a render with the prototype, and a symbolic render of
another scene in the same process.

The prototype's sampling is a defensive mixture, 0.85 Beckmann normals
(alpha = 2 sigma / T, Mitsuba's MicrofacetDistribution) + 0.15 cosine, with
its exact pdf. The coherent lobe is left out (a prototype of the diffuse f).
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import time

import numpy as np

PROJECT_DIR = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(PROJECT_DIR, 'python'))
import stam_diffraction  # noqa: E402  (environment: libLLVM, cache dir)
from stam_diffraction import core  # noqa: E402

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402

mi.set_variant('llvm_ad_rgb')
# importing stam_diffraction switched evaluated mode on for the native
# plugin; the prototype runs with Dr.Jit's defaults.
stam_diffraction.set_evaluated_mode(False)

MATERIAL = {'surface': 'gaussian', 'sigma_um': 0.1, 'corr_um': 2.0}  # plugin_gaussian

# Header slots of the export (docs/jit.md, "Layout").
S = dict(FORMAT=0, MODEL=1, TOTAL_LEN=3, SIGMA_UM=4, CORR_X_UM=5, CORR_Y_UM=6,
         LAMBDA_MIN_NM=7, LAMBDA_MAX_NM=8, SERIES_OFFSET=9, SERIES_N_G=10, SERIES_N_RHO=11,
         SERIES_LN_G_MIN=12, SERIES_D_LN_G=13, SERIES_D_RHO=14, SERIES_G_MIN=15,
         SERIES_G_MAX=16, SERIES_RHO_MAX=17, FRESNEL_OFFSET=18, FRESNEL_ROWS=19,
         FRESNEL_COS_STEPS=20, FRESNEL_LAMBDA_OFFSET=21, FRESNEL_ROW_OF_NM_OFFSET=22,
         FRESNEL_ROW_OF_NM_LEN=23, FRESNEL_MAX_ROW_STEPS=24, RGB_OFFSET=25, RGB_NODES=26,
         RGB_COS_BINS=27, RGB_LAMBDA_OFFSET=28, SMALL_G_TERMS=29)

Float, UInt32, Int32 = mi.Float, mi.UInt32, mi.Int32


class GaussianRule:
    """The exported rule "gaussian-v1" on Dr.Jit arrays (mi.Float...): every
    number it uses comes from the export."""

    def __init__(self, e):
        e = np.asarray(e, dtype=np.float32)
        if int(e[S['FORMAT']]) != 1 or int(e[S['MODEL']]) != 1:
            raise ValueError('jit_prototype: not a "gaussian-v1" export')
        h = lambda k: float(e[S[k]])  # noqa: E731
        n = lambda k: int(e[S[k]])  # noqa: E731
        self.sigma, self.tx, self.ty = h('SIGMA_UM'), h('CORR_X_UM'), h('CORR_Y_UM')
        self.lam_min, self.lam_max = h('LAMBDA_MIN_NM'), h('LAMBDA_MAX_NM')
        self.n_g, self.n_rho = n('SERIES_N_G'), n('SERIES_N_RHO')
        self.ln_g_min = h('SERIES_LN_G_MIN')
        self.inv_d_ln_g, self.inv_d_rho = 1.0 / h('SERIES_D_LN_G'), 1.0 / h('SERIES_D_RHO')
        self.g_min, self.g_max, self.rho_max = h('SERIES_G_MIN'), h('SERIES_G_MAX'), h('SERIES_RHO_MAX')
        o = n('SERIES_OFFSET')
        self.series = Float(e[o:o + self.n_g * self.n_rho])
        self.small_terms = n('SMALL_G_TERMS')
        # Fresnel grid
        self.f_rows, self.f_steps = n('FRESNEL_ROWS'), n('FRESNEL_COS_STEPS')
        o = n('FRESNEL_OFFSET')
        self.f_table = Float(e[o:o + self.f_rows * (self.f_steps + 1)])
        o = n('FRESNEL_LAMBDA_OFFSET')
        lam = e[o:o + self.f_rows]
        self.f_lambda = Float(lam)
        self.f_lam_first, self.f_lam_last = float(lam[0]), float(lam[-1])
        o, m = n('FRESNEL_ROW_OF_NM_OFFSET'), n('FRESNEL_ROW_OF_NM_LEN')
        self.f_row_of_nm = UInt32(e[o:o + m].astype(np.uint32))
        self.f_row_of_nm_len = m
        self.f_max_steps = n('FRESNEL_MAX_ROW_STEPS')
        # RGB rule with F^2 folded in: (bins + 1) rows of N triples.
        self.n_nodes, self.bins = n('RGB_NODES'), n('RGB_COS_BINS')
        o = n('RGB_OFFSET')
        self.rgb_w = Float(e[o:o + (self.bins + 1) * self.n_nodes * 3])
        o = n('RGB_LAMBDA_OFFSET')
        self.node_lambda = [float(x) for x in e[o:o + self.n_nodes]]
        dr.eval(self.series, self.f_table, self.f_lambda, self.f_row_of_nm, self.rgb_w)

    # -- pieces ------------------------------------------------------------------
    @staticmethod
    def _bspline(t):
        s = 1.0 - t
        t2 = t * t
        t3 = t2 * t
        return [s * s * s * (1.0 / 6.0), 0.5 * t3 - t2 + 2.0 / 3.0,
                -0.5 * t3 + 0.5 * (t2 + t) + 1.0 / 6.0, t3 * (1.0 / 6.0)]

    def series_s(self, g, x, active):
        """S(g, x): table (bicubic B-spline in (ln g, rho)), small-g sum, 1/g form."""
        ln_g = dr.log(g)
        rho = dr.sqrt(x / (1.0 + g))
        in_table = active & (g >= self.g_min) & (g < self.g_max) & (rho < self.rho_max)
        fg = (ln_g - self.ln_g_min) * self.inv_d_ln_g + 1.0
        fx = rho * self.inv_d_rho + 1.0
        ig = dr.clip(Int32(dr.floor(fg)), 1, self.n_g - 3)
        ix = dr.clip(Int32(dr.floor(fx)), 1, self.n_rho - 3)
        wg = self._bspline(fg - Float(ig))
        wx = self._bspline(fx - Float(ix))
        base = UInt32((ig - 1) * self.n_rho + ix - 1)
        acc = Float(0.0)
        for a in range(4):
            row = Float(0.0)
            for b in range(4):
                row += wx[b] * dr.gather(Float, self.series, base + (a * self.n_rho + b), in_table)
            acc += wg[a] * row
        s_table = dr.exp(acc)
        # Small g: the first terms of the sum.
        s_small = Float(0.0)
        ln_fact = 0.0
        for m in range(1, self.small_terms + 1):
            ln_fact += np.log(m)
            s_small += dr.exp(-g + m * ln_g - (ln_fact + np.log(m)) - x * (1.0 / m))
        # Large g: (1/g) e^-y (1 + (y^2 - 4y + 2) / (2g)).
        y = x / g
        s_large = dr.exp(-y) / g * (1.0 + (y * y - 4.0 * y + 2.0) / (2.0 * g))
        s = dr.select(in_table, s_table, 0.0)
        s = dr.select(active & (g < self.g_min), s_small, s)
        s = dr.select(active & (g >= self.g_max), s_large, s)
        return s

    def fresnel(self, cos, lam, active):
        """F^2: Catmull-Rom over sqrt(cos) columns, linear between lambda rows."""
        steps = self.f_steps
        q = dr.sqrt(dr.clip(cos, 0.0, 1.0)) * steps
        i = dr.minimum(Int32(dr.floor(q)), steps - 1)
        t = q - Float(i)
        t2, t3 = t * t, t * t * t
        w = [0.5 * (-t3 + 2.0 * t2 - t), 0.5 * (3.0 * t3 - 5.0 * t2 + 2.0),
             0.5 * (-3.0 * t3 + 4.0 * t2 + t), 0.5 * (t3 - t2)]
        lam_c = dr.clip(lam, self.f_lam_first, self.f_lam_last)
        d = dr.minimum(UInt32(dr.floor(lam_c - self.f_lam_first)), self.f_row_of_nm_len - 1)
        r = dr.gather(UInt32, self.f_row_of_nm, d, active)
        for _ in range(self.f_max_steps):
            nxt = dr.gather(Float, self.f_lambda, r + 1, active)
            r = dr.select((r + 2 < self.f_rows) & (nxt <= lam_c), r + 1, r)
        x0 = dr.gather(Float, self.f_lambda, r, active)
        x1 = dr.gather(Float, self.f_lambda, r + 1, active)
        tl = dr.clip((lam_c - x0) / (x1 - x0), 0.0, 1.0)

        def row(rr):
            acc = Float(0.0)
            for j in range(4):
                col = UInt32(dr.clip(i - 1 + j, 0, steps))
                acc += w[j] * dr.gather(Float, self.f_table, rr * (steps + 1) + col, active)
            return acc
        lo, hi = row(r), row(r + 1)
        return lo + tl * (hi - lo)

    def _geometry(self, wi, wo):
        wi, wo = dr.normalize(wi), dr.normalize(wo)
        active = (wi.z > 1e-12) & (wo.z > 1e-12)
        u, v, w = -(wi.x + wo.x), -(wi.y + wo.y), -(wi.z + wo.z)
        # 1 + wi . wo as |wi + wo|^2 / 2: no cancellation near the grazing mirror.
        d = 0.5 * (u * u + v * v + w * w)
        geometric = d * d / (wi.z * wo.z)
        cos_half = dr.sqrt(dr.maximum(0.5 * d, 0.0))
        return active, u, v, w, geometric, cos_half

    def _kernel(self, k, u, v, w, active):
        """K at wavenumber k (1/um)."""
        a = k * self.sigma * w
        g = a * a
        x = 0.25 * k * k * (dr.square(self.tx * u) + dr.square(self.ty * v))
        pre = k * k * (self.tx * self.ty / (4.0 * dr.pi)) / (w * w)
        return pre * self.series_s(g, x, active)

    # -- the rule ----------------------------------------------------------------
    def eval_spectral(self, wi, wo, lam):
        """f(wi, wo; lambda) (1/sr, no cosine, no coherent lobe)."""
        active, u, v, w, geometric, cos_half = self._geometry(wi, wo)
        active &= (lam >= self.lam_min) & (lam <= self.lam_max)
        k = (2.0 * dr.pi * 1000.0) / lam
        f = self.fresnel(cos_half, lam, active) * geometric * self._kernel(k, u, v, w, active)
        return dr.select(active & (f > 0.0), f, 0.0)

    def eval_rgb(self, wi, wo, nodes=None):
        """f in linear sRGB: sum_j K(k_j) W_jc(cos_half) times G, gamut-mapped
        at constant luminance (the core's rule with its folded weights)."""
        active, u, v, w, geometric, cos_half = self._geometry(wi, wo)
        t = dr.clip(cos_half, 0.0, 1.0) * self.bins
        b = dr.minimum(UInt32(dr.floor(t)), self.bins - 1)
        frac = t - Float(b)
        rgb = mi.Color3f(0.0)
        n = self.n_nodes
        for j, lam in enumerate(self.node_lambda):
            kj = 2.0 * np.pi * 1000.0 / lam
            kern = self._kernel(kj, u, v, w, active)
            w0 = dr.gather(mi.Color3f, self.rgb_w, b * n + j, active)
            w1 = dr.gather(mi.Color3f, self.rgb_w, (b + 1) * n + j, active)
            rgb += kern * (w0 + frac * (w1 - w0))
        rgb *= geometric
        # Gamut mapping at constant luminance (spectrum::gamut_map).
        lo = dr.minimum(dr.minimum(rgb.x, rgb.y), rgb.z)
        y = 0.2126 * rgb.x + 0.7152 * rgb.y + 0.0722 * rgb.z
        s = lo / (lo - y)
        mapped = dr.select(y > 0.0, rgb + s * (y - rgb), 0.0)
        rgb = dr.select(lo < 0.0, mapped, rgb)
        return dr.select(active, dr.maximum(rgb, 0.0), 0.0)


class StamJitBSDF(mi.BSDF):
    """type="stam_jit": the prototype BSDF (diffuse f only, RGB)."""

    def __init__(self, props):
        mi.BSDF.__init__(self, props)
        params = json.loads(props.get('params', json.dumps(MATERIAL)))
        with core.Brdf(params) as brdf:
            self.rule = GaussianRule(brdf.export_table())
        self.alpha = float(min(max(2.0 * self.rule.sigma / np.sqrt(self.rule.tx * self.rule.ty), 1e-3), 2.0))
        self.p_cos = 0.15
        self.m_flags = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide
        self.m_components = [self.m_flags]

    def _distr(self):
        return mi.MicrofacetDistribution(mi.MicrofacetType.Beckmann, self.alpha, False)

    def _pdf(self, wi, wo, active):
        m = dr.normalize(wi + wo)
        distr = self._distr()
        p_m = distr.pdf(wi, m) / (4.0 * dr.abs(dr.dot(wo, m)))
        p_c = mi.warp.square_to_cosine_hemisphere_pdf(wo)
        p = (1.0 - self.p_cos) * p_m + self.p_cos * p_c
        ok = active & (mi.Frame3f.cos_theta(wi) > 0.0) & (mi.Frame3f.cos_theta(wo) > 0.0)
        return dr.select(ok & dr.isfinite(p), p, 0.0)

    def sample(self, ctx, si, sample1, sample2, active=True):
        wi = si.wi
        use_cos = sample1 < self.p_cos
        m, _ = self._distr().sample(wi, sample2)
        wo_m = mi.reflect(wi, m)
        wo_c = mi.warp.square_to_cosine_hemisphere(sample2)
        wo = dr.select(use_cos, wo_c, wo_m)
        bs = mi.BSDFSample3f()
        bs.wo = wo
        bs.pdf = self._pdf(wi, wo, active)
        bs.eta = 1.0
        bs.sampled_type = mi.UInt32(+mi.BSDFFlags.GlossyReflection)
        bs.sampled_component = mi.UInt32(0)
        f = self.rule.eval_rgb(wi, wo) * mi.Frame3f.cos_theta(wo)
        ok = active & (bs.pdf > 0.0)
        return bs, dr.select(ok, f / bs.pdf, 0.0)

    def eval(self, ctx, si, wo, active=True):
        f = self.rule.eval_rgb(si.wi, wo) * mi.Frame3f.cos_theta(wo)
        return dr.select(active, f, 0.0)

    def pdf(self, ctx, si, wo, active=True):
        return self._pdf(si.wi, wo, active)

    def eval_pdf(self, ctx, si, wo, active=True):
        return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)

    def traverse(self, callback):
        pass

    def to_string(self):
        return 'StamJitBSDF[%s]' % json.dumps(MATERIAL)


mi.register_bsdf('stam_jit', lambda props: StamJitBSDF(props))


# -- accuracy --------------------------------------------------------------------
def _directions(rng, n, zmin, zmax):
    z = rng.uniform(zmin, zmax, n)
    phi = rng.uniform(0, 2 * np.pi, n)
    r = np.sqrt(np.maximum(1 - z * z, 0))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], -1)


def _pairs(rng, n):
    """Random, grazing (either side within 5 degrees of the horizon) and near-mirror."""
    wi = _directions(rng, n, 0, 1)
    wo = _directions(rng, n, 0, 1)
    q = n // 4
    wi[q:2 * q] = _directions(rng, q, 1e-4, 0.09)
    wo[2 * q:3 * q] = _directions(rng, q, 1e-4, 0.09)
    mirror = wi[3 * q:] * np.array([-1, -1, 1])
    jitter = _directions(rng, n - 3 * q, -1, 1) * 0.05
    wo[3 * q:] = mirror + jitter
    wo[3 * q:] /= np.linalg.norm(wo[3 * q:], axis=-1, keepdims=True)
    return wi.astype(np.float32), wo.astype(np.float32)


def _vec(a):
    return mi.Vector3f(Float(a[:, 0]), Float(a[:, 1]), Float(a[:, 2]))


def accuracy(n=200_000):
    materials = [
        MATERIAL,
        {'surface': 'gaussian', 'sigma_um': 0.1, 'corr_um': 2.0, 'fresnel': 0.9},
        {'surface': 'gaussian', 'sigma_um': 0.5, 'corr_um': 5.0, 'fresnel': 'gold'},
        {'surface': 'gaussian', 'sigma_um': 0.02, 'corr_um': 1.0, 'fresnel': 'copper'},
        {'surface': 'gaussian', 'sigma_um': 0.15, 'corr_x_um': 1.0, 'corr_y_um': 15.0},
        {'surface': 'gaussian', 'sigma_um': 8.0, 'corr_um': 40.0, 'fresnel': 0.9},
    ]
    rng = np.random.default_rng(5)
    rows = []
    for params in materials:
        with core.Brdf(params) as brdf:
            rule = GaussianRule(brdf.export_table())
            wi, wo = _pairs(rng, n)
            lam = rng.uniform(360, 830, n).astype(np.float32)
            ref = brdf.eval_spectral(wi, wo, lam)
            got = np.array(rule.eval_spectral(_vec(wi), _vec(wo), Float(lam)), dtype=np.float64)
            peak = ref.max()
            sel = ref >= 1e-6 * peak
            rel = np.abs(got[sel] - ref[sel]) / ref[sel]
            spurious = np.max(np.where(~sel, got, 0)) / peak
            # RGB against the core's eval_rgb (its node table) on the same pairs.
            ref_rgb = brdf.eval_rgb(wi, wo)
            c = rule.eval_rgb(_vec(wi), _vec(wo))
            got_rgb = np.stack([np.array(c.x), np.array(c.y), np.array(c.z)], -1)
            lum = ref_rgb @ np.array([0.2126, 0.7152, 0.0722])
            sel_rgb = lum >= 1e-6 * lum.max()
            rel_rgb = (np.abs(got_rgb - ref_rgb).max(-1)[sel_rgb] / lum[sel_rgb])
            row = dict(material=params, pairs=n, checked=int(sel.sum()),
                       spectral_max_rel=float(rel.max()),
                       spectral_p99_rel=float(np.quantile(rel, 0.99)),
                       spurious_below=float(spurious),
                       rgb_max_rel_to_luminance=float(rel_rgb.max()),
                       rgb_p99=float(np.quantile(rel_rgb, 0.99)))
            rows.append(row)
            print(json.dumps(row))
    # Bad input: NaN, below the horizon, lambda 0.
    with core.Brdf(MATERIAL) as brdf:
        rule = GaussianRule(brdf.export_table())
    bad_wi = np.array([[np.nan, 0, 1], [0, 0, 1], [0, 0, 1], [0, 0, 0]], np.float32)
    bad_wo = np.array([[0, 0, 1], [0, 0, -1], [0, 0, 1], [0, 0, 1]], np.float32)
    lam = Float(np.array([500, 500, 0, 500], np.float32))
    f = np.array(rule.eval_spectral(_vec(bad_wi), _vec(bad_wo), lam))
    c = rule.eval_rgb(_vec(bad_wi), _vec(bad_wo))
    ok = np.all(np.isfinite(f)) and np.all(f >= 0) and np.all(np.isfinite(np.array(c.x)))
    print(json.dumps({'bad_input_finite_non_negative': bool(ok), 'values': f.tolist()}))
    return rows


# -- rendering -------------------------------------------------------------------
def scene(kind, spp):
    sigma, corr = MATERIAL['sigma_um'], MATERIAL['corr_um']
    if kind == 'roughconductor':
        bsdf = {'type': 'roughconductor', 'distribution': 'beckmann', 'alpha': 2 * sigma / corr}
    elif kind == 'gaussian':
        bsdf = {'type': 'stam_jit', 'params': json.dumps(MATERIAL)}
    elif kind == 'native_evaluated':
        bsdf = dict({'type': 'diffraction'}, **MATERIAL)
    elif kind == 'gaussian4':
        bsdf = {'type': 'stam_jit', 'params': json.dumps(dict(MATERIAL, rgb_nodes=4))}
    else:
        raise ValueError(kind)
    return {
        'type': 'scene',
        'integrator': {'type': 'path', 'max_depth': 6},
        'sensor': {
            'type': 'perspective', 'fov': 30,
            'to_world': mi.ScalarTransform4f().look_at(origin=[0, 0, 4.2], target=[0, 0, 0],
                                                       up=[0, 1, 0]),
            'film': {'type': 'hdrfilm', 'width': 128, 'height': 128,
                     'rfilter': {'type': 'box'}},
            'sampler': {'type': 'independent', 'sample_count': spp},
        },
        'sphere': {'type': 'sphere', 'bsdf': bsdf},
        'floor': {'type': 'rectangle', 'bsdf': {'type': 'diffuse'},
                  'to_world': mi.ScalarTransform4f().translate([0, -1.0, 0]).rotate([1, 0, 0], -90)
                  .scale(10)},
        'light': {'type': 'rectangle',
                  'to_world': mi.ScalarTransform4f().look_at(origin=[2, 3, 3], target=[0, 0, 0],
                                                             up=[0, 1, 0]).scale(0.7),
                  'emitter': {'type': 'area', 'radiance': {'type': 'rgb', 'value': 20.0}}},
        'env': {'type': 'constant', 'radiance': {'type': 'rgb', 'value': 0.2}},
    }


def render_once(kind, spp, repeats=3):
    """In this process: first render (trace + compile) then `repeats` more."""
    if kind == 'native_evaluated':
        # The native plugin as it stands: evaluated mode (for context only).
        stam_diffraction.set_evaluated_mode(True)
    flags_default = (dr.flag(dr.JitFlag.SymbolicLoops) and dr.flag(dr.JitFlag.SymbolicCalls))
    sc = mi.load_dict(scene(kind, spp))
    times = []
    img = None
    for i in range(repeats + 1):
        t0 = time.perf_counter()
        img = mi.render(sc, seed=i)
        dr.eval(img)
        dr.sync_thread()
        times.append(time.perf_counter() - t0)
    arr = np.array(img)
    return {'kind': kind, 'spp': spp, 'symbolic': bool(flags_default), 'first_s': times[0],
            'steady_s': min(times[1:]), 'mean': float(arr.mean()),
            'finite': bool(np.all(np.isfinite(arr)))}


def bench(spp, processes):
    kinds = ['roughconductor', 'gaussian', 'gaussian4', 'native_evaluated']
    results = {k: [] for k in kinds}
    for p in range(processes):
        for k in kinds:
            out = subprocess.run([sys.executable, os.path.abspath(__file__), 'render', k, str(spp)],
                                 capture_output=True, text=True, check=True)
            r = json.loads(out.stdout.strip().splitlines()[-1])
            results[k].append(r)
            print(json.dumps(r), flush=True)
    base = statistics.median(r['steady_s'] for r in results['roughconductor'])
    base_first = statistics.median(r['first_s'] for r in results['roughconductor'])
    for k in kinds:
        steady = statistics.median(r['steady_s'] for r in results[k])
        first = statistics.median(r['first_s'] for r in results[k])
        print('%-15s steady %.3f s (%.2fx roughconductor)  first render %.2f s (%.2fx)'
              % (k, steady, steady / base, first, first / base_first))


def freeze_check(spp=8):
    """dr.freeze of a render with the prototype (one recording, replays equal
    to the plain render), then a symbolic render of another scene in the
    same process."""
    sc = mi.load_dict(scene('gaussian', spp))
    plain = np.array(mi.render(sc, seed=1))

    @dr.freeze
    def frozen(scene_, seed):
        return mi.render(scene_, seed=seed)
    imgs = []
    for s in (1, 2, 1):
        img = frozen(sc, dr.opaque(mi.UInt32, s))
        dr.eval(img)
        imgs.append(np.array(img))
    other = np.array(mi.render(mi.load_dict(scene('roughconductor', spp))))
    print(json.dumps({
        'frozen_equals_plain': bool(np.array_equal(imgs[0], plain)),
        'replay_equals_first': bool(np.array_equal(imgs[2], imgs[0])),
        'other_seed_differs': bool(not np.array_equal(imgs[1], imgs[0])),
        'recordings': int(frozen.n_recordings),
        'other_scene_symbolic_finite': bool(np.isfinite(other).all()),
        'symbolic_flags': bool(dr.flag(dr.JitFlag.SymbolicCalls) and dr.flag(dr.JitFlag.SymbolicLoops)),
    }))


def chi2_check():
    """Mitsuba's chi-square test of the prototype's sampling against its pdf
    (chi2_gaussian of tests/materials.json) at normal, oblique and grazing
    incidence."""
    from mitsuba.chi2 import BSDFAdapter, ChiSquareTest, SphericalDomain
    params = json.dumps({'surface': 'gaussian', 'sigma_um': 0.15, 'corr_um': 0.8})
    for z in (1.0, 0.5, 0.1):
        wi = [(1 - z * z) ** 0.5, 0.0, z]
        sample_func, pdf_func = BSDFAdapter(
            'stam_jit', '<string name="params" value=\'%s\'/>' % params, wi=wi)
        test = ChiSquareTest(domain=SphericalDomain(), sample_func=sample_func,
                             pdf_func=pdf_func, sample_dim=3)
        ok = test.run()
        print(json.dumps({'wi_z': z, 'passed': bool(ok),
                          'result': test.messages.strip().splitlines()[-1]}))


if __name__ == '__main__':
    ap = argparse.ArgumentParser()
    ap.add_argument('what', choices=['accuracy', 'bench', 'render', 'freeze', 'chi2'])
    ap.add_argument('args', nargs='*')
    ap.add_argument('--spp', type=int, default=48)
    ap.add_argument('--processes', type=int, default=3)
    a = ap.parse_args()
    if a.what == 'accuracy':
        accuracy()
    elif a.what == 'chi2':
        chi2_check()
    elif a.what == 'freeze':
        freeze_check()
    elif a.what == 'bench':
        bench(a.spp, a.processes)
    else:
        print(json.dumps(render_once(a.args[0], int(a.args[1]))))
