"""raingauge.render"""
