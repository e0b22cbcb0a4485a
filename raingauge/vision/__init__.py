"""raingauge.vision"""
