# How much depth accuracy Aloe's novel view needs (docs/measurements.md, "What #43's shares of
# the gap ask of a depth"). Writes disparity maps (float .npy, the left image's pixels) that are
# the ground truth spoiled in known ways, or the estimate with the truth on one part:
#
#   python3 scripts/aloe-depth-bounds.py ESTIMATE.npy OUTDIR
#
# ESTIMATE.npy is the estimate's depth as `makeit4d eval scribbles ... --strokes 0 --no-nvs
# --save DIR` writes it (DIR/depth_0.npy); it is aligned to the truth here by least squares on
# disparity, as `eval depth` does. Each map is then scored with the pipeline's own renderer
# (which aligns it again, so a constant offset of the whole map means nothing):
#
#   makeit4d eval nvs --left L --right R --gt-disparity D --focal 3740 --baseline 160
#       --depth-file OUTDIR/NAME.npy
#
# Needs numpy, Pillow, scipy and scikit-image (SLIC; its counts vary a little between versions).
import os
import sys

import numpy as np
from PIL import Image
from scipy import ndimage
from skimage.segmentation import slic

DATA = '../shared/data/stereo/aloe'
estimate_path, out = sys.argv[1], sys.argv[2]
os.makedirs(out, exist_ok=True)
truth = np.asarray(Image.open(f'{DATA}/disparity.png')).astype(float)
known = truth > 0
inv = 1.0 / np.load(estimate_path).astype(float)
a = np.stack([inv[known], np.ones(known.sum())], 1)
scale, shift = np.linalg.lstsq(a, truth[known], rcond=None)[0]
estimate = scale * inv + shift
filled = np.where(known, truth, estimate)  # the truth's unknown pixels take the estimate
plant = known & (truth > 75)  # the plant and its pot; the cloth behind is 43-71 px
rng = np.random.default_rng(0)
noise = ndimage.gaussian_filter(rng.normal(size=truth.shape), 20)

maps = {
    'estimate': estimate,
    'truth': filled,
    'plant-true': np.where(plant, truth, estimate),
    'cloth-true': np.where(known & ~plant, truth, estimate),
    'truth-blur5': ndimage.gaussian_filter(filled, 5),
    'truth-blur15': ndimage.gaussian_filter(filled, 15),
    'cloth-plus2': np.where(plant, truth, filled + 2),
    'truth-noise2': filled + 2 * noise / noise.std(),
}
image = np.asarray(Image.open(f'{DATA}/left.jpg').convert('RGB'))
for n in (100, 300, 1000):
    segments = slic(image, n_segments=n, compactness=10, start_label=0)
    median = np.empty_like(filled)
    plane = np.empty_like(filled)
    for s in range(segments.max() + 1):
        k = segments == s
        median[k] = np.median(filled[k])
        ys, xs = np.nonzero(k)
        basis = np.stack([xs, ys, np.ones_like(xs)], 1).astype(float)
        plane[k] = basis @ np.linalg.lstsq(basis, filled[k], rcond=None)[0]
    count = segments.max() + 1
    maps[f'slic{count}-median'] = median
    maps[f'slic{count}-plane'] = plane
for name, disparity in maps.items():
    np.save(os.path.join(out, f'{name}.npy'), np.maximum(disparity, 0.5).astype(np.float32))
    print(f'{name}: mean |error| on known pixels {np.abs(disparity - truth)[known].mean():.2f} px')
