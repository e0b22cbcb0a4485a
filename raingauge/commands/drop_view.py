"""Look at the world through a raindrop: a near-perspective view from an image of a drop (Fig. 7).

A drop refracts a ~165 degree view of the scene behind it into its small
circular image (Sec. 4.2.2 of Garg & Nayar 2007).  This command finds the drop
(or takes its centre and radius), inverts the refraction mapping (Eq. 7) and
writes the perspective view a pinhole camera at the drop would see, looking
away from the camera.  Straight lines in the scene come out straight.

    raingauge drop-view drop.png --out view.png --fov 90
    raingauge drop-view drop.png --out view.png --center 412 305 --radius 57.5
"""

from __future__ import annotations

import argparse
from pathlib import Path


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("image", help="image file containing the drop")
    parser.add_argument("--out", required=True, help="output image (PNG, TIFF, ...)")
    parser.add_argument("--fov", type=float, default=90.0, metavar="DEG",
                        help="field of view of the output, degrees (default 90; below the drop's ~165)")
    parser.add_argument("--center", type=float, nargs=2, default=None, metavar=("X", "Y"),
                        help="column and row of the drop's centre, px (default: found automatically)")
    parser.add_argument("--radius", type=float, default=None, metavar="R",
                        help="radius of the drop's image, px (with --center)")
    parser.add_argument("--size", type=int, default=None, metavar="PX",
                        help="side of the square output, px (default: the drop's diameter, at least 64)")
    parser.add_argument("--mu", type=float, default=1.333,
                        help="refractive index of the drop (default 1.333, water; 1.49 acrylic)")
    parser.add_argument("--no-flatten", action="store_true",
                        help="keep the darkening towards the rim (Fresnel, Eq. 9) instead of undoing it")


def run(args: argparse.Namespace) -> int:
    import cv2
    import numpy as np

    from raingauge.errors import ConfigError, InputError
    from raingauge.render.drop import drop_to_perspective, find_drop

    src = Path(args.image)
    if src.is_dir():
        raise InputError(f"{src} is a folder; give the image file of the drop")
    if not src.is_file():
        raise InputError(f"image not found: {src}; give the path of a photograph of the drop")
    img = cv2.imread(str(src), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise InputError(f"cannot decode {src} as an image; give a PNG, JPEG or TIFF file")
    if img.ndim == 3 and img.shape[2] == 4:
        img = img[:, :, :3]
    out = Path(args.out)
    if not out.parent.exists():
        raise ConfigError(f"output folder {out.parent} does not exist; create it or choose another --out")
    if not cv2.haveImageWriter(str(out)):
        raise ConfigError(f"--out {out}: OpenCV writes no image of that extension; use .png, .tif or .jpg")
    if (args.center is None) != (args.radius is None):
        raise ConfigError("give --center X Y and --radius R together, or neither to find the drop "
                          "automatically")
    if not 1.0 < args.mu < 3.0:
        raise ConfigError(f"--mu must be a refractive index between 1 and 3, got {args.mu}")
    if args.size is not None and not 8 <= args.size <= 8192:
        raise ConfigError(f"--size must be between 8 and 8192 px, got {args.size}")
    if args.center is None:
        cx, cy, r = find_drop(img)
        how = "found"
    else:
        cx, cy = args.center
        r = args.radius
        if not r > 1:
            raise ConfigError(f"--radius must be more than 1 px, got {r}")
        if not (0 <= cx < img.shape[1] and 0 <= cy < img.shape[0]):
            raise ConfigError(f"--center ({cx}, {cy}) lies outside the {img.shape[1]}x{img.shape[0]} image")
        how = "given"
    size = args.size or max(64, int(round(2 * r)))
    view = drop_to_perspective(img, center_xy=(cx, cy), radius_px=r, fov_deg=args.fov, size_px=size,
                               mu=args.mu, flatten=not args.no_flatten)
    top = 65535 if img.dtype == np.uint16 else 255
    dtype = np.uint16 if img.dtype == np.uint16 else np.uint8
    result = np.clip(np.rint(view), 0, top).astype(dtype)
    if not cv2.imwrite(str(out), result):
        raise InputError(f"cannot write {out}; use an image extension OpenCV knows (.png, .tif, .jpg)")
    print(f"drop {how} at ({cx:.1f}, {cy:.1f}) px, radius {r:.1f} px; "
          f"wrote {out} ({size}x{size} px, field of view {args.fov:g} deg)")
    return 0
