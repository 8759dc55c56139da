"""python -m stam_diffraction [--plugin-dir]

--plugin-dir prints the directory to give the `mitsuba` command, in which it
finds plugins/diffraction.so:

    mitsuba -m scalar_spectral -a "$(python -m stam_diffraction --plugin-dir)" scene.xml

(llvm_* variants also need `-W -W`, which switches Dr.Jit's symbolic loops and
calls off). Without options it prints where the package's files are and the
versions it was compiled against. Importing the package checks those versions
first: a mismatch exits with its error.
"""

import argparse

import stam_diffraction as sd


def main(argv=None):
    parser = argparse.ArgumentParser(prog='python -m stam_diffraction',
                                     description='The diffraction BSDF for Mitsuba 3.')
    parser.add_argument('--plugin-dir', action='store_true',
                        help='print the directory for `mitsuba -a` (it holds '
                             'plugins/diffraction.so)')
    args = parser.parse_args(argv)
    if args.plugin_dir:
        print(sd.PLUGIN_DIR)
        return 0
    print('stam_diffraction %s' % (sd.__version__ or '(source checkout)'))
    print('plugin:       %s' % sd.PLUGIN)
    print('compiled for: %s' % sd.compiled_versions())
    print('core library: %s' % sd.CORE_LIB)
    print('mitsuba -a "%s" scene.xml   (llvm_* variants: add -W -W)' % sd.PLUGIN_DIR)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
