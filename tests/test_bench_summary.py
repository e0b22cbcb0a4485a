"""The accuracy benchmark's summary: a saved run read back gives the same rows, the table counts
each clip against its own target (15 % from 2 mm/h on, 0.2 mm/h below)."""

from __future__ import annotations

import math

import pytest
from bench_helpers import load_benchmark



@pytest.fixture(scope="module")
def bench():
    return load_benchmark("bench_gauge_accuracy")


def _row(rate, bg, noise, wind, dsd, true, meas, *, flags="", hi=None, dm_m=1.0, d_er=-1.2, comp=0.0):
    return dict(rate=rate, bg=bg, noise=noise, wind=wind, dsd=dsd, true=true, meas=meas, lo=0.8 * meas,
                hi=1.2 * meas if hi is None else hi, cov=0.8 * meas <= true <= (1.2 * meas if hi is None else hi),
                n=1234, stat=0.052, dm_t=1.00, dm_m=dm_m, fps=71.3, d_er=d_er, comp=comp, flags=flags)


ROWS = [
    _row(0.5, "dark_uniform", 1.0, 0.0, "marshall_palmer", 0.598, 0.547),      # 0.05 mm/h off: in
    _row(0.5, "dark_uniform", 1.0, 3.0, "gamma3", 0.498, 0.250, flags="too_few_drops,low_contrast"),  # out
    _row(2.0, "dark_uniform", 1.0, 0.0, "parsivel", 1.750, 1.900),             # true < 2: 0.15 mm/h, in
    _row(2.0, "dark_uniform", 1.0, 3.0, "marshall_palmer", 2.210, 2.600),      # +17.6 %: out
    _row(10.0, "bright_sky", 3.0, 0.0, "gamma3", 10.40, 11.50, hi=float("inf"), dm_m=float("nan"),
         d_er=float("nan"), comp=0.27),                                       # +10.6 %
    _row(10.0, "bright_sky", 3.0, 3.0, "gamma3", 10.40, 9.00),                 # -13.5 %: in
]


def test_saved_run_reads_back_as_printed(bench):
    text = "\n".join(["# gauge accuracy: 6 clips", *map(bench.format_row, ROWS), "# rain-free clips",
                      "   objects: 0.0031 mm/h  drops 2  flags scene_motion",
                      "   ripples: 0.0000 mm/h  drops 0  flags ", "     noise: 0.0120 mm/h  drops 1  flags "])
    rows, free = bench.parse_output(text)
    assert free == [0.0031, 0.0, 0.012]
    assert len(rows) == len(ROWS)
    for got, want in zip(rows, ROWS):
        for key in ("rate", "bg", "noise", "wind", "dsd", "cov", "n", "flags"):
            assert got[key] == want[key], key
        for key in ("true", "meas", "lo", "hi", "stat", "dm_t", "dm_m"):
            assert got[key] == pytest.approx(want[key], abs=6e-4) or (math.isnan(got[key]) and math.isnan(want[key]))
        if math.isnan(want["d_er"]):
            assert math.isnan(got["d_er"])
        else:
            assert got["d_er"] == pytest.approx(want["d_er"], abs=0.05)
        assert got["comp"] == pytest.approx(want["comp"], abs=6e-4)


def test_runs_saved_before_the_brightness_and_completion_columns_still_read(bench):
    """A row printed without the drop brightness error and the completed share (runs saved
    before those columns) reads back with them NaN, flags and all."""
    old = ("  10.0      bright_sky   3.0  3.0          gamma3 |   10.022   14.705  1.467 [  6.626,  26.797]   y"
           "  2041   3.6  1.52  1.31  23.8 low_contrast")
    (row,), _ = bench.parse_output(old)
    assert (row["meas"], row["fps"], row["flags"]) == (14.705, 23.8, "low_contrast")
    assert math.isnan(row["d_er"]) and math.isnan(row["comp"])
    new = bench.format_row({**row, "d_er": -0.9, "comp": 0.27})
    (again,), _ = bench.parse_output(new)
    assert (again["d_er"], again["comp"], again["flags"]) == (-0.9, 0.27, "low_contrast")


