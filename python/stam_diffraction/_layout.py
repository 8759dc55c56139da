"""Where the package's compiled files lie.

Installed from the wheel, they lie in the package: plugins/diffraction.so (the
Mitsuba plugin, the core linked in statically), plugins/diffraction.abi.json
(the mitsuba and drjit versions it was compiled against), libstam.so (the core
as a shared library, for stam_diffraction.core) and include/stam.h.

In a source checkout (the checkout's python/ directory on sys.path), they are
the build outputs of the checkout: build/plugins/ (`make plugin`),
target/release/libstam.so (`make core`) and rust-core/include/stam.h.

This module imports nothing but os: the package's __init__ and core read it.
"""

import os

PACKAGE_DIR = os.path.dirname(os.path.abspath(__file__))

if os.path.exists(os.path.join(PACKAGE_DIR, 'include', 'stam.h')):
    SOURCE_ROOT = None
    PLUGIN_DIR = PACKAGE_DIR
    CORE_LIB = os.path.join(PACKAGE_DIR, 'libstam.so')
    HEADER = os.path.join(PACKAGE_DIR, 'include', 'stam.h')
else:
    SOURCE_ROOT = os.path.dirname(os.path.dirname(PACKAGE_DIR))
    PLUGIN_DIR = os.path.join(SOURCE_ROOT, 'build')
    CORE_LIB = os.path.join(SOURCE_ROOT, 'target', 'release', 'libstam.so')
    HEADER = os.path.join(SOURCE_ROOT, 'rust-core', 'include', 'stam.h')

# PLUGIN_DIR is the directory Mitsuba's FileResolver needs: it loads
# type="diffraction" from <entry>/plugins/diffraction.so.
PLUGIN = os.path.join(PLUGIN_DIR, 'plugins', 'diffraction.so')
ABI_RECORD = os.path.join(PLUGIN_DIR, 'plugins', 'diffraction.abi.json')
