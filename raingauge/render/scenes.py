"""Rain-free scenes for the rain simulator: backgrounds and scripted scene motion.

A :class:`Scene` gives, for frame index k, the linear irradiance E_b of the
background [gray levels, the units of ``profile.linearize``], shape (M, N),
float32.  It is the I_b of Eqs. (16)-(18) [GargNayar2007] before rain is added.

Backgrounds (``background=``)
-----------------------------
``uniform:LEVEL``          constant code value LEVEL (0-255).
``ramp:LO:HI``             horizontal ramp of code values from LO (left) to HI (right).
``stripes:L1:L2:...``      horizontal stripes of the given code values, top to
                           bottom (the test scene of Fig. 8(b)).
``skimage:NAME`` / ``NAME``  a scene shipped with scikit-image (``camera``, ``astronaut``,
                           ``coffee``, ``brick``, ``grass``, ``gravel``, ...), see
                           :data:`SKIMAGE_SCENES`.
a path                     an image file, or a video file / folder of images (played
                           in a loop).
Images are converted to gray, centre-cropped to the profile's aspect ratio and
resized to its size; code values are linearised with the profile's response.

Scripted motion (``motion=``, a list of items, or one string of items joined by ``+``)
------------------------------------------------------------------------------------
The hard rain-free cases of Fig. 1(d, e) [GargNayar2007]:

``pan:SPEED[:DIR_DEG]``      the camera pans: the image moves at SPEED px/s; DIR (0 =
                             right, 90 = down) is the direction the camera's view moves
                             over the scene (the scene drifts the opposite way on screen).
                             Every frame integrates the moving scene over the exposure
                             (see :func:`pan_exposure`), so all frames are equally sharp.
``objects:COUNT[:SPEED]``    COUNT textured ellipses cross the scene at about SPEED px/s.
``ripples[:AMPLITUDE]``      water ripples (circular waves, relative amplitude) in
                             the lower third of the frame.
``foliage[:AMPLITUDE_PX]``   swaying foliage: a smooth, time-varying horizontal warp of
                             the upper half of the frame.

Notes
-----
The rain volume stays fixed to the camera during a pan: at pan rates of tens of
px/s the apparent motion of drops (10^3-10^5 px/s) changes by well under 1 %.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Sequence

import numpy as np

from raingauge.errors import ConfigError, InputError

__all__ = ["Scene", "SKIMAGE_SCENES", "MOTION_KINDS", "parse_motion", "level_to_linear", "pan_exposure",
           "PAN_PSF_SIGMA_PX"]

#: scikit-image scenes available offline (names of ``skimage.data`` functions)
SKIMAGE_SCENES = ("astronaut", "brick", "camera", "cat", "chelsea", "coffee", "coins", "grass",
                  "gravel", "horse", "moon", "page", "rocket", "text", "clock", "cell",
                  "hubble_deep_field", "immunohistochemistry", "retina", "colorwheel", "checkerboard")

MOTION_KINDS = ("pan", "objects", "ripples", "foliage")


def level_to_linear(profile, level: float) -> float:
    """Linear intensity [gray levels] of an 8-bit code value (fractional codes interpolate)."""
    table = np.asarray(profile.response_table, dtype=np.float64)
    return float(np.interp(float(level), np.arange(256.0), table))


def _parse_levels(spec: str, parts: Sequence[str], count: int | None) -> list[float]:
    try:
        levels = [float(p) for p in parts]
    except ValueError:
        raise ConfigError(f"background {spec!r}: levels must be numbers (code values 0-255)") from None
    if count is not None and len(levels) != count:
        raise ConfigError(f"background {spec!r}: expected {count} level(s)")
    if not levels or any(not (0.0 <= v <= 255.0) for v in levels):
        raise ConfigError(f"background {spec!r}: levels must lie in 0..255")
    return levels


def _fit_image(img: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Gray uint8 image centre-cropped to the aspect of ``shape`` and resized to it."""
    import cv2

    if img.ndim == 3:
        if img.shape[2] == 4:
            img = img[:, :, :3]
        img = cv2.cvtColor(np.ascontiguousarray(img), cv2.COLOR_RGB2GRAY)
    if img.dtype != np.uint8:
        img = img.astype(np.float64)
        hi = img.max() if img.max() > 0 else 1.0
        img = np.clip(img / (hi if hi > 255 or hi <= 1.0 else 255.0) * 255.0, 0, 255).astype(np.uint8)
    m, n = shape
    h, w = img.shape
    target = n / m
    if w / h > target:
        cw = max(1, int(round(h * target)))
        x0 = (w - cw) // 2
        img = img[:, x0:x0 + cw]
    else:
        ch = max(1, int(round(w / target)))
        y0 = (h - ch) // 2
        img = img[y0:y0 + ch, :]
    interp = cv2.INTER_AREA if img.shape[0] > m else cv2.INTER_CUBIC
    return cv2.resize(img, (n, m), interpolation=interp)


