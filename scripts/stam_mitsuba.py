"""stam_mitsuba: set up Mitsuba 3 for the project's scripts and tests, with the
package stam_diffraction from this checkout (python/).

    import sys; sys.path.insert(0, 'scripts')
    import stam_mitsuba
    mi = stam_mitsuba.setup('llvm_ad_rgb')
    bsdf = mi.load_dict({'type': 'diffraction', 'surface': 'cd'})

Importing this module imports stam_diffraction from python/ (what a user gets
from the wheel, here with the checkout's build outputs: build/plugins/
diffraction.so, target/release/libstam.so), which, before drjit is imported,
points DRJIT_LIBLLVM_PATH at a libLLVM >= 17 and DRJIT_CACHE_DIR at
<project>/.drjit-cache (unless set) and makes type="diffraction" loadable in
every variant. Dr.Jit's flags stay its defaults.

setup(variant) checks that the plugin is built (and, for cuda_* variants, that
Dr.Jit has a CUDA device) and selects the variant; it returns the mitsuba
module.

Run as a script (`python scripts/stam_mitsuba.py [variant]`, default scalar_rgb)
it loads a compact disc BSDF and prints it: a check that the plugin loads.
"""

import os
import sys

PROJECT_DIR = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(PROJECT_DIR, 'python'))
import stam_diffraction  # noqa: E402

def freeze_failure(scene, spp=0):
    """Mitsuba's own error, its messages joined, where it cannot record a
    dr.freeze-d render of `scene` (one without the plugin) in the current
    variant (3.9.1, spectral variants: its CIE table is not traversed);
    None where it can. spp 0: the scene's own."""
    import drjit as dr
    import mitsuba as mi
    frozen = dr.freeze(lambda scene_, seed: mi.render(scene_, spp=spp, seed=seed))
    try:
        dr.eval(frozen(scene, dr.opaque(mi.UInt32, 1)))
    except RuntimeError as e:
        msgs = []
        while e is not None:
            msgs.append(str(e).strip())
            e = e.__cause__ or e.__context__
        return ' '.join(msgs)
    return None


def setup(variant='scalar_rgb'):
    """Select `variant` for type="diffraction"; returns `mitsuba`."""
    if not os.path.exists(stam_diffraction.PLUGIN):
        raise FileNotFoundError('stam_mitsuba: %s not built (run `make plugin`)'
                                % stam_diffraction.PLUGIN)
    import mitsuba as mi
    if variant.startswith('cuda'):
        import drjit as dr
        if not dr.has_backend(dr.JitBackend.CUDA):
            raise RuntimeError('stam_mitsuba: %s needs a CUDA device, and Dr.Jit has no '
                               'CUDA backend here' % variant)
    mi.set_variant(variant)
    return mi


if __name__ == '__main__':
    v = sys.argv[1] if len(sys.argv) > 1 else 'scalar_rgb'
    mi = setup(v)
    print(mi.load_dict({'type': 'diffraction', 'surface': 'cd'}))
