#!/usr/bin/env python3
"""render_animation.py: the talk's last slide ("Animations rendered in Maya"),
rendered frame by frame on Dask distributed.

    .venv/bin/python scripts/render_animation.py --scene cd --frames 48 --res 384 \\
        --spp 128 --workers 2 --out out/animation/cd
    .venv/bin/python scripts/render_animation.py --scene brushed ... \\
        --scheduler tcp://head-node:8786          # an existing cluster
    make animation                              # the default animations

Scenes (ANIMATIONS below):
  cd       scenes/hero_cd.xml: the compact disc, tilted by 14 degrees, turning
           once about the vertical under the studio's strip lights: the
           rainbow arcs of its orders sweep round the disc.
  brushed  scenes/hero_brushed.xml: a small lamp swinging 75 degrees either
           way round the disc of concentrically brushed aluminium and back:
           the stretched highlight turns with it.
  brushed_sigma  a parameter sweep: the brushed disc with sigma from 0.02 to
           0.3 um, frame by frame.

Writes DIR/frame_NNNN.exr (linear) and DIR/frame_NNNN.png (one exposure for
the whole animation, sRGB), then DIR/NAME.mp4 (H.264 through imageio-ffmpeg's
own ffmpeg) and DIR/NAME.gif, and DIR/render.json (the settings). A progress
bar counts the frames.

Where the frames are rendered:
  --workers 0        in this process, one after another;
  --workers W        on a local Dask cluster of W worker processes (one task
                     each at a time; Mitsuba renders each frame on all cores);
  --scheduler ADDR   on an existing Dask cluster (docs/animation.md: starting
                     one on several machines, and Slurm with dask-jobqueue).
Every worker makes the plugin loadable itself (scripts/stam_mitsuba.py, i.e.
the package stam_diffraction: Mitsuba's plugins are resolved per process), so
a remote worker needs this checkout, built (`make plugin`), at the same path
(or pass --root).

Guarantees (tests/test_animation.py):
  * frame k is bitwise the same whichever way it is rendered: its seed is k,
    the scenes use a box pixel filter (every pixel is written by one image
    block, whatever thread renders it) and Mitsuba seeds each block by its
    index;
  * a worker that dies loses no frame: a frame is written under a temporary
    name and renamed when complete, and Dask reschedules the tasks of a lost
    worker (up to --retries times per frame);
  * a re-run renders only the frames not on disk (resume); frames rendered
    with other settings (render.json: size, samples, exposure, every frame's
    scene parameters) are rendered again.
"""

import argparse
import hashlib
import json
import math
import os
import sys
import time
import uuid

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)

# name: scene file, variant, fixed scene parameters, per-frame parameters as a
# function of t in [0, 1) (the animation loops), exposure of the PNGs and video.
ANIMATIONS = {
    'cd': dict(
        scene='hero_cd.xml', variant='scalar_rgb', exposure=0.16,
        description='compact disc, tilted 14 degrees, turning once under the strip lights',
        fixed={},
        frame=lambda t: {'tilt': 14.0, 'turn': 360.0 * t, 'spin': -360.0 * t,
                         'lift': 6.0 * math.sin(math.radians(14.0)) + 0.08}),
    'brushed': dict(
        scene='hero_brushed.xml', variant='scalar_rgb', exposure=1.0,
        description='a lamp swinging round the brushed aluminium disc and back',
        fixed={},
        # 75 degrees either way: the streak stays in view (further round, the
        # lamp ends up on the camera's side, and at 180 degrees in front of it)
        frame=lambda t: {'light_az': 75.0 * math.sin(2 * math.pi * t)}),
    # A parameter sweep rather than a loop: t runs from 0 to 1 inclusive.
    'brushed_sigma': dict(
        scene='hero_brushed.xml', variant='scalar_rgb', exposure=1.0, loop=False,
        description='brushed disc, sigma swept from 0.02 to 0.3 um (geometric)',
        fixed={'light_az': 35.0},
        frame=lambda t: {'sigma': 0.02 * 15.0 ** t}),
}

DEFAULTS = dict(frames=48, res=256, spp=64, fps=24)


def frame_params(name, k, frames):
    """Scene parameters of frame k of `frames` (all values as strings): t = k /
    frames for loops, k / (frames - 1) for sweeps (loop=False)."""
    a = ANIMATIONS[name]
    p = dict(a['fixed'])
    p.update(a['frame'](k / frames if a.get('loop', True) else k / max(frames - 1, 1)))
    return {key: ('%.9g' % v if isinstance(v, float) else str(v)) for key, v in p.items()}


def frame_paths(out_dir, k):
    base = os.path.join(out_dir, 'frame_%04d' % k)
    return base + '.exr', base + '.png'


