"""Camera profiles shipped with raingauge (TOML files beside this module)."""