def test_table_counts_each_clip_against_its_own_target(bench):
    table = bench.table_lines(ROWS)
    assert table[0] == "| background, noise | 0.5 mm/h | 2 mm/h | 10 mm/h |"
    assert table[2] == "| dark uniform, 1 | 1/2 (0.50-0.91) | 1/2 (1.09-1.18) |  |"
    assert table[3] == "| bright sky, 3 |  |  | 2/2 (0.87-1.11) |"


def test_summary_names_the_misses_and_the_targets(bench):
    lines = bench.summary_lines(ROWS, [0.0031, 0.0, 0.012])
    text = "\n".join(lines)
    # three clips of >= 2 mm/h: 17.6 %, 10.6 %, 13.5 %
    assert "rates >= 2 mm/h: 3 clips, median |error| 13.5 %" in text
    assert "max 17.6 %" in text and "within 15 %: 67 %" in text
    assert text.count("beyond 15 %:") == 1 and "2 mm/h dark_uniform noise 1 wind 3 marshall_palmer: 1.176" in text
    assert "rates < 2 mm/h: 3 clips, max |error| 0.248 mm/h [<= 0.2], within 0.2: 67 %" in text
    assert "rain-free: max 0.0120 mm/h" in text


def test_summarize_merges_saved_runs_and_refuses_what_is_not_one(bench, tmp_path, capsys):
    first = tmp_path / "full.txt"
    first.write_text("\n".join(map(bench.format_row, ROWS)) + "\n")
    rerun = dict(ROWS[3], meas=2.300)
    second = tmp_path / "rerun.txt"
    second.write_text(bench.format_row(rerun) + "\n")
    assert bench.main(["--summarize", str(first), str(second)]) == 0
    out = capsys.readouterr().out
    assert "# 6 clips from 2 file(s)" in out
    assert "beyond 15 %" not in out  # the rerun's 2.300 (+4.1 %) replaced the first run's 2.600
    assert "| dark uniform, 1 | 1/2 (0.50-0.91) | 2/2 (1.04-1.09) |  |" in out

    junk = tmp_path / "junk.txt"
    junk.write_text("not a run\n")
    assert bench.main(["--summarize", str(junk)]) == 2
    assert "holds no clip rows" in capsys.readouterr().err
    assert bench.main(["--summarize", str(tmp_path / "absent.txt")]) == 2
    assert "cannot read" in capsys.readouterr().err


def test_compare_pairs_two_versions_clip_by_clip(bench, tmp_path, capsys):
    """Two versions' runs side by side over the clips both ran, a star on each miss, and each
    version's count within target over those clips; runs that share no clip are refused."""
    before = tmp_path / "before.txt"
    before.write_text("\n".join(map(bench.format_row, ROWS)) + "\n")
    after_rows = [dict(ROWS[3], meas=2.300), dict(ROWS[5], meas=12.5)]       # +4.1 % and +20.2 %
    after = tmp_path / "after.txt"
    after.write_text("\n".join(map(bench.format_row, after_rows)) + "\n")
    assert bench.main(["--compare", str(before), str(after)]) == 0
    out = capsys.readouterr().out
    assert "# 2 clips run by both (6 before, 2 after)" in out
    assert "|  1.176*  1.041 " in out           # the first version's miss, the second's hit
    assert "|  0.865   1.202*" in out
    assert "# before: 1 of 2 within target" in out
    assert "# after: 1 of 2 within target" in out

    other = tmp_path / "other.txt"
    other.write_text(bench.format_row(ROWS[0]) + "\n")
    assert bench.main(["--compare", str(other), str(after)]) == 2
    assert "share no clip" in capsys.readouterr().err
    assert bench.main(["--compare", str(tmp_path / "absent.txt"), str(after)]) == 2
    assert "cannot read" in capsys.readouterr().err
