"""Writes a walk of any length from a UsdSkel avatar: its skeleton animation played forward,
backward and forward again (a mirrored loop), as an override layer over the avatar.

    python tools/bench/pingpong_walk.py AVATAR.usda OUT.usdc FRAMES

The layer sublayers AVATAR (by a path relative to OUT) and authors, on each SkelAnimation,
joint rotations and translations at time codes 0..FRAMES-1; time code t takes the source's
sample at the triangle wave of t over the source's range. The long-run check
(`tools/bench/long_runs.sh`) walks the skirt sample on it.
"""

import os
import sys

from pxr import Sdf, Usd, UsdSkel


def source_time(t: int, start: int, end: int) -> int:
    span = end - start
    s = t % (2 * span)
    return start + (s if s <= span else 2 * span - s)


def main(src: str, dst: str, frames: int) -> None:
    stage = Usd.Stage.Open(src)
    start, end = int(stage.GetStartTimeCode()), int(stage.GetEndTimeCode())
    if end <= start:
        sys.exit(f"{src}: the stage has no time range to loop")
    layer = Sdf.Layer.CreateNew(dst)
    layer.subLayerPaths.append(os.path.relpath(src, os.path.dirname(os.path.abspath(dst))))
    out = Usd.Stage.Open(layer)
    out.SetEditTarget(Usd.EditTarget(layer))
    # Stage metadata is read from the root layer only.
    for key in ("framesPerSecond", "timeCodesPerSecond", "metersPerUnit", "upAxis"):
        if stage.HasAuthoredMetadata(key):
            out.SetMetadata(key, stage.GetMetadata(key))
    if stage.GetDefaultPrim():
        layer.defaultPrim = stage.GetDefaultPrim().GetName()
    out.SetStartTimeCode(0)
    out.SetEndTimeCode(frames - 1)
    anims = [p for p in stage.Traverse() if p.IsA(UsdSkel.Animation)]
    if not anims:
        sys.exit(f"{src}: no SkelAnimation")
    with Sdf.ChangeBlock():
        for prim in anims:
            for name in ("rotations", "translations", "scales", "blendShapeWeights"):
                attr = prim.GetAttribute(name)
                if not attr or attr.GetNumTimeSamples() == 0:
                    continue
                spec = Sdf.CreatePrimInLayer(layer, prim.GetPath())
                spec.specifier = Sdf.SpecifierOver
                aspec = Sdf.AttributeSpec(spec, name, attr.GetTypeName())
                path = aspec.path
                for t in range(frames):
                    layer.SetTimeSample(path, t, attr.Get(source_time(t, start, end)))
    layer.Save()


if __name__ == "__main__":
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2], int(sys.argv[3]))
