# The edits behind docs/gallery/depth-edits-before-after.jpg (docs/measurements.md, "Depth edits"):
# adds depth.targets and depth.popups to projects saved by `makeit4d render PHOTO --save-project NAME.json`
# for ../shared/data/wild/{astronaut.png,garden.jpg,storm.jpg}, writing NAME_edited.json.
import json
def stroke(pts, depth, radius=0.02):
    return {"points": pts, "radius": radius, "depth": depth, "hidden": False}
def facing(seeds, depth):
    return {"seeds": seeds, "shape": {"kind": "facing", "depth": depth}, "hidden": False}
def tilted(seeds, a, da, b, db):
    return {"seeds": seeds, "shape": {"kind": "tilted", "from": a, "from_depth": da, "to": b, "to_depth": db}, "hidden": False}
edits = {
  "astronaut": (
    [stroke([[0.38,0.27],[0.5,0.27]], 13.0), stroke([[0.36,0.1],[0.52,0.1]], 13.0),
     stroke([[0.4,0.36],[0.5,0.36]], 12.5), stroke([[0.1,0.8],[0.5,0.8],[0.7,0.7]], 4.5),
     stroke([[0.3,0.52],[0.6,0.52]], 7.0)],
    [facing([[0.6,0.08],[0.25,0.12]], 30.0), facing([[0.05,0.1]], 20.0)]),
  "garden": (
    [stroke([[0.65,0.25],[0.8,0.45]], 6.0), stroke([[0.42,0.55],[0.55,0.58]], 6.0),
     stroke([[0.85,0.1],[0.95,0.1]], 13.0),
     stroke([[0.15,0.85]], 9.0, 0.03)],
    [facing([[0.2,0.3],[0.4,0.15],[0.29,0.3],[0.33,0.12],[0.28,0.4]], 13.0),
     facing([[0.15,0.85]], 9.0)]),
  "storm": (
    [stroke([[0.1,0.71],[0.9,0.71]], 13.0), stroke([[0.1,0.755],[0.9,0.755]], 13.0),
     stroke([[0.1,0.8],[0.9,0.8]], 11.0), stroke([[0.1,0.655],[0.9,0.655]], 40.0),
     stroke([[0.1,0.635],[0.9,0.635]], 120.0)],
    [tilted([[0.5,0.64],[0.2,0.63],[0.8,0.63]], [0.5,0.62], 200.0, [0.5,0.69], 26.0),
     tilted([[0.5,0.85],[0.5,0.9],[0.5,0.95],[0.2,0.9],[0.8,0.9]], [0.5,0.8], 11.0, [0.5,1.0], 5.4)]),
}
for name,(targets,popups) in edits.items():
    p = json.load(open(f'{name}.json'))
    p['depth']['targets'] = targets
    p['depth']['popups'] = popups
    json.dump(p, open(f'{name}_edited.json','w'), indent=1)
print("ok")
