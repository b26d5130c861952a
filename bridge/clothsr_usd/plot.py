"""Plots for ``clothsr eval``: error over time for a prediction and its baselines (the paper's Fig. 11).

Written with matplotlib's Agg backend (no display needed) to a temporary file, then renamed into
place, so a failed plot never leaves a partial PNG; the temporary files of a killed plot are
removed by the next one.
"""
import os
import pathlib

from .write import _temp_path


def plot_errors(path, frames, series, title):
    """Draws mean vertex error (solid) with a ±1 std band per series.

    path: output PNG; frames: list of frame numbers; series: list of
    (label, mean_mm list, std_mm list); title: the figure title.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    fig, ax = plt.subplots(figsize=(8, 4.5), dpi=120)
    x = np.asarray(frames, dtype=float)
    for label, mean, std in series:
        m = np.asarray(mean, dtype=float)
        s = np.asarray(std, dtype=float)
        (line,) = ax.plot(x, m, label=label, linewidth=1.6)
        ax.fill_between(x, m - s, m + s, color=line.get_color(), alpha=0.15, linewidth=0)
    ax.set_xlabel("frame")
    ax.set_ylabel("vertex error to the fine simulation (mm)")
    ax.set_title(title)
    ax.set_ylim(bottom=0)
    ax.grid(True, alpha=0.3)
    ax.legend()
    fig.tight_layout()
    tmp = str(_temp_path(pathlib.Path(os.path.abspath(path))))
    try:
        fig.savefig(tmp, format="png")
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    finally:
        plt.close(fig)
        if os.path.exists(tmp):
            os.remove(tmp)