def parse_motion(motion) -> list[tuple[str, list[float]]]:
    """Parse motion items (``"pan:30"``, ``"ripples"``, ... or a ``+``-joined string) into (kind, params)."""
    if motion is None:
        return []
    items = motion.split("+") if isinstance(motion, str) else list(motion)
    out = []
    for item in items:
        item = str(item).strip()
        if not item or item == "none":
            continue
        kind, *params = item.split(":")
        kind = kind.strip().lower()
        if kind not in MOTION_KINDS:
            raise ConfigError(f"unknown scene motion {kind!r}; valid: {', '.join(MOTION_KINDS)} "
                              f"(e.g. pan:40, objects:3:60, ripples:0.1, foliage:2)")
        try:
            values = [float(p) for p in params]
        except ValueError:
            raise ConfigError(f"scene motion {item!r}: parameters must be numbers") from None
        limits = {"pan": 2, "objects": 2, "ripples": 1, "foliage": 1}
        if len(values) > limits[kind]:
            raise ConfigError(f"scene motion {item!r}: {kind} takes at most {limits[kind]} parameter(s)")
        out.append((kind, values))
    return out


#: Gaussian point-spread function of the camera applied to a panning scene [px] (lens and pixel aperture)
PAN_PSF_SIGMA_PX = 0.6


def _symmetric_spectrum(img: np.ndarray, velocity: tuple[float, float]):
    """Real FFT of ``img`` mirrored along the axes the pan moves on (periodic, no edge jump)."""
    from scipy import fft as sfft

    axes = tuple(ax for ax, v in ((0, velocity[1]), (1, velocity[0])) if v != 0.0)
    ext = np.asarray(img, np.float32)
    for ax in axes:
        ext = np.concatenate([ext, np.flip(ext, axis=ax)], axis=ax)
    if not axes:
        return axes, ext
    return axes, sfft.rfftn(ext, axes=axes, workers=1)


