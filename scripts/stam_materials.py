"""stam_materials: the project's shared list of test materials, tests/materials.json.

The file is a JSON array; each entry is one material:
  name    unique identifier;
  label   (optional) the short name its users show (test ids, command-line
          choices, file names, report rows) where it differs from name; unique
          within each tag;
  model   surface model family: gaussian, fractal or periodic (the compact disc
          is periodic);
  tags    the lists it belongs to: plugin (tests/test_plugin.py), plugin-chi2
          (its chi-square tests), compare (scripts/compare.py), pareto
          (tools/stress/src/pareto.rs), abi (tests/abi), fuzz (the accepted
          materials of tools/stress/tests/fuzz_json.rs);
  params  the core's JSON parameters (docs/parameters.md);
  note    (optional) why the material is what it is.
Users take their materials in file order (the Pareto survey numbers its
configurations in that order).

    import stam_materials
    surfaces = stam_materials.by_label('plugin')   # {label: params}
"""

import json
import os

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PATH = os.path.join(ROOT, 'tests', 'materials.json')


def load(tag=None, path=PATH):
    """The entries (dicts) in file order; only those tagged `tag` if given."""
    with open(path) as f:
        entries = json.load(f)
    return [e for e in entries if tag is None or tag in e['tags']]


def label(entry):
    return entry.get('label', entry['name'])


def by_label(tag, path=PATH):
    """{label: params} of the entries tagged `tag`, in file order."""
    out = {}
    for e in load(tag, path):
        if label(e) in out:
            raise ValueError('%s: label %r twice in tag %r' % (path, label(e), tag))
        out[label(e)] = e['params']
    return out


def plugin_params(params):
    """The `diffraction` plugin's parameters for the core's JSON parameters:
    the same names, but a tabulated profile {"heights_um": [...]} becomes a
    comma-separated list and a Fresnel {"eta", "k"} object the keys eta, k."""
    d = {}
    for k, v in params.items():
        if k == 'fresnel' and isinstance(v, dict):
            d.update(v)
        elif k == 'profile' and isinstance(v, dict):
            d[k] = ', '.join(repr(float(h)) for h in v['heights_um'])
        else:
            d[k] = v
    return d


def model_of(params):
    """The surface model family of the core's JSON parameters: gaussian,
    fractal or periodic (the compact disc is periodic)."""
    surface = params.get('surface', 'gaussian')
    return 'periodic' if surface == 'cd' else surface
