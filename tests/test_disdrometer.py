"""Parsivel reader, rain from raw counts, the `raingauge dsd` command, and the real Locarno day."""

from __future__ import annotations

import gzip
import math
from datetime import datetime, timezone

import numpy as np
import pytest

from raingauge import disdrometer as dis
from raingauge.cli import main
from raingauge.errors import InputError
from raingauge.physics import drops

D_M = drops.PARSIVEL_D_CENTRES_MM * 1e-3
DW_M = drops.PARSIVEL_D_WIDTHS_MM * 1e-3
V = drops.PARSIVEL_V_CENTRES_M_S


def telegram(time: str = "28-10-2018 12:00:00", rate: str = "0012.500", counts=None) -> str:
    """One line in the campaign's format (24 fields, 20-22 quoted)."""
    if counts is None:
        counts = np.zeros((32, 32), dtype=int)
    raw = ",".join(f"{int(c):03d}" for c in np.asarray(counts).ravel()) + ","
    nd = ",".join(["-9.999"] * 32) + ","
    vd = ",".join(["00.000"] * 32) + ","
    head = ["610908", "4610.3530", "00847.2425", f'"{time}"', '"na"', '"OK"', f'"{rate}"', '"0000.02"',
            '"61"', '"61"', '"30.000"', '"5000"', '"09893"', '"00010"', '"017"', '"0.04"', '"26.6"', '"0"',
            '"000.002"', '"000"']
    return ",".join(head + [f'"{nd}"', f'"{vd}"', f'"{raw}"', '"0"'])


def counts_for(n_m4: np.ndarray, v_index: np.ndarray, interval_s: float = 30.0) -> np.ndarray:
    """Counts that a spectrum N(D) falling at class speeds would produce (may be fractional)."""
    c = np.zeros((32, 32))
    area = dis.effective_area_m2(D_M)
    c[v_index, np.arange(32)] = n_m4 * DW_M * area * interval_s * V[v_index]
    return c


# ---------------------------------------------------------------------------
# Rain and spectra from counts
# ---------------------------------------------------------------------------

def test_effective_area():
    assert dis.effective_area_m2(0.0) == pytest.approx(0.180 * 0.030)
    assert dis.effective_area_m2(2e-3) == pytest.approx(0.180 * 0.029)


def test_rain_rate_from_counts_by_hand():
    counts = np.zeros((32, 32), dtype=int)
    counts[20, 12] = 100  # 100 drops of 1.875 mm at 4.4 m/s
    d = 1.875e-3
    expected = 3.6e6 * 100 * math.pi / 6 * d ** 3 / (0.180 * (0.030 - d / 2) * 30.0)
    assert dis.counts_rain_rate_mm_h(counts) == pytest.approx(expected)
    assert dis.counts_rain_rate_mm_h(counts, interval_s=60.0) == pytest.approx(expected / 2)
    with pytest.raises(ValueError):
        dis.counts_rain_rate_mm_h(np.zeros((32, 31)))


def test_density_round_trip_from_a_known_spectrum():
    dsd = drops.MarshallPalmer(10.0)
    n = dsd.number_density(D_M)
    v_idx = np.array([np.argmin(abs(V - v)) for v in np.nan_to_num(drops.fall_velocity(D_M, "gunn_kinzer"), nan=0.05)])
    c = counts_for(n, v_idx)
    assert np.allclose(dis.record_density_m4(c), n, rtol=1e-12, atol=0)


def test_record_moments_agree_with_counts_rate():
    rng = np.random.default_rng(0)
    counts = rng.poisson(2.0, size=(32, 32)) * (np.arange(32)[None, :] < 20)
    m = dis.record_moments(counts)
    assert m["rain_rate_mm_h"] == pytest.approx(dis.counts_rain_rate_mm_h(counts), rel=1e-12)
    assert m["nt_m3"] == pytest.approx(np.sum(dis.record_density_m4(counts) * DW_M))
    dsd = dis.record_dsd(counts)
    assert dsd.concentration_m3() == pytest.approx(m["nt_m3"])
    empty = dis.record_moments(np.zeros((32, 32)))
    assert empty["rain_rate_mm_h"] == 0.0 and math.isnan(empty["z_dbz"])


# ---------------------------------------------------------------------------
# Reader
# ---------------------------------------------------------------------------

def test_reader_parses_fields(tmp_path):
    counts = np.zeros((32, 32), dtype=int)
    counts[21, 14] = 7
    path = tmp_path / "one.dat"
    path.write_text(telegram(counts=counts) + "\n")
    pf = dis.read_parsivel(path)
    assert pf.malformed_lines == 0 and len(pf.records) == 1
    r = pf.records[0]
    assert r.time == datetime(2018, 10, 28, 12, 0, 0, tzinfo=timezone.utc)
    assert r.reported_rate_mm_h == 12.5
    assert r.counts.shape == (32, 32) and r.counts[21, 14] == 7 and r.counts.sum() == 7
    assert r.reported_z_dbz == 30.0 and r.synop_4680 == 61 and r.particle_count == 10
    assert np.all(np.isnan(r.reported_log10_n))


