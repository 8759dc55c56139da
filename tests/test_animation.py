"""Animations on Dask distributed (scripts/render_animation.py): frames rendered
on a local cluster are bitwise those rendered in-process, a worker killed
during a run loses no frame, a re-run renders nothing, and the video has one
frame per rendered frame. Tiny frames and two workers: about 20-30 s."""

import os
import signal
import subprocess
import sys
import threading

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(ROOT, 'scripts'))

distributed = pytest.importorskip('distributed')
import render_animation as ra  # noqa: E402

PLUGIN = os.path.join(ROOT, 'build', 'plugins', 'diffraction.so')
pytestmark = pytest.mark.skipif(not os.path.exists(PLUGIN), reason='plugin not built')


def read_exr(path):
    import stam_mitsuba
    mi = stam_mitsuba.setup('scalar_rgb')
    return np.array(mi.Bitmap(path), dtype=np.float32)


@pytest.fixture(scope='module')
def reference(tmp_path_factory):
    """Frames 0-5 of the cd animation at 24 px, 8 spp, rendered in this process."""
    out = str(tmp_path_factory.mktemp('inproc'))
    res = ra.render('cd', 6, 24, 8, out, client=None, progress=False)
    return out, {k: r[4] for k, r in res.items()}


@pytest.fixture(scope='module')
def client():
    from dask.distributed import Client, LocalCluster
    import dask
    dask.config.set({'distributed.scheduler.allowed-failures': 5})
    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                           dashboard_address=None, silence_logs=50)
    c = Client(cluster)
    yield c
    c.close()
    cluster.close()


def test_two_workers_match_in_process(reference, client, tmp_path):
    ref_dir, ref = reference
    out = str(tmp_path / 'cd')
    res = ra.render('cd', 6, 24, 8, out, client=client, progress=False)
    assert sorted(res) == list(range(6))
    pids = {r[3] for r in res.values()}
    assert os.getpid() not in pids                      # rendered on the workers
    for k in range(4):
        assert res[k][4] == ref[k], 'frame %d differs from the in-process render' % k
        a = read_exr(ra.frame_paths(out, k)[0])
        b = read_exr(ra.frame_paths(ref_dir, k)[0])
        assert a.shape == (24, 24, 3) and np.array_equal(a, b)
        with open(ra.frame_paths(out, k)[1], 'rb') as fa, \
                open(ra.frame_paths(ref_dir, k)[1], 'rb') as fb:
            assert fa.read() == fb.read()

    # resume: nothing left to render, nothing rewritten
    mtimes = [os.path.getmtime(ra.frame_paths(out, k)[0]) for k in range(6)]
    assert ra.render('cd', 6, 24, 8, out, client=client, progress=False) == {}
    assert mtimes == [os.path.getmtime(ra.frame_paths(out, k)[0]) for k in range(6)]
    # a lost frame is rendered again, alone and identical
    os.remove(ra.frame_paths(out, 3)[1])
    again = ra.render('cd', 6, 24, 8, out, client=client, progress=False)
    assert sorted(again) == [3] and again[3][4] == ref[3]

    # other settings: every frame again
    rec = ra.settings('cd', 6, 24, 8)
    monkey = dict(ra.ANIMATIONS['cd'])
    ra.ANIMATIONS['cd_other'] = dict(monkey, frame=lambda t: {'tilt': 10.0})
    try:
        assert ra.settings('cd_other', 6, 24, 8)['frame_params_sha256'] != \
            rec['frame_params_sha256']
    finally:
        del ra.ANIMATIONS['cd_other']
    assert len(ra.pending_frames(out, 'cd', 6, 24, 16)) == 6     # other spp

    # the video and the GIF: one frame per rendered frame
    import imageio_ffmpeg
    from PIL import Image
    mp4, gif = ra.write_videos('cd', 6, out, fps=12)
    n, _ = imageio_ffmpeg.count_frames_and_secs(mp4)
    assert n == 6
    assert Image.open(gif).n_frames == 6


def test_killed_worker_loses_no_frame(reference, client, tmp_path):
    """SIGKILL a worker that is rendering a frame, as soon as the first frame
    is done: the run still completes with every frame, bitwise as in-process."""
    _, ref = reference
    out = str(tmp_path / 'cd')
    killed = []
    lock = threading.Lock()

    def on_frame(_result):
        with lock:
            if killed:
                return
            busy = [w for w, keys in client.processing().items() if keys]
            if not busy:
                return
            pid = client.run(os.getpid, workers=[busy[0]])[busy[0]]
            os.kill(pid, signal.SIGKILL)
            killed.append(pid)

    res = ra.render('cd', 6, 24, 8, out, client=client, progress=False, on_frame=on_frame)
    assert killed, 'no worker was busy after the first frame'
    assert sorted(res) == list(range(6))
    for k in range(6):
        assert os.path.exists(ra.frame_paths(out, k)[0])
        assert res[k][4] == ref[k]
    assert not [f for f in os.listdir(out) if '.tmp' in f]   # no partial frame left


def test_command_line_in_process(tmp_path):
    out = str(tmp_path / 'b')
    r = subprocess.run([sys.executable, os.path.join(ROOT, 'scripts', 'render_animation.py'),
                        '--scene', 'brushed', '--frames', '3', '--res', '16', '--spp', '4',
                        '--workers', '0', '--out', out, '--fps', '6'],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr
    for k in range(3):
        assert all(map(os.path.exists, ra.frame_paths(out, k)))
    assert os.path.exists(os.path.join(out, 'brushed.mp4'))
    assert os.path.exists(os.path.join(out, 'brushed.gif'))
    assert '3/3' in r.stderr                                # the progress bar
