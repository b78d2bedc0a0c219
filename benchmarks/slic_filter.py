"""Paparazzi's SLIC: scikit-image's ``slic`` against the compiled one of
algorithms/paparazzi/slic.py (``slic_labels``), on the pictures the ``slic`` filter sees.

    OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 python benchmarks/slic_filter.py
        [--meshes capsule.obj hippo.ply blob.obj] [--corpus DIR] [--views 16] [--repeat 5]
        [--per-picture]

For each mesh (``--corpus`` folder, default ../shared/corpus beside the checkout, then
resources/samples), cleaned with ``clean_mesh``, Paparazzi's ``slic`` run is built with its
defaults and its monitor views are rendered (256 x 256); each picture is clipped to [0, 1] and
cut with ``n = round(100 * foreground share)`` segments, compactness 10, as the filter does.
Both functions run on every picture (the median of ``--repeat`` calls each, alternating); the
labels must be identical (the script stops otherwise). Prints, per mesh (and per picture with
``--per-picture``): foreground pixels, segments asked and found, ms of scikit-image and of the
compiled version, their ratio, and the compiled version's split: *init* (rescale, rgb2lab,
the random seeds, the seeds' distances: NumPy / SciPy / scikit-image) and *kernels* (the
seeds' k-means, the two SLIC passes and the connectivity, Numba). Run it single-threaded (the
environment above) to compare like with like; the load average is printed.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def mesh_file(name: str, corpus: Path) -> Path:
    for folder in (corpus, ROOT / "resources" / "samples", ROOT / "tests" / "data"):
        if (folder / name).exists():
            return folder / name
    raise SystemExit(f"{name}: not found in {corpus}, resources/samples or tests/data")


def pictures(path: Path, views: int):
    """The monitor views of Paparazzi's slic run on the mesh: [(image in [0, 1], mask)]."""
    from algorithms.mesh.io import read_mesh
    from algorithms.mesh.validate import clean_mesh
    from algorithms.paparazzi import Paparazzi
    from algorithms.paparazzi.optimize import PaparazziParams
    from algorithms.render import render

    m = read_mesh(path)
    c = clean_mesh(m.V, m.F)
    run = Paparazzi(c.V, c.F, "slic", None, PaparazziParams())
    out = []
    for cam in run.monitor_cameras()[:views]:
        r = render(run.V0, run.F0, cam, run.shading)
        out.append((np.clip(r.image, 0.0, 1.0), np.asarray(r.mask, bool)))
    return len(c.V), out


def main() -> int:
    from skimage.segmentation import slic

    from algorithms.compiled import thread_count
    from algorithms.paparazzi.slic import _KERNELS, slic_labels

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--meshes", nargs="+", default=["capsule.obj", "hippo.ply", "blob.obj"])
    ap.add_argument("--corpus", type=Path, default=ROOT.parent / "shared" / "corpus")
    ap.add_argument("--views", type=int, default=16, help="monitor views per mesh (at most 16)")
    ap.add_argument("--repeat", type=int, default=5, help="calls per picture and function")
    ap.add_argument("--per-picture", action="store_true", help="a row per picture")
    a = ap.parse_args()
    if _KERNELS.get() is None:
        raise SystemExit("the compiled kernels are off (STYLIZE3D_NUMBA=0) or Numba is missing")
    warnings.filterwarnings("ignore", message="One of the clusters is empty")

    def skimage_slic(img, mask, n):
        return slic(img, n_segments=n, compactness=10.0, mask=mask, start_label=1,
                    channel_axis=-1)

    img0, mask0 = np.zeros((32, 32, 3)), np.ones((32, 32), bool)
    t = time.perf_counter()
    slic_labels(img0, mask0, 4)
    print(f"load average {os.getloadavg()[0]:.2f}; Numba threads {thread_count()}, "
          f"OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS', 'unset')}; first call (load or "
          f"compile the kernels) {time.perf_counter() - t:.2f} s; median of {a.repeat} calls")
    head = (f"{'':<14}{'pictures':>9}{'fg px':>8}{'n':>5}{'found':>6}{'skimage ms':>12}"
            f"{'ours ms':>9}{'ratio':>7}{'init ms':>9}{'kernels ms':>11}")
    print(head)
    total = {"sk": [], "ours": [], "init": [], "kern": []}
    n_pictures = 0
    for name in a.meshes:
        nv, pics = pictures(mesh_file(name, a.corpus), a.views)
        rows = []
        for i, (img, mask) in enumerate(pics):
            n = max(1, int(round(100 * float(mask.mean()))))
            ts, to, ti, tk = [], [], [], []
            for _ in range(max(1, a.repeat)):
                t0 = time.perf_counter()
                ref = skimage_slic(img, mask, n)
                t1 = time.perf_counter()
                split = {}
                out = slic_labels(img, mask, n, 10.0, timings=split)
                t2 = time.perf_counter()
                if not np.array_equal(out, ref):
                    raise SystemExit(f"{name} view {i}: {int((out != ref).sum())} labels differ")
                ts.append(t1 - t0)
                to.append(t2 - t1)
                ti.append(split["init"])
                tk.append(split["kernels"])
            row = (int(mask.sum()), n, int(ref.max()), *(1e3 * statistics.median(x)
                                                         for x in (ts, to, ti, tk)))
            rows.append(row)
            if a.per_picture:
                print(f"  view {i:<7}{1:>9}{row[0]:>8}{row[1]:>5}{row[2]:>6}{row[3]:>12.2f}"
                      f"{row[4]:>9.2f}{row[3] / row[4]:>7.2f}{row[5]:>9.2f}{row[6]:>11.2f}")
        r = np.array(rows, float)
        m = r.mean(0)
        print(f"{Path(name).stem[:13]:<14}{len(rows):>9}{m[0]:>8.0f}{m[1]:>5.0f}{m[2]:>6.0f}"
              f"{m[3]:>12.2f}{m[4]:>9.2f}{m[3] / m[4]:>7.2f}{m[5]:>9.2f}{m[6]:>11.2f}"
              f"   ({nv:,} vertices)")
        for key, col in (("sk", 3), ("ours", 4), ("init", 5), ("kern", 6)):
            total[key] += list(r[:, col])
        n_pictures += len(rows)
    sk, ours = np.mean(total["sk"]), np.mean(total["ours"])
    print(f"{'all':<14}{n_pictures:>9}{'':>19}{sk:>12.2f}{ours:>9.2f}{sk / ours:>7.2f}"
          f"{np.mean(total['init']):>9.2f}{np.mean(total['kern']):>11.2f}")
    print(f"labels identical on all {n_pictures} pictures; load average now "
          f"{os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
