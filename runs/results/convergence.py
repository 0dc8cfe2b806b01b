"""The resolution ladder read as limits: m_lf/m_t extrapolated to infinitely many grains per eta, and
the particle-size change's power of N, each with its 95 % interval (docs/validation.md,
"Convergence with resolution").

    python runs/results/convergence.py          # from the repository root, on any machine (CPU)

Reads the committed ladder (runs/results/resolution/, its x4 and x16 folders, and the paper's runs in
runs/results/fig3/) through figures.ladder_points; the fits are decco_warp.analysis.convergence's.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from figures import LADDER_ETAS, LADDER_SERIES, ladder_points  # noqa: E402

from decco_warp.analysis.convergence import power_law_slope, resolution_limit  # noqa: E402
from decco_warp.checks import InputError  # noqa: E402

#: The size change's slope is read from the paper's resolution up: at 1 562 grains it changes sign
#: between realizations (a ~1 000-grain pile is too coarse for it, validation.md).
SLOPE_FROM = 6000


def main() -> None:
    for label, folders in LADDER_SERIES:
        points = ladder_points(folders)
        print(f"{label}:")
        for eta in LADDER_ETAS:
            mine = [p for p in points if p["eta"] == eta]
            n = np.array([p["n"] for p in mine], dtype=float)
            m = np.array([p["value"] for p in mine])
            try:
                limit = resolution_limit(n, m)
                text = (f"m_lf/m_t -> {limit.value:.3f} ({limit.low:.3f} to {limit.high:.3f}), beta {limit.beta:.2f}, "
                        f"{limit.runs} runs at {limit.rungs} counts; the fit at 6 250 / 25 000: "
                        f"{limit.at(6250):.3f} / {limit.at(25000):.3f}")  # fmt: skip
            except (InputError, RuntimeError) as error:
                text = f"no limit: {error}"
            sized = [p for p in mine if p["size_change"] is not None and p["n"] >= SLOPE_FROM]
            try:
                slope = power_law_slope([p["n"] for p in sized], [p["size_change"] for p in sized])
                text += (f"; size change ~ N^{slope.value:.2f} ({slope.low:.2f} to {slope.high:.2f}), "
                         f"x {slope.per_fourfold:.2f} a fourfold N, {slope.runs} runs")  # fmt: skip
            except InputError as error:
                text += f"; no size-change slope: {error}"
            print(f"  eta {eta:g}: {text}")


if __name__ == "__main__":
    main()
