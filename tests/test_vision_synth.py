"""Hand-made synthetic frame stacks for the vision tests (and a check of their photometry).

A static (or panning) textured background, bright linear rain streaks whose
change follows Eq. (18) of Garg & Nayar (Delta I = alpha - beta I_b), camera
noise, and optional distractors: a moving object and rippling water.
"""

from __future__ import annotations

import numpy as np
import cv2


def texture(shape, seed=0, lo=30.0, hi=200.0, blur=2.0):
    """Smooth random texture [gray levels] with a wide range of backgrounds."""
    rng = np.random.default_rng(seed)
    t = cv2.GaussianBlur(rng.uniform(0, 1, shape).astype(np.float32), (0, 0), blur)
    t = (t - t.min()) / max(float(t.max() - t.min()), 1e-6)
    return (lo + (hi - lo) * t).astype(np.float32)


def streak_mask(shape, x, y, length, angle_deg, width=2):
    """Pixels of a straight streak centred at (x, y) (angle counter-clockwise on screen, 90 = vertical)."""
    m = np.zeros(shape, np.uint8)
    th = np.radians(angle_deg)
    dx, dy = 0.5 * length * np.cos(th), -0.5 * length * np.sin(th)
    cv2.line(m, (int(round(x - dx)), int(round(y - dy))), (int(round(x + dx)), int(round(y + dy))), 1, width)
    return m.astype(bool)


def make_clip(T=12, shape=(120, 160), *, n_streaks=15, seed=0, noise=1.0, angle_deg=100.0, angle_jitter=5.0,
              beta=0.02, alpha=(20.0, 45.0), length=(15, 35), width=2, moving_object=False, ripples=False,
              pan=(0.0, 0.0), bg_lo=30.0, bg_hi=200.0):
    """Return (frames uint8 (T, M, N), clean uint8 (T, M, N), rain truth (T, M, N) bool, backgrounds float)."""
    rng = np.random.default_rng(seed)
    M, N = shape
    pad = int(np.ceil(max(abs(pan[0]), abs(pan[1])) * T)) + 4
    big = texture((M + 2 * pad, N + 2 * pad), seed=seed + 1000, lo=bg_lo, hi=bg_hi)
    frames, cleans, truths = [], [], []
    for t in range(T):
        A = np.array([[1, 0, pad + pan[0] * t], [0, 1, pad + pan[1] * t]], dtype=np.float64)
        bg = cv2.warpAffine(big, A, (N, M), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP)
        if moving_object:
            ox = int(10 + 6 * t) % (N - 30)
            obj = texture((24, 24), seed=seed + 7, lo=150, hi=250)
            bg[40:64, ox:ox + 24] = obj
        if ripples:
            yy, xx = np.mgrid[0:M, 0:N]
            r = np.hypot(xx - 0.75 * N, yy - 0.7 * M)
            zone = r < 0.22 * min(M, N)
            # reflections on water modulate the scene radiance (multiplicative)
            wave = 0.25 * np.sin(0.9 * r - 2.6 * t) * zone
            bg = bg * (1.0 + wave.astype(np.float32))
        clean = bg.copy()
        img = bg.copy()
        truth = np.zeros(shape, bool)
        for _ in range(n_streaks):
            m = streak_mask(shape, rng.uniform(5, N - 5), rng.uniform(5, M - 5), rng.uniform(*length),
                            angle_deg + rng.uniform(-angle_jitter, angle_jitter), width)
            a = rng.uniform(*alpha)
            img[m] = img[m] + a - beta * bg[m]
            truth |= m
        img = img + rng.normal(0, noise, shape).astype(np.float32)
        frames.append(np.clip(np.rint(img), 0, 255).astype(np.uint8))
        cleans.append(np.clip(np.rint(clean), 0, 255).astype(np.uint8))
        truths.append(truth)
    return np.stack(frames), np.stack(cleans), np.stack(truths)


def test_synthetic_streaks_follow_eq18():
    """The generator's streak change is alpha - beta I_b, so tests built on it test Eq. (18)."""
    frames, clean, truth = make_clip(T=3, n_streaks=1, noise=0.0, seed=3, beta=0.03, alpha=(30.0, 30.0))
    m = truth[1]
    d = frames[1].astype(float)[m] - clean[1].astype(float)[m]
    slope, intercept = np.polyfit(clean[1].astype(float)[m], d, 1)
    assert abs(-slope - 0.03) < 0.01 and abs(intercept - 30) < 1.5
