"""The moments of one ramp's spectrum over random vibration phases, in closed form.

One engine's chirp, with the modulation index growing over the chirp
(beta_j(t) = K A_j t), expands by Jacobi-Anger on each vibration term into lines
indexed by integer vectors n (one integer per term a, b, p, m)::

    s(t) = (Gamma / 2) sum_n e^{i n.phi} g_n(t) [e^{i (K R0 + n.w) t} + (-1)^{sum n} e^{-i (K R0 - n.w) t}]
    g_n(t) = prod_j J_{n_j}(K A_j t)

(the factor i^{sum n} of Jacobi-Anger is a shift of every phase by pi / 2 and
drops out when the phases are uniform). The spectrum at bin b is
X(b) = sum_n e^{i n.phi} c_n(b), and each line's shape c_n(b) is the transform of
its envelope g_n, not the window's kernel. With the phases independent and
uniform, every moment of X is a sum over lines:

* ``E|X|^2 = sum_n |c_n|^2`` (exact);
* ``E|X|^4 = sum_D |S_D|^2`` with ``S_D = sum_n c_n conj(c_{n-D})`` (pairs of lines
  whose index vectors differ by D);
* over K consecutive ramps the phases advance by n.w T_r, so the K-ramp mean of
  |X|^2 keeps ``sum_D |F_K(D.w T_r)|^2 |S_D|^2`` of that variance (F_K the
  normalised Dirichlet kernel): the effective number of looks.

Engines add through their carrier lines (n = 0): those are not random and form,
with the body return, the steady line nu(b). Pairs of lines of two engines
differ in two blocks of D, so each such D has one pair.

How it is computed (:func:`line_sums`, compiled with numba):

* g_n is a polynomial in u = t / T_chirp (the Bessel series of each factor), so
  c_n(b) = sum_p a_{n,p} K_p(theta) with the kernel table K_p and its Taylor step
  between table points (:mod:`.line_tables`: error below 1e-8 of the line);
* lines whose envelope bound is below ``amp_tol`` of sum(Gamma) are dropped (the
  bound depends on the amplitudes only, so the result stays smooth in every
  frequency); pairs are summed over the lines whose power at the bin is at least
  ``pair_tol`` of the bin's power;
* the negative-frequency image is kept for the carrier lines (the others' images
  are below 1e-6 of the peak power in the window).

What :func:`line_sums` returns per bin is everything the moments need that does
not depend on the steady line's amplitude, so a caller can vary that (and its
phase) without recomputing the pair sums (:mod:`mdaug.inference.likelihood.closed_form`).
"""
from __future__ import annotations

import math

import numpy as np

from ..radar import RadarConfig
from .line_tables import (MAX_DEGREE, TABLE_OVERSAMPLE, TAYLOR_TERMS, bessel_poly, fejer_at, fejer_table,
                          kernel_table, line_tables, numba, order_for, table_at)

IMAGE_TOL = 0.02  # lines weaker than this (x sum Gamma) drop their image (below ~5e-5 of the line there)
N_SUMS = 15  # quantities per bin, see SUM_NAMES
SUM_NAMES = ("Tp", "Tm", "Dl", "P", "P2", "Pw", "Q", "Qw", "U", "Uw", "V", "Vw", "SF", "SFw", "C0")
"""Per bin: Tp, Tm the unit steady tone (sum(Gamma) / 2 K_0) at the line and at its
image; Dl the engines' carrier lines minus kappa' (Tp + Tm) (their taper shape);
P = sum |c_n|^2, P2 = sum |c_n|^4, Pw = sum F_n |c_n|^2 over the random lines;
Q = sum c_n c_{-n} (and Qw weighted); U = sum_D conj(S_D c_{-D}), V = sum_D conj(S_D) c_D
(and weighted); SF = sum_{D != 0} |S_D|^2 over pairs of random lines (SFw weighted);
C0 the engines' carrier lines with their images. Weights F = |F_K(D.w T_r)|^2."""


