"""Writes the trimmed point cache the tests use from the shared data's full bake.

    python tests/data/avatars/trim_bake.py FULL_BAKE.usdc tests/data/avatars/mh_walk_train_baked_2s.usdc

Keeps the time samples of time codes 0-60 (the first 2 s of the walk, every 2nd time code as
in the full bake) and nothing else: the kept samples are the full bake's values bit for bit.
"""

import sys

from pxr import Sdf, Usd

END = 60.0


def main(src: str, dst: str) -> None:
    stage = Usd.Stage.Open(src)
    layer = Sdf.Layer.CreateNew(dst)
    layer.TransferContent(stage.GetRootLayer())
    with Sdf.ChangeBlock():
        for t in list(layer.ListAllTimeSamples()):
            if t > END:
                for path in _sampled(layer):
                    if t in layer.ListTimeSamplesForPath(path):
                        layer.EraseTimeSample(path, t)
    layer.endTimeCode = END
    layer.Save()


def _sampled(layer):
    paths = []
    layer.Traverse(
        Sdf.Path.absoluteRootPath,
        lambda p: paths.append(p) if p.IsPropertyPath() and layer.GetNumTimeSamplesForPath(p) else None,
    )
    return paths


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
