"""Compiled per-streak loops of :func:`raingauge.gauge.streaks.measure_streak_table`.

The array form of the closed-form measurement (:func:`raingauge.gauge.streaks._profile_pass`)
spends most of its time building and reducing long lists of band pixels; the same
arithmetic as one loop per streak, compiled by numba, runs several times faster and
allocates almost nothing.  Both give the same measurement up to the order in which sums
are taken (tests/test_gauge_streaks.py compares them on simulated rain).

The detection's whole-frame passes over a linear camera's 8-bit frames are here too, each
giving exactly what its array or OpenCV form gives: the spike image of Eq. (19) summed along
the fall and thresholded in one pass (:func:`spike_masks`), the labelling of the sparse mask
from its runs with OpenCV's numbering (:func:`label_components`), the union of the pieces of
one streak (:func:`union_roots`) and the histogram of the change for its noise
(:func:`change_histogram`).  In a cross wind the spike is summed along each of the wind's
slants and the largest thresholded in one pass (:func:`slant_masks`), exactly where OpenCV's
float32 filters fall either side of a threshold a sum equals.

Without numba the array form is used: ``AVAILABLE`` says which.
"""

from __future__ import annotations

import math

import numpy as np

try:  # pragma: no cover - exercised by whichever is installed
    import numba

    AVAILABLE = True
except ImportError:  # pragma: no cover
    numba = None
    AVAILABLE = False

__all__ = ["AVAILABLE", "blob_partners", "change_histogram", "label_components", "own_pixels", "profile_pass",
           "slant_masks", "spike_masks", "streak_table", "union_roots", "warm_up"]


def _jit(fn):
    if not AVAILABLE:
        return fn
    return numba.njit(cache=True, nogil=True, error_model="numpy")(fn)


@_jit
def _sort_small(a, n):
    """Sort a[:n] in place by insertion, NaN last (the order of ``np.sort``)."""
    for i in range(1, n):
        v = a[i]
        j = i - 1
        if v != v:
            continue
        while j >= 0 and (a[j] != a[j] or a[j] > v):
            a[j + 1] = a[j]
            j -= 1
        a[j + 1] = v


