"""pytest's collection order for `make test` (pytest-xdist, --dist loadfile
--no-loadscope-reorder): whole files go to the two workers in this order,
each taking the next file when it runs dry, so the files that take longest
on a clean checkout (cold Dr.Jit cache; seconds measured 2026-12-02 with
--durations=0, summed per file) go first and the short ones fill the gaps
(longest-first scheduling). Files not listed keep their place after them.
test_gradients.py and test_inverse.py re-estimated 2026-12-03 from the
slowest tests of a clean-clone CI run; test_gradients.py again 2026-12-05
(its reverse-mode and rebuilt-material tests, cold, alone). On the slower 2-core AMD EPYC of
later sessions every file took 2-4 times these (test_gradients.py ~1,650 s
before its grating tests moved to the `direct` integrator, ~930 s after;
test_inverse.py ~480 s), in the same order.

`--quick` (what `make check` runs, the contributors' inner loop): the tests
of one variant (QUICK_VARIANT; a test parametrized over variants keeps that
one) without the slow ones (SLOW). `make test` runs them all."""

import pytest

COLD_SECONDS = {
    'test_jit.py': 314,
    'test_jit_render.py': 284,
    'test_gradients.py': 630,
    'test_inverse.py': 150,
    'test_plugin.py': 70,
    'test_heightmap.py': 40,  # 2026-12-07: 38 s cold (JIT kernels of 3 variants, demo renders)
    'test_textures.py': 48,
    'test_explorer.py': 100,  # 2026-12-07: 96 s (headless Chromium, SwiftShader compiles)
    'test_plugin_usability.py': 28,
    'test_compare.py': 25,  # 2026-12-05: 39.5 s cold on the AMD, where it was 15.7
    'test_wheel.py': 20,
    'test_core_binding.py': 17,
    'test_polarization.py': 5,  # 2026-12-06: 3.3 s warm (scalar variants)
    'test_rigorous.py': 10,  # 2026-12-05: 7-15 s by load, 2 cores (grcwa; no Dr.Jit)
    'test_animation.py': 8,
    'test_heightmaps_data.py': 1,  # 2026-12-07: 0.9 s (numpy only, 512 px maps)
}


# The variant of `--quick`: the JIT path, where the core's programs and the
# plugin's executor meet (the native path has the core's own tests).
QUICK_VARIANT = 'llvm_ad_rgb'
# Tests left out of `--quick`: seconds each took warm on 2 cores (2026-12-06,
# summed over its parameters in QUICK_VARIANT), file::function. Every one of
# them runs in `make test`.
SLOW = {
    'test_wheel.py::test_wheel_contents_and_size': 79,  # builds and installs the wheel
    'test_wheel.py::test_render_from_the_installed_wheel': 10,
    'test_inverse.py::test_short_inverse_rendering_moves_towards_the_truth': 51,
    'test_jit_render.py::test_mitsuba_command_renders_the_scene': 31,
    'test_jit_render.py::test_chi2_of_the_jit_sampling': 8,
    'test_gradients.py::test_render_gradient_equals_rebuilt_central_difference': 26,
    'test_gradients.py::test_gradient_equals_finite_difference': 24,
    'test_gradients.py::test_gradients_are_finite_and_reverse_equals_forward': 6,
    'test_compare.py::test_jit_eval_equals_native': 15,
    'test_explorer.py::test_page_renders_what_the_core_evaluates': 70,  # 8 browser loads
    'test_explorer.py::test_page_xml_and_dict_load_in_mitsuba_as_the_same_material': 14,
    'test_explorer.py::test_runtime_parameters_move_a_uniform_within_the_drift': 12,
    'test_textures.py::test_map_values_are_differentiable': 14,
    'test_jit.py::test_decoder_reads_every_exported_program': 8,  # compiles a C++ decoder
    'test_jit.py::test_decoder_refuses_malformed_arrays': 6,
    'test_rigorous_plugin.py::test_a_table_built_while_mitsuba_loads_a_scene_is_right': 6,
    'test_rigorous.py::test_converged_efficiencies_agree': 6,
}


def pytest_addoption(parser):
    parser.addoption('--quick', action='store_true',
                     help='make check\'s tier: %s only, without the slow tests (conftest.SLOW)'
                     % QUICK_VARIANT)


def _in_quick_tier(item):
    if '%s::%s' % (item.path.name, item.originalname) in SLOW:
        return False
    callspec = getattr(item, 'callspec', None)
    variant = callspec.params.get('variant') if callspec else None
    return variant is None or variant == QUICK_VARIANT


def pytest_collection_modifyitems(session, config, items):
    if config.getoption('quick'):
        # A name in SLOW that its collected file no longer has is stale.
        files = {item.path.name for item in items}
        names = {'%s::%s' % (item.path.name, item.originalname) for item in items}
        stale = [k for k in SLOW if k.split('::')[0] in files and k not in names]
        if stale:
            raise pytest.UsageError('tests/conftest.py SLOW names tests that do not exist: %s'
                                    % ', '.join(stale))
        left_out = [item for item in items if not _in_quick_tier(item)]
        if left_out:
            config.hook.pytest_deselected(items=left_out)
            items[:] = [item for item in items if _in_quick_tier(item)]

    def cost(item):
        return -COLD_SECONDS.get(item.path.name, 0)
    items.sort(key=cost)  # stable: each file's tests keep their order
