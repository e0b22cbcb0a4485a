"""Completeness of the gauge, measured with artificial drops in its own frames.

The sample volume (:class:`raingauge.gauge.volume.SampleVolume`) predicts the chance
that a drop of radius a at depth z is detected, measured and passes the defocus tests,
and how large it then looks, from a model of the streak over a locally uniform
background (Eqs. 17-19, 23-27 [GargNayar2007]).  A real scene departs from it: a streak
crossing a textured background changes its contrast E_r - I_b along its length and is
detected in pieces, a moving object hides the rain in front of it from the three-frame
test, noise breaks faint streaks and biases their widths.  None of it is in the model,
and all of it biases the rate.

The probe measures the bias where it happens.  In every few analysed frames it renders
artificial streaks of drops of known radius and depth (the uniform capsule of Eqs. 15-17
with the blur circle of Eq. 23, at the drop brightness E_r the gauge estimated, falling
at the velocity law's speed along the rain's measured direction) into copies of crops of
the frame, placed anywhere, runs them through the frame's own detection, measurement,
tests and sizing, and compares what the gauge makes of them with what they are.

The drops go into the copy of frame n as it is, with its rain, anywhere in the frame:
a drop there meets what a real drop of frame n meets, the streaks of frame n it may touch
and merge with (in rain of 100 mm/h a third of the drops), and the streaks of frames n-1
and n+1 that hide it from the three-frame test.  So the probe measures the losses to
merging too, which the gauge then does not count up again (the analytic merge chance of
:func:`raingauge.gauge.gauge.merge_probability` is for a gauge without the probe).  A
real drop of frame n that is whole and counted within the small reach that matches a
measured streak to an injected drop is rare (the counted drops are a few per frame).
Each crop is grown to hold whole the frame's streaks that reach into it
(:meth:`CompletenessProbe.enlarge`): a drop merged with one meets all of it in the canvas,
as in the frame.  Only a blob many times the crop (a moving object) stays cut, and a
drop merged with it counts as lost (:meth:`CompletenessProbe.cut_components`).  A drop
merged with streaks of the frame is credited with the merged blob as the gauge counts
it; where those streaks were counted alone (drops of the sample volume) the blob is
split fairly, the drop taking its own share and half of what the merge gained or lost,
so that over all drops the credits add up to what the gauge counts.  At 100 mm/h half
the drops lie in such blobs (mostly with streaks of defocused drops and specks of
noise).  Given the simulator's drop brightness, 30 s at 100 mm/h read 1.00 and 1.05 on
the dark backdrop (noise 1 and 3) and 1.01 on the textured one so; with the crops
cutting the frame's streaks and a drop merged with a cut piece counted lost, 1.18, 1.27
and 1.30, and kept as the canvas shows it, 1.05, 1.15 and 1.14.
The probe's drops also calibrate the drop brightness E_r the gauge estimates from its
streaks (:meth:`raingauge.gauge.gauge.RainGauge._brightness_q_of_contrast`): their
measured focus, against the E_r they were drawn with, gives the reference percentile the
streaks' is divided by.  In heavy rain a streak is lit further by the drops it overlaps,
and with the model's reference the estimate ran 3-5 % high at 100 mm/h, which the rate
follows several times over (and which had made up for the merges the cut crops counted
lost).
Placing the drops only where nothing was detected, as clear of the real streaks, would
bias the probe: the places where frame n shows no streak are those where frame n had no
drop or where a drop of frame n-1 or n+1 hid it, so they hide drops more often than the
frame does on the whole (in heavy, noisy rain over a bright sky the probe then finds its
drops at half the rate the real ones are found, and the gauge reads 1.5 times the rain).
Wiping frame n's detected streaks out of the copy instead, and leaving the merges with
them to the analytic chance, falls short: on textured scenes and in front of moving
objects that chance (from the density of the streaks detected there) misses merges, and
rain of 100 mm/h reads 0.81-0.86 of the truth (0.83-0.97 with the merges in the probe).

The injected streak is added as a real one is: over frame n's noisy pixels the change
beta (E_r - I_b) keeps only 1 - beta of their noise, so the rest is added back, and the
8-bit copy of frame n, rounded by the camera already, is rounded once more only after
drawing each pixel's value within its code's rounding interval, about what the
neighbour frames show there (rounded twice, a faint streak's change of 0.6 gray levels
becomes 1 at every pixel along it and is found more often than a real streak of that
change; drawn uniformly in the interval, the value is spread more than the camera's).

The correction is a ratio of sums over the injections of about the last window
(``memory_s``), and its sampling error adds to the rate's; the gauge reweights a window's
drops with the latest correction when it reports, and :meth:`CompletenessProbe.adapt`
probes more often (every ``fastest`` frames at most) while that error exceeds half the
rest of the rate's error, less often (every ``every`` frames) once it does not.  Against a
bright sky at 3 gray levels of noise one 30-s clip read 0.76-0.90 of the truth with the
probe's seed alone at the fixed effort of every sixth frame, 0.87-0.91 with the effort
set so (every second frame there).

Each injected drop i (radius a_i, depth z_i drawn uniformly over the
span Z_i where it can pass at all, :meth:`SampleVolume.depth_span`) stands for the
volume (z_i / f)^2 Z_i per pixel of image; the gauge turns it, when counted, into
(2 a_m)^3 v_m / kappa(a_m) (its own a, v and kappa), so per radius class

    c(a) = sum_i [counted_i] (z_i / f)^2 Z_i (2 a_m)^3 v_m / kappa(a_m)  /  sum_i (2 a_i)^3 v_i

is the factor by which the gauge over-reads (c > 1) or under-reads (c < 1) the rain of
drops of that size in this scene; the gauge multiplies kappa(a) by it.  The estimate is
shrunk toward the ratio pooled over all sizes while a class has few injections, and is 1
until ``min_injections`` were made.  This is the completeness test of crowded-field
photometry: artificial stars added to the images and measured as the real ones.

Pinned to one radius and depth (:meth:`CompletenessProbe.pin`), the probe's drops are
counted as often as the same drops rendered into the video by the simulator
(:func:`raingauge.gauge.fidelity.probe_fidelity`: 0.214 and 0.214 at a = 0.5 mm in focus
against the bright sky at 3 gray levels of noise, 0.074 and 0.073 at 0.45 mm and 2.48 m).
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from raingauge.gauge import _kernels
from raingauge.gauge._numeric import clip as _clip

__all__ = ["CompletenessProbe", "CLASS_EDGES_M"]

#: Edges of the probe's radius classes [m] (drop diameters 0.3-5.6 mm).
CLASS_EDGES_M = np.array([0.15e-3, 0.25e-3, 0.4e-3, 0.6e-3, 0.9e-3, 1.4e-3, 2.0e-3, 2.8e-3])

#: Clear margin around an injected streak inside its crop [px] (the detection's smoothing,
#: the measurement's flanks and the edge margin fit in it).
CROP_MARGIN_PX = 12

#: Clear columns between crops side by side in the probe's canvas [px], and clear rows
#: between its shelves of crops: more than the detection's reach along the fall (its
#: smoothing, its growth along the column and the gap it merges the pieces of a streak
#: across), so that nothing in one crop meets another.
CANVAS_GAP_PX = 2
CANVAS_GAP_ROWS = 16

#: A crop grows to hold the frame's components reaching into it up to this many times its
#: height or width (:meth:`CompletenessProbe.enlarge`) [-].
ENLARGE_REACH = 4.0

#: Per-class sums a recorded frame keeps: injected, counted, x (the gauge's estimate),
#: y (the model's), p (pass probability), x^2, y^2, x y.
_SUMS = ("n", "counted", "x", "y", "p", "xx", "yy", "xy")

#: The correction's sampling error is held under this share of the rest of the rate's
#: error (:meth:`CompletenessProbe.adapt`): in quadrature it then widens it by at most
#: 12 % [-].
PROBE_SD_SHARE = 0.5

#: Bounds of the correction factor [-].
CORRECTION_RANGE = (0.1, 10.0)


class CompletenessProbe:
    """Artificial drops injected into the gauge's frames: the factor c(a) by which the gauge
    reads the rain of drops of each radius class in this scene (module docstring).

    Parameters
    ----------
    profile : CameraProfile
    volume : SampleVolume
        The nominal sample volume (its depth spans and its lowest measurable radius).
    velocity_model : str
        The law the injected drops fall at.
    per_frame : int
        Drops injected per probed frame.
    every : int
        Probe every this many frames at the least effort (:meth:`adapt` probes more
        often while the correction is less certain than the rest of the rate).
    fastest : int
        Probe every this many frames at the most effort, once mature (the probe's share
        of the gauge's time at 1280x720: 10-15 % at ``every`` = 6, up to about 45 % at 2).
    history : int
        Injections remembered at most (the latest) [-].
    memory_s : float, optional
        Injections older than this, before the latest one, are forgotten [s] (given the
        times in :meth:`record`): the correction follows the scene over about a window.
    min_injections : int
        Injections before the correction differs from 1.
    prior_passes : float
        Weight of the pooled ratio in each class, in drops the model expects to pass.
    seed : int
        Seed of the probe's own random numbers (the gauge stays deterministic).
    """

    def __init__(self, profile, volume, velocity_model: str, *, per_frame: int = 16, every: int = 6,
                 fastest: int = 2, history: int = 50000, memory_s: float | None = None, min_injections: int = 300,
                 prior_passes: float = 10.0, seed: int = 2718):
        if per_frame < 1 or every < 1 or fastest < 1:
            raise ValueError(f"per_frame, every and fastest must be >= 1, got {per_frame!r}, {every!r}, "
                             f"{fastest!r}")
        if memory_s is not None and not memory_s > 0:
            raise ValueError(f"memory_s must be > 0 s, got {memory_s!r}")
        self.every = int(every)
        #: the interval between probed frames now [frames] (1 ... every, :meth:`adapt`)
        self.interval = int(every)
        self.fastest = int(fastest)
        self.history = int(history)
        self.memory_s = None if memory_s is None else float(memory_s)
        self.profile = profile
        self.volume = volume
        self.velocity_model = velocity_model
        self.per_frame = int(per_frame)
        self.min_injections = int(min_injections)
        self.prior_passes = float(prior_passes)
        self._rng = np.random.default_rng(seed)
        # per recorded frame: (t, per-class sums (n_cls, len(_SUMS))); and their total
        self._log: deque = deque()
        self._total = np.zeros((CLASS_EDGES_M.size - 1, len(_SUMS)))
        self._n_records = 0
        self.injected = 0
        self.passed = 0
        # classes the gauge can size at all (the model's kappa is positive in them)
        lo = np.maximum(CLASS_EDGES_M[:-1], volume.min_radius_m)
        self._class_lo = lo
        self._class_hi = CLASS_EDGES_M[1:]
        self._live = self._class_hi > lo * 1.05
        self._next_class = 0
        self._cache = None
        self._pin = None
        #: per recorded injection, when a list: (radius [m], depth [m], counted, model's p,
        #: the gauge's estimate (2 a_m)^3 v_m / kappa(a_m)) (:meth:`record`); None keeps none
        self.outcomes: list | None = None

    @property
    def class_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi): the radii [m] each class's drops are drawn between, uniformly in log a
        (a class's lower edge raised to the smallest size the gauge can size)."""
        return self._class_lo.copy(), self._class_hi.copy()

    @property
    def radius_range(self) -> tuple[float, float]:
        """(smallest, largest) radius [m] the probe's drops are drawn at (nan, nan when the
        gauge can size none)."""
        if not self._live.any():
            return math.nan, math.nan
        return float(self._class_lo[self._live].min()), float(self._class_hi[self._live].max())

    def pin(self, radius_m: float | None, depth_m: float | None = None) -> None:
        """Inject only drops of radius ``radius_m`` [m] at depth ``depth_m`` [m] from now on
        (both None: draw them again over the classes and depth spans).

        For checking the probe against drops of known size and depth rendered into the
        video itself (``benchmarks/diag_probe_fidelity.py``): the pinned drops still weigh
        in their radius class and depth span as drawn ones do.
        """
        if radius_m is None and depth_m is None:
            self._pin = None
            return
        a, z = float(radius_m), float(depth_m)
        if not (a > 0 and z > 0 and math.isfinite(a) and math.isfinite(z)):
            raise ValueError(f"a pinned drop needs a positive radius and depth, got {radius_m!r} m "
                             f"and {depth_m!r} m")
        if not CLASS_EDGES_M[0] <= a < CLASS_EDGES_M[-1]:
            raise ValueError(f"radius {a} m is outside the probe's classes "
                             f"({CLASS_EDGES_M[0]}-{CLASS_EDGES_M[-1]} m)")
        self._pin = (a, z)

    # ------------------------------------------------------------------ injection
    def plan(self, shape, slope: float, *, drift_m_s: float | None = None) -> list[dict]:
        """Drops to inject into a frame of ``shape``: radius, depth, streak end points in the
        frame and the crop around each, placed uniformly over the frame (crops are copied
        apart, so they may overlap).

        Parameters
        ----------
        shape : (int, int)
        slope : float
            The rain's direction dx/dy in the image [-] (when ``drift_m_s`` is not given).
        drift_m_s : float, optional
            The drops' horizontal speed across the image (the wind) [m/s]: each drop then
            slants by drift / v(a), the slower small drops more.
        """
        from raingauge.gauge.volume import _pitch
        from raingauge.physics.camera import blur_circle_px
        from raingauge.physics.drops import fall_velocity

        prof = self.profile
        M, N = shape
        f = prof.focal_length_px
        T = prof.exposure_s
        if self._pin is not None:
            a = np.full(self.per_frame, self._pin[0])
            k = np.full(a.size, int(np.searchsorted(CLASS_EDGES_M, self._pin[0], side="right")) - 1)
            near, far = (np.asarray(x, dtype=float) for x in self.volume.depth_span(a))
            z = np.full(a.size, self._pin[1])
        else:
            live = np.flatnonzero(self._live)
            if live.size == 0:
                return []
            k = live[(self._next_class + np.arange(self.per_frame)) % live.size]
            self._next_class += self.per_frame
            a = np.exp(self._rng.uniform(np.log(self._class_lo[k]), np.log(self._class_hi[k])))
            near, far = self.volume.depth_span(a)
            z = near + self._rng.random(a.size) * (far - near)
        v = np.asarray(fall_velocity(2.0 * a, model=self.velocity_model), dtype=float)
        a_i = f * a / z
        w = np.maximum(2.0 * a_i, 1.0)
        b = np.asarray(blur_circle_px(z, focal_length_px=f, f_number=prof.f_number,
                                      focus_distance_m=prof.focus_distance_m, pixel_pitch_m=_pitch(prof)))
        r = np.maximum(0.5 * (w + b), 0.5)
        L = f * v * T / z
        dx = slope * L if drift_m_s is None else f * float(drift_m_s) * T / z
        with np.errstate(invalid="ignore"):
            ch = np.ceil(L + 2 * r) + 2 * CROP_MARGIN_PX
            cw = np.ceil(np.abs(dx) + 2 * r) + 2 * CROP_MARGIN_PX
            ok = (far > near) & np.isfinite(v) & (v > 0) & (ch < M - 2) & (cw < N - 2)
        out = []
        for i in np.flatnonzero(ok):
            chi, cwi = int(ch[i]), int(cw[i])
            y0 = int(self._rng.integers(1, M - chi))
            x0 = int(self._rng.integers(1, N - cwi))
            # streak centre near the crop's centre, at a random place within the pixel
            # (the measured width depends on it)
            xc = x0 + 0.5 * (cwi - 1) + float(self._rng.uniform(-0.5, 0.5))
            yc = y0 + 0.5 * (chi - 1) + float(self._rng.uniform(-0.5, 0.5))
            out.append({"class": int(k[i]), "radius_m": float(a[i]), "depth_m": float(z[i]),
                        "span_m": float(far[i] - near[i]), "velocity_m_s": float(v[i]), "box": (x0, y0, cwi, chi),
                        "p0": (xc - 0.5 * dx[i], yc - 0.5 * L[i]), "p1": (xc + 0.5 * dx[i], yc + 0.5 * L[i]),
                        "radius_px": float(r[i]), "area_px": math.pi * float(a_i[i]) ** 2,
                        "centre": (xc, yc), "motion_px": float(L[i])})
        return out

    @staticmethod
    def enlarge(plan: list[dict], stats, shape, *, reach: float = ENLARGE_REACH) -> None:
        """Grow each crop of ``plan`` (in place, its ``box``) to hold whole the frame's
        components that reach into it (``stats`` of frame n's labels; merged pieces and
        components too small to measure too) with the clear margin :data:`CROP_MARGIN_PX`
        around them, so that a drop merged with one of them meets all of it in the canvas,
        as in the frame.  A component more than ``reach`` times the crop's height or width
        (a moving object's blob) is left cut: a drop merged with it is lost
        (:meth:`cut_components`).  The streak stays where it was drawn."""
        stats = np.asarray(stats)
        if stats.shape[0] < 2 or not plan:
            return
        M, N = shape
        sx, sy, sw, sh = (stats[1:, i].astype(np.int64) for i in range(4))
        real = (sw > 0) & (sh > 0)
        sx, sy, sw, sh = sx[real], sy[real], sw[real], sh[real]
        ex, ey = sx + sw, sy + sh
        m = CROP_MARGIN_PX
        # which components meet which crop (crops x components), and their extremes
        x0, y0, cw, ch = (np.array([p["box"][i] for p in plan], np.int64)[:, None] for i in range(4))
        meet = ((sx < x0 + cw) & (ex > x0) & (sy < y0 + ch) & (ey > y0)
                & (sw <= reach * cw) & (sh <= reach * ch))
        big = np.iinfo(np.int64).max
        lo_x = np.where(meet, sx, big).min(axis=1)
        lo_y = np.where(meet, sy, big).min(axis=1)
        hi_x = np.where(meet, ex, -big).max(axis=1)
        hi_y = np.where(meet, ey, -big).max(axis=1)
        for j in np.flatnonzero(meet.any(axis=1)).tolist():
            bx, by, bw, bh = plan[j]["box"]
            # (the frame's outermost row and column stay out, as in :meth:`plan`)
            nx0 = max(min(bx, int(lo_x[j]) - m), 1)
            ny0 = max(min(by, int(lo_y[j]) - m), 1)
            nx1 = min(max(bx + bw, int(hi_x[j]) + m), N - 1)
            ny1 = min(max(by + bh, int(hi_y[j]) + m), M - 1)
            plan[j]["box"] = (nx0, ny0, nx1 - nx0, ny1 - ny0)

    def canvas(self, frames, plan: list[dict], drop_brightness_dn: float, *, raws=None, delinearize=None,
               noise_dn: float = 0.0, linear: bool = True):
        """The crops of ``plan`` from frames n-1, n, n+1 side by side, with the artificial
        streaks added to frame n's, over its rain (module docstring; Eq. 17:
        I = I_b + beta (E_r - I_b)).

        Parameters
        ----------
        frames : (prev, cur, nxt) linear float32 (M, N) arrays
        plan : from :meth:`plan`
        drop_brightness_dn : float
            E_r [gray levels].
        raws : (prev, cur, nxt) uint8 arrays, optional
            The 8-bit frames of a linear camera: the crops are returned in 8 bits too, frame
            n's quantised after the streaks were added.
        delinearize : callable, optional
            Linear -> 8-bit codes (with ``raws``).
        noise_dn : float
            The frames' noise sigma [gray levels] (linear): the noise a streak's pixels keep.
        linear : bool
            With ``raws``: also return the linear canvases (False: lin is None, for a
            caller that works on the 8-bit ones alone).

        Returns
        -------
        (lin, raw, centres): lin and raw are (prev, cur, nxt) canvases (raw None without
        ``raws``, lin None with ``raws`` and not ``linear``); centres the streaks' centres
        (x, y) in the canvas [px].  Each crop's place in the canvas is noted in its plan
        entry as ``canvas_box`` (x, y, width, height).
        """
        from raingauge.render.simulator import compose_rain, render_streaks

        W, H = self._pack(plan)
        linear = linear or raws is None
        # (frame n's linear canvas is needed for the streaks either way)
        lin_idx = (0, 1, 2) if linear else (1,)
        lin = [np.zeros((H, W), np.float32) if i in lin_idx else None for i in range(3)]
        raw = None if raws is None else [np.zeros((H, W), np.uint8) for _ in range(3)]
        # the space between crops is the same in the three frames: nothing is detected there
        centres, p0, p1 = [], [], []
        for p in plan:
            x0, y0, cw, ch = p["box"]
            x, y = p["canvas_box"][:2]
            for i in lin_idx:
                lin[i][y:y + ch, x:x + cw] = frames[i][y0:y0 + ch, x0:x0 + cw]
            if raw is not None:
                for i in range(3):
                    raw[i][y:y + ch, x:x + cw] = raws[i][y0:y0 + ch, x0:x0 + cw]
            ox, oy = x - x0, y - y0
            p0.append((p["p0"][0] + ox, p["p0"][1] + oy))
            p1.append((p["p1"][0] + ox, p["p1"][1] + oy))
            centres.append((p["centre"][0] + ox, p["centre"][1] + oy))
        beta, _ = render_streaks((H, W), np.array(p0), np.array(p1), [p["radius_px"] for p in plan],
                                 [p["area_px"] for p in plan])
        # only the pixels under the streaks change (the row sums leave rounding residues of
        # 1e-15 along the rows: no pixel)
        on = np.nonzero(beta > 1e-9)
        cur = compose_rain(lin[1][on], beta[on], drop_brightness_dn=drop_brightness_dn)
        b = _clip(beta[on].astype(np.float64), 0.0, 1.0)
        if noise_dn > 0 and b.size:
            # I_b + beta (E_r - I_b) over a noisy I_b keeps only (1 - beta) of its noise,
            # where the camera's pixel has all of it: the rest, 2 beta - beta^2 of the variance
            cur += (float(noise_dn) * np.sqrt(2.0 * b - b * b) * self._rng.standard_normal(b.size)
                    ).astype(np.float32)
        if raw is not None:
            # the camera rounds once; the 8-bit frame n was rounded already, and rounding the
            # streak again would set a faint streak's change to a whole number of gray levels
            # everywhere along it (a change of 0.6 becomes 1 at every pixel, and is found 10 %
            # more often than a real one).  The value before the camera's rounding lies
            # within half a level of the code, drawn there before rounding again
            # (:meth:`_before_rounding`); the streak covers beta of it
            code = raw[1][on].astype(np.float64)
            prior = 0.5 * (raw[0][on].astype(np.float64) + raw[2][on])
            cur += ((1.0 - b) * (self._before_rounding(code, prior, noise_dn) - code)).astype(np.float32)
            raw[1][on] = delinearize(cur)
            if not linear:
                return None, tuple(raw), centres
            lin[1] = raw[1].astype(np.float32)
        else:
            lin[1][on] = cur
        return tuple(lin), (None if raw is None else tuple(raw)), centres

    def _before_rounding(self, code, prior, noise_dn: float) -> np.ndarray:
        """Draws of the values a camera rounded to ``code``, within half a level of it, given
        the mean ``prior`` of the same pixel in the neighbour frames (the noise of a frame
        and half of it apart from it: the frames' ``noise_dn`` times sqrt(1.5)): the normal
        density about the prior, truncated to the code's rounding interval.

        Drawn uniformly in that interval instead, the value is spread 1/6 of a squared gray
        level more than the camera's: at 1 gray level of noise a faint streak's pixels then
        cross the detection threshold more often than a real streak's: against the bright sky
        at 1 gray level in a 3 m/s cross wind (the drift given) the probe counted its drops
        of 0.4 mm in focus at 0.41 where the gauge counted the same drops in the video at
        0.38, and at 0.38 when drawn so (:func:`raingauge.gauge.fidelity.probe_fidelity`)."""
        from scipy.special import ndtr, ndtri

        code = np.asarray(code, dtype=np.float64)
        s = max(float(noise_dn), 0.3) * math.sqrt(1.5)
        lo = ndtr((code - 0.5 - prior) / s)
        hi = ndtr((code + 0.5 - prior) / s)
        u = self._rng.random(code.size)
        with np.errstate(all="ignore"):
            x = prior + s * ndtri(_clip(lo + (hi - lo) * u, 1e-15, 1.0 - 1e-15))
        # (a code many sigma from its prior leaves no mass to draw from: uniform there)
        flat = ~((hi - lo > 1e-12) & np.isfinite(x))
        x[flat] = code[flat] + u[flat] - 0.5
        return _clip(x, code - 0.5, code + 0.5)

    @staticmethod
    def _pack(plan: list[dict], gap: int = CANVAS_GAP_PX, gap_rows: int = CANVAS_GAP_ROWS) -> tuple[int, int]:
        """Place the crops of ``plan`` in shelves (tallest first, each shelf filled left to
        right up to a width near the square root of their total area), ``gap`` clear
        columns between crops side by side and ``gap_rows`` clear rows between shelves;
        each crop's place is noted as its ``canvas_box``.  Returns the canvas's (width,
        height)."""
        sizes = [(p["box"][2], p["box"][3]) for p in plan]
        area = sum((cw + gap) * (ch + gap_rows) for cw, ch in sizes)
        limit = max(max(cw for cw, _ in sizes) + 2 * gap, int(math.ceil(math.sqrt(area))))
        x, y, shelf, width = gap, 0, 0, 0
        for j in sorted(range(len(plan)), key=lambda i: -sizes[i][1]):
            cw, ch = sizes[j]
            if x + cw + gap > limit and x > gap:
                x, y, shelf = gap, y + shelf + gap_rows, 0
            plan[j]["canvas_box"] = (x, y, cw, ch)
            x += cw + gap
            shelf = max(shelf, ch)
            width = max(width, x)
        return width, y + shelf

    @staticmethod
    def cut_components(stats, plan: list[dict]) -> np.ndarray:
        """Which components of a canvas (``stats`` of its labels) reach the border of their
        crop: streaks of the frame cut by the crop, and any injected drop merged with one.
        In the frame such a blob is larger than the crop shows (a drop merged with a long
        streak there fails the tests the cut piece may pass), so the injected drop in it
        counts as lost (bool array over the labels; label 0 False)."""
        stats = np.asarray(stats)
        out = np.zeros(stats.shape[0], bool)
        if stats.shape[0] < 2 or not plan:
            return out
        bx, by, bw, bh = np.array([p["canvas_box"] for p in plan], dtype=float).T
        sx, sy, sw, sh = (stats[1:, i].astype(float)[:, None] for i in range(4))
        # each component lies in the crop that holds its top left corner
        inside = (sx >= bx) & (sx < bx + bw) & (sy >= by) & (sy < by + bh)
        j = np.argmax(inside, axis=1)
        bx, by, bw, bh = bx[j], by[j], bw[j], bh[j]
        sx, sy, sw, sh = sx[:, 0], sy[:, 0], sw[:, 0], sh[:, 0]
        out[1:] = ((sx <= bx) | (sx + sw >= bx + bw) | (sy <= by) | (sy + sh >= by + bh)
                   | ~inside.any(axis=1))
        return out

    @staticmethod
    def blobs(labels, stats, frame_labels, plan: list[dict], *, engine: str | None = None):
        """The component of a canvas each injected drop lies in, and the frame's streaks
        merged in it.

        A drop's blob is the label most of the points along its axis (one per pixel of its
        motion, at least 3; the smallest label on a tie) fall on, 0 when none does; its
        partners are the frame's labels (``frame_labels``) under the blob's pixels, each
        taken back from the canvas to the frame through the drop's crop (none when the blob
        was set aside, area 0).

        Parameters
        ----------
        labels, stats : the canvas's labels and stats (:func:`detect_streaks`)
        frame_labels : (M, N) int array
            The frame's own labels.
        plan : from :meth:`plan`, placed in the canvas (:meth:`canvas`)
        engine : {"compiled", "arrays"}, optional
            The partners from one compiled loop (numba; the default when it is installed) or
            one array pass per drop (the reference).  The same labels either way.

        Returns
        -------
        (blob, partners): (n,) int64 labels, and per drop a tuple of the frame's labels,
        ascending.
        """
        n = len(plan)
        blob = np.zeros(n, np.int64)
        partners = [()] * n
        if n == 0:
            return blob, partners
        cbox = np.array([p["canvas_box"] for p in plan], np.int64).reshape(n, 4)
        box = np.array([p["box"] for p in plan], np.int64).reshape(n, 4)
        ends = np.array([(*p["p0"], *p["p1"]) for p in plan], np.float64).reshape(n, 4)
        # the points along each axis: np.linspace(0, 1, m) of each drop, end to end
        m = np.array([max(int(p["motion_px"]) + 1, 3) for p in plan], np.int64)
        g = np.repeat(np.arange(n), m)
        k = np.arange(g.size) - np.repeat(np.cumsum(m) - m, m)
        u = k * np.repeat(1.0 / (m - 1), m)
        u[np.cumsum(m) - 1] = 1.0
        ax, ay, bx, by = (ends[g, i] for i in range(4))
        col = _clip(np.rint(ax + u * (bx - ax)).astype(int) - box[g, 0], 0, cbox[g, 2] - 1)
        row = _clip(np.rint(ay + u * (by - ay)).astype(int) - box[g, 1], 0, cbox[g, 3] - 1)
        on = labels[cbox[g, 1] + row, cbox[g, 0] + col].astype(np.int64)
        hit = on > 0
        g, on = g[hit], on[hit]
        if g.size:
            # each drop's most frequent label (the smallest of the most frequent)
            order = np.lexsort((on, g))
            g, on = g[order], on[order]
            first = np.flatnonzero(np.concatenate(([True], (g[1:] != g[:-1]) | (on[1:] != on[:-1]))))
            count = np.diff(np.append(first, g.size))
            gg, vv = g[first], on[first]
            best = np.lexsort((vv, -count, gg))
            top = best[np.concatenate(([True], gg[best][1:] != gg[best][:-1]))]
            blob[gg[top]] = vv[top]
        area = np.asarray(stats)[blob, 4]
        js = np.flatnonzero((blob > 0) & (area > 0))
        if js.size == 0:
            return blob, partners
        st = np.asarray(stats)[blob[js], :4].astype(np.int64)
        # canvas -> frame offsets of each drop's crop
        dy = box[js, 1] - cbox[js, 1]
        dx = box[js, 0] - cbox[js, 0]
        if _kernels.AVAILABLE and engine != "arrays":
            vals, ptr = _kernels.blob_partners(labels, frame_labels, blob[js], st, dy, dx)
            for i, j in enumerate(js.tolist()):
                partners[j] = tuple(vals[ptr[i]:ptr[i + 1]].tolist())
            return blob, partners
        M, N = frame_labels.shape
        for i, j in enumerate(js.tolist()):
            bx0, by0, bw, bh = st[i]
            yy, xx = np.nonzero(labels[by0:by0 + bh, bx0:bx0 + bw] == blob[j])
            fy = yy + by0 + dy[i]
            fx = xx + bx0 + dx[i]
            inside = (fy >= 0) & (fy < M) & (fx >= 0) & (fx < N)
            under = frame_labels[fy[inside], fx[inside]]
            partners[j] = tuple(int(v) for v in np.unique(under[under > 0]))
        return blob, partners

    def due(self, frame_index: int) -> bool:
        """Whether the frame of this index is probed."""
        return frame_index % self.interval == 0

    def adapt(self, probe_sd: float, rate_sd: float) -> int:
        """Set the interval between probed frames so that the correction's sampling error
        stays under :data:`PROBE_SD_SHARE` of the rest of the rate's error.

        Parameters
        ----------
        probe_sd : float
            Relative standard error the correction adds to the rate now
            (:meth:`rate_relative_sd`) [-].
        rate_sd : float
            Relative standard error of the rate without the probe's (its counting
            statistics and the gauge's base uncertainty) [-].

        Returns
        -------
        The new interval [frames], between ``fastest`` and ``every``: the error of a ratio
        estimator falls as one over the square root of its injections, so the interval
        scales with (target / probe_sd)^2.  Until the probe is mature every frame is
        probed; without a rate to compare with the interval is kept.
        """
        if not self.mature:
            self.interval = 1
        elif np.isfinite(probe_sd) and np.isfinite(rate_sd) and rate_sd > 0:
            target = PROBE_SD_SHARE * rate_sd
            k = self.interval * (target / max(probe_sd, 1e-9)) ** 2
            self.interval = int(_clip(np.floor(k), min(self.fastest, self.every), self.every))
        return self.interval

    def record(self, plan: list[dict], estimate, expected, p_pass, t_s: float | None = None) -> None:
        """Log the outcome of a frame's injections.

        Parameters
        ----------
        plan : from :meth:`plan`
        estimate : (n,) array
            Per drop, the gauge's (2 a_m)^3 v_m / kappa(a_m) summed over the streaks it
            counted of it (0: not counted) [m^4/s / (m^3/px^2)].
        expected : (n,) array
            Per drop, the same as the model of the sample volume expects it:
            p(a, z, C, sigma) (2 a)^3 v / kappa(a), p averaged over the contrasts C of the
            pixels behind the drop as kappa averages it over the frame's pixels.
        p_pass : (n,) array
            Per drop, the model's p(a, z, C, sigma) alone, so averaged [-].
        t_s : float, optional
            The frame's time [s] (for ``memory_s``).
        """
        if not plan:
            return
        f = self.profile.focal_length_px
        n_cls = CLASS_EDGES_M.size - 1
        cls = np.array([p["class"] for p in plan], dtype=int)
        dv = np.array([(p["depth_m"] / f) ** 2 * p["span_m"] for p in plan])
        x = dv * np.asarray(estimate, dtype=float)
        y = dv * np.asarray(expected, dtype=float)
        cols = (np.ones(cls.size), (x > 0).astype(float), x, y, np.asarray(p_pass, dtype=float), x * x, y * y, x * y)
        sums = np.stack([np.bincount(cls, c, minlength=n_cls) for c in cols], axis=1)
        self._log.append((t_s, sums))
        self._total += sums
        self._n_records += 1
        if self._n_records % 1024 == 0:
            # the running sums lose the rounding of what left them: start them afresh
            self._total = np.sum([e[1] for e in self._log], axis=0)
        self.injected += cls.size
        self.passed += int(np.count_nonzero(x > 0))
        if self.outcomes is not None:
            self.outcomes.extend((p["radius_m"], p["depth_m"], bool(e > 0), float(q), float(e))
                                 for p, e, q in zip(plan, np.asarray(estimate, dtype=float), np.asarray(p_pass, dtype=float)))
        # forget the oldest frames beyond the history or the memory
        while len(self._log) > 1:
            t0, old = self._log[0]
            too_many = self._total[:, 0].sum() - old[:, 0].sum() >= self.history
            too_old = (self.memory_s is not None and t_s is not None and t0 is not None
                       and t0 < t_s - self.memory_s)
            if not (too_many or too_old):
                break
            self._log.popleft()
            self._total -= old
        self._cache = None

    # ------------------------------------------------------------------ result
    @property
    def mature(self) -> bool:
        """Whether enough drops were injected for the correction to apply."""
        return self._total[:, 0].sum() >= self.min_injections

    def class_ratios(self) -> tuple[np.ndarray, np.ndarray]:
        """(c per class, injections per class): the rain the gauge made of the injected
        drops over the rain the model expected it to make of the same drops (a ratio
        estimator: both see the same depths and backgrounds), shrunk toward the pooled
        ratio; NaN for classes never injected."""
        n_cls = CLASS_EDGES_M.size - 1
        if not self._log:
            return np.full(n_cls, np.nan), np.zeros(n_cls, int)
        tot = self._total
        n = np.rint(tot[:, 0]).astype(int)
        found, expected, n_pass = tot[:, 2], tot[:, 3], tot[:, 4]
        pooled = found.sum() / expected.sum() if expected.sum() > 0 else 1.0
        # each class's ratio rests on the drops the model expected to pass in it; the
        # prior is worth prior_passes of them (a class the gauge hardly sees stays near
        # the pooled ratio)
        with np.errstate(all="ignore"):
            own = found / expected
            ratio = (own * n_pass + self.prior_passes * pooled) / (n_pass + self.prior_passes)
        ratio = np.where((n > 0) & (expected > 0), ratio, np.where(n > 0, pooled, np.nan))
        return ratio, n

    def class_counts(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(injected, counted, expected) per radius class: the drops injected, those the gauge
        counted, and the sum of the model's pass probabilities p(a, z, C, sigma) over them
        (what the model expects it to count) [-].  counted / expected is the count-based
        completeness of the class, beside the rate-based :meth:`class_ratios`."""
        n_cls = CLASS_EDGES_M.size - 1
        if not self._log:
            z = np.zeros(n_cls)
            return z.astype(int), z.astype(int), z
        tot = self._total
        return np.rint(tot[:, 0]).astype(int), np.rint(tot[:, 1]).astype(int), tot[:, 4].copy()

    def class_relative_sd(self) -> np.ndarray:
        """Relative standard error of each class's ratio (the ratio estimator's,
        sum (x_i - c y_i)^2 / (sum y_i)^2, shrinkage left out); 0 where it cannot be had [-]."""
        n_cls = CLASS_EDGES_M.size - 1
        if not self._log:
            return np.zeros(n_cls)
        tot = self._total
        sx, sy, sxx, syy, sxy = tot[:, 2], tot[:, 3], tot[:, 5], tot[:, 6], tot[:, 7]
        with np.errstate(all="ignore"):
            c = sx / sy
            # sum (x - c y)^2, expanded (rounding may leave it a hair below 0)
            res = np.maximum(sxx - 2.0 * c * sxy + c * c * syy, 0.0)
            rel = np.sqrt(res) / sy / c
        return np.where(np.isfinite(rel), rel, 0.0)

    def rate_relative_sd(self, radius_m, rate_share) -> float:
        """Relative standard error the correction adds to a rate made of drops of radii
        ``radius_m`` [m] carrying ``rate_share`` of it (classes independent) [-]."""
        if not self.mature:
            return 0.0
        a = np.asarray(radius_m, dtype=float).ravel()
        w = _clip(np.nan_to_num(np.asarray(rate_share, dtype=float).ravel(), nan=0.0, posinf=0.0), 0.0, None)
        if a.size == 0 or not np.sum(w) > 0:
            return 0.0
        k = _clip(np.searchsorted(CLASS_EDGES_M, a, side="right") - 1, 0, CLASS_EDGES_M.size - 2)
        per_class = np.bincount(k, w, minlength=CLASS_EDGES_M.size - 1) / np.sum(w)
        return float(np.sqrt(np.sum((per_class * self.class_relative_sd()) ** 2)))

    def correction(self, radius_m) -> np.ndarray:
        """c(a): the factor on the model's kappa(a) [-] (1 until mature); linear in log a
        between the classes' centres, constant beyond."""
        a = np.asarray(radius_m, dtype=float)
        if not self.mature:
            return np.ones_like(a)
        if self._cache is None:
            ratio, _n = self.class_ratios()
            centres = np.sqrt(self._class_lo * self._class_hi)
            ok = np.isfinite(ratio)
            if not ok.any():
                self._cache = (np.array([0.0]), np.array([1.0]))
            else:
                self._cache = (np.log(centres[ok]), _clip(ratio[ok], *CORRECTION_RANGE))
        x, y = self._cache
        return np.interp(np.log(_clip(a, 1e-9, None)), x, y)
