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
test_inverse.py ~480 s), in the same order."""

COLD_SECONDS = {
    'test_jit.py': 314,
    'test_jit_render.py': 284,
    'test_gradients.py': 630,
    'test_inverse.py': 150,
    'test_plugin.py': 70,
    'test_textures.py': 48,
    'test_plugin_usability.py': 28,
    'test_compare.py': 25,  # 2026-12-05: 39.5 s cold on the AMD, where it was 15.7
    'test_wheel.py': 20,
    'test_core_binding.py': 17,
    'test_rigorous.py': 10,  # 2026-12-05: 7-15 s by load, 2 cores (grcwa; no Dr.Jit)
    'test_animation.py': 8,
}


def pytest_collection_modifyitems(session, config, items):
    def cost(item):
        return -COLD_SECONDS.get(item.path.name, 0)
    items.sort(key=cost)  # stable: each file's tests keep their order
