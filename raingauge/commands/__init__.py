"""Subcommands of the ``raingauge`` command line (see :mod:`raingauge.cli`)."""
