"""benchmarks/diag_drop_brightness.py: the needed and the probe's reference of the drop
brightness at other percentiles (``--percentiles``)."""

from __future__ import annotations

import re

import numpy as np
import pytest
from bench_helpers import load_benchmark

from raingauge.gauge.gauge import focus_percentile


@pytest.fixture(scope="module")
def diag():
    return load_benchmark("diag_drop_brightness")


def _clip(q_true, probe_q, probe_w=None):
    probe_q = np.asarray(probe_q, dtype=float)
    return {"q_true": np.asarray(q_true, dtype=float), "probe_q": probe_q,
            "probe_w": np.ones(probe_q.size) if probe_w is None else np.asarray(probe_w, dtype=float),
            "q_min": 0.6}


def _ratios(lines):
    return [float(re.search(r"needed/probe's\s+(\S+)", line).group(1)) for line in lines if "needed/probe's" in line]


def test_the_same_samples_need_the_probe_s_own_reference(diag):
    q = np.clip(np.random.default_rng(1).normal(0.85, 0.12, 4000), 0.0, None)
    lines = diag.percentile_rows(_clip(q, q), [50, 75, 90])
    assert _ratios(lines) == pytest.approx([1.0, 1.0, 1.0], abs=1e-3)
    # one line per percentile, then the quantiles of either set, the same here
    assert len(lines) == 4
    streaks, probe = re.search(r"streaks (.*), probe's (.*)$", lines[-1]).groups()
    assert [float(x) for x in streaks.split()] == pytest.approx([float(x) for x in probe.split()], abs=2e-3)


def test_a_dimmer_probe_needs_a_larger_reference(diag):
    rng = np.random.default_rng(2)
    q = np.clip(rng.normal(0.9, 0.08, 5000), 0.0, None)
    lines = diag.percentile_rows(_clip(q, 0.9 * q), [50, 75, 95])
    # every q' scaled by 0.9 scales each fixed point by 0.9 (the cut q_min m scales with it)
    assert _ratios(lines) == pytest.approx([1 / 0.9] * 3, rel=2e-3)


def test_the_probe_s_samples_are_taken_with_their_weights(diag):
    rng = np.random.default_rng(4)
    lo, hi = rng.normal(0.7, 0.03, 2000), rng.normal(1.0, 0.03, 2000)
    probe_q = np.concatenate([lo, hi])
    weights = np.concatenate([np.full(2000, 0.1), np.ones(2000)])
    line = diag.percentile_rows(_clip(hi, probe_q, weights), [50])[0]
    need = focus_percentile(hi, q_min=0.6, percentile=50)
    own = focus_percentile(probe_q, weights, q_min=0.6, percentile=50)
    assert _ratios([line])[0] == pytest.approx(need / own, abs=1e-3)
    assert _ratios([line])[0] == pytest.approx(1.0, abs=0.03)
    # unweighted, half the probe's samples lie near 0.7 and its median far lower
    assert own > focus_percentile(probe_q, q_min=0.6, percentile=50) + 0.1


@pytest.mark.parametrize("bad", ["0,50", "75,100", "x"])
def test_percentiles_outside_0_100_end_the_script_with_the_fix(diag, bad, capsys):
    with pytest.raises(SystemExit) as exc:
        diag.main(["--percentiles", bad])
    assert exc.value.code == 2
    assert "--percentiles" in capsys.readouterr().err
