"""Dynamics of rain: the binary field b, its correlation R_b, needle maps, segmentation.

Sec. 4.1 and 5.1 [GargNayar2007].  Drops fall in straight lines, so the binary
rain field b (Eq. 2) has a strong zero-lag correlation R_b(m p, 0) between a
pixel and its neighbours along the direction of fall, for 0 <= m p <= v_i T
(Fig. 4(b)), and a weak one across it.  Computed over l x l neighbourhoods
(l = 11) and the last f frames (f = 30), averaged over 3 x 3 pixels
(Fig. 11(d)), and projected on oriented masks (note 14), it gives the
direction and strength of the rain (the needle map, Fig. 11(e)).  Weak or
non-directional correlation -- scene motion, ripples, noise (note 15) -- is
not rain: this segments the frame into rain and non-rain regions.

Beyond the paper: the edges of a textured object moving steadily in one
direction give a strong correlation along one direction too (note 15 assumes
their direction varies).  What rain alone has is independence from frame to
frame: a drop lasts one exposure, so near a rain pixel of frame n the field
of frame n-1 is no denser than elsewhere, while a moving object's false rain
pixels reappear a few pixels away.  Cells whose lag-one persistence is well
above chance are not rain (:func:`lag_one_persistence`).

Cost.  Only rain pixels carry correlation (b = 0 contributes nothing), so the
l x l neighbourhoods are gathered at the rain pixels alone (at most
``max_pixels`` of them per frame, taken evenly), projected on the masks with
one matrix product, and accumulated per 3 x 3 cell; a ring of the last f
frames' sparse contributions keeps the running sums exact.
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque

import numpy as np

__all__ = [
    "ORIENTATIONS_DEG",
    "oriented_masks",
    "rain_pixel_energies",
    "RainDynamics",
    "DynamicsField",
    "needle_map",
    "dominant_direction_deg",
    "lag_one_persistence",
    "persistent_cells",
]

#: Rows per matrix product in :func:`rain_pixel_energies`.
_GEMM_ROWS = 128

#: Orientations of the masks of note 14 [deg], 0 = horizontal, counter-clockwise on screen.
ORIENTATIONS_DEG = np.arange(0.0, 180.0, 10.0)


def oriented_masks(l: int = 11, *, angles_deg: np.ndarray | None = None, half_width_px: float = 1.5) -> np.ndarray:
    """Oriented binary masks of note 14 [GargNayar2007], shape (K, l, l), float32.

    Parameters
    ----------
    l : int
        Odd neighbourhood size [px].
    angles_deg : array, optional
        Orientations [deg], counter-clockwise on screen from +x (90 = vertical);
        default :data:`ORIENTATIONS_DEG`.
    half_width_px : float
        Pixels within this distance of the oriented line through the centre are
        set [px]; 1.5 gives the three central rows of m_0.

    Notes
    -----
    m_0 is the central row and its two neighbours; the others rotate it.  The
    text says "17 masks" but lists 18 angles, 0, 10, ..., 170 deg; all 18 are
    used (a gap of 10 deg would otherwise be left around one direction).
    """
    if l < 3 or l % 2 == 0:
        raise ValueError(f"neighbourhood size l must be an odd integer >= 3, got {l!r}")
    angles = ORIENTATIONS_DEG if angles_deg is None else np.asarray(angles_deg, dtype=np.float64)
    h = (l - 1) // 2
    yy, xx = np.mgrid[-h:h + 1, -h:h + 1].astype(np.float64)
    v = -yy  # screen up
    th = np.radians(angles)[:, None, None]
    dist = np.abs(-np.sin(th) * xx + np.cos(th) * v)
    return (dist <= half_width_px + 1e-9).astype(np.float32)


def rain_pixel_energies(b: np.ndarray, *, masks: np.ndarray, max_pixels: int | None = None,
                        work: np.ndarray | None = None, flat: np.ndarray | None = None
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Directional energy of R_b at each rain pixel of one frame.

    For each rain pixel p and mask k, ``E[p, k] = sum_m mask_k(m) b(p) b(p + m)``:
    the zero-lag correlation of note 14, before averaging over pixels and frames.

    Parameters
    ----------
    b : (M, N) bool array
        Binary rain field of one frame (Eq. 2).
    masks : (K, l, l) array
        From :func:`oriented_masks`.
    max_pixels : int, optional
        Evaluate at most this many rain pixels, spread evenly [px].
    work : (M + l - 1, N + l - 1) uint8 array, optional
        Scratch space for the zero-padded field (overwritten).
    flat : (P,) int array, optional
        The flat indices of the rain pixels of ``b`` in increasing order, when known.

    Returns
    -------
    rows, cols : (P,) int arrays
        The evaluated rain pixels.
    energy : (P, K) float32 array
        Mask energies [pixels].
    weight : float
        Rain pixels represented by each evaluated one (>= 1).
    """
    import cv2

    b = np.asarray(b)
    K, l, _ = masks.shape
    h = (l - 1) // 2
    flat = np.flatnonzero(b.ravel()) if flat is None else np.asarray(flat, np.int64)
    weight = 1.0
    if max_pixels is not None and flat.size > max_pixels:
        step = flat.size / max_pixels
        flat = flat[(np.arange(max_pixels) * step).astype(np.int64)]
        weight = step
    rows_n, cols_n = b.shape
    rows = flat // cols_n
    cols = flat % cols_n
    if flat.size == 0:
        return rows, cols, np.zeros((0, K), np.float32), weight
    if work is not None and work.shape != (rows_n + 2 * h, cols_n + 2 * h):
        work = None
    padded = cv2.copyMakeBorder(b.view(np.uint8) if b.dtype == np.bool_ else b.astype(np.uint8),
                                h, h, h, h, cv2.BORDER_CONSTANT, work, value=0)
    # the l x l window of each pixel (top-left (r, c) in padded coordinates),
    # gathered as whole rows of a strided view: no (P, l*l) index array
    windows = np.lib.stride_tricks.sliding_window_view(padded, (l, l))
    neigh = windows[rows, cols].reshape(rows.size, l * l).astype(np.float32)  # (P, l*l)
    mk = np.ascontiguousarray(masks.reshape(K, -1).T)
    # Blocks of _GEMM_ROWS rows: a product this small is fastest on one thread,
    # and a multithreaded BLAS (OpenBLAS threads larger ones) only contends
    # with the rest of the frame loop for the cores.
    energy = np.concatenate([neigh[i:i + _GEMM_ROWS] @ mk for i in range(0, neigh.shape[0], _GEMM_ROWS)])
    return rows, cols, energy, weight