def render_frame(name, k, frames, res, spp, out_dir, exposure, root=ROOT):
    """Render frame k into out_dir (EXR and PNG, each written under a temporary
    name and renamed when complete). Runs in this process or on a Dask worker:
    it sets up the plugin in the process it runs in. Returns (k, seconds, host,
    pid, sha256 of the float32 pixels)."""
    import socket
    for sub in ('scripts', 'python'):
        d = os.path.join(root, sub)
        if d not in sys.path:
            sys.path.insert(0, d)
    import stam_images
    import stam_mitsuba
    import studio_env
    a = ANIMATIONS[name]
    mi = stam_mitsuba.setup(a['variant'])
    studio_env.write(os.path.join(root, 'out', 'env'))
    params = frame_params(name, k, frames)
    params.update(res=str(res), spp=str(spp),
                  env=os.path.join(root, 'out', 'env', 'studio.exr'))
    if name == 'cd':
        params['label'] = os.path.join(root, 'out', 'env', 'cd_label.png')
    # Loaded in order: the BSDFs' registry ids, and so the kernels, are the
    # same in every worker and frame, which then reuse Dr.Jit's cached kernels
    # (a parallel load orders them as its threads finish; docs/guide.md)
    scene = mi.load_file(os.path.join(root, 'scenes', a['scene']), parallel=False, **params)
    t0 = time.time()
    img = np.array(mi.render(scene, seed=k), dtype=np.float32)
    dt = time.time() - t0
    exr, png = frame_paths(out_dir, k)
    tag = '.%s.%d.tmp' % (socket.gethostname(), os.getpid())
    stam_images.save_exr(mi, exr + tag + '.exr', img)
    stam_images.save_png(png + tag + '.png', img, exposure)
    os.replace(png + tag + '.png', png)
    os.replace(exr + tag + '.exr', exr)      # the EXR last: it marks the frame done
    digest = hashlib.sha256(np.ascontiguousarray(img).tobytes()).hexdigest()
    return k, dt, socket.gethostname(), os.getpid(), digest


def settings(name, frames, res, spp):
    """What the frames on disk were rendered with (render.json): a change of
    any of it, the scene parameters of any frame included, renders all again."""
    a = ANIMATIONS[name]
    per_frame = json.dumps([frame_params(name, k, frames) for k in range(frames)],
                           sort_keys=True)
    return dict(scene=name, frames=frames, res=res, spp=spp, scene_file=a['scene'],
                variant=a['variant'], exposure=a['exposure'],
                frame_params_sha256=hashlib.sha256(per_frame.encode()).hexdigest())


def pending_frames(out_dir, name, frames, res, spp):
    """Frames to render: all of them when out_dir holds frames of other
    settings, else those whose EXR and PNG are not both on disk."""
    rec = os.path.join(out_dir, 'render.json')
    want = settings(name, frames, res, spp)
    try:
        with open(rec) as f:
            same = json.load(f) == want
    except (FileNotFoundError, ValueError):
        same = False
    if not same:
        return list(range(frames))
    return [k for k in range(frames) if not all(map(os.path.exists, frame_paths(out_dir, k)))]


def _progress(total, initial, desc):
    try:
        from tqdm import tqdm
        return tqdm(total=total, initial=initial, desc=desc, unit='frame',
                    dynamic_ncols=True, file=sys.stderr)
    except ImportError:                       # pragma: no cover
        class Bar:
            def __init__(self):
                self.n = initial

            def update(self, n):
                self.n += n
                print('%s: %d/%d frames' % (desc, self.n, total), file=sys.stderr, flush=True)

            def close(self):
                pass
        return Bar()


def make_client(workers=0, scheduler=None):
    """(client, cluster): a Dask client on an existing scheduler, on a new local
    cluster of `workers` processes, or (None, None) for in-process rendering."""
    if not scheduler and not workers:
        return None, None
    import dask
    from dask.distributed import Client, LocalCluster
    # A lost worker's tasks go to another one; a frame is given up only after
    # this many workers died while rendering it.
    dask.config.set({'distributed.scheduler.allowed-failures': 5})
    if scheduler:
        return Client(scheduler), None
    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                           dashboard_address=None, silence_logs=40)
    return Client(cluster), cluster


