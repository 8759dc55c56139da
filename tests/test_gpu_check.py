"""scripts/gpu_check.py, the CUDA checks of the JIT path, as far as a machine
without a GPU can run them: its options, its exit where no CUDA device is,
and its freeze check on the CPU (--variant llvm_ad_*, the script's dry run).
The CUDA figures themselves are in docs/jit_measured.md ("CUDA")."""

import os
import subprocess
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCRIPT = os.path.join(ROOT, 'scripts', 'gpu_check.py')


def gpu_check(*args):
    r = subprocess.run([sys.executable, SCRIPT, *args], cwd=ROOT, capture_output=True,
                       text=True, timeout=900)
    return r.returncode, r.stdout + r.stderr


def has_cuda():
    import drjit as dr
    return dr.has_backend(dr.JitBackend.CUDA)


def test_unknown_check_is_named():
    rc, out = gpu_check('--checks', 'accuracy,speeed')
    assert rc == 2 and 'unknown check(s) speeed' in out, out


def test_no_cuda_device_exits_0():
    if has_cuda():
        pytest.skip('a CUDA device is present: run the script itself')
    rc, out = gpu_check('--variant', 'cuda_ad_rgb')
    assert rc == 0 and 'nothing to check' in out, out


def test_freeze_replays_once_recorded():
    """One recording, replayed with another seed, equal to the plain render."""
    rc, out = gpu_check('--variant', 'llvm_ad_rgb', '--checks', 'freeze', '--quick')
    assert rc == 0, out
    assert 'replay equals the plain render True, seeds differ True, recordings 1' in out, out


def test_freeze_is_skipped_where_mitsuba_cannot_freeze():
    """Mitsuba 3.9.1 cannot record a frozen spectral render without the plugin
    either: the check says so and does not fail."""
    rc, out = gpu_check('--variant', 'llvm_ad_spectral', '--checks', 'freeze', '--quick')
    assert rc == 0, out
    assert ('freeze: skipped' in out) != ('recordings 1' in out), out
