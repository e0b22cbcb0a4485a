"""raingauge.instrument"""