def pan_exposure(img: np.ndarray, velocity_px_s: tuple[float, float], t_s: float, exposure_s: float, *,
                 psf_sigma_px: float = PAN_PSF_SIGMA_PX, spectrum=None) -> np.ndarray:
    """The frame a panning camera records: ``img`` moving at ``velocity`` integrated over the exposure.

    ``frame(x) = (1 / T) int_0^T (g * img)(x + v (t + s)) ds``, with g a
    Gaussian point-spread function of ``psf_sigma_px``, evaluated exactly in
    the Fourier domain on the image mirrored about its edges (so the scene
    continues by reflection, and a long pan goes on indefinitely).

    Parameters
    ----------
    img : (M, N) float array
        Scene [gray levels], one sample per pixel.
    velocity_px_s : (vx, vy)
        Image motion of the scene [px/s]; the frame at time t shows the scene
        point x + v t at pixel x.
    t_s : float
        Start of the exposure [s].
    exposure_s : float
        Exposure time T [s]: the motion blur is a box of length |v| T.
    psf_sigma_px : float
        Optical point-spread function [px].
    spectrum : optional
        ``_symmetric_spectrum(img, velocity)`` computed beforehand.

    Returns
    -------
    (M, N) float32 array

    Notes
    -----
    Resampling a sub-pixel shift with a short kernel (bilinear, bicubic)
    blurs each frame by an amount that depends on the fractional part of the
    shift: at 2/3 px per frame every third frame is sharper than its
    neighbours, and texture peaks then look like one-frame spikes (Eq. 19).
    A real pan moves a continuous image past the sensor: every frame has the
    same sharpness.  The Fourier shift keeps the magnitude spectrum of every
    frame equal (a pure phase ramp), and the Gaussian PSF makes the scene
    close to band-limited, so no ringing appears at sharp edges.
    """
    from scipy import fft as sfft

    vx, vy = float(velocity_px_s[0]), float(velocity_px_s[1])
    m, n = img.shape
    if spectrum is None:
        spectrum = _symmetric_spectrum(img, (vx, vy))
    axes, spec = spectrum
    if not axes:
        return np.array(img, np.float32, copy=True)
    # shift at the middle of the exposure, box blur of the exposure's length
    mid = (vx * (t_s + 0.5 * exposure_s), vy * (t_s + 0.5 * exposure_s))
    ext_shape = [m, n]
    for ax in axes:
        ext_shape[ax] *= 2
    freqs = []
    for ax in (0, 1):
        if ax not in axes:
            freqs.append(None)
            continue
        size = ext_shape[ax]
        f = (sfft.rfftfreq(size) if ax == axes[-1] else sfft.fftfreq(size)).astype(np.float64)
        freqs.append(f)
    factor = None
    for ax, d, v in ((0, mid[1], vy), (1, mid[0], vx)):
        f = freqs[ax]
        if f is None:
            continue
        shape = [1, 1]
        shape[ax] = f.size
        g = np.exp(-2.0 * (math.pi * psf_sigma_px * f) ** 2)
        term = (np.exp(2j * math.pi * f * d) * g).reshape(shape)
        factor = term if factor is None else factor * term
    # motion blur along the pan direction (not separable for a diagonal pan)
    fy = freqs[0].reshape(-1, 1) if freqs[0] is not None else 0.0
    fx = freqs[1].reshape(1, -1) if freqs[1] is not None else 0.0
    blur = np.sinc((fx * vx + fy * vy) * exposure_s)
    out = sfft.irfftn(spec * (factor * blur).astype(np.complex64), s=[ext_shape[ax] for ax in axes],
                      axes=axes, workers=1)
    return np.ascontiguousarray(out[:m, :n], dtype=np.float32)


