"""stam_mitsuba: set up Mitsuba 3 for the project's `diffraction` BSDF plugin.

    import sys; sys.path.insert(0, 'scripts')
    import stam_mitsuba
    mi = stam_mitsuba.setup('llvm_ad_rgb')
    bsdf = mi.load_dict({'type': 'diffraction', 'surface': 'cd'})

setup(variant) does, in this order:
  * for llvm_* variants, before drjit/mitsuba are imported: DRJIT_LIBLLVM_PATH
    -> Debian's libLLVM.so.19.1 (the default system LLVM 14/15 is refused or
    crashes) and DRJIT_CACHE_DIR -> <project>/.drjit-cache (unless already set);
  * mi.set_variant(variant);
  * appends <project>/build to mi.file_resolver(), so build/plugins/diffraction.so
    loads as type="diffraction";
  * for JIT variants, switches dr.JitFlag.SymbolicLoops and SymbolicCalls off
    (evaluated mode: the plugin calls native code on concrete arrays).
It returns the mitsuba module.

Run as a script (`python scripts/stam_mitsuba.py [variant]`, default scalar_rgb)
it loads a compact disc BSDF and prints it: a check that the plugin loads.
"""

import os
import sys

PROJECT_DIR = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BUILD_DIR = os.path.join(PROJECT_DIR, 'build')
PLUGIN_PATH = os.path.join(BUILD_DIR, 'plugins', 'diffraction.so')
CACHE_DIR = os.path.join(PROJECT_DIR, '.drjit-cache')
LIBLLVM_CANDIDATES = (
    '/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1',
    '/usr/lib/llvm-19/lib/libLLVM.so.19.1',
    '/usr/lib/x86_64-linux-gnu/libLLVM-19.so',
)

SUPPORTED_VARIANTS = ('scalar_rgb', 'scalar_spectral', 'scalar_spectral_polarized',
                      'llvm_ad_rgb', 'llvm_ad_mono', 'llvm_ad_spectral',
                      'llvm_ad_mono_polarized', 'llvm_ad_spectral_polarized')


def configure_env():
    """Environment for Dr.Jit's LLVM backend (DRJIT_LIBLLVM_PATH, DRJIT_CACHE_DIR),
    unless already set. Must run before drjit is first imported; harmless for
    scalar variants. setup() calls it for llvm_* variants."""
    if 'DRJIT_LIBLLVM_PATH' not in os.environ:
        for path in LIBLLVM_CANDIDATES:
            if os.path.exists(path):
                os.environ['DRJIT_LIBLLVM_PATH'] = path
                break
        else:
            raise RuntimeError('stam_mitsuba: libLLVM 19 not found (%s); run '
                               'scripts/setup.sh' % ', '.join(LIBLLVM_CANDIDATES))
    if 'DRJIT_CACHE_DIR' not in os.environ:
        os.makedirs(CACHE_DIR, exist_ok=True)
        os.environ['DRJIT_CACHE_DIR'] = CACHE_DIR


def setup(variant='scalar_rgb', build_dir=BUILD_DIR, evaluated=True):
    """Select `variant`, make type="diffraction" loadable; returns `mitsuba`."""
    if variant.startswith('cuda'):
        raise ValueError('stam_mitsuba: CUDA variants are not supported by the '
                         'diffraction plugin (the core runs on the CPU)')
    is_llvm = variant.startswith('llvm')
    if is_llvm:
        if 'drjit' in sys.modules and 'DRJIT_LIBLLVM_PATH' not in os.environ:
            # Dr.Jit reads the variable when the LLVM backend first initialises;
            # set it anyway, but say why it may be too late.
            import warnings
            warnings.warn('stam_mitsuba.setup(): drjit was imported before '
                          'DRJIT_LIBLLVM_PATH was set; call setup() first')
        configure_env()

    import drjit as dr
    import mitsuba as mi

    mi.set_variant(variant)
    if not os.path.exists(os.path.join(build_dir, 'plugins', 'diffraction.so')):
        raise FileNotFoundError('stam_mitsuba: %s/plugins/diffraction.so not built '
                                '(run `make plugin`)' % build_dir)
    fr = mi.file_resolver()
    if not any(os.path.abspath(str(p)) == os.path.abspath(build_dir)
               for p in _resolver_paths(fr)):
        fr.append(build_dir)

    if is_llvm and evaluated:
        dr.set_flag(dr.JitFlag.SymbolicLoops, False)
        dr.set_flag(dr.JitFlag.SymbolicCalls, False)
    return mi


def _resolver_paths(fr):
    try:
        return [fr[i] for i in range(len(fr))]
    except TypeError:
        return []


if __name__ == '__main__':
    v = sys.argv[1] if len(sys.argv) > 1 else 'scalar_rgb'
    mi = setup(v)
    print(mi.load_dict({'type': 'diffraction', 'surface': 'cd'}))
