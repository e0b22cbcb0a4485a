"""The README keeps its promises: the register map is the generated one, the set-up commands are real."""

from __future__ import annotations

import re
from pathlib import Path

from firmware_interface.fields import render_register_table

REPO = Path(__file__).resolve().parents[1]
README = (REPO / "README.md").read_text()


def test_register_map_in_readme_is_generated_from_the_field_table():
    m = re.search(r"<!-- registers:begin -->\n(.*)<!-- registers:end -->", README, re.S)
    assert m, "README lost its register-map markers"
    assert m.group(1) == render_register_table(), (
        "README register map differs from firmware_interface/fields.py; regenerate it"
    )


def test_ci_runs_exactly_the_readme_test_command():
    blocks = re.findall(r"```sh\n(.*?)\n```", README, re.S)
    test_cmd = blocks[1].strip()
    ci = (REPO / ".ci" / "run").read_text().strip().splitlines()
    assert ci[-1].strip() == test_cmd


def test_readme_names_every_command():
    from raingauge.cli import COMMANDS

    for name in COMMANDS:
        assert f"raingauge {name}" in README, name