@_jit
def _median(a, n):
    """Median of a[:n] (mean of the two middle values for even n; NaN for none); a[:n]
    is sorted in place when short."""
    if n == 0:
        return np.nan
    if n <= 64:
        _sort_small(a, n)
        s = a
    else:
        s = np.sort(a[:n])
    if n % 2 == 1:
        return s[(n - 1) // 2]
    return (s[n // 2 - 1] + s[n // 2]) / 2.0


def _jit_sums(fn):
    # sums whose order may be changed (vectorised): no assumption about NaN or infinity
    if not AVAILABLE:
        return fn
    return numba.njit(cache=True, nogil=True, error_model="numpy", fastmath={"reassoc", "contract"})(fn)


@_jit_sums
def _box_gain(uu, vv, nk, hw):
    """The least-squares gain (sum c v)^2 / sum c^2 of a pixel-integrated box of half width
    ``hw`` over the pixels at |offset| uu[:nk] with change vv[:nk] (-inf when the fit is
    void).  A pixel at |u| is covered by min(min(1, 2 hw), max(hw + 1/2 - |u|, 0))."""
    c_in = 2.0 * hw if 2.0 * hw < 1.0 else 1.0
    b_ = hw + 0.5
    svc = 0.0
    scc = 0.0
    for i in range(nk):
        cov = min(c_in, max(b_ - uu[i], 0.0))
        svc += cov * vv[i]
        scc += cov * cov
    if scc > 0 and svc > 0:
        return svc * svc / scc
    return -np.inf


@_jit
def _refine_box_width(o, v, n, cen, w0, factors, uu, vv, gain):
    """:func:`raingauge.gauge.streaks._refine_box_width` for one streak: least-squares
    width of a pixel-integrated box (height free) over the pixels at offsets o[:n] with
    change v[:n], on the grid w0 * factors refined by a parabola in ln w; ``uu``, ``vv``
    (at least n) and ``gain`` (factors' size) are scratch space."""
    good = math.isfinite(w0) and math.isfinite(cen) and w0 > 0
    if good:
        base = w0 if w0 > 0.6 else 0.6
        c = cen
    else:
        base = 1.0
        c = 0.0
    nf = factors.size
    reach = 0.5 * base * factors[nf - 1] + 1.0
    nk = 0
    for i in range(n):
        u = abs(o[i] - c)
        if u <= reach:
            uu[nk] = u
            vv[nk] = v[i]
            nk += 1
    for j in range(nf):
        gain[j] = _box_gain(uu, vv, nk, 0.5 * base * factors[j])
    jbest = 0
    best = gain[0]
    for j in range(1, nf):
        if gain[j] > best:
            best = gain[j]
            jbest = j
    jj = min(max(jbest, 1), nf - 2)
    g0, g1, g2 = gain[jj - 1], gain[jj], gain[jj + 1]
    den = g0 - 2 * g1 + g2
    shift = 0.0
    if den < 0 and math.isfinite(den):
        shift = 0.5 * (g0 - g2) / den
    shift = min(max(shift, -1.0), 1.0)
    step = math.log(factors[1] / factors[0])
    w_fit = base * factors[jj] * math.exp(shift * step)
    inside = jbest >= 1 and jbest <= nf - 2 and math.isfinite(gain[jbest])
    return w_fit if (good and inside) else w0


@_jit
def _streak(k, bwk, has_bw, p_, c_, n_, tuple_mode, cur, has_cur, e_r, c_ref, has_contrast, lut, labels, valid,
            L, x, y, w, h, y0, y1, ch, xm, ym, slope, row_width, m, sigma_min, noise2, factors, flank_gap,
            flank_min, flank_half_rows, p_row, p_ob, p_val, s_o, s_v, s_row, uu, vv, gain, row_sum, f_sum,
            f_n, base, sm, buf):
    """One measurement of streak k by :func:`_pass`, its flanks beyond half of max(detected
    row width, ``bwk``) when ``has_bw``: (w', top, bottom, plateau, chi2, ok).  A ``lut``
    (not empty) holds c_ref / max(E_r - (p + n) / 2, c_ref / 4) for the sums p + n of 8-bit
    frames n-1 and n+1, when ``cur`` is frame n (:func:`_contrast_table`)."""
    N = labels.shape[1]
    use_lut = lut.size > 0
    mh = m + 2
    band_width = row_width[k]
    if has_bw:
        mh += int(math.ceil(0.5 * bwk))
        if bwk > band_width:
            band_width = bwk
    x0 = max(x[k] - mh, 0)
    x1 = min(x[k] + w[k] + mh, N)
    half = 0.5 * band_width + 1.5 + m / 2
    nrow = ch[k]
    yk0 = y0[k]
    lab_k = L[k]
    np_ = 0
    for r in range(nrow):
        row_sum[r] = 0.0
        f_sum[r] = 0.0
        f_n[r] = 0.0
    flank_at = 0.5 * band_width + flank_gap
    for r in range(nrow):
        gy = yk0 + r
        ax = xm[k] + slope[k] * (gy - ym[k])
        bx0 = int(math.floor(ax - half))
        bx0 = min(max(bx0, x0), x1)
        bx1 = int(math.ceil(ax + half)) + 1
        bx1 = min(max(bx1, bx0), x1)
        for gx in range(bx0, bx1):
            ob = gx - ax
            if abs(ob) > half:
                continue
            lab = labels[gy, gx]
            if lab != 0 and lab != lab_k and valid[lab]:
                continue
            if use_lut:
                pv = p_[gy, gx]
                nv = n_[gy, gx]
                raw = np.float64(c_[gy, gx]) - 0.5 * (np.float64(pv) + np.float64(nv))
                val = raw * lut[np.int64(pv) + np.int64(nv)]
            else:
                if tuple_mode:
                    raw = np.float64(c_[gy, gx]) - 0.5 * (np.float64(p_[gy, gx]) + np.float64(n_[gy, gx]))
                else:
                    raw = np.float64(c_[gy, gx])
                val = raw
                if has_contrast and has_cur:
                    cg = np.float64(cur[gy, gx])
                    d = e_r - (cg - raw)
                    lim = 0.25 * c_ref
                    val = raw * (c_ref / (d if d > lim else lim))
            p_row[np_] = r
            p_ob[np_] = ob
            p_val[np_] = val
            np_ += 1
            if has_bw and abs(ob) > flank_at:
                f_sum[r] += val
                f_n[r] += 1.0
    if has_bw:
        for r in range(nrow):
            base[r] = 0.0
            lo = max(r - flank_half_rows, 0)
            hi = min(r + flank_half_rows, nrow - 1)
            sv = 0.0
            sn = 0.0
            for q in range(lo, hi + 1):
                sv += f_sum[q]
                sn += f_n[q]
            if sn >= flank_min:
                base[r] = sv / sn
        for i in range(np_):
            p_val[i] -= base[p_row[i]]
    for i in range(np_):
        row_sum[p_row[i]] += p_val[i]
    # 3-row smoothing, zero padded
    for r in range(nrow):
        a = row_sum[r - 1] if r > 0 else 0.0
        b = row_sum[r + 1] if r + 1 < nrow else 0.0
        sm[r] = (a + row_sum[r] + b) / 3.0
    # plateau: median over the middle half of the streak's rows
    nb = 0
    lo_y = y[k] + 0.25 * h[k]
    hi_y = y[k] + 0.75 * h[k]
    for r in range(nrow):
        gy = yk0 + r
        if gy >= lo_y and gy <= hi_y:
            buf[nb] = sm[r]
            nb += 1
    if nb < 2:
        for r in range(nrow):
            buf[r] = sm[r]
        nb = nrow
    plateau = _median(buf, nb)
    lvl = 0.5 * plateau
    i0 = -1
    i1 = -1
    for r in range(nrow):
        if sm[r] >= lvl:
            if i0 < 0:
                i0 = r
            i1 = r
    has = i0 >= 0 and plateau > 0
    if i0 < 0:
        i0 = 0
        i1 = nrow - 1
    if i0 > 0:
        a = sm[i0 - 1]
        b = sm[i0]
        first = i0 - 1 + ((lvl - a) / (b - a) if b != a else 1.0)
    else:
        first = 0.0
    if i1 < nrow - 1:
        a = sm[i1]
        b = sm[i1 + 1]
        last = i1 + ((a - lvl) / (a - b) if a != b else 0.0)
    else:
        last = nrow - 1.0
    top_r = first + yk0
    bot_r = last + yk0
    # cross profile on the plateau rows
    cos_t = 1.0 / math.sqrt(1.0 + slope[k] ** 2)
    w_guess = band_width * cos_t - 2.0
    if w_guess < 1.0:
        w_guess = 1.0
    lo_r = top_r + 0.5 * w_guess + 1.0
    hi_r = bot_r - 0.5 * w_guess - 1.0
    n_pr = math.floor(min(hi_r, y1[k] - 1.0)) - math.ceil(max(lo_r, float(yk0))) + 1
    enough = n_pr >= 2
    mid = 0.5 * (top_r + bot_r)
    ns = 0
    for i in range(np_):
        gyf = float(yk0 + p_row[i])
        if enough:
            take = gyf >= lo_r and gyf <= hi_r
        else:
            take = abs(gyf - mid) <= 1.0
        if take:
            s_o[ns] = p_ob[i] * cos_t
            s_v[ns] = p_val[i]
            s_row[ns] = p_row[i]
            ns += 1
    # apparent width: three passes of the second moment, then the least-squares box
    rw = band_width * cos_t
    win = np.inf
    cen_o = 0.0
    cen = np.nan
    w_app = np.nan
    c0 = 0.0
    for it in range(3):
        c0 = 0.0
        c1 = 0.0
        c2 = 0.0
        for i in range(ns):
            o = s_o[i]
            if it == 0 or abs(o - cen_o) <= win:
                v = s_v[i]
                vo = v * o
                c0 += v
                c1 += vo
                c2 += vo * o
        cen = c1 / c0
        var = c2 / c0 - cen * cen
        t = var - 1.0 / 12.0 - sigma_min * sigma_min
        if t < 0.0:
            t = 0.0
        w_app = math.sqrt(12.0 * t)
        good = math.isfinite(w_app) and c0 > 0
        wl = w_app if good else rw
        wl = min(max(wl, 0.5 * rw - 1.0), rw + 2.0)
        if good:
            win = 0.5 * wl + 1.5
            cen_o = cen
    w_app = _refine_box_width(s_o, s_v, ns, cen, w_app, factors, uu, vv, gain)
    ok = has and c0 > 0 and ns >= 6 and math.isfinite(w_app) and w_app > 0
    # goodness of the uniform model on the plateau rows
    n_r = 0
    last_row = -1
    for i in range(ns):
        if s_row[i] != last_row:
            n_r += 1
            last_row = s_row[i]
    chi2 = np.inf
    if ok:
        amp = c0 / (max(n_r, 1) * w_app)
        hw = 0.5 * w_app
        ss = 0.0
        for i in range(ns):
            u = s_o[i] - cen
            cov = min(u + 0.5, hw) - max(u - 0.5, -hw)
            if cov < 0.0:
                cov = 0.0
            res = s_v[i] - amp * cov
            ss += res * res
        chi2 = ss / (max(ns, 1) * noise2)
        if not math.isfinite(chi2):
            chi2 = np.inf
    return w_app, top_r, bot_r, plateau, chi2, ok


@_jit
def _scratch(bw, has_bw, refit, m, x, w, ch, N, n_factors):
    """Scratch space of :func:`_streak` for the largest of the streaks, shared by all (the
    second measurement's flanks lie at most 4 max(w, 1) + 8 px apart)."""
    cap_max = 0
    row_max = 0
    for k in range(x.size):
        mh = m + 2
        if has_bw:
            mh += int(math.ceil(0.5 * bw[k]))
        if refit:
            mh = max(mh, m + 2 + int(math.ceil(0.5 * (4.0 * max(w[k], 1) + 8.0))))
        cap_k = ch[k] * (min(x[k] + w[k] + mh, N) - max(x[k] - mh, 0))
        cap_max = max(cap_max, cap_k)
        row_max = max(row_max, ch[k])
    return (np.empty(cap_max, np.int64), np.empty(cap_max), np.empty(cap_max), np.empty(cap_max), np.empty(cap_max),
            np.empty(cap_max, np.int64), np.empty(cap_max), np.empty(cap_max), np.empty(n_factors), np.empty(row_max),
            np.empty(row_max), np.empty(row_max), np.empty(row_max), np.empty(row_max), np.empty(row_max))


@_jit
def _streak_refit(k, bwk, has_bw, wide_margin, p_, c_, n_, tuple_mode, cur, has_cur, e_r, c_ref, has_contrast,
                  lut, labels, valid, L, x, y, w, h, y0, y1, ch, xm, ym, slope, row_width, m, sigma_min, noise2, factors,
                  flank_gap, flank_min, flank_half_rows, sc, w_out, top_out, bot_out, plat_out, chi2_out, ok_out):
    """Streak k measured by :func:`_streak`, and with ``wide_margin`` (not NaN) measured
    again at once (its pixels still in the cache) when wider than its detected rows by more
    than it, against the flanks beyond the width found; written to the outputs."""
    p_row, p_ob, p_val, s_o, s_v, s_row, uu, vv, gain, row_sum, f_sum, f_n, base, sm, buf = sc
    w_app, top_r, bot_r, plateau, chi2, ok = _streak(
        k, bwk, has_bw, p_, c_, n_, tuple_mode, cur, has_cur, e_r, c_ref, has_contrast, lut, labels, valid,
        L, x, y, w, h, y0, y1, ch, xm, ym, slope, row_width, m, sigma_min, noise2, factors, flank_gap,
        flank_min, flank_half_rows, p_row, p_ob, p_val, s_o, s_v, s_row, uu, vv, gain, row_sum, f_sum,
        f_n, base, sm, buf)
    # (NaN is not wide; +inf is, and is measured again as of no width)
    if wide_margin == wide_margin and (w_app == np.inf or w_app > row_width[k] + wide_margin):
        b2 = w_app if math.isfinite(w_app) else 0.0
        b2 = min(max(b2, 0.0), 4.0 * max(w[k], 1) + 8.0)
        w_app, top_r, bot_r, plateau, chi2, ok = _streak(
            k, b2, True, p_, c_, n_, tuple_mode, cur, has_cur, e_r, c_ref, has_contrast, lut, labels, valid,
            L, x, y, w, h, y0, y1, ch, xm, ym, slope, row_width, m, sigma_min, noise2, factors, flank_gap,
            flank_min, flank_half_rows, p_row, p_ob, p_val, s_o, s_v, s_row, uu, vv, gain, row_sum, f_sum,
            f_n, base, sm, buf)
    w_out[k] = w_app
    top_out[k] = top_r
    bot_out[k] = bot_r
    plat_out[k] = plateau
    chi2_out[k] = chi2
    ok_out[k] = ok


@_jit
def _pass_outputs(K):
    return (np.full(K, np.nan), np.zeros(K), np.zeros(K), np.full(K, np.nan), np.full(K, np.inf),
            np.zeros(K, np.bool_))


@_jit
def _pass(p_, c_, n_, tuple_mode, cur, has_cur, e_r, c_ref, has_contrast, lut, labels, valid,
          L, x, y, w, h, y0, y1, ch, xm, ym, slope, row_width, bw, has_bw, m, sigma_min,
          noise_sigma, factors, flank_gap, flank_min, flank_half_rows, wide_margin):
    """:func:`_streak_refit` over the K streaks: (w', top, bottom, plateau, chi2, ok)."""
    w_out, top_out, bot_out, plat_out, chi2_out, ok_out = _pass_outputs(L.size)
    noise2 = max(noise_sigma, 1e-3) ** 2
    sc = _scratch(bw, has_bw, wide_margin == wide_margin, m, x, w, ch, labels.shape[1], factors.size)
    for k in range(L.size):
        bwk = bw[k] if has_bw else 0.0
        _streak_refit(k, bwk, has_bw, wide_margin, p_, c_, n_, tuple_mode, cur, has_cur, e_r,
                      c_ref, has_contrast, lut, labels, valid, L, x, y, w, h, y0, y1, ch, xm, ym, slope, row_width, m,
                      sigma_min, noise2, factors, flank_gap, flank_min, flank_half_rows, sc, w_out, top_out, bot_out,
                      plat_out, chi2_out, ok_out)
    return w_out, top_out, bot_out, plat_out, chi2_out, ok_out


@_jit
def _table(p_, c_, n_, tuple_mode, cur, has_cur, prev, has_prev, e_r, c_ref, has_contrast, lut, labels, valid, L,
           x, y, w, h, x0, y0, y1, ch, m, sigma_min, noise_sigma, factors, flank_gap, flank_min, flank_half_rows,
           wide_margin):
    """:func:`_own` and :func:`_pass` (flanks beyond the detected rows, ``wide_margin``)
    streak by streak, each streak's pixels still in the cache from the first when the
    second reads them."""
    K = L.size
    vals, own_k, own_y, own_x, xm, ym, slope, row_width, bg_dn, beta = _own_outputs(w, h)
    w_out, top_out, bot_out, plat_out, chi2_out, ok_out = _pass_outputs(K)
    noise2 = max(noise_sigma, 1e-3) ** 2
    bw = np.zeros(K)
    sc = _scratch(bw, True, wide_margin == wide_margin, m, x, w, ch, labels.shape[1], factors.size)
    n_all = 0
    for k in range(K):
        n_all = _own_one(k, n_all, p_, c_, n_, tuple_mode, cur, has_cur, prev, has_prev, e_r, c_ref, has_contrast,
                         labels, L, x, y, w, h, x0, y0, vals, own_k, own_y, own_x, xm, ym, slope, row_width, bg_dn,
                         beta)
        _streak_refit(k, 0.0, True, wide_margin, p_, c_, n_, tuple_mode, cur, has_cur, e_r, c_ref, has_contrast,
                      lut, labels, valid, L, x, y, w, h, y0, y1, ch, xm, ym, slope, row_width, m, sigma_min, noise2,
                      factors, flank_gap, flank_min, flank_half_rows, sc, w_out, top_out, bot_out, plat_out,
                      chi2_out, ok_out)
    return (xm, ym, slope, row_width, bg_dn, beta, own_k[:n_all], own_y[:n_all], own_x[:n_all], w_out, top_out,
            bot_out, plat_out, chi2_out, ok_out)


@_jit
def _own_one(k, n_all, p_, c_, n_, tuple_mode, cur, has_cur, prev, has_prev, e_r, c_ref, has_contrast, labels, L, x,
             y, w, h, x0, y0, vals, own_k, own_y, own_x, xm, ym, slope, row_width, bg_dn, beta):
    """Streak k's own pixels for :func:`_own` (appended to own_k, own_y, own_x from
    ``n_all``) and its entries of xm, ym, slope, row_width, bg_dn and beta; returns the
    new count of own pixels."""
    start = n_all
    lab_k = L[k]
    n_rows = 0
    s0 = 0.0
    sx = 0.0
    sy = 0.0
    s_bg = 0.0
    sb = 0.0
    sbb = 0.0
    sd = 0.0
    sbd = 0.0
    for gy in range(y[k], y[k] + h[k]):
        row_has = False
        for gx in range(x[k], x[k] + w[k]):
            if labels[gy, gx] != lab_k:
                continue
            row_has = True
            if tuple_mode:
                raw = np.float64(c_[gy, gx]) - 0.5 * (np.float64(p_[gy, gx]) + np.float64(n_[gy, gx]))
            else:
                raw = np.float64(c_[gy, gx])
            val = raw
            if has_cur:
                cg = np.float64(cur[gy, gx])
                s_bg += cg - raw
                if has_contrast:
                    d = e_r - (cg - raw)
                    lim = 0.25 * c_ref
                    val = raw * (c_ref / (d if d > lim else lim))
                if has_prev:
                    b = np.float64(prev[gy, gx])
                    dd = cg - b
                    sb += b
                    sbb += b * b
                    sd += dd
                    sbd += b * dd
            vals[n_all - start] = val
            own_k[n_all] = k
            own_y[n_all] = gy
            own_x[n_all] = gx
            n_all += 1
            wt = val if val > 0.0 else 0.0
            s0 += wt
            sx += wt * (gx - x0[k])
            sy += wt * (gy - y0[k])
        if row_has:
            n_rows += 1
    n_own = n_all - start
    safe = s0 if s0 > 0 else 1.0
    xm_l = sx / safe
    ym_l = sy / safe
    myy = 0.0
    mxy = 0.0
    for i in range(n_own):
        wt = vals[i] if vals[i] > 0.0 else 0.0
        dy = (own_y[start + i] - y0[k]) - ym_l
        myy += wt * dy * dy
        mxy += wt * ((own_x[start + i] - x0[k]) - xm_l) * dy
    myy /= safe
    mxy /= safe
    if s0 > 0:
        xm[k] = xm_l + x0[k]
        ym[k] = ym_l + y0[k]
        slope[k] = mxy / myy if myy > 1e-9 else 0.0
    else:
        xm[k] = x[k] + w[k] / 2.0
        ym[k] = y[k] + h[k] / 2.0
        slope[k] = 0.0
    row_width[k] = n_own / max(n_rows, 1)
    if has_cur:
        bg_dn[k] = s_bg / n_own
        if has_prev:
            n = max(n_own, 1)
            vb = sbb / n - (sb / n) ** 2
            cov = sbd / n - sb * sd / n ** 2
            if n_own >= 6 and vb >= 16.0:
                beta[k] = -cov / vb
    return n_all


@_jit
def _own_outputs(w, h):
    """The outputs of :func:`_own` for streaks of boxes w x h, with room for all their pixels,
    and a scratch array for the biggest (one for all streaks: an array allocated in the loop
    would be reference-counted in the inner loops): (vals, own_k, own_y, own_x, xm, ym,
    slope, row_width, bg_dn, beta)."""
    K = w.size
    total = 0
    biggest = 0
    for k in range(K):
        total += w[k] * h[k]
        biggest = max(biggest, w[k] * h[k])
    return (np.empty(biggest), np.empty(total, np.int64), np.empty(total, np.int64), np.empty(total, np.int64),
            np.empty(K), np.empty(K), np.empty(K), np.empty(K), np.full(K, np.nan), np.full(K, np.nan))


@_jit
def _own(p_, c_, n_, tuple_mode, cur, has_cur, prev, has_prev, e_r, c_ref, has_contrast, labels, L, x, y, w, h,
         x0, y0):
    K = L.size
    vals, own_k, own_y, own_x, xm, ym, slope, row_width, bg_dn, beta = _own_outputs(w, h)
    n_all = 0
    for k in range(K):
        n_all = _own_one(k, n_all, p_, c_, n_, tuple_mode, cur, has_cur, prev, has_prev, e_r, c_ref, has_contrast,
                         labels, L, x, y, w, h, x0, y0, vals, own_k, own_y, own_x, xm, ym, slope, row_width, bg_dn,
                         beta)
    return xm, ym, slope, row_width, bg_dn, beta, own_k[:n_all], own_y[:n_all], own_x[:n_all]


def own_pixels(change, labels, L, x, y, w, h, x0, y0, *, cur, prev, contrast):
    """:func:`raingauge.gauge.streaks._own_streak_pixels`' per-streak quantities from its own
    (detected) pixels: (xm, ym, slope, row_width, background_dn, beta, own_k, own_y, own_x)."""
    p_, c_, n_, tuple_mode = _frames(change)
    has_cur = cur is not None
    has_prev = prev is not None
    e_r, c_ref = (float(contrast[0]), float(contrast[1])) if contrast is not None else (0.0, 1.0)
    return _own(p_, c_, n_, tuple_mode, np.ascontiguousarray(cur) if has_cur else _DUMMY, has_cur,
                np.ascontiguousarray(prev) if has_prev else _DUMMY, has_prev, e_r, c_ref, contrast is not None,
                np.ascontiguousarray(labels), _i64(L), _i64(x), _i64(y), _i64(w), _i64(h), _i64(x0), _i64(y0))


def _frames(change):
    if isinstance(change, tuple):
        p_, c_, n_ = (np.ascontiguousarray(a) for a in change)
        return p_, c_, n_, True
    c_ = np.ascontiguousarray(change)
    return c_, c_, c_, False


def _i64(a):
    return np.ascontiguousarray(a, dtype=np.int64)


def _f64(a):
    return np.ascontiguousarray(a, dtype=np.float64)


_DUMMY = np.zeros((1, 1), np.float32)
_NO_LUT = np.zeros(0)


def _contrast_table(change, cur, e_r, c_ref):
    """c_ref / max(E_r - (p + n) / 2, c_ref / 4) for every sum p + n of two 8-bit frames
    (511,): the factor of Eq. (18)'s division by the local contrast, E_r - (cur - change),
    when ``change`` is the three 8-bit frames and ``cur`` the middle one (cur - change is
    then (p + n) / 2 exactly); else empty (the division is taken pixel by pixel)."""
    if not (isinstance(change, tuple) and cur is change[1] and cur.dtype == np.uint8
            and all(f.dtype == np.uint8 for f in change)):
        return _NO_LUT
    d = e_r - 0.5 * np.arange(511, dtype=np.float64)
    lim = 0.25 * c_ref
    return c_ref / np.where(d > lim, d, lim)


def profile_pass(change, labels, valid, own, *, margin_px, sigma_min, cur, contrast, noise_sigma,
                 baseline_width, factors, flank_gap, flank_min, flank_half_rows):
    """The per-streak part of one pass of :func:`raingauge.gauge.streaks._profile_pass`:
    returns (w', top, bottom (before the cap offset), plateau, chi2, ok), each (K,)."""
    p_, c_, n_, tuple_mode = _frames(change)
    has_cur = cur is not None
    cur_a = np.ascontiguousarray(cur) if has_cur else _DUMMY
    has_contrast = contrast is not None
    e_r, c_ref = (float(contrast[0]), float(contrast[1])) if has_contrast else (0.0, 1.0)
    K = own["L"].size
    has_bw = baseline_width is not None
    if has_bw:
        bw = np.nan_to_num(np.asarray(baseline_width, dtype=np.float64), nan=0.0, posinf=0.0)
        bw = np.clip(bw, 0.0, 4.0 * np.maximum(own["w"], 1) + 8.0)
    else:
        bw = np.zeros(K)

    lut = _contrast_table(change, cur, e_r, c_ref) if has_contrast and has_cur else _NO_LUT
    return _pass(p_, c_, n_, tuple_mode, cur_a, has_cur, e_r, c_ref, has_contrast, lut, np.ascontiguousarray(labels),
                 np.ascontiguousarray(valid, dtype=np.bool_), _i64(own["L"]), _i64(own["x"]), _i64(own["y"]),
                 _i64(own["w"]), _i64(own["h"]), _i64(own["y0"]), _i64(own["y1"]), _i64(own["ch"]), _f64(own["xm"]),
                 _f64(own["ym"]), _f64(own["slope"]), _f64(own["row_width"]), _f64(bw), has_bw, int(margin_px),
                 float(sigma_min), float(noise_sigma), _f64(factors), float(flank_gap), float(flank_min),
                 int(flank_half_rows), math.nan)


def streak_table(change, labels, valid, L, x, y, w, h, x0, y0, y1, ch, *, cur, prev, contrast, margin_px, sigma_min,
                 noise_sigma, factors, flank_gap, flank_min, flank_half_rows, wide_margin):
    """:func:`own_pixels` and :func:`profile_pass` (against the flanks beyond the detected rows,
    measured again when wider than them by ``wide_margin``) in one loop over the streaks:
    (xm, ym, slope, row_width, background_dn, beta, own_k, own_y, own_x, w', top, bottom
    (before the cap offset), plateau, chi2, ok)."""
    p_, c_, n_, tuple_mode = _frames(change)
    has_cur = cur is not None
    has_prev = prev is not None
    e_r, c_ref = (float(contrast[0]), float(contrast[1])) if contrast is not None else (0.0, 1.0)
    lut = _contrast_table(change, cur, e_r, c_ref) if contrast is not None and has_cur else _NO_LUT
    return _table(p_, c_, n_, tuple_mode, np.ascontiguousarray(cur) if has_cur else _DUMMY, has_cur,
                  np.ascontiguousarray(prev) if has_prev else _DUMMY, has_prev, e_r, c_ref, contrast is not None, lut,
                  np.ascontiguousarray(labels), np.ascontiguousarray(valid, dtype=np.bool_), _i64(L), _i64(x), _i64(y),
                  _i64(w), _i64(h), _i64(x0), _i64(y0), _i64(y1), _i64(ch), int(margin_px), float(sigma_min),
                  float(noise_sigma), _f64(factors), float(flank_gap), float(flank_min), int(flank_half_rows),
                  math.nan if wide_margin is None else float(wide_margin))


@_jit
def _scan_run(mask, y, x0, x1, start, n, xs, xe):
    """Columns x0..x1-1 of row y of :func:`_runs`: a run begins at the first nonzero pixel
    after a zero one (``start``, -1 outside a run) and ends, recorded as run n, before the
    next zero one.  Returns the updated (start, n)."""
    for x in range(x0, x1):
        if mask[y, x] != 0:
            if start < 0:
                start = x
        elif start >= 0:
            xs[n] = start
            xe[n] = x - 1
            n += 1
            start = -1
    return start, n


def _byte_segments():
    """For each pattern of 8 bits (bit i: pixel i of a word set), its runs of set bits:
    (count (256,), first bit (256, 4), last bit (256, 4))."""
    n = np.zeros(256, np.int64)
    first = np.zeros((256, 4), np.int64)
    last = np.zeros((256, 4), np.int64)
    for b in range(256):
        i = 0
        while i < 8:
            if b >> i & 1:
                j = i
                while j + 1 < 8 and b >> (j + 1) & 1:
                    j += 1
                first[b, n[b]] = i
                last[b, n[b]] = j
                n[b] += 1
                i = j + 1
            else:
                i += 1
    return n, first, last


_SEG_N, _SEG_FIRST, _SEG_LAST = _byte_segments()


@_jit
def _runs(mask, words, use_words):
    """The runs of nonzero pixels of ``mask`` row by row: (row start index (M + 1,), first
    column, last column (inclusive)) of each run, in raster order.  With ``use_words`` the
    mask's rows are read as 8-pixel words (``words``, uint64): a zero word is skipped whole,
    and the set pixels of the others, gathered into 8 bits, give their runs from a table."""
    M, N = mask.shape
    # (room for the most runs a mask can hold: untouched memory costs nothing, and arrays
    # not rebound in the loop keep it free of reference counting)
    cap = M * ((N + 1) // 2)
    xs = np.empty(cap, np.int64)
    xe = np.empty(cap, np.int64)
    row_ptr = np.empty(M + 1, np.int64)
    n = 0
    nw = N // 8 if use_words else 0
    # a byte's nonzero bits folded into its lowest bit, the 8 lowest bits into the top byte
    # (byte i to bit 56 + i: the words are little-endian, pixel 8 wi + i in byte i)
    s1 = np.uint64(1)
    s2 = np.uint64(2)
    s4 = np.uint64(4)
    s56 = np.uint64(56)
    low_bits = np.uint64(0x0101010101010101)
    gather = np.uint64(0x0102040810204080)
    for y in range(M):
        row_ptr[y] = n
        start = -1
        for wi in range(nw):
            wd = words[y, wi]
            if wd == 0:
                if start >= 0:
                    xs[n] = start
                    xe[n] = 8 * wi - 1
                    n += 1
                    start = -1
                continue
            t = wd | (wd >> s4)
            t |= t >> s2
            t |= t >> s1
            b = np.int64(((t & low_bits) * gather) >> s56)
            base = 8 * wi
            if start >= 0 and (b & 1) == 0:
                xs[n] = start
                xe[n] = base - 1
                n += 1
                start = -1
            for j in range(_SEG_N[b]):
                first = _SEG_FIRST[b, j]
                if first > 0 or start < 0:
                    start = base + first
                last = _SEG_LAST[b, j]
                if last < 7:
                    xs[n] = start
                    xe[n] = base + last
                    n += 1
                    start = -1
        start, n = _scan_run(mask, y, 8 * nw, N, start, n, xs, xe)
        if start >= 0:
            xs[n] = start
            xe[n] = N - 1
            n += 1
    row_ptr[M] = n
    return row_ptr, xs[:n].copy(), xe[:n].copy()


@_jit
def _find(parent, i):
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


@_jit
def _run_components(row_ptr, xs, xe):
    """8-connected components of the runs of :func:`_runs`, numbered as OpenCV's block-based
    labelling (``cv2.connectedComponentsWithStats``, 8-connectivity) numbers them: by the
    first 2 x 2 block (in raster order of the blocks) holding a pixel of each.  Returns the
    label of each run and the stats (n + 1, 5) int32: x, y, width, height, area (row 0, the
    background, all 0)."""
    M = row_ptr.size - 1
    n = xs.size
    parent = np.arange(n)
    for y in range(1, M):
        j = row_ptr[y - 1]
        j_end = row_ptr[y]
        for i in range(row_ptr[y], row_ptr[y + 1]):
            # runs of the row above touching this one (8-connectivity: one column beyond)
            while j < j_end and xe[j] < xs[i] - 1:
                j += 1
            k = j
            while k < j_end and xs[k] <= xe[i] + 1:
                ri = _find(parent, i)
                rk = _find(parent, k)
                if ri != rk:
                    if ri < rk:
                        parent[rk] = ri
                    else:
                        parent[ri] = rk
                k += 1
    # each component's first block: the least (y // 2, x // 2) of its runs
    width = 0
    for i in range(n):
        if xe[i] + 1 > width:
            width = xe[i] + 1
    bw = width // 2 + 1
    root = np.empty(n, np.int64)
    for i in range(n):
        root[i] = _find(parent, i)
    key = np.full(n, np.iinfo(np.int64).max)
    for y in range(M):
        for i in range(row_ptr[y], row_ptr[y + 1]):
            r = root[i]
            kk = (y // 2) * bw + xs[i] // 2
            if kk < key[r]:
                key[r] = kk
    roots = np.empty(n, np.int64)
    n_comp = 0
    for i in range(n):
        if parent[i] == i:
            roots[n_comp] = i
            n_comp += 1
    roots = roots[:n_comp]
    order = np.argsort(key[roots])
    comp_label = np.zeros(n, np.int64)
    for c in range(n_comp):
        comp_label[roots[order[c]]] = c + 1
    run_label = np.empty(n, np.int64)
    x0 = np.full(n_comp + 1, np.iinfo(np.int64).max)
    y0 = np.full(n_comp + 1, np.iinfo(np.int64).max)
    x1 = np.full(n_comp + 1, -1)
    y1 = np.full(n_comp + 1, -1)
    area = np.zeros(n_comp + 1, np.int64)
    for y in range(M):
        for i in range(row_ptr[y], row_ptr[y + 1]):
            lab = comp_label[root[i]]
            run_label[i] = lab
            x0[lab] = min(x0[lab], xs[i])
            x1[lab] = max(x1[lab], xe[i])
            y0[lab] = min(y0[lab], y)
            y1[lab] = max(y1[lab], y)
            area[lab] += xe[i] - xs[i] + 1
    stats = np.zeros((n_comp + 1, 5), np.int32)
    for c in range(1, n_comp + 1):
        stats[c, 0] = x0[c]
        stats[c, 1] = y0[c]
        stats[c, 2] = x1[c] - x0[c] + 1
        stats[c, 3] = y1[c] - y0[c] + 1
        stats[c, 4] = area[c]
    return run_label, stats


@_jit
def _paint_runs(labels, row_ptr, xs, xe, run_label):
    """Write each run's label into ``labels`` (zero elsewhere, as given)."""
    M = row_ptr.size - 1
    for y in range(M):
        for i in range(row_ptr[y], row_ptr[y + 1]):
            lab = run_label[i]
            for x in range(xs[i], xe[i] + 1):
                labels[y, x] = lab


def label_components(mask):
    """``cv2.connectedComponentsWithStats(mask, connectivity=8, ltype=...)`` for a sparse
    mask, from its runs: (n, labels, stats), the labels uint16 while there are at most 65536
    labels (else int32; half the memory to clear and write, and a frame of heavy rain has a
    few thousand), numbered as OpenCV numbers them; the stats' row 0 (the background) is 0
    and only their first five columns are given.

    Parameters
    ----------
    mask : (M, N) uint8 array
        Nonzero where a pixel is set.
    """
    mask = np.ascontiguousarray(mask, dtype=np.uint8)
    M, N = mask.shape
    use_words = N >= 8 and N % 8 == 0
    words = mask.view(np.uint64) if use_words else np.zeros((1, 1), np.uint64)
    row_ptr, xs, xe = _runs(mask, words, use_words)
    run_label, stats = _run_components(row_ptr, xs, xe)
    labels = np.zeros((M, N), np.uint16 if stats.shape[0] <= 65536 else np.int32)
    _paint_runs(labels, row_ptr, xs, xe, run_label)
    return stats.shape[0], labels, stats


@_jit
def _spike_masks(prev, cur, nxt, n_s, thr, thr_low, has_low, mask, low):
    """Eq. (19) summed over ``n_s`` rows along the fall, from the 8-bit frames of a linear
    camera: mask = 255 where sum min(I_n - I_{n-1}, I_n - I_{n+1}) >= thr (and low where it
    is >= thr_low), the sum centred on the row (its first n_s // 2 and last n_s - 1 - n_s // 2
    rows, where no window is whole, summing to 0).  Integer sums, exact."""
    M, N = cur.shape
    half = n_s // 2
    ring = np.zeros((n_s, N), np.int64)
    acc = np.zeros(N, np.int64)
    zero_hi = 255 if 0 >= thr else 0
    zero_lo = 255 if 0 >= thr_low else 0
    for y in range(half):
        for x in range(N):
            mask[y, x] = zero_hi
            if has_low:
                low[y, x] = zero_lo
    for y in range(M - (n_s - 1 - half), M):
        for x in range(N):
            mask[y, x] = zero_hi
            if has_low:
                low[y, x] = zero_lo
    for r in range(M):
        slot = r % n_s
        out = r - (n_s - 1) + half
        for x in range(N):
            a = np.int64(prev[r, x])
            b = np.int64(nxt[r, x])
            v = np.int64(cur[r, x]) - (a if a > b else b)
            t = acc[x] + v - ring[slot, x]
            ring[slot, x] = v
            acc[x] = t
            if r >= n_s - 1:
                mask[out, x] = 255 if t >= thr else 0
                if has_low:
                    low[out, x] = 255 if t >= thr_low else 0


def spike_masks(prev, cur, nxt, smooth_px, threshold, threshold_low=None):
    """The detection masks of :func:`raingauge.gauge.streaks.detect_streaks` straight from
    the 8-bit frames n-1, n, n+1 of a linear camera: (mask, low) uint8 (0 or 255), the spike
    image of Eq. (19) summed over ``smooth_px`` rows compared with ``threshold`` (and
    ``threshold_low``; low is None without it)."""
    prev, cur, nxt = (np.ascontiguousarray(a, dtype=np.uint8) for a in (prev, cur, nxt))
    mask = np.empty(cur.shape, np.uint8)
    has_low = threshold_low is not None
    low = np.empty(cur.shape, np.uint8) if has_low else np.empty((1, 1), np.uint8)
    _spike_masks(prev, cur, nxt, int(smooth_px), float(threshold), float(threshold_low) if has_low else 0.0,
                 has_low, mask, low)
    return mask, (low if has_low else None)


@_jit
def _slant_masks(spike, offs, frac, reach, thr, thr_low, has_low, mask, low):
    """The largest over K directions of the spike image summed along each (direction k's row
    i: the value at column x + offs[k, i] + frac[k, i], read between that column and the
    next), the rows and columns reflected at the frame's borders (``cv2.BORDER_REFLECT``),
    compared with ``thr`` (and ``thr_low``).  In float32, each row's value taken as
    v0 + frac (v1 - v0): exact for whole gray levels and fractions of quarter pixels, so a
    sum that equals a threshold reaches it.  The padded rows are converted once each and
    kept in a ring of n rows."""
    M, N = spike.shape
    K, n = offs.shape
    half = n // 2
    W = N + 2 * reach + 1
    ring = np.zeros((n, W), np.float32)
    acc = np.empty(N, np.float32)
    best = np.empty(N, np.float32)
    # the ring's slot s holds virtual row v (v % n == s) of the frame reflected at its top
    # and bottom (row -1 is row 0, row M is row M - 1)
    for v in range(-half, M + n - half - 1):
        r = v
        if r < 0:
            r = -r - 1
        elif r >= M:
            r = 2 * M - r - 1
        r = min(max(r, 0), M - 1)
        row = ring[v % n]
        for x in range(N):
            row[reach + x] = np.float32(spike[r, x])
        for j in range(reach):
            # columns reflected: column -1 - j is column j, column N + j is column N - 1 - j
            row[reach - 1 - j] = row[reach + min(j, N - 1)]
            row[reach + N + j] = row[reach + max(N - 1 - j, 0)]
        row[W - 1] = row[W - 2]
        y = v - (n - 1 - half)
        if y < 0:
            continue
        for k in range(K):
            for i in range(n):
                o = reach + offs[k, i]
                # (slices: indices the compiler knows are not negative, so the loops are vectorised)
                s0 = ring[(y + i - half) % n, o:o + N]
                s1 = ring[(y + i - half) % n, o + 1:o + 1 + N]
                f = frac[k, i]
                if i == 0:
                    for x in range(N):
                        acc[x] = s0[x] + f * (s1[x] - s0[x])
                else:
                    for x in range(N):
                        acc[x] = acc[x] + (s0[x] + f * (s1[x] - s0[x]))
            if k == 0:
                for x in range(N):
                    best[x] = acc[x]
            else:
                for x in range(N):
                    if acc[x] > best[x]:
                        best[x] = acc[x]
        for x in range(N):
            mask[y, x] = 255 if best[x] >= thr else 0
            if has_low:
                low[y, x] = 255 if best[x] >= thr_low else 0


#: A sum within this share of a threshold reaches it: the thresholds are decimal numbers
#: (3 x 0.6 gray levels is 1.7999999999999998 in binary), the sums of whole gray levels
#: along quarter-pixel slopes exact multiples of 1/4 [-].
TIE_REL = 1e-6


def slant_weights(smooth_px: int, slopes):
    """Where the line kernels of :func:`raingauge.gauge.streaks.fall_kernel` along each of
    ``slopes`` [px/px] over ``smooth_px`` rows read each row: per direction k and row i the
    column offset (int64) and the fraction of the way to the next column (float32) of the
    line's crossing, ((K, n) each), and the largest reach [px]."""
    n = int(smooth_px)
    half = n // 2
    K = len(slopes)
    offs = np.zeros((K, n), np.int64)
    frac = np.zeros((K, n), np.float32)
    for k, slope in enumerate(slopes):
        for i in range(n):
            x = float(slope) * (i - half)
            x0 = math.floor(x)
            offs[k, i] = x0
            frac[k, i] = x - x0
    reach = int(np.abs(offs).max()) + 1 if K else 1
    return offs, frac, reach


def slant_masks(spike, smooth_px: int, slopes, threshold, threshold_low=None):
    """The detection masks of :func:`raingauge.gauge.streaks.detect_streaks` in a cross wind:
    the spike image (int16 or float32) smoothed over ``smooth_px`` rows along each of
    ``slopes`` [px/px] (the line kernels of :func:`raingauge.gauge.streaks.fall_kernel`, the
    frame reflected at its borders), the largest of them compared with ``threshold`` (and
    ``threshold_low``), a smoothed spike that equals one reaching it (:data:`TIE_REL`):
    (mask, low) uint8 (0 or 255), low None without it."""
    if len(slopes) == 0:
        raise ValueError("slant_masks needs at least one direction to smooth along")
    n = int(smooth_px)
    offs, frac, reach = slant_weights(n, slopes)
    spike = np.ascontiguousarray(spike)
    if spike.dtype not in (np.int16, np.float32):
        spike = spike.astype(np.float32)
    mask = np.empty(spike.shape, np.uint8)
    has_low = threshold_low is not None
    low = np.empty(spike.shape, np.uint8) if has_low else np.empty((1, 1), np.uint8)

    def level(t):
        # the mean over n rows compared with t is the sum compared with n t
        t = float(t) * n
        return np.float32(t - TIE_REL * abs(t))

    _slant_masks(spike, offs, frac, int(reach), level(threshold),
                 level(threshold_low) if has_low else np.float32(0.0), has_low, mask, low)
    return mask, (low if has_low else None)


@_jit
def _change_hist(prev, cur, nxt, row_step, col_step, hist):
    M, N = cur.shape
    for y in range(0, M, row_step):
        for x in range(0, N, col_step):
            hist[2 * np.int64(cur[y, x]) - np.int64(prev[y, x]) - np.int64(nxt[y, x]) + 510] += 1


def union_roots(n_nodes, first, second):
    """Groups of the pairs (first[i], second[i]) of nodes < ``n_nodes``, joined in order (each
    pair's second set under its first's root): (members, root of each)."""
    return _union_roots(int(n_nodes), _i64(first), _i64(second))


def change_histogram(prev, cur, nxt, row_step, col_step):
    """Histogram of 2 I_n - I_{n-1} - I_{n+1} + 510 over every ``row_step``-th row and
    ``col_step``-th column of 8-bit frames: (1021,) int64 counts (as ``np.bincount`` of
    those samples)."""
    hist = np.zeros(1021, np.int64)
    _change_hist(np.ascontiguousarray(prev, dtype=np.uint8), np.ascontiguousarray(cur, dtype=np.uint8),
                 np.ascontiguousarray(nxt, dtype=np.uint8), int(row_step), int(col_step), hist)
    return hist


@_jit
def _union_roots(n_nodes, first, second):
    """Union-find over the pairs (first[i], second[i]) taken in order, the root of the second's
    set put under the root of the first's: (members, their roots), the members in the order
    they first appear in the pairs (first, then second, of each pair)."""
    parent = np.full(n_nodes, -1, np.int64)
    members = np.empty(2 * first.size, np.int64)
    n_mem = 0
    for i in range(first.size):
        for node in (first[i], second[i]):
            if parent[node] < 0:
                parent[node] = node
                members[n_mem] = node
                n_mem += 1
        rb = _find(parent, second[i])
        ra = _find(parent, first[i])
        parent[rb] = ra
    members = members[:n_mem]
    roots = np.empty(n_mem, np.int64)
    for j in range(n_mem):
        roots[j] = _find(parent, members[j])
    return members, roots


_WARMED: set = set()


@_jit
def _blob_partners(labels, frame_labels, blob, st, dy, dx, vals, ptr):
    M, N = frame_labels.shape
    n_out = 0
    for i in range(blob.size):
        ptr[i] = n_out
        b = blob[i]
        start = n_out
        for y in range(st[i, 1], st[i, 1] + st[i, 3]):
            fy = y + dy[i]
            if fy < 0 or fy >= M:
                continue
            for x in range(st[i, 0], st[i, 0] + st[i, 2]):
                if labels[y, x] != b:
                    continue
                fx = x + dx[i]
                if fx < 0 or fx >= N:
                    continue
                v = np.int64(frame_labels[fy, fx])
                if v <= 0:
                    continue
                # insert into the sorted, distinct labels of this blob
                j = n_out
                while j > start and vals[j - 1] > v:
                    j -= 1
                if j > start and vals[j - 1] == v:
                    continue
                if n_out >= vals.size:
                    return -1
                for q in range(n_out, j, -1):
                    vals[q] = vals[q - 1]
                vals[j] = v
                n_out += 1
    ptr[blob.size] = n_out
    return n_out


def blob_partners(labels, frame_labels, blob, boxes, dy, dx):
    """The frame's labels under each blob of a canvas (:meth:`raingauge.gauge.completeness.
    CompletenessProbe.blobs`): for blob i, the pixels of ``labels == blob[i]`` in its box
    ``boxes[i]`` (x, y, width, height), moved by (``dx[i]``, ``dy[i]``) into the frame, and
    the positive ``frame_labels`` there, distinct and ascending.  Returns (values, ptr): blob
    i's labels are values[ptr[i]:ptr[i + 1]]."""
    blob, dy, dx = _i64(blob), _i64(dy), _i64(dx)
    boxes = np.ascontiguousarray(boxes, dtype=np.int64).reshape(-1, 4)
    ptr = np.zeros(blob.size + 1, np.int64)
    size = 64
    while True:
        vals = np.empty(size, np.int64)
        n = _blob_partners(labels, frame_labels, blob, boxes, dy, dx, vals, ptr)
        if n >= 0:
            return vals[:n], ptr
        size *= 8


def warm_up(frames_8bit: bool = False) -> None:
    """Compile the loops (or load them from numba's cache) for the gauge's inputs now rather
    than on the first frames of a live camera; once per process and kind of frames.

    Parameters
    ----------
    frames_8bit : bool
        The frames are a linear camera's 8-bit ones, measured as they are (else float32
        linearised frames); 16- and 32-bit labels either way.
    """
    kind = bool(frames_8bit)
    if kind in _WARMED or not AVAILABLE:
        return
    from raingauge.gauge.streaks import measure_streak_table

    rng = np.random.default_rng(0)
    frames = [rng.normal(50.0, 2.0, (48, 32)).astype(np.float32) for _ in range(3)]
    frames[1][8:40, 14:17] += 80.0
    if kind:
        frames = [np.rint(f).astype(np.uint8) for f in frames]
    for dtype in (np.uint16, np.int32):
        labels = np.zeros((48, 32), dtype)
        labels[8:40, 14:17] = 1
        stats = np.array([[0, 0, 0, 0, 0], [14, 8, 3, 32, 96]], np.int32)
        measure_streak_table(tuple(frames), labels, stats, [1], cur=frames[1], prev=frames[0],
                             contrast=(200.0, 150.0), engine="compiled")
    if kind:
        # the noise histogram and the detection masks of 8-bit frames
        change_histogram(*frames, 3, 4)
        spike_masks(*frames, 5, 15.0, 7.5)
        spike_masks(*frames, 5, 15.0)
    # the detection masks in a cross wind, of the 8-bit frames' int16 spike or the float one
    spike = (frames[1].astype(np.int16) - np.maximum(frames[0], frames[2]).astype(np.int16) if kind
             else frames[1] - np.maximum(frames[0], frames[2]))
    slant_masks(spike, 5, (0.3, 0.6), 3.0, 1.8)
    slant_masks(spike, 5, (0.3, 0.6), 3.0)
    union_roots(4, np.array([0, 2]), np.array([1, 1]))
    for lt in (np.uint16, np.int32):
        for ft in (np.uint16, np.int32):
            blob_partners(np.ones((4, 4), lt), np.ones((4, 4), ft), np.array([1]), np.array([[0, 0, 4, 4]]),
                          np.array([0]), np.array([0]))
    # the labelling, into 16- and 32-bit labels, of masks with and without a ragged last word
    for width in (32, 30):
        mask = np.zeros((48, width), np.uint8)
        mask[8:40, 14:17] = 255
        label_components(mask)
    row_ptr, xs, xe = _runs(mask, np.zeros((1, 1), np.uint64), False)
    run_label = _run_components(row_ptr, xs, xe)[0]
    _paint_runs(np.zeros(mask.shape, np.int32), row_ptr, xs, xe, run_label)
    _WARMED.add(kind)
