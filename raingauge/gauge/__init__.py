"""raingauge.gauge"""