def _line_sums_py(gam, amp, freq, beta_scale, carrier_bin, centres, offsets, table, vectors, neg, codes_pow,
                  code_base, line_of_code, ftab, ramps, ramp_rad, g1, amp_tol, pair_tol, hz_per_bin,
                  coherent, reach_tol):  # pragma: no cover
    """Compiled kernel; see :func:`line_sums` for the arguments."""
    n_w, n_e = gam.shape[0], gam.shape[1]
    n_m, n_b = centres.shape[1], offsets.shape[0]
    n_t, n_r = table.shape[0], table.shape[1]
    degree = n_r - 1 - TAYLOR_TERMS
    n_l = vectors.shape[0]
    order = 0
    for i in range(n_l):
        s = abs(vectors[i, 0]) + abs(vectors[i, 1]) + abs(vectors[i, 2]) + abs(vectors[i, 3])
        if s > order:
            order = s
    off = 2 * order
    out = np.zeros((n_w, n_m, n_b, N_SUMS), np.complex128)
    n_codes = code_base ** 4 if coherent else 1
    acc = np.zeros(n_codes, np.complex128)
    acc_w = np.zeros(n_codes)  # the Fejer weight of each touched code
    touched = np.empty(n_l * n_l + 1 if coherent else 1, np.int64)
    two_pi = 2.0 * math.pi
    image_tol = IMAGE_TOL
    cell_bins = table.shape[0] / TABLE_OVERSAMPLE / beta_scale[1]  # FFT bins per resolution cell
    taylor_fact = np.ones(TAYLOR_TERMS + 1)
    for q in range(1, TAYLOR_TERMS + 1):
        taylor_fact[q] = taylor_fact[q - 1] * q
    n_samples = beta_scale[1]
    for w in range(n_w):
        gsum = 0.0
        for k in range(n_e):
            gsum += gam[w, k]
        # ---- per engine and term: Bessel polynomials and their bounds on [0, 1]
        jc = np.zeros((n_e, 4, order + 1, degree + 1))
        jb = np.zeros((n_e, 4, order + 1))
        for k in range(n_e):
            for j in range(4):
                beta = beta_scale[0] * abs(amp[w, k, j])
                jc[k, j] = bessel_poly(beta, order, degree)
                for m in range(order + 1):
                    tot = 0.0
                    for p in range(degree + 1):
                        tot += abs(jc[k, j, m, p])
                    jb[k, j, m] = tot
        # ---- active lines: envelope polynomial, position (bins), frequency (rad/s)
        act_k = np.empty(n_e * n_l, np.int64)
        act_i = np.empty(n_e * n_l, np.int64)
        act_deg = np.empty(n_e * n_l, np.int64)
        act_pos = np.empty(n_e * n_l)
        act_w = np.empty(n_e * n_l)
        act_img = np.zeros(n_e * n_l, np.bool_)
        act_reach = np.zeros(n_e * n_l)
        coef = np.zeros((n_e * n_l, degree + 1))
        index = np.full((n_e, n_l), -1, np.int64)
        n_act = 0
        for k in range(n_e):
            for i in range(n_l):
                bound = gam[w, k]
                for j in range(4):
                    bound *= jb[k, j, abs(vectors[i, j])]
                if bound < amp_tol * gsum:
                    continue
                poly = np.zeros(degree + 1)
                poly[0] = 1.0
                for j in range(4):
                    m = vectors[i, j]
                    sign = -1.0 if (m < 0 and (-m) % 2 == 1) else 1.0
                    src = jc[k, j, abs(m)]
                    new = np.zeros(degree + 1)
                    for p in range(degree + 1):
                        if poly[p] == 0.0:
                            continue
                        for r in range(degree + 1 - p):
                            if src[r] != 0.0:
                                new[p + r] += poly[p] * src[r] * sign
                    poly = new
                top = 0.0
                mean_bound = 0.0
                for p in range(degree + 1):
                    top += abs(poly[p])
                    mean_bound += abs(poly[p]) / (p + 1.0)
                if gam[w, k] * mean_bound < amp_tol * gsum:
                    continue  # the line's mean envelope over the chirp is below the tolerance
                dg = degree
                while dg > 0 and abs(poly[dg]) < 1e-7 * top:
                    dg -= 1
                act_img[n_act] = gam[w, k] * top >= image_tol * gsum
                # how far (FFT bins) the line's sidelobes stay above reach_tol x sum(Gamma):
                # amplitude / (pi x distance in resolution cells), cells of fft / N_s bins
                act_reach[n_act] = gam[w, k] * mean_bound / (math.pi * reach_tol * gsum) * cell_bins
                coef[n_act] = poly
                act_deg[n_act] = dg
                wl = 0.0
                for j in range(4):
                    wl += vectors[i, j] * freq[w, k, j]
                act_w[n_act] = wl
                act_pos[n_act] = carrier_bin[w] + wl / (two_pi * hz_per_bin)
                act_k[n_act] = k
                act_i[n_act] = i
                index[k, i] = n_act
                n_act += 1
        # carrier-line polynomials and their kappa (mean of the envelope over the chirp)
        c0poly = np.zeros((n_e, degree + 1))
        kappa = 0.0
        for k in range(n_e):
            poly = np.zeros(degree + 1)
            poly[0] = 1.0
            for j in range(4):
                src = jc[k, j, 0]
                new = np.zeros(degree + 1)
                for p in range(degree + 1):
                    if poly[p] == 0.0:
                        continue
                    for r in range(degree + 1 - p):
                        new[p + r] += poly[p] * src[r]
                poly = new
            c0poly[k] = poly
            for p in range(degree + 1):
                kappa += gam[w, k] * poly[p] / (p + 1.0)
        kappa /= gsum
        fej = np.empty(n_act)
        for a in range(n_act):
            fej[a] = fejer_at(ftab, act_w[a] * ramp_rad)
        c = np.zeros((n_act, n_b), np.complex128)
        er = np.zeros(n_r, np.complex128)
        sig = np.empty(n_act, np.int64)
        for m in range(n_m):
            centre = centres[w, m]
            # ---- line amplitudes at every bin
            for a in range(n_act):
                dg = act_deg[a]
                scale = 0.5 * gam[w, act_k[a]] * math.sqrt(g1)
                # the line at +(carrier + n.w) and its image at -(carrier - n.w), sign (-1)^(sum n)
                img_pos = act_pos[a] - 2.0 * carrier_bin[w]
                sgn = 1.0
                vi = act_i[a]
                if (vectors[vi, 0] + vectors[vi, 1] + vectors[vi, 2] + vectors[vi, 3]) % 2 != 0:
                    sgn = -1.0
                for b in range(n_b):
                    c[a, b] = 0.0
                for side in range(2 if act_img[a] else 1):
                    jf = ((act_pos[a] if side == 0 else img_pos) - centre) * TABLE_OVERSAMPLE
                    j0 = math.floor(jf + 0.5)
                    d = (jf - j0) * two_pi / n_t * n_samples  # N x theta step
                    for r in range(n_r):
                        er[r] = 0.0
                    fq = 1.0 + 0.0j
                    for q in range(TAYLOR_TERMS + 1):
                        f = fq / taylor_fact[q]
                        for p in range(dg + 1):
                            er[p + q] += coef[a, p] * f
                        fq *= 1j * d
                    fac = scale if side == 0 else scale * sgn
                    line_at = (act_pos[a] if side == 0 else img_pos) - centre
                    reach = act_reach[a]
                    for b in range(n_b):
                        # beyond its reach a line is left out, smoothly (cos^2 taper over the last half)
                        dist = abs(line_at - offsets[b])
                        if dist >= reach:
                            continue
                        taper = 1.0
                        if dist > 0.5 * reach:
                            h = math.cos(math.pi * (dist / reach - 0.5))
                            taper = h * h
                        idx = (j0 - offsets[b] * TABLE_OVERSAMPLE) % n_t
                        v = 0.0 + 0.0j
                        for r in range(dg + TAYLOR_TERMS + 1):
                            v += er[r] * table[idx, r]
                        c[a, b] += v * (fac * taper)
            # ---- the steady parts: unit tone, its image, the carrier lines' taper
            for b in range(n_b):
                pos = centre + offsets[b]
                jp = ((carrier_bin[w] - pos) * TABLE_OVERSAMPLE)
                jm = ((-carrier_bin[w] - pos) * TABLE_OVERSAMPLE)
                kp = table_at(table, jp, 0, n_samples)
                km = table_at(table, jm, 0, n_samples)
                tp = 0.5 * gsum * kp
                tm = 0.5 * gsum * km
                c0 = 0.0 + 0.0j
                for k in range(n_e):
                    for p in range(degree + 1):
                        if c0poly[k, p] != 0.0:
                            c0 += 0.5 * gam[w, k] * c0poly[k, p] * (table_at(table, jp, p, n_samples)
                                                                     + table_at(table, jm, p, n_samples))
                out[w, m, b, 0] = tp
                out[w, m, b, 1] = tm
                out[w, m, b, 2] = c0 - kappa * (tp + tm)
                out[w, m, b, 14] = c0
                # ---- sums over the random lines
                ptot = 0.0
                p2 = 0.0
                pw = 0.0
                qq = 0.0 + 0.0j
                qw = 0.0 + 0.0j
                for a in range(n_act):
                    pa = c[a, b].real ** 2 + c[a, b].imag ** 2
                    ptot += pa
                    p2 += pa * pa
                    pw += fej[a] * pa
                    na = index[act_k[a], neg[act_i[a]]]
                    if na >= 0:
                        qq += c[a, b] * c[na, b]
                        qw += fej[a] * c[a, b] * c[na, b]
                thr = pair_tol * (ptot + abs(c0) ** 2)
                n_sig = 0
                for a in range(n_act):
                    if c[a, b].real ** 2 + c[a, b].imag ** 2 >= thr:
                        sig[n_sig] = a
                        n_sig += 1
                sf = 0.0
                sfw = 0.0
                uu = 0.0 + 0.0j
                uw = 0.0 + 0.0j
                vv = 0.0 + 0.0j
                vw = 0.0 + 0.0j
                if coherent:
                    for k in range(n_e):
                        n_touch = 0
                        for ia in range(n_sig):
                            a = sig[ia]
                            if act_k[a] != k:
                                continue
                            for ib in range(n_sig):
                                bb = sig[ib]
                                if bb == a or act_k[bb] != k:
                                    continue
                                code = 0
                                for j in range(4):
                                    code += (vectors[act_i[a], j] - vectors[act_i[bb], j] + off) * codes_pow[j]
                                if acc[code] == 0.0:
                                    touched[n_touch] = code
                                    n_touch += 1
                                    acc_w[code] = fejer_at(ftab, (act_w[a] - act_w[bb]) * ramp_rad)
                                acc[code] += c[a, b] * np.conj(c[bb, b])
                        for t in range(n_touch):
                            code = touched[t]
                            s_d = acc[code]
                            fw = acc_w[code]
                            mag2 = s_d.real ** 2 + s_d.imag ** 2
                            sf += mag2
                            sfw += fw * mag2
                            # the D line and the -D line of this engine, when active
                            li = line_of_code[code] if code < line_of_code.shape[0] else -1
                            if li >= 0:
                                la = index[k, li]
                                if la >= 0:
                                    vv += np.conj(s_d) * c[la, b]
                                    vw += fw * np.conj(s_d) * c[la, b]
                                ln = neg[li]
                                la = index[k, ln]
                                if la >= 0:
                                    uu += np.conj(s_d * c[la, b])
                                    uw += fw * np.conj(s_d * c[la, b])
                            acc[code] = 0.0
                    # pairs of lines of two engines: one pair per D
                    if n_e > 1:
                        for ia in range(n_sig):
                            a = sig[ia]
                            pa = c[a, b].real ** 2 + c[a, b].imag ** 2
                            for ib in range(n_sig):
                                bb = sig[ib]
                                if act_k[bb] == act_k[a]:
                                    continue
                                pb = c[bb, b].real ** 2 + c[bb, b].imag ** 2
                                sf += pa * pb
                                sfw += fejer_at(ftab, (act_w[a] - act_w[bb]) * ramp_rad) * pa * pb
                else:
                    # pairs summed incoherently (every D taken as one pair): sum_{a != b} p_a p_b,
                    # its Fejer-weighted part over the significant lines, the rest at the mean
                    # weight 1 / K
                    sf = ptot * ptot - p2
                    sig_pairs = 0.0
                    for ia in range(n_sig):
                        a = sig[ia]
                        pa = c[a, b].real ** 2 + c[a, b].imag ** 2
                        for ib in range(n_sig):
                            if ib == ia:
                                continue
                            bb = sig[ib]
                            pb = c[bb, b].real ** 2 + c[bb, b].imag ** 2
                            sig_pairs += pa * pb
                            sfw += fejer_at(ftab, (act_w[a] - act_w[bb]) * ramp_rad) * pa * pb
                    sfw += max(sf - sig_pairs, 0.0) / ramps
                o = out[w, m, b]
                o[3] = ptot
                o[4] = p2
                o[5] = pw
                o[6] = qq
                o[7] = qw
                o[8] = uu
                o[9] = uw
                o[10] = vv
                o[11] = vw
                o[12] = sf
                o[13] = sfw
    return out


