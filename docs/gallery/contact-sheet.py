# How docs/gallery/depth-no-harm-contact-sheet.jpg is made (docs/measurements.md, "The ground in
# front of the camera"): for each binary (BEFORE, AFTER) and each photo of ../shared/data/photos/
# (cold_ripple, evening_glow, forest_path, starry_night) and ../shared/data/wild/, render at the
# photo's own shape with at least 640x400 (W = max(640, 400 w/h), H = max(400, 640 h/w)):
#   BIN render PHOTO --out DIR/TAG/NAME-fly-in --size WxH --frames 40 --preset fly-in --range 39..40
#   BIN render PHOTO --out DIR/TAG/NAME-orbit  --size WxH --frames 40 --preset orbit  --range 20..21
# then, from the repository root, `python3 docs/gallery/contact-sheet.py DIR OUT.jpg` (Pillow):
# each frame's centre 640x400 (what a 640x400 output fills with square pixels), halved; rows =
# photos, columns = fly-in before / after, orbit before / after.
import os
import sys

from PIL import Image, ImageDraw

root, out_path = sys.argv[1], sys.argv[2]
wild = sorted(os.path.splitext(f)[0] for f in os.listdir('../shared/data/wild'))
names = ['cold_ripple', 'evening_glow', 'forest_path', 'starry_night'] + wild
TW, TH = 320, 200


def tile(path):
    im = Image.open(path).convert('RGB')
    w, h = im.size
    s = max(640 / w, 400 / h)
    im = im.resize((round(w * s), round(h * s)), Image.LANCZOS)
    w, h = im.size
    left, top = (w - 640) // 2, (h - 400) // 2
    return im.crop((left, top, left + 640, top + 400)).resize((TW, TH), Image.LANCZOS)


sheet = Image.new('RGB', (4 * TW, len(names) * TH))
draw = ImageDraw.Draw(sheet)
columns = [('fly-in', 'before', 39), ('fly-in', 'after', 39), ('orbit', 'before', 20), ('orbit', 'after', 20)]
for r, name in enumerate(names):
    for c, (preset, tag, frame) in enumerate(columns):
        path = os.path.join(root, tag, f'{name}-{preset}', f'frame_{frame:04d}.png')
        sheet.paste(tile(path), (c * TW, r * TH))
        draw.text((c * TW + 4, r * TH + 3), f"{name} {preset.replace('-', '')} {tag}", fill=(255, 255, 255))
sheet.save(out_path, quality=80)