def lag_one_persistence(b_prev: np.ndarray, b: np.ndarray, *, radius_px: int = 3, block_px: int = 31
                        ) -> tuple[np.ndarray, np.ndarray]:
    """Lag-one persistence of the binary field: which rain pixels of frame n had one nearby in frame n-1.

    A drop crosses the field of view of a pixel within one exposure, and the
    drops of consecutive frames are independent (Sec. 4.1 [GargNayar2007]):
    R_b(m p, T) is high only at displacements v_i T to 2 v_i T along the rain,
    the length of a streak and more, so near a rain pixel of frame n the field
    of frame n-1 is no denser than anywhere else.  The false rain pixels of a
    moving textured object (its edges, after global motion compensation) move
    with the object and reappear a few pixels away in the next frame.

    Parameters
    ----------
    b_prev, b : (M, N) bool arrays
        Binary rain fields of frames n-1 and n.
    radius_px : int
        A rain pixel is persistent when frame n-1 has a rain pixel within this
        Chebyshev distance [px].
    block_px : int
        Side of the box over which the chance level (the local fraction of
        pixels within ``radius_px`` of a rain pixel of frame n-1) is taken [px].

    Returns
    -------
    near : (M, N) bool array
        Rain pixels of frame n that are persistent.
    chance : (M, N) float32 array
        Probability that a pixel is persistent by chance (the local coverage).
        Rain gives ``near.sum() ~ chance[b].sum()``; moving texture several times more.
    """
    import cv2

    k = 2 * int(radius_px) + 1
    dil = cv2.dilate(np.asarray(b_prev).view(np.uint8), np.ones((k, k), np.uint8))
    chance = cv2.blur(dil.astype(np.float32), (int(block_px), int(block_px)), borderType=cv2.BORDER_REFLECT)
    return np.asarray(b) & dil.view(bool), chance