if numba is not None:
    _line_sums = numba.njit(cache=True)(_line_sums_py)


def line_sums(gam, amp, freq, carrier_bin, centres, offsets, *, ramps: int = 1, g1: float = 1.0,
              amp_tol: float = 1e-5, pair_tol: float = 1e-4, order: int | None = None, coherent: bool = True,
              reach_tol: float = 0.0,
              radar: RadarConfig = RadarConfig()) -> np.ndarray:
    """Per-bin sums of the line spectrum (see :data:`SUM_NAMES`), compiled.

    gam (W, E) Gamma per engine; amp (W, E, 4) term amplitudes (m) and freq (W, E, 4)
    term frequencies (rad/s), terms a, b, p, m; carrier_bin (W,) the carrier's
    fractional FFT bin; centres (W, M) each measurement's centre (fractional bin);
    offsets (B,) integer bins from the centre. ramps: K (for the Fejer weights);
    g1: mean power gain of the random lines (1 + 1/N with an N-frame MTI).
    Returns (W, M, B, N_SUMS) complex128.
    """
    if numba is None:  # pragma: no cover
        raise ImportError("the closed-form moments need numba (pip install numba)")
    amp = np.ascontiguousarray(amp, np.float64)
    beta_scale = np.array([radar.model_k * radar.chirp_duration_s, float(radar.samples_per_chirp)])
    if order is None:
        order = order_for(float(beta_scale[0] * np.abs(amp).max()) if amp.size else 0.0, max(amp_tol, 1e-9))
    tables = line_tables(int(order))
    degree = int(min(MAX_DEGREE, max(8, 2 * order + 10)))
    table = kernel_table(radar.samples_per_chirp, radar.fft_points, degree + TAYLOR_TERMS)
    return _line_sums(np.ascontiguousarray(gam, np.float64), amp, np.ascontiguousarray(freq, np.float64),
                      beta_scale, np.ascontiguousarray(carrier_bin, np.float64),
                      np.ascontiguousarray(centres, np.float64), np.ascontiguousarray(offsets, np.int64),
                      table, tables.vectors, tables.neg, tables.powers, tables.base, tables.line_of_code,
                      fejer_table(int(ramps)), int(ramps), float(radar.ramp_period_s), float(g1), float(amp_tol), float(pair_tol),
                      float(radar.bin_hz), bool(coherent),
                      float(reach_tol) if reach_tol > 0 else 1e-300)