class Scene:
    """Rain-free background frames in linear units.

    Parameters
    ----------
    profile : CameraProfile
        Gives the frame size, the frame rate and the radiometric response.
    background : str or ndarray
        See the module docstring; an array is taken as 8-bit code values (M, N).
    motion : str or list of str, optional
        Scripted motion items (module docstring).
    seed : int or numpy.random.Generator
        Random source for the motion scripts (object shapes, ripple centres, ...).
    """

    def __init__(self, profile, background="uniform:60", motion=None, seed=0):
        self.profile = profile
        self.shape = (int(profile.height_px), int(profile.width_px))
        self.fps = float(profile.frame_rate_hz)
        self.spec = background if isinstance(background, str) else "array"
        self._video = None
        self._base = self._load(background)
        self.motion = parse_motion(motion)
        rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
        self._setup_motion(rng)
        self.static = not self.motion and self._video is None

    # ---------------------------------------------------------------- loading
    def _linear(self, codes: np.ndarray) -> np.ndarray:
        return self.profile.linearize(np.asarray(codes, dtype=np.uint8)).astype(np.float32)

    def _load(self, background) -> np.ndarray:
        m, n = self.shape
        if isinstance(background, np.ndarray):
            arr = np.asarray(background)
            if arr.ndim == 3:
                arr = _fit_image(arr, self.shape)
            if arr.shape != self.shape:
                arr = _fit_image(arr.astype(np.uint8), self.shape)
            return self._linear(arr)
        if not isinstance(background, str) or not background:
            raise ConfigError(f"background must be a string or an array, got {background!r}")
        spec = background.strip()
        kind, _, rest = spec.partition(":")
        kind_l = kind.lower()
        if kind_l == "uniform" and rest:
            (level,) = _parse_levels(spec, rest.split(":"), 1)
            return np.full(self.shape, level_to_linear(self.profile, level), np.float32)
        if kind_l == "ramp" and rest:
            lo, hi = _parse_levels(spec, rest.split(":"), 2)
            row = np.linspace(lo, hi, n)
            table = np.asarray(self.profile.response_table, dtype=np.float64)
            lin = np.interp(row, np.arange(256.0), table)
            return np.broadcast_to(lin.astype(np.float32), self.shape).copy()
        if kind_l == "stripes" and rest:
            levels = _parse_levels(spec, rest.split(":"), None)
            idx = np.minimum((np.arange(m) * len(levels)) // m, len(levels) - 1)
            lin = np.array([level_to_linear(self.profile, v) for v in levels], np.float32)[idx]
            return np.broadcast_to(lin[:, None], self.shape).copy()
        name = rest if kind_l == "skimage" and rest else spec
        if kind_l == "skimage" or (name in SKIMAGE_SCENES and not Path(spec).exists()):
            if name not in SKIMAGE_SCENES:
                raise InputError(f"unknown scikit-image scene {name!r}; valid: {', '.join(SKIMAGE_SCENES)}")
            import skimage.data

            try:
                img = getattr(skimage.data, name)()
            except Exception as exc:  # data not available offline
                raise InputError(f"scikit-image scene {name!r} cannot be loaded ({exc}). "
                                 "Fix: choose another scene or give an image file") from None
            return self._linear(_fit_image(np.asarray(img), self.shape))
        path = Path(spec)
        if not path.exists():
            raise InputError(
                f"background {spec!r}: no such file or folder. Fix: give an image or video path, "
                f"uniform:LEVEL, ramp:LO:HI, stripes:L1:L2:..., or a scikit-image scene "
                f"({', '.join(SKIMAGE_SCENES[:6])}, ...)")
        from raingauge.videoio import IMAGE_SUFFIXES, FrameReader

        if path.is_file() and path.suffix.lower() in IMAGE_SUFFIXES:
            import cv2

            img = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
            if img is None or img.size == 0:
                raise InputError(f"background {path}: unreadable image. Fix: give a PNG/JPEG/TIFF file")
            return self._linear(_fit_image(img, self.shape))
        try:
            reader = FrameReader(path, mode="gray")
            frames = [self._linear(_fit_image(f, self.shape)) for f in reader]
        except InputError:
            raise
        except Exception as exc:
            raise InputError(f"background {path}: cannot be read as a video ({exc}). "
                             "Fix: give an image, a video file or a folder of images") from None
        if not frames:
            raise InputError(f"background {path}: no readable frame. Fix: check the file")
        if len(frames) == 1:
            return frames[0]
        self._video = frames
        return frames[0]

    # ----------------------------------------------------------------- motion
    def _setup_motion(self, rng: np.random.Generator) -> None:
        m, n = self.shape
        self._objects = []
        self._ripples = None
        self._foliage = None
        for kind, p in self.motion:
            if kind == "pan":
                speed = p[0] if p else 30.0
                ang = math.radians(p[1] if len(p) > 1 else 0.0)
                self._pan = (speed * math.cos(ang), speed * math.sin(ang))
            elif kind == "objects":
                count = int(p[0]) if p else 2
                speed = p[1] if len(p) > 1 else 60.0
                if count < 0 or count > 1000:
                    raise ConfigError("scene motion objects: COUNT must be 0..1000")
                for _ in range(count):
                    ry = rng.uniform(0.08, 0.2) * m
                    rx = ry * rng.uniform(0.4, 1.0)
                    level = rng.uniform(20.0, 230.0)
                    texture = rng.uniform(-25.0, 25.0, size=(8, 8))
                    ang = rng.uniform(-0.4, 0.4) + (0.0 if rng.random() < 0.5 else math.pi)
                    vel = speed * rng.uniform(0.6, 1.4) * np.array([math.cos(ang), math.sin(ang) * 0.3])
                    start = np.array([rng.uniform(0, n), rng.uniform(0.2 * m, 0.8 * m)])
                    self._objects.append((start, vel, rx, ry, level, texture))
            elif kind == "ripples":
                amp = p[0] if p else 0.12
                k = rng.uniform(0.25, 0.6, size=6)              # rad/px
                omega = rng.uniform(4.0, 9.0, size=6)            # rad/s
                cx = rng.uniform(0, n, size=6)
                cy = rng.uniform(2 * m / 3, m, size=6)
                phase = rng.uniform(0, 2 * math.pi, size=6)
                y0 = (2 * m) // 3
                yy, xx = np.mgrid[y0:m, 0:n].astype(np.float32)
                # k |r - c_i| + phase_i, fixed; each frame only shifts the phase by omega_i t
                spatial = [(k[i] * np.hypot(xx - cx[i], yy - cy[i]) + phase[i]).astype(np.float32)
                           for i in range(6)]
                self._ripples = (amp, omega, spatial, y0)
            elif kind == "foliage":
                amp = p[0] if p else 2.0
                import cv2

                field = rng.standard_normal((max(2, m // 32), max(2, n // 32)))
                field = cv2.resize(field, (n, m), interpolation=cv2.INTER_CUBIC)
                field = (field - field.mean()) / (field.std() + 1e-9)
                self._foliage = (amp, field.astype(np.float32), rng.uniform(1.5, 3.5))
        if not hasattr(self, "_pan"):
            self._pan = None
        # a bit of texture so that a pan shows on uniform or smooth backgrounds
        if self._pan is not None and float(np.ptp(self._base)) < 1.0:
            import cv2

            tex = rng.standard_normal((max(2, m // 16), max(2, n // 16)))
            tex = cv2.resize(tex, (n, m), interpolation=cv2.INTER_CUBIC).astype(np.float32)
            self._base = np.clip(self._base + 15.0 * tex, 0, 255).astype(np.float32)

    def _pan_spectrum(self):
        """Spectrum of the static background's symmetric extension, computed once (see :func:`pan_exposure`)."""
        if getattr(self, "_pan_spec", None) is None:
            self._pan_spec = _symmetric_spectrum(self._base, self._pan)
        return self._pan_spec

    def describe(self) -> dict:
        """The scene as written into the truth."""
        return {"background": self.spec, "motion": [f"{k}:{':'.join(f'{v:g}' for v in p)}".rstrip(":")
                                                    for k, p in self.motion]}

    def bounds(self) -> tuple[float, float]:
        """(min, max) linear background intensity the scene can reach [gray levels]."""
        if self.static:
            return float(self._base.min()), float(self._base.max())
        top = float(self.profile.response_table[-1])
        return 0.0, top

    def frame(self, k: int) -> np.ndarray:
        """Background E_b for frame ``k``, (M, N) float32 linear (do not modify in place)."""
        import cv2

        t = k / self.fps
        img = self._video[k % len(self._video)] if self._video is not None else self._base
        if self.static:
            return img
        m, n = self.shape
        if self._pan is not None:
            img = pan_exposure(img, self._pan, t, float(self.profile.exposure_s),
                               spectrum=None if self._video is not None else self._pan_spectrum())
        else:
            img = img.copy()
        if self._foliage is not None:
            amp, field, omega = self._foliage
            half = m // 2
            disp = amp * np.sin(omega * t + 2.0 * field[:half])
            map_x = (np.arange(n, dtype=np.float32)[None, :] + disp).astype(np.float32)
            map_y = np.repeat(np.arange(half, dtype=np.float32)[:, None], n, axis=1)
            img[:half] = cv2.remap(img, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT_101)
        if self._ripples is not None:
            amp, omega, spatial, y0 = self._ripples
            wave = np.zeros_like(spatial[0])
            for i, field in enumerate(spatial):
                wave += np.sin(field - np.float32(omega[i] * t))
            img[y0:] = img[y0:] * (1.0 + (2.0 * amp / len(spatial)) * wave)
        for start, vel, rx, ry, level, texture in self._objects:
            cxy = start + vel * t
            cxy[0] = (cxy[0] + rx) % (n + 2 * rx) - rx
            x_lo, x_hi = int(max(0, cxy[0] - rx - 1)), int(min(n, cxy[0] + rx + 2))
            y_lo, y_hi = int(max(0, cxy[1] - ry - 1)), int(min(m, cxy[1] + ry + 2))
            if x_lo >= x_hi or y_lo >= y_hi:
                continue
            yy, xx = np.mgrid[y_lo:y_hi, x_lo:x_hi].astype(np.float32)
            u, v = (xx - cxy[0]) / rx, (yy - cxy[1]) / ry
            inside = np.clip((1.0 - np.hypot(u, v)) * min(rx, ry), 0.0, 1.0)
            ti = np.clip(((u + 1) * 3.999).astype(int), 0, 7)
            tj = np.clip(((v + 1) * 3.999).astype(int), 0, 7)
            obj = level + texture[tj, ti]
            patch = img[y_lo:y_hi, x_lo:x_hi]
            img[y_lo:y_hi, x_lo:x_hi] = patch * (1 - inside) + obj * inside
        np.clip(img, 0.0, float(self.profile.response_table[-1]), out=img)
        return img
