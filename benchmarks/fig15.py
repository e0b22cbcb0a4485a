"""Reproduce Fig. 15 of [GargNayar2007]: sigma_r (Eq. 27) against T, N and z0, as three PNGs.

Caption settings: (a) T = 8-125 ms, f = 3155 px, N = 5.6, z0 = 10 m;
(b) N = 1.8-8, f = 8000 px, T = 16 ms, z0 = 14 m; (c) z0 = 4-40 m,
f = 8000 px, T = 16 ms, N = 6.7; pixel pitch of the Canon XL1 profile
(6.7 um), single drop radius a_ref = 0.5 mm, rain-visible limit R = 3.

    python benchmarks/fig15.py OUT_DIR

Prints the shape checks the paper describes: (a) sigma_r sqrt(T) constant,
(b) the slope in N at the end as a fraction of the slope at the start,
(c) where the interior maximum lies.
"""

from __future__ import annotations

import sys

import numpy as np


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    out = argv[0] if argv else "fig15"
    from raingauge.cli import main as cli
    from raingauge.commands.visibility import fig15_curves
    from raingauge.profile import load_profile

    rc = cli(["visibility", "--camera", "canon_xl1", "--fig15", out])
    curves = fig15_curves(load_profile("canon_xl1").pixel_pitch_m, n_points=60)
    _, t, s = curves["a"]
    k = s * np.sqrt(t)
    print(f"(a) sigma_r * sqrt(T): {k.min():.6g} .. {k.max():.6g} (falls as 1/sqrt(T)); "
          f"sigma_r(8 ms) / sigma_r(125 ms) = {s[0] / s[-1]:.3f}")
    _, n, s = curves["b"]
    slope = np.diff(s) / np.diff(n)
    print(f"(b) sigma_r(N=8) / sigma_r(N=1.8) = {s[-1] / s[0]:.3f}; final slope / initial slope = "
          f"{slope[-1] / slope[0]:.3f} (rises, then flattens)")
    _, z, s = curves["c"]
    i = int(np.argmax(s))
    print(f"(c) maximum at z0 = {z[i]:.1f} m; sigma_r(4 m) / max = {s[0] / s[i]:.3f}, "
          f"sigma_r(40 m) / max = {s[-1] / s[i]:.3f}")
    return rc


if __name__ == "__main__":
    sys.exit(main())