def render(name, frames, res, spp, out_dir, client=None, root=ROOT, retries=3,
           progress=True, on_frame=None):
    """Render the frames of animation `name` not yet in out_dir, in this
    process (client None) or on the Dask client's cluster. on_frame(result)
    is called as each frame completes. Returns the results of the rendered
    frames, by frame number."""
    os.makedirs(out_dir, exist_ok=True)
    exposure = ANIMATIONS[name]['exposure']
    todo = pending_frames(out_dir, name, frames, res, spp)
    with open(os.path.join(out_dir, 'render.json'), 'w') as f:
        json.dump(settings(name, frames, res, spp), f, indent=1)
    bar = _progress(frames, frames - len(todo), name) if progress else None
    results = {}

    def done(r):
        results[r[0]] = r
        if bar:
            bar.update(1)
        if on_frame:
            on_frame(r)

    try:
        if client is None:
            for k in todo:
                done(render_frame(name, k, frames, res, spp, out_dir, exposure, root))
        else:
            import cloudpickle
            from dask.distributed import as_completed
            # Send this module's functions by value: the workers need only the
            # checkout at `root`, not this script on their import path.
            if render_frame.__module__ != '__main__':
                cloudpickle.register_pickle_by_value(sys.modules[render_frame.__module__])
            # A key of its own for each call: a key the scheduler still holds
            # from an earlier call (its release is asynchronous) would return
            # that call's result without rendering the frame again.
            run = uuid.uuid4().hex[:8]
            futures = [client.submit(render_frame, name, k, frames, res, spp, out_dir,
                                     exposure, root, key='%s-frame-%04d-%s' % (name, k, run),
                                     pure=False, retries=retries)
                       for k in todo]
            for fut in as_completed(futures):
                done(fut.result())
    finally:
        if bar:
            bar.close()
    missing = [k for k in range(frames) if not os.path.exists(frame_paths(out_dir, k)[0])]
    if missing:
        raise RuntimeError('frames missing after the run: %s' % missing)
    # what a worker killed while writing a frame left behind
    for f in os.listdir(out_dir):
        if f.startswith('frame_') and '.tmp.' in f:
            os.remove(os.path.join(out_dir, f))
    return results


def write_videos(name, frames, out_dir, fps=24):
    """DIR/NAME.mp4 (H.264, yuv420p) and DIR/NAME.gif from the PNG frames."""
    import imageio.v2 as imageio
    from PIL import Image
    pngs = [frame_paths(out_dir, k)[1] for k in range(frames)]
    mp4 = os.path.join(out_dir, name + '.mp4')
    with imageio.get_writer(mp4, fps=fps, codec='libx264', quality=8,
                            pixelformat='yuv420p', macro_block_size=2,
                            ffmpeg_log_level='error') as w:
        for p in pngs:
            w.append_data(np.asarray(Image.open(p).convert('RGB')))
    gif = os.path.join(out_dir, name + '.gif')
    ims = [Image.open(p).convert('RGB') for p in pngs]
    side = 256
    ims = [im.resize((side, round(side * im.height / im.width)), Image.LANCZOS)
           if im.width > side else im for im in ims]
    ims = [im.quantize(colors=255, method=Image.Quantize.MEDIANCUT) for im in ims]
    ims[0].save(gif, save_all=True, append_images=ims[1:], duration=round(1000 / fps),
                loop=0, optimize=False)
    return mp4, gif


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--scene', required=True, choices=sorted(ANIMATIONS))
    ap.add_argument('--frames', type=int, default=DEFAULTS['frames'])
    ap.add_argument('--res', type=int, default=DEFAULTS['res'], help='square frame size (even)')
    ap.add_argument('--spp', type=int, default=DEFAULTS['spp'])
    ap.add_argument('--workers', type=int, default=0,
                    help='worker processes of a local Dask cluster (0: render in this process)')
    ap.add_argument('--scheduler', default=None,
                    help='address of an existing Dask scheduler (tcp://host:8786)')
    ap.add_argument('--out', default=None, help='output folder (default out/animation/SCENE)')
    ap.add_argument('--fps', type=int, default=DEFAULTS['fps'])
    ap.add_argument('--retries', type=int, default=3,
                    help='times a frame is retried after an error in the task')
    ap.add_argument('--root', default=ROOT,
                    help='the checkout on the workers (default: this one)')
    args = ap.parse_args(argv)
    if args.frames < 1 or args.res < 2 or args.res % 2 or args.spp < 1:
        ap.error('--frames >= 1, --res even and >= 2, --spp >= 1')
    if args.workers < 0:
        ap.error('--workers >= 0')
    out = os.path.abspath(args.out or os.path.join(ROOT, 'out', 'animation', args.scene))

    t0 = time.time()
    client, cluster = make_client(args.workers, args.scheduler)
    where = ('in this process' if client is None else
             'on %d local workers' % args.workers if cluster else 'on ' + args.scheduler)
    print('[animation] %s: %s; %d frames, %dx%d, %d spp, %s -> %s' % (
        args.scene, ANIMATIONS[args.scene]['description'], args.frames, args.res, args.res,
        args.spp, where, out), flush=True)
    try:
        results = render(args.scene, args.frames, args.res, args.spp, out, client=client,
                         root=args.root, retries=args.retries)
    finally:
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()
    mp4, gif = write_videos(args.scene, args.frames, out, args.fps)
    secs = [r[1] for r in results.values()]
    print('[animation] rendered %d frames (%d already on disk)%s; wrote %s and %s; '
          'total %.1f s' % (len(results), args.frames - len(results),
                            ', %.1f s a frame' % (sum(secs) / len(secs)) if secs else '',
                            mp4, gif, time.time() - t0), flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