def test_malformed_lines_are_counted_never_fatal(tmp_path):
    good = telegram()
    bad = [
        "garbage",
        good.replace('"28-10-2018 12:00:00"', '"2018/10/28 12:00"'),      # bad time
        good.replace('"0012.500"', '"12,5x"'),                             # bad rate
        good.replace('"000,000,', '"000,', 1),                            # 1023 counts
        good.replace('"000,000,', '"abc,000,', 1),                        # non-numeric count
        good.rsplit(",", 1)[0],                                            # 23 fields
    ]
    lines = [good, *bad, "", good.replace("12:00:00", "12:00:30")]
    path = tmp_path / "mixed.dat.gz"
    with gzip.open(path, "wt") as fh:
        fh.write("\n".join(lines) + "\n")
    pf = dis.read_parsivel(path)
    assert len(pf.records) == 2
    assert pf.malformed_lines == len(bad)
    assert [n for n, _ in pf.malformed_examples] == [2, 3, 4, 5, 6, 7]
    assert any("time" in why for _, why in pf.malformed_examples)


def test_missing_file_is_a_clear_error(tmp_path):
    with pytest.raises(InputError, match="not found"):
        dis.read_parsivel(tmp_path / "nope.dat")
    broken = tmp_path / "broken.dat.gz"
    broken.write_bytes(gzip.compress(b"x" * 1000)[:15])
    with pytest.raises(InputError, match="cannot read"):
        dis.read_parsivel(broken)


def test_dsd_command_writes_rows_and_summary(tmp_path, capsys):
    counts = np.zeros((32, 32), dtype=int)
    counts[20, 12] = 50
    lines = [telegram(counts=counts), "broken line", telegram(time="29-10-2018 00:00:30", counts=counts)]
    src = tmp_path / "in.dat"
    src.write_text("\n".join(lines) + "\n")
    out = tmp_path / "out.csv"
    assert main(["dsd", str(src), "--csv", str(out)]) == 0
    err = capsys.readouterr().err
    assert "1 malformed" in err and "2018-10-28" in err and "2018-10-29" in err
    rows = out.read_text().splitlines()
    header = rows[0].split(",")
    for col in ("time", "reported_rate_mm_h", "rate_mm_h", "z_dbz", "dm_mm", "nt_m3"):
        assert col in header
    assert len(rows) == 3
    first = dict(zip(header, rows[1].split(",")))
    assert first["time"] == "2018-10-28T12:00:00Z"
    assert float(first["rate_mm_h"]) == pytest.approx(dis.counts_rain_rate_mm_h(counts), abs=1e-3)
    # to standard output
    assert main(["dsd", str(src), "--csv", "-"]) == 0
    assert capsys.readouterr().out.splitlines()[0].startswith("time,")


def test_dsd_command_missing_file(tmp_path, capsys):
    assert main(["dsd", str(tmp_path / "none.dat")]) == 2
    assert "not found" in capsys.readouterr().err


# ---------------------------------------------------------------------------
# The real Parsivel day (Locarno, 26-29 Oct 2018)
# ---------------------------------------------------------------------------

@pytest.fixture(scope="module")
def locarno(shared_data):
    path = shared_data / "parsivel" / "locarno_2018-10-29.dat.gz"
    if not path.is_file():
        pytest.skip(f"Parsivel data not found at {path}")
    pf = dis.read_parsivel(path)
    ours = np.array([dis.counts_rain_rate_mm_h(r.counts) for r in pf.records])
    reported = np.array([r.reported_rate_mm_h for r in pf.records])
    return pf, ours, reported


@pytest.mark.shared_data
def test_locarno_reads_every_record(locarno):
    pf, ours, reported = locarno
    assert len(pf.records) == 6526 and pf.malformed_lines == 0
    assert reported.max() == pytest.approx(38.472)


@pytest.mark.shared_data
def test_locarno_total_within_5_percent(locarno):
    pf, ours, reported = locarno
    total_ours = ours.sum() * 30 / 3600
    total_reported = reported.sum() * 30 / 3600
    assert total_reported == pytest.approx(166.1, abs=0.5)
    # the instrument's own accumulator agrees with its intensities
    assert pf.records[-1].reported_accumulation_mm == pytest.approx(total_reported, rel=0.01)
    assert total_ours == pytest.approx(total_reported, rel=0.05)
    for day, (o, r) in dis.daily_totals_mm(pf.records).items():
        if r > 10:
            assert o == pytest.approx(r, rel=0.05), day


@pytest.mark.shared_data
def test_locarno_per_record_median_ratio(locarno):
    pf, ours, reported = locarno
    wet = reported > 0.1
    assert wet.sum() > 3000
    ratio = np.median(ours[wet] / reported[wet])
    assert 0.95 <= ratio <= 1.05


@pytest.mark.shared_data
def test_locarno_reflectivity_matches_the_instrument(locarno):
    pf, ours, reported = locarno
    sel = [r for r in pf.records if r.reported_rate_mm_h > 1.0][::10]
    dz = [dis.record_moments(r.counts)["z_dbz"] - r.reported_z_dbz for r in sel]
    assert abs(np.nanmedian(dz)) < 1.0


@pytest.mark.parametrize("content, args, message", [
    (b"\x89PNG\r\n\x1a\n" + bytes(range(256)) * 4, [], "holds no Parsivel telegram"),
    (b"", [], "holds no Parsivel telegram"),
    (b"garbage\n", [], "line 1: 1 fields"),
    (None, [], "is a folder"),
    (b"x\n", ["--interval", "inf"], "--interval"),
    (b"x\n", ["--interval", "0"], "--interval"),
    (b"x\n", ["--interval", "abc"], "invalid float value: 'abc'"),
])
def test_dsd_command_bad_input(tmp_path, cli_error, content, args, message):
    src = tmp_path / "in.dat"
    if content is None:
        src = tmp_path
    else:
        src.write_bytes(content)
    out = tmp_path / "out.csv"
    _, err = cli_error(["dsd", src, "--csv", out, *args], message)
    assert "Fix" in err or "give" in err
    # the input is refused before the table is opened: no empty CSV is left behind
    assert not out.exists()