def persistent_cells(persistent: np.ndarray, chance: np.ndarray, *, max_ratio: float = 1.5,
                     sigmas: float = 2.0) -> np.ndarray:
    """Cells whose lag-one persistence is too high for rain (see :func:`lag_one_persistence`).

    Parameters
    ----------
    persistent : array
        Persistent rain pixels counted in each cell over the window.
    chance : array
        The count expected by chance (sum of the chance level at the cell's rain pixels).
    max_ratio : float
        Largest persistence over chance that rain may show.
    sigmas : float
        Poisson allowance on top [standard deviations].
    """
    chance = np.asarray(chance, np.float32)
    return np.asarray(persistent) > max_ratio * chance + sigmas * np.sqrt(max_ratio * chance) + 1.0


def _persistence_step(b, rows, cols, cid, prev_near, *, radius_px, side_px, grid, work=None, out=None):
    """Persistence (0/1) and chance level at the evaluated rain pixels; the dilated field for the next frame.

    ``work`` and ``out`` are optional uint8 arrays of the frame's shape for the
    dilation and for the returned field (not ``prev_near``).
    """
    import cv2

    k = 2 * int(radius_px) + 1
    b8 = np.asarray(b).view(np.uint8) if b.dtype == np.bool_ else np.asarray(b, np.uint8)
    # 0 / 255, so that the area average below keeps its fractions in uint8
    dil = cv2.compare(cv2.dilate(b8, np.ones((k, k), np.uint8), work), 0, cv2.CMP_GT, out)
    if prev_near is None or rows.size == 0:
        return (np.zeros(rows.size, np.float32), np.zeros(rows.size, np.float32), dil)
    near = (prev_near[rows, cols] > 0).astype(np.float32)
    # chance: the coverage of the previous frame's dilated field, on the grid
    # of correlation cells, averaged over 3 x 3 of them
    gh, gw = grid
    M, N = b.shape
    fh, fw = max(M // side_px, 1), max(N // side_px, 1)     # whole cells (a view, no copy)
    cov = cv2.resize(prev_near[:fh * side_px, :fw * side_px], (fw, fh), interpolation=cv2.INTER_AREA)
    if (fh, fw) != (gh, gw):
        cov = cv2.copyMakeBorder(cov, 0, gh - fh, 0, gw - fw, cv2.BORDER_REPLICATE)
    cov = cov.astype(np.float32) * np.float32(1.0 / 255.0)
    cov = cv2.blur(cov, (3, 3), borderType=cv2.BORDER_REFLECT)
    chance = cov.ravel()[cid]
    return near, chance, dil


@dataclasses.dataclass
class DynamicsField:
    """Correlation of the binary rain field on a grid of ``cell`` x ``cell`` pixel cells.

    Each grid cell summarises the R_b of the surrounding ``smooth`` x ``smooth``
    correlation cells of :class:`RainDynamics`.

    Attributes
    ----------
    energy : (GH, GW, K) float32
        R_b summed over each oriented mask, averaged over the cell's pixels and
        the frames of the window (spatially smoothed over ``smooth`` cells),
        less the part an uncorrelated field of the same density would give.
    strength : (GH, GW)
        Largest mask energy: the strength of the rain (needle length).
    ratio : (GH, GW)
        Largest over smallest mask energy: how directional the correlation is.
    direction_deg : (GH, GW)
        Orientation of the largest energy [deg], 90 = vertical.
    events : (GH, GW)
        Rain pixels seen in the (smoothed) cell over the window.
    rain : (GH, GW) bool
        Cells segmented as rain.
    cell : int
        Cell size [px].
    frames : int
        Frames in the window.
    persistence : (GH, GW) or None
        Lag-one persistence of the binary field over its chance level
        (about 1 for rain, several for moving texture); see
        :func:`lag_one_persistence`.
    """

    energy: np.ndarray
    strength: np.ndarray
    ratio: np.ndarray
    direction_deg: np.ndarray
    events: np.ndarray
    rain: np.ndarray
    cell: int
    frames: int
    shape: tuple[int, int]
    persistence: np.ndarray | None = None

    def region_mask(self, *, dilate_px: int = 0) -> np.ndarray:
        """Rain region at pixel resolution, (M, N) bool."""
        import cv2

        M, N = self.shape
        gh, gw = self.rain.shape
        up = cv2.resize(self.rain.view(np.uint8), (gw * self.cell, gh * self.cell),
                        interpolation=cv2.INTER_NEAREST)
        if up.shape[0] < M or up.shape[1] < N:
            up = cv2.copyMakeBorder(up, 0, max(M - up.shape[0], 0), 0, max(N - up.shape[1], 0),
                                    cv2.BORDER_REPLICATE)
        up = up[:M, :N]
        if dilate_px > 0:
            k = 2 * int(dilate_px) + 1
            up = cv2.dilate(up, np.ones((k, k), np.uint8))
        return up.astype(bool)


class RainDynamics:
    """Running zero-lag correlation R_b of the binary rain field, Secs. 4.1 and 5.1 [GargNayar2007].

    Parameters
    ----------
    shape : (M, N)
        Frame shape [px].
    l : int
        Correlation neighbourhood size [px] (11 in the paper).
    f : int
        Frames in the running window (30 in the paper).
    cell : int
        R_b is averaged over disjoint cell x cell pixels (3 in the paper).
    smooth : int
        The cell statistics are further summed over about smooth x smooth
        cells before direction and segmentation [cells] (see ``stride``).
    max_pixels : int
        Rain pixels evaluated per frame, at most [px].
    min_ratio : float
        Rain cells need a maximum-to-minimum mask energy ratio of at least this.
    min_strength : float
        Rain cells need a maximum mask energy (R_b units: co-occurring rain
        pixels per pixel per frame) of at least this.
    min_events : float
        Rain cells need at least this many rain pixels in the smoothed cell
        over the window.
    max_angle_dev_deg : float or None
        Rain cells must lie within this angle of the frame's dominant rain
        direction [deg]; ``None`` turns the test off (rain whose direction
        varies across the frame).
    stride : int, optional
        The field is evaluated every ``stride`` cells, each value summing
        3 stride x 3 stride cells (default round(smooth / 3)): its needles and
        regions are ``cell * stride`` pixels apart.
    min_frame_fraction : float
        Rain is stationary in time (Sec. 4.1): a rain region must have seen
        rain pixels in at least this fraction of the window's frames (and in
        two at least).  An object edge seen in one or two frames is not rain.
    persistence_px : int
        Radius of the lag-one test [px] (see :func:`lag_one_persistence`);
        0 turns the test off.
    max_persistence : float
        Rain cells need a lag-one persistence at most this many times the
        chance level (1 for rain).  The binary field of a moving textured
        object reappears next frame a few pixels away; rain does not.
    persistence_box : int
        The persistence is pooled over about ``persistence_box`` x
        ``persistence_box`` field cells [cells] (more counts than the
        direction needs, for a steadier ratio).
    """

    def __init__(self, shape: tuple[int, int], *, l: int = 11, f: int = 30, cell: int = 3, smooth: int = 7,
                 max_pixels: int = 2000, min_ratio: float = 2.5, min_strength: float = 0.08,
                 min_events: float = 20.0, max_angle_dev_deg: float | None = 30.0,
                 min_frame_fraction: float = 1.0 / 6.0, stride: int | None = None,
                 persistence_px: int = 3, max_persistence: float = 1.5, persistence_box: int = 5):
        if f < 1:
            raise ValueError(f"window f must be at least one frame, got {f!r}")
        if cell < 1 or smooth < 1:
            raise ValueError("cell and smooth must be positive integers")
        self.shape = (int(shape[0]), int(shape[1]))
        self.l, self.f, self.cell, self.smooth = int(l), int(f), int(cell), int(smooth)
        self.masks = oriented_masks(self.l)
        self.K = self.masks.shape[0]
        # Normalise the masks to the same pixel count so that energies compare.
        size = self.masks.reshape(self.K, -1).sum(axis=1)
        self._mask_norm = (size.mean() / size).astype(np.float32)
        self._chance = ((size - 1.0) * self._mask_norm).astype(np.float32)
        self.max_pixels = max_pixels
        self.min_ratio, self.min_strength, self.min_events = float(min_ratio), float(min_strength), float(min_events)
        self.max_angle_dev_deg = max_angle_dev_deg
        self.stride = max(1, int(round(self.smooth / 3.0))) if stride is None else max(1, int(stride))
        self.min_frame_fraction = float(min_frame_fraction)
        # Coarse blocks (smooth x smooth cells) counting the frames that saw rain.
        self.block = self.cell * self.smooth
        self.bh = -(-self.shape[0] // self.block)
        self.bw = -(-self.shape[1] // self.block)
        self._frames_seen = np.zeros(self.bh * self.bw, np.int32)
        # the cell grid, padded to whole blocks of stride x stride cells
        st = self.stride
        self.gh = -(-(-(-self.shape[0] // self.cell)) // st) * st
        self.gw = -(-(-(-self.shape[1] // self.cell)) // st) * st
        # running sums kept directly on the grid of stride x stride cells (the
        # resolution of the field), so that field() needs no reduction
        self._sbh, self._sbw = self.gh // st, self.gw // st
        self._acc = np.zeros((self._sbh * self._sbw, self.K), np.float64)
        self._cnt = np.zeros(self._sbh * self._sbw, np.float64)
        # lag-one persistence: rain pixels near a rain pixel of the previous
        # frame, and the number expected by chance
        self.persistence_px = int(persistence_px)
        self.max_persistence = float(max_persistence)
        self.persistence_box = int(persistence_box)
        self._pers = np.zeros(self._sbh * self._sbw, np.float64)
        self._pers_chance = np.zeros(self._sbh * self._sbw, np.float64)
        self._prev_near: np.ndarray | None = None
        self._ring: deque = deque()
        # frame-sized scratch arrays reused frame after frame: the padded field,
        # the dilation, and two fields alternating as the previous frame's
        self._pad_buf = np.empty((self.shape[0] + 2 * (self.l // 2), self.shape[1] + 2 * (self.l // 2)), np.uint8)
        self._dil_buf = np.empty(self.shape, np.uint8)
        self._near_bufs = [np.empty(self.shape, np.uint8), np.empty(self.shape, np.uint8)]

    @property
    def frames(self) -> int:
        """Frames currently in the window."""
        return len(self._ring)

    def reset(self) -> None:
        self._acc[:] = 0
        self._cnt[:] = 0
        self._pers[:] = 0
        self._pers_chance[:] = 0
        self._prev_near = None
        self._frames_seen[:] = 0
        self._ring.clear()

    def update(self, b: np.ndarray, *, flat: np.ndarray | None = None) -> None:
        """Add the binary rain field of the newest frame, dropping the one f frames older.

        ``flat``: the flat indices of the rain pixels of ``b`` (increasing), when known.
        """
        b = np.asarray(b)
        if b.shape != self.shape:
            raise ValueError(f"binary field has shape {b.shape}, expected {self.shape}")
        rows, cols, energy, w = rain_pixel_energies(b, masks=self.masks, max_pixels=self.max_pixels,
                                                    work=self._pad_buf, flat=flat)
        side = self.cell * self.stride
        cid = (rows // side) * self._sbw + cols // side
        near = chance = None
        if self.persistence_px > 0:
            out = self._near_bufs[0] if self._prev_near is not self._near_bufs[0] else self._near_bufs[1]
            near, chance, self._prev_near = _persistence_step(
                b, rows, cols, cid, self._prev_near, radius_px=self.persistence_px, side_px=side,
                grid=(self._sbh, self._sbw), work=self._dil_buf, out=out)
        # Sum the frame's contributions per cell (sorted segments, no scatter-add).
        if cid.size:
            order = np.argsort(cid, kind="stable")
            cs = cid[order]
            starts = np.flatnonzero(np.r_[True, cs[1:] != cs[:-1]])
            ucid = cs[starts]
            e = np.add.reduceat(energy[order], starts, axis=0).astype(np.float64) * w
            n = np.diff(np.r_[starts, cs.size]).astype(np.float64) * w
            if near is not None:
                pn = np.add.reduceat(near[order], starts).astype(np.float64) * w
                pc = np.add.reduceat(chance[order], starts).astype(np.float64) * w
            else:
                pn = pc = np.zeros(ucid.size)
        else:
            ucid = cid
            e = np.zeros((0, self.K))
            n = pn = pc = np.zeros(0)
        self._acc[ucid] += e
        self._cnt[ucid] += n
        self._pers[ucid] += pn
        self._pers_chance[ucid] += pc
        # the blocks that saw rain, in increasing order (np.unique, without the sort)
        seen = np.zeros(self.bh * self.bw, bool)
        seen[(rows // self.block) * self.bw + cols // self.block] = True
        blocks = np.flatnonzero(seen)
        self._frames_seen[blocks] += 1
        self._ring.append((ucid, e, n, blocks, pn, pc))
        while len(self._ring) > self.f:
            ocid, oe, on, ob, opn, opc = self._ring.popleft()
            self._acc[ocid] -= oe
            self._cnt[ocid] -= on
            self._pers[ocid] -= opn
            self._pers_chance[ocid] -= opc
            self._frames_seen[ob] -= 1

    def field(self) -> DynamicsField:
        """Direction, strength and segmentation from the current window."""
        import cv2

        frames = max(len(self._ring), 1)
        # Sum the cells in blocks of stride x stride, then over 3 x 3 blocks: a
        # box of about smooth x smooth cells evaluated every `stride` cells.
        st = self.stride
        bh, bw = self.gh // st, self.gw // st
        blk = self._acc.reshape(bh, bw, self.K).astype(np.float32)
        blkn = self._cnt.reshape(bh, bw).astype(np.float32)
        sm = cv2.boxFilter(blk, -1, (3, 3), normalize=False, borderType=cv2.BORDER_CONSTANT)
        events = np.maximum(cv2.boxFilter(blkn, -1, (3, 3), normalize=False, borderType=cv2.BORDER_CONSTANT), 0.0)
        cy = np.arange(bh) * st + st // 2
        cx = np.arange(bw) * st + st // 2
        box = 3 * st
        area = float(self.cell * self.cell * box * box * frames)
        # Remove what an uncorrelated field of the same density would give,
        # rho^2 (|mask| - 1): in dense rain, streaks crossing the perpendicular
        # mask would otherwise hide the directionality.
        rho = (events / area)[..., None]
        # (in place on sm, a new array: the same operations as
        # sm * norm - rho^2 * chance, clipped at 0, without temporaries)
        energy = np.multiply(sm, self._mask_norm / area, out=sm)
        np.subtract(energy, np.multiply(rho * rho, self._chance), out=energy)
        np.maximum(energy, 0.0, out=energy)
        flat_e = energy.reshape(-1, self.K)
        emax = cv2.reduce(flat_e, 1, cv2.REDUCE_MAX).reshape(bh, bw)
        emin = cv2.reduce(flat_e, 1, cv2.REDUCE_MIN).reshape(bh, bw)
        kmax = energy.argmax(axis=2)
        floor = 0.05 * rho[..., 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(emax > 0, emax / np.maximum(emin, np.maximum(floor, 1e-12)), 0.0)
        direction = ORIENTATIONS_DEG[kmax]
        rain = (emax >= self.min_strength) & (ratio >= self.min_ratio) & (events >= self.min_events)
        need = max(2, math.ceil(self.min_frame_fraction * len(self._ring)))
        seen = cv2.dilate(self._frames_seen.reshape(self.bh, self.bw).astype(np.float32), np.ones((3, 3), np.uint8))
        by = np.minimum((cy * self.cell) // self.block, self.bh - 1)
        bx = np.minimum((cx * self.cell) // self.block, self.bw - 1)
        rain &= seen[by[:, None], bx[None, :]] >= need
        persistence = None
        if self.persistence_px > 0:
            # pooled over persistence_box x persistence_box blocks (about 30 px at the defaults)
            pb = (self.persistence_box, self.persistence_box)
            pers = cv2.boxFilter(self._pers.reshape(bh, bw).astype(np.float32), -1, pb, normalize=False,
                                 borderType=cv2.BORDER_CONSTANT)
            pch = cv2.boxFilter(self._pers_chance.reshape(bh, bw).astype(np.float32), -1, pb, normalize=False,
                                borderType=cv2.BORDER_CONSTANT)
            pers = np.maximum(pers, 0.0)
            pch = np.maximum(pch, 0.0)
            with np.errstate(divide="ignore", invalid="ignore"):
                persistence = np.where(pch > 0, pers / np.maximum(pch, 1e-12), np.where(pers > 0, np.inf, 0.0))
            rain &= ~persistent_cells(pers, pch, max_ratio=self.max_persistence)
        if self.max_angle_dev_deg is not None and np.any(rain):
            # Within a frame rain falls in one direction (Sec. 4.1); cells that
            # disagree with the dominant direction are scene motion.
            w = np.where(rain, emax, 0.0)
            th = np.radians(2.0 * direction)
            dom = 0.5 * math.atan2(float(np.sum(w * np.sin(th))), float(np.sum(w * np.cos(th))))
            dev = np.abs((direction - math.degrees(dom) + 90.0) % 180.0 - 90.0)
            rain &= dev <= self.max_angle_dev_deg
        return DynamicsField(energy=energy, strength=emax, ratio=ratio, direction_deg=direction,
                             events=events, rain=rain, cell=self.cell * st, frames=len(self._ring),
                             shape=self.shape, persistence=persistence)


def dominant_direction_deg(field: DynamicsField) -> float:
    """Strength-weighted mean orientation of the rain cells [deg, 0-180, 90 = vertical]; NaN if none."""
    w = np.where(field.rain, field.strength, 0.0)
    if not np.any(w > 0):
        return float("nan")
    th = np.radians(2.0 * field.direction_deg)
    c = float(np.sum(w * np.cos(th)))
    s = float(np.sum(w * np.sin(th)))
    return float(np.degrees(0.5 * math.atan2(s, c)) % 180.0)


def needle_map(image: np.ndarray, field: DynamicsField, *, step_px: int = 12, color=(0, 255, 255),
               region_color=(0, 0, 255), thickness: int = 1) -> np.ndarray:
    """Draw the needle map of Fig. 11(e) over a frame, BGR uint8 (M, N, 3).

    Needles sit every ``step_px`` pixels inside the rain region, along the rain
    direction, with length proportional to the strength; the rain region is
    tinted with ``region_color``.
    """
    import cv2

    img = np.asarray(image)
    if img.dtype != np.uint8:
        img = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    out = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR) if img.ndim == 2 else img.copy()
    region = field.region_mask()
    tint = np.zeros_like(out)
    tint[:] = region_color
    blend = cv2.addWeighted(out, 0.75, tint, 0.25, 0)
    out[region] = blend[region]
    smax = float(field.strength[field.rain].max()) if np.any(field.rain) else 1.0
    stride = max(1, int(round(step_px / field.cell)))
    half = 0.5 * step_px
    for gy in range(stride // 2, field.rain.shape[0], stride):
        for gx in range(stride // 2, field.rain.shape[1], stride):
            if not field.rain[gy, gx]:
                continue
            L = half * min(field.strength[gy, gx] / smax, 1.0) + 1.0
            th = math.radians(field.direction_deg[gy, gx])
            cx = (gx + 0.5) * field.cell
            cy = (gy + 0.5) * field.cell
            dx, dy = L * math.cos(th), -L * math.sin(th)
            cv2.line(out, (int(round(cx - dx)), int(round(cy - dy))), (int(round(cx + dx)), int(round(cy + dy))),
                     color, thickness, cv2.LINE_AA)
    return out
