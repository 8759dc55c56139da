"""stam_diffraction: Stam's "Diffraction Shaders" (SIGGRAPH 1999) as the Mitsuba 3
BSDF type="diffraction", for the stock mitsuba wheel.

    import stam_diffraction               # before or after mi.set_variant
    import mitsuba as mi
    mi.set_variant('scalar_spectral')
    bsdf = mi.load_dict({'type': 'diffraction', 'surface': 'cd'})

Importing the package:
  * checks that the installed mitsuba and drjit are the versions the plugin was
    compiled against (their C++ ABI must match exactly); otherwise it raises
    VersionMismatchError (an ImportError) naming both, before mitsuba is loaded;
  * if drjit is not imported yet and DRJIT_LIBLLVM_PATH is unset, points it at
    the newest libLLVM >= 17 found in the system's library directories (the
    llvm_* variants need LLVM >= 17; Dr.Jit reads the variable when it is first
    imported, so afterwards it is too late). In a source checkout it also sets
    DRJIT_CACHE_DIR, if unset, to the checkout's .drjit-cache;
  * appends PLUGIN_DIR to Mitsuba's FileResolver, which is shared by all
    variants: type="diffraction" then loads in every variant, whether
    mi.set_variant was called before or after.
It leaves Dr.Jit's flags alone: the JIT variants (llvm_ad_*, cuda_ad_*) run
the core's programs with Dr.Jit's default flags (symbolic loops and calls,
dr.freeze).

The `mitsuba` command finds the plugin with
`mitsuba -a "$(python -m stam_diffraction --plugin-dir)" scene.xml`.
stam_diffraction.core is the core's C ABI through ctypes, for scripted
comparisons (core.Brdf(params).eval_rgb(wi, wo), ...).
"""

import glob
import json
import os
import re
import sys
from importlib import metadata

from ._layout import ABI_RECORD, CORE_LIB, HEADER, PLUGIN, PLUGIN_DIR, SOURCE_ROOT

__all__ = ['PLUGIN_DIR', 'PLUGIN', 'CORE_LIB', 'HEADER', 'VersionMismatchError',
           'compiled_versions', 'installed_versions', 'check_versions', 'find_libllvm']

# The packages whose C++ ABI the plugin follows exactly (docs/mitsuba.md).
ABI_PACKAGES = ('mitsuba', 'drjit')

# Dr.Jit's LLVM backend needs LLVM >= 17 (older ones are refused or crash).
LLVM_MIN_MAJOR = 17
LLVM_PATTERNS = ('/usr/lib/x86_64-linux-gnu/libLLVM[.-]*', '/usr/lib/llvm-*/lib/libLLVM[.-]*',
                 '/usr/lib64/libLLVM[.-]*', '/usr/local/lib/libLLVM[.-]*')


class VersionMismatchError(ImportError):
    """The installed mitsuba/drjit are not those the plugin was compiled against."""


def compiled_versions(path=ABI_RECORD):
    """{package: version} the plugin was compiled against (the file the build
    writes beside it), or None where no plugin was built (source checkout)."""
    try:
        with open(path) as f:
            return json.load(f)
    except FileNotFoundError:
        return None


def installed_versions():
    """{package: version or None} of the installed mitsuba and drjit (from
    their metadata: nothing is imported)."""
    found = {}
    for name in ABI_PACKAGES:
        try:
            found[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            found[name] = None
    return found


def check_versions(compiled=None, installed=None):
    """Raise VersionMismatchError unless the installed mitsuba and drjit are
    those of `compiled` (default: the plugin's record)."""
    compiled = compiled_versions() if compiled is None else compiled
    if compiled is None:
        return
    installed = installed_versions() if installed is None else installed
    if all(installed.get(p) == compiled[p] for p in ABI_PACKAGES):
        return

    def describe(versions):
        return ' and '.join('%s %s' % (p, versions.get(p) or '(not installed)')
                            for p in ABI_PACKAGES)
    raise VersionMismatchError(
        'stam_diffraction: the diffraction plugin (%s) was compiled against %s, but this '
        'environment has %s. Mitsuba\'s C++ ABI must match exactly: install %s.'
        % (PLUGIN, describe(compiled), describe(installed),
           ' '.join('%s==%s' % (p, compiled[p]) for p in ABI_PACKAGES)))


def find_libllvm(min_major=LLVM_MIN_MAJOR, patterns=LLVM_PATTERNS):
    """Path of the newest libLLVM with major version >= min_major among the
    files matching `patterns`, or None."""
    found = []
    for pattern in patterns:
        for path in glob.glob(pattern):
            m = (re.match(r'libLLVM(?:\.so\.|-)(\d+)', os.path.basename(path))
                 or re.search(r'/llvm-(\d+)/', path))
            if m and int(m.group(1)) >= min_major:
                found.append((int(m.group(1)), path))
    return max(found)[1] if found else None


def _configure_drjit_environment():
    if 'drjit' in sys.modules:
        return
    if 'DRJIT_LIBLLVM_PATH' not in os.environ:
        path = find_libllvm()
        if path:
            os.environ['DRJIT_LIBLLVM_PATH'] = path
    if SOURCE_ROOT and 'DRJIT_CACHE_DIR' not in os.environ:
        cache = os.path.join(SOURCE_ROOT, '.drjit-cache')
        os.makedirs(cache, exist_ok=True)
        os.environ['DRJIT_CACHE_DIR'] = cache


def _register_plugin_dir():
    import mitsuba as mi
    fr = mi.file_resolver()
    if not any(os.path.abspath(str(fr[i])) == PLUGIN_DIR for i in range(len(fr))):
        fr.append(PLUGIN_DIR)


check_versions()
_configure_drjit_environment()
_register_plugin_dir()
# The distribution's version (the core's), None in a source checkout.
__version__ = None if SOURCE_ROOT else metadata.version('stam-diffraction')
