"""Shared pytest fixtures."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def shared_data_dir() -> Path:
    """Where the outside test material lives: $RAINGAUGE_SHARED_DATA or ../shared/data."""
    env = os.environ.get("RAINGAUGE_SHARED_DATA")
    return Path(env) if env else REPO.parent / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """Path to ../shared/data; skips the test when the material is absent."""
    path = shared_data_dir()
    if not path.is_dir():
        pytest.skip(f"outside test data not found at {path} (set RAINGAUGE_SHARED_DATA to its folder)")
    return path


@pytest.fixture
def run_cli(capsys):
    """Run ``raingauge ARGV`` in this process -> (exit status, stdout, stderr).

    Option errors found by argparse leave through SystemExit; its code is the status.
    """
    from raingauge.cli import main

    def run(argv):
        try:
            status = main([str(a) for a in argv])
        except SystemExit as exc:
            status = exc.code
        out, err = capsys.readouterr()
        return status, out, err

    return run


@pytest.fixture
def cli_error(run_cli):
    """Check that ``raingauge ARGV`` is refused: status 2, one ``raingauge: error: ...`` line naming
    ``message``, no traceback.  Returns (stdout, stderr)."""

    def check(argv, message):
        status, out, err = run_cli(argv)
        assert status == 2, (status, err)
        assert err.splitlines()[-1].startswith("raingauge: error:"), err
        assert message in err, err
        assert "Traceback" not in err
        return out, err

    return check
