"""The one table of output fields drives registers, sentences, columns and docs."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from firmware_interface import fields as F

REPO = Path(__file__).resolve().parents[1]


def test_docs_file_matches_the_table():
    """docs/modbus_registers.md is exactly what the table renders (regenerate with
    `python -m firmware_interface.fields > docs/modbus_registers.md`)."""
    text = (REPO / "docs" / "modbus_registers.md").read_text()
    assert text == F.render_docs()


def test_contract_addresses_of_the_issue():
    """The register map agreed with station integrators."""
    reg = {f.name: (f.register, f.reg_type) for f in F.FIELDS if f.register is not None}
    assert reg["device_id_version"] == (0, "uint16")
    assert reg["status"] == (1, "uint16")
    assert reg["rain_rate_mm_h"] == (2, "uint16")
    assert reg["accumulation_mm"] == (3, "uint32")
    assert reg["drops_counted"] == (5, "uint16")
    assert reg["dm_mm"] == (6, "uint16")
    assert reg["z_dbz"] == (7, "int16")
    assert reg["intensity_class"] == (8, "uint16")
    assert reg["synop_4680"] == (9, "uint16")
    assert reg["time_unix"] == (10, "uint32")
    nd = F.FIELD_BY_NAME["dsd_n_m3_mm"]
    assert (nd.register, nd.register + nd.register_count - 1) == (100, 131)
    assert min(f.float_register for f in F.FIELDS if f.float_register is not None) == 200
    assert F.STATUS_BITS == {"camera_ok": 0, "rain_detected": 1, "low_confidence": 2,
                             "calibrated": 3, "storage_fault": 4, "output_fault": 5}
    assert [h.address for h in F.HOLDING_REGISTERS] == [0, 1, 2]


NAN = float("nan")


@pytest.mark.parametrize("name,value,words,back", [
    ("rain_rate_mm_h", 12.34, [1234], 12.34),
    ("rain_rate_mm_h", NAN, [65535], NAN),
    ("rain_rate_mm_h", 1e6, [65534], 655.34),          # saturates below "invalid"
    ("rain_rate_mm_h", -1.0, [0], 0.0),
    ("accumulation_mm", 1234.56, [0x0001, 0xE240], 1234.56),   # 123456, high word first
    ("z_dbz", -3.2, [0x10000 - 32], -3.2),
    ("z_dbz", None, [0x7FFF], NAN),
    ("dsd_n_m3_mm", 100.0, [2000], 100.0),           # log10(100) x 1000
    ("dsd_n_m3_mm", 0.0, [0x8000], 0.0),
    ("dsd_n_m3_mm", 0.01, [0x10000 - 2000], 0.01),
])
def test_register_encoding(name, value, words, back):
    f = F.FIELD_BY_NAME[name]
    assert F.encode_register(f, value) == words
    got = F.decode_register(f, words)
    if math.isnan(back):
        assert math.isnan(got)
    else:
        assert got == pytest.approx(back, rel=1e-6)


def test_float32_words_high_first():
    import struct

    words = F.encode_float32(12.5)
    assert struct.unpack(">f", struct.pack(">HH", *words))[0] == 12.5
    assert math.isnan(F.decode_float32(F.encode_float32(None)))


def test_sql_row_has_every_column_and_flattens():
    rec = F.record_defaults()
    rec.update(rain_rate_mm_h=3.0, quality=["few_drops", "short_window"],
               dsd_n_m3_mm=[1.0] * 32, dsd_d_mm=list(range(32)), drops_counted=7)
    row = F.sql_row(rec)
    assert list(row) == F.csv_header() == list(F.sql_columns())
    assert row["quality"] == "few_drops,short_window"
    assert row["dsd_n_m3_mm_01"] == 1.0 and row["dsd_n_m3_mm_32"] == 1.0
    assert row["dsd_d_mm_32"] == 31.0
    assert row["dm_mm"] is None            # NaN -> NULL
    assert row["drops_counted"] == 7


def test_status_word_and_intensity_names():
    assert F.status_word(camera_ok=True, storage_fault=True) == 0b10001
    with pytest.raises(ValueError, match="valid"):
        F.status_word(on_fire=True)
    assert F.intensity_code("heavy") == 3
    assert F.intensity_code(2) == 2
    with pytest.raises(ValueError, match="valid"):
        F.intensity_code("drizzle")


def test_register_image_covers_the_map():
    rec = F.record_defaults()
    rec.update(rain_rate_mm_h=1.0, dsd_n_m3_mm=[10.0] * 32)
    image = F.input_register_image(rec, device_id=7)
    assert image[0] == [(7 << 8) | F.FIRMWARE_VERSION_BYTE]
    assert image[2] == [100]
    assert image[100] == [1000] * 32
    assert len(image[230]) == 64
