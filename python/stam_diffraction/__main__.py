"""python -m stam_diffraction [--plugin-dir] [--help]

--plugin-dir prints the directory to give the `mitsuba` command, in which it
finds plugins/diffraction.so:

    mitsuba -m scalar_spectral -a "$(python -m stam_diffraction --plugin-dir)" scene.xml

(every variant, llvm_* and cuda_* included, with Dr.Jit's default flags).
--help lists the parameters of <bsdf type="diffraction">: each surface
model's keys with their units, accepted ranges and defaults, read from the
core (stam_parameter_reference, the ranges its parameter readers check).
Without options it prints where the package's files are and the versions it
was compiled against. Importing the package checks those versions first: a
mismatch exits with its error.
"""

import argparse
import re
import textwrap

import stam_diffraction as sd

# The plugin's own keys (mitsuba-plugin/diffraction.cpp), which the core does
# not read: the frame and the complex index's plugin names.
PLUGIN_KEYS = (
    ('twist', 'degrees', 'rotation of the tracks (the tangent frame) about the normal; '
                         'a number in [-360, 360] or a texture (a twist map)', '0'),
    ('tracks', '', '"linear" (along the shape\'s u direction) or "concentric" (circles '
                   'about a centre, a compact disc)', '"linear"'),
    ('center_u, center_v', 'uv units', 'centre of concentric tracks', '0.5, 0.5'),
    ('eta, k', '', 'instead of fresnel: a constant complex index (the core\'s '
                   'fresnel.eta, fresnel.k above)', 'none; k: 0 with eta'),
)


def _wrap(text, indent, more):
    return textwrap.fill(text, width=88, initial_indent=indent, subsequent_indent=more)


def _value(v):
    """A default as the JSON or XML would hold it: "rect", 2.5, 1e-5, false."""
    if isinstance(v, str):
        return '"%s"' % v
    if isinstance(v, bool):
        return str(v).lower()
    if isinstance(v, float) and v.is_integer() and abs(v) < 1e15:
        return str(int(v))
    return re.sub(r'e([-+])0*(\d)', r'e\1\2', repr(v)).replace('e+', 'e')


def _describe_key(doc):
    """The lines of one key of the core's parameter reference."""
    unit = ' (%s)' % doc['unit'] if doc['unit'] else ''
    facts = ['accepted ' + doc['accepted']]
    if doc['required']:
        facts.append('required')
    elif doc['default'] is not None:
        facts.append('default ' + _value(doc['default']))
    if doc['note']:
        facts.append(doc['note'])
    return '\n'.join([_wrap('%s%s: %s' % (doc['key'], unit, doc['meaning']), '  ', '      '),
                      _wrap('; '.join(facts), '      ', '      ')])


def parameter_help():
    """The parameters of type="diffraction" as text: the core's reference
    (units, ranges, defaults) and the plugin's own keys."""
    from . import core
    try:
        ref = core.parameter_reference()
    except (OSError, AttributeError) as e:
        return 'Parameters: see docs/parameters.md (the core library cannot be read: %s)' % e
    out = [_wrap('Parameters of <bsdf type="diffraction"> (from the core %s; %s; '
                 'docs/parameters.md has the same with more words):'
                 % (ref['version'], ref['units']), '', ''),
           '', 'Every surface:']
    out += [_describe_key(d) for d in ref['material']]
    for s in ref['surfaces']:
        out += ['', 'surface "%s":' % s['surface']]
        out += [_describe_key(d) for d in s['keys']]
    out += ['', 'The plugin\'s own keys:']
    for key, unit, meaning, default in PLUGIN_KEYS:
        out.append(_wrap('%s%s: %s' % (key, ' (%s)' % unit if unit else '', meaning),
                         '  ', '      '))
        out.append('      default ' + default)
    out += ['', _wrap('Every parameter, defaults included, can be changed through '
                      'mi.traverse; in the AD variants the numbers the material\'s programs '
                      'read are differentiable (mi.traverse marks them).', '', '')]
    return '\n'.join(out)


def main(argv=None):
    parser = argparse.ArgumentParser(prog='python -m stam_diffraction',
                                     description='The diffraction BSDF for Mitsuba 3 '
                                                 '(Stam\'s "Diffraction Shaders", SIGGRAPH 1999).',
                                     epilog=parameter_help(),
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
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
    print('mitsuba -a "%s" scene.xml' % sd.PLUGIN_DIR)
    print('python -m stam_diffraction --help   (the parameters, their units, ranges '
          'and defaults)')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
